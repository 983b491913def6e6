use std::path::Path;

/// A linear RGB float image, row by row from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 3]>,
}

/// An image that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot write image: {msg}", path.display())]
pub struct ImageError {
    pub path: std::path::PathBuf,
    pub msg: String,
}

fn srgb(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5) as u8
}

impl Image {
    pub fn new(width: u32, height: u32) -> Image {
        Image { width, height, pixels: vec![[0.0; 3]; width as usize * height as usize] }
    }

    /// 8-bit sRGB bytes (linear values clamped to [0, 1]).
    pub fn to_srgb8(&self) -> Vec<u8> {
        self.pixels.iter().flat_map(|p| p.map(srgb)).collect()
    }

    /// Writes a PNG (sRGB) through a temporary file renamed into place: never half-written.
    pub fn save_png(&self, path: &Path) -> Result<(), ImageError> {
        let err = |msg: String| ImageError { path: path.to_path_buf(), msg };
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let name = path.file_name().ok_or_else(|| err("not a file name".into()))?.to_string_lossy();
        let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
        let res = image::save_buffer_with_format(
            &tmp,
            &self.to_srgb8(),
            self.width,
            self.height,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(|e| err(e.to_string()))
        .and_then(|_| std::fs::rename(&tmp, path).map_err(|e| err(e.to_string())));
        if res.is_err() {
            let _ = std::fs::remove_file(&tmp);
        }
        res
    }
}
