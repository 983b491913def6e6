//! The denoiser for progressive frames: an edge-avoiding à-trous wavelet filter (Dammertz et
//! al. 2010, "Edge-avoiding À-Trous wavelet transform for fast global illumination
//! filtering"), with the variance guidance of SVGF (Schied et al. 2017).
//!
//! The image is divided by the albedo (so textures and albedo edges are not blurred: only the
//! illumination is filtered) and filtered five times with a 5x5 B3-spline kernel whose taps
//! spread 1, 2, 4, 8, 16 pixels apart. A tap counts in proportion to how alike it is to the
//! centre: its normal (a power of the cosine), its depth (against the depth's local slope), its
//! albedo, and its illumination measured in units of the centre's noise (the standard error of
//! its mean, from the accumulator's per-pixel spread, or from its neighbourhood before four
//! frames exist; filtered along). Pixels where nothing was hit are never filtered or used.
//!
//! The filter fades out as frames accumulate: each pixel's result is blended toward its
//! unfiltered value as its relative noise falls from 2.2 % to 0.2 %, below which the pixel
//! passes through unchanged (a converged image is not filtered).

use rayon::prelude::*;

/// What the filter reads, all `width * height` long, row by row.
pub struct DenoiseInput<'a> {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// The mean colour of each pixel.
    pub color: &'a [[f32; 3]],
    /// Per pixel, the variance of the mean luminance (its squared standard error); `None`
    /// (before two frames) estimates it from the pixel's neighbourhood.
    pub variance: Option<&'a [f32]>,
    /// Frames in the mean (scales the neighbourhood estimate).
    pub frames: u32,
    /// Per pixel, the surface albedo (zero where nothing was hit).
    pub albedo: &'a [[f32; 3]],
    /// Per pixel, the shading normal (zero where nothing was hit).
    pub normal: &'a [[f32; 3]],
    /// Per pixel, the distance to the first hit (infinite where nothing was hit).
    pub depth: &'a [f32],
    /// Filter passes, 1 to 5 (taps 1, 2, 4, 8, 16 pixels apart); fewer is cheaper and smooths
    /// less far. [`PASSES`] by default.
    pub passes: u32,
}

const KERNEL: [f32; 5] = [1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0];
/// The passes of a full filtering.
pub const PASSES: u32 = 5;
/// Relative noise below which a pixel is left as it is, and the span over which the filter
/// fades in above it.
const CLEAN: f32 = 0.002;
const FADE: f32 = 0.02;

