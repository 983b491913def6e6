//! The box test: a ray against the eight boxes of a [`Node8`] at once ([`RayBox`]), 8-wide on
//! AVX2 and as two 4-wide SSE halves (the baseline and reference), conservative (Ize 2013).

use glam::{Vec3A, Vec4};
use megaray_base::Ray;
use megaray_scene::format::{Node8, NODE_WIDTH};

use crate::tri::Splats;

/// Conservative widening of box exit distances so that boxes never cull a hit that the
/// watertight triangle test would find (Ize 2013: 1 + 2 gamma(3)).
pub(crate) const BOX_EPS: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// The widening of the single-ray kernel's box exits, folded into the reciprocals of its far
/// planes ([`RayBox::ninv_far`]) and into the closest hit it compares them with, so that a
/// node's test has no multiply after its reductions (the exit's chain is then as long as the
/// entry's). A far distance `(plane - o) * (inv * FAR_EPS)` takes four roundings (the
/// difference, the reciprocal, its widening, the product: within a factor `1 - gamma(4)` of
/// `FAR_EPS` times the exact one), an entry distance three (at most `1 + gamma(3)` over); a
/// box is kept whenever `FAR_EPS >= (1 + gamma(3)) / (1 - gamma(4))`, about `1 + 7u`
/// (`u = 2^-24`). This is `1 + 16u`, above [`BOX_EPS`] (`1 + 6u`), which it replaces for
/// the closest hit as well.
pub(crate) const FAR_EPS: f32 = 1.0 + 8.0 * f32::EPSILON;
const _: () = assert!(FAR_EPS > BOX_EPS);

/// The smallest magnitude of a direction component the box test takes as it is: smaller
/// ones (and zeros) become +-`TINY`, so that their reciprocals stay finite ([`RayBox::new`]).
pub(crate) const TINY: f32 = 1e-20;

/// Lanes of a node's box test.
pub(crate) const W: usize = NODE_WIDTH;

/// Precomputed per-ray values for box tests: the eight slots of a [`Node8`] are tested at
/// once, as one 8-wide AVX pass ([`RayBox::test_avx2`]) or two 4-wide SSE halves
/// ([`RayBox::test_sse`], the baseline and reference). The near and far planes of each axis are
/// chosen once per ray from the direction's signs, as byte offsets of the node's six plane
/// rows (`lo_x, hi_x, lo_y, hi_y, lo_z, hi_z`, 32 bytes each), so the test has no branches.
pub(crate) struct RayBox {
    pub(crate) org: [f32; 3],
    pub(crate) inv: [f32; 3],
    /// `-inv`: the box tests' distances are `(o - plane) * -inv` ([`RayBox::test_avx2`]).
    /// Negated once per ray, so that the kernel broadcasts them from memory as they are.
    pub(crate) ninv: [f32; 3],
    /// `-inv * FAR_EPS`: the reciprocals the far planes are scaled by ([`FAR_EPS`]).
    pub(crate) ninv_far: [f32; 3],
    /// Byte offsets in a [`Node8`] of the rows ([`Node8::planes`]) of the near planes of x, y
    /// and z, then of the far planes: `32 * row`, the row of a far plane being the other one
    /// of its pair. Always one of 0, 32, .., 160 (the AVX test reads through them unchecked).
    pub(crate) rows: &'static [usize; 6],
}

/// [`RayBox::rows`] of each octant, so that a new ray looks its rows up rather than making
/// them (and its walk reads them from here, not from copies on the machine stack).
pub(crate) const ROWS: [[usize; 6]; 8] = {
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
    pub(crate) fn new(r: &Ray) -> RayBox {
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
    pub(crate) fn octant(r: &Ray) -> usize {
        RayBox::octant_of(r.dir)
    }

    /// [`RayBox::octant`] of direction `d`.
    #[inline(always)]
    pub(crate) fn octant_of(d: glam::Vec3) -> usize {
        Vec3A::from(d).is_negative_bitmask() as usize & 7
    }

    /// [`RayBox::rows`] of rays in octant `oct`: the near plane of an axis is its high one
    /// when the direction is negative along it.
    #[inline(always)]
    pub(crate) const fn rows(oct: usize) -> [usize; 6] {
        let near = [oct & 1, 2 + ((oct >> 1) & 1), 4 + ((oct >> 2) & 1)];
        [32 * near[0], 32 * near[1], 32 * near[2], 32 * (near[0] ^ 1), 32 * (near[1] ^ 1), 32 * (near[2] ^ 1)]
    }

    /// Whether the ray's origin lies in box `b` (then it enters the box, if at all, at once).
    #[inline(always)]
    pub(crate) fn starts_inside(&self, b: &megaray_base::Aabb) -> bool {
        let o = Vec3A::from_array(self.org);
        (o.cmpge(Vec3A::from_array(b.min)) & o.cmple(Vec3A::from_array(b.max))).all()
    }

    /// Whether the ray enters box `b` within `[t0, t1]`: one box, its three slabs at once,
    /// with the same slab products and widening as the slot tests (and so never stricter than
    /// them; no NaN arises, so `min` and `max` pick the near and far planes alike).
    #[inline(always)]
    pub(crate) fn enters(&self, b: &megaray_base::Aabb, t0: f32, t1: f32) -> bool {
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
    pub(crate) fn splats<const AVX: bool>(&self, t_min: f32) -> Splats {
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
    pub(crate) fn splats_avx2(&self, t_min: f32) -> Splats {
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
    /// critical path (docs/PERF.md, "Box test"). Integer order is float order on floats
    /// whose sign bit is clear; any with it
    /// set is below them all, and so never the entry (`t0` is above it) and always the exit
    /// if present, an exit that fails the comparison with every entry. So it gives the float
    /// test's result but for one case: an exit of `-0.0` (an origin exactly on a far plane,
    /// leaving it in the direction of its axis) misses where the float test would let an
    /// entry of `+0.0` through; only a hit at exactly 0 can lie there ([`Ray::t_min`] says
    /// so). The SSE test (the reference) does the same, by testing the exits' sign bits.
    #[inline(always)]
    pub(crate) fn test<const AVX: bool>(&self, n: &Node8, t0: f32, t1: f32) -> (Near, u32) {
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
    pub(crate) fn test_avx2(&self, n: &Node8, t0: f32, t1: f32) -> (Near, u32) {
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
    pub(crate) fn test_sse(&self, n: &Node8, t0: f32, t1: f32) -> (Near, u32) {
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
pub(crate) struct Near(pub(crate) [f32; W]);

/// `min` as `minps` computes it (the second operand when either is NaN), so that loops of it
/// vectorize.
#[inline(always)]
pub(crate) fn fmin(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// `max` as `maxps` computes it.
#[inline(always)]
pub(crate) fn fmax(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::isa::Isa;
    use crate::tri::tests::Rng;
    use megaray_scene::format::Node8;

    /// The AVX box test (distances compared as integers) gives the SSE reference's mask and
    /// entry distances: on random boxes, on empty and flat ones, on rays of every octant
    /// with components of zero, and on origins exactly on a plane (distances of zero, whose
    /// sign decides an exit there).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn box_test_avx_equals_sse_reference() {
        if !Isa::available().contains(&Isa::Avx2) {
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
