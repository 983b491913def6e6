//! The commands: argument structs (validated into library option structs) and their bodies.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use megaray_base::{format_size, parse_size, Progress, Vec3};
use megaray_build::{build_scene, BuildOptions, Quality};
use megaray_gen::GenSpec;
use megaray_render::{
    read_exr, render_progressive, render_progressive_with, write_env, Accumulator, Builtin, Camera, EnvMap,
    Environment, RenderSettings, Renderer, SkySpec, Stop, ToneCurve, ToneMap, DEFAULT_OFFSET,
};
use megaray_scene::Scene;
use megaray_trace::Tracer;

use crate::progress::Bars;

pub(crate) fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{s}` is not X,Y,Z (three numbers separated by commas)"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Vec3::new(x, y, z)),
        _ => Err(format!("`{s}` is not X,Y,Z (three finite numbers separated by commas)")),
    }
}

pub(crate) fn parse_res(s: &str) -> Result<(u32, u32), String> {
    let err = || format!("`{s}` is not a resolution like 1024x768");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(err)?;
    let (w, h): (u32, u32) = (w.trim().parse().map_err(|_| err())?, h.trim().parse().map_err(|_| err())?);
    if w == 0 || h == 0 || w > 32768 || h > 32768 {
        return Err(format!("`{s}`: width and height must be 1..=32768"));
    }
    Ok((w, h))
}

fn parse_mem(s: &str) -> Result<u64, String> {
    parse_size(s)
}

pub(crate) fn pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let n = threads.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1));
    if n == 0 {
        bail!("--threads must be at least 1");
    }
    rayon::ThreadPoolBuilder::new().num_threads(n).build().context("cannot start worker threads")
}

// ---------------------------------------------------------------------------------------
#[derive(Args)]
pub struct GenArgs {
    /// What to generate: grid:N, sphereflake:L[:S], plant:T, forest:T[:U[:S]] or sky:... (see `megaray gen --help`).
    spec: String,
    /// Output file: binary little-endian PLY for models, .hdr (or .exr) for sky.
    #[arg(short, long, value_name = "FILE")]
    out: PathBuf,
    /// Seed for plant:T and forest:T (the same seed gives the same model).
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

pub fn gen(a: GenArgs, bars: &dyn Progress) -> Result<()> {
    if a.spec.starts_with("sky") {
        let spec: SkySpec = a.spec.parse().map_err(|e: String| anyhow::anyhow!(e))?;
        let map = spec.map();
        write_env(&map, &a.out)?;
        eprintln!(
            "wrote {}: {}x{} sky, sun at elevation {} azimuth {}",
            a.out.display(),
            map.width,
            map.height,
            spec.sun_elev,
            spec.sun_azim
        );
        return Ok(());
    }
    if a.spec.starts_with("forest:") {
        let mut spec: megaray_gen::forest::ForestSpec = a.spec.parse()?;
        spec.seed = a.seed as u32;
        let f = megaray_gen::forest::write_forest(&spec, &a.out, bars)?;
        eprintln!(
            "wrote {} and {} tree files: {:.3e} triangles shown ({} unique, {} levels of groves)",
            a.out.display(),
            f.files.len() - 1,
            f.shown,
            f.unique,
            f.levels
        );
        return Ok(());
    }
    let spec: GenSpec = a.spec.parse()?;
    let spec = spec.with_seed(a.seed);
    let t = Instant::now();
    let (verts, tris) = megaray_gen::write_ply(&spec, &a.out, bars)?;
    bars.finish();
    eprintln!(
        "wrote {}: {} vertices, {} triangles in {:.1} s",
        a.out.display(),
        verts,
        tris,
        t.elapsed().as_secs_f64()
    );
    Ok(())
}

// ---------------------------------------------------------------------------------------
/// `megaray build --quality`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum QualityArg {
    High,
    Medium,
}

#[derive(Args)]
pub struct BuildArgs {
    /// Model files: .ply, .obj, .stl, .gltf, .glb (merged into one scene), or gen SPECs
    /// (e.g. plant:1G; see `megaray gen --help`): specs alone are streamed straight into the
    /// build, specs among files generated first into a temporary PLY beside the output; or one
    /// scene: a .pbrt file, or a .gltf/.glb alone (objects and instances kept). The build
    /// first checks that the file systems have room for it.
    #[arg(required = true, value_name = "INPUT")]
    inputs: Vec<PathBuf>,
    /// The scene file to write.
    #[arg(short, long, value_name = "SCENE.mray")]
    out: PathBuf,
    /// Memory budget of the build (e.g. 512M, 4G). Models larger than it are split on disk.
    #[arg(long, value_name = "SIZE", default_value = "2G", value_parser = parse_mem)]
    build_mem: u64,
    /// Target tile size (the unit of paging), e.g. 64K .. 1M.
    #[arg(long, value_name = "SIZE", default_value = "256K", value_parser = parse_mem)]
    tile_size: u64,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// How hard the builder looks for good splits: `high` (binned SAH on all three axes at
    /// every node: traces faster) or `medium` (about 25% faster to build, trees a few percent
    /// slower to trace).
    #[arg(long, value_enum, default_value = "high")]
    quality: QualityArg,
    /// Make no levels of detail (by default each part gets coarser stand-ins, made by vertex
    /// clustering, for `render --lod-error` to trace far geometry in and for rays to fall
    /// back on while tiles load; a few percent of the file).
    #[arg(long)]
    no_lod: bool,
    /// Where temporary files go (default: beside the output). They peak at about 36 bytes a
    /// triangle (72 where holes cannot be punched in files as they are read; more with
    /// attributes); the scene file takes about 20-25 (46-55 with --plain).
    #[arg(long, value_name = "DIR")]
    tmp: Option<PathBuf>,
    /// Store tiles as they are traced instead of compact (about twice the bytes; nothing to
    /// decode as they load). Both kinds of file render the same.
    #[arg(long)]
    plain: bool,
    /// Print the build summary as one JSON object.
    #[arg(long)]
    json: bool,
}

pub fn build(a: BuildArgs, bars: &dyn Progress) -> Result<()> {
    if !(4096..=(64 << 20)).contains(&a.tile_size) {
        bail!("--tile-size must be between 4K and 64M");
    }
    let opts = BuildOptions {
        build_mem: a.build_mem,
        threads: a.threads.unwrap_or(BuildOptions::default().threads).max(1),
        tile_target: a.tile_size as u32,
        quality: match a.quality {
            QualityArg::High => Quality::High,
            QualityArg::Medium => Quality::Medium,
        },
        lod: if a.no_lod { None } else { BuildOptions::default().lod },
        tmp_dir: a.tmp.clone(),
        compact: !a.plain,
        ..BuildOptions::default()
    };
    let cancel = opts.cancel.clone();
    let _ = ctrlc::set_handler(move || cancel.store(true, Ordering::Relaxed));
    let inputs = crate::inputs::BuildInputs::of(&a.inputs, &a.out, bars)?;
    let structured = crate::open::structured_scene(&a.inputs, bars)?;
    if structured.is_none() {
        megaray_build::check_space(inputs.estimate_tris(), &a.out, &opts)?;
    }
    let built = match structured {
        Some(p) => megaray_build::build_objects(megaray_build::pbrt_input(p), &a.out, &opts, bars),
        None if !inputs.streamed.is_empty() => {
            megaray_build::build_objects(inputs.streamed_scene(bars), &a.out, &opts, bars)
        }
        None => build_scene(&inputs.files, &a.out, &opts, bars),
    };
    let s = built.map_err(|e| {
        // Faults in temporary files name those; say which build they stopped.
        let named = e.to_string().contains(&*a.out.to_string_lossy());
        let e = anyhow::Error::from(e);
        if named {
            e
        } else {
            e.context(format!("building {}", a.out.display()))
        }
    })?;
    drop(inputs);
    bars.finish();
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "out": a.out, "inputs": s.inputs, "triangles": s.triangles,
                "degenerate_dropped": s.degenerate_dropped, "parts": s.parts, "tiles": s.tiles,
                "lod_parts": s.lod_parts, "lod_bytes": s.lod_bytes,
                "split_levels": s.split_levels, "split_passes": s.split_passes, "part_limit": s.part_limit, "file_bytes": s.file_bytes,
                "input_bytes": s.input_bytes, "temp_read": s.temp_read, "temp_written": s.temp_written, "temp_peak": s.temp_peak,
                "import_s": s.import_s, "split_s": s.split_s, "parts_s": s.parts_s, "total_s": s.total_s,
                "mtris_s": s.triangles as f64 / s.total_s / 1e6,
                "build_mem": a.build_mem, "peak_rss": megaray_base::peak_rss(),
                "quality": match a.quality { QualityArg::High => "high", QualityArg::Medium => "medium" },
            })
        );
    } else {
        eprintln!(
            "built {}: {} triangles ({} degenerate dropped), {} parts after {} split levels ({} passes over the stream), {} tiles, {} ({:.1} bytes/triangle)",
            a.out.display(),
            s.triangles,
            s.degenerate_dropped,
            s.parts,
            s.split_levels,
            s.split_passes,
            s.tiles,
            format_size(s.file_bytes),
            s.file_bytes as f64 / s.triangles as f64
        );
        if s.lod_parts > 0 {
            eprintln!(
                "levels of detail: {} parts, {} ({:.1}% of the file)",
                s.lod_parts,
                format_size(s.lod_bytes),
                100.0 * s.lod_bytes as f64 / s.file_bytes as f64
            );
        }
        eprintln!(
            "time {:.1} s (import {:.1}, split {:.1}, parts {:.1}), {:.2} M triangles/s; read {} input + {} temp, wrote {} temp + {} scene; temporary files peaked at {}",
            s.total_s,
            s.import_s,
            s.split_s,
            s.parts_s,
            s.triangles as f64 / s.total_s / 1e6,
            format_size(s.input_bytes),
            format_size(s.temp_read),
            format_size(s.temp_written),
            format_size(s.file_bytes),
            format_size(s.temp_peak)
        );
        if let Some(rss) = megaray_base::peak_rss() {
            eprintln!("peak memory {} (budget --build-mem {})", format_size(rss), format_size(a.build_mem));
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
#[derive(Args)]
pub struct RenderArgs {
    /// The scene file, or a model file or pbrt-v4 scene (PLY, OBJ, STL, glTF/GLB, .pbrt), built into a scene first
    /// (cached under ~/.cache/megaray/models, keyed by its content).
    scene: PathBuf,
    /// Output image: .png (tone-mapped sRGB) or .exr (linear float, with --aov layers).
    #[arg(short, long, value_name = "OUT.png|OUT.exr")]
    out: PathBuf,
    /// Image size.
    #[arg(long, value_name = "WxH", default_value = "1024x1024", value_parser = parse_res)]
    res: (u32, u32),
    /// Camera position (default: the benchmark `default` camera).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, conflicts_with = "cam_offset")]
    eye: Option<Vec3>,
    /// Point looked at (default: the centre of the scene's bounds).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3)]
    at: Option<Vec3>,
    /// World up direction.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, default_value = "0,1,0")]
    up: Vec3,
    /// Vertical field of view, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 60.0)]
    fov: f32,
    /// Camera at centre + offset * diagonal (default 0,0.3,1.6; the `close` camera is 0,0.3,0.6).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    cam_offset: Option<Vec3>,
    /// Direction toward the directional light (lights diffuse and phong when there is no
    /// --env/--sky) [default: the scene's sun if its source gave one, else 0.5,1,0.8].
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    light: Option<Vec3>,
    /// Primary samples per pixel per frame (the first frame's first sample is the pixel centre).
    #[arg(long, value_name = "N", default_value_t = 1)]
    spp: u32,
    /// Adaptive sampling over progressive frames: from the second frame on, pixels where the
    /// picture changes sharply between neighbours (thin parts against the sky, fine detail,
    /// shadow edges) take N samples a frame, the others --spp; chosen again after 2, 4, 8
    /// ... 64 frames (the choice only grows). 0: off.
    #[arg(long, value_name = "N", default_value_t = 0)]
    adaptive: u32,
    /// Shader: normal, diffuse, phong, mirror, glass, ao, env, path, auto (by material).
    #[arg(long, value_name = "NAME", default_value = "auto")]
    shader: String,
    /// Environment light: a lat-long Radiance .hdr or OpenEXR .exr map.
    #[arg(long, value_name = "FILE.hdr|FILE.exr", conflicts_with = "sky")]
    env: Option<PathBuf>,
    /// Environment light: a procedural sky made in memory, e.g. sky:sun_elev=35,sun_azim=120
    /// (keys as in `megaray gen --help`).
    #[arg(long, value_name = "SPEC")]
    sky: Option<String>,
    /// Turn the environment about the up (+Y) axis, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 0.0, allow_hyphen_values = true)]
    env_rotate: f32,
    /// Multiply the environment's radiance.
    #[arg(long, value_name = "X", default_value_t = 1.0)]
    env_scale: f32,
    /// Number of virtual directional lights the environment becomes.
    #[arg(long, value_name = "N", default_value_t = 1024)]
    env_lights: u32,
    /// Light subsets for interleaved sampling (neighbouring pixels use different subsets).
    #[arg(long, value_name = "M", default_value_t = 16)]
    light_subsets: u32,
    /// Shadow rays per hit toward the subset's lights (0: all lights of the subset); AO rays per hit.
    #[arg(long, value_name = "K", default_value_t = 2)]
    light_samples: u32,
    /// How a hit draws its K lights from its subset: `contribution` (in proportion to power
    /// times cosine there; lights below the horizon never) or `uniform` (the seed tutorial's
    /// interleaved sampling)
    #[arg(long, value_name = "HOW", default_value = "contribution")]
    light_select: String,
    /// Frames to accumulate (new sample positions each); default 1, or unlimited with --time.
    #[arg(long, value_name = "N")]
    frames: Option<u32>,
    /// Stop accumulating frames after this many seconds (at least one frame).
    #[arg(long, value_name = "SECONDS")]
    time: Option<f64>,
    /// PNG exposure in stops: radiance is multiplied by 2^EV before tone mapping.
    #[arg(long, value_name = "EV", default_value_t = 0.0, allow_hyphen_values = true)]
    exposure: f32,
    /// PNG tone curve: clamp (radiance 1 is white) or reinhard (x / (1 + x)).
    #[arg(long, value_name = "CURVE", default_value = "clamp")]
    tonemap: String,
    /// Extra EXR layers, comma-separated: depth, normal, albedo.
    #[arg(long, value_name = "LIST")]
    aov: Option<String>,
    /// Denoise the accumulated image: an edge-avoiding filter guided by the albedo, normal and
    /// depth of the first hits (computed for it), fading out as the image converges
    #[arg(long)]
    denoise: bool,
    /// Mirror and glass bounce limit.
    #[arg(long, value_name = "N", default_value_t = 6)]
    max_depth: u32,
    /// Ambient occlusion distance, as a fraction of the scene diagonal.
    #[arg(long, value_name = "F", default_value_t = 0.05)]
    ao_radius: f32,
    /// After each frame, print the RMSE relative to this reference image (.exr), for
    /// convergence measurements.
    #[arg(long, value_name = "REF.exr")]
    reference: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// Render a saved view (the `.view.json` the viewer writes beside each screenshot): its
    /// camera, shader, sky, hidden, X-rayed and highlighted parts and sections, as the viewer
    /// showed them (the viewer's light and sky; --res, --frames and the rest still apply).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["eye", "at", "cam_offset"])]
    view: Option<PathBuf>,
    #[command(flatten)]
    show: crate::show::ShowArgs,
    #[command(flatten)]
    paging: crate::paging::PagingArgs,
    #[command(flatten)]
    open: crate::open::OpenArgs,
    /// End each frame after MS milliseconds even if pixels wait for scene data (they are
    /// left to the next frames; with one frame they stay black and are counted). With levels
    /// of detail in the scene, rays that need a tile not yet resident are answered by a
    /// coarser level that is, at once (the tile is loaded for the next frames), so no pixel
    /// waits for data.
    #[arg(long, value_name = "MS")]
    deadline: Option<u64>,
    /// The error allowed to levels of detail, in pixels: far geometry is traced in coarser
    /// stand-ins whose error (every point within it of the full model) is at most this many
    /// pixels' footprint where a ray meets them. 0: full detail (the image then equals that
    /// of a scene built without levels of detail). With --mem, the error rises above this
    /// when a frame's working set would not fit the budget, and falls back when it does
    /// (printed with --stats and --json). Default: 1, or 0 for a scene lit by area lights
    /// (its levels of detail would misplace light and shadow near the lamps: see docs/PERF.md).
    #[arg(long, value_name = "PIXELS")]
    lod_error: Option<f32>,
    /// Under mpirun: a rank that holds tiles and sends nothing back for this long is lost
    /// (its tiles go to the others; once the image is written the job is ended).
    #[arg(long, value_name = "SECS", default_value_t = 60.0)]
    mpi_timeout: f64,
    /// A camera path instead of a still: N frames orbiting the point looked at (DEG degrees
    /// in all, default 360), each rendered on its own; prints frame times and bytes read
    /// (one JSON line per frame with --json); the image is the last frame, or every frame
    /// with `-o name_####.png` (the last run of # becomes the frame number, zero-padded).
    #[arg(long, value_name = "N[:DEG]")]
    orbit: Option<String>,
    /// Rigid motion of a scene's instances: N frames, the instances named NAME (default: the
    /// top-level ones) spinning about their centres, orbiting their group's centre, or moved
    /// along a path of displacements (path=0,0,0/10,0,0/10,0,10: the first frame at the first
    /// point, the last at the last); only the instance trees are rebuilt each frame (their time
    /// in --json); the image is the last frame, or every frame with `-o name_####.png`.
    #[arg(long, value_name = "N[:spin|:orbit|:path=X,Y,Z/X,Y,Z...][:NAME]")]
    animate: Option<String>,
}

