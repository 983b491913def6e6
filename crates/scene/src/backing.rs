//! Where an open scene's bytes live.
//!
//! - [`Backing::Mapped`]: the file mapped read-only; the operating system pages it on demand.
//!   For scenes traced in core (and the benchmark, which wants 2 MiB pages).
//! - [`Backing::Owned`]: an anonymous region as long as the file, into which a pager reads
//!   (`pread`) the byte ranges it wants and from which it releases them (`madvise
//!   DONTNEED`). Resident memory is then exactly what the pager loaded, in 4 KiB pages,
//!   whatever the page cache holds: a file mapping maps whatever folio a fault lands in
//!   (2 MiB when the file was read before through another map), past any budget. A file
//!   truncated under the process makes a read fail with an error, not a `SIGBUS`.
//!
//! - [`Backing::Image`]: a compact file's image (`compact.rs`) decoded whole into a region,
//!   for scenes traced in core.
//!
//! The same offsets address all three, so the tracer reads any through one slice. A region
//! of a compact file maps image offsets to the file through its extents: plain runs are
//! read as they are, tiles read and decoded.
//! Ranges loaded into an owned region may share their first and last pages with a
//! neighbour's range (a tile's attributes are not page aligned): those pages are counted
//! (`shared`) and read once, released when the last range holding them is released.

use std::collections::HashMap;
use std::fs::File;
use std::io;
use std::os::fd::AsRawFd;
use std::sync::Mutex;

use memmap2::Mmap;

use crate::compact::{self, TilePlace};
use crate::format::{Extent, EXTENT_TILE, PAGE};

pub(crate) enum Backing {
    Mapped(Mmap),
    Owned(Region),
    Image(Region),
}

impl Backing {
    #[inline(always)]
    pub(crate) fn bytes(&self) -> &[u8] {
        match self {
            Backing::Mapped(m) => m,
            Backing::Owned(r) | Backing::Image(r) => r.bytes(),
        }
    }

    /// A compact file's extents; empty for a file that is its own image.
    pub(crate) fn extents(&self) -> &[Extent] {
        match self {
            Backing::Mapped(_) => &[],
            Backing::Owned(r) | Backing::Image(r) => &r.extents,
        }
    }
}

/// An anonymous, private, unreserved mapping of `len` bytes that mirrors a file's offsets.
pub(crate) struct Region {
    ptr: *mut u8,
    /// The file's length (the mapping is rounded up to whole pages).
    len: usize,
    mapped: usize,
    file: File,
    /// Pages only partly covered by a loaded range, and how many loaded ranges hold each.
    shared: Mutex<HashMap<u64, u32>>,
    /// A compact file's extents, in image order (checked by the reader); empty when the
    /// file is its own image.
    extents: Vec<Extent>,
}

thread_local! {
    /// A stored tile's bytes, read into a buffer each thread keeps.
    static STORED: std::cell::RefCell<Vec<u8>> = const { std::cell::RefCell::new(Vec::new()) };
}

// SAFETY: the region is plain memory owned by this struct. Bytes are written only by
// `load` (through the kernel, `pread`) into pages no reader may be reading: pages counted in
// `shared` are written only by their first holder, under the lock; whole pages belong to
// one range, which its owner (the pager) loads before publishing it and releases only after
// a grace period in which no reader can still hold it.
unsafe impl Send for Region {}
unsafe impl Sync for Region {}

