//! Levels of detail: coarser stand-ins for a part's triangles, made by vertex clustering (as
//! the seed's tutorial suggests for triangle soups; Rossignac and Borrel 1993). Level 1
//! clusters the part's vertices into cubic cells of a few mean edge lengths and keeps each
//! triangle whose corners fall in three different cells, its corners moved to their cells'
//! mean vertex (duplicates made so kept once); cells that would not halve the triangles are
//! doubled first. What collapses would vanish (a pipe thinner
//! than a cell, a bolt smaller than one), so it is stood in for by a thin prism or a small
//! octahedron of about its width: a view of a plant from afar is mostly such things, and
//! their coverage of the pixels is the picture. Level `k + 1` clusters level `k` in cells
//! twice as large, until a level is small ([`LodOptions::min_tris`]) or stops shrinking.
//!
//! **Error.** A level's triangle is the image of some input triangle whose corners each moved
//! (within their cell) to a representative, so every point of it lies within the largest of
//! those three moves of that input triangle (an affine combination moves no more than its
//! corners); a prism's axis or an octahedron's centre likewise, and its surface within its
//! radius more. The build measures these per triangle: a level's reach is the largest, and
//! level `k`'s error the sum of the reaches of levels `1..=k`. Every point of a level-`k`
//! triangle lies within it of the part's own triangles, and it grows from level to level. The renderer uses a level only where this
//! error is below the footprint of a pixel (`render --lod-error`).

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

/// How levels are made.
#[derive(Clone, Copy, Debug)]
pub struct LodOptions {
    /// Level 1's cell size, in mean edge lengths of the part's triangles.
    pub first_cell: f32,
    /// Stop after a level of at most this many triangles (it is the coarsest).
    pub min_tris: usize,
    /// The finest level keeps at most this fraction of the part's triangles (so that the
    /// levels together stay a small part of the file); cells that would keep more are
    /// doubled until they do not (a dense mesh's finest level starts coarser than a thin one's).
    pub first_keep: f32,
    /// Each coarser level keeps at most this fraction of the level before it (cells doubled
    /// likewise).
    pub max_keep: f32,
    /// At most this many levels.
    pub max_levels: usize,
}

impl Default for LodOptions {
    fn default() -> Self {
        LodOptions { first_cell: 1.0, min_tris: 2048, first_keep: 0.125, max_keep: 0.5, max_levels: 12 }
    }
}

/// One level of detail of a part.
#[derive(Clone, Debug, Default)]
pub struct Level {
    /// Its triangles.
    pub tris: Vec<[[f32; 3]; 3]>,
    /// For each, the index of one of the part's own triangles it stands for (for attributes).
    pub source: Vec<u32>,
    /// Every point of `tris` lies within this distance of the part's triangles.
    pub error: f32,
}

/// The levels of detail of a part's triangles `tris`, finest first; none when the part is
/// small already.
pub fn levels(tris: &[[[f32; 3]; 3]], opts: &LodOptions) -> Vec<Level> {
    let mut out: Vec<Level> = Vec::new();
    if tris.len() <= opts.min_tris {
        return out;
    }
    let mut cell = opts.first_cell * mean_edge(tris);
    if !(cell.is_finite() && cell > 0.0) {
        return out;
    }
    // The finest level's cell, first tried on a sample: the triangles of the middle eighth
    // of the part's box (a trial on the whole part costs as much as the level).
    let sample = middle(tris);
    while sample.len() >= 4 * opts.min_tris.max(256) {
        match cluster(&sample, cell) {
            Some((lt, _, _)) if lt.len() as f32 > opts.first_keep * sample.len() as f32 => cell *= 2.0,
            _ => break,
        }
    }
    drop(sample);
    let mut error = 0.0f32;
    let mut tries = 0;
    while out.len() < opts.max_levels {
        let (src_tris, src_ids): (&[[[f32; 3]; 3]], Option<&[u32]>) = match out.last() {
            None => (tris, None),
            Some(l) => (&l.tris, Some(&l.source)),
        };
        let Some((lt, ls, reach)) = cluster(src_tris, cell) else { break };
        // Within `reach` of the level before, which was within `error` of the part.
        error += reach;
        // The source triangle of the part, through the level before.
        let source: Vec<u32> = ls.iter().map(|&i| src_ids.map_or(i, |s| s[i as usize])).collect();
        if lt.is_empty() {
            break;
        }
        let keep = if out.is_empty() { opts.first_keep } else { opts.max_keep };
        if (lt.len() as f32) > keep * src_tris.len() as f32 {
            // Not worth a level (cells too small for this mesh): try cells twice as large.
            error -= reach;
            cell *= 2.0;
            tries += 1;
            if tries > opts.max_levels {
                break;
            }
            continue;
        }
        let small = lt.len() <= opts.min_tris;
        out.push(Level { tris: lt, source, error });
        if small {
            break;
        }
        cell *= 2.0;
    }
    out
}

