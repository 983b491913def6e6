//! # megaray-import: streaming mesh readers
//!
//! Every reader turns a file into a stream of triangles handed one at a time to a
//! [`TriangleSink`], in bounded memory whatever the file's size (see [`ImportOptions::mem_limit`]).
//! Polygons are fan-triangulated. Per-corner attributes (normals, texture coordinates,
//! colours) and a material id travel with each triangle in a [`TriAttr`].
//!
//! | format | what is read |
//! |---|---|
//! | PLY | ascii, binary little/big endian, any scalar types; `vertex` x,y,z (+ nx,ny,nz, red,green,blue\[,alpha\], u,v / s,t), `face` `vertex_indices`/`vertex_index` lists; other elements and properties skipped |
//! | OBJ | `v` (+ optional `r g b`), `vt`, `vn`, `f` (negative indices, polygons), `g`/`o` groups, `usemtl` + `mtllib` (.mtl Kd, Ks, Ns, d, Tr, map_Kd) |
//! | STL | ascii and binary (a binary file whose header starts with `solid` is still binary) |
//! | glTF 2.0 / GLB | every triangle primitive of the default scene, node transforms applied; a mesh used by several nodes is emitted once per node (loaded into memory: see the module) |
//!
//! Memory: files are read through one 1 MiB buffer; indexed formats keep their vertex
//! tables in a [`store::VertexStore`], which holds at most half of
//! [`ImportOptions::mem_limit`] in memory and spills the rest to an anonymous temporary file
//! in [`ImportOptions::temp_dir`]. Nothing is ever allocated from a count a header claims.
//!
//! Errors name the file, where in it, and what is wrong ([`ImportError`]): `line 12` for
//! text formats, `vertex 7` / `face 17` for binary PLY (numbered from 0 like PLY indices),
//! `triangle 3` for binary STL, `mesh "wheel" primitive 0` for glTF, `byte 4096` for read
//! errors. Zero-area triangles are passed through (the builder drops and counts them).
//!
//! ```no_run
//! use megaray_import::{import_file, ImportOptions, TriangleSink, TriAttr, Material, ImportError};
//! struct Count(u64);
//! impl TriangleSink for Count {
//!     fn triangle(&mut self, _p: [[f32; 3]; 3], _a: &TriAttr) -> Result<(), ImportError> {
//!         self.0 += 1;
//!         Ok(())
//!     }
//!     fn material(&mut self, _m: Material) -> u32 { 0 }
//! }
//! let mut n = Count(0);
//! import_file("bunny.obj".as_ref(), &ImportOptions::default(), &mut n, &megaray_base::NoProgress).unwrap();
//! println!("{} triangles", n.0);
//! ```

#![warn(missing_docs)]

use std::fs::File;
use std::path::{Path, PathBuf};

mod gltf;
pub mod gltf_scene;
mod obj;
pub mod pbrt;
mod ply;
mod reader;
mod stl;
pub mod store;

/// Per-triangle attributes, per corner where it applies. `None` where the input has none.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriAttr {
    /// Vertex normals of the three corners (as given, not necessarily normalised).
    pub normal: Option<[[f32; 3]; 3]>,
    /// Texture coordinates of the three corners.
    pub uv: Option<[[f32; 2]; 3]>,
    /// Linear RGBA colours in `[0, 1]` of the three corners.
    pub color: Option<[[f32; 4]; 3]>,
    /// Material id returned by [`TriangleSink::material`], or [`NO_MATERIAL`].
    pub material: u32,
}

/// The material id of triangles that have none.
pub const NO_MATERIAL: u32 = u32::MAX;

/// A material or group as the input names it. Fields the input does not give are `None`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Material {
    /// Material name (OBJ `usemtl`, glTF material name) or group name when no material is given.
    pub name: String,
    /// Diffuse / base colour, linear RGB (OBJ `Kd`, glTF `baseColorFactor` rgb).
    pub diffuse: Option<[f32; 3]>,
    /// Specular colour (OBJ `Ks`).
    pub specular: Option<[f32; 3]>,
    /// Specular exponent (OBJ `Ns`).
    pub shininess: Option<f32>,
    /// Opacity (OBJ `d`, or `1 - Tr`; glTF base colour alpha).
    pub opacity: Option<f32>,
    /// glTF metallic factor.
    pub metallic: Option<f32>,
    /// glTF roughness factor.
    pub roughness: Option<f32>,
    /// Path of the base colour / diffuse texture (OBJ `map_Kd`, glTF base colour texture URI),
    /// resolved against the input's folder. Embedded glTF images have none.
    pub texture: Option<PathBuf>,
}

