//! Inspecting a model: component names through the build (`info --parts`), picks that name
//! what they hit and measure the wall behind it (`pick`, `pick --to`), and the viewer's
//! click: the picked component highlighted, its name and the measured distance reported.

mod common;

use std::path::{Path, PathBuf};

use common::*;
use serde_json::Value;

/// A closed box (`o wall`: x, y in [-1, 1], z in [0, 0.2], wound outward) in front of a plate
/// (`o back`: x, y in [-3, 3] at z = -1, facing +z), built into a scene.
fn scene(dir: &Path) -> PathBuf {
    let obj = dir.join("box.obj");
    std::fs::write(
        &obj,
        "o wall\n\
         v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n\
         v -1 -1 0.2\nv 1 -1 0.2\nv 1 1 0.2\nv -1 1 0.2\n\
         f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n\
         o back\n\
         v -3 -3 -1\nv 3 -3 -1\nv 3 3 -1\nv -3 3 -1\n\
         f 9 10 11 12\n",
    )
    .unwrap();
    let out = dir.join("box.mray");
    let (code, _, err) = run(&["build", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    out
}

fn json(out: &str) -> Value {
    serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out}"))
}

#[test]
fn parts_are_listed_and_picks_name_and_measure() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let s = scene.to_str().unwrap();

    let (code, out, err) = run(&["info", s, "--parts", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v = json(&out);
    let list: Vec<(String, u64)> = v["component_list"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| (c["name"].as_str().unwrap().to_string(), c["triangles"].as_u64().unwrap()))
        .collect();
    assert_eq!(list, vec![("box.obj/wall".to_string(), 12), ("box.obj/back".to_string(), 2)]);
    let (_, text, _) = run(&["info", s, "--parts"]);
    assert!(text.contains("components       2") && text.contains("box.obj/back"), "{text}");

    // Straight at the box: its front face, the wall 0.2 thick behind it.
    let cam = ["--eye", "0,0,5", "--at", "0,0,0", "--fov", "40", "--res", "64x48"];
    let (code, out, err) = run(&[&["pick", s, "--pixel", "32,24", "--json"][..], &cam[..]].concat());
    assert_eq!(code, 0, "{err}");
    let p = json(&out);
    assert_eq!((&p["component"], &p["front"]), (&"box.obj/wall".into(), &true.into()), "{p}");
    let behind = p["behind"].as_f64().unwrap();
    assert!((behind - 0.2).abs() < 1e-3, "thickness {behind}");
    assert!((p["position"][2].as_f64().unwrap() - 0.2).abs() < 1e-5, "{p}");
    let n = &p["normal"];
    assert!((n[2].as_f64().unwrap() - 1.0).abs() < 1e-5, "the normal faces the eye: {p}");

    // A corner pixel misses the box and meets the plate; --to measures between the two.
    let (code, out, err) = run(&[&["pick", s, "--pixel", "32,24", "--to", "2,2", "--json"][..], &cam[..]].concat());
    assert_eq!(code, 0, "{err}");
    let v = json(&out);
    let (a, b) = (&v["picks"][0], &v["picks"][1]);
    assert_eq!((&b["component"], &b["behind"]), (&"box.obj/back".into(), &Value::Null), "{v}");
    assert!((b["position"][2].as_f64().unwrap() + 1.0).abs() < 1e-5, "{v}");
    let d: f64 =
        (0..3).map(|k| (a["position"][k].as_f64().unwrap() - b["position"][k].as_f64().unwrap()).powi(2)).sum();
    assert!((v["measured"].as_f64().unwrap() - d.sqrt()).abs() < 1e-9, "{v}");
    let (_, text, _) = run(&[&["pick", s, "--pixel", "32,24", "--to", "2,2"][..], &cam[..]].concat());
    assert!(text.contains("box.obj/wall") && text.contains("thickness") && text.contains("distance between"), "{text}");

    // From behind the plate (its back face): the clearance to the box.
    let back = ["--eye", "0,0,-5", "--at", "0,0,0", "--fov", "40", "--res", "64x48", "--pixel", "32,24", "--json"];
    let (_, out, _) = run(&[&["pick", s][..], &back[..]].concat());
    let p = json(&out);
    assert_eq!((&p["component"], &p["front"]), (&"box.obj/back".into(), &false.into()), "{p}");
    assert!((p["behind"].as_f64().unwrap() - 1.0).abs() < 1e-3, "clearance: {p}");
}

#[test]
fn a_click_in_the_viewer_highlights_and_names_the_part() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let script = dir.path().join("clicks.txt");
    std::fs::write(&script, "frames 1\nclick 32 24\nframes 1\nclick 33 25 measure\nframes 1\nclick 0 0\nframes 1\n")
        .unwrap();
    let out = dir.path().join("frames");
    let args = ["view", scene.to_str().unwrap(), "--res", "64x48", "--script"];
    let (code, _, err) = run(&[&args[..], &[script.to_str().unwrap(), "--out", out.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{err}");
    let log = std::fs::read_to_string(out.join("frames.jsonl")).unwrap();
    let f: Vec<Value> = log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(f.len(), 4);
    assert!(f[0].get("picked").is_none());
    let picked = &f[1]["picked"];
    let name = picked["component"].as_str().unwrap().to_string();
    assert!(name == "box.obj/wall" || name == "box.obj/back", "{picked}");
    // The measuring click: the distance between the two picks' points.
    let (p, q) = (&f[1]["picked"]["position"], &f[2]["picked"]["position"]);
    let d: f64 = (0..3).map(|k| (p[k].as_f64().unwrap() - q[k].as_f64().unwrap()).powi(2)).sum();
    assert!(d > 0.0 && (f[2]["measured"].as_f64().unwrap() - d.sqrt()).abs() < 1e-9, "{}", f[2]);
    // Highlighted: the picked surface turns orange (grey surfaces under a blue sky otherwise).
    let orange = |n: usize| {
        let img = image::open(out.join(format!("frame-{n:05}.png"))).unwrap().to_rgb8();
        img.pixels().filter(|p| p[0] as i32 > p[2] as i32 + 60).count()
    };
    assert_eq!(orange(1), 0);
    assert!(orange(2) > 20, "{} orange pixels", orange(2));
    // A click on nothing (the sky in the corner, or a surface: whatever is there) replaces it.
    assert_eq!(orange(4) > 0, f[3].get("picked").is_some());
}
