//! A frame in pieces: rectangles of pixels rendered on their own ([`render_pieces`]) and put
//! together into a [`Frame`] ([`Frame::put`]), for front ends that share one frame between
//! processes (`megaray-cluster`). A pixel is a pure function of (pixel, frame) and the
//! scene, so a frame put together from pieces equals, bit for bit, the frame
//! [`crate::render_frame`] renders at once (without a deadline: pieces always finish).

use megaray_trace::jobs::{self, JobOptions, JobStats};
use megaray_trace::{RayCaster, Tracer};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use crate::frame::{Frame, Renderer, TILE};
use crate::rows::{Group, GROUP};

/// A rectangle of pixels: columns `x0..x1` of rows `y0..y1`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Rect {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

impl Rect {
    /// Its pixel count.
    pub fn area(&self) -> usize {
        ((self.x1 - self.x0) * (self.y1 - self.y0)) as usize
    }

    /// The [`TILE`] x [`TILE`] tiles of a `w` x `h` frame, in rows of tiles (edge tiles cut
    /// to the frame).
    pub fn tiles(w: u32, h: u32) -> Vec<Rect> {
        let mut out = Vec::new();
        for ty in 0..h.div_ceil(TILE) {
            for tx in 0..w.div_ceil(TILE) {
                let (x0, y0) = (tx * TILE, ty * TILE);
                out.push(Rect { x0, y0, x1: (x0 + TILE).min(w), y1: (y0 + TILE).min(h) });
            }
        }
        out
    }

    /// Whether it lies within a `w` x `h` frame and is not empty.
    pub fn within(&self, w: u32, h: u32) -> bool {
        self.x0 < self.x1 && self.y0 < self.y1 && self.x1 <= w && self.y1 <= h
    }
}

/// The pixels of one rectangle of a frame, row by row; AOVs only when the renderer makes
/// them (`settings.aovs`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Piece {
    /// Where it lies in the frame.
    pub rect: Rect,
    /// Per pixel, the mean radiance of its samples.
    pub color: Vec<[f32; 3]>,
    /// Per pixel, the nearest primary hit distance (AOV).
    pub depth: Vec<f32>,
    /// Per pixel, the mean shading normal (AOV).
    pub normal: Vec<[f32; 3]>,
    /// Per pixel, the mean albedo (AOV).
    pub albedo: Vec<[f32; 3]>,
    /// Per pixel, whether a stand-in answered one of its rays; empty when none did.
    pub approx: Vec<bool>,
    /// Rays fired.
    pub rays: u64,
    /// Seconds of one thread spent rendering it (in core timed whole; on a paged tracer one
    /// job in four timed and scaled): what the tile costs, for a queue that hands out the
    /// costly tiles first (`megaray-cluster`).
    pub secs: f32,
}

impl Piece {
    /// A black piece of `rect`, with AOV buffers when `aovs`.
    pub(crate) fn blank(rect: Rect, aovs: bool) -> Piece {
        let n = rect.area();
        Piece {
            rect,
            color: vec![[0.0; 3]; n],
            depth: if aovs { vec![0.0; n] } else { Vec::new() },
            normal: if aovs { vec![[0.0; 3]; n] } else { Vec::new() },
            albedo: if aovs { vec![[0.0; 3]; n] } else { Vec::new() },
            approx: Vec::new(),
            rays: 0,
            secs: 0.0,
        }
    }

    pub(crate) fn mark_approx(&mut self, i: usize) {
        if self.approx.is_empty() {
            self.approx = vec![false; self.color.len()];
        }
        self.approx[i] = true;
    }
}

