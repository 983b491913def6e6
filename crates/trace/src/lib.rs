//! # megaray-trace: rays through a scene file
//!
//! [`Tracer`] walks the two-level tree of a [`Scene`] (mapped, or read in tile by tile by a
//! pager): the top-level tree over parts, then each part's 8-wide BVH, crossing from tile to
//! tile through links. Every tile is checked the first time it is entered (see
//! [`Scene::tile`]); a corrupt tile is skipped and reported through [`Scene::first_error`],
//! never read as garbage.
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

//!
//! ## Where things are
//!
//! | module | holds |
//! |---|---|
//! | `lib.rs` | the API types: [`Hit`], [`RayCaster`], [`Suspended`], [`Pending`], [`Traced`] |
//! | [`isa`] | the one choice of kernels: [`Isa`] (detected once), [`Kernels`], the kernel tables |
//! | `tracer.rs` | [`Tracer`]: set-up, stack entries, tiles, prefetch, nodes and blocks, hits |
//! | `driver.rs` | the queries, the driver of a ray's walk, the thread's scratch memory |
//! | `walk.rs` | the single-ray kernel's hot loop and its per-instruction-set builds |
//! | `boxes.rs` | the box test of a node's eight children ([`Node8`](megaray_scene::Node8)) |
//! | `tri.rs` | triangle blocks and the 4- and 8-wide watertight tests |
//! | `lod.rs` | the level of detail chosen per ray ([`RayCone`], [`LodHit`]) |
//! | `asm.rs`, `walk_avx2.s` | the hand-written AVX2 kernel for incoherent rays (x86-64 Linux) |
//! | [`packet`] | 16 coherent rays at once |
//! | [`jobs`] | work that suspends on missing tiles and resumes (ray reordering) |
//! | [`stats`] | traversal counters (the `stats` feature) |

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
mod asm;
mod boxes;
mod driver;
mod inst;
mod inst_bvh;
pub mod isa;
pub mod jobs;
mod lod;
pub mod packet;
pub mod stats;
mod tracer;
mod tri;
mod walk;

pub use isa::{Isa, Kernels};
pub use lod::{Cone, LodHit, RayCone};
pub use tracer::Tracer;

use megaray_base::{Ray, Vec3};
use megaray_scene::Scene;

use crate::tracer::Entry;
use crate::walk::Found;

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
    /// The triangle's corners (in world space: an instance's are moved there).
    pub tri: [[f32; 3]; 3],
    /// Where the hit's object was placed, for a hit through instances (`None` otherwise):
    /// what turns its object-space attributes into the world's.
    pub placed: Option<Placement>,
}

/// How an instanced hit's object was placed: the transform of its normals and the material
/// the instance gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// Object-space normals to world space (rows; the inverse transpose of the placement,
    /// not normalising).
    pub normal: [[f32; 3]; 3],
    /// A material index (into the scene's material table) overriding the triangle's, or
    /// `u32::MAX`.
    pub material: u32,
}

impl Placement {
    /// An object-space normal in world space (not normalised).
    pub fn normal_to_world(&self, n: Vec3) -> Vec3 {
        let m = &self.normal;
        Vec3::new(
            m[0][0] * n.x + m[0][1] * n.y + m[0][2] * n.z,
            m[1][0] * n.x + m[1][1] * n.y + m[1][2] * n.z,
            m[2][0] * n.x + m[2][1] * n.y + m[2][2] * n.z,
        )
    }

