use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// An axis-aligned bounding box. 24 bytes: `min` then `max`, each three `f32`.
///
/// The empty box has `min = +inf`, `max = -inf`, so that growing it by anything gives that thing.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Aabb {
    pub min: [f32; 3],
    pub max: [f32; 3],
}
const _: () = assert!(std::mem::size_of::<Aabb>() == 24);

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The box that contains nothing.
    pub const EMPTY: Aabb = Aabb { min: [f32::INFINITY; 3], max: [f32::NEG_INFINITY; 3] };

    pub fn from_points(points: &[[f32; 3]]) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in points {
            b.grow_point(*p);
        }
        b
    }

    #[inline]
    pub fn lo(&self) -> Vec3 {
        Vec3::from(self.min)
    }

    #[inline]
    pub fn hi(&self) -> Vec3 {
        Vec3::from(self.max)
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.min[0] > self.max[0] || self.min[1] > self.max[1] || self.min[2] > self.max[2]
    }

    #[inline]
    pub fn grow_point(&mut self, p: [f32; 3]) {
        self.min = [self.min[0].min(p[0]), self.min[1].min(p[1]), self.min[2].min(p[2])];
        self.max = [self.max[0].max(p[0]), self.max[1].max(p[1]), self.max[2].max(p[2])];
    }

    #[inline]
    pub fn grow(&mut self, o: &Aabb) {
        self.min = [self.min[0].min(o.min[0]), self.min[1].min(o.min[1]), self.min[2].min(o.min[2])];
        self.max = [self.max[0].max(o.max[0]), self.max[1].max(o.max[1]), self.max[2].max(o.max[2])];
    }

    #[inline]
    pub fn union(mut self, o: &Aabb) -> Aabb {
        self.grow(o);
        self
    }

    #[inline]
    pub fn extent(&self) -> Vec3 {
        if self.is_empty() {
            Vec3::ZERO
        } else {
            self.hi() - self.lo()
        }
    }

    #[inline]
    pub fn center(&self) -> Vec3 {
        (self.lo() + self.hi()) * 0.5
    }

    /// Half the surface area (the SAH only needs ratios, so the factor 2 is left out).
    #[inline]
    pub fn half_area(&self) -> f32 {
        let e = self.extent();
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    /// Length of the diagonal (the `d` of the benchmark cameras).
    pub fn diagonal(&self) -> f32 {
        self.extent().length()
    }

    /// The axis (0, 1, 2) along which the box is longest.
    pub fn longest_axis(&self) -> usize {
        let e = self.extent();
        if e.x >= e.y && e.x >= e.z {
            0
        } else if e.y >= e.z {
            1
        } else {
            2
        }
    }

    pub fn contains(&self, o: &Aabb) -> bool {
        (0..3).all(|k| self.min[k] <= o.min[k] && self.max[k] >= o.max[k])
    }
}
