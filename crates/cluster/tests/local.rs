//! A cluster of ranks as threads of one process (`local::world`): frames equal the ones one
//! process renders, bit for bit; a rank with another scene file stops the start; a rank that
//! goes silent mid-frame loses its tiles to the others and the frame is still exact.

use std::sync::Arc;
use std::time::Duration;

use megaray_base::Vec3;
use megaray_cluster::local::{world, LocalTransport};
use megaray_cluster::wire::{ToRoot, ToWorker};
use megaray_cluster::{Cluster, ClusterError, ClusterOptions, Transport};
use megaray_page::{Pager, PagerOptions};
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::Tracer;

fn pool() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap()
}

fn renderer(scene: &Scene, aovs: bool) -> Renderer {
    let b = scene.header().bounds;
    let cam = Camera::framing(&b, Vec3::new(0.1, 0.3, 0.6), 150, 83);
    let mut s = RenderSettings::new(cam);
    s.shader = Builtin::Env;
    s.light_samples = 2;
    s.aovs = aovs;
    let env = Environment::new(SkySpec { width: 64, ..SkySpec::default() }.map(), 256, 8);
    Renderer::new(s, &b).with_environment(Arc::new(env))
}

fn bits(f: &Frame) -> Vec<u32> {
    f.image.pixels.iter().flatten().map(|v| v.to_bits()).collect()
}

/// The accumulator's image as a frame (to compare bits).
fn frame_of(acc: &Accumulator) -> Frame {
    let img = acc.image();
    let mut f = Frame::new(img.width, img.height, false);
    f.image = img;
    f
}

/// Runs the root's part `f`; whatever happens in it (a failed assertion), ends the session
/// so that the other ranks' threads return and the test ends.
fn as_root(c: &mut Option<Cluster<LocalTransport>>, f: impl FnOnce(&mut Cluster<LocalTransport>)) -> Vec<usize> {
    let res = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(c.as_mut().unwrap())));
    let lost = c.take().unwrap().finish();
    if let Err(p) = res {
        std::panic::resume_unwind(p);
    }
    lost
}

fn opts() -> ClusterOptions {
    ClusterOptions { timeout: Duration::from_millis(500), ..ClusterOptions::default() }
}

#[test]
fn frames_equal_one_process_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let ply = megaray_testkit::gen(dir.path(), "plant:30k");
    let (path, _) = megaray_testkit::build_without_lod(dir.path(), &[ply], "plant", Some(4000));
    let scene = Scene::open(&path).unwrap();
    let checksum = scene.header().header_checksum;
    // The third run cuts the model with a section plane: the other ranks learn it from the
    // frame's message (their own renderers have none).
    for (aovs, cut) in [(false, false), (true, false), (false, true)] {
        let mut one = renderer(&scene, aovs);
        if cut {
            let b = scene.header().bounds;
            let sections = vec![Section::new(b.center(), Vec3::new(1.0, 0.2, 0.5))];
            one.settings.visibility = Some(Arc::new(Visibility { sections, ..Visibility::default() }));
        }
        let tracer = Tracer::new(&scene);
        let expected: Vec<Frame> = (0..3).map(|f| pool().install(|| render_frame(&one, &tracer, f))).collect();
        let mut ranks = world(3);
        let root_t = ranks.remove(0);
        std::thread::scope(|s| {
            for t in ranks {
                let (scene, path) = (&scene, &path);
                s.spawn(move || {
                    // Rank 1 pages within a small budget; rank 2 maps the file whole.
                    let pager =
                        Pager::open(path, PagerOptions { budget: Pager::min_budget(scene) + (256 << 10), fetchers: 1 })
                            .unwrap();
                    let tracer = if t.rank() == 1 { Tracer::paged(&pager) } else { Tracer::new(scene) };
                    let mut r = renderer(scene, aovs);
                    let mut c = Cluster::join(t, checksum, 1, opts()).unwrap();
                    assert_eq!(c.serve(&mut r, None, &tracer, &pool()).unwrap(), 6);
                    assert_eq!(r.settings.visibility.is_some(), cut);
                });
            }
            let mut c = Some(Cluster::join(root_t, checksum, 1, opts()).unwrap());
            let p = pool();
            let lost = as_root(&mut c, |c| {
                // Each frame begun on the other ranks before it is asked for (`next`).
                for (f, want) in expected.iter().enumerate() {
                    let got = c.render_frame(&one, &tracer, &p, f as u32, f < 2).unwrap();
                    assert_eq!(bits(&got), bits(want), "frame {f} aovs {aovs}");
                    assert_eq!(
                        (got.depth.clone(), got.normal.clone(), got.albedo.clone()),
                        (want.depth.clone(), want.normal.clone(), want.albedo.clone())
                    );
                    assert_eq!(got.rays, want.rays);
                    assert_eq!(c.last.tiles, Rect::tiles(150, 83).len() as u64);
                    assert!(c.last.root_tiles < c.last.tiles, "the other ranks rendered nothing: {:?}", c.last);
                    assert!(c.last.bytes_in > 0 && c.last.bytes_out > 0);
                }
                // Added as they come, the pieces give the sums of the frames added whole.
                let (mut acc, mut want) = (Accumulator::new(150, 83), Accumulator::new(150, 83));
                for (f, frame) in expected.iter().enumerate() {
                    c.accumulate_frame(&one, &tracer, &p, f as u32, &mut acc, f < 2).unwrap();
                    want.add_frame(frame);
                    assert_eq!(bits(&frame_of(&acc)), bits(&frame_of(&want)), "frame {f} aovs {aovs}");
                    assert_eq!((acc.frames(), acc.rays()), (want.frames(), want.rays()));
                    if aovs {
                        let (a, b) = (acc.aovs(), want.aovs());
                        assert_eq!((a.depth, a.normal, a.albedo), (b.depth, b.normal, b.albedo));
                    }
                }
            });
            assert!(lost.is_empty());
        });
    }
}

