//! The library in one page: make a model, build its scene file, open it, trace a ray,
//! render an image.
//!
//! ```sh
//! cargo run --release -p megaray-render --example quickstart [OUT.png]
//! ```

use megaray_base::{NoProgress, Ray, Vec3};
use megaray_build::{build_scene, BuildOptions};
use megaray_render::{render, Camera, RenderSettings, CLOSE_OFFSET};
use megaray_scene::Scene;
use megaray_trace::Tracer;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).unwrap_or_else(|| "quickstart.png".into());
    let dir = tempfile::tempdir()?;

    // 1. A model: a sphere flake of 91 spheres, as a binary PLY (any PLY/OBJ/STL/glTF works).
    let model = dir.path().join("flake.ply");
    megaray_gen::write_ply(&"sphereflake:2".parse()?, &model, &NoProgress)?;

    // 2. The scene file, built out of core (here small parts, to show the two-level tree).
    let scene_path = dir.path().join("flake.mray");
    let opts = BuildOptions { max_part_tris: Some(10_000), ..BuildOptions::default() };
    let summary = build_scene(&[model], &scene_path, &opts, &NoProgress)?;
    println!("built {} triangles into {} parts", summary.triangles, summary.parts);

    // 3. Open it (memory-mapped, checked) and trace one ray down onto the root sphere.
    let scene = Scene::open(&scene_path)?;
    let tracer = Tracer::new(&scene);
    let ray = Ray::new(Vec3::new(0.0, 10.0, 0.0), -Vec3::Y);
    match tracer.intersect(&ray) {
        Some(hit) => println!("ray hits part {} triangle {} at distance {:.4}", hit.part, hit.prim, hit.t),
        None => println!("ray misses"),
    }

    // 4. Render an image from the close benchmark camera and save it.
    let camera = Camera::framing(&scene.header().bounds, CLOSE_OFFSET, 640, 480);
    let mut settings = RenderSettings::new(camera);
    settings.spp = 4;
    let image = render(&tracer, &settings);
    if let Some(e) = scene.first_error() {
        return Err(e.into());
    }
    image.save_png(out.as_ref())?;
    println!("wrote {out}");
    Ok(())
}
