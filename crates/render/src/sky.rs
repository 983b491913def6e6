//! A procedural sky with a sun, as a lat-long environment map: for tests and the demo (no
//! environment maps are shipped with megaray).
//!
//! Spec: `sky[:key=value,...]` with keys
//!
//! | key | meaning | default |
//! |---|---|---|
//! | `sun_elev` | sun elevation above the horizon, degrees | 35 |
//! | `sun_azim` | sun azimuth, degrees from +X toward +Z | 120 |
//! | `turbidity` | haze, 1.7 (clear) .. 10 (hazy): whiter horizon, wider glow | 3 |
//! | `sun` | irradiance (luminance) of the sun disk on a surface facing it | 3 |
//! | `sun_size` | angular diameter of the sun disk, degrees | 2 |
//! | `width` | map width in pixels (height is half) | 512 |
//!
//! The model is a simple analytic one, not a physical one: a gradient from a bright horizon
//! to a deep blue zenith, a glow around the sun (a Rayleigh-like `1 + cos^2` term and a
//! forward-scattering lobe that widens with turbidity), a darker uniform ground below the
//! horizon, and a sun disk whose total power is set exactly to `sun` (however few pixels
//! it covers). Zenith radiance is about 0.4, so the sky's irradiance on an upward surface is
//! about 2 (plus the sun's).

use std::f32::consts::PI;
use std::path::Path;

use megaray_base::Vec3;

use crate::env::{dir_from_angles, luminance, EnvMap};
use crate::image_out::{temp_path, ImageError};

/// The parameters of a procedural sky (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct SkySpec {
    /// Sun elevation above the horizon, degrees.
    pub sun_elev: f32,
    /// Sun azimuth, degrees from +X toward +Z.
    pub sun_azim: f32,
    /// Haze, 1.7 (clear) to 10 (hazy).
    pub turbidity: f32,
    /// Irradiance (luminance) of the sun disk on a surface facing it.
    pub sun: f32,
    /// Angular diameter of the sun disk, degrees.
    pub sun_size: f32,
    /// Map width in pixels (the height is half).
    pub width: u32,
}

impl Default for SkySpec {
    fn default() -> SkySpec {
        SkySpec { sun_elev: 35.0, sun_azim: 120.0, turbidity: 3.0, sun: 3.0, sun_size: 2.0, width: 512 }
    }
}

impl std::str::FromStr for SkySpec {
    type Err = String;

    /// Parses `sky` or `sky:key=value,...`.
    fn from_str(s: &str) -> Result<SkySpec, String> {
        let rest = match s.strip_prefix("sky") {
            Some("") => return Ok(SkySpec::default()),
            Some(r) => r.strip_prefix(':').ok_or_else(|| format!("`{s}`: a sky spec is sky:key=value,..."))?,
            None => return Err(format!("`{s}` is not a sky spec (sky:key=value,...)")),
        };
        let mut spec = SkySpec::default();
        for kv in rest.split(',').filter(|kv| !kv.trim().is_empty()) {
            let (k, v) = kv.split_once('=').ok_or_else(|| format!("`{s}`: `{kv}` is not key=value"))?;
            let num = || -> Result<f32, String> {
                v.trim()
                    .parse::<f32>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| format!("`{s}`: `{v}` is not a number (for {k})"))
            };
            let check = |x: f32, lo: f32, hi: f32| {
                if (lo..=hi).contains(&x) {
                    Ok(x)
                } else {
                    Err(format!("`{s}`: {k} must be in {lo}..={hi}"))
                }
            };
            match k.trim() {
                "sun_elev" => spec.sun_elev = check(num()?, -90.0, 90.0)?,
                "sun_azim" => spec.sun_azim = num()?,
                "turbidity" => spec.turbidity = check(num()?, 1.0, 20.0)?,
                "sun" => spec.sun = check(num()?, 0.0, 1e6)?,
                "sun_size" => spec.sun_size = check(num()?, 0.01, 30.0)?,
                "width" => {
                    spec.width = v
                        .trim()
                        .parse()
                        .ok()
                        .filter(|w| (8..=16384).contains(w))
                        .ok_or_else(|| format!("`{s}`: width must be a whole number in 8..=16384"))?
                }
                _ => {
                    return Err(format!(
                        "`{s}`: unknown key `{k}` (known: sun_elev, sun_azim, turbidity, sun, sun_size, width)"
                    ))
                }
            }
        }
        Ok(spec)
    }
}

impl SkySpec {
    /// The direction toward the sun.
    pub fn sun_dir(&self) -> Vec3 {
        dir_from_angles((90.0 - self.sun_elev).to_radians(), self.sun_azim.to_radians())
    }

