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

/// Dimensions (after the first) drawn from Kronecker sequences; later ones are white noise.
pub const KRONECKER_DIMS: usize = 17;

/// The fractional parts of the square roots of the primes from 2 (5 left out: the golden
/// ratio of the first dimension is made of its root), two per dimension after the first.
const ROOT_STEPS: [f64; 32] = {
    const P: [f64; 32] = [
        2.0, 3.0, 7.0, 11.0, 13.0, 17.0, 19.0, 23.0, 29.0, 31.0, 37.0, 41.0, 43.0, 47.0, 53.0, 59.0, 61.0, 67.0, 71.0,
        73.0, 79.0, 83.0, 89.0, 97.0, 101.0, 103.0, 107.0, 109.0, 113.0, 127.0, 131.0, 137.0,
    ];
    let mut out = [0.0; 32];
    let mut i = 0;
    while i < 32 {
        // Newton's method in a const context (f64::sqrt is not const).
        let mut x = P[i];
        let mut k = 0;
        while k < 60 {
            x = 0.5 * (x + P[i] / x);
            k += 1;
        }
        out[i] = x - (x as u64) as f64;
        i += 1;
    }
    out
};

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

/// The random numbers of one sample: dimension after dimension, each a per-pixel shifted
/// Kronecker (Weyl) sequence along the sample index. The first dimension uses the golden
/// ratio (1D) and R2 (2D); later ones the square roots of primes, so that no two dimensions
/// are the same sequence shifted (they would be perfectly correlated, and an integral over
/// several dimensions, such as a path of bounces, would converge to the wrong value); past
/// [`KRONECKER_DIMS`] dimensions, hashed white noise. Cheap to create; create one per sample.
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

    /// The sequence's step for component `k` (0 or 1) of the current dimension, or `None`
    /// past the Kronecker dimensions.
    fn step(&self, k: usize, two_d: bool) -> Option<f64> {
        let d = self.dim as usize;
        if d == 0 {
            return Some(match (two_d, k) {
                (false, _) => G1,
                (true, 0) => R2_A1,
                _ => R2_A2,
            });
        }
        ROOT_STEPS.get(2 * (d - 1) + k).copied().filter(|_| d < KRONECKER_DIMS)
    }

    fn value(&self, k: usize, two_d: bool) -> f32 {
        match self.step(k, two_d) {
            Some(a) => frac(self.shift(k as u32) + self.index as f64 * a),
            None => u01(hash32(self.seed ^ hash32(self.index ^ hash32(self.dim.wrapping_mul(0x27d4_eb2f) ^ k as u32)))),
        }
    }

    fn shift(&self, k: u32) -> f64 {
        u01(hash32(self.seed ^ hash32(self.dim.wrapping_mul(0x68e3_1da4).wrapping_add(k)))) as f64
    }

    /// The next value in `[0, 1)`.
    pub fn next_1d(&mut self) -> f32 {
        let v = self.value(0, false);
        self.dim += 1;
        v
    }

    /// The next pair of values in `[0, 1)^2`.
    pub fn next_2d(&mut self) -> (f32, f32) {
        let v = (self.value(0, true), self.value(1, true));
        self.dim += 1;
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_steps_are_the_roots_fractions() {
        let p = [2.0f64, 3.0, 7.0, 11.0, 13.0, 17.0, 19.0, 23.0, 29.0, 31.0, 37.0, 41.0, 43.0, 47.0, 53.0, 59.0];
        for (i, p) in p.iter().enumerate() {
            assert!((ROOT_STEPS[i] - p.sqrt().fract()).abs() < 1e-12, "{p}");
        }
    }

    /// No dimension is another shifted: the difference of two dimensions (mod 1) changes with
    /// the sample index, and pairs of dimensions fill the square (each of 8x8 cells gets its
    /// share over 4096 samples).
    #[test]
    fn dimensions_are_not_shifted_copies_of_each_other() {
        for (a, b) in [(0usize, 1usize), (1, 2), (2, 7), (5, 16), (16, 17), (17, 30)] {
            let mut cells = [0u32; 64];
            let mut diffs = Vec::new();
            for i in 0..4096 {
                let mut s = Sampler::new(3, 5, i);
                let v: Vec<f32> = (0..=b).map(|_| s.next_1d()).collect();
                let (x, y) = (v[a], v[b]);
                cells[(x * 8.0) as usize * 8 + (y * 8.0) as usize] += 1;
                diffs.push((y - x).rem_euclid(1.0));
            }
            assert!(cells.iter().all(|&c| (40..=90).contains(&c)), "dims {a},{b}: {cells:?}");
            let spread = diffs.iter().fold(0.0f32, |m, &d| m.max((d - diffs[0]).abs()));
            assert!(spread > 0.5, "dims {a},{b} move together");
        }
    }

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
