//! Traversal counters: nodes visited, triangle blocks tested, tiles entered, rays traced.
//!
//! Compiled in only with the `stats` feature (`cargo build --release --features
//! megaray-trace/stats`); without it every call here is an empty inline function, so the
//! kernels pay nothing. Counters are per thread (no atomics on the hot path); [`take`] sums and
//! resets those of the calling thread, [`Counters::add`] merges threads.

/// Counts of one thread (or a sum of several).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    pub rays: u64,
    pub nodes: u64,
    pub blocks: u64,
    pub tiles_entered: u64,
}

impl Counters {
    pub fn add(&mut self, o: &Counters) {
        self.rays += o.rays;
        self.nodes += o.nodes;
        self.blocks += o.blocks;
        self.tiles_entered += o.tiles_entered;
    }
}

/// Whether this build counts (the `stats` feature).
pub const ENABLED: bool = cfg!(feature = "stats");

#[cfg(feature = "stats")]
thread_local! {
    static COUNTERS: std::cell::Cell<Counters> = const { std::cell::Cell::new(Counters { rays: 0, nodes: 0, blocks: 0, tiles_entered: 0 }) };
}

#[inline(always)]
#[allow(unused_variables)]
pub(crate) fn count(f: impl FnOnce(&mut Counters)) {
    #[cfg(feature = "stats")]
    COUNTERS.with(|c| {
        let mut v = c.get();
        f(&mut v);
        c.set(v);
    });
}

/// The calling thread's counters since its last `take`, reset to zero.
pub fn take() -> Counters {
    #[cfg(feature = "stats")]
    {
        COUNTERS.with(|c| c.replace(Counters::default()))
    }
    #[cfg(not(feature = "stats"))]
    Counters::default()
}
