//! The view core ([`ViewCore`]): a camera that keys, drags and the wheel move, and a frame
//! loop that keeps up with them. While the camera moves, each frame is rendered at the
//! resolution that fits the frame budget (adapted from frame to frame) and ends on time
//! (rays whose tiles are not resident are answered by resident levels of detail); when it
//! stops, frames accumulate at full resolution, progressively, and converge to the picture
//! `megaray render` makes of the same pose. The display is an RGB8 image at the view's size,
//! with the statistics line and the help drawn over it.

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use megaray_base::{Aabb, Vec3};
use megaray_render::{
    render_frame_with, Accumulator, Builtin, Environment, Frame, FrameOptions, Image, ImageError, LodGovernor,
    RenderSettings, Renderer, Section, ToneMap, Visibility,
};
use megaray_trace::Tracer;

use crate::camera::{FlyCamera, Pose};
use crate::input::{help_lines, Event, Key};
use crate::overlay::draw_lines;
use crate::pick::{pick, Picked};
use crate::viewpoint::Viewpoint;

/// How a view renders.
#[derive(Clone)]
pub struct ViewOptions {
    /// The view's size in pixels (the window's, the page's canvas).
    pub width: u32,
    pub height: u32,
    /// Vertical field of view, degrees.
    pub fov: f32,
    /// The shader the view starts with (C cycles through the built-ins).
    pub shader: Builtin,
    /// Shadow rays per hit toward the environment's lights.
    pub light_samples: u32,
    /// The sky: an environment light that K turns on and off, and whether it starts on.
    pub sky: Option<Arc<Environment>>,
    pub sky_on: bool,
    /// The scene's area lights (a pbrt scene's): every shader shows them, `path` is lit by
    /// them, and with the sky off the background is black rather than the constant sky.
    pub area: Option<Arc<megaray_render::AreaLights>>,
    /// The time from input to the frame that shows it. While the camera moves, frames render
    /// at the resolution that takes half of it, and end at it; still frames end at half of it
    /// (a key pressed waits for one to end). Pixels a frame's end leaves are filled from
    /// neighbours; rays whose tiles are missing are answered from levels of detail. `None`:
    /// every frame at full resolution, exact (scripts and tests, whose frames must not depend
    /// on the machine).
    pub frame_budget: Option<Duration>,
    /// Frames accumulated at most while the camera stands still (then the view idles).
    pub max_frames: u32,
    /// Show still frames through the denoiser ([`megaray_render::denoise`]; still frames
    /// then carry the albedo, normal and depth it needs). [`ViewCore::image`] stays the plain
    /// accumulated picture.
    pub denoise: bool,
    /// Where the view starts (and R returns): the scene's own camera, if its source gave
    /// one; `None`: the default framing of `megaray render`.
    pub home: Option<Pose>,
    /// What is shown at the start (`--hide`, `--isolate`, `--xray`, `--section`); keys
    /// change it from there.
    pub visibility: Option<Arc<Visibility>>,
    /// A saved view to start from (`--view`), over `home` and `visibility`.
    pub start: Option<Viewpoint>,
}

/// Whether the still frame that brings the accumulation to `frames` frames is shown denoised:
/// the first 2 and every 16th after (the denoiser's cost kept off most frames; three passes).
fn denoises_after(frames: u32) -> bool {
    frames <= 2 || frames.is_multiple_of(16)
}

impl ViewOptions {
    /// A view of `width` x `height` with the defaults of `megaray render` (shader `auto`, 2
    /// light samples, 60 degrees) and a budget of 100 ms a frame.
    pub fn new(width: u32, height: u32) -> ViewOptions {
        ViewOptions {
            width,
            height,
            fov: 60.0,
            shader: Builtin::Auto,
            light_samples: 2,
            sky: None,
            sky_on: false,
            area: None,
            frame_budget: Some(Duration::from_millis(100)),
            max_frames: 1024,
            denoise: true,
            home: None,
            visibility: None,
            start: None,
        }
    }
}

