//! Bad input ends in a one-line error naming the file and the fault, exit code 1, no panic,
//! and no half-written output.

mod common;

use common::*;
use std::path::Path;

fn fails(args: &[&str], words: &[&str]) -> String {
    let (code, _, err) = run(args);
    assert_eq!(code, 1, "megaray {args:?} should fail with exit code 1; stderr: {err}");
    assert!(!err.contains("panicked"), "megaray {args:?} panicked: {err}");
    let line = err.lines().find(|l| l.starts_with("megaray: error:")).unwrap_or_else(|| panic!("no error line: {err}"));
    for w in words {
        assert!(line.contains(w), "error line {line:?} lacks {w:?}");
    }
    line.to_string()
}

fn small_scene(dir: &Path) -> std::path::PathBuf {
    let (p, _) = build(dir, &[model("spot.obj")], "spot", Some(1000));
    p
}

#[test]
fn corrupt_scene_files() {
    let dir = tempfile::tempdir().unwrap();
    let good = small_scene(dir.path());
    let bytes = std::fs::read(&good).unwrap();
    let out = dir.path().join("o.png");
    let o = out.to_str().unwrap();
    let write = |name: &str, b: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, b).unwrap();
        p.to_str().unwrap().to_string()
    };

    let p = write("truncated.mray", &bytes[..bytes.len() - 4096]);
    fails(&["info", &p], &["truncated.mray", "truncated"]);
    let p = write("tiny.mray", &bytes[..100]);
    fails(&["render", &p, "-o", o], &["tiny.mray", "too short"]);
    let mut b = bytes.clone();
    b[0] = b'X';
    let p = write("magic.mray", &b);
    fails(&["info", &p], &["magic.mray", "not a megaray scene"]);
    let mut b = bytes.clone();
    b[8] = 99;
    let p = write("version.mray", &b);
    fails(&["info", &p], &["version.mray", "version 99"]);
    let mut b = bytes.clone();
    b[30] ^= 1; // tri_count, under the header checksum
    let p = write("header.mray", &b);
    fails(&["info", &p], &["header.mray", "header"]);
    // A flipped byte inside a tile: open works, rendering reports the tile.
    let scene = megaray_scene::Scene::open(&good).unwrap();
    let t = scene.tiles()[scene.parts()[0].root_tile as usize];
    let mut b = bytes.clone();
    b[megaray_testkit::stored_offset(&scene, t.offset + 200) as usize] ^= 0x40;
    let p = write("tile.mray", &b);
    fails(&["render", &p, "-o", o, "--res", "64x64"], &["tile.mray", "tile", "checksum"]);
    // Nor is any frame of an orbit written from it.
    let frames = dir.path().join("f_#.png");
    fails(
        &["render", &p, "-o", frames.to_str().unwrap(), "--res", "32x32", "--orbit", "2"],
        &["tile.mray", "checksum"],
    );
    assert!(!dir.path().join("f_0.png").exists(), "a frame drawn from a damaged scene was written");
    fails(&["info", "--verify", &p], &["tile.mray", "checksum"]);
    // The benchmark checks every tile before it traces.
    fails(
        &["bench", &p, "--kinds", "primary_1", "--res", "16x16", "--reps", "1", "--min-ms", "1"],
        &["tile.mray", "checksum"],
    );
    assert!(!out.exists(), "no image is written from a corrupt scene");
    fails(&["info", "/nonexistent/x.mray"], &["x.mray", "cannot open"]);
}

