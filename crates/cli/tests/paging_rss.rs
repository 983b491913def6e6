//! Resident memory holds the budget while rendering a scene several times larger than it.
//! (Its own test binary: RSS is per process, and other tests would map scenes of their own.)

mod common;

use std::sync::Arc;

use common::*;
use megaray_page::{Pager, PagerOptions};
use megaray_render::{render_frame, Camera, RenderSettings, Renderer};
use megaray_scene::Scene;
use megaray_trace::Tracer;

/// File-backed resident memory of this process (`RssFile` in /proc/self/status): the pages
/// of mapped files, the scene's among them.
fn rss_file() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap();
    let l = s.lines().find(|l| l.starts_with("RssFile:")).expect("RssFile in /proc/self/status");
    l.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap() * 1024
}

#[test]
fn resident_scene_memory_stays_within_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:600k");
    let (path, _) = build(dir.path(), &[ply], "big", Some(60_000));
    let file = std::fs::metadata(&path).unwrap().len();
    let budget: u64 = 6 << 20;
    assert!(file > 4 * budget, "the scene ({file} bytes) is not several times the budget");
    let scene = Arc::new(Scene::open(&path).unwrap());
    let pager = Pager::new(scene.clone(), PagerOptions { budget, fetchers: 2 }).unwrap();
    let tracer = Tracer::paged(&pager);
    let b = scene.header().bounds;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
    // A first frame brings this process's own code pages in; measure from there.
    let cam = |k: u32| {
        let a = k as f32 * 0.9;
        Camera::framing(&b, megaray_base::Vec3::new(a.sin() * 0.7, 0.35, a.cos() * 0.7), 128, 96)
    };
    let frame = |k: u32| {
        let r = Renderer::new(RenderSettings::new(cam(k)), &b);
        pool.install(|| render_frame(&r, &tracer, 0))
    };
    frame(0);
    let base = rss_file().saturating_sub(pager.stats().resident);
    let mut worst = 0;
    for k in 1..8 {
        let f = frame(k);
        assert_eq!(f.jobs.unfinished, 0);
        worst = worst.max(rss_file().saturating_sub(base));
    }
    let st = pager.stats();
    assert!(st.bytes_loaded > 2 * budget, "the frames did not page much: {st:?}");
    assert!(st.evicted > 0);
    // Pinned tables are in the budget; allow 1 MiB for code and data pages first touched late.
    assert!(worst <= budget + (1 << 20), "scene pages resident {worst} over the budget {budget}");
}
