//! The renderer and the frame loop.
//!
//! [`Renderer::sample`] is the whole work of one sample: the camera ray, the shader at its
//! hit (with whatever rays it fires), the AOVs. It is a pure function of (pixel, sample
//! index) and the rays' answers, and returns [`Suspended`] if any ray was, so a paging frame
//! loop can park the sample and run it again later. [`render_frame`] is the frame loop:
//! pixels in 32x32 tiles as [`megaray_trace::jobs`] over rayon's threads, each pixel `spp`
//! samples; on a paged tracer, pixels that wait for tiles are parked and resumed.

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use megaray_base::{Aabb, Ray, Vec3};

use megaray_trace::jobs::{self, JobOptions, JobStats};
use megaray_trace::{Hit, RayCaster, RayCone, Suspended, Tracer};
use rayon::prelude::*;

use crate::env::Environment;
use crate::image_out::Image;
use crate::rows;
use crate::sampling::{light_subset, pixel_offset, Sampler};
use crate::settings::RenderSettings;
use crate::shader::{ShadeCtx, Shader, SurfaceHit};
use crate::visibility::{camera_view, through, Filtered, CAP_COLOR};
use crate::world::World;

/// What one sample (or the average of a pixel's samples) yields.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SampleOut {
    /// Radiance along the camera ray (linear RGB).
    pub radiance: Vec3,
    /// Distance to the primary hit (`f32::INFINITY` on a miss). Only with `settings.aovs`.
    pub depth: f32,
    /// Shading normal at the primary hit (zero on a miss). Only with `settings.aovs`.
    pub normal: Vec3,
    /// Albedo at the primary hit (zero on a miss). Only with `settings.aovs`.
    pub albedo: Vec3,
    /// Rays fired (camera ray included).
    pub rays: u32,
}

/// Everything needed to shade samples: the [`World`] (settings, environment, textures) and
/// the shader. Shared by all threads. Reads as its world (`renderer.settings`,
/// `renderer.background(dir)`), which it derefs to.
pub struct Renderer {
    world: World,
    shader: Arc<dyn Shader>,
    /// Frames run so far: the frame loop walks the pixels forward on even passes and
    /// backward on odd ones (see [`render_frame_with`]).
    passes: AtomicU32,
    /// The pixels that take more samples (`settings.adaptive`), chosen between frames by
    /// the progressive loop ([`Renderer::sample_more`]).
    more: std::sync::OnceLock<crate::adaptive::PixelSamples>,
    /// Buffers of frames done with, filled again by the next ([`Renderer::recycle`]): a
    /// frame's are megabytes, and fresh ones cost their page faults on every frame.
    spare: Mutex<Spare>,
}

/// See [`Renderer::recycle`].
#[derive(Default)]
struct Spare {
    pixels: Vec<[f32; 3]>,
    groups: jobs::JobsBuffers<rows::GroupDone>,
}

impl std::ops::Deref for Renderer {
    type Target = World;
    fn deref(&self) -> &World {
        &self.world
    }
}

impl std::ops::DerefMut for Renderer {
    fn deref_mut(&mut self) -> &mut World {
        &mut self.world
    }
}

/// A highlighted surface's colour: its brightness, in orange, over a little of its own.
fn highlight(c: Vec3) -> Vec3 {
    let lum = c.dot(Vec3::new(0.2126, 0.7152, 0.0722));
    c * 0.3 + Vec3::new(1.0, 0.45, 0.05) * (0.7 * lum + 0.08)
}

impl Renderer {
    /// A renderer for a scene with bounds `bounds`, shading with `settings.shader`, with the
    /// constant sky `settings.sky` as its (implicit) environment.
    pub fn new(settings: RenderSettings, bounds: &Aabb) -> Renderer {
        Renderer {
            shader: Arc::new(settings.shader),
            world: World::new(settings, bounds),
            passes: AtomicU32::new(0),
            more: Default::default(),
            spare: Mutex::default(),
        }
    }

    /// Takes back a frame rendered with it and done with: the next frame of the same size
    /// fills its image buffer again instead of a new one.
    pub fn recycle(&self, f: Frame) {
        self.spare().pixels = f.image.pixels;
    }

