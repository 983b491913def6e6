//! The cost of rendering a frame in pieces against at once, one thread: the overhead a
//! cluster's ranks pay per tile batch. `cargo run --release -p megaray-cluster --example
//! pieces_cost -- SCENE.mray [BATCH]`.
use std::time::Instant;

use megaray_base::Vec3;
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::Tracer;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = Scene::open(std::path::Path::new(&args[1])).expect("a scene file");
    let batch: usize = args.get(2).map_or(4, |b| b.parse().unwrap());
    let b = scene.header().bounds;
    let mut s = RenderSettings::new(Camera::framing(&b, Vec3::new(0.35, 0.25, 0.45), 1280, 960));
    s.shader = Builtin::Diffuse;
    let r = Renderer::new(s, &b);
    let tracer = Tracer::new(&scene);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    for round in 0..3 {
        let t = Instant::now();
        for f in 0..4 {
            pool.install(|| render_frame(&r, &tracer, f));
        }
        let whole = t.elapsed().as_secs_f64() / 4.0;
        let t = Instant::now();
        let tiles = Rect::tiles(1280, 960);
        for f in 0..4 {
            let mut fr = Frame::new(1280, 960, false);
            pool.install(|| {
                for c in tiles.chunks(batch) {
                    let (pieces, _) = render_pieces(&r, &tracer, f, c);
                    pieces.iter().for_each(|p| fr.put(p));
                }
            });
        }
        let pieces = t.elapsed().as_secs_f64() / 4.0;
        println!(
            "round {round}: at once {:.1} ms, in batches of {batch} tiles {:.1} ms ({:+.1}%)",
            whole * 1e3,
            pieces * 1e3,
            100.0 * (pieces / whole - 1.0)
        );
    }
}
