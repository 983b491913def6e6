//! `megaray bench`: arguments, and printing the figures of `megaray-bench`.

use std::io::Write;

use anyhow::Result;
use clap::{Args, ValueEnum};
use megaray_base::Progress;
use megaray_bench::{run, BenchOptions, Event, Kind, Loaded, Record, Source, View};

#[derive(Clone, Copy, ValueEnum)]
enum Cam {
    /// eye = centre + (0, 0.3, 1.6) * diagonal: the model covers a few percent of the image
    Default,
    /// eye = centre + (0, 0.3, 0.6) * diagonal: about half the image; scene name gets `@close`
    Close,
}

#[derive(Args)]
pub struct BenchArgs {
    /// What to measure: a .mray scene file, a model file (.ply .obj .stl .gltf .glb: built into a
    /// temporary scene first) or a gen spec (grid:1000, sphereflake:4, plant:1M).
    #[arg(value_name = "SCENE")]
    scene: String,
    /// Comma-separated kinds: primary_1, primary_8, primary_16, shadow_1, diffuse_1, build
    /// (the in-core builder at medium quality, held against the peer's build_medium) and
    /// build_high (at high quality, the quality of the scenes that are traced, against the
    /// peer's build_high).
    #[arg(long, value_name = "K,K,..", default_value = Kind::DEFAULT)]
    kinds: String,
    /// Comma-separated thread counts, one figure each.
    #[arg(long, value_name = "N,N,..", default_value = "1,2")]
    threads: String,
    /// Benchmark camera.
    #[arg(long, value_enum, default_value = "default")]
    cam: Cam,
    /// Image size.
    #[arg(long, value_name = "WxH", default_value = "1024x1024", value_parser = crate::cmd::parse_res)]
    res: (u32, u32),
    /// Print one JSON object per figure (the peer harness's lines) instead of a table.
    #[arg(long)]
    json: bool,
    /// Timed repetitions after the warm-up pass; the figure is their median (builds: at most 3).
    #[arg(long, value_name = "N", default_value_t = 5)]
    reps: u32,
    /// Each repetition repeats the pass until it lasts at least this many milliseconds.
    #[arg(long, value_name = "MS", default_value_t = 200.0)]
    min_ms: f64,
    /// Scene name in the output (default: the gen spec or the file name; `@close` is appended
    /// with --cam close).
    #[arg(long, value_name = "NAME")]
    name: Option<String>,
    /// Trace within this memory budget for resident scene data (e.g. 512M): tiles are paged
    /// in by fetcher threads and evicted to hold it; rays wait for missing tiles. Default:
    /// the whole scene file is mapped.
    #[arg(long, value_name = "SIZE", value_parser = |s: &str| megaray_base::parse_size(s).map_err(|e| e.to_string()))]
    mem: Option<u64>,
}

pub fn bench(a: BenchArgs, bars: &dyn Progress) -> Result<()> {
    // Check every option before loading anything (building a big scene takes a while).
    let opts = BenchOptions {
        kinds: Kind::parse_list(&a.kinds)?,
        threads: megaray_bench::parse_threads(&a.threads)?,
        view: match a.cam {
            Cam::Default => View::Default,
            Cam::Close => View::Close,
        },
        width: a.res.0,
        height: a.res.1,
        reps: a.reps,
        min_ms: a.min_ms,
        name: a.name,
        mem: a.mem,
    };
    opts.check()?;
    let src = Source::parse(&a.scene)?;
    let loaded = Loaded::open(&src, bars)?;
    bars.finish();
    let h = loaded.scene.header();
    eprintln!(
        "scene {}: {} triangles, {} parts, {} tiles ({})",
        loaded.name, h.tri_count, h.part_count, h.tile_count, loaded.origin
    );
    let mut header = !a.json;
    let mut out = std::io::stdout();
    run(&loaded, &opts, bars, &mut |e| match e {
        Event::Info(msg) => {
            bars.finish();
            eprintln!("{msg}");
        }
        Event::Line(r) => {
            if header {
                let _ = writeln!(out, "{}", Record::table_header());
                header = false;
            }
            let _ = writeln!(out, "{}", if a.json { r.json() } else { r.table_row() });
            let _ = out.flush();
        }
    })?;
    Ok(())
}