    fn spare(&self) -> std::sync::MutexGuard<'_, Spare> {
        self.spare.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A `w` x `h` frame (AOV buffers when `aovs`), in a recycled image buffer when there
    /// is one of its size: black if `black`, else its pixels left as they were (for a
    /// frame loop that writes every pixel, or blackens those it leaves).
    fn blank_frame(&self, w: u32, h: u32, aovs: bool, black: bool) -> Frame {
        Frame::blank_in(std::mem::take(&mut self.spare().pixels), w, h, aovs, black)
    }

    /// Lights the scene with `env` (what misses see, and the lights of every shader).
    pub fn with_environment(mut self, env: Arc<Environment>) -> Renderer {
        self.world.set_environment(env);
        self
    }

    /// Adds the scene's area lights: every shader shows them, `path` is lit by them.
    pub fn with_area_lights(mut self, area: Arc<crate::AreaLights>) -> Renderer {
        self.world.set_area_lights(area);
        self
    }

    /// Shades with `shader` instead of `settings.shader`.
    pub fn with_shader(mut self, shader: Arc<dyn Shader>) -> Renderer {
        self.shader = shader;
        self
    }

    /// The shader.
    pub fn shader(&self) -> &dyn Shader {
        &*self.shader
    }

    /// What the shaders see: settings, environment, textures.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// One sample: sample `sample_index` of pixel (`px`, `py`). Deterministic: the same
    /// arguments fire the same rays. Returns [`Suspended`] if the caster did.
    pub fn sample(
        &self,
        px: u32,
        py: u32,
        sample_index: u32,
        caster: &mut dyn RayCaster,
    ) -> Result<SampleOut, Suspended> {
        let mut f = Filtered::new(caster, self.settings.visibility.as_deref());
        self.sample_in(px, py, sample_index, &mut f)
    }

    /// [`Renderer::sample`] through a caster that applies the settings' visibility.
    pub(crate) fn sample_in<C: RayCaster + ?Sized>(
        &self,
        px: u32,
        py: u32,
        sample_index: u32,
        f: &mut Filtered<'_, C>,
    ) -> Result<SampleOut, Suspended> {
        let (ox, oy) = pixel_offset(sample_index);
        let ray = self.settings.camera.ray(px as f32 + ox, py as f32 + oy);
        self.camera_sample(px, py, sample_index, &ray, f)
    }

    /// Traces and shades camera ray `ray` of sample `sample_index` of pixel (`px`, `py`):
    /// X-ray layers over what lies behind them, a section cap, or the shaded hit.
    #[inline]
    pub(crate) fn camera_sample<C: RayCaster + ?Sized>(
        &self,
        px: u32,
        py: u32,
        sample_index: u32,
        ray: &Ray,
        f: &mut Filtered<'_, C>,
    ) -> Result<SampleOut, Suspended> {
        let view = camera_view(f, ray, &self.camera_cone())?;
        let mut out = match view.cap {
            Some((t, n)) => {
                let n = if n.dot(ray.dir) > 0.0 { -n } else { n };
                let c = Vec3::from(CAP_COLOR);
                let lit = c * (0.35 + 0.65 * n.dot(self.settings.light.normalize_or_zero()).abs());
                let mut o = SampleOut { radiance: lit, depth: f32::INFINITY, rays: 1, ..SampleOut::default() };
                if self.settings.aovs {
                    (o.depth, o.normal, o.albedo) = (t, n, c);
                }
                o
            }
            None => self.shade_camera_hit(px, py, sample_index, ray, view.hit, f)?,
        };
        if view.layers > 0 {
            out.radiance = out.radiance * through(view.layers) + view.ghost;
        }
        Ok(out)
    }

    /// The footprint of camera rays.
    #[inline]
    pub(crate) fn camera_cone(&self) -> RayCone {
        RayCone::camera(self.settings.camera.pixel_angle())
    }

