//! Images out: tone-mapped sRGB PNG, and linear float OpenEXR with optional extra layers
//! (depth, normal, albedo). Every file is written to a temporary name beside the target and
//! renamed into place, so a failed write never leaves half a file.

use std::path::{Path, PathBuf};

/// A linear RGB float image, row by row from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB, `width * height`, row by row from the top.
    pub pixels: Vec<[f32; 3]>,
}

/// Per-pixel extra outputs (arbitrary output variables) of the primary hits, each the same
/// size as the image when present.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Aovs {
    /// Distance from the eye along the camera ray; `f32::INFINITY` where nothing was hit.
    pub depth: Option<Vec<f32>>,
    /// World-space shading normal, facing the camera; zero where nothing was hit.
    pub normal: Option<Vec<[f32; 3]>>,
    /// Surface albedo (diffuse colour); zero where nothing was hit.
    pub albedo: Option<Vec<[f32; 3]>>,
}

/// An image that could not be written (or, for [`read_exr`], read).
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot write image: {msg}", path.display())]
pub struct ImageError {
    /// The image's file.
    pub path: std::path::PathBuf,
    /// What went wrong.
    pub msg: String,
}

/// How linear radiance becomes display values in `[0, 1]` before sRGB encoding.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ToneCurve {
    /// `min(x, 1)`: the default; radiance 1 is white.
    #[default]
    Clamp,
    /// Reinhard's `x / (1 + x)` per channel: no clipping, compressed highlights.
    Reinhard,
}

/// Tone mapping for 8-bit output: scale by `2^exposure`, apply the curve, encode as sRGB.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ToneMap {
    /// Exposure in stops (EV): the linear values are multiplied by `2^exposure`.
    pub exposure: f32,
    /// The curve applied after the exposure.
    pub curve: ToneCurve,
}

impl ToneMap {
    /// The 8-bit sRGB value of linear `x`.
    pub fn map(&self, x: f32) -> u8 {
        self.map_scaled(x, self.exposure.exp2())
    }

    /// [`ToneMap::map`] with the exposure's factor `scale` worked out once.
    #[inline]
    fn map_scaled(&self, x: f32, scale: f32) -> u8 {
        let x = x * scale;
        let x = match self.curve {
            ToneCurve::Clamp => x,
            ToneCurve::Reinhard => x / (1.0 + x.max(0.0)),
        };
        srgb_by_table(x)
    }
}

/// The sRGB encoding of linear `x` (clamped to `[0, 1]`), rounded to 8 bits.
pub fn srgb(x: f32) -> u8 {
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    let s = if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5) as u8
}

/// [`srgb`] by a table: for each code `k`, the least linear value that [`srgb`] takes to `k`
/// or more, found by bisection over the floats in `[0, 1]`, so the table answers exactly as
/// [`srgb`] does (which is monotonic) in 8 comparisons instead of a `powf`.
pub fn srgb_by_table(x: f32) -> u8 {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    let t = TABLE.get_or_init(|| {
        let mut t = [0.0f32; 256];
        for (k, slot) in t.iter_mut().enumerate().skip(1) {
            // The least bit pattern in [0, 1] whose code is k or more.
            let (mut lo, mut hi) = (0u32, 1.0f32.to_bits());
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if srgb(f32::from_bits(mid)) as usize >= k {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            *slot = f32::from_bits(lo);
        }
        t
    });
    if x.is_nan() || x <= 0.0 {
        return 0;
    }
    let mut k = 0usize;
    for step in [128, 64, 32, 16, 8, 4, 2, 1] {
        if t[k + step] <= x {
            k += step;
        }
    }
    k as u8
}

/// `.NAME.tmp-PID` beside `path` ([`megaray_base::temp`]); temporaries of killed writers in
/// that folder are removed first.
pub(crate) fn temp_path(path: &Path) -> Result<PathBuf, String> {
    let tmp = megaray_base::temp::temp_path(path).ok_or_else(|| "not a file name".to_string())?;
    megaray_base::temp::clean_stale(tmp.parent().unwrap_or(Path::new(".")));
    Ok(tmp)
}

/// Runs `write` on a temporary path, then renames it to `path`; removes it on failure.
fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<(), String>) -> Result<(), ImageError> {
    let err = |msg: String| ImageError { path: path.to_path_buf(), msg };
    let tmp = temp_path(path).map_err(err)?;
    let res = write(&tmp).and_then(|_| std::fs::rename(&tmp, path).map_err(|e| e.to_string()));
    if res.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    res.map_err(err)
}

impl Image {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Image {
        Image { width, height, pixels: vec![[0.0; 3]; width as usize * height as usize] }
    }

    /// 8-bit sRGB bytes (linear values clamped to [0, 1]).
    pub fn to_srgb8(&self) -> Vec<u8> {
        self.to_srgb8_with(&ToneMap::default())
    }

    /// 8-bit sRGB bytes after tone mapping `tm`.
    pub fn to_srgb8_with(&self, tm: &ToneMap) -> Vec<u8> {
        use rayon::prelude::*;
        let scale = tm.exposure.exp2();
        let mut out = vec![0u8; self.pixels.len() * 3];
        // In rows of pixels on the current thread pool: a view tone maps every frame.
        out.par_chunks_mut(3 * 4096).zip(self.pixels.par_chunks(4096)).for_each(|(o, px)| {
            for (o, p) in o.chunks_exact_mut(3).zip(px) {
                for c in 0..3 {
                    o[c] = tm.map_scaled(p[c], scale);
                }
            }
        });
        out
    }

