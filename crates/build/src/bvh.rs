//! The in-core builder: a binned-SAH binary BVH over primitive boxes, then collapsed into a
//! 8-wide BVH in a build layout ([`Bvh`]). The same builder makes each part's tree (over
//! triangles) and the top-level tree (over parts). Layout for the file is [`crate::tiles`]'s job.

use glam::{Vec3, Vec4};
use megaray_base::Aabb;
use megaray_scene::format::NODE_WIDTH;

/// Cost of one node traversal relative to one test of a block of four primitives. Two, not
/// one, though a node step takes fewer instructions than a block test: a node is 256 bytes
/// against a block's 144, every block test comes after a node visit, and trees priced so
/// measured at least as fast, with fewer nodes and bytes. Against 1 (`megaray info --tree`;
/// `bench/ab.sh` with the two scenes, one binary, Intel Xeon): grid:1000 67K 8-wide nodes
/// instead of 95K, 46.0 bytes per triangle instead of 49.6; sphereflake:4 50.3 (52.8);
/// stanford-bunny 47.7 (50.7); 3-4% fewer node visits and 13-19% more blocks tested per
/// shadow or diffuse ray (leaves fuller, two-block leaves tested in one pass), +0.5-2% shadow
/// and diffuse rays per second on sphereflake:3 and stanford-bunny (30 rounds), +2-5% on
/// grid:1000, primary rays within noise, build time unchanged. 3 gains nothing more
/// (+-1.5%); 1.5 and 0.7 are noise.
const C_TRAV: f32 = 2.0;
/// Primitives are tested four at a time (one SIMD block), so the SAH counts blocks.
const BLOCK: u32 = 4;

#[inline(always)]
fn blocks(n: u32) -> f32 {
    n.div_ceil(BLOCK) as f32
}

/// How hard the builder looks for good splits (as Embree's build qualities: the trees it
/// traces are its `HIGH` ones, its build time is quoted for `MEDIUM`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Quality {
    /// Binned SAH with 32 bins on all three axes for nodes of at least 1024 primitives; 16
    /// bins (from 128) and 8 bins below, on the axis of the longest centroid extent only.
    Medium,
    /// Binned SAH on all three axes at every node: 64 bins from 1024 primitives, 32 from 128,
    /// 16 below, and the collapse into 8-wide nodes by a dynamic program (`Costs`) rather
    /// than greedily. About 25% slower to build than [`Quality::Medium`]; leaves are packed
    /// fuller and trees trace faster (measured on grid:1000: 64.9 bytes per triangle instead
    /// of 67.4, 7% fewer triangle blocks and 3% fewer nodes tested per diffuse ray; the
    /// dynamic program then 56.6 -> 49.6 bytes and SAH cost 16.26 -> 15.59; these with
    /// [`C_TRAV`] at 1, since raised to 2: 46.0 bytes).
    #[default]
    High,
}

/// Builder settings.
#[derive(Clone, Copy, Debug)]
pub struct BvhConfig {
    /// Leaves hold at most this many primitives (unless the SAH cannot separate them).
    pub max_leaf: usize,
    /// Build subtrees of more primitives than this in parallel (rayon); `usize::MAX`: never.
    pub parallel_above: usize,
    /// How splits are searched for.
    pub quality: Quality,
}

