//! Analytic checks of the environment light: converged images equal what the rendering
//! equation gives for configurations simple enough to integrate by hand.

mod common;

use std::sync::Arc;

use common::Obj;
use megaray_base::Vec3;
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::Tracer;

/// Renders `frames` frames of the `env` shader under a constant environment of radiance
/// `l`, every light of the sample's subset per hit (so that 16 frames, one per subset, sum
/// exactly over all `lights` virtual lights).
fn converged(scene: &Scene, cam: Camera, l: f32, lights: u32, frames: u32, eps_scale: f32) -> Accumulator {
    let mut s = RenderSettings::new(cam);
    s.shader = Builtin::Env;
    s.light_samples = 0;
    s.aovs = true;
    s.eps_scale = eps_scale;
    let env = Environment::constant([l; 3], lights, 16);
    let r = Renderer::new(s, &scene.header().bounds).with_environment(Arc::new(env));
    render_progressive(&r, &Tracer::new(scene), Stop { frames: Some(frames), time: None }, |_| {})
}

#[test]
fn white_sphere_under_constant_sky_shows_albedo_times_radiance() {
    // A convex surface sees its whole upper hemisphere unoccluded: reflected radiance of a
    // Lambertian surface of albedo a under constant radiance L is a * L everywhere. The
    // sphere has no material, so a = 0.8; the facets are flat (no vertex normals), so the
    // hemisphere of each is exactly unoccluded.
    let dir = tempfile::tempdir().unwrap();
    let mut obj = Obj::default();
    obj.sphere(Vec3::ZERO, 1.0, 24, false);
    let path = obj.build(dir.path(), "sphere", None);
    let scene = Scene::open(&path).unwrap();
    let cam = Camera::look_at(Vec3::new(0.0, 1.0, 4.0), Vec3::ZERO, Vec3::Y, 40.0, 32, 32);
    let l = 1.5;
    let acc = converged(&scene, cam, l, 1024, 32, 1e-4);
    let img = acc.image();
    let depth = acc.aovs().depth.unwrap();
    let (mut n, mut worst, mut mean) = (0, 0.0f32, 0.0f32);
    for (i, p) in img.pixels.iter().enumerate() {
        let (x, y) = (i % 32, i / 32);
        // Pixels whose every sample hits the sphere: the centre ray passes well inside the
        // silhouette (a pixel is about 0.1 wide at the sphere).
        let r = cam.ray(x as f32 + 0.5, y as f32 + 0.5);
        let inside = (-r.org).cross(r.dir).length() < 0.8;
        if inside {
            assert!(depth[i].is_finite());
            for c in p {
                worst = worst.max((c / (0.8 * l) - 1.0).abs());
                mean += c;
            }
            n += 3;
        } else if depth[i].is_infinite() {
            assert_eq!(*p, [l; 3], "the sky shows the environment");
        }
    }
    mean /= n as f32;
    assert!(n > 600, "only {n} sphere samples");
    assert!((mean / (0.8 * l) - 1.0).abs() < 0.01, "mean {mean}, expected {}", 0.8 * l);
    assert!(worst < 0.02, "worst pixel off by {:.1}%", 100.0 * worst);
}

#[test]
fn plane_beside_a_wall_receives_the_analytic_fraction() {
    // A ground plane y = 0 and a wall x = 0 of height h, both very long in z. A ground
    // point at distance d from the wall: in the cross-section the wall's top is seen at
    // angle atan(d / h) from the zenith, toward the wall. For an infinitely long strip the
    // cosine-weighted fraction of the hemisphere between polar angles a and b, measured in
    // the cross-section plane, is (sin b - sin a) / 2 (the 2D view factor, Nusselt's
    // analogue). The wall covers angles from -90 degrees to -atan(d / h), so it blocks
    // (1 - d / sqrt(d^2 + h^2)) / 2, and the point receives the fraction
    // (1 + d / sqrt(d^2 + h^2)) / 2 of a * L (h infinite: one half).
    let dir = tempfile::tempdir().unwrap();
    let (big, h) = (400.0, 1.0);
    let mut obj = Obj::default();
    obj.quad([
        Vec3::new(-big, 0.0, -big),
        Vec3::new(-big, 0.0, big),
        Vec3::new(big, 0.0, big),
        Vec3::new(big, 0.0, -big),
    ]);
    obj.quad([Vec3::new(0.0, 0.0, -big), Vec3::new(0.0, h, -big), Vec3::new(0.0, h, big), Vec3::new(0.0, 0.0, big)]);
    let path = obj.build(dir.path(), "wall", None);
    let scene = Scene::open(&path).unwrap();
    for d in [0.5f32, 1.0, 3.0] {
        // Looking straight down at (d, 0, 0) with a narrow view: every pixel sees ground
        // within 0.5 % of d from the wall.
        let cam = Camera::look_at(Vec3::new(d, 0.5, 0.0), Vec3::new(d, 0.0, 0.0), Vec3::Z, 0.5, 8, 8);
        let acc = converged(&scene, cam, 1.0, 4096, 16, 1e-7);
        let img = acc.image();
        let mean: f32 = img.pixels.iter().map(|p| p[1]).sum::<f32>() / 64.0;
        let expect = 0.8 * (1.0 + d / (d * d + h * h).sqrt()) / 2.0;
        assert!((mean / expect - 1.0).abs() < 0.02, "d = {d}: {mean}, analytic {expect}");
    }
}

