//! Every real model of `shared/models` imports with the triangle count its README states.

mod common;

use common::{models_dir, Count};
use megaray_base::NoProgress;
use megaray_import::{import_file, ImportOptions, ImportSummary};

fn count(name: &str) -> (Count, ImportSummary) {
    let path = models_dir().join(name);
    let mut c = Count::default();
    let s = import_file(&path, &ImportOptions::default(), &mut c, &NoProgress)
        .unwrap_or_else(|e| panic!("{name} failed to import: {e}"));
    assert_eq!(s.triangles, c.tris, "{name}: summary and sink disagree");
    assert_eq!(s.bytes, std::fs::metadata(&path).unwrap().len(), "{name}: bytes read");
    (c, s)
}

#[test]
fn spot_obj() {
    let (c, s) = count("spot.obj");
    assert_eq!(c.tris, 5_856);
    assert!(s.vertices > 0);
    assert_eq!(c.with_uv, c.tris, "spot.obj has texture coordinates on every face");
}

#[test]
fn teapot_obj() {
    assert_eq!(count("teapot.obj").0.tris, 6_320);
}

#[test]
fn stanford_bunny_obj() {
    let (c, _) = count("stanford-bunny.obj");
    assert_eq!(c.tris, 69_451);
    assert!(c.min.iter().zip(&c.max).all(|(a, b)| a < b), "empty bounds {:?} {:?}", c.min, c.max);
}

#[test]
fn dog_ribcage_stl_binary_with_color_header() {
    let (c, s) = count("dog_ribcage.stl");
    assert_eq!(c.tris, 73_960);
    assert_eq!(s.vertices, 3 * 73_960);
}

#[test]
fn two_cylinder_engine_glb_instanced() {
    let (c, _) = count("2CylinderEngine.glb");
    assert_eq!(c.tris, 121_496);
    assert!(!c.materials.is_empty(), "glTF materials are declared");
}

#[test]
fn horse_ply_with_normals() {
    let (c, s) = count("horse.ply");
    assert_eq!(c.tris, 96_966);
    assert_eq!(s.vertices, 48_485);
    assert_eq!(c.with_normals, c.tris, "horse.ply has vertex normals");
}

#[test]
fn horse_ply_spilled_matches_in_memory() {
    // The same model through a 64 KiB budget: nearly every vertex is on disk.
    let path = models_dir().join("horse.ply");
    let tmp = tempfile::tempdir().unwrap();
    let small = ImportOptions { mem_limit: 64 << 10, temp_dir: tmp.path().to_path_buf() };
    let (a, sa) = common::collect_with(&path, &small).unwrap();
    let (b, sb) = common::collect(&path).unwrap();
    assert!(sa.spilled > 40_000, "spilled {}", sa.spilled);
    assert_eq!(sb.spilled, 0);
    assert!(a.tris == b.tris, "spilled import differs");
}
