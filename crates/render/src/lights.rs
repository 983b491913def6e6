//! Choosing which of a sample's virtual lights to trace shadow rays to.
//!
//! Interleaved sampling gives each sample a subset of the environment's virtual lights; of
//! those, `light_samples` are traced. [`LightSelect::Contribution`] (the default) draws them in
//! proportion to what each can bring to the shaded point: its power (luminance) times the
//! cosine there, so lights below the surface's horizon are never drawn and bright lights
//! overhead are drawn often. [`LightSelect::Uniform`] is the seed tutorial's choice: every light
//! of the subset alike. Both are unbiased estimates of the sum over the subset's lights; both
//! are stratified ([`Draws`]: draw `j` of `k` uses `(j + u) / k` for one random `u`).

/// How a sample draws its shadow rays' lights from its subset.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LightSelect {
    /// In proportion to power times cosine at the shaded point (the default).
    #[default]
    Contribution,
    /// Uniformly (the seed tutorial's interleaved sampling).
    Uniform,
}

impl LightSelect {
    /// Every choice, with the name the command line takes.
    pub const ALL: [(&'static str, LightSelect); 2] =
        [("contribution", LightSelect::Contribution), ("uniform", LightSelect::Uniform)];
}

/// `k` stratified draws of indices in proportion to the weights `w`: draw `j` takes the index
/// whose share of the cumulative weight holds `(j + u) / k` of the total. Each item is an index
/// and the factor `1 / (k p)` (`p` = its weight over the total) that makes the sum of the drawn
/// terms, each times its factor, an unbiased estimate of the sum of all terms. Indices of
/// weight 0 are never drawn; with every weight 0 there are no draws.
pub struct Draws<'a> {
    w: &'a [f32],
    total: f32,
    last: usize,
    k: usize,
    u: f32,
    j: usize,
    i: usize,
    below: f32,
}

impl<'a> Draws<'a> {
    /// The draws for weights `w` (non-negative), `k` of them, from the random number `u` in `[0, 1)`.
    pub fn new(w: &'a [f32], k: usize, u: f32) -> Draws<'a> {
        let total: f32 = w.iter().sum();
        let last = w.iter().rposition(|&x| x > 0.0).unwrap_or(0);
        let k = if total > 0.0 { k } else { 0 };
        Draws { w, total, last, k, u, j: 0, i: 0, below: 0.0 }
    }
}

impl Iterator for Draws<'_> {
    type Item = (usize, f32);

    fn next(&mut self) -> Option<(usize, f32)> {
        if self.j >= self.k {
            return None;
        }
        let t = (self.j as f32 + self.u) / self.k as f32 * self.total;
        self.j += 1;
        // The targets rise with j: one pass over the weights serves every draw.
        while self.i < self.last && (self.below + self.w[self.i] <= t || self.w[self.i] == 0.0) {
            self.below += self.w[self.i];
            self.i += 1;
        }
        let p = self.w[self.i] / self.total;
        Some((self.i, 1.0 / (self.k as f32 * p)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The expectation over `u` of the estimate, exactly: the draws change only where a
    /// target `(j + u) / k * total` crosses a cumulative weight, so the estimate is constant
    /// between those points; sum it at each interval's middle times the interval's length.
    fn expectation(w: &[f32], f: &[f64], k: usize) -> f64 {
        let total: f64 = w.iter().map(|&x| x as f64).sum();
        let mut cuts = vec![0.0f64, 1.0];
        let mut c = 0.0f64;
        for &x in w {
            c += x as f64;
            for j in 0..k {
                let u = c / total * k as f64 - j as f64;
                if u > 0.0 && u < 1.0 {
                    cuts.push(u);
                }
            }
        }
        cuts.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let mut e = 0.0;
        for p in cuts.windows(2) {
            let len = p[1] - p[0];
            if len < 1e-9 {
                continue;
            }
            let u = ((p[0] + p[1]) / 2.0) as f32;
            let est: f64 = Draws::new(w, k, u).map(|(i, s)| f[i] * s as f64).sum();
            e += est * len;
        }
        e
    }

    /// Unbiased: the expected estimate equals the sum of every term, for weights that are
    /// proportional to the terms or not, with zeros anywhere, and any number of draws.
    #[test]
    fn the_expected_estimate_is_the_full_sum() {
        let cases: [(&[f32], &[f64]); 4] = [
            (&[1.0, 2.0, 3.0, 4.0], &[1.0, 2.0, 3.0, 4.0]),
            (&[0.5, 0.0, 3.0, 0.25, 0.0, 1.0], &[0.3, 0.0, 2.0, 1.5, 0.0, 0.1]),
            (&[0.0, 0.0, 7.0], &[0.0, 0.0, 5.0]),
            (&[1e-3, 10.0, 1.0, 0.0, 2.0, 2.0, 0.01, 5.0], &[0.2, 8.0, 1.0, 0.0, 3.0, 1.0, 0.5, 4.0]),
        ];
        for (w, f) in cases {
            let want: f64 = f.iter().sum();
            for k in [1, 2, 3, 5] {
                let got = expectation(w, f, k);
                assert!((got - want).abs() <= 1e-4 * want, "weights {w:?}, k {k}: {got} against {want}");
            }
        }
    }

    /// Lights of weight 0 (below the horizon) are never drawn, whatever `u`.
    #[test]
    fn weightless_lights_are_never_drawn() {
        let w = [0.0, 1.0, 0.0, 0.0, 2.0, 0.0];
        for s in 0..1000 {
            let u = s as f32 / 1000.0;
            for k in 1..6 {
                let d: Vec<(usize, f32)> = Draws::new(&w, k, u).collect();
                assert_eq!(d.len(), k);
                assert!(d.iter().all(|&(i, _)| w[i] > 0.0), "u {u} k {k}: {d:?}");
            }
        }
        assert_eq!(Draws::new(&[0.0, 0.0], 3, 0.5).count(), 0);
        let u_max = 1.0 - f32::EPSILON;
        assert!(Draws::new(&w, 4, u_max).all(|(i, _)| w[i] > 0.0));
    }

    /// Draws in proportion: with weights proportional to the terms, every draw's estimate is
    /// the exact sum (zero variance).
    #[test]
    fn proportional_weights_give_the_sum_every_time() {
        let w = [0.2f32, 1.0, 3.0, 0.0, 0.8];
        let want: f32 = w.iter().sum();
        for s in 0..100 {
            let u = s as f32 / 100.0;
            let got: f32 = Draws::new(&w, 2, u).map(|(i, f)| w[i] * f).sum();
            assert!((got - want).abs() < 1e-4 * want, "u {u}: {got}");
        }
    }
}
