//! Packet traversal: 16 coherent rays (a 4x4 pixel block) walk the tree together. Each node's
//! eight boxes are tested against all 16 rays, one box at a time across the rays, so a node is
//! fetched and decoded once for the packet and the box arithmetic runs 16 rays wide. Leaves
//! are tested one triangle against all 16 rays at once when the rays share the watertight
//! test's axis permutation ([`PacketTri`]), else ray by ray.
//!
//! The kernel is written once, as plain loops over the 16 lanes ([`traverse`]), and compiled
//! three times: for AVX-512, for AVX2 and for the baseline (SSE2 on x86-64), which the compiler
//! vectorizes to its widest registers. The tracer's [`Kernels`](crate::Kernels) choose one; the tests
//! check every path the machine supports against single-ray traversal.

use megaray_base::{Rays16, TriHit, WatertightRay};
use megaray_scene::format::Node8;

use crate::boxes::{fmax, fmin, BOX_EPS, W};
use crate::isa::Isa;
use crate::tracer::{Entry, Step, Tracer, TOP};
use crate::tri::{corners, Block, RayTri4};
use crate::walk::Found;
use crate::Hit;

/// Rays in a packet.
pub const WIDTH: usize = 16;

/// The packet's rays, structure of arrays.
struct Packet {
    ox: [f32; WIDTH],
    oy: [f32; WIDTH],
    oz: [f32; WIDTH],
    ix: [f32; WIDTH],
    iy: [f32; WIDTH],
    iz: [f32; WIDTH],
    t_min: [f32; WIDTH],
    /// Current closest hit distance per ray (the ray's `t_max` at first).
    t_max: [f32; WIDTH],
}

/// Bounds of a packet's rays for a test of a node's eight boxes against all of them at once
/// (interval arithmetic, as in Wald et al., "Ray tracing deformable scenes using dynamic
/// bounding volume hierarchies", 2007): which children no ray can enter, before the per-ray
/// tests. Conservative by construction: every per-ray slab distance is
/// `fl(fl(plane - o) * inv)`, which is monotone in `o` and in `inv`, so its extremes over
/// the packet are those of the corners of the bounds of `o` and `inv`, computed with the same
/// operations; a child that passes a per-ray test passes this one.
struct Frustum {
    o_lo: [f32; 3],
    o_hi: [f32; 3],
    i_lo: [f32; 3],
    i_hi: [f32; 3],
    /// Per axis: 1 when every ray runs forward along it (its near plane is the box's low
    /// one), -1 when every ray runs backward, 0 when they differ.
    sign: [i8; 3],
    /// The smallest `t_min` of the rays.
    t_min: f32,
}

impl Frustum {
    /// The bounds of the rays of `p` (whose unused lanes repeat ray 0). Plain loops over
    /// the 16 lanes, which the compiler vectorizes.
    fn new(p: &Packet) -> Frustum {
        let mut f = Frustum {
            o_lo: [0.0; 3],
            o_hi: [0.0; 3],
            i_lo: [0.0; 3],
            i_hi: [0.0; 3],
            sign: [0; 3],
            t_min: min16(&p.t_min),
        };
        let axes = [(&p.ox, &p.ix), (&p.oy, &p.iy), (&p.oz, &p.iz)];
        for (a, (o, inv)) in axes.into_iter().enumerate() {
            (f.o_lo[a], f.o_hi[a]) = (min16(o), max16(o));
            (f.i_lo[a], f.i_hi[a]) = (min16(inv), max16(inv));
            // Reciprocals are never zero (directions are fixed away from zero first).
            f.sign[a] = if f.i_lo[a] > 0.0 {
                1
            } else if f.i_hi[a] < 0.0 {
                -1
            } else {
                0
            };
        }
        f
    }

