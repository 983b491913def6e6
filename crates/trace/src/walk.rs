//! The walk: the single-ray kernel's hot loop ([`Tracer::walk`]), its leaf tests, its state
//! between runs ([`Walk`]) and what it hands back ([`Event`], [`Found`]), compiled once per
//! instruction set (the `walk_*` and `new_ray_*` functions the kernel tables name).

use glam::Vec3A;
use megaray_base::{t_start, Ray, TriHit};
use megaray_scene::format::{ChildRef, Node8};

use crate::boxes::{RayBox, FAR_EPS, ROWS, W};
use crate::driver::{Scratch, Streak};
use crate::isa::GENERIC;
use crate::stats;
use crate::tracer::{Entry, Tracer, STACK, TOP};
use crate::tri::{lanes, lanes8, Exact, RayTri4, Splats};

impl<'s> Tracer<'s> {
    /// The next blocks of a leaf (`left` triangles from the block at `unit`) against the
    /// ray: two at once by [`RayTri4::try_test8`] on AVX when two or more remain, else one by
    /// [`RayTri4::try_test`]. Says how many blocks it tested; a hit's lane counts across them.
    /// With `dyn_rows` (a constant where it inlines), the tests read the rows by the ray's
    /// axes ([`RayTri4::try_test_dyn`]).
    #[inline(always)]
    pub(crate) fn test_blocks<const AVX: bool, const ANY: bool>(
        &self,
        dyn_rows: bool,
        rt: &RayTri4,
        sp: &Splats,
        unit: u64,
        left: u32,
        t_max: f32,
    ) -> (Result<Option<(usize, TriHit)>, Exact>, u32) {
        #[cfg(target_arch = "x86_64")]
        if AVX && left > 4 {
            stats::count(|s| s.blocks += 2);
            let (b0, b1, lanes) = (self.walk_block_at(unit), self.walk_block_at(unit + 9), lanes8(left));
            return match dyn_rows {
                true => (rt.try_test8_dyn::<ANY>(sp, b0, b1, lanes, t_max), 2),
                false => (rt.try_test8::<ANY>(sp, b0, b1, lanes, t_max), 2),
            };
        }
        stats::count(|s| s.blocks += 1);
        let (b, lanes) = (self.walk_block_at(unit), lanes(left));
        match dyn_rows {
            true => (rt.try_test_dyn(sp, b, lanes, t_max), 1),
            false => (rt.try_test(sp, b, lanes, t_max), 1),
        }
    }

