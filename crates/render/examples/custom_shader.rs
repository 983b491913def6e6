//! A shader of your own, without touching the tracer: a "toon" shader that bands the
//! light under the environment into three steps and draws dark outlines where the surface
//! turns away from the eye, plus a reflection ray on surfaces facing up (a wet floor).
//! It fires rays only through its `ShadeCtx`, so it works unchanged on a paging tracer.
//!
//! ```sh
//! cargo run --release -p megaray-render --example custom_shader [OUT.png]
//! ```

use std::sync::Arc;

use megaray_base::{NoProgress, Ray, Vec3};
use megaray_build::{build_scene, BuildOptions};
use megaray_render::{
    render_progressive, Camera, Environment, RenderSettings, Renderer, ShadeCtx, Shader, SkySpec, Stop, SurfaceHit,
    CLOSE_OFFSET,
};
use megaray_scene::Scene;
use megaray_trace::{Suspended, Tracer};

/// Banded diffuse light, outlines, and a faint reflection on upward-facing surfaces.
struct Toon {
    bands: f32,
}

impl Shader for Toon {
    fn shade(&self, ray: &Ray, hit: &SurfaceHit, ctx: &mut ShadeCtx<'_>) -> Result<Vec3, Suspended> {
        // Outlines: the surface seen nearly edge-on.
        if hit.ns.dot(hit.wo) < 0.2 {
            return Ok(Vec3::splat(0.02));
        }
        // The diffuse light of the environment (shadow rays through the context), banded.
        let albedo = ctx.material(hit).albedo;
        let light = ctx.env_direct(hit, |_| Vec3::splat(1.0 / std::f32::consts::PI))?;
        let level = (light.length() / 3f32.sqrt()).min(1.0);
        let banded = (level * self.bands).ceil() / self.bands;
        let mut c = albedo * banded;
        // A reflection ray, shaded recursively (by this shader), on floors.
        if hit.ns.y > 0.9 {
            let d = ray.dir - hit.ns * (2.0 * ray.dir.dot(hit.ns));
            c += ctx.trace(&ctx.spawn(hit, d))? * 0.3;
        }
        Ok(c)
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).unwrap_or_else(|| "custom_shader.png".into());
    let dir = tempfile::tempdir()?;
    let model = dir.path().join("flake.ply");
    megaray_gen::write_ply(&"sphereflake:2".parse()?, &model, &NoProgress)?;
    let scene_path = dir.path().join("flake.mray");
    build_scene(&[model], &scene_path, &BuildOptions::default(), &NoProgress)?;
    let scene = Scene::open(&scene_path)?;

    let bounds = scene.header().bounds;
    let mut settings = RenderSettings::new(Camera::framing(&bounds, CLOSE_OFFSET, 640, 480));
    settings.light_samples = 0; // every light of the pixel's subset: smoother bands

    let sky = Environment::new(SkySpec::default().map(), 1024, 16);
    let renderer =
        Renderer::new(settings, &bounds).with_environment(Arc::new(sky)).with_shader(Arc::new(Toon { bands: 3.0 }));
    let acc = render_progressive(&renderer, &Tracer::new(&scene), Stop { frames: Some(8), time: None }, |a| {
        eprintln!("frame {}", a.frames())
    });
    acc.image().save_png(out.as_ref())?;
    println!("wrote {out}");
    Ok(())
}