impl RenderArgs {
    /// Defaults for a scene and an output, as the command line would give them.
    fn new(scene: PathBuf, out: PathBuf) -> RenderArgs {
        RenderArgs {
            scene,
            out,
            res: (1024, 1024),
            eye: None,
            at: None,
            up: Vec3::Y,
            fov: 60.0,
            cam_offset: None,
            light: None,
            spp: 1,
            adaptive: 0,
            shader: "auto".into(),
            env: None,
            sky: None,
            env_rotate: 0.0,
            env_scale: 1.0,
            env_lights: 1024,
            light_subsets: 16,
            light_samples: 2,
            light_select: "contribution".into(),
            frames: None,
            time: None,
            exposure: 0.0,
            tonemap: "clamp".into(),
            aov: None,
            denoise: false,
            max_depth: 6,
            ao_radius: 0.05,
            reference: None,
            json: false,
            threads: None,
            paging: Default::default(),
            show: Default::default(),
            view: None,
            open: crate::open::OpenArgs { no_cache: false, build_mem: 2 << 30 },
            deadline: None,
            lod_error: Some(1.0),
            orbit: None,
            animate: None,
            mpi_timeout: 60.0,
        }
    }
}

/// Which output format `path` asks for.
fn is_exr(path: &Path) -> Result<bool> {
    match path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref() {
        Some("png") => Ok(false),
        Some("exr") => Ok(true),
        _ => bail!("{}: the output must end in .png or .exr", path.display()),
    }
}

