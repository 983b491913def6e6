//! Streaming PLY reader: ascii, binary little endian and binary big endian.
//!
//! The header is parsed into elements and properties; data is then read element by element
//! in file order through a [`ByteReader`]. The `vertex` element's records are decoded into
//! `f32` records (position, then optional normal, colour and uv) kept in a [`VertexStore`],
//! which spills to disk beyond half of [`ImportOptions::mem_limit`]; the `face` element's
//! index lists are fan-triangulated and handed to the sink as they are read. Other elements
//! and properties are skipped (elements after `face` are not read at all).
//!
//! Nothing is allocated from header counts: before any data is read, the header's promises
//! are checked against the file size (each record has a minimum size), and reading stops
//! with an error at the first record the data does not hold.
//!
//! Fast paths: binary vertex records without list properties are decoded in batches straight
//! from the read buffer (all-`float` little-endian records need no conversion at all), and
//! face elements whose only property is a `uchar`-counted 4-byte index list are parsed
//! without per-property dispatch.

use std::fs::File;
use std::io;
use std::path::Path;

use megaray_base::Progress;

use crate::reader::{ByteReader, TextError, DEFAULT_BUF};
use crate::store::VertexStore;
use crate::{ImportError, ImportOptions, ImportSummary, TriAttr, TriangleSink, NO_MATERIAL};

/// Longest header line accepted.
const MAX_HEADER_LINE: usize = 64 << 10;
/// Longest ascii token accepted.
const MAX_TOKEN: usize = 4 << 10;
/// Floats in the largest vertex record (position, normal, rgba, uv).
const MAX_REC: usize = 12;

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Ty {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Ty {
    fn parse(s: &str) -> Option<Ty> {
        Some(match s {
            "char" | "int8" => Ty::I8,
            "uchar" | "uint8" => Ty::U8,
            "short" | "int16" => Ty::I16,
            "ushort" | "uint16" => Ty::U16,
            "int" | "int32" => Ty::I32,
            "uint" | "uint32" => Ty::U32,
            "float" | "float32" => Ty::F32,
            "double" | "float64" => Ty::F64,
            _ => return None,
        })
    }

    #[inline]
    fn size(self) -> usize {
        match self {
            Ty::I8 | Ty::U8 => 1,
            Ty::I16 | Ty::U16 => 2,
            Ty::I32 | Ty::U32 | Ty::F32 => 4,
            Ty::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Ty::F32 | Ty::F64)
    }

    /// The divisor that maps the type's range onto `[0, 1]` for colours (1 for floats).
    fn unit_divisor(self) -> f32 {
        match self {
            Ty::I8 => 127.0,
            Ty::U8 => 255.0,
            Ty::I16 => 32767.0,
            Ty::U16 => 65535.0,
            Ty::I32 => 2147483647.0,
            Ty::U32 => 4294967295.0,
            Ty::F32 | Ty::F64 => 1.0,
        }
    }

    /// Decodes a binary value (`b` holds at least `size()` bytes).
    #[inline(always)]
    fn get(self, b: &[u8], be: bool) -> f64 {
        macro_rules! rd {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap();
                (if be { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
            }};
        }
        match self {
            Ty::I8 => b[0] as i8 as f64,
            Ty::U8 => b[0] as f64,
            Ty::I16 => rd!(i16, 2),
            Ty::U16 => rd!(u16, 2),
            Ty::I32 => rd!(i32, 4),
            Ty::U32 => rd!(u32, 4),
            Ty::F32 => rd!(f32, 4),
            Ty::F64 => rd!(f64, 8),
        }
    }

    /// Decodes a binary integer (floats must hold whole numbers).
    #[inline(always)]
    fn get_int(self, b: &[u8], be: bool) -> Option<i64> {
        match self {
            Ty::U8 => Some(b[0] as i64),
            Ty::I32 | Ty::U32 => {
                let a: [u8; 4] = b[..4].try_into().unwrap();
                Some(match (self, be) {
                    (Ty::I32, false) => i32::from_le_bytes(a) as i64,
                    (Ty::I32, true) => i32::from_be_bytes(a) as i64,
                    (_, false) => u32::from_le_bytes(a) as i64,
                    (_, true) => u32::from_be_bytes(a) as i64,
                })
            }
            _ => whole(self.get(b, be)),
        }
    }

    /// Parses an ascii value.
    fn parse_ascii(self, tok: &[u8]) -> Option<f64> {
        let s = std::str::from_utf8(tok).ok()?;
        match self {
            Ty::F32 => s.parse::<f32>().ok().map(f64::from),
            Ty::F64 => s.parse::<f64>().ok(),
            _ => s.parse::<i64>().ok().map(|v| v as f64).or_else(|| s.parse::<f64>().ok().filter(|v| v.fract() == 0.0)),
        }
    }

    /// Parses an ascii integer (list counts and indices).
    fn parse_ascii_int(self, tok: &[u8]) -> Option<i64> {
        let s = std::str::from_utf8(tok).ok()?;
        s.parse::<i64>().ok().or_else(|| s.parse::<f64>().ok().and_then(whole))
    }
}

/// `v` as an integer when it is a whole number in range.
fn whole(v: f64) -> Option<i64> {
    (v.fract() == 0.0 && v.abs() < 9.0e18).then_some(v as i64)
}

/// A property of an element.
#[derive(Clone, Debug)]
enum Kind {
    Scalar(Ty),
    /// `list <count type> <item type>`.
    List(Ty, Ty),
}

#[derive(Clone, Debug)]
struct Prop {
    name: String,
    kind: Kind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Prop>,
}

impl Element {
    /// Size of a record in binary, when it has no list properties.
    fn fixed_size(&self) -> Option<usize> {
        self.props.iter().map(|p| if let Kind::Scalar(t) = p.kind { Some(t.size()) } else { None }).sum()
    }

    /// The smallest binary record.
    fn min_size(&self) -> u64 {
        self.props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(t) | Kind::List(t, _) => t.size() as u64,
            })
            .sum()
    }

    fn prop(&self, names: &[&str]) -> Option<usize> {
        self.props.iter().position(|p| names.contains(&p.name.as_str()) && matches!(p.kind, Kind::Scalar(_)))
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    Le,
    Be,
}

