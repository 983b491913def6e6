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
use crate::tiled::TileLayout;

/// Running sums of frames: per pixel the colour sum and the sum of squared luminance (for
/// the error estimate), and the AOV sums. Every per-pixel buffer is stored tile by tile
/// ([`TileLayout`]): a piece (a tile) is added as one contiguous block; frames, images and
/// AOVs go in and out row-major.
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
    /// Nothing has been added since [`Accumulator::new`] or [`Accumulator::reset`].
    clear: bool,
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

/// Whether any flag is set: a loop without an early exit, which compiles to vector code
/// (`contains(&true)` went byte by byte: 7 % of a moving frame in a view).
#[inline]
fn any(flags: &[bool]) -> bool {
    flags.iter().fold(false, |a, &f| a | f)
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
            clear: true,
        }
    }

    /// Forgets every frame (the camera moved).
    pub fn reset(&mut self) {
        if self.clear {
            // Nothing added since it was made or last reset (a view resets on every moving
            // frame).
            return;
        }
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

    /// Where each pixel's sums are stored.
    fn layout(&self) -> TileLayout {
        TileLayout { w: self.width, h: self.height }
    }

    /// Forgets the samples of the pixels marked in `pixels` (row-major; as if no frame had
    /// finished them yet): adaptive sampling restarts the pixels it chooses.
    pub fn restart(&mut self, pixels: &[bool]) {
        let w = self.width.max(1) as usize;
        for (i, _) in pixels.iter().enumerate().filter(|(_, &p)| p) {
            if i < self.sum.len() {
                let s = self.layout().index((i % w) as u32, (i / w) as u32);
                (self.sum[s], self.lum_sq[s], self.counts[s], self.provisional[s]) = ([0.0; 3], 0.0, 0, false);
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
        // In bands of tile rows on the current thread pool (a view adds a frame every frame):
        // a band's sums span what its rows span row-major.
        self.clear = false;
        let layout = self.layout();
        let band = layout.band().max(1);
        let plain = f.done.is_empty() && f.approx.is_empty();
        let (counts, provisional) = (&mut self.counts, &mut self.provisional);
        self.sum
            .par_chunks_mut(band)
            .zip(self.lum_sq.par_chunks_mut(band))
            .zip(counts.par_chunks_mut(band).zip(provisional.par_chunks_mut(band)))
            .enumerate()
            .for_each(|(b, ((sum, lum_sq), (counts, provisional)))| {
                let all_plain = plain && !any(provisional);
                layout.band_tile_runs(b, sum.len() / layout.w as usize, |s, at, n| {
                    let i = b * band + at;
                    let (sum, lum_sq) = (&mut sum[s..s + n], &mut lum_sq[s..s + n]);
                    let (counts, provisional) = (&mut counts[s..s + n], &mut provisional[s..s + n]);
                    if all_plain {
                        // Every pixel done, exactly, onto exact sums: add_sample's plain case.
                        return add_plain(sum, lum_sq, counts, &f.image.pixels[i..i + n]);
                    }
                    for j in 0..n {
                        if f.is_done(i + j) {
                            let (p, approx) = (f.image.pixels[i + j], f.is_approx(i + j));
                            add_sample(&mut sum[j], &mut lum_sq[j], &mut counts[j], &mut provisional[j], p, approx);
                        }
                    }
                });
            });
        if !f.depth.is_empty() {
            if self.frames == 0 || self.depth.is_empty() {
                self.depth = layout.scatter(&f.depth);
                self.normal = vec![[0.0; 3]; f.normal.len()];
                self.albedo = vec![[0.0; 3]; f.albedo.len()];
            }
            let (depth, normal, albedo) = (&mut self.depth, &mut self.normal, &mut self.albedo);
            layout.runs(|s, i, n| {
                for (d, e) in depth[s..s + n].iter_mut().zip(&f.depth[i..i + n]) {
                    *d = d.min(*e);
                }
                let normals = normal[s..s + n].iter_mut().zip(&f.normal[i..i + n]);
                for (a, b) in normals.chain(albedo[s..s + n].iter_mut().zip(&f.albedo[i..i + n])) {
                    for k in 0..3 {
                        a[k] += b[k];
                    }
                }
            });
        }
        self.rays += f.rays;
        self.end_frame(&f.jobs);
    }

    /// Starts adding a frame piece by piece, as the pieces come (a frame shared between
    /// processes): [`Accumulator::add_piece`] for each, every pixel once, then
    /// [`Accumulator::end_frame`]. The sums equal, bit for bit, [`Accumulator::add_frame`]
    /// of the frame the pieces make, with no frame put together.
    pub fn begin_frame(&mut self, aovs: bool) {
        self.clear = false;
        self.first_aovs = aovs && (self.frames == 0 || self.depth.is_empty());
        if self.first_aovs {
            let n = (self.width * self.height) as usize;
            (self.depth, self.normal, self.albedo) = (vec![0.0; n], vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        }
    }

    /// Adds piece `p` of the frame begun (its rays counted). Panics if it lies outside.
    pub fn add_piece(&mut self, p: &Piece) {
        self.clear = false;
        let rc = p.rect;
        assert!(rc.within(self.width, self.height), "piece {rc:?} outside the accumulator");
        let aovs = !p.depth.is_empty() && !self.depth.is_empty();
        // The piece's pixels in runs contiguous in the sums (a piece that is a tile is one).
        self.layout().rect_runs(rc, |at, q, n| {
            let (to, from) = (at..at + n, q..q + n);
            if p.approx.is_empty() && !any(&self.provisional[to.clone()]) {
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
        });
        self.rays += p.rays;
    }

    /// Ends a frame begun with [`Accumulator::begin_frame`] (or added whole), with the
    /// frame loop's counts.
    pub fn end_frame(&mut self, jobs: &JobStats) {
        self.clear = false;
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
            pixels: self.layout().gather_runs(|out, s| {
                let n = out.len();
                for (o, (sum, &k)) in out.iter_mut().zip(self.sum[s..s + n].iter().zip(&self.counts[s..s + n])) {
                    let inv = 1.0 / k.max(1) as f64;
                    *o = sum.map(|c| (c * inv) as f32);
                }
            }),
        }
    }

    /// Per pixel, the variance of the mean luminance (its squared standard error, from the
    /// spread of the frames that finished it); `None` before the second frame.
    pub fn variance_of_mean(&self) -> Option<Vec<f32>> {
        if self.frames < 2 {
            return None;
        }
        let v = self.layout().gather(|i| {
            mean_and_variance(&self.sum[i], self.lum_sq[i], self.counts[i]).map_or(0.0, |(_, var)| var as f32)
        });
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
        let layout = self.layout();
        Aovs {
            depth: Some(layout.gather(|i| self.depth[i])),
            normal: Some(layout.gather(|i| megaray_base::Vec3::from(self.normal[i]).normalize_or_zero().to_array())),
            albedo: Some(layout.gather(|i| self.albedo[i].map(|c| c * inv))),
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
        // Summed in row-major order (the same figure, to the bit, whatever the layout).
        let mut var_sum = 0.0;
        let mut lum_sum = 0.0;
        self.layout().runs(|s, _, n| {
            for i in s..s + n {
                if let Some((mean, var)) = mean_and_variance(&self.sum[i], self.lum_sq[i], self.counts[i]) {
                    var_sum += var;
                    lum_sum += mean;
                }
            }
        });
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
        let f = render_frame(r, tracer, i);
        acc.add_frame(&f);
        r.recycle(f);
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
        pieces_of(Rect::tiles(w, h), k, aovs)
    }

    /// The same over rectangles that are not tiles (20 x 12, crossing tiles' edges).
    fn odd_pieces(w: u32, h: u32, k: u32, aovs: bool) -> Vec<Piece> {
        let rects = (0..h.div_ceil(12))
            .flat_map(|j| (0..w.div_ceil(20)).map(move |i| (i * 20, j * 12)))
            .map(|(x0, y0)| Rect { x0, y0, x1: (x0 + 20).min(w), y1: (y0 + 12).min(h) })
            .collect();
        pieces_of(rects, k, aovs)
    }

    fn pieces_of(rects: Vec<Rect>, k: u32, aovs: bool) -> Vec<Piece> {
        let mut ps: Vec<Piece> = rects.into_iter().map(|r| Piece::blank(r, aovs)).collect();
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
        for (aovs, cut) in
            [(false, pieces as fn(u32, u32, u32, bool) -> Vec<Piece>), (true, pieces), (true, odd_pieces)]
        {
            let (mut whole, mut piecewise) = (Accumulator::new(w, h), Accumulator::new(w, h));
            for k in 0..4 {
                let ps = cut(w, h, k, aovs);
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

    /// What the accumulator gives out (image, variance, error, AOVs; restarted pixels) is
    /// what sums kept row-major, pixel by pixel, give: the tile layout is only storage.
    #[test]
    fn outputs_are_the_row_major_means() {
        let (w, h) = (70, 45);
        let n = (w * h) as usize;
        let mut acc = Accumulator::new(w, h);
        let (mut sum, mut lum_sq, mut counts, mut prov) =
            (vec![[0.0; 3]; n], vec![0.0; n], vec![0u32; n], vec![false; n]);
        let (mut depth, mut normal, mut albedo) = (vec![f32::INFINITY; n], vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n]);
        for k in 0..5 {
            let mut f = Frame::new(w, h, true);
            odd_pieces(w, h, k, true).iter().for_each(|p| f.put(p));
            if k == 3 {
                // A frame that left some pixels undone.
                f.done = (0..n).map(|i| i % 7 != 0).collect();
            }
            acc.add_frame(&f);
            for i in (0..n).filter(|&i| f.is_done(i)) {
                add_sample(
                    &mut sum[i],
                    &mut lum_sq[i],
                    &mut counts[i],
                    &mut prov[i],
                    f.image.pixels[i],
                    f.is_approx(i),
                );
            }
            for i in 0..n {
                depth[i] = depth[i].min(f.depth[i]);
                for c in 0..3 {
                    (normal[i][c], albedo[i][c]) = (normal[i][c] + f.normal[i][c], albedo[i][c] + f.albedo[i][c]);
                }
            }
            if k == 2 {
                let chosen: Vec<bool> = (0..n).map(|i| i % 11 == 3).collect();
                acc.restart(&chosen);
                for i in (0..n).filter(|&i| chosen[i]) {
                    (sum[i], lum_sq[i], counts[i], prov[i]) = ([0.0; 3], 0.0, 0, false);
                }
            }
        }
        let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|c| c.to_bits()).collect::<Vec<_>>();
        let want: Vec<[f32; 3]> = (0..n).map(|i| sum[i].map(|c| (c / counts[i].max(1) as f64) as f32)).collect();
        assert_eq!(bits(&acc.image().pixels), bits(&want));
        let var: Vec<f32> =
            (0..n).map(|i| mean_and_variance(&sum[i], lum_sq[i], counts[i]).map_or(0.0, |(_, v)| v as f32)).collect();
        assert_eq!(acc.variance_of_mean().unwrap(), var);
        let (mut var_sum, mut lum_sum) = (0.0, 0.0);
        for i in 0..n {
            if let Some((m, v)) = mean_and_variance(&sum[i], lum_sq[i], counts[i]) {
                (var_sum, lum_sum) = (var_sum + v, lum_sum + m);
            }
        }
        let err = (var_sum / n as f64).sqrt() / (lum_sum / n as f64);
        assert_eq!(acc.error().unwrap().to_bits(), err.to_bits());
        assert_eq!((acc.unfinished(), acc.approx_pixels()), (counts.iter().filter(|&&c| c == 0).count(), 0));
        let a = acc.aovs();
        assert_eq!(a.depth.unwrap(), depth);
        let normal: Vec<[f32; 3]> =
            normal.iter().map(|v| megaray_base::Vec3::from(*v).normalize_or_zero().to_array()).collect();
        assert_eq!(bits(&a.normal.unwrap()), bits(&normal));
        let albedo: Vec<[f32; 3]> = albedo.iter().map(|v| v.map(|c| c * (1.0 / 5.0))).collect();
        assert_eq!(bits(&a.albedo.unwrap()), bits(&albedo));
    }
}
