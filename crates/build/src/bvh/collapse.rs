//! The collapse of the binary tree into 8-wide nodes: greedily (largest box opened first,
//! [`Quality::Medium`](super::Quality)) or by the dynamic program of Ylitie et al. 2017
//! ([`Costs`], [`Collapse`], [`combine`]), written straight into the output array in
//! parallel.

use megaray_base::Aabb;
use megaray_scene::format::NODE_WIDTH;

use crate::bvh::binary::{BNode, FNode, Flat};
use crate::bvh::{blocks, Kid, NodeB, C_TRAV};

/// `Costs[i - 1]`: the least SAH cost (area-weighted, in [`blocks`] and [`C_TRAV`] as the
/// builder's) of a binary subtree as at most `i` slots of an 8-wide node: the slot of its
/// root (a leaf, or an 8-wide node of its own), or its root opened and its two subtrees
/// sharing the slots. The dynamic program of Ylitie et al. ("Efficient incoherent ray
/// traversal on GPUs through compressed wide BVHs", 2017) with our leaves and soft nodes.
pub(crate) type Costs = [f32; NODE_WIDTH];

/// Per slot count `i` (entry `i - 1`) of a binary inner node: how many of the `i` slots its
/// left subtree takes when the node is opened (low bits), and [`SLOT`] when the
/// node costs less as one slot than opened.
pub(crate) type Collapse = [u8; NODE_WIDTH];
pub(crate) const SLOT: u8 = 0x80;

/// The [`Costs`] and [`Collapse`] choices of an inner node of box area `area` from its
/// children's costs; `soft` is its number of primitives if it is soft ([`BRef::soft`]: a
/// leaf as a slot), else 0.
pub(crate) fn combine(area: f32, soft: u32, l: &Costs, r: &Costs) -> (Costs, Collapse) {
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

/// A node of the binary tree, whichever way it is stored: what the collapse walks.
#[derive(Clone, Copy)]
pub(crate) enum BRef<'a> {
    /// A boxed inner node: its bounds, children and collapse choices.
    Boxed(&'a Aabb, &'a [BNode; 2], Option<&'a Collapse>),
    /// Node `i` of a flat subtree.
    Flat(&'a Flat, u32),
}

impl<'a> BRef<'a> {
    pub(crate) fn of(n: &'a BNode) -> BRef<'a> {
        match n {
            BNode::Inner { bounds, kids, dp } => BRef::Boxed(bounds, kids, dp.as_ref().map(|d| &d.1)),
            BNode::Flat(f) => BRef::Flat(f, 0),
        }
    }

    pub(crate) fn bounds(&self) -> Aabb {
        match *self {
            BRef::Boxed(bounds, ..) => *bounds,
            BRef::Flat(f, i) => f.nodes[i as usize].bounds,
        }
    }

    /// `Some((start, count))` for a leaf.
    pub(crate) fn leaf(&self) -> Option<(u32, u32)> {
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
    /// block where it was two (docs/PERF.md, "Soft nodes").
    pub(crate) fn soft(&self) -> Option<(u32, u32)> {
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
    pub(crate) fn slot_leaf(&self) -> Option<(u32, u32)> {
        self.leaf().or_else(|| self.soft())
    }

    /// The two children of an inner node.
    pub(crate) fn kids(&self) -> [BRef<'a>; 2] {
        match *self {
            BRef::Boxed(_, kids, _) => [BRef::of(&kids[0]), BRef::of(&kids[1])],
            BRef::Flat(f, i) => [BRef::Flat(f, i + 1), BRef::Flat(f, f.nodes[i as usize].b)],
        }
    }

    /// The collapse choices of an inner node of a [`Quality::High`] build.
    pub(crate) fn collapse(&self) -> Option<&'a Collapse> {
        match *self {
            BRef::Boxed(_, _, dp) => dp,
            BRef::Flat(f, i) => f.dp.get(i as usize),
        }
    }

    /// Half the surface area of an inner node, -1 for a leaf (never opened).
    pub(crate) fn area(&self) -> f32 {
        match self.leaf() {
            Some(_) => -1.0,
            None => self.bounds().half_area(),
        }
    }
}

/// Collapses the binary tree into 8-wide nodes (pre-order) in `out`; returns the depth. The
/// top `par` levels of 8-wide nodes are laid out first (their subtrees' sizes counted in
/// parallel), then their subtrees are written in parallel, each straight into its own range
/// of `out`: no subtree is built apart and copied, so each node is written once.
pub(crate) fn collapse(root: BRef<'_>, out: &mut Vec<NodeB>, par: u32) -> u32 {
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
pub(crate) fn slots_of(node: BRef<'_>) -> ([BRef<'_>; NODE_WIDTH], usize) {
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
pub(crate) fn take<'a>(node: BRef<'a>, i: u8, slot: &mut [BRef<'a>; NODE_WIDTH], len: &mut usize) {
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
pub(crate) struct Sizes {
    pub(crate) total: usize,
    /// One per slot for a node of the top levels (0 for leaf slots); empty below them.
    pub(crate) kids: Vec<Sizes>,
}

impl Sizes {
    pub(crate) fn of(node: BRef<'_>, par: u32) -> Sizes {
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
pub(crate) fn count(node: BRef<'_>) -> usize {
    let (slot, len) = slots_of(node);
    1 + slot[..len].iter().filter(|s| s.slot_leaf().is_none()).map(|s| count(*s)).sum::<usize>()
}

/// Writes the subtree at binary inner node `node` into `out` (exactly its size), its root
/// first; `base` is the index of `out[0]` in the whole array. Returns its depth.
pub(crate) fn fill(node: BRef<'_>, sizes: &Sizes, out: &mut [NodeB], base: u32) -> u32 {
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
pub(crate) fn fill_serial(node: BRef<'_>, out: &mut [NodeB], at: &mut usize, base: u32) -> u32 {
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
