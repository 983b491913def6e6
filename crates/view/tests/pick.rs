//! A click picks exactly: the full-detail closest hit, equal to brute force over every
//! triangle, where the frame was drawn from coarse levels of detail and where the tiles the
//! pick needs were not resident (a budget of a few tiles).

use megaray_page::{Pager, PagerOptions};
use megaray_scene::Scene;
use megaray_testkit::*;
use megaray_trace::Tracer;
use megaray_view::{Event, FlyCamera, Pose, ViewCore, ViewOptions};

#[test]
fn clicks_pick_full_detail_whatever_the_frame_drew() {
    let dir = tempfile::tempdir().unwrap();
    let (path, s) = build(dir.path(), &[gen(dir.path(), "plant:120k")], "plant", Some(20_000));
    assert!(s.lod_parts > 0, "the scene has levels of detail");
    let scene = Scene::open(&path).unwrap();
    assert!(scene.check_all_tiles());
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let (w, h) = (48u32, 36u32);
    for paged in [false, true] {
        let budget = Pager::min_budget(&scene) + 1;
        let pager = paged.then(|| Pager::open(&path, PagerOptions { budget, fetchers: 2 }).unwrap());
        let base = match &pager {
            Some(p) => Tracer::paged(p),
            None => Tracer::new(&scene),
        };
        // Frames from coarse levels: an error of 40 pixels.
        let tracer = base.with_lod_error(40.0);
        let opts = ViewOptions { frame_budget: None, ..ViewOptions::new(w, h) };
        let mut view = ViewCore::new(&tracer, &pool, opts);
        let b = scene.header().bounds;
        let eye = b.center() + megaray_base::CLOSE_OFFSET * b.diagonal();
        view.set_camera(FlyCamera { pose: Pose::looking_at(eye, b.center()), ..view.camera() });
        view.step(1.0 / 30.0);
        let cam = view.pose().camera(60.0, w, h);
        let mut checked = 0;
        for y in (1..h).step_by(3) {
            for x in (1..w).step_by(3) {
                let (sx, sy) = (x as f32 + 0.5, y as f32 + 0.5);
                view.handle(Event::Click(sx, sy, false));
                let want = brute_closest(&scene, &cam.ray(sx, sy));
                let got = view.picked().map(|p| (p.t, p.part, p.triangle));
                match (want, got) {
                    (None, None) => {}
                    (Some(a), Some(b)) => {
                        assert_eq!((a.1, a.2), (b.1, b.2), "pixel {x},{y} (paged {paged})");
                        assert!((a.0 - b.0).abs() <= 1e-5 * a.0.max(1.0));
                        checked += 1;
                    }
                    _ => panic!("pixel {x},{y} (paged {paged}): brute force {want:?}, pick {got:?}"),
                }
            }
        }
        assert!(checked >= 10, "only {checked} hit pixels");
        if let Some(p) = &pager {
            assert!(p.stats().loaded > 0, "the picks loaded tiles");
        }
    }
}