fn lum(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The filtered image (see the module documentation).
pub fn denoise(inp: &DenoiseInput) -> Vec<[f32; 3]> {
    let (w, h) = (inp.width as usize, inp.height as usize);
    let n = w * h;
    assert!(
        [inp.color.len(), inp.albedo.len(), inp.normal.len(), inp.depth.len()].iter().all(|&l| l == n)
            && inp.variance.is_none_or(|v| v.len() == n),
        "denoise: buffers of {w}x{h} pixels expected"
    );
    let hit: Vec<bool> = inp.depth.iter().map(|d| d.is_finite()).collect();
    // Illumination: colour over albedo where the albedo is known.
    let demod = |i: usize| -> [f32; 3] {
        let a = inp.albedo[i];
        if hit[i] {
            std::array::from_fn(|k| if a[k] > 0.01 { inp.color[i][k] / a[k] } else { inp.color[i][k] })
        } else {
            inp.color[i]
        }
    };
    let scale = |i: usize| {
        let a = lum(inp.albedo[i]);
        if hit[i] && a > 0.01 {
            1.0 / (a * a)
        } else {
            1.0
        }
    };
    let mut illum: Vec<[f32; 3]> = (0..n).map(demod).collect();
    // Slope of depth per pixel: per axis the smaller one-sided difference (at a silhouette
    // one side is the same surface), then the larger axis.
    let slope: Vec<f32> = (0..n)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let d = |j: usize| if hit[j] { inp.depth[j] } else { inp.depth[i] };
            let z = inp.depth[i];
            let gx = (d(y * w + (x + 1).min(w - 1)) - z).abs().min((z - d(y * w + x.saturating_sub(1))).abs());
            let gy = (d((y + 1).min(h - 1) * w + x) - z).abs().min((z - d(y.saturating_sub(1) * w + x)).abs());
            gx.max(gy)
        })
        .collect();
    // Noise: the accumulator's, or the neighbourhood's spread over the frames.
    let mut var: Vec<f32> = match inp.variance {
        Some(v) if inp.frames >= 4 => (0..n).map(|i| v[i] * scale(i)).collect(),
        _ => (0..n)
            .into_par_iter()
            .map(|i| {
                if !hit[i] {
                    return 0.0;
                }
                let (x, y) = (i as isize % w as isize, i as isize / w as isize);
                let (mut s, mut s2, mut k) = (0.0f32, 0.0f32, 0.0f32);
                for dy in -2..=2 {
                    for dx in -2..=2 {
                        let (qx, qy) = (x + dx, y + dy);
                        if qx < 0 || qy < 0 || qx >= w as isize || qy >= h as isize {
                            continue;
                        }
                        let q = (qy * w as isize + qx) as usize;
                        if !hit[q] || dot(inp.normal[i], inp.normal[q]) < 0.9 {
                            continue;
                        }
                        let l = lum(illum[q]);
                        s += l;
                        s2 += l * l;
                        k += 1.0;
                    }
                }
                let m = s / k;
                (s2 / k - m * m).max(0.0) / inp.frames.max(1) as f32
            })
            .collect(),
    };
    let rel_noise: Vec<f32> = (0..n).map(|i| var[i].sqrt() / lum(illum[i]).max(1e-4)).collect();
    for pass in 0..inp.passes.clamp(1, PASSES) {
        let step = 1isize << pass;
        let (next, next_var): (Vec<[f32; 3]>, Vec<f32>) = (0..n)
            .into_par_iter()
            .map(|i| {
                if !hit[i] || rel_noise[i] <= CLEAN {
                    return (illum[i], var[i]);
                }
                let (x, y) = (i as isize % w as isize, i as isize / w as isize);
                let (lp, zp, np, ap) = (lum(illum[i]), inp.depth[i], inp.normal[i], inp.albedo[i]);
                let sigma_l = 4.0 * var[i].sqrt() + 1e-6;
                let (mut acc, mut wsum, mut vsum) = ([0.0f32; 3], 0.0f32, 0.0f32);
                for (ky, hy) in KERNEL.iter().enumerate() {
                    for (kx, hx) in KERNEL.iter().enumerate() {
                        let (dx, dy) = ((kx as isize - 2) * step, (ky as isize - 2) * step);
                        let (qx, qy) = (x + dx, y + dy);
                        if qx < 0 || qy < 0 || qx >= w as isize || qy >= h as isize {
                            continue;
                        }
                        let q = (qy * w as isize + qx) as usize;
                        if !hit[q] {
                            continue;
                        }
                        let dist = dx.abs().max(dy.abs()) as f32;
                        let wn = dot(np, inp.normal[q]).max(0.0).powi(64);
                        let wz = (-(zp - inp.depth[q]).abs() / (slope[i] * dist + 0.002 * zp + 1e-6)).exp();
                        let aq = inp.albedo[q];
                        let da = (ap[0] - aq[0]).powi(2) + (ap[1] - aq[1]).powi(2) + (ap[2] - aq[2]).powi(2);
                        let wa = (-da / 0.01).exp();
                        let wl = (-(lp - lum(illum[q])).abs() / sigma_l).exp();
                        let wt = hx * hy * wn * wz * wa * wl;
                        for k in 0..3 {
                            acc[k] += wt * illum[q][k];
                        }
                        wsum += wt;
                        vsum += wt * wt * var[q];
                    }
                }
                // The centre always counts (all its weights are 1), so wsum > 0.
                (acc.map(|c| c / wsum), vsum / (wsum * wsum))
            })
            .unzip();
        illum = next;
        var = next_var;
    }
    (0..n)
        .into_par_iter()
        .map(|i| {
            if !hit[i] {
                return inp.color[i];
            }
            let a = inp.albedo[i];
            let f: [f32; 3] = std::array::from_fn(|k| if a[k] > 0.01 { illum[i][k] * a[k] } else { illum[i][k] });
            let s = ((rel_noise[i] - CLEAN) / FADE).clamp(0.0, 1.0);
            if s == 0.0 {
                return inp.color[i];
            }
            std::array::from_fn(|k| inp.color[i][k] + s * (f[k] - inp.color[i][k]))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: u32 = 48;
    const H: u32 = 32;

    /// Noise in [-1, 1), fixed per pixel.
    fn noise(i: usize) -> f32 {
        megaray_base::hash32(i as u32 ^ 0x9e37_79b9) as f32 / u32::MAX as f32 * 2.0 - 1.0
    }

    struct Wall {
        color: Vec<[f32; 3]>,
        albedo: Vec<[f32; 3]>,
        normal: Vec<[f32; 3]>,
        depth: Vec<f32>,
    }

    /// A wall facing the camera at depth 5 (or `depth(x)`), of albedo `albedo(x)`, lit by
    /// 1, with noise of amplitude `amp` times the albedo.
    fn wall(albedo: impl Fn(usize) -> f32, depth: impl Fn(usize) -> f32, amp: f32) -> Wall {
        let n = (W * H) as usize;
        let a: Vec<[f32; 3]> = (0..n).map(|i| [albedo(i % W as usize); 3]).collect();
        Wall {
            color: (0..n).map(|i| a[i].map(|c| c * (1.0 + amp * noise(i)))).collect(),
            albedo: a,
            normal: vec![[0.0, 0.0, 1.0]; n],
            depth: (0..n).map(|i| depth(i % W as usize)).collect(),
        }
    }

    fn run(w: &Wall, variance: Option<&[f32]>, frames: u32) -> Vec<[f32; 3]> {
        denoise(&DenoiseInput {
            width: W,
            height: H,
            color: &w.color,
            variance,
            frames,
            albedo: &w.albedo,
            normal: &w.normal,
            depth: &w.depth,
            passes: PASSES,
        })
    }

    fn rms(v: &[[f32; 3]], want: impl Fn(usize) -> f32) -> f32 {
        let s: f32 = v.iter().enumerate().map(|(i, p)| (p[1] - want(i)).powi(2)).sum();
        (s / v.len() as f32).sqrt()
    }

    #[test]
    fn a_constant_image_stays_constant() {
        let w = wall(|_| 0.5, |_| 5.0, 0.0);
        let var = vec![0.01; (W * H) as usize];
        let out = run(&w, Some(&var), 8);
        assert!(out.iter().all(|p| p.iter().all(|&c| (c - 0.5).abs() < 1e-6)), "{:?}", &out[..4]);
    }

    #[test]
    fn noise_on_a_flat_wall_falls_at_least_fourfold() {
        let w = wall(|_| 0.5, |_| 5.0, 0.2);
        let before = rms(&w.color, |_| 0.5);
        let after = rms(&run(&w, None, 1), |_| 0.5);
        assert!(after * 4.0 <= before, "rms {before} -> {after}");
        // The same with the accumulator's variance (the noise's own: amplitude 0.1 uniform).
        let var = vec![(0.1f32 * 0.5).powi(2) / 3.0 * 0.2 / 0.1; (W * H) as usize];
        let after = rms(&run(&w, Some(&var), 8), |_| 0.5);
        assert!(after * 4.0 <= before, "rms {before} -> {after} with a given variance");
    }

    #[test]
    fn a_sharp_albedo_edge_is_kept() {
        let edge = |x: usize| if x < W as usize / 2 { 0.2 } else { 0.8 };
        let w = wall(edge, |_| 5.0, 0.2);
        let out = run(&w, None, 1);
        for (i, p) in out.iter().enumerate() {
            let a = edge(i % W as usize);
            assert!((p[1] - a).abs() < 0.25 * a, "pixel {i}: {} on albedo {a}", p[1]);
        }
        // Each side is smoother than it was, and the columns beside the edge keep their side's level.
        assert!(rms(&out, |i| edge(i % W as usize)) * 3.0 < rms(&w.color, |i| edge(i % W as usize)));
        let col = |x: usize| (0..H as usize).map(|y| out[y * W as usize + x][1]).sum::<f32>() / H as f32;
        let (l, r) = (col(W as usize / 2 - 1), col(W as usize / 2));
        assert!((l - 0.2).abs() < 0.02 && (r - 0.8).abs() < 0.05, "columns at the edge: {l} {r}");
    }

    #[test]
    fn a_geometric_edge_is_not_blurred() {
        // Two walls of one albedo, one far behind the other, lit differently.
        let near = |x: usize| x < W as usize / 2;
        let mut w = wall(|_| 0.5, |x| if near(x) { 2.0 } else { 9.0 }, 0.2);
        for (i, c) in w.color.iter_mut().enumerate() {
            if !near(i % W as usize) {
                *c = c.map(|v| v * 0.2);
            }
        }
        let out = run(&w, None, 1);
        let col = |x: usize| (0..H as usize).map(|y| out[y * W as usize + x][1]).sum::<f32>() / H as f32;
        let (l, r) = (col(W as usize / 2 - 1), col(W as usize / 2));
        assert!((l - 0.5).abs() < 0.03 && (r - 0.1).abs() < 0.01, "columns at the edge: {l} {r}");
    }

    #[test]
    fn a_converged_image_passes_through_unchanged() {
        let w = wall(|x| 0.2 + 0.01 * x as f32, |_| 5.0, 0.001);
        // Standard errors of 0.1 % of the value: converged.
        let var: Vec<f32> = w.color.iter().map(|c| (0.001 * c[1]).powi(2)).collect();
        let out = run(&w, Some(&var), 4096);
        assert_eq!(out, w.color);
    }

    #[test]
    fn the_sky_is_left_alone() {
        let mut w = wall(|_| 0.5, |_| 5.0, 0.2);
        for i in 0..(W * 4) as usize {
            w.depth[i] = f32::INFINITY;
            w.normal[i] = [0.0; 3];
            w.albedo[i] = [0.0; 3];
            w.color[i] = [0.3, 0.5, 0.9 + 0.1 * noise(i)];
        }
        let out = run(&w, None, 1);
        assert_eq!(out[..(W * 4) as usize], w.color[..(W * 4) as usize]);
    }
}
