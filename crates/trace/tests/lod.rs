//! Levels of detail chosen per ray: an error of 0 traces full detail exactly; a larger one
//! answers far rays from stand-ins; a paged frame whose tiles are missing is answered from
//! resident stand-ins (no pixel waits), and later frames converge to the exact answers.

use std::path::{Path, PathBuf};
use std::time::Duration;

use megaray_base::{Camera, Ray, Vec3, CLOSE_OFFSET};
use megaray_page::{Pager, PagerOptions};
use megaray_scene::Scene;
use megaray_testkit::*;
use megaray_trace::jobs::{self, JobOptions};
use megaray_trace::{RayCaster, RayCone, Tracer};

fn plant(dir: &Path) -> PathBuf {
    let ply = gen(dir, "plant:120k");
    let (path, s) = build(dir, &[ply], "plant", Some(20_000));
    assert!(s.lod_parts >= 2, "{} parts, {} levels of detail", s.parts, s.lod_parts);
    path
}

/// Per pixel of `cam`: the primary hit's distance bits and part, by `trace`.
fn view(cam: &Camera, mut trace: impl FnMut(&Ray, &RayCone) -> Option<(u32, u32)>) -> Vec<Option<(u32, u32)>> {
    let cone = RayCone::camera(cam.pixel_angle());
    (0..cam.width * cam.height)
        .map(|i| trace(&cam.ray((i % cam.width) as f32 + 0.5, (i / cam.width) as f32 + 0.5), &cone))
        .collect()
}

#[test]
fn an_error_of_zero_traces_full_detail_and_a_large_one_stand_ins() {
    let dir = tempfile::tempdir().unwrap();
    let path = plant(dir.path());
    let scene = Scene::open(&path).unwrap();
    let full = scene.full_part_count();
    let b = scene.header().bounds;
    let plain = Tracer::new(&scene);
    for off in [Vec3::new(0.2, 0.35, 0.9), CLOSE_OFFSET] {
        let cam = Camera::framing(&b, off, 96, 72);
        let want = view(&cam, |r, _| plain.intersect(r).map(|h| (h.t.to_bits(), h.part)));
        let shown = want.iter().filter(|h| h.is_some()).count();
        assert!(shown > 200, "{shown} pixels show the plant");
        let zero = Tracer::new(&scene).with_lod_error(0.0);
        assert_eq!(view(&cam, |r, c| zero.trace_cone(r, false, c).map(|h| (h.t.to_bits(), h.part))), want);
        // Far coarser than a pixel allows: the view is drawn from levels of detail.
        let coarse = Tracer::new(&scene).with_lod_error(200.0);
        let got = view(&cam, |r, c| coarse.trace_cone(r, false, c).map(|h| (h.t.to_bits(), h.part)));
        let from_lod = got.iter().flatten().filter(|h| h.1 >= full).count();
        assert!(from_lod * 2 > got.iter().flatten().count(), "{from_lod} of the hits came from levels of detail");
        // Any-hit queries agree with closest-hit ones on whether something is hit.
        for (i, h) in got.iter().enumerate().step_by(7) {
            let r = cam.ray((i as u32 % 96) as f32 + 0.5, (i as u32 / 96) as f32 + 0.5);
            let c = RayCone::camera(cam.pixel_angle());
            assert_eq!(coarse.trace_cone(&r, true, &c).is_some(), h.is_some(), "pixel {i}");
        }
    }
}

