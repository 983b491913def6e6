//! The in-core builder: a binned-SAH binary BVH over primitive boxes, then collapsed into a
//! 4-wide BVH in a build layout ([`Bvh4`]). The same builder makes each part's tree (over
//! triangles) and the top-level tree (over parts). Layout for the file is [`crate::tiles`]'s job.

use megaray_base::Aabb;

/// Bins per axis for in-core SAH.
const BINS: usize = 16;
/// Cost of one node traversal relative to one primitive test.
const C_TRAV: f32 = 1.0;

/// Builder settings.
#[derive(Clone, Copy, Debug)]
pub struct BvhConfig {
    /// Leaves hold at most this many primitives (unless the SAH cannot separate them).
    pub max_leaf: usize,
    /// Build subtrees of more primitives than this in parallel (rayon); `usize::MAX`: never.
    pub parallel_above: usize,
}

enum BNode {
    Leaf { bounds: Aabb, start: u32, count: u32 },
    Inner { bounds: Aabb, kids: Box<[BNode; 2]> },
}

impl BNode {
    fn bounds(&self) -> &Aabb {
        match self {
            BNode::Leaf { bounds, .. } | BNode::Inner { bounds, .. } => bounds,
        }
    }
}

/// A child slot of a build-layout 4-wide node.
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

/// A build-layout 4-wide node.
#[derive(Clone, Copy, Debug)]
pub struct Node4B {
    pub bounds: [Aabb; 4],
    pub kids: [Kid; 4],
}

/// A 4-wide BVH in build layout: nodes in pre-order (children after their parent; node 0
/// is the root) and the primitive order its leaves index.
pub struct Bvh4 {
    pub nodes: Vec<Node4B>,
    pub order: Vec<u32>,
    pub bounds: Aabb,
    pub depth: u32,
}

/// Builds a 4-wide BVH over primitives with the given boxes (centroids are box centres).
pub fn build_bvh4(boxes: &[Aabb], cfg: BvhConfig) -> Bvh4 {
    assert!(!boxes.is_empty(), "build_bvh4 needs at least one primitive");
    let centroids: Vec<[f32; 3]> = boxes.iter().map(|b| b.center().into()).collect();
    let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
    let ctx = Ctx { boxes, centroids: &centroids, cfg };
    let root = ctx.build(&mut order, 0);
    let bounds = *root.bounds();
    let mut nodes = Vec::new();
    let depth = collapse(&root, &mut nodes);
    Bvh4 { nodes, order, bounds, depth }
}

struct Ctx<'a> {
    boxes: &'a [Aabb],
    centroids: &'a [[f32; 3]],
    cfg: BvhConfig,
}

