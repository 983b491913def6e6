//! Work that traces rays and never stalls on a missing tile.
//!
//! [`run`] executes `n` jobs (a renderer's jobs are pixels or pixel samples) over the
//! threads of the current rayon pool. A job fires its rays through a [`Replay`], which
//! implements [`RayCaster`]. On a paged tracer, a ray that needs an absent tile makes the
//! job return [`Suspended`]; the job is *parked* with its ray log and the thread goes on
//! with other jobs (ray reordering, as in Wald et al. 2002). When the tile has arrived the
//! job runs again from the start: the rays it already fired are answered from its log, the
//! ray that stopped resumes its saved traversal ([`Tracer::resume`]), so no work is lost and
//! each traversal needs one tile at a time. Jobs must therefore be deterministic (the same
//! index fires the same rays); a job that is not is still answered correctly (the log is
//! dropped from the first ray that differs), only slower.
//!
//! Threads wait only when every job left is parked; that time is [`JobStats::wait_secs`].
//! At most [`JobOptions::max_parked`] jobs are parked at once; past that, threads retire
//! parked jobs before taking new ones. A small cap ([`MAX_PARKED`], the default) keeps a
//! frame's accesses together, so that a frame larger than the memory budget re-reads little
//! more than its working set. Against a deadline a large cap ([`MAX_PARKED_DEADLINE`]) is
//! better: threads race ahead through the pixels whose tiles are resident, and more pixels
//! finish in time (docs/PERF.md, "Parking cap and pixel order"). Either way memory is
//! bounded (a parked job keeps a few hundred bytes). With a deadline, [`run`] returns when
//! it passes and the jobs not finished are `None`.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering::*};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use megaray_base::Ray;
use megaray_scene::Scene;

use crate::{Hit, Memo, Pending, RayCaster, RayCone, Suspended, Traced, Tracer};

/// The default cap on jobs parked at once (see the module documentation).
pub const MAX_PARKED: usize = 1 << 8;

/// A cap for runs against a deadline.
pub const MAX_PARKED_DEADLINE: usize = 1 << 16;

/// How to run jobs.
#[derive(Clone, Copy, Debug)]
pub struct JobOptions {
    /// Jobs a thread takes at a time (neighbouring indices: keep them coherent).
    pub chunk: usize,
    /// Stop when this passes, leaving the remaining jobs unfinished.
    pub deadline: Option<Instant>,
    /// The most jobs parked at once (see the module documentation).
    pub max_parked: usize,
    /// Rays with a level of detail ([`RayCaster::intersect_cone`]) that need a tile not
    /// resident are answered by a coarser resident stand-in ([`Tracer::stand_in`]) instead
    /// of suspending the job; the job's result is then marked approximate
    /// ([`Replay::approx`]).
    pub stand_in: bool,
}

impl Default for JobOptions {
    fn default() -> JobOptions {
        JobOptions { chunk: 64, deadline: None, max_parked: MAX_PARKED, stand_in: false }
    }
}

/// What happened while running jobs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JobStats {
    /// Jobs run to the end.
    pub finished: u64,
    /// Jobs left unfinished at the deadline.
    pub unfinished: u64,
    /// Times a job was suspended (parked) for a missing tile.
    pub suspended: u64,
    /// Rays fired (answered from logs on re-runs are not counted again).
    pub rays: u64,
    /// Seconds threads spent waiting because every job left was parked, summed over threads.
    pub wait_secs: f64,
}

/// The results of [`run`]: the finished jobs' values, by job index, in no particular order
/// (each thread's, as they finished).
pub struct JobsResult<T> {
    per_thread: Vec<Vec<(u32, T)>>,
    pub stats: JobStats,
}

impl<T> JobsResult<T> {
    /// (job index, value) of every finished job, in no particular order.
    pub fn finished(&self) -> impl Iterator<Item = (usize, &T)> {
        self.per_thread.iter().flatten().map(|(i, v)| (*i as usize, v))
    }

    /// The finished jobs' results, moved out (as [`Run::finished`]).
    pub fn into_finished(self) -> impl Iterator<Item = (usize, T)> {
        self.per_thread.into_iter().flatten().map(|(i, v)| (i as usize, v))
    }

