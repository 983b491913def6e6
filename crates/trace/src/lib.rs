//! # megaray-trace: rays through a scene file
//!
//! [`Tracer`] walks the two-level tree of a memory-mapped [`Scene`]: the top-level tree over
//! parts, then each part's 4-wide BVH, crossing from tile to tile through links. Every tile is
//! checked the first time it is entered (see [`Scene::tile`]); a corrupt tile is skipped and
//! reported through [`Scene::first_error`], never read as garbage.
//!
//! - [`Tracer::intersect`]: the closest hit ([`Hit`]: distance, barycentrics, which triangle);
//! - [`Tracer::occluded`]: any hit, for shadow rays (stops at the first).
//!
//! ```no_run
//! use megaray_scene::Scene;
//! use megaray_trace::Tracer;
//! use megaray_base::{Ray, Vec3};
//! let scene = Scene::open("model.mray".as_ref()).unwrap();
//! let tracer = Tracer::new(&scene);
//! if let Some(hit) = tracer.intersect(&Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z)) {
//!     println!("hit part {} triangle {} at t = {}", hit.part, hit.prim, hit.t);
//! }
//! ```

pub mod jobs;
pub mod packet;
pub mod stats;

use glam::Vec4;
use megaray_base::{Ray, TriHit, Vec3, WatertightRay};
use megaray_page::{Access, Pager};
use megaray_scene::format::{Child, ChildRef, Node4, Tri4};
use megaray_scene::{PartEntry, Scene, Tile, TileEntry};

/// A closest hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the ray (in units of the direction's length).
    pub t: f32,
    /// Barycentric weight of corner 1.
    pub u: f32,
    /// Barycentric weight of corner 2.
    pub v: f32,
    /// The part the triangle belongs to.
    pub part: u32,
    /// The triangle's slot within its part (indexes the part's attributes).
    pub prim: u32,
    /// The triangle's corners.
    pub tri: [[f32; 3]; 3],
}

impl Hit {
    /// The unnormalised geometric normal (e1 x e2, following the triangle's winding).
    pub fn geometric_normal(&self) -> Vec3 {
        let a = Vec3::from(self.tri[0]);
        (Vec3::from(self.tri[1]) - a).cross(Vec3::from(self.tri[2]) - a)
    }
}

/// A ray could not be finished because scene data it needs is not resident yet (out-of-core
/// rendering with a memory budget: the tile was requested and will arrive later). Whoever
/// asked gives up on the work that needed the ray and retries it later. A [`Tracer`] over a
/// fully mapped scene never reports it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Suspended;

/// Rays on demand, as shaders see them: the closest hit and any hit of arbitrary rays, either
/// answered now or [`Suspended`]. Shaders propagate a suspension with `?`; they must be
/// deterministic (the same inputs fire the same rays) because suspended work is re-run.
pub trait RayCaster {
    /// The scene the rays are traced in (for its attributes and materials).
    fn scene(&self) -> &Scene;
    /// The closest hit of `ray` in `[ray.t_min, ray.t_max)`.
    fn intersect(&mut self, ray: &Ray) -> Result<Option<Hit>, Suspended>;
    /// Whether anything lies on `ray` in `[ray.t_min, ray.t_max)`.
    fn occluded(&mut self, ray: &Ray) -> Result<bool, Suspended>;
}

/// A plain tracer answers every ray at once.
impl RayCaster for &Tracer<'_> {
    fn scene(&self) -> &Scene {
        self.scene
    }
    fn intersect(&mut self, ray: &Ray) -> Result<Option<Hit>, Suspended> {
        Ok(Tracer::intersect(self, ray))
    }
    fn occluded(&mut self, ray: &Ray) -> Result<bool, Suspended> {
        Ok(Tracer::occluded(self, ray))
    }
}

/// Which node array a stack entry refers to.
const TOP: u32 = u32::MAX;
/// Capacity of the traversal stack kept on the machine stack.
const STACK: usize = 32;

