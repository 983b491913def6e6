//! [`Affine`]: the 3x4 transforms that place instances (rotation, scale, shear, mirror and
//! translation; no projection).

use glam::Vec3;

use crate::{Aabb, Ray};

/// An affine map `p -> M p + t`, stored row-major as three rows `[m_r0, m_r1, m_r2, t_r]`:
/// exactly the 48 bytes an instance record holds on disk. `Default` is the identity.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Affine(pub [[f32; 4]; 3]);

const _: () = assert!(std::mem::size_of::<Affine>() == 48);

impl Default for Affine {
    fn default() -> Self {
        Affine::IDENTITY
    }
}

impl Affine {
    pub const IDENTITY: Affine = Affine([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]);

    pub fn translation(t: Vec3) -> Affine {
        Affine([[1.0, 0.0, 0.0, t.x], [0.0, 1.0, 0.0, t.y], [0.0, 0.0, 1.0, t.z]])
    }

    pub fn scale(s: Vec3) -> Affine {
        Affine([[s.x, 0.0, 0.0, 0.0], [0.0, s.y, 0.0, 0.0], [0.0, 0.0, s.z, 0.0]])
    }

    /// A rotation by `degrees` about `axis` (right-handed; pbrt's `Rotate`).
    pub fn rotation(degrees: f32, axis: Vec3) -> Affine {
        let a = axis.normalize_or_zero();
        let (s, c) = (degrees.to_radians() as f64).sin_cos();
        let (x, y, z) = (a.x as f64, a.y as f64, a.z as f64);
        let m = |v: f64| v as f32;
        Affine([
            [m(x * x + (1.0 - x * x) * c), m(x * y * (1.0 - c) - z * s), m(x * z * (1.0 - c) + y * s), 0.0],
            [m(x * y * (1.0 - c) + z * s), m(y * y + (1.0 - y * y) * c), m(y * z * (1.0 - c) - x * s), 0.0],
            [m(x * z * (1.0 - c) - y * s), m(y * z * (1.0 - c) + x * s), m(z * z + (1.0 - z * z) * c), 0.0],
        ])
    }

    /// From a column-major 4x4 matrix as pbrt and glTF write them (`m[col][row]`); the last
    /// row is ignored (it must be 0 0 0 1 for an affine map).
    pub fn from_cols4(m: [[f32; 4]; 4]) -> Affine {
        Affine(std::array::from_fn(|r| std::array::from_fn(|c| m[c][r])))
    }

