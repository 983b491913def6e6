//! Small deterministic helpers: a SplitMix64 generator and trigonometry made of `+ - * /`
//! only, so that a plant is the same byte for byte on every machine and C library.

/// SplitMix64 (Steele, Lea and Flood 2014): tiny, fast, good enough for layouts.
#[derive(Clone, Debug)]
pub(crate) struct Rng(u64);

impl Rng {
    /// A generator for a sub-stream (a unit, an object), independent of how much the parent
    /// stream has been used by then.
    pub(crate) fn derive(seed: u64, stream: u64) -> Rng {
        let mut r = Rng(seed ^ stream.wrapping_mul(0xd6e8_feb8_6659_fd93));
        r.next();
        Rng(r.next() ^ stream)
    }

    #[inline]
    pub(crate) fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub(crate) fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    #[inline]
    pub(crate) fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit() as f32
    }

    /// Uniform integer in `lo..=hi`.
    #[inline]
    pub(crate) fn int(&mut self, lo: u32, hi: u32) -> u32 {
        debug_assert!(lo <= hi);
        lo + (((self.next() >> 32) * (hi - lo + 1) as u64) >> 32) as u32
    }

    /// `true` with probability `p`.
    #[inline]
    pub(crate) fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }

    /// One element of a non-empty slice.
    pub(crate) fn pick<T: Copy>(&mut self, xs: &[T]) -> T {
        xs[self.int(0, xs.len() as u32 - 1) as usize]
    }

    /// An index drawn with the given (non-negative, not all zero) weights.
    pub(crate) fn weighted(&mut self, w: &[f64]) -> usize {
        let total: f64 = w.iter().sum();
        let mut x = self.unit() * total;
        for (i, &wi) in w.iter().enumerate() {
            if x < wi {
                return i;
            }
            x -= wi;
        }
        w.len() - 1
    }
}

/// `(sin x, cos x)` from a Taylor series after reduction to `[-π/4, π/4]`: about 1e-15
/// accurate for the angles used here, and the same everywhere.
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    const FRAC_PI_2: f64 = std::f64::consts::FRAC_PI_2;
    let q = (x / FRAC_PI_2).round();
    let r = x - q * FRAC_PI_2;
    let r2 = r * r;
    // Horner forms of the series up to r^17 and r^18.
    let mut s = 1.0;
    let mut c = 1.0;
    let mut k = 18.0;
    while k > 1.0 {
        c = 1.0 - c * r2 / (k * (k - 1.0));
        s = 1.0 - s * r2 / ((k + 1.0) * k);
        k -= 2.0;
    }
    let s = s * r;
    match (q as i64).rem_euclid(4) {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// Cube root by bisection and Newton steps (only `+ - * /`).
pub(crate) fn cbrt(x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let mut y = 1.0;
    while y * y * y < x {
        y *= 2.0;
    }
    for _ in 0..64 {
        y = (2.0 * y + x / (y * y)) / 3.0;
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trig_is_accurate() {
        for i in -400..400 {
            let x = i as f64 * 0.0137;
            let (s, c) = sin_cos(x);
            assert!((s - x.sin()).abs() < 1e-14 && (c - x.cos()).abs() < 1e-14, "{x}");
        }
        assert!((cbrt(1e9) - 1000.0).abs() < 1e-9);
        assert!((cbrt(2.0) - 2f64.cbrt()).abs() < 1e-15);
    }

    #[test]
    fn rng_ranges() {
        let mut r = Rng::derive(5, 0);
        for _ in 0..1000 {
            let i = r.int(3, 7);
            assert!((3..=7).contains(&i));
            let f = r.range(-2.0, 2.0);
            assert!((-2.0..2.0).contains(&f));
        }
        assert_ne!(Rng::derive(1, 2).next(), Rng::derive(1, 3).next());
    }
}
