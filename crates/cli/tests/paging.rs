//! `render --mem` from the command line: the budgeted picture equals the unbudgeted one,
//! `--json` carries the paging statistics, bad budgets and damaged tiles are one-line errors.

mod common;

use std::sync::Arc;

use common::*;
use megaray_page::Pager;
use megaray_scene::Scene;

fn scene(dir: &std::path::Path, spec: &str) -> Arc<Scene> {
    let ply = gen(dir, spec);
    let (path, s) = build(dir, &[ply], "paged", Some(20_000));
    assert!(s.tiles >= 20, "only {} tiles", s.tiles);
    Arc::new(Scene::open(&path).unwrap())
}

/// The command line: `render --mem` gives the same picture as no budget, `--json` carries
/// the paging statistics, a budget below the minimum and `--deadline` behave.
#[test]
fn render_with_a_budget_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path(), "plant:120k");
    let path = scene.path().to_str().unwrap().to_string();
    // What the scene takes in memory (its image: a compact file's is larger than the file).
    let bytes = scene.bytes().len() as u64;
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let common = ["--res", "96x64", "--cam-offset", "0,0.3,0.6", "--threads", "3"];
    let (code, _, err) = run(&[&["render", &path, "-o", a.to_str().unwrap()], &common[..]].concat());
    assert_eq!(code, 0, "{err}");
    let mem = format!("{}", bytes / 4);
    let args = [&["render", &path, "-o", b.to_str().unwrap(), "--mem", &mem, "--json"], &common[..]].concat();
    let (code, out, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "the budgeted render differs");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    let p = &v["paging"];
    assert!(p["tiles_loaded"].as_u64().unwrap() > 0 && p["suspensions"].as_u64().unwrap() > 0, "{p}");
    assert_eq!(p["pixels_unfinished"].as_u64(), Some(0));
    // Too small a budget: one line naming the file.
    let (code, _, err) = run(&[&["render", &path, "-o", b.to_str().unwrap(), "--mem", "8K"], &common[..]].concat());
    assert_eq!(code, 1);
    assert!(err.contains("paged.mray") && err.contains("too small") && err.trim().lines().count() == 1, "{err}");
    // A deadline of 0 ms ends the cold frame at once: pixels are left and counted.
    let args = [&["render", &path, "-o", b.to_str().unwrap(), "--mem", &mem, "--deadline", "0", "--json"], &common[..]]
        .concat();
    let (code, out, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert!(v["paging"]["pixels_unfinished"].as_u64().unwrap() > 0, "{v}");
}

/// `render --mem` on a scene with a damaged tile: one line naming the file and the tile.
#[test]
fn render_with_a_budget_reports_a_corrupt_tile() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path(), "plant:60k");
    let path = scene.path().to_path_buf();
    // The root tile of the part nearest the middle of the part list: the view enters it.
    let t = scene.parts()[scene.parts().len() / 2].root_tile;
    let off = scene.tiles()[t as usize].offset;
    // Where the tile's bytes are stored (a compact file packs them elsewhere).
    let off = match scene.extents().iter().find(|e| e.image_off == off) {
        Some(e) => e.stored_off + e.stored_len / 2,
        None => off + 64,
    };
    let mem = (scene.bytes().len() / 2).to_string();
    drop(scene);
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[off as usize] ^= 0x01;
    std::fs::write(&path, &bytes).unwrap();
    let out = dir.path().join("c.png");
    let (code, _, err) = run(&[
        "render",
        path.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--res",
        "64x48",
        "--cam-offset",
        "0,0.3,0.6",
        "--mem",
        &mem,
    ]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("paged.mray") && err.contains(&format!("tile {t}")), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!out.exists(), "no image is written from a damaged scene");
}

/// A model with attributes (spot: texture coordinates) under a budget of a few tiles: each
/// slot maps to the tile that holds its attributes, and the picture equals the unbudgeted one.
#[test]
fn attributes_page_with_their_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let (path, s) = build(dir.path(), &[model("spot.obj")], "spot", Some(1_500));
    assert!(s.tiles >= 4, "only {} tiles", s.tiles);
    let scene = Scene::open(&path).unwrap();
    let mut parts_with = 0;
    for (pi, p) in scene.parts().iter().enumerate() {
        parts_with += scene.has_attributes(pi as u32) as u32;
        for t in p.first_tile..p.first_tile + p.tile_count {
            let e = &scene.tiles()[t as usize];
            for slot in [e.first_slot, e.first_slot + 4 * e.blocks - 1] {
                assert_eq!(scene.tile_of_slot(pi as u32, slot), Some(t), "part {pi} slot {slot}");
            }
        }
        assert_eq!(scene.tile_of_slot(pi as u32, p.slot_count as u32), None);
    }
    assert!(parts_with > 0, "spot.obj's texture coordinates were not kept");
    let p = path.to_str().unwrap();
    let mem = (Pager::min_budget(&scene) + 8192).to_string();
    drop(scene);
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let common = ["--res", "64x64", "--cam-offset", "0.3,0.3,0.9", "--threads", "3", "--shader", "auto"];
    let (code, _, err) = run(&[&["render", p, "-o", a.to_str().unwrap()], &common[..]].concat());
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(&[&["render", p, "-o", b.to_str().unwrap(), "--mem", &mem], &common[..]].concat());
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "the budgeted render differs");
}

/// A compact scene that does not fit in memory, rendered without `--mem`: paged within half
/// of the machine's memory, said in one line, the same picture. (The scene's header is made
/// to claim an image of 16 TiB, all but its first pages zeros no table points into.)
#[test]
fn a_compact_scene_larger_than_memory_is_paged_without_asking() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path(), "plant:60k");
    assert!(scene.header().is_compact());
    let path = scene.path().to_path_buf();
    drop(scene);
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let common = ["--res", "64x48", "--cam-offset", "0,0.3,0.6"];
    let (code, _, err) = run(&[&["render", path.to_str().unwrap(), "-o", a.to_str().unwrap()], &common[..]].concat());
    assert_eq!(code, 0, "{err}");
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[216..224].copy_from_slice(&(1u64 << 44).to_le_bytes());
    let sum = xxhash_rust::xxh3::xxh3_64(&bytes[..248]);
    bytes[248..256].copy_from_slice(&sum.to_le_bytes());
    let huge = dir.path().join("huge.mray");
    std::fs::write(&huge, &bytes).unwrap();
    let e = Scene::open(&huge).err().expect("too large to open in core").to_string();
    assert!(e.contains("huge.mray") && e.contains("--mem"), "{e}");
    let (code, _, err) = run(&[&["render", huge.to_str().unwrap(), "-o", b.to_str().unwrap()], &common[..]].concat());
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("huge.mray") && err.contains("paged within"), "{err}");
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    // `info --verify` checks it tile by tile; a damaged tile is then one error line.
    let (code, out, err) = run(&["info", huge.to_str().unwrap(), "--verify"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("verified") && out.contains("compact"), "{out}");
    let probe = Scene::open_owned(&huge).unwrap();
    let at = megaray_testkit::stored_offset(&probe, probe.tiles()[1].offset + 100) as usize;
    drop(probe);
    bytes[at] ^= 0x10;
    std::fs::write(&huge, &bytes).unwrap();
    let (code, _, err) = run(&["info", huge.to_str().unwrap(), "--verify"]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("huge.mray") && err.contains("tile 1") && err.trim().lines().count() == 1, "{err}");
}
