//! # megaray-trace: rays through a scene file
//!
//! [`Tracer`] walks the two-level tree of a memory-mapped [`Scene`]: the top-level tree over
//! parts, then each part's 8-wide BVH, crossing from tile to tile through links. Every tile is
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

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
mod asm;
pub mod jobs;
pub mod packet;
pub mod stats;

use glam::{Vec3A, Vec3Swizzles, Vec4};
use megaray_base::{t_start, Ray, Rays16, TriHit, Vec3, WatertightRay};
use megaray_page::{Access, Pager};
use megaray_scene::format::{ChildRef, Node8, Tri4, NODE_BYTES, NODE_WIDTH};
use megaray_scene::{CheckedTiles, Scene, TileEntry};
use std::cell::RefCell;

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
/// Capacity of the single-ray kernel's traversal stack on the machine stack ([`Walk::fixed`]);
/// deeper stacks spill to the heap.
const STACK: usize = 64;

/// Conservative widening of box exit distances so that boxes never cull a hit that the
/// watertight triangle test would find (Ize 2013: 1 + 2 gamma(3)).
const BOX_EPS: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// The widening of the single-ray kernel's box exits, folded into the reciprocals of its far
/// planes ([`RayBox::ninv_far`]) and into the closest hit it compares them with, so that a
/// node's test has no multiply after its reductions (the exit's chain is then as long as the
/// entry's). A far distance `(plane - o) * (inv * FAR_EPS)` takes four roundings (the
/// difference, the reciprocal, its widening, the product: within a factor `1 - gamma(4)` of
/// `FAR_EPS` times the exact one), an entry distance three (at most `1 + gamma(3)` over); a
/// box is kept whenever `FAR_EPS >= (1 + gamma(3)) / (1 - gamma(4))`, about `1 + 7u`
/// (`u = 2^-24`). This is `1 + 16u`, above [`BOX_EPS`] (`1 + 6u`), which it replaces for
/// the closest hit as well.
const FAR_EPS: f32 = 1.0 + 8.0 * f32::EPSILON;
const _: () = assert!(FAR_EPS > BOX_EPS);

/// A traversal stack entry: something to visit, and the entry distance of its box. Aligned
/// to its size, so that no entry of the stack straddles two cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Entry {
    /// A [`ChildRef`]: an inner node or a leaf of node array `arr`, a link, or a part.
    r: u64,
    /// The tile `r` lies in ([`TOP`] for the top-level tree): the one the entry was pushed
    /// from.
    arr: u32,
    /// Entry distance of its box along the ray.
    t: f32,
}

const _: () = assert!(std::mem::size_of::<Entry>() == 16);

impl Entry {
    /// All zero bits: what unused stack slots hold (cheapest to initialise).
    const ZERO: Entry = Entry { r: 0, arr: 0, t: 0.0 };
}

/// What a popped [`Entry`] turned out to be, its tile opened.
enum Step<'a> {
    /// An inner node to test, in node array `arr`.
    Node(&'a Node8, u32),
    /// A leaf: `count` triangles from the block at `unit` (`offset / 16`) of the open tile.
    Leaf { unit: u64, count: u32 },
    /// Nothing to visit (an empty slot, a corrupt tile).
    Skip,
    /// Its tile is not resident (it has been requested).
    Missing(u32),
}

/// The smallest magnitude of a direction component the box test takes as it is: smaller
/// ones (and zeros) become +-`TINY`, so that their reciprocals stay finite ([`RayBox::new`]).
const TINY: f32 = 1e-20;

/// Lanes of a node's box test.
const W: usize = NODE_WIDTH;

/// Precomputed per-ray values for box tests: the eight slots of a [`Node8`] are tested at
/// once, as one 8-wide AVX pass ([`RayBox::test_avx2`]) or two 4-wide SSE halves
/// ([`RayBox::test_sse`], the baseline and reference). The near and far planes of each axis are
/// chosen once per ray from the direction's signs, as byte offsets of the node's six plane
/// rows (`lo_x, hi_x, lo_y, hi_y, lo_z, hi_z`, 32 bytes each), so the test has no branches.
struct RayBox {
    org: [f32; 3],
    inv: [f32; 3],
    /// `-inv`: the box tests' distances are `(o - plane) * -inv` ([`RayBox::test_avx2`]).
    /// Negated once per ray, so that the kernel broadcasts them from memory as they are.
    ninv: [f32; 3],
    /// `-inv * FAR_EPS`: the reciprocals the far planes are scaled by ([`FAR_EPS`]).
    ninv_far: [f32; 3],
    /// Byte offsets in a [`Node8`] of the rows ([`Node8::planes`]) of the near planes of x, y
    /// and z, then of the far planes: `32 * row`, the row of a far plane being the other one
    /// of its pair. Always one of 0, 32, .., 160 (the AVX test reads through them unchecked).
    rows: &'static [usize; 6],
}

/// [`RayBox::rows`] of each octant, so that a new ray looks its rows up rather than making
/// them (and its walk reads them from here, not from copies on the machine stack).
const ROWS: [[usize; 6]; 8] = {
    let mut t = [[0; 6]; 8];
    let mut oct = 0;
    while oct < 8 {
        t[oct] = RayBox::rows(oct);
        oct += 1;
    }
    t
};

impl RayBox {
    #[inline(always)]
    fn new(r: &Ray) -> RayBox {
        // Direction components of (nearly) zero become +-1e-20: finite reciprocals, so that no
        // 0 * inf makes a NaN in the slab distances. One vector division (`divps` rounds each
        // lane as `divss` would).
        let d = Vec3A::from(r.dir);
        let fixed = d.abs().max(Vec3A::splat(TINY)).copysign(d);
        let inv = Vec3A::ONE / fixed;
        // (Negation is exact: `-(inv * FAR_EPS)` is `-inv * FAR_EPS`, bit for bit.)
        let ninv = -inv;
        RayBox {
            org: r.org.into(),
            inv: inv.to_array(),
            ninv: ninv.to_array(),
            ninv_far: (ninv * FAR_EPS).to_array(),
            rows: &ROWS[d.is_negative_bitmask() as usize & 7],
        }
    }

    /// The ray's octant: bit `k` set when the direction's component `k` is negative (its
    /// sign bit set: `-0.0` is negative, as its reciprocal in [`RayBox::new`] is). One
    /// `movmskps` of the direction's sign bits.
    #[inline(always)]
    fn octant(r: &Ray) -> usize {
        Vec3A::from(r.dir).is_negative_bitmask() as usize & 7
    }

    /// [`RayBox::rows`] of rays in octant `oct`: the near plane of an axis is its high one
    /// when the direction is negative along it.
    #[inline(always)]
    const fn rows(oct: usize) -> [usize; 6] {
        let near = [oct & 1, 2 + ((oct >> 1) & 1), 4 + ((oct >> 2) & 1)];
        [32 * near[0], 32 * near[1], 32 * near[2], 32 * (near[0] ^ 1), 32 * (near[1] ^ 1), 32 * (near[2] ^ 1)]
    }

    /// Whether the ray's origin lies in box `b` (then it enters the box, if at all, at once).
    #[inline(always)]
    fn starts_inside(&self, b: &megaray_base::Aabb) -> bool {
        let o = Vec3A::from_array(self.org);
        (o.cmpge(Vec3A::from_array(b.min)) & o.cmple(Vec3A::from_array(b.max))).all()
    }

    /// Whether the ray enters box `b` within `[t0, t1]`: one box, its three slabs at once,
    /// with the same slab products and widening as the slot tests (and so never stricter than
    /// them; no NaN arises, so `min` and `max` pick the near and far planes alike).
    #[inline(always)]
    fn enters(&self, b: &megaray_base::Aabb, t0: f32, t1: f32) -> bool {
        let (o, inv) = (Vec3A::from_array(self.org), Vec3A::from_array(self.inv));
        let lo = (Vec3A::from_array(b.min) - o) * inv;
        let hi = (Vec3A::from_array(b.max) - o) * inv;
        // Reduced with `fmin`/`fmax` (one `minss`/`maxss` each: no NaN to care for).
        let (n, f) = (lo.min(hi), lo.max(hi));
        let tn = fmax(fmax(n.x, n.y), fmax(n.z, t0));
        let tf = fmin(fmin(f.x, f.y), fmin(f.z, t1));
        tn <= tf * BOX_EPS
    }

    /// The triangle test's [`Splats`] (origin and `t_min` in four lanes) as the box test
    /// makes its own: with `AVX`, the low halves of the 8-wide splats of
    /// [`RayBox::test_avx2`], the same values, so that the compiler keeps one register each.
    #[inline(always)]
    fn splats<const AVX: bool>(&self, t_min: f32) -> Splats {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `RayBox::test`: only instantiated inside `walk_avx2`.
            return unsafe { self.splats_avx2(t_min) };
        }
        Splats { o: self.org.map(Vec4::splat), t_min: Vec4::splat(t_min) }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn splats_avx2(&self, t_min: f32) -> Splats {
        use std::arch::x86_64::*;
        let low = |x: f32| Vec4::from(_mm256_castps256_ps128(_mm256_set1_ps(x)));
        Splats { o: self.org.map(low), t_min: low(t_min) }
    }

