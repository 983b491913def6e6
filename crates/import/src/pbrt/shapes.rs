//! pbrt shapes as triangles: `trianglemesh`, `bilinearmesh` (two triangles a quad) and
//! `plymesh` (through the PLY reader), moved by their transforms as an object is built.

use std::path::{Path, PathBuf};

use megaray_base::{Affine, Progress, Vec3};

use super::lex::Loc;
use super::{ObjectDesc, Params, ShapeKind};
use crate::{ImportError, ImportOptions, Material, TriAttr, TriangleSink, NO_MATERIAL};

/// The shape `kind` with `p`, or `None` for a kind megaray does not draw (spheres, curves,
/// subdivision surfaces...).
pub(crate) fn shape(kind: &str, p: &Params, file: &Path, loc: &Loc) -> Result<Option<ShapeKind>, ImportError> {
    match kind {
        "trianglemesh" | "bilinearmesh" => {
            let pts = p.nums("P").ok_or_else(|| loc.err(format!("{kind} without \"point3 P\"")))?;
            if pts.len() % 3 != 0 {
                return Err(loc.err(format!("{kind}: {} values of P (not whole points)", pts.len())));
            }
            let pts: Vec<[f32; 3]> = pts.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            let per = if kind == "trianglemesh" { 3 } else { 4 };
            let idx: Vec<f64> = match p.values("indices") {
                Some(i) => i.to_vec(),
                None if pts.len() == per => (0..per).map(|i| i as f64).collect(),
                None => return Err(loc.err(format!("{kind} without \"integer indices\""))),
            };
            if !idx.len().is_multiple_of(per) {
                return Err(loc.err(format!("{kind}: {} indices (not a multiple of {per})", idx.len())));
            }
            let mut indices = Vec::with_capacity(idx.len() / per * 3);
            for c in idx.chunks_exact(per) {
                if let Some(bad) = c.iter().find(|&&i| i < 0.0 || i >= pts.len() as f64 || i.fract() != 0.0) {
                    return Err(loc.err(format!("{kind}: index {bad} out of range (0..{})", pts.len())));
                }
                let c: Vec<u32> = c.iter().map(|&i| i as u32).collect();
                match per {
                    3 => indices.extend_from_slice(&c),
                    // Bilinear patches list p00 p10 p01 p11.
                    _ => indices.extend_from_slice(&[c[0], c[1], c[3], c[0], c[3], c[2]]),
                }
            }
            let n = p.nums("N").map(|v| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>());
            let uv = p.nums("uv").map(|v| v.chunks_exact(2).map(|c| [c[0], c[1]]).collect::<Vec<_>>());
            let n = n.filter(|n| n.len() == pts.len());
            let uv = uv.filter(|uv| uv.len() == pts.len());
            Ok(Some(ShapeKind::Mesh { p: pts, indices, n, uv, color: None }))
        }
        "plymesh" => {
            let f = p.string("filename").ok_or_else(|| loc.err("plymesh without \"string filename\""))?;
            let path = file.parent().unwrap_or(Path::new(".")).join(f);
            if !path.is_file() {
                return Err(loc.err(format!("plymesh \"{f}\": no such file")));
            }
            Ok(Some(ShapeKind::Ply(path)))
        }
        _ => Ok(None),
    }
}

