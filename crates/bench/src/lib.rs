//! # megaray-bench: the benchmark harness behind `megaray bench`
//!
//! Measures megaray the way the Intel Embree peer harness (`shared/peers/embree`) measures
//! Embree, and prints the same lines, so that `shared/bench/compare.py` can pair them:
//!
//! - [`Source`] reads the SCENE argument (a `.mray` file, a model file or a gen spec) and
//!   [`Loaded::open`] turns it into an open scene (model files and gen specs are built into a
//!   temporary scene file first);
//! - [`run`] takes the kinds and thread counts of [`BenchOptions`] and reports each figure as a
//!   [`Record`] (a [`TraceLine`] or a [`BuildLine`]), whose [`Record::json`] is the output line.
//!
//! The definitions (shared/BENCH.md, shared/peers/embree/README.md), in short: camera at
//! `c + (0, 0.3, 1.6)·d` (`close`: `(0, 0.3, 0.6)·d`), 60 degrees, rays through pixel
//! centres; `primary_1` one ray at a time and `primary_16` 4x4 packets, in 32x32 pixel tiles
//! handed to the threads dynamically; `shadow_1` and `diffuse_1` one ray per primary hit from
//! `hit + 1e-4·d·n`, generated before timing, in chunks of 4096 rays; `build` the in-core
//! builder (median of 3 after a warm-up). Timing in [`measure`]: a warm-up pass, then `reps`
//! repetitions of at least `min_ms`; checksums (`hits`, `sum_t`) reduced in a fixed order.
//!
//! ```no_run
//! use megaray_bench::{run, BenchOptions, Event, Kind, Loaded, Source};
//! let src = Source::parse("grid:1000").unwrap();
//! let scene = Loaded::open(&src, &megaray_base::NoProgress).unwrap();
//! let opts = BenchOptions { kinds: vec![Kind::Primary1], threads: vec![1, 2], ..BenchOptions::default() };
//! run(&scene, &opts, &megaray_base::NoProgress, &mut |e| match e {
//!     Event::Info(msg) => eprintln!("{msg}"),
//!     Event::Line(r) => println!("{}", r.json()),
//! })
//! .unwrap();
//! ```

mod error;
pub mod measure;
pub mod rays;
mod report;
mod source;

use std::str::FromStr;
use std::time::Instant;

use megaray_base::{Progress, TriVerts, Vec3};
use megaray_build::Quality;
use megaray_render::{Camera, CLOSE_OFFSET, DEFAULT_OFFSET};
use megaray_trace::{Hit, Tracer};
use rayon::ThreadPool;

pub use error::BenchError;
pub use report::{BuildLine, Record, TraceLine};
pub use source::{Loaded, Source};

use measure::{measure_items, median, Acc, Measured};
use rays::{pixel_ray, Primary, Secondary, SEC_CHUNK};

/// What is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    /// The in-core builder ([`megaray_build::build_in_core`]) at [`Quality::Medium`]; pairs
    /// with the peer's `build_medium`.
    Build,
    /// The in-core builder at [`Quality::High`], the quality of the trees that are traced
    /// (as the peer traces its `HIGH` builds); pairs with the peer's `build_high`.
    BuildHigh,
    /// One primary ray at a time ([`Tracer::intersect`]).
    Primary1,
    /// 8x1 pixel packets ([`Tracer::intersect_packet`]).
    Primary8,
    /// 4x4 pixel packets ([`Tracer::intersect_packet`]).
    Primary16,
    /// One shadow ray per primary hit ([`Tracer::occluded`]).
    Shadow1,
    /// One diffuse bounce ray per primary hit ([`Tracer::intersect`]).
    Diffuse1,
}

impl Kind {
    /// Every kind, in the order they are measured.
    pub const ALL: [Kind; 7] =
        [Kind::Build, Kind::BuildHigh, Kind::Primary1, Kind::Primary8, Kind::Primary16, Kind::Shadow1, Kind::Diffuse1];
    /// The kinds measured when none are named.
    pub const DEFAULT: &'static str = "primary_1,primary_16,shadow_1,diffuse_1,build,build_high";

    /// Whether this kind times the builder (rather than tracing).
    pub fn is_build(self) -> bool {
        matches!(self, Kind::Build | Kind::BuildHigh)
    }

