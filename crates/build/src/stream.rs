//! Triangle stream files: the positions-only, fixed-record files the out-of-core build
//! splits recursively. Each record is a [`StreamTri`] (48 bytes); the triangle's id keys its
//! attributes in the separate attribute streams ([`crate::attrs`]).

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use bytemuck::{Pod, Zeroable};
use megaray_base::Aabb;

use crate::BuildError;

/// One triangle in a stream file. 48 bytes: corners, padding, id.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct StreamTri {
    pub v: [[f32; 3]; 3],
    pub reserved: u32,
    /// The triangle's number in import order (keys the attribute streams).
    pub id: u64,
}
const _: () = assert!(std::mem::size_of::<StreamTri>() == 48);

impl StreamTri {
    #[inline]
    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(&self.v)
    }
    #[inline]
    pub fn centroid(&self) -> [f32; 3] {
        let b = self.bounds();
        [(b.min[0] + b.max[0]) * 0.5, (b.min[1] + b.max[1]) * 0.5, (b.min[2] + b.max[2]) * 0.5]
    }
}

/// Buffer size of stream readers and writers.
pub const IO_BUF: usize = 4 << 20;

/// Number of SAH bins per axis.
pub const BINS: usize = 32;

/// Binned centroid statistics over a fixed box, gathered while a stream is written.
#[derive(Clone, Debug)]
pub struct Bins {
    pub range: Aabb,
    pub count: [[u64; BINS]; 3],
    pub bounds: [[Aabb; BINS]; 3],
}

impl Bins {
    pub fn new(range: Aabb) -> Bins {
        Bins { range, count: [[0; BINS]; 3], bounds: [[Aabb::EMPTY; BINS]; 3] }
    }

    #[inline]
    pub fn bin_of(&self, axis: usize, c: f32) -> usize {
        let lo = self.range.min[axis];
        let ext = self.range.max[axis] - lo;
        if ext.is_nan() || ext <= 0.0 {
            return 0;
        }
        let b = ((c - lo) / ext * BINS as f32) as isize;
        b.clamp(0, BINS as isize - 1) as usize
    }

    #[inline]
    pub fn add(&mut self, c: [f32; 3], b: &Aabb) {
        for (axis, &ca) in c.iter().enumerate() {
            let i = self.bin_of(axis, ca);
            self.count[axis][i] += 1;
            self.bounds[axis][i].grow(b);
        }
    }
}

/// A finished stream file and what is known about its contents.
#[derive(Debug)]
pub struct StreamFile {
    pub path: PathBuf,
    pub count: u64,
    pub bounds: Aabb,
    pub cbounds: Aabb,
    pub bins: Option<Bins>,
    /// How many file splits led to this stream (the input stream is level 0).
    pub level: u32,
}

/// Writes a stream file, keeping its count, bounds, centroid bounds and (optionally) bins.
pub struct StreamWriter {
    path: PathBuf,
    out: BufWriter<File>,
    count: u64,
    bounds: Aabb,
    cbounds: Aabb,
    bins: Option<Bins>,
    level: u32,
}

impl StreamWriter {
    pub fn create(path: &Path, bin_range: Option<Aabb>, level: u32) -> Result<StreamWriter, BuildError> {
        let f = File::create(path).map_err(|e| BuildError::io(path, "create", e))?;
        Ok(StreamWriter {
            path: path.to_path_buf(),
            out: BufWriter::with_capacity(IO_BUF, f),
            count: 0,
            bounds: Aabb::EMPTY,
            cbounds: Aabb::EMPTY,
            bins: bin_range.map(Bins::new),
            level,
        })
    }

    #[inline]
    pub fn push(&mut self, t: &StreamTri) -> Result<(), BuildError> {
        let b = t.bounds();
        let c = [(b.min[0] + b.max[0]) * 0.5, (b.min[1] + b.max[1]) * 0.5, (b.min[2] + b.max[2]) * 0.5];
        self.bounds.grow(&b);
        self.cbounds.grow_point(c);
        if let Some(bins) = &mut self.bins {
            bins.add(c, &b);
        }
        self.count += 1;
        self.out.write_all(bytemuck::bytes_of(t)).map_err(|e| BuildError::io(&self.path, "write", e))
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    pub fn finish(self) -> Result<StreamFile, BuildError> {
        let path = self.path;
        self.out.into_inner().map_err(|e| BuildError::io(&path, "write", e.into_error()))?;
        Ok(StreamFile {
            path,
            count: self.count,
            bounds: self.bounds,
            cbounds: self.cbounds,
            bins: self.bins,
            level: self.level,
        })
    }
}

/// Reads a stream file sequentially in blocks of records.
pub struct StreamReader {
    path: PathBuf,
    inp: BufReader<File>,
    left: u64,
}

impl StreamReader {
    pub fn open(s: &StreamFile) -> Result<StreamReader, BuildError> {
        let f = File::open(&s.path).map_err(|e| BuildError::io(&s.path, "open", e))?;
        Ok(StreamReader { path: s.path.clone(), inp: BufReader::with_capacity(IO_BUF, f), left: s.count })
    }

    /// Fills `buf` with up to `buf.len()` records; returns how many (0 at the end).
    pub fn read(&mut self, buf: &mut [StreamTri]) -> Result<usize, BuildError> {
        let n = (buf.len() as u64).min(self.left) as usize;
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut buf[..n]);
        self.inp.read_exact(bytes).map_err(|e| BuildError::io(&self.path, "read", e))?;
        self.left -= n as u64;
        Ok(n)
    }
}
