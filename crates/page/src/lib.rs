//! # megaray-page: a scene file within a memory budget
//!
//! A [`Pager`] keeps the resident part of a [`Scene`] under a budget, the way
//! the seed's out-of-core ray tracer did for the Boeing 777 (Wald et al. 2004, "Interactive
//! out-of-core rendering"), with today's tools:
//!
//! - **Tile table.** One 32-bit state word per tile ([`Pager::acquire`]): *available*,
//!   *referenced* (second chance), *requested*, *evicting*, *corrupt*. Tile numbers are dense
//!   (0..tile_count) and links name them directly, so the table is indexed by tile number:
//!   the seed's hash table with a base address to detect collisions is not needed (there
//!   are no collisions). Tracing threads read it lock-free; a tile's bytes are touched only
//!   after its *available* bit was seen under a [`Pin`].
//! - **Asynchronous fetchers** (threads): take requests, deduplicated (one queue entry per
//!   tile, the *requested* bit), most-wanted first (a count of the rays that asked), read
//!   the tile's byte ranges with `pread` into the scene's own memory ([`Scene::load`] of a
//!   scene opened with [`Scene::open_owned`]: nothing of the file is mapped, so resident
//!   memory is exactly what was read, whatever the page cache holds), verify its checksum
//!   and references ([`Scene::check_tile`]) and publish it.
//! - **Second-chance eviction** (clock) whenever resident tile bytes would pass the budget:
//!   a hand sweeps the tile numbers; a referenced tile loses its bit and survives one
//!   sweep, an unreferenced one is evicted. Victims stop being *available*, then a grace
//!   period (epochs, below) waits until no thread can still be reading them, then their
//!   pages are released ([`Scene::release`]: madvise DONTNEED of the owned memory). The
//!   page cache is the operating system's: a tile read again soon may come from it.
//!   Eviction runs down to a low watermark (15/16 of the budget) so that grace periods are
//!   few.
//! - **Pins and grace periods.** A tracing thread holds a [`Pin`] while it traverses (a ray,
//!   or a sample's few rays); pins count into per-thread stripes of two epoch parities.
//!   The evictor flips the epoch and waits for the old parity's counts to drain (classic
//!   two-phase quiescence, as in userspace RCU). Readers never wait for the evictor.
//! - The header page and the tables (top-level tree, part and tile directories, materials)
//!   stay resident: they are "pinned" and counted against the budget up front; so do the
//!   tiles of the coarsest level of detail of every part (a scene built with levels of
//!   detail), loaded when the pager starts: a ray can always be answered by a stand-in.
//!
//! What a resident tile costs: its node and block bytes plus the attributes of its triangle
//! slots ([`Scene::tile_ranges`]), each range widened to whole pages.
//!
//! ```no_run
//! use megaray_page::{Pager, PagerOptions};
//! let pager = Pager::open("big.mray".as_ref(), PagerOptions { budget: 2 << 30, fetchers: 2 }).unwrap();
//! // Hand `&pager` to megaray_trace::Tracer::paged; print pager.stats() after a frame.
//! ```

use std::path::Path;
use std::sync::atomic::{fence, AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering::*};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam::utils::CachePadded;
use megaray_base::format_size;
use megaray_scene::{Scene, SceneError, SceneErrorKind};

/// The tile's bytes are resident and checked: traversal may read them (under a [`Pin`]).
const AVAIL: u32 = 1;
/// Used since the clock hand last passed (second chance).
const REFD: u32 = 2;
/// In the fetchers' queue (or being loaded): further requests only raise its priority.
const REQ: u32 = 4;
/// Chosen as a victim, its pages not yet released: a request for it waits.
const EVICTING: u32 = 8;
/// Failed its check: never loaded again; traversal skips it.
const CORRUPT: u32 = 16;
/// Loaded and not yet used: protected from eviction for [`FRESH_MS`], so that the rays
/// waiting for it get to use it before a busy fetcher pushes it out again.
const FRESH: u32 = 32;

/// Loaded at the start and never evicted: the tiles of the coarsest level of detail of every
/// part, what a ray falls back on when nothing finer is resident.
const PINNED: u32 = 64;

/// How long the one steering by the working set may be silent before another takes over
/// ([`Pager::steer`]).
pub const STEER_STALE_MS: u64 = 2000;

/// How long a loaded tile nobody has used yet is protected from eviction.
const FRESH_MS: u64 = 50;

/// Number of per-thread counter stripes (pins, lookups).
const STRIPES: usize = 64;
/// The page size the pager rounds to.
const PAGE: u64 = 4096;

