//! Streaming Wavefront OBJ reader (with `.mtl` material libraries).
//!
//! The file is read line by line through a [`ByteReader`] (no per-line allocation). `v`
//! (with the optional `r g b` vertex colour extension), `vt` and `vn` records go into three
//! [`VertexStore`]s (plus a colour store created at the first coloured vertex), which spill
//! to disk beyond their share of [`ImportOptions::mem_limit`]. Each `f` line is
//! fan-triangulated as its corners are parsed (`i`, `i/t`, `i//n`, `i/t/n`, negative
//! indices counting back from the last record), so polygons of any size need no buffer.
//!
//! Materials: `mtllib` files (relative to the OBJ's folder; a missing one is only a note)
//! are parsed for `newmtl`, `Kd`, `Ks`, `Ns`, `d`, `Tr` and `map_Kd`. Each name given to
//! `usemtl` is declared once to the sink and its id goes with the following faces. A file
//! without any `usemtl` that has groups (`g`, `o`) gets one name-only material per group
//! that has faces. Other statements (`s`, `l`, `p`, curves...) are skipped.

use std::collections::HashMap;
use std::fs::File;
use std::path::{Path, PathBuf};

use megaray_base::{NoProgress, Progress};

use crate::reader::{ByteReader, DEFAULT_BUF};
use crate::store::VertexStore;
use crate::{ImportError, ImportOptions, ImportSummary, Material, TriAttr, TriangleSink, NO_MATERIAL};

/// Longest line accepted (a polygon with a million corners fits).
const MAX_LINE: usize = 16 << 20;

/// The whitespace-separated tokens of a line.
fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty())
}

fn parse_f32(tok: &[u8]) -> Option<f32> {
    std::str::from_utf8(tok).ok()?.parse().ok()
}

fn parse_i64(tok: &[u8]) -> Option<i64> {
    std::str::from_utf8(tok).ok()?.parse().ok()
}

/// The line after its keyword, trimmed, as text.
fn rest_of_line(line: &[u8], keyword_len: usize) -> String {
    String::from_utf8_lossy(line.trim_ascii_start()[keyword_len..].trim_ascii()).into_owned()
}

/// Turns a 1-based (or negative, relative) OBJ index into a 0-based one.
#[inline]
fn resolve(idx: i64, count: u64) -> Option<u64> {
    if idx > 0 && idx as u64 <= count {
        Some(idx as u64 - 1)
    } else if idx < 0 && idx.unsigned_abs() <= count {
        Some(count - idx.unsigned_abs())
    } else {
        None
    }
}

/// One resolved polygon corner.
#[derive(Clone, Copy, Default)]
struct Corner {
    p: [f32; 3],
    n: Option<[f32; 3]>,
    t: Option<[f32; 2]>,
    c: Option<[f32; 4]>,
}

struct Obj<'a> {
    path: &'a Path,
    dir: PathBuf,
    opts: &'a ImportOptions,
    progress: &'a dyn Progress,
    pos: VertexStore,
    /// Vertex colours (r, g, b; NaN r for vertices without), once a coloured vertex appears.
    col: Option<VertexStore>,
    nrm: VertexStore,
    tex: VertexStore,
    library: HashMap<String, Material>,
    declared: HashMap<String, u32>,
    groups: HashMap<String, u32>,
    usemtl: Option<u32>,
    seen_usemtl: bool,
    group: Option<String>,
    /// The last `o` name (components are `object/group`).
    object: String,
    /// Material of the next face, `None` when it must be recomputed.
    material: Option<u32>,
    faces: u64,
    /// Faces of fewer than three vertices (lines written as faces), skipped.
    short_faces: u64,
    triangles: u64,
    attr: TriAttr,
}