#[test]
fn bad_arguments_and_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let scene = small_scene(dir.path());
    let s = scene.to_str().unwrap();
    // Refused before the render (a million frames would take long), not after it.
    fails(
        &["render", s, "-o", "/nonexistent-dir/x.png", "--res", "16x16", "--frames", "1000000"],
        &["x.png", "cannot write there"],
    );
    fails(&["build", &model("spot.obj").to_string_lossy(), "-o", "/nonexistent-dir/x.mray"], &["nonexistent-dir"]);
    fails(&["build", "nothere.ply", "-o", dir.path().join("y.mray").to_str().unwrap()], &["nothere.ply"]);
    fails(&["gen", "plant:abc", "-o", dir.path().join("z.ply").to_str().unwrap()], &["plant:abc"]);
    fails(&["gen", "grid:10", "-o", "/nonexistent-dir/z.ply"], &["z.ply"]);
    let (code, _, err) = run(&["render", s, "-o", "a.png", "--res", "0x10"]);
    assert_eq!(code, 2, "clap rejects a bad resolution: {err}");
    assert!(err.contains("0x10"));
    fails(&["render", s, "-o", "a.png", "--eye", "0,0,0", "--at", "0,0,0"], &["camera"]);
    fails(&["render", s, "-o", "a.png", "--res", "16x16", "--adaptive", "300"], &["--adaptive", "255"]);
    fails(&["build", &model("spot.obj").to_string_lossy(), "-o", "q.mray", "--build-mem", "1M"], &["too small"]);
    // A failed build leaves no output and no temporary files.
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.iter().all(|n| !n.to_string_lossy().starts_with(".megaray")), "{left:?}");
}

#[test]
fn malformed_models_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.mray");
    let o = out.to_str().unwrap();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("lying.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3000000000\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\0\0\0\0".to_vec(), "lying.ply"),
        ("nan.obj", b"v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n".to_vec(), "nan.obj"),
        ("inf.obj", b"v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n".to_vec(), "inf.obj"),
        ("range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n".to_vec(), "range.obj"),
        ("empty.stl", Vec::new(), "empty.stl"),
        ("magic.ply", b"plx\nformat ascii 1.0\nend_header\n".to_vec(), "magic.ply"),
    ];
    for (name, bytes, word) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        fails(&["build", p.to_str().unwrap(), "-o", o], &[word]);
        assert!(!out.exists());
    }
}

/// Ctrl-C during a build: the build stops with an error and removes its temporary files.
#[test]
fn interrupted_build_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:3M");
    let out = dir.path().join("big.mray");
    let child = std::process::Command::new(bin())
        .args(["build", ply.to_str().unwrap(), "-o", out.to_str().unwrap(), "--build-mem", "130M"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the build has started writing temporary files, then interrupt it.
    let started = std::time::Instant::now();
    let temp_exists = || {
        std::fs::read_dir(dir.path()).unwrap().any(|e| e.unwrap().file_name().to_string_lossy().starts_with(".megaray"))
    };
    while !temp_exists() && started.elapsed().as_secs() < 20 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    std::thread::sleep(std::time::Duration::from_millis(100));
    let killed = std::process::Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(killed.success());
    let res = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&res.stderr);
    if res.status.success() {
        // The build won the race: it finished before the signal arrived. Nothing to check.
        assert!(out.exists());
        return;
    }
    assert_eq!(res.status.code(), Some(1), "{err}");
    assert!(err.contains("interrupted"), "{err}");
    assert!(!out.exists());
    assert!(!temp_exists(), "temporary files left after Ctrl-C");
}

/// A byte flipped anywhere in a scene file is caught (open fails, or the damaged tile is
/// reported), or lands where it changes nothing the checks cover (attribute values, padding):
/// never a panic, never an out-of-bounds read.
#[test]
fn random_byte_flips_never_panic() {
    use megaray_render::{render, Camera, RenderSettings, CLOSE_OFFSET};
    let dir = tempfile::tempdir().unwrap();
    let good = small_scene(dir.path());
    let bytes = std::fs::read(&good).unwrap();
    // The stored bytes of the tiles: in a compact file a small share of it (attributes are raw).
    let tiles: Vec<(u64, u64)> = megaray_scene::Scene::open(&good)
        .unwrap()
        .extents()
        .iter()
        .filter(|e| e.kind == megaray_scene::format::EXTENT_TILE)
        .map(|e| (e.stored_off, e.stored_len))
        .collect();
    assert!(!tiles.is_empty(), "the test scene is compact");
    // The header page and the tables before the first tile (the top-level tree, the parts).
    let tables = tiles.iter().map(|t| t.0).min().unwrap().min(16384);
    let mut rng = Rng(99);
    let (mut open_errors, mut tile_errors) = (0, 0);
    for i in 0..300 {
        let mut b = bytes.clone();
        // A third of the flips in the header and the tables before the tiles, a third in a
        // tile's stored bytes, a third anywhere.
        let at = match i % 3 {
            0 => (rng.next_u64() % tables) as usize,
            1 => {
                let (off, len) = tiles[(rng.next_u64() % tiles.len() as u64) as usize];
                (off + rng.next_u64() % len) as usize
            }
            _ => (rng.next_u64() % b.len() as u64) as usize,
        };
        b[at] ^= 1 << (rng.next_u64() % 8);
        let p = dir.path().join("flipped.mray");
        std::fs::write(&p, &b).unwrap();
        let scene = match megaray_scene::Scene::open(&p) {
            Ok(s) => s,
            Err(e) => {
                assert!(e.to_string().contains("flipped.mray"), "{e}");
                open_errors += 1;
                continue;
            }
        };
        let cam = Camera::framing(&scene.header().bounds, CLOSE_OFFSET, 24, 24);
        let _ = render(&megaray_trace::Tracer::new(&scene), &RenderSettings::new(cam));
        if scene.verify_all().is_err() {
            tile_errors += 1;
        }
    }
    assert!(open_errors >= 10 && tile_errors >= 90, "{open_errors} open errors, {tile_errors} tile errors");
}

