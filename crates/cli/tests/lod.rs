//! Levels of detail from the command line: `--lod-error 0` draws exactly what a build without
//! levels of detail draws, `info` reports them, and against a deadline with a tiny budget no
//! pixel is left black for want of data.

mod common;

use common::*;

#[test]
fn an_error_of_zero_is_full_detail_and_info_reports_the_levels() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:60k");
    let (lod, nolod) = (dir.path().join("lod.mray"), dir.path().join("nolod.mray"));
    let p = ply.to_str().unwrap();
    let (code, _, err) = run(&["build", p, "-o", lod.to_str().unwrap(), "--tile-size", "64K", "-q"]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(&["build", p, "-o", nolod.to_str().unwrap(), "--tile-size", "64K", "--no-lod", "-q"]);
    assert_eq!(code, 0, "{err}");
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let common = ["--res", "96x64", "--cam-offset", "0,0.3,0.9", "--threads", "2", "--lod-error", "0"];
    let (code, _, err) = run(&[&["render", lod.to_str().unwrap(), "-o", a.to_str().unwrap()], &common[..]].concat());
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(&[&["render", nolod.to_str().unwrap(), "-o", b.to_str().unwrap()], &common[..]].concat());
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "--lod-error 0 differs from full detail");
    let (code, out, err) = run(&["info", lod.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert!(v["lod"]["parts"].as_u64().unwrap() > 0, "{v}");
    assert!(v["lod"]["fraction_of_file"].as_f64().unwrap() < 0.15, "{v}");
    let (code, out, _) = run(&["info", nolod.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["lod"]["parts"].as_u64(), Some(0), "{v}");
    // A bad error is one line.
    let (code, _, err) = run(&["render", lod.to_str().unwrap(), "-o", a.to_str().unwrap(), "--lod-error=-1"]);
    assert_eq!(code, 1);
    assert!(err.contains("--lod-error") && err.trim().lines().count() == 1, "{err}");
}

#[test]
fn a_deadline_with_a_tiny_budget_leaves_no_pixel_black() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:120k");
    let (path, _) = build(dir.path(), &[ply], "plant", Some(20_000));
    let scene = megaray_scene::Scene::open(&path).unwrap();
    let mem = (megaray_page::Pager::min_budget(&scene) + 128 * 1024).to_string();
    drop(scene);
    let out = dir.path().join("o.png");
    let (code, stdout, err) = run(&[
        "render",
        path.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--res",
        "96x72",
        "--mem",
        &mem,
        "--deadline",
        "5000",
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(v["paging"]["pixels_unfinished"].as_u64(), Some(0), "{v}");
    assert_eq!(v["paging"]["suspensions"].as_u64(), Some(0), "{v} {err}");
}