/// Conservative widening of box exit distances so that boxes never cull a hit that the
/// watertight triangle test would find (Ize 2013: 1 + 2 gamma(3)).
const BOX_EPS: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

#[derive(Clone, Copy, Debug)]
struct Entry {
    arr: u32,
    node: u32,
    t: f32,
}

/// Precomputed per-ray values for box tests: the four slots of a [`Node4`] are tested at
/// once with 4-wide vectors (`glam::Vec4`, SSE on x86-64), near and far planes chosen once
/// per ray from the direction's signs.
struct RayBox {
    org: [Vec4; 3],
    inv: [Vec4; 3],
    neg: [bool; 3],
}

impl RayBox {
    fn new(r: &Ray) -> RayBox {
        // Direction components of (nearly) zero become +-1e-20: finite reciprocals, so that no
        // 0 * inf makes a NaN in the slab distances.
        let fix = |d: f32| d.abs().max(1e-20).copysign(d);
        let inv = [1.0 / fix(r.dir.x), 1.0 / fix(r.dir.y), 1.0 / fix(r.dir.z)];
        RayBox {
            org: [Vec4::splat(r.org.x), Vec4::splat(r.org.y), Vec4::splat(r.org.z)],
            inv: inv.map(Vec4::splat),
            neg: inv.map(|i| i < 0.0),
        }
    }

    /// Entry distances of the four slots and a bit mask of the slots the ray enters
    /// within `[t0, t1]`.
    #[inline(always)]
    fn test(&self, n: &Node4, t0: f32, t1: f32) -> ([f32; 4], u32) {
        // Near and far planes chosen by the direction's sign (the same for every node).
        let slab = |lo: &[f32; 4], hi: &[f32; 4], k: usize| {
            let (near, far) = if self.neg[k] { (hi, lo) } else { (lo, hi) };
            (
                (Vec4::from_array(*near) - self.org[k]) * self.inv[k],
                (Vec4::from_array(*far) - self.org[k]) * self.inv[k],
            )
        };
        let (nx, fx) = slab(&n.lo_x, &n.hi_x, 0);
        let (ny, fy) = slab(&n.lo_y, &n.hi_y, 1);
        let (nz, fz) = slab(&n.lo_z, &n.hi_z, 2);
        let near = nx.max(ny).max(nz).max(Vec4::splat(t0));
        // Both the box's exit and the current closest hit are widened: a box's entry distance
        // may round up past the distance of a hit inside it.
        let far = fx.min(fy).min(fz).min(Vec4::splat(t1)) * BOX_EPS;
        (near.to_array(), near.cmple(far).bitmask())
    }
}

/// Per-ray constants of the 4-wide watertight test (the lanes of a [`Tri4`] block at once).
/// Each lane computes exactly what [`WatertightRay::intersect`] computes, operation for
/// operation, so results are bit-identical to the scalar reference.
struct RayTri4 {
    wt: WatertightRay,
    o: [Vec4; 3],
    s: [Vec4; 3],
    t_min: Vec4,
}

impl RayTri4 {
    fn new(r: &Ray) -> RayTri4 {
        let wt = WatertightRay::new(r);
        let [kx, ky, kz] = wt.k;
        RayTri4 {
            o: [Vec4::splat(wt.org[kx]), Vec4::splat(wt.org[ky]), Vec4::splat(wt.org[kz])],
            s: wt.s.map(Vec4::splat),
            t_min: Vec4::splat(r.t_min),
            wt,
        }
    }