#[test]
fn env_lights_preserve_power_and_follow_brightness() {
    // The sky with its sun: total power within 1 %.
    let sky = SkySpec { width: 256, ..SkySpec::default() }.map();
    for (n, m) in [(1024, 16), (256, 4), (4096, 16)] {
        let lights = EnvLights::from_map(&sky, n, m);
        let (p, q) = (sky.power(), lights.power());
        let rel = ((q - p) / p).abs().max_element();
        assert!(rel < 0.01, "{n} lights: power {q} vs map {p}");
        // Every subset on its own (times M) is also near the total.
        let sub: Vec3 = lights.subset(1).iter().map(|l| l.weight).sum::<Vec3>() * m as f32;
        assert!(((sub - p) / p).abs().max_element() < 0.1, "subset power {sub} vs {p}");
    }
    // A map four times brighter in its left half: four times the lights there.
    let mut m = EnvMap::constant([1.0; 3], 64, 32);
    for y in 0..32 {
        for x in 0..32 {
            m.pixels[y * 64 + x] = [4.0; 3];
        }
    }
    let lights = EnvLights::from_map(&m, 1000, 1);
    // The left half is azimuth 0..pi, i.e. z >= 0.
    let bright = lights.all().iter().filter(|l| l.dir.z >= 0.0).count();
    assert!((790..=810).contains(&bright), "{bright} of 1000 lights in the bright half");
    assert!(((lights.power() - m.power()) / m.power()).abs().max_element() < 1e-3);
    // The sky: more lights near the sun than in the same solid angle opposite it.
    let spec = SkySpec::default();
    let lights = EnvLights::from_map(&spec.map(), 1024, 16);
    let near = |c: Vec3| lights.all().iter().filter(|l| l.dir.dot(c) > 0.98).count();
    let sun = spec.sun_dir();
    let opposite = Vec3::new(-sun.x, sun.y, -sun.z);
    assert!(near(sun) > 4 * near(opposite).max(1), "{} lights at the sun, {} opposite", near(sun), near(opposite));
}

/// The relative spread (standard deviation over mean) of the sphere's pixels after `frames`
/// frames of the `env` shader with the default settings (2 light samples, 1024 lights in 16
/// subsets) but `select`. Under a constant sky every pixel of the convex sphere converges to
/// the same value, so the spread is noise.
fn sphere_spread(select: LightSelect, frames: u32) -> f32 {
    let dir = tempfile::tempdir().unwrap();
    let mut obj = Obj::default();
    obj.sphere(Vec3::ZERO, 1.0, 24, false);
    let scene = Scene::open(&obj.build(dir.path(), "sphere", None)).unwrap();
    let cam = Camera::look_at(Vec3::new(0.0, 1.0, 4.0), Vec3::ZERO, Vec3::Y, 40.0, 32, 32);
    let mut s = RenderSettings::new(cam);
    s.shader = Builtin::Env;
    s.light_select = select;
    let env = Environment::constant([1.0; 3], 1024, 16);
    let r = Renderer::new(s, &scene.header().bounds).with_environment(Arc::new(env));
    let acc = render_progressive(&r, &Tracer::new(&scene), Stop { frames: Some(frames), time: None }, |_| {});
    let img = acc.image();
    let v: Vec<f32> = img
        .pixels
        .iter()
        .enumerate()
        .filter(|(i, _)| {
            let r = cam.ray((i % 32) as f32 + 0.5, (i / 32) as f32 + 0.5);
            (-r.org).cross(r.dir).length() < 0.8
        })
        .map(|(_, p)| luminance(Vec3::from(*p)))
        .collect();
    let mean = v.iter().sum::<f32>() / v.len() as f32;
    let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f32>() / v.len() as f32;
    var.sqrt() / mean
}

/// Light selection by contribution: a white sphere under a constant sky is smooth after 16
/// frames with the default 2 light samples (under 3 % pixel-to-pixel), where uniform
/// selection within the subset leaves it grainy.
#[test]
fn drawing_lights_by_contribution_smooths_the_sphere() {
    let by_contribution = sphere_spread(LightSelect::Contribution, 16);
    let uniform = sphere_spread(LightSelect::Uniform, 16);
    eprintln!("sphere spread after 16 frames: contribution {by_contribution:.4}, uniform {uniform:.4}");
    assert!(by_contribution < 0.03, "spread {by_contribution}");
    assert!(uniform > 2.0 * by_contribution, "uniform {uniform}, contribution {by_contribution}");
}