/// What the last frames did, for the statistics line and `--json`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewStats {
    /// Frames a second and millions of rays a second (smoothed over the last frames).
    pub fps: f64,
    pub mrays_s: f64,
    /// Rays the last frame traced.
    pub rays: u64,
    /// The last frame's time, seconds.
    pub frame_secs: f64,
    /// The resolution the last frame was rendered at (lower than the view's while moving).
    pub width: u32,
    pub height: u32,
    /// Frames accumulated at full resolution since the camera last moved.
    pub frames: u32,
    /// Scene bytes resident and the budget (0 without a pager).
    pub resident: u64,
    pub budget: u64,
    /// Tiles asked for and not arrived yet.
    pub in_flight: u64,
    /// The level-of-detail error in force, pixels.
    pub lod_error: f32,
    /// Pixels of the last frame answered by stand-ins or filled from neighbours.
    pub approx: u64,
    /// Whether the camera moved for the last frame.
    pub moving: bool,
}

/// What to do with a component ([`ViewCore::set_part`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PartOp {
    Hide,
    Show,
    XRay,
    /// Not X-rayed.
    Solid,
    /// Show only it, or, when it is so already, everything.
    Isolate,
}

/// Where a view's frames come from instead of its own pool: a function of the renderer (the
/// frame's camera, shader, AOVs) and the frame index, such as a cluster of processes
/// (`megaray-cluster`). Its frames are whole and exact (no frame budget); an error ends the
/// view ([`ViewCore::error`]).
pub type FrameSource<'t> = Box<dyn FnMut(&Renderer, u32) -> Result<Frame, String> + 't>;

/// An interactive view of a scene (see the module documentation).
pub struct ViewCore<'t, 's> {
    tracer: &'t Tracer<'s>,
    pool: &'t rayon::ThreadPool,
    bounds: Aabb,
    opts: ViewOptions,
    cam: FlyCamera,
    home: FlyCamera,
    held: Vec<Key>,
    /// The camera moved (a drag, the wheel's speed does not count) since the last frame.
    moved: bool,
    shader: Builtin,
    sky_on: bool,
    renderer: Renderer,
    acc: Accumulator,
    /// The last frame rendered while moving at a reduced size.
    preview: Option<Image>,
    /// The last frame rendered while moving at the view's size (sample 0): shown as it is,
    /// and the accumulator's first frame if the camera then stays still. Moving frames never
    /// go through the accumulator (its sums are 84 bytes a pixel, read and written).
    pending: Option<Frame>,
    /// The last denoised picture and the frames it was made of (the denoiser runs on the
    /// first 4 still frames and every 8th after, to keep its cost off most frames).
    denoised: Option<(u32, Image)>,
    /// How long the denoiser takes (its last time, or most of its longest recent one).
    denoise_time: Duration,
    /// The fraction of the view's width and height rendered while moving.
    scale: f32,
    governor: LodGovernor,
    display: Vec<u8>,
    stats: ViewStats,
    help: bool,
    info: bool,
    quit: bool,
    screenshots: u32,
    source: Option<FrameSource<'t>>,
    error: Option<String>,
    /// The last pick (a click), highlighted; and the distance measured to the one before.
    picked: Option<Picked>,
    measured: Option<f64>,
    /// The component shown highlighted (the last pick's, or a viewpoint's).
    highlight: Option<u32>,
    /// Hidden and X-rayed components and sections, as options and keys left them.
    vis: Visibility,
}

