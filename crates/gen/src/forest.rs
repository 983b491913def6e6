//! `forest:T[:U[:S]]`: a procedural forest after the seed's, written as a pbrt-v4 scene. `S`
//! tree species (default 4), objects of about `U` triangles each (a trunk and a crown of leaf
//! clusters; default 100k), are placed as instances in a grove (25 trees, or one of each
//! species when there are more), and the grove is instanced again level upon level (each
//! level a 4x4 field of the one below, turned at random) until the scene shows at least `T`
//! triangles (say `1e14`): bytes per instance, not per triangle; `S x U` triangles are
//! unique (`forest:1e14:10M:100`: a billion). The trees are
//! binary PLY files beside the scene; levels nest `ObjectInstance` inside `ObjectBegin`
//! (megaray's extension of pbrt-v4, see `megaray_import::pbrt`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use megaray_base::{hash32, u01, Progress};

use crate::{GenError, MeshSink, PlyWriter};

/// Tree species (objects) in a forest, unless the spec says.
pub const SPECIES: usize = 4;
/// The most species a forest may have.
pub const MAX_SPECIES: usize = 10_000;
/// Trees in a grove (or one of each species, when there are more).
pub const GROVE: usize = 25;
/// Copies of a level in the next (a 4x4 field).
pub const FIELD: usize = 16;

/// A forest to generate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForestSpec {
    /// Triangles the scene should show at least (every instance counted).
    pub shown: f64,
    /// Triangles of each tree, about.
    pub tree_tris: u64,
    /// Tree species (objects), each its own PLY file.
    pub species: usize,
    /// Seeds the trees and their places.
    pub seed: u32,
}

impl std::str::FromStr for ForestSpec {
    type Err = GenError;
    /// `forest:1e14`, `forest:1e12:20k`, `forest:1e14:10M:100`.
    fn from_str(s: &str) -> Result<ForestSpec, GenError> {
        let bad = |w: &str| GenError::spec(s, w.to_string());
        let rest = s.strip_prefix("forest:").ok_or_else(|| bad("not a forest (forest:T[:U[:S]])"))?;
        let mut it = rest.split(':');
        let shown = it.next().and_then(parse_big).ok_or_else(|| bad("T: a triangle count such as 1e14 or 500G"))?;
        let tree_tris = match it.next() {
            Some(u) => parse_big(u)
                .filter(|&u| (1e3..=1e7).contains(&u))
                .ok_or_else(|| bad("U: 1k to 10M triangles a tree"))?,
            None => 1e5,
        };
        let species = match it.next() {
            Some(n) => n
                .parse::<usize>()
                .ok()
                .filter(|n| (1..=MAX_SPECIES).contains(n))
                .ok_or_else(|| bad("S: 1 to 10000 species"))?,
            None => SPECIES,
        };
        if it.next().is_some() || !(1.0..=1e20).contains(&shown) {
            return Err(bad("expected forest:T[:U[:S]] with T up to 1e20"));
        }
        Ok(ForestSpec { shown, tree_tris: tree_tris as u64, species, seed: 1 })
    }
}

/// `1e14`, `500G`, `2T`, `100k`.
fn parse_big(s: &str) -> Option<f64> {
    let (num, mult) = match s.as_bytes().last()? {
        b'k' | b'K' => (&s[..s.len() - 1], 1e3),
        b'm' | b'M' => (&s[..s.len() - 1], 1e6),
        b'g' | b'G' => (&s[..s.len() - 1], 1e9),
        b't' | b'T' => (&s[..s.len() - 1], 1e12),
        _ => (s, 1.0),
    };
    let v = num.parse::<f64>().ok()? * mult;
    (v.is_finite() && v > 0.0).then_some(v)
}

/// What [`write_forest`] wrote.
#[derive(Clone, Debug)]
pub struct ForestSummary {
    /// Triangles in the tree objects (unique).
    pub unique: u64,
    /// Triangles the scene shows.
    pub shown: f64,
    /// Levels of groves above the grove.
    pub levels: u32,
    /// The files written: the scene, then the trees.
    pub files: Vec<PathBuf>,
}