/// Reads an OBJ file into `sink`.
pub(crate) fn import(
    path: &Path,
    file: File,
    file_len: u64,
    opts: &ImportOptions,
    sink: &mut dyn TriangleSink,
    progress: &dyn Progress,
) -> Result<ImportSummary, ImportError> {
    let mut r = ByteReader::new(file, DEFAULT_BUF, progress);
    let m = opts.mem_limit;
    let hint = file_len / 40;
    let mut obj = Obj {
        path,
        dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
        opts,
        progress,
        pos: VertexStore::new(3, m / 4, &opts.temp_dir, hint),
        col: None,
        nrm: VertexStore::new(3, m / 8, &opts.temp_dir, 0),
        tex: VertexStore::new(2, m / 16, &opts.temp_dir, 0),
        library: HashMap::new(),
        declared: HashMap::new(),
        groups: HashMap::new(),
        usemtl: None,
        seen_usemtl: false,
        group: None,
        object: String::new(),
        material: None,
        faces: 0,
        short_faces: 0,
        triangles: 0,
        attr: TriAttr::default(),
    };
    loop {
        let line_no = r.line();
        let line = match r.read_line(MAX_LINE) {
            Ok(Some(l)) => l,
            Ok(None) => break,
            Err(e) => return Err(ImportError::new(path, Some(format!("line {line_no}")), e.to_string())),
        };
        obj.line(line, line_no, sink)?;
    }
    r.flush_progress();
    if obj.short_faces > 0 {
        progress.note(&format!("{}: skipped {} faces with fewer than 3 vertices", path.display(), obj.short_faces));
    }
    let spilled =
        obj.pos.spilled() + obj.nrm.spilled() + obj.tex.spilled() + obj.col.as_ref().map_or(0, VertexStore::spilled);
    Ok(ImportSummary { triangles: obj.triangles, vertices: obj.pos.len(), bytes: r.total_read(), spilled })
}

