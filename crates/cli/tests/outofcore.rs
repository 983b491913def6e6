//! `megaray build` from the command line: within `--build-mem`, from gen specs.

mod common;

use common::*;

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
    // The split passes give each parent's blocks back as they read it: the temporary files
    // never hold much more than one stream (parent and children whole would be two).
    let stream = v["triangles"].as_u64().unwrap() * 36;
    let peak = v["temp_peak"].as_u64().unwrap();
    if cfg!(target_os = "linux") {
        assert!(
            peak >= stream && peak < stream + stream / 4,
            "temporary files peaked at {peak} for a {stream}-byte stream"
        );
    }
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

/// A spec alone is streamed into the build (no PLY written): split out of core, its
/// temporary files in `--tmp`, the scene equals the one built from the spec's PLY byte for
/// byte (one thread: parts are then written in the same order).
#[test]
fn a_streamed_spec_split_out_of_core_equals_its_ply_built() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:400k");
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let (a, b) = (dir.path().join("a.mray"), dir.path().join("b.mray"));
    let common = ["--build-mem", "128M", "--threads", "1", "--json"];
    let mut args = vec!["build", ply.to_str().unwrap(), "-o", a.to_str().unwrap()];
    args.extend(common);
    let (code, _, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let mut args = vec!["build", "plant:400k", "-o", b.to_str().unwrap(), "--tmp", tmp.to_str().unwrap()];
    args.extend(common);
    let (code, json, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert!(v["split_levels"].as_u64().unwrap() >= 1, "not split: {v}");
    assert_eq!(v["input_bytes"], 0, "a file was read: {v}");
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(), "the scenes differ");
    assert_eq!(std::fs::read_dir(&tmp).unwrap().count(), 0, "temporary files left in --tmp");
    // Nothing was written beside the output but the scenes (and the test's own PLY).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 4);
    // Files and specs mixed: the spec goes through a temporary PLY, removed afterwards.
    let c = dir.path().join("c.mray");
    let (code, _, err) = run(&["build", ply.to_str().unwrap(), "sphereflake:1", "-o", c.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 5);
}

/// A build that cannot fit the disk stops before any work, in one line naming the folder
/// and the space needed; a `--tmp` that does not exist is one line too.
#[test]
fn a_build_larger_than_the_disk_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.mray");
    let (code, _, err) = run(&["build", "plant:100G", "-o", out.to_str().unwrap()]);
    assert_eq!(code, 1);
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("megaray")).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("not enough free space") && lines[0].contains("needs about"), "{err}");
    assert!(lines[0].contains(&*dir.path().canonicalize().unwrap().to_string_lossy()), "{err}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "something was written");
    let missing = dir.path().join("no-such-dir");
    let (code, _, err) = run(&["build", "plant:20k", "-o", out.to_str().unwrap(), "--tmp", missing.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("no-such-dir"), "{err}");
    assert!(!out.exists());
}
