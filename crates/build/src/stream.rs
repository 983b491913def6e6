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

/// A uniform random sample (reservoir sampling, deterministic) of the triangle boxes of a
/// stream, gathered while the stream is written; the split planner works on it.
#[derive(Clone, Debug)]
pub struct Sample {
    pub boxes: Vec<Aabb>,
    seen: u64,
    cap: usize,
    rng: u64,
}

impl Sample {
    pub fn new(cap: usize) -> Sample {
        Sample { boxes: Vec::new(), seen: 0, cap, rng: 0x9e37_79b9_7f4a_7c15 }
    }

    #[inline]
    pub fn add(&mut self, b: &Aabb) {
        self.seen += 1;
        if self.boxes.len() < self.cap {
            self.boxes.push(*b);
            return;
        }
        // xorshift64*
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        let j = self.rng.wrapping_mul(0x2545_f491_4f6c_dd1d) % self.seen;
        if (j as usize) < self.cap {
            self.boxes[j as usize] = *b;
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
    pub sample: Sample,
    /// How many file splits led to this stream (the input stream is level 0).
    pub level: u32,
}

/// Writes a stream file, keeping its count, bounds, centroid bounds and a sample of its boxes.
pub struct StreamWriter {
    path: PathBuf,
    out: BufWriter<File>,
    count: u64,
    bounds: Aabb,
    cbounds: Aabb,
    sample: Sample,
    level: u32,
}

impl StreamWriter {
    pub fn create(path: &Path, sample_cap: usize, buf: usize, level: u32) -> Result<StreamWriter, BuildError> {
        let f = File::create(path).map_err(|e| BuildError::io(path, "create", e))?;
        Ok(StreamWriter {
            path: path.to_path_buf(),
            out: BufWriter::with_capacity(buf, f),
            count: 0,
            bounds: Aabb::EMPTY,
            cbounds: Aabb::EMPTY,
            sample: Sample::new(sample_cap),
            level,
        })
    }

    #[inline]
    pub fn push(&mut self, t: &StreamTri) -> Result<(), BuildError> {
        let b = t.bounds();
        let c = [(b.min[0] + b.max[0]) * 0.5, (b.min[1] + b.max[1]) * 0.5, (b.min[2] + b.max[2]) * 0.5];
        self.bounds.grow(&b);
        self.cbounds.grow_point(c);
        self.sample.add(&b);
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
            sample: self.sample,
            level: self.level,
        })
    }
}

/// Reads a stream file sequentially in blocks of records.
pub struct StreamReader {
    path: PathBuf,
    inp: BufReader<File>,
    left: u64,
    /// Bytes handed out by [`StreamReader::read`], and the prefix of them given back to the
    /// file system ([`StreamReader::release`]).
    consumed: u64,
    released: u64,
    /// Whether the file is released as it is read (opened for writing; the system can).
    releasing: bool,
}

/// The least a [`StreamReader::release`] gives back at once.
pub const RELEASE_STEP: u64 = 16 << 20;

impl StreamReader {
    pub fn open(s: &StreamFile) -> Result<StreamReader, BuildError> {
        let f = File::open(&s.path).map_err(|e| BuildError::io(&s.path, "open", e))?;
        Ok(StreamReader::of(s, f, false))
    }

    /// Opens `s` to be read once and thrown away: [`StreamReader::release`] gives the disk
    /// blocks already read back to the file system (a hole punched in the file), so that a
    /// split pass needs room for the children alone, not for the parent beside them.
    pub fn open_consuming(s: &StreamFile) -> Result<StreamReader, BuildError> {
        let f = File::options().read(true).write(true).open(&s.path).map_err(|e| BuildError::io(&s.path, "open", e))?;
        Ok(StreamReader::of(s, f, cfg!(target_os = "linux")))
    }

    fn of(s: &StreamFile, f: File, releasing: bool) -> StreamReader {
        let inp = BufReader::with_capacity(IO_BUF, f);
        StreamReader { path: s.path.clone(), inp, left: s.count, consumed: 0, released: 0, releasing }
    }

    /// Fills `buf` with up to `buf.len()` records; returns how many (0 at the end).
    pub fn read(&mut self, buf: &mut [StreamTri]) -> Result<usize, BuildError> {
        let n = (buf.len() as u64).min(self.left) as usize;
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut buf[..n]);
        self.inp.read_exact(bytes).map_err(|e| BuildError::io(&self.path, "read", e))?;
        self.left -= n as u64;
        self.consumed += bytes.len() as u64;
        Ok(n)
    }

    /// On a stream opened with [`StreamReader::open_consuming`], gives back the blocks of
    /// what has been read, once at least [`RELEASE_STEP`] bytes have gathered; returns
    /// whether it did. A file system that cannot punch holes keeps them (the build then
    /// needs more room, as before).
    pub fn release(&mut self) -> bool {
        let upto = self.consumed & !4095;
        if !self.releasing || upto < self.released + RELEASE_STEP {
            return false;
        }
        #[cfg(target_os = "linux")]
        {
            use rustix::fs::{fallocate, FallocateFlags};
            let mode = FallocateFlags::PUNCH_HOLE | FallocateFlags::KEEP_SIZE;
            if fallocate(self.inp.get_ref(), mode, self.released, upto - self.released).is_err() {
                self.releasing = false;
                return false;
            }
        }
        self.released = upto;
        true
    }
}

/// Bytes the files in `dir` (not below it) take on disk: what a build's temporary files use.
pub fn disk_usage(dir: &Path) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    entries.filter_map(|e| e.ok()?.metadata().ok()).filter(|m| m.is_file()).map(|m| allocated(&m)).sum()
}

#[cfg(unix)]
fn allocated(m: &std::fs::Metadata) -> u64 {
    std::os::unix::fs::MetadataExt::blocks(m) * 512
}

#[cfg(not(unix))]
fn allocated(m: &std::fs::Metadata) -> u64 {
    m.len()
}
