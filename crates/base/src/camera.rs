use crate::{Aabb, Ray, Rays16, Vec3};

/// A pinhole camera. Pixel (0, 0) is the top-left; rays go through pixel centres at
/// sample offset (0.5, 0.5), exactly as the benchmark definitions (`shared/BENCH.md`) say.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Position of the eye.
    pub eye: Vec3,
    /// Unit viewing direction.
    pub fwd: Vec3,
    /// Unit vector to the image's right.
    pub right: Vec3,
    /// Unit vector to the image's top.
    pub up: Vec3,
    /// tan(vertical fov / 2)
    pub tan_half: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Camera {
    /// A camera at `eye` looking at `at`, with world `up` and vertical field of view `fov_deg`.
    pub fn look_at(eye: Vec3, at: Vec3, up: Vec3, fov_deg: f32, width: u32, height: u32) -> Camera {
        let fwd = (at - eye).normalize();
        let right = fwd.cross(up).normalize();
        let up = right.cross(fwd);
        Camera { eye, fwd, right, up, tan_half: (fov_deg.to_radians() * 0.5).tan(), width, height }
    }

    /// The benchmark camera: looking at the centre `c` of `bounds` from `c + offset * d`
    /// (`d` the length of the diagonal), world up +y, 60 degrees. `offset` (0, 0.3, 1.6) is
    /// the `default` camera, (0, 0.3, 0.6) the `close` one.
    pub fn framing(bounds: &Aabb, offset: Vec3, width: u32, height: u32) -> Camera {
        let c = bounds.center();
        let d = bounds.diagonal();
        Camera::look_at(c + offset * d, c, Vec3::Y, 60.0, width, height)
    }

    /// The angle a pixel spans (radians, vertically; near enough across for the square
    /// pixels of any image): the spread of a camera ray's footprint.
    pub fn pixel_angle(&self) -> f32 {
        2.0 * self.tan_half / self.height as f32
    }

    /// The ray through image position (`px`, `py`) (pixel units, `(x + 0.5, y + 0.5)` is the
    /// centre of pixel (x, y)), with a normalised direction.
    #[inline]
    pub fn ray(&self, px: f32, py: f32) -> Ray {
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * px / self.width as f32 - 1.0) * self.tan_half * aspect;
        let sy = (1.0 - 2.0 * py / self.height as f32) * self.tan_half;
        Ray::new(self.eye, (self.fwd + self.right * sx + self.up * sy).normalize())
    }

    /// [`Camera::ray`] at 16 image positions at once (a packet's pixels): lane for lane the
    /// same operations in the same order, so the same bits, in loops the compiler vectorizes.
    /// As the packet kernel reads them ([`Rays16`]: structure of arrays).
    pub fn rays16(&self, px: &[f32; 16], py: &[f32; 16]) -> Rays16 {
        crate::wide::dispatch!(self.rays16_in(px, py), Camera::rays16_avx512, Camera::rays16_avx2)
    }

    crate::wide::compiled_for!(rays16_avx512, rays16_avx2, rays16_in(&self, px: &[f32; 16], py: &[f32; 16]) -> Rays16);

    /// [`Camera::rays16`] as written, compiled for whichever instruction set calls it.
    #[inline(always)]
    pub(crate) fn rays16_in(&self, px: &[f32; 16], py: &[f32; 16]) -> Rays16 {
        let aspect = self.width as f32 / self.height as f32;
        let (w, h) = (self.width as f32, self.height as f32);
        let (f, r, u) = (self.fwd, self.right, self.up);
        let mut p = Rays16 {
            org: [[self.eye.x; 16], [self.eye.y; 16], [self.eye.z; 16]],
            dir: [[0.0; 16]; 3],
            t_min: [0.0; 16],
            t_max: [f32::INFINITY; 16],
            len: 16,
        };
        for i in 0..16 {
            let sx = (2.0 * px[i] / w - 1.0) * self.tan_half * aspect;
            let sy = (1.0 - 2.0 * py[i] / h) * self.tan_half;
            // `fwd + right * sx + up * sy`, then `normalize` as glam computes it: times the
            // reciprocal of the square root of the dot product.
            let (x, y, z) = (f.x + r.x * sx + u.x * sy, f.y + r.y * sx + u.y * sy, f.z + r.z * sx + u.z * sy);
            let inv = 1.0 / (x * x + y * y + z * z).sqrt();
            (p.dir[0][i], p.dir[1][i], p.dir[2][i]) = (x * inv, y * inv, z * inv);
        }
        p
    }
}

/// The `default` benchmark camera offset.
pub const DEFAULT_OFFSET: Vec3 = Vec3::new(0.0, 0.3, 1.6);
/// The `close` benchmark camera offset.
pub const CLOSE_OFFSET: Vec3 = Vec3::new(0.0, 0.3, 0.6);

#[cfg(test)]
mod tests {
    use super::*;

    /// The batch of 16 gives exactly the rays of one at a time.
    #[test]
    fn rays16_equal_single_rays() {
        let b = Aabb { min: [-1.0, -0.5, -2.0], max: [3.0, 1.0, 0.5] };
        for (off, w, h) in [(Vec3::new(0.0, 0.3, 1.6), 1024, 1024), (Vec3::new(0.2, -0.4, 0.6), 640, 361)] {
            let cam = Camera::framing(&b, off, w, h);
            for y0 in (0..h).step_by(37) {
                for x0 in (0..w).step_by(29) {
                    let px: [f32; 16] = std::array::from_fn(|i| (x0 + i as u32 % 4) as f32 + 0.5);
                    let py: [f32; 16] = std::array::from_fn(|i| (y0 + i as u32 / 4) as f32 + 0.5);
                    let batch = cam.rays16(&px, &py);
                    let plain = cam.rays16_in(&px, &py);
                    #[cfg(target_arch = "x86_64")]
                    if std::arch::is_x86_feature_detected!("avx2") {
                        // SAFETY: the CPU has AVX2.
                        let two = unsafe { cam.rays16_avx2(&px, &py) };
                        assert_eq!(two.dir.map(|a| a.map(f32::to_bits)), plain.dir.map(|a| a.map(f32::to_bits)));
                    }
                    for i in 0..16 {
                        let one = cam.ray(px[i], py[i]);
                        let batch = batch.ray(i);
                        assert_eq!(batch.t_min, one.t_min);
                        assert_eq!(batch.t_max, one.t_max);
                        assert_eq!(batch.dir.to_array().map(f32::to_bits), one.dir.to_array().map(f32::to_bits));
                        assert_eq!(batch.org, one.org);
                        // The dispatched path (AVX-512 or AVX2 here) equals the baseline's.
                        assert_eq!(plain.ray(i).dir.to_array().map(f32::to_bits), one.dir.to_array().map(f32::to_bits));
                    }
                }
            }
        }
    }
}
