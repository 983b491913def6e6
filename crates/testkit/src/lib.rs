//! # megaray-testkit: helpers for the megaray crates' tests (a dev-dependency only)
//!
//! The real test models (`shared/models` beside the repository), generated models, scenes
//! built from them into temporary folders, and a small deterministic random number generator.

use std::path::{Path, PathBuf};

use megaray_base::NoProgress;
use megaray_build::{build_scene, BuildOptions, BuildSummary};

/// The folder of real test models (`shared/models` beside the repository).
pub fn models_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/models");
    assert!(d.is_dir(), "test models not found at {} (shared/ must sit beside the repository)", d.display());
    d
}

pub fn model(name: &str) -> PathBuf {
    models_dir().join(name)
}

/// Generates `spec` as PLY into `dir`.
pub fn gen(dir: &Path, spec: &str) -> PathBuf {
    let s: megaray_gen::GenSpec = spec.parse().unwrap();
    let p = dir.join(format!("{}.ply", spec.replace(':', "_")));
    megaray_gen::write_ply(&s, &p, &NoProgress).unwrap();
    p
}

/// Builds `inputs` into `dir/name.mray`, with at most `max_part` triangles a part and
/// tiles of about 64 KiB (many tiles, so that links and paging are exercised).
pub fn build(dir: &Path, inputs: &[PathBuf], name: &str, max_part: Option<u64>) -> (PathBuf, BuildSummary) {
    build_with(dir, inputs, name, BuildOptions { max_part_tris: max_part, ..test_options() })
}

/// [`build`] without levels of detail.
pub fn build_without_lod(dir: &Path, inputs: &[PathBuf], name: &str, max_part: Option<u64>) -> (PathBuf, BuildSummary) {
    build_with(dir, inputs, name, BuildOptions { max_part_tris: max_part, lod: None, ..test_options() })
}

/// The options [`build`] starts from: 512 MiB, tiles of 64 KiB, two threads.
pub fn test_options() -> BuildOptions {
    BuildOptions { build_mem: 512 << 20, tile_target: 64 << 10, threads: 2, ..BuildOptions::default() }
}

/// Builds `inputs` into `dir/name.mray` with `opts`.
pub fn build_with(dir: &Path, inputs: &[PathBuf], name: &str, opts: BuildOptions) -> (PathBuf, BuildSummary) {
    let out = dir.join(format!("{name}.mray"));
    let s = build_scene(inputs, &out, &opts, &NoProgress).unwrap();
    (out, s)
}

/// A small deterministic random number generator (splitmix64).
pub struct Rng(pub u64);
impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// The distance from `p` to the triangle `[a, b, c]` (its closest point, Ericson 2004, 5.1.5).
pub fn point_triangle_distance(p: [f32; 3], [a, b, c]: [[f32; 3]; 3]) -> f32 {
    let v = |x: [f32; 3]| megaray_base::Vec3::from(x);
    let (p, a, b, c) = (v(p), v(a), v(b), v(c));
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (p - a).length();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length();
    }
    let (vc, vb, va) = (d1 * d4 - d3 * d2, d5 * d2 - d1 * d6, d3 * d6 - d5 * d4);
    let q = if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        a + ab * (d1 / (d1 - d3))
    } else if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        a + ac * (d2 / (d2 - d6))
    } else if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))
    } else {
        let den = 1.0 / (va + vb + vc);
        a + ab * (vb * den) + ac * (vc * den)
    };
    (p - q).length()
}

/// A triangle's corners.
pub type Tri = [[f32; 3]; 3];

/// Builds a scene of `objects` (triangles in memory) placed by `plan` into `dir/name.mray`.
pub fn build_instanced(
    dir: &Path,
    name: &str,
    objects: &[Vec<Tri>],
    plan: &megaray_build::objects::InstancePlan,
    opts: BuildOptions,
) -> (PathBuf, BuildSummary) {
    use megaray_build::{ObjectInput, SceneInput};
    let out = dir.join(format!("{name}.mray"));
    let objects = objects
        .iter()
        .enumerate()
        .map(|(k, tris)| ObjectInput { name: format!("object {k}"), source: feed(tris.clone()) })
        .collect();
    let input = SceneInput { objects, instancing: Some(plan.clone()), materials: Vec::new(), settings: String::new() };
    let s = megaray_build::build_objects(input, &out, &opts, &NoProgress).unwrap();
    (out, s)
}

