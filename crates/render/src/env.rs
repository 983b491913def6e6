//! HDR environment light: a latitude-longitude map, and its approximation by virtual
//! directional lights (Agarwal et al. 2003, Kollig and Keller 2003).
//!
//! **Map convention.** Column `u` (0 at the left) is the azimuth `phi = 2 pi (u + 0.5) / width`
//! measured from +X toward +Z; row `v` (0 at the top) is the polar angle
//! `theta = pi (v + 0.5) / height` from +Y (up). Direction
//! `(sin theta cos phi, cos theta, sin theta sin phi)`. `rotate` turns the map about +Y
//! (adds to `phi`); `scale` multiplies its radiance.
//!
//! **Virtual lights.** [`EnvLights::from_map`] draws `N` directions with probability
//! proportional to luminance times the solid angle of each pixel (a CDF over the pixels,
//! inverted at `N` stratified points; inside a pixel the direction is uniform in solid
//! angle). Each light's RGB weight is `radiance * solid angle / (pdf * N)`, so the weights
//! sum to the integral of the map over the sphere: the luminance exactly (every light carries
//! the same luminance, `total / N`), the colour within the stratification error. The lights
//! are then dealt round-robin into `M` subsets (light `k` to subset `k mod M`), each a
//! stratified sample of the whole sky; a hit shades against one subset with weights times
//! `M` (see [`crate::sampling::light_subset`]).

use std::f32::consts::PI;
use std::path::{Path, PathBuf};

use megaray_base::{hash32, u01, Vec3};

/// Relative luminance of linear Rec.709 RGB.
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// An environment map that could not be read.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot read environment map: {msg}", path.display())]
pub struct EnvError {
    /// The map's file.
    pub path: PathBuf,
    /// What is wrong with it.
    pub msg: String,
}

/// A latitude-longitude map of radiance (see the module documentation for the convention).
#[derive(Clone, Debug, PartialEq)]
pub struct EnvMap {
    /// Pixels around (azimuth 0 to 360 degrees).
    pub width: u32,
    /// Pixels from the zenith (top) to the nadir.
    pub height: u32,
    /// Linear RGB radiance, row by row from the top (+Y).
    pub pixels: Vec<[f32; 3]>,
    /// Rotation about +Y, radians.
    pub rotate: f32,
    /// Radiance multiplier.
    pub scale: f32,
}

impl EnvMap {
    /// A map of `width` x `height` pixels, all `c`.
    pub fn constant(c: [f32; 3], width: u32, height: u32) -> EnvMap {
        EnvMap { width, height, pixels: vec![c; (width * height) as usize], rotate: 0.0, scale: 1.0 }
    }

    /// Reads a Radiance RGBE (`.hdr`) or OpenEXR (`.exr`) lat-long map. Negative values are
    /// clamped to 0; a non-finite value, an empty image or an undecodable file is an error
    /// naming the file.
    pub fn load(path: &Path) -> Result<EnvMap, EnvError> {
        let err = |msg: String| EnvError { path: path.to_path_buf(), msg };
        let reader = image::ImageReader::open(path)
            .map_err(|e| err(e.to_string()))?
            .with_guessed_format()
            .map_err(|e| err(e.to_string()))?;
        let is_exr = match reader.format() {
            Some(image::ImageFormat::Hdr) => false,
            Some(image::ImageFormat::OpenExr) => true,
            _ => return Err(err("not a Radiance .hdr or OpenEXR .exr file".into())),
        };
        // Sizes from the header are checked before anything is allocated from them: at most
        // 2^28 pixels, and at most 1,024 per byte of the file (no real compression packs
        // more; a lying header would otherwise make the decoder allocate gigabytes).
        let len = std::fs::metadata(path).map_err(|e| err(e.to_string()))?.len();
        let (w, h) = reader.into_dimensions().map_err(|e| err(format!("malformed header ({e})")))?;
        let pixels = w as u64 * h as u64;
        if pixels > (1 << 28) || pixels > len.saturating_mul(1024) {
            return Err(err(format!("the header claims {w}x{h} pixels, more than a {len}-byte file can hold")));
        }
        if is_exr {
            check_exr_sizes(path, len).map_err(err)?;
        }
        let mut reader = image::ImageReader::open(path)
            .map_err(|e| err(e.to_string()))?
            .with_guessed_format()
            .map_err(|e| err(e.to_string()))?;
        let mut limits = image::Limits::default();
        limits.max_alloc = Some(pixels * 32 + (64 << 20));
        reader.limits(limits);
        let img = reader.decode().map_err(|e| err(format!("malformed or truncated image data ({e})")))?.into_rgb32f();
        let (width, height) = img.dimensions();
        if width == 0 || height == 0 {
            return Err(err("the image is empty".into()));
        }
        let mut pixels = Vec::with_capacity((width * height) as usize);
        for (i, p) in img.pixels().enumerate() {
            if !p.0.iter().all(|c| c.is_finite()) {
                let (x, y) = (i as u32 % width, i as u32 / width);
                return Err(err(format!("pixel ({x}, {y}) is not a finite number")));
            }
            pixels.push(p.0.map(|c| c.max(0.0)));
        }
        Ok(EnvMap { width, height, pixels, rotate: 0.0, scale: 1.0 })
    }