    /// The children of `node` that some ray may enter before `t_max` (the largest of the
    /// rays' closest distances), as a bit mask: a superset of what the per-ray tests find.
    /// Eight children at once, in plain loops the compiler vectorizes.
    #[inline(always)]
    fn cull(&self, node: &Node8, t_max: f32) -> u32 {
        let mut tn = [self.t_min; W];
        let mut tf = [t_max; W];
        let planes = [(&node.lo_x, &node.hi_x), (&node.lo_y, &node.hi_y), (&node.lo_z, &node.hi_z)];
        for (a, (lo, hi)) in planes.into_iter().enumerate() {
            let (olo, ohi, ilo, ihi) = (self.o_lo[a], self.o_hi[a], self.i_lo[a], self.i_hi[a]);
            // The least and greatest slab distance of a plane over the packet.
            let range = |q: f32| {
                let (d0, d1) = (q - ohi, q - olo);
                let (x0, x1, x2, x3) = (d0 * ilo, d0 * ihi, d1 * ilo, d1 * ihi);
                (fmin(fmin(x0, x1), fmin(x2, x3)), fmax(fmax(x0, x1), fmax(x2, x3)))
            };
            match self.sign[a] {
                // One direction for all: the near plane is known (for a box, whose low
                // plane is not above its high one, the per-ray `min` picks it).
                1 => {
                    for k in 0..W {
                        tn[k] = fmax(tn[k], range(lo[k]).0);
                        tf[k] = fmin(tf[k], range(hi[k]).1);
                    }
                }
                -1 => {
                    for k in 0..W {
                        tn[k] = fmax(tn[k], range(hi[k]).0);
                        tf[k] = fmin(tf[k], range(lo[k]).1);
                    }
                }
                _ => {
                    for k in 0..W {
                        let (a0, a1) = range(lo[k]);
                        let (b0, b1) = range(hi[k]);
                        tn[k] = fmax(tn[k], fmin(a0, b0));
                        tf[k] = fmin(tf[k], fmax(a1, b1));
                    }
                }
            }
        }
        let mut m = 0;
        for h in 0..W / 4 {
            let n = glam::Vec4::from_slice(&tn[4 * h..4 * h + 4]);
            let f = glam::Vec4::from_slice(&tf[4 * h..4 * h + 4]) * BOX_EPS;
            m |= n.cmple(f).bitmask() << (4 * h);
        }
        m
    }
}

/// The least of 16 values, by halving (vector `min`s).
#[inline(always)]
fn min16(v: &[f32; WIDTH]) -> f32 {
    halve16(v, fmin)
}

/// The greatest of 16 values, by halving.
#[inline(always)]
fn max16(v: &[f32; WIDTH]) -> f32 {
    halve16(v, fmax)
}

/// `op` over 16 values by halving: each step folds the upper half onto the lower one (plain
/// loops the compiler vectorizes).
#[inline(always)]
fn halve16(v: &[f32; WIDTH], op: impl Fn(f32, f32) -> f32) -> f32 {
    let mut m = *v;
    let mut w = WIDTH / 2;
    while w > 0 {
        for i in 0..w {
            m[i] = op(m[i], m[i + w]);
        }
        w /= 2;
    }
    m[0]
}

/// The watertight test's per-ray constants across a packet (structure of arrays), for
/// packets whose rays all share the test's dominant axis `kz` (coherent rays do): then one
/// triangle is tested against all 16 rays at once ([`PacketTri::test`]). As in
/// [`RayTri4`], the other axes are `kz + 1` and `kz + 2` (mod 3) without the reference's
/// swap, which changes no result.
struct PacketTri {
    kz: usize,
    ox: [f32; WIDTH],
    oy: [f32; WIDTH],
    oz: [f32; WIDTH],
    sx: [f32; WIDTH],
    sy: [f32; WIDTH],
    sz: [f32; WIDTH],
    t_min: [f32; WIDTH],
}

/// A triangle as a packet's hits record it: its tile and its block and lane as [`Found16`]
/// holds them (`at_lo`, `at_hi`).
#[derive(Clone, Copy)]
struct Taken {
    arr: u32,
    at: u64,
}