/// The triangles of `tris` whose first corner lies in the middle eighth of their box (half
/// its extent on each axis, about its centre).
fn middle(tris: &[Tri]) -> Vec<Tri> {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for t in tris {
        for a in 0..3 {
            lo[a] = lo[a].min(t[0][a]);
            hi[a] = hi[a].max(t[0][a]);
        }
    }
    let inside = |p: &[f32; 3]| (0..3).all(|a| (p[a] - 0.5 * (lo[a] + hi[a])).abs() <= 0.25 * (hi[a] - lo[a]));
    tris.iter().filter(|t| inside(&t[0])).copied().collect()
}

/// The mean edge length of `tris` (of at most 64K of them, evenly spread).
fn mean_edge(tris: &[[[f32; 3]; 3]]) -> f32 {
    let step = (tris.len() / 65_536).max(1);
    let (mut sum, mut n) = (0.0f64, 0u64);
    for t in tris.iter().step_by(step) {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            sum += d as f64;
            n += 1;
        }
    }
    (sum / n.max(1) as f64) as f32
}

/// A triangle's corners.
type Tri = [[f32; 3]; 3];

/// A cell of the clustering grid: its integer coordinates, packed.
type Cell = u64;

/// The cell of `p`, counted from `lo` in cells of size `1 / inv`, 21 bits an axis.
fn cell_of(p: [f32; 3], lo: [f32; 3], inv: f32) -> Cell {
    // `as` truncates toward zero and takes negatives and NaN to 0: the floor of what is not
    // below 0, with no call to libm's `floorf` (the baseline build has no rounding instruction).
    let q = |a: usize| (((p[a] - lo[a]) * inv) as u64).min((1 << 21) - 1);
    q(0) | (q(1) << 21) | (q(2) << 42)
}

/// What a cell gathers of the vertices that fall in it: their count, and the sum and sum of
/// outer products of their offsets from the cell's corner (small numbers: `f32` sums lose
/// nothing that matters), for their mean (the cell's representative) and spread.
#[derive(Clone, Copy, Default)]
struct Moments {
    n: u32,
    s: [f32; 3],
    /// xx, xy, xz, yy, yz, zz.
    ss: [f32; 6],
}

const _: () = assert!(std::mem::size_of::<Moments>() == 40);

impl Moments {
    /// Adds a vertex at offset `p` from the cell's corner.
    fn add(&mut self, p: [f32; 3]) {
        self.n += 1;
        for (s, x) in self.s.iter_mut().zip(p) {
            *s += x;
        }
        let o = [p[0] * p[0], p[0] * p[1], p[0] * p[2], p[1] * p[1], p[1] * p[2], p[2] * p[2]];
        for (a, b) in self.ss.iter_mut().zip(o) {
            *a += b;
        }
    }

    /// The mean offset from the cell's corner.
    fn mean_offset(&self) -> [f64; 3] {
        self.s.map(|x| x as f64 / self.n as f64)
    }

