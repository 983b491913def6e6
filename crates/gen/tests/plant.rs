//! `plant:T`: counts, budget, determinism, geometry sanity, variety.

use megaray_base::{tri_is_degenerate, tri_is_finite, NoProgress};
use megaray_gen::{generate, CountingSink, GenError, GenSpec, MeshSink};
use std::hash::Hasher;

/// Checks every chunk and gathers statistics.
#[derive(Default)]
struct Check {
    verts: u64,
    tris: u64,
    chunks: u64,
    degenerate: u64,
    non_finite: u64,
    foreign_refs: u64,
    max_chunk: usize,
    /// Triangle areas, sampled (every 7th triangle).
    areas: Vec<f32>,
    hash: std::collections::hash_map::DefaultHasher,
}

impl MeshSink for Check {
    fn chunk(&mut self, verts: &[[f32; 3]], tris: &[[u32; 3]]) -> Result<(), GenError> {
        let base = self.verts;
        for t in tris {
            let local = t.map(|i| i as u64);
            if local.iter().any(|&i| i < base || i >= base + verts.len() as u64) {
                self.foreign_refs += 1;
                continue;
            }
            let c = local.map(|i| verts[(i - base) as usize]);
            if !tri_is_finite(&c) {
                self.non_finite += 1;
            } else if tri_is_degenerate(&c) {
                self.degenerate += 1;
            }
            if self.tris % 7 == 0 {
                let [a, b, cc] = c.map(megaray_base::Vec3::from);
                self.areas.push(0.5 * (b - a).cross(cc - a).length());
            }
            self.tris += 1;
        }
        for v in verts {
            for c in v {
                self.hash.write_u32(c.to_bits());
            }
        }
        for t in tris {
            for &i in t {
                self.hash.write_u32(i);
            }
        }
        self.verts += verts.len() as u64;
        self.chunks += 1;
        self.max_chunk = self.max_chunk.max(tris.len());
        Ok(())
    }
}

fn check(spec: &GenSpec) -> Check {
    let mut c = Check::default();
    generate(spec, &mut c, &NoProgress).unwrap();
    c
}

fn plant(t: u64, seed: u64) -> GenSpec {
    GenSpec::Plant { tris: t, seed }
}

#[test]
fn counts_are_exact_and_close_to_the_target() {
    for t in [1000, 10_000, 55_555, 100_000, 1_000_000] {
        for seed in [1, 2, 77] {
            let spec = plant(t, seed);
            let mut sink = CountingSink::default();
            generate(&spec, &mut sink, &NoProgress).unwrap();
            assert_eq!((sink.verts, sink.tris), spec.counts(), "{spec}");
            let err = (sink.tris as f64 - t as f64).abs() / t as f64;
            assert!(err < 0.02, "{spec}: {} triangles", sink.tris);
            let ratio = sink.verts as f64 / sink.tris as f64;
            assert!((0.45..=1.0).contains(&ratio), "{spec}: {ratio} vertices per triangle");
        }
    }
}

#[test]
fn geometry_is_sane_and_varied() {
    let c = check(&plant(1_000_000, 1));
    assert_eq!(c.non_finite, 0);
    assert_eq!(c.degenerate, 0);
    assert_eq!(c.foreign_refs, 0, "plant chunks are self-contained");
    assert!(c.chunks >= 2000 && c.chunks < 100_000, "{} objects", c.chunks);
    assert!(c.max_chunk < 1_000_000);
    let mut a = c.areas;
    a.sort_by(f32::total_cmp);
    let (p10, p50, p90) = (a[a.len() / 10], a[a.len() / 2], a[a.len() * 9 / 10]);
    assert!(p10 > 0.0 && p90 / p10 > 100.0, "triangle areas p10 {p10} p50 {p50} p90 {p90}");
}

#[test]
fn small_plants_are_sane_for_many_seeds() {
    for seed in 0..40 {
        let c = check(&plant(30_000, seed));
        assert_eq!((c.non_finite, c.degenerate, c.foreign_refs), (0, 0, 0), "seed {seed}");
        assert!(c.chunks >= 50, "seed {seed}: {} objects", c.chunks);
    }
}

#[test]
fn deterministic_per_seed() {
    let h = |spec: &GenSpec| check(spec).hash.finish();
    let a = h(&plant(200_000, 5));
    assert_eq!(a, h(&plant(200_000, 5)));
    assert_ne!(a, h(&plant(200_000, 6)));
    assert_ne!(a, h(&plant(200_001, 5)));
    // The seed only comes in through the spec.
    assert_eq!(a, h(&"plant:200k".parse::<GenSpec>().unwrap().with_seed(5)));
}

#[test]
fn bigger_plants_stay_in_small_chunks() {
    let spec = plant(10_000_000, 3);
    let mut sink = CountingSink::default();
    generate(&spec, &mut sink, &NoProgress).unwrap();
    assert_eq!((sink.verts, sink.tris), spec.counts());
    assert!(sink.max_chunk_tris < 100_000, "largest object {}", sink.max_chunk_tris);
    assert!(sink.tris.abs_diff(10_000_000) < 200_000);
    let e = sink.bounds.extent();
    assert!(e.x > 200.0 && e.z > 200.0 && e.y > 10.0 && e.y < e.x, "{e:?}");
}
