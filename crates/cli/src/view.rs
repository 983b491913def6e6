//! `megaray view`: a window over the view core (`megaray-view`), or, with `--script`, the same
//! core driven by a recorded script with its frames written to a folder. Thin: keys and mouse
//! become the core's events, its display goes to the window.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use megaray_render::{Builtin, EnvMap, Environment, SkySpec};
use megaray_trace::Tracer;
use megaray_view::{Event, FrameSource, Key, Script, Step, ViewCore, ViewOptions};
use serde_json::json;

use crate::progress::Bars;

/// The controls, as `megaray view --help` lists them (kept equal to the core's help text by a
/// test).
pub const CONTROLS: &str = "\
Controls:
  W / Up     fly forward
  S / Down   fly back
  A / Left   fly left
  D / Right  fly right
  E          fly up
  Q          fly down
  drag       look around
  wheel      flying speed
  click      pick: name, point, thickness (highlighted)
  shift+clk  measure from the last pick
  R          reset to the default view
  F          frame the whole model
  P          save a screenshot (PNG)
  C          next shader
  K          sky light on / off
  H          this help
  I          statistics line on / off
  X          X-ray the picked part on / off
  V          hide the picked part
  B          show only the picked part / all
  N          section through the picked wall (eye's side cut)
  ]          move the last section on (cut more)
  [          move the last section back (cut less)
  U          show everything (no hide, X-ray, section)
  Esc        quit";

/// What the viewers (`view`, `serve`) share: the scene, how it is lit and shaded, paging.
#[derive(Args, Clone, Debug)]
pub struct ViewerArgs {
    /// The scene file, or a model file or pbrt-v4 scene (PLY, OBJ, STL, glTF/GLB, .pbrt: built into a cached scene
    /// first). None: the demo's plant (generated and built the first time).
    pub scene: Option<PathBuf>,
    /// Starting shader: normal, diffuse, phong, mirror, glass, ao, env, auto (C cycles them).
    #[arg(long, default_value = "auto")]
    pub shader: String,
    /// An HDR environment map (.hdr, .exr) for the sky light (K turns it on and off; given, it
    /// starts on).
    #[arg(long, value_name = "FILE", conflicts_with = "sky")]
    pub env: Option<PathBuf>,
    /// A procedural sky for the sky light (see `megaray gen --help`); given, it starts on.
    #[arg(long, value_name = "SPEC")]
    pub sky: Option<String>,
    /// The error allowed to levels of detail, in pixels (see `megaray render --help`).
    #[arg(long, value_name = "PIXELS", default_value_t = 1.0)]
    pub lod_error: f32,
    /// Milliseconds from input to the frame that shows it: while the camera moves the view
    /// renders at the resolution that takes half of it; when it stops, frames of at most
    /// half of it accumulate at full resolution.
    #[arg(long, value_name = "MS", default_value_t = 100)]
    pub frame_budget: u64,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Writes a line of JSON for every frame shown: when (`t`, seconds since 1970), the pose,
    /// resolution, accumulated frames, seconds, Mrays/s, resident bytes, tiles in flight.
    #[arg(long, value_name = "FILE")]
    pub log: Option<PathBuf>,
    /// Show still frames as they accumulate, not denoised (by default an edge-avoiding filter
    /// guided by the first hits' albedo, normal and depth smooths them until they converge)
    #[arg(long)]
    pub no_denoise: bool,
    /// Under mpirun: a rank that holds tiles and sends nothing back for this long is lost
    /// (see `megaray render --help`). Frames across ranks are whole and exact (no frame
    /// budget).
    #[arg(long, value_name = "SECS", default_value_t = 60.0)]
    pub mpi_timeout: f64,
    #[command(flatten)]
    pub paging: crate::paging::PagingArgs,
    #[command(flatten)]
    pub open: crate::open::OpenArgs,
    #[command(flatten)]
    pub show: crate::show::ShowArgs,
    /// Start from a saved view (the `.view.json` written beside each screenshot).
    #[arg(long, value_name = "FILE")]
    pub view: Option<PathBuf>,
}

/// The demo's sky, what K lights the scene with when no --env or --sky is given.
pub(crate) const DEFAULT_SKY: &str = "sky:sun_elev=35,sun_azim=120,turbidity=3";

impl ViewerArgs {
    /// The view options for a `w` x `h` view: shader, sky, frame budget.
    pub fn options(&self, w: u32, h: u32) -> Result<ViewOptions> {
        let shader: Builtin = self.shader.parse().map_err(|e: String| anyhow::anyhow!("--shader: {e}"))?;
        if !(self.lod_error >= 0.0 && self.lod_error.is_finite()) {
            bail!("--lod-error must be a number of pixels, 0 or more");
        }
        if !(1..=10_000).contains(&self.frame_budget) {
            bail!("--frame-budget must be 1..=10000 milliseconds");
        }
        let map = match (&self.env, &self.sky) {
            (Some(p), _) => EnvMap::load(p)?,
            (None, spec) => spec
                .as_deref()
                .unwrap_or(DEFAULT_SKY)
                .parse::<SkySpec>()
                .map_err(|e| anyhow::anyhow!("--sky: {e}"))?
                .map(),
        };
        Ok(ViewOptions {
            shader,
            sky: Some(Arc::new(Environment::new(map, Environment::DEFAULT_LIGHTS, Environment::DEFAULT_SUBSETS))),
            sky_on: self.env.is_some() || self.sky.is_some(),
            frame_budget: Some(Duration::from_millis(self.frame_budget)),
            denoise: !self.no_denoise,
            ..ViewOptions::new(w, h)
        })
    }
}

/// `megaray view`.
#[derive(Args)]
#[command(after_help = CONTROLS)]
pub struct ViewArgs {
    #[command(flatten)]
    pub viewer: ViewerArgs,
    /// The window's size (it can be resized).
    #[arg(long, value_name = "WxH", default_value = "960x720", value_parser = crate::cmd::parse_res)]
    pub res: (u32, u32),
    /// No window: replay this script of input (see below) and write every frame to --out.
    /// Script lines: `frames N`, `key NAME down|up` (NAME: forward, back, left, right, up,
    /// down, reset, frame, screenshot, nextshader, togglesky, help, info, xray, hide, isolate,
    /// section, cutmore, cutless, showall, quit), `drag DX DY`, `wheel N`, `resize W H`, `click X Y [measure]`;
    /// `#` starts a comment.
    #[arg(long, value_name = "FILE", requires = "out")]
    pub script: Option<PathBuf>,
    /// The folder for --script's frames (frame-00001.png, ...) and frames.jsonl (the pose
    /// and statistics of each).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// With --script: the frames keep to --frame-budget as in the window (by default a
    /// script's frames are exact, at full resolution, whatever the machine).
    #[arg(long)]
    pub budgeted: bool,
}

/// Maps a window key to the core's.
fn key_of(k: minifb::Key) -> Option<Key> {
    use minifb::Key as K;
    Some(match k {
        K::W | K::Up => Key::Forward,
        K::S | K::Down => Key::Back,
        K::A | K::Left => Key::Left,
        K::D | K::Right => Key::Right,
        K::E => Key::Up,
        K::Q => Key::Down,
        K::R => Key::Reset,
        K::F => Key::Frame,
        K::P => Key::Screenshot,
        K::C => Key::NextShader,
        K::K => Key::ToggleSky,
        K::H => Key::Help,
        K::I => Key::Info,
        K::X => Key::XRay,
        K::V => Key::Hide,
        K::B => Key::Isolate,
        K::N => Key::Section,
        K::RightBracket => Key::CutMore,
        K::LeftBracket => Key::CutLess,
        K::U => Key::ShowAll,
        K::Escape => Key::Quit,
        _ => return None,
    })
}

pub fn view(a: ViewArgs, bars: &Bars) -> Result<()> {
    let opened = crate::open::scene_for(a.viewer.scene.as_deref(), &a.viewer.open, bars)?;
    let (scene, pager) = a.viewer.paging.open(&opened.path)?;
    let tracer = Tracer::paged_or_new(&scene, pager.as_ref()).with_lod_error(a.viewer.lod_error);
    let pool = crate::cmd::pool(a.viewer.threads)?;
    let mut opts = a.viewer.options(a.res.0, a.res.1)?;
    scene_options(&mut opts, &a.viewer, &scene)?;
    let name = opened.path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    // Under mpirun rank 0 shows the view and the other ranks render its frames' tiles.
    let mut cluster = crate::cluster::session(&scene, pool.current_num_threads(), a.viewer.mpi_timeout)?;
    if let Some(c) = cluster.as_mut().filter(|c| !c.is_root()) {
        return crate::cluster::serve_view(c, &opts, &tracer, &pool);
    }
    let source = cluster.as_mut().map(|c| crate::cluster::frame_source(c, &tracer, &pool));
    let res = match &a.script {
        Some(script) => {
            if !a.budgeted {
                opts.frame_budget = None;
            }
            let out = a.out.as_deref().expect("clap requires --out with --script");
            replay(&tracer, &pool, opts, source, script, out, FrameLog::create(a.viewer.log.as_deref())?)
        }
        None => window(&tracer, &pool, opts, source, &name, FrameLog::create(a.viewer.log.as_deref())?),
    };
    if let Some(c) = cluster {
        crate::cluster::finish(c, "the view ended");
    }
    res
}

/// The window loop: input to the core, a step, the display to the window; P saves the picture
/// beside the working folder, Escape or closing the window ends it.
fn window<'t>(
    tracer: &'t Tracer,
    pool: &'t rayon::ThreadPool,
    opts: ViewOptions,
    source: Option<FrameSource<'t>>,
    name: &str,
    mut log: FrameLog,
) -> Result<()> {
    let (w, h) = (opts.width as usize, opts.height as usize);
    let title = format!("megaray - {name}");
    // A few tries: an X server that has just started, or is busy, can refuse a connection
    // for a moment (seen under Xvfb on a loaded machine: `XOpenDisplay failed`).
    let open = || minifb::Window::new(&title, w, h, minifb::WindowOptions { resize: true, ..Default::default() });
    let mut win = open()
        .or_else(|_| {
            std::thread::sleep(std::time::Duration::from_millis(500));
            open()
        })
        .or_else(|_| {
            std::thread::sleep(std::time::Duration::from_secs(2));
            open()
        })
        .map_err(|e| {
            anyhow::anyhow!("cannot open a window ({e:?}); is DISPLAY set? (megaray serve shows the view in a browser)")
        })?;
    // minifb sleeps in each update until 4 ms have passed since the last; the loop updates
    // twice a frame (input, then the picture), so that would cost each frame up to 4 ms. The
    // loop paces itself (it sleeps when there is nothing to render).
    win.set_target_fps(0);
    let mut view = with_source(ViewCore::new(tracer, pool, opts), source);
    let stem = name.trim_end_matches(".mray").to_string();
    let mut mouse = Mouse::default();
    let mut buf: Vec<u32> = Vec::new();
    let mut last = Instant::now();
    let mut shown = 0u64;
    eprintln!("{title}: H for help, Esc to quit");
    while win.is_open() && !view.quit_requested() {
        let (ww, wh) = win.get_size();
        if ww > 0 && wh > 0 && (ww as u32, wh as u32) != (view.display().0, view.display().1) {
            view.handle(Event::Resize(ww as u32, wh as u32));
        }
        // Input as late as it can be: the events that came while the last frame rendered.
        // (Each update of the window keeps the key changes of its own events only: input is
        // read after every one.)
        win.update();
        poll(&win, &mut view, &mut mouse, &stem);
        let dt = last.elapsed().as_secs_f32().min(0.25);
        last = Instant::now();
        let rendered = view.step(dt);
        if let Some(e) = crate::paging::fault(tracer) {
            return Err(e.into());
        }
        let (dw, dh, rgb) = view.display();
        buf.clear();
        buf.extend(rgb.chunks_exact(3).map(|p| (p[0] as u32) << 16 | (p[1] as u32) << 8 | p[2] as u32));
        win.update_with_buffer(&buf, dw as usize, dh as usize).context("cannot draw into the window")?;
        poll(&win, &mut view, &mut mouse, &stem);
        if rendered {
            shown += 1;
            log.write(&frame_line(&view, shown, None));
        } else {
            // Converged: nothing to render until something moves.
            std::thread::sleep(Duration::from_millis(15));
        }
    }
    match view.error() {
        Some(e) => bail!("{e}"),
        None => Ok(()),
    }
}

