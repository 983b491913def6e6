use glam::Vec3;

use crate::Aabb;

/// A ray: origin, direction (not necessarily normalised) and the parametric interval
/// `[t_min, t_max]` in which hits count. 32 bytes, in this order (the assembly kernel of
/// `megaray-trace` reads them so).
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct Ray {
    pub org: Vec3,
    pub dir: Vec3,
    /// Where hits start, at least 0: a negative `t_min` (or NaN) counts as 0 ([`t_start`]:
    /// hits behind the origin are never reported; as in Embree, where it must not be
    /// negative). The tracers' box tests rely on it (they compare distances that are never
    /// below 0 as integers). With `t_min = 0`, a hit at exactly 0 (the origin exactly on a
    /// triangle) may be missed where the triangle lies in a face of its leaf's box that the
    /// ray leaves: rays leaving a surface should start a little off it, or at `t_min > 0`.
    pub t_min: f32,
    pub t_max: f32,
}

const _: () = assert!(std::mem::size_of::<Ray>() == 32);

impl Ray {
    /// A copy read field by field, each a 4-byte load the compiler may not merge: what a
    /// tracer's entry reads its ray with. A ray written just before the call (its fields
    /// stored one by one, as a struct literal of scalars is) is then taken from the pending
    /// stores at once; a wider load spanning several of them, such as a 16-byte load of the
    /// direction and `t_min`, waits until they reach the cache (15-25 cycles a ray;
    /// docs/PERF.md, "A ray's fields read one by one"). Kept in registers, the copy is read
    /// as it likes.
    #[inline(always)]
    pub fn settled(&self) -> Ray {
        Ray {
            org: settled3(&self.org),
            dir: self.settled_dir(),
            t_min: settled1(&self.t_min),
            t_max: settled1(&self.t_max),
        }
    }

    /// The direction alone, read as [`Ray::settled`] reads it (three loads, not eight).
    #[inline(always)]
    pub fn settled_dir(&self) -> Vec3 {
        settled3(&self.dir)
    }
}

/// One `f32` read by a load the compiler may not merge with its neighbours' ([`Ray::settled`]).
#[inline(always)]
fn settled1(x: &f32) -> f32 {
    // SAFETY: a read of a live reference to an `f32`; volatile only so that it is not merged
    // with its neighbours into one wider load.
    unsafe { std::ptr::read_volatile(x) }
}

/// A vector read component by component ([`settled1`]).
#[inline(always)]
fn settled3(v: &Vec3) -> Vec3 {
    Vec3::new(settled1(&v.x), settled1(&v.y), settled1(&v.z))
}

impl Ray {
    pub fn new(org: Vec3, dir: Vec3) -> Ray {
        Ray { org, dir, t_min: 0.0, t_max: f32::INFINITY }
    }
}

/// A ray's `t_min` as every test takes it: `+0.0` for anything not above 0 (negative
/// values, `-0.0`, NaN), else itself. (`f32::max` may return `-0.0` for `-0.0` and `0.0`.)
#[inline(always)]
pub fn t_start(t_min: f32) -> f32 {
    if t_min > 0.0 {
        t_min
    } else {
        0.0
    }
}

/// Up to 16 rays as structure of arrays: what the packet kernel reads, made so by whoever
/// makes the rays (a camera's 4x4 pixels), with no transposition in between. Lanes from
/// `len` on are unused: their contents are ignored.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct Rays16 {
    /// Origins, per axis.
    pub org: [[f32; 16]; 3],
    /// Directions, per axis.
    pub dir: [[f32; 16]; 3],
    pub t_min: [f32; 16],
    pub t_max: [f32; 16],
    /// How many lanes hold rays (at most 16).
    pub len: usize,
}

impl Rays16 {
    /// The rays of `rays` (at most 16).
    pub fn from_rays(rays: &[Ray]) -> Rays16 {
        assert!(rays.len() <= 16, "a packet holds at most 16 rays, not {}", rays.len());
        let mut p =
            Rays16 { org: [[0.0; 16]; 3], dir: [[0.0; 16]; 3], t_min: [0.0; 16], t_max: [0.0; 16], len: rays.len() };
        for (i, r) in rays.iter().enumerate() {
            (p.org[0][i], p.org[1][i], p.org[2][i]) = (r.org.x, r.org.y, r.org.z);
            (p.dir[0][i], p.dir[1][i], p.dir[2][i]) = (r.dir.x, r.dir.y, r.dir.z);
            (p.t_min[i], p.t_max[i]) = (r.t_min, r.t_max);
        }
        p
    }