    /// The result vectors, emptied, to be filled by a later run ([`run_reusing`]).
    pub fn into_buffers(self) -> JobsBuffers<T> {
        let mut v = self.per_thread;
        v.iter_mut().for_each(Vec::clear);
        JobsBuffers(v)
    }

    /// One slot per job `0..n`, `None` where the job did not finish by the deadline.
    pub fn into_ordered(self, n: usize) -> Vec<Option<T>> {
        let mut out: Vec<Option<T>> = (0..n).map(|_| None).collect();
        for (i, v) in self.into_finished() {
            out[i] = Some(v);
        }
        out
    }
}

/// The result vectors of an earlier run ([`JobsResult::into_buffers`]), for [`run_reusing`]
/// to fill again: a frame's results are megabytes, and fresh vectors cost their page faults
/// on every frame.
pub struct JobsBuffers<T>(Vec<Vec<(u32, T)>>);

impl<T> Default for JobsBuffers<T> {
    fn default() -> JobsBuffers<T> {
        JobsBuffers(Vec::new())
    }
}

/// One query a job made, in order.
enum Logged {
    Hit(Ray, Option<Hit>),
    Occluded(Ray, bool),
    Pending(Ray, Box<Pending>),
    /// A finished piece of the job, standing for the queries it made ([`RayCaster::checkpoint`]).
    Memo(Memo),
}

/// The [`RayCaster`] jobs fire their rays through: answers from the job's log first (when it
/// is re-run after a suspension), then from the tracer.
pub struct Replay<'t, 's> {
    tracer: &'t Tracer<'s>,
    log: Vec<Logged>,
    cursor: usize,
    waiting: Option<u32>,
    rays: u64,
    /// Answer rays with a level of detail from stand-ins rather than suspend
    /// ([`JobOptions::stand_in`]).
    stand_in: bool,
    /// Some ray of this run of the job was answered by a stand-in for a missing tile.
    approx: bool,
}

impl<'t, 's> Replay<'t, 's> {
    /// A caster with an empty log.
    pub fn new(tracer: &'t Tracer<'s>) -> Replay<'t, 's> {
        Replay { tracer, log: Vec::new(), cursor: 0, waiting: None, rays: 0, stand_in: false, approx: false }
    }

    /// Whether some ray of the job's current run was answered by a stand-in for a tile that
    /// was not resident ([`JobOptions::stand_in`]): its result is approximate.
    pub fn approx(&self) -> bool {
        self.approx
    }

    #[inline]
    fn restart(&mut self, log: Vec<Logged>) {
        if !(log.is_empty() && self.log.is_empty()) {
            self.log = log;
        }
        self.cursor = 0;
        self.waiting = None;
        self.approx = false;
    }

    /// A query of a ray with a footprint: from a stand-in where levels of detail apply and
    /// the run allows it, else waiting for the tiles of the level its cone chooses.
    fn query_cone(&mut self, ray: &Ray, any: bool, cone: &RayCone) -> Result<Option<Hit>, Suspended> {
        if !self.tracer.lod_applies(cone) {
            return self.query(ray, any, None);
        }
        if self.stand_in && self.tracer.pager().is_some() {
            if let Ok(h) = self.tracer.stand_in(ray, any, cone) {
                self.rays += 1;
                self.approx |= h.approx;
                return Ok(if any { h.hit.map(|_| HIT_ANY) } else { h.hit });
            }
        }
        self.query(ray, any, Some(cone))
    }

    /// The tile whose residency covers `h`'s attributes, if its part has any.
    fn attribute_tile(&self, h: &Hit) -> Option<u32> {
        let scene = self.tracer.scene();
        if scene.has_attributes(h.part) {
            scene.tile_of_slot(h.part, h.prim)
        } else {
            None
        }
    }