impl Region {
    /// Reserves address space for `file` of `len` bytes (nothing resident yet: every page
    /// reads as zero until loaded). With `extents`, `len` is a compact file's image length
    /// and loads go through the extents; `huge` asks for 2 MiB pages (a region loaded whole
    /// and traced in core) rather than 4 KiB ones (a pager's, whose resident memory is
    /// what it loaded).
    pub(crate) fn new(file: File, len: u64, extents: Vec<Extent>, huge: bool) -> io::Result<Region> {
        let len = usize::try_from(len).map_err(|_| io::Error::other("file larger than the address space"))?;
        let mapped = len.div_ceil(PAGE as usize).max(1) * PAGE as usize;
        // SAFETY: a fresh anonymous private mapping at an address of the kernel's choice;
        // it aliases nothing. NORESERVE: address space only, no commit charge for a file
        // far larger than memory.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                mapped,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS | libc::MAP_NORESERVE,
                -1,
                0,
            )
        };
        if ptr == libc::MAP_FAILED {
            return Err(io::Error::last_os_error());
        }
        // 4 KiB pages only, so that resident memory is what was loaded. (A kernel without
        // transparent huge pages refuses the advice, EINVAL: then there are none to avoid.)
        #[cfg(target_os = "linux")]
        // SAFETY: advice on the mapping just made.
        unsafe {
            libc::madvise(ptr, mapped, if huge { libc::MADV_HUGEPAGE } else { libc::MADV_NOHUGEPAGE });
        }
        // Reads fetch exactly the ranges asked for: no read-ahead around them (a pager's
        // tiles are scattered over the file, and read-ahead would read what it never asked).
        #[cfg(target_os = "linux")]
        // SAFETY: advice on a file descriptor `file` keeps open; it reads no memory of ours.
        unsafe {
            libc::posix_fadvise(file.as_raw_fd(), 0, 0, libc::POSIX_FADV_NORMAL);
        }
        Ok(Region { ptr: ptr.cast(), len, mapped, file, shared: Mutex::new(HashMap::new()), extents })
    }

    #[inline(always)]
    pub(crate) fn bytes(&self) -> &[u8] {
        // SAFETY: `ptr` is a live mapping of at least `len` readable bytes for as long as
        // `self` lives. Pages not loaded read as zero; see the `Sync` note for writes.
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }

    /// Reads the file's bytes `off..off + len`, widened to whole pages, into the region.
    /// On error nothing stays counted as loaded.
    pub(crate) fn load(&self, off: u64, len: u64) -> io::Result<()> {
        if let Some(e) = self.whole_tile(off, len) {
            return self.load_tile(e);
        }
        let Some(span) = self.span(off, len) else { return Ok(()) };
        let mut held = Vec::with_capacity(2);
        let result = (|| {
            for p in span.partial() {
                self.hold(p)?;
                held.push(p);
            }
            if span.whole.1 > span.whole.0 {
                self.read((span.whole.0 * PAGE) as usize, ((span.whole.1 - span.whole.0) * PAGE) as usize)?;
            }
            Ok(())
        })();
        if result.is_err() {
            for p in held {
                self.unhold(p);
            }
            self.discard(span.whole.0, span.whole.1);
        }
        result
    }

    /// The tile extent that is exactly `off..off + len`, if any (what a pager loads).
    fn whole_tile(&self, off: u64, len: u64) -> Option<&Extent> {
        let e = self.extents_in(off, off.saturating_add(len)).first()?;
        (e.kind == EXTENT_TILE && e.image_off == off && e.image_len == len).then_some(e)
    }

    /// Loads tile extent `e`, decoded straight into place. A tile starts on a page and the
    /// rest of its last page holds nothing else (the reader checks both when it opens the
    /// file, `reader/image.rs`), so that page is counted as held, as [`Region::release`]
    /// expects, but not read apart.
    fn load_tile(&self, e: &Extent) -> io::Result<()> {
        let Some(span) = self.span(e.image_off, e.image_len) else { return Ok(()) };
        if let Some(p) = span.tail {
            *self.shared.lock().unwrap_or_else(|x| x.into_inner()).entry(p).or_insert(0) += 1;
        }
        let (at, n) = (e.image_off as usize, e.image_len as usize);
        self.populate(at, n);
        // SAFETY: the destination lies inside the mapping, and no reader reads it until the
        // load is published (see the `Sync` note); the tile's pages are its own.
        let out = unsafe { std::slice::from_raw_parts_mut(self.ptr.add(at), n) };
        let result = self.decode_tile(e, out);
        if result.is_err() {
            if let Some(p) = span.tail {
                self.unhold(p);
            }
            self.discard(span.whole.0, span.whole.1);
        }
        result
    }

    /// Starts reading the file's bytes `off..off + len` into the page cache (posix_fadvise
    /// WILLNEED), so that a [`Region::load`] of them soon after waits less: a pager asks so
    /// for every tile it queues, which keeps many reads in flight.
    pub(crate) fn prefetch(&self, off: u64, len: u64) {
        if self.extents.is_empty() {
            self.advise_will_need(off, len);
            return;
        }
        for e in self.extents_in(off, off.saturating_add(len)) {
            self.advise_will_need(e.stored_off, e.stored_len);
        }
    }

    fn advise_will_need(&self, off: u64, len: u64) {
        #[cfg(target_os = "linux")]
        // SAFETY: advice on a file descriptor `self.file` keeps open; it reads no memory.
        unsafe {
            libc::posix_fadvise(
                self.file.as_raw_fd(),
                off as libc::off_t,
                len as libc::off_t,
                libc::POSIX_FADV_WILLNEED,
            );
        }
    }

    /// The extents that overlap image bytes `from..to`.
    fn extents_in(&self, from: u64, to: u64) -> &[Extent] {
        let first = self.extents.partition_point(|e| e.image_off + e.image_len <= from);
        let last = self.extents.partition_point(|e| e.image_off < to);
        &self.extents[first..last.max(first)]
    }

    /// Loads the whole image (a compact file opened in core), on `threads` threads, before
    /// anyone reads it.
    pub(crate) fn load_all(&self, threads: usize) -> io::Result<()> {
        let n = self.extents.len();
        let threads = threads.clamp(1, n.max(1));
        std::thread::scope(|s| {
            let jobs: Vec<_> = (0..threads)
                .map(|t| {
                    s.spawn(move || -> io::Result<()> {
                        // Whole extents, every `threads`-th: no page is written by two
                        // threads but a page two extents share, which `read` writes only
                        // within each extent's own bytes.
                        for e in self.extents.iter().skip(t).step_by(threads) {
                            self.read(e.image_off as usize, e.image_len as usize)?;
                        }
                        Ok(())
                    })
                })
                .collect();
            jobs.into_iter().try_for_each(|j| j.join().unwrap_or_else(|_| Err(io::Error::other("a loader panicked"))))
        })
    }

    /// Releases what [`Region::load`] loaded for the same range: its whole pages now, its
    /// shared pages when no other loaded range holds them. The caller guarantees that no
    /// thread still reads the range.
    pub(crate) fn release(&self, off: u64, len: u64) {
        let Some(span) = self.span(off, len) else { return };
        for p in span.partial() {
            self.unhold(p);
        }
        self.discard(span.whole.0, span.whole.1);
    }

    /// The pages of a range: those it covers whole, and the first and last when only partly
    /// covered. `None` for an empty range or one past the file.
    fn span(&self, off: u64, len: u64) -> Option<Span> {
        let end = off.saturating_add(len).min(self.len as u64);
        if off >= end {
            return None;
        }
        let (first, last) = (off / PAGE, (end - 1) / PAGE);
        // The file's last page is whole for a range that ends at the end of the file only
        // if the file ends on a page boundary; count it shared otherwise (harmless).
        let head = (!off.is_multiple_of(PAGE)).then_some(first);
        let tail = (!end.is_multiple_of(PAGE) && head != Some(last)).then_some(last);
        let whole = (first + head.is_some() as u64, last + 1 - tail.is_some() as u64);
        let whole = if head == Some(last) { (last + 1, last + 1) } else { whole };
        Some(Span { head, tail, whole })
    }

    /// Counts a holder of shared page `p`, reading it if it had none.
    fn hold(&self, p: u64) -> io::Result<()> {
        let mut shared = self.shared.lock().unwrap_or_else(|e| e.into_inner());
        let n = shared.entry(p).or_insert(0);
        if *n == 0 {
            let at = (p * PAGE) as usize;
            if let Err(e) = self.read(at, (PAGE as usize).min(self.len - at)) {
                shared.remove(&p);
                return Err(e);
            }
        }
        *shared.get_mut(&p).expect("just counted") += 1;
        Ok(())
    }

    fn unhold(&self, p: u64) {
        let mut shared = self.shared.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(n) = shared.get_mut(&p) {
            *n -= 1;
            if *n == 0 {
                shared.remove(&p);
                self.discard(p, p + 1);
            }
        }
    }

    /// Drops pages `from..to` (they read as zero again).
    fn discard(&self, from: u64, to: u64) {
        if to <= from {
            return;
        }
        let at = (from * PAGE) as usize;
        let n = (((to - from) * PAGE) as usize).min(self.mapped - at);
        // SAFETY: the pages lie inside the mapping; no reader holds them (the caller's
        // promise, or the shared count fell to zero). DONTNEED on private anonymous memory
        // frees the pages: nothing references them afterwards.
        unsafe {
            libc::madvise(self.ptr.add(at).cast(), n, libc::MADV_DONTNEED);
        }
    }

    /// Reads image bytes `at..at + n` into the region: the file's bytes at the same offset,
    /// or, for a compact file, what its extents give.
    fn read(&self, at: usize, n: usize) -> io::Result<()> {
        let n = n.min(self.len.saturating_sub(at));
        self.populate(at, n);
        if self.extents.is_empty() {
            return self.pread(at, n, at as u64);
        }
        self.read_image(at, n)
    }

    /// [`Region::read`] through the extents (image bytes no extent covers stay as they are:
    /// zero, as the pages being read are not loaded). A stored tile that does not decode
    /// reads as zeros: its checksum then fails when it is checked, as a damaged plain
    /// tile's does. Only reading the file can fail. A tile covered in part (no load of
    /// megaray's own does so: a pager loads whole tiles, [`Region::load_tile`]) is decoded
    /// aside and its part copied.
    fn read_image(&self, at: usize, n: usize) -> io::Result<()> {
        let (from, to) = (at as u64, (at + n) as u64);
        for e in self.extents_in(from, to) {
            let (lo, hi) = (from.max(e.image_off), to.min(e.image_off + e.image_len));
            if e.kind != EXTENT_TILE {
                self.pread(lo as usize, (hi - lo) as usize, e.stored_off + (lo - e.image_off))?;
                continue;
            }
            if lo == e.image_off && hi == e.image_off + e.image_len {
                // SAFETY: the destination lies inside the mapping, and no reader reads it
                // until the load is published (see the `Sync` note).
                let out = unsafe { std::slice::from_raw_parts_mut(self.ptr.add(lo as usize), (hi - lo) as usize) };
                self.decode_tile(e, out)?;
                continue;
            }
            let mut tile = vec![0u8; e.image_len as usize];
            self.decode_tile(e, &mut tile)?;
            let part = &tile[(lo - e.image_off) as usize..(hi - e.image_off) as usize];
            // SAFETY: as above.
            unsafe { std::ptr::copy_nonoverlapping(part.as_ptr(), self.ptr.add(lo as usize), part.len()) };
        }
        Ok(())
    }

    /// Decodes tile extent `e` into `out` (its image length): zeros where the stored tile
    /// does not decode (its checksum then fails when checked). Only reading can fail.
    fn decode_tile(&self, e: &Extent, out: &mut [u8]) -> io::Result<()> {
        STORED.with(|b| {
            let mut buf = b.borrow_mut();
            buf.resize(e.stored_len as usize, 0);
            let mut done = 0;
            while done < buf.len() {
                match std::os::unix::fs::FileExt::read_at(&self.file, &mut buf[done..], e.stored_off + done as u64) {
                    Ok(0) => return Err(truncated(e.stored_off + e.stored_len)),
                    Ok(got) => done += got,
                    Err(x) if x.kind() == io::ErrorKind::Interrupted => {}
                    Err(x) => return Err(x),
                }
            }
            let place = TilePlace::at(e.image_off, compact::stored_counts(&buf).map_or(0, |c| c.0));
            if compact::decode(&buf, out, place).is_err() {
                out.fill(0);
            }
            Ok(())
        })
    }

    /// Faults the region's pages `at..at + n` in with one call rather than one trap per
    /// page during the copy. (Advice: a kernel before 5.14 refuses it, and the copy faults.)
    fn populate(&self, at: usize, n: usize) {
        #[cfg(target_os = "linux")]
        // SAFETY: the pages lie inside the mapping and are written by nobody else now.
        unsafe {
            let first = at / PAGE as usize * PAGE as usize;
            libc::madvise(
                self.ptr.add(first).cast(),
                (at + n).div_ceil(PAGE as usize) * PAGE as usize - first,
                libc::MADV_POPULATE_WRITE,
            );
        }
    }

    /// Reads `n` bytes of the file at `from` into the region at `at`.
    fn pread(&self, at: usize, n: usize, from: u64) -> io::Result<()> {
        let mut done = 0;
        while done < n {
            // SAFETY: the destination `at + done .. at + n` lies inside the mapping, and no
            // reader reads it until the load is published (see the `Sync` note).
            let got = unsafe {
                libc::pread(
                    self.file.as_raw_fd(),
                    self.ptr.add(at + done).cast(),
                    n - done,
                    (from + done as u64) as libc::off_t,
                )
            };
            if got < 0 {
                let e = io::Error::last_os_error();
                if e.kind() == io::ErrorKind::Interrupted {
                    continue;
                }
                return Err(e);
            }
            if got == 0 {
                return Err(truncated(from + n as u64));
            }
            done += got as usize;
        }
        Ok(())
    }
}