#[test]
fn a_frame_begun_and_not_asked_for_is_finished_and_thrown_away() {
    let dir = tempfile::tempdir().unwrap();
    let ply = megaray_testkit::gen(dir.path(), "plant:10k");
    let (path, _) = megaray_testkit::build_without_lod(dir.path(), &[ply], "plant", None);
    let scene = Scene::open(&path).unwrap();
    let checksum = scene.header().header_checksum;
    let r = renderer(&scene, false);
    let tracer = Tracer::new(&scene);
    let mut ranks = world(3);
    let root_t = ranks.remove(0);
    std::thread::scope(|s| {
        let served: Vec<_> = ranks
            .into_iter()
            .map(|t| {
                let scene = &scene;
                s.spawn(move || {
                    let mut r = renderer(scene, false);
                    let mut c = Cluster::join(t, checksum, 1, opts()).unwrap();
                    c.serve(&mut r, None, &Tracer::new(scene), &pool()).unwrap()
                })
            })
            .collect();
        let mut c = Some(Cluster::join(root_t, checksum, 1, opts()).unwrap());
        let p = pool();
        let lost = as_root(&mut c, |c| {
            // Frame 1 is begun, frame 2 asked for: frame 1 is finished first, and frame 2 is
            // still exact; frame 3 is begun and the session ends.
            c.render_frame(&r, &tracer, &p, 0, true).unwrap();
            let got = c.render_frame(&r, &tracer, &p, 2, true).unwrap();
            assert_eq!(bits(&got), bits(&pool().install(|| render_frame(&r, &tracer, 2))));
        });
        assert!(lost.is_empty());
        for h in served {
            assert_eq!(h.join().unwrap(), 4, "frames 0 to 3 each started on every rank");
        }
    });
}

