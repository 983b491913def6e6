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
//! The same file offsets address both, so the tracer reads either through one slice.
//! Ranges loaded into an owned region may share their first and last pages with a
//! neighbour's range (a tile's attributes are not page aligned): those pages are counted
//! (`shared`) and read once, released when the last range holding them is released.

use std::collections::HashMap;
use std::fs::File;
use std::io;
use std::os::fd::AsRawFd;
use std::sync::Mutex;

use memmap2::Mmap;

use crate::format::PAGE;

pub(crate) enum Backing {
    Mapped(Mmap),
    Owned(Region),
}

impl Backing {
    #[inline(always)]
    pub(crate) fn bytes(&self) -> &[u8] {
        match self {
            Backing::Mapped(m) => m,
            Backing::Owned(r) => r.bytes(),
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
    /// reads as zero until loaded).
    pub(crate) fn new(file: File, len: u64) -> io::Result<Region> {
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
            libc::madvise(ptr, mapped, libc::MADV_NOHUGEPAGE);
        }
        // Reads fetch exactly the ranges asked for: no read-ahead around them (a pager's
        // tiles are scattered over the file, and read-ahead would read what it never asked).
        #[cfg(target_os = "linux")]
        // SAFETY: advice on a file descriptor `file` keeps open; it reads no memory of ours.
        unsafe {
            libc::posix_fadvise(file.as_raw_fd(), 0, 0, libc::POSIX_FADV_NORMAL);
        }
        Ok(Region { ptr: ptr.cast(), len, mapped, file, shared: Mutex::new(HashMap::new()) })
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

    /// Starts reading the file's bytes `off..off + len` into the page cache (posix_fadvise
    /// WILLNEED), so that a [`Region::load`] of them soon after waits less: a pager asks so
    /// for every tile it queues, which keeps many reads in flight.
    pub(crate) fn prefetch(&self, off: u64, len: u64) {
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

    /// Reads `n` bytes of the file at `at` into the same offset of the region.
    fn read(&self, at: usize, n: usize) -> io::Result<()> {
        let n = n.min(self.len.saturating_sub(at));
        // Fault the destination's pages in with one call rather than one trap per page
        // during the copy. (Advice: a kernel before 5.14 refuses it, and the copy faults.)
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
        let mut done = 0;
        while done < n {
            // SAFETY: the destination `at + done .. at + n` lies inside the mapping, and no
            // reader reads it until the load is published (see the `Sync` note).
            let got = unsafe {
                libc::pread(self.file.as_raw_fd(), self.ptr.add(at + done).cast(), n - done, (at + done) as libc::off_t)
            };
            if got < 0 {
                let e = io::Error::last_os_error();
                if e.kind() == io::ErrorKind::Interrupted {
                    continue;
                }
                return Err(e);
            }
            if got == 0 {
                return Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    format!("the file ends before byte {} (truncated while open?)", at + n),
                ));
            }
            done += got as usize;
        }
        Ok(())
    }
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
        let r = Region::new(File::open(&path).unwrap(), len as u64).unwrap();
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
