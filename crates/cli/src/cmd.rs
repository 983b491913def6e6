//! The commands: argument structs (validated into library option structs) and their bodies.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use megaray_base::{format_size, parse_size, Progress, Vec3};
use megaray_build::{build_scene, BuildOptions};
use megaray_gen::GenSpec;
use megaray_render::{render as render_image, Camera, RenderSettings, DEFAULT_OFFSET};
use megaray_scene::Scene;
use megaray_trace::Tracer;

fn parse_vec3(s: &str) -> Result<Vec3, String> {
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

fn pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let n = threads.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1));
    if n == 0 {
        bail!("--threads must be at least 1");
    }
    rayon::ThreadPoolBuilder::new().num_threads(n).build().context("cannot start worker threads")
}

// ---------------------------------------------------------------------------------------
#[derive(Args)]
pub struct GenArgs {
    /// What to generate: grid:N, sphereflake:L[:S] or plant:T (see `megaray gen --help`).
    spec: String,
    /// Output file (binary little-endian PLY).
    #[arg(short, long, value_name = "FILE.ply")]
    out: PathBuf,
    /// Seed for plant:T (the same seed gives the same plant).
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

pub fn gen(a: GenArgs, bars: &dyn Progress) -> Result<()> {
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
#[derive(Args)]
pub struct BuildArgs {
    /// Model files: .ply, .obj, .stl, .gltf, .glb (merged into one scene).
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
        ..BuildOptions::default()
    };
    let cancel = opts.cancel.clone();
    let _ = ctrlc::set_handler(move || cancel.store(true, Ordering::Relaxed));
    let s = build_scene(&a.inputs, &a.out, &opts, bars)?;
    bars.finish();
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "out": a.out, "inputs": s.inputs, "triangles": s.triangles,
                "degenerate_dropped": s.degenerate_dropped, "parts": s.parts, "tiles": s.tiles,
                "split_levels": s.split_levels, "split_passes": s.split_passes, "part_limit": s.part_limit, "file_bytes": s.file_bytes,
                "input_bytes": s.input_bytes, "temp_read": s.temp_read, "temp_written": s.temp_written,
                "import_s": s.import_s, "split_s": s.split_s, "parts_s": s.parts_s, "total_s": s.total_s,
                "mtris_s": s.triangles as f64 / s.total_s / 1e6,
                "build_mem": a.build_mem, "peak_rss": megaray_base::peak_rss(),
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
        eprintln!(
            "time {:.1} s (import {:.1}, split {:.1}, parts {:.1}), {:.2} M triangles/s; read {} input + {} temp, wrote {} temp + {} scene",
            s.total_s,
            s.import_s,
            s.split_s,
            s.parts_s,
            s.triangles as f64 / s.total_s / 1e6,
            format_size(s.input_bytes),
            format_size(s.temp_read),
            format_size(s.temp_written),
            format_size(s.file_bytes)
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
    /// The scene file.
    scene: PathBuf,
    /// Output image (.png).
    #[arg(short, long, value_name = "OUT.png")]
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
    /// Direction toward the light.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, default_value = "0.5,1,0.8", allow_hyphen_values = true)]
    light: Vec3,
    /// Samples per pixel (jittered when more than 1).
    #[arg(long, value_name = "N", default_value_t = 1)]
    spp: u32,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
}

pub fn render(a: RenderArgs, _bars: &dyn Progress) -> Result<()> {
    if !(1..=65536).contains(&a.spp) {
        bail!("--spp must be 1..=65536");
    }
    if !(a.fov > 0.0 && a.fov < 180.0) {
        bail!("--fov must be between 0 and 180 degrees");
    }
    if a.light.length() == 0.0 {
        bail!("--light must not be 0,0,0");
    }
    let scene = Scene::open(&a.scene)?;
    let b = scene.header().bounds;
    let (w, h) = a.res;
    let at = a.at.unwrap_or(b.center());
    let eye = a.eye.unwrap_or_else(|| b.center() + a.cam_offset.unwrap_or(DEFAULT_OFFSET) * b.diagonal());
    if (at - eye).length() == 0.0 || (at - eye).normalize().cross(a.up.normalize_or_zero()).length() < 1e-6 {
        bail!("--eye, --at and --up do not make a camera (eye equals at, or up is parallel to the view)");
    }
    let cam = Camera::look_at(eye, at, a.up, a.fov, w, h);
    let mut settings = RenderSettings::new(cam);
    settings.light = a.light;
    settings.spp = a.spp;
    let pool = pool(a.threads)?;
    let t = Instant::now();
    let tracer = Tracer::new(&scene);
    let img = pool.install(|| render_image(&tracer, &settings));
    let secs = t.elapsed().as_secs_f64();
    if let Some(e) = scene.first_error() {
        return Err(e.into());
    }
    img.save_png(&a.out)?;
    eprintln!("rendered {} ({w}x{h}, {} spp) in {:.2} s", a.out.display(), a.spp, secs);
    Ok(())
}

// ---------------------------------------------------------------------------------------
#[derive(Args)]
pub struct InfoArgs {
    /// The scene file.
    scene: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Also check every tile's checksum (reads the whole file).
    #[arg(long)]
    verify: bool,
}

pub fn info(a: InfoArgs) -> Result<()> {
    let scene = Scene::open(&a.scene)?;
    if a.verify {
        scene.verify_all()?;
    }
    let h = *scene.header();
    let parts = scene.parts();
    let tiles = scene.tiles();
    let n = h.tri_count.max(1) as f64;
    let node_bytes: u64 = tiles.iter().map(|t| t.node_count as u64 * 128).sum();
    let tri_bytes: u64 = tiles.iter().map(|t| t.blocks as u64 * 144).sum();
    let slots: u64 = parts.iter().map(|p| p.slot_count).sum();
    let fill = h.tri_count as f64 / slots.max(1) as f64;
    let tile_total: u64 = parts.iter().map(|p| p.tile_bytes).sum();
    let padding = tile_total - node_bytes - tri_bytes;
    let attr_bytes: u64 = parts
        .iter()
        .map(|p| {
            let t = p.slot_count;
            [(p.normals_off, 12), (p.uvs_off, 24), (p.colors_off, 12), (p.materials_off, 4)]
                .iter()
                .filter(|(o, _)| *o != 0)
                .map(|(_, s)| (t * s).div_ceil(4096) * 4096)
                .sum::<u64>()
        })
        .sum();
    let meta = h.file_bytes - tile_total - attr_bytes;
    let depths: Vec<u32> = parts.iter().map(|p| p.depth).collect();
    let (dmin, dmax) = (depths.iter().min().copied().unwrap_or(0), depths.iter().max().copied().unwrap_or(0));
    let tile_sizes: Vec<u32> = tiles.iter().map(|t| t.bytes).collect();
    let tmean = tile_sizes.iter().map(|&b| b as f64).sum::<f64>() / tile_sizes.len().max(1) as f64;
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "file": a.scene, "format_version": h.version, "file_bytes": h.file_bytes,
                "triangles": h.tri_count, "degenerate_dropped": h.degenerate_dropped,
                "bounds": {"min": h.bounds.min, "max": h.bounds.max},
                "parts": h.part_count, "tiles": h.tile_count, "tile_target": h.tile_target,
                "tile_bytes_mean": tmean, "materials": h.material_count, "block_fill": fill,
                "top_depth": h.top_depth, "top_nodes": h.top_node_count,
                "part_depth_min": dmin, "part_depth_max": dmax,
                "attributes": {"normals": h.attr_flags & 1 != 0, "uvs": h.attr_flags & 2 != 0,
                               "colors": h.attr_flags & 4 != 0, "materials": h.attr_flags & 8 != 0},
                "bytes_per_triangle": {
                    "total": h.file_bytes as f64 / n, "nodes": node_bytes as f64 / n,
                    "triangle_blocks": tri_bytes as f64 / n, "tile_padding": padding as f64 / n,
                    "attributes": attr_bytes as f64 / n, "tables": meta as f64 / n,
                },
                "verified": a.verify,
            })
        );
        return Ok(());
    }
    println!("{} (scene format version {})", a.scene.display(), h.version);
    println!("  triangles        {} ({} degenerate dropped at build)", h.tri_count, h.degenerate_dropped);
    println!("  bounds           {:?} .. {:?}", h.bounds.min, h.bounds.max);
    println!("  parts            {} (top-level tree: {} nodes, depth {})", h.part_count, h.top_node_count, h.top_depth);
    println!("  part tree depth  {dmin} .. {dmax}");
    println!(
        "  tiles            {} (target {}, mean payload {})",
        h.tile_count,
        format_size(h.tile_target as u64),
        format_size(tmean as u64)
    );
    println!("  materials        {}", h.material_count);
    println!("  file             {} = {:.1} bytes/triangle:", format_size(h.file_bytes), h.file_bytes as f64 / n);
    println!("    nodes          {:.1}", node_bytes as f64 / n);
    println!("    triangles      {:.1} (blocks of 4, {:.0}% of lanes used)", tri_bytes as f64 / n, 100.0 * fill);
    println!("    tile padding   {:.1}", padding as f64 / n);
    println!("    attributes     {:.1}", attr_bytes as f64 / n);
    println!("    tables, header {:.1}", meta as f64 / n);
    if a.verify {
        println!("  every tile's checksum verified");
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
    /// Samples per pixel.
    #[arg(long, default_value_t = 4)]
    spp: u32,
}

