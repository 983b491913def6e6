//! The trees over a group's instances: binary BVHs of instance boxes, built in core each
//! time instances move (the seed rebuilds its top level every frame): by binned SAH, or,
//! above [`LBVH`] instances, as a linear BVH in Morton order; walked by a scalar loop (a
//! group's tree is shallow beside an object's).

use megaray_base::{Aabb, Ray};

/// A node: its box, and either its children (the left one follows it, the right at
/// `index`) or a leaf of `count` instances from `index` of the tree's order. 32 bytes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct InstNode {
    pub(crate) bounds: Aabb,
    /// Instances in a leaf; 0 for an inner node.
    pub(crate) count: u32,
    pub(crate) index: u32,
}
const _: () = assert!(std::mem::size_of::<InstNode>() == 32);

/// Most instances in a leaf.
const LEAF: usize = 2;
/// Bins of the SAH sweep.
const BINS: usize = 16;
/// Subtrees over more instances than this are built on two threads.
const PARALLEL: usize = 8192;

/// A tree over boxes (`order` holds the indices of `boxes` in leaf order).
#[derive(Clone, Debug, Default)]
pub(crate) struct InstTree {
    pub(crate) nodes: Vec<InstNode>,
    pub(crate) order: Vec<u32>,
}

impl InstTree {
    /// The tree over `boxes` (empty ones are left out: they hold nothing to hit).
    #[cfg(test)]
    pub(crate) fn build(boxes: &[Aabb]) -> InstTree {
        let mut t = InstTree::default();
        t.rebuild(boxes, &mut Scratch::default());
        t
    }

    /// Makes this the tree over `boxes` (empty ones are left out: they hold nothing to
    /// hit), in this tree's arrays and `scratch` (kept from build to build: fresh memory
    /// costs a page fault per 4 KiB, more than the build itself).
    pub(crate) fn rebuild(&mut self, boxes: &[Aabb], scratch: &mut Scratch) {
        self.order.clear();
        if boxes.len() > LBVH {
            return self.rebuild_lbvh(boxes, scratch);
        }
        self.nodes.clear();
        let Scratch { refs, sorted, .. } = scratch;
        refs.clear();
        refs.extend(
            (0..boxes.len() as u32)
                .filter(|&i| !boxes[i as usize].is_empty())
                .map(|i| Ref { c: boxes[i as usize].center().into(), i }),
        );
        if refs.is_empty() {
            return;
        }
        // A binary tree with leaves of at most two holds at most 2n - 1 nodes; each subtree
        // is given exactly that many slots, so that the two sides fill disjoint ranges (the
        // unused slots are never reached).
        self.nodes.resize(2 * refs.len() - 1, InstNode { bounds: Aabb::EMPTY, count: 0, index: 0 });
        sorted.clear();
        sorted.extend_from_slice(refs);
        build_into(boxes, refs, sorted, 0, &mut self.nodes, 0);
        self.order.extend(refs.iter().map(|r| r.i));
    }

