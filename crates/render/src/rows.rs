//! Camera rays a row at a time: the frame loops' path for frames without AOVs. A job is up to
//! [`GROUP`] pixels of one row (side by side, or every 4th in a pass against a deadline);
//! their camera rays are made 16 at a time ([`Camera::rays16`]: the same bits as
//! [`Camera::ray`]) and traced through the caster before any shading context exists; a miss
//! is the background, a hit is shaded as [`Renderer::sample`] shades it. The same samples as
//! [`Renderer::pixel`], for less work per pixel and per job (docs/PERF.md, "Camera rays a row
//! at a time").
//!
//! [`Camera::rays16`]: megaray_base::Camera::rays16
//! [`Camera::ray`]: megaray_base::Camera::ray

use megaray_trace::{RayCaster, Suspended};

use crate::frame::{Renderer, TILE};
use crate::sampling::pixel_offset;
use crate::visibility::Filtered;

/// The most pixels of a job.
pub(crate) const GROUP: usize = 16;

/// A job's pixels: `len` pixels of row `y` from `x0`, `step` apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Group {
    pub y: u32,
    pub x0: u32,
    pub step: u32,
    pub len: u32,
}

impl Group {
    /// The row-major index of pixel `k` of the group in a `w`-wide image.
    #[inline]
    pub fn index(&self, k: usize, w: u32) -> usize {
        (self.y * w + self.x0 + self.step * k as u32) as usize
    }
}

/// What the frame loop keeps of a finished group whose pixels it has written: the rays
/// they fired, which of them a stand-in answered (bit `k`: pixel `k`).
pub(crate) struct GroupDone {
    pub rays: u32,
    pub approx: u16,
}

/// A group's result: its pixels' colours, and as [`GroupDone`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct GroupOut {
    pub rgb: [[f32; 3]; GROUP],
    pub rays: u32,
    pub approx: u16,
}

/// Pushes the groups of row `y` over `xs` (`step` apart) onto `out`, at most [`GROUP`] each.
fn push_row(out: &mut Vec<Group>, y: u32, xs: std::iter::StepBy<std::ops::Range<u32>>, step: u32) {
    let xs: Vec<u32> = xs.collect();
    for c in xs.chunks(GROUP) {
        out.push(Group { y, x0: c[0], step, len: c.len() as u32 });
    }
}

/// The groups of a `w` x `h` frame in tile order (32x32 tiles in rows, rows within a tile),
/// backward when `backward` (see [`crate::render_frame_with`]).
pub(crate) fn tile_groups(w: u32, h: u32, backward: bool) -> Vec<Group> {
    let mut out = Vec::new();
    for ty in 0..h.div_ceil(TILE) {
        for tx in 0..w.div_ceil(TILE) {
            for y in ty * TILE..((ty + 1) * TILE).min(h) {
                push_row(&mut out, y, (tx * TILE..((tx + 1) * TILE).min(w)).step_by(1), 1);
            }
        }
    }
    if backward {
        out.reverse();
    }
    out
}

/// The groups of a frame against a deadline: the first pass of [`crate::frame::PASSES`] (one
/// pixel of every 4x4 block) over the whole image, then band by band (32 rows, a row of tiles)
/// the other fifteen passes. Within a band, each row across pairs of tiles (a group's 16
/// pixels, 4 apart, span 64: two tiles); bands and pairs backward when `backward`. What a
/// deadline leaves has a done pixel in every block (for [`crate::frame`]'s fill) once the
/// first pass is done, while the rest of the frame goes through the image (and the scene)
/// once, a band at a time: fifteen passes over the whole image made a frame read its image
/// and scene data fifteen times (docs/PERF.md, "Deadline frames band by band").
pub(crate) fn interleaved_groups(w: u32, h: u32, backward: bool) -> Vec<Group> {
    const SPAN: u32 = 2 * TILE;
    let mut blocks: Vec<(u32, u32)> =
        (0..h.div_ceil(TILE)).flat_map(|ty| (0..w.div_ceil(SPAN)).map(move |bx| (bx, ty))).collect();
    if backward {
        blocks.reverse();
    }
    let mut out = Vec::new();
    let mut pass = |(dx, dy): (u32, u32), (bx, ty): (u32, u32)| {
        for y in (ty * TILE + dy..((ty + 1) * TILE).min(h)).step_by(4) {
            push_row(&mut out, y, (bx * SPAN + dx..((bx + 1) * SPAN).min(w)).step_by(4), 4);
        }
    };
    for &b in &blocks {
        pass(crate::frame::PASSES[0], b);
    }
    for band in blocks.chunk_by(|a, b| a.1 == b.1) {
        for &p in &crate::frame::PASSES[1..] {
            for &b in band {
                pass(p, b);
            }
        }
    }
    out
}

/// The groups of an in-core frame against a deadline (nothing suspends, so every group runs
/// when it comes): the first pass of [`crate::frame::PASSES`] over the whole image (groups of
/// pixels 4 apart), then every pixel band by band in the in-core loop's order (bands of
/// `band_rows`, 32-pixel columns, a row's 16 neighbours a group), the first pass's pixels
/// again (a sixteenth of the work, the same values). What a deadline leaves has a done pixel
/// in every 4x4 block once the first pass is done; the rest goes as fast as a frame without
/// a deadline (groups 4 apart cost about a third more: their rays spread over more of the
/// scene). Backward when `backward`.
pub(crate) fn first_pass_then_bands(w: u32, h: u32, band_rows: u32, backward: bool) -> Vec<Group> {
    let mut out = Vec::new();
    let (dx, dy) = crate::frame::PASSES[0];
    for y in (dy..h).step_by(4) {
        push_row(&mut out, y, (dx..w).step_by(4), 4);
    }
    let first = out.len();
    for y0 in (0..h).step_by(band_rows as usize) {
        for x0 in (0..w).step_by(TILE as usize) {
            for y in y0..(y0 + band_rows).min(h) {
                push_row(&mut out, y, (x0..(x0 + TILE).min(w)).step_by(1), 1);
            }
        }
    }
    if backward {
        out[..first].reverse();
        out[first..].reverse();
    }
    out
}

