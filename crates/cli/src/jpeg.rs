//! JPEG frames for `serve`, encoded in horizontal strips on all threads and joined into one
//! baseline JPEG with restart markers: a restart interval of one strip's MCUs makes each
//! strip's entropy-coded data stand alone (the DC predictions start again at a marker), so
//! strips encoded apart join, with a marker between each, into the bytes of one picture that
//! decodes to exactly what encoding it whole gives.

use anyhow::{bail, Context, Result};
use jpeg_encoder::{ColorType, Encoder, SamplingFactor};
use rayon::prelude::*;

/// Rows of an MCU with 2x2 chroma subsampling.
const MCU: u32 = 16;

/// `rgb` (`w` x `h`, 3 bytes a pixel, rows top first) as a JPEG of `quality`, its strips
/// encoded at once on the current rayon pool (at most `strips` of them; one when the picture
/// is too small to split).
pub fn encode(rgb: &[u8], w: u32, h: u32, quality: u8, strips: u32) -> Result<Vec<u8>> {
    if rgb.len() != (w as usize) * (h as usize) * 3 || w == 0 || h == 0 || w > 65535 || h > 65535 {
        bail!("cannot encode a frame: {w}x{h} with {} bytes", rgb.len());
    }
    // Strips of whole MCU rows, the same height but the last; a restart interval holds at
    // most 65,535 MCUs.
    let mcu_rows = h.div_ceil(MCU);
    let cols = w.div_ceil(MCU);
    let per = mcu_rows.div_ceil(strips.clamp(1, mcu_rows)).min(65535 / cols.max(1));
    if per == 0 || per >= mcu_rows {
        return encode_one(rgb, w, h, quality);
    }
    let rows = per * MCU;
    let row_bytes = w as usize * 3;
    let parts: Vec<Result<Vec<u8>>> = rgb
        .par_chunks(rows as usize * row_bytes)
        .map(|strip| encode_one(strip, w, (strip.len() / row_bytes) as u32, quality))
        .collect();
    let parts = parts.into_iter().collect::<Result<Vec<_>>>()?;
    join(&parts, h, (per * cols) as u16)
}

/// One JPEG, 2x2 chroma subsampling, no restart markers.
fn encode_one(rgb: &[u8], w: u32, h: u32, quality: u8) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(rgb.len() / 8);
    let mut enc = Encoder::new(&mut out, quality);
    enc.set_sampling_factor(SamplingFactor::F_2_2);
    enc.encode(rgb, w as u16, h as u16, ColorType::Rgb).context("cannot encode a frame")?;
    Ok(out)
}

/// The segments of a JPEG before its scan data, and where that data starts and ends.
struct Layout {
    /// Offset of the SOF0 segment's marker.
    sof: usize,
    /// Offset of the SOS segment's marker.
    sos: usize,
    /// First byte of entropy-coded data, and the offset of the EOI marker after it.
    data: std::ops::Range<usize>,
}

fn layout(j: &[u8]) -> Result<Layout> {
    if j.len() < 4 || j[..2] != [0xFF, 0xD8] || j[j.len() - 2..] != [0xFF, 0xD9] {
        bail!("a strip is not a whole JPEG");
    }
    let (mut at, mut sof) = (2, None);
    while at + 4 <= j.len() {
        if j[at] != 0xFF {
            bail!("a strip's JPEG has no marker at byte {at}");
        }
        let len = u16::from_be_bytes([j[at + 2], j[at + 3]]) as usize;
        match j[at + 1] {
            0xC0 => sof = Some(at),
            0xDA => {
                let sof = sof.context("a strip's JPEG has no baseline frame header")?;
                return Ok(Layout { sof, sos: at, data: at + 2 + len..j.len() - 2 });
            }
            _ => {}
        }
        at += 2 + len;
    }
    bail!("a strip's JPEG has no scan")
}

/// The strips as one JPEG of height `h`: the first strip's headers with that height and a
/// restart interval of `interval` MCUs, then each strip's scan data, a restart marker
/// (RST0..RST7 in turn) between each two.
fn join(parts: &[Vec<u8>], h: u32, interval: u16) -> Result<Vec<u8>> {
    let first = layout(&parts[0])?;
    let mut out = Vec::with_capacity(parts.iter().map(Vec::len).sum::<usize>() + 16 * parts.len());
    out.extend_from_slice(&parts[0][..first.sos]);
    // SOF0: marker, length, precision, then the height.
    out[first.sof + 5..first.sof + 7].copy_from_slice(&(h as u16).to_be_bytes());
    out.extend_from_slice(&[0xFF, 0xDD, 0x00, 0x04]);
    out.extend_from_slice(&interval.to_be_bytes());
    out.extend_from_slice(&parts[0][first.sos..first.data.end]);
    for (k, p) in parts.iter().enumerate().skip(1) {
        let l = layout(p)?;
        out.extend_from_slice(&[0xFF, 0xD0 + ((k - 1) % 8) as u8]);
        out.extend_from_slice(&p[l.data]);
    }
    out.extend_from_slice(&[0xFF, 0xD9]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A picture with edges, gradients and noise, so that every block has AC terms.
    fn picture(w: u32, h: u32) -> Vec<u8> {
        let mut s = 12345u32;
        let mut out = Vec::with_capacity((w * h * 3) as usize);
        for y in 0..h {
            for x in 0..w {
                s = s.wrapping_mul(1_103_515_245).wrapping_add(12345);
                let noise = (s >> 24) as u8 / 8;
                let edge = if (x / 7 + y / 11) % 2 == 0 { 90 } else { 0 };
                out.extend_from_slice(&[(x * 255 / w) as u8 / 2 + edge, (y * 255 / h) as u8 / 2 + noise, edge + noise]);
            }
        }
        out
    }

    fn decode(j: &[u8]) -> image::RgbImage {
        image::load_from_memory_with_format(j, image::ImageFormat::Jpeg).expect("a valid JPEG").to_rgb8()
    }

    #[test]
    fn strips_joined_decode_to_the_picture_encoded_whole() {
        for (w, h) in [(640, 480), (333, 250), (17, 100), (1000, 47)] {
            let rgb = picture(w, h);
            let whole = decode(&encode_one(&rgb, w, h, 85).unwrap());
            for strips in [2, 3, 8, 64] {
                let joined = encode(&rgb, w, h, 85, strips).unwrap();
                let got = decode(&joined);
                assert_eq!((got.width(), got.height()), (w, h));
                assert!(got == whole, "{w}x{h} in {strips} strips decodes differently");
            }
        }
    }

    #[test]
    fn small_pictures_are_encoded_whole_and_bad_sizes_refused() {
        let rgb = picture(40, 16);
        assert_eq!(encode(&rgb, 40, 16, 85, 4).unwrap(), encode_one(&rgb, 40, 16, 85).unwrap());
        assert!(encode(&rgb, 40, 15, 85, 4).is_err());
        assert!(encode(&[], 0, 0, 85, 2).is_err());
    }
}
