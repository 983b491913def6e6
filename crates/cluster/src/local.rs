//! A [`Transport`] between threads of one process: what the tests run a cluster on (each
//! rank a thread with its own renderer and tracer), and a model of MPI's ordering (messages
//! between two ranks arrive in the order sent).

use std::sync::mpsc::{channel, Receiver, Sender};

use crate::{Tag, Transport};

/// One rank's end of an in-process cluster.
pub struct LocalTransport {
    rank: usize,
    to: Vec<Sender<(usize, Tag, Vec<u8>)>>,
    rx: Receiver<(usize, Tag, Vec<u8>)>,
}

/// The ends of an `n`-rank in-process cluster, rank 0 first. Each end may move to a thread
/// of its own.
pub fn world(n: usize) -> Vec<LocalTransport> {
    let (txs, rxs): (Vec<_>, Vec<_>) = (0..n).map(|_| channel()).unzip();
    rxs.into_iter().enumerate().map(|(rank, rx)| LocalTransport { rank, to: txs.clone(), rx }).collect()
}

impl Transport for LocalTransport {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.to.len()
    }
    fn send(&self, to: usize, tag: Tag, bytes: &[u8]) {
        // A rank that has gone (its thread ended) takes nothing, as a dead process would.
        let _ = self.to[to].send((self.rank, tag, bytes.to_vec()));
    }
    fn try_recv(&self) -> Option<(usize, Tag, Vec<u8>)> {
        self.rx.try_recv().ok()
    }
    /// In one process there is no job to end: panics with the code.
    fn abort(&self, code: i32) -> ! {
        panic!("rank {} aborted the in-process cluster with code {code}", self.rank)
    }
}
