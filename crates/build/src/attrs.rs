//! Attribute streams: per-triangle normals, texture coordinates, colours and material ids,
//! kept apart from the positions stream (which the split passes read and write many times)
//! and keyed by triangle id. Each kind is a file of fixed records, created when the first
//! triangle carrying that kind arrives (earlier triangles get the "none" record).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use bytemuck::Pod;
use megaray_import::TriAttr;
use megaray_scene::format::{encode_normal, PackedNormals};

use crate::BuildError;

struct AttrFile {
    path: PathBuf,
    out: Option<BufWriter<File>>,
    rec: usize,
}

impl AttrFile {
    fn create(path: PathBuf, rec: usize, backfill: u64, none: &[u8]) -> Result<AttrFile, BuildError> {
        let f = File::create(&path).map_err(|e| BuildError::io(&path, "create", e))?;
        let mut out = BufWriter::with_capacity(1 << 20, f);
        for _ in 0..backfill {
            out.write_all(none).map_err(|e| BuildError::io(&path, "write", e))?;
        }
        Ok(AttrFile { path, out: Some(out), rec })
    }

    fn push(&mut self, bytes: &[u8]) -> Result<(), BuildError> {
        let out = self.out.as_mut().expect("attribute stream already closed");
        out.write_all(bytes).map_err(|e| BuildError::io(&self.path, "write", e))
    }
}

/// The four attribute streams of a build.
pub struct AttrStreams {
    dir: PathBuf,
    files: [Option<AttrFile>; 4],
    count: u64,
}

/// Attribute kinds, in the order of [`AttrStreams`]' files.
pub const NORMAL: usize = 0;
pub const UV: usize = 1;
pub const COLOR: usize = 2;
pub const MATERIAL: usize = 3;
/// Kinds of attribute.
pub const KINDS: usize = 4;
const REC: [usize; 4] = [12, 24, 12, 4];
const NAMES: [&str; 4] = ["normals.attr", "uvs.attr", "colors.attr", "materials.attr"];

fn none_record(kind: usize) -> Vec<u8> {
    match kind {
        COLOR => vec![255u8; 12],
        MATERIAL => u32::MAX.to_le_bytes().to_vec(),
        _ => vec![0u8; REC[kind]],
    }
}

impl AttrStreams {
    pub fn new(dir: &Path) -> AttrStreams {
        AttrStreams { dir: dir.to_path_buf(), files: [None, None, None, None], count: 0 }
    }

    /// Appends the attributes of the next triangle.
    pub fn push(&mut self, a: &TriAttr) -> Result<(), BuildError> {
        let mut recs: [Option<Vec<u8>>; 4] = [None, None, None, None];
        if let Some(n) = &a.normal {
            let p = PackedNormals([encode_normal(n[0]), encode_normal(n[1]), encode_normal(n[2])]);
            recs[NORMAL] = Some(bytemuck::bytes_of(&p).to_vec());
        }
        if let Some(uv) = &a.uv {
            recs[UV] = Some(bytemuck::bytes_of(uv).to_vec());
        }
        if let Some(c) = &a.color {
            let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
            let c8: [[u8; 4]; 3] = c.map(|c| c.map(q));
            recs[COLOR] = Some(bytemuck::bytes_of(&c8).to_vec());
        }
        if a.material != megaray_import::NO_MATERIAL {
            recs[MATERIAL] = Some(a.material.to_le_bytes().to_vec());
        }
        for (kind, rec) in recs.iter().enumerate() {
            if self.files[kind].is_none() && rec.is_some() {
                let path = self.dir.join(NAMES[kind]);
                self.files[kind] = Some(AttrFile::create(path, REC[kind], self.count, &none_record(kind))?);
            }
            if let Some(f) = &mut self.files[kind] {
                match rec {
                    Some(r) => f.push(r)?,
                    None => f.push(&none_record(kind))?,
                }
            }
        }
        self.count += 1;
        Ok(())
    }

    /// Flushes and closes the writers; the streams are then read by [`AttrStreams::gather`].
    pub fn finish_writing(&mut self) -> Result<(), BuildError> {
        for f in self.files.iter_mut().flatten() {
            if let Some(out) = f.out.take() {
                out.into_inner().map_err(|e| BuildError::io(&f.path, "write", e.into_error()))?;
            }
        }
        Ok(())
    }

    pub fn has(&self, kind: usize) -> bool {
        self.files[kind].is_some()
    }

    /// Reads the records of triangles `ids` (in that order) of one kind.
    pub fn gather<T: Pod>(&self, kind: usize, ids: &[u64]) -> Result<Option<Vec<T>>, BuildError> {
        let Some(f) = &self.files[kind] else { return Ok(None) };
        assert_eq!(std::mem::size_of::<T>(), f.rec);
        let file = File::open(&f.path).map_err(|e| BuildError::io(&f.path, "open", e))?;
        let mut sorted: Vec<(u64, u32)> = ids.iter().enumerate().map(|(i, &id)| (id, i as u32)).collect();
        sorted.sort_unstable();
        let mut out = vec![T::zeroed(); ids.len()];
        let mut buf = Vec::new();
        let mut i = 0;
        while i < sorted.len() {
            // Read a run of nearby ids with one call.
            let first = sorted[i].0;
            let mut j = i + 1;
            while j < sorted.len() && sorted[j].0 - sorted[j - 1].0 <= 64 && sorted[j].0 - first < 65536 {
                j += 1;
            }
            let last = sorted[j - 1].0;
            buf.resize(((last - first + 1) as usize) * f.rec, 0);
            file.read_exact_at(&mut buf, first * f.rec as u64).map_err(|e| BuildError::io(&f.path, "read", e))?;
            for &(id, pos) in &sorted[i..j] {
                let at = (id - first) as usize * f.rec;
                out[pos as usize] = bytemuck::pod_read_unaligned(&buf[at..at + f.rec]);
            }
            i = j;
        }
        Ok(Some(out))
    }
}
