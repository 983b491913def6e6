//! The binned-SAH binary build: primitive references ([`PrimRef`]), the bins and the sweep
//! that finds each split, the in-place partition, and the binary tree it makes ([`BNode`]:
//! boxed at the top, split in parallel, and [`Flat`] arrays below).

use glam::{Vec3, Vec4};
use megaray_base::Aabb;
use megaray_scene::format::NODE_WIDTH;

use crate::bvh::collapse::{combine, Collapse, Costs};
use crate::bvh::{blocks, BvhConfig, Quality, BLOCK, C_TRAV};

/// The binary tree while building. Its top (the nodes the build splits in parallel) is
/// boxed; each subtree built by one thread is a [`Flat`] array, one allocation in the order
/// the collapse reads it.
pub(crate) enum BNode {
    /// `dp`: its [`Costs`] and [`Collapse`] choices, for a [`Quality::High`] build.
    Inner {
        bounds: Aabb,
        kids: Box<[BNode; 2]>,
        dp: Option<(Costs, Collapse)>,
    },
    Flat(Flat),
}

impl BNode {
    /// The [`Costs`] of this subtree's root, for a [`Quality::High`] build.
    pub(crate) fn costs(&self) -> Option<Costs> {
        match self {
            BNode::Inner { dp, .. } => dp.map(|d| d.0),
            BNode::Flat(f) => (!f.dp.is_empty()).then_some(f.cost),
        }
    }
}

/// A binary subtree in one array, in pre-order: node 0 is its root, an inner node's left
/// child follows it and `right` says where its right child is. For a [`Quality::High`]
/// build, `dp` holds each node's [`Collapse`] choices (empty otherwise) and `cost` its
/// root's [`Costs`].
pub(crate) struct Flat {
    pub(crate) nodes: Vec<FNode>,
    pub(crate) dp: Vec<Collapse>,
    pub(crate) cost: Costs,
}

impl Flat {
    /// A flat subtree, with its collapse choices when `dp` (children after their parent in
    /// pre-order: made in reverse, children's costs on a stack).
    pub(crate) fn new(nodes: Vec<FNode>, dp: bool) -> Flat {
        if !dp {
            return Flat { nodes, dp: Vec::new(), cost: [0.0; NODE_WIDTH] };
        }
        let mut choices = vec![[0u8; NODE_WIDTH]; nodes.len()];
        let mut stack: Vec<Costs> = Vec::with_capacity(64);
        for (i, n) in nodes.iter().enumerate().rev() {
            let area = n.bounds.half_area();
            if n.b & FNode::LEAF != 0 {
                stack.push([area * blocks(n.b & !FNode::LEAF); NODE_WIDTH]);
            } else {
                // The left subtree was done last: its root's costs are on top.
                let l = stack.pop().expect("a left subtree");
                let r = stack.pop().expect("a right subtree");
                let (cost, choice) = combine(area, n.a, &l, &r);
                choices[i] = choice;
                stack.push(cost);
            }
        }
        let cost = stack.pop().expect("a root");
        Flat { nodes, dp: choices, cost }
    }
}

/// A node of a [`Flat`] subtree: a leaf of primitives `start..start + count` (`a`, and `b`
/// with [`FNode::LEAF`] set), or an inner node whose right child is node `b`; `a` of an inner
/// node is 0, or, for a *soft* one, its number of primitives ([`BRef::soft`]).
#[derive(Clone, Copy)]
pub(crate) struct FNode {
    pub(crate) bounds: Aabb,
    pub(crate) a: u32,
    pub(crate) b: u32,
}
const _: () = assert!(std::mem::size_of::<FNode>() == 32);

impl FNode {
    pub(crate) const LEAF: u32 = 1 << 31;
}

/// A primitive reference while building: its box, with its number in the `w` lane of `hi`
/// ([`ID_FLIP`]).
/// 32 bytes, so that the builder's passes stream through memory instead of chasing indices;
/// `glam::Vec4` keeps each corner in one SIMD register.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub(crate) struct PrimRef {
    pub(crate) lo: Vec4,
    pub(crate) hi: Vec4,
}
const _: () = assert!(std::mem::size_of::<PrimRef>() == 32);

