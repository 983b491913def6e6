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

use glam::Vec4;
use megaray_base::{Ray, Vec3, WatertightRay};
use megaray_scene::format::{Child, ChildRef, Node4};
use megaray_scene::{Scene, Tile};

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
    /// The triangle's number within its part (indexes the part's attributes).
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

/// Which node array a stack entry refers to.
const TOP: u32 = u32::MAX;
/// Capacity of the traversal stack kept on the machine stack.
const STACK: usize = 512;

/// Conservative widening of box exit distances so that boxes never cull a hit that the
/// watertight triangle test would find (Ize 2013: 1 + 2 gamma(3)).
const BOX_EPS: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

#[derive(Clone, Copy)]
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
        let fix = |d: f32| if d.abs() < 1e-20 { 1e-20f32.copysign(d) } else { d };
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
    fn test(&self, n: &Node4, t0: f32, t1: f32) -> (Vec4, u32) {
        let axis = |lo: &[f32; 4], hi: &[f32; 4], k: usize| {
            let (near, far) = if self.neg[k] { (hi, lo) } else { (lo, hi) };
            (
                (Vec4::from_array(*near) - self.org[k]) * self.inv[k],
                (Vec4::from_array(*far) - self.org[k]) * self.inv[k],
            )
        };
        let (nx, fx) = axis(&n.lo_x, &n.hi_x, 0);
        let (ny, fy) = axis(&n.lo_y, &n.hi_y, 1);
        let (nz, fz) = axis(&n.lo_z, &n.hi_z, 2);
        let near = nx.max(ny).max(nz).max(Vec4::splat(t0));
        let far = (fx.min(fy).min(fz) * BOX_EPS).min(Vec4::splat(t1));
        (near, near.cmple(far).bitmask())
    }
}

/// Traces rays through one scene. Cheap to create; share one across threads.
pub struct Tracer<'s> {
    scene: &'s Scene,
}

/// Traversal state kept between node visits: the tile currently open.
struct Cursor<'s> {
    arr: u32,
    nodes: &'s [Node4],
    tile: Option<Tile<'s>>,
    part: u32,
    first_tri: u32,
}

impl<'s> Tracer<'s> {
    pub fn new(scene: &'s Scene) -> Tracer<'s> {
        Tracer { scene }
    }

    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// Points `c` at node array `arr`; `false` when that tile is corrupt (skip the entry).
    #[inline]
    fn open(&self, c: &mut Cursor<'s>, arr: u32) -> bool {
        if c.arr == arr {
            return true;
        }
        if arr == TOP {
            c.nodes = self.scene.top_nodes();
            c.tile = None;
        } else {
            let Some(t) = self.scene.tile(arr) else { return false };
            let e = &self.scene.tiles()[arr as usize];
            c.nodes = t.nodes;
            c.tile = Some(t);
            c.part = e.part;
            c.first_tri = e.first_tri;
        }
        c.arr = arr;
        true
    }

    fn part_root(&self, p: u32) -> Entry {
        let e = &self.scene.parts()[p as usize];
        Entry { arr: e.root_tile, node: e.root_node, t: 0.0 }
    }

    /// The closest hit of `ray` in `[ray.t_min, ray.t_max)`.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.traverse(ray, false)
    }

    /// The closest hits of a packet of rays (coherent ones, such as 4x4 pixels), into `hits`
    /// (same length as `rays`). Exactly the results of [`Tracer::intersect`] on each ray.
    pub fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        for (r, h) in rays.iter().zip(hits.iter_mut()) {
            *h = self.intersect(r);
        }
    }

    /// Whether anything lies on `ray` in `[ray.t_min, ray.t_max)`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.traverse(ray, true).is_some()
    }

    fn traverse(&self, ray: &Ray, any: bool) -> Option<Hit> {
        let rb = RayBox::new(ray);
        let wt = WatertightRay::new(ray);
        let mut best: Option<Hit> = None;
        let mut t_best = ray.t_max;
        let mut stack = [Entry { arr: TOP, node: 0, t: 0.0 }; STACK];
        let mut sp = 1;
        // Entries beyond the fixed stack (only for pathologically deep trees; order does not
        // matter for correctness, only for speed).
        let mut spill: Vec<Entry> = Vec::new();
        let mut c = Cursor { arr: TOP, nodes: self.scene.top_nodes(), tile: None, part: 0, first_tri: 0 };
        loop {
            let e = if sp > 0 {
                sp -= 1;
                stack[sp]
            } else if let Some(e) = spill.pop() {
                e
            } else {
                break;
            };
            if e.t >= t_best {
                continue;
            }
            if !self.open(&mut c, e.arr) {
                continue;
            }
            let node = &c.nodes[e.node as usize];
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
                    for i in first..first + count {
                        let tri = &tile.tris[i as usize].v;
                        if let Some(h) = wt.intersect(tri, t_best) {
                            t_best = h.t;
                            best = Some(Hit { t: h.t, u: h.u, v: h.v, part: c.part, prim: c.first_tri + i, tri: *tri });
                            if any {
                                return best;
                            }
                        }
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
                if d >= t_best {
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
        best
    }
}