    /// The rest of [`Renderer::sample`] once its camera ray `ray` was traced (with the
    /// footprint [`Renderer::camera_cone`]) and gave `hit`: the background on a miss, the
    /// shader (and whatever rays it fires) on a hit.
    #[inline]
    pub(crate) fn shade_camera_hit(
        &self,
        px: u32,
        py: u32,
        sample_index: u32,
        ray: &Ray,
        hit: Option<Hit>,
        caster: &mut dyn RayCaster,
    ) -> Result<SampleOut, Suspended> {
        let mut out = SampleOut { depth: f32::INFINITY, rays: 1, ..SampleOut::default() };
        let Some(hit) = hit else {
            out.radiance = self.background(ray.dir);
            return Ok(out);
        };
        let subset = light_subset(px, py, sample_index, self.environment().lights.subsets());
        let sampler = Sampler::new(px, py, sample_index);
        let mut ctx = ShadeCtx::new(&self.world, &*self.shader, caster, sampler, subset);
        ctx.count_camera_ray();
        let sh = SurfaceHit::new(ctx.scene(), ray, hit);
        if self.settings.aovs {
            out.depth = hit.t;
            out.normal = sh.ns;
            out.albedo = ctx.material(&sh).albedo;
        }
        ctx.enter(&hit);
        out.radiance = self.shader.shade(ray, &sh, &mut ctx)?;
        if let Some(c) = self.settings.highlight {
            if ctx.scene().components().of(hit.part, hit.prim) == Some(c) {
                out.radiance = highlight(out.radiance);
            }
        }
        out.rays = ctx.rays();
        Ok(out)
    }

    /// The samples pixel (`px`, `py`) takes a frame: `settings.spp`, or more where adaptive
    /// sampling chose it (`more`: the choice, read once per frame or job).
    #[inline]
    pub(crate) fn spp_at(&self, px: u32, py: u32, more: Option<&crate::adaptive::PixelSamples>) -> u32 {
        let (c, spp) = (&self.settings.camera, self.settings.spp.max(1));
        more.and_then(|m| m.get(px, py, c.width, c.height)).map_or(spp, |n| n.max(spp))
    }

    /// Adaptive sampling (`settings.adaptive` above 1): chooses the pixels of `img` (the
    /// picture so far) that change sharply between neighbours to take that many samples a
    /// frame from now on (the choice only grows; it belongs to the first size it is made
    /// for). Returns the pixels chosen now that were not before (empty when off).
    pub fn sample_more(&self, img: &crate::Image) -> Vec<bool> {
        let n = self.settings.adaptive.min(255) as u8;
        if n <= 1 {
            return Vec::new();
        }
        let chosen = crate::adaptive::sharp_pixels(img);
        let more = self.more.get_or_init(|| crate::adaptive::PixelSamples::new(img.width, img.height));
        more.choose(&chosen, n)
    }

    /// How many pixels adaptive sampling has chosen so far.
    pub fn sampled_more(&self) -> usize {
        self.more().map_or(0, |m| m.count())
    }

    /// The adaptive choice (`None` when off or not made yet).
    #[inline]
    pub(crate) fn more(&self) -> Option<&crate::adaptive::PixelSamples> {
        if self.settings.adaptive > 1 {
            self.more.get()
        } else {
            None
        }
    }

    /// The `spp` samples of pixel (`px`, `py`) in frame `frame` (sample indices
    /// `frame * spp .. (frame + 1) * spp`), averaged. Depth is the nearest of the samples'.
    pub fn pixel(&self, px: u32, py: u32, frame: u32, caster: &mut dyn RayCaster) -> Result<SampleOut, Suspended> {
        let mut f = Filtered::new(caster, self.settings.visibility.as_deref());
        self.pixel_in(px, py, frame, &mut f)
    }

    /// [`Renderer::pixel`] through a caster that applies the settings' visibility.
    pub(crate) fn pixel_in<C: RayCaster + ?Sized>(
        &self,
        px: u32,
        py: u32,
        frame: u32,
        f: &mut Filtered<'_, C>,
    ) -> Result<SampleOut, Suspended> {
        let spp = self.spp_at(px, py, self.more());
        let mut acc = SampleOut { depth: f32::INFINITY, ..SampleOut::default() };
        for k in 0..spp {
            let s = self.sample_in(px, py, frame.wrapping_mul(spp).wrapping_add(k), f)?;
            acc.radiance += s.radiance;
            acc.normal += s.normal;
            acc.albedo += s.albedo;
            acc.depth = acc.depth.min(s.depth);
            acc.rays += s.rays;
        }
        let inv = 1.0 / spp as f32;
        acc.radiance *= inv;
        acc.albedo *= inv;
        acc.normal = acc.normal.normalize_or_zero();
        Ok(acc)
    }
}