/// What a [`PrimRef`]'s id is xored with to make its `hi.w`: a normal float for every id
/// below 2^30 - 2^23 (an id's own bits are a denormal below 2^23). The builder's vector
/// arithmetic runs on that lane too (and ignores it), and arithmetic on denormals takes a
/// microcode assist of a hundred cycles or more on Intel CPUs (docs/PERF.md, "Denormals in
/// the ignored lane").
/// (Larger ids give an infinity or NaN there, which costs nothing; the bits are exact anyway:
/// references are moved, never computed.)
pub(crate) const ID_FLIP: u32 = 0x4000_0000;

impl PrimRef {
    #[inline(always)]
    pub(crate) fn new(b: &Aabb, id: u32) -> PrimRef {
        PrimRef { lo: Vec3::from(b.min).extend(0.0), hi: Vec3::from(b.max).extend(f32::from_bits(id ^ ID_FLIP)) }
    }

    #[inline(always)]
    pub(crate) fn id(&self) -> u32 {
        self.hi.w.to_bits() ^ ID_FLIP
    }
}

/// Bounds and doubled-centroid bounds of a range of primitives (`w` lanes are ignored).
#[derive(Clone, Copy)]
pub(crate) struct Extent {
    pub(crate) lo: Vec4,
    pub(crate) hi: Vec4,
    pub(crate) clo: Vec4,
    pub(crate) chi: Vec4,
}

impl Extent {
    pub(crate) const EMPTY: Extent =
        Extent { lo: Vec4::INFINITY, hi: Vec4::NEG_INFINITY, clo: Vec4::INFINITY, chi: Vec4::NEG_INFINITY };
    #[inline(always)]
    pub(crate) fn add(&mut self, r: &PrimRef) {
        self.lo = self.lo.min(r.lo);
        self.hi = self.hi.max(r.hi);
        let c = r.lo + r.hi;
        self.clo = self.clo.min(c);
        self.chi = self.chi.max(c);
    }
    pub(crate) fn bounds(&self) -> Aabb {
        Aabb { min: self.lo.truncate().into(), max: self.hi.truncate().into() }
    }
    pub(crate) fn merge(self, o: Extent) -> Extent {
        Extent { lo: self.lo.min(o.lo), hi: self.hi.max(o.hi), clo: self.clo.min(o.clo), chi: self.chi.max(o.chi) }
    }
    pub(crate) fn of(refs: &[PrimRef]) -> Extent {
        let mut e = Extent::EMPTY;
        refs.iter().for_each(|r| e.add(r));
        e
    }
}

