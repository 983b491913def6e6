//! The in-core builder: an 8-wide BVH over primitive boxes by binned SAH, each wide node made
//! from binary splits of its largest child ([`Ctx`]), in a build layout ([`Bvh`]). The same builder makes each part's tree (over
//! triangles) and the top-level tree (over parts). Layout for the file is [`crate::tiles`]'s job.

use glam::{Vec3, Vec4};
use megaray_base::Aabb;
use megaray_scene::format::NODE_WIDTH;

/// Cost of one node traversal relative to one test of a block of four primitives.
const C_TRAV: f32 = 1.0;
/// Primitives are tested four at a time (one SIMD block), so the SAH counts blocks.
const BLOCK: u32 = 4;

#[inline(always)]
fn blocks(n: u32) -> f32 {
    n.div_ceil(BLOCK) as f32
}

/// Builder settings.
#[derive(Clone, Copy, Debug)]
pub struct BvhConfig {
    /// Leaves hold at most this many primitives (unless the SAH cannot separate them).
    pub max_leaf: usize,
    /// Build subtrees of more primitives than this in parallel (rayon); `usize::MAX`: never.
    pub parallel_above: usize,
}

/// A child slot of a build-layout 8-wide node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kid {
    Empty,
    Inner(u32),
    /// Primitives `order[start..start + count]`.
    Leaf {
        start: u32,
        count: u32,
    },
}

/// A build-layout 8-wide node.
#[derive(Clone, Copy, Debug)]
pub struct NodeB {
    pub bounds: [Aabb; NODE_WIDTH],
    pub kids: [Kid; NODE_WIDTH],
}

/// An 8-wide BVH in build layout: nodes in pre-order (children after their parent; node 0
/// is the root) and the primitive order its leaves index.
pub struct Bvh {
    pub nodes: Vec<NodeB>,
    pub order: Vec<u32>,
    pub bounds: Aabb,
    pub depth: u32,
}

/// A primitive reference while building: its box, with its number in the `w` lane of `hi`.
/// 32 bytes, so that the builder's passes stream through memory instead of chasing indices;
/// `glam::Vec4` keeps each corner in one SIMD register.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct PrimRef {
    lo: Vec4,
    hi: Vec4,
}
const _: () = assert!(std::mem::size_of::<PrimRef>() == 32);

impl PrimRef {
    #[inline(always)]
    fn id(&self) -> u32 {
        self.hi.w.to_bits()
    }
}

/// Bounds and doubled-centroid bounds of a range of primitives (`w` lanes are ignored).
#[derive(Clone, Copy)]
struct Extent {
    lo: Vec4,
    hi: Vec4,
    clo: Vec4,
    chi: Vec4,
}

impl Extent {
    const EMPTY: Extent =
        Extent { lo: Vec4::INFINITY, hi: Vec4::NEG_INFINITY, clo: Vec4::INFINITY, chi: Vec4::NEG_INFINITY };
    #[inline(always)]
    fn add(&mut self, r: &PrimRef) {
        self.lo = self.lo.min(r.lo);
        self.hi = self.hi.max(r.hi);
        let c = r.lo + r.hi;
        self.clo = self.clo.min(c);
        self.chi = self.chi.max(c);
    }
    fn bounds(&self) -> Aabb {
        Aabb { min: self.lo.truncate().into(), max: self.hi.truncate().into() }
    }
    fn merge(self, o: Extent) -> Extent {
        Extent { lo: self.lo.min(o.lo), hi: self.hi.max(o.hi), clo: self.clo.min(o.clo), chi: self.chi.max(o.chi) }
    }
    fn of(refs: &[PrimRef]) -> Extent {
        let mut e = Extent::EMPTY;
        refs.iter().for_each(|r| e.add(r));
        e
    }
}