/// The window's input since its last update, to the core: keys that went down and up (a tap
/// between two updates too), a drag with the left button, the wheel. P saves a screenshot
/// `<stem>-NNN.png` in the working folder.
fn poll(win: &minifb::Window, view: &mut ViewCore, mouse: &mut Mouse, stem: &str) {
    for k in win.get_keys_pressed(minifb::KeyRepeat::No) {
        if let Some(key) = key_of(k) {
            view.handle(Event::Key(key, true));
            if key == Key::Screenshot {
                let path = PathBuf::from(format!("{stem}-{:03}.png", view.screenshots() + 1));
                match view.save_screenshot(&path) {
                    Ok(()) => eprintln!("saved {}", path.display()),
                    Err(e) => eprintln!("megaray: {e}"),
                }
            }
        }
    }
    for k in win.get_keys_released() {
        if let Some(key) = key_of(k) {
            view.handle(Event::Key(key, false));
        }
    }
    let pos = win.get_mouse_pos(minifb::MouseMode::Pass);
    if win.get_mouse_down(minifb::MouseButton::Left) {
        if let (Some((x0, y0)), Some((x, y))) = (mouse.last, pos) {
            view.handle(Event::Drag(x - x0, y - y0));
            mouse.travel += (x - x0).abs() + (y - y0).abs();
        }
        if mouse.last.is_none() {
            (mouse.start, mouse.travel) = (pos, 0.0);
        }
        mouse.last = pos;
    } else if mouse.last.take().is_some() {
        // A press and release that hardly moved is a click: pick there.
        if let (Some((x, y)), true) = (mouse.start, mouse.travel < 3.0) {
            let shift = win.is_key_down(minifb::Key::LeftShift) || win.is_key_down(minifb::Key::RightShift);
            view.handle(Event::Click(x, y, shift));
            if let Some(l) = view.pick_lines().first() {
                eprintln!("{l}");
            }
        }
    }
    if let Some((_, dy)) = win.get_scroll_wheel() {
        if dy != 0.0 {
            view.handle(Event::Wheel(dy.signum()));
        }
    }
}