/// What traversal may do with a tile, from [`Pager::acquire`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    /// Resident and checked: read it (the caller holds a [`Pin`]).
    Ready,
    /// Not resident: it has been requested; suspend the ray until it arrives.
    Missing,
    /// Failed its check: skip it (the fault is in [`Pager::first_error`]).
    Corrupt,
}

/// How to page.
#[derive(Clone, Copy, Debug)]
pub struct PagerOptions {
    /// Budget for resident scene bytes: the pinned tables plus resident tiles.
    pub budget: u64,
    /// Number of fetcher threads (loads in flight at once). Random tile reads scale with
    /// the reads in flight: 8 is a good default on a local SSD.
    pub fetchers: usize,
}

/// Why a pager could not start.
#[derive(Debug, thiserror::Error)]
pub enum PagerError {
    #[error("{path}: a memory budget of {budget} is too small for this scene: at least {need} (its tables take {pinned} and its largest tile {tile})")]
    BudgetTooSmall { path: String, budget: String, need: String, pinned: String, tile: String },
    #[error("{path}: a pager needs the scene opened with Scene::open_owned (this one is mapped)")]
    Mapped { path: String },
    #[error(transparent)]
    Scene(#[from] SceneError),
}

/// Counters since the pager started. See [`Pager::stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PagerStats {
    /// Distinct tile requests queued (a tile asked for by many rays counts once).
    pub requested: u64,
    /// Tiles loaded and published.
    pub loaded: u64,
    /// Tiles evicted.
    pub evicted: u64,
    /// Bytes loaded (page-rounded tile ranges).
    pub bytes_loaded: u64,
    /// Tile-table lookups by traversal, and how many found the tile absent.
    pub lookups: u64,
    pub misses: u64,
    /// Tiles found corrupt.
    pub corrupt: u64,
    /// Resident tile bytes now, and the most there ever were.
    pub resident: u64,
    pub peak_resident: u64,
    /// Bytes always resident (header page and tables).
    pub pinned: u64,
    /// The budget for tiles: the budget less the pinned bytes.
    pub tile_budget: u64,
    /// Seconds fetchers spent loading and checking tiles, and waiting for grace periods.
    pub load_secs: f64,
    pub grace_secs: f64,
    /// The whole process's resident memory as the kernel counts it, when the stats were
    /// taken (Linux): file-backed pages (a pager maps none of the scene) and anonymous ones
    /// (the scene's resident tiles among them), beside the pager's own accounting above.
    pub process: Option<megaray_base::ProcessMemory>,
}

impl PagerStats {
    /// The fraction of tile-table lookups that found the tile resident.
    pub fn hit_rate(&self) -> f64 {
        if self.lookups == 0 {
            1.0
        } else {
            1.0 - self.misses as f64 / self.lookups as f64
        }
    }
}

/// Pages a scene within a budget. Create one per open scene; dropping it stops the fetchers.
pub struct Pager {
    shared: Arc<Shared>,
    fetchers: Vec<JoinHandle<()>>,
}

impl Shared {
    /// Counts tile `t` into the working set, once.
    #[inline]
    fn note(&self, t: u32) {
        let (m, seen) = (self.mark.load(Relaxed), &self.seen[t as usize]);
        if seen.load(Relaxed) != m && seen.swap(m, Relaxed) != m {
            self.working[(m & 1) as usize].fetch_add(self.cost[t as usize], Relaxed);
        }
    }
}

struct Shared {
    scene: Arc<Scene>,
    state: Vec<AtomicU32>,
    /// How many rays asked for each requested tile (the queue's priority).
    want: Vec<AtomicU32>,
    /// Resident bytes of each tile (its page-rounded ranges).
    cost: Vec<u64>,
    /// How many times each tile's pages were released (a generation, for tests).
    releases: Vec<AtomicU32>,
    /// The working set ([`Pager::begin_working_set`]): each tile's mark when it was last
    /// looked up, the current mark, and the bytes of the tiles looked up under it.
    seen: Vec<AtomicU32>,
    mark: AtomicU32,
    /// Indexed by the mark's parity: a lookup that read the mark just before a new working
    /// set began counts into the old one's bytes, not the new one's.
    working: [AtomicU64; 2],
    /// Who steers by the working set ([`Pager::steer`]): an id, and when it last did (ms
    /// since `start`).
    steerer: AtomicU64,
    steered_at: AtomicU64,
    /// When each tile was last loaded, in milliseconds since `start`.
    loaded_at: Vec<AtomicU64>,
    start: Instant,
    queue: Mutex<Vec<u32>>,
    queue_cv: Condvar,
    /// Publication count, bumped (and waiters woken) whenever a tile arrives or fails.
    arrivals: Mutex<u64>,
    arrival_cv: Condvar,
    clock: Mutex<Clock>,
    tile_budget: u64,
    pinned: u64,
    epoch: AtomicU64,
    readers: [Box<[CachePadded<AtomicUsize>]>; 2],
    grace: Mutex<()>,
    lookups: Box<[CachePadded<AtomicU64>]>,
    misses: AtomicU64,
    requested: AtomicU64,
    loaded: AtomicU64,
    evicted: AtomicU64,
    bytes_loaded: AtomicU64,
    corrupt: AtomicU64,
    peak: AtomicU64,
    load_ns: AtomicU64,
    grace_ns: AtomicU64,
    first_error: Mutex<Option<SceneError>>,
    shutdown: AtomicBool,
}