    /// Which lanes may enter `b` within their `[t_min, t_max]` (bit `i`: lane `i`; lanes past
    /// `len` clear). Conservative: the box is tested grown by a margin far above the test's
    /// rounding, so a clear bit means the ray surely misses everything inside `b` (a
    /// renderer answers those rays with the background, without a trace). In loops the
    /// compiler vectorizes.
    pub fn entering(&self, b: &Aabb) -> u16 {
        crate::wide::dispatch!(self.entering_in(b), Rays16::entering_avx512, Rays16::entering_avx2)
    }

    crate::wide::compiled_for!(entering_avx512, entering_avx2, entering_in(&self, b: &Aabb) -> u16);

    /// [`Rays16::entering`] as written, compiled for whichever instruction set calls it.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // lane loops over several arrays, to vectorize
    pub(crate) fn entering_in(&self, b: &Aabb) -> u16 {
        if !(b.min[0] <= b.max[0] && b.min[1] <= b.max[1] && b.min[2] <= b.max[2]) {
            return 0; // an empty box (a scene without triangles)
        }
        // The margin, per lane: relative to the box and to how far the origin is from it
        // (the distances the test multiplies). An axis where 0 times infinity gives NaN (an
        // origin on a face of the grown box, parallel to it) constrains nothing.
        let ext = (b.max[0] - b.min[0]).max(b.max[1] - b.min[1]).max(b.max[2] - b.min[2]);
        let c = [0.5 * (b.min[0] + b.max[0]), 0.5 * (b.min[1] + b.max[1]), 0.5 * (b.min[2] + b.max[2])];
        let mut m = [0.0f32; 16];
        for i in 0..16 {
            let reach =
                ext + (self.org[0][i] - c[0]).abs() + (self.org[1][i] - c[1]).abs() + (self.org[2][i] - c[2]).abs();
            m[i] = reach * 1e-4 + f32::MIN_POSITIVE;
        }
        let mut near = [0.0f32; 16];
        let mut far = [0.0f32; 16];
        for i in 0..16 {
            (near[i], far[i]) = (t_start(self.t_min[i]), self.t_max[i]);
        }
        for a in 0..3 {
            for i in 0..16 {
                let (lo, hi) = (b.min[a] - m[i], b.max[a] + m[i]);
                let inv = 1.0 / self.dir[a][i];
                let (t0, t1) = ((lo - self.org[a][i]) * inv, (hi - self.org[a][i]) * inv);
                near[i] = near[i].max(t0.min(t1));
                far[i] = far[i].min(t0.max(t1));
            }
        }
        let mut mask = 0u16;
        for i in 0..self.len.min(16) {
            let miss = near[i] > far[i] * (1.0 + 1e-5);
            mask |= (!miss as u16) << i;
        }
        mask
    }

    /// The ray in lane `i`.
    #[inline]
    pub fn ray(&self, i: usize) -> Ray {
        Ray {
            org: Vec3::new(self.org[0][i], self.org[1][i], self.org[2][i]),
            dir: Vec3::new(self.dir[0][i], self.dir[1][i], self.dir[2][i]),
            t_min: self.t_min[i],
            t_max: self.t_max[i],
        }
    }
}

/// A ray-triangle hit: distance along the ray and barycentrics (`u` weights corner 1,
/// `v` corner 2, `1 - u - v` corner 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
}