    /// A query that may suspend (with a level of detail chosen by `cone`, if given), its
    /// answers logged for the job's re-runs.
    #[inline]
    fn query(&mut self, ray: &Ray, any: bool, cone: Option<&RayCone>) -> Result<Option<Hit>, Suspended> {
        if self.tracer.pager().is_none() {
            // Nothing can suspend: no log.
            self.rays += 1;
            return Ok(match cone {
                Some(c) => self.tracer.trace_cone(ray, any, c).map(|h| if any { HIT_ANY } else { h }),
                None if any => self.tracer.occluded(ray).then_some(HIT_ANY),
                None => self.tracer.intersect(ray),
            });
        }
        if self.tracer.misses_bounds(ray) {
            // Nothing to wait for, and the same answer when the job runs again: not logged.
            self.rays += 1;
            return Ok(None);
        }
        let tracer = self.tracer;
        let fresh = |ray: &Ray| match cone {
            Some(c) => tracer.try_cone(ray, any, c, None),
            None if any => tracer.try_occluded(ray),
            None => tracer.try_intersect(ray),
        };
        let mut resumed = false;
        let traced = if self.cursor < self.log.len() {
            let same = |r: &Ray| r.org == ray.org && r.dir == ray.dir && r.t_min == ray.t_min && r.t_max == ray.t_max;
            match &self.log[self.cursor] {
                Logged::Hit(r, h) if !any && same(r) => {
                    let h = *h;
                    if let Some(t) = h.and_then(|h| self.attribute_tile(&h)) {
                        // The hit came from an earlier run; its tile (which holds its
                        // attributes, which the shader may read next) may have been evicted
                        // since. Have it resident under this pin, or wait for it.
                        if let Some(p) = self.tracer.pager() {
                            if p.acquire(t) == megaray_page::Access::Missing {
                                self.waiting = Some(t);
                                return Err(Suspended);
                            }
                        }
                    }
                    self.cursor += 1;
                    return Ok(h);
                }
                Logged::Occluded(r, o) if any && same(r) => {
                    self.cursor += 1;
                    return Ok(o.then_some(HIT_ANY));
                }
                Logged::Pending(r, p) if same(r) && p.any == any => {
                    let Logged::Pending(_, p) = self.log.swap_remove(self.cursor) else { unreachable!() };
                    // swap_remove moved the last entry here; the pending one was the last
                    // (a job stops at its first pending ray), so nothing moved.
                    resumed = true;
                    match cone {
                        Some(c) => self.tracer.try_cone(ray, any, c, Some(p)),
                        None => self.tracer.resume(ray, p),
                    }
                }
                _ => {
                    // The job fired a different ray than last time: forget the rest.
                    self.log.truncate(self.cursor);
                    self.rays += 1;
                    fresh(ray)
                }
            }
        } else {
            self.rays += 1;
            fresh(ray)
        };
        self.log.truncate(self.cursor);
        match traced {
            Traced::Done(h) => {
                self.log.push(if any { Logged::Occluded(*ray, h.is_some()) } else { Logged::Hit(*ray, h) });
                if let (true, Some(t)) = (resumed && !any, h.and_then(|h| self.attribute_tile(&h))) {
                    // A resumed ray's hit may be the one found before it was suspended, in a
                    // tile evicted since: as a logged hit, the tile resident or the job waits
                    // (the run after finds the hit in the log).
                    if self.tracer.pager().is_some_and(|p| p.acquire(t) == megaray_page::Access::Missing) {
                        self.waiting = Some(t);
                        return Err(Suspended);
                    }
                }
                self.cursor += 1;
                Ok(if any { h.map(|_| HIT_ANY) } else { h })
            }
            Traced::Pending(p) => {
                self.waiting = Some(p.tile());
                self.log.push(Logged::Pending(*ray, p));
                Err(Suspended)
            }
        }
    }
}

/// A stand-in hit for any-hit answers (only `is_some` matters).
const HIT_ANY: Hit = Hit { t: 0.0, u: 0.0, v: 0.0, part: 0, prim: 0, tri: [[0.0; 3]; 3], placed: None };