impl Ctx<'_> {
    fn build(&self, idx: &mut [u32], start: u32) -> BNode {
        let n = idx.len();
        let mut bounds = Aabb::EMPTY;
        let mut cb = Aabb::EMPTY;
        for &i in idx.iter() {
            bounds.grow(&self.boxes[i as usize]);
            cb.grow_point(self.centroids[i as usize]);
        }
        if n <= 1 {
            return BNode::Leaf { bounds, start, count: n as u32 };
        }
        // Binned SAH over all three axes.
        let mut best = (f32::INFINITY, 0usize, 0usize); // cost, axis, split bin (left = bins < split)
        let ext = cb.extent();
        for axis in 0..3 {
            if ext[axis].is_nan() || ext[axis] <= 0.0 {
                continue;
            }
            let lo = cb.min[axis];
            let scale = BINS as f32 / ext[axis];
            let mut cnt = [0u32; BINS];
            let mut bb = [Aabb::EMPTY; BINS];
            for &i in idx.iter() {
                let b = (((self.centroids[i as usize][axis] - lo) * scale) as usize).min(BINS - 1);
                cnt[b] += 1;
                bb[b].grow(&self.boxes[i as usize]);
            }
            let mut right_area = [0f32; BINS];
            let mut right_cnt = [0u32; BINS];
            let (mut acc, mut ac) = (Aabb::EMPTY, 0u32);
            for b in (1..BINS).rev() {
                acc.grow(&bb[b]);
                ac += cnt[b];
                right_area[b] = acc.half_area();
                right_cnt[b] = ac;
            }
            let (mut acc, mut ac) = (Aabb::EMPTY, 0u32);
            for s in 1..BINS {
                acc.grow(&bb[s - 1]);
                ac += cnt[s - 1];
                if ac == 0 || right_cnt[s] == 0 {
                    continue;
                }
                let cost = acc.half_area() * ac as f32 + right_area[s] * right_cnt[s] as f32;
                if cost < best.0 {
                    best = (cost, axis, s);
                }
            }
        }
        let parent_area = bounds.half_area().max(f32::MIN_POSITIVE);
        let split_cost = C_TRAV + best.0 / parent_area;
        let leaf_cost = n as f32;
        if n <= self.cfg.max_leaf && (leaf_cost <= split_cost || !best.0.is_finite()) {
            return BNode::Leaf { bounds, start, count: n as u32 };
        }
        let mid = if best.0.is_finite() {
            let (axis, s) = (best.1, best.2);
            let lo = cb.min[axis];
            let scale = BINS as f32 / ext[axis];
            let c = self.centroids;
            partition(idx, |i| ((((c[i as usize][axis] - lo) * scale) as usize).min(BINS - 1)) < s)
        } else {
            n / 2 // all centroids coincide: split the list in two
        };
        let (l, r) = idx.split_at_mut(mid);
        let (ln, rn) = if n > self.cfg.parallel_above {
            rayon::join(|| self.build(l, start), || self.build(r, start + mid as u32))
        } else {
            (self.build(l, start), self.build(r, start + mid as u32))
        };
        BNode::Inner { bounds, kids: Box::new([ln, rn]) }
    }
}

/// In-place partition; returns the number of elements for which `pred` holds (they come first).
fn partition(v: &mut [u32], pred: impl Fn(u32) -> bool) -> usize {
    let mut i = 0;
    let mut j = v.len();
    while i < j {
        if pred(v[i]) {
            i += 1;
        } else {
            j -= 1;
            v.swap(i, j);
        }
    }
    i
}

/// Collapses the binary tree into 4-wide nodes (pre-order); returns the depth.
fn collapse(root: &BNode, out: &mut Vec<Node4B>) -> u32 {
    match root {
        BNode::Leaf { bounds, start, count } => {
            // A tree that is a single leaf: a root node with one leaf child.
            out.push(Node4B {
                bounds: [*bounds, Aabb::EMPTY, Aabb::EMPTY, Aabb::EMPTY],
                kids: [Kid::Leaf { start: *start, count: *count }, Kid::Empty, Kid::Empty, Kid::Empty],
            });
            1
        }
        BNode::Inner { .. } => collapse_inner(root, out),
    }
}

fn collapse_inner(node: &BNode, out: &mut Vec<Node4B>) -> u32 {
    let BNode::Inner { kids, .. } = node else { unreachable!() };
    let mut slots: Vec<&BNode> = vec![&kids[0], &kids[1]];
    while slots.len() < 4 {
        // Open the inner child with the largest surface area.
        let pick = slots
            .iter()
            .enumerate()
            .filter(|(_, n)| matches!(n, BNode::Inner { .. }))
            .max_by(|a, b| a.1.bounds().half_area().total_cmp(&b.1.bounds().half_area()))
            .map(|(i, _)| i);
        let Some(i) = pick else { break };
        let BNode::Inner { kids, .. } = slots[i] else { unreachable!() };
        slots[i] = &kids[0];
        slots.insert(i + 1, &kids[1]);
    }
    let me = out.len();
    out.push(Node4B { bounds: [Aabb::EMPTY; 4], kids: [Kid::Empty; 4] });
    let mut depth = 0;
    for (k, s) in slots.iter().enumerate() {
        out[me].bounds[k] = *s.bounds();
        out[me].kids[k] = match s {
            BNode::Leaf { start, count, .. } => Kid::Leaf { start: *start, count: *count },
            BNode::Inner { .. } => {
                let child = out.len() as u32;
                depth = depth.max(collapse_inner(s, out));
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
        let b = build_bvh4(&boxes, BvhConfig { max_leaf: 4, parallel_above: 1000 });
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
}