struct Header {
    enc: Encoding,
    elements: Vec<Element>,
}

/// Where each decoded vertex property goes in the `f32` record.
struct VertexPlan {
    rec_len: usize,
    normal: Option<usize>,
    color: Option<usize>,
    uv: Option<usize>,
    /// Per property: destination slot and divisor (colours of integer types map to `[0, 1]`).
    dest: Vec<Option<(usize, f32)>>,
    /// Record defaults (alpha 1).
    template: [f32; MAX_REC],
}

impl VertexPlan {
    fn new(el: &Element) -> Result<VertexPlan, String> {
        let mut dest = vec![None; el.props.len()];
        let mut rec_len = 0;
        let mut template = [0.0; MAX_REC];
        let mut place = |idx: &[usize], rec_len: &mut usize, scale: &dyn Fn(usize) -> f32| {
            let at = *rec_len;
            for (k, &i) in idx.iter().enumerate() {
                dest[i] = Some((at + k, scale(i)));
            }
            *rec_len += idx.len();
            at
        };
        let scalar_ty = |i: usize| match el.props[i].kind {
            Kind::Scalar(t) => t,
            Kind::List(..) => unreachable!("prop() only finds scalars"),
        };
        let find3 = |a: &[&str], b: &[&str], c: &[&str]| Some([el.prop(a)?, el.prop(b)?, el.prop(c)?]);
        let pos = find3(&["x"], &["y"], &["z"]).ok_or("the vertex element has no x, y, z properties")?;
        place(&pos, &mut rec_len, &|_| 1.0);
        let normal = find3(&["nx"], &["ny"], &["nz"]).map(|n| place(&n, &mut rec_len, &|_| 1.0));
        let color =
            find3(&["red", "diffuse_red", "r"], &["green", "diffuse_green", "g"], &["blue", "diffuse_blue", "b"]).map(
                |c| {
                    let at = place(&c, &mut rec_len, &|i| scalar_ty(i).unit_divisor());
                    if let Some(a) = el.prop(&["alpha", "diffuse_alpha", "a"]) {
                        place(&[a], &mut rec_len, &|i| scalar_ty(i).unit_divisor());
                    } else {
                        rec_len += 1;
                    }
                    template[at + 3] = 1.0;
                    at
                },
            );
        let uv_pairs: [(&str, &str); 4] =
            [("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t")];
        let uv = uv_pairs
            .iter()
            .find_map(|(u, v)| Some([el.prop(&[u])?, el.prop(&[v])?]))
            .map(|t| place(&t, &mut rec_len, &|_| 1.0));
        Ok(VertexPlan { rec_len, normal, color, uv, dest, template })
    }
}

