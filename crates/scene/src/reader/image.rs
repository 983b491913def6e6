//! Opening a compact file (`compact.rs`): its extent table, read and checked, and the
//! memory its image needs when opened in core.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::Path;

use crate::error::SceneError;
use crate::format::{Extent, Header, EXTENT_RAW, EXTENT_TILE, PAGE};
use crate::reader::Scene;

/// The longest image a reader takes: the format addresses 2^44 bytes (`ChildRef`).
const MAX_IMAGE: u64 = 1 << 44;
/// The longest tile a reader decodes (`megaray build --tile-size` is at most 64 MiB).
const MAX_TILE: u64 = 1 << 30;
/// The most a stored tile grows when decoded: a node is at least its one byte of used
/// slots (256 bytes decoded), a block its one byte of lanes (144), after a 16-byte head.
const MAX_GROWTH: u64 = 256;

/// Reads and checks the extent table of the compact file `path` (`len` bytes): within the
/// file, its checksum, an image of whole pages within what the format addresses; extents in
/// image order inside the image, none overlapping, their stored forms in file order inside
/// the file, none overlapping; tiles starting on a page, alone in their last page, at most
/// [`MAX_TILE`] long, stored smaller and at most [`MAX_GROWTH`] times smaller; the first
/// extent the header, stored where it lies; less than a page of padding between extents
/// ([`check_tail`]: and after the last, for a file opened in core). A file that passes makes
/// every load read each stored byte at most once per tile and allocate at most a tile's
/// bytes.
pub(super) fn read_extents(path: &Path, file: &File, h: &Header, len: u64) -> Result<Vec<Extent>, SceneError> {
    let bad = |what: String| SceneError::corrupt(path, what);
    let bytes = h
        .extent_count
        .checked_mul(std::mem::size_of::<Extent>() as u64)
        .filter(|&b| h.extents_off.is_multiple_of(8) && h.extents_off.checked_add(b).is_some_and(|e| e <= len))
        .ok_or_else(|| {
            bad(format!("extent table ({} extents at byte {}) lies outside the file", h.extent_count, h.extents_off))
        })?;
    let mut raw = vec![0u8; bytes as usize];
    file.read_exact_at(&mut raw, h.extents_off).map_err(|e| SceneError::io(path, "read", &e))?;
    if !super::sums_match(xxhash_rust::xxh3::xxh3_64(&raw), h.extents_checksum) {
        return Err(bad("extent table checksum mismatch (the table is damaged)".into()));
    }
    let extents: Vec<Extent> = raw.chunks_exact(40).map(bytemuck::pod_read_unaligned).collect();
    if !h.image_bytes.is_multiple_of(PAGE) || h.image_bytes > MAX_IMAGE {
        return Err(bad(format!("image of {} bytes is not whole pages within 16 TiB", h.image_bytes)));
    }
    // Where the last extent's image and stored bytes end (a tile's image: its last page).
    let (mut end, mut stored) = (0, 0);
    for (i, e) in extents.iter().enumerate() {
        let image_end = e.image_off.checked_add(e.image_len).filter(|&x| x <= h.image_bytes);
        let stored_end = e.stored_off.checked_add(e.stored_len).filter(|&x| x <= len);
        let kind_ok = e.reserved == 0
            && e.image_len > 0
            && match e.kind {
                EXTENT_RAW => e.stored_len == e.image_len,
                EXTENT_TILE => {
                    e.image_off.is_multiple_of(PAGE)
                        && e.image_len.is_multiple_of(16)
                        && e.image_len <= MAX_TILE
                        && e.stored_len < e.image_len
                        && e.image_len <= e.stored_len.saturating_mul(MAX_GROWTH)
                }
                _ => false,
            };
        let first_ok = i > 0 || (e.image_off == 0 && e.stored_off == 0 && e.image_len >= 256 && e.kind == EXTENT_RAW);
        if e.image_off < end
            || e.stored_off < stored
            || image_end.is_none()
            || stored_end.is_none()
            || !kind_ok
            || !first_ok
        {
            return Err(bad(format!("extent {i} is out of order, out of bounds or of an unknown kind")));
        }
        if e.image_off - end >= PAGE {
            return Err(bad(format!(
                "extent {i} leaves {} bytes of the image before it uncovered (a writer pads less than a page)",
                e.image_off - end
            )));
        }
        end = covered_end(e);
        stored = e.stored_off + e.stored_len;
    }
    if extents.is_empty() {
        return Err(bad("a compact file without extents".into()));
    }
    Ok(extents)
}