impl PacketTri {
    /// `None` unless every ray has the same dominant axis. `rays`' unused lanes repeat
    /// ray 0.
    // Lane loops index several arrays in step (the form that vectorizes).
    #[allow(clippy::needless_range_loop)]
    fn new(rays: &Rays16) -> Option<PacketTri> {
        let kz = WatertightRay::new(&rays.ray(0)).k[2];
        let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
        let (d, o, t_min) = (&rays.dir, &rays.org, rays.t_min);
        // Every lane's axis must be ray 0's: `WatertightRay::new`'s comparisons, branch-free,
        // over all lanes at once.
        let mut differ = 0u32;
        for i in 0..WIDTH {
            let (ax, ay, az) = (d[0][i].abs(), d[1][i].abs(), d[2][i].abs());
            let k = if ax > ay {
                if ax > az {
                    0
                } else {
                    2
                }
            } else if ay > az {
                1
            } else {
                2
            };
            differ |= (k != kz) as u32;
        }
        if differ != 0 {
            return None;
        }
        let mut p = PacketTri {
            kz,
            ox: o[kx],
            oy: o[ky],
            oz: o[kz],
            sx: [0.0; WIDTH],
            sy: [0.0; WIDTH],
            sz: [0.0; WIDTH],
            t_min,
        };
        for i in 0..WIDTH {
            // As `WatertightRay::new`: sz = 1 / d[kz], then d[kx] * sz and d[ky] * sz.
            p.sz[i] = 1.0 / d[kz][i];
            p.sx[i] = d[kx][i] * p.sz[i];
            p.sy[i] = d[ky][i] * p.sz[i];
        }
        Some(p)
    }

    /// [`PacketTri::test_k`] for this packet's axes.
    #[inline(always)]
    fn test(
        &self,
        b: &Block,
        lane: usize,
        live: &[bool; WIDTH],
        hit: Taken,
        t_max: &mut [f32; WIDTH],
        res: &mut Found16,
    ) -> u32 {
        match self.kz {
            0 => self.test_k::<1, 2, 0>(b, lane, live, hit, t_max, res),
            1 => self.test_k::<2, 0, 1>(b, lane, live, hit, t_max, res),
            _ => self.test_k::<0, 1, 2>(b, lane, live, hit, t_max, res),
        }
    }