    /// [`InstTree::rebuild`] of many boxes: the linear BVH over their Morton order (the
    /// codes made on all threads, sorted with the boxes' indices, which are all the tree
    /// needs).
    fn rebuild_lbvh(&mut self, boxes: &[Aabb], scratch: &mut Scratch) {
        use rayon::prelude::*;
        let Scratch { keys, tmp, in_order, .. } = scratch;
        // The codes quantize the centres over a box: the last build's box, where there was
        // one (a frame's moves shift it little; a centre outside it is clamped to its edge,
        // which costs the tree some quality, never a hit), else the centres' own.
        let cb = match self.nodes.first() {
            Some(root) if !root.bounds.is_empty() => root.bounds,
            _ => boxes
                .par_iter()
                .with_min_len(1 << 15)
                .filter(|b| !b.is_empty())
                .map(|b| {
                    let c = b.center().into();
                    Aabb { min: c, max: c }
                })
                .reduce(|| Aabb::EMPTY, |a, b| a.union(&b)),
        };
        let ext = cb.extent();
        let scale: [f32; 3] = std::array::from_fn(|k| if ext[k] > 0.0 { 1023.0 / ext[k] } else { 0.0 });
        // Empty boxes get the greatest key, are sorted last and cut off.
        boxes
            .par_iter()
            .with_min_len(1 << 15)
            .enumerate()
            .map(|(i, b)| {
                if b.is_empty() {
                    return u64::MAX;
                }
                let c = b.center();
                let q = |k: usize| (((c[k] - cb.min[k]) * scale[k]).max(0.0) as u32).min(1023);
                ((spread(q(0)) | (spread(q(1)) << 1) | (spread(q(2)) << 2)) as u64) << 32 | i as u64
            })
            .collect_into_vec(keys);
        radix_sort_high(keys, tmp);
        keys.truncate(keys.partition_point(|&k| k != u64::MAX));
        if keys.is_empty() {
            self.nodes.clear();
            return;
        }
        self.nodes.resize(2 * keys.len() - 1, InstNode { bounds: Aabb::EMPTY, count: 0, index: 0 });
        // The boxes gathered in the tree's order on all threads (many loads in flight at
        // once), so that the build reads them in order: its leaves' loads were a third of
        // its time (docs/PERF.md, "Instances").
        keys.par_iter().with_min_len(1 << 14).map(|&k| boxes[k as u32 as usize]).collect_into_vec(in_order);
        build_lbvh(in_order, keys, 0, &mut self.nodes, 0);
        self.order.extend(keys.iter().map(|&k| k as u32));
    }

    /// Calls `visit(instance, t_near)` for each instance whose leaf box `ray` enters within
    /// `[t_min, t_max)`, nearest boxes first, `t_max` read again after each visit (`visit`
    /// lowers it as hits are found); stops when `visit` returns false.
    #[inline]
    pub(crate) fn walk(&self, ray: &Ray, t_max: &dyn Fn() -> f32, mut visit: impl FnMut(u32) -> bool) {
        if self.nodes.is_empty() {
            return;
        }
        let inv = ray.dir.recip();
        let t0 = megaray_base::t_start(ray.t_min);
        let enter = |b: &Aabb, t1: f32| -> Option<f32> {
            let (mut near, mut far) = (t0, t1);
            for k in 0..3 {
                let a = (b.min[k] - ray.org[k]) * inv[k];
                let c = (b.max[k] - ray.org[k]) * inv[k];
                // `max`/`min` skip a NaN (0 * inf: the origin in the slab's plane, the ray
                // along it): that axis then cuts nothing, which is never too strict.
                near = near.max(a.min(c));
                far = far.min(a.max(c) * (1.0 + 4.0 * f32::EPSILON));
            }
            (near <= far).then_some(near)
        };
        // The stack on the machine stack; a tree deeper than it spills to the heap.
        let mut fixed = [(0u32, 0f32); 64];
        let mut sp = 0;
        let mut spill: Vec<(u32, f32)> = Vec::new();
        fn push(e: (u32, f32), fixed: &mut [(u32, f32); 64], sp: &mut usize, spill: &mut Vec<(u32, f32)>) {
            if *sp == fixed.len() {
                spill.extend_from_slice(&fixed[..]);
                *sp = 0;
            }
            fixed[*sp] = e;
            *sp += 1;
        }
        if let Some(t) = enter(&self.nodes[0].bounds, t_max()) {
            push((0, t), &mut fixed, &mut sp, &mut spill);
        }
        loop {
            if sp == 0 {
                // Refill from the spill (only a degenerate, very deep tree has one).
                let n = spill.len().min(fixed.len());
                if n == 0 {
                    return;
                }
                fixed[..n].copy_from_slice(&spill[spill.len() - n..]);
                spill.truncate(spill.len() - n);
                sp = n;
            }
            sp -= 1;
            let (i, t) = fixed[sp];
            if t > t_max() {
                continue;
            }
            let n = &self.nodes[i as usize];
            if n.count > 0 {
                for &inst in &self.order[n.index as usize..(n.index + n.count) as usize] {
                    if !visit(inst) {
                        return;
                    }
                }
                continue;
            }
            let (l, r) = (i + 1, n.index);
            let tm = t_max();
            match (enter(&self.nodes[l as usize].bounds, tm), enter(&self.nodes[r as usize].bounds, tm)) {
                (Some(a), Some(b)) => {
                    // The nearer popped first.
                    let (near, far) = if a <= b { ((l, a), (r, b)) } else { ((r, b), (l, a)) };
                    push(far, &mut fixed, &mut sp, &mut spill);
                    push(near, &mut fixed, &mut sp, &mut spill);
                }
                (Some(a), None) => push((l, a), &mut fixed, &mut sp, &mut spill),
                (None, Some(b)) => push((r, b), &mut fixed, &mut sp, &mut spill),
                (None, None) => {}
            }
        }
    }
}

