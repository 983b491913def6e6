//! Component names survive the build: OBJ objects and groups, several input files, glTF
//! node paths; every triangle slot, split out of core or not, finds the component its
//! triangle came from.

use std::fmt::Write as _;
use std::path::Path;

use megaray_build::{build_scene, BuildOptions};
use megaray_scene::Scene;

/// An OBJ of `per` small triangles per component, each component in its own band of x
/// (component k at x in [10k, 10k + 5]), under `o`/`g` statements; returns the names the
/// build should give them, in file order.
fn write_obj(path: &Path, per: usize) -> Vec<(String, f32)> {
    // (The second value, each component's first band, documents the layout.)
    let file = path.file_name().unwrap().to_string_lossy().into_owned();
    let plan = [("o", "body"), ("g", "wheel"), ("g", "door"), ("o", "engine"), ("g", "")];
    let names = ["body", "body/wheel", "body/door", "engine", "engine"];
    let mut text = String::from("# components test\n");
    let mut v = 0;
    let mut out = Vec::new();
    for (k, ((kw, name), full)) in plan.iter().zip(names).enumerate() {
        writeln!(text, "{kw} {name}").unwrap();
        let x0 = 10.0 * k as f32;
        for i in 0..per {
            let (x, y) = (x0 + (i % 50) as f32 * 0.1, (i / 50) as f32 * 0.1);
            writeln!(text, "v {x} {y} 0\nv {} {y} 0.05\nv {x} {} 0.02", x + 0.08, y + 0.08).unwrap();
            writeln!(text, "f {} {} {}", v + 1, v + 2, v + 3).unwrap();
            v += 3;
        }
        out.push((format!("{file}/{full}"), x0));
    }
    std::fs::write(path, text).unwrap();
    out
}

/// An ASCII STL of `n` triangles at x in [100, 105].
fn write_stl(path: &Path, n: usize) {
    let mut text = String::from("solid s\n");
    for i in 0..n {
        let (x, y) = (100.0 + (i % 50) as f32 * 0.1, (i / 50) as f32 * 0.1);
        writeln!(
            text,
            "facet normal 0 0 1\nouter loop\nvertex {x} {y} 1\nvertex {} {y} 1\nvertex {x} {} 1\nendloop\nendfacet",
            x + 0.08,
            y + 0.08
        )
        .unwrap();
    }
    text.push_str("endsolid s\n");
    std::fs::write(path, text).unwrap();
}

#[test]
fn every_slot_finds_the_component_of_its_triangle() {
    let dir = tempfile::tempdir().unwrap();
    let (obj, stl) = (dir.path().join("car.obj"), dir.path().join("wing.stl"));
    let mut expect = write_obj(&obj, 1_500);
    write_stl(&stl, 1_000);
    // "engine" appears twice in the OBJ (`o engine`, then an unnamed group, at x = 40): one
    // component (3), the STL (x = 100) the last.
    expect.remove(4);
    expect.push(("wing.stl".to_string(), 100.0));
    for split in [None, Some(700)] {
        let out = dir.path().join("s.mray");
        let opts = BuildOptions { max_part_tris: split, ..Default::default() };
        let s = build_scene(&[obj.clone(), stl.clone()], &out, &opts, &megaray_base::NoProgress).unwrap();
        assert_eq!(s.parts > 3, split.is_some(), "{} parts", s.parts);
        let scene = Scene::open(&out).unwrap();
        let comps = scene.components();
        let names: Vec<&str> = comps.names.iter().map(String::as_str).collect();
        let want: Vec<&str> = expect.iter().map(|e| e.0.as_str()).collect();
        assert_eq!(names, want);
        assert_eq!(comps.tri_counts, vec![1_500, 1_500, 1_500, 3_000, 1_000]);
        // Each full-detail slot's component, from its triangle's place (the bands of x).
        let band = |x: f32| [0, 1, 2, 3, 3, 4, 4, 4, 4, 4, 4][(x / 10.0) as usize];
        let mut seen = vec![0u64; names.len()];
        for (t, e) in scene.tiles().iter().enumerate() {
            let lod = scene.parts()[e.part as usize].lod_level != 0;
            for (slot, tri) in scene.tile_view(t as u32).triangles() {
                let c = comps.of(e.part, e.first_slot + slot).expect("a slot without a component");
                if lod {
                    continue;
                }
                assert_eq!(c, band(tri[0][0]), "part {} slot {}", e.part, e.first_slot + slot);
                seen[c as usize] += 1;
            }
        }
        assert_eq!(seen, comps.tri_counts);
        assert!(comps.runs.len() < 200, "{} runs", comps.runs.len());
    }
}

#[test]
fn gltf_nodes_are_named_by_their_paths() {
    let glb = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/models/2CylinderEngine.glb");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("e.mray");
    build_scene(&[glb], &out, &BuildOptions::default(), &megaray_base::NoProgress).unwrap();
    let scene = Scene::open(&out).unwrap();
    let comps = scene.components();
    assert!(comps.names.len() > 20, "{} components", comps.names.len());
    assert!(comps.names.iter().all(|n| n.starts_with("2CylinderEngine.glb/") && n.contains(": ")), "{:?}", comps.names);
    // Node paths nest: some name has a parent node in it.
    assert!(comps.names.iter().any(|n| n.matches('/').count() >= 2), "{:?}", &comps.names[..4]);
    assert_eq!(comps.tri_counts.iter().sum::<u64>(), scene.header().tri_count);
}