    /// Lane `lane` of block `b` against the `live` rays: per ray exactly the operations of
    /// `RayTri4::test` (and so of the scalar reference), in plain loops over the 16 rays
    /// that the compiler vectorizes. The rays that hit it nearer than their `t_max` take it
    /// (`hit` into `res`, selects across the lanes: no branch); returned are the rays that
    /// must take the reference's double-precision path instead (an edge function exactly
    /// zero).
    // Lane loops index several arrays in step (the form that vectorizes).
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn test_k<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        b: &Block,
        lane: usize,
        live: &[bool; WIDTH],
        hit: Taken,
        t_max: &mut [f32; WIDTH],
        res: &mut Found16,
    ) -> u32 {
        let (kx, ky, kz) = (KX, KY, KZ);
        let c = |corner: usize, k: usize| b[3 * corner + k][lane];
        let (a_x, a_y, a_z) = (c(0, kx), c(0, ky), c(0, kz));
        let (b_x, b_y, b_z) = (c(1, kx), c(1, ky), c(1, kz));
        let (c_x, c_y, c_z) = (c(2, kx), c(2, ky), c(2, kz));
        let mut exact = [false; WIDTH];
        for r in 0..WIDTH {
            let (ox, oy, oz) = (self.ox[r], self.oy[r], self.oz[r]);
            let (sx, sy, sz) = (self.sx[r], self.sy[r], self.sz[r]);
            let az = a_z - oz;
            let bz = b_z - oz;
            let cz = c_z - oz;
            let ax = (a_x - ox) - sx * az;
            let ay = (a_y - oy) - sy * az;
            let bx = (b_x - ox) - sx * bz;
            let by = (b_y - oy) - sy * bz;
            let cx = (c_x - ox) - sx * cz;
            let cy = (c_y - oy) - sy * cz;
            let u = cx * by - cy * bx;
            let v = ax * cy - ay * cx;
            let w = bx * ay - by * ax;
            // Bitwise `|` and `&`, not short-circuits: branch-free, so the loop vectorizes.
            exact[r] = (u == 0.0) | (v == 0.0) | (w == 0.0);
            // With no edge function zero (else the ray is `exact`), they agree in sign (the
            // reference's `!((u < 0 || v < 0 || w < 0) && (u > 0 || ..))`) exactly when their
            // sign bits do; and then their sum, the determinant, is not zero either (the
            // reference's `det == 0` test never rejects such a ray).
            let (su, sv, sw) = (u.to_bits(), v.to_bits(), w.to_bits());
            let agree = ((su ^ sv) | (su ^ sw)) >> 31 == 0;
            let det = u + v + w;
            let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
            let inv_det = 1.0 / det;
            let t = t_scaled * inv_det;
            let ok = agree & (t >= self.t_min[r]) & (t < t_max[r]) & !exact[r] & live[r];
            t_max[r] = if ok { t } else { t_max[r] };
            res.u[r] = if ok { v * inv_det } else { res.u[r] };
            res.v[r] = if ok { w * inv_det } else { res.v[r] };
            res.arr[r] = if ok { hit.arr } else { res.arr[r] };
            res.at_lo[r] = if ok { hit.at as u32 } else { res.at_lo[r] };
            res.at_hi[r] = if ok { (hit.at >> 32) as u32 } else { res.at_hi[r] };
        }
        let mut m = 0;
        for r in 0..WIDTH {
            m |= (exact[r] as u32) << r;
        }
        m
    }
}

/// Kernel flavours: how [`le_mask`] is computed (everything else is the same code).
const BASE: u8 = 0;
const AVX512: u8 = 2;