/// With every tile checked, an unpaged tracer with levels of detail stops only where links
/// enter the root tiles of parts with levels (`Scene::checked_but_lod_roots`), and follows
/// every other link inline: the same answers, closest and any hit, as a tracer that stops at
/// every crossing (a scene whose tiles are checked as rays enter them).
#[test]
fn stopping_only_at_part_roots_gives_the_answers_of_stopping_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let path = plant(dir.path());
    let everywhere = Scene::open(&path).unwrap();
    let at_roots = Scene::open(&path).unwrap();
    assert!(at_roots.check_all_tiles());
    assert!(everywhere.checked_but_lod_roots().is_none());
    let view_of = at_roots.checked_but_lod_roots().expect("every tile checked");
    let stops = (0..at_roots.header().tile_count).filter(|&t| !view_of.get(t)).count();
    assert!(stops >= 2 && stops < at_roots.header().tile_count as usize, "{stops} tiles to stop at");
    let b = at_roots.header().bounds;
    let lods = [0.5, 2.0, 200.0];
    // Made before any ray: the tracers over `everywhere` see no tile checked yet.
    let slow: Vec<Tracer> = lods.iter().map(|&l| Tracer::new(&everywhere).with_lod_error(l)).collect();
    let fast: Vec<Tracer> = lods.iter().map(|&l| Tracer::new(&at_roots).with_lod_error(l)).collect();
    let full = at_roots.full_part_count();
    let mut from_lod = 0;
    for off in [Vec3::new(0.2, 0.35, 0.9), CLOSE_OFFSET, Vec3::new(-0.3, 0.1, 2.5)] {
        let cam = Camera::framing(&b, off, 96, 72);
        for (a, f) in slow.iter().zip(&fast) {
            let key = |h: megaray_trace::Hit| (h.t.to_bits(), h.part * 1_000_003 + h.prim);
            let want = view(&cam, |r, c| a.trace_cone(r, false, c).map(key));
            let got = view(&cam, |r, c| f.trace_cone(r, false, c).map(key));
            assert_eq!(got, want, "closest hits differ (offset {off}, error {})", a.lod_error());
            let any = |t: &Tracer| view(&cam, |r, c| t.trace_cone(r, true, c).map(|_| (0, 0)));
            assert_eq!(any(f), any(a), "any hits differ (offset {off}, error {})", a.lod_error());
            from_lod += got.iter().flatten().filter(|h| h.1 / 1_000_003 >= full).count();
        }
    }
    assert!(from_lod > 500, "{from_lod} hits came from levels of detail");
}

#[test]
fn stand_ins_answer_at_once_and_frames_converge_to_the_exact_answers() {
    let dir = tempfile::tempdir().unwrap();
    let path = plant(dir.path());
    let scene = Scene::open(&path).unwrap();
    let b = scene.header().bounds;
    let cam = Camera::framing(&b, Vec3::new(0.2, 0.35, 0.9), 80, 60);
    let lod = 0.5;
    let unpaged = Tracer::new(&scene).with_lod_error(lod);
    let want = view(&cam, |r, c| unpaged.trace_cone(r, false, c).map(|h| (h.t.to_bits(), h.part)));
    // A budget of the pinned coarsest levels and a quarter of the other tiles.
    let pinned_only = Pager::min_budget(&scene);
    let quarter: u64 = scene.tiles().iter().map(|t| t.bytes as u64).sum::<u64>() / 4;
    let pager = Pager::open(&path, PagerOptions { budget: pinned_only + quarter, fetchers: 2 }).unwrap();
    let tracer = Tracer::paged(&pager).with_lod_error(lod);
    let n = (cam.width * cam.height) as usize;
    let cone = RayCone::camera(cam.pixel_angle());
    let opts = JobOptions { stand_in: true, ..JobOptions::default() };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
    let mut exact: Vec<Option<Option<(u32, u32)>>> = vec![None; n];
    let mut first_approx = None;
    for frame in 0..80 {
        let seen = pager.arrivals();
        let r = pool.install(|| {
            jobs::run(&tracer, n, &opts, |i, c| {
                let ray = cam.ray((i as u32 % cam.width) as f32 + 0.5, (i as u32 / cam.width) as f32 + 0.5);
                let h = c.intersect_cone(&ray, &cone)?;
                Ok((h.map(|h| (h.t.to_bits(), h.part)), c.approx()))
            })
        });
        // No pixel waits: every one is answered in the frame, none suspended.
        assert_eq!((r.stats.unfinished, r.stats.suspended), (0, 0), "frame {frame}");
        let mut approx = 0;
        for (i, (h, a)) in r.into_finished() {
            if a {
                approx += 1;
            } else {
                assert_eq!(h, want[i], "frame {frame}, pixel {i}: an exact answer differs from the unpaged one");
                exact[i] = Some(h);
            }
        }
        first_approx.get_or_insert(approx);
        if exact.iter().all(|e| e.is_some()) {
            break;
        }
        pager.wait_arrival(seen, Duration::from_millis(100));
    }
    assert!(first_approx.unwrap() > 0, "the first frame found every tile resident");
    let missing = exact.iter().filter(|e| e.is_none()).count();
    assert_eq!(missing, 0, "{missing} pixels never got an exact answer");
    let st = pager.stats();
    assert!(st.peak_resident <= st.tile_budget, "{st:?}");
}
