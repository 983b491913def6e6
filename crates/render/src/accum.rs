//! Progressive rendering: successive frames (new sample positions and light subsets each)
//! summed into a float buffer, with an estimate of the remaining error.
//!
//! An interactive viewer drives it: [`Accumulator::reset`] when the camera moves, then
//! `acc.add_frame(&render_frame(&renderer, &tracer, acc.frames()))` while it stands still,
//! showing [`Accumulator::image`] after each. [`render_progressive`] does that loop until a
//! frame count or a time is reached.

use rayon::prelude::*;
use std::time::{Duration, Instant};

use megaray_trace::jobs::JobStats;
use megaray_trace::Tracer;

use crate::env::luminance;
use crate::frame::{render_frame, Frame, Renderer};
use crate::image_out::{Aovs, Image};
use crate::region::Piece;

/// Running sums of frames: per pixel the colour sum and the sum of squared luminance (for
/// the error estimate), and the AOV sums.
#[derive(Clone, Debug)]
pub struct Accumulator {
    width: u32,
    height: u32,
    frames: u32,
    /// Frames that finished each pixel (a frame with a deadline may leave some).
    counts: Vec<u32>,
    /// Pixels whose sums hold only approximate samples ([`Frame::approx`]): the first exact
    /// sample replaces them.
    provisional: Vec<bool>,
    sum: Vec<[f64; 3]>,
    lum_sq: Vec<f64>,
    depth: Vec<f32>,
    normal: Vec<[f32; 3]>,
    albedo: Vec<[f32; 3]>,
    rays: u64,
    jobs: JobStats,
    /// Between [`Accumulator::begin_frame`] and [`Accumulator::end_frame`]: whether the
    /// frame's AOVs are the first (set, not combined).
    first_aovs: bool,
}

/// Adds one sample `p` to a pixel's sums (`approx`: see [`Accumulator::add_frame`]).
#[inline]
fn add_sample(
    sum: &mut [f64; 3],
    lum_sq: &mut f64,
    count: &mut u32,
    provisional: &mut bool,
    p: [f32; 3],
    approx: bool,
) {
    if approx && *count > 0 && !*provisional {
        return;
    }
    if !approx && *provisional {
        (*sum, *lum_sq, *count) = ([0.0; 3], 0.0, 0);
    }
    *provisional = approx;
    *count += 1;
    for k in 0..3 {
        sum[k] += p[k] as f64;
    }
    let l = luminance(p.into()) as f64;
    *lum_sq += l * l;
}

/// [`add_sample`] of every pixel of `px` that is neither approximate nor onto provisional
/// sums, in a loop without its branches, compiled for the widest vectors the machine has
/// (the same bits: only the width differs; `accum`'s tests compare it with `add_sample`).
fn add_plain(sum: &mut [[f64; 3]], lum_sq: &mut [f64], counts: &mut [u32], px: &[[f32; 3]]) {
    #[inline(always)]
    fn body(sum: &mut [[f64; 3]], lum_sq: &mut [f64], counts: &mut [u32], px: &[[f32; 3]]) {
        let n = sum.len().min(lum_sq.len()).min(counts.len()).min(px.len());
        for j in 0..n {
            let p = px[j];
            counts[j] += 1;
            for k in 0..3 {
                sum[j][k] += p[k] as f64;
            }
            let l = luminance(p.into()) as f64;
            lum_sq[j] += l * l;
        }
    }
    megaray_base::compiled_for!(wide512, wide2, fn body(sum: &mut [[f64; 3]], lum_sq: &mut [f64], counts: &mut [u32], px: &[[f32; 3]]));
    megaray_base::dispatch!(body(sum, lum_sq, counts, px), wide512, wide2)
}

impl Accumulator {
    /// An empty accumulator for `width` x `height` frames.
    pub fn new(width: u32, height: u32) -> Accumulator {
        let n = (width * height) as usize;
        Accumulator {
            width,
            height,
            frames: 0,
            counts: vec![0; n],
            provisional: vec![false; n],
            sum: vec![[0.0; 3]; n],
            lum_sq: vec![0.0; n],
            depth: Vec::new(),
            normal: Vec::new(),
            albedo: Vec::new(),
            rays: 0,
            jobs: JobStats::default(),
            first_aovs: false,
        }
    }