/// The watertight ray-triangle test of Woop, Benthin and Wald (JCGT 2013), scalar.
///
/// Returns a hit with `ray.t_min <= t < t_max` (strictly less than `t_max`, so the closest hit
/// among several is found by shrinking `t_max`). Rays through a shared edge or vertex of a closed
/// mesh hit at least one of its triangles: no ray slips through. Both faces count.
///
/// This is the reference implementation; the traversal kernels may use a faster form and are
/// tested against it.
#[inline]
pub fn intersect_triangle(ray: &Ray, tri: [Vec3; 3], t_max: f32) -> Option<TriHit> {
    WatertightRay::new(ray).intersect(&tri.map(Into::into), t_max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether `r` meets box `b` within its interval, in f64 (`m`: the box grown by that).
    fn meets(r: &Ray, b: &Aabb, m: f64) -> bool {
        let (mut near, mut far) = (t_start(r.t_min) as f64, r.t_max as f64);
        for a in 0..3 {
            let (lo, hi) = (b.min[a] as f64 - m, b.max[a] as f64 + m);
            let (o, d) = (r.org[a] as f64, r.dir[a] as f64);
            if d == 0.0 {
                if o < lo || o > hi {
                    return false;
                }
                continue;
            }
            let (t0, t1) = ((lo - o) / d, (hi - o) / d);
            near = near.max(t0.min(t1));
            far = far.min(t0.max(t1));
        }
        near <= far
    }

    /// `entering` keeps every ray that meets the box (exactly, in f64), and clears rays
    /// that miss it by more than ten times its margin; lanes past `len` are clear.
    #[test]
    fn entering_is_conservative_and_tight() {
        let b = Aabb { min: [-1.0, 2.0, -0.5], max: [3.0, 2.5, 4.0] };
        let mut x = 0x2545_f491u32;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as f32 / u32::MAX as f32
        };
        let (mut kept, mut cleared) = (0, 0);
        for round in 0..4000 {
            let far = if round % 2 == 0 { 10.0 } else { 1000.0 };
            let rays: Vec<Ray> = (0..16)
                .map(|i| {
                    let org = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * far + Vec3::new(1.0, 2.2, 1.5);
                    // Aimed near the box, some exactly along an axis.
                    let to = Vec3::new(next() * 6.0 - 2.0, next() * 2.0 + 1.2, next() * 6.0 - 1.5);
                    let mut dir = to - org;
                    if i % 5 == 0 {
                        dir[i % 3] = 0.0;
                    }
                    let t_max = if i % 7 == 0 { next() * far } else { f32::INFINITY };
                    Ray { org, dir, t_min: if i % 3 == 0 { 0.5 } else { 0.0 }, t_max }
                })
                .collect();
            let len = 1 + round % 16;
            let p = Rays16::from_rays(&rays[..len]);
            let mask = p.entering(&b);
            assert_eq!(mask, p.entering_in(&b), "the dispatched path equals the baseline's");
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2.
                assert_eq!(mask, unsafe { p.entering_avx2(&b) }, "the AVX2 path equals the baseline's");
            }
            assert_eq!((mask as u32) >> len, 0, "lanes past len are clear");
            for (i, r) in rays[..len].iter().enumerate() {
                let bit = mask & (1 << i) != 0;
                if meets(r, &b, 0.0) {
                    assert!(bit, "a ray that meets the box is kept: {r:?}");
                    kept += 1;
                } else if !meets(r, &b, far as f64 * 1e-3) {
                    assert!(!bit, "a ray far from the box is cleared: {r:?}");
                    cleared += 1;
                }
            }
        }
        assert!(kept > 1000 && cleared > 1000, "both cases tested: {kept} kept, {cleared} cleared");
        let empty = Aabb { min: [f32::INFINITY; 3], max: [f32::NEG_INFINITY; 3] };
        assert_eq!(Rays16::from_rays(&[Ray::new(Vec3::ZERO, Vec3::X)]).entering(&empty), 0);
    }

    /// `t_start` gives `+0.0` (its bits) for everything not above 0, and a positive value
    /// itself; the scalar test counts a negative `t_min` as 0 (no hit behind the origin).
    #[test]
    fn negative_t_min_counts_as_zero() {
        for t in [-1.0f32, -0.0, 0.0, f32::NAN, f32::NEG_INFINITY, -1e-40] {
            assert_eq!(t_start(t).to_bits(), 0, "{t}");
        }
        for t in [1e-40f32, 0.5, f32::INFINITY] {
            assert_eq!(t_start(t), t);
        }
        let tri = [Vec3::new(-1.0, -1.0, -1.0), Vec3::new(1.0, -1.0, -1.0), Vec3::new(0.0, 1.0, -1.0)];
        let mut ray = Ray::new(Vec3::ZERO, Vec3::Z);
        ray.t_min = -5.0;
        assert!(intersect_triangle(&ray, tri, f32::INFINITY).is_none(), "the triangle lies behind the origin");
        ray.dir = -Vec3::Z;
        assert_eq!(intersect_triangle(&ray, tri, f32::INFINITY).map(|h| h.t), Some(1.0));
    }

    /// A packet gives back exactly the rays it was made of, in order.
    #[test]
    fn rays16_round_trip() {
        let rays: Vec<Ray> = (0..11)
            .map(|i| {
                let f = i as f32;
                Ray {
                    org: Vec3::new(f, -f, 0.5 * f),
                    dir: Vec3::new(1.0, f, -2.0 * f),
                    t_min: 0.1 * f,
                    t_max: 10.0 + f,
                }
            })
            .collect();
        let p = Rays16::from_rays(&rays);
        assert_eq!(p.len, 11);
        for (i, r) in rays.iter().enumerate() {
            let q = p.ray(i);
            assert_eq!((q.org, q.dir, q.t_min, q.t_max), (r.org, r.dir, r.t_min, r.t_max));
        }
    }

    #[test]
    fn hits_inside_misses_outside() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let r = Ray::new(Vec3::new(0.2, 0.3, 1.0), -Vec3::Z);
        let h = intersect_triangle(&r, tri, f32::INFINITY).unwrap();
        assert!((h.t - 1.0).abs() < 1e-6);
        assert!((h.u - 0.2).abs() < 1e-6 && (h.v - 0.3).abs() < 1e-6);
        let r = Ray::new(Vec3::new(0.8, 0.3, 1.0), -Vec3::Z);
        assert!(intersect_triangle(&r, tri, f32::INFINITY).is_none());
    }

    #[test]
    fn shared_edge_never_slips() {
        // Two triangles sharing the diagonal of the unit square.
        let t0 = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)];
        let t1 = [Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        for i in 1..990 {
            let s = i as f32 / 1000.0;
            let r = Ray::new(Vec3::new(s, s, 1.0), Vec3::new(0.001, -0.0007, -1.0));
            let a = intersect_triangle(&r, t0, f32::INFINITY);
            let b = intersect_triangle(&r, t1, f32::INFINITY);
            let inside = {
                let p = r.org + r.dir * (1.0 / -r.dir.z);
                (0.0..=1.0).contains(&p.x) && (0.0..=1.0).contains(&p.y)
            };
            if inside {
                assert!(a.is_some() || b.is_some(), "ray {i} slipped through");
            }
        }
    }

    #[test]
    fn respects_interval() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let r = Ray::new(Vec3::new(0.2, 0.3, 1.0), -Vec3::Z);
        assert!(intersect_triangle(&r, tri, 0.5).is_none());
        assert!(intersect_triangle(&r, tri, 1.0).is_none());
    }
}