/// The clock: a hand over tile numbers and the resident (or reserved) byte count.
struct Clock {
    hand: usize,
    bytes: u64,
}

/// Proof that the holder may read available tiles: while any pin taken before an eviction
/// lives, the evicted tile's pages are not released. Hold it across one traversal (or a
/// sample's rays), never while waiting for a tile.
pub struct Pin<'p> {
    pager: &'p Shared,
    parity: usize,
    stripe: usize,
}

impl Drop for Pin<'_> {
    fn drop(&mut self) {
        self.pager.readers[self.parity][self.stripe].fetch_sub(1, Release);
    }
}

thread_local! {
    static STRIPE: usize = {
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        NEXT.fetch_add(1, Relaxed) % STRIPES
    };
}

fn stripe() -> usize {
    STRIPE.with(|s| *s)
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn pages(len: u64, off: u64) -> u64 {
    (off + len).div_ceil(PAGE) * PAGE - off / PAGE * PAGE
}

/// The resident cost of each tile (its ranges widened to pages) and of what is pinned: the
/// tables and the tiles of [`pinned_tiles`].
fn costs(scene: &Scene) -> (Vec<u64>, u64) {
    let sum = |r: &[(u64, u64)]| r.iter().map(|&(o, l)| pages(l, o)).sum::<u64>();
    let tiles: Vec<u64> =
        (0..scene.tiles().len() as u32).map(|t| sum(&scene.tile_ranges(t).unwrap_or_default())).collect();
    let pinned = sum(&scene.pinned_ranges()) + pinned_tiles(scene).map(|t| tiles[t as usize]).sum::<u64>();
    (tiles, pinned)
}

/// The tiles always resident in a scene with levels of detail: those of the coarsest level of
/// every part (the part itself where the build made none: it was small).
fn pinned_tiles(scene: &Scene) -> impl Iterator<Item = u32> + '_ {
    let lod = scene.header().lod_part_count > 0;
    (0..scene.full_part_count()).filter(move |_| lod).filter_map(move |p| scene.lod_chain(p).last()).flat_map(
        move |q| {
            let e = &scene.parts()[q as usize];
            e.first_tile..e.first_tile + e.tile_count
        },
    )
}

/// The largest tile that is not pinned (what the budget must have room for, twice).
fn largest_unpinned(scene: &Scene, cost: &[u64]) -> u64 {
    let pinned: std::collections::HashSet<u32> = pinned_tiles(scene).collect();
    (0..cost.len() as u32).filter(|t| !pinned.contains(t)).map(|t| cost[t as usize]).max().unwrap_or(0)
}

impl Pager {
    /// Opens `path` for paging ([`Scene::open_owned`]) and starts a pager on it.
    pub fn open(path: &Path, opts: PagerOptions) -> Result<Pager, PagerError> {
        Pager::new(Arc::new(Scene::open_owned(path)?), opts)
    }