/// Renders the pixels of `rects` in frame `frame` (as [`crate::render_frame`] would, without
/// a deadline) over the current rayon pool: on a paged tracer as [`megaray_trace::jobs`]
/// (pixels that wait for tiles are parked while the others go on), else straight through.
pub fn render_pieces(r: &Renderer, tracer: &Tracer, frame: u32, rects: &[Rect]) -> (Vec<Piece>, JobStats) {
    let aovs = r.settings.aovs;
    let mut pieces: Vec<Piece> = rects.iter().map(|&rect| Piece::blank(rect, aovs)).collect();
    let mut stats = JobStats::default();
    if tracer.pager().is_none() {
        // Nothing can suspend: a piece a task, its pixels straight into it (as the in-core
        // frame loop does).
        pieces.par_iter_mut().for_each(|pc| {
            let t = Instant::now();
            fill_in_core(r, tracer, frame, pc);
            pc.secs = t.elapsed().as_secs_f32();
        });
    } else {
        render_paged(r, tracer, frame, rects, &mut pieces, &mut stats);
    }
    // The loop's counts are of jobs; the pieces', of pixels.
    stats.finished = pieces.iter().map(|p| p.rect.area() as u64).sum();
    stats.unfinished = 0;
    stats.rays = pieces.iter().map(|p| p.rays).sum();
    (pieces, stats)
}

/// Renders piece `pc` on an unpaged tracer: rows a group at a time, or with AOVs a pixel
/// at a time.
fn fill_in_core(r: &Renderer, tracer: &Tracer, frame: u32, pc: &mut Piece) {
    let mut caster = tracer;
    let rc = pc.rect;
    let w = (rc.x1 - rc.x0) as usize;
    for (row, y) in (rc.y0..rc.y1).enumerate() {
        if pc.depth.is_empty() {
            for x0 in (rc.x0..rc.x1).step_by(GROUP) {
                let g = Group { y, x0, step: 1, len: (rc.x1 - x0).min(GROUP as u32) };
                let out = r.group(g, frame, &mut caster).expect("a plain in-core Tracer never suspends");
                let start = row * w + (x0 - rc.x0) as usize;
                pc.color[start..start + g.len as usize].copy_from_slice(&out.rgb[..g.len as usize]);
                pc.rays += out.rays as u64;
            }
            continue;
        }
        for x in rc.x0..rc.x1 {
            let s = r.pixel(x, y, frame, &mut caster).expect("a plain in-core Tracer never suspends");
            let i = row * w + (x - rc.x0) as usize;
            pc.color[i] = s.radiance.to_array();
            pc.depth[i] = s.depth;
            pc.normal[i] = s.normal.to_array();
            pc.albedo[i] = s.albedo.to_array();
            pc.rays += s.rays as u64;
        }
    }
}

/// Renders `pieces` (of `rects`) on a paged tracer as [`megaray_trace::jobs`]: pixels that
/// wait for tiles are parked while the others go on.
fn render_paged(r: &Renderer, tracer: &Tracer, frame: u32, rects: &[Rect], pieces: &mut [Piece], stats: &mut JobStats) {
    let job_opts =
        |chunk| JobOptions { chunk, deadline: None, max_parked: jobs::MAX_PARKED, stand_in: r.settings.stand_in };
    // Each piece's cost: nanoseconds of its jobs, summed over the threads that ran them.
    let nanos: Vec<AtomicU64> = rects.iter().map(|_| AtomicU64::new(0)).collect();
    if r.settings.aovs {
        // A pixel a job: (piece, index in it).
        let order: Vec<(u32, u32)> =
            rects.iter().enumerate().flat_map(|(p, rc)| (0..rc.area() as u32).map(move |i| (p as u32, i))).collect();
        let run = jobs::run(tracer, order.len(), &job_opts(64), |k, caster| {
            let (p, i) = order[k];
            let rc = rects[p as usize];
            let w = rc.x1 - rc.x0;
            timed(&nanos[p as usize], k, 16, || r.pixel(rc.x0 + i % w, rc.y0 + i / w, frame, caster))
                .map(|s| (s, caster.take_approx()))
        });
        *stats = run.stats;
        for (k, (s, apx)) in run.into_finished() {
            let (p, i) = order[k];
            let pc = &mut pieces[p as usize];
            let i = i as usize;
            pc.color[i] = s.radiance.to_array();
            pc.depth[i] = s.depth;
            pc.normal[i] = s.normal.to_array();
            pc.albedo[i] = s.albedo.to_array();
            pc.rays += s.rays as u64;
            if apx {
                pc.mark_approx(i);
            }
        }
    } else {
        // A group of a row a job: (piece, group).
        let mut groups: Vec<(u32, Group)> = Vec::new();
        for (p, rc) in rects.iter().enumerate() {
            for y in rc.y0..rc.y1 {
                for x0 in (rc.x0..rc.x1).step_by(GROUP) {
                    groups.push((p as u32, Group { y, x0, step: 1, len: (rc.x1 - x0).min(GROUP as u32) }));
                }
            }
        }
        let run = jobs::run(tracer, groups.len(), &job_opts(8), |k, caster| {
            timed(&nanos[groups[k].0 as usize], k, 4, || r.group(groups[k].1, frame, caster))
        });
        *stats = run.stats;
        for (k, out) in run.into_finished() {
            let (p, g) = groups[k];
            let pc = &mut pieces[p as usize];
            let w = pc.rect.x1 - pc.rect.x0;
            let start = ((g.y - pc.rect.y0) * w + (g.x0 - pc.rect.x0)) as usize;
            for j in 0..g.len as usize {
                pc.color[start + j] = out.rgb[j];
                if out.approx & (1 << j) != 0 {
                    pc.mark_approx(start + j);
                }
            }
            pc.rays += out.rays as u64;
        }
    }
    for (pc, n) in pieces.iter_mut().zip(&nanos) {
        pc.secs = n.load(Ordering::Relaxed) as f32 * 1e-9;
    }
}

