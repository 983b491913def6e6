//! Times a model's generation into a counting sink (no disk):
//! `cargo run --release -p megaray-gen --example gen_speed -- plant:10M [more specs...]`;
//! with `--ply DIR` first, also times writing each model to `DIR/SPEC.ply`.

use megaray_base::NoProgress;
use megaray_gen::{generate, CountingSink, GenSpec};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut specs: Vec<String> = std::env::args().skip(1).collect();
    let ply_dir = if specs.first().map(String::as_str) == Some("--ply") && specs.len() > 1 {
        let d = specs[1].clone();
        specs.drain(..2);
        Some(std::path::PathBuf::from(d))
    } else {
        None
    };
    let specs = if specs.is_empty() { vec!["plant:10M".to_string()] } else { specs };
    for s in specs {
        let spec: GenSpec = s.parse()?;
        let t0 = Instant::now();
        let (v, t) = spec.counts();
        let t_counts = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let mut sink = CountingSink::default();
        generate(&spec, &mut sink, &NoProgress)?;
        let secs = t0.elapsed().as_secs_f64();
        assert_eq!((sink.verts, sink.tris), (v, t));
        let b = sink.bounds;
        println!(
            "{}: {} verts, {} tris ({:+.3}% of asked), {} chunks (largest {} tris), bounds {:?}-{:?}; \
             counts() {:.3} s, generate {:.3} s = {:.1} Mtris/s",
            spec.name(),
            v,
            t,
            match spec {
                GenSpec::Plant { tris, .. } => 100.0 * (t as f64 - tris as f64) / tris as f64,
                _ => 0.0,
            },
            sink.chunks,
            sink.max_chunk_tris,
            b.min,
            b.max,
            t_counts,
            secs,
            t as f64 / secs / 1e6
        );
        if let Some(dir) = &ply_dir {
            let path = dir.join(format!("{}.ply", spec.name().replace(':', "_")));
            let t0 = Instant::now();
            megaray_gen::write_ply(&spec, &path, &NoProgress)?;
            let secs = t0.elapsed().as_secs_f64();
            let bytes = std::fs::metadata(&path)?.len();
            println!(
                "  wrote {} ({:.1} MB) in {:.2} s = {:.0} MB/s, {:.1} Mtris/s",
                path.display(),
                bytes as f64 / 1e6,
                secs,
                bytes as f64 / 1e6 / secs,
                t as f64 / secs / 1e6
            );
        }
    }
    Ok(())
}
