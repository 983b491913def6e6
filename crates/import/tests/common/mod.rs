//! Shared helpers of the integration tests: sinks, the models folder, a PLY writer.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use megaray_base::NoProgress;
use megaray_import::{import_file, ImportError, ImportOptions, ImportSummary, Material, TriAttr, TriangleSink};

/// A triangle as imported.
pub type Tri = ([[f32; 3]; 3], TriAttr);

/// Keeps every triangle and material.
#[derive(Default)]
pub struct Collect {
    pub tris: Vec<Tri>,
    pub materials: Vec<Material>,
}

impl TriangleSink for Collect {
    fn triangle(&mut self, p: [[f32; 3]; 3], a: &TriAttr) -> Result<(), ImportError> {
        self.tris.push((p, a.clone()));
        Ok(())
    }
    fn material(&mut self, m: Material) -> u32 {
        self.materials.push(m);
        self.materials.len() as u32 - 1
    }
}

/// Counts triangles and which attributes they carry.
#[derive(Default)]
pub struct Count {
    pub tris: u64,
    pub with_normals: u64,
    pub with_uv: u64,
    pub with_color: u64,
    pub materials: Vec<Material>,
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl TriangleSink for Count {
    fn triangle(&mut self, p: [[f32; 3]; 3], a: &TriAttr) -> Result<(), ImportError> {
        if self.tris == 0 {
            self.min = [f32::INFINITY; 3];
            self.max = [f32::NEG_INFINITY; 3];
        }
        self.tris += 1;
        self.with_normals += a.normal.is_some() as u64;
        self.with_uv += a.uv.is_some() as u64;
        self.with_color += a.color.is_some() as u64;
        for v in p {
            for (k, c) in v.into_iter().enumerate() {
                self.min[k] = self.min[k].min(c);
                self.max[k] = self.max[k].max(c);
            }
        }
        Ok(())
    }
    fn material(&mut self, m: Material) -> u32 {
        self.materials.push(m);
        self.materials.len() as u32 - 1
    }
}

/// The shared real-model folder (`shared/models` beside the repository). Panics, failing the
/// test, when it is missing.
pub fn models_dir() -> PathBuf {
    let d = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/models/"));
    assert!(
        d.is_dir(),
        "the real test models are missing: expected the folder {} (the 'shared' repository cloned beside 'main')",
        d.display()
    );
    d
}

/// Imports `path` with default options into a [`Collect`].
pub fn collect(path: &Path) -> Result<(Collect, ImportSummary), ImportError> {
    collect_with(path, &ImportOptions::default())
}

/// Imports `path` with `opts` into a [`Collect`].
pub fn collect_with(path: &Path, opts: &ImportOptions) -> Result<(Collect, ImportSummary), ImportError> {
    let mut c = Collect::default();
    let s = import_file(path, opts, &mut c, &NoProgress)?;
    Ok((c, s))
}

/// Imports `path`, expecting an error; returns its text.
pub fn import_error(path: &Path) -> String {
    match collect(path) {
        Ok((c, _)) => panic!("{} imported {} triangles, expected an error", path.display(), c.tris.len()),
        Err(e) => e.to_string(),
    }
}

/// Asserts that an error text names the file and contains one of `words` (case-insensitive).
pub fn assert_error(msg: &str, file: &str, words: &[&str]) {
    assert!(msg.contains(file), "error does not name the file {file}: {msg}");
    let lower = msg.to_lowercase();
    assert!(words.iter().any(|w| lower.contains(&w.to_lowercase())), "error does not say {words:?}: {msg}");
}

/// Fan triangulation of `faces` over `verts`: what a reader must produce.
pub fn fan(verts: &[[f32; 3]], faces: &[Vec<u32>]) -> Vec<[[f32; 3]; 3]> {
    let mut out = Vec::new();
    for f in faces {
        for i in 1..f.len().saturating_sub(1) {
            out.push([verts[f[0] as usize], verts[f[i] as usize], verts[f[i + 1] as usize]]);
        }
    }
    out
}

/// PLY encodings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Enc {
    Ascii,
    Le,
    Be,
}

impl Enc {
    pub const ALL: [Enc; 3] = [Enc::Ascii, Enc::Le, Enc::Be];
    fn header_name(self) -> &'static str {
        match self {
            Enc::Ascii => "ascii",
            Enc::Le => "binary_little_endian",
            Enc::Be => "binary_big_endian",
        }
    }
}

/// Appends `v` as PLY type `ty` in encoding `enc` (ascii values end with a space).
pub fn put(out: &mut Vec<u8>, enc: Enc, ty: &str, v: f64) {
    if enc == Enc::Ascii {
        let s = match ty {
            "float" | "float32" => format!("{} ", v as f32),
            "double" | "float64" => format!("{v} "),
            _ => format!("{} ", v as i64),
        };
        out.extend_from_slice(s.as_bytes());
        return;
    }
    macro_rules! bytes {
        ($t:ty) => {{
            let x = v as $t;
            if enc == Enc::Le {
                out.extend_from_slice(&x.to_le_bytes())
            } else {
                out.extend_from_slice(&x.to_be_bytes())
            }
        }};
    }
    match ty {
        "char" | "int8" => bytes!(i8),
        "uchar" | "uint8" => bytes!(u8),
        "short" | "int16" => bytes!(i16),
        "ushort" | "uint16" => bytes!(u16),
        "int" | "int32" => bytes!(i32),
        "uint" | "uint32" => bytes!(u32),
        "float" | "float32" => bytes!(f32),
        "double" | "float64" => bytes!(f64),
        _ => panic!("unknown type {ty}"),
    }
}

