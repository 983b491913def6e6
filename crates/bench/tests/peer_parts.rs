//! `gen grid:1000` and `gen sphereflake:4` built out of core into many parts give the Embree
//! peer harness's triangles: the same count, and the same hit count and sum of hit distances
//! for the benchmark camera's primary rays (the peer's figures, from
//! shared/peers/embree/results, are stored here).

use megaray_base::{Camera, DEFAULT_OFFSET};
use megaray_scene::Scene;
use megaray_testkit::*;
use megaray_trace::Tracer;
use rayon::prelude::*;

fn checksum(scene: &std::path::Path) -> (u64, u64, f64) {
    let scene = Scene::open(scene).unwrap();
    let cam = Camera::framing(&scene.header().bounds, DEFAULT_OFFSET, 1024, 1024);
    let tracer = Tracer::new(&scene);
    let rows: Vec<(u64, f64)> = (0..1024u32)
        .into_par_iter()
        .map(|y| {
            let (mut hits, mut sum) = (0u64, 0f64);
            for x in 0..1024u32 {
                if let Some(h) = tracer.intersect(&cam.ray(x as f32 + 0.5, y as f32 + 0.5)) {
                    hits += 1;
                    sum += h.t as f64;
                }
            }
            (hits, sum)
        })
        .collect();
    let hits = rows.iter().map(|r| r.0).sum();
    let sum = rows.iter().map(|r| r.1).sum();
    (scene.header().tri_count, hits, sum)
}

fn agree(name: &str, got: (u64, u64, f64), tris: u64, hits: u64, sum_t: f64) {
    assert_eq!(got.0, tris, "{name}: triangle count");
    let dh = (got.1 as f64 - hits as f64).abs();
    assert!(dh <= (1e-4 * hits as f64).max(1.0), "{name}: hits {} vs peer {hits}", got.1);
    assert!((got.2 - sum_t).abs() <= 1e-4 * sum_t, "{name}: sum_t {} vs peer {sum_t}", got.2);
}

#[test]
fn grid_1000_matches_peer() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "grid:1000");
    let (scene, _) = build(dir.path(), &[ply], "grid", Some(400_000));
    // shared/peers/embree/results/grid1000.jsonl, primary_1
    agree("grid:1000", checksum(&scene), 2_000_000, 38173, 164783.074750);
}

#[test]
fn sphereflake_4_matches_peer() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "sphereflake:4");
    let (scene, _) = build(dir.path(), &[ply], "flake", Some(800_000));
    // shared/peers/embree/results/sphereflake4.jsonl, primary_1
    agree("sphereflake:4", checksum(&scene), 3_897_168, 55406, 491002.829798);
}