/// An instance being sorted into the tree: its box's centre and its index. 16 bytes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ref {
    c: [f32; 3],
    i: u32,
}

/// Groups of more instances than this are built as a linear BVH (Lauterbach et al. 2009:
/// sorted along a Morton curve, split where the codes' highest differing bit changes),
/// several times faster than binning at every level, for the trees that must be rebuilt
/// every frame when many instances move (docs/PERF.md, "Instances").
const LBVH: usize = 1 << 16;

/// The arrays a build works in, kept from one rebuild to the next (fresh memory costs a
/// page fault per 4 KiB).
#[derive(Default)]
pub(crate) struct Scratch {
    refs: Vec<Ref>,
    sorted: Vec<Ref>,
    keys: Vec<u64>,
    tmp: Vec<u64>,
    /// The boxes in the keys' order.
    in_order: Vec<Aabb>,
}

/// The low 10 bits of `v` spread to every third bit (a Morton code's one axis).
fn spread(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x030000ff;
    x = (x | (x << 8)) & 0x0300f00f;
    x = (x | (x << 4)) & 0x030c30c3;
    (x | (x << 2)) & 0x09249249
}

/// Sorts `keys` by their high 32 bits (30-bit Morton codes): one pass on the codes' top 10
/// bits into 1024 buckets, then each bucket on its own, on all threads, by the other 20 bits
/// (two 10-bit passes, least significant first), through `tmp`.
fn radix_sort_high(keys: &mut Vec<u64>, tmp: &mut Vec<u64>) {
    use rayon::prelude::*;
    if tmp.len() != keys.len() {
        tmp.resize(keys.len(), 0);
    }
    let digit = |k: u64, shift: u32| ((k >> shift) & 0x3ff) as usize;
    let mut count = vec![0usize; 1025];
    for &k in keys.iter() {
        count[digit(k, 52) + 1] += 1;
    }
    for d in 0..1024 {
        count[d + 1] += count[d];
    }
    let starts = count.clone();
    for &k in keys.iter() {
        let d = digit(k, 52);
        tmp[count[d]] = k;
        count[d] += 1;
    }
    // The buckets as disjoint slices of both arrays.
    let mut pairs = Vec::with_capacity(1024);
    let (mut a, mut b): (&mut [u64], &mut [u64]) = (&mut tmp[..], &mut keys[..]);
    for d in 0..1024 {
        let len = starts[d + 1] - starts[d];
        let (x, rest_a) = std::mem::take(&mut a).split_at_mut(len);
        let (y, rest_b) = std::mem::take(&mut b).split_at_mut(len);
        (a, b) = (rest_a, rest_b);
        if len > 1 {
            pairs.push((x, y));
        }
    }
    pairs.par_iter_mut().with_min_len(8).for_each(|(bucket, spare)| {
        for (from_bucket, shift) in [(true, 32u32), (false, 42)] {
            let (src, dst): (&[u64], &mut [u64]) =
                if from_bucket { (&bucket[..], &mut spare[..]) } else { (&spare[..], &mut bucket[..]) };
            let mut c = [0usize; 1025];
            for &k in src {
                c[digit(k, shift) + 1] += 1;
            }
            for d in 0..1024 {
                c[d + 1] += c[d];
            }
            for &k in src {
                let d = digit(k, shift);
                dst[c[d]] = k;
                c[d] += 1;
            }
        }
    });
    // Sorted in `tmp` (each bucket went there and back).
    std::mem::swap(keys, tmp);
}