impl<'t, 's> ViewCore<'t, 's> {
    /// A view of `tracer`'s scene from the default camera (as `megaray render` frames it),
    /// rendering on `pool`.
    pub fn new(tracer: &'t Tracer<'s>, pool: &'t rayon::ThreadPool, opts: ViewOptions) -> ViewCore<'t, 's> {
        let bounds = tracer.scene().header().bounds;
        let home = match opts.home {
            Some(p) => FlyCamera::at(p, &bounds, opts.fov),
            None => FlyCamera::home(&bounds, opts.fov),
        };
        let (w, h) = (opts.width.max(1), opts.height.max(1));
        let mut v = ViewCore {
            tracer,
            pool,
            bounds,
            cam: home,
            home,
            held: Vec::new(),
            moved: true,
            shader: opts.shader,
            sky_on: opts.sky_on && opts.sky.is_some(),
            renderer: Renderer::new(RenderSettings::new(home.pose.camera(opts.fov, w, h)), &bounds),
            acc: Accumulator::new(w, h),
            preview: None,
            pending: None,
            denoised: None,
            denoise_time: Duration::ZERO,
            scale: 0.5,
            governor: LodGovernor::new(tracer),
            display: vec![0; (3 * w * h) as usize],
            stats: ViewStats::default(),
            help: false,
            info: true,
            quit: false,
            screenshots: 0,
            source: None,
            error: None,
            picked: None,
            measured: None,
            highlight: None,
            vis: opts.visibility.as_deref().cloned().unwrap_or_default(),
            opts: ViewOptions { width: w, height: h, ..opts },
        };
        v.rebuild_renderer();
        if let Some(vp) = v.opts.start.clone() {
            v.set_viewpoint(&vp);
        }
        v
    }

    /// Frames from `source` from now on (see [`FrameSource`]): whole, exact, at full
    /// resolution, as with no frame budget.
    pub fn with_frame_source(mut self, source: FrameSource<'t>) -> ViewCore<'t, 's> {
        self.opts.frame_budget = None;
        self.source = Some(source);
        self.rebuild_renderer();
        self
    }

    /// Why the frame source failed, if it did (the view then asks to quit).
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    /// The renderer for the current shader, sky and size.
    fn rebuild_renderer(&mut self) {
        let (w, h) = (self.opts.width, self.opts.height);
        let mut s = RenderSettings::new(self.cam.pose.camera(self.opts.fov, w, h));
        s.shader = self.shader;
        s.light_samples = self.opts.light_samples;
        s.stand_in = self.opts.frame_budget.is_some();
        s.highlight = self.highlight;
        s.visibility = (!self.vis.is_empty()).then(|| Arc::new(self.vis.clone()));
        if self.opts.area.is_some() {
            s.sky = [0.0; 3];
        }
        let mut r = Renderer::new(s, &self.bounds);
        if let Some(area) = &self.opts.area {
            r = r.with_area_lights(area.clone());
        }
        self.renderer = match (&self.opts.sky, self.sky_on) {
            (Some(env), true) => r.with_environment(env.clone()),
            _ => r,
        };
        self.acc = Accumulator::new(w, h);
        self.pending = None;
        self.moved = true;
    }

    /// Takes one input event.
    pub fn handle(&mut self, ev: Event) {
        match ev {
            Event::Key(k, true) if k.is_action() => self.act(k),
            Event::Key(k, true) => {
                if !self.held.contains(&k) {
                    self.held.push(k);
                }
            }
            Event::Key(k, false) => self.held.retain(|&x| x != k),
            Event::Drag(dx, dy) => {
                if dx != 0.0 || dy != 0.0 {
                    self.cam.look(dx, dy);
                    self.moved = true;
                }
            }
            Event::Wheel(n) => self.cam.wheel(n),
            Event::Resize(w, h) => {
                let (w, h) = (w.clamp(1, 16384), h.clamp(1, 16384));
                if (w, h) != (self.opts.width, self.opts.height) {
                    (self.opts.width, self.opts.height) = (w, h);
                    self.display = vec![0; (3 * w * h) as usize];
                    self.preview = None;
                    self.rebuild_renderer();
                }
            }
            Event::Click(x, y, measure) => self.click(x, y, measure),
        }
    }

