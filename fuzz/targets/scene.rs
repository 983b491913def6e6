//! A scene file: opened for a pager (every tile loaded, checked, released), opened in core
//! (header and tables checked), every tile checked, and, when all pass, rays traced through it (the traversal must stay inside what the checks allowed).
//! Checksums are off in fuzzing builds (`cfg(fuzzing)`), so mutations reach the checks.
use megaray_base::{Ray, Vec3};
use megaray_scene::Scene;
use megaray_trace::Tracer;

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let path = megaray_fuzz::file("input.mray", data);
        // Opened for a pager (tables only), then every tile loaded, checked and released;
        // then opened in core.
        if let Ok(owned) = Scene::open_owned(&path) {
            for t in 0..owned.tiles().len() as u32 {
                let ranges = owned.tile_ranges(t).unwrap_or_default();
                if ranges.iter().all(|&(o, l)| owned.load(o, l).is_ok()) {
                    let _ = owned.check_tile(t);
                }
                for &(o, l) in &ranges {
                    let _ = owned.release(o, l);
                }
            }
        }
        let Ok(scene) = Scene::open(&path) else { return };
        if !scene.check_all_tiles() {
            return;
        }
        let tracer = Tracer::new(&scene);
        let b = scene.header().bounds;
        let (lo, hi) = (b.lo(), b.hi());
        let c = (lo + hi) * 0.5;
        if !c.is_finite() {
            return;
        }
        for i in 0..16 {
            let a = i as f32 * 0.7;
            let d = Vec3::new(a.cos(), (a * 1.3).sin(), a.sin()).normalize_or(Vec3::X);
            let _ = tracer.intersect(&Ray::new(c - d * (hi - lo).length().min(1e30), d));
            let _ = tracer.occluded(&Ray::new(c, d));
        }
    });
}
