//! `grid` and `sphereflake` against the Embree peer harness: counts, bounds, vertices
//! recomputed from the peer's formulas, and the exact bytes of its `--dump-ply` output.

use megaray_base::NoProgress;
use megaray_gen::{generate, write_ply, CountingSink, GenError, GenSpec, MeshSink};

/// FNV-1a, 64 bit.
fn fnv64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x100_0000_01b3);
    }
    h
}

/// Collects everything (small models only).
#[derive(Default)]
struct Collect {
    verts: Vec<[f32; 3]>,
    tris: Vec<[u32; 3]>,
    chunks: usize,
}

impl MeshSink for Collect {
    fn chunk(&mut self, verts: &[[f32; 3]], tris: &[[u32; 3]]) -> Result<(), GenError> {
        self.verts.extend_from_slice(verts);
        self.tris.extend_from_slice(tris);
        self.chunks += 1;
        Ok(())
    }
}

fn ply_hash(spec: &str) -> (u64, usize) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.ply");
    write_ply(&spec.parse().unwrap(), &out, &NoProgress).unwrap();
    let bytes = std::fs::read(&out).unwrap();
    if let Ok(peer) = std::env::var("MEGARAY_PEER_PLY_DIR") {
        // Optional: byte-compare with `embree_bench --gen SPEC --dump-ply DIR/SPEC.ply`.
        let p = std::path::Path::new(&peer).join(format!("{spec}.ply"));
        if let Ok(theirs) = std::fs::read(&p) {
            assert!(theirs == bytes, "{spec}: differs from {}", p.display());
            eprintln!("{spec}: identical to {}", p.display());
        }
    }
    (fnv64(&bytes), bytes.len())
}

/// With `MEGARAY_PEER_PLY_DIR` set, also compares other sizes with the peer's dumps there.
#[test]
fn other_sizes_match_the_peer_when_its_dumps_are_given() {
    if std::env::var("MEGARAY_PEER_PLY_DIR").is_err() {
        return;
    }
    for spec in ["grid:3", "grid:37", "sphereflake:0:2", "sphereflake:2:5", "sphereflake:3:31"] {
        ply_hash(spec);
    }
}

#[test]
fn grid_1000_is_the_peers_byte_for_byte() {
    let spec: GenSpec = "grid:1000".parse().unwrap();
    assert_eq!(spec.counts(), (1_002_001, 2_000_000));
    assert_eq!(ply_hash("grid:1000"), (GRID_1000_FNV, 38_024_193));
}

#[test]
fn sphereflake_4_is_the_peers_byte_for_byte() {
    let spec: GenSpec = "sphereflake:4".parse().unwrap();
    assert_eq!(spec.counts(), (1_963_346, 3_897_168));
    assert_eq!(ply_hash("sphereflake:4"), (FLAKE_4_FNV, 74_223_517));
}

/// FNV-1a of the peer's `embree_bench --gen grid:1000 --dump-ply` (g++ 12.2 -O3
/// -march=native, glibc 2.36) and of `--gen sphereflake:4`.
const GRID_1000_FNV: u64 = 6_234_363_117_050_747_119;
const FLAKE_4_FNV: u64 = 11_130_078_148_253_437_770;

/// The peer's `3.14159265358979f`.
const PI: f32 = std::f32::consts::PI;