    /// Starts paging `scene` (opened with [`Scene::open_owned`], whose tables are resident
    /// already) within `opts.budget` bytes: tiles are read when traversal first asks for
    /// them. Fails when the budget cannot hold the tables plus two of the largest tiles.
    pub fn new(scene: Arc<Scene>, opts: PagerOptions) -> Result<Pager, PagerError> {
        let path = scene.path().display().to_string();
        if !scene.is_owned() {
            return Err(PagerError::Mapped { path });
        }
        let n = scene.tiles().len();
        let (cost, pinned) = costs(&scene);
        let max_tile = largest_unpinned(&scene, &cost);
        let need = pinned + 2 * max_tile;
        if opts.budget < need {
            return Err(PagerError::BudgetTooSmall {
                path,
                budget: format_size(opts.budget),
                need: format_size(need),
                pinned: format_size(pinned),
                tile: format_size(max_tile),
            });
        }
        let stripes = || (0..STRIPES).map(|_| CachePadded::new(AtomicUsize::new(0))).collect::<Box<[_]>>();
        let shared = Arc::new(Shared {
            state: (0..n).map(|_| AtomicU32::new(0)).collect(),
            want: (0..n).map(|_| AtomicU32::new(0)).collect(),
            cost,
            releases: (0..n).map(|_| AtomicU32::new(0)).collect(),
            seen: (0..n).map(|_| AtomicU32::new(0)).collect(),
            mark: AtomicU32::new(1),
            working: [AtomicU64::new(0), AtomicU64::new(0)],
            steerer: AtomicU64::new(0),
            steered_at: AtomicU64::new(0),
            loaded_at: (0..n).map(|_| AtomicU64::new(0)).collect(),
            start: Instant::now(),
            queue: Mutex::new(Vec::new()),
            queue_cv: Condvar::new(),
            arrivals: Mutex::new(0),
            arrival_cv: Condvar::new(),
            clock: Mutex::new(Clock { hand: 0, bytes: 0 }),
            tile_budget: opts.budget - pinned,
            pinned,
            epoch: AtomicU64::new(0),
            readers: [stripes(), stripes()],
            grace: Mutex::new(()),
            lookups: (0..STRIPES).map(|_| CachePadded::new(AtomicU64::new(0))).collect(),
            misses: AtomicU64::new(0),
            requested: AtomicU64::new(0),
            loaded: AtomicU64::new(0),
            evicted: AtomicU64::new(0),
            bytes_loaded: AtomicU64::new(0),
            corrupt: AtomicU64::new(0),
            peak: AtomicU64::new(0),
            load_ns: AtomicU64::new(0),
            grace_ns: AtomicU64::new(0),
            first_error: Mutex::new(None),
            shutdown: AtomicBool::new(false),
            scene,
        });
        // The coarsest levels of detail, now: read and checked as any tile (a damaged one is
        // recorded and skipped like any other), then never evicted.
        for t in pinned_tiles(&shared.scene) {
            let scene = &*shared.scene;
            let ranges = scene.tile_ranges(t).unwrap_or_default();
            let word = &shared.state[t as usize];
            let read = ranges.iter().try_for_each(|&(o, l)| scene.load(o, l));
            match read
                .map_err(|e| SceneError::new(scene.path(), SceneErrorKind::Io, format!("tile {t}: cannot read: {e}")))
                .and_then(|_| scene.check_tile(t))
            {
                Ok(()) => {
                    word.store(AVAIL | PINNED, SeqCst);
                }
                Err(e) => {
                    shared.corrupt.fetch_add(1, Relaxed);
                    lock(&shared.first_error).get_or_insert(e);
                    word.store(CORRUPT, SeqCst);
                }
            }
        }
        let fetchers = (0..opts.fetchers.max(1))
            .map(|i| {
                let s = shared.clone();
                std::thread::Builder::new()
                    .name(format!("megaray-fetch-{i}"))
                    .spawn(move || s.fetch_loop())
                    .expect("spawning a fetcher thread")
            })
            .collect();
        Ok(Pager { shared, fetchers })
    }

    /// The smallest budget [`Pager::new`] accepts for `scene`: what is pinned (tables, the
    /// coarsest levels of detail) plus two of its largest other tiles.
    pub fn min_budget(scene: &Scene) -> u64 {
        let (cost, pinned) = costs(scene);
        pinned + 2 * largest_unpinned(scene, &cost)
    }

    /// The scene being paged.
    pub fn scene(&self) -> &Arc<Scene> {
        &self.shared.scene
    }