    /// Entry distances of the eight slots and a bit mask of the slots the ray enters
    /// within `[t0, t1]`, `t1` widened by the caller (the closest hit times [`FAR_EPS`]) as
    /// the exits are here; with `AVX`, by [`RayBox::test_avx2`] (which the caller must only
    /// ask for in code compiled for AVX2).
    ///
    /// `t0` must be `+0.0` or above ([`t_start`]). The AVX test then reduces and compares
    /// the distances' bits as signed integers, as Embree does: one cycle each for `vpmaxsd`,
    /// `vpminsd` and `vpcmpgtd` where their float forms take four, on the traversal's
    /// critical path (measured +10-15% rays per second, stanford-bunny@close, all three
    /// kinds). Integer order is float order on floats whose sign bit is clear; any with it
    /// set is below them all, and so never the entry (`t0` is above it) and always the exit
    /// if present, an exit that fails the comparison with every entry. So it gives the float
    /// test's result but for one case: an exit of `-0.0` (an origin exactly on a far plane,
    /// leaving it in the direction of its axis) misses where the float test would let an
    /// entry of `+0.0` through; only a hit at exactly 0 can lie there ([`Ray::t_min`] says
    /// so). The SSE test (the reference) does the same, by testing the exits' sign bits.
    #[inline(always)]
    fn test<const AVX: bool>(&self, n: &Node8, t0: f32, t1: f32) -> (Near, u32) {
        debug_assert!(t0.is_sign_positive(), "box tests start at +0 or later, not {t0}");
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` box tests are only instantiated inside `walk_avx2`, which
            // runs only on CPUs with AVX2 and FMA (`Tracer::traverse`).
            return unsafe { self.test_avx2(n, t0, t1) };
        }
        self.test_sse(n, t0, t1)
    }

    /// The box test as 8-wide AVX operations. Each slab distance is `(o - plane) * -inv`,
    /// as in [`RayBox::test_sse`] (bit for bit, the sign of a zero included: it decides an
    /// exit of zero); written this way the plane rows are memory operands.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn test_avx2(&self, n: &Node8, t0: f32, t1: f32) -> (Near, u32) {
        use std::arch::x86_64::*;
        let base = (n as *const Node8).cast::<u8>();
        // SAFETY: every offset in `rows` is that of one of the node's rows of eight f32s (set
        // only by `RayBox::new`).
        let ld = |k: usize, far: usize| unsafe { _mm256_loadu_ps(base.add(self.rows[3 * far + k]).cast::<f32>()) };
        let o = self.org.map(|x| _mm256_set1_ps(x));
        let ninv = [self.ninv.map(|x| _mm256_set1_ps(x)), self.ninv_far.map(|x| _mm256_set1_ps(x))];
        let q =
            |k: usize, far: usize| _mm256_castps_si256(_mm256_mul_ps(_mm256_sub_ps(o[k], ld(k, far)), ninv[far][k]));
        let splat = |t: f32| _mm256_castps_si256(_mm256_set1_ps(t));
        // Reduced as trees of two levels, not chains of three: a node's test is on the
        // traversal's critical path. And on the distances' bits as signed integers
        // ([`RayBox::test`]: one cycle each where a float `max`, `min` or comparison takes
        // four).
        let tn = _mm256_max_epi32(_mm256_max_epi32(q(0, 0), q(1, 0)), _mm256_max_epi32(q(2, 0), splat(t0)));
        // Exits come widened ([`FAR_EPS`]): no multiply after the reduction.
        let tf = _mm256_min_epi32(_mm256_min_epi32(q(0, 1), q(1, 1)), _mm256_min_epi32(q(2, 1), splat(t1)));
        let miss = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(tn, tf))) as u32;
        let mut near = Near([0.0; W]);
        // SAFETY: `near` has room for eight f32s, aligned to 32 bytes.
        unsafe { _mm256_store_si256(near.0.as_mut_ptr().cast(), tn) };
        (near, !miss & 0xff)
    }

    /// The box test as two 4-wide SSE halves (the baseline of x86-64, and the reference).
    #[inline(always)]
    fn test_sse(&self, n: &Node8, t0: f32, t1: f32) -> (Near, u32) {
        let planes = n.planes();
        // `& 7`: in range by construction, and the compiler sees it.
        let row = |k: usize, far: usize| &planes[(self.rows[3 * far + k] / 32) & 7];
        let (nx, ny, nz) = (row(0, 0), row(1, 0), row(2, 0));
        let (fx, fy, fz) = (row(0, 1), row(1, 1), row(2, 1));
        let o = self.org.map(Vec4::splat);
        let ninv = [self.ninv.map(Vec4::splat), self.ninv_far.map(Vec4::splat)];
        let (t0, t1) = (Vec4::splat(t0), Vec4::splat(t1));
        // Slots 0..4, then 4..8: one 4-wide half at a time.
        let half = |h: usize| {
            // `(o - plane) * -inv`: `(plane - o) * inv` but for the sign of a zero, which
            // decides an exit of zero ([`RayBox::test`]; the AVX test's form).
            let q = |r: &[f32; W], k: usize, far: usize| (o[k] - Vec4::from_slice(&r[4 * h..4 * h + 4])) * ninv[far][k];
            let tn = q(nx, 0, 0).max(q(ny, 1, 0)).max(q(nz, 2, 0).max(t0));
            // Both the box's exit and the current closest hit are widened ([`FAR_EPS`]: the
            // exits by their reciprocals, the hit by the caller): a box's entry distance
            // may round up past the distance of a hit inside it.
            let (ex, ey, ez) = (q(fx, 0, 1), q(fy, 1, 1), q(fz, 2, 1));
            let tf = ex.min(ey).min(ez.min(t1));
            // An exit with its sign bit set misses, `-0.0` too (as on AVX, [`RayBox::test`]).
            let behind = ex.is_negative_bitmask() | ey.is_negative_bitmask() | ez.is_negative_bitmask();
            (tn, tn.cmple(tf).bitmask() & !behind & !t1.is_negative_bitmask())
        };
        let (n0, m0) = half(0);
        let (n1, m1) = half(1);
        let mut near = Near([0.0; W]);
        near.0[..4].copy_from_slice(&n0.to_array());
        near.0[4..].copy_from_slice(&n1.to_array());
        (near, m0 | (m1 << 4))
    }
}

/// The entry distances of a node's eight slots ([`RayBox::test`]), aligned to their size, so
/// that the box test's one 32-byte store of them never straddles two cache lines.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct Near([f32; W]);

/// `min` as `minps` computes it (the second operand when either is NaN), so that loops of it
/// vectorize.
#[inline(always)]
fn fmin(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// `max` as `maxps` computes it.
#[inline(always)]
fn fmax(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// A [`Tri4`](megaray_scene::format::Tri4) block as the tracer reads it (its `v`), nine
/// 16-byte units of the node pool from the block's `offset / 16` ([`Tracer::block_at`]).
type Block = [[f32; 4]; 9];

/// The corners of the triangle in `lane` of a block (as `Tri4::tri`).
#[inline]
fn corners(v: &Block, lane: usize) -> [[f32; 3]; 3] {
    [[v[0][lane], v[1][lane], v[2][lane]], [v[3][lane], v[4][lane], v[5][lane]], [v[6][lane], v[7][lane], v[8][lane]]]
}

/// The row of axis `k` of corner `c` of block `b` (the four lanes' coordinate `k` of their
/// corner `c`), given `kb = 16 * k`, the row's byte offset within its corner: so that a
/// row read by the ray's axes is one load at `b + kb + 48 * c` (the ray's `kb` in a
/// register, the corner's offset a constant), with no index arithmetic per block or per
/// ray. No bounds check.
///
/// # Safety
/// `c` must be below 3 and `kb` one of 0, 16, 32 (then the row is one of the block's nine).
#[inline(always)]
unsafe fn row(b: &Block, c: usize, kb: usize) -> [f32; 4] {
    debug_assert!(c < 3 && kb < 48 && kb.is_multiple_of(16));
    // SAFETY: 48 * c + kb <= 128 (the caller's promise): the start of one of the nine
    // 16-byte rows of `b`, aligned as `b` is.
    unsafe { b.as_ptr().cast::<u8>().add(48 * c + kb).cast::<[f32; 4]>().read() }
}

/// A block that [`RayTri4::try_test`] leaves to the double-precision reference.
#[derive(Clone, Copy, Debug)]
struct Exact;

/// Per-ray constants of the 4-wide watertight test (the lanes of a [`Block`] at once).
/// Each lane computes what [`WatertightRay::intersect`] computes, operation for operation,
/// but for one thing: the reference swaps its `x` and `y` axes when the ray runs backward
/// along its dominant axis (`kz`), which negates every edge function, the determinant and
/// the scaled distance exactly (IEEE rounding is symmetric), and so changes no distance or
/// barycentric. Results are bit-identical to the scalar reference.
struct RayTri4 {
    /// The ray, for the scalar reference ([`RayTri4::scalar`]).
    ray: Ray,
    /// The dominant axis: the kernel's rows are `kx = kz + 1`, `ky = kz + 2` (mod 3).
    kz: usize,
    /// `16 * [kx, ky, kz]`: the byte offsets of their rows in a corner of a block ([`row`]),
    /// for the test that reads its rows by the ray's axes ([`RayTri4::try_test_dyn`]).
    kb: [usize; 3],
    /// The shear: `d[kx] / d[kz]`, `d[ky] / d[kz]`, `1 / d[kz]`.
    s: [Vec4; 3],
    /// The origin's `kx`, `ky`, `kz` components, for [`RayTri4::try_test_dyn`].
    ok: [Vec4; 3],
    /// The ray's own [`Splats`], for [`RayTri4::test`] (the single-ray kernel shares its
    /// box test's instead).
    own: Splats,
}

/// `[kx, ky, kz]` of each dominant axis `kz`: `kx = kz + 1`, `ky = kz + 2` (mod 3).
const AXES: [[usize; 3]; 3] = [[1, 2, 0], [2, 0, 1], [0, 1, 2]];

/// [`AXES`] as byte offsets of rows within a corner of a block ([`row`]).
const AXES_BYTES: [[usize; 3]; 3] = [[16, 32, 0], [32, 0, 16], [0, 16, 32]];
const _: () = {
    let mut kz = 0;
    while kz < 3 {
        let mut j = 0;
        while j < 3 {
            assert!(AXES_BYTES[kz][j] == 16 * AXES[kz][j]);
            j += 1;
        }
        kz += 1;
    }
};

/// The dominant axis ([`RayTri4::dominant`]) for each outcome of its three comparisons:
/// bit 0 `|x| > |y|`, bit 1 `|x| > |z|`, bit 2 `|y| > |z|`. x when above y and z, else y
/// when above z, else z.
const DOMINANT: [u8; 8] = {
    let mut t = [0; 8];
    let mut m = 0;
    while m < 8 {
        let (xy, xz, yz) = (m & 1 != 0, m & 2 != 0, m & 4 != 0);
        t[m] = if xy && xz {
            0
        } else if !xy && yz {
            1
        } else {
            2
        };
        m += 1;
    }
    t
};

/// [`AXES`] as the lane indices of a vector permute (`vpermilps`), the fourth lane unused.
#[cfg(target_arch = "x86_64")]
const PERMUTE: [[i32; 4]; 3] = [[1, 2, 0, 3], [2, 0, 1, 3], [0, 1, 2, 3]];

/// The axis parameter of [`RayTri4::test_k`] and [`RayTri4::test8_k`] that reads the rows
/// by the ray's axes.
const DYN_AXES: usize = 3;

/// The ray's origin (x, y, z, not permuted) and `t_min` in all four lanes: what the
/// triangle test needs besides its own constants. The single-ray kernel takes them from its
/// box test's 8-wide ones (their low halves, [`RayBox::splats`]), so that both tests share
/// the registers that hold them (the tests reading rows by the ray's axes take only
/// `t_min` from here, and the origin permuted from [`RayTri4::ok`]).
#[derive(Clone, Copy)]
struct Splats {
    o: [Vec4; 3],
    t_min: Vec4,
}

impl RayTri4 {
    #[inline(always)]
    fn new(r: &Ray) -> RayTri4 {
        RayTri4::with_inv(r, &RayBox::new(r).inv)
    }

    /// [`RayTri4::new`] given the ray's reciprocal direction as [`RayBox`] makes it (which
    /// is exactly `1 / d` on the dominant axis, saving a division). Written without indexing
    /// by the axis (which would put the ray's arrays in memory): one case per dominant axis.
    #[inline(always)]
    fn with_inv(r: &Ray, inv: &[f32; 3]) -> RayTri4 {
        RayTri4::with_axis(r, inv, RayTri4::dominant(r))
    }

    /// The ray's dominant axis: the reference's choice, comparison for comparison
    /// (`WatertightRay::new`).
    #[inline(always)]
    fn dominant(r: &Ray) -> usize {
        let ad = r.dir.abs();
        if ad.x > ad.y {
            if ad.x > ad.z {
                0
            } else {
                2
            }
        } else if ad.y > ad.z {
            1
        } else {
            2
        }
    }

    /// [`RayTri4::dominant`] without a branch: for rays whose axes come at random
    /// (diffuse bounces), whose choices would mispredict.
    #[inline(always)]
    fn dominant_unbranched(r: &Ray) -> usize {
        // `dominant`'s three comparisons at once, `(x, x, y) > (y, z, z)`, as the bits of a
        // `movmskps` (a NaN compares false in both), then its choices for each outcome.
        let ad = Vec3A::from(r.dir).abs();
        DOMINANT[ad.xxy().cmpgt(ad.yzz()).bitmask() as usize & 7] as usize
    }

    /// [`RayTri4::with_inv`] for dominant axis `kz` (permuting by a branch on it: for rays
    /// whose axis is steady, camera and shadow rays; [`RayTri4::with_axis_unbranched`]
    /// otherwise).
    #[inline(always)]
    fn with_axis(r: &Ray, inv: &[f32; 3], kz: usize) -> RayTri4 {
        let d = r.dir;
        // (d[kx], d[ky], d[kz], inv[kz]) with kx = kz + 1, ky = kz + 2 (mod 3).
        let (dx, dy, dz, iz) = match kz {
            0 => (d.y, d.z, d.x, inv[0]),
            1 => (d.z, d.x, d.y, inv[1]),
            _ => (d.x, d.y, d.z, inv[2]),
        };
        RayTri4::with_shear(r, kz, (dx, dy, dz, iz))
    }

    /// [`RayTri4::with_inv`] with the axis found and the components permuted by indexing,
    /// not by branches (for [`RayTri4::try_test_dyn`]).
    #[inline(always)]
    fn with_axis_unbranched(r: &Ray, inv: &[f32; 3]) -> RayTri4 {
        let kz = RayTri4::dominant_unbranched(r);
        let [kx, ky, _] = AXES[kz];
        let d = r.dir.to_array();
        RayTri4::with_shear(r, kz, (d[kx], d[ky], d[kz], inv[kz]))
    }

    /// [`RayTri4::with_axis_unbranched`] by vector permutes (one per vector of the ray's,
    /// by its axes' [`PERMUTE`]; one per splat), where the scalar form goes through the
    /// machine stack to index the ray's arrays. The same products, so the same constants
    /// (tested). With the dominant axis by one comparison of vectors and the rows as byte
    /// offsets ([`row`]), the generic AVX-512 kernel's set-up went from 203 to 152
    /// instructions (objdump), and callgrind (AVX2 path, stanford-bunny@close diffuse_1)
    /// counts 1067 -> 1012 instructions per ray.
    ///
    /// # Safety
    /// The CPU must have AVX (inlined into the AVX kernels, as [`RayTri4::test8_k`] is).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn with_axis_avx(r: &Ray, inv: Vec3A) -> RayTri4 {
        use std::arch::x86_64::*;
        let kz = RayTri4::dominant_unbranched(r);
        // SAFETY: `kz` is below 3 (`dominant_unbranched`); a row of `PERMUTE` is 16 bytes.
        let (dp, ip, op) = unsafe {
            let idx = _mm_loadu_si128(PERMUTE.get_unchecked(kz).as_ptr().cast());
            let perm = |v: Vec3A| _mm_permutevar_ps(v.into(), idx);
            (perm(Vec3A::from(r.dir)), perm(inv), perm(Vec3A::from(r.org)))
        };
        let dz = _mm_cvtss_f32(_mm_permute_ps::<0xaa>(dp));
        // As in `with_shear`: `inv[kz]` wherever `RayBox` left the component as it was.
        let sz = if dz.abs() >= TINY { _mm_permute_ps::<0xaa>(ip) } else { _mm_set1_ps(1.0 / dz) };
        let sxy = _mm_mul_ps(dp, sz);
        let splat = |v: __m128, lane: i32| {
            Vec4::from(match lane {
                0 => _mm_permute_ps::<0x00>(v),
                1 => _mm_permute_ps::<0x55>(v),
                _ => _mm_permute_ps::<0xaa>(v),
            })
        };
        RayTri4 {
            kz,
            kb: AXES_BYTES[kz],
            s: [splat(sxy, 0), splat(sxy, 1), Vec4::from(sz)],
            ok: [splat(op, 0), splat(op, 1), splat(op, 2)],
            own: Splats { o: r.org.to_array().map(Vec4::splat), t_min: Vec4::splat(t_start(r.t_min)) },
            ray: *r,
        }
    }

    /// The constants of axis `kz` given `(d[kx], d[ky], d[kz], inv[kz])`.
    #[inline(always)]
    fn with_shear(r: &Ray, kz: usize, (dx, dy, dz, iz): (f32, f32, f32, f32)) -> RayTri4 {
        // The reference's `1 / d[kz]`: `inv` is that wherever `RayBox` left the component
        // as it was (a dominant component below 1e-20 is a ray of no direction).
        let sz = if dz.abs() >= 1e-20 { iz } else { 1.0 / dz };
        let k = AXES[kz];
        let o = r.org.to_array();
        RayTri4 {
            kz,
            kb: AXES_BYTES[kz],
            s: [Vec4::splat(dx * sz), Vec4::splat(dy * sz), Vec4::splat(sz)],
            ok: k.map(|a| Vec4::splat(o[a])),
            // A negative `t_min` counts as 0 ([`Ray::t_min`]).
            own: Splats { o: r.org.to_array().map(Vec4::splat), t_min: Vec4::splat(t_start(r.t_min)) },
            ray: *r,
        }
    }

    /// The nearest hit among the lanes of `b` set in `lanes`, in `[t_min, t_max)`.
    #[inline(always)]
    fn test(&self, b: &Block, lanes: u32, t_max: f32) -> Option<(usize, TriHit)> {
        self.try_test(&self.own, b, lanes, t_max).unwrap_or_else(|Exact| self.scalar(b, lanes, t_max))
    }

    /// [`RayTri4::test`] where it needs no double precision; [`Exact`] when an edge or vertex
    /// of a lane lies exactly on the ray, for [`RayTri4::scalar`] to decide (rare: the
    /// single-ray kernel handles it outside its hot loop).
    #[inline(always)]
    fn try_test(&self, sp: &Splats, b: &Block, lanes: u32, t_max: f32) -> Result<Option<(usize, TriHit)>, Exact> {
        // One body per dominant axis, so that the rows it reads are constants (no index
        // arithmetic or bounds checks per block); the axis is fixed per ray.
        match self.kz {
            0 => self.test_k::<0>(sp, b, lanes, t_max),
            1 => self.test_k::<1>(sp, b, lanes, t_max),
            _ => self.test_k::<2>(sp, b, lanes, t_max),
        }
    }

    /// [`RayTri4::try_test`] reading the block's rows by the ray's axes (`k`) rather than
    /// by a branch to a body of constant rows: for the kernel of rays whose axes come at
    /// random ([`Tracer::walk_on`]). The same operations, so the same results. Of `sp` it
    /// reads `t_min` only (the origin comes permuted, [`RayTri4::ok`]).
    #[inline(always)]
    fn try_test_dyn(&self, sp: &Splats, b: &Block, lanes: u32, t_max: f32) -> Result<Option<(usize, TriHit)>, Exact> {
        self.test_k::<DYN_AXES>(sp, b, lanes, t_max)
    }

    /// The rows `[kx, ky, kz]` of dominant axis `KZ` (as [`row`]'s byte offsets) and the
    /// origin's components in that order: constants (`AXES_BYTES`) and the shared splats
    /// for an axis below 3, the ray's own for [`DYN_AXES`].
    #[inline(always)]
    fn axes<const KZ: usize>(&self, sp: &Splats) -> ([usize; 3], [Vec4; 3]) {
        match KZ {
            0..3 => (AXES_BYTES[KZ], AXES[KZ].map(|a| sp.o[a])),
            _ => (self.kb, self.ok),
        }
    }

    /// [`RayTri4::try_test`] of two blocks at once (`b0` in lanes 0..4, `b1` in lanes 4..8
    /// of `lanes`), as one 8-wide AVX pass: for leaves of two blocks, which then cost little
    /// more than one. The caller must only ask for it in code compiled for AVX2
    /// ([`walk_avx2`]). Lane for lane the operations of [`RayTri4::test_k`], so the
    /// same results.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn try_test8<const ANY: bool>(
        &self,
        sp: &Splats,
        b0: &Block,
        b1: &Block,
        lanes: u32,
        t_max: f32,
    ) -> Result<Option<(usize, TriHit)>, Exact> {
        // SAFETY: only called in the AVX kernels (`Tracer::walk` with `AVX`), which run only
        // on CPUs with AVX2 and FMA (`Tracer::traverse`), and by a test that checks first.
        unsafe {
            match self.kz {
                0 => self.test8_k::<ANY, 0>(sp, b0, b1, lanes, t_max),
                1 => self.test8_k::<ANY, 1>(sp, b0, b1, lanes, t_max),
                _ => self.test8_k::<ANY, 2>(sp, b0, b1, lanes, t_max),
            }
        }
    }

    /// [`RayTri4::try_test8`] reading the rows by the ray's axes ([`RayTri4::try_test_dyn`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn try_test8_dyn<const ANY: bool>(
        &self,
        sp: &Splats,
        b0: &Block,
        b1: &Block,
        lanes: u32,
        t_max: f32,
    ) -> Result<Option<(usize, TriHit)>, Exact> {
        // SAFETY: as in `try_test8`.
        unsafe { self.test8_k::<ANY, DYN_AXES>(sp, b0, b1, lanes, t_max) }
    }

    /// [`RayTri4::try_test8`] for dominant axis `KZ` (the ray's), or, for [`DYN_AXES`], with
    /// the rows read by the ray's axes ([`RayTri4::axes`]). Inlined into the AVX kernels,
    /// whose instruction set its intrinsics then use: it is not compiled for AVX itself, as
    /// `#[target_feature]` would forbid `inline(always)`, and without that one instance did
    /// not inline (an out-of-line call per leaf test, which clobbered the kernel's vector
    /// registers).
    ///
    /// # Safety
    /// The CPU must have AVX.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn test8_k<const ANY: bool, const KZ: usize>(
        &self,
        sp: &Splats,
        b0: &Block,
        b1: &Block,
        lanes: u32,
        t_max: f32,
    ) -> Result<Option<(usize, TriHit)>, Exact> {
        use std::arch::x86_64::*;
        let (k, o) = self.axes::<KZ>(sp);
        let [kx, ky, kz] = k;
        let t_min = sp.t_min;
        // Row `k` of corner `c`: block 0's four lanes low, block 1's high.
        // SAFETY (`row`): `c` is a constant below 3 and `k` one of `axes`'s offsets, each
        // 0, 16 or 32 (from `AXES_BYTES`, as `RayTri4::kb` is).
        let v = |c: usize, k: usize| {
            let (lo, hi) = unsafe { (Vec4::from_array(row(b0, c, k)), Vec4::from_array(row(b1, c, k))) };
            _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(lo.into()), hi.into())
        };
        // The 4-wide splats' values in all eight lanes.
        let wide = |x: Vec4| _mm256_set1_ps(x.x);
        let (ox, oy, oz) = (wide(o[0]), wide(o[1]), wide(o[2]));
        let [sx, sy, sz] = self.s.map(wide);
        let (sub, mul, add) = (_mm256_sub_ps, _mm256_mul_ps, _mm256_add_ps);
        let az = sub(v(0, kz), oz);
        let bz = sub(v(1, kz), oz);
        let cz = sub(v(2, kz), oz);
        let ax = sub(sub(v(0, kx), ox), mul(sx, az));
        let ay = sub(sub(v(0, ky), oy), mul(sy, az));
        let bx = sub(sub(v(1, kx), ox), mul(sx, bz));
        let by = sub(sub(v(1, ky), oy), mul(sy, bz));
        let cx = sub(sub(v(2, kx), ox), mul(sx, cz));
        let cy = sub(sub(v(2, ky), oy), mul(sy, cz));
        let u = sub(mul(cx, by), mul(cy, bx));
        let vv = sub(mul(ax, cy), mul(ay, cx));
        let w = sub(mul(bx, ay), mul(by, ax));
        let z = _mm256_setzero_ps();
        let eq = |a| _mm256_cmp_ps::<_CMP_EQ_OQ>(a, z);
        let zero = _mm256_movemask_ps(_mm256_or_ps(_mm256_or_ps(eq(u), eq(vv)), eq(w))) as u32 & lanes;
        if zero != 0 {
            return Err(Exact);
        }
        let (su, sv, sw) = (_mm256_movemask_ps(u) as u32, _mm256_movemask_ps(vv) as u32, _mm256_movemask_ps(w) as u32);
        let inside = lanes & !((su ^ sv) | (su ^ sw));
        if inside == 0 {
            return Ok(None);
        }
        let det = add(add(u, vv), w);
        let t_scaled = add(add(mul(u, mul(sz, az)), mul(vv, mul(sz, bz))), mul(w, mul(sz, cz)));
        let inv_det = _mm256_div_ps(_mm256_set1_ps(1.0), det);
        let t = mul(t_scaled, inv_det);
        // (`det` is not zero in an `inside` lane: see `test_k`.)
        let ok = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GE_OS>(t, wide(t_min)),
            _mm256_cmp_ps::<_CMP_LT_OS>(t, _mm256_set1_ps(t_max)),
        );
        let mut ok = inside & _mm256_movemask_ps(ok) as u32;
        if ok == 0 {
            return Ok(None);
        }
        if ANY && ok & 0xf != 0 {
            // The hit two single-block tests would stop at: the first block's nearest.
            ok &= 0xf;
        }
        let (mut ts, mut vs, mut ws, mut is) = ([0f32; 8], [0f32; 8], [0f32; 8], [0f32; 8]);
        // SAFETY: each array has room for eight f32s.
        unsafe {
            _mm256_storeu_ps(ts.as_mut_ptr(), t);
            _mm256_storeu_ps(vs.as_mut_ptr(), vv);
            _mm256_storeu_ps(ws.as_mut_ptr(), w);
            _mm256_storeu_ps(is.as_mut_ptr(), inv_det);
        }
        let mut lane = ok.trailing_zeros() as usize;
        let mut rest = ok & (ok - 1);
        while rest != 0 {
            let l = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            if ts[l & 7] < ts[lane & 7] {
                lane = l;
            }
        }
        let lane = lane & 7;
        Ok(Some((lane, TriHit { t: ts[lane], u: vs[lane] * is[lane], v: ws[lane] * is[lane] })))
    }

    /// [`RayTri4::test`] for dominant axis `KZ` (the ray's), or, for [`DYN_AXES`], with the
    /// rows read by the ray's axes ([`RayTri4::axes`]).
    #[inline(always)]
    fn test_k<const KZ: usize>(
        &self,
        sp: &Splats,
        b: &Block,
        lanes: u32,
        t_max: f32,
    ) -> Result<Option<(usize, TriHit)>, Exact> {
        let ([kx, ky, kz], [ox, oy, oz]) = self.axes::<KZ>(sp);
        let t_min = sp.t_min;
        let [sx, sy, sz] = self.s;
        // SAFETY (`row`): `c` is a constant below 3 and `k` one of `axes`'s offsets, each
        // 0, 16 or 32 (from `AXES_BYTES`, as `RayTri4::kb` is).
        let v = |c: usize, k: usize| Vec4::from_array(unsafe { row(b, c, k) });
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
        let z = Vec4::ZERO;
        // Masks combined as vectors, one `movmskps` each.
        let zero = (u.cmpeq(z) | vv.cmpeq(z) | w.cmpeq(z)).bitmask() & lanes;
        if zero != 0 {
            // An edge or vertex exactly on the ray: the reference's double-precision path.
            return Err(Exact);
        }
        // No lane of `lanes` has a zero among its edge functions, so they agree in sign (the
        // reference's `(u < 0 || v < 0 || w < 0) && (u > 0 || ..)` is false) exactly when
        // their sign bits do.
        let (su, sv, sw) = (u.is_negative_bitmask(), vv.is_negative_bitmask(), w.is_negative_bitmask());
        let inside = lanes & !((su ^ sv) | (su ^ sw));
        if inside == 0 {
            // The usual outcome: no lane's edge functions agree in sign (no division needed).
            return Ok(None);
        }
        // The determinant of an `inside` lane, the sum of three edge functions of one sign
        // and none zero, is not zero either: the reference's `det == 0` test never rejects
        // such a lane, and none is needed here.
        let det = u + vv + w;
        let t_scaled = u * (sz * az) + vv * (sz * bz) + w * (sz * cz);
        let inv_det = Vec4::ONE / det;
        let t = t_scaled * inv_det;
        let ok = inside & (t.cmpge(t_min) & t.cmplt(Vec4::splat(t_max))).bitmask();
        if ok == 0 {
            return Ok(None);
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
        Ok(Some((lane, TriHit { t: t[lane], u: vv[lane] * inv_det[lane], v: w[lane] * inv_det[lane] })))
    }

    /// The reference test lane by lane.
    fn scalar(&self, b: &Block, lanes: u32, mut t_max: f32) -> Option<(usize, TriHit)> {
        let wt = WatertightRay::new(&self.ray);
        let mut best = None;
        for lane in 0..4 {
            if lanes & (1 << lane) != 0 {
                if let Some(h) = wt.intersect(&corners(b, lane), t_max) {
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
    /// The tile directory (for hits: a tile's part and first slot).
    tiles: &'s [TileEntry],
    /// The whole file as nodes ([`Scene::node_pool`]; the file is a whole number of
    /// pages), which child references index directly (they hold absolute positions): inner
    /// nodes and links by node, triangle blocks by 16-byte unit of the same memory.
    nodes: &'s [Node8],
    /// The instruction set of the single-ray kernel (chosen once, at creation): the AVX2
    /// kernel on AVX2 machines, its AVX-512 build on AVX-512 ones, the baseline's otherwise.
    isa: packet::Isa,
    /// Where traversals start: the top-level tree's root, or, when the scene has a single
    /// part, that part's root (the top level would only test the part's box again).
    root: Entry,
    /// The scene's bounding box: rays that miss it end before any setup.
    bounds: megaray_base::Aabb,
    /// The tiles checked so far (held here so that the hot loop reads it without going
    /// through the scene): a link into one of them needs nothing more. A paged tracer holds
    /// [`CheckedTiles::NONE`], so that it asks the pager at every link instead.
    checked: CheckedTiles<'s>,
    /// Every tile was checked and found sound when this tracer was made (unpaged only,
    /// [`Scene::all_tiles_checked`]): the single-ray kernel then follows links as it
    /// follows inner nodes, with no tile to check or compare ([`Tracer::walk`]).
    all_checked: bool,
    /// Which AVX2 single-ray kernels run: `None` chooses by the rays' coherence
    /// ([`Tracer::walk_on`]), `Some(true)` always the octant ones, `Some(false)` always the
    /// generic one (for tests).
    octant_kernels: Option<bool>,
    /// The single-ray kernels of this tracer's instruction set and tile bookkeeping
    /// ([`Tracer::kernel_table`]), by query kind (`[closest, any]`) and kernel number
    /// ([`Tracer::walk_on`]): chosen once, so that a ray's walk starts with one indirect
    /// call, not a test of each setting and a jump through a table.
    kernels: [[Kernel; KERNELS]; 2],
    /// The same kernels for a new ray on a tracer whose every tile is checked, each in one
    /// function with its walk's state in registers ([`Tracer::new_ray`]): what
    /// [`Tracer::intersect`] and [`Tracer::occluded`] run. `None` on the baseline instruction
    /// set and where tiles are checked as the walk goes.
    new_ray: Option<[[NewRay; KERNELS]; 2]>,
    /// New rays run the assembly kernel (`asm.rs`): on AVX2 machines where every tile is
    /// checked (and not in a `stats` build, whose counters it does not keep).
    asm: bool,
    /// How many stack entries the assembly kernel may have below a node whose children it
    /// pushes (`STACK - W`, but fewer in tests of the driver's spill, [`Tracer::with_asm_stack`]).
    #[cfg_attr(not(all(target_arch = "x86_64", target_os = "linux")), allow(dead_code))]
    asm_stack: usize,
}

/// A single-ray kernel: [`Tracer::walk`] compiled for one instruction set, query kind, tile
/// bookkeeping and kernel number. Unsafe: the AVX ones must only run where the CPU has the
/// instructions, which [`Tracer::kernel_table`] sees to.
type Kernel = for<'a, 'b, 'c, 'd> unsafe fn(&'a Tracer<'b>, &'c mut Walk<'d>, &Ray) -> Event;

/// A kernel for a new ray ([`Tracer::new_ray`]): what [`Kernel`] is for a walk, from the
/// thread's scratch memory to the closest (or any) hit. Unsafe as [`Kernel`] is.
type NewRay = for<'a, 'b, 'c> unsafe fn(&'a Tracer<'b>, &'c mut Scratch, &Ray) -> Option<Found>;

/// The generic kernel's number ([`Tracer::walk_on`]; octants' are `0..8`).
const GENERIC: usize = 8;

/// A row of a kernel table: `$f` with the given leading const arguments, then each kernel
/// number (the eight octants, then [`GENERIC`]), as function pointers of type `$ty`.
#[cfg_attr(not(target_arch = "x86_64"), allow(unused_macros))]
macro_rules! kernel_row {
    ($f:ident, $ty:ty, $($arg:literal),+) => {
        [
            $f::<$($arg,)+ 0> as $ty,
            $f::<$($arg,)+ 1> as $ty,
            $f::<$($arg,)+ 2> as $ty,
            $f::<$($arg,)+ 3> as $ty,
            $f::<$($arg,)+ 4> as $ty,
            $f::<$($arg,)+ 5> as $ty,
            $f::<$($arg,)+ 6> as $ty,
            $f::<$($arg,)+ 7> as $ty,
            $f::<$($arg,)+ GENERIC> as $ty,
        ]
    };
}

/// Kernels per query kind: eight octant ones and the generic one ([`Tracer::walk_on`]).
const KERNELS: usize = GENERIC + 1;

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

impl<'s> Tracer<'s> {
    pub fn new(scene: &'s Scene) -> Tracer<'s> {
        let top0 = scene.header().top_nodes_off / NODE_BYTES as u64;
        // Read once: the kernel table must be the one of the settings the tracer records
        // (another thread may finish checking every tile meanwhile).
        let (isa, all_checked) = (packet::Isa::detect(), scene.all_tiles_checked());
        Tracer {
            scene,
            pager: None,
            tiles: scene.tiles(),
            nodes: scene.node_pool(),
            isa,
            bounds: scene.header().bounds,
            checked: scene.checked_tiles(),
            all_checked,
            octant_kernels: None,
            kernels: Tracer::kernel_table(isa, all_checked),
            new_ray: Tracer::new_ray_table(isa, all_checked),
            asm: Tracer::asm_kernel(isa, all_checked),
            asm_stack: STACK - W,
            root: match scene.parts() {
                // The part's root, as the top-level tree links to it (in range: checked by
                // `Scene::open`).
                [p] => {
                    let root = scene.tiles()[p.root_tile as usize].node0() + p.root_node as u64;
                    Entry { r: ChildRef::link(p.root_tile, root).0, arr: TOP, t: f32::NEG_INFINITY }
                }
                _ => Entry { r: ChildRef::inner(top0).0, arr: TOP, t: f32::NEG_INFINITY },
            },
        }
    }

    /// This tracer with single-ray kernels for `isa` (one of [`packet::Isa::available`]):
    /// for tests and benchmarks that compare the paths. [`Tracer::new`] picks the best one.
    pub fn with_isa(mut self, isa: packet::Isa) -> Tracer<'s> {
        assert!(packet::Isa::available().contains(&isa), "{isa:?} is not available on this machine");
        self.isa = isa;
        self.kernels = Tracer::kernel_table(isa, self.all_checked);
        self.new_ray = Tracer::new_ray_table(isa, self.all_checked);
        self.asm = Tracer::asm_kernel(isa, self.all_checked);
        self
    }

    /// Whether new rays on `isa` run the assembly kernel where every tile is checked (`all`).
    fn asm_kernel(isa: packet::Isa, all: bool) -> bool {
        #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
        if all && isa == packet::Isa::Avx2 && !cfg!(feature = "stats") {
            return asm_enabled() && asm::supported();
        }
        let _ = (isa, all);
        false
    }

    /// This tracer with new rays on the assembly kernel (`true`, where it would run) or on
    /// the Rust kernels (`false`): for tests that compare the kernels.
    #[doc(hidden)]
    pub fn with_asm_kernel(mut self, on: bool) -> Tracer<'s> {
        self.asm = on && Tracer::asm_kernel(self.isa, self.all_checked);
        self
    }

    /// Whether new rays run the assembly kernel (`asm.rs`) where they would run the generic
    /// AVX2 kernel.
    #[doc(hidden)]
    pub fn runs_asm_kernel(&self) -> bool {
        self.asm
    }

    /// This tracer with the assembly kernel's stack cut to `entries` below a node whose
    /// children it pushes (at least 1, at most `STACK - W`), so that it hands its walk to the
    /// driver for room often: for tests of that hand-over.
    #[doc(hidden)]
    pub fn with_asm_stack(mut self, entries: usize) -> Tracer<'s> {
        self.asm_stack = entries.clamp(1, STACK - W);
        self
    }

    /// This tracer with the AVX2 single-ray kernel for each octant of ray directions
    /// always (`true`) or never (`false`) instead of as the rays' coherence suggests: for
    /// tests that compare the kernels.
    #[doc(hidden)]
    pub fn with_octant_kernels(mut self, always: bool) -> Tracer<'s> {
        self.octant_kernels = Some(always);
        self
    }

    /// This tracer with its tile bookkeeping kept even when every tile is checked
    /// ([`Tracer::skips_tile_checks`]): for tests that compare the kernels.
    #[doc(hidden)]
    pub fn with_tile_checks(mut self) -> Tracer<'s> {
        self.all_checked = false;
        self.kernels = Tracer::kernel_table(self.isa, false);
        self.new_ray = None;
        self.asm = false;
        self
    }

    /// Whether the single-ray kernel follows links with no tile to check (every tile of
    /// the scene was checked when this unpaged tracer was made: [`Scene::check_all_tiles`]).
    pub fn skips_tile_checks(&self) -> bool {
        self.all_checked
    }

    /// A tracer that reads only the tiles `pager` has made resident.
    pub fn paged(pager: &'s Pager) -> Tracer<'s> {
        let scene: &'s Scene = pager.scene();
        Tracer::new(scene).with_tile_checks().with_pager(pager)
    }

    /// This tracer reading through `pager` ([`Tracer::paged`]).
    fn with_pager(self, pager: &'s Pager) -> Tracer<'s> {
        Tracer { pager: Some(pager), checked: CheckedTiles::NONE, ..self }
    }

    /// The pager, for a paged tracer.
    pub fn pager(&self) -> Option<&'s Pager> {
        self.pager
    }

    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// Makes tile `arr` the open one (`*c`); fails with [`Step::Skip`] when that tile is
    /// corrupt and, on a paged tracer, with [`Step::Missing`] when it is not resident (now
    /// requested).
    #[inline(always)]
    fn open(&self, c: &mut u32, arr: u32) -> Result<(), Step<'s>> {
        if *c == arr {
            return Ok(());
        }
        if self.checked.get(arr) {
            // The common crossing, inline: an unpaged tile already checked.
            stats::count(|s| s.tiles_entered += 1);
            *c = arr;
            return Ok(());
        }
        self.enter(c, arr)
    }

    /// [`Tracer::open`] when `arr` is not the open array: the tile is checked (or, paged,
    /// acquired from the pager).
    #[inline(never)]
    fn enter(&self, c: &mut u32, arr: u32) -> Result<(), Step<'s>> {
        if arr != TOP {
            match self.pager {
                None => {
                    if !self.scene.tile_usable(arr) {
                        return Err(Step::Skip);
                    }
                }
                Some(p) => match p.acquire(arr) {
                    Access::Ready => {}
                    Access::Corrupt => return Err(Step::Skip),
                    Access::Missing => return Err(Step::Missing(arr)),
                },
            }
        }
        stats::count(|s| s.tiles_entered += 1);
        *c = arr;
        Ok(())
    }

    /// Resolves a popped entry (for the packet kernel): opens the tile it lives in and says
    /// what it is.
    #[inline(always)]
    fn step(&self, c: &mut u32, e: &Entry) -> Step<'s> {
        // `ChildRef::decode`, written out, its kind's two bits tested one at a time in order
        // of frequency (as a `match`, the compiler jumps through a table, an indirect branch
        // that predicts worse). An empty slot has kind 3 and is caught with the parts.
        let r = e.r;
        let leaf_or_part = r & (1 << 62) != 0;
        let (arr, node) = if (r as i64) >= 0 {
            if let Err(s) = self.open(c, e.arr) {
                return s;
            }
            if leaf_or_part {
                return Step::Leaf { unit: r & ChildRef::MAX_UNIT, count: ((r >> 40) & 0xff) as u32 };
            }
            (e.arr, r & ChildRef::MAX_NODE)
        } else if !leaf_or_part {
            (((r >> 36) as u32) & ChildRef::MAX_TILE, r & ChildRef::MAX_NODE)
        } else {
            // An empty slot (the top-level tree links to part roots).
            return Step::Skip;
        };
        if let Err(s) = self.open(c, arr) {
            return s;
        }
        // In range: node positions were checked with the tile (`Scene::check_tile`).
        Step::Node(&self.nodes[node as usize], arr)
    }

    /// Starts loading the node or leaf that child reference `r` names (a whole node, 256
    /// bytes; a leaf's one or two blocks, 144 or 288), as Embree's traversal does
    /// for the children it hits. Called for the children pushed (the nearest is loaded next
    /// anyway): they are popped later and find their data in cache, so an incoherent ray's
    /// misses overlap instead of queueing.
    /// Only the address is computed: a prefetch never faults and needs no bounds (an absent
    /// tile's pages are not touched, so a paged tracer never waits for one).
    #[inline(always)]
    fn prefetch(&self, r: u64) {
        let base = self.nodes.as_ptr() as *const u8;
        // Inner nodes and links (bit 62 clear) by node, leaves by block; parts not.
        let at = if r & (1 << 62) == 0 {
            (r & ChildRef::MAX_NODE) as usize * NODE_BYTES
        } else if (r as i64) >= 0 {
            let at = (r & ChildRef::MAX_UNIT) as usize * 16;
            if (r >> 40) & 0xff > 4 {
                // Two blocks, 288 bytes: the lines past the first 256 bytes too.
                let p = base.wrapping_add(at);
                megaray_base::prefetch_addr(p.wrapping_add(256));
                megaray_base::prefetch_addr(p.wrapping_add(2 * std::mem::size_of::<Tri4>() - 1));
            }
            at
        } else {
            return;
        };
        let p = base.wrapping_add(at);
        for line in 0..4 {
            megaray_base::prefetch_addr(p.wrapping_add(64 * line));
        }
    }

    /// The [`Hit`] of what a kernel found (single-ray or packet): its part, slot and corners.
    #[inline(always)]
    fn hit_of(&self, f: Option<Found>) -> Option<Hit> {
        let f = f?;
        let (part, slot0) = self.slots(f.arr, f.unit);
        let tri = corners(self.block_at(f.unit), f.lane as usize);
        Some(Hit { t: f.t, u: f.u, v: f.v, part, prim: slot0 + f.lane, tri })
    }

    /// The part of tile `arr` and the slot of lane 0 of its block at `unit` (lane `l` of the
    /// tile's block `b` is slot `first_slot + 4 b + l`).
    #[inline]
    fn slots(&self, arr: u32, unit: u64) -> (u32, u32) {
        if arr == TOP {
            // A hit of a walk that kept no tile ([`Tracer::walk`]): the tile whose blocks
            // hold it (tiles lie in file order).
            return self.scene.slot_of_unit(unit);
        }
        let e = &self.tiles[arr as usize];
        (e.part, e.first_slot + 4 * ((unit - e.unit0()) / 9) as u32)
    }

    /// The triangle block at `unit` (`offset / 16`).
    #[inline(always)]
    fn block_at(&self, unit: u64) -> &'s Block {
        let s = unit as usize;
        // The nodes as 16-byte units: the same pointer, 16 times the length (no copy).
        let units: &'s [[f32; 4]] = bytemuck::cast_slice(self.nodes);
        units[s..s + 9].try_into().expect("nine units")
    }

    /// [`Tracer::block_at`] without its bounds check, for the hot loop ([`Tracer::walk`]):
    /// `unit` must be a block of a leaf reference read from a checked tile.
    #[inline(always)]
    fn walk_block_at(&self, unit: u64) -> &'s Block {
        let s = unit as usize;
        debug_assert!((s + 9) * 16 <= std::mem::size_of_val(self.nodes), "block {s} beyond the file");
        // SAFETY: the walk reads blocks only through leaf references of checked tiles (or of
        // a tile entered through `Tracer::enter`, which checks it), and `Scene::check_tile`
        // verified that all blocks of each such leaf lie inside its tile, which
        // `Scene::open` verified to lie inside the file, all of which `nodes` covers (but a
        // tail shorter than a node, which no tile reaches into: tiles end on pages). A
        // `Block` is nine `[f32; 4]` units: the pointer is aligned for it.
        unsafe { &*(self.nodes.as_ptr().cast::<[f32; 4]>().add(s).cast::<Block>()) }
    }

    /// The node at position `node` without a bounds check, for the hot loop
    /// ([`Tracer::walk`]): `node` must come from a checked reference.
    #[inline(always)]
    fn walk_node_at(&self, node: u64) -> &'s Node8 {
        debug_assert!((node as usize) < self.nodes.len(), "node {node} beyond the file");
        // SAFETY: the walk follows only references of checked tiles (`Scene::check_tile`:
        // inner nodes and links point at nodes inside their tiles), of the top-level tree
        // and the root (both checked by `Scene::open`), and `Scene::open` verified every tile
        // to lie inside the file, which `nodes` covers. (A debug build asserts it.)
        unsafe { self.nodes.get_unchecked(node as usize) }
    }

    /// The closest hit of `ray` in `[ray.t_min, ray.t_max)`. On a paged tracer this waits
    /// for missing tiles (use [`Tracer::try_intersect`] not to).
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if self.pager.is_none() {
            return self.hit_of(self.unpaged::<false>(ray));
        }
        self.blocking(ray, false)
    }

    /// Whether anything lies on `ray` in `[ray.t_min, ray.t_max)`. On a paged tracer this
    /// waits for missing tiles (use [`Tracer::try_occluded`] not to).
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        if self.pager.is_none() {
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
    pub fn resume(&self, ray: &Ray, pending: Pending) -> Traced {
        let any = pending.any;
        self.traverse(ray, any, Some(pending), 0)
    }

    /// Traces to the end, waiting for missing tiles (pinned only while traversing).
    #[inline]
    fn blocking(&self, ray: &Ray, any: bool) -> Option<Hit> {
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
        for (r, h) in rays.chunks(packet::WIDTH).zip(hits.chunks_mut(packet::WIDTH)) {
            self.intersect16_with(&Rays16::from_rays(r), h, isa);
        }
    }

    /// [`Tracer::intersect_packet`] of rays already in structure of arrays (as
    /// [`Rays16`]; the hits of its `len` rays into the first `len` of `hits`).
    pub fn intersect16(&self, rays: &Rays16, hits: &mut [Option<Hit>]) {
        self.intersect16_with(rays, hits, packet::Isa::detect());
    }

    /// [`Tracer::intersect16`] on a chosen instruction set.
    pub fn intersect16_with(&self, rays: &Rays16, hits: &mut [Option<Hit>], isa: packet::Isa) {
        assert!(rays.len <= packet::WIDTH && rays.len <= hits.len(), "one hit slot per ray, at most 16");
        let hits = &mut hits[..rays.len];
        if self.pager.is_some() {
            // Packets do not suspend: a paged tracer traces them ray by ray.
            for (i, h) in hits.iter_mut().enumerate() {
                *h = self.intersect(&rays.ray(i));
            }
            return;
        }
        assert!(packet::Isa::available().contains(&isa), "{isa:?} is not available on this machine");
        // One stack per thread, kept between calls: callers pass one packet at a time.
        thread_local! {
            static STACK: std::cell::RefCell<packet::PacketStack> = const { std::cell::RefCell::new(Vec::new()) };
        }
        STACK.with_borrow_mut(|stack| packet::intersect16(self, rays, hits, isa, stack));
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
    fn traverse(&self, ray: &Ray, any: bool, from: Option<Pending>, pad: usize) -> Traced {
        #[cfg(target_arch = "x86_64")]
        match self.isa {
            // `isa` is one that the CPU reported (`Isa::detect`, `Isa::available`). The
            // same kernel on both, compiled for each ([`walk_avx512`]).
            packet::Isa::Avx2 | packet::Isa::Avx512 => {
                return match any {
                    true => self.traverse_in::<true, true>(ray, from, pad),
                    false => self.traverse_in::<true, false>(ray, from, pad),
                };
            }
            packet::Isa::Baseline => {}
        }
        match any {
            true => self.traverse_in::<false, true>(ray, from, pad),
            false => self.traverse_in::<false, false>(ray, from, pad),
        }
    }

    /// The kernel's driver, its box test on AVX2 (`AVX`) or on the baseline's 4-wide SSE;
    /// `ANY`: stop at the first hit found (shadow rays). It runs the hot loop
    /// ([`Tracer::walk`]) with a stack kept per thread; what the loop cannot finish alone
    /// goes to [`Tracer::drive_rare`].
    #[inline(always)]
    fn traverse_in<const AVX: bool, const ANY: bool>(&self, ray: &Ray, from: Option<Pending>, pad: usize) -> Traced {
        stats::count(|s| s.rays += 1);
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut scratch) => self.drive::<AVX, ANY>(ray, from, pad, &mut scratch),
            // Taken (never, since traversals do not nest, but a fresh one is as good).
            Err(_) => self.drive::<AVX, ANY>(ray, from, pad, &mut Scratch::fresh()),
        })
    }

    /// A new ray on an unpaged tracer (which never suspends): the shortest way into the
    /// kernel, for [`Tracer::intersect`] and [`Tracer::occluded`]. The closure given to the
    /// thread-local is kept small so that it inlines (and with it the thread-local's access).
    #[inline(always)]
    fn unpaged<const ANY: bool>(&self, ray: &Ray) -> Option<Found> {
        stats::count(|s| s.rays += 1);
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut scratch) => self.unpaged_in::<ANY>(ray, &mut scratch),
            Err(_) => self.unpaged_in::<ANY>(ray, &mut Scratch::fresh()),
        })
    }

    /// [`Tracer::unpaged`] with the thread's scratch memory: by a new-ray kernel where
    /// every tile is checked ([`Tracer::new_ray`]), else by the driver.
    #[inline(never)]
    fn unpaged_in<const ANY: bool>(&self, ray: &Ray, scratch: &mut Scratch) -> Option<Found> {
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
        if self.isa != packet::Isa::Baseline {
            return match self.walk_on::<true, ANY>(&mut w, ray) {
                Event::Empty | Event::Hit => w.best,
                ev => self.drive_rare::<true, ANY>(ray, &mut w, Vec::new(), Some(ev), NO_PRIOR).expect(UNPAGED),
            };
        }
        match self.walk_on::<false, ANY>(&mut w, ray) {
            Event::Empty | Event::Hit => w.best,
            ev => self.drive_rare::<false, ANY>(ray, &mut w, Vec::new(), Some(ev), NO_PRIOR).expect(UNPAGED),
        }
    }

    /// [`Tracer::traverse_in`] with a stack: the common case (a new ray that the hot loop
    /// finishes in one go) inline, the rest in [`Tracer::drive_rare`].
    #[inline(always)]
    fn drive<const AVX: bool, const ANY: bool>(
        &self,
        ray: &Ray,
        from: Option<Pending>,
        pad: usize,
        scratch: &mut Scratch,
    ) -> Traced {
        let mut w = Walk::new(scratch, self.root, ray.t_max);
        if from.is_none() && pad == 0 {
            match self.walk_on::<AVX, ANY>(&mut w, ray) {
                Event::Empty | Event::Hit => Traced::Done(self.hit_of(w.best)),
                ev => self.traced(self.drive_rare::<AVX, ANY>(ray, &mut w, Vec::new(), Some(ev), NO_PRIOR), NO_PRIOR),
            }
        } else {
            self.drive_from::<AVX, ANY>(ray, &mut w, from, pad)
        }
    }

    /// A resumed (or, in tests, padded) traversal: its saved stack becomes the spill.
    #[inline(never)]
    fn drive_from<const AVX: bool, const ANY: bool>(
        &self,
        ray: &Ray,
        w: &mut Walk<'_>,
        from: Option<Pending>,
        pad: usize,
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
        self.traced(self.drive_rare::<AVX, ANY>(ray, w, spill, None, prior), prior)
    }

    /// The public form of the driver's outcome.
    fn traced(&self, r: Result<Option<Found>, Box<Pending>>, prior: Prior) -> Traced {
        match r {
            Ok(f) => Traced::Done(self.hit_after(f, prior)),
            Err(p) => Traced::Pending(*p),
        }
    }

    /// The [`Hit`] of `f`: the one made before the ray was suspended if it is still the
    /// closest (its tile may have been evicted since), else made now (its tile is resident:
    /// the traversal is pinned).
    fn hit_after(&self, f: Option<Found>, prior: Prior) -> Option<Hit> {
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
    fn drive_rare<const AVX: bool, const ANY: bool>(
        &self,
        ray: &Ray,
        w: &mut Walk<'_>,
        mut spill: Vec<Entry>,
        mut first: Option<Event>,
        prior: Prior,
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
                Event::Enter(arr) => match self.enter(&mut w.c, arr) {
                    Ok(()) => {}
                    Err(Step::Missing(tile)) => {
                        spill.extend_from_slice(&w.fixed[..w.sp]);
                        spill.extend(w.next);
                        let hit = self.hit_after(w.best, prior);
                        return Err(Box::new(Pending { stack: spill, best: w.best, hit, any: ANY, tile }));
                    }
                    // A corrupt tile: what needed it is skipped.
                    Err(_) => w.next = None,
                },
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
    /// offsets held in registers: 4% fewer instructions per ray), and one for any
    /// direction, which reads the triangle test's rows by the ray's axes (held per ray, so
    /// that nothing branches on them: diffuse rays, whose axis comes at random, mispredicted
    /// a choice by it per block (+5-9% diffuse rays per second when it went), and then, with
    /// a kernel per axis, the choice of kernel per ray). Eight kernels are
    /// more code than the instruction cache holds at once, so the octant kernels run only for
    /// coherent rays: when this thread's last [`STREAK_MIN`] new rays ran in the same octant
    /// (camera and shadow rays; measured +10% on them), and the generic kernel otherwise
    /// (diffuse bounces, whose octants come at random; measured +7% on them). All give the
    /// same hits (tested).
    #[inline(always)]
    fn walk_on<const AVX: bool, const ANY: bool>(&self, w: &mut Walk<'_>, ray: &Ray) -> Event {
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
    fn first_kernel<const AVX: bool>(&self, streak: &mut Streak, ray: &Ray) -> Option<usize> {
        // Most rays of a wide view miss the whole scene: they end here, before any
        // kernel's set-up. But where rays come that enter the scene's box (a view filled
        // by the model, secondary rays), the test is 10-35 instructions that never cull,
        // and the root node's test would cull as well: after a ray that entered the box,
        // the thread's next [`SKIP_BOUNDS`] new rays go without it (callgrind, AVX2 path,
        // stanford-bunny primary_1: at the close camera 752 -> 718 instructions per ray,
        // at the default one, most of whose rays miss the box, 261 -> 239).
        if streak.skip_bounds > 0 {
            streak.skip_bounds -= 1;
        } else if self.misses_bounds(ray) {
            return None;
        } else {
            streak.skip_bounds = SKIP_BOUNDS;
        }
        if !AVX {
            return Some(GENERIC);
        }
        let oct = RayBox::octant(ray);
        Some(match self.octant_kernels {
            Some(true) => oct,
            Some(false) => GENERIC,
            None => {
                // Without branches: diffuse rays' octants come at random, and a branch on
                // `last == oct` mispredicted for 0.31 of them (callgrind).
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
    /// (callgrind, AVX2 path: 15-19 fewer instructions per ray, bunny@close primary_1 691 ->
    /// 672 and diffuse_1 998 -> 983; `bench/ab.sh` +1-2% on each single-ray kind). The rare
    /// events go on in [`Tracer::drive_rare`] with the walk kernels.
    #[inline(always)]
    fn new_ray<const AVX: bool, const ANY: bool, const OCT: usize>(
        &self,
        scratch: &mut Scratch,
        ray: &Ray,
    ) -> Option<Found> {
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
    fn new_ray_rare<const AVX: bool, const ANY: bool>(&self, ray: &Ray, mut w: Walk<'_>, ev: Event) -> Option<Found> {
        self.drive_rare::<AVX, ANY>(ray, &mut w, Vec::new(), Some(ev), NO_PRIOR).expect(UNPAGED)
    }

    /// The new-ray kernels for `isa` where every tile is checked (`all`), else `None`
    /// ([`Tracer::new_ray`]).
    fn new_ray_table(isa: packet::Isa, all: bool) -> Option<[[NewRay; KERNELS]; 2]> {
        if !all {
            return None;
        }
        #[cfg(target_arch = "x86_64")]
        match isa {
            packet::Isa::Avx512 => {
                return Some([kernel_row!(new_ray_avx512, NewRay, false), kernel_row!(new_ray_avx512, NewRay, true)])
            }
            packet::Isa::Avx2 => {
                return Some([kernel_row!(new_ray_avx2, NewRay, false), kernel_row!(new_ray_avx2, NewRay, true)])
            }
            _ => {}
        }
        let _ = isa;
        None
    }

    /// Whether `ray` misses the scene's box (its origin outside it, and its segment not
    /// entering it): with the slab products and widening of the kernels' box tests, so never
    /// stricter than them.
    #[inline(always)]
    fn misses_bounds(&self, ray: &Ray) -> bool {
        let rb = RayBox::new(ray);
        !rb.starts_inside(&self.bounds) && !rb.enters(&self.bounds, t_start(ray.t_min), ray.t_max)
    }

    /// The kernels for `isa`, with tile bookkeeping unless `all` tiles are checked
    /// ([`Tracer::kernels`]).
    fn kernel_table(isa: packet::Isa, all: bool) -> [[Kernel; KERNELS]; 2] {
        #[cfg(target_arch = "x86_64")]
        match (isa, all) {
            (packet::Isa::Avx512, true) => {
                return [kernel_row!(walk_avx512, Kernel, false, true), kernel_row!(walk_avx512, Kernel, true, true)]
            }
            (packet::Isa::Avx512, false) => {
                return [kernel_row!(walk_avx512, Kernel, false, false), kernel_row!(walk_avx512, Kernel, true, false)]
            }
            (packet::Isa::Avx2, true) => {
                return [kernel_row!(walk_avx2, Kernel, false, true), kernel_row!(walk_avx2, Kernel, true, true)]
            }
            (packet::Isa::Avx2, false) => {
                return [kernel_row!(walk_avx2, Kernel, false, false), kernel_row!(walk_avx2, Kernel, true, false)]
            }
            _ => {}
        }
        let _ = isa;
        match all {
            true => {
                [[walk_baseline::<false, true> as Kernel; KERNELS], [walk_baseline::<true, true> as Kernel; KERNELS]]
            }
            false => {
                [[walk_baseline::<false, false> as Kernel; KERNELS], [walk_baseline::<true, false> as Kernel; KERNELS]]
            }
        }
    }

    /// The next blocks of a leaf (`left` triangles from the block at `unit`) against the
    /// ray: two at once by [`RayTri4::try_test8`] on AVX when two or more remain, else one by
    /// [`RayTri4::try_test`]. Says how many blocks it tested; a hit's lane counts across them.
    /// With `dyn_rows` (a constant where it inlines), the tests read the rows by the ray's
    /// axes ([`RayTri4::try_test_dyn`]).
    #[inline(always)]
    fn test_blocks<const AVX: bool, const ANY: bool>(
        &self,
        dyn_rows: bool,
        rt: &RayTri4,
        sp: &Splats,
        unit: u64,
        left: u32,
        t_max: f32,
    ) -> (Result<Option<(usize, TriHit)>, Exact>, u32) {
        #[cfg(target_arch = "x86_64")]
        if AVX && left > 4 {
            stats::count(|s| s.blocks += 2);
            let (b0, b1, lanes) = (self.walk_block_at(unit), self.walk_block_at(unit + 9), lanes8(left));
            return match dyn_rows {
                true => (rt.try_test8_dyn::<ANY>(sp, b0, b1, lanes, t_max), 2),
                false => (rt.try_test8::<ANY>(sp, b0, b1, lanes, t_max), 2),
            };
        }
        stats::count(|s| s.blocks += 1);
        let (b, lanes) = (self.walk_block_at(unit), lanes(left));
        match dyn_rows {
            true => (rt.try_test_dyn(sp, b, lanes, t_max), 1),
            false => (rt.try_test(sp, b, lanes, t_max), 1),
        }
    }

    /// The hot loop of the single-ray kernel. Near-first: of the children a node's box test
    /// hits, the nearest is visited next, the others are pushed far to near (unsorted for
    /// `ANY`). Leaves are children like any other, so they too are tested nearest first.
    ///
    /// It calls no function (all it uses is inlined, bounds checks aside, which never
    /// return): a call would clobber every vector register, and the compiler would then keep
    /// the ray's constants on the machine stack and reload them at every node (measured: 1.9x
    /// Embree's instructions per ray before this split). What is rare returns to the driver
    /// as an [`Event`], the walk's state saved in `w`: a link into a tile that is paged or not
    /// checked yet, an edge exactly on the ray, a full or empty fixed stack, an any-hit.
    /// Entries popped from a tile other than the open one reopen it without a check on an
    /// unpaged tracer: the traversal entered it through a link before. With `ALL` (every
    /// tile checked, [`Tracer::all_checked`]) there is nothing to check at all: a link is
    /// followed as an inner node is, and no tile is kept: `c` stays [`TOP`], and a hit is
    /// credited to its tile when made a [`Hit`] (if ever: `occluded` needs none), from its
    /// block's position ([`Scene::slot_of_unit`]: one lookup per hit, where keeping the
    /// tile cost six instructions per node, the tile of every link chosen without a branch
    /// and that of every popped entry moved in).
    #[inline(always)]
    fn walk<const AVX: bool, const ANY: bool, const ALL: bool, const OCT: usize>(
        &self,
        w: &mut Walk<'_>,
        ray: &Ray,
    ) -> Event {
        // The ray's constants, made here rather than passed in: the loop then holds them in
        // registers without a copy (events are rare, and the few that come back remake them).
        let mut rb = RayBox::new(ray);
        if OCT < 8 {
            // The ray's octant (`walk_on` chose this kernel by it), as a constant.
            rb.rows = &ROWS[OCT];
        }
        // Never below +0 ([`Ray::t_min`]): the box tests need it ([`RayBox::test`]).
        let t_min = t_start(ray.t_min);
        // The generic kernel (`walk_on`) reads the triangles' rows by the ray's axes: no
        // choice by them, per ray or per block.
        let rt = match OCT {
            // SAFETY: `AVX` kernels run only on CPUs with AVX2 (`Tracer::kernel_table`).
            #[cfg(target_arch = "x86_64")]
            GENERIC if AVX => unsafe { RayTri4::with_axis_avx(ray, Vec3A::from_array(rb.inv)) },
            GENERIC => RayTri4::with_axis_unbranched(ray, &rb.inv),
            _ => RayTri4::with_inv(ray, &rb.inv),
        };
        let shared = rb.splats::<AVX>(t_min);
        // With `ALL` no tile is kept: [`TOP`] throughout, a constant (no register for it).
        let mut c = if ALL { TOP } else { w.c };
        let mut sp = w.sp;
        let mut t_best = w.t_best;
        // The closest hit widened as box exits are ([`FAR_EPS`]), for the box tests and for
        // skipping popped entries beyond it.
        let mut t_wide = t_best * FAR_EPS;
        let mut next = w.next.take();
        // One place pops, and it asks first whether an interrupted entry is pending. Both
        // ways of not asking (a pop at each dead end; the pending entry pushed before the
        // loop) made any-hit rays ~10% slower on AVX-512 (bench/ab.sh, sphereflake:2): the
        // compiler then copies the pop into every dead end, and those branches predict worse.
        let event = 'walk: loop {
            let e = match next.take() {
                Some(e) => e,
                None => {
                    if sp == 0 {
                        break Event::Empty;
                    }
                    sp -= 1;
                    let e = w.fixed[sp % STACK];
                    // Beyond the closest hit: skipped. (An any-hit query's `t_best` is the
                    // ray's end until it ends, so its entries are never beyond it.)
                    if !ANY && e.t > t_wide {
                        continue;
                    }
                    e
                }
            };
            // An inner node or a leaf of the tile the entry was pushed from, which this
            // traversal entered before: unpaged, it is still there and checked. Paged, it may
            // have been evicted while the ray was pending: the pager is asked again (a ray
            // needs one tile at a time). (A link or part names its own tile.)
            if ALL {
                // Every tile is checked: nothing to open, and no tile kept ([`Tracer::walk`]).
            } else if (e.r as i64) >= 0 && e.arr != c {
                if self.pager.is_none() || e.arr == TOP {
                    c = e.arr;
                } else {
                    next = Some(e);
                    break 'walk Event::Enter(e.arr);
                }
            }
            // Descend from `e`, always into the nearest child hit (which lies in the open
            // tile, or names its own).
            let mut r = e.r;
            loop {
                // `ChildRef::decode`, written out, its kind's two bits tested one at a time in
                // order of frequency (as a `match`, the compiler jumps through a table, an
                // indirect branch that predicts worse). An empty slot is caught with the parts.
                // References hold absolute positions: no tile needs looking up to follow one.
                let leaf_or_part = r & (1 << 62) != 0;
                let node = if ALL && !leaf_or_part {
                    // Every tile checked: an inner node, or a link, followed alike.
                    r & ChildRef::MAX_NODE
                } else if (r as i64) >= 0 {
                    if leaf_or_part {
                        // A leaf: `count` triangles from the block at `unit`.
                        let (mut unit, mut left) = (r & ChildRef::MAX_UNIT, ((r >> 40) & 0xff) as u32);
                        while left > 0 {
                            let (found, blocks) =
                                self.test_blocks::<AVX, ANY>(OCT == GENERIC, &rt, &shared, unit, left, t_best);
                            match found {
                                Ok(None) => {}
                                Ok(Some((lane, h))) => {
                                    t_best = h.t;
                                    t_wide = h.t * FAR_EPS;
                                    // Lanes 4..8 are the second block's.
                                    w.best = Some(Found::new(h, c, unit + 9 * (lane / 4) as u64, lane % 4));
                                    if ANY {
                                        break 'walk Event::Hit;
                                    }
                                }
                                Err(Exact) => break 'walk Event::Exact { unit, count: left },
                            }
                            left = left.saturating_sub(4 * blocks);
                            unit += 9 * blocks as u64;
                        }
                        continue 'walk;
                    }
                    r & ChildRef::MAX_NODE
                } else {
                    // A link (tile, node; the top-level tree links to part roots), or an
                    // empty slot (all ones, the only reference of kind 3 a checked tile has).
                    if leaf_or_part {
                        continue 'walk;
                    }
                    let (arr, node) = (((r >> 36) as u32) & ChildRef::MAX_TILE, r & ChildRef::MAX_NODE);
                    if arr != c {
                        if self.checked.get(arr) {
                            // The common crossing: an unpaged tile already checked.
                            stats::count(|s| s.tiles_entered += 1);
                            c = arr;
                        } else {
                            // (`arr` of a link entry is not read: it names its own tile.)
                            next = Some(Entry { r, arr: c, t: f32::NEG_INFINITY });
                            break 'walk Event::Enter(arr);
                        }
                    }
                    node
                };
                // Read without a bounds check: node positions were checked with the tile.
                let node = self.walk_node_at(node);
                // The node's last line (its child references, which the box test does not
                // read) asked for with the boxes, not after the test has picked a child: a
                // second miss in a row on a node not in cache. bench/ab.sh, 6-8 rounds on an
                // Intel Xeon (2 MiB L2 per core): shadow +6-7% and diffuse +3-5% on
                // sphereflake:4@close, grid:1000 and stanford-bunny@close (an earlier session
                // had measured it neutral on an AMD Zen 4).
                let refs = std::mem::offset_of!(Node8, child);
                megaray_base::prefetch_addr((node as *const Node8 as *const u8).wrapping_add(refs));
                let arr = c;
                stats::count(|s| s.nodes += 1);
                let (dist, mask) = rb.test::<AVX>(node, t_min, t_wide);
                if mask == 0 {
                    continue 'walk;
                }
                let k0 = mask.trailing_zeros();
                let m1 = mask & (mask - 1);
                if m1 == 0 {
                    r = node.child[k0 as usize];
                    continue;
                }
                // Two or more children: pushes ahead. (Asked here, not at every node:
                // most visits go on into one child and push nothing.)
                if sp > STACK - W {
                    // No room for seven more entries: the node is visited again after
                    // the driver has made room.
                    next = Some(Entry { r, arr: c, t: f32::NEG_INFINITY });
                    break 'walk Event::Full;
                }
                // (An any-hit query reads no entry distance: none is kept.)
                let at =
                    |k: u32| Entry { r: node.child[k as usize], arr, t: if ANY { 0.0 } else { dist.0[k as usize] } };
                let mut push = |x: Entry| {
                    self.prefetch(x.r);
                    w.fixed[sp % STACK] = x;
                    sp += 1;
                };
                if ANY {
                    // Any hit ends the ray, so order matters less than the cost of sorting:
                    // the first child next, the others pushed as they come.
                    let mut m = m1;
                    while m != 0 {
                        push(at(m.trailing_zeros()));
                        m &= m - 1;
                    }
                    r = node.child[k0 as usize];
                    continue;
                }
                let (a, b) = (at(k0), at(m1.trailing_zeros()));
                let (near, far) = if b.t < a.t { (b, a) } else { (a, b) };
                let m2 = m1 & (m1 - 1);
                if m2 == 0 {
                    push(far);
                    r = near.r;
                    continue;
                }
                // Three or more: pushed as they come and sorted in place on the stack, far to
                // near (insertion sort, at most eight: no array of them to fill and copy);
                // the nearest, on top, is taken off again as the next to visit.
                push(far);
                push(near);
                let base = sp - 2;
                let mut m = m2;
                while m != 0 {
                    let x = at(m.trailing_zeros());
                    m &= m - 1;
                    self.prefetch(x.r);
                    let mut j = sp;
                    while j > base && w.fixed[(j - 1) % STACK].t < x.t {
                        w.fixed[j % STACK] = w.fixed[(j - 1) % STACK];
                        j -= 1;
                    }
                    w.fixed[j % STACK] = x;
                    sp += 1;
                }
                sp -= 1;
                r = w.fixed[sp % STACK].r;
            }
        };
        w.c = c;
        w.sp = sp;
        w.t_best = t_best;
        w.next = next;
        event
    }
}

/// [`Tracer::walk`] compiled for AVX2 (one [`Kernel`]): a function of its own, never inlined,
/// so that its registers are allocated for the loop alone. Free (not a method), so that it
/// is one function for tracers of every lifetime and fits the kernel table's type.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline(never)]
fn walk_avx2<const ANY: bool, const ALL: bool, const OCT: usize>(t: &Tracer<'_>, w: &mut Walk<'_>, ray: &Ray) -> Event {
    t.walk::<true, ANY, ALL, OCT>(w, ray)
}

/// [`walk_avx2`] compiled for AVX-512: the same operations (256 bits wide), but 32 vector
/// registers, so that the ray's constants stay in registers (with 16, four of them are kept
/// on the machine stack and reloaded at every node), and comparisons into mask registers.
/// bench/ab.sh against the AVX2 build on this project's Zen 4: stanford-bunny@close +8%
/// (primary, shadow, diffuse), grid:1000@close diffuse +5%, memory-bound sphereflake:4
/// unchanged.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
#[inline(never)]
fn walk_avx512<const ANY: bool, const ALL: bool, const OCT: usize>(
    t: &Tracer<'_>,
    w: &mut Walk<'_>,
    ray: &Ray,
) -> Event {
    t.walk::<true, ANY, ALL, OCT>(w, ray)
}

/// [`Tracer::new_ray`] compiled for AVX2, as [`walk_avx2`] is.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline(never)]
fn new_ray_avx2<const ANY: bool, const OCT: usize>(t: &Tracer<'_>, s: &mut Scratch, ray: &Ray) -> Option<Found> {
    t.new_ray::<true, ANY, OCT>(s, ray)
}

/// [`Tracer::new_ray`] compiled for AVX-512, as [`walk_avx512`] is.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
#[inline(never)]
fn new_ray_avx512<const ANY: bool, const OCT: usize>(t: &Tracer<'_>, s: &mut Scratch, ray: &Ray) -> Option<Found> {
    t.new_ray::<true, ANY, OCT>(s, ray)
}

/// [`Tracer::walk`] on the baseline instruction set (SSE2 on x86-64).
#[inline(never)]
fn walk_baseline<const ANY: bool, const ALL: bool>(t: &Tracer<'_>, w: &mut Walk<'_>, ray: &Ray) -> Event {
    t.walk::<false, ANY, ALL, { usize::MAX }>(w, ray)
}

/// The environment variable that turns the assembly kernel (`asm.rs`) off (`0`) or on (`1`,
/// the default where it runs), to compare it with the compiled kernels or rule it out.
pub const ASM_VAR: &str = "MEGARAY_ASM";

/// Whether [`ASM_VAR`] lets new rays run the assembly kernel (unset or empty: yes), or an
/// error naming the value when it is neither `0` nor `1`. (Front ends check it at start; the
/// tracer reads it once and takes a bad value as unset.)
pub fn asm_from_env() -> Result<bool, String> {
    let Some(v) = std::env::var_os(ASM_VAR) else {
        return Ok(true);
    };
    match v.to_string_lossy().trim() {
        "" | "1" | "on" => Ok(true),
        "0" | "off" => Ok(false),
        other => Err(format!("{ASM_VAR}: unknown value {other:?} (use 0 to turn the assembly kernel off, 1 for on)")),
    }
}

/// [`asm_from_env`], read once.
#[cfg_attr(not(all(target_arch = "x86_64", target_os = "linux")), allow(dead_code))]
fn asm_enabled() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| asm_from_env().unwrap_or(true))
}

/// The lanes of a block that hold triangles, when `left` triangles of a leaf remain.
#[inline(always)]
fn lanes(left: u32) -> u32 {
    if left >= 4 {
        0b1111
    } else {
        (1u32 << left) - 1
    }
}

/// The lanes of two blocks that hold triangles, when `left` triangles of a leaf remain.
#[inline(always)]
fn lanes8(left: u32) -> u32 {
    if left >= 8 {
        0xff
    } else {
        (1u32 << left) - 1
    }
}

/// The single-ray kernel's state between runs of its hot loop ([`Tracer::walk`]).
struct Walk<'a> {
    /// The traversal stack (entries `..sp`); what does not fit is spilled by the driver.
    fixed: &'a mut [Entry; STACK],
    /// The thread's [`Scratch::streak`].
    streak: &'a mut Streak,
    sp: usize,
    /// The entry to visit before popping (the one an [`Event`] interrupted).
    next: Option<Entry>,
    /// The tile open (whose tile an inner node or leaf popped is, [`TOP`] for the top-level
    /// tree): what a hit is credited to, and what a paged walk must ask for again.
    c: u32,
    /// The distance of the closest hit so far (the ray's end when none).
    t_best: f32,
    best: Option<Found>,
    /// Not run yet: the first run tests the scene's box before anything else
    /// ([`Tracer::walk_on`]).
    fresh: bool,
}

impl<'a> Walk<'a> {
    /// A new ray's walk from `root` (and so, first, through the scene's box).
    #[inline(always)]
    fn new(scratch: &'a mut Scratch, root: Entry, t_max: f32) -> Walk<'a> {
        let c = TOP;
        let Scratch { stack: fixed, streak } = scratch;
        Walk { fixed, streak, sp: 0, next: Some(root), c, t_best: t_max, best: None, fresh: true }
    }
}

/// How many new rays go without the test of the scene's box after one that entered it
/// ([`Tracer::walk_on`]): a view's rays come in tiles of neighbouring pixels, and a ray that
/// misses the box all the same costs its set-up (about a hundred instructions) and one node.
const SKIP_BOUNDS: u8 = 15;

/// How many new rays in a row of one octant make a thread use that octant's kernel
/// ([`Tracer::walk_on`]).
const STREAK_MIN: u8 = 4;

/// What a resumed ray had found before it stopped, and its [`Hit`] ([`Pending::hit`]).
type Prior = (Option<Found>, Option<Hit>);
const NO_PRIOR: Prior = (None, None);

/// What an unpaged tracer's driver can never end with.
const UNPAGED: &str = "an unpaged tracer never suspends";

/// A thread's memory for the single-ray kernel, kept from ray to ray (not made and zeroed
/// for each), in one thread-local ([`SCRATCH`]).
struct Scratch {
    /// The traversal stack.
    stack: [Entry; STACK],
    /// What the thread's recent new rays were like ([`Tracer::walk_on`]).
    streak: Streak,
}

/// What a thread's recent new rays were like, for the kernel's choices for its next ones.
#[derive(Clone, Copy, Debug)]
struct Streak {
    /// The octant of the thread's last new ray ([`Tracer::walk_on`]).
    octant: u8,
    /// How many new rays before it had the same octant.
    run: u8,
    /// How many more new rays go without the test of the scene's box ([`Tracer::walk_on`]).
    skip_bounds: u8,
}

impl Scratch {
    const NEW: Scratch = Scratch { stack: [Entry::ZERO; STACK], streak: Streak { octant: 0, run: 0, skip_bounds: 0 } };

    /// One for a thread whose own is taken (never: traversals do not nest).
    fn fresh() -> Scratch {
        Scratch::NEW
    }
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = const { RefCell::new(Scratch::NEW) };
}

/// Why the hot loop returned to the driver.
#[derive(Clone, Copy, Debug)]
enum Event {
    /// The stack is empty (the driver refills it from its spill, or the ray is done).
    Empty,
    /// An any-hit query found a hit.
    Hit,
    /// [`Walk::next`] needs node array `arr` opened (through [`Tracer::enter`]).
    Enter(u32),
    /// An edge exactly on the ray in the block at `unit` of a leaf, `count` triangles from
    /// there to its end, left to the double-precision reference.
    Exact { unit: u64, count: u32 },
    /// The fixed stack has no room for a node's children.
    Full,
}

/// The closest hit so far of the single-ray kernel, as little as the hot loop needs to
/// write: which lane of which block (of which tile), and the test's results. Made a [`Hit`]
/// at the end ([`Tracer::hit_of`]).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Found {
    t: f32,
    u: f32,
    v: f32,
    /// The block's tile, or [`TOP`] when the walk kept none (found then from `unit`).
    arr: u32,
    lane: u32,
    /// The block's position (`offset / 16`).
    unit: u64,
}

impl Found {
    #[inline(always)]
    fn new(h: TriHit, arr: u32, unit: u64, lane: usize) -> Found {
        Found { t: h.t, u: h.u, v: h.v, arr, lane: lane as u32, unit }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use megaray_scene::format::Tri4;

    struct Rng(u64);
    impl Rng {
        fn f(&mut self) -> f32 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (self.0 >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        }
        fn v(&mut self) -> Vec3 {
            Vec3::new(self.f(), self.f(), self.f())
        }

        /// `n` random triangles, a ray origin, and targets for rays from it: a random
        /// point, then every vertex and edge midpoint of the triangles.
        fn case(&mut self, n: usize) -> (Vec<[[f32; 3]; 3]>, Vec3, Vec<Vec3>) {
            let tris: Vec<[[f32; 3]; 3]> =
                (0..n).map(|_| [self.v().into(), self.v().into(), self.v().into()]).collect();
            let org = self.v() * 3.0;
            let mut targets = vec![self.v() * 0.5];
            for t in &tris {
                let [a, b, c] = t.map(Vec3::from);
                targets.extend([a, b, c, (a + b) * 0.5, (b + c) * 0.5, (a + c) * 0.5]);
            }
            (tris, org, targets)
        }
    }

    /// The 4-wide triangle test gives exactly the scalar reference's hits, on random rays and
    /// on rays aimed exactly at vertices and edge midpoints.
    #[test]
    fn block_test_equals_scalar_reference() {
        let mut rng = Rng(3);
        let mut checked = 0;
        for _ in 0..2000 {
            let (tris, org, targets) = rng.case(4);
            let mut b = Tri4 { v: [[0.0; 4]; 9] };
            for (l, t) in tris.iter().enumerate() {
                b.set(l, t);
            }
            for target in targets {
                let ray = Ray::new(org, target - org);
                let rt = RayTri4::new(&ray);
                for lanes in [0b1111u32, 0b0111, 0b0001] {
                    let got = rt.test(&b.v, lanes, f32::INFINITY);
                    let want = rt.scalar(&b.v, lanes, f32::INFINITY);
                    assert_eq!(got.map(|g| g.1), want.map(|w| w.1), "ray {ray:?} lanes {lanes:b}");
                    // The form reading its rows by the ray's axes: the same, Exact included.
                    let (fixed, dyn_rows) = (
                        rt.try_test(&rt.own, &b.v, lanes, f32::INFINITY),
                        rt.try_test_dyn(&rt.own, &b.v, lanes, f32::INFINITY),
                    );
                    assert_eq!(fixed.map_err(|_| ()), dyn_rows.map_err(|_| ()), "ray {ray:?} lanes {lanes:b}");
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

    /// The 8-wide test of two blocks gives exactly the scalar reference's nearest hit of the
    /// eight lanes (an any-hit query: the first block's nearest when it has one), or leaves
    /// the decision to it ([`Exact`]) only where an edge lies exactly on the ray, on random
    /// rays and on rays aimed exactly at vertices and edge midpoints.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn two_block_test_equals_scalar_reference() {
        if !packet::Isa::available().contains(&packet::Isa::Avx2) {
            return;
        }
        let mut rng = Rng(5);
        let (mut checked, mut exact) = (0, 0);
        for _ in 0..1000 {
            let (tris, org, targets) = rng.case(8);
            let mut b = [Tri4 { v: [[0.0; 4]; 9] }, Tri4 { v: [[0.0; 4]; 9] }];
            for (l, t) in tris.iter().enumerate() {
                b[l / 4].set(l % 4, t);
            }
            for target in targets {
                let ray = Ray::new(org, target - org);
                let rt = RayTri4::new(&ray);
                for lanes in [0xffu32, 0x7f, 0x1f] {
                    // The reference: each block in turn, the second against the first's hit.
                    let first = rt.scalar(&b[0].v, lanes & 0xf, f32::INFINITY);
                    let second = rt.scalar(&b[1].v, lanes >> 4, first.map_or(f32::INFINITY, |h| h.1.t));
                    let nearest = second.map(|(l, h)| (l + 4, h)).or(first);
                    let any = first.or(second.map(|(l, h)| (l + 4, h)));
                    let cases = [
                        (rt.try_test8::<false>(&rt.own, &b[0].v, &b[1].v, lanes, f32::INFINITY), nearest),
                        (rt.try_test8::<true>(&rt.own, &b[0].v, &b[1].v, lanes, f32::INFINITY), any),
                        (rt.try_test8_dyn::<false>(&rt.own, &b[0].v, &b[1].v, lanes, f32::INFINITY), nearest),
                        (rt.try_test8_dyn::<true>(&rt.own, &b[0].v, &b[1].v, lanes, f32::INFINITY), any),
                    ];
                    for (got, want) in cases {
                        match got {
                            Ok(got) => assert_eq!(got, want, "ray {ray:?} lanes {lanes:b}"),
                            Err(Exact) => exact += 1,
                        }
                        checked += 1;
                    }
                }
            }
        }
        // Most targets are vertices and edges: the lanes aimed at leave many to the reference.
        assert!(checked - exact > 100_000, "{checked} checked, {exact} left to the reference");
    }

    /// The dominant axis found without branches is the reference's, ties, zeros, infinities
    /// and NaNs included; and the constants made by indexing equal those made by branches.
    #[test]
    fn unbranched_axis_equals_reference() {
        let vals = [0.0f32, -0.0, 1.0, -1.0, 2.0, -2.0, 1e-30, f32::INFINITY, f32::NAN, 0.5];
        for &x in &vals {
            for &y in &vals {
                for &z in &vals {
                    let ray = Ray::new(Vec3::new(0.25, -0.5, 2.0), Vec3::new(x, y, z));
                    let kz = RayTri4::dominant(&ray);
                    assert_eq!(RayTri4::dominant_unbranched(&ray), kz, "{ray:?}");
                    assert_eq!(kz, WatertightRay::new(&ray).k[2], "{ray:?}");
                    let inv = RayBox::new(&ray).inv;
                    let (a, b) = (RayTri4::with_axis(&ray, &inv, kz), RayTri4::with_axis_unbranched(&ray, &inv));
                    let bits =
                        |r: &RayTri4| (r.kz, r.kb, [r.s, r.ok].map(|v| v.map(|l| l.to_array().map(f32::to_bits))));
                    assert_eq!(bits(&a), bits(&b), "{ray:?}");
                    #[cfg(target_arch = "x86_64")]
                    if std::arch::is_x86_feature_detected!("avx") {
                        // SAFETY: the CPU has AVX (just checked).
                        let c = unsafe { RayTri4::with_axis_avx(&ray, Vec3A::from_array(inv)) };
                        assert_eq!(bits(&a), bits(&c), "{ray:?}");
                    }
                }
            }
        }
    }

    /// The AVX box test (distances compared as integers) gives the SSE reference's mask and
    /// entry distances: on random boxes, on empty and flat ones, on rays of every octant
    /// with components of zero, and on origins exactly on a plane (distances of zero, whose
    /// sign decides an exit there).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn box_test_avx_equals_sse_reference() {
        if !packet::Isa::available().contains(&packet::Isa::Avx2) {
            return;
        }
        let mut rng = Rng(7);
        let (mut checked, mut hits, mut on_plane) = (0, 0, 0);
        for case in 0..20_000 {
            let mut n = Node8::EMPTY;
            for i in 0..W {
                match case % 5 + i {
                    // Empty slots, and flat boxes (one axis of no extent).
                    7 => continue,
                    3 => {
                        let (a, b) = (rng.v(), rng.v());
                        let mut b = megaray_base::Aabb { min: a.min(b).into(), max: a.max(b).into() };
                        b.max[i % 3] = b.min[i % 3];
                        n.set(i, &b, i as u64);
                    }
                    _ => {
                        let (a, b) = (rng.v(), rng.v());
                        n.set(i, &megaray_base::Aabb { min: a.min(b).into(), max: a.max(b).into() }, i as u64);
                    }
                }
            }
            let mut org = rng.v() * 1.5;
            if case % 3 == 0 {
                // The origin on a plane of a slot (when not empty).
                let (k, i) = (case / 3 % 6, case % W);
                let p = n.planes()[k][i];
                if p.is_finite() {
                    org[k / 2] = p;
                    on_plane += 1;
                }
            }
            let mut dir = rng.v();
            if case % 7 == 0 {
                dir[case % 3] = if case % 2 == 0 { 0.0 } else { -0.0 };
            }
            let ray = Ray::new(org, dir);
            let rb = RayBox::new(&ray);
            for (t0, t1) in [(0.0, f32::INFINITY), (0.0, 0.5), (0.25, 1.0 * FAR_EPS), (0.0, 0.0)] {
                let (want_d, want) = rb.test_sse(&n, t0, t1);
                // SAFETY: the CPU has AVX2 and FMA (checked above).
                let (got_d, got) = unsafe { rb.test_avx2(&n, t0, t1) };
                assert_eq!(got, want, "ray {ray:?} in [{t0}, {t1}], node {n:?}");
                for i in 0..W {
                    if want & (1 << i) != 0 {
                        assert_eq!(got_d.0[i], want_d.0[i], "slot {i}, ray {ray:?}");
                    }
                }
                hits += want.count_ones();
                checked += 1;
            }
        }
        assert!(checked == 80_000 && hits > 10_000 && on_plane > 3_000, "{checked} {hits} {on_plane}");
    }
}