fn truncated(end: u64) -> io::Error {
    io::Error::new(io::ErrorKind::UnexpectedEof, format!("the file ends before byte {end} (truncated while open?)"))
}

impl Drop for Region {
    fn drop(&mut self) {
        // SAFETY: the mapping made in `new`; no view outlives `self` (they borrow it).
        unsafe {
            libc::munmap(self.ptr.cast(), self.mapped);
        }
    }
}

/// A range's pages ([`Region::span`]).
struct Span {
    head: Option<u64>,
    tail: Option<u64>,
    /// Pages covered whole, `from..to`.
    whole: (u64, u64),
}

impl Span {
    fn partial(&self) -> impl Iterator<Item = u64> {
        self.head.into_iter().chain(self.tail)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn region(len: usize) -> (tempfile::TempPath, Region, Vec<u8>) {
        let data: Vec<u8> = (0..len).map(|i| (i * 7 + 1) as u8 | 1).collect();
        let mut f = tempfile::NamedTempFile::new().unwrap();
        f.write_all(&data).unwrap();
        let path = f.into_temp_path();
        let r = Region::new(File::open(&path).unwrap(), len as u64, Vec::new(), false).unwrap();
        (path, r, data)
    }

    /// Bytes of a loaded range equal the file's; released, they read as zero, but a page
    /// shared with a range still loaded keeps its bytes.
    #[test]
    fn loads_and_releases_with_shared_pages() {
        let len = 10 * PAGE as usize + 100;
        let (_p, r, data) = region(len);
        assert!(r.bytes().iter().all(|&b| b == 0));
        let a = (100u64, 2 * PAGE + 50); // pages 0..=2, partial both ends
        let b = (2 * PAGE + 150, 3 * PAGE); // shares page 2 with a
        let c = (8 * PAGE, len as u64 - 8 * PAGE); // to the end of the file
        for (o, l) in [a, b, c] {
            r.load(o, l).unwrap();
            assert_eq!(&r.bytes()[o as usize..(o + l) as usize], &data[o as usize..(o + l) as usize]);
        }
        r.release(a.0, a.1);
        assert!(r.bytes()[..2 * PAGE as usize].iter().all(|&x| x == 0), "a's own pages released");
        let (o, l) = (b.0 as usize, b.1 as usize);
        assert_eq!(&r.bytes()[o..o + l], &data[o..o + l], "b's bytes, page 2 among them, stay");
        r.release(b.0, b.1);
        r.release(c.0, c.1);
        assert!(r.bytes().iter().all(|&x| x == 0));
        assert!(r.shared.lock().unwrap().is_empty());
    }

    /// A range inside one page, ranges past the file, a file truncated under the region.
    #[test]
    fn edge_ranges_and_truncation() {
        let len = 3 * PAGE as usize;
        let (path, r, data) = region(len);
        r.load(10, 20).unwrap();
        r.load(40, 20).unwrap();
        assert_eq!(&r.bytes()[10..60], &data[10..60]);
        r.release(10, 20);
        assert_eq!(&r.bytes()[40..60], &data[40..60]);
        r.release(40, 20);
        r.load(len as u64 + 5, 10).unwrap();
        std::fs::OpenOptions::new().write(true).open(&path).unwrap().set_len(PAGE).unwrap();
        let e = r.load(PAGE, 2 * PAGE).unwrap_err();
        assert!(e.to_string().contains("truncated"), "{e}");
        assert!(r.shared.lock().unwrap().is_empty());
    }
}