    /// Pins the calling thread: tiles seen available stay readable until the pin drops.
    #[inline]
    pub fn pin(&self) -> Pin<'_> {
        self.shared.pin()
    }

    /// The tile table lookup that traversal makes before it enters tile `t` (under a
    /// [`Pin`]): [`Access::Ready`] marks the tile referenced; [`Access::Missing`] requests it.
    #[inline]
    pub fn acquire(&self, t: u32) -> Access {
        let s = &self.shared;
        s.lookups[stripe()].fetch_add(1, Relaxed);
        let Some(word) = s.state.get(t as usize) else { return Access::Corrupt };
        // SeqCst: ordered after the pin's epoch check (see `Shared::pin`).
        let st = word.load(SeqCst);
        if st & PINNED == 0 {
            s.note(t);
        }
        if st & AVAIL != 0 {
            if st & (REFD | FRESH) != REFD {
                word.fetch_or(REFD, Relaxed);
                word.fetch_and(!FRESH, Relaxed);
            }
            return Access::Ready;
        }
        if st & CORRUPT != 0 {
            return Access::Corrupt;
        }
        s.misses.fetch_add(1, Relaxed);
        self.request(t);
        Access::Missing
    }

    /// Starts a new working set: the tiles (not pinned) that traversal looks up from now on,
    /// present or not, each counted once. The working set of a frame whose rays are traced to
    /// the end is a function of those rays, not of what was resident or of which thread or
    /// process traced them, so a renderer that steers the level of detail by it
    /// ([`Pager::working_set_bytes`]) makes the same choices however the frame is divided.
    /// (A ray that takes a stand-in for a missing tile also looks up the coarser levels it
    /// tried, and a frame cut short by a deadline only what it traced.) Call it between
    /// frames.
    pub fn begin_working_set(&self) {
        let s = &self.shared;
        let next = s.mark.load(Relaxed).wrapping_add(1).max(1);
        if next == 1 {
            // The marks wrapped: forget the old ones, which could equal new ones.
            s.seen.iter().for_each(|m| m.store(0, Relaxed));
        }
        s.working[(next & 1) as usize].store(0, Relaxed);
        s.mark.store(next, Relaxed);
    }

    /// The resident bytes the working set's tiles take (page-rounded, as the budget counts).
    pub fn working_set_bytes(&self) -> u64 {
        let s = &self.shared;
        s.working[(s.mark.load(Relaxed) & 1) as usize].load(Relaxed)
    }

    /// Makes the caller, known by `id` (non-zero, its own), the one that steers by the
    /// working set ([`Pager::steer`]), whoever did before: the newest frame loop steers.
    pub fn take_steering(&self, id: u64) {
        let s = &self.shared;
        s.steerer.store(id, Relaxed);
        s.steered_at.store(s.start.elapsed().as_millis() as u64, Relaxed);
    }

    /// Whether the caller, known by `id`, still steers by the working set: it took over
    /// last ([`Pager::take_steering`]), or the one that did has not asked for
    /// [`STEER_STALE_MS`] (its viewer closed) and the caller takes over. Several viewers
    /// share a pager (one a page in `serve`), and each frame's end would begin a new working
    /// set under the others' frames: one of them steers, the others follow its error.
    pub fn steer(&self, id: u64) -> bool {
        let s = &self.shared;
        let now = s.start.elapsed().as_millis() as u64;
        let owner = s.steerer.load(Relaxed);
        let mine = owner == id
            || ((owner == 0 || now.saturating_sub(s.steered_at.load(Relaxed)) > STEER_STALE_MS)
                && s.steerer.compare_exchange(owner, id, Relaxed, Relaxed).is_ok());
        if mine {
            s.steered_at.store(now, Relaxed);
        }
        mine
    }

    /// The working set's tiles, in tile order (to send to another process).
    pub fn working_set(&self) -> Vec<u32> {
        let s = &self.shared;
        let m = s.mark.load(Relaxed);
        (0..s.seen.len() as u32).filter(|&t| s.seen[t as usize].load(Relaxed) == m).collect()
    }

    /// Adds tiles another process looked up to the working set (those out of range or
    /// pinned are ignored), as if traversal here had looked them up.
    pub fn note_working_set(&self, tiles: &[u32]) {
        let s = &self.shared;
        for &t in tiles {
            if s.state.get(t as usize).is_some_and(|w| w.load(Relaxed) & PINNED == 0) {
                s.note(t);
            }
        }
    }

    /// Asks for tile `t` (a prefetch, or a miss). Deduplicated: a tile already asked for
    /// only gains priority.
    pub fn request(&self, t: u32) {
        let s = &self.shared;
        let Some(word) = s.state.get(t as usize) else { return };
        s.want[t as usize].fetch_add(1, Relaxed);
        let old = word.fetch_or(REQ, SeqCst);
        if old & (REQ | AVAIL | CORRUPT) == 0 {
            s.requested.fetch_add(1, Relaxed);
            // The read starts now; the fetcher that takes the request waits less for it.
            for (o, l) in s.scene.tile_ranges(t).unwrap_or_default() {
                s.scene.prefetch(o, l);
            }
            lock(&s.queue).push(t);
            s.queue_cv.notify_one();
        } else if old & REQ == 0 {
            // Already there (or never will be): undo the flag.
            word.fetch_and(!REQ, SeqCst);
        }
    }

    /// Whether tile `t` has settled since it was asked for: resident, or found corrupt.
    pub fn settled(&self, t: u32) -> bool {
        self.shared.state.get(t as usize).is_none_or(|w| w.load(SeqCst) & (AVAIL | CORRUPT) != 0)
    }

    /// The number of tiles published so far (loaded or failed); pass it to
    /// [`Pager::wait_arrival`].
    pub fn arrivals(&self) -> u64 {
        *lock(&self.shared.arrivals)
    }

    /// Waits until more than `seen` tiles have been published, or `timeout` passes.
    pub fn wait_arrival(&self, seen: u64, timeout: Duration) -> u64 {
        let g = lock(&self.shared.arrivals);
        let (g, _) =
            self.shared.arrival_cv.wait_timeout_while(g, timeout, |n| *n <= seen).unwrap_or_else(|p| p.into_inner());
        *g
    }

    /// Counters since the start.
    pub fn stats(&self) -> PagerStats {
        let s = &self.shared;
        PagerStats {
            requested: s.requested.load(Relaxed),
            loaded: s.loaded.load(Relaxed),
            evicted: s.evicted.load(Relaxed),
            bytes_loaded: s.bytes_loaded.load(Relaxed),
            lookups: s.lookups.iter().map(|c| c.load(Relaxed)).sum(),
            misses: s.misses.load(Relaxed),
            corrupt: s.corrupt.load(Relaxed),
            resident: lock(&s.clock).bytes,
            peak_resident: s.peak.load(Relaxed),
            pinned: s.pinned,
            tile_budget: s.tile_budget,
            load_secs: s.load_ns.load(Relaxed) as f64 * 1e-9,
            grace_secs: s.grace_ns.load(Relaxed) as f64 * 1e-9,
            process: megaray_base::process_memory(),
        }
    }

    /// The first corrupt tile met, if any: renderers report it after a frame.
    pub fn first_error(&self) -> Option<SceneError> {
        lock(&self.shared.first_error).clone()
    }

    /// How many times tile `t`'s pages have been released. A reader that saw the tile
    /// available under a pin sees this number unchanged until the pin drops (the grace
    /// period's promise; the stress tests check it).
    pub fn release_count(&self, t: u32) -> u32 {
        self.shared.releases.get(t as usize).map_or(0, |r| r.load(SeqCst))
    }

    /// Whether tile `t` is resident now (for tests and statistics).
    pub fn is_resident(&self, t: u32) -> bool {
        self.shared.state.get(t as usize).is_some_and(|w| w.load(SeqCst) & AVAIL != 0)
    }
}

