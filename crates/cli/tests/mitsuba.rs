//! The `path` shader against Mitsuba 3, a renderer no one here wrote: the same scene (an open
//! box of diffuse walls with a diffuse sphere, under a constant sky) rendered by megaray is
//! compared with Mitsuba's converged image, stored with the scene in
//! `crates/render/tests/data/mitsuba` (made by its `compare.py`, which also runs the
//! comparison end to end where Mitsuba is installed).

mod common;
use common::*;

use std::path::PathBuf;

fn data(name: &str) -> String {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../render/tests/data/mitsuba").join(name);
    p.to_string_lossy().into_owned()
}

#[test]
fn the_path_shader_matches_mitsuba_on_the_open_box() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("box.mray").to_string_lossy().into_owned();
    let (code, _, err) = run(&["build", &data("box.obj"), "-o", &scene, "-q"]);
    assert_eq!(code, 0, "{err}");
    let out = dir.path().join("box.exr").to_string_lossy().into_owned();
    let sky = data("sky.hdr");
    let args = [
        "render",
        &scene,
        "-o",
        &out,
        "-q",
        "--shader",
        "path",
        "--env",
        &sky,
        "--res",
        "160x120",
        "--frames",
        "256",
        "--max-depth",
        "64",
        "--fov",
        "40",
        "--eye",
        "0,1.3,4.2",
        "--at",
        "0,0.8,0",
    ];
    let (code, _, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let (ours, _) = megaray_render::read_exr(std::path::Path::new(&out)).unwrap();
    let (theirs, _) = megaray_render::read_exr(std::path::Path::new(&data("box-mitsuba.exr"))).unwrap();
    assert_eq!((ours.width, ours.height), (theirs.width, theirs.height));
    let flat = |i: &megaray_render::Image| i.pixels.iter().flatten().map(|&v| v as f64).collect::<Vec<_>>();
    let (a, b) = (flat(&ours), flat(&theirs));
    let mean = b.iter().sum::<f64>() / b.len() as f64;
    let mad = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).sum::<f64>() / b.len() as f64 / mean;
    let bias = (a.iter().sum::<f64>() / a.len() as f64 - mean) / mean;
    // Measured: 0.9 % after 256 frames (noise; 0.2 % after 4,096), bias under 0.1 %.
    assert!(mad < 0.02, "mean absolute difference {:.2} % of the mean", 100.0 * mad);
    assert!(bias.abs() < 0.005, "mean off by {:.2} %", 100.0 * bias);
}