#[inline(always)]
fn half_area(lo: Vec4, hi: Vec4) -> f32 {
    let e = (hi - lo).max(Vec4::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// Builds an 8-wide BVH over primitives with the given boxes (centroids are box centres).
pub fn build_bvh(boxes: &[Aabb], cfg: BvhConfig) -> Bvh {
    build_bvh_of(boxes.len(), |i| boxes[i], cfg)
}

/// [`build_bvh`] over `n` primitives whose boxes `box_of` gives (made as the builder's
/// references are, so that no array of boxes is needed in between).
pub fn build_bvh_of(n: usize, box_of: impl Fn(usize) -> Aabb + Sync, cfg: BvhConfig) -> Bvh {
    assert!(n > 0, "build_bvh needs at least one primitive");
    use rayon::prelude::*;
    let parallel = n > cfg.parallel_above;
    let make = |i: usize| {
        let b = box_of(i);
        PrimRef { lo: Vec3::from(b.min).extend(0.0), hi: Vec3::from(b.max).extend(f32::from_bits(i as u32)) }
    };
    let (mut refs, ext): (Vec<PrimRef>, Extent) = if parallel {
        let refs: Vec<PrimRef> = (0..n).into_par_iter().with_min_len(1 << 14).map(make).collect();
        let ext = refs.par_chunks(1 << 15).map(Extent::of).reduce(|| Extent::EMPTY, Extent::merge);
        (refs, ext)
    } else {
        let refs: Vec<PrimRef> = (0..n).map(make).collect();
        let ext = Extent::of(&refs);
        (refs, ext)
    };
    let ctx = Ctx { cfg };
    let root = ctx.cand(&refs, ext, 0);
    let bounds = ext.bounds();
    let mut nodes = Vec::new();
    let depth = if root.split.is_none() {
        // A tree that is a single leaf: a root node with one leaf child.
        let mut n = NodeB { bounds: [Aabb::EMPTY; NODE_WIDTH], kids: [Kid::Empty; NODE_WIDTH] };
        n.bounds[0] = bounds;
        n.kids[0] = Kid::Leaf { start: 0, count: root.end };
        nodes.push(n);
        1
    } else {
        ctx.node8(root, &mut refs, &mut nodes)
    };
    let order: Vec<u32> =
        if parallel { refs.par_iter().map(|r| r.id()).collect() } else { refs.iter().map(|r| r.id()).collect() };
    Bvh { nodes, order, bounds, depth }
}

/// How an inner candidate's references split (decided when the candidate is made).
#[derive(Clone, Copy, Debug)]
enum Split {
    /// By bin `bin_on(axis) < first` among `nb` bins over its centroids' extent.
    Bins { axis: usize, first: usize, nb: usize },
    /// In two halves as they lie (all centroids coincide).
    Halves,
}

/// A range of references (`start..end` of the order) and what the SAH made of it: a leaf
/// (`split` none) or a node to split, maybe already split (`halves`, ahead of the greedy
/// order, when several large ones are split in parallel).
struct Cand {
    start: u32,
    end: u32,
    ext: Extent,
    split: Option<Split>,
    halves: Option<Box<[Cand; 2]>>,
}

impl Cand {
    fn len(&self) -> usize {
        (self.end - self.start) as usize
    }
}

struct Ctx {
    cfg: BvhConfig,
}

/// The builder: top-down binned SAH, binary splits, each 8-wide node made as they are made
/// (as Embree builds its wide trees): starting from a node's range, the child of largest
/// surface area is split until there are eight, then each inner child becomes a node the same
/// way. The tree is the one that a binary tree collapsed greedily by area would give, without
/// the binary tree (a node per allocation, a collapse pass chasing them, their freeing).
impl Ctx {
    /// What the SAH makes of `refs` (positions `start..` of the order, extent `ext`).
    fn cand(&self, refs: &[PrimRef], ext: Extent, start: u32) -> Cand {
        let n = refs.len();
        let leaf = Cand { start, end: start + n as u32, ext, split: None, halves: None };
        // One block's worth is always a leaf: splitting it costs a traversal step (C_TRAV)
        // plus at least one block test, against the leaf's one block test.
        if n <= 1 || (n <= self.cfg.max_leaf && n as u32 <= BLOCK) {
            return leaf;
        }
        // Binned SAH over all three axes in one pass; fewer bins for small nodes, where the
        // per-node cost of clearing and sweeping bins would dominate.
        let (best, nb) = if n >= 1024 {
            (find_split::<32, 2, false>(refs, &ext, n > self.cfg.parallel_above), 32)
        } else if n >= 128 {
            (find_split::<16, 1, true>(refs, &ext, false), 16)
        } else {
            (find_split::<8, 1, true>(refs, &ext, false), 8)
        };
        let parent_area = ext.bounds().half_area().max(f32::MIN_POSITIVE);
        let split_cost = C_TRAV + best.0 / parent_area;
        let leaf_cost = blocks(n as u32);
        if n <= self.cfg.max_leaf && (leaf_cost <= split_cost || !best.0.is_finite()) {
            return leaf;
        }
        let split = if best.0.is_finite() { Split::Bins { axis: best.1, first: best.2, nb } } else { Split::Halves };
        Cand { split: Some(split), ..leaf }
    }

    /// Splits inner candidate `c` (whose references are `refs`): its two halves, each decided.
    fn open(&self, c: &Cand, refs: &mut [PrimRef]) -> [Cand; 2] {
        let n = refs.len();
        let (mid, le, re) = match c.split.expect("only inner candidates are split") {
            Split::Bins { axis, first, nb } => {
                let (cmin, scale) = (c.ext.clo, bin_scale(&c.ext, nb));
                // One body per axis, so that the lane it reads is a constant.
                match axis {
                    0 => partition(refs, |r| bin_on::<0>(r, cmin, scale, nb) < first),
                    1 => partition(refs, |r| bin_on::<1>(r, cmin, scale, nb) < first),
                    _ => partition(refs, |r| bin_on::<2>(r, cmin, scale, nb) < first),
                }
            }
            Split::Halves => {
                let mid = n / 2;
                (mid, Extent::of(&refs[..mid]), Extent::of(&refs[mid..]))
            }
        };
        let (l, r) = refs.split_at_mut(mid);
        let m = c.start + mid as u32;
        let (a, b) = if n > self.cfg.parallel_above {
            rayon::join(|| self.cand(l, le, c.start), || self.cand(r, re, m))
        } else {
            (self.cand(l, le, c.start), self.cand(r, re, m))
        };
        [a, b]
    }

    /// Makes the 8-wide node of inner candidate `c` (whose references are `refs`) and its
    /// subtree into `out`, the node first (pre-order, children in slot order); returns the
    /// subtree's depth.
    fn node8(&self, c: Cand, refs: &mut [PrimRef], out: &mut Vec<NodeB>) -> u32 {
        let base = c.start;
        let first = match c.halves {
            Some(h) => *h,
            None => self.open(&c, refs),
        };
        let mut slots: Vec<Cand> = Vec::with_capacity(NODE_WIDTH);
        slots.extend(first);
        while slots.len() < NODE_WIDTH {
            self.open_ahead(&mut slots, refs);
            // Split the inner child with the largest surface area (the last of equal ones).
            let mut pick = None;
            let mut best = -1.0;
            for (k, s) in slots.iter().enumerate() {
                if s.split.is_some() {
                    let a = s.ext.bounds().half_area();
                    if pick.is_none() || a >= best {
                        (pick, best) = (Some(k), a);
                    }
                }
            }
            let Some(i) = pick else { break };
            let s = slots.remove(i);
            let halves = match s.halves {
                Some(h) => *h,
                None => self.open(&s, &mut refs[(s.start - base) as usize..(s.end - base) as usize]),
            };
            slots.splice(i..i, halves);
        }
        let me = out.len();
        out.push(NodeB { bounds: [Aabb::EMPTY; NODE_WIDTH], kids: [Kid::Empty; NODE_WIDTH] });
        let subs = slot_refs(&slots, refs);
        let mut depth = 0;
        // Children of many references are made in parallel, each into its own vector,
        // appended in slot order with its indices shifted: the serial layout. (Not smaller
        // ones: the copies would cost more than they save.)
        let big = |s: &Cand| s.split.is_some() && s.len() > self.cfg.parallel_above.saturating_mul(16);
        if slots.iter().any(big) {
            use rayon::prelude::*;
            let kept: Vec<(Aabb, u32, u32, bool)> =
                slots.iter().map(|s| (s.ext.bounds(), s.start, s.end, s.split.is_some())).collect();
            let made: Vec<(Vec<NodeB>, u32)> = slots
                .into_par_iter()
                .zip(subs)
                .map(|(s, r)| {
                    let mut v = Vec::new();
                    let d = if s.split.is_some() { self.node8(s, r, &mut v) } else { 0 };
                    (v, d)
                })
                .collect();
            for (k, ((bounds, start, end, inner), (sub, d))) in kept.into_iter().zip(made).enumerate() {
                out[me].bounds[k] = bounds;
                out[me].kids[k] = if !inner {
                    Kid::Leaf { start, count: end - start }
                } else {
                    let base = out.len() as u32;
                    out.extend(sub.into_iter().map(|mut n| {
                        for kid in &mut n.kids {
                            if let Kid::Inner(c) = kid {
                                *c += base;
                            }
                        }
                        n
                    }));
                    depth = depth.max(d);
                    Kid::Inner(base)
                };
            }
            return depth + 1;
        }
        for (k, (s, r)) in slots.into_iter().zip(subs).enumerate() {
            out[me].bounds[k] = s.ext.bounds();
            out[me].kids[k] = if s.split.is_none() {
                Kid::Leaf { start: s.start, count: s.end - s.start }
            } else {
                let child = out.len() as u32;
                depth = depth.max(self.node8(s, r, out));
                Kid::Inner(child)
            };
        }
        depth + 1
    }

    /// Splits now, in parallel, the inner children of many references not split yet, when
    /// there are two or more (what splitting them later would give, since their ranges are
    /// disjoint): the splits near the root then use all threads, as a binary build's would.
    fn open_ahead(&self, slots: &mut [Cand], refs: &mut [PrimRef]) {
        let ahead = |s: &Cand| s.split.is_some() && s.halves.is_none() && s.len() > self.cfg.parallel_above;
        if slots.iter().filter(|s| ahead(s)).count() < 2 {
            return;
        }
        use rayon::prelude::*;
        let subs = slot_refs(slots, refs);
        let work: Vec<(&mut Cand, &mut [PrimRef])> = slots.iter_mut().zip(subs).filter(|(s, _)| ahead(s)).collect();
        work.into_par_iter().for_each(|(s, r)| {
            let h = self.open(s, r);
            s.halves = Some(Box::new(h));
        });
    }
}

/// The references of each of `slots` (consecutive ranges that `refs` covers, in order).
fn slot_refs<'r>(slots: &[Cand], refs: &'r mut [PrimRef]) -> Vec<&'r mut [PrimRef]> {
    let mut rest = refs;
    slots
        .iter()
        .map(|s| {
            let (a, b) = std::mem::take(&mut rest).split_at_mut(s.len());
            rest = b;
            a
        })
        .collect()
}

