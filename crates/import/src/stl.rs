//! Streaming STL reader, binary and ascii.
//!
//! Detection: a file whose size is exactly `84 + 50 * count` (`count` being the `u32` at
//! byte 80) is binary, even when its 80-byte header begins with `solid` (many exporters
//! write that); otherwise a file beginning with `solid` (after optional whitespace) is ascii;
//! anything else is an error. Binary facets are decoded in batches from the read buffer;
//! their stored normal is ignored (it is often wrong). Ascii files are read line by line
//! (`facet` / `outer loop` / `vertex x y z` / `endloop` / `endfacet`, several `solid`s
//! allowed); a loop of more than three vertices is fan-triangulated.

use std::fs::File;
use std::io;
use std::path::Path;

use megaray_base::Progress;

use crate::reader::{ByteReader, DEFAULT_BUF};
use crate::{ImportError, ImportSummary, TriAttr, TriangleSink, NO_MATERIAL};

const HEADER: u64 = 84;
const RECORD: usize = 50;

/// Reads an STL file into `sink`.
pub(crate) fn import(
    path: &Path,
    file: File,
    len: u64,
    sink: &mut dyn TriangleSink,
    progress: &dyn Progress,
) -> Result<ImportSummary, ImportError> {
    let mut r = ByteReader::new(file, DEFAULT_BUF, progress);
    r.fill_to(HEADER as usize).map_err(|e| io_error(path, 0, e))?;
    let head = r.available();
    let count = (head.len() >= HEADER as usize).then(|| u32::from_le_bytes(head[80..84].try_into().unwrap()));
    let solid = head.trim_ascii_start().starts_with(b"solid");
    let summary = match count {
        Some(n) if HEADER + RECORD as u64 * n as u64 == len => {
            r.consume(HEADER as usize);
            read_binary(path, &mut r, n as u64, sink)?
        }
        _ if solid => {
            let s = read_ascii(path, &mut r, sink, progress)?;
            if let (0, Some(n)) = (s.triangles, count) {
                // Most likely a binary file whose count lies.
                return Err(ImportError::new(
                    path,
                    None,
                    format!(
                        "no triangles: the file starts with 'solid' but holds no ascii facets, and as a \
                         binary STL its header says {n} triangles ({} bytes) but file is {len} bytes",
                        HEADER + RECORD as u64 * n as u64
                    ),
                ));
            }
            s
        }
        Some(n) => {
            return Err(ImportError::new(
                path,
                None,
                format!(
                    "binary STL: header says {n} triangles ({} bytes) but file is {len} bytes",
                    HEADER + RECORD as u64 * n as u64
                ),
            ))
        }
        None => {
            return Err(ImportError::new(
                path,
                None,
                "not an STL file: too short for binary STL and it does not start with 'solid'",
            ))
        }
    };
    r.flush_progress();
    Ok(ImportSummary { bytes: r.total_read(), ..summary })
}

fn io_error(path: &Path, offset: u64, e: io::Error) -> ImportError {
    ImportError::new(path, Some(format!("byte {offset}")), format!("read error: {e}"))
}

fn nonfinite(path: &Path, tri: u64, p: &[[f32; 3]; 3]) -> ImportError {
    let k = p.iter().position(|v| !v.iter().all(|c| c.is_finite())).unwrap_or(0);
    let what = if p[k].iter().any(|c| c.is_nan()) { "NaN" } else { "infinite" };
    ImportError::new(
        path,
        Some(format!("triangle {tri}")),
        format!("vertex {k} of the triangle has a {what} coordinate (non-finite)"),
    )
}