/// Fan-triangulates index lists, fetching vertices from the store.
struct Fan<'a> {
    path: &'a Path,
    store: &'a mut VertexStore,
    nverts: u64,
    rec_len: usize,
    normal: Option<usize>,
    color: Option<usize>,
    uv: Option<usize>,
    recs: [[f32; MAX_REC]; 3],
    /// Corners of the current polygon so far.
    n: usize,
    attr: TriAttr,
    triangles: u64,
    short_faces: u64,
}

impl Fan<'_> {
    #[inline(always)]
    fn corner(&mut self, idx: i64, face: u64, sink: &mut dyn TriangleSink) -> Result<(), ImportError> {
        if idx < 0 || idx as u64 >= self.nverts {
            return Err(ImportError::new(
                self.path,
                Some(format!("face {face}")),
                format!("vertex index {idx} out of range (the file has {} vertices)", self.nverts),
            ));
        }
        let slot = if self.n == 0 { 0 } else { 1 + (self.n - 1) % 2 };
        self.store.get(idx as u64, &mut self.recs[slot][..self.rec_len]).map_err(|e| {
            ImportError::new(self.path, Some(format!("face {face}")), format!("vertex spill file: {e}"))
        })?;
        self.n += 1;
        if self.n >= 3 {
            let (a, b, c) = (&self.recs[0], &self.recs[3 - slot], &self.recs[slot]);
            let p3 = |r: &[f32; MAX_REC], o: usize| [r[o], r[o + 1], r[o + 2]];
            let p = [p3(a, 0), p3(b, 0), p3(c, 0)];
            self.attr.normal = self.normal.map(|o| [p3(a, o), p3(b, o), p3(c, o)]);
            let p4 = |r: &[f32; MAX_REC], o: usize| [r[o], r[o + 1], r[o + 2], r[o + 3]];
            self.attr.color = self.color.map(|o| [p4(a, o), p4(b, o), p4(c, o)]);
            let p2 = |r: &[f32; MAX_REC], o: usize| [r[o], r[o + 1]];
            self.attr.uv = self.uv.map(|o| [p2(a, o), p2(b, o), p2(c, o)]);
            sink.triangle(p, &self.attr)?;
            self.triangles += 1;
        }
        Ok(())
    }

    #[inline(always)]
    fn end_face(&mut self) {
        if self.n < 3 {
            self.short_faces += 1;
        }
        self.n = 0;
    }
}

