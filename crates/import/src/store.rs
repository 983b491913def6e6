//! A vertex table that spills to disk: [`VertexStore`].
//!
//! Indexed formats (PLY, OBJ) need random access to every vertex read so far while faces
//! stream by. A [`VertexStore`] holds fixed-size records of `f32`s. The first records, up to
//! half of its byte budget, live in a `Vec`; the rest go to an anonymous temporary file (in
//! the given folder, removed when the store is dropped, also on error or panic) written in
//! blocks, and are served through a small clock-replacement block cache (a quarter of the
//! budget, at most [`MAX_CACHE_BYTES`]). Faces usually reference vertices near each other, so
//! the cache hit rate is high even when most of the table is on disk.
//!
//! Records can be appended while lookups happen (OBJ interleaves `v` and `f` lines): the
//! file only ever receives whole blocks, which never change afterwards, and the block being
//! filled is served from memory.

use std::fs::File;
use std::io;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

/// The largest block of the spill file, in bytes.
pub const MAX_BLOCK_BYTES: usize = 64 << 10;
/// The smallest block of the spill file, in bytes.
pub const MIN_BLOCK_BYTES: usize = 4 << 10;
/// The block cache never holds more than this many bytes.
pub const MAX_CACHE_BYTES: u64 = 4 << 20;

/// An append-only table of fixed-size `f32` records with random lookup, bounded in memory.
///
/// ```
/// use megaray_import::store::VertexStore;
/// let dir = std::env::temp_dir();
/// // 3 floats per record, 4 KiB budget: most of these records go to disk.
/// let mut s = VertexStore::new(3, 4096, &dir, 0);
/// for i in 0..10_000 {
///     s.push(&[i as f32, 0.0, 1.0]).unwrap();
/// }
/// let mut r = [0.0; 3];
/// s.get(9_999, &mut r).unwrap();
/// assert_eq!(r, [9_999.0, 0.0, 1.0]);
/// assert!(s.spilled() > 0);
/// ```
pub struct VertexStore {
    rec: usize,
    len: u64,
    mem: Vec<f32>,
    /// Records kept in `mem`.
    mem_cap: u64,
    budget: u64,
    temp_dir: PathBuf,
    spill: Option<Spill>,
}

/// The on-disk part of a store.
struct Spill {
    file: File,
    /// Records per block.
    block_recs: usize,
    /// The block being filled (fewer than `block_recs` records).
    wbuf: Vec<f32>,
    /// Whole blocks written to `file`.
    blocks: u64,
    cache: BlockCache,
}

/// A clock (second chance) cache of spill-file blocks. It holds few blocks (at most
/// [`MAX_CACHE_BYTES`] / [`MIN_BLOCK_BYTES`]), so lookups scan a dense array of block numbers.
struct BlockCache {
    slots: Vec<Slot>,
    /// The block held by each slot.
    tags: Vec<u64>,
    cap: usize,
    hand: usize,
    /// The slot of the last hit, checked before the map.
    last: usize,
}

struct Slot {
    data: Vec<f32>,
    referenced: bool,
}

/// Copies `src` into `dst[..src.len()]`, inlined for the short records stores hold (a
/// plain `copy_from_slice` of a run-time length is a `memcpy` call).
#[inline(always)]
fn copy_rec(dst: &mut [f32], src: &[f32]) {
    macro_rules! fixed {
        ($($n:literal)*) => {
            match src.len() {
                $($n => dst[..$n].copy_from_slice(&src[..$n]),)*
                n => dst[..n].copy_from_slice(src),
            }
        };
    }
    fixed!(1 2 3 4 5 6 7 8 9 10 11 12)
}

impl VertexStore {
    /// A store of `rec` floats per record that may use about `budget` bytes of memory: half
    /// for records kept in memory, a quarter for the block cache of the spill file created
    /// (on demand) in `temp_dir`. `hint` is the expected number of records (0 when unknown);
    /// it only sizes the first reservation, capped by the budget, so a lying hint costs
    /// nothing.
    pub fn new(rec: usize, budget: u64, temp_dir: &Path, hint: u64) -> VertexStore {
        let rec = rec.max(1);
        let rec_bytes = (rec * 4) as u64;
        let mem_cap = budget / 2 / rec_bytes;
        let first = hint.min(mem_cap).min(1 << 20) as usize;
        VertexStore {
            rec,
            len: 0,
            mem: Vec::with_capacity(first * rec),
            mem_cap,
            budget,
            temp_dir: temp_dir.to_path_buf(),
            spill: None,
        }
    }

    /// Floats per record.
    pub fn record_len(&self) -> usize {
        self.rec
    }

    /// Number of records.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// `true` when no record was pushed.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Number of records held on disk (0 until the in-memory part is full).
    pub fn spilled(&self) -> u64 {
        self.len - self.len.min(self.mem_cap)
    }

    /// Appends a record of [`VertexStore::record_len`] floats.
    pub fn push(&mut self, r: &[f32]) -> io::Result<()> {
        debug_assert_eq!(r.len(), self.rec);
        if self.len < self.mem_cap {
            if self.mem.len() == self.mem.capacity() {
                let have = (self.mem.len() / self.rec) as u64;
                let more = have.max(1024).min(self.mem_cap - have) as usize;
                self.mem.reserve_exact(more * self.rec);
            }
            let at = self.mem.len();
            self.mem.resize(at + self.rec, 0.0);
            copy_rec(&mut self.mem[at..], r);
        } else {
            if self.spill.is_none() {
                self.spill = Some(Spill::new(self.rec, self.budget, &self.temp_dir)?);
            }
            let s = self.spill.as_mut().expect("spill just created");
            s.wbuf.extend_from_slice(r);
            if s.wbuf.len() == s.block_recs * self.rec {
                let bytes: &[u8] = bytemuck::cast_slice(&s.wbuf);
                s.file.write_all_at(bytes, s.blocks * bytes.len() as u64)?;
                s.blocks += 1;
                s.wbuf.clear();
            }
        }
        self.len += 1;
        Ok(())
    }

