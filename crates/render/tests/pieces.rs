//! A frame rendered in pieces (rectangles in any order, on any tracer) and put together is
//! the frame rendered at once, bit for bit: what a cluster of processes relies on.

mod common;

use std::sync::Arc;

use megaray_base::Vec3;
use megaray_page::{Pager, PagerOptions};
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::Tracer;

/// The balls scene in `dir`, a camera on it 75 x 41 (not a multiple of the tile edge, so
/// that edge tiles are cut), and a pager over it with little room.
fn balls(dir: &std::path::Path) -> (Scene, Camera, Pager) {
    let path = common::balls(dir, 48, 16);
    let scene = Scene::open(&path).unwrap();
    let cam = Camera::look_at(Vec3::new(3.0, 3.0, 5.0), Vec3::new(0.0, 0.5, 0.0), Vec3::Y, 45.0, 75, 41);
    let pager =
        Pager::open(&path, PagerOptions { budget: Pager::min_budget(&scene) + 256 * 1024, fetchers: 2 }).unwrap();
    (scene, cam, pager)
}

fn bits(f: &Frame) -> Vec<u32> {
    f.image.pixels.iter().flatten().map(|v| v.to_bits()).collect()
}

#[test]
fn pieces_put_together_equal_the_whole_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, cam, pager) = balls(dir.path());
    let (w, h) = (cam.width, cam.height);
    for aovs in [false, true] {
        for spp in [1, 3] {
            let mut s = RenderSettings::new(cam);
            s.shader = Builtin::Env;
            s.light_samples = 2;
            s.spp = spp;
            s.aovs = aovs;
            let env = Environment::new(SkySpec { width: 64, ..SkySpec::default() }.map(), 256, 8);
            let r = Renderer::new(s, &scene.header().bounds).with_environment(Arc::new(env));
            let whole = render_frame(&r, &Tracer::new(&scene), 5);
            // Tiles in reverse, in batches of 3, on the in-core and on a paged tracer.
            let mut tiles = Rect::tiles(w, h);
            tiles.reverse();
            for tracer in [Tracer::new(&scene), Tracer::paged(&pager)] {
                let mut f = Frame::new(w, h, aovs);
                let mut secs = 0.0;
                for batch in tiles.chunks(3) {
                    let (pieces, stats) = render_pieces(&r, &tracer, 5, batch);
                    assert_eq!(stats.finished, batch.iter().map(|t| t.area() as u64).sum::<u64>());
                    for p in &pieces {
                        f.put(p);
                        // What each tile cost (sampled on a paged tracer: an edge tile may show 0).
                        assert!(p.secs.is_finite() && p.secs >= 0.0, "{:?} took {} s", p.rect, p.secs);
                        secs += p.secs;
                    }
                }
                assert!(secs > 0.0, "no piece measured its cost");
                assert_eq!(bits(&f), bits(&whole), "aovs {aovs} spp {spp} paged {}", tracer.pager().is_some());
                assert_eq!(f.rays, whole.rays);
                if aovs {
                    assert_eq!(f.depth, whole.depth);
                    assert_eq!(f.normal, whole.normal);
                    assert_eq!(f.albedo, whole.albedo);
                }
            }
        }
    }
}

/// A frame rendered into the buffers of one done with (`Renderer::recycle`) is the frame
/// rendered fresh, and what a deadline leaves is black, not the old frame's pixels.
#[test]
fn recycled_buffers_give_the_same_frames() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, cam, pager) = balls(dir.path());
    for tracer in [Tracer::new(&scene), Tracer::paged(&pager)] {
        let r = Renderer::new(RenderSettings::new(cam), &scene.header().bounds);
        let fresh = render_frame(&r, &tracer, 5);
        for _ in 0..2 {
            r.recycle(render_frame(&r, &tracer, 6));
            let again = render_frame(&r, &tracer, 5);
            assert_eq!(bits(&again), bits(&fresh));
            assert_eq!((again.rays, again.jobs.finished), (fresh.rays, fresh.jobs.finished));
        }
        // A deadline far off: every pixel, as without one (the pixels in another order).
        r.recycle(render_frame(&r, &tracer, 6));
        let far = FrameOptions {
            deadline: Some(std::time::Instant::now() + std::time::Duration::from_secs(600)),
            stand_in: false,
        };
        let f = render_frame_with(&r, &tracer, 5, &far);
        assert_eq!(bits(&f), bits(&fresh));
        assert_eq!((f.rays, f.jobs.finished, f.jobs.unfinished, f.filled), (fresh.rays, fresh.jobs.finished, 0, 0));
        // A deadline already past: pixels not done are black.
        r.recycle(f);
        let late = FrameOptions { deadline: Some(std::time::Instant::now()), stand_in: false };
        let f = render_frame_with(&r, &tracer, 5, &late);
        assert!(f.jobs.unfinished > 0, "the deadline left nothing");
        for (i, p) in f.image.pixels.iter().enumerate() {
            assert!(f.is_done(i) || *p == [0.0; 3], "pixel {i} not done but {p:?}");
        }
        // A deadline within the frame: what it finished is the frame's, the rest black.
        let soon = FrameOptions {
            deadline: Some(std::time::Instant::now() + std::time::Duration::from_micros(300)),
            stand_in: false,
        };
        let f = render_frame_with(&r, &tracer, 5, &soon);
        for (i, p) in f.image.pixels.iter().enumerate() {
            let want = if f.is_done(i) { fresh.image.pixels[i] } else { [0.0; 3] };
            assert_eq!(p.map(f32::to_bits), want.map(f32::to_bits), "pixel {i}");
        }
    }
}
