//! Rigid motion: the time to rebuild the instance trees when every one of N instances moves
//! (the seed rebuilds its top level every frame). `cargo run --release -p megaray-trace
//! --example instance_rebuild -- 1000000` builds a scene of one small object placed N times,
//! then moves all instances each frame and prints each rebuild's time and a ray count that
//! shows the moved scene is traced.

use megaray_base::{Affine, Camera, Vec3};
use megaray_build::InstancePlan;
use megaray_scene::{Group, Instance, Scene, Target};
use megaray_trace::Tracer;

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(1_000_000);
    let dir = tempfile::tempdir().unwrap();
    let side = (n as f64).sqrt().ceil() as usize;
    let place = |k: usize, frame: f32| {
        let (x, z) = ((k % side) as f32 * 3.0, (k / side) as f32 * 3.0);
        Affine::translation(Vec3::new(x, (frame * 0.1 + k as f32 * 0.37).sin(), z))
            .then_after(&Affine::rotation(frame * 10.0 + k as f32, Vec3::Y))
    };
    let plan = InstancePlan {
        groups: vec![Group { name: "field".into(), first: 0, count: n as u32 }],
        instances: (0..n)
            .map(|k| Instance { name: String::new(), xform: place(k, 0.0), target: Target::Object(0), material: None })
            .collect(),
    };
    let object = megaray_testkit::sphere([0.0; 3], 1.0, 16);
    let opts = megaray_build::BuildOptions { threads: 2, ..megaray_testkit::test_options() };
    let (path, s) = megaray_testkit::build_instanced(dir.path(), "field", &[object], &plan, opts);
    let scene = Scene::open(&path).unwrap();
    println!("{n} instances of {} triangles; file {} bytes", s.triangles, s.file_bytes);
    let t = std::time::Instant::now();
    let mut tracer = Tracer::new(&scene);
    println!("tracer made (trees built) in {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    let b = scene.header().bounds;
    let cam = Camera::look_at(
        b.center() + Vec3::new(0.0, b.diagonal() * 0.3, -b.diagonal() * 0.3),
        b.center(),
        Vec3::Y,
        60.0,
        256,
        256,
    );
    let mut times = Vec::new();
    for frame in 1..=10 {
        for k in 0..n {
            tracer.set_instance_transform(k, place(k, frame as f32));
        }
        let dt = tracer.rebuild_instances();
        times.push(dt.as_secs_f64() * 1e3);
        let hits = (0..256 * 256)
            .filter(|i| tracer.intersect(&cam.ray((i % 256) as f32 + 0.5, (i / 256) as f32 + 0.5)).is_some())
            .count();
        println!("frame {frame}: top-level rebuild {:.1} ms, {hits} of 65536 camera rays hit", dt.as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "median rebuild {:.1} ms (min {:.1}, max {:.1})",
        times[times.len() / 2],
        times[0],
        times[times.len() - 1]
    );
}