    /// Forgets every frame (the camera moved).
    pub fn reset(&mut self) {
        // Cleared in place: a view resets on every moving frame, and fresh buffers cost their
        // page faults again.
        let (w, h) = (self.width, self.height);
        let (mut counts, mut provisional) = (std::mem::take(&mut self.counts), std::mem::take(&mut self.provisional));
        let (mut sum, mut lum_sq) = (std::mem::take(&mut self.sum), std::mem::take(&mut self.lum_sq));
        counts.fill(0);
        provisional.fill(false);
        sum.fill([0.0; 3]);
        lum_sq.fill(0.0);
        *self = Accumulator { counts, provisional, sum, lum_sq, ..Accumulator::new(0, 0) };
        (self.width, self.height) = (w, h);
    }

    /// Forgets the samples of the pixels marked in `pixels` (row-major; as if no frame had
    /// finished them yet): adaptive sampling restarts the pixels it chooses.
    pub fn restart(&mut self, pixels: &[bool]) {
        for (i, _) in pixels.iter().enumerate().filter(|(_, &p)| p) {
            if i < self.sum.len() {
                (self.sum[i], self.lum_sq[i], self.counts[i], self.provisional[i]) = ([0.0; 3], 0.0, 0, false);
            }
        }
    }

    /// Frames added since the last reset.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Rays fired by the frames added.
    pub fn rays(&self) -> u64 {
        self.rays
    }

    /// Adds one frame (of this accumulator's size). Pixels the frame did not finish
    /// ([`Frame::done`]) are left out: each pixel is the mean of the frames that finished it.
    /// An approximate pixel ([`Frame::approx`]: a stand-in answered for a missing tile)
    /// counts only until the pixel's first exact sample, which replaces what it had; after
    /// that, approximate samples of it are left out. The image converges to the exact one.
    pub fn add_frame(&mut self, f: &Frame) {
        assert_eq!(
            (f.image.width, f.image.height),
            (self.width, self.height),
            "frame size differs from the accumulator's"
        );
        // In rows on the current thread pool (a view adds a frame every frame).
        const ROW: usize = 4096;
        let plain = f.done.is_empty() && f.approx.is_empty();
        let (counts, provisional) = (&mut self.counts, &mut self.provisional);
        self.sum
            .par_chunks_mut(ROW)
            .zip(self.lum_sq.par_chunks_mut(ROW))
            .zip(counts.par_chunks_mut(ROW).zip(provisional.par_chunks_mut(ROW)))
            .enumerate()
            .for_each(|(r, ((sum, lum_sq), (counts, provisional)))| {
                if plain && !provisional.contains(&true) {
                    // Every pixel done, exactly, onto exact sums: add_sample's plain case.
                    add_plain(sum, lum_sq, counts, &f.image.pixels[r * ROW..r * ROW + sum.len()]);
                    return;
                }
                for j in 0..sum.len() {
                    let i = r * ROW + j;
                    if !f.is_done(i) {
                        continue;
                    }
                    let p = f.image.pixels[i];
                    add_sample(&mut sum[j], &mut lum_sq[j], &mut counts[j], &mut provisional[j], p, f.is_approx(i));
                }
            });
        if !f.depth.is_empty() {
            if self.frames == 0 || self.depth.is_empty() {
                self.depth = f.depth.clone();
                self.normal = vec![[0.0; 3]; f.normal.len()];
                self.albedo = vec![[0.0; 3]; f.albedo.len()];
            }
            for (d, e) in self.depth.iter_mut().zip(&f.depth) {
                *d = d.min(*e);
            }
            for (a, b) in self.normal.iter_mut().zip(&f.normal).chain(self.albedo.iter_mut().zip(&f.albedo)) {
                for k in 0..3 {
                    a[k] += b[k];
                }
            }
        }
        self.rays += f.rays;
        self.end_frame(&f.jobs);
    }

