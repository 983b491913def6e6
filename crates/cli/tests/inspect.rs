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

/// Renders `scene` straight at the box (normal shader: no shadows, exact per hit) with
/// `extra` options; the image's RGB bytes.
fn shot(scene: &Path, dir: &Path, name: &str, extra: &[&str]) -> image::RgbImage {
    let out = dir.join(format!("{name}.png"));
    let args = ["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q", "--res", "64x48"];
    let cam = ["--eye", "0.3,0.2,5", "--at", "0,0,0", "--fov", "50", "--shader", "normal"];
    let (code, _, err) = run(&[&args[..], &cam[..], extra].concat());
    assert_eq!(code, 0, "{err}");
    image::open(&out).unwrap().to_rgb8()
}

/// Pixels in the colour of section caps (red, where the normal shader draws none).
fn caps(img: &image::RgbImage) -> usize {
    img.pixels().filter(|p| p[0] as u32 > p[1] as u32 + 60 && p[0] as u32 > p[2] as u32 + 60).count()
}

#[test]
fn hide_isolate_xray_and_sections() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = scene(d);
    // The plate alone and the box alone, built apart, for what hiding must equal.
    let lines: Vec<&str> = std::fs::read_to_string(d.join("box.obj")).unwrap().leak().lines().collect();
    let (wall, back) = (lines[..15].join("\n"), lines[15..].join("\n").replace("f 9 10 11 12", "f 1 2 3 4"));
    let mut alone = Vec::new();
    for (name, text) in [("wall", wall), ("back", back)] {
        std::fs::write(d.join(format!("{name}.obj")), text).unwrap();
        let out = d.join(format!("{name}.mray"));
        let (code, _, err) =
            run(&["build", d.join(format!("{name}.obj")).to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
        assert_eq!(code, 0, "{err}");
        alone.push(shot(&out, d, &format!("{name}-alone"), &[]));
    }
    let plain = shot(&scene, d, "plain", &[]);
    assert_eq!(caps(&plain), 0);
    // Hide and isolate, by glob: the same picture as the other part alone.
    assert!(shot(&scene, d, "hide", &["--hide", "*wall"]) == alone[1], "hiding the wall shows the plate alone");
    assert!(shot(&scene, d, "iso", &["--isolate", "box.obj/w*"]) == alone[0], "isolating the wall shows it alone");
    // X-ray: the wall's pixels change (a faint layer over the plate), the rest is the plate's.
    let xray = shot(&scene, d, "xray", &["--xray", "*wall"]);
    let over = xray.pixels().zip(alone[1].pixels()).filter(|(x, q)| x != q).count();
    let same = xray.pixels().len() - over;
    assert!(over > 100 && same > 100, "{over} pixels under the X-ray layer, {same} as the plate alone");

    // A plane through the box (z = 0.1, the eye's side cut): the box's front is gone and the
    // cut shows a solid cap where the box was.
    let cut = shot(&scene, d, "cut", &["--section", "0,0,0.1,0,0,1"]);
    let n_cap = caps(&cut);
    assert!(n_cap > 200, "{n_cap} cap pixels");
    // Every cap pixel lies where the box is (the box alone covers it).
    let sky = alone[0].get_pixel(0, 0);
    for (x, y, p) in cut.enumerate_pixels() {
        if caps(&image::RgbImage::from_pixel(1, 1, *p)) == 1 {
            assert_ne!(alone[0].get_pixel(x, y), sky, "a cap pixel at {x},{y} off the box");
        }
    }
    // Two planes: the intersection of their kept sides (x > 0 cut too): about half the cap.
    let half = caps(&shot(&scene, d, "cut2", &["--section", "0,0,0.1,0,0,1", "--section", "0,0,0,1,0,0"]));
    assert!(half * 10 > n_cap * 4 && half * 10 < n_cap * 6, "{half} of {n_cap}");
    // A box keeps its inside: the box's slab z in [-0.5, 0.1] (the plate and the front face cut).
    let boxed = shot(&scene, d, "boxed", &["--section-box", "-5,-5,-0.5,5,5,0.1"]);
    assert!(
        caps(&boxed) > 200 && boxed.pixels().filter(|p| *p == sky).count() > cut.pixels().filter(|p| *p == sky).count()
    );
    // A plane limited to the plate (cutting z < -0.5) takes the plate away, the wall stays whole.
    let only = shot(&scene, d, "only", &["--section", "0,0,-0.5,0,0,-1@*back"]);
    assert!(only == alone[0], "the limited plane cut only the plate");
    // Bad patterns and planes: one line each.
    for (opt, val, says) in [("--hide", "*door", "matches none"), ("--section", "1,2", "6 numbers")] {
        let out = d.join("bad.png");
        let (code, _, err) = run(&["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), opt, val]);
        assert!(code == 1 && err.contains(says) && err.lines().count() == 1, "{err}");
    }
}

#[test]
fn viewer_keys_hide_show_and_cut_the_picked_part() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let script = dir.path().join("keys.txt");
    let press = |k: &str| format!("key {k} down\nkey {k} up\nframes 1\n");
    let tap = |k: &str| format!("key {k} down\nkey {k} up\n");
    let text = format!(
        "frames 1\nclick 32 24\nframes 1\n{}{}{}{}{}{}{}",
        press("hide"),
        press("showall"),
        press("xray"),
        press("showall"),
        press("section"),
        // The plane (z = 0.1, the middle of the wall) moved on past the wall (a step is 1/100 of
        // the diagonal, 0.087): nothing of it is left; then back into it.
        tap("cutmore").repeat(3) + "frames 1\n",
        tap("cutless").repeat(3) + "frames 1\n",
    );
    std::fs::write(&script, text).unwrap();
    let out = dir.path().join("frames");
    let args = ["view", scene.to_str().unwrap(), "--res", "64x48", "--script"];
    let (code, _, err) = run(&[&args[..], &[script.to_str().unwrap(), "--out", out.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{err}");
    let log = std::fs::read_to_string(out.join("frames.jsonl")).unwrap();
    let f: Vec<Value> = log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(f.len(), 9);
    assert_eq!(f[1]["picked"]["component"], "box.obj/wall", "{}", f[1]);
    let png = |n: usize| image::open(out.join(format!("frame-{n:05}.png"))).unwrap().to_rgb8();
    let orange = |n: usize| png(n).pixels().filter(|p| p[0] as i32 > p[2] as i32 + 60 && p[1] > p[2]).count();
    assert!(orange(2) > 20);
    // Hidden: the wall is gone (no highlight left), then shown again exactly as before.
    assert_eq!((orange(3), &f[2]["hidden"]), (0, &1.into()), "{}", f[2]);
    assert!(png(4) == png(2), "show all brings back the same picture");
    // X-rayed: not the picked orange any more, but not the plate alone either.
    assert_eq!(f[4]["xrayed"], 1);
    assert!(png(5) != png(2) && png(5) != png(3));
    // A section through the picked point, the eye's side cut: the wall's cut face is capped.
    assert_eq!(f[6]["sections"], 1);
    assert!(caps(&png(7)) > 20, "{} cap pixels", caps(&png(7)));
    assert_eq!(caps(&png(8)), 0, "cut past the wall");
    assert!(png(9) == png(7), "and back where it was");
}

#[test]
fn a_saved_view_renders_as_the_viewer_showed_it() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let script = dir.path().join("save.txt");
    // Look a little aside, pick the wall, X-ray it, cut the plate, let 3 frames gather, save.
    std::fs::write(
        &script,
        "drag 12 -6\nframes 1\nclick 30 26\nkey xray down\nkey xray up\nframes 3\nkey screenshot down\nframes 1\n",
    )
    .unwrap();
    let out = dir.path().join("frames");
    let s = scene.to_str().unwrap();
    let args = ["view", s, "--res", "64x48", "--section", "0,0,-0.5,0,0,-1@*back", "--script"];
    let (code, _, err) = run(&[&args[..], &[script.to_str().unwrap(), "--out", out.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{err}");
    let saved = out.join("screenshot-1.view.json");
    let text = std::fs::read_to_string(&saved).unwrap();
    let v = json(&text);
    assert_eq!((&v["xray"][0], &v["highlight"]), (&"box.obj/wall".into(), &"box.obj/wall".into()), "{v}");
    assert_eq!(v["sections"][0]["only"][0], "box.obj/back");
    // `render --view` gives the screenshot, byte for byte.
    let png = dir.path().join("again.png");
    let (code, _, err) = run(&[
        "render",
        s,
        "--view",
        saved.to_str().unwrap(),
        "--res",
        "64x48",
        "--frames",
        "3",
        "-q",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let (a, b) = (image::open(out.join("screenshot-1.png")).unwrap(), image::open(&png).unwrap());
    assert!(a == b, "render --view differs from the viewer's screenshot");
    // The viewer starts from it too: its first frame's pose is the saved one.
    std::fs::write(&script, "frames 1\n").unwrap();
    let out2 = dir.path().join("frames2");
    let args = ["view", s, "--res", "64x48", "--view", saved.to_str().unwrap(), "--script"];
    let (code, _, err) = run(&[&args[..], &[script.to_str().unwrap(), "--out", out2.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{err}");
    let f = json(&std::fs::read_to_string(out2.join("frames.jsonl")).unwrap());
    assert_eq!((&f["eye"], &f["yaw"], &f["xrayed"]), (&v["eye"], &v["yaw"], &1.into()), "{f}");
    // A view naming a component the scene lacks: one line.
    std::fs::write(&saved, text.replace("box.obj/wall", "box.obj/roof")).unwrap();
    let (code, _, err) = run(&["render", s, "--view", saved.to_str().unwrap(), "-q", "-o", png.to_str().unwrap()]);
    assert!(code == 1 && err.contains("roof") && err.contains("view.json") && err.lines().count() == 1, "{err}");
}

#[test]
fn a_pbrt_scene_names_its_shapes() {
    let dir = tempfile::tempdir().unwrap();
    let pbrt = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/models/pbrt-staircase/staircase.pbrt");
    let out = dir.path().join("stairs.mray");
    let (code, _, err) = run(&["build", pbrt.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    let (code, text, err) = run(&["info", out.to_str().unwrap(), "--parts", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v = json(&text);
    let list = v["component_list"].as_array().unwrap();
    assert!(list.len() > 100, "{} components", list.len());
    // Its shapes are PLY meshes of the object "world": named by their files.
    assert!(list.iter().all(|c| c["name"].as_str().unwrap().starts_with("world/")), "{:?}", &list[..3]);
    assert!(list.iter().any(|c| c["name"].as_str().unwrap().ends_with(".ply")));
    let sum: u64 = list.iter().map(|c| c["triangles"].as_u64().unwrap()).sum();
    assert_eq!(sum, v["triangles"].as_u64().unwrap());
}