#[test]
fn grid_vertices_follow_the_formula() {
    let n = 1000u32;
    let mut sink = Collect::default();
    generate(&GenSpec::Grid { n }, &mut sink, &NoProgress).unwrap();
    assert_eq!(sink.verts.len(), 1_002_001);
    assert_eq!(sink.tris.len(), 2_000_000);
    assert_eq!(sink.chunks, 1001, "one chunk per row");
    // x and z exactly as the peer computes them: -1.0f + 2.0f * i / n.
    for (i, j) in [(0u32, 0u32), (1, 0), (0, 1), (500, 250), (999, 1000), (1000, 1000), (123, 877)] {
        let v = sink.verts[(j * (n + 1) + i) as usize];
        let x = -1.0f32 + (2.0 * i as f32) / n as f32;
        let z = -1.0f32 + (2.0 * j as f32) / n as f32;
        assert_eq!((v[0], v[2]), (x, z));
        let y = 0.10 * (3.0 * PI * x).sin() * (2.0 * PI * z).cos()
            + 0.05 * (11.0 * x + 7.0 * z).sin()
            + 0.02 * (37.0 * x).sin() * (41.0 * z).sin();
        assert!((v[1] - y).abs() < 1e-6, "{i},{j}: {} vs {y}", v[1]);
    }
    // The peer's first cell: (a, c, b), (b, c, d).
    assert_eq!(sink.tris[0], [0, 1001, 1]);
    assert_eq!(sink.tris[1], [1, 1001, 1002]);
    let b = megaray_base::Aabb::from_points(&sink.verts);
    assert_eq!((b.min[0], b.min[2], b.max[0], b.max[2]), (-1.0, -1.0, 1.0, 1.0));
    // The peer prints bbox (-1 -0.16324 -1)-(1 0.165771 1).
    assert!((b.min[1] + 0.16324).abs() < 1e-5 && (b.max[1] - 0.165771).abs() < 1e-5, "{b:?}");
}

#[test]
fn sphereflake_structure_and_bounds() {
    let spec: GenSpec = "sphereflake:4".parse().unwrap();
    let mut sink = CountingSink::default();
    generate(&spec, &mut sink, &NoProgress).unwrap();
    assert_eq!(sink.chunks, 7381, "one chunk per sphere");
    assert_eq!(sink.max_chunk_tris, 528);
    assert_eq!((sink.verts, sink.tris), (1_963_346, 3_897_168));
    // The peer prints bbox (-1.78917 -1 -1.91137)-(1.7296 1.75366 1.91137).
    let b = sink.bounds;
    let want = ([-1.78917, -1.0, -1.91137], [1.7296, 1.75366, 1.91137]);
    for k in 0..3 {
        assert!((b.min[k] - want.0[k]).abs() < 1e-5 && (b.max[k] - want.1[k]).abs() < 1e-5, "{b:?}");
    }

    // The root sphere: poles, and ring vertices on the unit sphere at the peer's angles.
    let mut one = Collect::default();
    generate(&"sphereflake:0".parse().unwrap(), &mut one, &NoProgress).unwrap();
    assert_eq!((one.verts.len(), one.tris.len()), (266, 528));
    assert_eq!(one.verts[0], [0.0, 1.0, 0.0]);
    assert_eq!(one.verts[265], [0.0, -1.0, 0.0]);
    let (i, k) = (3u32, 5u32);
    let th = PI * i as f32 / 12.0;
    let ph = 2.0 * PI * k as f32 / 24.0;
    let v = one.verts[(1 + (i - 1) * 24 + k) as usize];
    let want = [th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()];
    for c in 0..3 {
        assert!((v[c] - want[c]).abs() < 1e-6, "{v:?} vs {want:?}");
    }
    assert_eq!(one.tris[0], [0, 2, 1], "north cap winding as the peer's");
    assert_eq!(*one.tris.last().unwrap(), [265, 264, 241], "south cap closes the last ring");
    assert!(one.verts.iter().all(|v| ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() - 1.0).abs() < 1e-6));

    // The first child: radius 1/3, centre at distance 4/3 on the root's equator (azimuth 0).
    let mut two = Collect::default();
    generate(&"sphereflake:1".parse().unwrap(), &mut two, &NoProgress).unwrap();
    assert_eq!(two.chunks, 10);
    let child = &two.verts[266..532];
    let c =
        [(child[0][0] + child[265][0]) / 2.0, (child[0][1] + child[265][1]) / 2.0, (child[0][2] + child[265][2]) / 2.0];
    assert!(((c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() - 4.0 / 3.0).abs() < 1e-5, "{c:?}");
    assert!(c[1].abs() < 1e-6, "on the equator: {c:?}");
    assert!(((child[0][1] - child[265][1]) / 2.0 - 1.0 / 3.0).abs() < 1e-6);
}
