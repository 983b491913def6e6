//! Triangle stream files: the positions-only, fixed-record files the out-of-core build
//! splits recursively. In memory a record is a [`StreamTri`] (48 bytes: corners and the
//! triangle's id, which keys its attributes in the separate attribute streams,
//! [`crate::attrs`]). On disk it is 36 bytes, the corners alone, unless the id must be kept
//! ([`Ids`]): an object's import stream is in id order, so its ids are implicit, and a model
//! without attributes needs none; only the split children of a model with attributes carry
//! the full 48.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use megaray_base::Aabb;

use crate::behind::{Target, WriteBehind};
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

/// What a stream file says of its triangles' ids.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ids {
    /// Records in id order from `base` (an object's import stream): 36 bytes.
    Implicit(u64),
    /// Each record holds its id: 48 bytes.
    Stored,
    /// Not needed (no attributes): 36 bytes, ids read as 0.
    Absent,
}

impl Ids {
    /// Bytes of a record on disk.
    pub fn record_bytes(self) -> u64 {
        match self {
            Ids::Stored => 48,
            Ids::Implicit(_) | Ids::Absent => 36,
        }
    }
}

/// Bytes of the corners alone, the head of a [`StreamTri`].
const CORNER_BYTES: usize = 36;

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
    /// Its records' ids, and so their size on disk.
    pub ids: Ids,
}

impl StreamFile {
    /// Bytes of its records on disk.
    pub fn bytes(&self) -> u64 {
        self.count * self.ids.record_bytes()
    }
}

/// Writes a stream file, keeping its count, bounds, centroid bounds and a sample of its boxes.
/// Its bytes go in whole buffers to a [`WriteBehind`] thread (shared by a split pass's
/// children), so that the copy into the page cache overlaps the caller's work.
pub struct StreamWriter {
    path: PathBuf,
    target: Arc<Target>,
    buf: Vec<u8>,
    cap: usize,
    wb: Arc<WriteBehind>,
    count: u64,
    bounds: Aabb,
    cbounds: Aabb,
    sample: Sample,
    level: u32,
    ids: Ids,
}

impl StreamWriter {
    /// A stream file at `path`, written by `wb`'s thread in buffers of `buf` bytes.
    pub fn create(
        path: &Path,
        sample_cap: usize,
        buf: usize,
        level: u32,
        ids: Ids,
        wb: &Arc<WriteBehind>,
    ) -> Result<StreamWriter, BuildError> {
        let f = File::create(path).map_err(|e| BuildError::io(path, "create", e))?;
        Ok(StreamWriter {
            path: path.to_path_buf(),
            target: Arc::new(Target { path: path.to_path_buf(), file: f }),
            buf: wb.buffer(buf),
            cap: buf,
            wb: wb.clone(),
            count: 0,
            bounds: Aabb::EMPTY,
            cbounds: Aabb::EMPTY,
            sample: Sample::new(sample_cap),
            level,
            ids,
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
        let bytes = bytemuck::bytes_of(t);
        let rec = if self.ids == Ids::Stored { bytes } else { &bytes[..CORNER_BYTES] };
        if self.buf.len() + rec.len() > self.cap {
            let full = std::mem::replace(&mut self.buf, self.wb.buffer(self.cap));
            self.wb.write(&self.target, full)?;
        }
        self.buf.extend_from_slice(rec);
        Ok(())
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    pub fn finish(self) -> Result<StreamFile, BuildError> {
        let path = self.path;
        if !self.buf.is_empty() {
            self.wb.write(&self.target, self.buf)?;
        }
        self.wb.sync()?;
        Ok(StreamFile {
            path,
            count: self.count,
            bounds: self.bounds,
            cbounds: self.cbounds,
            sample: self.sample,
            level: self.level,
            ids: self.ids,
        })
    }
}

/// Reads a stream file sequentially in blocks of records.
pub struct StreamReader {
    path: PathBuf,
    inp: BufReader<File>,
    left: u64,
    ids: Ids,
    /// Records read so far (the ids of an [`Ids::Implicit`] stream).
    index: u64,
    /// Corners read from a 36-byte stream, before they become records.
    scratch: Vec<u8>,
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
        let (left, ids) = (s.count, s.ids);
        StreamReader {
            path: s.path.clone(),
            inp,
            left,
            ids,
            index: 0,
            scratch: Vec::new(),
            consumed: 0,
            released: 0,
            releasing,
        }
    }

    /// Fills `buf` with up to `buf.len()` records; returns how many (0 at the end).
    pub fn read(&mut self, buf: &mut [StreamTri]) -> Result<usize, BuildError> {
        let n = (buf.len() as u64).min(self.left) as usize;
        let bytes = if self.ids == Ids::Stored {
            let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut buf[..n]);
            self.inp.read_exact(bytes).map_err(|e| BuildError::io(&self.path, "read", e))?;
            bytes.len()
        } else {
            self.scratch.resize(n * CORNER_BYTES, 0);
            self.inp.read_exact(&mut self.scratch).map_err(|e| BuildError::io(&self.path, "read", e))?;
            for (k, (t, rec)) in buf.iter_mut().zip(self.scratch.chunks_exact(CORNER_BYTES)).enumerate() {
                t.v = bytemuck::pod_read_unaligned(rec);
                t.id = match self.ids {
                    Ids::Implicit(base) => base + self.index + k as u64,
                    _ => 0,
                };
            }
            self.scratch.len()
        };
        self.left -= n as u64;
        self.index += n as u64;
        self.consumed += bytes as u64;
        Ok(n)
    }

    /// Reads the rest of the stream: its triangles' corners onto `tris` and, unless the
    /// stream has no ids ([`Ids::Absent`]), their ids onto `ids`. A 36-byte stream is read
    /// straight into `tris` (no record copies); a 48-byte one through a small buffer. This is
    /// how a part is loaded whole (its peak then 36 bytes a triangle, 44 with ids, where
    /// records and a buffer of the whole stream took 128).
    pub fn read_all(&mut self, tris: &mut Vec<[[f32; 3]; 3]>, ids: &mut Vec<u64>) -> Result<(), BuildError> {
        let n = self.left as usize;
        tris.reserve(n);
        if self.ids == Ids::Stored {
            ids.reserve(n);
            let mut buf = vec![StreamTri::zeroed(); n.min(1 << 16)];
            while self.left > 0 {
                let got = self.read(&mut buf)?;
                tris.extend(buf[..got].iter().map(|t| t.v));
                ids.extend(buf[..got].iter().map(|t| t.id));
            }
            return Ok(());
        }
        let start = tris.len();
        tris.resize(start + n, [[0.0; 3]; 3]);
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut tris[start..]);
        self.inp.read_exact(bytes).map_err(|e| BuildError::io(&self.path, "read", e))?;
        if let Ids::Implicit(base) = self.ids {
            ids.extend((0..n as u64).map(|k| base + self.index + k));
        }
        self.left = 0;
        self.index += n as u64;
        self.consumed += bytes.len() as u64;
        Ok(())
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
