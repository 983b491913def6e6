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

/// A colour that is a function of a triangle's corners, whatever their order.
fn colour_of(t: &[[f32; 3]; 3]) -> u8 {
    let s: f32 = t.iter().flatten().sum();
    (s.to_bits().wrapping_mul(0x9e37_79b9) >> 24) as u8
}

/// Split streams of a model with attributes keep each triangle's id (48-byte records; a
/// model without attributes needs 36): every hit's colour is its own triangle's, in a scene
/// split into many parts as in one part.
#[test]
fn attributes_follow_their_triangles_through_the_splits() {
    use megaray_build::{ObjectSource, SceneInput};
    let dir = tempfile::tempdir().unwrap();
    let n = 100u32;
    let mut tris = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (x, z) = (i as f32 / n as f32 - 0.5, j as f32 / n as f32 - 0.5);
            let y = |a: f32, b: f32| 0.1 * (7.0 * a).sin() * (5.0 * b).cos();
            let d = 1.0 / n as f32;
            let p = |a: f32, b: f32| [a, y(a, b), b];
            tris.push([p(x, z), p(x + d, z), p(x, z + d)]);
            tris.push([p(x + d, z), p(x + d, z + d), p(x, z + d)]);
        }
    }
    let build = |name: &str, max_part: Option<u64>| {
        let tris = tris.clone();
        let source = ObjectSource::Fn(Box::new(move |sink| {
            for t in &tris {
                let c = colour_of(t) as f32 / 255.0;
                let color = Some([[c, 0.0, 0.0, 1.0]; 3]);
                let attr =
                    megaray_import::TriAttr { color, material: megaray_import::NO_MATERIAL, ..Default::default() };
                sink.triangle(*t, &attr)?;
            }
            Ok(())
        }));
        let out = dir.path().join(format!("{name}.mray"));
        let opts =
            megaray_build::BuildOptions { max_part_tris: Some(max_part.unwrap_or(1 << 20)), ..Default::default() };
        let s =
            megaray_build::build_objects(SceneInput::plain(source), &out, &opts, &megaray_base::NoProgress).unwrap();
        (out, s)
    };
    let (one, s1) = build("one", None);
    let (many, s2) = build("many", Some(1_000));
    assert_eq!((s1.parts, s2.triangles), (1, 20_000));
    assert!(s2.parts >= 16 && s2.split_levels >= 1, "{} parts", s2.parts);
    for path in [&one, &many] {
        let scene = Scene::open(path).unwrap();
        let cam = Camera::framing(&scene.header().bounds, Vec3::new(0.2, 1.0, 0.4), 120, 90);
        let tracer = Tracer::new(&scene);
        let mut seen = 0;
        for i in 0..120 * 90 {
            let Some(h) = tracer.intersect(&cam.ray((i % 120) as f32 + 0.5, (i / 120) as f32 + 0.5)) else { continue };
            let c = scene.colors(h.part, h.prim).expect("colours kept");
            let want = (colour_of(&h.tri) as f32 / 255.0 * 255.0).round() as u8;
            assert!(
                c[0][0].abs_diff(want) <= 1,
                "{}: part {} prim {}: colour {} for {}",
                path.display(),
                h.part,
                h.prim,
                c[0][0],
                want
            );
            seen += 1;
        }
        assert!(seen > 1000, "{seen} hits");
    }
}

/// Parts finish in any order on several threads, but are written in order: with the part
/// size fixed, the same model gives the same file, byte for byte, on one thread or several,
/// build after build.
#[test]
fn a_scene_file_is_the_same_bytes_whatever_the_threads() {
    let dir = tempfile::tempdir().unwrap();
    let build = |name: &str, threads: usize| {
        let opts = megaray_build::BuildOptions { max_part_tris: Some(1000), threads, ..test_options() };
        std::fs::read(build_with(dir.path(), &[model("spot.obj")], name, opts).0).unwrap()
    };
    let one = build("t1", 1);
    for (k, threads) in [2, 3, 4, 3, 2, 4].into_iter().enumerate() {
        assert!(build(&format!("t{threads}-{k}"), threads) == one, "{threads} threads (build {k}) wrote other bytes");
    }
}