/// The linear BVH over `keys` (Morton code high, box index low, sorted; the first being
/// `at_order` of the tree's order) and their `boxes` (in the same order) into `nodes[0]` and
/// the slots after it (laid out as [`build_into`] does); returns its box.
fn build_lbvh(boxes: &[Aabb], keys: &[u64], at_order: u32, nodes: &mut [InstNode], at: u32) -> Aabb {
    let n = keys.len();
    if n <= LEAF {
        let bounds = boxes.iter().fold(Aabb::EMPTY, |b, x| b.union(x));
        nodes[0] = InstNode { bounds, count: n as u32, index: at_order };
        return bounds;
    }
    let (first, last) = ((keys[0] >> 32) as u32, (keys[n - 1] >> 32) as u32);
    let mid = if first == last {
        n / 2
    } else {
        // The first code with the highest differing bit set.
        let bit = 31 - (first ^ last).leading_zeros();
        keys.partition_point(|&c| (c >> 32) as u32 & (1 << bit) == 0).clamp(1, n - 1)
    };
    let left_slots = 2 * mid - 1;
    let (_, rest) = nodes.split_at_mut(1);
    let (ln, rn) = rest.split_at_mut(left_slots);
    let (lk, rk) = keys.split_at(mid);
    let (lb, rb) = boxes.split_at(mid);
    let mut left = move || build_lbvh(lb, lk, at_order, ln, at + 1);
    let mut right = move || build_lbvh(rb, rk, at_order + mid as u32, rn, at + 1 + left_slots as u32);
    let (a, b) = if n > PARALLEL { rayon::join(left, right) } else { (left(), right()) };
    let bounds = a.union(&b);
    nodes[0] = InstNode { bounds, count: 0, index: at + 1 + left_slots as u32 };
    bounds
}

/// Subtrees over more instances than this choose their split on a sample of them (every
/// k-th), so that a level of the build is one pass over its instances.
const SAMPLED: usize = 4096;

/// Builds the subtree over `refs` (whose first element is `refs_at` of the whole order)
/// into `nodes[0]` and the slots after it; returns its box.
fn build_into(
    boxes: &[Aabb],
    refs: &mut [Ref],
    scratch: &mut [Ref],
    refs_at: u32,
    nodes: &mut [InstNode],
    at: u32,
) -> Aabb {
    if refs.len() <= LEAF {
        let bounds = refs.iter().fold(Aabb::EMPTY, |b, r| b.union(&boxes[r.i as usize]));
        nodes[0] = InstNode { bounds, count: refs.len() as u32, index: refs_at };
        return bounds;
    }
    let mid = split(boxes, refs, scratch);
    let parallel = refs.len() > PARALLEL;
    let (lr, rr) = refs.split_at_mut(mid);
    let (ls, rs) = scratch.split_at_mut(mid);
    let left_slots = 2 * lr.len() - 1;
    let (_, rest) = nodes.split_at_mut(1);
    let (ln, rn) = rest.split_at_mut(left_slots);
    let mut left = move || build_into(boxes, lr, ls, refs_at, ln, at + 1);
    let mut right = move || build_into(boxes, rr, rs, refs_at + mid as u32, rn, at + 1 + left_slots as u32);
    let (a, b) = if parallel { rayon::join(left, right) } else { (left(), right()) };
    let bounds = a.union(&b);
    nodes[0] = InstNode { bounds, count: 0, index: at + 1 + left_slots as u32 };
    bounds
}