/// One rendered frame: the image and (with `settings.aovs`) the AOVs.
#[derive(Clone, Debug)]
pub struct Frame {
    /// The mean radiance of each pixel's samples.
    pub image: Image,
    /// Per pixel, the nearest primary hit distance; empty without `settings.aovs`.
    pub depth: Vec<f32>,
    /// Per pixel, the mean shading normal (renormalised); empty without `settings.aovs`.
    pub normal: Vec<[f32; 3]>,
    /// Per pixel, the mean albedo; empty without `settings.aovs`.
    pub albedo: Vec<[f32; 3]>,
    /// Per pixel, whether it was finished: empty when every pixel was. Only a frame with a
    /// deadline ([`FrameOptions::deadline`]) can leave pixels unfinished; they are black.
    pub done: Vec<bool>,
    /// Per pixel, whether a stand-in answered some ray for want of a tile (its value is
    /// approximate; a later frame with the tile refines it): empty when none did. Only a
    /// frame with [`FrameOptions::stand_in`] has them.
    pub approx: Vec<bool>,
    /// Pixels the deadline left that were filled from done neighbours (with
    /// [`FrameOptions::stand_in`]; counted in [`Frame::approx`] and [`Frame::done`]).
    pub filled: u64,
    /// Rays fired in the frame.
    pub rays: u64,
    /// What the frame loop did: pixels finished and not, suspensions, waiting.
    pub jobs: JobStats,
}

impl Frame {
    /// A black `w` x `h` frame, with zeroed AOV buffers when `aovs`.
    pub(crate) fn blank(w: u32, h: u32, aovs: bool) -> Frame {
        Frame::blank_in(Vec::new(), w, h, aovs, true)
    }

    /// [`Frame::blank`], its image in `pixels` when they are `w * h` (zeroed if `black`).
    fn blank_in(mut pixels: Vec<[f32; 3]>, w: u32, h: u32, aovs: bool, black: bool) -> Frame {
        let n = (w * h) as usize;
        let image = match pixels.len() == n {
            true => {
                if black {
                    pixels.fill([0.0; 3]);
                }
                Image { width: w, height: h, pixels }
            }
            false => Image::new(w, h),
        };
        Frame {
            image,
            depth: if aovs { vec![0.0; n] } else { Vec::new() },
            normal: if aovs { vec![[0.0; 3]; n] } else { Vec::new() },
            albedo: if aovs { vec![[0.0; 3]; n] } else { Vec::new() },
            done: Vec::new(),
            approx: Vec::new(),
            filled: 0,
            rays: 0,
            jobs: JobStats::default(),
        }
    }

    /// Whether pixel `i` (row-major) is approximate ([`Frame::approx`]).
    pub fn is_approx(&self, i: usize) -> bool {
        self.approx.get(i).copied().unwrap_or(false)
    }

    /// Whether pixel `i` (row-major) was finished.
    pub fn is_done(&self, i: usize) -> bool {
        self.done.get(i).copied().unwrap_or(true)
    }
}

/// How to run one frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameOptions {
    /// End the frame at this instant even if pixels are left (they are flagged in
    /// [`Frame::done`]).
    pub deadline: Option<Instant>,
    /// Rays that need a tile not resident are answered by a coarser level of detail that is
    /// (the tile requested; the pixel flagged in [`Frame::approx`]) rather than wait for it.
    pub stand_in: bool,
}

/// The tile edge of the frame loop, in pixels.
pub const TILE: u32 = 32;