/// The left button: where it went down, where it was last, how far it moved since.
#[derive(Default)]
struct Mouse {
    start: Option<(f32, f32)>,
    last: Option<(f32, f32)>,
    travel: f32,
}

/// One frame's line of `frames.jsonl` and `--log`: when it was shown (`t`, seconds since
/// 1970), the pose, the frame's statistics; `client` numbers a page of `serve`.
pub fn frame_line(view: &ViewCore, n: u64, client: Option<u64>) -> String {
    let (p, s) = (view.pose(), view.stats());
    let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64());
    let mut v = json!({
        "frame": n, "t": t, "eye": p.eye.to_array(), "yaw": p.yaw, "pitch": p.pitch,
        "width": s.width, "height": s.height, "accumulated": s.frames, "moving": s.moving,
        "seconds": s.frame_secs, "mrays_s": s.mrays_s, "rays": s.rays, "shader": view.shader().name(),
        "resident_bytes": s.resident, "budget": s.budget, "tiles_in_flight": s.in_flight,
        "lod_error": s.lod_error, "approx_pixels": s.approx,
    });
    if let Some(c) = client {
        v["client"] = c.into();
    }
    if let Some(pk) = view.picked() {
        v["picked"] = json!({
            "component": pk.name, "part": pk.part, "triangle": pk.triangle, "position": pk.position,
            "normal": pk.normal, "distance": pk.distance, "behind": pk.behind, "front": pk.front,
        });
    }
    if let Some(d) = view.measured() {
        v["measured"] = d.into();
    }
    let vis = view.visibility();
    if !vis.is_empty() {
        let count = |f: &[bool]| f.iter().filter(|&&x| x).count();
        v["hidden"] = count(&vis.hidden).into();
        v["xrayed"] = count(&vis.xray).into();
        v["sections"] = vis.sections.len().into();
    }
    v.to_string() + "\n"
}

