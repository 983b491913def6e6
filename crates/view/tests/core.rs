//! The view core without a window: scripted input gives the expected camera poses; a still
//! camera accumulates frames and converges to the picture `megaray render` makes of the same
//! pose; a move starts the accumulation again.

use megaray_base::Vec3;
use megaray_render::{render_progressive, RenderSettings, Renderer, Stop};
use megaray_scene::Scene;
use megaray_testkit::*;
use megaray_trace::Tracer;
use megaray_view::{Event, FlyCamera, Key, Script, Step, ViewCore, ViewOptions};

fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
    (a - b).length() <= tol
}

#[test]
fn scripted_input_moves_the_camera_as_expected() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = build(dir.path(), &[model("stanford-bunny.obj")], "bunny", None);
    let scene = Scene::open(&path).unwrap();
    let tracer = Tracer::new(&scene);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let opts = ViewOptions { frame_budget: None, ..ViewOptions::new(64, 48) };
    let mut view = ViewCore::new(&tracer, &pool, opts);
    let home = FlyCamera::home(&scene.header().bounds, 60.0);
    assert_eq!(view.pose(), home.pose);
    let script = Script::parse(
        "# one second forward at 30 frames a second\nkey forward down\nframes 30\nkey forward up\n\
         drag 100 -20\nframes 1\nwheel 1\nkey up down\nframes 15\nkey up up\n",
    )
    .unwrap();
    let mut poses = Vec::new();
    for step in &script.steps {
        match step {
            Step::Input(e) => view.handle(*e),
            Step::Frames(n) => {
                for _ in 0..*n {
                    assert!(view.step(1.0 / 30.0));
                }
                poses.push(view.pose());
            }
        }
    }
    let f = home.pose.forward();
    let after_fly = home.pose.eye + f * home.speed;
    assert!(close(poses[0].eye, after_fly, 1e-3 * home.speed), "{:?} vs {after_fly:?}", poses[0].eye);
    // The drag turned right (yaw down) and looked up, without moving the eye.
    assert!((poses[1].yaw - (home.pose.yaw - 0.5)).abs() < 1e-5);
    assert!((poses[1].pitch - (home.pose.pitch + 0.1)).abs() < 1e-5);
    assert_eq!(poses[1].eye, poses[0].eye);
    // Half a second up at 1.2 times the speed.
    let up = poses[1].eye + Vec3::Y * (1.2 * home.speed * 0.5);
    assert!(close(poses[2].eye, up, 1e-3 * home.speed), "{:?} vs {up:?}", poses[2].eye);
    // R goes home, keeping the speed; F frames the model; Escape asks to quit.
    view.handle(Event::Key(Key::Reset, true));
    assert_eq!(view.pose(), home.pose);
    view.handle(Event::Key(Key::Frame, true));
    let d = (view.pose().eye - scene.header().bounds.center()).length();
    assert!(d > 0.5 * scene.header().bounds.diagonal() && d < 3.0 * scene.header().bounds.diagonal());
    assert!(!view.quit_requested());
    view.handle(Event::Key(Key::Quit, true));
    assert!(view.quit_requested());
    // A bad script line is an error naming it.
    let e = Script::parse("frames 2\nkey jump down\n").unwrap_err();
    assert_eq!(e.line, 2);
    assert!(e.msg.contains("jump"), "{e}");
}

#[test]
fn a_still_camera_converges_to_the_rendered_image_and_a_move_starts_again() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = build(dir.path(), &[model("stanford-bunny.obj")], "bunny", None);
    let scene = Scene::open(&path).unwrap();
    let tracer = Tracer::new(&scene);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let opts = ViewOptions { frame_budget: None, ..ViewOptions::new(80, 60) };
    let mut view = ViewCore::new(&tracer, &pool, opts);
    for _ in 0..6 {
        view.step(1.0 / 30.0);
    }
    assert_eq!(view.stats().frames, 6);
    // `megaray render` of the same pose, 6 frames.
    let cam = view.pose().camera(60.0, 80, 60);
    let r = Renderer::new(RenderSettings::new(cam), &scene.header().bounds);
    let want = pool.install(|| render_progressive(&r, &tracer, Stop { frames: Some(6), time: None }, |_| {}));
    assert_eq!(view.image().pixels, want.image().pixels, "the view's accumulated frames differ from render's");
    let (w, h, rgb) = view.display();
    assert_eq!((w, h, rgb.len()), (80, 60, 80 * 60 * 3));
    assert!(rgb.chunks(3).any(|p| p != rgb[..3].as_ref()), "a blank display");
    // A move starts the accumulation again.
    view.handle(Event::Drag(5.0, 0.0));
    view.step(1.0 / 30.0);
    assert_eq!(view.stats().frames, 1);
    assert!(view.stats().moving);
    view.step(1.0 / 30.0);
    assert_eq!(view.stats().frames, 2);
    // A new size renders at it.
    view.handle(Event::Resize(40, 30));
    view.step(1.0 / 30.0);
    assert_eq!(view.display().0, 40);
    assert_eq!((view.stats().width, view.stats().height), (40, 30));
}

#[test]
fn with_a_budget_moving_frames_are_smaller_and_still_ones_full() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = build(dir.path(), &[model("stanford-bunny.obj")], "bunny", None);
    let scene = Scene::open(&path).unwrap();
    let tracer = Tracer::new(&scene).with_lod_error(1.0);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let mut view = ViewCore::new(&tracer, &pool, ViewOptions::new(320, 240));
    view.handle(Event::Key(Key::Forward, true));
    view.step(0.05);
    assert!(view.stats().moving && view.stats().width < 320, "{:?}", view.stats());
    view.handle(Event::Key(Key::Forward, false));
    view.step(0.05);
    assert!(!view.stats().moving);
    assert_eq!((view.stats().width, view.stats().height), (320, 240));
    // C cycles the shader, H shows the help (drawn over the display).
    let before = view.shader();
    view.handle(Event::Key(Key::NextShader, true));
    assert_ne!(view.shader(), before);
    let plain = view.display().2.to_vec();
    view.handle(Event::Key(Key::Help, true));
    assert_ne!(view.display().2, &plain[..]);
}