    #[inline]
    pub fn point(&self, p: Vec3) -> Vec3 {
        let m = &self.0;
        Vec3::new(
            m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3],
            m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3],
            m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3],
        )
    }

    #[inline]
    pub fn vector(&self, v: Vec3) -> Vec3 {
        let m = &self.0;
        Vec3::new(
            m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
            m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
            m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z,
        )
    }

    /// A normal of a surface this map moved (by the inverse transpose; not normalised).
    /// `self` must be the inverse of the map that moved the surface.
    #[inline]
    pub fn normal_by_inverse(&self, n: Vec3) -> Vec3 {
        let m = &self.0;
        Vec3::new(
            m[0][0] * n.x + m[1][0] * n.y + m[2][0] * n.z,
            m[0][1] * n.x + m[1][1] * n.y + m[2][1] * n.z,
            m[0][2] * n.x + m[1][2] * n.y + m[2][2] * n.z,
        )
    }

    /// `self` after `o`: the map `p -> self(o(p))`. Composed in double precision.
    pub fn then_after(&self, o: &Affine) -> Affine {
        let (a, b) = (&self.0, &o.0);
        Affine(std::array::from_fn(|r| {
            std::array::from_fn(|c| {
                let mut s: f64 = if c == 3 { a[r][3] as f64 } else { 0.0 };
                for k in 0..3 {
                    s += a[r][k] as f64 * b[k][c] as f64;
                }
                s as f32
            })
        }))
    }

    /// The determinant of the linear part (negative for a mirroring map).
    pub fn determinant(&self) -> f64 {
        let m = |r: usize, c: usize| self.0[r][c] as f64;
        m(0, 0) * (m(1, 1) * m(2, 2) - m(1, 2) * m(2, 1)) - m(0, 1) * (m(1, 0) * m(2, 2) - m(1, 2) * m(2, 0))
            + m(0, 2) * (m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0))
    }

    /// The inverse map, or `None` when the linear part is singular (or not finite).
    pub fn inverse(&self) -> Option<Affine> {
        let det = self.determinant();
        if !det.is_finite() || det.abs() < 1e-30 || self.0.iter().flatten().any(|v| !v.is_finite()) {
            return None;
        }
        let m = |r: usize, c: usize| self.0[r][c] as f64;
        let inv = |r: usize, c: usize| {
            // The cofactor of (c, r) over the determinant.
            let (r0, r1) = ([1, 0, 0][c], [2, 2, 1][c]);
            let (c0, c1) = ([1, 0, 0][r], [2, 2, 1][r]);
            let minor = m(r0, c0) * m(r1, c1) - m(r0, c1) * m(r1, c0);
            let sign = if (r + c).is_multiple_of(2) { 1.0 } else { -1.0 };
            sign * minor / det
        };
        let l: [[f64; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|c| inv(r, c)));
        let t: [f64; 3] = std::array::from_fn(|r| -(l[r][0] * m(0, 3) + l[r][1] * m(1, 3) + l[r][2] * m(2, 3)));
        Some(Affine(std::array::from_fn(|r| [l[r][0] as f32, l[r][1] as f32, l[r][2] as f32, t[r] as f32])))
    }

    /// The box of `b`'s eight corners moved by this map (empty stays empty): the moved
    /// centre plus the extent through the absolute matrix (Arvo 1990), no corner by corner.
    #[inline]
    pub fn aabb(&self, b: &Aabb) -> Aabb {
        if b.is_empty() {
            return Aabb::EMPTY;
        }
        let m = &self.0;
        let c = self.point(b.center());
        let e = (b.hi() - b.lo()) * 0.5;
        let r = Vec3::new(
            m[0][0].abs() * e.x + m[0][1].abs() * e.y + m[0][2].abs() * e.z,
            m[1][0].abs() * e.x + m[1][1].abs() * e.y + m[1][2].abs() * e.z,
            m[2][0].abs() * e.x + m[2][1].abs() * e.y + m[2][2].abs() * e.z,
        );
        // Widened by a few ulps of the box's size: rounding must never leave a corner out.
        let pad = (c.abs() + r) * (4.0 * f32::EPSILON);
        Aabb { min: (c - r - pad).into(), max: (c + r + pad).into() }
    }

    /// `ray` in the space this map takes to world space, when `self` is that map's inverse:
    /// origin and direction moved, the direction not renormalised, so that distances `t`
    /// along both rays name the same points.
    #[inline]
    pub fn ray(&self, ray: &Ray) -> Ray {
        Ray { org: self.point(ray.org), dir: self.vector(ray.dir), t_min: ray.t_min, t_max: ray.t_max }
    }

    pub fn is_finite(&self) -> bool {
        self.0.iter().flatten().all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_undoes_the_map() {
        let a = Affine::translation(Vec3::new(1.0, -2.0, 3.0))
            .then_after(&Affine::rotation(37.0, Vec3::new(1.0, 2.0, 0.5)))
            .then_after(&Affine::scale(Vec3::new(2.0, -0.5, 3.0)));
        let inv = a.inverse().unwrap();
        for p in [Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), Vec3::new(-5.0, 0.25, 9.0)] {
            assert!((inv.point(a.point(p)) - p).length() < 1e-5);
        }
        assert!(a.determinant() < 0.0, "one negative scale mirrors");
        assert!(Affine::scale(Vec3::new(1.0, 0.0, 1.0)).inverse().is_none());
        // The normal of a moved plane stays perpendicular to its moved vectors.
        let n = inv.normal_by_inverse(Vec3::Z);
        for v in [Vec3::X, Vec3::Y] {
            assert!(n.dot(a.vector(v)).abs() < 1e-5);
        }
    }

    #[test]
    fn pbrt_columns_and_rotation() {
        let m = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [5.0, 6.0, 7.0, 1.0]];
        assert_eq!(Affine::from_cols4(m), Affine::translation(Vec3::new(5.0, 6.0, 7.0)));
        let r = Affine::rotation(90.0, Vec3::Z);
        assert!((r.vector(Vec3::X) - Vec3::Y).length() < 1e-6);
    }
}