/// The scalar watertight test split in two: per-ray constants computed once
/// ([`WatertightRay::new`]: the dominant axis and the shear) and reused for every triangle the
/// ray meets ([`WatertightRay::intersect`]). [`intersect_triangle`] is the two in one call.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    pub org: [f32; 3],
    pub k: [usize; 3],
    pub s: [f32; 3],
    pub t_min: f32,
}

impl WatertightRay {
    #[inline]
    pub fn new(ray: &Ray) -> WatertightRay {
        let d = ray.dir;
        let ad = d.abs();
        let kz = if ad.x > ad.y {
            if ad.x > ad.z {
                0
            } else {
                2
            }
        } else if ad.y > ad.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = 1.0 / d[kz];
        // A negative `t_min` counts as 0 ([`Ray::t_min`]).
        let t_min = t_start(ray.t_min);
        WatertightRay { org: ray.org.into(), k: [kx, ky, kz], s: [d[kx] * sz, d[ky] * sz, sz], t_min }
    }

    /// The watertight test against triangle `tri` (corners as arrays), hits in `[t_min, t_max)`.
    #[inline(always)]
    pub fn intersect(&self, tri: &[[f32; 3]; 3], t_max: f32) -> Option<TriHit> {
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.s;
        let o = self.org;
        let (a, b, c) = (&tri[0], &tri[1], &tri[2]);
        let (az, bz, cz) = (a[kz] - o[kz], b[kz] - o[kz], c[kz] - o[kz]);
        let ax = (a[kx] - o[kx]) - sx * az;
        let ay = (a[ky] - o[ky]) - sy * az;
        let bx = (b[kx] - o[kx]) - sx * bz;
        let by = (b[ky] - o[ky]) - sy * bz;
        let cx = (c[kx] - o[kx]) - sx * cz;
        let cy = (c[ky] - o[ky]) - sy * cz;
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            let (axd, ayd, bxd, byd, cxd, cyd) = (ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64);
            u = (cxd * byd - cyd * bxd) as f32;
            v = (axd * cyd - ayd * cxd) as f32;
            w = (bxd * ayd - byd * axd) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
        let inv_det = 1.0 / det;
        let t = t_scaled * inv_det;
        if !(t >= self.t_min && t < t_max) {
            return None;
        }
        Some(TriHit { t, u: v * inv_det, v: w * inv_det })
    }
}