/// Fails at once when `out` cannot be written, not after the render: a temporary file made
/// and removed in its folder, where the image's own goes before it is renamed into place.
fn check_writable(out: &Path) -> Result<()> {
    let dir = out.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    match tempfile::Builder::new().prefix(".megaray-check").tempfile_in(dir) {
        Ok(_) => Ok(()),
        Err(e) => bail!("{}: cannot write there: {e}", out.display()),
    }
}

/// Writes a still (no AOVs): EXR linear, PNG tone-mapped.
fn save(img: &megaray_render::Image, out: &Path, exr: bool, exposure: f32, curve: ToneCurve) -> Result<()> {
    if exr {
        img.save_exr(out, None)?;
    } else {
        img.save_png_with(out, &ToneMap { exposure, curve })?;
    }
    Ok(())
}

/// The largest scene file an unpaged render checks whole before its first frame (about a
/// second of reading and hashing, which traversal would mostly do anyway).
const CHECK_AT_ONCE: u64 = 1 << 30;

pub fn render(a: RenderArgs, bars: &Bars) -> Result<()> {
    if !(1..=65536).contains(&a.spp) {
        bail!("--spp must be 1..=65536");
    }
    if a.adaptive > 255 {
        bail!("--adaptive must be 0..=255 samples a frame");
    }
    if a.lod_error.is_some_and(|e| !(e >= 0.0 && e.is_finite())) {
        bail!("--lod-error must be a number of pixels, 0 or more");
    }
    if !(a.fov > 0.0 && a.fov < 180.0) {
        bail!("--fov must be between 0 and 180 degrees");
    }
    if a.light.is_some_and(|l| l.length() == 0.0) {
        bail!("--light must not be 0,0,0");
    }
    let shader: Builtin = a.shader.parse().map_err(|e: String| anyhow::anyhow!("--shader: {e}"))?;
    let curve = match a.tonemap.as_str() {
        "clamp" => ToneCurve::Clamp,
        "reinhard" => ToneCurve::Reinhard,
        other => bail!("--tonemap: unknown curve `{other}` (known: clamp, reinhard)"),
    };
    let exr = is_exr(&a.out)?;
    // Only rank 0 of an MPI job writes the image (the others may see another file system).
    if crate::cluster::launched_rank().is_none_or(|r| r == 0) {
        check_writable(&a.out)?;
    }
    let (mut aov_depth, mut aov_normal, mut aov_albedo) = (false, false, false);
    for name in a.aov.as_deref().unwrap_or("").split(',').map(str::trim).filter(|n| !n.is_empty()) {
        match name {
            "depth" => aov_depth = true,
            "normal" => aov_normal = true,
            "albedo" => aov_albedo = true,
            other => bail!("--aov: unknown layer `{other}` (known: depth, normal, albedo)"),
        }
    }
    let aovs = aov_depth || aov_normal || aov_albedo;
    if aovs && !exr {
        bail!("{}: --aov layers need an .exr output", a.out.display());
    }
    if a.frames == Some(0) {
        bail!("--frames must be at least 1");
    }
    if let Some(t) = a.time {
        if !(t > 0.0 && t.is_finite()) {
            bail!("--time must be a positive number of seconds");
        }
    }
    if !(a.env_scale >= 0.0 && a.env_scale.is_finite() && a.env_rotate.is_finite()) {
        bail!("--env-scale must be a number >= 0 and --env-rotate a number");
    }
    if !(1..=1 << 20).contains(&a.env_lights) || !(1..=4096).contains(&a.light_subsets) {
        bail!("--env-lights must be 1..=1048576 and --light-subsets 1..=4096");
    }
    if a.light_samples > 4096 || a.max_depth > 64 || a.ao_radius.is_nan() || a.ao_radius <= 0.0 {
        bail!("--light-samples must be at most 4096, --max-depth at most 64, --ao-radius above 0");
    }
    if !a.exposure.is_finite() {
        bail!("--exposure must be a number");
    }
    if !(a.mpi_timeout > 0.0 && a.mpi_timeout <= 1e6) {
        bail!("--mpi-timeout must be a number of seconds above 0");
    }
    // The environment, read before the scene so that a bad map fails fast.
    let map = match (&a.env, &a.sky) {
        (Some(p), _) => Some(EnvMap::load(p)?),
        (None, Some(spec)) => Some(spec.parse::<SkySpec>().map_err(|e| anyhow::anyhow!("--sky: {e}"))?.map()),
        (None, None) => None,
    };
    let reference = match &a.reference {
        Some(p) => Some(read_exr(p)?.0),
        None => None,
    };
    crate::cluster::refuse_single_process_options(&[
        ("--orbit", a.orbit.is_some()),
        ("--animate", a.animate.is_some()),
        ("--deadline", a.deadline.is_some()),
        ("--adaptive", a.adaptive > 1),
    ])?;
    let animate = a.animate.as_deref().map(crate::animate::parse_animate).transpose()?;
    let opened = crate::open::scene_for(Some(&a.scene), &a.open, bars)?;
    let (scene, pager) = a.paging.open(&opened.path)?;
    // The scene's own environment map and sun (a pbrt scene's), where none was given.
    let own_lights = crate::open::scene_lights(&scene);
    let viewpoint = match &a.view {
        Some(p) if a.show.any() => bail!("{}: give --view or --hide/--isolate/--xray/--section, not both", p.display()),
        Some(p) => Some(crate::show::read_viewpoint(p, scene.components())?),
        None => None,
    };
    // A saved view is lit as the viewer lit it: its sky (the viewer's default unless --env or
    // --sky names one) or none, and the default light.
    let map = match &viewpoint {
        Some(vp) if !vp.sky => None,
        Some(_) if map.is_none() => {
            Some(crate::view::DEFAULT_SKY.parse::<SkySpec>().map_err(anyhow::Error::msg)?.map())
        }
        _ => map,
    };
    let own_lights = if viewpoint.is_some() { (None, None) } else { own_lights };
    let map = match (map, &own_lights.0) {
        (None, Some((path, scale))) if a.sky.is_none() => {
            let mut m = EnvMap::load(path)?;
            m.scale = *scale;
            Some(m)
        }
        (m, _) => m,
    };
    let b = scene.header().bounds;
    let (w, h) = a.res;
    let at = a.at.unwrap_or(b.center());
    let eye = a.eye.unwrap_or_else(|| b.center() + a.cam_offset.unwrap_or(DEFAULT_OFFSET) * b.diagonal());
    if (at - eye).length() == 0.0 || (at - eye).normalize().cross(a.up.normalize_or_zero()).length() < 1e-6 {
        bail!("--eye, --at and --up do not make a camera (eye equals at, or up is parallel to the view)");
    }
    if let Some(r) = &reference {
        if (r.width, r.height) != (w, h) {
            bail!(
                "{}: the reference is {}x{}, the image {w}x{h}",
                a.reference.as_ref().unwrap().display(),
                r.width,
                r.height
            );
        }
    }
    let own = if a.eye.is_none() && a.at.is_none() { crate::open::scene_camera(&scene, w, h) } else { None };
    let cam = match &viewpoint {
        Some(vp) => vp.pose.camera(vp.fov, w, h),
        None => own.unwrap_or_else(|| Camera::look_at(eye, at, a.up, a.fov, w, h)),
    };
    let mut settings = RenderSettings::new(cam);
    settings.light = a.light.or(own_lights.1).unwrap_or(megaray_render::default_light());
    settings.spp = a.spp;
    settings.adaptive = a.adaptive;
    settings.shader = shader;
    settings.light_samples = a.light_samples;
    settings.light_select =
        megaray_render::LightSelect::ALL.iter().find(|(n, _)| *n == a.light_select).map(|&(_, l)| l).ok_or_else(
            || anyhow::anyhow!("--light-select must be contribution or uniform, not '{}'", a.light_select),
        )?;
    settings.max_depth = a.max_depth;
    settings.ao_radius = a.ao_radius;
    settings.aovs = aovs || a.denoise;
    settings.frame_deadline = a.deadline.map(Duration::from_millis);
    // Frames against a deadline answer rays from resident stand-ins rather than wait.
    settings.stand_in = a.deadline.is_some();
    settings.visibility = a.show.visibility(scene.components())?;
    if let Some(vp) = &viewpoint {
        settings.shader = vp.shader;
        settings.visibility = Some(std::sync::Arc::new(vp.shown.clone())).filter(|v| !v.is_empty());
        settings.highlight = vp.highlight;
    }
    // The scene's area lights; a source lit by them alone (no map, no sun) has a black sky.
    let area = if viewpoint.is_some() { None } else { crate::open::scene_area_lights(&scene)? };
    if area.is_some() && map.is_none() && own_lights.1.is_none() {
        settings.sky = [0.0; 3];
    }
    let pool = pool(a.threads)?;
    let t = Instant::now();
    let mut renderer = Renderer::new(settings, &b);
    if let Some(area) = &area {
        renderer = renderer.with_area_lights(area.clone());
    }
    let env = map.map(|mut map| {
        map.rotate = a.env_rotate.to_radians();
        map.scale *= a.env_scale;
        Arc::new(Environment::new(map, a.env_lights, a.light_subsets))
    });
    if let Some(env) = &env {
        renderer = renderer.with_environment(env.clone());
    }
    let setup = t.elapsed().as_secs_f64();
    let stop = Stop { frames: a.frames, time: a.time.map(Duration::from_secs_f64) };
    let mut tracer = match &pager {
        Some(p) => Tracer::paged(p),
        None => {
            // Unpaged, a scene small enough to read at once has all its tiles checked now,
            // so that its tracer skips the checks on the way (a faster kernel); a larger
            // one is checked tile by tile as rays first enter them.
            if scene.bytes().len() as u64 <= CHECK_AT_ONCE {
                // Pages read from now on in 2 MiB pages where the kernel can (advice; a
                // file cached before is not read again: the render starts at once).
                let _ = scene.advise_huge_pages();
                scene.check_all_tiles();
            }
            Tracer::new(&scene)
        }
    }
    .with_lod_error(a.lod_error.unwrap_or(if area.is_some() { 0.0 } else { 1.0 }));
    // `-o name_####.png`: each frame of an animation or orbit to its own file.
    let numbered = animate.is_some() || a.orbit.is_some();
    let fault = || scene.first_error().or_else(|| pager.as_ref().and_then(|p| p.first_error()));
    let mut each = |f: u32, img: &megaray_render::Image| -> Result<()> {
        // A frame drawn while a tile could not be read is not written.
        if let Some(e) = fault() {
            return Err(e.into());
        }
        match numbered.then(|| crate::animate::frame_path(&a.out, f)).flatten() {
            Some(p) => save(img, &p, exr, a.exposure, curve),
            None => Ok(()),
        }
    };
    let last = |img: &megaray_render::Image| match numbered && crate::animate::frame_path(&a.out, 0).is_some() {
        true => Ok(()),
        false => save(img, &a.out, exr, a.exposure, curve),
    };
    if let Some(an) = &animate {
        // (`each` saw every frame: a tile that could not be read has ended the run there.)
        let img = crate::animate::run(an, &scene, &renderer, &mut tracer, &pool, a.json, &mut each)?;
        return last(&img);
    }
    if let Some(spec) = &a.orbit {
        let o = crate::paging::parse_orbit(spec)?;
        let (fov, up) = (a.fov, a.up);
        let camera = |angle: f32| {
            let (s, c) = angle.sin_cos();
            let d = eye - at;
            Camera::look_at(at + Vec3::new(c * d.x + s * d.z, d.y, -s * d.x + c * d.z), at, up, fov, w, h)
        };
        let img = crate::paging::orbit(o, renderer, camera, &tracer, &pool, a.json, &mut each)?;
        return last(&img);
    }
    // Under mpirun: the other ranks render what rank 0 hands out, and are done.
    let mut cluster = crate::cluster::session(&scene, pool.current_num_threads(), a.mpi_timeout)?;
    if let Some(c) = cluster.as_mut().filter(|c| !c.is_root()) {
        c.serve(&mut renderer, env, &tracer, &pool)?;
        return Ok(());
    }
    bars.stage("frames", stop.frames.filter(|_| stop.time.is_none()).unwrap_or(0) as u64);
    let denoise = a.denoise;
    let t = Instant::now();
    let mut on_frame = |acc: &Accumulator| {
        bars.inc(1);
        if bars.visible() {
            let err = acc.error().map(|e| format!("error ~{:.2}%", 100.0 * e)).unwrap_or_default();
            bars.message(&format!("frame {} {err}", acc.frames()));
        }
        if let Some(r) = &reference {
            let rmse = acc.image().relative_rmse(r);
            let denoised = match acc.denoised().filter(|_| denoise) {
                Some(d) => format!(" denoised_rmse {:.3}%", 100.0 * d.relative_rmse(r)),
                None => String::new(),
            };
            eprintln!(
                "frame {} t {:.3} s rmse {:.3}%{denoised} error_estimate {}",
                acc.frames(),
                t.elapsed().as_secs_f64(),
                100.0 * rmse,
                acc.error().map(|e| format!("{:.3}%", 100.0 * e)).unwrap_or_else(|| "-".into())
            );
        }
    };
    // Rank 0 of a cluster runs the frames' queue on this thread (the one that talks MPI), its
    // own share of the tiles over the pool.
    let acc = match cluster.as_mut() {
        Some(c) => {
            // The other ranks begin each frame while this one finishes the last (a frame
            // whose level of detail the governor then changes is begun again).
            let more = |i: u32| stop.time.is_none() && stop.frames.is_some_and(|n| i + 1 < n);
            let frame = |i, acc: &mut Accumulator| c.accumulate_frame(&renderer, &tracer, &pool, i, acc, more(i));
            render_progressive_with(&renderer, &tracer, stop, frame, &mut on_frame)?
        }
        None => pool.install(|| render_progressive(&renderer, &tracer, stop, &mut on_frame)),
    };
    let secs = t.elapsed().as_secs_f64();
    bars.finish();
    if let Some(e) = scene.first_error().or_else(|| pager.as_ref().and_then(|p| p.first_error())) {
        return Err(e.into());
    }
    let img = if a.denoise { acc.denoised().expect("the frames carried AOVs") } else { acc.image() };
    if exr {
        let mut l = acc.aovs();
        if !aov_depth {
            l.depth = None;
        }
        if !aov_normal {
            l.normal = None;
        }
        if !aov_albedo {
            l.albedo = None;
        }
        img.save_exr(&a.out, Some(&l))?;
    } else {
        img.save_png_with(&a.out, &ToneMap { exposure: a.exposure, curve })?;
    }
    let frames = acc.frames();
    let mrays = acc.rays() as f64 / secs / 1e6;
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "out": a.out, "width": w, "height": h, "spp": a.spp, "adaptive": a.adaptive, "adaptive_pixels": renderer.sampled_more(), "shader": shader.name(),
                "frames": frames, "seconds": secs, "setup_seconds": setup, "fps": frames as f64 / secs,
                "rays": acc.rays(), "mrays_s": mrays, "error_estimate": acc.error(), "lod_error": tracer.lod_error(),
                "light_samples": a.light_samples, "env_lights": a.env_lights, "light_subsets": a.light_subsets,
                "threads": pool.current_num_threads(),
                "paging": crate::paging::stats_json(pager.as_ref(), &acc.jobs()),
                "cluster": cluster.as_ref().map(|c| crate::cluster::stats_json(c, frames)),
            })
        );
    } else {
        eprintln!(
            "rendered {} ({w}x{h}, {} spp, shader {}, {frames} frame{}) in {secs:.2} s: {:.2} frames/s, {mrays:.2} Mrays/s{}",
            a.out.display(),
            a.spp,
            shader.name(),
            if frames == 1 { "" } else { "s" },
            frames as f64 / secs,
            acc.error().map(|e| format!(", error estimate {:.2}%", 100.0 * e)).unwrap_or_default()
        );
        if acc.jobs().unfinished > 0 {
            eprintln!("{} pixels not finished by the --deadline (left black)", acc.unfinished());
        }
        if a.paging.stats {
            crate::paging::print_stats(pager.as_ref(), &acc.jobs());
        }
        if let Some(c) = &cluster {
            crate::cluster::print_stats(c, frames);
        }
    }
    if let Some(c) = cluster {
        crate::cluster::finish(c, &format!("{} written", a.out.display()));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
#[derive(Args)]
pub struct DemoArgs {
    /// Plant size in triangles.
    #[arg(long, default_value = "3M")]
    tris: String,
    /// Cache folder for the generated model and scene (default: ~/.cache/megaray).
    #[arg(long, value_name = "DIR")]
    cache: Option<PathBuf>,
    /// Build memory budget: small on purpose, so the out-of-core split runs.
    #[arg(long, value_name = "SIZE", default_value = "192M", value_parser = parse_mem)]
    build_mem: u64,
    /// Image size.
    #[arg(long, value_name = "WxH", default_value = "1280x960", value_parser = parse_res)]
    res: (u32, u32),
    /// Frames accumulated (1 primary sample and --light-samples shadow rays per pixel each).
    #[arg(long, default_value_t = 8)]
    frames: u32,
    /// From the second frame on, pixels where the picture changes sharply (thin pipes against
    /// the sky) take this many samples a frame (see `megaray render --adaptive`; 0: off).
    /// 32 makes 8 frames far cleaner (the sub-pixel pipes converge) at several times the time.
    #[arg(long, value_name = "N", default_value_t = 0)]
    adaptive: u32,
    /// Save the accumulated image as it is (by default it is denoised)
    #[arg(long)]
    no_denoise: bool,
    /// Shadow rays per hit toward the sky's virtual lights.
    #[arg(long, value_name = "K", default_value_t = 2)]
    light_samples: u32,
    /// The procedural sky (see `megaray gen --help`).
    #[arg(long, value_name = "SPEC", default_value = "sky:sun_elev=35,sun_azim=120,turbidity=3")]
    sky: String,
    /// PNG exposure in stops (the sunlit white plant is brighter than 1 at 0).
    #[arg(long, value_name = "EV", default_value_t = -0.5, allow_hyphen_values = true)]
    exposure: f32,
    /// The error allowed to levels of detail, in pixels (see `megaray render --help`).
    #[arg(long, value_name = "PIXELS", default_value_t = 1.0)]
    lod_error: f32,
    /// Render without a memory budget (by default the demo pages its scene within a third of
    /// the file's size, and far geometry comes from levels of detail).
    #[arg(long, conflicts_with = "mem")]
    no_budget: bool,
    #[command(flatten)]
    paging: crate::paging::PagingArgs,
}

pub(crate) fn cache_dir(given: Option<PathBuf>) -> PathBuf {
    given.unwrap_or_else(|| {
        std::env::var_os("XDG_CACHE_HOME")
            .map(PathBuf::from)
            .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".cache")))
            .unwrap_or_else(std::env::temp_dir)
            .join("megaray")
    })
}