/// The bin of `r` on each axis: its doubled centroid mapped through `scale`, clamped to
/// `0..nb` and rounded to the nearest integer by the 2^23 trick (no float-to-int conversion,
/// whose saturation checks dominated the builder's profile).
#[inline(always)]
fn bins_of(r: &PrimRef, cmin: Vec4, scale: Vec4, nb: usize) -> [usize; 3] {
    const MAGIC: f32 = 8_388_608.0; // 2^23: adding it leaves the integer in the low mantissa bits
    let f = ((r.lo + r.hi - cmin) * scale).clamp(Vec4::ZERO, Vec4::splat(nb as f32 - 1.0)) + Vec4::splat(MAGIC);
    [(f.x.to_bits() & 0xff) as usize, (f.y.to_bits() & 0xff) as usize, (f.z.to_bits() & 0xff) as usize]
}

/// [`bins_of`] on axis `A` alone (the same operations, so the same bin).
#[inline(always)]
fn bin_on<const A: usize>(r: &PrimRef, cmin: Vec4, scale: Vec4, nb: usize) -> usize {
    const MAGIC: f32 = 8_388_608.0;
    let f = ((r.lo + r.hi - cmin) * scale).clamp(Vec4::ZERO, Vec4::splat(nb as f32 - 1.0)) + Vec4::splat(MAGIC);
    (f.to_array()[A].to_bits() & 0xff) as usize
}