    /// Picks under (x, y) of the view (exactly, through the full-detail index): the picked
    /// component is highlighted; with `measure`, the distance from the last pick is kept.
    fn click(&mut self, x: f32, y: f32, measure: bool) {
        let (w, h) = (self.opts.width, self.opts.height);
        let ray = self.cam.pose.camera(self.opts.fov, w, h).ray(x, y);
        let found = pick(self.tracer, &ray);
        self.measured = match (measure, &self.picked, &found) {
            (true, Some(a), Some(b)) => Some(a.distance_to(b)),
            _ => None,
        };
        self.picked = found;
        let highlight = self.picked.as_ref().and_then(|p| p.component);
        if highlight != self.highlight {
            self.highlight = highlight;
            self.rebuild_renderer();
        }
        self.compose();
    }

    /// Acts on the visibility for key `k` (X, V, B on the picked component, N a section
    /// through the pick, U all shown); whether anything changed.
    fn inspect(&mut self, k: Key) -> bool {
        let n = self.tracer.scene().components().names.len();
        let v = &mut self.vis;
        if k == Key::ShowAll {
            let changed = !v.is_empty();
            *v = Visibility::default();
            return changed;
        }
        if let (Key::CutMore | Key::CutLess, Some(s)) = (k, v.sections.last_mut()) {
            // A step of 1/100 of the model's diagonal (the kept side is where n·p <= offset).
            let step = 0.01 * self.bounds.diagonal();
            s.offset += if k == Key::CutMore { -step } else { step };
            return true;
        }
        let Some(p) = &self.picked else { return false };
        if k == Key::Section {
            // Facing the eye (the eye's side cut away), through the middle of the wall the
            // pick entered (the picked point itself when it left one).
            let n = Vec3::from(p.normal);
            let depth = if p.front { p.behind.unwrap_or(0.0) as f32 * 0.5 } else { 0.0 };
            v.sections.push(Section::new(Vec3::from(p.position.map(|x| x as f32)) - n * depth, n));
            return true;
        }
        let Some(c) = p.component.filter(|&c| (c as usize) < n) else { return false };
        let op = match k {
            Key::XRay if v.xray.get(c as usize).copied().unwrap_or(false) => PartOp::Solid,
            Key::XRay => PartOp::XRay,
            Key::Hide => PartOp::Hide,
            _ => PartOp::Isolate,
        };
        self.part_op(c, op)
    }

    /// Changes how component `c` is shown (the viewer's keys on a pick; the page's part
    /// list); whether anything changed. The renderer follows.
    pub fn set_part(&mut self, c: u32, op: PartOp) {
        if self.part_op(c, op) {
            self.rebuild_renderer();
            self.compose();
        }
    }

    fn part_op(&mut self, c: u32, op: PartOp) -> bool {
        let n = self.tracer.scene().components().names.len();
        let c = c as usize;
        if c >= n {
            return false;
        }
        let v = &mut self.vis;
        for flags in [&mut v.hidden, &mut v.xray] {
            flags.resize(n, false);
        }
        let before = (v.hidden.clone(), v.xray.clone());
        match op {
            PartOp::Hide => v.hidden[c] = true,
            PartOp::Show => v.hidden[c] = false,
            PartOp::XRay => v.xray[c] = true,
            PartOp::Solid => v.xray[c] = false,
            PartOp::Isolate => {
                // Isolated already (everything else hidden): show all again.
                let isolated = (0..n).all(|i| v.hidden[i] == (i != c));
                for (i, h) in v.hidden.iter_mut().enumerate() {
                    *h = !isolated && i != c;
                }
            }
        }
        (v.hidden.clone(), v.xray.clone()) != before
    }

    /// The view as it stands now, to save ([`Viewpoint`]).
    pub fn viewpoint(&self) -> Viewpoint {
        Viewpoint {
            pose: self.cam.pose,
            fov: self.opts.fov,
            shader: self.shader,
            sky: self.sky_on,
            shown: self.vis.clone(),
            highlight: self.highlight,
        }
    }