/// Renders the `path` shader under a constant sky of radiance `l` for `frames` frames (one
/// light sample per surface).
fn path_traced(scene: &Scene, cam: Camera, l: f32, frames: u32, max_depth: u32) -> Accumulator {
    let mut s = RenderSettings::new(cam);
    s.shader = Builtin::Path;
    s.light_samples = 0;
    s.max_depth = max_depth;
    s.aovs = true;
    let env = Environment::constant([l; 3], 1024, 16);
    let r = Renderer::new(s, &scene.header().bounds).with_environment(Arc::new(env));
    render_progressive(&r, &Tracer::new(scene), Stop { frames: Some(frames), time: None }, |_| {})
}

/// A convex object bounces nothing onto itself: under a constant sky `L` the path shader
/// shows albedo times `L`, 0.8 `L`, exactly as the direct-only shader does.
#[test]
fn path_on_a_convex_object_is_albedo_times_the_sky() {
    let dir = tempfile::tempdir().unwrap();
    let mut obj = Obj::default();
    obj.sphere(Vec3::ZERO, 1.0, 24, false);
    let scene = Scene::open(&obj.build(dir.path(), "sphere", None)).unwrap();
    let cam = Camera::look_at(Vec3::new(0.0, 1.0, 4.0), Vec3::ZERO, Vec3::Y, 40.0, 32, 32);
    let l = 1.5;
    let img = path_traced(&scene, cam, l, 512, 16).image();
    let (mut n, mut worst) = (0, 0.0f32);
    for (i, p) in img.pixels.iter().enumerate() {
        let r = cam.ray((i % 32) as f32 + 0.5, (i / 32) as f32 + 0.5);
        if (-r.org).cross(r.dir).length() < 0.8 {
            worst = p.iter().fold(worst, |w, c| w.max((c / (0.8 * l) - 1.0).abs()));
            n += 1;
        }
    }
    assert!(n > 200);
    assert!(worst < 0.02, "worst pixel off by {:.1}%", 100.0 * worst);
}

/// The white furnace: inside an open box of albedo 1 under a constant sky `L`, light
/// bounces until it leaves, and every surface converges to `L`: the box vanishes (the mean
/// within 1 %, nine pixels in ten within 3 %, every pixel within 6 % after 512 frames).
#[test]
fn path_in_a_white_furnace_converges_to_the_sky() {
    let dir = tempfile::tempdir().unwrap();
    let mut obj = Obj::default();
    obj.material("white");
    let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    // Floor and four walls of a 2 x 1 x 2 box, open at the top, facing inward.
    obj.quad([p(-1.0, 0.0, -1.0), p(-1.0, 0.0, 1.0), p(1.0, 0.0, 1.0), p(1.0, 0.0, -1.0)]);
    obj.quad([p(-1.0, 0.0, -1.0), p(1.0, 0.0, -1.0), p(1.0, 1.0, -1.0), p(-1.0, 1.0, -1.0)]);
    obj.quad([p(-1.0, 0.0, 1.0), p(-1.0, 1.0, 1.0), p(1.0, 1.0, 1.0), p(1.0, 0.0, 1.0)]);
    obj.quad([p(-1.0, 0.0, -1.0), p(-1.0, 1.0, -1.0), p(-1.0, 1.0, 1.0), p(-1.0, 0.0, 1.0)]);
    obj.quad([p(1.0, 0.0, -1.0), p(1.0, 0.0, 1.0), p(1.0, 1.0, 1.0), p(1.0, 1.0, -1.0)]);
    let scene = Scene::open(&obj.build(dir.path(), "box", Some("newmtl white\nKd 1 1 1\n"))).unwrap();
    let cam = Camera::look_at(Vec3::new(0.0, 3.5, 0.3), Vec3::new(0.0, 0.0, 0.0), Vec3::Y, 45.0, 24, 24);
    let l = 2.0;
    let acc = path_traced(&scene, cam, l, 512, 64);
    let img = acc.image();
    let depth = acc.aovs().depth.unwrap();
    let mut errors: Vec<f32> = Vec::new();
    let mut sum = 0.0f64;
    for (i, px) in img.pixels.iter().enumerate() {
        if depth[i].is_finite() {
            let v = (px[0] + px[1] + px[2]) / 3.0;
            sum += v as f64;
            errors.push((v / l - 1.0).abs());
        }
    }
    let n = errors.len();
    let mean = (sum / n as f64) as f32;
    errors.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let p90 = errors[n * 9 / 10];
    eprintln!(
        "furnace: {n} pixels, mean {mean} (sky {l}), 90th percentile {:.1}%, worst {:.1}%",
        100.0 * p90,
        100.0 * errors[n - 1]
    );
    assert!(n > 300, "only {n} pixels on the box");
    assert!((mean / l - 1.0).abs() < 0.01, "mean {mean} against the sky's {l}");
    assert!(p90 < 0.03, "nine pixels in ten within {:.1}%", 100.0 * p90);
    assert!(errors[n - 1] < 0.06, "worst pixel off by {:.1}%", 100.0 * errors[n - 1]);
}