/// Writes the forest `spec` to the pbrt scene `out` and its trees beside it.
pub fn write_forest(spec: &ForestSpec, out: &Path, progress: &dyn Progress) -> Result<ForestSummary, GenError> {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "forest".into());
    let dir = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut files = vec![out.to_path_buf()];
    let mut unique = 0u64;
    let mut tree_tris = vec![0u64; spec.species];
    progress.stage("trees", spec.species as u64);
    for (k, tris) in tree_tris.iter_mut().enumerate() {
        let path = dir.join(format!("{stem}-tree{k}.ply"));
        let mut w = PlyWriter::create(&path)?;
        *tris = tree(&mut w, spec.tree_tris, spec.seed.wrapping_mul(977).wrapping_add(k as u32))?;
        w.finish()?;
        unique += *tris;
        files.push(path);
        progress.inc(1);
    }
    progress.finish();
    // A grove of 25 trees (or one of each species), species in turn, then levels of 4x4
    // fields of the one below.
    let trees = GROVE.max(spec.species);
    let side = (trees as f64).sqrt().ceil() as usize;
    let grove: f64 = (0..trees).map(|i| tree_tris[i % spec.species] as f64).sum();
    let mut levels = 0;
    let mut shown = grove;
    while shown < spec.shown {
        shown *= FIELD as f64;
        levels += 1;
    }
    let mut s = String::new();
    let grove_size = 12.0 * side as f32;
    let _ = writeln!(s, "# megaray gen forest: {} triangles shown, {unique} unique, {levels} levels of groves", shown);
    // From just above the canopy at a corner, across the forest to the horizon.
    let _ = writeln!(s, "LookAt -12 26 -12  120 0 150  0 1 0");
    let _ = writeln!(s, "Camera \"perspective\" \"float fov\" [ 50 ]");
    let _ = writeln!(s, "Film \"rgb\" \"integer xresolution\" [ 1024 ] \"integer yresolution\" [ 768 ]");
    let _ = writeln!(s, "WorldBegin");
    let _ = writeln!(
        s,
        "LightSource \"distant\" \"point3 from\" [ 0.4 1 0.3 ] \"point3 to\" [ 0 0 0 ] \"rgb L\" [ 3 3 2.8 ]"
    );
    let _ = writeln!(s, "MakeNamedMaterial \"bark\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.25 0.17 0.1 ]");
    let _ =
        writeln!(s, "MakeNamedMaterial \"leaves\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.12 0.35 0.08 ]");
    let _ =
        writeln!(s, "MakeNamedMaterial \"ground\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.3 0.25 0.18 ]");
    for k in 0..spec.species {
        let _ = writeln!(s, "ObjectBegin \"tree{k}\"\n  NamedMaterial \"leaves\"\n  Shape \"plymesh\" \"string filename\" \"{stem}-tree{k}.ply\"\nObjectEnd");
    }
    let mut rng = spec.seed.wrapping_add(12345);
    let mut rnd = || {
        rng = hash32(rng);
        u01(rng)
    };
    let _ = writeln!(s, "ObjectBegin \"grove\"");
    for i in 0..trees {
        let (gx, gz) = ((i % side) as f32, (i / side) as f32);
        let cell = grove_size / side as f32;
        let (x, z) = ((gx + 0.2 + 0.6 * rnd()) * cell, (gz + 0.2 + 0.6 * rnd()) * cell);
        let (turn, size) = (360.0 * rnd(), 0.7 + 0.6 * rnd());
        let _ = writeln!(s, "  AttributeBegin\n    Translate {x} 0 {z}\n    Rotate {turn} 0 1 0\n    Scale {size} {size} {size}\n    ObjectInstance \"tree{}\"\n  AttributeEnd", i % spec.species);
    }
    let _ = writeln!(s, "ObjectEnd");
    let mut below = "grove".to_string();
    let mut size = grove_size;
    for l in 1..=levels {
        let name = format!("level{l}");
        let _ = writeln!(s, "ObjectBegin \"{name}\"");
        for i in 0..FIELD {
            let (gx, gz) = ((i % 4) as f32 * size, (i / 4) as f32 * size);
            // A quarter turn at random about the copy's centre: fields do not repeat in rows.
            let turn = 90.0 * (4.0 * rnd()).floor();
            let h = size / 2.0;
            let _ = writeln!(s, "  AttributeBegin\n    Translate {} 0 {}\n    Rotate {turn} 0 1 0\n    Translate {} 0 {}\n    ObjectInstance \"{below}\"\n  AttributeEnd", gx + h, gz + h, -h, -h);
        }
        let _ = writeln!(s, "ObjectEnd");
        below = name;
        size *= 4.0;
    }
    let _ = writeln!(s, "ObjectInstance \"{below}\"");
    let _ = writeln!(s, "NamedMaterial \"ground\"\nShape \"bilinearmesh\" \"point3 P\" [ 0 0 0  {size} 0 0  0 0 {size}  {size} 0 {size} ]");
    let tmp =
        megaray_base::temp::temp_path(out).ok_or_else(|| GenError::spec("forest", "the output is not a file name"))?;
    std::fs::write(&tmp, s.as_bytes()).map_err(|e| GenError::io(&tmp, "write", e))?;
    std::fs::rename(&tmp, out).map_err(|e| GenError::io(out, "rename into place", e))?;
    Ok(ForestSummary { unique, shown, levels, files })
}

