//! Area lights: triangles whose surface emits (a pbrt scene's `AreaLightSource "diffuse"`).
//! Every shader shows an emitting surface at its radiance where a ray meets it; the `path`
//! shader also samples them as lights (next-event estimation), drawing a triangle in
//! proportion to its power and a point uniformly on it, and weighs that against its bounces
//! that hit them by multiple importance sampling ([`AreaLights::pdf`]).
//!
//! A hit is known to emit by its material: each light names the material of its
//! triangles (the importer gives each light a material of its own).

use std::collections::HashMap;

use megaray_base::Vec3;

use crate::luminance;

/// One light as a scene gives it: the material of its triangles, what they emit, and the
/// triangles in world space, wound so that their front emits (both sides if `two_sided`).
#[derive(Clone, Debug, PartialEq)]
pub struct AreaLight {
    /// Index in the scene's material table of the light's triangles.
    pub material: u32,
    /// Emitted radiance, linear RGB.
    pub radiance: Vec3,
    /// Whether both sides emit.
    pub two_sided: bool,
    /// Its triangles (world space).
    pub triangles: Vec<[Vec3; 3]>,
}

/// One emitting triangle, ready to sample.
#[derive(Clone, Copy, Debug)]
struct Emitter {
    p0: Vec3,
    e1: Vec3,
    e2: Vec3,
    /// Unit normal of the emitting (front) side.
    n: Vec3,
    radiance: Vec3,
    two_sided: bool,
}

/// A point drawn on the lights, seen from a surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// The point drawn.
    pub point: Vec3,
    /// Unit direction from the surface point to the light's point.
    pub dir: Vec3,
    /// Distance to the light's point.
    pub dist: f32,
    /// Radiance it sends toward the surface point.
    pub radiance: Vec3,
    /// Density of the draw, per unit solid angle at the surface point.
    pub pdf: f32,
}

/// The scene's area lights: what each emitting material sends, and the triangles to sample.
#[derive(Debug, Default)]
pub struct AreaLights {
    emitters: Vec<Emitter>,
    /// Cumulative power of `emitters`, the last entry 1.
    cdf: Vec<f32>,
    /// Total power: sum of luminance x area x sides.
    total: f32,
    by_material: HashMap<u32, (Vec3, bool)>,
}

impl AreaLights {
    /// The lights `lights` (triangles without area, and lights that emit nothing or
    /// not-finite radiance, dropped).
    pub fn new(lights: &[AreaLight]) -> AreaLights {
        let mut a = AreaLights::default();
        let mut acc = 0.0f64;
        for l in lights {
            let ok = l.radiance.is_finite() && l.radiance.min_element() >= 0.0 && luminance(l.radiance) > 0.0;
            if !ok {
                continue;
            }
            a.by_material.insert(l.material, (l.radiance, l.two_sided));
            let sides = if l.two_sided { 2.0 } else { 1.0 };
            for t in &l.triangles {
                let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
                let c = e1.cross(e2);
                let area = 0.5 * c.length();
                if !(area.is_finite() && area > 0.0 && t[0].is_finite()) {
                    continue;
                }
                acc += (luminance(l.radiance) * area * sides) as f64;
                a.emitters.push(Emitter {
                    p0: t[0],
                    e1,
                    e2,
                    n: c.normalize(),
                    radiance: l.radiance,
                    two_sided: l.two_sided,
                });
                a.cdf.push(acc as f32);
            }
        }
        a.total = acc as f32;
        if acc > 0.0 {
            for c in &mut a.cdf {
                *c = (*c as f64 / acc) as f32;
            }
            if let Some(last) = a.cdf.last_mut() {
                *last = 1.0;
            }
        }
        a
    }

    /// Whether there is nothing to sample.
    pub fn is_empty(&self) -> bool {
        self.emitters.is_empty()
    }

    /// How many triangles emit.
    pub fn triangle_count(&self) -> usize {
        self.emitters.len()
    }

    /// What a surface of `material` emits, and whether both its sides do; `None` if it does
    /// not emit.
    pub fn emission(&self, material: u32) -> Option<(Vec3, bool)> {
        self.by_material.get(&material).copied()
    }

    /// Draws a point on the lights for the surface point `p` from `(u, v, w)` in `[0, 1)^3`:
    /// `u` chooses the triangle, `(v, w)` the point. `None` when the point faces away from
    /// `p` (the draw contributes nothing) or there are no lights.
    pub fn sample(&self, p: Vec3, u: f32, v: f32, w: f32) -> Option<LightSample> {
        if self.total <= 0.0 {
            return None;
        }
        let i = self.cdf.partition_point(|&c| c <= u).min(self.emitters.len() - 1);
        let e = &self.emitters[i];
        // Uniform on the triangle (the square root map).
        let s = v.sqrt();
        let q = e.p0 + e.e1 * (s * (1.0 - w)) + e.e2 * (s * w);
        let d = q - p;
        let dist = d.length();
        if dist.is_nan() || dist <= 0.0 {
            return None;
        }
        let dir = d / dist;
        let cos_l = -e.n.dot(dir);
        if cos_l <= 0.0 && !e.two_sided {
            return None;
        }
        let pdf = self.pdf(e.radiance, e.two_sided, dist, cos_l.abs());
        (pdf > 0.0 && pdf.is_finite()).then_some(LightSample { point: q, dir, dist, radiance: e.radiance, pdf })
    }

