//! The lighting options end to end: a generated sky as the environment, progressive frames,
//! PNG and EXR with AOV layers.

mod common;

use common::*;

#[test]
fn sky_env_frames_and_aovs() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, _) = build(dir.path(), &[gen(dir.path(), "sphereflake:1")], "flake", None);
    let s = scene.to_str().unwrap();
    let sky = dir.path().join("sky.hdr");
    let (code, _, err) = run(&["gen", "sky:sun_elev=40,width=128", "-o", sky.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let map = megaray_render::EnvMap::load(&sky).unwrap();
    assert_eq!((map.width, map.height), (128, 64));

    let exr = dir.path().join("o.exr");
    let (code, out, err) = run(&[
        "render",
        s,
        "-o",
        exr.to_str().unwrap(),
        "--res",
        "48x32",
        "--env",
        sky.to_str().unwrap(),
        "--shader",
        "env",
        "--frames",
        "4",
        "--aov",
        "depth,normal,albedo",
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["frames"], 4);
    assert!(v["rays"].as_u64().unwrap() >= 4 * 48 * 32);
    let (img, aovs) = megaray_render::read_exr(&exr).unwrap();
    assert_eq!((img.width, img.height), (48, 32));
    let depth = aovs.depth.unwrap();
    assert!(depth.iter().any(|d| d.is_finite()) && depth.iter().any(|d| d.is_infinite()));
    assert!(aovs.normal.is_some() && aovs.albedo.is_some());

    // --time stops after the time (at least one frame); the PNG is written.
    let png = dir.path().join("o.png");
    let (code, out, err) = run(&[
        "render",
        s,
        "-o",
        png.to_str().unwrap(),
        "--res",
        "32x32",
        "--sky",
        "sky",
        "--time",
        "0.2",
        "--json",
        "--exposure",
        "-1",
        "--tonemap",
        "reinhard",
    ]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert!(v["frames"].as_u64().unwrap() >= 1);
    assert_eq!(image_dims(&png), (32, 32));

    // A reference: the per-frame RMSE lines.
    let (code, _, err) = run(&[
        "render",
        s,
        "-o",
        png.to_str().unwrap(),
        "--res",
        "48x32",
        "--env",
        sky.to_str().unwrap(),
        "--shader",
        "env",
        "--frames",
        "3",
        "--reference",
        exr.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(err.lines().filter(|l| l.starts_with("frame ") && l.contains("rmse")).count(), 3, "{err}");
}

fn image_dims(p: &std::path::Path) -> (u32, u32) {
    let d = std::fs::read(p).unwrap();
    assert_eq!(&d[1..4], b"PNG");
    (u32::from_be_bytes(d[16..20].try_into().unwrap()), u32::from_be_bytes(d[20..24].try_into().unwrap()))
}