/// Builds `inputs` into `out` with the defaults of `megaray build` and `build_mem`.
pub(crate) fn build_into(inputs: Vec<PathBuf>, out: &Path, build_mem: u64, bars: &dyn Progress) -> Result<()> {
    build(
        BuildArgs {
            inputs,
            out: out.to_path_buf(),
            build_mem,
            tile_size: 256 << 10,
            threads: None,
            quality: QualityArg::High,
            no_lod: false,
            tmp: None,
            plain: false,
            json: false,
        },
        bars,
    )
}

pub(crate) fn demo_scene(dir: &Path, tris: &str, build_mem: u64, bars: &dyn Progress) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create cache folder", dir.display()))?;
    let spec: GenSpec = format!("plant:{tris}").parse()?;
    let name = spec.name().replace(':', "-");
    let ply = dir.join(format!("{name}.ply"));
    let mray = dir.join(format!("{name}.mray"));
    if Scene::open_owned(&mray).is_ok() {
        eprintln!("1/3 model, 2/3 scene: {} (cached)", mray.display());
        return Ok(mray);
    }
    if ply.exists() {
        eprintln!("1/3 model: {} (cached)", ply.display());
    } else {
        eprintln!("1/3 model: generating {} -> {}", spec.name(), ply.display());
        gen(GenArgs { spec: spec.name(), out: ply.clone(), seed: 1 }, bars)?;
    }
    eprintln!("2/3 scene: building with --build-mem {} (out of core)", format_size(build_mem));
    build_into(vec![ply], &mray, build_mem, bars)?;
    Ok(mray)
}