/// The positions within a 4x4 block in the order a frame against a deadline takes them: each
/// group of passes halves the spacing of the pixels done (a Bayer order), so that whatever
/// the deadline leaves is scattered and filled from done neighbours ([`fill_unfinished`]).
pub(crate) const PASSES: [(u32, u32); 16] = [
    (0, 0),
    (2, 2),
    (2, 0),
    (0, 2),
    (1, 1),
    (3, 3),
    (3, 1),
    (1, 3),
    (1, 0),
    (3, 2),
    (3, 0),
    (1, 2),
    (0, 1),
    (2, 3),
    (2, 1),
    (0, 3),
];

/// Fills each pixel of `f` not done from a done pixel nearby (the first of its 4x4 block in
/// [`PASSES`] order, else of the blocks around it), marking it done and approximate
/// ([`Frame::approx`]: a later frame replaces it). Returns how many it filled.
fn fill_unfinished(f: &mut Frame) -> u64 {
    let (w, h) = (f.image.width, f.image.height);
    let n = (w * h) as usize;
    if f.done.is_empty() {
        return 0;
    }
    if f.approx.is_empty() {
        f.approx = vec![false; n];
    }
    let was_done = f.done.clone();
    let mut filled = 0;
    for p in 0..n {
        if was_done[p] {
            continue;
        }
        let (x, y) = (p as u32 % w, p as u32 / w);
        let (bx, by) = (x & !3, y & !3);
        let mut from = None;
        'search: for ring in 0..3i64 {
            for oy in -ring..=ring {
                for ox in -ring..=ring {
                    if ox.abs().max(oy.abs()) != ring {
                        continue;
                    }
                    let (cx, cy) = (bx as i64 + 4 * ox, by as i64 + 4 * oy);
                    for &(dx, dy) in &PASSES {
                        let (sx, sy) = (cx + dx as i64, cy + dy as i64);
                        if sx >= 0 && sy >= 0 && (sx as u32) < w && (sy as u32) < h {
                            let q = (sy as u32 * w + sx as u32) as usize;
                            if was_done[q] {
                                from = Some(q);
                                break 'search;
                            }
                        }
                    }
                }
            }
        }
        if let Some(q) = from {
            f.image.pixels[p] = f.image.pixels[q];
            if !f.depth.is_empty() {
                (f.depth[p], f.normal[p], f.albedo[p]) = (f.depth[q], f.normal[q], f.albedo[q]);
            }
            f.done[p] = true;
            f.approx[p] = true;
            filled += 1;
        }
    }
    filled
}

/// Renders frame `frame` (sample positions and light subsets move on from frame to frame):
/// [`Renderer::pixel`] for each pixel, in 32x32 tiles over the current rayon pool.
/// With `settings.frame_deadline`, the frame ends that long after it started.
pub fn render_frame(r: &Renderer, tracer: &Tracer, frame: u32) -> Frame {
    let deadline = r.settings.frame_deadline.map(|d| Instant::now() + d);
    render_frame_with(r, tracer, frame, &FrameOptions { deadline, stand_in: r.settings.stand_in })
}