/// Bad lighting and output options: environment maps, shader names, sky specs, AOVs.
#[test]
fn bad_lighting_inputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = small_scene(dir.path());
    let s = scene.to_str().unwrap();
    let out = dir.path().join("o.png");
    let o = out.to_str().unwrap();
    let sky = dir.path().join("sky.hdr");
    let (code, _, err) = run(&["gen", "sky:width=64", "-o", sky.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let bytes = std::fs::read(&sky).unwrap();
    let write = |name: &str, b: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, b).unwrap();
        p.to_str().unwrap().to_string()
    };
    let p = write("truncated.hdr", &bytes[..bytes.len() / 2]);
    fails(&["render", s, "-o", o, "--env", &p], &["truncated.hdr", "environment map"]);
    let p = write("garbage.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 9999999 +X 9999999\n");
    fails(&["render", s, "-o", o, "--env", &p], &["garbage.hdr", "environment map"]);
    let p = write("notexr.exr", b"this is not an exr file at all");
    fails(&["render", s, "-o", o, "--env", &p], &["notexr.exr", "environment map"]);
    let p = write("image.hdr", b"\x89PNG\r\n\x1a\n");
    fails(&["render", s, "-o", o, "--env", &p], &["image.hdr"]);
    fails(&["render", s, "-o", o, "--env", "/nonexistent/sky.hdr"], &["sky.hdr"]);
    fails(&["render", s, "-o", o, "--shader", "plastic"], &["--shader", "plastic", "known"]);
    fails(&["render", s, "-o", o, "--sky", "sky:sun_elev=abc"], &["--sky", "sun_elev"]);
    fails(&["render", s, "-o", o, "--aov", "depth"], &["--aov", ".exr"]);
    fails(&["render", s, "-o", "x.exr", "--aov", "speed"], &["--aov", "speed"]);
    fails(&["render", s, "-o", "x.tif"], &["x.tif", ".png or .exr"]);
    fails(&["render", s, "-o", o, "--frames", "0"], &["--frames"]);
    fails(&["render", s, "-o", o, "--tonemap", "filmic"], &["--tonemap", "filmic"]);
    fails(&["gen", "sky:turbidity=0", "-o", sky.to_str().unwrap()], &["turbidity"]);
    fails(&["gen", "sky:width=64", "-o", "/nonexistent-dir/sky.hdr"], &["sky.hdr", "cannot write"]);
    assert!(!out.exists(), "no image is written after a bad option");
}

#[test]
fn an_unknown_instruction_set_is_a_clear_error() {
    let out = std::process::Command::new(bin()).args(["info", "grid:4"]).env("MEGARAY_ISA", "neon").output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("megaray: error: MEGARAY_ISA: unknown instruction set \"neon\""), "{err}");
}

#[test]
fn a_bad_assembly_kernel_switch_is_a_clear_error() {
    let out = std::process::Command::new(bin()).args(["info", "grid:4"]).env("MEGARAY_ASM", "maybe").output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("megaray: error: MEGARAY_ASM: unknown value \"maybe\""), "{err}");
}