impl Renderer {
    /// The pixels of `g` in frame `frame` (as [`Renderer::pixel`] gives them), traced through
    /// `caster`; entries past `g.len` are left black.
    pub(crate) fn group<C: RayCaster>(&self, g: Group, frame: u32, caster: &mut C) -> Result<GroupOut, Suspended> {
        let caster = &mut Filtered::new(caster, self.settings.visibility.as_deref());
        let mut out = GroupOut { rgb: [[0.0; 3]; GROUP], rays: 0, approx: 0 };
        let len = g.len as usize;
        // One sample a pixel: sample index `frame`, the same offset for every pixel.
        let one = self.settings.spp.max(1) == 1;
        let rays = one.then(|| {
            let (ox, oy) = pixel_offset(frame);
            let sx: [f32; 16] = std::array::from_fn(|k| (g.x0 + g.step * k.min(len - 1) as u32) as f32 + ox);
            self.settings.camera.rays16(&sx, &[g.y as f32 + oy; 16])
        });
        // Camera rays that miss the caster's box are the background, with no query (most of
        // a distant model's view): the same answer the trace would give.
        let entering = match (&rays, caster.bounds()) {
            (Some(rays), Some(b)) => rays.entering(&b),
            _ => u16::MAX,
        };
        // Pixels that adaptive sampling chose take all their samples in `pixel_in`.
        let more = self.more();
        for k in 0..len {
            let x = g.x0 + g.step * k as u32;
            let single = rays.is_some() && (more.is_none() || self.spp_at(x, g.y, more) == 1);
            if let (true, Some(r)) = (single && entering & (1 << k) == 0, &rays) {
                out.rgb[k] = self.background(r.ray(k).dir).to_array();
                out.rays += 1;
                continue;
            }
            // A pixel finished in an earlier run of this job (before it was suspended) is
            // recalled, not redone: the job needs one pixel's tiles at a time.
            if let Some(m) = caster.recall() {
                out.rgb[k] = [f32::from_bits(m[0]), f32::from_bits(m[1]), f32::from_bits(m[2])];
                out.rays += m[3];
                out.approx |= ((m[4] != 0) as u16) << k;
                continue;
            }
            let mark = caster.mark();
            let s = match &rays {
                Some(rays) if single => self.camera_sample(x, g.y, frame, &rays.ray(k), caster)?,
                _ => self.pixel_in(x, g.y, frame, caster)?,
            };
            let rgb = s.radiance.to_array();
            let approx = caster.take_approx();
            out.rgb[k] = rgb;
            out.rays += s.rays;
            out.approx |= (approx as u16) << k;
            caster.checkpoint(mark, [rgb[0].to_bits(), rgb[1].to_bits(), rgb[2].to_bits(), s.rays, approx as u32]);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel in exactly one group, whatever the size and order.
    #[test]
    fn groups_cover_each_pixel_once() {
        for (w, h) in [(1, 1), (7, 3), (33, 65), (64, 32), (100, 37)] {
            for backward in [false, true] {
                for groups in [tile_groups(w, h, backward), interleaved_groups(w, h, backward)] {
                    let mut seen = vec![0u32; (w * h) as usize];
                    for g in &groups {
                        assert!((1..=GROUP as u32).contains(&g.len));
                        for k in 0..g.len as usize {
                            seen[g.index(k, w)] += 1;
                        }
                    }
                    assert!(seen.iter().all(|&c| c == 1), "{w}x{h}");
                }
            }
        }
    }

    /// The first pass, then every pixel: the first pass's pixels (one of every 4x4 block,
    /// `PASSES[0]`) come first and twice, every other pixel once, after them.
    #[test]
    fn the_first_pass_then_every_pixel_band_by_band() {
        let (dx, dy) = crate::frame::PASSES[0];
        for (w, h) in [(1, 1), (7, 3), (33, 65), (64, 32), (100, 37)] {
            for backward in [false, true] {
                let groups = first_pass_then_bands(w, h, 8, backward);
                let first = groups.iter().take_while(|g| g.step == 4).count();
                let mut seen = vec![0u32; (w * h) as usize];
                for (i, g) in groups.iter().enumerate() {
                    assert!((1..=GROUP as u32).contains(&g.len));
                    assert_eq!(g.step, if i < first { 4 } else { 1 }, "{w}x{h}: group {i}");
                    for k in 0..g.len as usize {
                        let p = g.index(k, w);
                        let (x, y) = (p as u32 % w, p as u32 / w);
                        assert!(i >= first || (x % 4, y % 4) == (dx, dy), "{w}x{h}: ({x}, {y}) in the first pass");
                        seen[p] += 1;
                    }
                }
                for (p, &c) in seen.iter().enumerate() {
                    let (x, y) = (p as u32 % w, p as u32 / w);
                    let want = if (x % 4, y % 4) == (dx, dy) { 2 } else { 1 };
                    assert_eq!(c, want, "{w}x{h}: pixel ({x}, {y})");
                }
                // Band by band: after the first pass, rows never go back to an earlier band
                // (forward) or a later one (backward).
                let bands: Vec<u32> = groups[first..].iter().map(|g| g.y / 8).collect();
                assert!(bands.windows(2).all(|b| if backward { b[0] >= b[1] } else { b[0] <= b[1] }), "{w}x{h}");
            }
        }
    }
}