    /// Goes to a saved view (its sky only if the view has one to light with).
    pub fn set_viewpoint(&mut self, vp: &Viewpoint) {
        self.cam.pose = vp.pose;
        self.opts.fov = vp.fov;
        self.shader = vp.shader;
        self.sky_on = vp.sky && self.opts.sky.is_some();
        self.vis = vp.shown.clone();
        self.highlight = vp.highlight;
        self.picked = None;
        self.measured = None;
        self.rebuild_renderer();
        self.compose();
    }

    /// What is shown now (hidden, X-rayed, sections).
    pub fn visibility(&self) -> &Visibility {
        &self.vis
    }

    /// The last pick, if the last click hit something.
    pub fn picked(&self) -> Option<&Picked> {
        self.picked.as_ref()
    }

    /// The distance between the last two picks, after a measuring click.
    pub fn measured(&self) -> Option<f64> {
        self.measured
    }

    /// The lines a viewer shows of the picks: the last one, and the measured distance.
    pub fn pick_lines(&self) -> Vec<String> {
        let mut v: Vec<String> = self.picked.iter().map(Picked::line).collect();
        if let Some(d) = self.measured {
            v.push(format!("measured {d:.4} from the previous pick (scene units)"));
        }
        v
    }

    fn act(&mut self, k: Key) {
        match k {
            Key::Reset => {
                self.cam = FlyCamera { speed: self.cam.speed, ..self.home };
                self.moved = true;
            }
            Key::Frame => {
                self.cam.frame(&self.bounds);
                self.moved = true;
            }
            Key::NextShader => {
                let i = Builtin::ALL.iter().position(|b| b.1 == self.shader).unwrap_or(0);
                self.shader = Builtin::ALL[(i + 1) % Builtin::ALL.len()].1;
                self.rebuild_renderer();
            }
            Key::ToggleSky if self.opts.sky.is_some() => {
                self.sky_on = !self.sky_on;
                self.rebuild_renderer();
            }
            // (`inspect` changes what is shown; the renderer follows when it did.)
            Key::XRay | Key::Hide | Key::Isolate | Key::Section | Key::CutMore | Key::CutLess | Key::ShowAll
                if self.inspect(k) =>
            {
                self.rebuild_renderer()
            }
            Key::Help => self.help = !self.help,
            Key::Info => self.info = !self.info,
            Key::Quit => self.quit = true,
            // Screenshots are the front end's to write ([`ViewCore::save_screenshot`]).
            _ => {}
        }
        self.compose();
    }

    /// Whether Escape was pressed.
    pub fn quit_requested(&self) -> bool {
        self.quit
    }

    /// The camera's pose now.
    pub fn pose(&self) -> Pose {
        self.cam.pose
    }

    /// The camera (pose, speed, field of view).
    pub fn camera(&self) -> FlyCamera {
        self.cam
    }

    /// Puts the camera at `cam` (a saved view).
    pub fn set_camera(&mut self, cam: FlyCamera) {
        self.cam = cam;
        self.moved = true;
    }

    /// The shader in use.
    pub fn shader(&self) -> Builtin {
        self.shader
    }

    /// What the last frames did.
    pub fn stats(&self) -> &ViewStats {
        &self.stats
    }