    /// The sky as a lat-long map, `width` x `width / 2`.
    pub fn map(&self) -> EnvMap {
        let (w, h) = (self.width, (self.width / 2).max(4));
        let sun = self.sun_dir();
        let haze = ((self.turbidity - 1.7) / 8.3).clamp(0.0, 1.0);
        let zenith = Vec3::new(0.12, 0.25, 0.6).lerp(Vec3::splat(0.45), haze * 0.6);
        let horizon = Vec3::new(0.65, 0.75, 0.9).lerp(Vec3::splat(0.85), haze);
        // Sun colour: redder when low.
        let low = (1.0 - sun.y.max(0.0)).powi(4);
        let sun_col = Vec3::new(1.0, 0.95 - 0.35 * low, 0.85 - 0.6 * low);
        // The disk's colour at unit luminance, so that `sun` is its luminance irradiance.
        let disk_col = sun_col / luminance(sun_col);
        let ground = Vec3::new(0.22, 0.2, 0.17) * (0.3 + 0.7 * sun.y.max(0.0));
        let glow_width = 2.0 + 6.0 * haze;
        let cos_disk = (self.sun_size.to_radians() * 0.5).cos();
        let mut sky = Vec::with_capacity((w * h) as usize);
        let mut disk = Vec::with_capacity((w * h) as usize);
        let mut disk_power = 0.0f64;
        for y in 0..h {
            let omega =
                2.0 * PI / w as f32 * ((PI * y as f32 / h as f32).cos() - (PI * (y + 1) as f32 / h as f32).cos());
            for x in 0..w {
                // 2x2 sub-samples per pixel so that a small sun disk is not missed.
                let mut s = Vec3::ZERO;
                let mut dk = 0.0;
                for (sx, sy) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                    let d = dir_from_angles(PI * (y as f32 + sy) / h as f32, 2.0 * PI * (x as f32 + sx) / w as f32);
                    let cos_g = d.dot(sun).clamp(-1.0, 1.0);
                    if d.y >= 0.0 {
                        let base = horizon.lerp(zenith, d.y.sqrt());
                        let rayleigh = 0.75 * (1.0 + cos_g * cos_g);
                        let mie = (0.15 + 0.5 * haze) * (glow_width * (cos_g - 1.0)).exp() * 3.0;
                        let sun_up = (sun.y + 0.1).clamp(0.0, 1.0);
                        s += base * rayleigh * (0.3 + 0.7 * sun_up) + sun_col * mie * sun_up;
                    } else {
                        s += ground.lerp(horizon * 0.5, (1.0 + d.y * 8.0).max(0.0));
                    }
                    if cos_g >= cos_disk {
                        dk += 0.25;
                    }
                }
                sky.push(s * 0.25);
                disk.push(dk);
                disk_power += (dk * omega) as f64;
            }
        }
        // The disk's radiance so that its power is exactly `sun`.
        let disk_l = if disk_power > 0.0 { self.sun / disk_power as f32 } else { 0.0 };
        let pixels = sky.iter().zip(&disk).map(|(s, &dk)| (*s + disk_col * dk * disk_l).to_array()).collect();
        EnvMap { width: w, height: h, pixels, rotate: 0.0, scale: 1.0 }
    }
}

/// Writes `map` as a Radiance RGBE `.hdr` file (or OpenEXR when `path` ends in `.exr`),
/// through a temporary file renamed into place. Rotation and scale are baked in only if they
/// are the identity (they are settings of the reader, not of the file).
pub fn write_env(map: &EnvMap, path: &Path) -> Result<(), ImageError> {
    let err = |msg: String| ImageError { path: path.to_path_buf(), msg };
    let exr = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if exr {
        let img = crate::Image { width: map.width, height: map.height, pixels: map.pixels.clone() };
        return crate::image_out::save_exr(&img, None, path);
    }
    let tmp = temp_path(path).map_err(err)?;
    let res = (|| -> Result<(), String> {
        let f = std::fs::File::create(&tmp).map_err(|e| e.to_string())?;
        let mut wr = std::io::BufWriter::new(f);
        let px: Vec<image::Rgb<f32>> = map.pixels.iter().map(|p| image::Rgb(*p)).collect();
        image::codecs::hdr::HdrEncoder::new(&mut wr)
            .encode(&px, map.width as usize, map.height as usize)
            .map_err(|e| e.to_string())?;
        std::io::Write::flush(&mut wr).map_err(|e| e.to_string())?;
        drop(wr);
        std::fs::rename(&tmp, path).map_err(|e| e.to_string())
    })();
    if res.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    res.map_err(err)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_specs() {
        assert_eq!("sky".parse::<SkySpec>().unwrap(), SkySpec::default());
        let s: SkySpec = "sky:sun_elev=20,sun_azim=90,turbidity=5,width=64".parse().unwrap();
        assert_eq!((s.sun_elev, s.sun_azim, s.turbidity, s.width), (20.0, 90.0, 5.0, 64));
        for bad in ["skyx", "sky:foo=1", "sky:sun_elev", "sky:sun_elev=abc", "sky:width=3", "cloud"] {
            assert!(bad.parse::<SkySpec>().is_err(), "{bad}");
        }
    }

    #[test]
    fn sun_power_is_as_asked_and_sky_is_brightest_at_the_sun() {
        let spec = SkySpec { width: 128, ..SkySpec::default() };
        let m = spec.map();
        let sky_only = SkySpec { sun: 0.0, ..spec.clone() }.map();
        let diff = crate::env::luminance(m.power() - sky_only.power());
        assert!((diff - spec.sun).abs() < 1e-3 * spec.sun, "{diff}");
        let at_sun = m.eval(spec.sun_dir());
        assert!(at_sun.max_element() > 10.0 * m.eval(Vec3::Y).max_element());
    }
}
