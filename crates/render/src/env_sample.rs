//! Sampling directions from an environment map in proportion to its brightness, for the
//! `path` shader's next-event estimation with multiple importance sampling.
//!
//! A pixel is chosen with probability proportional to its luminance times its solid angle,
//! then a direction uniformly (in solid angle) within it: uniform azimuth across the pixel,
//! uniform cosine of the polar angle across its row. The density of a direction is then the
//! luminance of its pixel over the map's total ([`EnvSampler::pdf`]), which is what makes the
//! weights of multiple importance sampling computable for any direction a bounce takes.

use std::f32::consts::PI;

use megaray_base::Vec3;

use crate::env::{luminance, EnvMap};

/// The cumulative distribution over a map's pixels.
#[derive(Clone, Debug)]
pub struct EnvSampler {
    width: u32,
    height: u32,
    rotate: f32,
    /// `cdf[i]`: the luminance times solid angle of pixels `0..i`, over the total; `w*h + 1` long.
    cdf: Vec<f32>,
    /// The luminance (times the map's scale) integrated over the sphere.
    total: f32,
    /// Each pixel's luminance (times the map's scale).
    lum: Vec<f32>,
}

impl EnvSampler {
    /// The sampler of `map`.
    pub fn new(map: &EnvMap) -> EnvSampler {
        let (w, h) = (map.width as usize, map.height as usize);
        let lum: Vec<f32> = map.pixels.iter().map(|p| luminance(Vec3::from(*p)) * map.scale).collect();
        let mut cdf = Vec::with_capacity(w * h + 1);
        let mut acc = 0.0f64;
        cdf.push(0.0);
        for y in 0..h {
            let omega = map.pixel_solid_angle(y as u32) as f64;
            for x in 0..w {
                acc += lum[y * w + x] as f64 * omega;
                cdf.push(acc as f32);
            }
        }
        let total = acc as f32;
        if total > 0.0 {
            for c in &mut cdf {
                *c /= total;
            }
        }
        EnvSampler { width: map.width, height: map.height, rotate: map.rotate, cdf, total, lum }
    }

    /// Whether the map is black (nothing to sample).
    pub fn is_black(&self) -> bool {
        self.total <= 0.0
    }

    /// A direction for the random numbers `u` (chooses the pixel), `v`, `w` (the point in
    /// it), and its density in solid angle. `None` for a black map.
    pub fn sample(&self, u: f32, v: f32, w: f32) -> Option<(Vec3, f32)> {
        if self.is_black() {
            return None;
        }
        // The first pixel whose cumulative share exceeds u (never one of zero weight).
        let n = self.lum.len();
        let i = self.cdf[1..].partition_point(|&c| c <= u).min(n - 1);
        let i = (0..=i).rev().find(|&j| self.cdf[j + 1] > self.cdf[j]).unwrap_or(i);
        let (x, y) = ((i % self.width as usize) as f32, (i / self.width as usize) as f32);
        let phi = 2.0 * PI * (x + v) / self.width as f32 + self.rotate;
        let (c0, c1) = ((PI * y / self.height as f32).cos(), (PI * (y + 1.0) / self.height as f32).cos());
        let cos_t = c0 + (c1 - c0) * w;
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let d = Vec3::new(sin_t * phi.cos(), cos_t, sin_t * phi.sin());
        Some((d, self.lum[i] / self.total))
    }

    /// The density in solid angle with which [`EnvSampler::sample`] gives direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        if self.is_black() {
            return 0.0;
        }
        self.lum[crate::env::pixel_of(d, self.width, self.height, self.rotate)] / self.total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The estimate of the map's luminance integral from samples, L(d) / pdf(d), is exact for
    /// a piecewise constant map sampled by its own pixels; and the sampled direction's pdf is
    /// what pdf() says of it.
    #[test]
    fn samples_and_density_agree() {
        let mut m = EnvMap::constant([0.1; 3], 16, 8);
        m.pixels[2 * 16 + 3] = [50.0; 3];
        m.pixels[6 * 16 + 11] = [0.0; 3];
        m.rotate = 0.7;
        let s = EnvSampler::new(&m);
        let total: f32 = (0..8u32)
            .map(|y| {
                (0..16).map(|x| luminance(Vec3::from(m.pixels[(y * 16 + x) as usize]))).sum::<f32>()
                    * m.pixel_solid_angle(y)
            })
            .sum();
        for k in 0..2000 {
            let u = (k as f32 + 0.5) / 2000.0;
            let (d, pdf) = s.sample(u, (k as f32 * 0.618).fract(), (k as f32 * 0.754).fract()).unwrap();
            assert!((d.length() - 1.0).abs() < 1e-4);
            assert!((s.pdf(d) - pdf).abs() <= 1e-3 * pdf, "sample {k}: {} vs {pdf}", s.pdf(d));
            assert!(pdf > 0.0);
        }
        // The density integrates to one over the sphere.
        let integral: f32 = (0..8u32)
            .map(|y| {
                (0..16).map(|x| luminance(Vec3::from(m.pixels[(y * 16 + x) as usize]))).sum::<f32>()
                    * m.pixel_solid_angle(y)
            })
            .sum::<f32>()
            / total;
        assert!((integral - 1.0).abs() < 1e-5);
        assert!(EnvSampler::new(&EnvMap::constant([0.0; 3], 4, 2)).sample(0.5, 0.5, 0.5).is_none());
    }
}