    /// The direction through the centre of map position (`u`, `v`) in `[0, 1)^2`, rotation
    /// included.
    pub fn direction(&self, u: f32, v: f32) -> Vec3 {
        dir_from_angles(PI * v, 2.0 * PI * u + self.rotate)
    }

    /// The radiance seen in direction `d` (normalised), bilinear between pixel centres
    /// (wrapping around in azimuth, clamped at the poles).
    pub fn eval(&self, d: Vec3) -> Vec3 {
        let theta = d.y.clamp(-1.0, 1.0).acos();
        let phi = (d.z.atan2(d.x) - self.rotate).rem_euclid(2.0 * PI);
        let fx = phi / (2.0 * PI) * self.width as f32 - 0.5;
        let fy = (theta / PI * self.height as f32 - 0.5).clamp(0.0, (self.height - 1) as f32);
        let (x0, y0) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - x0, fy - y0);
        let w = self.width as i64;
        let xa = (x0 as i64).rem_euclid(w) as u32;
        let xb = (x0 as i64 + 1).rem_euclid(w) as u32;
        let ya = y0 as u32;
        let yb = (ya + 1).min(self.height - 1);
        let px = |x: u32, y: u32| Vec3::from(self.pixels[(y * self.width + x) as usize]);
        let top = px(xa, ya).lerp(px(xb, ya), tx);
        let bottom = px(xa, yb).lerp(px(xb, yb), tx);
        top.lerp(bottom, ty) * self.scale
    }

    /// The radiance of the pixel that holds direction `d` (normalised), unfiltered.
    pub fn eval_pixel(&self, d: Vec3) -> Vec3 {
        Vec3::from(self.pixels[pixel_of(d, self.width, self.height, self.rotate)]) * self.scale
    }

    /// The solid angle of a pixel of row `y`.
    pub fn pixel_solid_angle(&self, y: u32) -> f32 {
        let (c0, c1) = self.row_cos(y);
        2.0 * PI / self.width as f32 * (c0 - c1)
    }

    fn row_cos(&self, y: u32) -> (f32, f32) {
        let t0 = PI * y as f32 / self.height as f32;
        let t1 = PI * (y + 1) as f32 / self.height as f32;
        (t0.cos(), t1.cos())
    }

    /// The integral of the radiance over the sphere (RGB): what the virtual lights' weights
    /// add up to.
    pub fn power(&self) -> Vec3 {
        let mut sum = [0.0f64; 3];
        for y in 0..self.height {
            let omega = self.pixel_solid_angle(y) as f64;
            for x in 0..self.width {
                let p = self.pixels[(y * self.width + x) as usize];
                for k in 0..3 {
                    sum[k] += p[k] as f64 * omega;
                }
            }
        }
        Vec3::new(sum[0] as f32, sum[1] as f32, sum[2] as f32) * self.scale
    }
}

/// The index of the pixel of a `width` x `height` lat-long map rotated by `rotate` that holds
/// direction `d` (normalised).
pub(crate) fn pixel_of(d: Vec3, width: u32, height: u32, rotate: f32) -> usize {
    let theta = d.y.clamp(-1.0, 1.0).acos();
    let phi = (d.z.atan2(d.x) - rotate).rem_euclid(2.0 * PI);
    let x = ((phi / (2.0 * PI) * width as f32) as u32).min(width - 1);
    let y = ((theta / PI * height as f32) as u32).min(height - 1);
    (y * width + x) as usize
}

