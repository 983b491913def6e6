//! Which way of loading tiles is faster on this machine: through the map (madvise WILLNEED,
//! then touching every page while checksumming) or pread into a buffer of our own.
//!
//! ```sh
//! cargo run --release -p megaray-page --example load_paths -- big.mray [TILES] [THREADS]
//! ```
//!
//! For each path and thread count: drop the file from the page cache (posix_fadvise
//! DONTNEED, and madvise DONTNEED of our map), then load the same random TILES tiles (default
//! 2000), verifying each checksum, split over THREADS threads; prints MB/s. Run it on a scene
//! much larger than the page cache holds between runs for honest cold figures.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use megaray_scene::Scene;

fn drop_cache(scene: &Scene, file: &File) {
    let len = scene.bytes().len() as u64;
    let _ = scene.release(0, len);
    megaray_page::drop_page_cache(file, 0, 0);
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: load_paths SCENE.mray [TILES] [THREADS,..]");
        std::process::exit(2);
    };
    let want: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(2000);
    let threads: Vec<usize> =
        args.get(3).map_or(vec![1, 2, 4], |s| s.split(',').filter_map(|t| t.parse().ok()).collect());
    let scene = match Scene::open(path.as_ref()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("load_paths: {e}");
            std::process::exit(1);
        }
    };
    let file = File::open(path).expect("reopen the scene");
    let _ = scene.advise_random();
    let n = scene.tiles().len();
    // A fixed pseudo-random choice of tiles.
    let mut x = 0x9e3779b97f4a7c15u64;
    let mut pick: Vec<u32> = (0..want.min(n))
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % n as u64) as u32
        })
        .collect();
    pick.sort_unstable();
    pick.dedup();
    let bytes: u64 = pick.iter().map(|&t| scene.tiles()[t as usize].bytes as u64).sum();
    println!("{path}: {} tiles of {n}, {:.1} MB", pick.len(), bytes as f64 / 1e6);
    for &th in &threads {
        for method in ["map", "pread"] {
            drop_cache(&scene, &file);
            let next = AtomicUsize::new(0);
            let t0 = Instant::now();
            std::thread::scope(|s| {
                for _ in 0..th {
                    s.spawn(|| {
                        let mut buf = Vec::new();
                        loop {
                            let i = next.fetch_add(1, Ordering::Relaxed);
                            let Some(&t) = pick.get(i) else { break };
                            let e = &scene.tiles()[t as usize];
                            match method {
                                "map" => {
                                    let _ = scene.will_need(e.offset, e.bytes as u64);
                                    scene.check_tile(t).expect("tile checks");
                                }
                                _ => {
                                    buf.resize(e.bytes as usize, 0);
                                    file.read_exact_at(&mut buf, e.offset).expect("pread");
                                    assert_eq!(xxhash_rust::xxh3::xxh3_64(&buf), e.checksum);
                                }
                            }
                        }
                    });
                }
            });
            let secs = t0.elapsed().as_secs_f64();
            println!(
                "{method:>5} {th} threads: {:.3} s, {:.0} MB/s, {:.0} tiles/s",
                secs,
                bytes as f64 / secs / 1e6,
                pick.len() as f64 / secs
            );
        }
    }
    drop_cache(&scene, &file);
}
