//! The ray sets, defined exactly as the peer harness defines them (same float operations in
//! the same order, same random numbers), so that checksums can be compared with the peer's.

use std::f32::consts::PI;

use megaray_base::{Ray, Vec3};
use megaray_render::Camera;
use megaray_trace::Tracer;
use rayon::prelude::*;

/// Side of the square pixel tiles that primary rays are scheduled in.
pub const TILE: u32 = 32;
/// Secondary rays are scheduled in chunks of this many rays.
pub const SEC_CHUNK: usize = 4096;

/// Direction toward the directional light: normalize(0.5, 1, 0.8).
pub fn light_dir() -> Vec3 {
    normalize(Vec3::new(0.5, 1.0, 0.8))
}

/// The peer's normalize: `v / |v|`, or `v` itself when it has zero length.
#[inline]
fn normalize(v: Vec3) -> Vec3 {
    let l = v.length();
    if l > 0.0 {
        v * (1.0 / l)
    } else {
        v
    }
}

pub use megaray_base::{hash32, u01};

/// The cosine-distributed direction around the unit normal `n` of pixel `p` (`y * W + x`).
pub fn diffuse_dir(p: u32, n: Vec3) -> Vec3 {
    let h1 = hash32(p.wrapping_mul(2).wrapping_add(0x9e37_79b9));
    let h2 = hash32(h1 ^ 0x85eb_ca6b);
    let (r1, r2) = (u01(h1), u01(h2));
    let phi = 2.0 * PI * r1;
    let sr = r2.sqrt();
    let a = if n.x.abs() > 0.9 { Vec3::Y } else { Vec3::X };
    let t = normalize(a.cross(n));
    let b = n.cross(t);
    normalize(t * (sr * phi.cos()) + b * (sr * phi.sin()) + n * (1.0 - r2).max(0.0).sqrt())
}

/// The camera ray through the centre of pixel (`x`, `y`).
#[inline]
pub fn pixel_ray(cam: &Camera, x: u32, y: u32) -> Ray {
    cam.ray(x as f32 + 0.5, y as f32 + 0.5)
}

/// The tiles of a `w` x `h` image, row by row: `(x0, y0, x1, y1)`, end exclusive.
pub fn tiles(w: u32, h: u32) -> Vec<(u32, u32, u32, u32)> {
    let mut out = Vec::new();
    for y0 in (0..h).step_by(TILE as usize) {
        for x0 in (0..w).step_by(TILE as usize) {
            out.push((x0, y0, (x0 + TILE).min(w), (y0 + TILE).min(h)));
        }
    }
    out
}

/// The reference primary pass: for every pixel, the hit distance (`-1` on a miss) and the
/// unit geometric normal turned to face the eye.
pub struct Primary {
    pub t: Vec<f32>,
    pub n: Vec<Vec3>,
}

impl Primary {
    /// Traces one ray per pixel on the current rayon pool.
    pub fn trace(tracer: &Tracer, cam: &Camera) -> Primary {
        let (w, h) = (cam.width as usize, cam.height as usize);
        let mut t = vec![-1.0f32; w * h];
        let mut n = vec![Vec3::ZERO; w * h];
        t.par_chunks_mut(w).zip(n.par_chunks_mut(w)).enumerate().for_each(|(y, (ts, ns))| {
            for x in 0..w {
                let ray = pixel_ray(cam, x as u32, y as u32);
                if let Some(hit) = tracer.intersect(&ray) {
                    let g = normalize(hit.geometric_normal());
                    ts[x] = hit.t;
                    ns[x] = if g.dot(ray.dir) > 0.0 { -g } else { g };
                }
            }
        });
        Primary { t, n }
    }

    pub fn hits(&self) -> u64 {
        self.t.iter().filter(|&&t| t >= 0.0).count() as u64
    }
}

/// The secondary rays, one of each kind per primary hit, in scanline order.
pub struct Secondary {
    pub shadow: Vec<Ray>,
    pub diffuse: Vec<Ray>,
}

impl Secondary {
    /// From hit point `P = eye + d t + n eps` (`eps = 1e-4` times the scene diagonal): a ray
    /// toward the light and a cosine-distributed one around `n`, both over `[0, inf)`.
    pub fn generate(cam: &Camera, primary: &Primary, eps: f32) -> Secondary {
        let nhit = primary.hits() as usize;
        let mut s = Secondary { shadow: Vec::with_capacity(nhit), diffuse: Vec::with_capacity(nhit) };
        let l = light_dir();
        let w = cam.width as usize;
        for (p, (&t, &n)) in primary.t.iter().zip(&primary.n).enumerate() {
            if t < 0.0 {
                continue;
            }
            let d = pixel_ray(cam, (p % w) as u32, (p / w) as u32).dir;
            let org = cam.eye + d * t + n * eps;
            s.shadow.push(Ray::new(org, l));
            s.diffuse.push(Ray::new(org, diffuse_dir(p as u32, n)));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hash_is_lowbias32() {
        // Values of the peer's hash32, computed from its C++ source.
        assert_eq!(hash32(0), 0);
        assert_eq!(hash32(1), 0x6889_90c0);
        assert_eq!(hash32(0x9e37_79b9), 0x01fc_e552);
        assert_eq!(hash32(12345), 0x912e_fcf7);
        assert!(u01(u32::MAX) < 1.0);
        assert_eq!(u01(0), 0.0);
    }

    #[test]
    fn diffuse_dirs_are_unit_and_above_the_surface() {
        for (i, n) in [Vec3::Y, Vec3::X, -Vec3::Z, normalize(Vec3::new(0.3, -0.4, 0.8))].into_iter().enumerate() {
            for p in 0..1000u32 {
                let d = diffuse_dir(p * 7 + i as u32, n);
                assert!((d.length() - 1.0).abs() < 1e-5);
                assert!(d.dot(n) >= -1e-6, "{d} below {n}");
            }
        }
    }

    #[test]
    fn tiles_cover_the_image_once() {
        let t = tiles(100, 70);
        assert_eq!(t.len(), 4 * 3);
        let area: u32 = t.iter().map(|&(x0, y0, x1, y1)| (x1 - x0) * (y1 - y0)).sum();
        assert_eq!(area, 100 * 70);
    }
}