    /// Advances `dt` seconds: the camera flies by the keys held, then a frame is rendered: at
    /// a reduced resolution if the camera moved, else accumulated at full resolution (none
    /// once [`ViewOptions::max_frames`] are). Returns whether a frame was rendered.
    pub fn step(&mut self, dt: f32) -> bool {
        if self.cam.fly(&self.held, dt) {
            self.moved = true;
        }
        let moving = std::mem::replace(&mut self.moved, false);
        if moving {
            if let Some(f) = self.pending.take() {
                self.renderer.recycle(f);
            }
            self.acc.reset();
        } else {
            if let Some(f) = self.pending.take() {
                // The camera stayed: the last moving frame is the first still one.
                self.acc.add_frame(&f);
                self.renderer.recycle(f);
            }
            if self.acc.frames() >= self.opts.max_frames {
                return false;
            }
        }
        let (w, h) = (self.opts.width, self.opts.height);
        // While moving (and only with a budget): a reduced resolution.
        let (rw, rh) = match (moving, self.opts.frame_budget) {
            (true, Some(_)) => {
                (((w as f32 * self.scale) as u32).max(8).min(w), ((h as f32 * self.scale) as u32).max(8).min(h))
            }
            _ => (w, h),
        };
        self.renderer.settings.camera = self.cam.pose.camera(self.opts.fov, rw, rh);
        self.renderer.settings.aovs = self.opts.denoise && !moving;
        let t0 = Instant::now();
        let opts = FrameOptions {
            // Still frames take half the budget: a key pressed while one renders waits for
            // it, and then for the first moving frame (input to frame within the budget).
            // A still frame that will be denoised leaves the denoiser its time (as last
            // measured) within that half.
            deadline: self.opts.frame_budget.map(|b| {
                let denoise = if !moving && self.opts.denoise && denoises_after(self.acc.frames() + 1) {
                    self.denoise_time
                } else {
                    Duration::ZERO
                };
                t0 + if moving { b } else { (b / 2).saturating_sub(denoise).max(b / 8) }
            }),
            stand_in: self.opts.frame_budget.is_some(),
        };
        let index = if moving { 0 } else { self.acc.frames() };
        let frame = match &mut self.source {
            Some(source) => match source(&self.renderer, index) {
                Ok(f) => f,
                Err(e) => {
                    (self.error, self.quit) = (Some(e), true);
                    return false;
                }
            },
            None => self.pool.install(|| render_frame_with(&self.renderer, self.tracer, index, &opts)),
        };
        let secs = t0.elapsed().as_secs_f64().max(1e-6);
        self.governor.after_frame(self.tracer);
        let (rays, approx) = (frame.rays, frame.approx.iter().filter(|&&a| a).count() as u64);
        self.preview = None;
        if (rw, rh) != (w, h) {
            self.preview = Some(frame.image);
        } else if moving {
            self.pending = Some(frame);
        } else {
            self.acc.add_frame(&frame);
            self.renderer.recycle(frame);
        }
        if moving {
            if let Some(b) = self.opts.frame_budget {
                // The resolution whose frame takes about half the budget (a frame's cost
                // goes with its pixels), changed by at most a factor of 1.5 a frame.
                let want = (0.5 * b.as_secs_f64() / secs).sqrt() as f32;
                self.scale = (self.scale * want.clamp(0.67, 1.5)).clamp(0.15, 1.0);
            }
        }
        let p = self.tracer.pager().map(|p| p.stats());
        let smooth = |old: f64, new: f64| if old == 0.0 { new } else { 0.7 * old + 0.3 * new };
        self.stats = ViewStats {
            fps: smooth(self.stats.fps, 1.0 / secs),
            mrays_s: smooth(self.stats.mrays_s, rays as f64 / secs * 1e-6),
            rays,
            frame_secs: secs,
            width: rw,
            height: rh,
            frames: self.acc.frames() + self.pending.is_some() as u32,
            resident: p.map_or(0, |s| s.resident + s.pinned),
            budget: p.map_or(0, |s| s.tile_budget + s.pinned),
            in_flight: p.map_or(0, |s| s.requested.saturating_sub(s.loaded + s.corrupt)),
            lod_error: self.tracer.lod_error(),
            approx,
            moving,
        };
        self.compose();
        true
    }

    /// The picture shown now, before overlays: the accumulated frames, or the last preview
    /// scaled to the view's size.
    pub fn image(&self) -> Image {
        match (&self.preview, &self.pending) {
            (Some(p), _) => upscale(p, self.opts.width, self.opts.height),
            (None, Some(f)) => f.image.clone(),
            (None, None) => self.acc.image(),
        }
    }

