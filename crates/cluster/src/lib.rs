//! One frame rendered by many processes: image-space distribution with a work queue.
//!
//! Every rank opens the same scene file itself (checked by its header checksum when the
//! session starts, [`Cluster::join`]) and pages it within its own budget. Rank 0 (the root)
//! owns the frame: it hands out 32x32 tiles on demand ([`Cluster::render_frame`]), renders
//! some itself on a thread of its own, and puts the pieces together (or adds them to an
//! accumulator as they come, [`Cluster::accumulate_frame`]); the other ranks
//! ([`Cluster::serve`]) render what they are given and send it back. A pixel is a pure
//! function of (pixel, frame), so the frame equals, bit for bit, the one a single process
//! renders.
//!
//! The queue hands each rank a batch of tiles in proportion to its threads, shrinking as
//! the frame nears its end, and keeps [`LANES`] batches in flight per rank, so that a rank
//! finds its next batch waiting when it sends one back. A rank that sends nothing for
//! [`ClusterOptions::timeout`] while it holds tiles is *lost*: its tiles go back to the
//! queue and the others finish the frame. Nobody busy-waits: a rank with nothing to do
//! sleeps [`ClusterOptions::poll`] between looks at its messages, so that ranks sharing a
//! machine do not steal each other's cores.
//!
//! The ranks talk through a [`Transport`]: MPI (`mpi::MpiTransport`, behind the `mpi`
//! feature) or threads of one process ([`local`], for tests).

use std::time::Duration;

pub mod local;
#[cfg(feature = "mpi")]
pub mod mpi;
mod root;
pub mod wire;
mod worker;

pub use root::{Cluster, FrameComm};
pub use wire::Tag;

/// Batches in flight per rank.
pub const LANES: u32 = 2;

/// How ranks exchange messages: byte messages with a tag, point to point, in order between
/// any two ranks. Only the thread that made it calls it.
pub trait Transport {
    /// This process's rank, `0..size`.
    fn rank(&self) -> usize;
    /// The number of ranks.
    fn size(&self) -> usize;
    /// Sends `bytes` tagged `tag` to rank `to`.
    fn send(&self, to: usize, tag: Tag, bytes: &[u8]);
    /// A message that has arrived, if any: (from, tag, bytes). Never blocks.
    fn try_recv(&self) -> Option<(usize, Tag, Vec<u8>)>;
    /// Ends every rank of the job with `code` (a lost rank can be neither waited for nor
    /// finalised).
    fn abort(&self, code: i32) -> !;
}

impl<T: Transport + ?Sized> Transport for Box<T> {
    fn rank(&self) -> usize {
        (**self).rank()
    }
    fn size(&self) -> usize {
        (**self).size()
    }
    fn send(&self, to: usize, tag: Tag, bytes: &[u8]) {
        (**self).send(to, tag, bytes)
    }
    fn try_recv(&self) -> Option<(usize, Tag, Vec<u8>)> {
        (**self).try_recv()
    }
    fn abort(&self, code: i32) -> ! {
        (**self).abort(code)
    }
}

/// How patient the ranks are.
#[derive(Clone, Copy, Debug)]
pub struct ClusterOptions {
    /// A rank holding tiles that sends nothing for this long is lost (its tiles go to the
    /// others); a worker that hears nothing from the root for twice this long in a frame
    /// gives up; the root waits this long for every rank's hello.
    pub timeout: Duration,
    /// The sleep between looks at the messages when there is nothing to do.
    pub poll: Duration,
    /// The nice value the render threads run at (the thread that talks to the other ranks
    /// keeps its own): a rank hands out and takes in work while its render threads hold
    /// every core, and a batch waiting on it leaves a render thread idle somewhere else
    /// (`docs/PERF.md`). Linux only; 0 leaves them as they are.
    pub render_nice: i32,
}

impl Default for ClusterOptions {
    fn default() -> ClusterOptions {
        ClusterOptions { timeout: Duration::from_secs(60), poll: Duration::from_micros(50), render_nice: 10 }
    }
}

/// Why a cluster session stopped.
#[derive(Debug, thiserror::Error)]
pub enum ClusterError {
    /// A rank opened a scene file other than rank 0's.
    #[error("rank {rank}'s scene file differs from rank 0's (header checksum {theirs:#018x}, rank 0's {ours:#018x}): every rank must open the same file; not starting")]
    SceneDiffers { rank: usize, ours: u64, theirs: u64 },
    /// The root refused to start because of another rank (the root says why).
    #[error("rank 0 refused to start (rank {0}'s scene file differs)")]
    Refused(usize),
    /// A rank did not say hello in time.
    #[error("rank {rank} did not join within {secs:.0} s")]
    NoHello { rank: usize, secs: f64 },
    /// A worker heard nothing from the root.
    #[error("rank {rank}: nothing from rank 0 for {secs:.0} s; giving up")]
    RootSilent { rank: usize, secs: f64 },
    /// A message that makes no sense.
    #[error("rank {rank} sent a bad message: {what}")]
    Protocol { rank: usize, what: String },
}

/// Lowers every thread of `pool` to `nice` (a per-thread attribute on Linux, which any
/// process may raise; a thread already nicer keeps its value). Elsewhere does nothing.
pub fn lower_priority(pool: &rayon::ThreadPool, nice: i32) {
    #[cfg(target_os = "linux")]
    pool.broadcast(|_| {
        use rustix::process::{getpriority_process, setpriority_process};
        let me = Some(rustix::thread::gettid());
        if getpriority_process(me).is_ok_and(|now| now < nice) {
            // Best effort: a thread that keeps its priority only waits longer.
            let _ = setpriority_process(me, nice);
        }
    });
    #[cfg(not(target_os = "linux"))]
    let _ = (pool, nice);
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use rustix::process::getpriority_process;
    use rustix::thread::gettid;

    #[test]
    fn render_threads_run_nicer_and_never_less_nice() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let now = getpriority_process(Some(gettid())).unwrap();
        let want = (now + 3).min(19);
        super::lower_priority(&pool, want);
        let nice = || pool.broadcast(|_| getpriority_process(Some(gettid())).unwrap());
        assert_eq!(nice(), vec![want; 2]);
        // Asked for less nice than they are, they stay as they are.
        super::lower_priority(&pool, now);
        assert_eq!(nice(), vec![want; 2]);
        // The calling thread is not the pool's.
        assert_eq!(getpriority_process(Some(gettid())).unwrap(), now);
    }
}