/// Per-axis factors that map a doubled centroid to its bin (0 on flat axes).
fn bin_scale(ext: &Extent, nb: usize) -> Vec4 {
    let cext = ext.chi - ext.clo;
    Vec4::select(cext.cmpgt(Vec4::ZERO), Vec4::splat(nb as f32) / cext, Vec4::ZERO)
}

/// Per-axis bins: primitive counts and bounds.
struct Bins<const NB: usize> {
    cnt: [[u32; NB]; 3],
    lo: [[Vec4; NB]; 3],
    hi: [[Vec4; NB]; 3],
}

impl<const NB: usize> Bins<NB> {
    fn empty() -> Self {
        Bins { cnt: [[0; NB]; 3], lo: [[Vec4::INFINITY; NB]; 3], hi: [[Vec4::NEG_INFINITY; NB]; 3] }
    }

    fn merge(mut self, o: &Self) -> Self {
        for k in 0..3 {
            for i in 0..NB {
                self.cnt[k][i] += o.cnt[k][i];
                self.lo[k][i] = self.lo[k][i].min(o.lo[k][i]);
                self.hi[k][i] = self.hi[k][i].max(o.hi[k][i]);
            }
        }
        self
    }

    /// Bins `refs`, alternating between `SETS` bin sets (2 for large nodes, so that neighbours
    /// falling into the same bin do not wait on each other's stores).
    /// With `only` < 3, only that axis's bins are filled (the others stay empty).
    fn gather<const SETS: usize>(refs: &[PrimRef], cmin: Vec4, scale: Vec4, only: usize) -> Self {
        let mut sets: [Bins<NB>; SETS] = std::array::from_fn(|_| Bins::empty());
        let mut add = |j: usize, r: &PrimRef| {
            let bi = bins_of(r, cmin, scale, NB);
            let b = &mut sets[j];
            if only < 3 {
                let (k, i) = (only, bi[only]);
                b.cnt[k][i] += 1;
                b.lo[k][i] = b.lo[k][i].min(r.lo);
                b.hi[k][i] = b.hi[k][i].max(r.hi);
                return;
            }
            for (k, &i) in bi.iter().enumerate() {
                b.cnt[k][i] += 1;
                b.lo[k][i] = b.lo[k][i].min(r.lo);
                b.hi[k][i] = b.hi[k][i].max(r.hi);
            }
        };
        let mut groups = refs.chunks_exact(SETS);
        for g in &mut groups {
            for (j, r) in g.iter().enumerate() {
                add(j, r);
            }
        }
        for r in groups.remainder() {
            add(0, r);
        }
        let mut it = sets.into_iter();
        let first = it.next().expect("at least one bin set");
        it.fold(first, |acc, b| acc.merge(&b))
    }
}

