//! Scenes with instances end to end: a pbrt-v4 scene and a generated forest built, described
//! by `info`, rendered from their own camera, animated; bad scenes refused in one line.

mod common;
use common::*;

const SCENE: &str = r#"LookAt 0 3 12  0 0 0  0 1 0
Camera "perspective" "float fov" 40
WorldBegin
LightSource "distant" "point3 from" [1 2 1] "point3 to" [0 0 0]
ObjectBegin "quad"
  Shape "bilinearmesh" "point3 P" [-1 -1 0  1 -1 0  -1 1 0  1 1 0]
ObjectEnd
ObjectBegin "row"
  Translate -3 0 0  ObjectInstance "quad"
  Translate 3 0 0   ObjectInstance "quad"
  Translate 3 0 0   ObjectInstance "quad"
ObjectEnd
AttributeBegin Translate 0 2 0 ObjectInstance "row" AttributeEnd
AttributeBegin Translate 0 -2 0 Rotate 30 0 1 0 ObjectInstance "row" AttributeEnd
Shape "trianglemesh" "point3 P" [-6 -4 -1  6 -4 -1  0 -4 -8] "integer indices" [0 1 2]
"#;

#[test]
fn a_pbrt_scene_builds_renders_from_its_camera_and_animates() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    std::fs::write(d("s.pbrt"), SCENE).unwrap();
    let (code, _, err) = run(&["build", &d("s.pbrt"), "-o", &d("s.mray")]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = run(&["info", &d("s.mray"), "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    // 3 unique triangles: a quad (2) and the world's triangle; 6 quads shown.
    assert_eq!(v["triangles"], 3);
    assert_eq!(v["instances"]["instanced_triangles"], "13");
    let (code, _, err) = run(&["render", &d("s.mray"), "-o", &d("s.png"), "--res", "64x48", "--shader", "normal"]);
    assert_eq!(code, 0, "{err}");
    // The pbrt file itself opens too (built into a scene first), to the same picture.
    let (code, _, err) =
        run(&["render", &d("s.pbrt"), "--no-cache", "-o", &d("p.png"), "--res", "64x48", "--shader", "normal"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read(d("p.png")).unwrap(), std::fs::read(d("s.png")).unwrap());
    let img = image::open(d("s.png")).unwrap().to_rgb8();
    // The scene's camera looks at the quads: the middle of the image is not background.
    let bg = img.get_pixel(0, 0);
    assert_ne!(img.get_pixel(32, 14), bg, "the upper row of quads is in view");
    let (code, out, err) =
        run(&["render", &d("s.mray"), "-o", &d("a.png"), "--res", "32x24", "--animate", "4:orbit", "--json"]);
    assert_eq!(code, 0, "{err}");
    let lines: Vec<serde_json::Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 5, "four frames and a summary");
    assert!(lines[..4].iter().all(|l| l["top_rebuild_ms"].as_f64().is_some() && l["moved_instances"] == 3));
    let (code, _, err) = run(&["render", &d("s.mray"), "-o", &d("a.png"), "--animate", "2:spin:ghost"]);
    assert!(code != 0 && err.contains("no instance named `ghost`"), "{err}");
    // Moved along a path, every frame to its own file: the first frame (the path's first point
    // is where the instances rest) is the still; the last is not.
    let (code, _, err) = run(&[
        "render",
        &d("s.mray"),
        "-o",
        &d("f_##.png"),
        "--res",
        "64x48",
        "--shader",
        "normal",
        "--animate",
        "3:path=0,0,0/0,-1,0/2,-1,0",
    ]);
    assert_eq!(code, 0, "{err}");
    let frame = |k: u32| std::fs::read(d(&format!("f_{k:02}.png"))).unwrap();
    assert_eq!(frame(0), std::fs::read(d("s.png")).unwrap(), "frame 0 at rest is the still");
    assert_ne!(frame(2), frame(0), "the last frame has the instances moved");
    assert!(!dir.path().join("f_##.png").exists(), "no file under the pattern's own name");
    // A camera orbit numbers its frames the same way.
    let (code, _, err) = run(&["render", &d("s.mray"), "-o", &d("o#.png"), "--res", "32x24", "--orbit", "2"]);
    assert_eq!(code, 0, "{err}");
    assert!(dir.path().join("o0.png").exists() && dir.path().join("o1.png").exists());
    // The viewer starts at the scene's camera too.
    std::fs::write(d("script.txt"), "frames 1\n").unwrap();
    let (code, _, err) = run(&["view", &d("s.mray"), "--script", &d("script.txt"), "--out", &d("v"), "--res", "32x24"]);
    assert_eq!(code, 0, "{err}");
    let log = std::fs::read_to_string(dir.path().join("v/frames.jsonl")).unwrap();
    let first: serde_json::Value = serde_json::from_str(log.lines().next().unwrap()).unwrap();
    let eye: Vec<f64> = first["eye"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!((eye[0]).abs() < 1e-4 && (eye[1] - 3.0).abs() < 1e-4 && (eye[2] - 12.0).abs() < 1e-4, "{eye:?}");
}

/// A floor under a lamp: a pbrt area light, the scene's only light.
const LAMP: &str = r#"LookAt 0 2 4  0 0 0  0 1 0
Camera "perspective" "float fov" 50
WorldBegin
Material "diffuse" "rgb reflectance" [0.6 0.6 0.6]
Shape "trianglemesh" "point3 P" [-3 0 -3  3 0 -3  3 0 3  -3 0 3] "integer indices" [0 2 1 0 3 2]
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [20 20 20]
  Material "diffuse" "rgb reflectance" [0 0 0]
  Shape "trianglemesh" "point3 P" [-0.3 1.5 -0.3  0.3 1.5 -0.3  0.3 1.5 0.3  -0.3 1.5 0.3]
    "integer indices" [0 1 2 0 2 3] "normal N" [0 -1 0  0 -1 0  0 -1 0  0 -1 0]
AttributeEnd
"#;

/// An area light lights `path` (and nothing else lights the scene: the background is black),
/// in `render` and in the viewer alike.
#[test]
fn a_pbrt_area_light_lights_the_path_shader_in_render_and_view() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    std::fs::write(d("lamp.pbrt"), LAMP).unwrap();
    let (code, _, err) = run(&["build", &d("lamp.pbrt"), "-o", &d("lamp.mray"), "-q"]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) =
        run(&["render", &d("lamp.mray"), "-o", &d("r.png"), "--res", "48x32", "--shader", "path", "--frames", "16"]);
    assert_eq!(code, 0, "{err}");
    let img = image::open(d("r.png")).unwrap().to_rgb8();
    let lum = |x: u32, y: u32| img.get_pixel(x, y).0.iter().map(|&c| c as u32).sum::<u32>();
    // The corners look past the floor into the black sky; the floor below the lamp is lit,
    // brighter near it than at the far edge.
    assert_eq!(lum(0, 0), 0, "the background is black");
    let (below, far, near) = (lum(24, 15), lum(24, 9), lum(24, 31));
    assert!(below > 400 && below > far && below > near, "floor below the lamp {below}, beyond {far}, nearer {near}");
    // The viewer (a still script: exact frames) draws the same light.
    std::fs::write(d("script.txt"), "frames 4\n").unwrap();
    let (code, _, err) = run(&[
        "view",
        &d("lamp.mray"),
        "--script",
        &d("script.txt"),
        "--out",
        &d("v"),
        "--res",
        "48x32",
        "--shader",
        "path",
    ]);
    assert_eq!(code, 0, "{err}");
    let v = image::open(dir.path().join("v/frame-00004.png")).unwrap().to_rgb8();
    let vl = |x: u32, y: u32| v.get_pixel(x, y).0.iter().map(|&c| c as u32).sum::<u32>();
    assert!(vl(24, 15) > 400 && vl(0, 0) == 0, "the view: floor {}, corner {}", vl(24, 15), vl(0, 0));
}

#[test]
fn a_forest_shows_trillions_of_triangles_from_a_few_objects() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    let (code, _, err) = run(&["gen", "forest:1e12:2k", "-o", &d("f.pbrt")]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(&["build", &d("f.pbrt"), "-o", &d("f.mray")]);
    assert_eq!(code, 0, "{err}");
    let (_, out, _) = run(&["info", &d("f.mray"), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["instances"]["instanced_triangles_f64"].as_f64().unwrap() >= 1e12);
    assert!(v["triangles"].as_u64().unwrap() < 20_000, "a few trees and the ground");
    let (code, _, err) = run(&["render", &d("f.mray"), "-o", &d("f.png"), "--res", "64x48", "--shader", "diffuse"]);
    assert_eq!(code, 0, "{err}");
    // Species as a parameter: 40 of them, each a PLY file and an object, a grove of one of each.
    let (code, _, err) = run(&["gen", "forest:1e9:2k:40", "-o", &d("g.pbrt")]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("40 tree files"), "{err}");
    let (code, _, err) = run(&["build", &d("g.pbrt"), "-o", &d("g.mray")]);
    assert_eq!(code, 0, "{err}");
    let (_, out, _) = run(&["info", &d("g.mray"), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let tris = v["triangles"].as_u64().unwrap();
    assert!((40 * 1_900..40 * 2_200 + 10).contains(&tris), "{tris} unique triangles");
    assert!(v["instances"]["instanced_triangles_f64"].as_f64().unwrap() >= 1e9);
    for bad in ["forest:1e9:2k:0", "forest:1e9:2k:x", "forest:1e9:2k:4:1"] {
        let (code, _, err) = run(&["gen", bad, "-o", &d("h.pbrt")]);
        assert!(code == 1 && err.lines().count() == 1, "{bad}: {err}");
    }
}

#[test]
fn bad_scenes_are_one_line_with_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.pbrt");
    std::fs::write(&p, "WorldBegin\nAttributeEnd\n").unwrap();
    let (code, _, err) = run(&["build", &p.to_string_lossy(), "-o", &dir.path().join("x.mray").to_string_lossy()]);
    assert_eq!(code, 1);
    assert!(err.contains("bad.pbrt: line 2:1: unbalanced AttributeEnd"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}