/// Reads a PLY file into `sink`.
pub(crate) fn import(
    path: &Path,
    file: File,
    file_len: u64,
    opts: &ImportOptions,
    sink: &mut dyn TriangleSink,
    progress: &dyn Progress,
) -> Result<ImportSummary, ImportError> {
    let mut r = ByteReader::new(file, DEFAULT_BUF, progress);
    let header = parse_header(path, &mut r)?;
    let data_start = r.offset();
    let enc = header.enc;

    let vi = header.elements.iter().position(|e| e.name == "vertex");
    let fi = header.elements.iter().position(|e| e.name == "face");
    let err = |loc: Option<String>, msg: String| ImportError::new(path, loc, msg);
    let (vi, fi) = match (vi, fi) {
        (Some(v), Some(f)) if f < v => {
            return Err(err(None, "the face element comes before the vertex element".into()))
        }
        (Some(v), Some(f)) => (v, f),
        (None, _) => return Err(err(None, "no vertex element".into())),
        (Some(_), None) => return Err(err(None, "no face element: no triangles".into())),
    };
    let vel = &header.elements[vi];
    let fel = &header.elements[fi];
    let plan = VertexPlan::new(vel).map_err(|m| err(None, m))?;
    let list_prop = fel
        .props
        .iter()
        .position(|p| matches!(p.kind, Kind::List(..)) && (p.name == "vertex_indices" || p.name == "vertex_index"))
        .ok_or_else(|| err(None, "the face element has no vertex_indices list".into()))?;

    // Check the header's promises against the file size before reading anything.
    let remaining = file_len.saturating_sub(data_start) as u128;
    let mut need: u128 = 0;
    for el in &header.elements[..=fi] {
        let (per_rec, what) = match enc {
            Encoding::Ascii => (2 * el.props.len() as u128, "values"),
            _ => (el.min_size() as u128, "bytes"),
        };
        need += el.count as u128 * per_rec;
        if need > remaining + 1 {
            return Err(err(
                Some(format!("byte {data_start}")),
                format!(
                    "truncated: the header promises {} {} records (at least {} {what} each) but only {} bytes follow the header",
                    el.count, el.name, if enc == Encoding::Ascii { per_rec / 2 } else { per_rec }, remaining
                ),
            ));
        }
    }

    let hint = match enc {
        Encoding::Ascii => vel.count.min(remaining as u64 / (2 * vel.props.len() as u64).max(1)),
        _ => vel.count.min(remaining as u64 / vel.min_size().max(1)),
    };
    let mut store = VertexStore::new(plan.rec_len, opts.mem_limit, &opts.temp_dir, hint);

    for (ei, el) in header.elements.iter().enumerate() {
        if ei == vi {
            match enc {
                Encoding::Ascii => read_vertices_ascii(path, &mut r, el, &plan, &mut store)?,
                _ => read_vertices_binary(path, &mut r, el, &plan, &mut store, enc == Encoding::Be)?,
            }
        } else if ei == fi {
            break;
        } else {
            skip_element(path, &mut r, el, enc)?;
        }
    }

    let nverts = store.len();
    let mut fan = Fan {
        path,
        store: &mut store,
        nverts,
        rec_len: plan.rec_len,
        normal: plan.normal,
        color: plan.color,
        uv: plan.uv,
        recs: [plan.template; 3],
        n: 0,
        attr: TriAttr { material: NO_MATERIAL, ..TriAttr::default() },
        triangles: 0,
        short_faces: 0,
    };
    match enc {
        Encoding::Ascii => read_faces_ascii(path, &mut r, fel, list_prop, &mut fan, sink)?,
        _ => read_faces_binary(path, &mut r, fel, list_prop, &mut fan, sink, enc == Encoding::Be)?,
    }
    if fan.short_faces > 0 {
        progress.note(&format!("{}: skipped {} faces with fewer than 3 vertices", path.display(), fan.short_faces));
    }
    let triangles = fan.triangles;
    r.flush_progress();
    Ok(ImportSummary { triangles, vertices: nverts, bytes: r.total_read(), spilled: store.spilled() })
}