impl Drop for Pager {
    fn drop(&mut self) {
        self.shared.shutdown.store(true, SeqCst);
        {
            let _q = lock(&self.shared.queue);
            self.shared.queue_cv.notify_all();
        }
        for f in self.fetchers.drain(..) {
            let _ = f.join();
        }
    }
}

impl Shared {
    #[inline]
    fn pin(&self) -> Pin<'_> {
        let stripe = stripe();
        loop {
            let e = self.epoch.load(SeqCst);
            let parity = (e & 1) as usize;
            self.readers[parity][stripe].fetch_add(1, SeqCst);
            // If the epoch is unchanged, any evictor that flips it later will wait for this
            // count; if it changed, an eviction may have missed us: count again under the
            // new parity (and see its cleared availability bits).
            if self.epoch.load(SeqCst) == e {
                return Pin { pager: self, parity, stripe };
            }
            self.readers[parity][stripe].fetch_sub(1, Release);
        }
    }

    /// Waits until every pin taken before now has dropped.
    fn synchronize(&self) {
        let _g = lock(&self.grace);
        let t0 = Instant::now();
        fence(SeqCst);
        let old = self.epoch.fetch_add(1, SeqCst);
        let parity = (old & 1) as usize;
        let mut spins = 0u32;
        while self.readers[parity].iter().any(|c| c.load(SeqCst) != 0) {
            spins += 1;
            if spins < 64 {
                std::hint::spin_loop();
            } else if spins < 256 {
                std::thread::yield_now();
            } else {
                std::thread::sleep(Duration::from_micros(50));
            }
        }
        self.grace_ns.fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
    }

    /// The most-wanted queued tile, waiting for one; `None` at shutdown.
    fn next_request(&self) -> Option<u32> {
        let mut q = lock(&self.queue);
        loop {
            if self.shutdown.load(SeqCst) {
                return None;
            }
            if !q.is_empty() {
                let (i, _) = q.iter().enumerate().max_by_key(|&(_, &t)| self.want[t as usize].load(Relaxed))?;
                return Some(q.swap_remove(i));
            }
            q = self.queue_cv.wait(q).unwrap_or_else(|p| p.into_inner());
        }
    }

    fn fetch_loop(&self) {
        // Below the tracing threads: a load waits a little when the cores are busy, a frame
        // against a deadline does not (its rays answered from stand-ins meanwhile).
        #[cfg(target_os = "linux")]
        // SAFETY: setpriority takes integers; 0 names the calling thread on Linux.
        unsafe {
            libc::setpriority(libc::PRIO_PROCESS, 0, 10);
        }
        while let Some(t) = self.next_request() {
            let st = self.state[t as usize].load(SeqCst);
            if st & (AVAIL | CORRUPT) != 0 {
                self.state[t as usize].fetch_and(!REQ, SeqCst);
                continue;
            }
            if st & EVICTING != 0 {
                // Its pages are being released by another fetcher: ask again shortly.
                lock(&self.queue).push(t);
                std::thread::sleep(Duration::from_micros(200));
                continue;
            }
            self.load(t);
        }
    }

    /// Makes room for tile `t` (evicting), reads and checks it, and publishes it.
    fn load(&self, t: u32) {
        let cost = self.cost[t as usize];
        let victims = match self.make_room(t, cost) {
            Ok(v) => v,
            // Loaded meanwhile (or found damaged): the request is answered.
            Err(seen) if seen & (AVAIL | CORRUPT) != 0 => {
                self.state[t as usize].fetch_and(!REQ, SeqCst);
                return;
            }
            // Its pages being released by another fetcher: asked again after a pause (decided
            // by the state seen under the lock: the other may finish meanwhile).
            Err(_) => {
                lock(&self.queue).push(t);
                std::thread::sleep(Duration::from_micros(200));
                return;
            }
        };
        if !victims.is_empty() {
            self.synchronize();
            for &v in &victims {
                self.release(v);
                self.state[v as usize].fetch_and(!EVICTING, SeqCst);
            }
            self.evicted.fetch_add(victims.len() as u64, Relaxed);
        }
        let t0 = Instant::now();
        let scene = &*self.scene;
        let ranges = scene.tile_ranges(t).unwrap_or_default();
        // Read every range (on a failure, those read are released again), then check.
        let mut read = 0;
        let mut checked = Ok(());
        for &(o, l) in &ranges {
            if let Err(e) = scene.load(o, l) {
                checked = Err(SceneError::new(scene.path(), SceneErrorKind::Io, format!("tile {t}: cannot read: {e}")));
                break;
            }
            read += 1;
        }
        if checked.is_ok() {
            checked = scene.check_tile(t);
        } else {
            for &(o, l) in &ranges[..read] {
                let _ = scene.release(o, l);
            }
        }
        self.load_ns.fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
        let word = &self.state[t as usize];
        match checked {
            Ok(()) => {
                self.bytes_loaded.fetch_add(cost, Relaxed);
                self.loaded.fetch_add(1, Relaxed);
                self.want[t as usize].store(0, Relaxed);
                // Referenced and fresh: a tile just loaded for waiting rays is not evicted
                // before they used it (or FRESH_MS passed).
                self.loaded_at[t as usize].store(self.start.elapsed().as_millis() as u64, Relaxed);
                let prev = word.fetch_or(AVAIL | REFD | FRESH, SeqCst);
                debug_assert!(prev & (AVAIL | EVICTING) == 0, "tile {t} published twice");
                word.fetch_and(!REQ, SeqCst);
            }
            Err(e) => {
                self.corrupt.fetch_add(1, Relaxed);
                lock(&self.first_error).get_or_insert(e);
                if read == ranges.len() {
                    self.release(t);
                }
                lock(&self.clock).bytes -= cost;
                word.fetch_or(CORRUPT, SeqCst);
                word.fetch_and(!REQ, SeqCst);
            }
        }
        let mut n = lock(&self.arrivals);
        *n += 1;
        self.arrival_cv.notify_all();
    }

    /// Reserves `cost` bytes for a tile about to load, choosing victims by the clock until
    /// the reservation fits (evicting down to the low watermark once over the budget).
    /// Victims are no longer available when this returns; their pages are still mapped.
    /// Tile `t`'s state instead, as seen under the clock lock, if it is available, damaged or
    /// still being released: a tile is made evicting only under that lock, so one seen
    /// neither available nor evicting there is not being released while it loads.
    fn make_room(&self, t: u32, cost: u64) -> Result<Vec<u32>, u32> {
        let mut c = lock(&self.clock);
        let seen = self.state[t as usize].load(SeqCst);
        if seen & (AVAIL | EVICTING | CORRUPT) != 0 {
            return Err(seen);
        }
        let mut victims = Vec::new();
        let low = (self.tile_budget - self.tile_budget / 16).saturating_sub(cost);
        let n = self.state.len();
        let mut sweeps = 0u32;
        while c.bytes + cost > self.tile_budget {
            if sweeps > 0 {
                if self.shutdown.load(Relaxed) {
                    break;
                }
                // Everything resident is fresh (loaded for rays that have not used it yet):
                // wait for them rather than exceed the budget.
                drop(c);
                std::thread::sleep(Duration::from_millis(1));
                c = lock(&self.clock);
            }
            sweeps += 1;
            let now = self.start.elapsed().as_millis() as u64;
            // Two full sweeps clear every referenced bit once and then evict; a third is
            // only needed if tiles became referenced again meanwhile.
            let mut steps = 0;
            while c.bytes > low && steps < 3 * n {
                let v = c.hand;
                c.hand = (c.hand + 1) % n;
                steps += 1;
                let word = &self.state[v];
                let st = word.load(SeqCst);
                if st & AVAIL == 0 || st & PINNED != 0 {
                    continue;
                }
                if st & FRESH != 0 && now.saturating_sub(self.loaded_at[v].load(Relaxed)) < FRESH_MS {
                    continue;
                }
                if st & REFD != 0 {
                    word.fetch_and(!REFD, Relaxed);
                    continue;
                }
                // Evict: no longer available (new lookups miss), pages released after the
                // grace period.
                // In one step: a state with neither bit would let another fetcher load the
                // tile again, and this one's release would then drop the fresh pages.
                let evict = |s: u32| (s & AVAIL != 0).then_some((s & !AVAIL) | EVICTING);
                if word.fetch_update(SeqCst, SeqCst, evict).is_err() {
                    continue;
                }
                c.bytes -= self.cost[v];
                victims.push(v as u32);
            }
        }
        c.bytes += cost;
        self.peak.fetch_max(c.bytes, Relaxed);
        Ok(victims)
    }

    /// Drops tile `t`'s pages from this process.
    fn release(&self, t: u32) {
        self.releases[t as usize].fetch_add(1, SeqCst);
        for (o, l) in self.scene.tile_ranges(t).unwrap_or_default() {
            let _ = self.scene.release(o, l);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fetcher asked to load a tile that another is evicting (no longer available, its
    /// pages not yet released) leaves it alone and asks again later: were it to load it, the
    /// other's release would leave an available tile of zeros.
    #[test]
    fn a_tile_being_evicted_is_not_loaded_again_until_released() {
        let dir = tempfile::tempdir().unwrap();
        let ply = megaray_testkit::gen(dir.path(), "plant:60k");
        let (path, _) = megaray_testkit::build_without_lod(dir.path(), &[ply], "paged", Some(20_000));
        let pager = Pager::open(&path, PagerOptions { budget: 1 << 30, fetchers: 1 }).unwrap();
        let s = &pager.shared;
        let t = 3;
        while pager.acquire(t) != Access::Ready {
            std::thread::sleep(Duration::from_millis(1));
        }
        // What an evicting fetcher does under the clock lock ...
        {
            let mut c = lock(&s.clock);
            let evict = |w: u32| (w & AVAIL != 0).then_some((w & !AVAIL) | EVICTING);
            s.state[t as usize].fetch_update(SeqCst, SeqCst, evict).unwrap();
            c.bytes -= s.cost[t as usize];
        }
        // ... while another is asked for the tile and loads it.
        let releases = pager.release_count(t);
        s.state[t as usize].fetch_or(REQ, SeqCst);
        s.load(t);
        assert_eq!(s.state[t as usize].load(SeqCst) & AVAIL, 0, "loaded while being evicted");
        assert_ne!(s.state[t as usize].load(SeqCst) & REQ, 0, "no longer asked for");
        assert_eq!(pager.release_count(t), releases);
        // The evicting fetcher finishes; the tile loads again whole.
        s.release(t);
        s.state[t as usize].fetch_and(!EVICTING, SeqCst);
        s.queue_cv.notify_all();
        while pager.acquire(t) != Access::Ready {
            std::thread::sleep(Duration::from_millis(1));
        }
        let _pin = pager.pin();
        s.scene.check_tile(t).unwrap();
        assert!(pager.first_error().is_none());
    }
}
