use megaray_base::{Aabb, Ray, Vec3};

/// A pinhole camera. Pixel (0, 0) is the top-left; rays go through pixel centres at
/// sample offset (0.5, 0.5), exactly as the benchmark definitions (`shared/BENCH.md`) say.
#[derive(Clone, Copy, Debug)]
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

    /// The ray through image position (`px`, `py`) (pixel units, `(x + 0.5, y + 0.5)` is the
    /// centre of pixel (x, y)), with a normalised direction.
    #[inline]
    pub fn ray(&self, px: f32, py: f32) -> Ray {
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * px / self.width as f32 - 1.0) * self.tan_half * aspect;
        let sy = (1.0 - 2.0 * py / self.height as f32) * self.tan_half;
        Ray::new(self.eye, (self.fwd + self.right * sx + self.up * sy).normalize())
    }
}

/// The `default` benchmark camera offset.
pub const DEFAULT_OFFSET: Vec3 = Vec3::new(0.0, 0.3, 1.6);
/// The `close` benchmark camera offset.
pub const CLOSE_OFFSET: Vec3 = Vec3::new(0.0, 0.3, 0.6);