/// Checks an OpenEXR file's header before its pixels are decoded: the bytes its layers (and
/// any one tile) claim to hold, uncompressed, must fit in 1,024 per byte of the file and in
/// 4 GiB. The decoder allocates what a block claims; a lying header would make it allocate
/// gigabytes (fuzzing found such files).
pub(crate) fn check_exr_sizes(path: &Path, len: u64) -> Result<(), String> {
    let meta =
        exr::meta::MetaData::read_from_file(path, false).map_err(|e| format!("malformed OpenEXR header ({e})"))?;
    let bound = (len as u128 * 1024).min(4 << 30);
    let mut total = 0u128;
    for h in meta.headers.iter() {
        let bpp = h.channels.list.iter().map(|c| c.sample_type.bytes_per_sample() as u128).sum::<u128>();
        total += h.layer_size.0 as u128 * h.layer_size.1 as u128 * bpp;
        if let exr::meta::BlockDescription::Tiles(t) = &h.blocks {
            if t.tile_size.0 as u128 * t.tile_size.1 as u128 * bpp > bound {
                return Err(format!(
                    "a tile of {}x{} pixels is more than the file can hold",
                    t.tile_size.0, t.tile_size.1
                ));
            }
        }
    }
    if total > bound {
        return Err(format!("the header claims {total} bytes of pixels, more than a {len}-byte file can hold"));
    }
    Ok(())
}

/// The unit direction at polar angle `theta` (from +Y) and azimuth `phi` (from +X toward +Z).
pub fn dir_from_angles(theta: f32, phi: f32) -> Vec3 {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    Vec3::new(st * cp, ct, st * sp)
}

/// A directional light: the direction toward it and its weight (irradiance on a surface
/// facing it, RGB).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirLight {
    /// Unit direction toward the light.
    pub dir: Vec3,
    /// Irradiance it gives a surface facing it (RGB).
    pub weight: Vec3,
}

/// Virtual directional lights approximating an environment map, split into subsets for
/// interleaved sampling.
#[derive(Clone, Debug)]
pub struct EnvLights {
    /// The lights, subset after subset (subset `j` is `lights[starts[j]..starts[j + 1]]`).
    lights: Vec<DirLight>,
    starts: Vec<usize>,
}

impl EnvLights {
    /// Draws `n` lights from `map` (see the module documentation) and deals them into
    /// `subsets` subsets. A black map gives no lights.
    pub fn from_map(map: &EnvMap, n: u32, subsets: u32) -> EnvLights {
        let m = subsets.max(1) as usize;
        let (w, h) = (map.width as usize, map.height as usize);
        // CDF over pixels of luminance * solid angle.
        let mut cdf = Vec::with_capacity(w * h + 1);
        cdf.push(0.0f64);
        let mut total = 0.0f64;
        for y in 0..h {
            let omega = map.pixel_solid_angle(y as u32) as f64;
            for x in 0..w {
                total += luminance(Vec3::from(map.pixels[y * w + x])) as f64 * omega;
                cdf.push(total);
            }
        }
        let mut drawn = Vec::with_capacity(n as usize);
        if total > 0.0 && n > 0 {
            for k in 0..n {
                let xi = u01(hash32(k.wrapping_mul(0x2c1b_3c6d) ^ 0x297a_2d39)) as f64;
                let target = (k as f64 + xi) / n as f64 * total;
                // The pixel i with cdf[i] <= target < cdf[i + 1], skipping empty pixels.
                let i = cdf.partition_point(|&c| c <= target).clamp(1, w * h) - 1;
                let (x, y) = (i % w, i / w);
                let c = Vec3::from(map.pixels[i]);
                let lum = luminance(c);
                if lum <= 0.0 {
                    continue;
                }
                let (r1, r2) = (u01(hash32(k ^ 0x8a5c_d789)), u01(hash32(k.wrapping_add(0x1b87_3593))));
                let (c0, c1) = map.row_cos(y as u32);
                let cos_t = c0 - r2 * (c0 - c1);
                let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                let phi = 2.0 * PI * (x as f32 + r1) / w as f32 + map.rotate;
                let dir = Vec3::new(sin_t * phi.cos(), cos_t, sin_t * phi.sin());
                // radiance * omega / (pdf * n), pdf = lum * omega / total.
                let weight = c * (map.scale * (total / n as f64) as f32 / lum);
                drawn.push(DirLight { dir, weight });
            }
        }
        let mut lights = Vec::with_capacity(drawn.len());
        let mut starts = Vec::with_capacity(m + 1);
        for j in 0..m {
            starts.push(lights.len());
            lights.extend(drawn.iter().skip(j).step_by(m).copied());
        }
        starts.push(lights.len());
        EnvLights { lights, starts }
    }