    /// Copies record `i` (which must be `< len()`) into `out`.
    #[inline]
    pub fn get(&mut self, i: u64, out: &mut [f32]) -> io::Result<()> {
        assert!(i < self.len, "vertex store index {i} out of range ({} records)", self.len);
        let rec = self.rec;
        if i < self.mem_cap {
            let o = i as usize * rec;
            copy_rec(out, &self.mem[o..o + rec]);
            return Ok(());
        }
        let s = self.spill.as_mut().expect("spilled records have a spill file");
        let j = i - self.mem_cap;
        let block = j / s.block_recs as u64;
        let o = (j % s.block_recs as u64) as usize * rec;
        let data = if block == s.blocks { &s.wbuf[..] } else { s.cache.block(&s.file, block, s.block_recs * rec)? };
        copy_rec(out, &data[o..o + rec]);
        Ok(())
    }
}

impl Spill {
    fn new(rec: usize, budget: u64, temp_dir: &Path) -> io::Result<Spill> {
        let file = tempfile::tempfile_in(temp_dir).map_err(|e| {
            io::Error::new(e.kind(), format!("cannot create a spill file in {}: {e}", temp_dir.display()))
        })?;
        let cache_bytes = (budget / 4).min(MAX_CACHE_BYTES);
        // Aim for at least 8 blocks in the cache, within the block size limits.
        let block_bytes = ((cache_bytes / 8) as usize).clamp(MIN_BLOCK_BYTES, MAX_BLOCK_BYTES);
        let block_recs = (block_bytes / (rec * 4)).max(1);
        let cap = ((cache_bytes as usize) / (block_recs * rec * 4)).max(2);
        Ok(Spill {
            file,
            block_recs,
            wbuf: Vec::with_capacity(block_recs * rec),
            blocks: 0,
            cache: BlockCache { slots: Vec::new(), tags: Vec::new(), cap, hand: 0, last: 0 },
        })
    }
}

impl BlockCache {
    /// The floats of block `block` (of `floats` floats), loading it on a miss.
    #[inline]
    fn block(&mut self, file: &File, block: u64, floats: usize) -> io::Result<&[f32]> {
        if self.tags.get(self.last) == Some(&block) {
            self.slots[self.last].referenced = true;
            return Ok(&self.slots[self.last].data);
        }
        if let Some(k) = self.tags.iter().position(|&t| t == block) {
            self.last = k;
            self.slots[k].referenced = true;
            return Ok(&self.slots[k].data);
        }
        self.load(file, block, floats)
    }

    #[cold]
    fn load(&mut self, file: &File, block: u64, floats: usize) -> io::Result<&[f32]> {
        let k = if self.slots.len() < self.cap {
            self.slots.push(Slot { data: vec![0.0; floats], referenced: false });
            self.tags.push(block);
            self.slots.len() - 1
        } else {
            loop {
                let h = self.hand;
                self.hand = (self.hand + 1) % self.slots.len();
                if self.slots[h].referenced {
                    self.slots[h].referenced = false;
                } else {
                    break h;
                }
            }
        };
        // Invalidate the slot first: a failed read must not leave stale data tagged.
        self.tags[k] = u64::MAX;
        let slot = &mut self.slots[k];
        slot.referenced = true;
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut slot.data);
        let at = block * bytes.len() as u64;
        file.read_exact_at(bytes, at)?;
        self.tags[k] = block;
        self.last = k;
        Ok(&self.slots[k].data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(i: u64) -> [f32; 5] {
        let f = i as f32;
        [f, -f, f * 0.5, 1.0, (i % 7) as f32]
    }

    #[test]
    fn in_memory_only() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = VertexStore::new(5, 1 << 20, dir.path(), 1_000_000_000);
        for i in 0..1000 {
            s.push(&rec(i)).unwrap();
        }
        assert_eq!(s.spilled(), 0);
        let mut r = [0.0; 5];
        for i in (0..1000).rev() {
            s.get(i, &mut r).unwrap();
            assert_eq!(r, rec(i));
        }
    }

    #[test]
    fn spills_and_reads_back_randomly() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = VertexStore::new(5, 16 << 10, dir.path(), 0);
        let n = 200_000u64;
        for i in 0..n {
            s.push(&rec(i)).unwrap();
        }
        assert!(s.spilled() > n - 1000, "spilled {}", s.spilled());
        let mut r = [0.0; 5];
        let mut x = 12345u64;
        for _ in 0..50_000 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let i = (x >> 33) % n;
            s.get(i, &mut r).unwrap();
            assert_eq!(r, rec(i));
        }
        // Sequential scan, too.
        for i in 0..n {
            s.get(i, &mut r).unwrap();
            assert_eq!(r, rec(i));
        }
    }

    #[test]
    fn interleaved_push_and_get() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = VertexStore::new(5, 8 << 10, dir.path(), 0);
        let mut r = [0.0; 5];
        for i in 0..50_000u64 {
            s.push(&rec(i)).unwrap();
            for j in [i, i / 2, i.saturating_sub(3), i / 1000] {
                s.get(j, &mut r).unwrap();
                assert_eq!(r, rec(j));
            }
        }
    }

    #[test]
    fn spill_file_is_removed() {
        let dir = tempfile::tempdir().unwrap();
        {
            let mut s = VertexStore::new(3, 1024, dir.path(), 0);
            for i in 0..10_000 {
                s.push(&[i as f32; 3]).unwrap();
            }
            assert!(s.spilled() > 0);
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