/// The best binned-SAH split of `refs` with `NB` bins per axis (binned by `SETS` interleaved
/// sets, and across threads when `parallel`); with `LONGEST`, on the axis of the longest
/// centroid extent only (for small nodes, where the sweeps cost more than the binning).
/// Returns (cost, axis, first bin of the right side); the cost is infinite when no split
/// separates anything.
fn find_split<const NB: usize, const SETS: usize, const LONGEST: bool>(
    refs: &[PrimRef],
    ext: &Extent,
    parallel: bool,
) -> (f32, usize, usize) {
    let cmin = ext.clo;
    let scale = bin_scale(ext, NB);
    let c = ext.chi - ext.clo;
    let longest = if c.x >= c.y && c.x >= c.z {
        0
    } else if c.y >= c.z {
        1
    } else {
        2
    };
    let only = if LONGEST { longest } else { 3 };
    let bins = if parallel && refs.len() >= 1 << 17 {
        use rayon::prelude::*;
        refs.par_chunks(1 << 15)
            .map(|c| Bins::<NB>::gather::<SETS>(c, cmin, scale, only))
            .reduce(Bins::empty, |a, b| a.merge(&b))
    } else {
        Bins::<NB>::gather::<SETS>(refs, cmin, scale, only)
    };
    let (cnt, blo, bhi) = (&bins.cnt, &bins.lo, &bins.hi);
    let mut best = (f32::INFINITY, 0usize, 0usize);
    for axis in 0..3 {
        if scale[axis] == 0.0 || (LONGEST && axis != longest) {
            continue;
        }
        let mut right_area = [0f32; NB];
        let mut right_cnt = [0u32; NB];
        let (mut lo, mut hi, mut ac) = (Vec4::INFINITY, Vec4::NEG_INFINITY, 0u32);
        for b in (1..NB).rev() {
            lo = lo.min(blo[axis][b]);
            hi = hi.max(bhi[axis][b]);
            ac += cnt[axis][b];
            right_area[b] = half_area(lo, hi);
            right_cnt[b] = ac;
        }
        let (mut lo, mut hi, mut ac) = (Vec4::INFINITY, Vec4::NEG_INFINITY, 0u32);
        for s in 1..NB {
            lo = lo.min(blo[axis][s - 1]);
            hi = hi.max(bhi[axis][s - 1]);
            ac += cnt[axis][s - 1];
            if ac == 0 || right_cnt[s] == 0 {
                continue;
            }
            let cost = half_area(lo, hi) * blocks(ac) + right_area[s] * blocks(right_cnt[s]);
            if cost < best.0 {
                best = (cost, axis, s);
            }
        }
    }
    best
}

