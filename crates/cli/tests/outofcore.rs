//! The out-of-core build gives the same scene, as far as rays can tell, as an in-core one.

mod common;

use common::*;
use megaray_render::{render, Camera, RenderSettings, CLOSE_OFFSET, DEFAULT_OFFSET};
use megaray_scene::Scene;
use megaray_trace::Tracer;

fn image(scene: &std::path::Path, offset: megaray_base::Vec3) -> megaray_render::Image {
    let scene = Scene::open(scene).unwrap();
    let cam = Camera::framing(&scene.header().bounds, offset, 160, 120);
    let mut s = RenderSettings::new(cam);
    s.spp = 2;
    let img = render(&Tracer::new(&scene), &s);
    assert!(scene.first_error().is_none());
    img
}

#[test]
fn three_levels_of_splits_render_like_one_part() {
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
        let a = image(&one, off);
        for other in [&many, &binary] {
            let b = image(other, off);
            let worst = a
                .pixels
                .iter()
                .zip(&b.pixels)
                .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs()))
                .fold(0.0f32, f32::max);
            assert!(worst <= 1e-6, "{}: images differ by {worst}", other.display());
        }
        // And the picture is not empty: something was hit.
        let sky = a.pixels[0];
        assert!(a.pixels.iter().filter(|p| **p != sky).count() > 100);
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

/// A model whose in-core build would need several times the budget builds within it.
#[test]
fn peak_memory_stays_within_build_mem() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:2M");
    let out = dir.path().join("p.mray");
    let (code, json, err) =
        run(&["build", ply.to_str().unwrap(), "-o", out.to_str().unwrap(), "--build-mem", "160M", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    let rss = v["peak_rss"].as_u64().expect("peak_rss reported on Linux");
    // In core this model needs about 2M x 170 bytes = 340 MB.
    assert!(v["parts"].as_u64().unwrap() >= 4, "{v}");
    assert!(rss < (160 << 20) + (32 << 20), "peak RSS {} MiB over the 160 MiB budget + 32 MiB", rss >> 20);
}

/// A gen SPEC is a build input too: the scene equals the one built from the generated PLY,
/// and no temporary PLY is left beside it; a SPEC that does not parse is a one-line error.
#[test]
fn build_accepts_gen_specs() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "sphereflake:2");
    let from_ply = dir.path().join("a.mray");
    let from_spec = dir.path().join("b.mray");
    for (input, out) in [(ply.to_str().unwrap(), &from_ply), ("sphereflake:2", &from_spec)] {
        let (code, _, err) = run(&["build", input, "-o", out.to_str().unwrap(), "-q"]);
        assert_eq!(code, 0, "build {input}: {err}");
    }
    assert!(std::fs::read(&from_ply).unwrap() == std::fs::read(&from_spec).unwrap(), "the scenes differ");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 3, "files left: {left:?}");
    let (code, _, err) = run(&["build", "grid:0", "-o", dir.path().join("c.mray").to_str().unwrap()]);
    assert_eq!(code, 1);
    let line = err.lines().find(|l| l.starts_with("megaray: error:")).expect("an error line");
    assert!(line.contains("grid:0") && line.contains("grid size"), "{line}");
}