    /// Makes the display: the picture tone mapped, the statistics line and the help over it.
    fn compose(&mut self) {
        let frames = self.acc.frames();
        let shown = match (&self.preview, &self.pending, self.opts.denoise) {
            (None, Some(f), _) => {
                self.denoised = None;
                self.display = f.image.to_srgb8_with(&ToneMap::default());
                return self.overlay();
            }
            (None, None, true) => {
                let stale = self.denoised.as_ref().is_none_or(|(n, _)| *n > frames || frames - n >= 16);
                if (frames <= 4 || frames.is_multiple_of(8) || stale)
                    && self.denoised.as_ref().is_none_or(|(n, _)| *n != frames)
                {
                    self.denoised = self.acc.denoised_with(3).map(|img| (frames, img));
                }
                match &self.denoised {
                    Some((_, img)) => img.clone(),
                    None => self.acc.image(),
                }
            }
            _ => {
                self.denoised = None;
                self.image()
            }
        };
        self.display = shown.to_srgb8_with(&ToneMap::default());
        self.overlay();
    }

    /// Draws the statistics line, the picked point and the help over the display.
    fn overlay(&mut self) {
        let (w, h) = (self.opts.width, self.opts.height);
        let mut lines = Vec::new();
        if self.info {
            lines.push(self.stats_line());
        }
        lines.extend(self.pick_lines());
        if self.help {
            lines.extend(help_lines());
        }
        let scale = if w >= 1600 { 2 } else { 1 };
        draw_lines(&mut self.display, w, h, &lines, scale);
    }

    /// The statistics line.
    pub fn stats_line(&self) -> String {
        let s = &self.stats;
        let mut line = format!(
            "{:.1} fps  {:.1} Mrays/s  {}x{}  {} frames  {}",
            s.fps,
            s.mrays_s,
            s.width,
            s.height,
            s.frames,
            self.shader.name()
        );
        if s.budget > 0 {
            line += &format!(
                "  {} / {} MiB  {} tiles in flight  lod {:.1} px",
                s.resident >> 20,
                s.budget >> 20,
                s.in_flight,
                s.lod_error
            );
        }
        line + "  (H: help)"
    }

    /// The display: RGB8, the view's width x height, rows top first.
    pub fn display(&self) -> (u32, u32, &[u8]) {
        (self.opts.width, self.opts.height, &self.display)
    }

    /// Saves the picture (no overlays) as a PNG, tone mapped as `megaray render` does.
    pub fn save_screenshot(&mut self, path: &Path) -> Result<(), ImageError> {
        self.screenshots += 1;
        self.image().save_png_with(path, &ToneMap::default())?;
        // Its view beside it, for `megaray render --view` (written whole, then renamed).
        let json = path.with_extension("view.json");
        let tmp = path.with_extension("view.json.tmp");
        let text = self.viewpoint().to_json(self.tracer.scene().components());
        std::fs::write(&tmp, text + "\n")
            .and_then(|_| std::fs::rename(&tmp, &json))
            .map_err(|e| ImageError { path: json.clone(), msg: e.to_string() })
    }

    /// Screenshots saved so far (to number the next one).
    pub fn screenshots(&self) -> u32 {
        self.screenshots
    }
}

/// `img` scaled to `w` x `h` (nearest pixel).
fn upscale(img: &Image, w: u32, h: u32) -> Image {
    let mut out = Image::new(w, h);
    for y in 0..h {
        let sy = (y as u64 * img.height as u64 / h as u64) as u32;
        for x in 0..w {
            let sx = (x as u64 * img.width as u64 / w as u64) as u32;
            out.pixels[(y * w + x) as usize] = img.pixels[(sy * img.width + sx) as usize];
        }
    }
    out
}