    /// The kind that times the builder at `quality`.
    pub fn build(quality: Quality) -> Kind {
        match quality {
            Quality::Medium => Kind::Build,
            Quality::High => Kind::BuildHigh,
        }
    }

    /// The name in the output lines (and on the command line).
    pub fn name(self) -> &'static str {
        match self {
            Kind::Build => "build",
            Kind::BuildHigh => "build_high",
            Kind::Primary1 => "primary_1",
            Kind::Primary8 => "primary_8",
            Kind::Primary16 => "primary_16",
            Kind::Shadow1 => "shadow_1",
            Kind::Diffuse1 => "diffuse_1",
        }
    }

    /// Parses a comma-separated list (`primary_1,build`); duplicates are measured once.
    pub fn parse_list(s: &str) -> Result<Vec<Kind>, BenchError> {
        let names = s.split(',').map(str::trim).filter(|k| !k.is_empty());
        let mut kinds: Vec<Kind> = names.map(Kind::from_str).collect::<Result<_, _>>()?;
        kinds.sort();
        kinds.dedup();
        if kinds.is_empty() {
            return Err(BenchError::Option("--kinds: no kind given".into()));
        }
        Ok(kinds)
    }
}

impl FromStr for Kind {
    type Err = BenchError;

    fn from_str(s: &str) -> Result<Kind, BenchError> {
        Kind::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| {
            let all: Vec<&str> = Kind::ALL.iter().map(|k| k.name()).collect();
            BenchError::Option(format!("--kinds: unknown kind `{s}` (expected {})", all.join(", ")))
        })
    }
}

impl std::fmt::Display for Kind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Parses a comma-separated list of thread counts (`1,2`), each 1 to 1024.
pub fn parse_threads(s: &str) -> Result<Vec<usize>, BenchError> {
    let list: Vec<&str> = s.split(',').map(str::trim).filter(|t| !t.is_empty()).collect();
    if list.is_empty() {
        return Err(BenchError::Option("--threads: no thread count given".into()));
    }
    list.iter()
        .map(|t| match t.parse::<usize>() {
            Ok(n) if (1..=1024).contains(&n) => Ok(n),
            _ => Err(BenchError::Option(format!("--threads: `{t}` is not a thread count (1 to 1024)"))),
        })
        .collect()
}

/// The two benchmark cameras.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum View {
    /// Eye at `c + (0, 0.3, 1.6)·d`: the model covers a few percent of the image.
    #[default]
    Default,
    /// Eye at `c + (0, 0.3, 0.6)·d`: about half the image; scene names get `@close`.
    Close,
}

impl View {
    pub fn offset(self) -> Vec3 {
        match self {
            View::Default => DEFAULT_OFFSET,
            View::Close => CLOSE_OFFSET,
        }
    }
}

/// What [`run`] measures and how.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Kinds to measure (measured in [`Kind::ALL`] order whatever the order here).
    pub kinds: Vec<Kind>,
    /// A figure for each thread count, in this order.
    pub threads: Vec<usize>,
    pub view: View,
    pub width: u32,
    pub height: u32,
    /// Timed repetitions after the warm-up (builds: at most 3).
    pub reps: u32,
    /// Each repetition repeats the pass until it lasts at least this long.
    pub min_ms: f64,
    /// Scene name in the output (default: [`Source::name`]); `@close` is appended for [`View::Close`].
    pub name: Option<String>,
    /// Trace within this memory budget for resident scene data (a [`megaray_page::Pager`]
    /// with eight fetchers); rays wait for missing tiles. `None`: the whole file is mapped.
    pub mem: Option<u64>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            kinds: Kind::parse_list(Kind::DEFAULT).expect("default kinds parse"),
            threads: vec![1, 2],
            view: View::Default,
            width: 1024,
            height: 1024,
            reps: 5,
            min_ms: 200.0,
            name: None,
            mem: None,
        }
    }
}

