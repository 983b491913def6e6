//! The memory-budget options shared by the commands that trace (`render`, `bench`), their
//! statistics, and the camera-path mode of `render`.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use megaray_base::{format_size, parse_size};
use megaray_page::{Pager, PagerOptions};
use megaray_render::{render_frame, Camera, Renderer};
use megaray_scene::Scene;
use megaray_trace::jobs::JobStats;
use megaray_trace::Tracer;
use serde_json::json;

#[derive(Args, Clone, Debug, Default)]
pub struct PagingArgs {
    /// Memory budget for resident scene data (e.g. 2G): tiles are loaded by fetcher threads
    /// and evicted (second chance) to stay within it, and rays that need a missing tile wait
    /// parked while threads trace others. Without it the whole scene is read into memory (a
    /// plain file is mapped and the operating system pages it); a compact scene larger than
    /// three quarters of this machine's memory is then paged within half of it. Process
    /// memory is this plus a fixed overhead (see docs/ARCHITECTURE.md).
    #[arg(long, value_name = "SIZE", value_parser = parse_mem)]
    pub mem: Option<u64>,
    /// Fetcher threads loading tiles (with --mem). Each waits on one tile read at a time;
    /// more of them keep more reads in flight, and random tile reads scale with the reads in
    /// flight (docs/PERF.md, "Fetchers").
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub fetchers: usize,
    /// Print paging statistics: tiles requested, loaded, evicted, bytes read, tile-table
    /// hit rate, suspended pixels, time threads waited.
    #[arg(long)]
    pub stats: bool,
}

fn parse_mem(s: &str) -> Result<u64, String> {
    parse_size(s).map_err(|e| e.to_string())
}

impl PagingArgs {
    /// Opens `path`: mapped without a budget; with one, read into memory of its own tile by
    /// tile by a pager ([`Scene::open_owned`]).
    pub fn open(&self, path: &Path) -> Result<(Arc<Scene>, Option<Pager>)> {
        crate::fault::watch(path);
        let Some(budget) = self.mem.or_else(|| default_budget(path)) else {
            return Ok((Arc::new(Scene::open(path)?), None));
        };
        if !(1..=64).contains(&self.fetchers) {
            bail!("--fetchers must be 1..=64");
        }
        let pager = Pager::open(path, PagerOptions { budget, fetchers: self.fetchers })?;
        Ok((pager.scene().clone(), Some(pager)))
    }
}

/// A budget for a compact scene given none whose image would not fit in memory: half of
/// the machine's memory (said on stderr). `None` for any other scene.
fn default_budget(path: &Path) -> Option<u64> {
    let h = *Scene::open_owned(path).ok()?.header();
    if !h.is_compact() || megaray_scene::fits_in_memory(h.image_len()) {
        return None;
    }
    let budget = megaray_scene::physical_memory() / 2;
    eprintln!(
        "{}: the scene takes {} in memory, more than this machine holds: paged within {} (--mem sets the budget)",
        path.display(),
        format_size(h.image_len()),
        format_size(budget)
    );
    Some(budget)
}

/// The first fault found in the scene's tiles (damaged, or unreadable because the file was
/// truncated under us), by the scene or its pager: a front end ends with it as an error.
pub fn fault(tracer: &megaray_trace::Tracer) -> Option<megaray_scene::SceneError> {
    tracer.scene().first_error().or_else(|| tracer.pager().and_then(|p| p.first_error()))
}

/// Bytes this process has caused to be read from storage (`/proc/self/io`), if known.
pub fn read_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/io").ok()?;
    s.lines().find_map(|l| l.strip_prefix("read_bytes:")).and_then(|v| v.trim().parse().ok())
}

/// The paging and frame-loop statistics as JSON (`null` pager fields without a budget).
pub fn stats_json(pager: Option<&Pager>, jobs: &JobStats) -> serde_json::Value {
    let p = pager.map(|p| p.stats());
    json!({
        "budget": p.map(|s| s.pinned + s.tile_budget),
        "pinned_bytes": p.map(|s| s.pinned),
        "tiles_requested": p.map(|s| s.requested),
        "tiles_loaded": p.map(|s| s.loaded),
        "tiles_evicted": p.map(|s| s.evicted),
        "tiles_corrupt": p.map(|s| s.corrupt),
        "bytes_loaded": p.map(|s| s.bytes_loaded),
        "resident_bytes": p.map(|s| s.resident),
        "peak_resident_bytes": p.map(|s| s.peak_resident),
        "table_lookups": p.map(|s| s.lookups),
        "table_hit_rate": p.map(|s| s.hit_rate()),
        "fetch_seconds": p.map(|s| s.load_secs),
        "grace_seconds": p.map(|s| s.grace_secs),
        "pixels_finished": jobs.finished,
        "pixels_unfinished": jobs.unfinished,
        "suspensions": jobs.suspended,
        "wait_seconds": jobs.wait_secs,
        "read_bytes": read_bytes(),
        "peak_rss": megaray_base::peak_rss(),
        "rss_file": megaray_base::process_memory().map(|m| m.file),
        "rss_anon": megaray_base::process_memory().map(|m| m.anon),
    })
}

