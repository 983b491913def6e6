//! Levels of detail as the build writes them: every stand-in lies within its stored error of
//! the triangles it stands for (checked by brute force on real models), errors never shrink
//! from one level to the next coarser, the levels are a small part of the file, and a build
//! without them holds none.

use megaray_base::Vec3;
use megaray_scene::Scene;
use megaray_testkit::*;

/// Every triangle of part `p` of `scene`.
fn part_tris(scene: &Scene, p: u32) -> Vec<[Vec3; 3]> {
    let e = scene.parts()[p as usize];
    let mut out = Vec::new();
    for t in e.first_tile..e.first_tile + e.tile_count {
        for (_, tri) in scene.tile(t).expect("tile is sound").triangles() {
            out.push(tri.map(Vec3::from));
        }
    }
    out
}

/// Checks every level of detail of `scene`: sampled points of (a sample of) its triangles lie
/// within its error of the full-detail part's triangles; errors grow along each chain.
fn check(scene: &Scene, name: &str) {
    let full = scene.full_part_count();
    let mut levels = 0;
    for p in 0..full {
        let chain: Vec<u32> = scene.lod_chain(p).collect();
        let errors: Vec<f32> = chain.iter().map(|&q| scene.parts()[q as usize].lod_error).collect();
        assert!(errors.windows(2).all(|w| w[0] <= w[1]), "{name}: part {p}: errors {errors:?} shrink");
        let tris = part_tris(scene, p);
        for &q in &chain[1..] {
            levels += 1;
            let e = scene.parts()[q as usize];
            assert_eq!((e.lod_of, e.lod_level as usize), (p, chain.iter().position(|&x| x == q).unwrap()));
            let stand_in = part_tris(scene, q);
            let step = (stand_in.len() / 150).max(1);
            let mut worst = 0.0f32;
            for t in stand_in.iter().step_by(step) {
                for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0 / 3.0, 1.0 / 3.0), (0.5, 0.25)] {
                    let x = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
                    let d = tris
                        .iter()
                        .map(|s| point_triangle_distance(x.into(), s.map(|v| v.into())))
                        .fold(f32::INFINITY, f32::min);
                    worst = worst.max(d);
                }
            }
            // (A small allowance for the float arithmetic of both sides.)
            assert!(
                worst <= e.lod_error * 1.0001 + 1e-6,
                "{name}: part {p} level {}: a point {worst} from the part, error {}",
                e.lod_level,
                e.lod_error
            );
        }
    }
    assert!(levels > 0, "{name}: no levels of detail");
}

#[test]
fn stand_ins_lie_within_their_error_of_real_models() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["stanford-bunny.obj", "2CylinderEngine.glb", "horse.ply"] {
        let (path, s) = build(dir.path(), &[model(name)], name, Some(40_000));
        let scene = Scene::open(&path).unwrap();
        assert!(scene.verify_all().is_ok());
        assert_eq!(s.lod_parts, scene.header().lod_part_count);
        check(&scene, name);
        let share = scene.stored_bytes().lod as f64 / scene.header().file_bytes as f64;
        assert!(share <= 0.15, "{name}: levels of detail are {:.1}% of the file", 100.0 * share);
    }
}

#[test]
fn stand_ins_of_a_generated_plant_lie_within_their_error() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:120k");
    let (path, _) = build(dir.path(), &[ply], "plant", Some(40_000));
    let scene = Scene::open(&path).unwrap();
    check(&scene, "plant:120k");
}

#[test]
fn a_build_without_levels_of_detail_has_none() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("nolod.mray");
    let opts = megaray_build::BuildOptions { lod: None, tile_target: 64 << 10, ..Default::default() };
    let s = megaray_build::build_scene(&[model("stanford-bunny.obj")], &out, &opts, &megaray_base::NoProgress).unwrap();
    let scene = Scene::open(&out).unwrap();
    assert_eq!((s.lod_parts, scene.header().lod_part_count, scene.stored_bytes().lod), (0, 0, 0));
    assert_eq!(scene.full_part_count(), scene.header().part_count);
    assert_eq!(scene.lod_chain(0).count(), 1);
}