/// A `--log` file: a line a frame shown, flushed as it goes.
pub struct FrameLog(Option<std::io::BufWriter<std::fs::File>>);

impl FrameLog {
    pub fn create(path: Option<&Path>) -> Result<FrameLog> {
        let Some(p) = path else { return Ok(FrameLog(None)) };
        let f = std::fs::File::create(p).with_context(|| format!("{}: cannot create the log", p.display()))?;
        Ok(FrameLog(Some(std::io::BufWriter::new(f))))
    }

    pub fn write(&mut self, line: &str) {
        use std::io::Write;
        if let Some(w) = &mut self.0 {
            // A full disk ends the log, not the view.
            if w.write_all(line.as_bytes()).and_then(|_| w.flush()).is_err() {
                eprintln!("megaray: cannot write the frame log; it stops here");
                self.0 = None;
            }
        }
    }
}

/// `--script`: the script's events and frames, each frame's picture written to `out` and its
/// pose and statistics to `out/frames.jsonl`; a screenshot key saves `out/screenshot-N.png`.
fn replay<'t>(
    tracer: &'t Tracer,
    pool: &'t rayon::ThreadPool,
    opts: ViewOptions,
    source: Option<FrameSource<'t>>,
    script: &Path,
    out: &Path,
    mut flog: FrameLog,
) -> Result<()> {
    let text = std::fs::read_to_string(script).with_context(|| format!("{}: cannot read", script.display()))?;
    let script = Script::parse(&text).map_err(|e| anyhow::anyhow!("{}: {e}", script.display()))?;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create the folder", out.display()))?;
    let mut view = with_source(ViewCore::new(tracer, pool, opts), source);
    let mut log = String::new();
    let mut n = 0u64;
    for step in &script.steps {
        match *step {
            Step::Input(ev) => {
                view.handle(ev);
                if ev == Event::Key(Key::Screenshot, true) {
                    let path = out.join(format!("screenshot-{}.png", view.screenshots() + 1));
                    view.save_screenshot(&path)?;
                }
            }
            Step::Frames(k) => {
                for _ in 0..k {
                    view.step(1.0 / 30.0);
                    if let Some(e) = crate::paging::fault(tracer) {
                        return Err(e.into());
                    }
                    n += 1;
                    view.image().save_png_with(&out.join(format!("frame-{n:05}.png")), &Default::default())?;
                    let line = frame_line(&view, n, None);
                    flog.write(&line);
                    log += &line;
                }
            }
        }
        if view.quit_requested() {
            break;
        }
    }
    if let Some(e) = view.error() {
        bail!("{e}");
    }
    let jsonl = out.join("frames.jsonl");
    std::fs::write(&jsonl, log).with_context(|| format!("{}: cannot write", jsonl.display()))?;
    eprintln!("{n} frames written to {}", out.display());
    Ok(())
}