    /// The hot loop of the single-ray kernel. Near-first: of the children a node's box test
    /// hits, the nearest is visited next, the others are pushed far to near (for `ANY`, in slot
    /// order from the far side of the splits, [`FAR_HIGH`]). Leaves are children like any
    /// other, so they too are tested nearest first.
    ///
    /// It calls no function (all it uses is inlined, bounds checks aside, which never
    /// return): a call would clobber every vector register, and the compiler would then keep
    /// the ray's constants on the machine stack and reload them at every node (docs/PERF.md,
    /// "A hot loop that calls nothing"). What is rare returns to the driver
    /// as an [`Event`], the walk's state saved in `w`: a link into a tile that is paged or not
    /// checked yet, an edge exactly on the ray, a full or empty fixed stack, an any-hit.
    /// Entries popped from a tile other than the open one reopen it without a check on an
    /// unpaged tracer: the traversal entered it through a link before. With `ALL` (every
    /// tile checked, [`Tracer::all_checked`]) there is nothing to check at all: a link is
    /// followed as an inner node is, and no tile is kept: `c` stays [`TOP`], and a hit is
    /// credited to its tile when made a [`Hit`] (if ever: `occluded` needs none), from its
    /// block's position ([`Scene::slot_of_unit`]: one lookup per hit, where keeping the
    /// tile cost six instructions per node, the tile of every link chosen without a branch
    /// and that of every popped entry moved in).
    #[inline(always)]
    pub(crate) fn walk<const AVX: bool, const ANY: bool, const ALL: bool, const OCT: usize>(
        &self,
        w: &mut Walk<'_>,
        ray: &Ray,
    ) -> Event {
        // The ray's constants, made here rather than passed in: the loop then holds them in
        // registers without a copy (events are rare, and the few that come back remake them).
        let mut rb = RayBox::new(ray);
        if OCT < 8 {
            // The ray's octant (`walk_on` chose this kernel by it), as a constant.
            rb.rows = &ROWS[OCT];
        }
        // Never below +0 ([`Ray::t_min`]): the box tests need it ([`RayBox::test`]).
        let t_min = t_start(ray.t_min);
        // The generic kernel (`walk_on`) reads the triangles' rows by the ray's axes: no
        // choice by them, per ray or per block.
        let rt = match OCT {
            // SAFETY: `AVX` kernels run only on CPUs with AVX2 (`Tracer::kernel_table`).
            #[cfg(target_arch = "x86_64")]
            GENERIC if AVX => unsafe { RayTri4::with_axis_avx(ray, Vec3A::from_array(rb.inv)) },
            GENERIC => RayTri4::with_axis_unbranched(ray, &rb.inv),
            _ => RayTri4::with_inv(ray, &rb.inv),
        };
        let shared = rb.splats::<AVX>(t_min);
        // An any-hit walk's order of a node's children: a constant in an octant's kernel.
        let far_high = FAR_HIGH[if OCT < 8 { OCT } else { RayBox::octant(ray) }];
        // With `ALL` no tile is kept: [`TOP`] throughout, a constant (no register for it).
        let mut c = if ALL { TOP } else { w.c };
        let mut sp = w.sp;
        let mut t_best = w.t_best;
        // The closest hit widened as box exits are ([`FAR_EPS`]), for the box tests and for
        // skipping popped entries beyond it.
        let mut t_wide = t_best * FAR_EPS;
        let mut next = w.next.take();
        // One place pops, and it asks first whether an interrupted entry is pending. Both
        // ways of not asking (a pop at each dead end; the pending entry pushed before the
        // loop) made any-hit rays slower: the compiler then copies the pop into every dead
        // end, and those branches predict worse (docs/PERF.md, "One pop site").
        let event = 'walk: loop {
            let e = match next.take() {
                Some(e) => e,
                None => {
                    if sp == 0 {
                        break Event::Empty;
                    }
                    sp -= 1;
                    let e = w.fixed[sp % STACK];
                    // Beyond the closest hit: skipped. (An any-hit query's `t_best` is the
                    // ray's end until it ends, so its entries are never beyond it.)
                    if !ANY && e.t > t_wide {
                        continue;
                    }
                    e
                }
            };
            // An inner node or a leaf of the tile the entry was pushed from, which this
            // traversal entered before: unpaged, it is still there and checked. Paged, it may
            // have been evicted while the ray was pending: the pager is asked again (a ray
            // needs one tile at a time). (A link or part names its own tile.)
            if ALL {
                // Every tile is checked: nothing to open, and no tile kept ([`Tracer::walk`]).
            } else if (e.r as i64) >= 0 && e.arr != c {
                if self.pager.is_none() || e.arr == TOP {
                    c = e.arr;
                } else {
                    next = Some(e);
                    break 'walk Event::Enter(e.arr);
                }
            }
            // Descend from `e`, always into the nearest child hit (which lies in the open
            // tile, or names its own).
            let mut r = e.r;
            loop {
                // `ChildRef::decode`, written out, its kind's two bits tested one at a time in
                // order of frequency (as a `match`, the compiler jumps through a table, an
                // indirect branch that predicts worse). An empty slot is caught with the parts.
                // References hold absolute positions: no tile needs looking up to follow one.
                let leaf_or_part = r & (1 << 62) != 0;
                let node = if ALL && !leaf_or_part {
                    // Every tile checked: an inner node, or a link, followed alike.
                    r & ChildRef::MAX_NODE
                } else if (r as i64) >= 0 {
                    if leaf_or_part {
                        // A leaf: `count` triangles from the block at `unit`.
                        let (mut unit, mut left) = (r & ChildRef::MAX_UNIT, ((r >> 40) & 0xff) as u32);
                        while left > 0 {
                            let (found, blocks) =
                                self.test_blocks::<AVX, ANY>(OCT == GENERIC, &rt, &shared, unit, left, t_best);
                            match found {
                                Ok(None) => {}
                                Ok(Some((lane, h))) => {
                                    t_best = h.t;
                                    t_wide = h.t * FAR_EPS;
                                    // Lanes 4..8 are the second block's.
                                    w.best = Some(Found::new(h, c, unit + 9 * (lane / 4) as u64, lane % 4));
                                    if ANY {
                                        break 'walk Event::Hit;
                                    }
                                }
                                Err(Exact) => break 'walk Event::Exact { unit, count: left },
                            }
                            left = left.saturating_sub(4 * blocks);
                            unit += 9 * blocks as u64;
                        }
                        continue 'walk;
                    }
                    r & ChildRef::MAX_NODE
                } else {
                    // A link (tile, node; the top-level tree links to part roots), or an
                    // empty slot (all ones, the only reference of kind 3 a checked tile has).
                    if leaf_or_part {
                        continue 'walk;
                    }
                    let (arr, node) = (((r >> 36) as u32) & ChildRef::MAX_TILE, r & ChildRef::MAX_NODE);
                    if arr != c {
                        if self.checked.get(arr) {
                            // The common crossing: an unpaged tile already checked.
                            stats::count(|s| s.tiles_entered += 1);
                            c = arr;
                        } else {
                            // (`arr` of a link entry is not read: it names its own tile.)
                            next = Some(Entry { r, arr: c, t: f32::NEG_INFINITY });
                            break 'walk Event::Enter(arr);
                        }
                    }
                    node
                };
                // Read without a bounds check: node positions were checked with the tile.
                let node = self.walk_node_at(node);
                // The node's last line (its child references, which the box test does not
                // read) asked for with the boxes, not after the test has picked a child: a
                // second miss in a row on a node not in cache (docs/PERF.md, "Prefetching").
                let refs = std::mem::offset_of!(Node8, child);
                megaray_base::prefetch_addr((node as *const Node8 as *const u8).wrapping_add(refs));
                let arr = c;
                stats::count(|s| s.nodes += 1);
                let (dist, mask) = rb.test::<AVX>(node, t_min, t_wide);
                if mask == 0 {
                    continue 'walk;
                }
                let k0 = mask.trailing_zeros();
                let m1 = mask & (mask - 1);
                if m1 == 0 {
                    r = node.child[k0 as usize];
                    continue;
                }
                // Two or more children: pushes ahead. (Asked here, not at every node:
                // most visits go on into one child and push nothing.)
                if sp > STACK - W {
                    // No room for seven more entries: the node is visited again after
                    // the driver has made room.
                    next = Some(Entry { r, arr: c, t: f32::NEG_INFINITY });
                    break 'walk Event::Full;
                }
                // (An any-hit query reads no entry distance: none is kept.)
                let at =
                    |k: u32| Entry { r: node.child[k as usize], arr, t: if ANY { 0.0 } else { dist.0[k as usize] } };
                let mut push = |x: Entry| {
                    self.prefetch(x.r);
                    w.fixed[sp % STACK] = x;
                    sp += 1;
                };
                if ANY {
                    // Any hit ends the ray, so no sorting by distance; but the far side of
                    // the node's splits first ([`FAR_HIGH`]): slots from the last down (the
                    // last next, the others pushed from the first up), or from the first up.
                    let first = if far_high { 31 - mask.leading_zeros() } else { k0 };
                    let mut m = mask & !(1 << first);
                    while m != 0 {
                        let k = if far_high { m.trailing_zeros() } else { 31 - m.leading_zeros() };
                        push(at(k));
                        m &= !(1 << k);
                    }
                    r = node.child[first as usize];
                    continue;
                }
                let (a, b) = (at(k0), at(m1.trailing_zeros()));
                let (near, far) = if b.t < a.t { (b, a) } else { (a, b) };
                let m2 = m1 & (m1 - 1);
                if m2 == 0 {
                    push(far);
                    r = near.r;
                    continue;
                }
                // Three or more: pushed as they come and sorted in place on the stack, far to
                // near (insertion sort, at most eight: no array of them to fill and copy);
                // the nearest, on top, is taken off again as the next to visit.
                push(far);
                push(near);
                let base = sp - 2;
                let mut m = m2;
                while m != 0 {
                    let x = at(m.trailing_zeros());
                    m &= m - 1;
                    self.prefetch(x.r);
                    let mut j = sp;
                    while j > base && w.fixed[(j - 1) % STACK].t < x.t {
                        w.fixed[j % STACK] = w.fixed[(j - 1) % STACK];
                        j -= 1;
                    }
                    w.fixed[j % STACK] = x;
                    sp += 1;
                }
                sp -= 1;
                r = w.fixed[sp % STACK].r;
            }
        };
        w.c = c;
        w.sp = sp;
        w.t_best = t_best;
        w.next = next;
        event
    }
}