/// [`render_frame`] with options. The pixels run as [`megaray_trace::jobs`]: on a paged
/// tracer a pixel whose rays need a tile not yet resident is parked and finished when the
/// tile has arrived, while the threads go on with other pixels; no thread waits on the disk
/// while there is any pixel it can work on.
pub fn render_frame_with(r: &Renderer, tracer: &Tracer, frame: u32, opts: &FrameOptions) -> Frame {
    if tracer.pager().is_none() && opts.deadline.is_none() {
        return render_in_core(r, tracer, frame);
    }
    let (w, h) = (r.settings.camera.width, r.settings.camera.height);
    // Every other frame walks the pixels backward. When a frame needs more tiles than the
    // memory budget holds, walking them in the same order every time is the worst case of
    // least-recently-used eviction (each tile is evicted just before it is needed again);
    // walking back starts with the tiles the last frame used last, still resident. Against
    // a deadline, the pixels go in interleaved passes (what is left is filled from
    // neighbours), tiles walked back on alternate frames.
    let backward = r.passes.fetch_add(1, Ordering::Relaxed) % 2 == 1;
    // Against a deadline, race through the pixels whose tiles are resident; without one,
    // keep the frame's accesses together (see `megaray_trace::jobs`).
    let max_parked = if opts.deadline.is_some() { jobs::MAX_PARKED_DEADLINE } else { jobs::MAX_PARKED };
    let n = (w * h) as usize;
    let aovs = r.settings.aovs;
    // Pixels the frame leaves are blackened below.
    let mut f = r.blank_frame(w, h, aovs, false);
    let mut finished: Vec<u32> = Vec::new();
    let mut approx: Vec<u32> = Vec::new();
    // Jobs in the order of rows' groups (`rows`): tiles, and against a deadline interleaved
    // passes, so that what the deadline leaves is scattered.
    let in_core = tracer.pager().is_none();
    let groups = match opts.deadline {
        Some(_) if in_core && !aovs => rows::first_pass_then_bands(w, h, BAND_ROWS, backward),
        Some(_) => rows::interleaved_groups(w, h, backward),
        None => rows::tile_groups(w, h, backward),
    };
    if aovs {
        // A pixel a job, the full sample its result: the groups' pixels one by one.
        let order: Vec<u32> =
            groups.iter().flat_map(|g| (0..g.len as usize).map(move |k| g.index(k, w) as u32)).collect();
        let job_opts = JobOptions { chunk: 64, deadline: opts.deadline, max_parked, stand_in: opts.stand_in };
        let run = jobs::run(tracer, n, &job_opts, |i, caster| {
            let p = order[i];
            r.pixel(p % w, p / w, frame, caster).map(|s| (s, caster.approx()))
        });
        f.jobs = run.stats;
        for (i, (s, apx)) in run.into_finished() {
            let p = order[i] as usize;
            finished.push(p as u32);
            if apx {
                approx.push(p as u32);
            }
            f.image.pixels[p] = s.radiance.to_array();
            f.rays += s.rays as u64;
            f.depth[p] = s.depth;
            f.normal[p] = s.normal.to_array();
            f.albedo[p] = s.albedo.to_array();
        }
    } else if in_core {
        // Nothing can suspend (an unpaged tracer, against a deadline): no job bookkeeping.
        // The groups go over some pixels twice (`first_pass_then_bands`).
        let image = megaray_base::pixels_as_atomic(&mut f.image.pixels);
        let (done, [rays, again], apx) = groups_until(r, tracer, frame, &groups, opts.deadline, image);
        // A whole frame's rays are its pixels' once (a partial one's count the first pass's
        // pixels traced again too).
        let rays = if done == groups.len() { rays } else { rays + again };
        let mut pixels = n as u64;
        if done < groups.len() {
            let mut seen = vec![false; n];
            for g in &groups[..done] {
                for k in 0..g.len as usize {
                    seen[g.index(k, w)] = true;
                }
            }
            finished.extend(seen.iter().enumerate().filter(|(_, &s)| s).map(|(p, _)| p as u32));
            pixels = finished.len() as u64;
        }
        approx = apx;
        f.rays = rays;
        f.jobs = JobStats { finished: pixels, unfinished: n as u64 - pixels, rays, ..JobStats::default() };
    } else {
        // A group a job, its pixels written into the image where it finishes (a group's
        // are its own: interleaved groups scattered over the image would be gathered back
        // from their threads' results at random).
        let job_opts = JobOptions { chunk: 8, deadline: opts.deadline, max_parked, stand_in: opts.stand_in };
        let spare = std::mem::take(&mut r.spare().groups);
        let image = megaray_base::pixels_as_atomic(&mut f.image.pixels);
        let run = jobs::run_reusing(
            tracer,
            groups.len(),
            &job_opts,
            |i, caster| {
                let (g, out) = (groups[i], r.group(groups[i], frame, caster)?);
                put_group(image, g, w, &out);
                Ok(rows::GroupDone { rays: out.rays, approx: out.approx })
            },
            spare,
        );
        f.jobs = run.stats;
        let partial = f.jobs.unfinished > 0;
        let mut pixels = 0u64;
        for (i, out) in run.finished() {
            let g = groups[i];
            f.rays += out.rays as u64;
            pixels += g.len as u64;
            if !partial && out.approx == 0 {
                continue;
            }
            for k in 0..g.len as usize {
                let p = g.index(k, w) as u32;
                if partial {
                    finished.push(p);
                }
                if out.approx & (1 << k) != 0 {
                    approx.push(p);
                }
            }
        }
        // The loop's counts are of jobs; the frame's, of pixels.
        (f.jobs.finished, f.jobs.unfinished) = (pixels, n as u64 - pixels);
        r.spare().groups = run.into_buffers();
    }
    if !approx.is_empty() {
        f.approx = vec![false; n];
        for p in approx {
            f.approx[p as usize] = true;
        }
    }
    if f.jobs.unfinished > 0 {
        f.done = vec![false; n];
        for p in finished {
            f.done[p as usize] = true;
        }
        for (px, _) in f.image.pixels.iter_mut().zip(&f.done).filter(|(_, &d)| !d) {
            *px = [0.0; 3];
        }
        if opts.stand_in {
            f.filled = fill_unfinished(&mut f);
        }
    }
    f
}

