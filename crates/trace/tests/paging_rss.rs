//! The process's resident memory holds the budget while rendering a scene several times
//! larger than it, whatever the page cache holds of the file: read before through a map
//! in 2 MiB folios (as an unbudgeted render reads it), read by `cat`, or mapped by another
//! process. (Its own test binary: RSS is per process, and other tests would map scenes of
//! their own.)

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Command, Stdio};

use megaray_base::{process_memory, Camera, Ray, Vec3};
use megaray_page::{Pager, PagerOptions};
use megaray_scene::Scene;
use megaray_testkit::*;
use megaray_trace::jobs::{self, JobOptions};
use megaray_trace::{RayCaster, Tracer};

/// What budgeted frames may add to the process on top of the budget and of what the process
/// held before they started: the tile table, the jobs' buffers, thread stacks and code pages
/// first touched (docs/ARCHITECTURE.md, Paging: "Memory bound").
const OVERHEAD: u64 = 12 << 20;

/// Resets this process's peak resident set (`VmHWM`) to its current size (Linux 4.0+).
fn reset_peak() {
    std::fs::write("/proc/self/clear_refs", "5").expect("writing /proc/self/clear_refs");
}

fn rss() -> u64 {
    let m = process_memory().unwrap();
    m.file + m.anon
}

/// Reads the whole scene through a map advised HUGEPAGE, as an unbudgeted render of a small
/// enough scene does (the page cache then holds the file in 2 MiB folios where the kernel
/// makes them), and unmaps it.
fn read_through_a_huge_page_map(path: &Path) {
    let scene = Scene::open(path).unwrap();
    scene.advise_huge_pages().unwrap();
    assert!(scene.check_all_tiles());
}

/// Traces 8 frames of orbiting views (primary and shadow rays) with `budget` and returns the
/// peak RSS above the RSS before the pager started.
fn budgeted_peak(path: &Path, budget: u64) -> (u64, megaray_page::PagerStats) {
    let base = rss();
    reset_peak();
    let pager = Pager::open(path, PagerOptions { budget, fetchers: 2 }).unwrap();
    let tracer = Tracer::paged(&pager);
    let b = pager.scene().header().bounds;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
    for k in 0..8 {
        let a = k as f32 * 0.9;
        let cam = Camera::framing(&b, Vec3::new(a.sin() * 0.7, 0.35, a.cos() * 0.7), 128, 96);
        let eps = 1e-4 * b.diagonal();
        let n = (cam.width * cam.height) as usize;
        // Each pixel: its primary hit, and a shadow ray from it.
        let r = pool.install(|| {
            jobs::run(&tracer, n, &JobOptions::default(), |i, c| {
                let ray = cam.ray((i as u32 % cam.width) as f32 + 0.5, (i as u32 / cam.width) as f32 + 0.5);
                let Some(h) = c.intersect(&ray)? else { return Ok(false) };
                let p = ray.org + ray.dir * h.t;
                c.occluded(&Ray::new(p - ray.dir * eps, Vec3::new(0.5, 1.0, 0.8).normalize()))
            })
        });
        assert_eq!(r.stats.unfinished, 0);
    }
    let st = pager.stats();
    assert!(st.bytes_loaded > 2 * budget, "the frames did not page much: {st:?}");
    assert!(st.evicted > 0);
    let m = st.process.expect("process memory is reported on Linux");
    assert!(m.anon > 0);
    let peak = process_memory().unwrap().peak;
    (peak.saturating_sub(base), st)
}

/// Not a test on its own: run as a child by the test below (MEGARAY_HOLD_MAP=path), it maps
/// the scene, reads all of it, says so, and holds the map until its stdin closes.
#[test]
fn hold_a_map_of_the_scene() {
    let Some(path) = std::env::var_os("MEGARAY_HOLD_MAP") else { return };
    let scene = Scene::open(Path::new(&path)).unwrap();
    scene.advise_huge_pages().unwrap();
    assert!(scene.check_all_tiles());
    println!("mapped");
    std::io::stdout().flush().unwrap();
    let mut line = String::new();
    let _ = std::io::stdin().read_line(&mut line);
}

#[test]
fn process_memory_stays_within_the_budget_whatever_the_page_cache_holds() {
    if std::env::var_os("MEGARAY_HOLD_MAP").is_some() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:1200k");
    let (path, _) = build(dir.path(), &[ply], "big", Some(60_000));
    // What the scene takes in memory: its image (a compact file's is larger than the file).
    let file = Scene::open_owned(&path).unwrap().bytes().len() as u64;
    let budget: u64 = 6 << 20;
    assert!(file > 3 * (budget + OVERHEAD), "the scene ({file} bytes) is not several times the bound");

    // 1. The file read before through a map in 2 MiB folios (an unbudgeted render).
    read_through_a_huge_page_map(&path);
    let (peak, st) = budgeted_peak(&path, budget);
    assert!(
        peak <= budget + OVERHEAD,
        "after a mapped read: peak RSS {peak} over the budget {budget} + {OVERHEAD} (pager: {st:?})"
    );

    // 2. The file read by `cat`.
    let status = Command::new("cat").arg(&path).stdout(Stdio::null()).status().unwrap();
    assert!(status.success());
    let (peak, st) = budgeted_peak(&path, budget);
    assert!(peak <= budget + OVERHEAD, "after cat: peak RSS {peak} over the budget (pager: {st:?})");

    // 3. Another process holding a map of the whole file while we render.
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "hold_a_map_of_the_scene", "--nocapture", "--test-threads", "1"])
        .env("MEGARAY_HOLD_MAP", &path)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    while !line.contains("mapped") {
        line.clear();
        assert!(out.read_line(&mut line).unwrap() > 0, "the map-holding child ended early");
    }
    let (peak, st) = budgeted_peak(&path, budget);
    drop(child.stdin.take());
    child.wait().unwrap();
    assert!(peak <= budget + OVERHEAD, "with another process mapping it: peak RSS {peak} over the budget ({st:?})");
}
