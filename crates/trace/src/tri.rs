//! Triangle blocks and their tests: a [`Tri4`] block of four triangles as the tracer reads it
//! ([`Block`]) and the 4-wide (and two-block 8-wide) watertight test of Woop et al. 2013
//! ([`RayTri4`]), lane for lane the scalar reference's operations.

use glam::{Vec3A, Vec3Swizzles, Vec4};
use megaray_base::{t_start, Ray, TriHit, WatertightRay};

use crate::boxes::{RayBox, TINY};

/// A [`Tri4`](megaray_scene::format::Tri4) block as the tracer reads it (its `v`), nine
/// 16-byte units of the node pool from the block's `offset / 16` ([`Tracer::block_at`]).
pub(crate) type Block = [[f32; 4]; 9];

/// The corners of the triangle in `lane` of a block (as `Tri4::tri`).
#[inline]
pub(crate) fn corners(v: &Block, lane: usize) -> [[f32; 3]; 3] {
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
pub(crate) unsafe fn row(b: &Block, c: usize, kb: usize) -> [f32; 4] {
    debug_assert!(c < 3 && kb < 48 && kb.is_multiple_of(16));
    // SAFETY: 48 * c + kb <= 128 (the caller's promise): the start of one of the nine
    // 16-byte rows of `b`, aligned as `b` is.
    unsafe { b.as_ptr().cast::<u8>().add(48 * c + kb).cast::<[f32; 4]>().read() }
}

/// A block that [`RayTri4::try_test`] leaves to the double-precision reference.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Exact;

/// Per-ray constants of the 4-wide watertight test (the lanes of a [`Block`] at once).
/// Each lane computes what [`WatertightRay::intersect`] computes, operation for operation,
/// but for one thing: the reference swaps its `x` and `y` axes when the ray runs backward
/// along its dominant axis (`kz`), which negates every edge function, the determinant and
/// the scaled distance exactly (IEEE rounding is symmetric), and so changes no distance or
/// barycentric. Results are bit-identical to the scalar reference.
pub(crate) struct RayTri4 {
    /// The ray, for the scalar reference ([`RayTri4::scalar`]).
    pub(crate) ray: Ray,
    /// The dominant axis: the kernel's rows are `kx = kz + 1`, `ky = kz + 2` (mod 3).
    pub(crate) kz: usize,
    /// `16 * [kx, ky, kz]`: the byte offsets of their rows in a corner of a block ([`row`]),
    /// for the test that reads its rows by the ray's axes ([`RayTri4::try_test_dyn`]).
    pub(crate) kb: [usize; 3],
    /// The shear: `d[kx] / d[kz]`, `d[ky] / d[kz]`, `1 / d[kz]`.
    pub(crate) s: [Vec4; 3],
    /// The origin's `kx`, `ky`, `kz` components, for [`RayTri4::try_test_dyn`].
    pub(crate) ok: [Vec4; 3],
    /// The ray's own [`Splats`], for [`RayTri4::test`] (the single-ray kernel shares its
    /// box test's instead).
    pub(crate) own: Splats,
}

/// `[kx, ky, kz]` of each dominant axis `kz`: `kx = kz + 1`, `ky = kz + 2` (mod 3).
pub(crate) const AXES: [[usize; 3]; 3] = [[1, 2, 0], [2, 0, 1], [0, 1, 2]];

/// [`AXES`] as byte offsets of rows within a corner of a block ([`row`]).
pub(crate) const AXES_BYTES: [[usize; 3]; 3] = [[16, 32, 0], [32, 0, 16], [0, 16, 32]];
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
pub(crate) const DOMINANT: [u8; 8] = {
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
pub(crate) const PERMUTE: [[i32; 4]; 3] = [[1, 2, 0, 3], [2, 0, 1, 3], [0, 1, 2, 3]];

/// The axis parameter of [`RayTri4::test_k`] and [`RayTri4::test8_k`] that reads the rows
/// by the ray's axes.
pub(crate) const DYN_AXES: usize = 3;

/// The ray's origin (x, y, z, not permuted) and `t_min` in all four lanes: what the
/// triangle test needs besides its own constants. The single-ray kernel takes them from its
/// box test's 8-wide ones (their low halves, [`RayBox::splats`]), so that both tests share
/// the registers that hold them (the tests reading rows by the ray's axes take only
/// `t_min` from here, and the origin permuted from [`RayTri4::ok`]).
#[derive(Clone, Copy)]
pub(crate) struct Splats {
    pub(crate) o: [Vec4; 3],
    pub(crate) t_min: Vec4,
}

impl RayTri4 {
    #[inline(always)]
    pub(crate) fn new(r: &Ray) -> RayTri4 {
        RayTri4::with_inv(r, &RayBox::new(r).inv)
    }

    /// [`RayTri4::new`] given the ray's reciprocal direction as [`RayBox`] makes it (which
    /// is exactly `1 / d` on the dominant axis, saving a division). Written without indexing
    /// by the axis (which would put the ray's arrays in memory): one case per dominant axis.
    #[inline(always)]
    pub(crate) fn with_inv(r: &Ray, inv: &[f32; 3]) -> RayTri4 {
        RayTri4::with_axis(r, inv, RayTri4::dominant(r))
    }

    /// The ray's dominant axis: the reference's choice, comparison for comparison
    /// (`WatertightRay::new`).
    #[inline(always)]
    pub(crate) fn dominant(r: &Ray) -> usize {
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
    pub(crate) fn dominant_unbranched(r: &Ray) -> usize {
        // `dominant`'s three comparisons at once, `(x, x, y) > (y, z, z)`, as the bits of a
        // `movmskps` (a NaN compares false in both), then its choices for each outcome.
        let ad = Vec3A::from(r.dir).abs();
        DOMINANT[ad.xxy().cmpgt(ad.yzz()).bitmask() as usize & 7] as usize
    }

    /// [`RayTri4::with_inv`] for dominant axis `kz` (permuting by a branch on it: for rays
    /// whose axis is steady, camera and shadow rays; [`RayTri4::with_axis_unbranched`]
    /// otherwise).
    #[inline(always)]
    pub(crate) fn with_axis(r: &Ray, inv: &[f32; 3], kz: usize) -> RayTri4 {
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
    pub(crate) fn with_axis_unbranched(r: &Ray, inv: &[f32; 3]) -> RayTri4 {
        let kz = RayTri4::dominant_unbranched(r);
        let [kx, ky, _] = AXES[kz];
        let d = r.dir.to_array();
        RayTri4::with_shear(r, kz, (d[kx], d[ky], d[kz], inv[kz]))
    }

    /// [`RayTri4::with_axis_unbranched`] by vector permutes (one per vector of the ray's,
    /// by its axes' [`PERMUTE`]; one per splat), where the scalar form goes through the
    /// machine stack to index the ray's arrays. The same products, so the same constants
    /// (tested). With the dominant axis by one comparison of vectors and the rows as byte
    /// offsets ([`row`]), this keeps the generic kernel's per-ray set-up short
    /// (docs/PERF.md, "Per-ray set-up").
    ///
    /// # Safety
    /// The CPU must have AVX (inlined into the AVX kernels, as [`RayTri4::test8_k`] is).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) unsafe fn with_axis_avx(r: &Ray, inv: Vec3A) -> RayTri4 {
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
    pub(crate) fn with_shear(r: &Ray, kz: usize, (dx, dy, dz, iz): (f32, f32, f32, f32)) -> RayTri4 {
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
    pub(crate) fn test(&self, b: &Block, lanes: u32, t_max: f32) -> Option<(usize, TriHit)> {
        self.try_test(&self.own, b, lanes, t_max).unwrap_or_else(|Exact| self.scalar(b, lanes, t_max))
    }

    /// [`RayTri4::test`] where it needs no double precision; [`Exact`] when an edge or vertex
    /// of a lane lies exactly on the ray, for [`RayTri4::scalar`] to decide (rare: the
    /// single-ray kernel handles it outside its hot loop).
    #[inline(always)]
    pub(crate) fn try_test(
        &self,
        sp: &Splats,
        b: &Block,
        lanes: u32,
        t_max: f32,
    ) -> Result<Option<(usize, TriHit)>, Exact> {
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
    pub(crate) fn try_test_dyn(
        &self,
        sp: &Splats,
        b: &Block,
        lanes: u32,
        t_max: f32,
    ) -> Result<Option<(usize, TriHit)>, Exact> {
        self.test_k::<DYN_AXES>(sp, b, lanes, t_max)
    }

    /// The rows `[kx, ky, kz]` of dominant axis `KZ` (as [`row`]'s byte offsets) and the
    /// origin's components in that order: constants (`AXES_BYTES`) and the shared splats
    /// for an axis below 3, the ray's own for [`DYN_AXES`].
    #[inline(always)]
    pub(crate) fn axes<const KZ: usize>(&self, sp: &Splats) -> ([usize; 3], [Vec4; 3]) {
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
    pub(crate) fn try_test8<const ANY: bool>(
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
    pub(crate) fn try_test8_dyn<const ANY: bool>(
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
    pub(crate) unsafe fn test8_k<const ANY: bool, const KZ: usize>(
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
    pub(crate) fn test_k<const KZ: usize>(
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
    pub(crate) fn scalar(&self, b: &Block, lanes: u32, mut t_max: f32) -> Option<(usize, TriHit)> {
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

/// The lanes of a block that hold triangles, when `left` triangles of a leaf remain.
#[inline(always)]
pub(crate) fn lanes(left: u32) -> u32 {
    if left >= 4 {
        0b1111
    } else {
        (1u32 << left) - 1
    }
}

/// The lanes of two blocks that hold triangles, when `left` triangles of a leaf remain.
#[inline(always)]
pub(crate) fn lanes8(left: u32) -> u32 {
    if left >= 8 {
        0xff
    } else {
        (1u32 << left) - 1
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::isa::Isa;
    use megaray_base::Vec3;
    use megaray_scene::format::Tri4;

    pub(crate) struct Rng(pub(crate) u64);
    impl Rng {
        fn f(&mut self) -> f32 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (self.0 >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        }
        pub(crate) fn v(&mut self) -> Vec3 {
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
        if !Isa::available().contains(&Isa::Avx2) {
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
}