/// `view` with its frames from `source`, if there is one.
pub(crate) fn with_source<'t, 's>(view: ViewCore<'t, 's>, source: Option<FrameSource<'t>>) -> ViewCore<'t, 's> {
    match source {
        Some(s) => view.with_frame_source(s),
        None => view,
    }
}

/// What of `opts` comes from the scene: its own camera, what `--hide` and the like show of
/// it, the `--view` to start from.
pub(crate) fn scene_options(opts: &mut ViewOptions, a: &ViewerArgs, scene: &megaray_scene::Scene) -> Result<()> {
    scene_home(opts, scene);
    opts.area = crate::open::scene_area_lights(scene)?;
    opts.visibility = a.show.visibility(scene.components())?;
    if let Some(p) = &a.view {
        if a.show.any() {
            bail!("{}: give --view or --hide/--isolate/--xray/--section, not both", p.display());
        }
        opts.start = Some(crate::show::read_viewpoint(p, scene.components())?);
    }
    Ok(())
}

/// Starts `opts`'s view at `scene`'s own camera (a pbrt or glTF scene's), with its field of
/// view, where the scene has one.
fn scene_home(opts: &mut ViewOptions, scene: &megaray_scene::Scene) {
    if let Some(c) = crate::open::scene_camera(scene, opts.width.max(1), opts.height.max(1)) {
        opts.home = Some(megaray_view::Pose::looking_at(c.eye, c.eye + c.fwd));
        opts.fov = (2.0 * c.tan_half.atan()).to_degrees();
    }
}

#[cfg(test)]
mod tests {
    /// `megaray view --help` lists exactly the core's controls.
    #[test]
    fn the_help_lists_the_cores_controls() {
        let want: Vec<String> = megaray_view::help_lines().iter().map(|l| format!("  {l}")).collect();
        let got: Vec<&str> = super::CONTROLS.lines().skip(1).collect();
        assert_eq!(got, want);
    }
}