fn parse_header<R: io::Read>(path: &Path, r: &mut ByteReader<'_, R>) -> Result<Header, ImportError> {
    let text_err = |line: u64, e: TextError| ImportError::new(path, Some(format!("line {line}")), e.to_string());
    let magic = r.read_line(MAX_HEADER_LINE);
    let ok = matches!(&magic, Ok(Some(l)) if l.trim_ascii() == b"ply");
    if !ok {
        return Err(ImportError::new(
            path,
            Some("line 1".into()),
            "not a PLY file (bad magic: the first line is not 'ply')",
        ));
    }
    let mut enc = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let line_no = r.line();
        let line = match r.read_line(MAX_HEADER_LINE) {
            Ok(Some(l)) => l,
            Ok(None) => {
                return Err(ImportError::new(path, Some(format!("line {line_no}")), "truncated header (no end_header)"))
            }
            Err(e) => return Err(text_err(line_no, e)),
        };
        let at = || Some(format!("line {line_no}"));
        let e = |msg: String| ImportError::new(path, at(), msg);
        let line = std::str::from_utf8(line).map_err(|_| e("the header is not text".into()))?;
        let mut w = line.split_ascii_whitespace();
        match w.next() {
            None | Some("comment") | Some("obj_info") => {}
            Some("end_header") => break,
            Some("format") => {
                enc = Some(match w.next() {
                    Some("ascii") => Encoding::Ascii,
                    Some("binary_little_endian") => Encoding::Le,
                    Some("binary_big_endian") => Encoding::Be,
                    other => return Err(e(format!("unknown PLY format '{}'", other.unwrap_or("")))),
                });
            }
            Some("element") => {
                let name = w.next().ok_or_else(|| e("element without a name".into()))?;
                let count = w
                    .next()
                    .and_then(|c| c.parse::<u64>().ok())
                    .ok_or_else(|| e(format!("bad element count for '{name}'")))?;
                elements.push(Element { name: name.to_string(), count, props: Vec::new() });
            }
            Some("property") => {
                let el = elements.last_mut().ok_or_else(|| e("property before any element".into()))?;
                let toks: Vec<&str> = w.collect();
                let ty = |s: &str| Ty::parse(s).ok_or_else(|| e(format!("unknown PLY type '{s}'")));
                let prop = match toks.as_slice() {
                    ["list", c, i, name] => {
                        let c = ty(c)?;
                        if c.is_float() {
                            return Err(e(format!("list count type of '{name}' is not an integer type")));
                        }
                        Prop { name: name.to_string(), kind: Kind::List(c, ty(i)?) }
                    }
                    [t, name] if *t != "list" => Prop { name: name.to_string(), kind: Kind::Scalar(ty(t)?) },
                    _ => return Err(e(format!("bad property line '{line}'"))),
                };
                el.props.push(prop);
            }
            Some(other) => return Err(e(format!("unknown header keyword '{other}'"))),
        }
    }
    let enc = enc.ok_or_else(|| ImportError::new(path, None, "the header has no format line"))?;
    Ok(Header { enc, elements })
}

fn truncated(path: &Path, el: &Element, i: u64) -> ImportError {
    ImportError::new(
        path,
        Some(format!("{} {i}", el.name)),
        format!("truncated: the file ends inside {} {i} of the {} the header promises", el.name, el.count),
    )
}

fn io_error(path: &Path, offset: u64, e: io::Error) -> ImportError {
    ImportError::new(path, Some(format!("byte {offset}")), format!("read error: {e}"))
}

fn nonfinite(path: &Path, i: u64, rec: &[f32]) -> ImportError {
    let what = if rec[..3].iter().any(|c| c.is_nan()) { "NaN" } else { "infinite" };
    ImportError::new(path, Some(format!("vertex {i}")), format!("vertex coordinate is {what} (non-finite)"))
}

fn spill_error(path: &Path, e: io::Error) -> ImportError {
    ImportError::new(path, None, format!("vertex spill file: {e}"))
}

