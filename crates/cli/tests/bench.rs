//! `megaray bench`: the peer harness's JSON lines on stdout, one-line errors with exit code 1.

mod common;

use common::*;

fn fails(args: &[&str], words: &[&str]) {
    let (code, out, err) = run(args);
    assert_eq!(code, 1, "megaray {args:?} should fail with exit code 1; stderr: {err}");
    assert!(out.is_empty(), "no figures on failure: {out}");
    assert!(!err.contains("panicked"), "megaray {args:?} panicked: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("megaray: error:")).collect();
    assert_eq!(lines.len(), 1, "one error line: {err}");
    for w in words {
        assert!(lines[0].contains(w), "error line {:?} lacks {w:?}", lines[0]);
    }
}

#[test]
fn bad_arguments_fail_with_one_line() {
    fails(&["bench", "grid:10", "--kinds", "primary_1,bogus"], &["bogus", "primary_16"]);
    fails(&["bench", "grid:10", "--threads", "0"], &["--threads", "`0`"]);
    fails(&["bench", "grid:10", "--threads", "two"], &["two"]);
    fails(&["bench", "no-such-model.obj"], &["no-such-model.obj", "no such file"]);
    fails(&["bench", "grid:x"], &["grid:x"]);
    fails(&["bench", "grid:10", "--reps", "0"], &["--reps"]);
    let dir = tempfile::tempdir().unwrap();
    let txt = dir.path().join("model.txt");
    std::fs::write(&txt, "v 0 0 0").unwrap();
    fails(&["bench", txt.to_str().unwrap()], &["model.txt", "unknown scene type"]);
}

#[test]
fn json_lines_on_stdout() {
    let args = ["bench", "grid:16", "--res", "64x64", "--reps", "1", "--min-ms", "0", "--threads", "1"];
    let (code, out, err) = run(&[&args[..], &["--kinds", "primary_1,build", "--json", "--cam", "close"]].concat());
    assert_eq!(code, 0, "{err}");
    let lines: Vec<serde_json::Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 2, "{out}");
    assert_eq!(lines[0]["kind"], "build");
    assert_eq!(lines[1]["kind"], "primary_1");
    for l in &lines {
        assert_eq!((&l["peer"], &l["scene"], &l["tris"]), (&"megaray".into(), &"grid:16@close".into(), &512.into()));
    }
    assert!(err.contains("primary hits"), "progress notes on stderr: {err}");

    // Without --json: a table with a header.
    let (code, out, err) = run(&[&args[..], &["--kinds", "shadow_1", "--name", "g"]].concat());
    assert_eq!(code, 0, "{err}");
    let rows: Vec<&str> = out.lines().collect();
    assert_eq!(rows.len(), 2, "{out}");
    assert!(rows[0].starts_with("scene") && rows[1].starts_with("g ") && rows[1].contains("shadow_1"), "{out}");
}

#[test]
fn help_teaches_the_comparison() {
    let (code, out, _) = run(&["bench", "--help"]);
    assert_eq!(code, 0);
    for w in ["compare.py", "primary_16", "diffuse_1", "--threads", "--cam", "grid:1000"] {
        assert!(out.contains(w), "help lacks {w}: {out}");
    }
}

/// `megaray info --tree`: the tree statistics count every node, leaf and block of every
/// part exactly, and the SAH cost is at least the roots' (1 per part, weighted by triangles).
#[test]
fn tree_statistics_count_every_node() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "sphereflake:2");
    let (path, _) = build(dir.path(), &[ply], "flake", Some(3000));
    let scene = megaray_scene::Scene::open(&path).unwrap();
    let t = scene.tree_stats();
    let tiles = scene.tiles();
    let parts = scene.parts().len() as u64;
    assert!(parts > 1, "the test wants several parts");
    assert_eq!(t.inner_nodes, tiles.iter().map(|e| e.node_count as u64).sum::<u64>());
    assert_eq!(t.blocks, tiles.iter().map(|e| e.blocks as u64).sum::<u64>());
    // Every node but a part's root is some node's child, and so is every leaf.
    assert_eq!(t.child_slots, t.inner_nodes - parts + t.leaves);
    assert!(t.leaves > 0 && t.sah() >= 1.0 && t.sah_leaves > 0.0, "{t:?}");
    let (code, out, err) = run(&["info", "--tree", "--json", path.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(j["tree"]["inner_nodes"].as_u64(), Some(t.inner_nodes));
    assert_eq!(j["tree"]["blocks"].as_u64(), Some(t.blocks));
}
