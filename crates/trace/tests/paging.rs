//! Paged tracing within a memory budget: a paged tracer gives exactly the hits of an unpaged
//! one, however small the budget, with tiles evicted and rays suspended on the way.

use std::sync::Arc;

use megaray_base::Ray;
use megaray_base::{Camera, CLOSE_OFFSET, DEFAULT_OFFSET};
use megaray_page::{Access, Pager, PagerOptions};
use megaray_scene::Scene;
use megaray_testkit::*;
use megaray_trace::jobs::{self, JobOptions};
use megaray_trace::{RayCaster, Tracer};

/// What a job computes per pixel: the primary hit (distance bits and triangle) and whether a
/// shadow ray toward a fixed light from it is blocked.
type Answer = Option<(u32, u32, u32, bool)>;

fn pixel(cam: &Camera, eps: f32, i: usize, c: &mut impl RayCaster) -> Result<Answer, megaray_trace::Suspended> {
    let (x, y) = ((i as u32 % cam.width) as f32 + 0.5, (i as u32 / cam.width) as f32 + 0.5);
    let ray = cam.ray(x, y);
    let Some(h) = c.intersect(&ray)? else { return Ok(None) };
    let p = ray.org + ray.dir * h.t;
    let n = h.geometric_normal().normalize_or_zero();
    let n = if n.dot(ray.dir) > 0.0 { -n } else { n };
    let shadow = Ray::new(p + n * eps, megaray_base::Vec3::new(0.5, 1.0, 0.8).normalize());
    let blocked = c.occluded(&shadow)?;
    Ok(Some((h.t.to_bits(), h.part, h.prim, blocked)))
}

fn frame(tracer: &Tracer, cam: &Camera) -> (Vec<Answer>, jobs::JobStats) {
    let eps = 1e-4 * tracer.scene().header().bounds.diagonal();
    let n = (cam.width * cam.height) as usize;
    let r = jobs::run(tracer, n, &JobOptions::default(), |i, c| pixel(cam, eps, i, c));
    let stats = r.stats;
    (r.into_ordered(n).into_iter().map(|a| a.expect("no deadline: every job finishes")).collect(), stats)
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap()
}

fn scene(dir: &std::path::Path, spec: &str) -> Arc<Scene> {
    let ply = gen(dir, spec);
    let (path, s) = build(dir, &[ply], "paged", Some(20_000));
    assert!(s.tiles >= 20, "only {} tiles", s.tiles);
    Arc::new(Scene::open(&path).unwrap())
}

#[test]
fn a_budget_of_a_few_tiles_gives_the_hits_of_no_budget() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path(), "plant:120k");
    let cam = Camera::framing(&scene.header().bounds, CLOSE_OFFSET, 96, 72);
    let (want, s0) = pool(4).install(|| frame(&Tracer::new(&scene), &cam));
    assert_eq!(s0.suspended, 0);
    let shown = want.iter().filter(|a| a.is_some()).count();
    assert!(shown > 500, "the view shows the model ({shown} hits)");
    let budget = Pager::min_budget(&scene) + (64 << 10);
    let pager = Pager::open(scene.path(), PagerOptions { budget, fetchers: 2 }).unwrap();
    let tracer = Tracer::paged(&pager);
    for round in 0..2 {
        let (got, s) = pool(4).install(|| frame(&tracer, &cam));
        assert_eq!(got, want, "round {round}: paged hits differ");
        assert!(s.suspended > 0, "round {round}: no ray was suspended");
        assert_eq!(s.finished as usize, want.len());
    }
    let st = pager.stats();
    assert!(st.evicted > 0, "nothing was evicted: {st:?}");
    assert!(st.loaded > st.evicted);
    assert!(
        st.peak_resident <= st.tile_budget,
        "resident {} over the tile budget {}",
        st.peak_resident,
        st.tile_budget
    );
    assert!(st.misses > 0 && st.hit_rate() < 1.0);
    assert!(pager.first_error().is_none());
}

