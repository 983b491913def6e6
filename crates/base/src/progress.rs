/// How long-running library code (import, build, render) reports progress.
///
/// The library never draws anything; the command line implements this with progress bars
/// (quiet when not on a terminal). Implementations must be cheap to call from many threads.
pub trait Progress: Sync {
    /// Starts a new stage of `total` units (`0` when unknown) named `what`.
    fn stage(&self, what: &str, total: u64);
    /// `n` more units of the current stage are done.
    fn inc(&self, n: u64);
    /// The current stage is finished.
    fn finish(&self) {}
    /// A message worth showing the user (a summary line, a warning).
    fn note(&self, _msg: &str) {}
}

/// A [`Progress`] that shows nothing.
pub struct NoProgress;

impl Progress for NoProgress {
    fn stage(&self, _what: &str, _total: u64) {}
    fn inc(&self, _n: u64) {}
}