impl RayCaster for Replay<'_, '_> {
    fn scene(&self) -> &Scene {
        self.tracer.scene()
    }
    fn bounds(&self) -> Option<megaray_base::Aabb> {
        Some(self.tracer.bounds)
    }
    fn intersect(&mut self, ray: &Ray) -> Result<Option<Hit>, Suspended> {
        self.query(ray, false, None)
    }
    fn occluded(&mut self, ray: &Ray) -> Result<bool, Suspended> {
        self.query(ray, true, None).map(|h| h.is_some())
    }
    fn intersect_cone(&mut self, ray: &Ray, cone: &RayCone) -> Result<Option<Hit>, Suspended> {
        self.query_cone(ray, false, cone)
    }
    fn occluded_cone(&mut self, ray: &Ray, cone: &RayCone) -> Result<bool, Suspended> {
        self.query_cone(ray, true, cone).map(|h| h.is_some())
    }
    fn take_approx(&mut self) -> bool {
        std::mem::take(&mut self.approx)
    }
    fn mark(&mut self) -> usize {
        self.cursor
    }
    fn checkpoint(&mut self, mark: usize, memo: Memo) {
        if self.tracer.pager().is_none() {
            return;
        }
        self.log.truncate(mark.min(self.cursor));
        self.log.push(Logged::Memo(memo));
        self.cursor = self.log.len();
    }
    fn recall(&mut self) -> Option<Memo> {
        match self.log.get(self.cursor) {
            Some(Logged::Memo(m)) => {
                let m = *m;
                self.cursor += 1;
                Some(m)
            }
            _ => None,
        }
    }
}

/// A suspended job: its index and its ray log.
struct Parked {
    index: usize,
    log: Vec<Logged>,
}

/// Parked jobs by the tile they wait for.
#[derive(Default)]
struct ParkLot {
    by_tile: HashMap<u32, Vec<Parked>>,
    count: usize,
}

/// Runs jobs `0..n` on the current rayon pool; see the module documentation.
pub fn run<T, F>(tracer: &Tracer, n: usize, opts: &JobOptions, job: F) -> JobsResult<T>
where
    T: Send,
    F: Fn(usize, &mut Replay) -> Result<T, Suspended> + Sync,
{
    run_reusing(tracer, n, opts, job, JobsBuffers::default())
}