pub fn demo(a: DemoArgs, bars: &Bars) -> Result<()> {
    let dir = cache_dir(a.cache);
    let mray = demo_scene(&dir, &a.tris, a.build_mem, bars)?;
    let png = dir.join("demo.png");
    let mut paging = a.paging;
    if paging.mem.is_none() && !a.no_budget {
        // A model larger than its budget: a third of what it takes in memory, or what the
        // pager needs at least (the tables and the pinned coarsest levels of detail, two tiles).
        let probe = Scene::open_owned(&mray)?;
        let need = megaray_page::Pager::min_budget(&probe);
        paging.mem = Some((probe.bytes().len() as u64 / 3).max(need + (4 << 20)));
    }
    eprintln!(
        "3/3 image: {}x{} under the procedural sky ({}), env shader, {} frames of 1 primary + {} light samples per pixel{}, denoised unless --no-denoise",
        a.res.0,
        a.res.1,
        a.sky,
        a.frames,
        a.light_samples,
        if a.adaptive > 1 { format!(" ({} primaries where the picture changes sharply)", a.adaptive) } else { String::new() }
    );
    if let Some(mem) = paging.mem {
        eprintln!(
            "    the scene paged within {} (it takes {} in memory, its file {}); levels of detail within {} pixel{}",
            format_size(mem),
            format_size(Scene::open_owned(&mray).map_or(0, |s| s.bytes().len() as u64)),
            format_size(std::fs::metadata(&mray).map(|m| m.len()).unwrap_or(0)),
            a.lod_error,
            if a.lod_error == 1.0 { "" } else { "s" }
        );
    }
    let mut r = RenderArgs::new(mray, png.clone());
    r.res = a.res;
    r.cam_offset = Some(Vec3::new(0.35, 0.25, 0.45));
    r.shader = "env".into();
    r.sky = Some(a.sky);
    r.frames = Some(a.frames.max(1));
    r.light_samples = a.light_samples;
    r.adaptive = a.adaptive;
    r.denoise = !a.no_denoise;
    r.exposure = a.exposure;
    r.lod_error = Some(a.lod_error);
    r.paging = paging;
    render(r, bars)?;
    println!("{}", png.display());
    Ok(())
}