/// How [`write_ply`] writes a mesh.
#[derive(Clone, Debug)]
pub struct PlySpec {
    pub enc: Enc,
    pub coord: &'static str,
    pub count: &'static str,
    pub index: &'static str,
    /// Unknown elements before, between and after vertex and face, and unknown properties
    /// around x, y, z and the index list.
    pub extras: bool,
    /// Per-vertex normals (derived from the position) and uchar colours.
    pub attrs: bool,
}

impl PlySpec {
    pub fn new(enc: Enc) -> PlySpec {
        PlySpec { enc, coord: "float", count: "uchar", index: "int", extras: false, attrs: false }
    }
}

/// The normal [`write_ply`] gives vertex `v` when `attrs` is set.
pub fn normal_of(v: [f32; 3]) -> [f32; 3] {
    [v[1], v[2], v[0]]
}

/// The colour (as uchar) [`write_ply`] gives vertex `i` when `attrs` is set.
pub fn color_of(i: usize) -> [u8; 3] {
    [(i * 7 % 256) as u8, (i * 13 % 256) as u8, 255]
}

/// Writes a PLY file.
pub fn write_ply(path: &Path, spec: &PlySpec, verts: &[[f32; 3]], faces: &[Vec<u32>]) {
    let enc = spec.enc;
    let mut h = format!("ply\nformat {} 1.0\ncomment written by the megaray-import tests\n", enc.header_name());
    if spec.extras {
        h += "obj_info nothing to see\nelement material 2\nproperty float shininess\nproperty list uchar uchar name\n";
    }
    h += &format!("element vertex {}\n", verts.len());
    if spec.extras {
        h += "property double confidence\n";
    }
    h += &format!("property {c} x\nproperty {c} y\n", c = spec.coord);
    if spec.extras {
        h += "property uchar flags\n";
    }
    h += &format!("property {} z\n", spec.coord);
    if spec.attrs {
        h += "property float nx\nproperty float ny\nproperty float nz\n";
        h += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    }
    if spec.extras {
        h += "element edge 2\nproperty int vertex1\nproperty list uchar int more\n";
    }
    h += &format!("element face {}\n", faces.len());
    if spec.extras {
        h += "property short flags\n";
    }
    h += &format!("property list {} {} vertex_indices\n", spec.count, spec.index);
    if spec.extras {
        h += "property list uchar float texcoord\n";
        h += "element trailer 3\nproperty int a\n";
    }
    h += "end_header\n";
    let mut out = h.into_bytes();
    let nl = |out: &mut Vec<u8>| {
        if enc == Enc::Ascii {
            out.push(b'\n')
        }
    };
    if spec.extras {
        for i in 0..2 {
            put(&mut out, enc, "float", 0.5 * i as f64);
            put(&mut out, enc, "uchar", 3.0);
            for c in b"abc" {
                put(&mut out, enc, "uchar", *c as f64);
            }
            nl(&mut out);
        }
    }
    for (i, v) in verts.iter().enumerate() {
        if spec.extras {
            put(&mut out, enc, "double", 0.25);
        }
        put(&mut out, enc, spec.coord, v[0] as f64);
        put(&mut out, enc, spec.coord, v[1] as f64);
        if spec.extras {
            put(&mut out, enc, "uchar", 7.0);
        }
        put(&mut out, enc, spec.coord, v[2] as f64);
        if spec.attrs {
            for c in normal_of(*v) {
                put(&mut out, enc, "float", c as f64);
            }
            for c in color_of(i) {
                put(&mut out, enc, "uchar", c as f64);
            }
        }
        nl(&mut out);
    }
    if spec.extras {
        for i in 0..2 {
            put(&mut out, enc, "int", i as f64);
            put(&mut out, enc, "uchar", 2.0);
            put(&mut out, enc, "int", 1.0);
            put(&mut out, enc, "int", 0.0);
            nl(&mut out);
        }
    }
    for f in faces {
        if spec.extras {
            put(&mut out, enc, "short", -3.0);
        }
        put(&mut out, enc, spec.count, f.len() as f64);
        for &i in f {
            put(&mut out, enc, spec.index, i as f64);
        }
        if spec.extras {
            put(&mut out, enc, "uchar", 2.0);
            put(&mut out, enc, "float", 0.5);
            put(&mut out, enc, "float", 0.75);
        }
        nl(&mut out);
    }
    if spec.extras {
        for i in 0..3 {
            put(&mut out, enc, "int", i as f64);
            nl(&mut out);
        }
    }
    std::fs::write(path, out).unwrap();
}

/// The positions of imported triangles.
pub fn positions(c: &Collect) -> Vec<[[f32; 3]; 3]> {
    c.tris.iter().map(|t| t.0).collect()
}

/// A progress sink that records the notes (warnings) a reader gives.
#[derive(Default)]
pub struct Notes(pub std::sync::Mutex<Vec<String>>);

impl megaray_base::Progress for Notes {
    fn stage(&self, _: &str, _: u64) {}
    fn inc(&self, _: u64) {}
    fn note(&self, msg: &str) {
        self.0.lock().unwrap().push(msg.to_string());
    }
}
