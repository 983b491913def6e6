use glam::Vec3;

/// A ray: origin, direction (not necessarily normalised) and the parametric interval
/// `[t_min, t_max]` in which hits count.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub org: Vec3,
    pub dir: Vec3,
    pub t_min: f32,
    pub t_max: f32,
}

impl Ray {
    pub fn new(org: Vec3, dir: Vec3) -> Ray {
        Ray { org, dir, t_min: 0.0, t_max: f32::INFINITY }
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
        WatertightRay { org: ray.org.into(), k: [kx, ky, kz], s: [d[kx] * sz, d[ky] * sz, sz], t_min: ray.t_min }
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