/// In-place partition; returns the number of elements for which `pred` holds (they come
/// first) and the extents of both sides. Hoare-style: scan from both ends and swap pairs of
/// misplaced elements; every element is added to its side's extent as it is placed, so the
/// data is read once.
fn partition(v: &mut [PrimRef], pred: impl Fn(&PrimRef) -> bool) -> (usize, Extent, Extent) {
    let (mut le, mut re) = (Extent::EMPTY, Extent::EMPTY);
    let (mut i, mut j) = (0, v.len());
    loop {
        while i < j && pred(&v[i]) {
            le.add(&v[i]);
            i += 1;
        }
        while i < j && !pred(&v[j - 1]) {
            re.add(&v[j - 1]);
            j -= 1;
        }
        if i >= j {
            break;
        }
        v.swap(i, j - 1);
        le.add(&v[i]);
        re.add(&v[j - 1]);
        i += 1;
        j -= 1;
    }
    (i, le, re)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_primitive_in_exactly_one_leaf() {
        let mut boxes = Vec::new();
        let mut s = 1u64;
        for _ in 0..5000 {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let x = (s >> 40) as f32 / 16777216.0;
            let y = (s >> 20 & 0xfffff) as f32 / 1048576.0;
            boxes.push(Aabb { min: [x, y, 0.0], max: [x + 0.01, y + 0.01, 0.01] });
        }
        for _ in 0..100 {
            boxes.push(Aabb { min: [0.5; 3], max: [0.5; 3] }); // coincident centroids
        }
        let b = build_bvh(&boxes, BvhConfig { max_leaf: 4, parallel_above: 1000 });
        let mut seen = vec![0u32; boxes.len()];
        for n in &b.nodes {
            for (k, kid) in n.kids.iter().enumerate() {
                if let Kid::Leaf { start, count } = kid {
                    for &p in &b.order[*start as usize..(*start + *count) as usize] {
                        seen[p as usize] += 1;
                        assert!(n.bounds[k].contains(&boxes[p as usize]));
                    }
                    assert!(*count <= 4);
                }
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
    }

    /// The parallel build (parallel reference setup, splits ahead and subtrees) lays out exactly
    /// the tree of the serial one.
    #[test]
    fn parallel_build_equals_serial() {
        let mut boxes = Vec::new();
        let mut s = 7u64;
        for _ in 0..20_000 {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let (x, y, z) = ((s >> 40) as f32 / 16777216.0, (s >> 20 & 0xfffff) as f32 / 1048576.0, (s & 0xff) as f32);
            boxes.push(Aabb { min: [x, y, z * 0.01], max: [x + 0.003, y + 0.002, z * 0.01 + 0.001] });
        }
        let serial = build_bvh(&boxes, BvhConfig { max_leaf: 4, parallel_above: usize::MAX });
        let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
        let par = pool.install(|| build_bvh(&boxes, BvhConfig { max_leaf: 4, parallel_above: 500 }));
        assert_eq!(serial.order, par.order);
        assert_eq!(serial.depth, par.depth);
        assert_eq!(serial.nodes.len(), par.nodes.len());
        for (a, b) in serial.nodes.iter().zip(&par.nodes) {
            assert_eq!(a.kids, b.kids);
            assert_eq!(a.bounds, b.bounds);
        }
    }
}