impl BenchOptions {
    /// Fails on options that cannot be used (no kinds, a thread count of 0, ...).
    pub fn check(&self) -> Result<(), BenchError> {
        let bad = |m: &str| Err(BenchError::Option(m.into()));
        if self.kinds.is_empty() {
            return bad("--kinds: no kind given");
        }
        if self.threads.is_empty() || self.threads.iter().any(|&t| !(1..=1024).contains(&t)) {
            return bad("--threads: thread counts must be 1 to 1024");
        }
        if self.width == 0 || self.height == 0 || self.width > 32768 || self.height > 32768 {
            return bad("--res: width and height must be 1 to 32768");
        }
        if self.reps == 0 || self.reps > 1000 {
            return bad("--reps must be 1 to 1000");
        }
        if !(self.min_ms.is_finite() && self.min_ms >= 0.0) {
            return bad("--min-ms must be a number of milliseconds, 0 or more");
        }
        Ok(())
    }

    /// The scene name the lines carry.
    pub fn scene_name(&self, loaded: &Loaded) -> String {
        let base = self.name.clone().unwrap_or_else(|| loaded.name.clone());
        match self.view {
            View::Close if !base.ends_with("@close") => format!("{base}@close"),
            _ => base,
        }
    }
}

/// What [`run`] reports as it goes.
#[derive(Clone, Debug)]
pub enum Event {
    /// Something for the user (camera, primary hits, triangles loaded): not a figure.
    Info(String),
    /// A figure.
    Line(Record),
}

fn pool(threads: usize, stack: Option<usize>) -> Result<ThreadPool, BenchError> {
    let mut b = rayon::ThreadPoolBuilder::new().num_threads(threads).thread_name(|i| format!("bench-{i}"));
    if let Some(s) = stack {
        b = b.stack_size(s);
    }
    b.build().map_err(|e| BenchError::Threads { threads, msg: e.to_string() })
}