    /// The density (per solid angle) with which [`AreaLights::sample`] draws a point of a
    /// light of `radiance` (two-sided or not) at distance `dist`, seen at `cos_l` to its
    /// normal: the triangle's share of the power times one over its area is the same for
    /// every triangle of that radiance, `luminance x sides / total`.
    pub fn pdf(&self, radiance: Vec3, two_sided: bool, dist: f32, cos_l: f32) -> f32 {
        if self.total <= 0.0 || cos_l <= 0.0 {
            return 0.0;
        }
        let sides = if two_sided { 2.0 } else { 1.0 };
        luminance(radiance) * sides / self.total * dist * dist / cos_l
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(y: f32, half: f32, down: bool) -> Vec<[Vec3; 3]> {
        let (a, b, c, d) = (
            Vec3::new(-half, y, -half),
            Vec3::new(half, y, -half),
            Vec3::new(half, y, half),
            Vec3::new(-half, y, half),
        );
        // Wound counter-clockwise seen from below when `down`.
        if down {
            vec![[a, b, c], [a, c, d]]
        } else {
            vec![[a, c, b], [a, d, c]]
        }
    }

    /// The estimator `cos / pdf` of the irradiance at a point below a square light (per
    /// unit radiance) averages to a fine quadrature of it.
    #[test]
    fn sampling_integrates_the_irradiance_and_pdf_matches_the_draws() {
        let light = AreaLight {
            material: 3,
            radiance: Vec3::new(2.0, 1.0, 0.5),
            two_sided: false,
            triangles: quad(2.0, 0.5, true),
        };
        let lights = AreaLights::new(std::slice::from_ref(&light));
        assert_eq!(lights.triangle_count(), 2);
        assert_eq!(lights.emission(3), Some((light.radiance, false)));
        assert_eq!(lights.emission(4), None);
        let p = Vec3::new(0.3, 0.0, -0.2);
        let n = Vec3::Y;
        // Quadrature over the square: E = sum L cos_s cos_l / d^2 dA.
        let steps = 800;
        let mut exact = 0.0f64;
        for i in 0..steps {
            for j in 0..steps {
                let q = Vec3::new(-0.5 + (i as f32 + 0.5) / steps as f32, 2.0, -0.5 + (j as f32 + 0.5) / steps as f32);
                let d = q - p;
                let r2 = d.length_squared();
                let dir = d / r2.sqrt();
                exact += (n.dot(dir) * dir.y / r2) as f64 / (steps * steps) as f64;
            }
        }
        // Stratified draws.
        let k = 256;
        let mut est = 0.0f64;
        for a in 0..k {
            for b in 0..k {
                let u = ((a * 7919 + b * 104729) % (k * k)) as f32 / (k * k) as f32;
                let s = lights.sample(p, u, (a as f32 + 0.5) / k as f32, (b as f32 + 0.5) / k as f32).unwrap();
                assert!((s.radiance - light.radiance).length() < 1e-6);
                // The density the draw reports is the one pdf() gives for that point.
                let cos_l = s.dir.y;
                assert!((s.pdf - lights.pdf(s.radiance, false, s.dist, cos_l)).abs() <= 1e-5 * s.pdf);
                est += (n.dot(s.dir) / s.pdf) as f64;
            }
        }
        est /= (k * k) as f64;
        assert!((est - exact).abs() < 2e-3 * exact, "estimate {est}, quadrature {exact}");
        // Above the light (its back): nothing is drawn.
        assert!(lights.sample(Vec3::new(0.0, 4.0, 0.0), 0.5, 0.5, 0.5).is_none());
        // Two-sided: drawn from above too.
        let two = AreaLights::new(&[AreaLight { two_sided: true, ..light }]);
        assert!(two.sample(Vec3::new(0.0, 4.0, 0.0), 0.5, 0.5, 0.5).is_some());
    }

    #[test]
    fn triangles_are_drawn_in_proportion_to_power() {
        let bright =
            AreaLight { material: 0, radiance: Vec3::splat(3.0), two_sided: false, triangles: quad(1.0, 0.5, true) };
        let big =
            AreaLight { material: 1, radiance: Vec3::splat(1.0), two_sided: false, triangles: quad(1.0, 1.0, true) };
        let none = AreaLight { material: 2, radiance: Vec3::ZERO, two_sided: false, triangles: quad(1.0, 1.0, true) };
        let lights = AreaLights::new(&[bright, big, none]);
        assert_eq!(lights.triangle_count(), 4, "a light that emits nothing is dropped");
        assert_eq!(lights.emission(2), None);
        // Power: 3 x 1 (bright) against 1 x 4 (big): 3/7 of the draws on the bright one.
        let n = 10_000;
        let on_bright = (0..n)
            .filter(|&i| {
                let s = lights.sample(Vec3::ZERO, (i as f32 + 0.5) / n as f32, 0.5, 0.5).unwrap();
                s.radiance.x == 3.0
            })
            .count();
        assert!((on_bright as f32 / n as f32 - 3.0 / 7.0).abs() < 1e-3, "{on_bright}");
    }
}
