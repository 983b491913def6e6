//! Progressive accumulation converges like Monte Carlo: the error against a high-frame
//! reference falls roughly as 1 / sqrt(frames), and the accumulator's own estimate tracks it.

mod common;

use std::sync::Arc;

use megaray_base::Vec3;
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::Tracer;

#[test]
fn error_falls_as_one_over_sqrt_frames() {
    let dir = tempfile::tempdir().unwrap();
    let path = common::balls(dir.path(), 12, 8);
    let scene = Scene::open(&path).unwrap();
    let cam = Camera::look_at(Vec3::new(3.0, 3.0, 5.0), Vec3::new(0.0, 0.5, 0.0), Vec3::Y, 45.0, 32, 32);
    let mut s = RenderSettings::new(cam);
    s.shader = Builtin::Env;
    s.light_samples = 1;
    let env = Environment::new(SkySpec { width: 64, ..SkySpec::default() }.map(), 1024, 16);
    let r = Renderer::new(s, &scene.header().bounds).with_environment(Arc::new(env));
    let tracer = Tracer::new(&scene);
    let run = |frames| render_progressive(&r, &tracer, Stop { frames: Some(frames), time: None }, |_| {});
    let reference = run(2048).image();
    let mut acc = Accumulator::new(32, 32);
    let mut rmse = Vec::new();
    let mut estimate = Vec::new();
    for f in 0..256 {
        acc.add_frame(&render_frame(&r, &tracer, f));
        if [4, 16, 64, 256].contains(&acc.frames()) {
            rmse.push(acc.image().relative_rmse(&reference));
            estimate.push(acc.error().unwrap());
        }
    }
    // Each quadrupling of the frames should halve the error: allow 1.5 .. 3.5 (the
    // low-discrepancy sequence and the interleaving cycle can do better than Monte Carlo).
    for k in 0..3 {
        let ratio = rmse[k] / rmse[k + 1];
        assert!((1.5..=3.5).contains(&ratio), "rmse {rmse:?}: ratio {ratio} at step {k}");
    }
    // The estimate is of the right size (within a factor 3 of the true error) while the
    // reference's own error is small.
    for k in 0..3 {
        let q = estimate[k] / rmse[k];
        assert!((0.33..=3.0).contains(&q), "estimate {estimate:?} vs rmse {rmse:?}");
    }
    // Restarting gives the same frames again (deterministic samples).
    acc.reset();
    assert_eq!(acc.frames(), 0);
    acc.add_frame(&render_frame(&r, &tracer, 0));
    assert_eq!(acc.image(), run(1).image());
}

/// Adaptive sampling (`settings.adaptive`) chooses the pixels where the picture changes
/// sharply between neighbours (outlines, shadow edges, and here, under two light samples, much
/// of the noisy floor after one frame), not all, and with it a progressive run converges
/// faster to the same picture.
#[test]
fn adaptive_sampling_takes_more_samples_at_edges_and_converges_faster_to_the_same_picture() {
    let dir = tempfile::tempdir().unwrap();
    let path = common::balls(dir.path(), 12, 8);
    let scene = Scene::open(&path).unwrap();
    let cam = Camera::look_at(Vec3::new(3.0, 3.0, 5.0), Vec3::new(0.0, 0.5, 0.0), Vec3::Y, 45.0, 48, 48);
    let env = Arc::new(Environment::new(SkySpec { width: 64, ..SkySpec::default() }.map(), 1024, 16));
    let renderer = |adaptive| {
        let mut s = RenderSettings::new(cam);
        (s.shader, s.light_samples, s.adaptive) = (Builtin::Env, 2, adaptive);
        Renderer::new(s, &scene.header().bounds).with_environment(env.clone())
    };
    let tracer = Tracer::new(&scene);
    let run = |r: &Renderer, frames| render_progressive(r, &tracer, Stop { frames: Some(frames), time: None }, |_| {});
    let reference = run(&renderer(0), 2048).image();
    let plain = run(&renderer(0), 16).image().relative_rmse(&reference);
    let adaptive = renderer(16);
    let more = run(&adaptive, 16).image().relative_rmse(&reference);
    let chosen = adaptive.sampled_more();
    assert!((48..=48 * 48 * 9 / 10).contains(&chosen), "{chosen} of {} pixels chosen", 48 * 48);
    assert!(more < 0.75 * plain, "after 16 frames: {more} adaptive against {plain} without");
    // Unbiased: many frames later, the same picture as without.
    let late = run(&renderer(16), 512).image().relative_rmse(&reference);
    assert!(late < 0.6 * plain && late < 0.03, "after 512 frames {late} (16 frames without: {plain})");
    // Off (0 or 1), the frames are those of before, bit for bit.
    assert_eq!(run(&renderer(1), 3).image(), run(&renderer(0), 3).image());
}