/// Receives the triangles of an import, in input order.
pub trait TriangleSink {
    /// One triangle: its corner positions and attributes.
    fn triangle(&mut self, p: [[f32; 3]; 3], attr: &TriAttr) -> Result<(), ImportError>;
    /// Declares a material; the returned id goes into the [`TriAttr::material`] of the
    /// triangles that use it.
    fn material(&mut self, m: Material) -> u32;
    /// The triangles from here on belong to the component `name` within the file (an OBJ
    /// object or group, a glTF node path and mesh); the empty name is the file itself. Sinks
    /// that do not name components ignore it.
    fn component(&mut self, _name: &str) {}
}

/// How an import may use resources.
#[derive(Clone, Debug)]
pub struct ImportOptions {
    /// Upper bound, in bytes, on the memory a reader may hold (vertex tables and caches).
    /// Vertex data beyond it is spilled to temporary files in [`ImportOptions::temp_dir`].
    pub mem_limit: u64,
    /// Where spill files go (they are removed when the import ends, also on error).
    pub temp_dir: PathBuf,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions { mem_limit: 256 << 20, temp_dir: std::env::temp_dir() }
    }
}

/// A summary of one import.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImportSummary {
    /// Triangles handed to the sink.
    pub triangles: u64,
    /// Vertices read (for formats that index vertices).
    pub vertices: u64,
    /// Bytes of the input file read.
    pub bytes: u64,
    /// Vertex records that did not fit in memory and went to a spill file (0 when the
    /// vertex tables fit in [`ImportOptions::mem_limit`]).
    pub spilled: u64,
}

/// An import failure: which file, where in it, and what is wrong.
#[derive(Debug, thiserror::Error)]
#[error("{}{}: {msg}", path.display(), location.as_ref().map(|l| format!(": {l}")).unwrap_or_default())]
pub struct ImportError {
    /// The file being read.
    pub path: PathBuf,
    /// Where in the file: `line 12`, `byte 4096`, `face 17`, `mesh "wheel" primitive 0`...
    pub location: Option<String>,
    /// What is wrong.
    pub msg: String,
}

impl ImportError {
    /// An error about `path`, at `location` (if known), saying `msg`.
    pub fn new(path: &Path, location: Option<String>, msg: impl Into<String>) -> ImportError {
        ImportError { path: path.to_path_buf(), location, msg: msg.into() }
    }
}

/// The input formats, chosen by [`Format::detect`] from the file name (and contents).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Stanford PLY (`.ply`).
    Ply,
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// STL, ascii or binary (`.stl`).
    Stl,
    /// glTF 2.0 JSON (`.gltf`).
    Gltf,
    /// glTF 2.0 binary (`.glb`).
    Glb,
}

impl Format {
    /// Picks the format from the extension (case-insensitive).
    pub fn detect(path: &Path) -> Result<Format, ImportError> {
        let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("ply") => Ok(Format::Ply),
            Some("obj") => Ok(Format::Obj),
            Some("stl") => Ok(Format::Stl),
            Some("gltf") => Ok(Format::Gltf),
            Some("glb") => Ok(Format::Glb),
            _ => Err(ImportError::new(path, None, "unknown model format (expected .ply, .obj, .stl, .gltf or .glb)")),
        }
    }
}

/// Reads one model file into `sink`.
///
/// The format comes from [`Format::detect`]. Progress is reported as one stage named
/// `import <file name>` counting the file's bytes. Fails (naming the file and where in it)
/// on unreadable, malformed or empty input, and when the file holds no triangles.
pub fn import_file(
    path: &Path,
    opts: &ImportOptions,
    sink: &mut dyn TriangleSink,
    progress: &dyn megaray_base::Progress,
) -> Result<ImportSummary, ImportError> {
    let format = Format::detect(path)?;
    let (file, len) = open(path)?;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    progress.stage(&format!("import {name}"), len);
    let result = match format {
        Format::Ply => ply::import(path, file, len, opts, sink, progress),
        Format::Obj => obj::import(path, file, len, opts, sink, progress),
        Format::Stl => stl::import(path, file, len, sink, progress),
        Format::Gltf | Format::Glb => gltf::import(path, file, len, sink, progress),
    };
    progress.finish();
    let summary = result?;
    if summary.triangles == 0 {
        return Err(ImportError::new(path, None, "no triangles"));
    }
    Ok(summary)
}

/// Opens `path` for reading and returns its length; errors for missing files, folders and
/// empty files.
fn open(path: &Path) -> Result<(File, u64), ImportError> {
    let fail = |msg: String| ImportError::new(path, None, msg);
    let file = File::open(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            fail("cannot open: file not found".into())
        } else {
            fail(format!("cannot open: {e}"))
        }
    })?;
    let meta = file.metadata().map_err(|e| fail(format!("cannot open: {e}")))?;
    if meta.is_dir() {
        return Err(fail("cannot open: is a directory".into()));
    }
    if meta.len() == 0 {
        return Err(fail("empty file".into()));
    }
    Ok((file, meta.len()))
}
