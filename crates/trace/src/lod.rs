//! Level of detail chosen per ray. A scene built with levels of detail holds, for each
//! full-detail part, coarser stand-ins of it as parts of their own, each with a geometric
//! error (`PartEntry::lod_error`: its triangles lie within it of the part's). A ray carries
//! a [`Cone`] (its width where it starts and how fast it widens: a pixel's footprint for a
//! camera ray) and an error allowed in footprints ([`LodRay::pixels`], `render --lod-error`).
//! Where the ray enters a part from the top-level tree, it takes the coarsest level whose
//! error fits the footprint at its entry distance (`Tracer::lod_entry`): far parts are
//! traced in their small stand-ins, whose tiles are few, and near ones in full detail. The
//! error allowed is the tracer's ([`Tracer::with_lod_error`], [`Tracer::set_lod_error`]);
//! the ray's footprint is the caller's ([`RayCone`]).
//!
//! **A stand-in instead of a stall** ([`Tracer::stand_in`]). A level whose root tile is not
//! resident is passed over for the next coarser one (the coarsest of every part is pinned by
//! the pager), and a ray that meets a missing tile inside the level it took is traced again
//! with that part held to a coarser level; the tiles it lacked were requested, so that later
//! frames refine. Such an answer is marked approximate ([`LodHit::approx`]). Renders that
//! must be exact at their level wait instead ([`Tracer::try_cone`], [`Tracer::trace_cone`]).
//!
//! **Secondary rays** leave a surface of some level ([`RayCone::from_part`]): they keep to
//! that level or coarser on the same part, so that a finer copy of the same surface cannot
//! shadow it, and their caller starts them past the level's error.

use std::cell::Cell;
use std::sync::atomic::Ordering::Relaxed;

use megaray_base::Ray;
use megaray_page::Access;
use megaray_scene::format::{ChildRef, NO_PART};
use megaray_scene::Scene;

use crate::isa::Kernels;
use crate::tracer::{Entry, Tracer};
use crate::walk::Walk;
use crate::{Hit, Pending, Traced};

/// The footprint of a ray: `width + spread * t` at distance `t` (world units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    /// Width where the ray starts.
    pub width: f32,
    /// Growth of the width per unit of distance (a camera ray: a pixel's angle).
    pub spread: f32,
}

impl Cone {
    /// The width at distance `t` (negative distances count as 0).
    pub fn at(&self, t: f32) -> f32 {
        self.width + self.spread * t.max(0.0)
    }
}

/// What a caller says of a ray for its level of detail: its footprint, and the part whose
/// surface it leaves (a secondary ray), if any.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayCone {
    pub cone: Cone,
    /// The part (full detail or a level of detail) of the surface the ray leaves.
    pub from_part: Option<u32>,
}

impl RayCone {
    /// A camera ray: no width at the eye, `spread` a pixel's angle.
    pub fn camera(spread: f32) -> RayCone {
        RayCone { cone: Cone { width: 0.0, spread }, from_part: None }
    }
}

/// How a ray chooses its level of detail (the driver's view of a [`RayCone`]).
#[derive(Clone, Debug)]
pub(crate) struct LodRay {
    cone: Cone,
    /// The error allowed, in footprints.
    pixels: f32,
    /// Parts held to a level or coarser: (full-detail part, lowest level allowed), the first
    /// `floors` of them (no allocation per ray).
    floor: [(u32, u32); FLOORS],
    floors: usize,
    /// Pass over levels whose root tile is not resident (a stand-in answers), rather than
    /// enter them and wait.
    stand_in: bool,
    /// Set when a level was passed over for want of its tiles (the answer is approximate).
    missed: Cell<bool>,
}

/// The most parts a ray holds to a coarser level at once.
const FLOORS: usize = 8;

impl LodRay {
    /// This ray entering an object placed at scale `s` (an instance's): an object-space
    /// error `e` is `e * s` in the world, so the error allowed is divided by `s`.
    pub(crate) fn scaled(&self, s: f32) -> LodRay {
        LodRay { pixels: self.pixels / s, ..self.clone() }
    }

    /// Takes over `other`'s mark of a level passed over (`other` made by [`LodRay::scaled`]).
    pub(crate) fn missed_in(&self, other: &LodRay) {
        if other.missed.get() {
            self.missed.set(true);
        }
    }

    /// The lowest level allowed for full-detail part `part`.
    fn floor_of(&self, part: u32) -> u32 {
        self.floor[..self.floors].iter().filter(|f| f.0 == part).map(|f| f.1).max().unwrap_or(0)
    }

    /// Holds `part` to `level` or coarser; `false` when the ray holds too many parts already.
    fn hold(&mut self, part: u32, level: u32) -> bool {
        if let Some(f) = self.floor[..self.floors].iter_mut().find(|f| f.0 == part) {
            f.1 = f.1.max(level);
            return true;
        }
        if self.floors == FLOORS {
            return false;
        }
        self.floor[self.floors] = (part, level);
        self.floors += 1;
        true
    }
}