fn cache_dir(given: Option<PathBuf>) -> PathBuf {
    given.unwrap_or_else(|| {
        std::env::var_os("XDG_CACHE_HOME")
            .map(PathBuf::from)
            .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".cache")))
            .unwrap_or_else(std::env::temp_dir)
            .join("megaray")
    })
}

pub fn demo(a: DemoArgs, bars: &dyn Progress) -> Result<()> {
    let dir = cache_dir(a.cache);
    std::fs::create_dir_all(&dir).with_context(|| format!("{}: cannot create cache folder", dir.display()))?;
    let spec: GenSpec = format!("plant:{}", a.tris).parse()?;
    let name = spec.name().replace(':', "-");
    let ply = dir.join(format!("{name}.ply"));
    let mray = dir.join(format!("{name}.mray"));
    if ply.exists() {
        eprintln!("1/3 model: {} (cached)", ply.display());
    } else {
        eprintln!("1/3 model: generating {} -> {}", spec.name(), ply.display());
        gen(GenArgs { spec: spec.name(), out: ply.clone(), seed: 1 }, bars)?;
    }
    if Scene::open(&mray).is_ok() {
        eprintln!("2/3 scene: {} (cached)", mray.display());
    } else {
        eprintln!("2/3 scene: building with --build-mem {} (out of core)", format_size(a.build_mem));
        build(
            BuildArgs {
                inputs: vec![ply],
                out: mray.clone(),
                build_mem: a.build_mem,
                tile_size: 256 << 10,
                threads: None,
                json: false,
            },
            bars,
        )?;
    }
    let png = dir.join("demo.png");
    eprintln!("3/3 image: rendering {}x{} at {} spp", a.res.0, a.res.1, a.spp);
    render(
        RenderArgs {
            scene: mray,
            out: png.clone(),
            res: a.res,
            eye: None,
            at: None,
            up: Vec3::Y,
            fov: 60.0,
            cam_offset: Some(Vec3::new(0.35, 0.25, 0.45)),
            light: Vec3::new(0.5, 1.0, 0.8),
            spp: a.spp,
            threads: None,
        },
        bars,
    )?;
    println!("{}", png.display());
    Ok(())
}