    /// Every light.
    pub fn all(&self) -> &[DirLight] {
        &self.lights
    }

    /// The number of subsets.
    pub fn subsets(&self) -> u32 {
        (self.starts.len() - 1) as u32
    }

    /// The lights of subset `j` (`j` taken modulo the number of subsets).
    pub fn subset(&self, j: u32) -> &[DirLight] {
        let j = j as usize % (self.starts.len() - 1);
        &self.lights[self.starts[j]..self.starts[j + 1]]
    }

    /// The sum of all weights (equals [`EnvMap::power`] up to the colour's stratification
    /// error; the luminance exactly).
    pub fn power(&self) -> Vec3 {
        self.lights.iter().map(|l| l.weight).sum()
    }
}

/// An environment: what rays that miss see, and the virtual lights that stand for it.
#[derive(Clone, Debug)]
pub struct Environment {
    /// The map rays that miss look up.
    pub map: EnvMap,
    /// Its virtual lights.
    pub lights: EnvLights,
    /// Continuous sampling of the map by brightness (the `path` shader's).
    pub sampler: crate::env_sample::EnvSampler,
}

impl Environment {
    /// The default number of virtual lights.
    pub const DEFAULT_LIGHTS: u32 = 1024;
    /// The default number of light subsets (a 4x4 pixel pattern).
    pub const DEFAULT_SUBSETS: u32 = 16;

    /// `map` with `n` virtual lights in `subsets` subsets.
    pub fn new(map: EnvMap, n: u32, subsets: u32) -> Environment {
        let lights = EnvLights::from_map(&map, n, subsets);
        let sampler = crate::env_sample::EnvSampler::new(&map);
        Environment { map, lights, sampler }
    }

    /// A constant environment of radiance `c` (a small map; the lights are spread evenly
    /// over the sphere).
    pub fn constant(c: [f32; 3], n: u32, subsets: u32) -> Environment {
        Environment::new(EnvMap::constant(c, 32, 16), n, subsets)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn direction_and_lookup_agree() {
        let mut m = EnvMap::constant([0.0; 3], 16, 8);
        m.pixels[3 * 16 + 5] = [1.0, 2.0, 3.0];
        for rot in [0.0, 1.0] {
            m.rotate = rot;
            let d = m.direction(5.5 / 16.0, 3.5 / 8.0);
            assert!((m.eval(d) - Vec3::new(1.0, 2.0, 3.0)).abs().max_element() < 1e-4);
            // Half way to the next pixel: half the value.
            let d = m.direction(6.0 / 16.0, 3.5 / 8.0);
            assert!((m.eval(d) - Vec3::new(0.5, 1.0, 1.5)).abs().max_element() < 1e-4);
        }
        // Wrapping around in azimuth.
        m.pixels[3 * 16 + 15] = [4.0; 3];
        m.rotate = 0.0;
        assert!((m.eval(m.direction(0.0, 3.5 / 8.0)) - Vec3::splat(2.0)).abs().max_element() < 1e-4);
    }

    #[test]
    fn constant_map_power_is_4_pi_l() {
        let m = EnvMap::constant([1.0, 0.5, 0.25], 32, 16);
        let p = m.power();
        assert!((p.x - 4.0 * PI).abs() < 1e-4 && (p.z - PI).abs() < 1e-4, "{p}");
        let l = EnvLights::from_map(&m, 1024, 16);
        assert_eq!(l.all().len(), 1024);
        assert_eq!(l.subsets(), 16);
        assert_eq!(l.subset(3).len(), 64);
        let q = l.power();
        assert!((q - p).abs().max_element() < 1e-3 * p.x, "{q} vs {p}");
        // Directions spread over the sphere: mean near zero.
        let mean: Vec3 = l.all().iter().map(|l| l.dir).sum::<Vec3>() / 1024.0;
        assert!(mean.length() < 0.05, "{mean}");
    }
}