/// Many threads, a tiny budget, many frames from moving cameras: every frame equals the
/// unpaged one (no lost ray, no stale tile), and readers holding a pin never see a tile's
/// pages released under them.
#[test]
fn stress_many_threads_tiny_budget_many_frames() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path(), "plant:120k");
    let plain = Tracer::new(&scene);
    let b = scene.header().bounds;
    let cams: Vec<Camera> = (0..12)
        .map(|k| {
            let a = k as f32 * 0.5;
            let off = megaray_base::Vec3::new(a.cos() * 0.6, 0.4 + 0.05 * k as f32, a.sin() * 0.6);
            Camera::framing(&b, off, 48, 36)
        })
        .collect();
    let want: Vec<Vec<Answer>> = cams.iter().map(|c| pool(2).install(|| frame(&plain, c).0)).collect();
    let pager = Pager::open(scene.path(), PagerOptions { budget: Pager::min_budget(&scene), fetchers: 3 }).unwrap();
    let tracer = Tracer::paged(&pager);
    let stop = std::sync::atomic::AtomicBool::new(false);
    let violations = std::sync::atomic::AtomicU64::new(0);
    std::thread::scope(|sc| {
        // Readers that hold pins over random tiles and check that they stay put.
        for k in 0..3u64 {
            let (pager, stop, violations, scene) = (&pager, &stop, &violations, &scene);
            sc.spawn(move || {
                let mut rng = Rng(k + 7);
                let n = scene.tiles().len() as u64;
                while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                    let t = (rng.next_u64() % n) as u32;
                    if !pager.is_resident(t) {
                        // (Asking would flood the fetchers with tiles nobody traces.)
                        std::thread::yield_now();
                        continue;
                    }
                    let _pin = pager.pin();
                    if pager.acquire(t) == Access::Ready {
                        let g = pager.release_count(t);
                        assert!(pager.scene().check_tile(t).is_ok(), "a resident tile reads as loaded");
                        std::thread::yield_now();
                        if pager.release_count(t) != g {
                            violations.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        }
                    }
                }
            });
        }
        let p = pool(8);
        for round in 0..2 {
            for (c, w) in cams.iter().zip(&want) {
                let (got, _) = p.install(|| frame(&tracer, c));
                assert!(got == *w, "round {round}: a paged frame differs from the unpaged one");
            }
        }
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
    });
    assert_eq!(violations.into_inner(), 0, "a tile was released under a pin");
    let st = pager.stats();
    assert!(st.evicted > 50, "{st:?}");
    assert!(st.peak_resident <= st.tile_budget);
}

#[test]
fn a_corrupt_tile_is_reported_by_file_and_tile() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path(), "plant:60k");
    let path = scene.path().to_path_buf();
    let t = scene.tiles().len() as u32 / 2;
    let off = megaray_testkit::stored_offset(&scene, scene.tiles()[t as usize].offset + 200);
    drop(scene);
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[off as usize] ^= 0x40;
    std::fs::write(&path, &bytes).unwrap();
    let scene = Arc::new(Scene::open(&path).unwrap());
    let pager = Pager::open(scene.path(), PagerOptions { budget: 1 << 30, fetchers: 2 }).unwrap();
    let tracer = Tracer::paged(&pager);
    // Ask for every tile, so the damaged one is met whatever the view.
    for i in 0..scene.tiles().len() as u32 {
        pager.request(i);
    }
    let cam = Camera::framing(&scene.header().bounds, DEFAULT_OFFSET, 64, 48);
    let (_, s) = pool(2).install(|| frame(&tracer, &cam));
    assert_eq!(s.unfinished, 0);
    while !(0..scene.tiles().len() as u32).all(|i| pager.settled(i)) {
        pager.wait_arrival(pager.arrivals(), std::time::Duration::from_millis(10));
    }
    let err = pager.first_error().expect("the damaged tile is reported").to_string();
    assert!(err.contains("paged.mray") && err.contains(&format!("tile {t}")) && err.contains("checksum"), "{err}");
    assert_eq!(pager.stats().corrupt, 1);
}