#[inline(always)]
pub(crate) fn half_area(lo: Vec4, hi: Vec4) -> f32 {
    let e = (hi - lo).max(Vec4::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

pub(crate) struct Ctx {
    pub(crate) cfg: BvhConfig,
}

/// Where a split puts its two sides: the boxed top of the tree (split in parallel), or a
/// [`Flat`] subtree's array.
pub(crate) enum Out<'a> {
    Top,
    Flat(&'a mut Vec<FNode>),
}

impl Ctx {
    /// The tree over `refs`: split in parallel (boxed nodes) while larger than
    /// `parallel_above`, below that one [`Flat`] subtree per thread's task.
    pub(crate) fn build(&self, refs: &mut [PrimRef], ext: Extent, start: u32) -> BNode {
        // (A node small enough to be a leaf is always flat: it may be a soft one.)
        if refs.len() > self.cfg.parallel_above.max(self.cfg.max_leaf) {
            return self.split(refs, ext, start, &mut Out::Top).expect("a node at the top");
        }
        let mut flat = Vec::with_capacity(refs.len());
        self.split(refs, ext, start, &mut Out::Flat(&mut flat));
        BNode::Flat(Flat::new(flat, self.cfg.quality == Quality::High))
    }

    /// Splits `refs` (or makes them a leaf) into `out`. For [`Out::Top`], returns the
    /// boxed node (a leaf there is a flat tree of one node); for [`Out::Flat`], pushes the
    /// subtree in pre-order and returns `None`.
    pub(crate) fn split(&self, refs: &mut [PrimRef], ext: Extent, start: u32, out: &mut Out<'_>) -> Option<BNode> {
        let n = refs.len();
        let bounds = ext.bounds();
        let leaf = |out: &mut Out<'_>| {
            let node = FNode { bounds, a: start, b: n as u32 | FNode::LEAF };
            match out {
                Out::Top => Some(BNode::Flat(Flat::new(vec![node], self.cfg.quality == Quality::High))),
                Out::Flat(v) => {
                    v.push(node);
                    None
                }
            }
        };
        // One block's worth is always a leaf: splitting it costs a traversal step (C_TRAV)
        // plus at least one block test, against the leaf's one block test.
        if n <= 1 || (n <= self.cfg.max_leaf && n as u32 <= BLOCK) {
            return leaf(out);
        }
        // Binned SAH over all three axes in one pass (on one axis for small nodes of a
        // `Medium` build); fewer bins for small nodes, where the per-node cost of clearing
        // and sweeping bins would dominate.
        let par = n > self.cfg.parallel_above;
        let (best, nb) = match (self.cfg.quality, n) {
            (Quality::Medium, 1024..) => (find_split::<32, 2, false>(refs, &ext, par), 32),
            (Quality::Medium, 128..) => (find_split::<16, 1, true>(refs, &ext, false), 16),
            (Quality::Medium, _) => (find_split::<8, 1, true>(refs, &ext, false), 8),
            (Quality::High, 1024..) => (find_split::<64, 2, false>(refs, &ext, par), 64),
            (Quality::High, 128..) => (find_split::<32, 1, false>(refs, &ext, false), 32),
            (Quality::High, _) => (find_split::<16, 1, false>(refs, &ext, false), 16),
        };
        let cmin = ext.clo;
        let scale = bin_scale(&ext, nb);
        let parent_area = bounds.half_area().max(f32::MIN_POSITIVE);
        let split_cost = C_TRAV + best.0 / parent_area;
        let leaf_cost = blocks(n as u32);
        if n <= self.cfg.max_leaf && !best.0.is_finite() {
            return leaf(out);
        }
        // Cheaper as a leaf: split all the same, as a soft node ([`BRef::soft`]).
        let soft = n <= self.cfg.max_leaf && leaf_cost <= split_cost;
        let (mid, le, re) = if best.0.is_finite() {
            let (axis, s) = (best.1, best.2);
            // One body per axis, so that the lane it reads is a constant.
            match axis {
                0 => partition(refs, |r| bin_on::<0>(r, cmin, scale, nb) < s),
                1 => partition(refs, |r| bin_on::<1>(r, cmin, scale, nb) < s),
                _ => partition(refs, |r| bin_on::<2>(r, cmin, scale, nb) < s),
            }
        } else {
            // All centroids coincide: split the list in two.
            let mid = n / 2;
            let (mut le, mut re) = (Extent::EMPTY, Extent::EMPTY);
            refs[..mid].iter().for_each(|r| le.add(r));
            refs[mid..].iter().for_each(|r| re.add(r));
            (mid, le, re)
        };
        let (l, r) = refs.split_at_mut(mid);
        let rstart = start + mid as u32;
        match out {
            Out::Top => {
                debug_assert!(!soft, "small nodes are flat");
                let (ln, rn) = rayon::join(|| self.build(l, le, start), || self.build(r, re, rstart));
                let dp = match (ln.costs(), rn.costs()) {
                    (Some(lc), Some(rc)) => Some(combine(bounds.half_area(), 0, &lc, &rc)),
                    _ => None,
                };
                Some(BNode::Inner { bounds, kids: Box::new([ln, rn]), dp })
            }
            Out::Flat(v) => {
                // The node first (pre-order), its right child's position filled in after
                // the left subtree.
                let me = v.len();
                v.push(FNode { bounds, a: if soft { n as u32 } else { 0 }, b: 0 });
                self.split(l, le, start, &mut Out::Flat(v));
                v[me].b = v.len() as u32;
                self.split(r, re, rstart, &mut Out::Flat(v));
                None
            }
        }
    }
}

/// The bin of `r` on each axis, as the low bits of its lanes: its doubled centroid mapped
/// through `scale`, clamped to `0..nb` and rounded to the nearest integer by the 2^23 trick
/// (no float-to-int conversion, whose saturation checks dominated the builder's profile).
#[inline(always)]
pub(crate) fn bin_lanes(r: &PrimRef, cmin: Vec4, scale: Vec4, nb: usize) -> Vec4 {
    pub(crate) const MAGIC: f32 = 8_388_608.0; // 2^23: adding it leaves the integer in the low mantissa bits
    ((r.lo + r.hi - cmin) * scale).clamp(Vec4::ZERO, Vec4::splat(nb as f32 - 1.0)) + Vec4::splat(MAGIC)
}

/// The bin of `r` on each axis ([`bin_lanes`]).
#[inline(always)]
pub(crate) fn bins_of(r: &PrimRef, cmin: Vec4, scale: Vec4, nb: usize) -> [usize; 3] {
    let f = bin_lanes(r, cmin, scale, nb);
    [(f.x.to_bits() & 0xff) as usize, (f.y.to_bits() & 0xff) as usize, (f.z.to_bits() & 0xff) as usize]
}

/// [`bins_of`] on axis `A` alone (the same operations, so the same bin).
#[inline(always)]
pub(crate) fn bin_on<const A: usize>(r: &PrimRef, cmin: Vec4, scale: Vec4, nb: usize) -> usize {
    (bin_lanes(r, cmin, scale, nb).to_array()[A].to_bits() & 0xff) as usize
}

/// Per-axis factors that map a doubled centroid to its bin (0 on flat axes).
pub(crate) fn bin_scale(ext: &Extent, nb: usize) -> Vec4 {
    let cext = ext.chi - ext.clo;
    Vec4::select(cext.cmpgt(Vec4::ZERO), Vec4::splat(nb as f32) / cext, Vec4::ZERO)
}

/// Per-axis bins: primitive counts and bounds.
pub(crate) struct Bins<const NB: usize> {
    pub(crate) cnt: [[u32; NB]; 3],
    pub(crate) lo: [[Vec4; NB]; 3],
    pub(crate) hi: [[Vec4; NB]; 3],
}

impl<const NB: usize> Bins<NB> {
    pub(crate) fn empty() -> Self {
        Bins { cnt: [[0; NB]; 3], lo: [[Vec4::INFINITY; NB]; 3], hi: [[Vec4::NEG_INFINITY; NB]; 3] }
    }

    pub(crate) fn merge(mut self, o: &Self) -> Self {
        for k in 0..3 {
            for i in 0..NB {
                self.cnt[k][i] += o.cnt[k][i];
                self.lo[k][i] = self.lo[k][i].min(o.lo[k][i]);
                self.hi[k][i] = self.hi[k][i].max(o.hi[k][i]);
            }
        }
        self
    }

    /// Bins `refs` on all three axes, alternating between `SETS` bin sets (2 for large
    /// nodes, so that neighbours falling into the same bin do not wait on each other's
    /// stores).
    pub(crate) fn gather<const SETS: usize>(refs: &[PrimRef], cmin: Vec4, scale: Vec4) -> Self {
        let mut sets: [Bins<NB>; SETS] = std::array::from_fn(|_| Bins::empty());
        let mut add = |j: usize, r: &PrimRef| {
            let bi = bins_of(r, cmin, scale, NB);
            let b = &mut sets[j];
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
pub(crate) fn find_split<const NB: usize, const SETS: usize, const LONGEST: bool>(
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
    if LONGEST {
        // One axis: only its bins are made (a small node's bins cost as much to clear as
        // its primitives to bin).
        if scale[longest] == 0.0 {
            return (f32::INFINITY, 0, 0);
        }
        let b = match longest {
            0 => AxisBins::<NB>::gather::<0>(refs, cmin, scale),
            1 => AxisBins::<NB>::gather::<1>(refs, cmin, scale),
            _ => AxisBins::<NB>::gather::<2>(refs, cmin, scale),
        };
        let (cost, s) = sweep(&b.cnt, &b.lo, &b.hi);
        return (cost, longest, s);
    }
    let bins = if parallel && refs.len() >= 1 << 17 {
        use rayon::prelude::*;
        refs.par_chunks(1 << 15)
            .map(|c| Bins::<NB>::gather::<SETS>(c, cmin, scale))
            .reduce(Bins::empty, |a, b| a.merge(&b))
    } else {
        Bins::<NB>::gather::<SETS>(refs, cmin, scale)
    };
    let mut best = (f32::INFINITY, 0usize, 0usize);
    for axis in 0..3 {
        if scale[axis] == 0.0 {
            continue;
        }
        let (cost, s) = sweep(&bins.cnt[axis], &bins.lo[axis], &bins.hi[axis]);
        if cost < best.0 {
            best = (cost, axis, s);
        }
    }
    best
}

/// The cheapest split of one axis's bins: (SAH cost, first bin of the right side), the cost
/// infinite when no split separates anything.
#[inline(always)]
pub(crate) fn sweep<const NB: usize>(cnt: &[u32; NB], blo: &[Vec4; NB], bhi: &[Vec4; NB]) -> (f32, usize) {
    // The boxes and counts left and right of each split, grown from both ends in one loop:
    // the two chains of `min`s and `max`s (which a small node's split waits on) overlap
    // (docs/PERF.md, "SAH sweep from both ends").
    let (mut left_area, mut left_cnt) = ([0f32; NB], [0u32; NB]);
    let (mut right_area, mut right_cnt) = ([0f32; NB], [0u32; NB]);
    let (mut llo, mut lhi, mut lc) = (Vec4::INFINITY, Vec4::NEG_INFINITY, 0u32);
    let (mut rlo, mut rhi, mut rc) = (Vec4::INFINITY, Vec4::NEG_INFINITY, 0u32);
    for i in 1..NB {
        // Split `i`'s left side: bins `..i`.
        llo = llo.min(blo[i - 1]);
        lhi = lhi.max(bhi[i - 1]);
        lc += cnt[i - 1];
        left_area[i] = half_area(llo, lhi);
        left_cnt[i] = lc;
        // Split `NB - i`'s right side: bins `NB - i..`.
        let b = NB - i;
        rlo = rlo.min(blo[b]);
        rhi = rhi.max(bhi[b]);
        rc += cnt[b];
        right_area[b] = half_area(rlo, rhi);
        right_cnt[b] = rc;
    }
    let mut best = (f32::INFINITY, 0usize);
    for s in 1..NB {
        if left_cnt[s] == 0 || right_cnt[s] == 0 {
            continue;
        }
        let cost = left_area[s] * blocks(left_cnt[s]) + right_area[s] * blocks(right_cnt[s]);
        if cost < best.0 {
            best = (cost, s);
        }
    }
    best
}

/// The bins of one axis, `A`: what [`find_split`] fills for small nodes.
pub(crate) struct AxisBins<const NB: usize> {
    pub(crate) cnt: [u32; NB],
    pub(crate) lo: [Vec4; NB],
    pub(crate) hi: [Vec4; NB],
}

impl<const NB: usize> AxisBins<NB> {
    /// Bins `refs` on axis `A` ([`bin_on`]: the bins the partition will use).
    #[inline(always)]
    pub(crate) fn gather<const A: usize>(refs: &[PrimRef], cmin: Vec4, scale: Vec4) -> Self {
        let mut b = AxisBins { cnt: [0; NB], lo: [Vec4::INFINITY; NB], hi: [Vec4::NEG_INFINITY; NB] };
        for r in refs {
            let i = bin_on::<A>(r, cmin, scale, NB);
            b.cnt[i] += 1;
            b.lo[i] = b.lo[i].min(r.lo);
            b.hi[i] = b.hi[i].max(r.hi);
        }
        b
    }
}

/// In-place partition; returns the number of elements for which `pred` holds (they come
/// first) and the extents of both sides. Hoare-style: scan from both ends and swap pairs of
/// misplaced elements; every element is added to its side's extent as it is placed, so the
/// data is read once.
pub(crate) fn partition(v: &mut [PrimRef], pred: impl Fn(&PrimRef) -> bool) -> (usize, Extent, Extent) {
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
