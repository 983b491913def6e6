//! The driver: the queries ([`Tracer::intersect`], [`Tracer::occluded`], the resumable
//! [`Tracer::try_intersect`] and [`Tracer::resume`], packets), which run a ray's walk through
//! the kernels and handle what the hot loop hands back (a tile to enter, an edge on the ray,
//! a full stack, a missing tile), and the thread's scratch memory.

use megaray_base::{t_start, Ray, Rays16};
use megaray_scene::format::ChildRef;
use std::cell::RefCell;

use crate::boxes::{RayBox, W};
use crate::isa::{Isa, GENERIC};
use crate::lod::LodRay;
use crate::tracer::{Entry, Step, Tracer, STACK, TOP};
use crate::tri::{lanes, RayTri4};
use crate::walk::{Event, Found, Walk};
use crate::{packet, stats, Hit, Pending, Traced};

impl<'s> Tracer<'s> {
    /// The closest hit of `ray` in `[ray.t_min, ray.t_max)`. On a paged tracer this waits
    /// for missing tiles (use [`Tracer::try_intersect`] not to).
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if self.pager.is_none() && self.layer.is_none() {
            return self.hit_of(self.unpaged::<false>(ray));
        }
        self.blocking(ray, false)
    }

    /// Whether anything lies on `ray` in `[ray.t_min, ray.t_max)`. On a paged tracer this
    /// waits for missing tiles (use [`Tracer::try_occluded`] not to).
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        if self.pager.is_none() && self.layer.is_none() {
            return self.unpaged::<true>(ray).is_some();
        }
        self.blocking(ray, true).is_some()
    }

    /// The closest hit of `ray`, or [`Traced::Pending`] when it needs an absent tile.
    /// Paged tracers: call under a pin ([`Pager::pin`]).
    pub fn try_intersect(&self, ray: &Ray) -> Traced {
        self.traverse(ray, false, None, 0)
    }

    /// Any hit of `ray` (`Done(Some(_))` means occluded), or [`Traced::Pending`].
    /// Paged tracers: call under a pin ([`Pager::pin`]).
    pub fn try_occluded(&self, ray: &Ray) -> Traced {
        self.traverse(ray, true, None, 0)
    }

    /// Continues a pending traversal of the same `ray` (same query kind) where it stopped.
    pub fn resume(&self, ray: &Ray, pending: Box<Pending>) -> Traced {
        let any = pending.any;
        self.traverse(ray, any, Some(pending), 0)
    }

    /// Traces to the end, waiting for missing tiles (pinned only while traversing).
    #[inline]
    pub(crate) fn blocking(&self, ray: &Ray, any: bool) -> Option<Hit> {
        let Some(pager) = self.pager else {
            return match self.traverse(ray, any, None, 0) {
                Traced::Done(h) => h,
                Traced::Pending(_) => unreachable!("an unpaged tracer never suspends"),
            };
        };
        let mut from = None;
        loop {
            let seen = pager.arrivals();
            let r = {
                let _pin = pager.pin();
                self.traverse(ray, any, from.take(), 0)
            };
            match r {
                Traced::Done(h) => return h,
                Traced::Pending(p) => {
                    let mut seen = seen;
                    while !pager.settled(p.tile) {
                        let now = pager.wait_arrival(seen, std::time::Duration::from_millis(20));
                        if now == seen {
                            // Nothing arrived: ask again (the tile may have come and gone).
                            pager.request(p.tile);
                        }
                        seen = now;
                    }
                    from = Some(p);
                }
            }
        }
    }

    /// The closest hits of a packet of rays (coherent ones, such as 4x4 pixels), into `hits`
    /// (same length as `rays`), traced 16 at a time by the packet kernel ([`packet`]) on the
    /// tracer's instruction set ([`Kernels::isa`]). Exactly the distances of
    /// [`Tracer::intersect`] on each ray.
    pub fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        for (r, h) in rays.chunks(packet::WIDTH).zip(hits.chunks_mut(packet::WIDTH)) {
            self.intersect16(&Rays16::from_rays(r), h);
        }
    }

    /// [`Tracer::intersect_packet`] of rays already in structure of arrays (as
    /// [`Rays16`]; the hits of its `len` rays into the first `len` of `hits`).
    pub fn intersect16(&self, rays: &Rays16, hits: &mut [Option<Hit>]) {
        assert!(rays.len <= packet::WIDTH && rays.len <= hits.len(), "one hit slot per ray, at most 16");
        let hits = &mut hits[..rays.len];
        if self.pager.is_some() || self.layer.is_some() {
            // Packets do not suspend, nor enter instances: a paged tracer, or one of a scene
            // with instances, traces them ray by ray.
            for (i, h) in hits.iter_mut().enumerate() {
                *h = self.intersect(&rays.ray(i));
            }
            return;
        }
        // One stack per thread, kept between calls: callers pass one packet at a time.
        thread_local! {
            static STACK: std::cell::RefCell<packet::PacketStack> = const { std::cell::RefCell::new(Vec::new()) };
        }
        STACK.with_borrow_mut(|stack| packet::intersect16(self, rays, hits, self.isa, stack));
    }

    /// The hit an [`Tracer::occluded`] query of an unpaged tracer stops at, by the same way
    /// into the kernels (the new-ray and assembly kernels): every kernel visits a node's
    /// children in the same order, so all stop at the same hit. For the tests.
    #[doc(hidden)]
    pub fn any_hit(&self, ray: &Ray) -> Option<Hit> {
        assert!(self.pager.is_none() && self.layer.is_none(), "any_hit is for unpaged tracers");
        self.hit_of(self.unpaged::<true>(ray))
    }

    /// [`Tracer::intersect`] (or, `any`, [`Tracer::occluded`]) of an unpaged tracer with
    /// `pad` empty entries under the root on the traversal stack, enough of them to fill it
    /// at the first node: the hits must be those of the unpadded query. For the tests of the
    /// stack's spill, which no real tree deep enough to need it would test as surely.
    #[doc(hidden)]
    pub fn trace_padded(&self, ray: &Ray, any: bool, pad: usize) -> Option<Hit> {
        assert!(self.pager.is_none(), "padded traces are for unpaged tracers");
        match self.traverse(ray, any, None, pad) {
            Traced::Done(h) => h,
            Traced::Pending(_) => unreachable!("an unpaged tracer never suspends"),
        }
    }

    /// The single-ray kernel on this tracer's instruction set (see [`Tracer::walk`]), `pad`
    /// as in [`Tracer::trace_padded`] (0 but in tests).
    pub(crate) fn traverse(&self, ray: &Ray, any: bool, from: Option<Box<Pending>>, pad: usize) -> Traced {
        self.traverse_with(ray, any, from, pad, None)
    }

    /// [`Tracer::traverse`] choosing levels of detail by `lod` where the ray enters a part
    /// ([`Tracer::lod_entry`]).
    pub(crate) fn traverse_with(
        &self,
        ray: &Ray,
        any: bool,
        from: Option<Box<Pending>>,
        pad: usize,
        lod: Option<&LodRay>,
    ) -> Traced {
        if let Some(l) = &self.layer {
            return l.traverse(ray, any, from, lod);
        }
        #[cfg(target_arch = "x86_64")]
        match self.isa {
            // `isa` is one that the CPU reported (`Isa::detect`, `Isa::available`). The
            // same kernel on both, compiled for each ([`walk_avx512`]).
            Isa::Avx2 | Isa::Avx512 => {
                return match any {
                    true => self.traverse_in::<true, true>(ray, from, pad, lod),
                    false => self.traverse_in::<true, false>(ray, from, pad, lod),
                };
            }
            Isa::Baseline => {}
        }
        match any {
            true => self.traverse_in::<false, true>(ray, from, pad, lod),
            false => self.traverse_in::<false, false>(ray, from, pad, lod),
        }
    }

    /// The kernel's driver, its box test on AVX2 (`AVX`) or on the baseline's 4-wide SSE;
    /// `ANY`: stop at the first hit found (shadow rays). It runs the hot loop
    /// ([`Tracer::walk`]) with a stack kept per thread; what the loop cannot finish alone
    /// goes to [`Tracer::drive_rare`].
    #[inline(always)]
    pub(crate) fn traverse_in<const AVX: bool, const ANY: bool>(
        &self,
        ray: &Ray,
        from: Option<Box<Pending>>,
        pad: usize,
        lod: Option<&LodRay>,
    ) -> Traced {
        stats::count(|s| s.rays += 1);
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut scratch) => self.drive::<AVX, ANY>(ray, from, pad, &mut scratch, lod),
            Err(_) => self.drive_fresh::<AVX, ANY>(ray, from, pad, lod),
        })
    }

    /// [`Tracer::drive`] with scratch memory of its own, for a thread whose own is taken
    /// (never, since traversals do not nest, but a fresh one is as good). Out of line: inlined,
    /// the fresh scratch's kilobyte was copied on every ray.
    #[cold]
    #[inline(never)]
    fn drive_fresh<const AVX: bool, const ANY: bool>(
        &self,
        ray: &Ray,
        from: Option<Box<Pending>>,
        pad: usize,
        lod: Option<&LodRay>,
    ) -> Traced {
        self.drive::<AVX, ANY>(ray, from, pad, &mut Scratch::fresh(), lod)
    }

    /// A new ray on an unpaged tracer (which never suspends): the shortest way into the
    /// kernel, for [`Tracer::intersect`] and [`Tracer::occluded`]. The closure given to the
    /// thread-local is kept small so that it inlines (and with it the thread-local's access).
    #[inline(always)]
    pub(crate) fn unpaged<const ANY: bool>(&self, ray: &Ray) -> Option<Found> {
        stats::count(|s| s.rays += 1);
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut scratch) => self.unpaged_in::<ANY>(ray, &mut scratch),
            Err(_) => self.unpaged_in::<ANY>(ray, &mut Scratch::fresh()),
        })
    }

    /// [`Tracer::unpaged`] with the thread's scratch memory: by a new-ray kernel where
    /// every tile is checked ([`Tracer::new_ray`]), else by the driver.
    #[inline(never)]
    pub(crate) fn unpaged_in<const ANY: bool>(&self, ray: &Ray, scratch: &mut Scratch) -> Option<Found> {
        if let Some(table) = &self.new_ray {
            let kernel = self.first_kernel::<true>(&mut scratch.streak, ray)?;
            #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
            if self.asm && kernel == GENERIC {
                // SAFETY: `asm` is set only where the CPU runs the kernel and every tile is
                // checked (`Tracer::asm_kernel`).
                return unsafe { self.new_ray_asm::<ANY>(scratch, ray) };
            }
            // SAFETY: the table holds kernels only for an instruction set the CPU has
            // (`Tracer::new_ray_table`), and `kernel` is below `KERNELS`.
            return unsafe { table[ANY as usize].get_unchecked(kernel)(self, scratch, ray) };
        }
        let mut w = Walk::new(scratch, self.root, ray.t_max);
        #[cfg(target_arch = "x86_64")]
        if self.isa != Isa::Baseline {
            return match self.walk_on::<true, ANY>(&mut w, ray) {
                Event::Empty | Event::Hit => w.best,
                ev => self.drive_rare::<true, ANY>(ray, &mut w, Vec::new(), Some(ev), NO_PRIOR, None).expect(UNPAGED),
            };
        }
        match self.walk_on::<false, ANY>(&mut w, ray) {
            Event::Empty | Event::Hit => w.best,
            ev => self.drive_rare::<false, ANY>(ray, &mut w, Vec::new(), Some(ev), NO_PRIOR, None).expect(UNPAGED),
        }
    }

    /// [`Tracer::traverse_in`] with a stack: the common case (a new ray that the hot loop
    /// finishes in one go) inline, the rest in [`Tracer::drive_rare`].
    #[inline(always)]
    pub(crate) fn drive<const AVX: bool, const ANY: bool>(
        &self,
        ray: &Ray,
        from: Option<Box<Pending>>,
        pad: usize,
        scratch: &mut Scratch,
        lod: Option<&LodRay>,
    ) -> Traced {
        let mut w = Walk::new(scratch, self.root, ray.t_max);
        if from.is_none() && pad == 0 {
            match self.walk_on::<AVX, ANY>(&mut w, ray) {
                Event::Empty | Event::Hit => Traced::Done(self.hit_of(w.best)),
                ev => {
                    let r = self.drive_rare::<AVX, ANY>(ray, &mut w, Vec::new(), Some(ev), NO_PRIOR, lod);
                    self.traced(r, NO_PRIOR)
                }
            }
        } else {
            self.drive_from::<AVX, ANY>(ray, &mut w, from, pad, lod)
        }
    }

    /// A resumed (or, in tests, padded) traversal: its saved stack becomes the spill.
    #[inline(never)]
    pub(crate) fn drive_from<const AVX: bool, const ANY: bool>(
        &self,
        ray: &Ray,
        w: &mut Walk<'_>,
        from: Option<Box<Pending>>,
        pad: usize,
        lod: Option<&LodRay>,
    ) -> Traced {
        let mut spill = Vec::new();
        let mut prior = NO_PRIOR;
        if let Some(p) = from {
            w.next = None;
            w.fresh = false;
            w.best = p.best;
            w.t_best = p.best.map_or(ray.t_max, |f| f.t);
            prior = (p.best, p.hit);
            spill = p.stack;
        }
        if pad > 0 {
            // One entry more than leaves room for a node's children, the rest below them.
            let empty = Entry { r: ChildRef::EMPTY.0, arr: TOP, t: f32::NEG_INFINITY };
            w.sp = pad.min(STACK - W + 1);
            w.fixed[..w.sp].fill(empty);
            spill.resize(pad - w.sp, empty);
        }
        self.traced(self.drive_rare::<AVX, ANY>(ray, w, spill, None, prior, lod), prior)
    }

    /// The public form of the driver's outcome.
    pub(crate) fn traced(&self, r: Result<Option<Found>, Box<Pending>>, prior: Prior) -> Traced {
        match r {
            Ok(f) => Traced::Done(self.hit_after(f, prior)),
            Err(p) => Traced::Pending(p),
        }
    }

    /// The [`Hit`] of `f`: the one made before the ray was suspended if it is still the
    /// closest (its tile may have been evicted since), else made now (its tile is resident:
    /// the traversal is pinned).
    pub(crate) fn hit_after(&self, f: Option<Found>, prior: Prior) -> Option<Hit> {
        match prior {
            (Some(pf), h) if f == Some(pf) => h,
            _ => self.hit_of(f),
        }
    }

    /// The driver's loop for what the hot loop returns to it ([`Event`]): refills and
    /// spills of the fixed stack, tiles to enter (checked, or asked of the pager), blocks
    /// left to the double-precision reference. Runs the hot loop again after each, starting
    /// with `first` if given. Ends with what was found, or with the ray pending.
    #[inline(never)]
    pub(crate) fn drive_rare<const AVX: bool, const ANY: bool>(
        &self,
        ray: &Ray,
        w: &mut Walk<'_>,
        mut spill: Vec<Entry>,
        mut first: Option<Event>,
        prior: Prior,
        lod: Option<&LodRay>,
    ) -> Result<Option<Found>, Box<Pending>> {
        loop {
            let ev = match first.take() {
                Some(ev) => ev,
                None => self.walk_on::<AVX, ANY>(w, ray),
            };
            match ev {
                Event::Hit => return Ok(w.best),
                Event::Empty => {
                    if spill.is_empty() {
                        return Ok(w.best);
                    }
                    // The top of the spill becomes the fixed stack.
                    let n = spill.len().min(STACK / 2);
                    let rest = spill.len() - n;
                    w.fixed[..n].copy_from_slice(&spill[rest..]);
                    spill.truncate(rest);
                    w.sp = n;
                }
                Event::Full => {
                    // The bottom half of the fixed stack goes to the spill (all of it when
                    // less is on it: the assembly kernel's stack may be cut short in tests,
                    // `Tracer::with_asm_stack`).
                    let n = (STACK / 2).min(w.sp);
                    spill.extend_from_slice(&w.fixed[..n]);
                    w.fixed.copy_within(n..w.sp, 0);
                    w.sp -= n;
                }
                Event::Enter(arr) => {
                    // Into a part from the top-level tree: at the level of detail `lod` chooses.
                    let arr = match lod {
                        Some(l) => self.lod_entry(w, arr, ray, l),
                        None => arr,
                    };
                    match self.enter(&mut w.c, arr) {
                        Ok(()) => {}
                        Err(Step::Missing(tile)) => {
                            spill.extend_from_slice(&w.fixed[..w.sp]);
                            spill.extend(w.next);
                            let hit = self.hit_after(w.best, prior);
                            return Err(Box::new(Pending {
                                stack: spill,
                                best: w.best,
                                hit,
                                any: ANY,
                                tile,
                                inside: None,
                            }));
                        }
                        // A corrupt tile: what needed it is skipped.
                        Err(_) => w.next = None,
                    }
                }
                Event::Exact { unit, count } => {
                    // The rest of the leaf by the double-precision reference (which gives
                    // the fast test's results wherever that one decides).
                    let rt = RayTri4::new(ray);
                    let (mut unit, mut left) = (unit, count);
                    while left > 0 {
                        let b = self.block_at(unit);
                        if let Some((lane, h)) = rt.scalar(b, lanes(left), w.t_best) {
                            w.t_best = h.t;
                            w.best = Some(Found::new(h, w.c, unit, lane));
                            if ANY {
                                return Ok(w.best);
                            }
                        }
                        left = left.saturating_sub(4);
                        unit += 9;
                    }
                }
            }
        }
    }

    /// [`Tracer::walk`] compiled for the driver's instruction set: a function of its own,
    /// never inlined, so that its registers are allocated for the loop alone.
    ///
    /// On AVX2 there is one kernel per octant of ray directions, in which the rows of the
    /// near and far planes are constants (memory operands of the box test rather than six
    /// offsets held in registers), and one for any direction, which reads the triangle
    /// test's rows by the ray's axes (held per ray, so that nothing branches on them: diffuse
    /// rays, whose axis comes at random, mispredicted a choice by it per block, and then,
    /// with a kernel per axis, the choice of kernel per ray). Eight kernels are more code
    /// than the instruction cache holds at once, so the octant kernels run only for coherent
    /// rays: when this thread's last [`STREAK_MIN`] new rays ran in the same octant (camera
    /// and shadow rays), and the generic kernel otherwise (diffuse bounces, whose octants
    /// come at random). Each choice was measured: docs/PERF.md, "Octant and generic
    /// kernels". All give the same hits (tested).
    #[inline(always)]
    pub(crate) fn walk_on<const AVX: bool, const ANY: bool>(&self, w: &mut Walk<'_>, ray: &Ray) -> Event {
        let kernel = if std::mem::replace(&mut w.fresh, false) {
            match self.first_kernel::<AVX>(w.streak, ray) {
                Some(kernel) => kernel,
                None => return Event::Empty,
            }
        } else if AVX && self.octant_kernels == Some(true) {
            RayBox::octant(ray)
        } else {
            // A walk resumed after an event keeps to the generic kernel. (The baseline's
            // table holds the same kernel under every number.)
            GENERIC
        };
        // SAFETY: the table holds AVX kernels only where `isa` says the CPU has their
        // instructions (`Tracer::kernel_table`), and `kernel` is below `KERNELS` (an octant
        // below 8, or [`GENERIC`]).
        unsafe { self.kernels[ANY as usize].get_unchecked(kernel)(self, w, ray) }
    }

    /// The kernel's number for a new ray (an octant's, `0..8`, or [`GENERIC`]; any on the
    /// baseline, whose table holds one kernel under every number), or `None` when the ray
    /// misses the scene's box, as [`Tracer::walk_on`] says. Updates the thread's `streak`.
    #[inline(always)]
    pub(crate) fn first_kernel<const AVX: bool>(&self, streak: &mut Streak, ray: &Ray) -> Option<usize> {
        // Most rays of a wide view miss the whole scene: they end here, before any
        // kernel's set-up. But where rays come that enter the scene's box (a view filled
        // by the model, secondary rays), the test is 10-35 instructions that never cull,
        // and the root node's test would cull as well: after a ray that entered the box,
        // the thread's next [`SKIP_BOUNDS`] new rays go without it (docs/PERF.md,
        // "Scene-box test"). In the driver, not the kernel, so that a miss never pays for
        // a kernel's set-up.
        if streak.skip_bounds > 0 {
            streak.skip_bounds -= 1;
        } else if self.misses_bounds(&ray.settled()) {
            return None;
        } else {
            streak.skip_bounds = SKIP_BOUNDS;
        }
        if !AVX {
            return Some(GENERIC);
        }
        // From the direction's three sign bits, read one by one (`Ray::settled`), as the
        // kernel reads the ray after.
        let oct = RayBox::octant_of(ray.settled_dir());
        Some(match self.octant_kernels {
            Some(true) => oct,
            Some(false) => GENERIC,
            None => {
                // Without branches: diffuse rays' octants come at random, and a branch on
                // `last == oct` mispredicted for nearly a third of them.
                let (last, n) = (streak.octant, streak.run);
                let n = std::hint::select_unpredictable(last as usize == oct, n.saturating_add(1), 0);
                (streak.octant, streak.run) = (oct as u8, n);
                std::hint::select_unpredictable(n >= STREAK_MIN, oct, GENERIC)
            }
        })
    }

    /// A new ray's whole walk on a tracer with every tile checked ([`Tracer::new_ray`]'s
    /// table): [`Tracer::walk`] inlined with its [`Walk`] a local of this function, so that
    /// the walk's state (stack depth, closest hit, the entry to start from) is made, kept and
    /// read in registers, not written to memory for the kernel and read back by a driver
    /// (docs/PERF.md, "New-ray kernels"). The rare events go on in [`Tracer::drive_rare`]
    /// with the walk kernels.
    #[inline(always)]
    pub(crate) fn new_ray<const AVX: bool, const ANY: bool, const OCT: usize>(
        &self,
        scratch: &mut Scratch,
        ray: &Ray,
    ) -> Option<Found> {
        // The ray read field by field (`Ray::settled`): one written just before the call is
        // taken from the pending stores, where the kernel's vector loads would wait for them.
        let ray = &ray.settled();
        let mut w = Walk::new(scratch, self.root, ray.t_max);
        // (Its scene-box test was [`Tracer::first_kernel`]'s.)
        w.fresh = false;
        match self.walk::<AVX, ANY, true, OCT>(&mut w, ray) {
            Event::Empty | Event::Hit => w.best,
            // The walk moved, not borrowed, so that nothing takes its address on the
            // common path.
            ev => self.new_ray_rare::<AVX, ANY>(ray, w, ev),
        }
    }

    /// [`Tracer::new_ray`] after an event: the driver's loop, with the walk kernels.
    #[cold]
    #[inline(never)]
    pub(crate) fn new_ray_rare<const AVX: bool, const ANY: bool>(
        &self,
        ray: &Ray,
        mut w: Walk<'_>,
        ev: Event,
    ) -> Option<Found> {
        self.drive_rare::<AVX, ANY>(ray, &mut w, Vec::new(), Some(ev), NO_PRIOR, None).expect(UNPAGED)
    }

    /// Whether `ray` misses the scene's box (its origin outside it, and its segment not
    /// entering it): with the slab products and widening of the kernels' box tests, so never
    /// stricter than them.
    #[inline(always)]
    pub(crate) fn misses_bounds(&self, ray: &Ray) -> bool {
        let rb = RayBox::new(ray);
        !rb.starts_inside(&self.bounds) && !rb.enters(&self.bounds, t_start(ray.t_min), ray.t_max)
    }
}