/// Writes group `g`'s pixels into `image` (`w` wide), which other threads write too (other
/// groups' pixels).
#[inline]
fn put_group(image: &[[AtomicU32; 3]], g: rows::Group, w: u32, out: &rows::GroupOut) {
    for k in 0..g.len as usize {
        for (px, c) in image[g.index(k, w)].iter().zip(out.rgb[k]) {
            px.store(c.to_bits(), Ordering::Relaxed);
        }
    }
}

/// The groups of frame `frame` on every thread of the pool, from a shared counter a chunk at
/// a time until `deadline`, each written into `image` (`put_group`) as it finishes, when
/// nothing can suspend (an unpaged tracer). Every chunk handed out is finished whole, so the
/// groups done are a prefix: returns its length, the rays fired (by groups of neighbours,
/// and by groups of pixels apart: `rows::first_pass_then_bands`) and the pixels a stand-in
/// answered.
fn groups_until(
    r: &Renderer,
    tracer: &Tracer,
    frame: u32,
    groups: &[rows::Group],
    deadline: Option<Instant>,
    image: &[[AtomicU32; 3]],
) -> (usize, [u64; 2], Vec<u32>) {
    const CHUNK: usize = 8;
    let w = r.settings.camera.width;
    let next = std::sync::atomic::AtomicUsize::new(0);
    let per_thread = rayon::broadcast(|_| {
        let (mut caster, mut rays, mut approx) = (tracer, [0u64; 2], Vec::new());
        while deadline.is_none_or(|d| Instant::now() < d) {
            let start = next.fetch_add(CHUNK, Ordering::Relaxed);
            if start >= groups.len() {
                break;
            }
            for &g in &groups[start..(start + CHUNK).min(groups.len())] {
                let out = r.group(g, frame, &mut caster).expect("a plain in-core Tracer never suspends");
                put_group(image, g, w, &out);
                rays[(g.step != 1) as usize] += out.rays as u64;
                approx.extend((0..g.len as usize).filter(|k| out.approx & (1 << k) != 0).map(|k| g.index(k, w) as u32));
            }
        }
        (rays, approx)
    });
    let done = next.load(Ordering::Relaxed).min(groups.len());
    let rays = per_thread.iter().fold([0; 2], |a, (r, _)| [a[0] + r[0], a[1] + r[1]]);
    (done, rays, per_thread.into_iter().flat_map(|(_, a)| a).collect())
}