/// Per octant of a ray's direction, whether an any-hit walk visits a node's children from its
/// last slot to its first (else first to last; every kernel alike, the assembly one too).
/// Slots hold a binary tree's subtrees in order, the lower side of each split first, so for a
/// ray going up along most axes (at most one negative component) the far side of most splits
/// lies in the higher slots. Far side first, because an any-hit ray mostly starts on a
/// surface and leaves it: what blocks it seldom lies next to its origin, where the near
/// children are (docs/PERF.md, "Any-hit order").
pub(crate) const FAR_HIGH: [bool; 8] = {
    let mut t = [false; 8];
    let mut oct = 0;
    while oct < 8 {
        t[oct] = (oct as u32).count_ones() <= 1;
        oct += 1;
    }
    t
};

/// [`Tracer::walk`] compiled for AVX2 (one [`Kernel`]): a function of its own, never inlined,
/// so that its registers are allocated for the loop alone. Free (not a method), so that it
/// is one function for tracers of every lifetime and fits the kernel table's type.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline(never)]
pub(crate) fn walk_avx2<const ANY: bool, const ALL: bool, const OCT: usize>(
    t: &Tracer<'_>,
    w: &mut Walk<'_>,
    ray: &Ray,
) -> Event {
    t.walk::<true, ANY, ALL, OCT>(w, ray)
}

