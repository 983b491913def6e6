//! Deterministic sample values: a low-discrepancy sequence per pixel and the interleaved
//! assignment of light subsets to pixels.
//!
//! Every random number a sample uses is a function of (pixel, sample index, dimension), so a
//! sample re-run after a suspension fires exactly the same rays. Along the sample index the
//! values follow the R2 sequence (Roberts 2018: additive recurrence with the plastic number,
//! low discrepancy in 2D, and a Weyl sequence with the golden ratio in 1D); each pixel and
//! each dimension gets its own toroidal shift (Cranley-Patterson rotation) from a hash, so
//! neighbouring pixels are decorrelated while each pixel's successive frames fill the domain
//! evenly.

use megaray_base::{hash32, u01};

/// 1 / golden ratio: the 1D Weyl sequence step.
const G1: f64 = 0.618_033_988_749_894_9;
/// 1 / plastic number and its square: the R2 sequence steps.
const R2_A1: f64 = 0.754_877_666_246_692_7;
const R2_A2: f64 = 0.569_840_290_998_053_3;

/// `x mod 1`, in `[0, 1)` as an f32 strictly below 1.
#[inline]
fn frac(x: f64) -> f32 {
    let f = (x - x.floor()) as f32;
    if f >= 1.0 {
        0.0
    } else {
        f
    }
}

/// The sub-pixel position of sample `index`: the R2 sequence starting at the pixel centre
/// (index 0 is `(0.5, 0.5)`, the benchmark position), the same pattern in every pixel.
#[inline]
pub fn pixel_offset(index: u32) -> (f32, f32) {
    let i = index as f64;
    (frac(0.5 + i * R2_A1), frac(0.5 + i * R2_A2))
}

/// The 4x4 Bayer matrix: neighbouring cells hold values far apart, so that adjacent pixels
/// use different light subsets.
const BAYER4: [[u32; 4]; 4] = [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]];

/// The light subset (of `subsets`) that sample `index` of pixel (`px`, `py`) shades with
/// (interleaved sampling, Keller and Heidrich 2001). The pattern repeats every 4x4 pixels
/// (a Bayer matrix, so neighbours differ) and moves on by one subset per sample index, so
/// every pixel cycles through all subsets in `subsets` successive samples. Each cycle
/// starts at a different, hashed, offset: the sub-pixel positions ([`pixel_offset`]) of
/// samples `i` and `i + subsets` are close, and without the offset a subset would always
/// be paired with the same part of the pixel (an error that never averages out).
#[inline]
pub fn light_subset(px: u32, py: u32, index: u32, subsets: u32) -> u32 {
    let m = subsets.max(1);
    let cycle_shift = hash32((index / m).wrapping_add(0x51ed_270b)) % m;
    (BAYER4[(py % 4) as usize][(px % 4) as usize] + index % m + cycle_shift) % m
}

/// The random numbers of one sample: dimension after dimension of a per-pixel shifted R2 /
/// Weyl sequence along the sample index. Cheap to create; create one per sample.
#[derive(Clone, Debug)]
pub struct Sampler {
    seed: u32,
    index: u32,
    dim: u32,
}

impl Sampler {
    /// The sampler of sample `index` of pixel (`px`, `py`).
    pub fn new(px: u32, py: u32, index: u32) -> Sampler {
        Sampler { seed: hash32(px.wrapping_mul(0x9e37_79b9) ^ hash32(py ^ 0x5bd1_e995)), index, dim: 0 }
    }

    fn shift(&self, k: u32) -> f64 {
        u01(hash32(self.seed ^ hash32(self.dim.wrapping_mul(0x68e3_1da4).wrapping_add(k)))) as f64
    }

    /// The next value in `[0, 1)`.
    pub fn next_1d(&mut self) -> f32 {
        let v = frac(self.shift(0) + self.index as f64 * G1);
        self.dim += 1;
        v
    }

    /// The next pair of values in `[0, 1)^2`.
    pub fn next_2d(&mut self) -> (f32, f32) {
        let i = self.index as f64;
        let v = (frac(self.shift(0) + i * R2_A1), frac(self.shift(1) + i * R2_A2));
        self.dim += 1;
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_centre_first_and_values_in_range() {
        assert_eq!(pixel_offset(0), (0.5, 0.5));
        let mut s = Sampler::new(3, 7, 12345);
        for _ in 0..100 {
            let v = s.next_1d();
            assert!((0.0..1.0).contains(&v));
        }
    }

    #[test]
    fn same_inputs_same_values() {
        let a: Vec<f32> = (0..8)
            .map({
                let mut s = Sampler::new(5, 9, 3);
                move |_| s.next_1d()
            })
            .collect();
        let b: Vec<f32> = (0..8)
            .map({
                let mut s = Sampler::new(5, 9, 3);
                move |_| s.next_1d()
            })
            .collect();
        assert_eq!(a, b);
    }

    #[test]
    fn sequence_is_evenly_spread() {
        // 64 successive indices of one pixel put one value in each of 16 bins, 4 +- 2 each.
        let mut bins = [0; 16];
        for i in 0..64 {
            let v = Sampler::new(11, 2, i).next_1d();
            bins[(v * 16.0) as usize] += 1;
        }
        assert!(bins.iter().all(|&b| (2..=6).contains(&b)), "{bins:?}");
    }

    #[test]
    fn neighbours_use_different_subsets_and_all_are_cycled() {
        for y in 0..8 {
            for x in 0..8 {
                let s = light_subset(x, y, 0, 16);
                assert_ne!(s, light_subset(x + 1, y, 0, 16));
                assert_ne!(s, light_subset(x, y + 1, 0, 16));
                let mut seen: Vec<u32> = (0..16).map(|i| light_subset(x, y, i, 16)).collect();
                seen.sort();
                assert_eq!(seen, (0..16).collect::<Vec<_>>());
            }
        }
    }
}