/// A full-detail part's levels, finest (the part itself) first, as the tracer reads them
/// where a ray enters the part ([`Tracer::lod_entry`]).
#[derive(Clone, Debug)]
pub(crate) struct LodLevels {
    /// The part's box (the entry distance of a ray).
    lo: [f32; 3],
    hi: [f32; 3],
    /// Per level: the link to its root (the finest's is what the top-level tree holds), its
    /// root tile, its error.
    levels: Vec<(u64, u32, f32)>,
}

/// The levels of every full-detail part of `scene` (indexed by part).
pub(crate) fn lod_levels(scene: &Scene) -> Vec<LodLevels> {
    let (parts, tiles) = (scene.parts(), scene.tiles());
    (0..scene.full_part_count())
        .map(|p| LodLevels {
            lo: parts[p as usize].bounds.min,
            hi: parts[p as usize].bounds.max,
            levels: scene
                .lod_chain(p)
                .map(|q| {
                    let e = &parts[q as usize];
                    let root = tiles[e.root_tile as usize].node0() + e.root_node as u64;
                    (ChildRef::link(e.root_tile, root).0, e.root_tile, e.lod_error)
                })
                .collect(),
        })
        .collect()
}

/// What a ray traced with a level of detail found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodHit {
    /// The closest hit (any hit, for an any-hit query): its part may be a level of detail.
    pub hit: Option<Hit>,
    /// Some tile the ray wanted was not resident: a coarser stand-in answered (the tile was
    /// requested). An exact answer needs that tile.
    pub approx: bool,
}

