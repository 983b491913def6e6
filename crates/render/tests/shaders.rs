//! Every built-in shader on a small scene gives the same picture as when its reference was
//! stored (mean colour and a 4x4 downsample, within a tolerance that allows for rounding
//! differences between machines); materials come through from OBJ .mtl files and PLY
//! vertex colours.
//!
//! To store new references after an intended change:
//! `MEGARAY_BLESS=1 cargo test --release -p megaray-render --test shaders`.

mod common;

use std::path::Path;
use std::sync::Arc;

use common::Obj;
use megaray_base::{Ray, Vec3};
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::{Suspended, Tracer};

const MTL: &str = "newmtl ground\nKd 0.5 0.6 0.5\n\
newmtl shiny\nKd 0.8 0.2 0.2\nKs 0.5 0.5 0.5\nNs 60\n\
newmtl glass\nKd 1 1 1\nd 0.4\n";

fn scene(dir: &Path) -> std::path::PathBuf {
    let mut obj = Obj::default();
    // No material: white diffuse (0.8).
    obj.sphere(Vec3::new(-1.2, 0.6, 0.0), 0.6, 10, false);
    obj.material("ground");
    obj.quad([
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(-4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, -4.0),
    ]);
    obj.material("shiny");
    obj.sphere(Vec3::new(0.3, 0.7, -0.5), 0.7, 12, true);
    obj.material("glass");
    obj.sphere(Vec3::new(1.3, 0.5, 0.8), 0.5, 12, true);
    obj.build(dir, "shaders", Some(MTL))
}

fn render_with(scene: &Scene, shader: Builtin, env: bool, aovs: bool) -> (Image, Aovs) {
    let cam = Camera::look_at(Vec3::new(0.0, 2.5, 5.0), Vec3::new(0.0, 0.5, 0.0), Vec3::Y, 40.0, 32, 32);
    let mut s = RenderSettings::new(cam);
    s.shader = shader;
    s.light_samples = 2;
    s.aovs = aovs;
    let mut r = Renderer::new(s, &scene.header().bounds);
    if env {
        let sky = SkySpec { width: 64, ..SkySpec::default() };
        r = r.with_environment(Arc::new(Environment::new(sky.map(), 256, 16)));
    }
    let acc = render_progressive(&r, &Tracer::new(scene), Stop { frames: Some(4), time: None }, |_| {});
    (acc.image(), acc.aovs())
}

/// Mean colour, then the 4x4 block means, row by row.
fn signature(img: &Image) -> Vec<f32> {
    let mut out = vec![0.0; 3];
    let mut blocks = vec![0.0; 48];
    for (i, p) in img.pixels.iter().enumerate() {
        let (x, y) = (i as u32 % img.width, i as u32 / img.width);
        let b = ((y * 4 / img.height) * 4 + x * 4 / img.width) as usize;
        for k in 0..3 {
            out[k] += p[k] / img.pixels.len() as f32;
            blocks[3 * b + k] += p[k] * 16.0 / img.pixels.len() as f32;
        }
    }
    out.extend(blocks);
    out
}

fn cases() -> Vec<(String, Builtin, bool)> {
    let mut v = vec![("diffuse-sun".to_string(), Builtin::Diffuse, false), ("phong-sun".into(), Builtin::Phong, false)];
    v.extend(Builtin::ALL.iter().map(|(n, b)| (format!("{n}-sky"), *b, true)));
    v
}

#[test]
fn every_shader_gives_its_stored_picture() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::open(&scene(dir.path())).unwrap();
    let refs_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/shader_refs.txt");
    let bless = std::env::var_os("MEGARAY_BLESS").is_some();
    let stored = std::fs::read_to_string(&refs_path).unwrap_or_default();
    let mut new = String::from("# shader mean_r mean_g mean_b then 4x4 block means (r g b), row by row\n");
    for (name, shader, env) in cases() {
        let (img, _) = render_with(&scene, shader, env, false);
        let sig = signature(&img);
        assert!(sig.iter().all(|v| v.is_finite()), "{name}: not finite");
        new.push_str(&name);
        for v in &sig {
            new.push_str(&format!(" {v:.5}"));
        }
        new.push('\n');
        if bless {
            continue;
        }
        let line = stored
            .lines()
            .find(|l| l.split_whitespace().next() == Some(&name))
            .unwrap_or_else(|| panic!("{name}: no stored reference (run with MEGARAY_BLESS=1)"));
        let want: Vec<f32> = line.split_whitespace().skip(1).map(|v| v.parse().unwrap()).collect();
        assert_eq!(want.len(), sig.len());
        for (k, (a, b)) in sig.iter().zip(&want).enumerate() {
            let tol = if k < 3 { 0.005 } else { 0.03 };
            assert!((a - b).abs() <= tol + 0.01 * b.abs(), "{name}: value {k} is {a}, stored {b}");
        }
    }
    if bless {
        std::fs::write(&refs_path, new).unwrap();
    }
}