    /// The nearest hit among the lanes of `b` set in `lanes`, in `[t_min, t_max)`.
    #[inline(always)]
    fn test(&self, b: &Tri4, lanes: u32, t_max: f32) -> Option<(usize, TriHit)> {
        let [kx, ky, kz] = self.wt.k;
        let [ox, oy, oz] = self.o;
        let [sx, sy, sz] = self.s;
        let v = |c: usize, k: usize| Vec4::from_array(b.v[3 * c + k]);
        let az = v(0, kz) - oz;
        let bz = v(1, kz) - oz;
        let cz = v(2, kz) - oz;
        let ax = (v(0, kx) - ox) - sx * az;
        let ay = (v(0, ky) - oy) - sy * az;
        let bx = (v(1, kx) - ox) - sx * bz;
        let by = (v(1, ky) - oy) - sy * bz;
        let cx = (v(2, kx) - ox) - sx * cz;
        let cy = (v(2, ky) - oy) - sy * cz;
        let u = cx * by - cy * bx;
        let vv = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let zero =
            (u.cmpeq(Vec4::ZERO).bitmask() | vv.cmpeq(Vec4::ZERO).bitmask() | w.cmpeq(Vec4::ZERO).bitmask()) & lanes;
        if zero != 0 {
            // An edge or vertex exactly on the ray: the reference's double-precision path.
            return self.scalar(b, lanes, t_max);
        }
        let neg = u.cmplt(Vec4::ZERO).bitmask() | vv.cmplt(Vec4::ZERO).bitmask() | w.cmplt(Vec4::ZERO).bitmask();
        let pos = u.cmpgt(Vec4::ZERO).bitmask() | vv.cmpgt(Vec4::ZERO).bitmask() | w.cmpgt(Vec4::ZERO).bitmask();
        let det = u + vv + w;
        let t_scaled = u * (sz * az) + vv * (sz * bz) + w * (sz * cz);
        let inv_det = Vec4::ONE / det;
        let t = t_scaled * inv_det;
        let ok = lanes
            & !(neg & pos)
            & !det.cmpeq(Vec4::ZERO).bitmask()
            & t.cmpge(self.t_min).bitmask()
            & t.cmplt(Vec4::splat(t_max)).bitmask();
        if ok == 0 {
            return None;
        }
        let mut lane = ok.trailing_zeros() as usize;
        let mut rest = ok & (ok - 1);
        while rest != 0 {
            let l = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            if t[l] < t[lane] {
                lane = l;
            }
        }
        Some((lane, TriHit { t: t[lane], u: vv[lane] * inv_det[lane], v: w[lane] * inv_det[lane] }))
    }

    /// The reference test lane by lane.
    fn scalar(&self, b: &Tri4, lanes: u32, mut t_max: f32) -> Option<(usize, TriHit)> {
        let mut best = None;
        for lane in 0..4 {
            if lanes & (1 << lane) != 0 {
                if let Some(h) = self.wt.intersect(&b.tri(lane), t_max) {
                    t_max = h.t;
                    best = Some((lane, h));
                }
            }
        }
        best
    }
}

/// Traces rays through one scene. Cheap to create; share one across threads.
///
/// Two modes: [`Tracer::new`] reads the whole mapped file (the operating system pages on
/// demand, stalling the thread on a miss); [`Tracer::paged`] reads only tiles that a
/// [`Pager`] has made resident, and a ray that needs an absent tile comes back
/// [`Traced::Pending`] (its traversal state saved) from [`Tracer::try_intersect`] and
/// [`Tracer::try_occluded`], to be resumed with [`Tracer::resume`] once the tile arrived.
/// A paged tracer must be used under a [`megaray_page::Pin`] (see [`jobs`], which pins and
/// reschedules for you); its blocking [`Tracer::intersect`] and [`Tracer::occluded`] pin
/// themselves and wait for missing tiles.
pub struct Tracer<'s> {
    scene: &'s Scene,
    pager: Option<&'s Pager>,
    // The scene's tables, looked up once rather than at every tile crossing.
    top: &'s [Node4],
    parts: &'s [PartEntry],
    tiles: &'s [TileEntry],
}

/// A ray whose traversal stopped at a tile that is not resident: its stack and best hit so
/// far. Resume it with [`Tracer::resume`] once [`Pending::tile`] has arrived.
#[derive(Clone, Debug)]
pub struct Pending {
    stack: Vec<Entry>,
    best: Option<Hit>,
    any: bool,
    tile: u32,
}

impl Pending {
    /// The tile the ray waits for.
    pub fn tile(&self) -> u32 {
        self.tile
    }
}

