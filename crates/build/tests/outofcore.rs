//! The out-of-core build gives the same scene, as far as rays can tell, as an in-core one.

use megaray_base::{Camera, Vec3, CLOSE_OFFSET, DEFAULT_OFFSET};
use megaray_scene::Scene;
use megaray_testkit::*;
use megaray_trace::Tracer;

/// The primary hits of a 160x120 view of `scene`: per pixel, the hit distance's bits (or
/// none).
fn hits(scene: &std::path::Path, offset: Vec3) -> Vec<Option<u32>> {
    let scene = Scene::open(scene).unwrap();
    let cam = Camera::framing(&scene.header().bounds, offset, 160, 120);
    let tracer = Tracer::new(&scene);
    let hits = (0..160 * 120)
        .map(|i| tracer.intersect(&cam.ray((i % 160) as f32 + 0.5, (i / 160) as f32 + 0.5)).map(|h| h.t.to_bits()))
        .collect();
    assert!(scene.first_error().is_none());
    hits
}

#[test]
fn three_levels_of_splits_trace_like_one_part() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:120k");
    let (one, s1) = build(dir.path(), std::slice::from_ref(&ply), "one", None);
    assert_eq!(s1.parts, 1);
    assert_eq!(s1.split_levels, 0);
    // Multi-way passes (the default), and classic binary splits: one pass per level.
    let (many, s2) = build(dir.path(), std::slice::from_ref(&ply), "many", Some(4_000));
    assert!(s2.split_levels >= 3, "only {} split levels", s2.split_levels);
    assert!(s2.parts >= 8);
    assert_eq!(s1.triangles, s2.triangles);
    let binary = dir.path().join("binary.mray");
    let opts = megaray_build::BuildOptions {
        max_part_tris: Some(4_000),
        split_fanout: 2,
        tile_target: 64 << 10,
        ..Default::default()
    };
    let s3 = megaray_build::build_scene(&[ply], &binary, &opts, &megaray_base::NoProgress).unwrap();
    assert!(s3.split_passes >= 7 && s3.split_levels >= 5, "{} passes, {} levels", s3.split_passes, s3.split_levels);
    for off in [DEFAULT_OFFSET, CLOSE_OFFSET] {
        let a = hits(&one, off);
        for other in [&many, &binary] {
            let b = hits(other, off);
            let differ = a.iter().zip(&b).filter(|(p, q)| p != q).count();
            assert_eq!(differ, 0, "{}: {differ} pixels' hits differ", other.display());
        }
        // And the view is not empty: something was hit.
        assert!(a.iter().filter(|h| h.is_some()).count() > 100);
    }
    // Temporary files are gone.
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "temporary files left behind: {left:?}");
}

#[test]
fn build_memory_bound_sets_part_size_and_degenerates_are_counted() {
    let dir = tempfile::tempdir().unwrap();
    // A triangle soup with some zero-area triangles, as an ascii PLY.
    let mut s = String::from("ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\nproperty float z\nelement face 3\nproperty list uchar int vertex_indices\nend_header\n");
    s += "0 0 0\n1 0 0\n0 1 0\n2 2 2\n2 2 2\n3 3 3\n3 0 1 2\n3 3 4 5\n3 0 0 1\n";
    let p = dir.path().join("soup.ply");
    std::fs::write(&p, s).unwrap();
    let (scene, sum) = build(dir.path(), &[p], "soup", None);
    assert_eq!(sum.triangles, 1);
    assert_eq!(sum.degenerate_dropped, 2);
    let sc = Scene::open(&scene).unwrap();
    assert_eq!(sc.header().degenerate_dropped, 2);
    let opts = megaray_build::BuildOptions { build_mem: 1 << 30, threads: 2, ..Default::default() };
    assert_eq!(opts.part_limit(), ((1u64 << 30) - (64 << 20)) / (2 * megaray_build::INCORE_BYTES_PER_TRI));
}
