//! [`TileLayout`]: per-pixel buffers stored tile by tile, so that a tile's values are one
//! contiguous block (the accumulator's sums: a piece of a frame, which is a tile, is added
//! as one stream instead of 32 short rows a frame's width apart).

use rayon::prelude::*;

use crate::frame::TILE;
use crate::Rect;

/// Where pixel (x, y) of a `w` x `h` frame is stored: the [`TILE`] x [`TILE`] tiles in rows
/// of tiles (as [`crate::Rect::tiles`], edge tiles cut), each tile row-major within itself.
/// A band of `TILE` rows keeps the span it has row-major, so each band converts on its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct TileLayout {
    pub w: u32,
    pub h: u32,
}

impl TileLayout {
    /// Pixels in all.
    pub fn len(&self) -> usize {
        (self.w * self.h) as usize
    }

    /// Pixels in a full band (`TILE` rows); the last band may be shorter.
    pub fn band(&self) -> usize {
        (TILE * self.w) as usize
    }

    /// The index of the first pixel of the tile whose corner is (`x0`, `y0`), multiples of
    /// `TILE`; its pixels follow, `tile_w(x0)` a row.
    pub fn tile_start(&self, x0: u32, y0: u32) -> usize {
        (y0 * self.w + x0 * TILE.min(self.h - y0)) as usize
    }

    /// The width of the tiles starting at column `x0`.
    pub fn tile_w(&self, x0: u32) -> u32 {
        TILE.min(self.w - x0)
    }

    /// Where pixel (`x`, `y`) is stored.
    pub fn index(&self, x: u32, y: u32) -> usize {
        let (x0, y0) = (x / TILE * TILE, y / TILE * TILE);
        self.tile_start(x0, y0) + ((y - y0) * self.tile_w(x0) + (x - x0)) as usize
    }

    /// Calls `f(stored, row_major, n)` for every run of `n` pixels that is contiguous both
    /// stored and row-major (a tile's row), in row-major order.
    pub fn runs(&self, mut f: impl FnMut(usize, usize, usize)) {
        for y in 0..self.h {
            self.band_runs(y, &mut f);
        }
    }

    /// [`TileLayout::runs`] of row `y` alone.
    fn band_runs(&self, y: u32, f: &mut impl FnMut(usize, usize, usize)) {
        let y0 = y / TILE * TILE;
        for x0 in (0..self.w).step_by(TILE as usize) {
            let tw = self.tile_w(x0);
            let stored = self.tile_start(x0, y0) + ((y - y0) * tw) as usize;
            f(stored, (y * self.w + x0) as usize, tw as usize);
        }
    }

    /// Calls `f(stored, in_band, n)` for the runs of band `b` (rows `b * TILE` on, `rows` of
    /// them) tile by tile, each tile's rows in turn: `stored` counts from the band's first
    /// stored pixel, `in_band` is row-major from the band's first pixel. Tile by tile, the
    /// stored side is one stream and the row-major side stays in the cache.
    pub fn band_tile_runs(&self, b: usize, rows: usize, mut f: impl FnMut(usize, usize, usize)) {
        let (y0, base) = (b as u32 * TILE, b * self.band());
        for x0 in (0..self.w).step_by(TILE as usize) {
            let (tw, start) = (self.tile_w(x0) as usize, self.tile_start(x0, y0) - base);
            for r in 0..rows {
                f(start + r * tw, r * self.w as usize + x0 as usize, tw);
            }
        }
    }

    /// Calls `f(stored, local, n)` for runs covering rectangle `rc`, whose pixels are numbered
    /// row-major within it (`local`): one run if `rc` is a whole tile, else a row's part in
    /// each tile it crosses.
    pub fn rect_runs(&self, rc: Rect, mut f: impl FnMut(usize, usize, usize)) {
        let (x0, y0) = (rc.x0 / TILE * TILE, rc.y0 / TILE * TILE);
        let whole = rc.x0 == x0 && rc.y0 == y0 && rc.x1 == x0 + self.tile_w(x0) && rc.y1 == (y0 + TILE).min(self.h);
        if whole {
            return f(self.tile_start(x0, y0), 0, rc.area());
        }
        let pw = (rc.x1 - rc.x0) as usize;
        for (row, y) in (rc.y0..rc.y1).enumerate() {
            let mut x = rc.x0;
            while x < rc.x1 {
                let end = ((x / TILE + 1) * TILE).min(rc.x1);
                f(self.index(x, y), row * pw + (x - rc.x0) as usize, (end - x) as usize);
                x = end;
            }
        }
    }

    /// A row-major buffer of `f(stored index)` for every pixel, band by band on the current
    /// thread pool.
    pub fn gather<T: Send + Clone + Default>(&self, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
        self.gather_runs(|out: &mut [T], s| out.iter_mut().enumerate().for_each(|(k, o)| *o = f(s + k)))
    }

    /// A row-major buffer filled a run at a time: `f(out, s)` fills `out` with the values of
    /// the pixels stored from `s` on (a tile's row; loops over slices, which vectorise).
    pub fn gather_runs<T: Send + Clone + Default>(&self, f: impl Fn(&mut [T], usize) + Sync) -> Vec<T> {
        let mut out = vec![T::default(); self.len()];
        if self.len() == 0 {
            return out;
        }
        out.par_chunks_mut(self.band()).enumerate().for_each(|(b, band)| {
            let (base, rows) = (b * self.band(), band.len() / self.w as usize);
            self.band_tile_runs(b, rows, |s, at, n| f(&mut band[at..at + n], base + s));
        });
        out
    }

    /// `v` (row-major) stored tile by tile.
    pub fn scatter<T: Copy + Default>(&self, v: &[T]) -> Vec<T> {
        let mut out = vec![T::default(); v.len()];
        self.runs(|stored, row_major, n| out[stored..stored + n].copy_from_slice(&v[row_major..row_major + n]));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_pixel_has_one_place_and_a_tile_is_one_block() {
        for (w, h) in [(1, 1), (31, 33), (64, 64), (70, 45), (100, 37), (33, 97)] {
            let l = TileLayout { w, h };
            let mut seen = vec![false; l.len()];
            for y in 0..h {
                for x in 0..w {
                    let i = l.index(x, y);
                    assert!(!seen[i], "{w}x{h}: ({x}, {y}) shares {i}");
                    seen[i] = true;
                }
            }
            for t in Rect::tiles(w, h) {
                // Row-major within the tile, from its start.
                let start = l.tile_start(t.x0, t.y0);
                for (k, (x, y)) in (t.y0..t.y1).flat_map(|y| (t.x0..t.x1).map(move |x| (x, y))).enumerate() {
                    assert_eq!(l.index(x, y), start + k, "{w}x{h} tile {t:?}");
                }
            }
            // Scattered and gathered back, a buffer is itself; runs visit each pixel once.
            let v: Vec<u32> = (0..l.len() as u32).collect();
            let s = l.scatter(&v);
            assert_eq!(l.gather(|i| s[i]), v);
            let mut n = 0;
            l.runs(|stored, row_major, len| {
                assert_eq!(row_major, n, "runs in row-major order");
                assert_eq!(&s[stored..stored + len], &v[row_major..row_major + len]);
                n += len;
            });
            assert_eq!(n, l.len());
        }
    }
}