/// Builds `tris` as a scene without instances into `dir/name.mray`.
pub fn build_tris(dir: &Path, name: &str, tris: Vec<Tri>, opts: BuildOptions) -> (PathBuf, BuildSummary) {
    let out = dir.join(format!("{name}.mray"));
    let s =
        megaray_build::build_objects(megaray_build::SceneInput::plain(feed(tris)), &out, &opts, &NoProgress).unwrap();
    (out, s)
}

fn feed<'a>(tris: Vec<Tri>) -> megaray_build::ObjectSource<'a> {
    megaray_build::ObjectSource::Fn(Box::new(move |sink| {
        let attr = megaray_import::TriAttr { material: megaray_import::NO_MATERIAL, ..Default::default() };
        for t in tris {
            sink.triangle(t, &attr)?;
        }
        Ok(())
    }))
}

/// Every triangle `plan` shows, in world space: each object's triangles moved along every
/// path of instances from group 0 down to it.
pub fn expand(objects: &[Vec<Tri>], plan: &megaray_build::objects::InstancePlan) -> Vec<Tri> {
    use megaray_base::{Affine, Vec3};
    use megaray_scene::Target;
    fn walk(
        objects: &[Vec<Tri>],
        plan: &megaray_build::objects::InstancePlan,
        g: usize,
        to_world: Affine,
        out: &mut Vec<Tri>,
    ) {
        let gr = &plan.groups[g];
        for inst in &plan.instances[gr.first as usize..(gr.first + gr.count) as usize] {
            let m = to_world.then_after(&inst.xform);
            match inst.target {
                Target::Group(h) => walk(objects, plan, h as usize, m, out),
                Target::Object(o) => {
                    out.extend(objects[o as usize].iter().map(|t| t.map(|c| m.point(Vec3::from(c)).into())))
                }
            }
        }
    }
    let mut out = Vec::new();
    walk(objects, plan, 0, Affine::IDENTITY, &mut out);
    out
}

/// A closed sphere of `2 n^2` triangles around `c`, radius `r`, slightly bumpy (so that
/// its triangles differ).
pub fn sphere(c: [f32; 3], r: f32, n: usize) -> Vec<Tri> {
    let p = |i: usize, j: usize| -> [f32; 3] {
        let th = std::f32::consts::PI * i as f32 / n as f32;
        let ph = 2.0 * std::f32::consts::PI * j as f32 / n as f32;
        let rr = r * (1.0 + 0.05 * ((3 * i + 5 * j) % 7) as f32 / 7.0);
        let rr = if i == 0 || i == n { r } else { rr };
        [c[0] + rr * th.sin() * ph.cos(), c[1] + rr * th.cos(), c[2] + rr * th.sin() * ph.sin()]
    };
    let mut out = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, cc, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
            out.push([a, b, cc]);
            out.push([a, cc, d]);
        }
    }
    out.retain(|t| !megaray_base::tri_is_degenerate(t));
    out
}

/// The closest hit of `ray` over every full-detail triangle of `scene`, by brute force:
/// (t, part, slot in the part). What picks are checked against.
pub fn brute_closest(scene: &megaray_scene::Scene, ray: &megaray_base::Ray) -> Option<(f32, u32, u32)> {
    let mut best: Option<(f32, u32, u32)> = None;
    for (t, e) in scene.tiles().iter().enumerate() {
        if scene.parts()[e.part as usize].lod_level != 0 {
            continue;
        }
        for (slot, tri) in scene.tile_view(t as u32).triangles() {
            let limit = best.map_or(f32::INFINITY, |b| b.0);
            if let Some(h) = megaray_base::intersect_triangle(ray, tri.map(megaray_base::Vec3::from), limit) {
                best = Some((h.t, e.part, e.first_slot + slot));
            }
        }
    }
    best
}

/// Where in `scene`'s file the byte at image offset `off` of a tile is stored, for tests that
/// damage a tile: the same offset in a plain file; in a compact one, the byte of the tile's
/// stored form as far into it (at most its last byte).
pub fn stored_offset(scene: &megaray_scene::Scene, off: u64) -> u64 {
    let ext = scene.extents();
    let i = ext.partition_point(|e| e.image_off + e.image_len <= off);
    match ext.get(i).filter(|e| e.image_off <= off) {
        Some(e) if e.kind == megaray_scene::format::EXTENT_TILE => {
            e.stored_off + (off - e.image_off).min(e.stored_len.saturating_sub(1))
        }
        Some(e) => e.stored_off + (off - e.image_off),
        None => off,
    }
}