/// Refuses an image that runs a page or more past its last extent when it is to be decoded
/// whole (in core): the writer pads less than a page, so the zeros would be the header's
/// claim alone, and `Scene::open` would allocate them. (A pager's region only reserves
/// address space for them, never touched.)
pub(super) fn check_tail(path: &Path, h: &Header, extents: &[Extent]) -> Result<(), SceneError> {
    let end = extents.last().map_or(0, covered_end);
    if h.image_bytes.saturating_sub(end) >= PAGE {
        return Err(SceneError::corrupt(
            path,
            format!(
                "the image runs {} bytes past its last extent (a writer pads less than a page)",
                h.image_bytes - end
            ),
        ));
    }
    Ok(())
}

/// Where the image bytes extent `e` accounts for end: a tile's whole last page is its own.
fn covered_end(e: &Extent) -> u64 {
    let end = e.image_off + e.image_len;
    if e.kind == EXTENT_TILE {
        end.next_multiple_of(PAGE)
    } else {
        end
    }
}

/// This machine's memory, in bytes (0 where unknown).
pub fn physical_memory() -> u64 {
    // SAFETY: sysconf only reads the system's configuration.
    let (pages, size) = unsafe { (libc::sysconf(libc::_SC_PHYS_PAGES), libc::sysconf(libc::_SC_PAGESIZE)) };
    (pages.max(0) as u64).saturating_mul(size.max(0) as u64)
}

/// Whether a scene whose image is `image_bytes` long may be opened in core: it takes at
/// most three quarters of this machine's memory.
pub fn fits_in_memory(image_bytes: u64) -> bool {
    let total = physical_memory();
    total == 0 || image_bytes <= total / 4 * 3
}

/// Refuses to decode a compact file whole (in core) when its image would not fit in
/// memory ([`fits_in_memory`]): such a scene is for a pager (`--mem`).
pub(super) fn check_fits(path: &Path, h: &Header) -> Result<(), SceneError> {
    let total = physical_memory();
    if !fits_in_memory(h.image_bytes) {
        return Err(SceneError::new(
            path,
            crate::SceneErrorKind::TooLarge,
            format!(
                "the scene takes {:.1} GiB in memory, more than this machine holds ({:.1} GiB): page it with a budget (--mem SIZE)",
                h.image_bytes as f64 / f64::from(1 << 30),
                total as f64 / f64::from(1 << 30)
            ),
        ));
    }
    Ok(())
}

impl Scene {
    /// Checks every tile of a scene opened for a pager ([`Scene::open_owned`]) one at a time:
    /// loaded, checked, released, so that a scene of any size is verified within a tile's
    /// memory. Returns the first fault. For a scene nothing traces meanwhile (`megaray info
    /// --verify`): its tiles count as checked afterwards but are not resident.
    pub fn verify_tile_by_tile(&self) -> Result<(), SceneError> {
        for t in 0..self.tiles().len() as u32 {
            let ranges = self.tile_ranges(t).unwrap_or_default();
            let read = ranges.iter().try_for_each(|&(o, l)| self.load(o, l));
            let checked = read.map_err(|e| SceneError::io(self.path(), "read", &e)).and_then(|_| self.check_tile(t));
            for &(o, l) in &ranges {
                self.release(o, l).map_err(|e| SceneError::io(self.path(), "release", &e))?;
            }
            checked?;
        }
        Ok(())
    }
}