impl Obj<'_> {
    fn err(&self, line: u64, msg: String) -> ImportError {
        ImportError::new(self.path, Some(format!("line {line}")), msg)
    }

    fn spill_err(&self, line: u64, e: std::io::Error) -> ImportError {
        self.err(line, format!("vertex spill file: {e}"))
    }

    /// Reads up to `N` numbers; returns how many there were.
    fn numbers<const N: usize>(&self, rest: &[u8], line: u64, out: &mut [f32; N]) -> Result<usize, ImportError> {
        let mut n = 0;
        for t in tokens(rest) {
            if n == N {
                break;
            }
            out[n] =
                parse_f32(t).ok_or_else(|| self.err(line, format!("bad number '{}'", String::from_utf8_lossy(t))))?;
            n += 1;
        }
        Ok(n)
    }

    fn line(&mut self, line: &[u8], no: u64, sink: &mut dyn TriangleSink) -> Result<(), ImportError> {
        let line = match line.iter().position(|&b| b == b'#') {
            Some(i) => &line[..i],
            None => line,
        };
        let trimmed = line.trim_ascii_start();
        let kw_len = trimmed.iter().position(|b| b.is_ascii_whitespace()).unwrap_or(trimmed.len());
        let (kw, rest) = trimmed.split_at(kw_len);
        match kw {
            b"v" => {
                let mut v = [0.0f32; 7];
                let n = self.numbers(rest, no, &mut v)?;
                if n < 3 {
                    return Err(self.err(no, "a vertex needs 3 coordinates".into()));
                }
                if !v[..3].iter().all(|c| c.is_finite()) {
                    let what = if v[..3].iter().any(|c| c.is_nan()) { "NaN" } else { "infinite" };
                    return Err(
                        self.err(no, format!("vertex {}: coordinate is {what} (non-finite)", self.pos.len() + 1))
                    );
                }
                self.pos.push(&v[..3]).map_err(|e| self.spill_err(no, e))?;
                let color = if n >= 6 { [v[3], v[4], v[5]] } else { [f32::NAN; 3] };
                if n >= 6 && self.col.is_none() {
                    // First coloured vertex: earlier ones have none.
                    let mut col = VertexStore::new(3, self.opts.mem_limit / 16, &self.opts.temp_dir, 0);
                    for _ in 1..self.pos.len() {
                        col.push(&[f32::NAN; 3]).map_err(|e| self.spill_err(no, e))?;
                    }
                    self.col = Some(col);
                }
                if let Some(col) = &mut self.col {
                    col.push(&color).map_err(|e| {
                        ImportError::new(self.path, Some(format!("line {no}")), format!("vertex spill file: {e}"))
                    })?;
                }
            }
            b"vn" => {
                let mut v = [0.0f32; 3];
                if self.numbers(rest, no, &mut v)? < 3 {
                    return Err(self.err(no, "a normal needs 3 coordinates".into()));
                }
                self.nrm.push(&v).map_err(|e| self.spill_err(no, e))?;
            }
            b"vt" => {
                let mut v = [0.0f32; 2];
                if self.numbers(rest, no, &mut v)? < 1 {
                    return Err(self.err(no, "a texture coordinate needs a number".into()));
                }
                self.tex.push(&v).map_err(|e| self.spill_err(no, e))?;
            }
            b"f" => self.face(rest, no, sink)?,
            b"g" | b"o" => {
                let name = rest_of_line(rest, 0);
                // The component: `o` names an object, `g` a group within it.
                if kw == b"o" {
                    self.object = name.clone();
                    sink.component(&name);
                } else if self.object.is_empty() || name.is_empty() {
                    sink.component(if name.is_empty() { &self.object } else { &name });
                } else {
                    sink.component(&format!("{}/{name}", self.object));
                }
                self.group = (!name.is_empty()).then_some(name);
                self.material = None;
            }
            b"usemtl" => {
                let name = rest_of_line(rest, 0);
                self.seen_usemtl = true;
                self.usemtl = if name.is_empty() { None } else { Some(self.declare(name, sink)) };
                self.material = None;
            }
            b"mtllib" => {
                let names = rest_of_line(rest, 0);
                if !names.is_empty() {
                    if self.dir.join(&names).is_file() {
                        self.load_library(&names);
                    } else {
                        for n in names.split_ascii_whitespace() {
                            self.load_library(n);
                        }
                    }
                }
            }
            _ => {}
        }
        Ok(())
    }

    /// Declares the `usemtl` material `name` (once).
    fn declare(&mut self, name: String, sink: &mut dyn TriangleSink) -> u32 {
        if let Some(&id) = self.declared.get(&name) {
            return id;
        }
        let m = match self.library.get(&name) {
            Some(m) => m.clone(),
            None => {
                if !self.library.is_empty() {
                    self.progress
                        .note(&format!("{}: material '{name}' is not in the material library", self.path.display()));
                }
                Material { name: name.clone(), ..Material::default() }
            }
        };
        let id = sink.material(m);
        self.declared.insert(name, id);
        id
    }

    /// The material of the next face.
    fn current_material(&mut self, sink: &mut dyn TriangleSink) -> u32 {
        if let Some(m) = self.material {
            return m;
        }
        let m = match (&self.usemtl, &self.group) {
            (Some(id), _) => *id,
            (None, Some(g)) if !self.seen_usemtl => match self.groups.get(g) {
                Some(&id) => id,
                None => {
                    let id = sink.material(Material { name: g.clone(), ..Material::default() });
                    self.groups.insert(g.clone(), id);
                    id
                }
            },
            _ => NO_MATERIAL,
        };
        self.material = Some(m);
        m
    }

    fn face(&mut self, rest: &[u8], no: u64, sink: &mut dyn TriangleSink) -> Result<(), ImportError> {
        self.faces += 1;
        let face = self.faces;
        self.attr.material = self.current_material(sink);
        let (nv, nt, nn) = (self.pos.len(), self.tex.len(), self.nrm.len());
        let mut corners = [Corner::default(); 3];
        let mut k = 0usize;
        for tok in tokens(rest) {
            let mut parts = tok.split(|&b| b == b'/');
            let bad = |what: &str, t: &[u8]| {
                self.err(no, format!("face {face}: bad {what} '{}'", String::from_utf8_lossy(t)))
            };
            let vi = parts.next().and_then(parse_i64).ok_or_else(|| bad("vertex", tok))?;
            let ti = match parts.next() {
                None | Some(b"") => None,
                Some(t) => Some(parse_i64(t).ok_or_else(|| bad("texture coordinate index", tok))?),
            };
            let ni = match parts.next() {
                None | Some(b"") => None,
                Some(t) => Some(parse_i64(t).ok_or_else(|| bad("normal index", tok))?),
            };
            let range = |what: &str, i: i64, n: u64| {
                self.err(no, format!("face {face}: {what} index {i} out of range ({n} defined so far)"))
            };
            let v = resolve(vi, nv).ok_or_else(|| range("vertex", vi, nv))?;
            let t = ti.map(|i| resolve(i, nt).ok_or_else(|| range("texture coordinate", i, nt))).transpose()?;
            let n = ni.map(|i| resolve(i, nn).ok_or_else(|| range("normal", i, nn))).transpose()?;

            let slot = if k == 0 { 0 } else { 1 + (k - 1) % 2 };
            let c = &mut corners[slot];
            let io = |e: std::io::Error| {
                ImportError::new(self.path, Some(format!("line {no}")), format!("vertex spill file: {e}"))
            };
            self.pos.get(v, &mut c.p).map_err(io)?;
            c.n = match n {
                Some(n) => {
                    let mut x = [0.0; 3];
                    self.nrm.get(n, &mut x).map_err(io)?;
                    Some(x)
                }
                None => None,
            };
            c.t = match t {
                Some(t) => {
                    let mut x = [0.0; 2];
                    self.tex.get(t, &mut x).map_err(io)?;
                    Some(x)
                }
                None => None,
            };
            c.c = match &mut self.col {
                Some(col) => {
                    let mut x = [0.0; 3];
                    col.get(v, &mut x).map_err(io)?;
                    (!x[0].is_nan()).then_some([x[0], x[1], x[2], 1.0])
                }
                None => None,
            };
            k += 1;
            if k >= 3 {
                let (a, b, c) = (&corners[0], &corners[3 - slot], &corners[slot]);
                self.attr.normal = match (a.n, b.n, c.n) {
                    (Some(x), Some(y), Some(z)) => Some([x, y, z]),
                    _ => None,
                };
                self.attr.uv = match (a.t, b.t, c.t) {
                    (Some(x), Some(y), Some(z)) => Some([x, y, z]),
                    _ => None,
                };
                self.attr.color = if a.c.is_some() || b.c.is_some() || c.c.is_some() {
                    let w = [1.0; 4];
                    Some([a.c.unwrap_or(w), b.c.unwrap_or(w), c.c.unwrap_or(w)])
                } else {
                    None
                };
                sink.triangle([a.p, b.p, c.p], &self.attr)?;
                self.triangles += 1;
            }
        }
        if k < 3 {
            self.short_faces += 1;
        }
        Ok(())
    }

    /// Parses the material library `name` (relative to the OBJ's folder) into `library`.
    /// Problems are notes, not errors.
    fn load_library(&mut self, name: &str) {
        let path = self.dir.join(name);
        let file = match File::open(&path) {
            Ok(f) => f,
            Err(e) => {
                self.progress.note(&format!(
                    "{}: material library {} cannot be read ({e}); materials keep only their names",
                    self.path.display(),
                    path.display()
                ));
                return;
            }
        };
        let mtl_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let mut r = ByteReader::new(file, 64 << 10, &NoProgress);
        let mut cur: Option<Material> = None;
        let mut tr: Option<f32> = None;
        fn finish(m: Option<Material>, tr: Option<f32>, lib: &mut HashMap<String, Material>) {
            if let Some(mut m) = m {
                if m.opacity.is_none() {
                    m.opacity = tr.map(|t| 1.0 - t);
                }
                lib.insert(m.name.clone(), m);
            }
        }
        loop {
            let line_no = r.line();
            let line = match r.read_line(1 << 20) {
                Ok(Some(l)) => l,
                Ok(None) => break,
                Err(e) => {
                    self.progress.note(&format!("{} line {line_no}: {e}; rest of the file ignored", path.display()));
                    break;
                }
            };
            let line = match line.iter().position(|&b| b == b'#') {
                Some(i) => &line[..i],
                None => line,
            };
            let toks: Vec<&[u8]> = tokens(line).collect();
            let Some((kw, args)) = toks.split_first() else { continue };
            let kw = String::from_utf8_lossy(kw).to_ascii_lowercase();
            if kw == "newmtl" {
                finish(cur.take(), tr.take(), &mut self.library);
                let name = rest_of_line(line, 6);
                cur = Some(Material { name, ..Material::default() });
                continue;
            }
            let Some(m) = cur.as_mut() else { continue };
            let nums: Vec<f32> = args.iter().map_while(|a| parse_f32(a)).take(3).collect();
            let rgb = || match nums.as_slice() {
                [r] => Some([*r; 3]),
                [r, g, b] => Some([*r, *g, *b]),
                _ => None,
            };
            match kw.as_str() {
                "kd" => m.diffuse = rgb(),
                "ks" => m.specular = rgb(),
                "ns" => m.shininess = nums.first().copied(),
                "d" => m.opacity = nums.first().copied(),
                "tr" => tr = nums.first().copied(),
                "map_kd" => {
                    if let Some(file) = args.last() {
                        let file = String::from_utf8_lossy(file).replace('\\', "/");
                        m.texture = Some(mtl_dir.join(file));
                    }
                }
                _ => {}
            }
        }
        finish(cur.take(), tr.take(), &mut self.library);
    }
}