/// Job `k`'s result; one job in `every` is timed (a clock read costs a tenth of a small job)
/// and `every` times its nanoseconds added to `cost`.
fn timed<R>(cost: &AtomicU64, k: usize, every: usize, job: impl FnOnce() -> R) -> R {
    if !k.is_multiple_of(every) {
        return job();
    }
    let t = Instant::now();
    let out = job();
    cost.fetch_add(t.elapsed().as_nanos() as u64 * every as u64, Ordering::Relaxed);
    out
}

impl Frame {
    /// A black `w` x `h` frame to put pieces into, with AOV buffers when `aovs`.
    pub fn new(w: u32, h: u32, aovs: bool) -> Frame {
        Frame::blank(w, h, aovs)
    }

    /// Copies `p` into its place (its rays counted). Panics if the piece lies outside the
    /// frame or its AOVs do not match the frame's.
    pub fn put(&mut self, p: &Piece) {
        let (w, h) = (self.image.width, self.image.height);
        assert!(p.rect.within(w, h), "piece {:?} outside the {w}x{h} frame", p.rect);
        assert_eq!(p.depth.is_empty(), self.depth.is_empty(), "a piece's AOVs differ from its frame's");
        let pw = (p.rect.x1 - p.rect.x0) as usize;
        for (row, y) in (p.rect.y0..p.rect.y1).enumerate() {
            let dst = (y * w + p.rect.x0) as usize..(y * w + p.rect.x1) as usize;
            let src = row * pw..(row + 1) * pw;
            self.image.pixels[dst.clone()].copy_from_slice(&p.color[src.clone()]);
            if !self.depth.is_empty() {
                self.depth[dst.clone()].copy_from_slice(&p.depth[src.clone()]);
                self.normal[dst.clone()].copy_from_slice(&p.normal[src.clone()]);
                self.albedo[dst.clone()].copy_from_slice(&p.albedo[src.clone()]);
            }
            if !p.approx.is_empty() {
                if self.approx.is_empty() {
                    self.approx = vec![false; (w * h) as usize];
                }
                self.approx[dst].copy_from_slice(&p.approx[src]);
            }
        }
        self.rays += p.rays;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_frame_once() {
        for (w, h) in [(1, 1), (33, 65), (64, 32), (100, 37)] {
            let mut seen = vec![0u32; (w * h) as usize];
            for t in Rect::tiles(w, h) {
                assert!(t.within(w, h));
                for y in t.y0..t.y1 {
                    for x in t.x0..t.x1 {
                        seen[(y * w + x) as usize] += 1;
                    }
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "{w}x{h}");
        }
    }
}