    /// The material override, if any.
    pub fn material(&self) -> Option<u32> {
        (self.material != u32::MAX).then_some(self.material)
    }
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
    /// [`RayCaster::intersect`] of a ray whose footprint is `cone`: a caster that traces
    /// levels of detail chooses by it ([`Tracer::with_lod_error`]). By default, full detail.
    fn intersect_cone(&mut self, ray: &Ray, cone: &RayCone) -> Result<Option<Hit>, Suspended> {
        let _ = cone;
        self.intersect(ray)
    }
    /// [`RayCaster::occluded`] of a ray whose footprint is `cone`.
    fn occluded_cone(&mut self, ray: &Ray, cone: &RayCone) -> Result<bool, Suspended> {
        let _ = cone;
        self.occluded(ray)
    }
    /// A box that every ray with a hit enters, if the caster knows one (the scene's, or its
    /// instances' as they stand): a ray that misses it misses everything, and a renderer may
    /// answer it without a query ([`megaray_base::Rays16::entering`]).
    fn bounds(&self) -> Option<megaray_base::Aabb> {
        None
    }
    /// Whether a stand-in answered some ray since the last call (the result made from those
    /// rays is approximate), and forgets it. A caster without stand-ins never does.
    fn take_approx(&mut self) -> bool {
        false
    }
    /// Where the job stands in its queries, for a later [`RayCaster::checkpoint`].
    fn mark(&mut self) -> usize {
        0
    }
    /// Records `memo`, the result of the work done since `mark` (a pixel of a job of
    /// several), in place of that work's queries: when a suspended job runs again,
    /// [`RayCaster::recall`] gives it back instead of the work being redone, so a job needs
    /// the tiles of one piece of work at a time, never those of all its pieces at once.
    fn checkpoint(&mut self, mark: usize, memo: Memo) {
        let _ = (mark, memo);
    }
    /// The memo recorded at this point of an earlier run of the job, if any.
    fn recall(&mut self) -> Option<Memo> {
        None
    }
}

/// A piece of a job's result recorded by [`RayCaster::checkpoint`]: five words whose meaning
/// is the job's (a pixel's colour bits, its ray count and whether it is approximate).
pub type Memo = [u32; 5];

/// A plain tracer answers every ray at once (a paged one waits for its tiles).
impl RayCaster for &Tracer<'_> {
    fn scene(&self) -> &Scene {
        self.scene
    }
    fn bounds(&self) -> Option<megaray_base::Aabb> {
        Some(self.bounds)
    }
    fn intersect(&mut self, ray: &Ray) -> Result<Option<Hit>, Suspended> {
        Ok(Tracer::intersect(self, ray))
    }
    fn occluded(&mut self, ray: &Ray) -> Result<bool, Suspended> {
        Ok(Tracer::occluded(self, ray))
    }
    fn intersect_cone(&mut self, ray: &Ray, cone: &RayCone) -> Result<Option<Hit>, Suspended> {
        Ok(self.trace_cone(ray, false, cone))
    }
    fn occluded_cone(&mut self, ray: &Ray, cone: &RayCone) -> Result<bool, Suspended> {
        Ok(self.trace_cone(ray, true, cone).is_some())
    }
}

/// A ray whose traversal stopped at a tile that is not resident: its stack and best hit so
/// far. Resume it with [`Tracer::resume`] once [`Pending::tile`] has arrived.
#[derive(Clone, Debug)]
pub struct Pending {
    stack: Vec<Entry>,
    best: Option<Found>,
    /// The [`Hit`] of `best`, made when the ray stopped (while its tile was resident: it
    /// may not be when the ray resumes).
    hit: Option<Hit>,
    any: bool,
    tile: u32,
    /// For a ray of the instance layer: the instances down to the object it stopped in
    /// (their indices), and its state in that object.
    inside: Option<Box<(Vec<u32>, Pending)>>,
}

impl Pending {
    /// A ray of the instance layer that stopped in the object at the end of `path`
    /// (`inner`), having found `hit` so far.
    pub(crate) fn inside(hit: Option<Hit>, any: bool, path: Vec<u32>, inner: Pending) -> Pending {
        let tile = inner.tile;
        Pending { stack: Vec::new(), best: None, hit, any, tile, inside: Some(Box::new((path, inner))) }
    }

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
    /// Stopped at an absent tile (now requested). Boxed: rare, and large enough that
    /// moving it inline cost every ray a copy.
    Pending(Box<Pending>),
}