/// How many new rays go without the test of the scene's box after one that entered it
/// ([`Tracer::walk_on`]): a view's rays come in tiles of neighbouring pixels, and a ray that
/// misses the box all the same costs its set-up (about a hundred instructions) and one node.
pub(crate) const SKIP_BOUNDS: u8 = 15;

/// How many new rays in a row of one octant make a thread use that octant's kernel
/// ([`Tracer::walk_on`]).
pub(crate) const STREAK_MIN: u8 = 4;

/// What a resumed ray had found before it stopped, and its [`Hit`] ([`Pending::hit`]).
pub(crate) type Prior = (Option<Found>, Option<Hit>);
pub(crate) const NO_PRIOR: Prior = (None, None);

/// What an unpaged tracer's driver can never end with.
pub(crate) const UNPAGED: &str = "an unpaged tracer never suspends";

/// A thread's memory for the single-ray kernel, kept from ray to ray (not made and zeroed
/// for each), in one thread-local ([`SCRATCH`]).
pub(crate) struct Scratch {
    /// The traversal stack.
    pub(crate) stack: [Entry; STACK],
    /// What the thread's recent new rays were like ([`Tracer::walk_on`]).
    pub(crate) streak: Streak,
}

/// What a thread's recent new rays were like, for the kernel's choices for its next ones.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Streak {
    /// The octant of the thread's last new ray ([`Tracer::walk_on`]).
    pub(crate) octant: u8,
    /// How many new rays before it had the same octant.
    pub(crate) run: u8,
    /// How many more new rays go without the test of the scene's box ([`Tracer::walk_on`]).
    pub(crate) skip_bounds: u8,
}

impl Scratch {
    pub(crate) const NEW: Scratch =
        Scratch { stack: [Entry::ZERO; STACK], streak: Streak { octant: 0, run: 0, skip_bounds: 0 } };

    /// One for a thread whose own is taken (never: traversals do not nest).
    pub(crate) fn fresh() -> Scratch {
        Scratch::NEW
    }
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = const { RefCell::new(Scratch::NEW) };
}