/// [`run`], its results put into `buffers` (an earlier run's) rather than new vectors.
pub fn run_reusing<T, F>(tracer: &Tracer, n: usize, opts: &JobOptions, job: F, buffers: JobsBuffers<T>) -> JobsResult<T>
where
    T: Send,
    F: Fn(usize, &mut Replay) -> Result<T, Suspended> + Sync,
{
    let buffers: Vec<Mutex<Vec<(u32, T)>>> = buffers.0.into_iter().map(Mutex::new).collect();
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let lot = Mutex::new(ParkLot::default());
    let suspended = AtomicU64::new(0);
    let rays = AtomicU64::new(0);
    let wait_ns = AtomicU64::new(0);
    let late = AtomicBool::new(false);
    let chunk = opts.chunk.max(1);
    let pager = tracer.pager();
    let lock = || lot.lock().unwrap_or_else(|p| p.into_inner());

    // Runs job `i` with `log` into `out`; parks it if it suspends. (Finished jobs are counted
    // into `done` by the caller, a batch at a time: one shared counter bumped per job costs
    // more than a cheap job.)
    // (The caller holds a pin across a batch of attempts: one pin a job costs more than a
    // cheap job; a batch never waits while pinned.)
    let attempt = |i: usize, log: Vec<Logged>, replay: &mut Replay, out: &mut Vec<(u32, T)>| {
        replay.restart(log);
        let r = job(i, replay);
        match r {
            Ok(v) => {
                out.push((i as u32, v));
                None
            }
            Err(Suspended) => {
                let tile = replay
                    .waiting
                    .take()
                    .expect("a job suspended without a pending ray (it returned Suspended itself)");
                suspended.fetch_add(1, Relaxed);
                Some((tile, Parked { index: i, log: std::mem::take(&mut replay.log) }))
            }
        }
    };

    assert!(n <= u32::MAX as usize, "at most 2^32 - 1 jobs a run");
    let threads = rayon::current_num_threads().max(1);
    // One worker loop on every thread of the pool (broadcast: a plain parallel iterator
    // could run two loops one after the other on one thread).
    let per_thread: Vec<Vec<(u32, T)>> = rayon::broadcast(|ctx| {
        let mut replay = Replay::new(tracer);
        replay.stand_in = opts.stand_in;
        let mut out: Vec<(u32, T)> = match buffers.get(ctx.index()) {
            Some(b) => std::mem::take(&mut *b.lock().unwrap_or_else(|p| p.into_inner())),
            None => Vec::new(),
        };
        out.reserve(n / threads + chunk);
        let mut to_park: Vec<(u32, Parked)> = Vec::new();
        let mut seen_arrivals = u64::MAX;
        // Set after a wait that saw no tile arrive: ask again for the tiles parked jobs wait
        // for (one may have arrived and been evicted before its jobs ran).
        let mut stale = false;
        loop {
            if opts.deadline.is_some_and(|d| Instant::now() >= d) {
                late.store(true, SeqCst);
            }
            if late.load(Relaxed) || done.load(SeqCst) == n {
                break;
            }
            // Parked jobs whose tiles have arrived, when anything arrived since we looked.
            let mut ready = Vec::new();
            let arrivals = pager.map_or(0, |p| p.arrivals());
            if let Some(p) = pager {
                if arrivals != seen_arrivals {
                    seen_arrivals = arrivals;
                    let mut l = lock();
                    let tiles: Vec<u32> = l
                        .by_tile
                        .keys()
                        .copied()
                        .filter(|&t| {
                            let ok = p.settled(t);
                            if !ok && stale {
                                p.request(t);
                            }
                            ok
                        })
                        .collect();
                    stale = false;
                    for t in tiles {
                        let jobs = l.by_tile.remove(&t).unwrap_or_default();
                        l.count -= jobs.len();
                        ready.extend(jobs);
                    }
                }
            }
            let crowded = pager.is_some() && lock().count >= opts.max_parked.max(1);
            let before = out.len();
            if ready.is_empty() && !crowded {
                let start = next.fetch_add(chunk, SeqCst);
                if start < n {
                    let _pin = pager.map(|p| p.pin());
                    for i in start..(start + chunk).min(n) {
                        if let Some(p) = attempt(i, Vec::new(), &mut replay, &mut out) {
                            to_park.push(p);
                        }
                    }
                } else if done.load(SeqCst) < n {
                    // No new work: the jobs left are running on other threads or parked.
                    let Some(p) = pager else { break };
                    if lock().count == 0 {
                        std::thread::sleep(Duration::from_micros(200));
                        continue;
                    }
                    let t0 = Instant::now();
                    let timeout = opts.deadline.map_or(Duration::from_millis(50), |d| {
                        d.saturating_duration_since(t0).min(Duration::from_millis(50))
                    });
                    stale = p.wait_arrival(arrivals, timeout) == arrivals;
                    wait_ns.fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
                    seen_arrivals = u64::MAX;
                }
            } else if ready.is_empty() {
                // Too many parked: wait for tiles before taking new work.
                let p = pager.expect("jobs are parked only on paged tracers");
                let t0 = Instant::now();
                stale = p.wait_arrival(arrivals, Duration::from_millis(50)) == arrivals;
                wait_ns.fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
                seen_arrivals = u64::MAX;
            }
            let _pin = (!ready.is_empty()).then(|| pager.map(|p| p.pin()));
            for job in ready {
                if let Some(p) = attempt(job.index, job.log, &mut replay, &mut out) {
                    to_park.push(p);
                }
            }
            if out.len() > before {
                done.fetch_add(out.len() - before, SeqCst);
            }
            if !to_park.is_empty() {
                let mut l = lock();
                l.count += to_park.len();
                for (t, p) in to_park.drain(..) {
                    l.by_tile.entry(t).or_default().push(p);
                }
            }
        }
        rays.fetch_add(replay.rays, Relaxed);
        out
    });
    let finished = per_thread.iter().map(|v| v.len() as u64).sum::<u64>();
    JobsResult {
        stats: JobStats {
            finished,
            unfinished: n as u64 - finished,
            suspended: suspended.load(Relaxed),
            rays: rays.load(Relaxed),
            wait_secs: wait_ns.load(Relaxed) as f64 * 1e-9,
        },
        per_thread,
    }
}