#[test]
fn shaders_differ_and_materials_come_through() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::open(&scene(dir.path())).unwrap();
    let (img, aovs) = render_with(&scene, Builtin::Normal, false, true);
    // The albedo layer holds the .mtl colours and the default 0.8 where there is no material.
    let cam = Camera::look_at(Vec3::new(0.0, 2.5, 5.0), Vec3::new(0.0, 0.5, 0.0), Vec3::Y, 40.0, 32, 32);
    let albedo = aovs.albedo.unwrap();
    let at = |p: Vec3| {
        let d = (p - cam.eye).normalize();
        // The pixel whose centre ray points closest to p.
        (0..32 * 32)
            .max_by(|&a, &b| {
                let da = cam.ray((a % 32) as f32 + 0.5, (a / 32) as f32 + 0.5).dir.dot(d);
                let db = cam.ray((b % 32) as f32 + 0.5, (b / 32) as f32 + 0.5).dir.dot(d);
                da.total_cmp(&db)
            })
            .unwrap()
    };
    let near = |a: [f32; 3], b: [f32; 3]| (0..3).all(|k| (a[k] - b[k]).abs() < 0.02);
    assert!(near(albedo[at(Vec3::new(-1.2, 0.6, 0.6))], [0.8; 3]), "{:?}", albedo[at(Vec3::new(-1.2, 0.6, 0.6))]);
    assert!(near(albedo[at(Vec3::new(0.3, 0.7, 0.2))], [0.8, 0.2, 0.2]));
    assert!(near(albedo[at(Vec3::new(-2.5, 0.0, 2.0))], [0.5, 0.6, 0.5]));
    // Normals face the camera.
    assert!(img.pixels.iter().all(|p| p.iter().all(|c| (0.0..=1.0).contains(c))));
    // Glass and mirror show something different from diffuse.
    let sig = |b| signature(&render_with(&scene, b, true, false).0);
    let d = sig(Builtin::Env);
    for b in [Builtin::Mirror, Builtin::Glass, Builtin::Ao, Builtin::Auto] {
        let s = sig(b);
        let diff: f32 = s.iter().zip(&d).map(|(a, b)| (a - b).abs()).sum();
        assert!(diff > 0.1, "{b:?} looks like env");
    }
}

#[test]
fn ply_vertex_colours_are_the_albedo() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("tri.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nelement face 2\n\
         property list uchar int vertex_indices\nend_header\n\
         -1 -1 0 255 0 0\n1 -1 0 255 0 0\n1 1 0 255 0 0\n-1 1 0 255 0 0\n3 0 1 2\n3 0 2 3\n",
    )
    .unwrap();
    let scene = Scene::open(&common::build_file(dir.path(), &ply, "tri")).unwrap();
    let cam = Camera::look_at(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, Vec3::Y, 20.0, 8, 8);
    let mut s = RenderSettings::new(cam);
    s.aovs = true;
    s.shader = Builtin::Env;
    let r = Renderer::new(s, &scene.header().bounds);
    let f = render_frame(&r, &Tracer::new(&scene), 0);
    assert!(f.albedo.iter().all(|a| (a[0] - 1.0).abs() < 1e-3 && a[1] < 1e-3 && a[2] < 1e-3), "{:?}", f.albedo[0]);
    assert!(f.depth.iter().all(|d| (d - 3.0).abs() < 0.1));
}

/// A user shader in a test, through the public interface only: counts the shadow rays it
/// fires, and shows that a suspension passes through `sample`.
struct Checker;
impl Shader for Checker {
    fn shade(&self, _ray: &Ray, hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>) -> Result<Vec3, Suspended> {
        let up = ctx.spawn(hit, Vec3::Y);
        Ok(if ctx.occluded(&up)? { Vec3::ZERO } else { Vec3::ONE })
    }
}

/// A caster that suspends every ray after the first `budget`.
struct Paged<'a> {
    tracer: &'a Tracer<'a>,
    budget: u32,
}
impl megaray_trace::RayCaster for Paged<'_> {
    fn scene(&self) -> &Scene {
        self.tracer.scene()
    }
    fn intersect(&mut self, ray: &Ray) -> Result<Option<megaray_trace::Hit>, Suspended> {
        if self.budget == 0 {
            return Err(Suspended);
        }
        self.budget -= 1;
        Ok(self.tracer.intersect(ray))
    }
    fn occluded(&mut self, ray: &Ray) -> Result<bool, Suspended> {
        if self.budget == 0 {
            return Err(Suspended);
        }
        self.budget -= 1;
        Ok(self.tracer.occluded(ray))
    }
}

#[test]
fn custom_shader_and_suspension() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::open(&scene(dir.path())).unwrap();
    let cam = Camera::look_at(Vec3::new(0.0, 2.5, 5.0), Vec3::new(0.0, 0.5, 0.0), Vec3::Y, 40.0, 32, 32);
    let r = Renderer::new(RenderSettings::new(cam), &scene.header().bounds).with_shader(Arc::new(Checker));
    let tracer = Tracer::new(&scene);
    // Pixel (16, 20) sees the ground or a sphere: two rays.
    let whole = r.sample(16, 20, 5, &mut &tracer).unwrap();
    assert_eq!(whole.rays, 2);
    assert_eq!(r.sample(16, 20, 5, &mut Paged { tracer: &tracer, budget: 1 }), Err(Suspended));
    // Re-run with the data there: the same answer as without paging.
    assert_eq!(r.sample(16, 20, 5, &mut Paged { tracer: &tracer, budget: 2 }), Ok(whole));
    for (name, b) in Builtin::ALL {
        let s = RenderSettings { shader: b, ..RenderSettings::new(cam) };
        let r = Renderer::new(s, &scene.header().bounds);
        let full = r.sample(16, 20, 3, &mut &tracer).unwrap();
        assert_eq!(r.sample(16, 20, 3, &mut Paged { tracer: &tracer, budget: full.rays }), Ok(full), "{name}");
        if full.rays > 1 {
            let short = Paged { tracer: &tracer, budget: full.rays - 1 };
            assert_eq!(r.sample(16, 20, 3, &mut { short }), Err(Suspended), "{name}");
        }
    }
}
