//! Write-behind: stream files written by a thread of their own. A writer fills a buffer
//! and hands it over whole; the thread copies it into the file (the system call's copy into
//! the page cache, and any wait for the disk) while the builder goes on routing or parsing.
//! Without it that copy ran on the one thread of the import and of each split pass while
//! the other core idled (docs/PERF.md, "Out-of-core build: disk").
//!
//! Memory: at most `depth` buffers queued, one being written, and the writers' own.

use std::fs::File;
use std::io::Write;
use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, Sender, SyncSender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use crate::BuildError;

/// A file written by a [`WriteBehind`] thread.
pub struct Target {
    pub path: PathBuf,
    pub file: File,
}

enum Job {
    Write(Arc<Target>, Vec<u8>),
    /// Answered once every job before it is done.
    Sync(Sender<()>),
}

/// One writing thread, shared by any number of files; jobs are done in the order given.
pub struct WriteBehind {
    tx: Option<SyncSender<Job>>,
    /// Written buffers, emptied, for the writers to fill again.
    spare: Mutex<Receiver<Vec<u8>>>,
    /// The first write that failed; later jobs are dropped.
    error: Arc<Mutex<Option<BuildError>>>,
    thread: Option<JoinHandle<()>>,
}

impl WriteBehind {
    /// A thread with at most `depth` buffers waiting for it.
    pub fn new(depth: usize) -> WriteBehind {
        let (tx, rx) = mpsc::sync_channel::<Job>(depth.max(1));
        let (back, spare) = mpsc::channel();
        let error = Arc::new(Mutex::new(None));
        let failed = error.clone();
        let thread = std::thread::Builder::new()
            .name("megaray-write".into())
            .spawn(move || {
                for job in rx {
                    match job {
                        Job::Write(t, mut buf) => {
                            let mut slot = failed.lock().unwrap_or_else(|e| e.into_inner());
                            if slot.is_none() {
                                if let Err(e) = (&t.file).write_all(&buf) {
                                    *slot = Some(BuildError::io(&t.path, "write", e));
                                }
                            }
                            drop(slot);
                            buf.clear();
                            let _ = back.send(buf);
                        }
                        Job::Sync(done) => {
                            let _ = done.send(());
                        }
                    }
                }
            })
            .expect("cannot start the build's writing thread");
        WriteBehind { tx: Some(tx), spare: Mutex::new(spare), error, thread: Some(thread) }
    }

    /// An empty buffer of at least `cap` bytes: a written one again, or a new one.
    pub fn buffer(&self, cap: usize) -> Vec<u8> {
        let again = self.spare.lock().ok().and_then(|r| r.try_recv().ok());
        match again {
            Some(b) if b.capacity() >= cap => b,
            _ => Vec::with_capacity(cap),
        }
    }

    /// Queues `buf` to be appended to `t` (waits while `depth` buffers are queued).
    pub fn write(&self, t: &Arc<Target>, buf: Vec<u8>) -> Result<(), BuildError> {
        self.check()?;
        let tx = self.tx.as_ref().expect("the sender lives until drop");
        tx.send(Job::Write(t.clone(), buf)).map_err(|_| BuildError::io(&t.path, "write", gone()))
    }

    /// Waits until everything queued so far is written; returns the first failure.
    pub fn sync(&self) -> Result<(), BuildError> {
        let (done, wait) = mpsc::channel();
        let tx = self.tx.as_ref().expect("the sender lives until drop");
        if tx.send(Job::Sync(done)).is_ok() {
            let _ = wait.recv();
        }
        self.check()
    }

    fn check(&self) -> Result<(), BuildError> {
        match self.error.lock().unwrap_or_else(|e| e.into_inner()).take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

impl Drop for WriteBehind {
    fn drop(&mut self) {
        drop(self.tx.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn gone() -> std::io::Error {
    std::io::Error::other("the writing thread has stopped")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_arrive_in_order_and_sync_waits_for_them() {
        let dir = tempfile::tempdir().unwrap();
        let wb = WriteBehind::new(2);
        let targets: Vec<Arc<Target>> = (0..3)
            .map(|k| {
                let path = dir.path().join(format!("f{k}"));
                Arc::new(Target { file: File::create(&path).unwrap(), path })
            })
            .collect();
        for round in 0..50u8 {
            for (k, t) in targets.iter().enumerate() {
                let mut b = wb.buffer(16);
                b.extend_from_slice(&[round, k as u8]);
                wb.write(t, b).unwrap();
            }
        }
        wb.sync().unwrap();
        for (k, t) in targets.iter().enumerate() {
            let bytes = std::fs::read(&t.path).unwrap();
            let want: Vec<u8> = (0..50u8).flat_map(|r| [r, k as u8]).collect();
            assert_eq!(bytes, want);
        }
    }

    #[test]
    fn a_failed_write_is_reported_with_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("read-only");
        std::fs::write(&path, b"x").unwrap();
        // Opened for reading only: every write fails.
        let t = Arc::new(Target { file: File::open(&path).unwrap(), path: path.clone() });
        let wb = WriteBehind::new(1);
        let _ = wb.write(&t, vec![1, 2, 3]);
        let e = wb.sync().unwrap_err().to_string();
        assert!(e.contains("read-only"), "{e}");
    }
}