/// [`walk_avx2`] compiled for AVX-512: the same operations (256 bits wide), but 32 vector
/// registers, so that the ray's constants stay in registers (with 16, four of them are kept
/// on the machine stack and reloaded at every node), and comparisons into mask registers
/// (docs/PERF.md, "The AVX-512 build").
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
#[inline(never)]
pub(crate) fn walk_avx512<const ANY: bool, const ALL: bool, const OCT: usize>(
    t: &Tracer<'_>,
    w: &mut Walk<'_>,
    ray: &Ray,
) -> Event {
    t.walk::<true, ANY, ALL, OCT>(w, ray)
}

/// [`Tracer::new_ray`] compiled for AVX2, as [`walk_avx2`] is.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline(never)]
pub(crate) fn new_ray_avx2<const ANY: bool, const OCT: usize>(
    t: &Tracer<'_>,
    s: &mut Scratch,
    ray: &Ray,
) -> Option<Found> {
    t.new_ray::<true, ANY, OCT>(s, ray)
}

/// [`Tracer::new_ray`] compiled for AVX-512, as [`walk_avx512`] is.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
#[inline(never)]
pub(crate) fn new_ray_avx512<const ANY: bool, const OCT: usize>(
    t: &Tracer<'_>,
    s: &mut Scratch,
    ray: &Ray,
) -> Option<Found> {
    t.new_ray::<true, ANY, OCT>(s, ray)
}

/// [`Tracer::walk`] on the baseline instruction set (SSE2 on x86-64).
#[inline(never)]
pub(crate) fn walk_baseline<const ANY: bool, const ALL: bool>(t: &Tracer<'_>, w: &mut Walk<'_>, ray: &Ray) -> Event {
    t.walk::<false, ANY, ALL, { usize::MAX }>(w, ray)
}

/// The single-ray kernel's state between runs of its hot loop ([`Tracer::walk`]).
pub(crate) struct Walk<'a> {
    /// The traversal stack (entries `..sp`); what does not fit is spilled by the driver.
    pub(crate) fixed: &'a mut [Entry; STACK],
    /// The thread's [`Scratch::streak`].
    pub(crate) streak: &'a mut Streak,
    pub(crate) sp: usize,
    /// The entry to visit before popping (the one an [`Event`] interrupted).
    pub(crate) next: Option<Entry>,
    /// The tile open (whose tile an inner node or leaf popped is, [`TOP`] for the top-level
    /// tree): what a hit is credited to, and what a paged walk must ask for again.
    pub(crate) c: u32,
    /// The distance of the closest hit so far (the ray's end when none).
    pub(crate) t_best: f32,
    pub(crate) best: Option<Found>,
    /// Not run yet: the first run tests the scene's box before anything else
    /// ([`Tracer::walk_on`]).
    pub(crate) fresh: bool,
}

impl<'a> Walk<'a> {
    /// A new ray's walk from `root` (and so, first, through the scene's box).
    #[inline(always)]
    pub(crate) fn new(scratch: &'a mut Scratch, root: Entry, t_max: f32) -> Walk<'a> {
        let c = TOP;
        let Scratch { stack: fixed, streak } = scratch;
        Walk { fixed, streak, sp: 0, next: Some(root), c, t_best: t_max, best: None, fresh: true }
    }
}

/// Why the hot loop returned to the driver.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Event {
    /// The stack is empty (the driver refills it from its spill, or the ray is done).
    Empty,
    /// An any-hit query found a hit.
    Hit,
    /// [`Walk::next`] needs node array `arr` opened (through [`Tracer::enter`]).
    Enter(u32),
    /// An edge exactly on the ray in the block at `unit` of a leaf, `count` triangles from
    /// there to its end, left to the double-precision reference.
    Exact { unit: u64, count: u32 },
    /// The fixed stack has no room for a node's children.
    Full,
}

/// The closest hit so far of the single-ray kernel, as little as the hot loop needs to
/// write: which lane of which block (of which tile), and the test's results. Made a [`Hit`]
/// at the end ([`Tracer::hit_of`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Found {
    pub(crate) t: f32,
    pub(crate) u: f32,
    pub(crate) v: f32,
    /// The block's tile, or [`TOP`] when the walk kept none (found then from `unit`).
    pub(crate) arr: u32,
    pub(crate) lane: u32,
    /// The block's position (`offset / 16`).
    pub(crate) unit: u64,
}

impl Found {
    #[inline(always)]
    pub(crate) fn new(h: TriHit, arr: u32, unit: u64, lane: usize) -> Found {
        Found { t: h.t, u: h.u, v: h.v, arr, lane: lane as u32, unit }
    }
}