/// The root's pager ends a frame with the whole frame's working set (its own lookups and the
/// other ranks'), which the level-of-detail governor steers by: the same tiles as one
/// process's frame, however the tiles were shared out.
#[test]
fn the_roots_working_set_is_the_whole_frames() {
    let dir = tempfile::tempdir().unwrap();
    let ply = megaray_testkit::gen(dir.path(), "plant:30k");
    let (path, _) = megaray_testkit::build_without_lod(dir.path(), &[ply], "plant", Some(2000));
    let scene = Scene::open(&path).unwrap();
    let checksum = scene.header().header_checksum;
    let budget = 64 << 20;
    let open = || Pager::open(&path, PagerOptions { budget, fetchers: 1 }).unwrap();
    let r = renderer(&scene, false);
    // One process: the frame's lookups.
    let one = open();
    let tracer = Tracer::paged(&one);
    one.begin_working_set();
    pool().install(|| render_frame(&r, &tracer, 0));
    let want = one.working_set();
    assert!(want.len() > 10, "{} tiles", want.len());
    let mut ranks = world(3);
    let root_t = ranks.remove(0);
    std::thread::scope(|s| {
        for t in ranks {
            let (scene, open) = (&scene, &open);
            s.spawn(move || {
                let pager = open();
                let mut r = renderer(scene, false);
                let mut c = Cluster::join(t, checksum, 1, opts()).unwrap();
                c.serve(&mut r, None, &Tracer::paged(&pager), &pool()).unwrap();
            });
        }
        let root_pager = open();
        let tracer = Tracer::paged(&root_pager);
        let mut c = Some(Cluster::join(root_t, checksum, 1, opts()).unwrap());
        let p = pool();
        let lost = as_root(&mut c, |c| {
            // Again with other tiles resident; then with frame 1 begun ahead and thrown away
            // (the ranks' lookups for it are not counted).
            for next in [false, false, true, false] {
                root_pager.begin_working_set();
                c.render_frame(&r, &tracer, &p, 0, next).unwrap();
                assert!(c.last.root_tiles < c.last.tiles, "the other ranks rendered nothing");
                assert_eq!(root_pager.working_set(), want);
                assert_eq!(root_pager.working_set_bytes(), one.working_set_bytes());
            }
        });
        assert!(lost.is_empty());
    });
}

#[test]
fn a_rank_with_another_scene_file_stops_the_start() {
    let mut ranks = world(3);
    let root = ranks.remove(0);
    let handles: Vec<_> = ranks
        .into_iter()
        .map(|t| {
            std::thread::spawn(move || {
                let sum = if t.rank() == 2 { 7 } else { 42 };
                Cluster::join(t, sum, 1, opts()).err()
            })
        })
        .collect();
    let e = Cluster::join(root, 42, 1, opts()).err().expect("the root started");
    assert!(matches!(e, ClusterError::SceneDiffers { rank: 2, ours: 42, theirs: 7 }), "{e}");
    assert!(e.to_string().contains("rank 2's scene file differs from rank 0's"), "{e}");
    for h in handles {
        assert!(matches!(h.join().unwrap(), Some(ClusterError::Refused(2))));
    }
}

/// Rank 1 says hello, takes its first tiles and then says nothing more.
fn silent_rank(t: LocalTransport, checksum: u64) {
    let (tag, b) = ToRoot::Hello { checksum, threads: 1 }.encode();
    t.send(0, tag, &b);
    let mut works = 0;
    while works < 2 {
        if let Some((_, tag, bytes)) = t.try_recv() {
            if let ToWorker::Work { .. } = ToWorker::decode(0, tag, &bytes).unwrap() {
                works += 1;
            }
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn a_silent_rank_loses_its_tiles_and_the_frame_is_still_exact() {
    let dir = tempfile::tempdir().unwrap();
    let ply = megaray_testkit::gen(dir.path(), "plant:10k");
    let (path, _) = megaray_testkit::build_without_lod(dir.path(), &[ply], "plant", None);
    let scene = Scene::open(&path).unwrap();
    let checksum = scene.header().header_checksum;
    let r = renderer(&scene, false);
    let tracer = Tracer::new(&scene);
    let want = pool().install(|| render_frame(&r, &tracer, 0));
    let mut ranks = world(3);
    let root_t = ranks.remove(0);
    let two = ranks.pop().unwrap();
    let one = ranks.pop().unwrap();
    std::thread::scope(|s| {
        s.spawn(move || silent_rank(one, checksum));
        s.spawn(|| {
            let mut r = renderer(&scene, false);
            let mut c = Cluster::join(two, checksum, 1, opts()).unwrap();
            c.serve(&mut r, None, &Tracer::new(&scene), &pool()).unwrap();
        });
        let mut c = Some(Cluster::join(root_t, checksum, 1, opts()).unwrap());
        let p = pool();
        let lost = as_root(&mut c, |c| {
            let got = c.render_frame(&r, &tracer, &p, 0, false).unwrap();
            assert_eq!(bits(&got), bits(&want));
            assert_eq!(c.lost(), vec![1]);
            // The next frame goes on without it.
            let got = c.render_frame(&r, &tracer, &p, 1, false).unwrap();
            assert_eq!(bits(&got), bits(&pool().install(|| render_frame(&r, &tracer, 1))));
        });
        assert_eq!(lost, vec![1]);
    });
}
