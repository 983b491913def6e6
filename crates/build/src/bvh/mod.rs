//! The in-core builder: a binned-SAH binary BVH over primitive boxes, then collapsed into a
//! 8-wide BVH in a build layout ([`Bvh`]). The same builder makes each part's tree (over
//! triangles) and the top-level tree (over parts). Layout for the file is [`crate::tiles`]'s job.

//!
//! | file | holds |
//! |---|---|
//! | `mod.rs` | the API: [`Quality`], [`BvhConfig`], [`build_bvh`], the build layout ([`Bvh`], [`NodeB`], [`Kid`]) |
//! | `binary.rs` | the binned-SAH binary build |
//! | `collapse.rs` | the collapse into 8-wide nodes (greedy, or the dynamic program) |
//! | `spare.rs` | arrays kept from one build to the next |

mod binary;
mod collapse;
pub(crate) mod spare;

use megaray_base::Aabb;
use megaray_scene::format::NODE_WIDTH;

use crate::bvh::binary::{Ctx, Extent, PrimRef};
use crate::bvh::collapse::BRef;
use crate::bvh::spare::{SPARE_NODES, SPARE_ORDER, SPARE_REFS};

/// Cost of one node traversal relative to one test of a block of four primitives. Two, not
/// one, though a node step takes fewer instructions than a block test: a node is 256 bytes
/// against a block's 144 and every block test follows a node visit, and trees priced so
/// traced at least as fast, with fewer nodes and bytes. Why 2: docs/PERF.md, "Node visit price".
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
    /// than greedily. About 25% slower to build than [`Quality::Medium`]; its trees are
    /// smaller and trace faster (docs/PERF.md, "Build qualities and the collapse").
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
    let depth = collapse::collapse(root_ref, &mut nodes, if parallel { 2 } else { 0 });
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

#[cfg(test)]
mod tests {
    use super::binary::*;
    use super::collapse::*;
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
