//! The pager alone, without a tracer: budgets, loads and evictions, what a loaded tile holds,
//! damaged tiles and files.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use megaray_page::{Access, Pager, PagerOptions};
use megaray_scene::Scene;
use megaray_testkit::*;

/// A generated plant of many small tiles, built into `dir/paged.mray` (without levels of
/// detail, whose coarsest tiles a pager pins: the tests of loads and evictions count tiles).
fn scene_file(dir: &Path) -> PathBuf {
    let ply = gen(dir, "plant:60k");
    let (path, s) = build_without_lod(dir, &[ply], "paged", Some(20_000));
    assert!(s.tiles >= 20, "only {} tiles", s.tiles);
    path
}

/// Asks for tile `t` and waits until it has settled (loaded or failed).
fn fetch(pager: &Pager, t: u32) -> Access {
    loop {
        let seen = pager.arrivals();
        let a = {
            let _pin = pager.pin();
            pager.acquire(t)
        };
        if a != Access::Missing {
            return a;
        }
        pager.wait_arrival(seen, Duration::from_millis(50));
    }
}

#[test]
fn a_budget_too_small_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = scene_file(dir.path());
    let err = Pager::open(&path, PagerOptions { budget: 4096, fetchers: 1 }).err().unwrap().to_string();
    assert!(err.contains("paged.mray") && err.contains("too small") && err.contains("at least"), "{err}");
    // A mapped scene is not for a pager: it would page behind the pager's back.
    let mapped = Arc::new(Scene::open(&path).unwrap());
    let err = Pager::new(mapped, PagerOptions { budget: 1 << 30, fetchers: 1 }).err().unwrap().to_string();
    assert!(err.contains("paged.mray") && err.contains("open_owned"), "{err}");
}

/// Every tile in turn under a budget of a few: each arrives holding the file's bytes (its
/// check passes under a pin), resident bytes never pass the budget, and tiles are evicted to
/// make room; a tile evicted reads as zeros until it is loaded again.
#[test]
fn every_tile_loads_within_a_budget_of_a_few() {
    let dir = tempfile::tempdir().unwrap();
    let path = scene_file(dir.path());
    let budget = Pager::min_budget(&Scene::open(&path).unwrap()) + (32 << 10);
    let pager = Pager::open(&path, PagerOptions { budget, fetchers: 2 }).unwrap();
    let scene = pager.scene().clone();
    let n = scene.tiles().len() as u32;
    for round in 0..2 {
        for t in 0..n {
            assert_eq!(fetch(&pager, t), Access::Ready, "round {round}: tile {t}");
            let _pin = pager.pin();
            if pager.acquire(t) == Access::Ready {
                scene.check_tile(t).unwrap_or_else(|e| panic!("round {round}: tile {t} as loaded: {e}"));
            }
            let st = pager.stats();
            assert!(st.resident <= st.tile_budget, "round {round}: {st:?}");
        }
    }
    let st = pager.stats();
    assert!(st.loaded >= 2 * n as u64 - 4 && st.evicted > n as u64, "{st:?}");
    assert!(st.peak_resident <= st.tile_budget);
    assert!(pager.first_error().is_none());
    let gone = (0..n).find(|&t| !pager.is_resident(t)).expect("a tile was evicted");
    let e = scene.tiles()[gone as usize];
    assert!(scene.bytes()[e.offset as usize..][..e.bytes as usize].iter().all(|&b| b == 0));
    let m = st.process.expect("process memory on Linux");
    assert!(m.file < 64 << 20, "the scene is not mapped: {m:?}");
}

/// A damaged tile is found on load: it is never available, the fault names file and tile,
/// and it is not asked for again. A file truncated while open: the load fails with an error
/// naming the tile, not a SIGBUS.
#[test]
fn damaged_and_truncated_files_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let path = scene_file(dir.path());
    let probe = Scene::open(&path).unwrap();
    let t = probe.tiles().len() as u32 / 2;
    let off = megaray_testkit::stored_offset(&probe, probe.tiles()[t as usize].offset + 200);
    let last = probe.tiles().len() as u32 - 1;
    let last_off = megaray_testkit::stored_offset(&probe, probe.tiles()[last as usize].offset);
    drop(probe);
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[off as usize] ^= 0x40;
    std::fs::write(&path, &bytes).unwrap();
    let pager = Pager::open(&path, PagerOptions { budget: 1 << 30, fetchers: 2 }).unwrap();
    assert_eq!(fetch(&pager, t), Access::Corrupt);
    let err = pager.first_error().expect("the damaged tile is reported").to_string();
    assert!(err.contains("paged.mray") && err.contains(&format!("tile {t}")) && err.contains("checksum"), "{err}");
    assert_eq!(pager.stats().corrupt, 1);
    assert!(!pager.is_resident(t));
    // Truncated under the open scene, before its last tile.
    std::fs::OpenOptions::new().write(true).open(&path).unwrap().set_len(last_off).unwrap();
    assert_eq!(fetch(&pager, last), Access::Corrupt);
    assert_eq!(pager.stats().corrupt, 2);
}