/// The binary tree while building. Its top (the nodes the build splits in parallel) is
/// boxed; each subtree built by one thread is a [`Flat`] array, one allocation in the order
/// the collapse reads it.
enum BNode {
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
    fn costs(&self) -> Option<Costs> {
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
struct Flat {
    nodes: Vec<FNode>,
    dp: Vec<Collapse>,
    cost: Costs,
}

/// `Costs[i - 1]`: the least SAH cost (area-weighted, in [`blocks`] and [`C_TRAV`] as the
/// builder's) of a binary subtree as at most `i` slots of an 8-wide node: the slot of its
/// root (a leaf, or an 8-wide node of its own), or its root opened and its two subtrees
/// sharing the slots. The dynamic program of Ylitie et al. ("Efficient incoherent ray
/// traversal on GPUs through compressed wide BVHs", 2017) with our leaves and soft nodes.
type Costs = [f32; NODE_WIDTH];

/// Per slot count `i` (entry `i - 1`) of a binary inner node: how many of the `i` slots its
/// left subtree takes when the node is opened (low bits), and [`SLOT`] when the
/// node costs less as one slot than opened.
type Collapse = [u8; NODE_WIDTH];
const SLOT: u8 = 0x80;

/// The [`Costs`] and [`Collapse`] choices of an inner node of box area `area` from its
/// children's costs; `soft` is its number of primitives if it is soft ([`BRef::soft`]: a
/// leaf as a slot), else 0.
fn combine(area: f32, soft: u32, l: &Costs, r: &Costs) -> (Costs, Collapse) {
    let mut open = [f32::INFINITY; NODE_WIDTH];
    let mut take = [1u8; NODE_WIDTH];
    for i in 2..=NODE_WIDTH {
        for j in 1..i {
            let c = l[j - 1] + r[i - j - 1];
            if c < open[i - 1] {
                (open[i - 1], take[i - 1]) = (c, j as u8);
            }
        }
    }
    // As a slot: a leaf (a soft node), or an 8-wide node whose eight slots share it.
    let slot = if soft > 0 { area * blocks(soft) } else { area * C_TRAV + open[NODE_WIDTH - 1] };
    let mut cost = [slot; NODE_WIDTH];
    let mut choice = [SLOT; NODE_WIDTH];
    for i in 2..=NODE_WIDTH {
        if open[i - 1] < slot {
            (cost[i - 1], choice[i - 1]) = (open[i - 1], take[i - 1]);
        } else {
            choice[i - 1] = SLOT | take[i - 1];
        }
    }
    (cost, choice)
}

impl Flat {
    /// A flat subtree, with its collapse choices when `dp` (children after their parent in
    /// pre-order: made in reverse, children's costs on a stack).
    fn new(nodes: Vec<FNode>, dp: bool) -> Flat {
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
struct FNode {
    bounds: Aabb,
    a: u32,
    b: u32,
}
const _: () = assert!(std::mem::size_of::<FNode>() == 32);

impl FNode {
    const LEAF: u32 = 1 << 31;
}

/// A node of the binary tree, whichever way it is stored: what the collapse walks.
#[derive(Clone, Copy)]
enum BRef<'a> {
    /// A boxed inner node: its bounds, children and collapse choices.
    Boxed(&'a Aabb, &'a [BNode; 2], Option<&'a Collapse>),
    /// Node `i` of a flat subtree.
    Flat(&'a Flat, u32),
}

impl<'a> BRef<'a> {
    fn of(n: &'a BNode) -> BRef<'a> {
        match n {
            BNode::Inner { bounds, kids, dp } => BRef::Boxed(bounds, kids, dp.as_ref().map(|d| &d.1)),
            BNode::Flat(f) => BRef::Flat(f, 0),
        }
    }

    fn bounds(&self) -> Aabb {
        match *self {
            BRef::Boxed(bounds, ..) => *bounds,
            BRef::Flat(f, i) => f.nodes[i as usize].bounds,
        }
    }

    /// `Some((start, count))` for a leaf.
    fn leaf(&self) -> Option<(u32, u32)> {
        match *self {
            BRef::Boxed(..) => None,
            BRef::Flat(f, i) => {
                let n = f.nodes[i as usize];
                (n.b & FNode::LEAF != 0).then_some((n.a, n.b & !FNode::LEAF))
            }
        }
    }

    /// `Some((start, count))` for a *soft* inner node: one of at most `max_leaf` primitives
    /// whose SAH found a leaf cheaper than a split, split all the same. A split inside an
    /// 8-wide node costs no traversal step, so the collapse opens a soft node like any
    /// other while its 8-wide node has free slots (as Embree's builder splits every child of
    /// more than a block's worth to fill a node), and keeps it a leaf of its primitives
    /// (contiguous: a subtree's are) when there is no room. A leaf test is then often one
    /// block where it was two (Embree's leaf SAH cost is 20-30% below a tree without them).
    fn soft(&self) -> Option<(u32, u32)> {
        match *self {
            BRef::Boxed(..) => None,
            BRef::Flat(f, i) => {
                let f = &f.nodes;
                let n = f[i as usize];
                if n.b & FNode::LEAF != 0 || n.a == 0 {
                    return None;
                }
                // Its first primitive is its leftmost leaf's.
                let mut j = i as usize + 1;
                while f[j].b & FNode::LEAF == 0 {
                    j += 1;
                }
                Some((f[j].a, n.a))
            }
        }
    }

    /// What a slot of an 8-wide node holds as a leaf: a leaf, or a soft node not opened.
    fn slot_leaf(&self) -> Option<(u32, u32)> {
        self.leaf().or_else(|| self.soft())
    }

    /// The two children of an inner node.
    fn kids(&self) -> [BRef<'a>; 2] {
        match *self {
            BRef::Boxed(_, kids, _) => [BRef::of(&kids[0]), BRef::of(&kids[1])],
            BRef::Flat(f, i) => [BRef::Flat(f, i + 1), BRef::Flat(f, f.nodes[i as usize].b)],
        }
    }

    /// The collapse choices of an inner node of a [`Quality::High`] build.
    fn collapse(&self) -> Option<&'a Collapse> {
        match *self {
            BRef::Boxed(_, _, dp) => dp,
            BRef::Flat(f, i) => f.dp.get(i as usize),
        }
    }

    /// Half the surface area of an inner node, -1 for a leaf (never opened).
    fn area(&self) -> f32 {
        match self.leaf() {
            Some(_) => -1.0,
            None => self.bounds().half_area(),
        }
    }
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

/// A primitive reference while building: its box, with its number in the `w` lane of `hi`
/// ([`ID_FLIP`]).
/// 32 bytes, so that the builder's passes stream through memory instead of chasing indices;
/// `glam::Vec4` keeps each corner in one SIMD register.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct PrimRef {
    lo: Vec4,
    hi: Vec4,
}
const _: () = assert!(std::mem::size_of::<PrimRef>() == 32);

/// What a [`PrimRef`]'s id is xored with to make its `hi.w`: a normal float for every id
/// below 2^30 - 2^23 (an id's own bits are a denormal below 2^23). The builder's vector
/// arithmetic runs on that lane too (and ignores it), and arithmetic on denormals takes a
/// microcode assist of a hundred cycles or more on Intel CPUs (grid:1000 builds 1.3x faster
/// without them, bench/ab.sh on an Intel Xeon).
/// (Larger ids give an infinity or NaN there, which costs nothing; the bits are exact anyway:
/// references are moved, never computed.)
const ID_FLIP: u32 = 0x4000_0000;

impl PrimRef {
    #[inline(always)]
    fn new(b: &Aabb, id: u32) -> PrimRef {
        PrimRef { lo: Vec3::from(b.min).extend(0.0), hi: Vec3::from(b.max).extend(f32::from_bits(id ^ ID_FLIP)) }
    }

    #[inline(always)]
    fn id(&self) -> u32 {
        self.hi.w.to_bits() ^ ID_FLIP
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
    let make = |i: usize| PrimRef::new(&box_of(i), i as u32);
    let (mut refs, mut nodes, mut order) = (SPARE_REFS.take(), SPARE_NODES.take(), SPARE_ORDER.take());
    let ext = if parallel {
        refs.par_extend((0..n).into_par_iter().with_min_len(1 << 14).map(make));
        refs.par_chunks(1 << 15).map(Extent::of).reduce(|| Extent::EMPTY, Extent::merge)
    } else {
        refs.extend((0..n).map(make));
        Extent::of(&refs)
    };
    let ctx = Ctx { cfg };
    let root = ctx.build(&mut refs, ext, 0);
    if parallel {
        order.par_extend(refs.par_iter().map(|r| r.id()));
    } else {
        order.extend(refs.iter().map(|r| r.id()));
    }
    SPARE_REFS.give(refs);
    let root_ref = BRef::of(&root);
    let bounds = root_ref.bounds();
    // The top two levels of 8-wide nodes collapse their subtrees in parallel (up to 64
    // tasks); the layout is the same as a serial collapse.
    let depth = collapse(root_ref, &mut nodes, if parallel { 2 } else { 0 });
    Bvh { nodes, order, bounds, depth }
}

/// Gives the big arrays of a BVH no longer needed to the next build ([`Spare`]).
pub fn recycle(bvh: Bvh) {
    SPARE_NODES.give(bvh.nodes);
    SPARE_ORDER.give(bvh.order);
}

/// Frees the arrays kept by [`recycle`] and the builds.
pub fn release_spare() {
    SPARE_REFS.clear();
    SPARE_NODES.clear();
    SPARE_ORDER.clear();
}

/// Arrays of one kind kept from one build to the next, emptied: the builder's largest
/// (references, 8-wide nodes, primitive order: about 70 bytes per primitive). Parts of a
/// model are built one after another and benchmarks repeat builds, and fresh memory costs a
/// page fault per 4 KiB when first written: 2.5-3.5 us each on a virtual machine
/// (measured), which on grid:1000 was over 100 ms of a 1.2 s build. At most
/// [`Spare::new`]'s `keep` arrays of a kind are kept (one per build running at once). The
/// price: a part's references stay allocated through its tile stage instead of being freed
/// before it, 32 bytes per triangle more at the peak (grid:1000 built as one part peaks at
/// 406 MiB instead of 321), within the [`crate::INCORE_BYTES_PER_TRI`] a part is budgeted.
pub(crate) struct Spare<T> {
    kept: std::sync::Mutex<Vec<Vec<T>>>,
    keep: usize,
}

static SPARE_REFS: Spare<PrimRef> = Spare::new(8);
static SPARE_NODES: Spare<NodeB> = Spare::new(8);
static SPARE_ORDER: Spare<u32> = Spare::new(8);

impl<T> Spare<T> {
    /// Keeping at most `keep` arrays.
    pub(crate) const fn new(keep: usize) -> Spare<T> {
        Spare { kept: std::sync::Mutex::new(Vec::new()), keep }
    }

    /// An empty array, with the capacity of an earlier build's when one was kept.
    pub(crate) fn take(&self) -> Vec<T> {
        self.kept.lock().unwrap_or_else(|p| p.into_inner()).pop().unwrap_or_default()
    }

    /// Frees every kept array.
    pub(crate) fn clear(&self) {
        std::mem::take(&mut *self.kept.lock().unwrap_or_else(|p| p.into_inner()));
    }

    pub(crate) fn give(&self, mut v: Vec<T>) {
        v.clear();
        let mut kept = self.kept.lock().unwrap_or_else(|p| p.into_inner());
        if v.capacity() > 0 && kept.len() < self.keep {
            kept.push(v);
        }
    }
}

struct Ctx {
    cfg: BvhConfig,
}

/// Where a split puts its two sides: the boxed top of the tree (split in parallel), or a
/// [`Flat`] subtree's array.
enum Out<'a> {
    Top,
    Flat(&'a mut Vec<FNode>),
}

impl Ctx {
    /// The tree over `refs`: split in parallel (boxed nodes) while larger than
    /// `parallel_above`, below that one [`Flat`] subtree per thread's task.
    fn build(&self, refs: &mut [PrimRef], ext: Extent, start: u32) -> BNode {
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
    fn split(&self, refs: &mut [PrimRef], ext: Extent, start: u32, out: &mut Out<'_>) -> Option<BNode> {
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
fn bin_lanes(r: &PrimRef, cmin: Vec4, scale: Vec4, nb: usize) -> Vec4 {
    const MAGIC: f32 = 8_388_608.0; // 2^23: adding it leaves the integer in the low mantissa bits
    ((r.lo + r.hi - cmin) * scale).clamp(Vec4::ZERO, Vec4::splat(nb as f32 - 1.0)) + Vec4::splat(MAGIC)
}

/// The bin of `r` on each axis ([`bin_lanes`]).
#[inline(always)]
fn bins_of(r: &PrimRef, cmin: Vec4, scale: Vec4, nb: usize) -> [usize; 3] {
    let f = bin_lanes(r, cmin, scale, nb);
    [(f.x.to_bits() & 0xff) as usize, (f.y.to_bits() & 0xff) as usize, (f.z.to_bits() & 0xff) as usize]
}

/// [`bins_of`] on axis `A` alone (the same operations, so the same bin).
#[inline(always)]
fn bin_on<const A: usize>(r: &PrimRef, cmin: Vec4, scale: Vec4, nb: usize) -> usize {
    (bin_lanes(r, cmin, scale, nb).to_array()[A].to_bits() & 0xff) as usize
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

    /// Bins `refs` on all three axes, alternating between `SETS` bin sets (2 for large
    /// nodes, so that neighbours falling into the same bin do not wait on each other's
    /// stores).
    fn gather<const SETS: usize>(refs: &[PrimRef], cmin: Vec4, scale: Vec4) -> Self {
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
fn sweep<const NB: usize>(cnt: &[u32; NB], blo: &[Vec4; NB], bhi: &[Vec4; NB]) -> (f32, usize) {
    // The boxes and counts left and right of each split, grown from both ends in one loop:
    // the two chains of `min`s and `max`s (which a small node's split waits on) overlap.
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
struct AxisBins<const NB: usize> {
    cnt: [u32; NB],
    lo: [Vec4; NB],
    hi: [Vec4; NB],
}

impl<const NB: usize> AxisBins<NB> {
    /// Bins `refs` on axis `A` ([`bin_on`]: the bins the partition will use).
    #[inline(always)]
    fn gather<const A: usize>(refs: &[PrimRef], cmin: Vec4, scale: Vec4) -> Self {
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

/// Collapses the binary tree into 8-wide nodes (pre-order) in `out`; returns the depth. The
/// top `par` levels of 8-wide nodes are laid out first (their subtrees' sizes counted in
/// parallel), then their subtrees are written in parallel, each straight into its own range
/// of `out`: no subtree is built apart and copied, so each node is written once.
fn collapse(root: BRef<'_>, out: &mut Vec<NodeB>, par: u32) -> u32 {
    let empty = NodeB { bounds: [Aabb::EMPTY; NODE_WIDTH], kids: [Kid::Empty; NODE_WIDTH] };
    if let Some((start, count)) = root.leaf() {
        // A tree that is a single leaf: a root node with one leaf child.
        let mut n = empty;
        n.bounds[0] = root.bounds();
        n.kids[0] = Kid::Leaf { start, count };
        out.push(n);
        return 1;
    }
    let sizes = Sizes::of(root, par);
    use rayon::prelude::*;
    // Filled in parallel, so that the pages are first touched by many threads.
    out.par_extend(rayon::iter::repeat_n(empty, sizes.total));
    fill(root, &sizes, out, 0)
}

/// The 8-wide slots of binary inner node `node`: as its [`Collapse`] choices have them
/// (a [`Quality::High`] build), else its children, the inner one of largest surface area
/// opened (replaced by its two children) until there are eight or only leaves.
fn slots_of(node: BRef<'_>) -> ([BRef<'_>; NODE_WIDTH], usize) {
    if let Some(c) = node.collapse() {
        // The choices of the dynamic program ([`Costs`]): the node opened, its slots shared
        // by its subtrees as the least cost has them.
        let mut slot = [node; NODE_WIDTH];
        let mut len = 0;
        let [l, r] = node.kids();
        let j = c[NODE_WIDTH - 1] & !SLOT;
        take(l, j, &mut slot, &mut len);
        take(r, NODE_WIDTH as u8 - j, &mut slot, &mut len);
        return (slot, len);
    }
    let kids = node.kids();
    // The slots, in order, with the area of each inner one (-1 for leaves: never opened).
    let mut slot: [BRef<'_>; NODE_WIDTH] = [kids[0]; NODE_WIDTH];
    let mut area = [-1f32; NODE_WIDTH];
    (slot[1], area[0], area[1]) = (kids[1], kids[0].area(), kids[1].area());
    let mut len = 2;
    while len < NODE_WIDTH {
        // Open the inner child with the largest surface area (the last of equal ones, as `max_by`).
        let mut i = usize::MAX;
        let mut best = -1.0;
        for (k, &a) in area[..len].iter().enumerate() {
            if a >= 0.0 && (i == usize::MAX || a >= best) {
                (i, best) = (k, a);
            }
        }
        if i == usize::MAX {
            break;
        }
        let kids = slot[i].kids();
        slot.copy_within(i + 1..len, i + 2);
        area.copy_within(i + 1..len, i + 2);
        (slot[i], slot[i + 1]) = (kids[0], kids[1]);
        (area[i], area[i + 1]) = (kids[0].area(), kids[1].area());
        len += 1;
    }
    (slot, len)
}

/// Appends to `slot` the slots of the subtree at `node` given at most `i` of them, as its
/// [`Collapse`] choices have it.
fn take<'a>(node: BRef<'a>, i: u8, slot: &mut [BRef<'a>; NODE_WIDTH], len: &mut usize) {
    let choice = match (i, node.leaf(), node.collapse()) {
        (2.., None, Some(c)) => c[i as usize - 1],
        _ => SLOT,
    };
    if choice & SLOT != 0 {
        slot[*len] = node;
        *len += 1;
        return;
    }
    let [l, r] = node.kids();
    take(l, choice, slot, len);
    take(r, i - choice, slot, len);
}

/// The number of 8-wide nodes of the subtree at binary inner node `node`, and (for the
/// top levels that are written in parallel) those of its inner slots' subtrees.
struct Sizes {
    total: usize,
    /// One per slot for a node of the top levels (0 for leaf slots); empty below them.
    kids: Vec<Sizes>,
}

impl Sizes {
    fn of(node: BRef<'_>, par: u32) -> Sizes {
        if par == 0 {
            return Sizes { total: count(node), kids: Vec::new() };
        }
        let (slot, len) = slots_of(node);
        use rayon::prelude::*;
        let kids: Vec<Sizes> = slot[..len]
            .par_iter()
            .map(|s| match s.slot_leaf() {
                Some(_) => Sizes { total: 0, kids: Vec::new() },
                None => Sizes::of(*s, par - 1),
            })
            .collect();
        Sizes { total: 1 + kids.iter().map(|k| k.total).sum::<usize>(), kids }
    }
}

/// The number of 8-wide nodes of the subtree at binary inner node `node`.
fn count(node: BRef<'_>) -> usize {
    let (slot, len) = slots_of(node);
    1 + slot[..len].iter().filter(|s| s.slot_leaf().is_none()).map(|s| count(*s)).sum::<usize>()
}

/// Writes the subtree at binary inner node `node` into `out` (exactly its size), its root
/// first; `base` is the index of `out[0]` in the whole array. Returns its depth.
fn fill(node: BRef<'_>, sizes: &Sizes, out: &mut [NodeB], base: u32) -> u32 {
    if sizes.kids.is_empty() {
        let mut at = 0;
        let depth = fill_serial(node, out, &mut at, base);
        assert_eq!(at, out.len(), "the subtree has the size counted");
        return depth;
    }
    let (slot, len) = slots_of(node);
    let (me, mut rest) = out.split_first_mut().expect("room for the node");
    let mut at = base + 1;
    // Each inner slot's subtree gets its range, and all are written in parallel.
    let mut jobs = Vec::new();
    for (k, s) in slot[..len].iter().enumerate() {
        me.bounds[k] = s.bounds();
        me.kids[k] = match s.slot_leaf() {
            Some((start, count)) => Kid::Leaf { start, count },
            None => {
                let n = sizes.kids[k].total;
                let (mine, r) = std::mem::take(&mut rest).split_at_mut(n);
                rest = r;
                jobs.push((*s, &sizes.kids[k], mine, at));
                at += n as u32;
                Kid::Inner(at - n as u32)
            }
        };
    }
    use rayon::prelude::*;
    jobs.into_par_iter().map(|(s, z, out, b)| fill(s, z, out, b)).max().unwrap_or(0) + 1
}

/// [`fill`] below the top levels: depth-first from `out[*at]`, which is node `base + *at`.
fn fill_serial(node: BRef<'_>, out: &mut [NodeB], at: &mut usize, base: u32) -> u32 {
    let (slot, len) = slots_of(node);
    let me = *at;
    *at += 1;
    let mut depth = 0;
    for (k, s) in slot[..len].iter().enumerate() {
        out[me].bounds[k] = s.bounds();
        out[me].kids[k] = match s.slot_leaf() {
            Some((start, count)) => Kid::Leaf { start, count },
            None => {
                let child = base + *at as u32;
                depth = depth.max(fill_serial(*s, out, at, base));
                Kid::Inner(child)
            }
        };
    }
    depth + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_ids_round_trip_and_are_no_denormals() {
        let b = Aabb { min: [0.0; 3], max: [1.0; 3] };
        for id in [0, 1, (1 << 23) - 1, 1 << 23, 1 << 24, (1 << 30) - 1, 0x3F7F_FFFF, 0x3F80_0000, u32::MAX] {
            let r = PrimRef::new(&b, id);
            assert_eq!(r.id(), id);
            if id < 0x3F80_0000 {
                assert!(r.hi.w.is_normal(), "id {id}: {:e}", r.hi.w);
            }
        }
    }

    /// `n` boxes made by `f` from the successive states of a linear congruential generator
    /// started at `seed` (deterministic test inputs).
    fn random_boxes(seed: u64, n: usize, f: impl Fn(u64) -> Aabb) -> Vec<Aabb> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                f(s)
            })
            .collect()
    }

    /// `s`'s high bits as three coordinates: two in `[0, 1)` and a third, `s & mask`.
    fn coords(s: u64, mask: u64) -> (f32, f32, f32) {
        ((s >> 40) as f32 / 16777216.0, (s >> 20 & 0xfffff) as f32 / 1048576.0, (s & mask) as f32)
    }

    /// 20,000 small boxes at random, in a thin slab.
    fn small_boxes() -> Vec<Aabb> {
        random_boxes(5, 20_000, |s| {
            let (x, y, z) = coords(s, 0xfff);
            Aabb { min: [x, y, z / 4096.0], max: [x + 0.004, y + 0.003, z / 4096.0 + 0.002] }
        })
    }

    /// 30,000 thin boxes of random lengths along x, many of them overlapping.
    fn thin_boxes() -> Vec<Aabb> {
        random_boxes(3, 30_000, |s| {
            let (x, y, z) = coords(s, 0xfff);
            let long = (s >> 12 & 0xff) as f32 / 2560.0;
            Aabb { min: [x, y, z / 4096.0], max: [x + long, y + 0.002, z / 4096.0 + 0.001] }
        })
    }

    /// The serial and parallel builds of the same input made the same tree.
    fn assert_same_tree(serial: &Bvh, par: &Bvh, what: &str) {
        assert_eq!(serial.order, par.order, "{what}");
        assert_eq!(serial.depth, par.depth, "{what}");
        assert_eq!(serial.nodes.len(), par.nodes.len(), "{what}");
        for (a, b) in serial.nodes.iter().zip(&par.nodes) {
            assert_eq!(a.kids, b.kids, "{what}");
            assert_eq!(a.bounds, b.bounds, "{what}");
        }
    }

    #[test]
    fn every_primitive_in_exactly_one_leaf() {
        let mut boxes = random_boxes(1, 5000, |s| {
            let (x, y, _) = coords(s, 0);
            Aabb { min: [x, y, 0.0], max: [x + 0.01, y + 0.01, 0.01] }
        });
        for _ in 0..100 {
            boxes.push(Aabb { min: [0.5; 3], max: [0.5; 3] }); // coincident centroids
        }
        for (quality, max_leaf) in [(Quality::Medium, 4), (Quality::High, 4), (Quality::Medium, 8), (Quality::High, 8)]
        {
            let b = build_bvh(&boxes, BvhConfig { max_leaf, parallel_above: 1000, quality });
            let mut seen = vec![0u32; boxes.len()];
            for n in &b.nodes {
                for (k, kid) in n.kids.iter().enumerate() {
                    if let Kid::Leaf { start, count } = kid {
                        for &p in &b.order[*start as usize..(*start + *count) as usize] {
                            seen[p as usize] += 1;
                            assert!(n.bounds[k].contains(&boxes[p as usize]));
                        }
                        assert!(*count as usize <= max_leaf);
                    }
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "{quality:?} {max_leaf}");
        }
    }

    /// A leaf of more than a block's worth (a soft node kept whole, [`BRef::soft`]) only
    /// where its 8-wide node has no free slot: with room, it is opened; and some are kept
    /// (a full node has no room for them).
    #[test]
    fn soft_nodes_open_into_free_slots() {
        let boxes = small_boxes();
        for quality in [Quality::Medium, Quality::High] {
            let b = build_bvh(&boxes, BvhConfig { max_leaf: 8, parallel_above: 3000, quality });
            let mut kept = 0;
            for n in &b.nodes {
                let used = n.kids.iter().filter(|k| !matches!(k, Kid::Empty)).count();
                for kid in &n.kids {
                    if let Kid::Leaf { count, .. } = kid {
                        if *count > BLOCK {
                            assert_eq!(used, NODE_WIDTH, "{quality:?}: a two-block leaf in a node with free slots");
                            kept += 1;
                        }
                    }
                }
            }
            assert!(kept > 0, "{quality:?}: no soft node kept whole");
        }
    }

    /// The SAH cost of an 8-wide tree as the builder counts it: a traversal step ([`C_TRAV`])
    /// per inner node and a block test per four primitives of a leaf, each weighted by its
    /// box's area.
    fn sah_cost(b: &Bvh) -> f64 {
        let step = C_TRAV as f64;
        let mut cost = b.bounds.half_area() as f64 * step;
        for n in &b.nodes {
            for (k, kid) in n.kids.iter().enumerate() {
                let area = n.bounds[k].half_area() as f64;
                match kid {
                    Kid::Inner(_) => cost += area * step,
                    Kid::Leaf { count, .. } => cost += area * count.div_ceil(BLOCK) as f64,
                    Kid::Empty => {}
                }
            }
        }
        cost / b.bounds.half_area() as f64
    }

    /// A high-quality build finds a better tree than a medium one (here: thin boxes at
    /// random, many of them overlapping) and packs its leaves at least as full.
    #[test]
    fn high_quality_builds_better_trees() {
        let boxes = thin_boxes();
        let build = |quality| build_bvh(&boxes, BvhConfig { max_leaf: 4, parallel_above: usize::MAX, quality });
        let (medium, high) = (build(Quality::Medium), build(Quality::High));
        let leaves = |b: &Bvh| b.nodes.iter().flat_map(|n| n.kids).filter(|k| matches!(k, Kid::Leaf { .. })).count();
        assert!(sah_cost(&high) < sah_cost(&medium), "high {} medium {}", sah_cost(&high), sah_cost(&medium));
        assert!(leaves(&high) <= leaves(&medium), "high {} leaves, medium {}", leaves(&high), leaves(&medium));
    }

    /// The binary tree `n` without its collapse choices (collapsed greedily then).
    fn greedy(n: BNode) -> BNode {
        match n {
            BNode::Inner { bounds, kids, .. } => {
                let [a, b] = *kids;
                BNode::Inner { bounds, kids: Box::new([greedy(a), greedy(b)]), dp: None }
            }
            BNode::Flat(f) => BNode::Flat(Flat { nodes: f.nodes, dp: Vec::new(), cost: f.cost }),
        }
    }

    /// The dynamic program's collapse of a binary tree costs no more (by the SAH it
    /// minimises) than the greedy one, largest box first, of the same tree, on trees with
    /// boxed tops, soft nodes and leaves of one and two blocks; and is cheaper on them all.
    #[test]
    fn dp_collapse_costs_no_more_than_greedy() {
        for (what, boxes) in [("thin", thin_boxes()), ("small", small_boxes())] {
            let cfg = BvhConfig { max_leaf: 8, parallel_above: 3000, quality: Quality::High };
            let mut refs: Vec<PrimRef> = boxes.iter().enumerate().map(|(i, b)| PrimRef::new(b, i as u32)).collect();
            let ext = Extent::of(&refs);
            let root = Ctx { cfg }.build(&mut refs, ext, 0);
            let bounds = BRef::of(&root).bounds();
            let tree = |root: &BNode| {
                let mut nodes = Vec::new();
                let depth = collapse(BRef::of(root), &mut nodes, 1);
                Bvh { nodes, order: Vec::new(), bounds, depth }
            };
            let dp = sah_cost(&tree(&root));
            let greedy = sah_cost(&tree(&greedy(root)));
            assert!(dp < greedy, "{what}: dynamic program {dp}, greedy {greedy}");
        }
    }

    /// Trees of a few primitives (a lone leaf at the root, boxed nodes over flat subtrees of
    /// one leaf) come out the same serial and parallel, every primitive in one leaf.
    #[test]
    fn tiny_trees_serial_and_parallel() {
        for n in 1..=40usize {
            let boxes: Vec<Aabb> = (0..n)
                .map(|i| Aabb { min: [i as f32, 0.0, (i % 3) as f32], max: [i as f32 + 0.5, 1.0, 1.0] })
                .collect();
            let quality = Quality::High;
            let serial = build_bvh(&boxes, BvhConfig { max_leaf: 4, parallel_above: usize::MAX, quality });
            let par = build_bvh(&boxes, BvhConfig { max_leaf: 4, parallel_above: 2, quality });
            assert_same_tree(&serial, &par, &format!("{n} primitives"));
            let mut seen = vec![0u32; n];
            for a in &serial.nodes {
                for kid in &a.kids {
                    if let Kid::Leaf { start, count } = kid {
                        for &p in &serial.order[*start as usize..(*start + *count) as usize] {
                            seen[p as usize] += 1;
                        }
                    }
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "{n} primitives: each in one leaf");
        }
    }

    /// The parallel build (parallel reference setup, subtrees and collapse) lays out exactly
    /// the tree of the serial one.
    #[test]
    fn parallel_build_equals_serial() {
        let boxes = random_boxes(7, 20_000, |s| {
            let (x, y, z) = coords(s, 0xff);
            Aabb { min: [x, y, z * 0.01], max: [x + 0.003, y + 0.002, z * 0.01 + 0.001] }
        });
        let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
        for quality in [Quality::Medium, Quality::High] {
            let serial = build_bvh(&boxes, BvhConfig { max_leaf: 4, parallel_above: usize::MAX, quality });
            let par = pool.install(|| build_bvh(&boxes, BvhConfig { max_leaf: 4, parallel_above: 500, quality }));
            assert_same_tree(&serial, &par, &format!("{quality:?}"));
        }
    }
}