fn read_binary<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    count: u64,
    sink: &mut dyn TriangleSink,
) -> Result<ImportSummary, ImportError> {
    let attr = TriAttr { material: NO_MATERIAL, ..TriAttr::default() };
    let per_batch = (r.capacity() / RECORD) as u64;
    let mut i = 0;
    while i < count {
        let want = (count - i).min(per_batch) as usize;
        r.fill_to(want * RECORD).map_err(|e| io_error(path, r.offset(), e))?;
        let avail = r.available();
        let n = (avail.len() / RECORD).min(want);
        if n == 0 {
            return Err(ImportError::new(
                path,
                Some(format!("triangle {i}")),
                "truncated: the file ends inside a triangle",
            ));
        }
        for (k, rec) in avail[..n * RECORD].chunks_exact(RECORD).enumerate() {
            let f = |j: usize| f32::from_le_bytes(rec[12 + 4 * j..16 + 4 * j].try_into().unwrap());
            let p = [[f(0), f(1), f(2)], [f(3), f(4), f(5)], [f(6), f(7), f(8)]];
            if !megaray_base::tri_is_finite(&p) {
                return Err(nonfinite(path, i + k as u64, &p));
            }
            sink.triangle(p, &attr)?;
        }
        r.consume(n * RECORD);
        i += n as u64;
    }
    Ok(ImportSummary { triangles: count, vertices: 3 * count, ..ImportSummary::default() })
}

fn read_ascii<R: io::Read>(
    path: &Path,
    r: &mut ByteReader<'_, R>,
    sink: &mut dyn TriangleSink,
    progress: &dyn Progress,
) -> Result<ImportSummary, ImportError> {
    let attr = TriAttr { material: NO_MATERIAL, ..TriAttr::default() };
    let mut short = 0u64;
    let mut triangles = 0u64;
    let mut vertices = 0u64;
    let mut in_loop = false;
    let mut k = 0usize;
    let mut v = [[0.0f32; 3]; 3];
    loop {
        let no = r.line();
        let line = match r.read_line(1 << 20) {
            Ok(Some(l)) => l,
            Ok(None) => break,
            Err(e) => return Err(ImportError::new(path, Some(format!("line {no}")), e.to_string())),
        };
        let err = |msg: String| ImportError::new(path, Some(format!("line {no}")), msg);
        let mut t = line.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty());
        let Some(kw) = t.next() else { continue };
        match kw {
            b"solid" | b"endsolid" | b"facet" | b"endfacet" => {}
            b"outer" => {
                in_loop = true;
                k = 0;
            }
            b"vertex" => {
                if !in_loop {
                    return Err(err("'vertex' outside 'outer loop'".into()));
                }
                let mut p = [0.0f32; 3];
                for c in &mut p {
                    let tok = t.next().ok_or_else(|| err("a vertex needs 3 coordinates".into()))?;
                    *c = std::str::from_utf8(tok)
                        .ok()
                        .and_then(|s| s.parse().ok())
                        .ok_or_else(|| err(format!("bad number '{}'", String::from_utf8_lossy(tok))))?;
                }
                if !p.iter().all(|c| c.is_finite()) {
                    let what = if p.iter().any(|c| c.is_nan()) { "NaN" } else { "infinite" };
                    return Err(err(format!("vertex {vertices}: coordinate is {what} (non-finite)")));
                }
                vertices += 1;
                let slot = if k == 0 { 0 } else { 1 + (k - 1) % 2 };
                v[slot] = p;
                k += 1;
                if k >= 3 {
                    sink.triangle([v[0], v[3 - slot], v[slot]], &attr)?;
                    triangles += 1;
                }
            }
            b"endloop" => {
                short += u64::from(k < 3);
                in_loop = false;
            }
            other => {
                return Err(err(format!(
                    "unexpected '{}' in an ascii STL file",
                    String::from_utf8_lossy(&other[..other.len().min(40)])
                )))
            }
        }
    }
    if in_loop {
        return Err(ImportError::new(
            path,
            Some(format!("line {}", r.line())),
            "truncated: the file ends inside a facet",
        ));
    }
    if short > 0 {
        progress.note(&format!("{}: skipped {short} facets with fewer than 3 vertices", path.display()));
    }
    Ok(ImportSummary { triangles, vertices, ..ImportSummary::default() })
}