/// The bits `r` for which `a[r] <= b[r]`: one compare into a mask register on AVX-512, four
/// 4-wide compares and `movmskps` otherwise (LLVM does not find either in a plain loop).
#[inline(always)]
fn le_mask<const ISA: u8>(a: &[f32; WIDTH], b: &[f32; WIDTH]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if ISA == AVX512 {
        // SAFETY: the AVX512 flavour is only instantiated in `traverse_avx512`, which runs
        // only on CPUs that reported AVX-512F.
        return unsafe { le_mask_avx512(a, b) };
    }
    let mut m = 0;
    for q in 0..WIDTH / 4 {
        let x = glam::Vec4::from_slice(&a[4 * q..4 * q + 4]);
        let y = glam::Vec4::from_slice(&b[4 * q..4 * q + 4]);
        m |= x.cmple(y).bitmask() << (4 * q);
    }
    m
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
fn le_mask_avx512(a: &[f32; WIDTH], b: &[f32; WIDTH]) -> u32 {
    use std::arch::x86_64::*;
    // SAFETY: both arrays hold sixteen readable f32s.
    let (x, y) = unsafe { (_mm512_loadu_ps(a.as_ptr()), _mm512_loadu_ps(b.as_ptr())) };
    _mm512_cmp_ps_mask::<_CMP_LE_OQ>(x, y) as u32
}

/// A packet stack entry: a child, the rays that entered its box and each ray's entry
/// distance. 64-byte aligned with the distances first, so that they are loaded and stored
/// as one vector within one cache line (at 96 bytes, most entries' distances straddled two
/// lines, and the load right after a push could not take the stored vector).
#[repr(C, align(64))]
#[derive(Clone, Copy)]
pub(crate) struct PacketEntry {
    dist: [f32; WIDTH],
    e: Entry,
    rays: u32,
}

const _: () = assert!(std::mem::size_of::<PacketEntry>() == 128);

/// The packet stack, kept by the caller across packets (no allocation per packet).
pub(crate) type PacketStack = Vec<PacketEntry>;

/// Traces up to 16 rays as one packet with the given instruction set, on `stack` (left empty).
pub(crate) fn intersect16(tracer: &Tracer, rays: &Rays16, hits: &mut [Option<Hit>], isa: Isa, stack: &mut PacketStack) {
    debug_assert!(rays.len <= WIDTH && rays.len == hits.len());
    match isa {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx512` is only produced by `detect`/`available` after
        // `is_x86_feature_detected!("avx512f")` said this CPU has it.
        Isa::Avx512 => unsafe { traverse_avx512(tracer, rays, hits, stack) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx2` is only produced after the CPU reported AVX2 and FMA.
        Isa::Avx2 => unsafe { traverse_avx2(tracer, rays, hits, stack) },
        _ => traverse::<BASE>(tracer, rays, hits, stack),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
unsafe fn traverse_avx512(tracer: &Tracer, rays: &Rays16, hits: &mut [Option<Hit>], stack: &mut PacketStack) {
    traverse::<AVX512>(tracer, rays, hits, stack)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn traverse_avx2(tracer: &Tracer, rays: &Rays16, hits: &mut [Option<Hit>], stack: &mut PacketStack) {
    traverse::<BASE>(tracer, rays, hits, stack)
}

/// The packet kernel. Every result equals [`Tracer::intersect`] on the same ray: the box tests
/// only decide which nodes are visited (conservatively, as in the single-ray kernel), and the
/// triangle tests are the single-ray ones.
#[inline(always)]
fn traverse<const ISA: u8>(tracer: &Tracer, rays: &Rays16, hits: &mut [Option<Hit>], stack: &mut PacketStack) {
    let n = rays.len;
    crate::stats::count(|s| s.rays += n as u64);
    // Unused lanes repeat ray 0 (they never enter a box: their `t_max` is -inf), so that
    // the packet's bounds can be taken over all 16 lanes.
    let mut q = *rays;
    // A negative `t_min` counts as 0 ([`Ray::t_min`](megaray_base::Ray::t_min)).
    q.t_min = q.t_min.map(megaray_base::t_start);
    for i in n..WIDTH {
        for a in 0..3 {
            (q.org[a][i], q.dir[a][i]) = (q.org[a][0], q.dir[a][0]);
        }
        (q.t_min[i], q.t_max[i]) = (q.t_min[0], f32::NEG_INFINITY);
    }
    let rays = &q;
    let fix = |d: f32| if d.abs() < 1e-20 { 1e-20f32.copysign(d) } else { d };
    let mut p = Packet {
        ox: q.org[0],
        oy: q.org[1],
        oz: q.org[2],
        ix: [0.0; WIDTH],
        iy: [0.0; WIDTH],
        iz: [0.0; WIDTH],
        t_min: q.t_min,
        t_max: q.t_max,
    };
    for i in 0..WIDTH {
        p.ix[i] = 1.0 / fix(q.dir[0][i]);
        p.iy[i] = 1.0 / fix(q.dir[1][i]);
        p.iz[i] = 1.0 / fix(q.dir[2][i]);
    }
    // Each ray's closest hit so far, recorded without its part, slot and corners, which are
    // looked up once at the end.
    let mut res = Found16 {
        u: [0.0; WIDTH],
        v: [0.0; WIDTH],
        at_lo: [u32::MAX; WIDTH],
        at_hi: [u32::MAX; WIDTH],
        arr: [0; WIDTH],
    };
    // Coherent packets test each triangle against all their rays at once (the constants
    // are made when the first leaf with several rays is reached).
    let mut coherent: Option<Option<PacketTri>> = None;
    // Entries with the mask of the rays that entered their box and each ray's entry
    // distance (kept per ray, as Embree's hybrid traversal does: no reduction across rays).
    let frustum = Frustum::new(&p);
    stack.clear();
    stack.push(PacketEntry { dist: [f32::NEG_INFINITY; WIDTH], e: tracer.root, rays: (1u32 << n) - 1 });
    let mut c = TOP;
    while let Some(PacketEntry { dist, e, rays: rays_in }) = stack.pop() {
        // Skip the rays that have found something nearer since, and the entry if all have.
        let t_far = p.t_max.map(|t| t * BOX_EPS);
        let live = rays_in & le_mask::<ISA>(&dist, &t_far);
        if live == 0 {
            continue;
        }
        let (node, arr) = match tracer.step(&mut c, &e) {
            Step::Node(node, arr) => (node, arr),
            Step::Leaf { unit, count }
                if live.count_ones() > 2 && coherent.get_or_insert_with(|| PacketTri::new(rays)).is_some() =>
            {
                // Triangle by triangle, against all rays; hits update each ray's closest.
                let pt = coherent.as_ref().and_then(|c| c.as_ref()).expect("checked");
                let mut live_b = [false; WIDTH];
                for (r, l) in live_b.iter_mut().enumerate() {
                    *l = live & (1 << r) != 0;
                }
                for i in 0..count {
                    let (blk, lane) = (i / 4, (i % 4) as usize);
                    let b_unit = unit + 9 * blk as u64;
                    let b = tracer.block_at(b_unit);
                    crate::stats::count(|s| s.blocks += (lane == 0) as u64);
                    let at = (b_unit << 2) | lane as u64;
                    let exact = pt.test(b, lane, &live_b, Taken { arr: c, at }, &mut p.t_max, &mut res);
                    // An edge exactly on the ray: the reference's double-precision path.
                    let mut m = exact & live;
                    while m != 0 {
                        let r = m.trailing_zeros() as usize;
                        m &= m - 1;
                        if let Some(t) = WatertightRay::new(&rays.ray(r)).intersect(&corners(b, lane), p.t_max[r]) {
                            res.record(r, t, Taken { arr: c, at }, &mut p.t_max);
                        }
                    }
                }
                continue;
            }
            Step::Leaf { unit, count } => {
                // Each ray that entered the box tests the triangles.
                let mut m = live;
                while m != 0 {
                    let r = m.trailing_zeros() as usize;
                    m &= m - 1;
                    // Made per leaf: cheaper than keeping 16 of them (3 KiB to initialise).
                    let rt = RayTri4::new(&rays.ray(r));
                    let mut left = count;
                    let mut blk = 0;
                    while left > 0 {
                        let lanes = if left >= 4 { 0b1111 } else { (1u32 << left) - 1 };
                        let b_unit = unit + 9 * blk as u64;
                        let b = tracer.block_at(b_unit);
                        crate::stats::count(|s| s.blocks += 1);
                        if let Some((lane, h)) = rt.test(b, lanes, p.t_max[r]) {
                            res.record(r, h, Taken { arr: c, at: (b_unit << 2) | lane as u64 }, &mut p.t_max);
                        }
                        left = left.saturating_sub(4);
                        blk += 1;
                    }
                }
                continue;
            }
            // Packets run on unpaged tracers only: nothing is ever missing.
            Step::Skip | Step::Missing(_) => continue,
        };
        crate::stats::count(|s| s.nodes += 1);
        // Box k against all rays: the mask of rays that enter it, and their entry distances.
        // Children hit go straight onto the stack, sorted there far to near (the nearest on
        // top); no staging array to initialise.
        let base = stack.len();
        // The children some ray may enter, by the packet's bounds; only those are tested ray
        // by ray. (This also culls empty slots, whose inverted box the per-ray form below
        // would let through, in packets whose rays agree in direction per axis.)
        let t_hi = max16(&p.t_max);
        let mut cand = frustum.cull(node, t_hi);
        while cand != 0 {
            let k = cand.trailing_zeros() as usize;
            cand &= cand - 1;
            let (lx, hx) = (node.lo_x[k], node.hi_x[k]);
            let (ly, hy) = (node.lo_y[k], node.hi_y[k]);
            let (lz, hz) = (node.lo_z[k], node.hi_z[k]);
            let mut t0 = [0f32; WIDTH];
            let mut t1 = [0f32; WIDTH];
            for r in 0..WIDTH {
                let ax = (lx - p.ox[r]) * p.ix[r];
                let bx = (hx - p.ox[r]) * p.ix[r];
                let ay = (ly - p.oy[r]) * p.iy[r];
                let by = (hy - p.oy[r]) * p.iy[r];
                let az = (lz - p.oz[r]) * p.iz[r];
                let bz = (hz - p.oz[r]) * p.iz[r];
                t0[r] = fmax(fmax(fmax(fmin(ax, bx), fmin(ay, by)), fmin(az, bz)), p.t_min[r]);
                t1[r] = fmin(fmin(fmin(fmax(ax, bx), fmax(ay, by)), fmax(az, bz)), p.t_max[r]) * BOX_EPS;
            }
            let m = le_mask::<ISA>(&t0, &t1) & live;
            if m == 0 {
                continue;
            }
            // Children ordered far to near by the entry distance of their first ray (an
            // order for speed only; culling uses every ray's own distance).
            let key = t0[m.trailing_zeros() as usize];
            tracer.prefetch(node.child[k]);
            stack.push(PacketEntry { dist: t0, e: Entry { r: node.child[k], arr, t: key }, rays: m });
            let mut j = stack.len() - 1;
            while j > base && stack[j - 1].e.t < key {
                stack.swap(j - 1, j);
                j -= 1;
            }
        }
    }
    for (r, hit) in hits.iter_mut().take(n).enumerate() {
        let at = (res.at_hi[r] as u64) << 32 | res.at_lo[r] as u64;
        if at == NONE {
            *hit = None;
            continue;
        }
        let h = TriHit { t: p.t_max[r], u: res.u[r], v: res.v[r] };
        *hit = tracer.hit_of(Some(Found::new(h, res.arr[r], at >> 2, (at & 3) as usize)));
    }
}

/// What [`Found16`]'s `at_lo` and `at_hi` hold, joined, for a ray that has hit nothing.
const NONE: u64 = u64::MAX;

/// The closest hit so far of each ray of a packet (its distance is the ray's `t_max`).
struct Found16 {
    u: [f32; WIDTH],
    v: [f32; WIDTH],
    /// The unit of the hit triangle's block, times 4, plus its lane, in its low and high
    /// 32 bits (so that every lane of the selects is 32 bits wide); [`NONE`] for none yet.
    at_lo: [u32; WIDTH],
    at_hi: [u32; WIDTH],
    /// The tile the block lies in.
    arr: [u32; WIDTH],
}

impl Found16 {
    /// Ray `r` hits triangle `hit` as `h`, nearer than before.
    #[inline(always)]
    fn record(&mut self, r: usize, h: TriHit, hit: Taken, t_max: &mut [f32; WIDTH]) {
        t_max[r] = h.t;
        (self.u[r], self.v[r], self.arr[r]) = (h.u, h.v, hit.arr);
        (self.at_lo[r], self.at_hi[r]) = (hit.at as u32, (hit.at >> 32) as u32);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isa_names_parse_to_what_this_machine_has() {
        assert_eq!(Isa::parse("baseline"), Ok(Isa::Baseline));
        assert_eq!(Isa::parse(" Scalar "), Ok(Isa::Baseline));
        for (name, isa) in [("avx2", Isa::Avx2), ("AVX512", Isa::Avx512)] {
            match Isa::available().contains(&isa) {
                true => assert_eq!(Isa::parse(name), Ok(isa)),
                false => assert!(Isa::parse(name).unwrap_err().contains("cannot run"), "{name}"),
            }
        }
        let e = Isa::parse("neon").unwrap_err();
        assert!(e.contains("\"neon\"") && e.contains("avx512, avx2 or baseline"), "{e}");
    }
}