fn read_vertices_binary<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    el: &Element,
    plan: &VertexPlan,
    store: &mut VertexStore,
    be: bool,
) -> Result<(), ImportError> {
    let mut rec = plan.template;
    let n_rec = plan.rec_len;
    let Some(size) = el.fixed_size() else {
        // Records with list properties: property by property.
        for i in 0..el.count {
            for (p, d) in el.props.iter().zip(&plan.dest) {
                match p.kind {
                    Kind::Scalar(t) => {
                        let b = take(path, r, t.size(), el, i)?;
                        if let Some((k, s)) = *d {
                            rec[k] = t.get(b, be) as f32 / s;
                        }
                    }
                    Kind::List(c, t) => skip_list_binary(path, r, el, i, c, t, be)?,
                }
            }
            if !rec[..3].iter().all(|c| c.is_finite()) {
                return Err(nonfinite(path, i, &rec));
            }
            store.push(&rec[..n_rec]).map_err(|e| spill_error(path, e))?;
        }
        return Ok(());
    };
    // Fixed-size records: decode in batches straight from the buffer.
    let mut fields: Vec<(usize, Ty, usize, f32)> = Vec::new();
    let mut off = 0;
    for (p, d) in el.props.iter().zip(&plan.dest) {
        let Kind::Scalar(t) = p.kind else { unreachable!("fixed-size records have no lists") };
        if let Some((k, s)) = *d {
            fields.push((off, t, k, s));
        }
        off += t.size();
    }
    let all_f32_le = !be && fields.iter().all(|f| f.1 == Ty::F32 && f.3 == 1.0);
    let per_batch = (r.capacity() / size.max(1)).max(1) as u64;
    let mut i = 0u64;
    while i < el.count {
        let want = (el.count - i).min(per_batch) as usize;
        r.fill_to(want * size).map_err(|e| io_error(path, r.offset(), e))?;
        let avail = r.available();
        let n = (avail.len() / size.max(1)).min(want);
        if n == 0 {
            return Err(truncated(path, el, i));
        }
        for (k, b) in avail[..n * size].chunks_exact(size).enumerate() {
            if all_f32_le {
                for &(o, _, d, _) in &fields {
                    rec[d] = f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
                }
            } else {
                for &(o, t, d, s) in &fields {
                    rec[d] = t.get(&b[o..], be) as f32 / s;
                }
            }
            if !(rec[0].is_finite() && rec[1].is_finite() && rec[2].is_finite()) {
                return Err(nonfinite(path, i + k as u64, &rec));
            }
            store.push(&rec[..n_rec]).map_err(|e| spill_error(path, e))?;
        }
        r.consume(n * size);
        i += n as u64;
    }
    Ok(())
}

/// Reads a binary list count (rejecting negative ones).
fn list_count<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    el: &Element,
    i: u64,
    c: Ty,
    be: bool,
) -> Result<u64, ImportError> {
    let b = take(path, r, c.size(), el, i)?;
    match c.get_int(b, be) {
        Some(n) if n >= 0 => Ok(n as u64),
        _ => Err(ImportError::new(path, Some(format!("{} {i}", el.name)), "negative or invalid list length")),
    }
}

fn skip_list_binary<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    el: &Element,
    i: u64,
    c: Ty,
    t: Ty,
    be: bool,
) -> Result<(), ImportError> {
    let n = list_count(path, r, el, i, c, be)?;
    let bytes = n * t.size() as u64;
    if r.skip(bytes).map_err(|e| io_error(path, r.offset(), e))? < bytes {
        return Err(truncated(path, el, i));
    }
    Ok(())
}

fn text_error(path: &Path, line: u64, e: TextError) -> ImportError {
    ImportError::new(path, Some(format!("line {line}")), e.to_string())
}

/// The next ascii token of record `i` of `el`, and its line.
fn token<'r, R: io::Read>(
    path: &Path,
    r: &'r mut ByteReader<'_, R>,
    el: &Element,
    i: u64,
) -> Result<(u64, &'r [u8]), ImportError> {
    let line = r.line();
    match r.next_token(MAX_TOKEN) {
        Ok(Some(t)) => Ok(t),
        Ok(None) => Err(truncated(path, el, i)),
        Err(e) => Err(text_error(path, line, e)),
    }
}

