//! Area lights against what the rendering equation gives: a glowing closed box (emission,
//! bounces and light samples weighed by multiple importance sampling must add up to
//! `L / (1 - albedo)`), and a floor under a small lamp (next-event estimation against a
//! quadrature of the lamp's irradiance).

mod common;

use std::sync::Arc;

use common::Obj;
use megaray_base::Vec3;
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::Tracer;

/// The triangles of `quads`, as `Obj::quad` splits them.
fn triangles(quads: &[[Vec3; 4]]) -> Vec<[Vec3; 3]> {
    quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect()
}

fn material(scene: &Scene, name: &str) -> u32 {
    scene.materials().iter().position(|m| m.name == name).unwrap() as u32
}

/// `frames` frames of the `path` shader, black sky, lit by `lights`.
fn path_traced(scene: &Scene, cam: Camera, lights: &[AreaLight], frames: u32, max_depth: u32) -> Accumulator {
    let mut s = RenderSettings::new(cam);
    s.shader = Builtin::Path;
    s.max_depth = max_depth;
    s.sky = [0.0; 3];
    s.aovs = true;
    let r = Renderer::new(s, &scene.header().bounds).with_area_lights(Arc::new(AreaLights::new(lights)));
    render_progressive(&r, &Tracer::new(scene), Stop { frames: Some(frames), time: None }, |_| {})
}

/// Inside a closed box whose walls all emit `L` and reflect half of what they receive,
/// every wall shows `L (1 + 1/2 + 1/4 + ...) = 2 L`: the mean within 1 %, nine pixels in
/// ten within 4 %.
#[test]
fn a_glowing_closed_box_converges_to_emission_over_one_minus_albedo() {
    let dir = tempfile::tempdir().unwrap();
    let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    // A 2 x 2 x 2 cube, wound so that its faces' fronts point inward.
    let quads = [
        [p(-1.0, -1.0, -1.0), p(-1.0, -1.0, 1.0), p(1.0, -1.0, 1.0), p(1.0, -1.0, -1.0)],
        [p(-1.0, 1.0, -1.0), p(1.0, 1.0, -1.0), p(1.0, 1.0, 1.0), p(-1.0, 1.0, 1.0)],
        [p(-1.0, -1.0, -1.0), p(1.0, -1.0, -1.0), p(1.0, 1.0, -1.0), p(-1.0, 1.0, -1.0)],
        [p(-1.0, -1.0, 1.0), p(-1.0, 1.0, 1.0), p(1.0, 1.0, 1.0), p(1.0, -1.0, 1.0)],
        [p(-1.0, -1.0, -1.0), p(-1.0, 1.0, -1.0), p(-1.0, 1.0, 1.0), p(-1.0, -1.0, 1.0)],
        [p(1.0, -1.0, -1.0), p(1.0, -1.0, 1.0), p(1.0, 1.0, 1.0), p(1.0, 1.0, -1.0)],
    ];
    let mut obj = Obj::default();
    obj.material("glow");
    for q in quads {
        obj.quad(q);
    }
    let scene = Scene::open(&obj.build(dir.path(), "box", Some("newmtl glow\nKd 0.5 0.5 0.5\n"))).unwrap();
    // One-sided, the front inward: the check that the winding is the emitting side.
    let l = 1.5;
    let lights = [AreaLight {
        material: material(&scene, "glow"),
        radiance: Vec3::splat(l),
        two_sided: false,
        triangles: triangles(&quads),
    }];
    let cam = Camera::look_at(Vec3::new(0.2, 0.3, 0.9), Vec3::new(-0.3, -0.5, -1.0), Vec3::Y, 90.0, 24, 24);
    let img = path_traced(&scene, cam, &lights, 256, 64).image();
    let want = 2.0 * l;
    let mut errors: Vec<f32> = img.pixels.iter().map(|px| ((px[0] + px[1] + px[2]) / 3.0 / want - 1.0).abs()).collect();
    let mean = img.pixels.iter().map(|px| (px[0] + px[1] + px[2]) as f64 / 3.0).sum::<f64>() / errors.len() as f64;
    errors.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let p90 = errors[errors.len() * 9 / 10];
    eprintln!("glowing box: mean {mean:.4} (want {want}), 90th percentile {:.1}%", 100.0 * p90);
    assert!((mean as f32 / want - 1.0).abs() < 0.01, "mean {mean} against {want}");
    assert!(p90 < 0.04, "nine pixels in ten within {:.1}%", 100.0 * p90);
}