/// With levels of detail, the coarsest level of every part (the part itself where it has
/// none) is resident from the start, counted as pinned, and never evicted however small the
/// budget; every other tile still loads.
#[test]
fn the_coarsest_levels_are_pinned() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:120k");
    let (path, s) = build(dir.path(), &[ply], "lod", Some(20_000));
    assert!(s.lod_parts > 0);
    let probe = Scene::open(&path).unwrap();
    let coarsest: Vec<u32> = (0..probe.full_part_count()).map(|p| probe.lod_chain(p).last().unwrap()).collect();
    let pinned: Vec<u32> = coarsest
        .iter()
        .flat_map(|&q| {
            let e = probe.parts()[q as usize];
            e.first_tile..e.first_tile + e.tile_count
        })
        .collect();
    let budget = Pager::min_budget(&probe);
    drop(probe);
    let pager = Pager::open(&path, PagerOptions { budget, fetchers: 2 }).unwrap();
    assert!(pinned.iter().all(|&t| pager.is_resident(t)), "a coarsest tile is not resident at the start");
    let n = pager.scene().tiles().len() as u32;
    for t in (0..n).filter(|t| !pinned.contains(t)) {
        assert_eq!(fetch(&pager, t), Access::Ready, "tile {t}");
    }
    let st = pager.stats();
    assert!(st.evicted > 0, "{st:?}");
    assert!(pinned.iter().all(|&t| pager.is_resident(t)), "a coarsest tile was evicted");
    assert!(st.pinned > 0 && st.peak_resident <= st.tile_budget, "{st:?}");
}

/// A working set counts each tile looked up once (present or missing), not the pinned ones,
/// adds tiles noted by another process (ignoring numbers out of range), and starts empty
/// again; its bytes are the tiles' resident costs, whatever was loaded or evicted.
#[test]
fn the_working_set_is_what_was_looked_up() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:120k");
    let (path, _) = build(dir.path(), &[ply], "lod", Some(20_000));
    let probe = Scene::open(&path).unwrap();
    let budget = Pager::min_budget(&probe);
    drop(probe);
    let pager = Pager::open(&path, PagerOptions { budget, fetchers: 1 }).unwrap();
    let n = pager.scene().tiles().len() as u32;
    let pinned: Vec<u32> = (0..n).filter(|&t| pager.is_resident(t)).collect();
    let free: Vec<u32> = (0..n).filter(|t| !pinned.contains(t)).collect();
    assert!(!pinned.is_empty() && free.len() >= 6, "{} pinned, {} not", pinned.len(), free.len());
    let alone = |ts: &[u32]| {
        pager.begin_working_set();
        pager.note_working_set(ts);
        pager.working_set_bytes()
    };
    let cost: Vec<u64> = free.iter().map(|&t| alone(&[t])).collect();
    assert!(cost.iter().all(|&c| c > 0 && c % 4096 == 0), "{cost:?}");
    pager.begin_working_set();
    assert_eq!((pager.working_set(), pager.working_set_bytes()), (Vec::new(), 0));
    // Looked up, twice each, loaded or not; the pinned ones too (not counted).
    for &t in free[..4].iter().chain(&free[..4]).chain(&pinned) {
        let _pin = pager.pin();
        pager.acquire(t);
    }
    // Noted from elsewhere: one already seen, a new one, a pinned one, one out of range.
    pager.note_working_set(&[free[1], free[5], pinned[0], n + 7]);
    let want = vec![free[0], free[1], free[2], free[3], free[5]];
    assert_eq!(pager.working_set(), want);
    assert_eq!(pager.working_set_bytes(), cost[..4].iter().sum::<u64>() + cost[5]);
    // Every tile looked up until loaded (evicting within the budget, some looked up many
    // times): each once.
    for &t in &free {
        fetch(&pager, t);
    }
    assert!(pager.stats().evicted > 0);
    assert_eq!(pager.working_set(), free);
    assert_eq!(pager.working_set_bytes(), cost.iter().sum::<u64>());
    pager.begin_working_set();
    assert_eq!((pager.working_set(), pager.working_set_bytes()), (Vec::new(), 0));
}

/// Many threads asking for tiles at random under a budget of one tile more than the least,
/// with many fetchers evicting at once: a tile found available always holds its checked
/// bytes, and every tile available at the end does too. (A fetcher could once load a tile
/// again while another, evicting it, had yet to release its pages: the release then left an
/// available tile of zeros.)
#[test]
fn tiles_found_available_hold_their_bytes_under_many_fetchers() {
    let dir = tempfile::tempdir().unwrap();
    let path = scene_file(dir.path());
    let probe = Scene::open(&path).unwrap();
    let biggest = probe.tiles().iter().map(|e| e.bytes as u64).max().unwrap();
    let budget = Pager::min_budget(&probe) + biggest;
    drop(probe);
    let pager = Pager::open(&path, PagerOptions { budget, fetchers: 8 }).unwrap();
    let scene = pager.scene().clone();
    let n = scene.tiles().len() as u32;
    std::thread::scope(|s| {
        for k in 0..12u64 {
            let (pager, scene) = (&pager, &scene);
            s.spawn(move || {
                // A few tiles again and again, so that loads and evictions of the same tile
                // meet: xorshift over the first eight tiles and the rest.
                let mut x = 0x9e37_79b9_7f4a_7c15u64 ^ (k + 1).wrapping_mul(0x2545_f491_4f6c_dd1d);
                for _ in 0..20_000 {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    let t = if x.is_multiple_of(4) { (x >> 8) as u32 % n } else { (x >> 8) as u32 % n.min(8) };
                    let _pin = pager.pin();
                    match pager.acquire(t) {
                        Access::Ready => {
                            scene.check_tile(t).unwrap_or_else(|e| panic!("tile {t} found available: {e}"))
                        }
                        Access::Missing => std::thread::yield_now(),
                        Access::Corrupt => panic!("tile {t} corrupt: {:?}", pager.first_error()),
                    }
                }
            });
        }
    });
    std::thread::sleep(Duration::from_millis(50));
    let _pin = pager.pin();
    for t in (0..n).filter(|&t| pager.is_resident(t)) {
        scene.check_tile(t).unwrap_or_else(|e| panic!("tile {t} resident at the end: {e}"));
    }
    let st = pager.stats();
    assert!(st.evicted > 100 && pager.first_error().is_none(), "{st:?}");
}