/// The next `n` bytes of record `i` of `el`.
#[inline]
fn take<'r, R: io::Read>(
    path: &Path,
    r: &'r mut ByteReader<'_, R>,
    n: usize,
    el: &Element,
    i: u64,
) -> Result<&'r [u8], ImportError> {
    let off = r.offset();
    match r.take(n) {
        Ok(Some(b)) => Ok(b),
        Ok(None) => Err(truncated(path, el, i)),
        Err(e) => Err(io_error(path, off, e)),
    }
}

fn bad_number(path: &Path, line: u64, el: &Element, i: u64, what: &str, tok: &[u8]) -> ImportError {
    ImportError::new(
        path,
        Some(format!("line {line}")),
        format!("bad number '{}' for {what} of {} {i}", String::from_utf8_lossy(tok), el.name),
    )
}

fn ascii_list_count<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    el: &Element,
    i: u64,
    p: &Prop,
    c: Ty,
) -> Result<u64, ImportError> {
    let (line, tok) = token(path, r, el, i)?;
    match c.parse_ascii_int(tok) {
        Some(n) if n >= 0 => Ok(n as u64),
        _ => Err(bad_number(path, line, el, i, &format!("the length of list '{}'", p.name), tok)),
    }
}

fn read_vertices_ascii<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    el: &Element,
    plan: &VertexPlan,
    store: &mut VertexStore,
) -> Result<(), ImportError> {
    let mut rec = plan.template;
    for i in 0..el.count {
        for (p, d) in el.props.iter().zip(&plan.dest) {
            match p.kind {
                Kind::Scalar(t) => {
                    let (line, tok) = token(path, r, el, i)?;
                    let v = t.parse_ascii(tok).ok_or_else(|| bad_number(path, line, el, i, &p.name, tok))?;
                    if let Some((k, s)) = *d {
                        rec[k] = v as f32 / s;
                    }
                }
                Kind::List(c, _) => {
                    let n = ascii_list_count(path, r, el, i, p, c)?;
                    for _ in 0..n {
                        token(path, r, el, i)?;
                    }
                }
            }
        }
        if !rec[..3].iter().all(|c| c.is_finite()) {
            return Err(nonfinite(path, i, &rec));
        }
        store.push(&rec[..plan.rec_len]).map_err(|e| spill_error(path, e))?;
    }
    Ok(())
}

fn skip_element<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    el: &Element,
    enc: Encoding,
) -> Result<(), ImportError> {
    let be = enc == Encoding::Be;
    match (enc, el.fixed_size()) {
        (Encoding::Ascii, _) => {
            for i in 0..el.count {
                for p in &el.props {
                    match p.kind {
                        Kind::Scalar(_) => {
                            token(path, r, el, i)?;
                        }
                        Kind::List(c, _) => {
                            let n = ascii_list_count(path, r, el, i, p, c)?;
                            for _ in 0..n {
                                token(path, r, el, i)?;
                            }
                        }
                    }
                }
            }
        }
        (_, Some(size)) => {
            let bytes = el.count.saturating_mul(size as u64);
            let got = r.skip(bytes).map_err(|e| io_error(path, r.offset(), e))?;
            if got < bytes {
                return Err(truncated(path, el, got / size.max(1) as u64));
            }
        }
        (_, None) => {
            for i in 0..el.count {
                for p in &el.props {
                    match p.kind {
                        Kind::Scalar(t) => {
                            if r.skip(t.size() as u64).map_err(|e| io_error(path, r.offset(), e))? < t.size() as u64 {
                                return Err(truncated(path, el, i));
                            }
                        }
                        Kind::List(c, t) => skip_list_binary(path, r, el, i, c, t, be)?,
                    }
                }
            }
        }
    }
    Ok(())
}

