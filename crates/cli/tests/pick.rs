//! `megaray pick`: the hit under a pixel equals the brute-force closest hit over every
//! triangle of the scene, mapped or paged within the smallest budget (its tiles not resident).

mod common;

use common::*;
use megaray_base::{Camera, Vec3};
use megaray_page::Pager;
use megaray_scene::Scene;

#[test]
fn picks_equal_brute_force_mapped_and_paged() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:20k");
    let (path, _) = build(dir.path(), &[ply], "plant", Some(4_000));
    let scene = Scene::open(&path).unwrap();
    assert!(scene.check_all_tiles());
    let b = scene.header().bounds;
    let (w, h) = (48u32, 36u32);
    let eye = b.center() + Vec3::new(0.3, 0.25, 0.5) * b.diagonal();
    let cam = Camera::look_at(eye, b.center(), Vec3::Y, 40.0, w, h);
    // Pixels whose centre ray hits, and some that miss, from every part of the image.
    let mut hits = Vec::new();
    let mut misses = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let k = megaray_base::hash32(y * w + x) % 7;
            if k != 0 {
                continue;
            }
            match megaray_testkit::brute_closest(&scene, &cam.ray(x as f32 + 0.5, y as f32 + 0.5)) {
                Some(hit) => hits.push(((x, y), hit)),
                None => misses.push((x, y)),
            }
        }
    }
    assert!(hits.len() >= 10, "only {} hit pixels", hits.len());
    let budget = (Pager::min_budget(&scene) + 1).to_string();
    let p = path.to_str().unwrap();
    let eye_s = format!("{},{},{}", eye.x, eye.y, eye.z);
    let c = b.center();
    let at_s = format!("{},{},{}", c.x, c.y, c.z);
    let res = format!("{w}x{h}");
    for mem in [None, Some(budget.as_str())] {
        for ((x, y), (t, part, slot)) in hits.iter().take(12) {
            let pixel = format!("{x},{y}");
            let mut args =
                vec!["pick", p, "--eye", &eye_s, "--at", &at_s, "--fov", "40", "--res", &res, "--pixel", &pixel];
            args.push("--json");
            if let Some(m) = mem {
                args.extend(["--mem", m]);
            }
            let (code, out, err) = run(&args);
            assert_eq!(code, 0, "{err}");
            let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
            assert_eq!(v["hit"], true, "pixel {x},{y} (mem {mem:?}): {out}");
            assert_eq!(
                (v["part"].as_u64().unwrap() as u32, v["triangle"].as_u64().unwrap() as u32),
                (*part, *slot),
                "pixel {x},{y}: {out}"
            );
            let got_t = v["t"].as_f64().unwrap() as f32;
            assert!((got_t - t).abs() <= 1e-5 * t.abs().max(1.0), "pixel {x},{y}: t {got_t} against {t}");
            let pos: Vec<f64> = v["position"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
            let r = cam.ray(*x as f32 + 0.5, *y as f32 + 0.5);
            let want = r.org + r.dir * *t;
            for k in 0..3 {
                assert!(
                    (pos[k] - want[k] as f64).abs() < 1e-4 * b.diagonal() as f64,
                    "pixel {x},{y}: {pos:?} against {want}"
                );
            }
        }
        for (x, y) in misses.iter().take(4) {
            let pixel = format!("{x},{y}");
            let mut args = vec![
                "pick", p, "--eye", &eye_s, "--at", &at_s, "--fov", "40", "--res", &res, "--pixel", &pixel, "--json",
            ];
            if let Some(m) = mem {
                args.extend(["--mem", m]);
            }
            let (code, out, err) = run(&args);
            assert_eq!(code, 0, "{err}");
            assert!(out.contains("\"hit\":false"), "pixel {x},{y}: {out}");
        }
    }
    let (code, _, err) = run(&["pick", p, "--pixel", "5000,1"]);
    assert_eq!(code, 1);
    assert!(err.contains("outside") && err.lines().count() == 1, "{err}");
}
