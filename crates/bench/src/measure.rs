//! Timing, exactly as the peer harness's `measure`: a warm-up pass that calibrates how many
//! passes (`iters`) make one repetition last at least `min_s`, then `reps` repetitions; the
//! figure is per pass. Work items (image tiles, ray chunks) go to the threads dynamically, and
//! each item's checksum lands in its own slot, reduced in item order, so checksums do not
//! depend on the thread count or on scheduling.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Instant;

use rayon::ThreadPool;

/// Checksum of one pass (or one work item): rays that hit, and the sum of their distances.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Acc {
    pub hits: u64,
    pub sum_t: f64,
}

/// The outcome of [`measure`].
#[derive(Clone, Copy, Debug)]
pub struct Measured {
    /// Median seconds per pass over the repetitions.
    pub med_s: f64,
    /// Best (shortest) seconds per pass.
    pub best_s: f64,
    /// Passes per repetition.
    pub iters: u32,
    /// Process CPU seconds per wall second over the repetitions (about the threads that ran).
    pub cpu_util: f64,
    /// Checksum of one pass (of the last repetition).
    pub acc: Acc,
}

/// The median (mean of the middle two for an even count).
pub fn median(mut x: Vec<f64>) -> f64 {
    x.sort_by(f64::total_cmp);
    let n = x.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => x[n / 2],
        _ => 0.5 * (x[n / 2 - 1] + x[n / 2]),
    }
}

/// User plus system CPU seconds of the whole process so far (`getrusage`, as the peer).
#[cfg(unix)]
pub fn cpu_seconds() -> f64 {
    let mut u = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: getrusage writes one rusage into the pointer it is given, which points to
    // zeroed memory of the right size; on failure the zeroed value is read.
    let u = unsafe {
        libc::getrusage(libc::RUSAGE_SELF, u.as_mut_ptr());
        u.assume_init()
    };
    let tv = |t: libc::timeval| t.tv_sec as f64 + 1e-6 * t.tv_usec as f64;
    tv(u.ru_utime) + tv(u.ru_stime)
}

/// CPU time is not measured on this platform (`cpu_util` reads 0).
#[cfg(not(unix))]
pub fn cpu_seconds() -> f64 {
    0.0
}

/// Runs `body(iters)` (which traces the whole ray set `iters` times and returns one pass's
/// checksum) once to warm up and calibrate `iters`, then `reps` times.
pub fn measure(reps: u32, min_s: f64, mut body: impl FnMut(u32) -> Acc) -> Measured {
    let t0 = Instant::now();
    body(1); // warm-up: caches, page faults, thread start-up
    let t1 = t0.elapsed().as_secs_f64();
    let iters = (min_s / t1.max(1e-6)).ceil().clamp(1.0, 1000.0) as u32;
    let mut ts = Vec::with_capacity(reps as usize);
    let mut acc = Acc::default();
    let (w0, c0) = (Instant::now(), cpu_seconds());
    for _ in 0..reps.max(1) {
        let a = Instant::now();
        acc = body(iters);
        ts.push(a.elapsed().as_secs_f64() / iters as f64);
    }
    let cpu_util = (cpu_seconds() - c0) / w0.elapsed().as_secs_f64().max(1e-9);
    let best_s = ts.iter().copied().fold(f64::INFINITY, f64::min);
    Measured { med_s: median(ts), best_s, iters, cpu_util, acc }
}

/// Calls `f(i)` for every `i` in `0..n` on all threads of `pool`, each thread taking the next
/// item from a shared counter (dynamic scheduling, as the peer's `parallel_for`).
pub fn parallel_for(pool: &ThreadPool, n: usize, f: impl Fn(usize) + Sync) {
    let next = AtomicUsize::new(0);
    pool.broadcast(|_| loop {
        let i = next.fetch_add(1, Ordering::Relaxed);
        if i >= n {
            break;
        }
        f(i);
    });
}

/// One checksum slot per work item, each on its own cache line (the threads write them
/// concurrently).
#[repr(align(64))]
#[derive(Default)]
struct Slot {
    hits: AtomicU64,
    sum_t: AtomicU64,
}

/// Per-item checksums, reduced in item order.
pub struct Slots(Vec<Slot>);

impl Slots {
    pub fn new(n: usize) -> Slots {
        Slots((0..n).map(|_| Slot::default()).collect())
    }

    pub fn reset(&self) {
        for s in &self.0 {
            s.hits.store(0, Ordering::Relaxed);
            s.sum_t.store(0, Ordering::Relaxed);
        }
    }

    pub fn set(&self, i: usize, a: Acc) {
        self.0[i].hits.store(a.hits, Ordering::Relaxed);
        self.0[i].sum_t.store(a.sum_t.to_bits(), Ordering::Relaxed);
    }

    /// The sum over all items, in item order (so the same at any thread count).
    pub fn reduce(&self) -> Acc {
        let mut a = Acc::default();
        for s in &self.0 {
            a.hits += s.hits.load(Ordering::Relaxed);
            a.sum_t += f64::from_bits(s.sum_t.load(Ordering::Relaxed));
        }
        a
    }
}

/// Measures `nitems` work items on `pool`: each pass runs `work(i)` for every item, `iters`
/// passes in one parallel region (item `k` of the region is item `k % nitems`).
pub fn measure_items(
    pool: &ThreadPool,
    reps: u32,
    min_s: f64,
    nitems: usize,
    work: impl Fn(usize) -> Acc + Sync,
) -> Measured {
    let slots = Slots::new(nitems);
    measure(reps, min_s, |iters| {
        slots.reset();
        parallel_for(pool, iters as usize * nitems, |k| {
            let i = k % nitems;
            slots.set(i, work(i));
        });
        slots.reduce()
    })
}
