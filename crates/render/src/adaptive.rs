//! Adaptive sampling for progressive frames: pixels where the picture so far changes sharply
//! between neighbours (silhouettes of thin parts against the sky, fine detail, hard shadow
//! edges) take `settings.adaptive` samples a frame, the others `settings.spp`. A pixel's
//! frame value is the mean of its samples, so the accumulated mean stays unbiased; only
//! its noise falls faster where the eye sees it. The set of such pixels only grows (once
//! chosen, always chosen), so no sample index is ever taken twice: a chosen pixel's frame
//! `f` takes indices `f * n .. (f + 1) * n`, above every index of its earlier frames.

use std::sync::atomic::{AtomicU8, Ordering::Relaxed};

use crate::env::luminance;
use crate::image_out::Image;

/// A pixel is chosen when the luminance of a neighbour (of 8) differs from its own by more
/// than this fraction of their sum.
pub const CONTRAST: f32 = 0.1;

/// After how many frames the choice is made again (it only grows). A pixel chosen then
/// starts its sums again ([`crate::Accumulator::restart`]): its frames so far, of one
/// sample each, would otherwise weigh as much as each of its frames of many.
pub fn updates_after(frames: u32) -> bool {
    frames.is_power_of_two() && frames <= 64
}

/// The pixels of `img` to sample more: those whose luminance differs from a neighbour's by
/// more than [`CONTRAST`] of the two's sum.
pub fn sharp_pixels(img: &Image) -> Vec<bool> {
    let (w, h) = (img.width as usize, img.height as usize);
    let lum: Vec<f32> = img.pixels.iter().map(|p| luminance((*p).into())).collect();
    let mut out = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let l = lum[y * w + x];
            'n: for dy in -1i32..=1 {
                for dx in -1i32..=1 {
                    let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                    if (dx, dy) == (0, 0) || nx < 0 || ny < 0 || nx >= w as i32 || ny >= h as i32 {
                        continue;
                    }
                    let m = lum[ny as usize * w + nx as usize];
                    if (l - m).abs() > CONTRAST * (l + m).max(1e-6) {
                        out[y * w + x] = true;
                        break 'n;
                    }
                }
            }
        }
    }
    out
}

/// Per pixel of a `width` x `height` frame, the samples a frame takes when more than the
/// setting's (0: the setting's). Written between frames, read by every thread during one
/// (relaxed: a frame reads what the last choice left; no lock on the way).
#[derive(Debug)]
pub struct PixelSamples {
    width: u32,
    height: u32,
    n: Vec<AtomicU8>,
}

impl PixelSamples {
    /// For `w` x `h` frames, no pixel sampled more.
    pub fn new(w: u32, h: u32) -> PixelSamples {
        PixelSamples { width: w, height: h, n: (0..w as usize * h as usize).map(|_| AtomicU8::new(0)).collect() }
    }

    /// The samples pixel (`x`, `y`) of a `w` x `h` frame takes, if more than the setting's.
    #[inline]
    pub fn get(&self, x: u32, y: u32, w: u32, h: u32) -> Option<u32> {
        if (w, h) != (self.width, self.height) {
            return None;
        }
        let n = self.n.get((y * w + x) as usize)?.load(Relaxed);
        (n > 0).then_some(n as u32)
    }

    /// Adds the `chosen` pixels (of a frame of this size; another size is ignored), each to
    /// take `n` samples. Returns the pixels chosen now that were not before.
    pub fn choose(&self, chosen: &[bool], n: u8) -> Vec<bool> {
        if self.n.len() != chosen.len() {
            return Vec::new();
        }
        self.n.iter().zip(chosen).map(|(s, &c)| c && s.swap(n, Relaxed) == 0).collect()
    }

    /// How many pixels are chosen.
    pub fn count(&self) -> usize {
        self.n.iter().filter(|s| s.load(Relaxed) > 0).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An edge is chosen on both of its sides, a flat field and gentle gradient are not.
    #[test]
    fn sharp_pixels_are_the_edges() {
        let (w, h) = (8u32, 5u32);
        let pixels = (0..w * h)
            .map(|i| {
                let x = i % w;
                let v = if x < 4 { 1.0 + 0.01 * x as f32 } else { 0.2 };
                [v, v, v]
            })
            .collect();
        let img = Image { width: w, height: h, pixels };
        let s = sharp_pixels(&img);
        for y in 0..h {
            for x in 0..w {
                assert_eq!(s[(y * w + x) as usize], x == 3 || x == 4, "pixel {x},{y}");
            }
        }
    }

    /// Choices only grow, are read per pixel, and a frame of another size reads none.
    #[test]
    fn choices_grow_and_belong_to_one_size() {
        let p = PixelSamples::new(2, 2);
        assert_eq!(p.get(0, 0, 2, 2), None);
        assert_eq!(p.choose(&[true, false, false, false], 16), [true, false, false, false]);
        assert_eq!(p.choose(&[true, false, true, false], 16), [false, false, true, false], "only the new ones");
        assert_eq!(p.choose(&[true; 3], 16), Vec::<bool>::new(), "a choice of another size is ignored");
        assert_eq!(p.count(), 2);
        assert_eq!((p.get(0, 0, 2, 2), p.get(1, 0, 2, 2), p.get(0, 1, 2, 2)), (Some(16), None, Some(16)));
        assert_eq!(p.get(0, 0, 3, 2), None);
    }
}