/// The frame loop when nothing can suspend (an unpaged tracer, no deadline): 32x32 tiles as
/// rayon tasks, each pixel straight through the tracer, with no job bookkeeping, which costs
/// most on frames of cheap pixels (docs/PERF.md, "In-core frame loop").
fn render_in_core(r: &Renderer, tracer: &Tracer, frame: u32) -> Frame {
    let (w, h) = (r.settings.camera.width, r.settings.camera.height);
    let aovs = r.settings.aovs;
    if !aovs {
        // Bands of rows, each written in place: within a band, 32-pixel columns a row's
        // group at a time (`rows`). No per-tile buffers, no copies. Bands go in order to
        // whichever thread is free (`par_bridge`), so the threads trace neighbouring bands,
        // whose scene data the caches then share (rayon's split by halves gave each thread
        // a far part of the image: docs/PERF.md, "Neighbouring bands").
        // Every pixel written below.
        let mut f = r.blank_frame(w, h, false, false);
        let band = (BAND_ROWS * w) as usize;
        f.rays = f
            .image
            .pixels
            .chunks_mut(band)
            .enumerate()
            .par_bridge()
            .map(|(b, px)| {
                let mut caster = tracer;
                let y0 = b as u32 * BAND_ROWS;
                let rows = px.len() as u32 / w;
                let mut rays = 0u64;
                for x0 in (0..w).step_by(TILE as usize) {
                    let x1 = (x0 + TILE).min(w);
                    for y in y0..y0 + rows {
                        for gx in (x0..x1).step_by(rows::GROUP) {
                            let g = rows::Group { y, x0: gx, step: 1, len: (x1 - gx).min(rows::GROUP as u32) };
                            let out = r.group(g, frame, &mut caster).expect("a plain in-core Tracer never suspends");
                            let at = ((y - y0) * w + gx) as usize;
                            px[at..at + g.len as usize].copy_from_slice(&out.rgb[..g.len as usize]);
                            rays += out.rays as u64;
                        }
                    }
                }
                rays
            })
            .sum();
        f.jobs.finished = (w * h) as u64;
        f.jobs.rays = f.rays;
        return f;
    }
    let tiles_x = w.div_ceil(TILE);
    let tiles: Vec<(u32, u32)> = (0..h.div_ceil(TILE)).flat_map(|ty| (0..tiles_x).map(move |tx| (tx, ty))).collect();
    // Per tile: its pixels in row order (and AOVs only when asked: the buffers are rebuilt
    // every frame, so they are kept small). Tiles go in order to whichever thread is free,
    // as bands do above; the results are put back in order after.
    let mut results: Vec<(usize, TileOut)> = tiles
        .iter()
        .enumerate()
        .par_bridge()
        .map(|(i, &(tx, ty))| {
            let mut caster = tracer;
            let mut out = TileOut::default();
            for y in ty * TILE..((ty + 1) * TILE).min(h) {
                for x in tx * TILE..((tx + 1) * TILE).min(w) {
                    let s = r.pixel(x, y, frame, &mut caster).expect("a plain in-core Tracer never suspends");
                    out.color.push(s.radiance.to_array());
                    out.rays += s.rays as u64;
                    if aovs {
                        out.depth.push(s.depth);
                        out.normal.push(s.normal.to_array());
                        out.albedo.push(s.albedo.to_array());
                    }
                }
            }
            (i, out)
        })
        .collect();
    results.sort_unstable_by_key(|&(i, _)| i);
    let n = (w * h) as usize;
    // Every pixel written below.
    let mut f = r.blank_frame(w, h, aovs, false);
    for ((tx, ty), (_, t)) in tiles.iter().zip(results) {
        f.rays += t.rays;
        let (x0, x1) = (tx * TILE, ((tx + 1) * TILE).min(w));
        let tw = (x1 - x0) as usize;
        for (row, y) in (ty * TILE..((ty + 1) * TILE).min(h)).enumerate() {
            let dst = (y * w + x0) as usize..(y * w + x1) as usize;
            let src = row * tw..(row + 1) * tw;
            f.image.pixels[dst.clone()].copy_from_slice(&t.color[src.clone()]);
            if aovs {
                f.depth[dst.clone()].copy_from_slice(&t.depth[src.clone()]);
                f.normal[dst.clone()].copy_from_slice(&t.normal[src.clone()]);
                f.albedo[dst].copy_from_slice(&t.albedo[src]);
            }
        }
    }
    f.jobs.finished = n as u64;
    f.jobs.rays = f.rays;
    f
}

/// Rows of a task of [`render_in_core`] without AOVs: bands this tall, the whole width.
const BAND_ROWS: u32 = 8;

/// The pixels of one tile, row by row.
#[derive(Default)]
struct TileOut {
    color: Vec<[f32; 3]>,
    depth: Vec<f32>,
    normal: Vec<[f32; 3]>,
    albedo: Vec<[f32; 3]>,
    rays: u64,
}
