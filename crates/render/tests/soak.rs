//! Soak: a 1,000-frame camera path under a budget of a few tiles, on 8 threads. Every frame
//! equals the unbudgeted one, and the process's resident memory does not grow after the
//! first 100 frames. A binary of its own: resident memory is per process.

mod common;

use common::*;
use megaray_base::{process_memory, Camera, Vec3};
use megaray_page::{Pager, PagerOptions};
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::Tracer;

const FRAMES: usize = 1000;

/// The system allocator, counting the bytes live: what the program holds, apart from what the
/// allocator keeps of freed memory (which resident memory also counts).
struct Counting;

static LIVE: std::sync::atomic::AtomicI64 = std::sync::atomic::AtomicI64::new(0);

// SAFETY: forwards every call to the system allocator unchanged; only counts.
unsafe impl std::alloc::GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: std::alloc::Layout) -> *mut u8 {
        LIVE.fetch_add(l.size() as i64, std::sync::atomic::Ordering::Relaxed);
        std::alloc::System.alloc(l)
    }
    unsafe fn dealloc(&self, p: *mut u8, l: std::alloc::Layout) {
        LIVE.fetch_sub(l.size() as i64, std::sync::atomic::Ordering::Relaxed);
        std::alloc::System.dealloc(p, l)
    }
    unsafe fn realloc(&self, p: *mut u8, l: std::alloc::Layout, new: usize) -> *mut u8 {
        LIVE.fetch_add(new as i64 - l.size() as i64, std::sync::atomic::Ordering::Relaxed);
        std::alloc::System.realloc(p, l, new)
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

fn live() -> i64 {
    LIVE.load(std::sync::atomic::Ordering::Relaxed)
}

fn hash(img: &Image) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for p in &img.pixels {
        std::hash::Hash::hash(&[p[0].to_bits(), p[1].to_bits(), p[2].to_bits()], &mut h);
    }
    std::hash::Hasher::finish(&h)
}

fn resident() -> u64 {
    process_memory().map_or(0, |m| m.anon + m.file)
}

#[test]
fn a_thousand_frames_under_a_tiny_budget_equal_the_unbudgeted_ones_in_flat_memory() {
    let dir = tempfile::tempdir().unwrap();
    let spec: megaray_gen::GenSpec = "plant:60k".parse().unwrap();
    let ply = dir.path().join("plant.ply");
    megaray_gen::write_ply(&spec, &ply, &megaray_base::NoProgress).unwrap();
    let path = build_file(dir.path(), &ply, "plant");
    let scene = Scene::open(&path).unwrap();
    let b = scene.header().bounds;
    assert!(scene.tiles().len() >= 20, "only {} tiles", scene.tiles().len());
    // An orbit that comes close and goes far: the working set changes all along.
    let renderer = |k: usize| {
        let a = k as f32 * 0.0251;
        let r = 0.35 + 0.3 * (k as f32 * 0.013).sin().abs();
        let cam = Camera::framing(&b, Vec3::new(a.cos() * r, 0.3 + 0.2 * (a * 0.7).sin(), a.sin() * r), 40, 30);
        Renderer::new(RenderSettings::new(cam), &b)
    };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(8).build().unwrap();
    let plain = Tracer::new(&scene);
    let want: Vec<u64> =
        pool.install(|| (0..FRAMES).map(|k| hash(&render_frame(&renderer(k), &plain, 0).image)).collect());

    let budget = Pager::min_budget(&scene) + 3 * (64 << 10);
    let pager = Pager::open(&path, PagerOptions { budget, fetchers: 3 }).unwrap();
    let tracer = Tracer::paged(&pager);
    let mut at_100 = 0;
    let mut most_after = 0;
    let (mut live_100, mut live_most) = (0, 0);
    pool.install(|| {
        for (k, w) in want.iter().enumerate() {
            let got = hash(&render_frame(&renderer(k), &tracer, 0).image);
            assert_eq!(got, *w, "frame {k} under the budget differs from the unbudgeted one");
            if k == 99 {
                at_100 = resident();
                live_100 = live();
            } else if k > 99 {
                most_after = most_after.max(resident());
                live_most = live_most.max(live());
            }
        }
    });
    let st = pager.stats();
    eprintln!(
        "soak: {FRAMES} frames, budget {budget} B, {} tiles loaded, {} evicted; resident at frame 100 {at_100} B, at most {most_after} B after; \
         heap live at frame 100 {live_100} B, at most {live_most} B after",
        st.loaded, st.evicted
    );
    assert!(st.evicted > 100, "the budget was not tight: {st:?}");
    assert!(st.peak_resident <= st.tile_budget, "{st:?}");
    assert!(pager.first_error().is_none());
    // Flat: the heap holds after frame 100 what it held then, give or take one frame's
    // buffers in flight (64 KiB); resident memory, which also counts what the allocator keeps
    // of freed memory across its 11 threads' arenas, within 2 MiB of it.
    assert!(
        live_most <= live_100 + (64 << 10),
        "the heap grew after frame 100: {live_100} -> at most {live_most} bytes"
    );
    assert!(
        most_after <= at_100 + (2 << 20),
        "resident memory grew after frame 100: {at_100} -> at most {most_after} bytes"
    );
}