impl<'s> Tracer<'s> {
    /// This tracer choosing levels of detail with an error of `pixels` footprints (0: full
    /// detail, the default). An unpaged tracer then stops where a link enters the root tile
    /// of a part with levels (every tile checked: [`Scene::checked_but_lod_roots`]), or at
    /// every tile crossing before then (its fastest kernels follow links without stopping,
    /// and would trace full detail).
    pub fn with_lod_error(self, pixels: f32) -> Tracer<'s> {
        let has_lod = self.scene.header().lod_part_count > 0;
        let stops = self.pager.is_some() || (has_lod && pixels > 0.0);
        let mut t = if self.pager.is_none() && has_lod && pixels > 0.0 {
            // Kernels that check tiles, counting as checked those where no level is chosen
            // (crossings into the others return to the driver, `Tracer::lod_entry` and
            // `Tracer::enter`); the instance layer (its trees) kept.
            let fresh = Tracer::bare(self.scene, Kernels { tile_checks: true, ..self.choice });
            let checked = self.scene.checked_but_lod_roots().unwrap_or(megaray_scene::CheckedTiles::NONE);
            Tracer { checked, layer: self.layer, bounds: self.bounds, ..fresh }
        } else {
            self
        };
        // Levels are chosen only where a part's entry stops in the driver (paged, or made so
        // above); a tracer that crosses tiles inline traces full detail.
        if has_lod && stops {
            t.lod = lod_levels(t.scene).into();
        }
        let t = t.rebase();
        t.set_lod_error(pixels);
        t
    }

    /// The error allowed in footprints ([`Tracer::with_lod_error`]).
    pub fn lod_error(&self) -> f32 {
        f32::from_bits(self.lod_px.load(Relaxed))
    }

    /// Changes the error allowed between frames (the budget steering it). A tracer made
    /// without levels of detail in mind (unpaged, full detail) keeps to full detail.
    pub fn set_lod_error(&self, pixels: f32) {
        self.lod_px.store(pixels.max(0.0).to_bits(), Relaxed);
    }

    /// Whether rays of cone `c` choose a level of detail on this tracer.
    pub(crate) fn lod_applies(&self, c: &RayCone) -> bool {
        self.lod_ray(c, false).is_some()
    }

    /// The driver's view of `c` on this tracer, or `None` where levels of detail do not
    /// apply (an error of 0, a scene without them, a tracer that never stops at a tile).
    fn lod_ray(&self, c: &RayCone, stand_in: bool) -> Option<LodRay> {
        let pixels = self.lod_error();
        if self.lod.is_empty() || (pixels <= 0.0 && c.from_part.is_none()) {
            return None;
        }
        let mut l =
            LodRay { cone: c.cone, pixels, floor: [(0, 0); FLOORS], floors: 0, stand_in, missed: Cell::new(false) };
        if let Some(p) = c.from_part.and_then(|p| self.scene.parts().get(p as usize)) {
            if p.lod_level > 0 {
                l.hold(p.lod_of, p.lod_level);
            }
        }
        Some(l)
    }

    /// The closest hit of `ray` (`any`: any hit) at the level of detail its cone chooses,
    /// waiting for missing tiles on a paged tracer (pinned only while traversing).
    pub fn trace_cone(&self, ray: &Ray, any: bool, c: &RayCone) -> Option<Hit> {
        if self.misses_bounds(ray) {
            // Before the level of detail's set-up: most of a distant model's rays.
            return None;
        }
        let Some(lod) = self.lod_ray(c, false) else {
            if self.pager.is_none() && self.layer.is_none() {
                // Full detail, unpaged: the fastest way in.
                return self.hit_of(if any { self.unpaged::<true>(ray) } else { self.unpaged::<false>(ray) });
            }
            return self.blocking(ray, any);
        };
        let Some(pager) = self.pager else {
            return match self.traverse_with(ray, any, None, 0, Some(&lod)) {
                Traced::Done(h) => h,
                Traced::Pending(_) => unreachable!("an unpaged tracer never suspends"),
            };
        };
        let mut from = None;
        loop {
            let seen = pager.arrivals();
            let r = {
                let _pin = pager.pin();
                self.traverse_with(ray, any, from.take(), 0, Some(&lod))
            };
            match r {
                Traced::Done(h) => return h,
                Traced::Pending(p) => {
                    let mut seen = seen;
                    while !pager.settled(p.tile()) {
                        let now = pager.wait_arrival(seen, std::time::Duration::from_millis(20));
                        if now == seen {
                            // Nothing arrived: ask again (the tile may have come and gone).
                            pager.request(p.tile());
                        }
                        seen = now;
                    }
                    from = Some(p);
                }
            }
        }
    }

    /// [`Tracer::try_intersect`] (`any`: [`Tracer::try_occluded`]) at the level of detail
    /// `c` chooses, or its resumption (`from`): the ray waits for the tiles of that level.
    /// Paged tracers: call under a pin.
    pub fn try_cone(&self, ray: &Ray, any: bool, c: &RayCone, from: Option<Box<Pending>>) -> Traced {
        let lod = self.lod_ray(c, false);
        let any = from.as_ref().map_or(any, |p| p.any);
        self.traverse_with(ray, any, from, 0, lod.as_ref())
    }

    /// The closest hit of `ray` (`any`: any hit) at the level of detail `c` chooses, never
    /// waiting for a tile where a coarser stand-in is resident (the tile is requested and
    /// the answer marked approximate). `Err` with the tile only where no stand-in exists (a
    /// part without levels of detail): then the ray must wait ([`Tracer::try_cone`]).
    /// Paged tracers: call under a pin.
    pub fn stand_in(&self, ray: &Ray, any: bool, c: &RayCone) -> Result<LodHit, u32> {
        let Some(mut lod) = self.lod_ray(c, true) else {
            return match self.traverse_with(ray, any, None, 0, None) {
                Traced::Done(hit) => Ok(LodHit { hit, approx: false }),
                Traced::Pending(p) => Err(p.tile()),
            };
        };
        let mut approx = false;
        loop {
            match self.traverse_with(ray, any, None, 0, Some(&lod)) {
                Traced::Done(hit) => return Ok(LodHit { hit, approx: approx || lod.missed.get() }),
                Traced::Pending(p) => {
                    // A tile inside the level taken is missing: again, that part one level
                    // coarser (the coarsest is pinned, so this ends).
                    let part = self.scene.parts()[self.tiles[p.tile() as usize].part as usize];
                    if part.lod_next == NO_PART || !lod.hold(part.lod_of, part.lod_level + 1) {
                        return Err(p.tile());
                    }
                    approx = true;
                }
            }
        }
    }

    /// Where a walk is about to enter a part from the top-level tree (`w.next` a link to the
    /// root of the full-detail part of tile `arr`): the level of detail `lod` chooses for it,
    /// the link redirected to that level's root. Returns the tile to enter (`arr` for any
    /// other crossing).
    pub(crate) fn lod_entry(&self, w: &mut Walk<'_>, arr: u32, ray: &Ray, lod: &LodRay) -> u32 {
        let Some(e) = w.next.as_mut() else { return arr };
        let Some(part) = self.tiles.get(arr as usize).map(|t| t.part) else { return arr };
        let Some(lv) = self.lod.get(part as usize) else { return arr };
        // A link to a part's root comes only from the top-level tree (whichever tile the walk
        // had open when it popped the entry).
        if lv.levels.len() < 2 || e.r != lv.levels[0].0 {
            return arr;
        }
        // The footprint where the ray enters the part's box (its slab entry).
        let mut t_enter = ray.t_min.max(0.0);
        for a in 0..3 {
            let inv = 1.0 / ray.dir[a];
            let (t0, t1) = ((lv.lo[a] - ray.org[a]) * inv, (lv.hi[a] - ray.org[a]) * inv);
            let near = t0.min(t1);
            if near > t_enter {
                t_enter = near;
            }
        }
        let allowed = lod.pixels * lod.cone.at(t_enter);
        // The coarsest level within the error allowed, but not finer than the floor.
        let want = lv.levels.iter().rposition(|l| l.2 <= allowed).unwrap_or(0);
        let want = want.max(lod.floor_of(part) as usize).min(lv.levels.len() - 1);
        let mut chosen = want;
        if let (Some(pg), true) = (self.pager, lod.stand_in) {
            // The first level from `want` whose root is resident (a miss requests it: a later
            // frame finds it); the coarsest always is.
            while chosen + 1 < lv.levels.len() && pg.acquire(lv.levels[chosen].1) != Access::Ready {
                lod.missed.set(true);
                chosen += 1;
            }
        }
        let (link, root_tile, _) = lv.levels[chosen];
        *e = Entry { r: link, ..*e };
        root_tile
    }
}