/// A floor of albedo 0.6 under a small square lamp facing down (and nothing else: the lamp
/// reflects nothing, the sky is black): each floor point shows `0.6 / pi` times the lamp's
/// irradiance there, which a quadrature over the lamp gives. Within 3 % on average over
/// the floor in view, and the lamp itself shows its radiance.
#[test]
fn a_floor_under_a_lamp_shows_its_irradiance() {
    let dir = tempfile::tempdir().unwrap();
    let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let (h, half, l) = (1.0, 0.25, 20.0);
    let lamp = [p(-half, h, -half), p(half, h, -half), p(half, h, half), p(-half, h, half)];
    let mut obj = Obj::default();
    obj.material("floor");
    obj.quad([p(-3.0, 0.0, -3.0), p(-3.0, 0.0, 3.0), p(3.0, 0.0, 3.0), p(3.0, 0.0, -3.0)]);
    obj.material("lamp");
    obj.quad(lamp);
    let mtl = "newmtl floor\nKd 0.6 0.6 0.6\nnewmtl lamp\nKd 0 0 0\n";
    let scene = Scene::open(&obj.build(dir.path(), "lamp", Some(mtl))).unwrap();
    let lights = [AreaLight {
        material: material(&scene, "lamp"),
        radiance: Vec3::splat(l),
        two_sided: false,
        triangles: triangles(&[lamp]),
    }];
    // The lamp's winding (a, b, c) faces down: the floor is lit.
    let cam = Camera::look_at(Vec3::new(0.0, 2.2, 2.0), Vec3::new(0.0, 0.3, 0.0), Vec3::Y, 60.0, 32, 32);
    let img = path_traced(&scene, cam, &lights, 256, 8).image();
    let irradiance = |x: Vec3| {
        let n = 100;
        let mut e = 0.0f64;
        for i in 0..n {
            for j in 0..n {
                let q = p(
                    -half + 2.0 * half * (i as f32 + 0.5) / n as f32,
                    h,
                    -half + 2.0 * half * (j as f32 + 0.5) / n as f32,
                );
                let d = q - x;
                let r2 = d.length_squared();
                e += ((d.y / r2.sqrt()).powi(2) / r2) as f64;
            }
        }
        (e * (2.0 * half as f64).powi(2) / (n * n) as f64) as f32 * l
    };
    let (mut got, mut want, mut lamp_px) = (0.0f64, 0.0f64, 0);
    for (i, px) in img.pixels.iter().enumerate() {
        let r = cam.ray((i % 32) as f32 + 0.5, (i / 32) as f32 + 0.5);
        let lamp_t = (h - r.org.y) / r.dir.y;
        let on_lamp = lamp_t > 0.0 && {
            let q = r.org + r.dir * lamp_t;
            q.x.abs() < half * 0.7 && q.z.abs() < half * 0.7
        };
        if on_lamp {
            // Seen from above: its back, which emits nothing.
            assert!(px[0] < 1e-3, "the lamp's back shows {px:?}");
            lamp_px += 1;
            continue;
        }
        let t = -r.org.y / r.dir.y;
        let x = r.org + r.dir * t;
        if t > 0.0 && x.x.abs() < 2.9 && x.z.abs() < 2.9 && (x.x.abs() > half * 1.5 || x.z.abs() > half * 1.5) {
            got += px[1] as f64;
            want += (0.6 / std::f32::consts::PI * irradiance(x)) as f64;
        }
    }
    assert!(lamp_px > 4, "the lamp is in view");
    eprintln!("floor under a lamp: {got:.3} against {want:.3}");
    assert!((got / want - 1.0).abs() < 0.03, "floor {got} against {want}");
}
