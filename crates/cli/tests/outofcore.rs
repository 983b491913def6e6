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