/// Partitions `refs` by the binned SAH on the centres' widest axis (chosen on a sample of
/// them above [`SAMPLED`]); returns the size of the left side (the middle when the centres
/// coincide or no split is cheaper).
fn split(boxes: &[Aabb], refs: &mut [Ref], scratch: &mut [Ref]) -> usize {
    let step = refs.len().div_ceil(SAMPLED);
    let sample = || refs.iter().step_by(step);
    let mut cb = Aabb::EMPTY;
    for r in sample() {
        cb.grow_point(r.c);
    }
    let axis = cb.longest_axis();
    let (lo, ext) = (cb.min[axis], cb.max[axis] - cb.min[axis]);
    if ext.is_nan() || ext <= 0.0 {
        return refs.len() / 2;
    }
    let scale = BINS as f32 / ext;
    let bin = move |r: &Ref| (((r.c[axis] - lo) * scale).max(0.0) as usize).min(BINS - 1);
    let mut bb = [Aabb::EMPTY; BINS];
    let mut bc = [0u32; BINS];
    for r in sample() {
        let b = bin(r);
        bb[b].grow(&boxes[r.i as usize]);
        bc[b] += 1;
    }
    let total: u32 = bc.iter().sum();
    // Costs of splitting after bin k: right sides by a sweep from the end.
    let mut right = [0.0f32; BINS];
    let (mut acc, mut n) = (Aabb::EMPTY, 0u32);
    for k in (1..BINS).rev() {
        acc.grow(&bb[k]);
        n += bc[k];
        right[k] = if n > 0 { acc.half_area() * n as f32 } else { 0.0 };
    }
    let (mut acc, mut n) = (Aabb::EMPTY, 0u32);
    let (mut best, mut best_k) = (f32::INFINITY, 0);
    for k in 0..BINS - 1 {
        acc.grow(&bb[k]);
        n += bc[k];
        let cost = if n > 0 { acc.half_area() * n as f32 } else { 0.0 } + right[k + 1];
        if n > 0 && n < total && cost < best {
            (best, best_k) = (cost, k);
        }
    }
    if best == f32::INFINITY {
        return refs.len() / 2;
    }
    // Partition through `scratch`, without branches (which side an instance goes is a
    // coin toss a branch would mispredict): each is written to both ends, and the end it
    // belongs to moves on.
    let n_refs = refs.len();
    let (mut i, mut j) = (0, n_refs);
    for &r in refs.iter() {
        let left = bin(&r) <= best_k;
        scratch[i] = r;
        scratch[j - 1] = r;
        i += left as usize;
        j -= !left as usize;
    }
    refs.copy_from_slice(scratch);
    if i == 0 || i == refs.len() {
        // The sample's split left one side empty on the whole.
        return refs.len() / 2;
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;
    use megaray_base::Vec3;

    /// Every box the ray enters is visited, whatever the tree's shape.
    #[test]
    fn walks_visit_every_box_the_ray_enters() {
        let mut s = 7u32;
        let mut rnd = || {
            s = megaray_base::hash32(s);
            megaray_base::u01(s)
        };
        for n in [1usize, 2, 3, 17, 1000, 20_000, 70_000] {
            let boxes: Vec<Aabb> = (0..n)
                .map(|_| {
                    let c = Vec3::new(rnd(), rnd(), rnd()) * 100.0;
                    let h = Vec3::splat(rnd() * 3.0 + 0.01);
                    Aabb { min: (c - h).into(), max: (c + h).into() }
                })
                .collect();
            let t = InstTree::build(&boxes);
            for _ in 0..50 {
                let o = Vec3::new(rnd(), rnd(), rnd()) * 100.0;
                let d = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
                let ray = Ray::new(o, d);
                let mut seen = vec![false; n];
                t.walk(&ray, &|| f32::INFINITY, |i| {
                    seen[i as usize] = true;
                    true
                });
                let rb = |b: &Aabb| {
                    let (mut near, mut far) = (0.0f32, f32::INFINITY);
                    for k in 0..3 {
                        let (a, c) = ((b.min[k] - o[k]) / d[k], (b.max[k] - o[k]) / d[k]);
                        near = near.max(a.min(c));
                        far = far.min(a.max(c));
                    }
                    near <= far
                };
                for (i, b) in boxes.iter().enumerate() {
                    if rb(b) {
                        assert!(seen[i], "n {n}: box {i} entered but not visited");
                    }
                }
            }
        }
    }

    /// The radix sort orders by the codes (high 32 bits) and keeps equal codes in their
    /// order (the low bits, indices, ascending as given).
    #[test]
    fn keys_sort_by_code_stably() {
        let mut s = 3u32;
        for n in [0usize, 1, 5, 1000, 200_000] {
            let mut keys: Vec<u64> = (0..n as u64)
                .map(|i| {
                    s = megaray_base::hash32(s);
                    // Few distinct codes in the small cases, all 30 bits in the large.
                    let code = if n < 2000 { s % 7 } else { s & 0x3fff_ffff };
                    ((code as u64) << 32) | i
                })
                .collect();
            let mut want = keys.clone();
            want.sort_by_key(|k| (k >> 32, k & 0xffff_ffff));
            radix_sort_high(&mut keys, &mut Vec::new());
            assert_eq!(keys, want, "n {n}");
        }
    }

    /// A linear BVH rebuilt after its boxes moved far out of the box it was built over
    /// (the codes' range comes from the last build) still leads every ray to every box it
    /// enters.
    #[test]
    fn rebuilt_after_a_move_visits_every_box_the_ray_enters() {
        let mut s = 11u32;
        let mut rnd = || {
            s = megaray_base::hash32(s);
            megaray_base::u01(s)
        };
        let n = LBVH + 5000;
        let mut boxes: Vec<Aabb> = (0..n)
            .map(|_| {
                let c = Vec3::new(rnd(), rnd(), rnd()) * 100.0;
                Aabb { min: (c - Vec3::splat(0.5)).into(), max: (c + Vec3::splat(0.5)).into() }
            })
            .collect();
        let mut tree = InstTree::default();
        let mut scratch = Scratch::default();
        tree.rebuild(&boxes, &mut scratch);
        // Half the boxes move 300 units away (far outside the first build's box), and every
        // tenth is emptied (an instance of an empty group: nothing to hit).
        for b in boxes.iter_mut().step_by(2) {
            *b = Aabb { min: (b.lo() + Vec3::X * 300.0).into(), max: (b.hi() + Vec3::X * 300.0).into() };
        }
        for b in boxes.iter_mut().step_by(10) {
            *b = Aabb::EMPTY;
        }
        tree.rebuild(&boxes, &mut scratch);
        assert_eq!(tree.order.len(), n - n.div_ceil(10), "empty boxes are left out");
        for _ in 0..200 {
            let o = Vec3::new(rnd() * 400.0, rnd() * 100.0, rnd() * 100.0);
            let d = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
            let ray = Ray::new(o, d);
            let mut seen = vec![false; n];
            tree.walk(&ray, &|| f32::INFINITY, |i| {
                seen[i as usize] = true;
                true
            });
            for (i, b) in boxes.iter().enumerate() {
                let (mut near, mut far) = (0.0f32, f32::INFINITY);
                for k in 0..3 {
                    let (a, c) = ((b.min[k] - o[k]) / d[k], (b.max[k] - o[k]) / d[k]);
                    near = near.max(a.min(c));
                    far = far.min(a.max(c));
                }
                assert!(b.is_empty() || near > far || seen[i], "box {i} entered but not visited");
                assert!(!(b.is_empty() && seen[i]), "empty box {i} visited");
            }
        }
    }
}