fn bad_index(path: &Path, face: u64) -> ImportError {
    ImportError::new(path, Some(format!("face {face}")), "vertex index is not a whole number")
}

fn read_faces_binary<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    el: &Element,
    list_prop: usize,
    fan: &mut Fan<'_>,
    sink: &mut dyn TriangleSink,
    be: bool,
) -> Result<(), ImportError> {
    let Kind::List(count_ty, item_ty) = el.props[list_prop].kind else { unreachable!("list_prop is a list") };
    if el.props.len() == 1 && count_ty == Ty::U8 && matches!(item_ty, Ty::I32 | Ty::U32) {
        // Fast path: `list uchar int|uint vertex_indices` alone.
        let signed = item_ty == Ty::I32;
        let mut f = 0u64;
        while f < el.count {
            r.fill_to(1 + 255 * 4).map_err(|e| io_error(path, r.offset(), e))?;
            let avail = r.available();
            let mut pos = 0;
            while f < el.count && pos < avail.len() {
                let n = avail[pos] as usize;
                if pos + 1 + 4 * n > avail.len() {
                    break;
                }
                for k in 0..n {
                    let b: [u8; 4] = avail[pos + 1 + 4 * k..pos + 5 + 4 * k].try_into().unwrap();
                    let idx = match (signed, be) {
                        (true, false) => i32::from_le_bytes(b) as i64,
                        (true, true) => i32::from_be_bytes(b) as i64,
                        (false, false) => u32::from_le_bytes(b) as i64,
                        (false, true) => u32::from_be_bytes(b) as i64,
                    };
                    fan.corner(idx, f, sink)?;
                }
                fan.end_face();
                pos += 1 + 4 * n;
                f += 1;
            }
            if pos == 0 {
                // Not even one whole face is left.
                return Err(truncated(path, el, f));
            }
            r.consume(pos);
        }
        return Ok(());
    }
    for f in 0..el.count {
        for (pi, p) in el.props.iter().enumerate() {
            match p.kind {
                Kind::Scalar(t) => {
                    if r.skip(t.size() as u64).map_err(|e| io_error(path, r.offset(), e))? < t.size() as u64 {
                        return Err(truncated(path, el, f));
                    }
                }
                Kind::List(c, t) if pi == list_prop => {
                    let n = list_count(path, r, el, f, c, be)?;
                    for _ in 0..n {
                        let b = take(path, r, t.size(), el, f)?;
                        let idx = t.get_int(b, be).ok_or_else(|| bad_index(path, f))?;
                        fan.corner(idx, f, sink)?;
                    }
                    fan.end_face();
                }
                Kind::List(c, t) => skip_list_binary(path, r, el, f, c, t, be)?,
            }
        }
    }
    Ok(())
}

fn read_faces_ascii<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    el: &Element,
    list_prop: usize,
    fan: &mut Fan<'_>,
    sink: &mut dyn TriangleSink,
) -> Result<(), ImportError> {
    for f in 0..el.count {
        for (pi, p) in el.props.iter().enumerate() {
            match p.kind {
                Kind::Scalar(t) => {
                    let (line, tok) = token(path, r, el, f)?;
                    t.parse_ascii(tok).ok_or_else(|| bad_number(path, line, el, f, &p.name, tok))?;
                }
                Kind::List(c, t) => {
                    let n = ascii_list_count(path, r, el, f, p, c)?;
                    for _ in 0..n {
                        let (line, tok) = token(path, r, el, f)?;
                        if pi == list_prop {
                            let idx = t
                                .parse_ascii_int(tok)
                                .ok_or_else(|| bad_number(path, line, el, f, "a vertex index", tok))?;
                            fan.corner(idx, f, sink)?;
                        }
                    }
                    if pi == list_prop {
                        fan.end_face();
                    }
                }
            }
        }
    }
    Ok(())
}