    /// Starts adding a frame piece by piece, as the pieces come (a frame shared between
    /// processes): [`Accumulator::add_piece`] for each, every pixel once, then
    /// [`Accumulator::end_frame`]. The sums equal, bit for bit, [`Accumulator::add_frame`]
    /// of the frame the pieces make, with no frame put together.
    pub fn begin_frame(&mut self, aovs: bool) {
        self.first_aovs = aovs && (self.frames == 0 || self.depth.is_empty());
        if self.first_aovs {
            let n = (self.width * self.height) as usize;
            (self.depth, self.normal, self.albedo) = (vec![0.0; n], vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        }
    }

    /// Adds piece `p` of the frame begun (its rays counted). Panics if it lies outside.
    pub fn add_piece(&mut self, p: &Piece) {
        let rc = p.rect;
        assert!(rc.within(self.width, self.height), "piece {rc:?} outside the accumulator");
        let pw = (rc.x1 - rc.x0) as usize;
        let aovs = !p.depth.is_empty() && !self.depth.is_empty();
        for (row, y) in (rc.y0..rc.y1).enumerate() {
            // A row of the piece against its place in the sums.
            let (at, q) = ((y * self.width + rc.x0) as usize, row * pw);
            let (to, from) = (at..at + pw, q..q + pw);
            if p.approx.is_empty() && !self.provisional[to.clone()].contains(&true) {
                // Every pixel exact, onto exact sums: add_sample's plain case, as add_frame.
                let (sum, lum_sq, counts) =
                    (&mut self.sum[to.clone()], &mut self.lum_sq[to.clone()], &mut self.counts[to.clone()]);
                add_plain(sum, lum_sq, counts, &p.color[from.clone()]);
            } else {
                let sums = self.sum[to.clone()].iter_mut().zip(&mut self.lum_sq[to.clone()]);
                let counts = self.counts[to.clone()].iter_mut().zip(&mut self.provisional[to.clone()]);
                for (j, ((sum, lum_sq), (count, provisional))) in sums.zip(counts).enumerate() {
                    let approx = !p.approx.is_empty() && p.approx[q + j];
                    add_sample(sum, lum_sq, count, provisional, p.color[q + j], approx);
                }
            }
            if aovs {
                // As `add_frame`: the first frame's depth is taken, later ones' minimum.
                for (d, &e) in self.depth[to.clone()].iter_mut().zip(&p.depth[from.clone()]) {
                    *d = if self.first_aovs { e } else { d.min(e) };
                }
                let normals = self.normal[to.clone()].iter_mut().zip(&p.normal[from.clone()]);
                for (a, b) in normals.chain(self.albedo[to].iter_mut().zip(&p.albedo[from])) {
                    for k in 0..3 {
                        a[k] += b[k];
                    }
                }
            }
        }
        self.rays += p.rays;
    }

    /// Ends a frame begun with [`Accumulator::begin_frame`] (or added whole), with the
    /// frame loop's counts.
    pub fn end_frame(&mut self, jobs: &JobStats) {
        self.frames += 1;
        self.first_aovs = false;
        let j = &mut self.jobs;
        j.finished += jobs.finished;
        j.unfinished += jobs.unfinished;
        j.suspended += jobs.suspended;
        j.rays += jobs.rays;
        j.wait_secs += jobs.wait_secs;
    }

    /// The mean of the frames added (black before the first), per pixel over the frames that
    /// finished it.
    pub fn image(&self) -> Image {
        Image {
            width: self.width,
            height: self.height,
            pixels: self
                .sum
                .par_iter()
                .zip(&self.counts)
                .map(|(s, &n)| {
                    let inv = 1.0 / n.max(1) as f64;
                    s.map(|c| (c * inv) as f32)
                })
                .collect(),
        }
    }

    /// Per pixel, the variance of the mean luminance (its squared standard error, from the
    /// spread of the frames that finished it); `None` before the second frame.
    pub fn variance_of_mean(&self) -> Option<Vec<f32>> {
        if self.frames < 2 {
            return None;
        }
        let v = self
            .sum
            .par_iter()
            .zip(&self.lum_sq)
            .zip(&self.counts)
            .map(|((s, &q), &k)| mean_and_variance(s, q, k).map_or(0.0, |(_, var)| var as f32))
            .collect();
        Some(v)
    }

    /// The mean image through the denoiser ([`crate::denoise`]), guided by the AOVs (render
    /// with `settings.aovs`); `None` when the frames had none.
    pub fn denoised(&self) -> Option<Image> {
        self.denoised_with(crate::denoise::PASSES)
    }

    /// [`Accumulator::denoised`] with `passes` filter passes (fewer: cheaper, for viewers).
    pub fn denoised_with(&self, passes: u32) -> Option<Image> {
        let aovs = self.aovs();
        let (depth, normal, albedo) = (aovs.depth?, aovs.normal?, aovs.albedo?);
        let img = self.image();
        let variance = self.variance_of_mean();
        let pixels = crate::denoise(&crate::DenoiseInput {
            width: self.width,
            height: self.height,
            color: &img.pixels,
            variance: variance.as_deref(),
            frames: self.frames,
            albedo: &albedo,
            normal: &normal,
            depth: &depth,
            passes,
        });
        Some(Image { pixels, ..img })
    }

    /// The frame loops' statistics, summed over the frames added (pixels finished and
    /// not, suspensions, time threads waited for tiles).
    pub fn jobs(&self) -> JobStats {
        self.jobs
    }

    /// Pixels with approximate samples only (stand-ins for tiles not loaded yet).
    pub fn approx_pixels(&self) -> usize {
        self.provisional.iter().filter(|&&p| p).count()
    }

    /// Pixels no frame has finished yet.
    pub fn unfinished(&self) -> usize {
        self.counts.iter().filter(|&&n| n == 0).count()
    }

    /// The AOVs: depth the nearest over the frames, normal (renormalised) and albedo the
    /// mean. Empty when the frames had none.
    pub fn aovs(&self) -> Aovs {
        if self.depth.is_empty() {
            return Aovs::default();
        }
        let inv = 1.0 / self.frames.max(1) as f32;
        Aovs {
            depth: Some(self.depth.clone()),
            normal: Some(
                self.normal.iter().map(|n| megaray_base::Vec3::from(*n).normalize_or_zero().to_array()).collect(),
            ),
            albedo: Some(self.albedo.iter().map(|a| a.map(|c| c * inv)).collect()),
        }
    }

    /// The estimated relative error of the mean image: the root mean square, over pixels, of
    /// the standard error of each pixel's mean luminance (from the spread of its frames),
    /// divided by the image's mean luminance. `None` before the second frame. It falls as
    /// 1 / sqrt(frames) for independent frames.
    pub fn error(&self) -> Option<f64> {
        if self.frames < 2 {
            return None;
        }
        let mut var_sum = 0.0;
        let mut lum_sum = 0.0;
        for ((s, &q), &k) in self.sum.iter().zip(&self.lum_sq).zip(&self.counts) {
            if let Some((mean, var)) = mean_and_variance(s, q, k) {
                var_sum += var;
                lum_sum += mean;
            }
        }
        let pixels = self.sum.len().max(1) as f64;
        let mean_lum = lum_sum / pixels;
        Some(if mean_lum > 0.0 { (var_sum / pixels).sqrt() / mean_lum } else { 0.0 })
    }
}

/// A pixel's mean luminance and the variance of that mean (its squared standard error), from
/// its colour sum `s`, its sum of squared luminance `q` and its `k` frames; `None` below two.
fn mean_and_variance(s: &[f64; 3], q: f64, k: u32) -> Option<(f64, f64)> {
    if k < 2 {
        return None;
    }
    let n = k as f64;
    let mean = luminance(megaray_base::Vec3::new(s[0] as f32, s[1] as f32, s[2] as f32)) as f64 / n;
    Some((mean, ((q / n - mean * mean) * n / (n - 1.0)).max(0.0) / n))
}

/// When [`render_progressive`] stops: after `frames` frames, or once `time` has passed
/// (checked after each frame; at least one frame is always rendered), whichever comes first.
#[derive(Clone, Copy, Debug, Default)]
pub struct Stop {
    /// Stop after this many frames.
    pub frames: Option<u32>,
    /// Stop once this much time has passed (checked after each frame).
    pub time: Option<Duration>,
}

/// Renders frames 0, 1, 2, ... into an accumulator until `stop`, calling `on_frame` after
/// each (for progress bars and previews). Stops early, after the frame in which it was found,
/// when the scene or its pager reports a fault (a damaged or vanished tile: see
/// `Scene::first_error`, `Pager::first_error`), for the caller to report.
pub fn render_progressive(
    r: &Renderer,
    tracer: &Tracer,
    stop: Stop,
    on_frame: impl FnMut(&Accumulator),
) -> Accumulator {
    let frame = |i, acc: &mut Accumulator| {
        acc.add_frame(&render_frame(r, tracer, i));
        Ok::<_, std::convert::Infallible>(())
    };
    render_progressive_with(r, tracer, stop, frame, on_frame).unwrap_or_else(|e| match e {})
}

/// [`render_progressive`] with frames added by `add` (frame index, the accumulator: adds
/// that frame to it), which may fail (a frame shared between processes): the first error
/// ends the run.
pub fn render_progressive_with<E>(
    r: &Renderer,
    tracer: &Tracer,
    stop: Stop,
    mut add: impl FnMut(u32, &mut Accumulator) -> Result<(), E>,
    mut on_frame: impl FnMut(&Accumulator),
) -> Result<Accumulator, E> {
    let (w, h) = (r.settings.camera.width, r.settings.camera.height);
    let mut acc = Accumulator::new(w, h);
    let mut governor = crate::LodGovernor::new(tracer);
    let start = Instant::now();
    let max_frames = match (stop.frames, stop.time) {
        (Some(n), _) => n.max(1),
        (None, Some(_)) => u32::MAX,
        (None, None) => 1,
    };
    while acc.frames() < max_frames {
        add(acc.frames(), &mut acc)?;
        let last = acc.frames() >= max_frames || stop.time.is_some_and(|t| start.elapsed() >= t);
        if r.settings.adaptive > 1 && crate::adaptive::updates_after(acc.frames()) && !last {
            // Pixels newly chosen start again at the next frame (`adaptive`).
            let newly = r.sample_more(&acc.image());
            acc.restart(&newly);
        }
        governor.after_frame(tracer);
        on_frame(&acc);
        if stop.time.is_some_and(|t| start.elapsed() >= t) {
            break;
        }
        let scene_fault = tracer.scene().first_error().is_some();
        if scene_fault || tracer.pager().is_some_and(|p| p.first_error().is_some()) {
            break;
        }
    }
    Ok(acc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::region::Rect;

    /// Frame `k` of a `w` x `h` sequence cut into pieces: values that differ per pixel and
    /// frame (a negative zero among them), some pixels approximate in the early frames.
    fn pieces(w: u32, h: u32, k: u32, aovs: bool) -> Vec<Piece> {
        let mut ps: Vec<Piece> = Rect::tiles(w, h).into_iter().map(|r| Piece::blank(r, aovs)).collect();
        for p in &mut ps {
            for i in 0..p.color.len() {
                let v = ((i as u32 * 7 + k * 13 + p.rect.x0 * 3 + p.rect.y0) % 17) as f32 * 0.37;
                p.color[i] = [v, 0.5 * v, -0.0];
                if aovs {
                    (p.depth[i], p.normal[i], p.albedo[i]) = (v + k as f32, [-0.0, v, 1.0], [v, v, v]);
                }
                if k < 2 && i % 5 == k as usize {
                    p.mark_approx(i);
                }
            }
            p.rays = 2;
        }
        ps
    }

    #[test]
    fn pieces_added_as_they_come_equal_the_frame_added_whole() {
        let (w, h) = (70, 45);
        for aovs in [false, true] {
            let (mut whole, mut piecewise) = (Accumulator::new(w, h), Accumulator::new(w, h));
            for k in 0..4 {
                let ps = pieces(w, h, k, aovs);
                let mut f = Frame::new(w, h, aovs);
                ps.iter().for_each(|p| f.put(p));
                f.jobs.finished = (w * h) as u64;
                whole.add_frame(&f);
                piecewise.begin_frame(aovs);
                // In another order than the frame's.
                ps.iter().rev().for_each(|p| piecewise.add_piece(p));
                piecewise.end_frame(&f.jobs);
                let bits = |a: &Accumulator| a.sum.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&piecewise), bits(&whole), "frame {k}");
                assert_eq!((&piecewise.lum_sq, &piecewise.counts), (&whole.lum_sq, &whole.counts));
                assert_eq!(piecewise.provisional, whole.provisional);
                let aov_bits = |a: &Accumulator| {
                    let n = a.normal.iter().chain(&a.albedo).flatten();
                    (a.depth.iter().chain(n).map(|v| v.to_bits()).collect::<Vec<_>>(), a.rays, a.frames)
                };
                assert_eq!(aov_bits(&piecewise), aov_bits(&whole), "frame {k}");
            }
        }
    }
}