/// The outcome of a traversal that may meet absent tiles.
#[derive(Clone, Debug)]
pub enum Traced {
    /// Finished: the closest hit (or, for an any-hit query, some hit), if any.
    Done(Option<Hit>),
    /// Stopped at an absent tile (now requested).
    Pending(Pending),
}

/// What opening a tile gave.
#[derive(PartialEq)]
enum Open {
    Ready,
    Skip,
    Missing,
}

/// Traversal state kept between node visits: the tile currently open.
struct Cursor<'s> {
    arr: u32,
    nodes: &'s [Node4],
    tile: Option<Tile<'s>>,
    part: u32,
    first_slot: u32,
}

impl<'s> Tracer<'s> {
    pub fn new(scene: &'s Scene) -> Tracer<'s> {
        Tracer { scene, pager: None, top: scene.top_nodes(), parts: scene.parts(), tiles: scene.tiles() }
    }

    /// A tracer that reads only the tiles `pager` has made resident.
    pub fn paged(pager: &'s Pager) -> Tracer<'s> {
        let scene: &'s Scene = pager.scene();
        Tracer { pager: Some(pager), ..Tracer::new(scene) }
    }

    /// The pager, for a paged tracer.
    pub fn pager(&self) -> Option<&'s Pager> {
        self.pager
    }

    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// Points `c` at node array `arr`: [`Open::Skip`] when that tile is corrupt (skip the
    /// entry), [`Open::Missing`] when a paged tile is not resident (it has been requested).
    #[inline]
    fn open(&self, c: &mut Cursor<'s>, arr: u32) -> Open {
        if c.arr == arr {
            return Open::Ready;
        }
        if arr == TOP {
            c.nodes = self.top;
            c.tile = None;
        } else {
            let t = match self.pager {
                None => match self.scene.tile(arr) {
                    Some(t) => t,
                    None => return Open::Skip,
                },
                Some(p) => match p.acquire(arr) {
                    Access::Ready => self.scene.tile_view(arr),
                    Access::Corrupt => return Open::Skip,
                    Access::Missing => return Open::Missing,
                },
            };
            stats::count(|s| s.tiles_entered += 1);
            let e = &self.tiles[arr as usize];
            c.nodes = t.nodes;
            c.tile = Some(t);
            c.part = e.part;
            c.first_slot = e.first_slot;
        }
        c.arr = arr;
        Open::Ready
    }

    fn part_root(&self, p: u32) -> Entry {
        let e = &self.parts[p as usize];
        Entry { arr: e.root_tile, node: e.root_node, t: 0.0 }
    }

    /// The closest hit of `ray` in `[ray.t_min, ray.t_max)`. On a paged tracer this waits
    /// for missing tiles (use [`Tracer::try_intersect`] not to).
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.blocking(ray, false)
    }

