//! A fly camera: where the eye is and where it looks ([`Pose`]), and how keys, drags and
//! the wheel move it ([`FlyCamera`]).

use megaray_base::{Aabb, Camera, Vec3};

use crate::input::Key;

/// Where the eye is and where it looks: `yaw` turns about +y (0 looks along -z), `pitch`
/// tilts up (radians, kept within 89 degrees of level).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub eye: Vec3,
    pub yaw: f32,
    pub pitch: f32,
}

/// The steepest the camera looks up or down.
const MAX_PITCH: f32 = 89.0 * std::f32::consts::PI / 180.0;

impl Pose {
    /// The pose at `eye` looking toward `at`.
    pub fn looking_at(eye: Vec3, at: Vec3) -> Pose {
        let d = (at - eye).normalize_or_zero();
        let d = if d == Vec3::ZERO { -Vec3::Z } else { d };
        Pose { eye, yaw: (-d.x).atan2(-d.z), pitch: d.y.clamp(-1.0, 1.0).asin().clamp(-MAX_PITCH, MAX_PITCH) }
    }

    /// The unit direction looked in.
    pub fn forward(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        Vec3::new(-sy * cp, sp, -cy * cp)
    }

    /// The unit direction to the right, level.
    pub fn right(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        Vec3::new(cy, 0.0, -sy)
    }

    /// The camera of this pose, `fov` degrees vertically, for a `w` x `h` image.
    pub fn camera(&self, fov: f32, w: u32, h: u32) -> Camera {
        Camera::look_at(self.eye, self.eye + self.forward(), Vec3::Y, fov, w, h)
    }
}

/// A fly camera: a [`Pose`] and a speed (world units a second).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlyCamera {
    pub pose: Pose,
    pub speed: f32,
    /// Vertical field of view, degrees.
    pub fov: f32,
}

/// Radians of turn per pixel dragged.
const TURN: f32 = 0.005;

impl FlyCamera {
    /// The benchmark's default view of `bounds` (as `megaray render` frames it: from
    /// `c + (0, 0.3, 1.6) d`), moving a quarter of the diagonal a second.
    /// The camera at `pose` over a scene of box `bounds` (its speed by the box's size).
    pub fn at(pose: Pose, bounds: &Aabb, fov: f32) -> FlyCamera {
        FlyCamera { pose, speed: 0.25 * bounds.diagonal().max(1e-6), fov }
    }

    pub fn home(bounds: &Aabb, fov: f32) -> FlyCamera {
        let (c, d) = (bounds.center(), bounds.diagonal().max(1e-6));
        FlyCamera { pose: Pose::looking_at(c + megaray_base::DEFAULT_OFFSET * d, c), speed: 0.25 * d, fov }
    }

    /// Moves by the keys held for `dt` seconds: forward and back along the view, sideways
    /// level, up and down along +y. Returns whether it moved.
    pub fn fly(&mut self, held: &[Key], dt: f32) -> bool {
        let p = &mut self.pose;
        let (f, r) = (p.forward(), p.right());
        let mut v = Vec3::ZERO;
        for k in held {
            v += match k {
                Key::Forward => f,
                Key::Back => -f,
                Key::Right => r,
                Key::Left => -r,
                Key::Up => Vec3::Y,
                Key::Down => -Vec3::Y,
                _ => Vec3::ZERO,
            };
        }
        if v == Vec3::ZERO || dt <= 0.0 {
            return false;
        }
        p.eye += v.normalize() * self.speed * dt;
        true
    }

    /// Turns by a drag of (`dx`, `dy`) pixels: right turns right, down looks down.
    pub fn look(&mut self, dx: f32, dy: f32) {
        let p = &mut self.pose;
        p.yaw -= dx * TURN;
        p.pitch = (p.pitch - dy * TURN).clamp(-MAX_PITCH, MAX_PITCH);
    }

    /// The wheel: each notch up 20% faster, down 20% slower.
    pub fn wheel(&mut self, notches: f32) {
        self.speed *= 1.2f32.powf(notches.clamp(-20.0, 20.0));
    }

    /// Frames the whole of `bounds`: looking as now, from far enough back that its bounding
    /// sphere fits the view.
    pub fn frame(&mut self, bounds: &Aabb) {
        let (c, radius) = (bounds.center(), 0.5 * bounds.diagonal());
        let dist = radius / (0.5 * self.fov.to_radians()).sin().max(1e-3);
        let f = self.pose.forward();
        self.pose.eye = c - f * dist;
    }
}