    /// The spread of the vertices about their mean across direction `d` (unit): the sum of
    /// their variances in the two directions perpendicular to it (`R^2` for a ring of radius
    /// `R` about an axis along `d`); with `d` zero, the total variance.
    fn spread_across(&self, d: [f64; 3]) -> f64 {
        let m = self.mean_offset();
        let n = self.n as f64;
        let c = |i: usize, a: usize, b: usize| self.ss[i] as f64 / n - m[a] * m[b];
        let (xx, xy, xz, yy, yz, zz) = (c(0, 0, 0), c(1, 0, 1), c(2, 0, 2), c(3, 1, 1), c(4, 1, 2), c(5, 2, 2));
        let along = d[0] * d[0] * xx
            + d[1] * d[1] * yy
            + d[2] * d[2] * zz
            + 2.0 * (d[0] * d[1] * xy + d[0] * d[2] * xz + d[1] * d[2] * yz);
        (xx + yy + zz - along).max(0.0)
    }
}

/// Vertex clustering of `tris` in cells of size `cell`: the triangles kept (corners moved to
/// their cells' mean vertex, duplicates and those of zero area dropped), then stand-ins for
/// what collapsed, so that thin and small things keep about their size on screen: a thin
/// triangular prism along each pair of cells joined only by collapsed triangles (a pipe
/// thinner than a cell), its width the spread of the cells' vertices across it, and an
/// octahedron in each cell that nothing else holds (a part smaller than a cell). Their radii
/// are at most the cell size. For each output triangle, the index of an input triangle it
/// stands for; and how far the output reaches from the input: every point of an output
/// triangle lies within it of its input triangle (measured, at most a cell diagonal plus a
/// radius). `None` when the grid would need more than 2^21 cells along an axis.
fn cluster(tris: &[Tri], cell: f32) -> Option<(Vec<Tri>, Vec<u32>, f32)> {
    let inv = 1.0 / cell;
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in tris.iter().flatten() {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let fits = |a: usize| (hi[a] - lo[a]) * inv < (1 << 21) as f32;
    if !(fits(0) && fits(1) && fits(2)) {
        return None;
    }
    let mut cells: HashMap<Cell, Moments, Fx> = HashMap::default();
    let mut keys: Vec<[Cell; 3]> = Vec::with_capacity(tris.len());
    // The corner of cell `c`.
    let corner =
        |c: Cell| -> [f64; 3] { [0, 21, 42].map(|sh| ((c >> sh) & ((1 << 21) - 1)) as f64).map(|q| q * cell as f64) };
    let corner = |c: Cell| -> [f64; 3] {
        let q = corner(c);
        [lo[0] as f64 + q[0], lo[1] as f64 + q[1], lo[2] as f64 + q[2]]
    };
    for t in tris {
        let k = t.map(|p| cell_of(p, lo, inv));
        for (p, c) in t.iter().zip(k) {
            let o = corner(c);
            cells.entry(c).or_default().add([0, 1, 2].map(|a| (p[a] as f64 - o[a]) as f32));
        }
        keys.push(k);
    }
    // A cell's mean vertex.
    let mean = |c: Cell| -> [f64; 3] {
        let (o, m) = (corner(c), cells[&c].mean_offset());
        [o[0] + m[0], o[1] + m[1], o[2] + m[2]]
    };
    let rep = |c: Cell| -> [f32; 3] { mean(c).map(|x| x as f32) };
    // The largest distance from a point of an output triangle to the input triangle it
    // stands for (measured per triangle, below).
    let mut reach = 0.0f32;
    // A corner of input triangle `i` that lies in cell `c`.
    let corner_in = |i: u32, c: Cell| -> [f32; 3] {
        let j = (0..3).find(|&j| keys[i as usize][j] == c).expect("the triangle has a corner in the cell");
        tris[i as usize][j]
    };
    let mut seen: HashSet<[Cell; 3], Fx> = HashSet::default();
    // Cells and cell pairs the kept triangles hold.
    let mut held: HashSet<Cell, Fx> = HashSet::default();
    let mut edges: HashSet<(Cell, Cell), Fx> = HashSet::default();
    let edge = |a: Cell, b: Cell| (a.min(b), a.max(b));
    let (mut out, mut source) = (Vec::new(), Vec::new());
    for (i, k) in keys.iter().enumerate() {
        if k[0] == k[1] || k[1] == k[2] || k[0] == k[2] {
            continue;
        }
        // One rotation per cyclic order (the winding is kept: a triangle and its reverse
        // both stay).
        let r = (0..3).min_by_key(|&j| k[j]).expect("three corners");
        if !seen.insert([k[r], k[(r + 1) % 3], k[(r + 2) % 3]]) {
            continue;
        }
        let t = [rep(k[0]), rep(k[1]), rep(k[2])];
        if area2(&t) > 0.0 {
            // Its points lie within the largest move of a corner of the triangle it came from.
            reach = (0..3).map(|j| dist3(t[j], tris[i][j])).fold(reach, f32::max);
            out.push(t);
            source.push(i as u32);
            held.extend(k.iter().copied());
            edges.extend([edge(k[0], k[1]), edge(k[1], k[2]), edge(k[0], k[2])]);
        }
    }
    // What collapsed: pairs of cells (thin things) and single cells (small things) that no
    // kept triangle holds.
    let mut thin: HashMap<(Cell, Cell), u32, Fx> = HashMap::default();
    let mut small: HashMap<Cell, u32, Fx> = HashMap::default();
    for (i, k) in keys.iter().enumerate() {
        let distinct = [k[0], k[1], k[2]];
        let (a, b, c) = (distinct[0], distinct[1], distinct[2]);
        if a != b && b != c && a != c {
            continue;
        }
        if a == b && b == c {
            if !held.contains(&a) {
                small.entry(a).or_insert(i as u32);
            }
            continue;
        }
        let (x, y) = if a == b { (a, c) } else { (a, b) };
        let e = edge(x, y);
        if !edges.contains(&e) {
            thin.entry(e).or_insert(i as u32);
        }
    }
    let mut thin: Vec<_> = thin.into_iter().collect();
    thin.sort_unstable();
    for ((a, b), src) in thin {
        held.insert(a);
        held.insert(b);
        let (pa, pb) = (mean(a), mean(b));
        let d = [pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if len == 0.0 {
            continue;
        }
        let d = d.map(|x| x / len);
        let r2 = 0.5 * (cells[&a].spread_across(d) + cells[&b].spread_across(d));
        // A triangle's width across its axis averages about 1.6 times its circumradius, a
        // pipe's is twice its radius: 1.25 R keeps the width.
        let rho = ((1.25 * r2.sqrt()) as f32).min(cell);
        if rho <= 0.0 {
            continue;
        }
        // The axis joins the two cells' representatives; the input triangle has an edge
        // between a corner in each: the axis lies within the larger move of those corners
        // of that edge, the prism's sides within `rho` more.
        let ends = [(pa, corner_in(src, a)), (pb, corner_in(src, b))];
        reach = ends.iter().map(|(r, p)| dist3(r.map(|x| x as f32), *p) + rho).fold(reach, f32::max);
        for t in prism(pa, pb, d, rho) {
            if area2(&t) > 0.0 {
                out.push(t);
                source.push(src);
            }
        }
    }
    let mut small: Vec<_> = small.into_iter().filter(|(c, _)| !held.contains(c)).collect();
    small.sort_unstable();
    for (c, src) in small {
        let rho = (cells[&c].spread_across([0.0; 3]).sqrt() as f32).min(0.5 * cell);
        if rho <= 0.0 {
            continue;
        }
        // The input triangle lies in the cell: the octahedron within the move of its
        // centre from a corner of it, plus `rho`.
        reach = reach.max(dist3(rep(c), corner_in(src, c)) + rho);
        for t in octahedron(mean(c), rho) {
            out.push(t);
            source.push(src);
        }
    }
    Some((out, source, reach))
}

fn dist3(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// A triangular prism of circumradius `rho` from `a` to `b` along unit `d` (its six sides).
fn prism(a: [f64; 3], b: [f64; 3], d: [f64; 3], rho: f32) -> [[[f32; 3]; 3]; 6] {
    // Any unit vector across `d`, and the third axis.
    let h = if d[0].abs() < 0.6 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let cross =
        |x: [f64; 3], y: [f64; 3]| [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]];
    let u = cross(d, h);
    let n = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    let u = u.map(|x| x / n);
    let v = cross(d, u);
    let ring = |p: [f64; 3], k: usize| -> [f32; 3] {
        let th = k as f64 * std::f64::consts::TAU / 3.0;
        let (s, c) = th.sin_cos();
        [0, 1, 2].map(|i| (p[i] + rho as f64 * (c * u[i] + s * v[i])) as f32)
    };
    let mut out = [[[0.0; 3]; 3]; 6];
    for k in 0..3 {
        let (a0, a1, b0, b1) = (ring(a, k), ring(a, (k + 1) % 3), ring(b, k), ring(b, (k + 1) % 3));
        out[2 * k] = [a0, b0, b1];
        out[2 * k + 1] = [a0, b1, a1];
    }
    out
}

/// An octahedron of radius `rho` about `c` (its eight faces, outward).
fn octahedron(c: [f64; 3], rho: f32) -> [[[f32; 3]; 3]; 8] {
    let p = |a: usize, s: f64| {
        let mut q = c;
        q[a] += s * rho as f64;
        q.map(|x| x as f32)
    };
    let mut out = [[[0.0; 3]; 3]; 8];
    let mut i = 0;
    for sx in [1.0, -1.0] {
        for sy in [1.0, -1.0] {
            for sz in [1.0, -1.0] {
                let (x, y, z) = (p(0, sx), p(1, sy), p(2, sz));
                // Outward winding: (x, y, z) is counter-clockwise seen from outside when the
                // octant has an even number of negative signs.
                out[i] = if sx * sy * sz > 0.0 { [x, y, z] } else { [x, z, y] };
                i += 1;
            }
        }
    }
    out
}

/// Twice the area of `t`, squared.
fn area2(t: &[[f32; 3]; 3]) -> f32 {
    let e1 = [t[1][0] - t[0][0], t[1][1] - t[0][1], t[1][2] - t[0][2]];
    let e2 = [t[2][0] - t[0][0], t[2][1] - t[0][1], t[2][2] - t[0][2]];
    let c = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
}

/// A fast hasher for cell keys (the multiply-rotate of rustc's FxHash, finished by a
/// MurmurHash3 mix): the clustering's maps take several lookups per triangle, and the
/// standard SipHash would be most of its time.
#[derive(Default)]
struct FxHasher(u64);

type Fx = BuildHasherDefault<FxHasher>;

impl Hasher for FxHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    fn finish(&self) -> u64 {
        // The product's low bits depend only on the key's low bits (one axis of a packed
        // cell): fold the high bits down (MurmurHash3's finaliser), or one axis would choose
        // the bucket and the others collide.
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^ (h >> 33)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of `n` x `n` squares (two triangles each) on a wavy height field.
    fn terrain(n: usize) -> Vec<[[f32; 3]; 3]> {
        let h = |x: usize, y: usize| ((x as f32 * 0.3).sin() + (y as f32 * 0.2).cos()) * 2.0;
        let p = |x: usize, y: usize| [x as f32, h(x, y), y as f32];
        let mut t = Vec::new();
        for y in 0..n {
            for x in 0..n {
                t.push([p(x, y), p(x, y + 1), p(x + 1, y)]);
                t.push([p(x + 1, y), p(x, y + 1), p(x + 1, y + 1)]);
            }
        }
        t
    }

    /// Thin pipes (cylinders of 12 sides along x, radius 0.05, unit segments) and small
    /// octahedra: what clustering collapses.
    fn pipes_and_bolts() -> Vec<[[f32; 3]; 3]> {
        let mut t = Vec::new();
        for j in 0..6 {
            let (y0, z0) = (j as f32 * 0.7, (j % 3) as f32 * 0.9);
            let ring = |x: f32, k: usize| {
                let a = k as f32 * std::f32::consts::TAU / 12.0;
                [x, y0 + 0.05 * a.cos(), z0 + 0.05 * a.sin()]
            };
            for s in 0..60 {
                let (x0, x1) = (s as f32 * 0.25, s as f32 * 0.25 + 0.25);
                for k in 0..12 {
                    t.push([ring(x0, k), ring(x1, k), ring(x1, (k + 1) % 12)]);
                    t.push([ring(x0, k), ring(x1, (k + 1) % 12), ring(x0, (k + 1) % 12)]);
                }
            }
            for b in 0..10 {
                let c = [b as f32 * 1.5 + 0.3, y0 + 0.35, z0];
                let r = 0.04;
                let p = |a: usize, s: f32| {
                    let mut q = c;
                    q[a] += s * r;
                    q
                };
                for sx in [1.0, -1.0] {
                    for sy in [1.0, -1.0] {
                        for sz in [1.0, -1.0] {
                            t.push([p(0, sx), p(1, sy), p(2, sz)]);
                        }
                    }
                }
            }
        }
        t
    }

    /// Levels shrink, their errors grow, and every sampled point of every level's triangles
    /// lies within the level's error of the part's own triangles (checked by brute force
    /// against all of them).
    #[test]
    fn levels_shrink_and_their_error_bounds_the_distance_to_the_part() {
        for tris in [terrain(60), pipes_and_bolts()] {
            check_levels(&tris);
        }
    }

    fn check_levels(tris: &[[[f32; 3]; 3]]) {
        let lv = levels(tris, &LodOptions { min_tris: 50, ..LodOptions::default() });
        assert!(lv.len() >= 3, "{} levels", lv.len());
        let mut before = (tris.len(), 0.0);
        for (k, l) in lv.iter().enumerate() {
            assert!(
                l.tris.len() < before.0 && l.error > before.1,
                "level {k}: {} tris, error {}",
                l.tris.len(),
                l.error
            );
            assert_eq!(l.tris.len(), l.source.len());
            assert!(l.source.iter().all(|&s| (s as usize) < tris.len()));
            before = (l.tris.len(), l.error);
            let mut worst = 0.0f32;
            for t in &l.tris {
                for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.33, 0.33), (0.5, 0.25)] {
                    let p = [0, 1, 2].map(|a| t[0][a] + u * (t[1][a] - t[0][a]) + v * (t[2][a] - t[0][a]));
                    let d = tris
                        .iter()
                        .map(|s| megaray_testkit::point_triangle_distance(p, *s))
                        .fold(f32::INFINITY, f32::min);
                    worst = worst.max(d);
                }
            }
            assert!(worst <= l.error, "level {k}: a point {worst} away, error {}", l.error);
        }
    }

    /// Pipes thinner than a cell do not vanish: every level finer than the pipes' spacing
    /// stands in for each with a prism along it (or keeps it), so a ray across a pipe still
    /// hits it, and one well beside it does not.
    #[test]
    fn thin_pipes_keep_their_coverage() {
        let tris = pipes_and_bolts();
        let lv = levels(&tris, &LodOptions { min_tris: 50, ..LodOptions::default() });
        assert!(lv.last().unwrap().tris.len() * 10 < tris.len(), "{} levels", lv.len());
        // Levels whose error is below the pipes' spacing (0.7): coarser ones may merge them.
        let fine: Vec<&Level> = lv.iter().filter(|l| l.error < 0.7).collect();
        assert!(!fine.is_empty(), "no level finer than the pipes' spacing");
        for (k, l) in fine.into_iter().enumerate() {
            // Rays straight down (-z) onto pipe 0 (y = 0, z = 0), every 0.5 along it, and
            // beside it (y = 0.2, four radii away).
            let hit = |org: [f32; 3]| {
                let ray = megaray_base::Ray::new(org.into(), glam::Vec3::new(0.0, 0.0, -1.0));
                l.tris.iter().any(|t| megaray_base::intersect_triangle(&ray, t.map(glam::Vec3::from), 10.0).is_some())
            };
            let hits = (1..28).filter(|&s| hit([s as f32 * 0.5 + 0.1, 0.0, 0.5])).count();
            assert!(hits >= 25, "level {}: only {hits} of 27 rays across a pipe hit it", k + 1);
            if l.error < 0.15 {
                let beside = (1..28).filter(|&s| hit([s as f32 * 0.5 + 0.1, 0.2, 0.5])).count();
                assert_eq!(beside, 0, "level {}: {beside} rays beside the pipe hit it", k + 1);
            }
        }
    }
}