    /// Whether anything lies on `ray` in `[ray.t_min, ray.t_max)`. On a paged tracer this
    /// waits for missing tiles (use [`Tracer::try_occluded`] not to).
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.blocking(ray, true).is_some()
    }

    /// The closest hit of `ray`, or [`Traced::Pending`] when it needs an absent tile.
    /// Paged tracers: call under a pin ([`Pager::pin`]).
    pub fn try_intersect(&self, ray: &Ray) -> Traced {
        self.traverse(ray, false, None)
    }

    /// Any hit of `ray` (`Done(Some(_))` means occluded), or [`Traced::Pending`].
    /// Paged tracers: call under a pin ([`Pager::pin`]).
    pub fn try_occluded(&self, ray: &Ray) -> Traced {
        self.traverse(ray, true, None)
    }

    /// Continues a pending traversal of the same `ray` (same query kind) where it stopped.
    pub fn resume(&self, ray: &Ray, pending: Pending) -> Traced {
        let any = pending.any;
        self.traverse(ray, any, Some(pending))
    }

    /// Traces to the end, waiting for missing tiles (pinned only while traversing).
    #[inline]
    fn blocking(&self, ray: &Ray, any: bool) -> Option<Hit> {
        let Some(pager) = self.pager else {
            return match self.traverse(ray, any, None) {
                Traced::Done(h) => h,
                Traced::Pending(_) => unreachable!("an unpaged tracer never suspends"),
            };
        };
        let mut from = None;
        loop {
            let seen = pager.arrivals();
            let r = {
                let _pin = pager.pin();
                self.traverse(ray, any, from.take())
            };
            match r {
                Traced::Done(h) => return h,
                Traced::Pending(p) => {
                    let mut seen = seen;
                    while !pager.settled(p.tile) {
                        seen = pager.wait_arrival(seen, std::time::Duration::from_millis(20));
                    }
                    from = Some(p);
                }
            }
        }
    }

    /// The closest hits of a packet of rays (coherent ones, such as 4x4 pixels), into `hits`
    /// (same length as `rays`), traced 16 at a time by the packet kernel ([`packet`]) on the
    /// best instruction set of this machine. Exactly the distances of [`Tracer::intersect`]
    /// on each ray.
    pub fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.intersect_packet_with(rays, hits, packet::Isa::detect());
    }

    /// [`Tracer::intersect_packet`] on a chosen instruction set (one of
    /// [`packet::Isa::available`]); for tests and benchmarks.
    pub fn intersect_packet_with(&self, rays: &[Ray], hits: &mut [Option<Hit>], isa: packet::Isa) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        if self.pager.is_some() {
            // Packets do not suspend: a paged tracer traces them ray by ray.
            for (r, h) in rays.iter().zip(hits.iter_mut()) {
                *h = self.intersect(r);
            }
            return;
        }
        assert!(packet::Isa::available().contains(&isa), "{isa:?} is not available on this machine");
        for (r, h) in rays.chunks(packet::WIDTH).zip(hits.chunks_mut(packet::WIDTH)) {
            packet::intersect16(self, r, h, isa);
        }
    }

    fn traverse(&self, ray: &Ray, any: bool, from: Option<Pending>) -> Traced {
        stats::count(|s| s.rays += 1);
        let rb = RayBox::new(ray);
        // The triangle test's constants, made when the ray first reaches a leaf (most rays
        // of a wide view never do).
        let mut rt: Option<RayTri4> = None;
        let mut best: Option<Hit> = None;
        let mut t_best = ray.t_max;
        let mut stack = [Entry { arr: TOP, node: 0, t: 0.0 }; STACK];
        let mut sp = 1;
        // Entries beyond the fixed stack (only for pathologically deep trees; order does not
        // matter for correctness, only for speed).
        let mut spill: Vec<Entry> = Vec::new();
        if let Some(p) = from {
            best = p.best;
            t_best = best.map_or(ray.t_max, |h| h.t);
            let k = p.stack.len().min(STACK);
            let split = p.stack.len() - k;
            stack[..k].copy_from_slice(&p.stack[split..]);
            sp = k;
            spill.extend_from_slice(&p.stack[..split]);
        }
        let mut c = Cursor { arr: TOP, nodes: self.top, tile: None, part: 0, first_slot: 0 };
        loop {
            let e = if sp > 0 {
                sp -= 1;
                stack[sp]
            } else if let Some(e) = spill.pop() {
                e
            } else {
                break;
            };
            if e.t > t_best * BOX_EPS {
                continue;
            }
            match self.open(&mut c, e.arr) {
                Open::Ready => {}
                Open::Skip => continue,
                Open::Missing => {
                    let mut stack_out = spill;
                    stack_out.extend_from_slice(&stack[..sp]);
                    stack_out.push(e);
                    return Traced::Pending(Pending { stack: stack_out, best, any, tile: e.arr });
                }
            }
            let node = &c.nodes[e.node as usize];
            stats::count(|s| s.nodes += 1);
            let (dist, mut mask) = rb.test(node, ray.t_min, t_best);
            // Children hit, sorted far to near (pushed in that order, the nearest pops first).
            let mut hits = [(0f32, 0u64); 4];
            let mut nh = 0;
            while mask != 0 {
                let k = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let child = node.child[k];
                if let Child::Leaf { first, count } = ChildRef(child).decode() {
                    let tile = c.tile.expect("leaves live in tiles");
                    let rt = rt.get_or_insert_with(|| RayTri4::new(ray));
                    let mut left = count;
                    let mut blk = first;
                    while left > 0 {
                        let lanes = if left >= 4 { 0b1111 } else { (1u32 << left) - 1 };
                        let b = &tile.blocks[blk as usize];
                        stats::count(|s| s.blocks += 1);
                        if let Some((lane, h)) = rt.test(b, lanes, t_best) {
                            t_best = h.t;
                            let prim = c.first_slot + 4 * blk + lane as u32;
                            best = Some(Hit { t: h.t, u: h.u, v: h.v, part: c.part, prim, tri: b.tri(lane) });
                            if any {
                                return Traced::Done(best);
                            }
                        }
                        left = left.saturating_sub(4);
                        blk += 1;
                    }
                    continue;
                }
                let d = dist[k];
                let mut j = nh;
                while j > 0 && hits[j - 1].0 < d {
                    hits[j] = hits[j - 1];
                    j -= 1;
                }
                hits[j] = (d, child);
                nh += 1;
            }
            for &(d, child) in &hits[..nh] {
                if d > t_best * BOX_EPS {
                    continue;
                }
                let entry = match ChildRef(child).decode() {
                    Child::Inner(n) => Entry { arr: e.arr, node: n, t: d },
                    Child::Link { tile, node } => Entry { arr: tile, node, t: d },
                    Child::Part(p) => Entry { t: d, ..self.part_root(p) },
                    Child::Empty | Child::Leaf { .. } => continue,
                };
                if sp < STACK {
                    stack[sp] = entry;
                    sp += 1;
                } else {
                    spill.push(entry);
                }
            }
        }
        Traced::Done(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Rng(u64);
    impl Rng {
        fn f(&mut self) -> f32 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (self.0 >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        }
        fn v(&mut self) -> Vec3 {
            Vec3::new(self.f(), self.f(), self.f())
        }
    }

    /// The 4-wide triangle test gives exactly the scalar reference's hits, on random rays and
    /// on rays aimed exactly at vertices and edge midpoints.
    #[test]
    fn block_test_equals_scalar_reference() {
        let mut rng = Rng(3);
        let mut checked = 0;
        for _ in 0..2000 {
            let mut b = Tri4 { v: [[0.0; 4]; 9] };
            let tris: Vec<[[f32; 3]; 3]> = (0..4).map(|_| [rng.v().into(), rng.v().into(), rng.v().into()]).collect();
            for (l, t) in tris.iter().enumerate() {
                b.set(l, t);
            }
            let org = rng.v() * 3.0;
            let mut targets = vec![rng.v() * 0.5];
            for t in &tris {
                let [a, bb, c] = t.map(Vec3::from);
                targets.extend([a, bb, c, (a + bb) * 0.5, (bb + c) * 0.5, (a + c) * 0.5]);
            }
            for target in targets {
                let ray = Ray::new(org, target - org);
                let rt = RayTri4::new(&ray);
                for lanes in [0b1111u32, 0b0111, 0b0001] {
                    let got = rt.test(&b, lanes, f32::INFINITY);
                    let want = rt.scalar(&b, lanes, f32::INFINITY);
                    assert_eq!(got.map(|g| g.1), want.map(|w| w.1), "ray {ray:?} lanes {lanes:b}");
                    // And the scalar lane test is the base reference itself.
                    let mut best: Option<TriHit> = None;
                    for (l, t) in tris.iter().enumerate() {
                        if lanes & (1 << l) != 0 {
                            let t_max = best.map_or(f32::INFINITY, |h| h.t);
                            if let Some(h) = megaray_base::intersect_triangle(&ray, t.map(Vec3::from), t_max) {
                                best = Some(h);
                            }
                        }
                    }
                    assert_eq!(want.map(|w| w.1), best);
                    checked += 1;
                }
            }
        }
        assert!(checked > 10_000);
    }
}