/// One tree of about `target` triangles into `w`: a trunk (a tapered cylinder) and a
/// crown of leaf clusters (bumpy spheres). Returns its triangle count.
fn tree(w: &mut dyn MeshSink, target: u64, seed: u32) -> Result<u64, GenError> {
    let mut s = seed;
    let mut rnd = || {
        s = hash32(s);
        u01(s)
    };
    let height = 8.0 + 4.0 * rnd();
    let mut base = 0u32;
    let mut tris_out = 0u64;
    // Trunk: 16 sides, 8 rings.
    let (sides, rings) = (16u32, 8u32);
    let mut verts = Vec::new();
    let mut tris = Vec::new();
    for r in 0..=rings {
        let y = height * 0.7 * r as f32 / rings as f32;
        let rad = 0.45 * (1.0 - 0.6 * r as f32 / rings as f32);
        for k in 0..sides {
            let a = std::f32::consts::TAU * k as f32 / sides as f32;
            verts.push([rad * a.cos(), y, rad * a.sin()]);
        }
    }
    for r in 0..rings {
        for k in 0..sides {
            let (a, b) = (r * sides + k, r * sides + (k + 1) % sides);
            let (c, d) = (a + sides, b + sides);
            tris.push([a, c, b]);
            tris.push([b, c, d]);
        }
    }
    w.chunk(&verts, &tris)?;
    tris_out += tris.len() as u64;
    base += verts.len() as u32;
    // Crown: clusters of the rest of the triangles.
    let clusters = 12u64;
    let per = target.saturating_sub(tris_out).max(clusters * 8) / clusters;
    let n = ((per as f64 / 2.0).sqrt().round() as u32).max(2);
    for _ in 0..clusters {
        let (cx, cy, cz) = ((rnd() - 0.5) * 4.0, height * (0.55 + 0.45 * rnd()), (rnd() - 0.5) * 4.0);
        let rad = 1.2 + 1.3 * rnd();
        verts.clear();
        tris.clear();
        for i in 0..=n {
            for j in 0..n {
                let th = std::f32::consts::PI * i as f32 / n as f32;
                let ph = std::f32::consts::TAU * j as f32 / n as f32;
                let bump = 1.0 + 0.15 * (hash32(seed ^ (i * 7919 + j)) as f32 / u32::MAX as f32);
                let rr = rad * bump;
                verts.push([cx + rr * th.sin() * ph.cos(), cy + rr * th.cos(), cz + rr * th.sin() * ph.sin()]);
            }
        }
        for i in 0..n {
            for j in 0..n {
                let (a, b) = (base + i * n + j, base + i * n + (j + 1) % n);
                let (c, d) = (a + n, b + n);
                if i > 0 {
                    tris.push([a, b, c]);
                }
                if i + 1 < n {
                    tris.push([b, d, c]);
                }
            }
        }
        w.chunk(&verts, &tris)?;
        tris_out += tris.len() as u64;
        base += verts.len() as u32;
    }
    Ok(tris_out)
}