    /// Writes a PNG (sRGB, clamped) through a temporary file renamed into place: never
    /// half-written.
    pub fn save_png(&self, path: &Path) -> Result<(), ImageError> {
        self.save_png_with(path, &ToneMap::default())
    }

    /// Writes a PNG after tone mapping `tm`, through a temporary file renamed into place.
    pub fn save_png_with(&self, path: &Path, tm: &ToneMap) -> Result<(), ImageError> {
        let bytes = self.to_srgb8_with(tm);
        write_atomically(path, |tmp| {
            image::save_buffer_with_format(
                tmp,
                &bytes,
                self.width,
                self.height,
                image::ExtendedColorType::Rgb8,
                image::ImageFormat::Png,
            )
            .map_err(|e| e.to_string())
        })
    }

    /// The root mean square difference from `reference` over all pixels and channels,
    /// divided by the reference's mean value: "RMSE below 1 %" means below 0.01.
    pub fn relative_rmse(&self, reference: &Image) -> f64 {
        assert_eq!(self.pixels.len(), reference.pixels.len(), "images of different sizes");
        let (mut se, mut sum) = (0.0f64, 0.0f64);
        for (p, q) in self.pixels.iter().zip(&reference.pixels) {
            for k in 0..3 {
                se += ((p[k] - q[k]) as f64).powi(2);
                sum += q[k] as f64;
            }
        }
        let n = (3 * self.pixels.len()).max(1) as f64;
        let mean = sum / n;
        if mean > 0.0 {
            (se / n).sqrt() / mean
        } else {
            (se / n).sqrt()
        }
    }

    /// Writes a linear float OpenEXR file (see [`save_exr`]).
    pub fn save_exr(&self, path: &Path, aovs: Option<&Aovs>) -> Result<(), ImageError> {
        save_exr(self, aovs, path)
    }
}

/// Writes `img` as OpenEXR, 32-bit float, channels `R`, `G`, `B`, plus the layers of `aovs`
/// that are present: `depth.Z`, `normal.X/Y/Z`, `albedo.R/G/B`. Lossless (ZIP) compression.
pub fn save_exr(img: &Image, aovs: Option<&Aovs>, path: &Path) -> Result<(), ImageError> {
    use exr::prelude::*;
    let n = img.pixels.len();
    let chan3 = |v: &[[f32; 3]], k: usize| v.iter().map(|p| p[k]).collect::<Vec<f32>>();
    let mut channels: Vec<AnyChannel<FlatSamples>> = Vec::new();
    for (k, name) in ["R", "G", "B"].iter().enumerate() {
        channels.push(AnyChannel::new(*name, FlatSamples::F32(chan3(&img.pixels, k))));
    }
    if let Some(a) = aovs {
        let bad =
            |what: &str| ImageError { path: path.to_path_buf(), msg: format!("the {what} layer has the wrong size") };
        if let Some(d) = &a.depth {
            if d.len() != n {
                return Err(bad("depth"));
            }
            channels.push(AnyChannel::new("depth.Z", FlatSamples::F32(d.clone())));
        }
        for (layer, names, data) in [("normal", ["X", "Y", "Z"], &a.normal), ("albedo", ["R", "G", "B"], &a.albedo)] {
            if let Some(v) = data {
                if v.len() != n {
                    return Err(bad(layer));
                }
                for (k, c) in names.iter().enumerate() {
                    channels.push(AnyChannel::new(format!("{layer}.{c}").as_str(), FlatSamples::F32(chan3(v, k))));
                }
            }
        }
    }
    let size = (img.width as usize, img.height as usize);
    let layer = Layer::new(
        size,
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(channels)),
    );
    let image = exr::image::Image::from_layer(layer);
    write_atomically(path, |tmp| image.write().to_file(tmp).map_err(|e| e.to_string()))
}

/// Reads an OpenEXR file written by [`save_exr`] (or any file with float or half `R`, `G`,
/// `B` channels in its first layer): the colour and whatever AOV layers it has.
pub fn read_exr(path: &Path) -> Result<(Image, Aovs), ImageError> {
    use exr::prelude::read_first_flat_layer_from_file;
    let err = |msg: String| ImageError { path: path.to_path_buf(), msg };
    let len = std::fs::metadata(path).map_err(|e| err(e.to_string()))?.len();
    crate::env::check_exr_sizes(path, len).map_err(err)?;
    let img = read_first_flat_layer_from_file(path).map_err(|e| err(e.to_string()))?;
    let layer = &img.layer_data;
    let (w, h) = (layer.size.0, layer.size.1);
    let get = |name: &str| -> Option<Vec<f32>> {
        let c = layer.channel_data.list.iter().find(|c| c.name == *name)?;
        Some(c.sample_data.values_as_f32().collect())
    };
    let three = |a: &str, b: &str, c: &str| -> Option<Vec<[f32; 3]>> {
        let (x, y, z) = (get(a)?, get(b)?, get(c)?);
        Some(x.iter().zip(&y).zip(&z).map(|((x, y), z)| [*x, *y, *z]).collect())
    };
    let pixels = three("R", "G", "B").ok_or_else(|| err("no R, G, B channels".into()))?;
    let aovs = Aovs {
        depth: get("depth.Z"),
        normal: three("normal.X", "normal.Y", "normal.Z"),
        albedo: three("albedo.R", "albedo.G", "albedo.B"),
    };
    Ok((Image { width: w as u32, height: h as u32, pixels }, aovs))
}