/// Measures `opts.kinds` at each of `opts.threads` on `loaded`, calling `on` with each figure
/// as soon as it is measured: the builds first, then the tracing kinds, thread count by thread
/// count (the peer's order). Fails on bad options, and if a corrupt tile was met.
pub fn run(
    loaded: &Loaded,
    opts: &BenchOptions,
    progress: &dyn Progress,
    on: &mut dyn FnMut(Event),
) -> Result<(), BenchError> {
    opts.check()?;
    let name = opts.scene_name(loaded);
    let want = |k: Kind| opts.kinds.contains(&k);
    if want(Kind::Build) || want(Kind::BuildHigh) {
        let t0 = Instant::now();
        let tris = loaded.triangles(progress)?;
        progress.finish();
        on(Event::Info(format!("{} triangles in memory for build ({:.1} s)", tris.len(), t0.elapsed().as_secs_f64())));
        // The peer's order: at each thread count, the high-quality build, then the medium one.
        for &t in &opts.threads {
            for quality in [Quality::High, Quality::Medium] {
                if want(Kind::build(quality)) {
                    on(Event::Line(Record::Build(bench_build(&name, &tris, t, opts.reps, quality)?)));
                }
            }
        }
    }
    if opts.kinds.iter().any(|k| !k.is_build()) {
        bench_trace(loaded, opts, &name, on)?;
    }
    match loaded.scene.first_error() {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

/// Tile target of the timed in-core builds (the builder's default).
const BUILD_TILE_TARGET: u32 = 256 << 10;

/// Times the in-core builder at `quality` on `threads` threads: one warm-up build, then the
/// median of up to 3 (`reps` capped to 3), as the peer times `rtcCommitScene`.
pub fn bench_build(
    scene: &str,
    tris: &[TriVerts],
    threads: usize,
    reps: u32,
    quality: Quality,
) -> Result<BuildLine, BenchError> {
    // The in-core builder recurses once per tree level: big stacks, as `build_scene` gives it.
    let pool = pool(threads, Some(256 << 20))?;
    let breps = reps.clamp(1, 3);
    let (mut ts, mut cpus) = (Vec::new(), Vec::new());
    for r in 0..=breps {
        let (t0, c0) = (Instant::now(), measure::cpu_seconds());
        let built = pool.install(|| megaray_build::build_in_core(tris, BUILD_TILE_TARGET, true, quality));
        let s = t0.elapsed().as_secs_f64();
        let cpu = (measure::cpu_seconds() - c0) / s.max(1e-9);
        megaray_build::recycle_part(built.0);
        if r > 0 {
            ts.push(s);
            cpus.push(cpu);
        }
    }
    // Repetitions reuse the builder's arrays, as parts of a model do; not kept after them.
    megaray_build::release_spare();
    let best = ts.iter().copied().fold(f64::INFINITY, f64::min);
    let med = median(ts);
    Ok(BuildLine {
        scene: scene.to_string(),
        tris: tris.len() as u64,
        kind: Kind::build(quality),
        threads,
        build_ms: med * 1e3,
        build_ms_best: best * 1e3,
        mtris_s: tris.len() as f64 / med * 1e-6,
        cpu_util: median(cpus),
        reps: breps,
    })
}

fn bench_trace(loaded: &Loaded, opts: &BenchOptions, name: &str, on: &mut dyn FnMut(Event)) -> Result<(), BenchError> {
    let scene = &loaded.scene;
    let bounds = scene.header().bounds;
    let (w, h) = (opts.width, opts.height);
    let cam = Camera::framing(&bounds, opts.view.offset(), w, h);
    let pager = match opts.mem {
        Some(budget) => Some(
            megaray_page::Pager::open(scene.path(), megaray_page::PagerOptions { budget, fetchers: 8 })
                .map_err(|e| BenchError::Option(e.to_string()))?,
        ),
        None => None,
    };
    let tracer = Tracer::paged_or_new(scene, pager.as_ref());
    on(Event::Info(format!(
        "camera eye ({} {} {}) at ({} {} {}), {w}x{h}",
        cam.eye.x,
        cam.eye.y,
        cam.eye.z,
        bounds.center().x,
        bounds.center().y,
        bounds.center().z
    )));

    // The reference primary pass and the secondary rays, before any timing.
    let all = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let primary = pool(all, None)?.install(|| Primary::trace(&tracer, &cam));
    let eps = 1e-4 * bounds.diagonal();
    let sec = Secondary::generate(&cam, &primary, eps);
    drop(primary);
    let npix = w as u64 * h as u64;
    let nsec = sec.shadow.len();
    on(Event::Info(format!(
        "primary hits {nsec} / {npix} ({:.1}%), secondary rays per kind {nsec}",
        100.0 * nsec as f64 / npix as f64
    )));

    let tiles = rays::tiles(w, h);
    let chunks = nsec.div_ceil(SEC_CHUNK);
    let (reps, min_s) = (opts.reps, opts.min_ms * 1e-3);
    for &threads in &opts.threads {
        let pool = pool(threads, None)?;
        for kind in Kind::ALL.into_iter().filter(|k| !k.is_build() && opts.kinds.contains(k)) {
            let secondary = matches!(kind, Kind::Shadow1 | Kind::Diffuse1);
            if secondary && nsec == 0 {
                on(Event::Info(format!("{kind}: no primary hits, so no rays: skipped")));
                continue;
            }
            if megaray_trace::stats::ENABLED {
                pool.broadcast(|_| megaray_trace::stats::take());
            }
            let m: Measured = match kind {
                Kind::Primary1 => measure_items(&pool, reps, min_s, tiles.len(), |i| {
                    let (x0, y0, x1, y1) = tiles[i];
                    let mut a = Acc::default();
                    for y in y0..y1 {
                        let mut x = x0;
                        // Sixteen rays of the row made at once (the same bits), traced one by one.
                        while x + 16 <= x1 {
                            let sx: [f32; 16] = std::array::from_fn(|k| (x + k as u32) as f32 + 0.5);
                            let rays = cam.rays16(&sx, &[y as f32 + 0.5; 16]);
                            for k in 0..16 {
                                add(&mut a, tracer.intersect(&rays.ray(k)));
                            }
                            x += 16;
                        }
                        for x in x..x1 {
                            add(&mut a, tracer.intersect(&pixel_ray(&cam, x, y)));
                        }
                    }
                    a
                }),
                Kind::Primary8 => {
                    measure_items(&pool, reps, min_s, tiles.len(), |i| packets(&tracer, &cam, tiles[i], 8, 1))
                }
                Kind::Primary16 => {
                    measure_items(&pool, reps, min_s, tiles.len(), |i| packets(&tracer, &cam, tiles[i], 4, 4))
                }
                Kind::Shadow1 => measure_items(&pool, reps, min_s, chunks, |c| {
                    let rays = &sec.shadow[c * SEC_CHUNK..((c + 1) * SEC_CHUNK).min(nsec)];
                    Acc { hits: rays.iter().filter(|r| tracer.occluded(r)).count() as u64, sum_t: 0.0 }
                }),
                Kind::Diffuse1 => measure_items(&pool, reps, min_s, chunks, |c| {
                    let mut a = Acc::default();
                    for r in &sec.diffuse[c * SEC_CHUNK..((c + 1) * SEC_CHUNK).min(nsec)] {
                        add(&mut a, tracer.intersect(r));
                    }
                    a
                }),
                Kind::Build | Kind::BuildHigh => unreachable!("filtered out above"),
            };
            if megaray_trace::stats::ENABLED {
                // Traversal counters of every pass (warm-up included), per ray traced.
                let mut c = megaray_trace::stats::Counters::default();
                for t in pool.broadcast(|_| megaray_trace::stats::take()) {
                    c.add(&t);
                }
                let per = |x: u64| x as f64 / c.rays.max(1) as f64;
                on(Event::Info(format!(
                    "{kind} {threads}T: {:.2} node visits, {:.2} triangle blocks, {:.2} tiles entered per ray{}",
                    per(c.nodes),
                    per(c.blocks),
                    per(c.tiles_entered),
                    if matches!(kind, Kind::Primary8 | Kind::Primary16) {
                        " (a packet's node visit counts once)"
                    } else {
                        ""
                    }
                )));
            }
            let rays = if secondary { nsec as u64 } else { npix };
            on(Event::Line(Record::Trace(TraceLine {
                scene: name.to_string(),
                tris: scene.header().tri_count,
                kind,
                threads,
                width: w,
                height: h,
                rays,
                mrays_s: rays as f64 / m.med_s * 1e-6,
                mrays_s_best: rays as f64 / m.best_s * 1e-6,
                ms_median: m.med_s * 1e3,
                cpu_util: m.cpu_util,
                reps,
                iters: m.iters,
                hits: m.acc.hits,
                sum_t: m.acc.sum_t,
            })));
        }
    }
    Ok(())
}

#[inline]
fn add(a: &mut Acc, hit: Option<Hit>) {
    if let Some(h) = hit {
        a.hits += 1;
        a.sum_t += h.t as f64;
    }
}

/// One tile in `pw` x `ph` pixel packets through [`Tracer::intersect_packet`] (pixels outside
/// the image are left out of their packet).
fn packets(tracer: &Tracer, cam: &Camera, (x0, y0, x1, y1): (u32, u32, u32, u32), pw: u32, ph: u32) -> Acc {
    const MAX: usize = 16;
    debug_assert!((pw * ph) as usize <= MAX);
    let mut rays = [megaray_base::Ray::new(Vec3::ZERO, Vec3::Z); MAX];
    let mut hits: [Option<Hit>; MAX] = [None; MAX];
    let mut a = Acc::default();
    for py in (y0..y1).step_by(ph as usize) {
        for px in (x0..x1).step_by(pw as usize) {
            let mut n = 0;
            if (pw, ph) == (4, 4) && px + 4 <= cam.width && py + 4 <= cam.height {
                // A whole 4x4 packet inside the image: its rays made together (the same bits;
                // lane k is pixel (k % 4, k / 4), by shifts: no division per lane).
                let sx: [f32; 16] = std::array::from_fn(|k| (px + (k as u32 & 3)) as f32 + 0.5);
                let sy: [f32; 16] = std::array::from_fn(|k| (py + (k as u32 >> 2)) as f32 + 0.5);
                tracer.intersect16(&cam.rays16(&sx, &sy), &mut hits);
                n = 16;
            } else {
                for k in 0..pw * ph {
                    let (x, y) = (px + k % pw, py + k / pw);
                    if x < cam.width && y < cam.height {
                        rays[n] = pixel_ray(cam, x, y);
                        n += 1;
                    }
                }
                tracer.intersect_packet(&rays[..n], &mut hits[..n]);
            }
            for &h in &hits[..n] {
                add(&mut a, h);
            }
        }
    }
    a
}