/// Hands object `obj`'s triangles to `sink`, each shape's moved by its transform, wound
/// the other way under `ReverseOrientation` or a mirroring transform (so that the winding
/// still faces outward), with the shape's material. Returns the bytes of files read.
pub fn feed_object(
    obj: &ObjectDesc,
    opts: &ImportOptions,
    sink: &mut dyn TriangleSink,
    progress: &dyn Progress,
) -> Result<u64, ImportError> {
    let mut bytes = 0;
    for s in &obj.shapes {
        // Each shape a component: its PLY file's name, or the kind and where it was declared.
        match &s.kind {
            ShapeKind::Ply(path) => sink.component(&path.file_name().unwrap_or_default().to_string_lossy()),
            ShapeKind::Mesh { .. } => sink.component(&format!("trianglemesh at {}", s.place)),
        }
        let normal = s.xform.inverse().unwrap_or(Affine::IDENTITY);
        let flip = s.reverse != (s.xform.determinant() < 0.0);
        let mut moved = Moved {
            sink: &mut *sink,
            xform: s.xform,
            normal,
            flip,
            material: s.material,
            orient: s.emitting,
            declared: &s.declared,
        };
        match &s.kind {
            ShapeKind::Mesh { p, indices, n, uv, color } => {
                for t in indices.chunks_exact(3) {
                    let c = [t[0] as usize, t[1] as usize, t[2] as usize];
                    let attr = TriAttr {
                        normal: n.as_ref().map(|n| c.map(|i| n[i])),
                        uv: uv.as_ref().map(|uv| c.map(|i| uv[i])),
                        color: color.as_ref().map(|a| c.map(|i| a[i])),
                        material: NO_MATERIAL,
                    };
                    moved.triangle(c.map(|i| p[i]), &attr)?;
                }
            }
            ShapeKind::Ply(path) => {
                let gz = path.extension().is_some_and(|e| e == "gz");
                let plain;
                let read = if gz {
                    plain = tempfile::Builder::new()
                        .suffix(".ply")
                        .tempfile_in(&opts.temp_dir)
                        .map_err(|e| ImportError::new(path, None, format!("cannot make a temporary file: {e}")))?;
                    let mut dec = flate2::read::GzDecoder::new(
                        std::fs::File::open(path)
                            .map_err(|e| ImportError::new(path, None, format!("cannot open: {e}")))?,
                    );
                    std::io::copy(&mut dec, &mut plain.as_file())
                        .map_err(|e| ImportError::new(path, None, format!("cannot decompress: {e}")))?;
                    plain.path().to_path_buf()
                } else {
                    path.clone()
                };
                bytes += crate::import_file(&read, opts, &mut moved, progress)?.bytes;
            }
        }
    }
    Ok(bytes)
}

/// A sink that moves triangles by a shape's transform on their way to another.
struct Moved<'a> {
    sink: &'a mut dyn TriangleSink,
    xform: Affine,
    /// The inverse of `xform`, whose transpose moves normals.
    normal: Affine,
    flip: bool,
    material: Option<u32>,
    /// Wind each triangle that has vertex normals to face the side they face.
    orient: bool,
    /// The shape's file and place in it, for errors.
    declared: &'a (PathBuf, String),
}

impl TriangleSink for Moved<'_> {
    fn triangle(&mut self, p: [[f32; 3]; 3], attr: &TriAttr) -> Result<(), ImportError> {
        let mut p: [[f32; 3]; 3] = p.map(|c| self.xform.point(Vec3::from(c)).into());
        // Readers pass finite corners; a transform can still take them out of range.
        if let Some(bad) = p.iter().flatten().find(|c| !c.is_finite()) {
            let what = if bad.is_nan() { "NaN" } else { "infinite" };
            let (file, at) = self.declared;
            return Err(ImportError::new(
                file,
                Some(at.clone()),
                format!("a corner is {what} (in the file, or after the shape's transform)"),
            ));
        }
        let mut a = attr.clone();
        a.normal = a.normal.map(|n| n.map(|n| self.normal.normal_by_inverse(Vec3::from(n)).normalize_or_zero().into()));
        if let Some(m) = self.material {
            a.material = m;
        }
        let mut flip = self.flip;
        if let (true, Some(n)) = (self.orient, a.normal) {
            let c = |i: usize| Vec3::from(p[i]);
            let wound = (c(1) - c(0)).cross(c(2) - c(0));
            let n = Vec3::from(n[0]) + Vec3::from(n[1]) + Vec3::from(n[2]);
            flip = wound.dot(n) < 0.0;
        }
        if flip {
            p.swap(1, 2);
            if let Some(n) = a.normal.as_mut() {
                n.swap(1, 2);
            }
            if let Some(uv) = a.uv.as_mut() {
                uv.swap(1, 2);
            }
            if let Some(c) = a.color.as_mut() {
                c.swap(1, 2);
            }
        }
        self.sink.triangle(p, &a)
    }

    fn material(&mut self, m: Material) -> u32 {
        self.sink.material(m)
    }
}
