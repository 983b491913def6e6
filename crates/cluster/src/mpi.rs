//! The MPI [`Transport`] (rsmpi over the system's MPI), for `mpirun -n N megaray ...`.
//! MPI is initialised with `MPI_THREAD_FUNNELED`: only the thread that made the transport
//! calls MPI (the render threads talk to it over channels). Receives probe without blocking
//! (`MPI_Improbe`) and sends are tested (`MPI_Isend`, `MPI_Test`), so that a waiting rank
//! sleeps instead of spinning on a core.

use mpi::environment::Universe;
use mpi::point_to_point::MatchedReceiveVec;
use mpi::topology::SimpleCommunicator;
use mpi::traits::*;
use mpi::Threading;

use crate::{Tag, Transport};

/// This process's place in an MPI job.
pub struct MpiTransport {
    world: SimpleCommunicator,
    rank: usize,
    size: usize,
    /// Finalises MPI when dropped: kept last.
    _universe: Universe,
}

impl MpiTransport {
    /// Initialises MPI. `None` if it was initialised already or could not be.
    pub fn init() -> Option<MpiTransport> {
        let (universe, _level) = mpi::initialize_with_threading(Threading::Funneled)?;
        let world = universe.world();
        let (rank, size) = (world.rank() as usize, world.size() as usize);
        Some(MpiTransport { world, rank, size, _universe: universe })
    }

    /// Whether this process was started by an MPI launcher (`mpirun`, `srun`) as one of
    /// several ranks, by the variables launchers set. Read before initialising MPI, so that a
    /// plain run never touches it.
    pub fn launched() -> bool {
        ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE", "MPI_LOCALNRANKS"]
            .iter()
            .filter_map(|v| std::env::var(v).ok())
            .any(|s| s.trim().parse::<u32>().is_ok_and(|n| n > 1))
    }
}

impl Transport for MpiTransport {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.size
    }
    /// A non-blocking send, tested until done with sleeps between: a blocking send of a
    /// large message spins in MPI's progress loop until the receiver takes it (a tenth of a
    /// worker's time, measured), on a core a render thread could use.
    fn send(&self, to: usize, tag: Tag, bytes: &[u8]) {
        mpi::request::scope(|scope| {
            let mut req = self.world.process_at_rank(to as i32).immediate_send_with_tag(scope, bytes, tag as i32);
            loop {
                match req.test() {
                    Ok(_) => break,
                    Err(r) => {
                        req = r;
                        std::thread::sleep(std::time::Duration::from_micros(50));
                    }
                }
            }
        });
    }
    fn try_recv(&self) -> Option<(usize, Tag, Vec<u8>)> {
        let probed = self.world.any_process().immediate_matched_probe()?;
        let (bytes, status) = probed.matched_receive_vec::<u8>();
        Some((status.source_rank() as usize, status.tag() as Tag, bytes))
    }
    fn abort(&self, code: i32) -> ! {
        self.world.abort(code)
    }
}