/// The statistics for people, on stderr.
pub fn print_stats(pager: Option<&Pager>, jobs: &JobStats) {
    if let Some(p) = pager {
        let s = p.stats();
        eprintln!(
            "paging: budget {} ({} pinned tables), resident {} (peak {})",
            format_size(s.pinned + s.tile_budget),
            format_size(s.pinned),
            format_size(s.resident),
            format_size(s.peak_resident)
        );
        eprintln!(
            "tiles: {} requested, {} loaded ({}), {} evicted, {} corrupt; table hit rate {:.4}% of {} lookups",
            s.requested,
            s.loaded,
            format_size(s.bytes_loaded),
            s.evicted,
            s.corrupt,
            100.0 * s.hit_rate(),
            s.lookups
        );
        eprintln!("fetchers: {:.2} s loading, {:.3} s in grace periods", s.load_secs, s.grace_secs);
    }
    eprintln!(
        "pixels: {} finished, {} unfinished, {} suspensions; threads waited {:.3} s",
        jobs.finished, jobs.unfinished, jobs.suspended, jobs.wait_secs
    );
    if let Some(r) = read_bytes() {
        eprintln!("read from storage: {}", format_size(r));
    }
    if let Some(m) = megaray_base::process_memory() {
        eprintln!(
            "process memory (RSS): {} now ({} file-backed, {} anonymous), peak {}",
            format_size(m.file + m.anon),
            format_size(m.file),
            format_size(m.anon),
            format_size(m.peak)
        );
    }
}

/// The frame count and the total angle of `--orbit N[:DEG]`.
pub fn parse_orbit(spec: &str) -> Result<(u32, f32)> {
    let (n, deg) = match spec.split_once(':') {
        Some((n, d)) => (n.parse::<u32>().ok(), d.parse::<f32>().ok()),
        None => (spec.parse::<u32>().ok(), Some(360.0)),
    };
    match (n.filter(|&n| n >= 1), deg.filter(|d| d.is_finite())) {
        (Some(n), Some(d)) => Ok((n, d)),
        _ => bail!("--orbit: expected N[:DEG] with N >= 1 (e.g. 100 or 100:90), got `{spec}`"),
    }
}

/// `render --orbit N[:DEG]`: N frames, frame k seen by `camera(angle_k)` (the eye turned
/// about the vertical axis through the point looked at), each rendered on its own (no
/// accumulation). Prints per-frame times and bytes read, and a summary. Returns the last
/// frame's image; each frame goes to `on_frame` (its index, the image) as it is made.
pub fn orbit(
    (n, deg): (u32, f32),
    mut r: Renderer,
    camera: impl Fn(f32) -> Camera,
    tracer: &Tracer,
    pool: &rayon::ThreadPool,
    json: bool,
    on_frame: &mut dyn FnMut(u32, &megaray_render::Image) -> Result<()>,
) -> Result<megaray_render::Image> {
    let mut times = Vec::with_capacity(n as usize);
    let mut bytes = Vec::with_capacity(n as usize);
    let mut jobs = JobStats::default();
    let mut last = None;
    let mut governor = megaray_render::LodGovernor::new(tracer);
    let start = Instant::now();
    for k in 0..n {
        let angle = (deg * k as f32 / n as f32).to_radians();
        r.settings.camera = camera(angle);
        let read0 = read_bytes().unwrap_or(0);
        let loaded0 = tracer.pager().map_or(0, |p| p.stats().bytes_loaded);
        let t = Instant::now();
        let lod_error = tracer.lod_error();
        let f = pool.install(|| render_frame(&r, tracer, 0));
        let secs = t.elapsed().as_secs_f64();
        let approx = f.approx.iter().filter(|&&a| a).count();
        governor.after_frame(tracer);
        let read = read_bytes().unwrap_or(0).saturating_sub(read0);
        let loaded = tracer.pager().map_or(0, |p| p.stats().bytes_loaded) - loaded0;
        times.push(secs);
        bytes.push(read);
        jobs.finished += f.jobs.finished;
        jobs.unfinished += f.jobs.unfinished;
        jobs.suspended += f.jobs.suspended;
        jobs.rays += f.jobs.rays;
        jobs.wait_secs += f.jobs.wait_secs;
        if json {
            println!(
                "{}",
                json!({
                    "frame": k, "seconds": secs, "read_bytes": read, "loaded_bytes": loaded,
                    "suspensions": f.jobs.suspended, "unfinished": f.jobs.unfinished,
                    "wait_seconds": f.jobs.wait_secs, "rays": f.rays,
                    "lod_error": lod_error, "approx_pixels": approx, "filled_pixels": f.filled,
                    "black_pixels": f.jobs.unfinished - f.filled,
                })
            );
        }
        on_frame(k, &f.image)?;
        last = Some(f.image);
    }
    let total = start.elapsed().as_secs_f64();
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    let pct = |p: f64| sorted[((sorted.len() - 1) as f64 * p).round() as usize];
    let read: u64 = bytes.iter().sum();
    let summary = json!({
        "frames": n, "degrees": deg, "seconds": total,
        "frame_seconds_median": pct(0.5), "frame_seconds_p99": pct(0.99), "frame_seconds_max": pct(1.0),
        "read_bytes_total": read, "read_bytes_per_frame": read as f64 / n as f64,
        "read_mb_s": read as f64 / total / 1e6,
        "paging": stats_json(tracer.pager(), &jobs),
    });
    if json {
        println!("{summary}");
    } else {
        eprintln!(
            "orbit: {n} frames in {total:.2} s; frame time median {:.3} s, p99 {:.3} s, max {:.3} s; read {} ({} a frame, {:.1} MB/s)",
            pct(0.5),
            pct(0.99),
            pct(1.0),
            format_size(read),
            format_size(read / n as u64),
            read as f64 / total / 1e6
        );
        print_stats(tracer.pager(), &jobs);
    }
    Ok(last.expect("at least one frame"))
}
