//! Views of which tiles a reader may enter without asking ([`CheckedTiles`]): the scene's
//! own record, and the view of a tracer that chooses levels of detail where rays enter parts.

use std::sync::atomic::{AtomicU8, Ordering};

use super::{Scene, TILE_OK, TILE_UNCHECKED};
use crate::format::NO_PART;

/// Which tiles have been checked and found sound ([`Scene::checked_tiles`]): a tile once
/// checked stays so, so a `true` never goes stale.
#[derive(Clone, Copy)]
pub struct CheckedTiles<'a>(pub(super) &'a [AtomicU8]);

impl CheckedTiles<'_> {
    /// A view in which no tile counts as checked (for a reader that must ask about every
    /// tile elsewhere, such as a paged tracer).
    pub const NONE: CheckedTiles<'static> = CheckedTiles(&[]);

    /// Whether this is [`CheckedTiles::NONE`].
    pub fn is_none(&self) -> bool {
        self.0.is_empty()
    }

    /// Whether tile `t` has been checked and found sound. Relaxed: the check publishes
    /// nothing but its verdict (the tile's bytes are the file's, never written), and a
    /// relaxed load lets the tracer's loop keep its other loads out of the loop.
    #[inline(always)]
    pub fn get(&self, t: u32) -> bool {
        self.0.get(t as usize).is_some_and(|s| s.load(Ordering::Relaxed) == TILE_OK)
    }
}

impl Scene {
    /// Every tile counted as checked except the root tiles of full-detail parts that have
    /// levels of detail, once every tile has been checked (`None` before): the view of an
    /// unpaged tracer that chooses a level where a ray enters a part. Its kernel follows
    /// links inline as a fully checked one does and stops only where a link leads into such
    /// a tile, where the level is chosen (a link into one of those tiles that is not a part's
    /// root is followed after the stop, unchanged).
    pub fn checked_but_lod_roots(&self) -> Option<CheckedTiles<'_>> {
        if !self.all_tiles_checked() {
            return None;
        }
        let states = self.lod_stops.get_or_init(|| {
            let states: Vec<AtomicU8> = (0..self.header.tile_count).map(|_| AtomicU8::new(TILE_OK)).collect();
            let parts = self.parts();
            for p in &parts[..(self.full_part_count() as usize).min(parts.len())] {
                if p.lod_next != NO_PART {
                    if let Some(s) = states.get(p.root_tile as usize) {
                        s.store(TILE_UNCHECKED, Ordering::Relaxed);
                    }
                }
            }
            states
        });
        Some(CheckedTiles(states))
    }
}
