//! The [`Tracer`]: its set-up over a scene (or a pager), the traversal stack's entries, and
//! what the kernels share: opening tiles, prefetching children, reading nodes and blocks
//! from the node pool, turning a found lane into a [`Hit`].

use megaray_page::{Access, Pager};
use megaray_scene::format::{ChildRef, Node8, Tri4, NODE_BYTES};
use megaray_scene::{CheckedTiles, Scene, TileEntry};

use crate::boxes::W;
use crate::isa::{Isa, Kernel, Kernels, NewRay, KERNELS};
use crate::tri::{corners, Block};
use crate::walk::Found;
use crate::{stats, Hit};

/// Which node array a stack entry refers to.
pub(crate) const TOP: u32 = u32::MAX;
/// Capacity of the single-ray kernel's traversal stack on the machine stack ([`Walk::fixed`]);
/// deeper stacks spill to the heap.
pub(crate) const STACK: usize = 64;

/// A traversal stack entry: something to visit, and the entry distance of its box. Aligned
/// to its size, so that no entry of the stack straddles two cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub(crate) struct Entry {
    /// A [`ChildRef`]: an inner node or a leaf of node array `arr`, a link, or a part.
    pub(crate) r: u64,
    /// The tile `r` lies in ([`TOP`] for the top-level tree): the one the entry was pushed
    /// from.
    pub(crate) arr: u32,
    /// Entry distance of its box along the ray.
    pub(crate) t: f32,
}

const _: () = assert!(std::mem::size_of::<Entry>() == 16);

impl Entry {
    /// All zero bits: what unused stack slots hold (cheapest to initialise).
    pub(crate) const ZERO: Entry = Entry { r: 0, arr: 0, t: 0.0 };

    /// The root of part `p`, as the top-level tree links to it (in range: checked by
    /// `Scene::open`): where a traversal of that part alone starts.
    pub(crate) fn part_root(scene: &Scene, p: &megaray_scene::PartEntry) -> Entry {
        let root = scene.tiles()[p.root_tile as usize].node0() + p.root_node as u64;
        Entry { r: ChildRef::link(p.root_tile, root).0, arr: TOP, t: f32::NEG_INFINITY }
    }
}

/// What a popped [`Entry`] turned out to be, its tile opened.
pub(crate) enum Step<'a> {
    /// An inner node to test, in node array `arr`.
    Node(&'a Node8, u32),
    /// A leaf: `count` triangles from the block at `unit` (`offset / 16`) of the open tile.
    Leaf { unit: u64, count: u32 },
    /// Nothing to visit (an empty slot, a corrupt tile).
    Skip,
    /// Its tile is not resident (it has been requested).
    Missing(u32),
}

/// Traces rays through one scene. Cheap to create; share one across threads.
///
/// Two modes: [`Tracer::new`] reads the whole mapped file (the operating system pages on
/// demand, stalling the thread on a miss); [`Tracer::paged`] reads only tiles that a
/// [`Pager`] has made resident, and a ray that needs an absent tile comes back
/// [`Traced::Pending`] (its traversal state saved) from [`Tracer::try_intersect`] and
/// [`Tracer::try_occluded`], to be resumed with [`Tracer::resume`] once the tile arrived.
/// A paged tracer must be used under a [`megaray_page::Pin`] (see [`jobs`], which pins and
/// reschedules for you); its blocking [`Tracer::intersect`] and [`Tracer::occluded`] pin
/// themselves and wait for missing tiles.
pub struct Tracer<'s> {
    pub(crate) scene: &'s Scene,
    pub(crate) pager: Option<&'s Pager>,
    /// The tile directory (for hits: a tile's part and first slot).
    pub(crate) tiles: &'s [TileEntry],
    /// The whole file as nodes ([`Scene::node_pool`]; the file is a whole number of
    /// pages), which child references index directly (they hold absolute positions): inner
    /// nodes and links by node, triangle blocks by 16-byte unit of the same memory.
    pub(crate) nodes: &'s [Node8],
    /// The instruction set of the single-ray kernel (chosen once, at creation): the AVX2
    /// kernel on AVX2 machines, its AVX-512 build on AVX-512 ones, the baseline's otherwise.
    pub(crate) isa: Isa,
    /// Where traversals start: the top-level tree's root, or, when the scene has a single
    /// part, that part's root (the top level would only test the part's box again).
    pub(crate) root: Entry,
    /// The scene's bounding box: rays that miss it end before any setup.
    pub(crate) bounds: megaray_base::Aabb,
    /// The tiles checked so far (held here so that the hot loop reads it without going
    /// through the scene): a link into one of them needs nothing more. A paged tracer holds
    /// [`CheckedTiles::NONE`], so that it asks the pager at every link instead.
    pub(crate) checked: CheckedTiles<'s>,
    /// Every tile was checked and found sound when this tracer was made (unpaged only,
    /// [`Scene::all_tiles_checked`]): the single-ray kernel then follows links as it
    /// follows inner nodes, with no tile to check or compare ([`Tracer::walk`]).
    pub(crate) all_checked: bool,
    /// Which AVX2 single-ray kernels run: `None` chooses by the rays' coherence
    /// ([`Tracer::walk_on`]), `Some(true)` always the octant ones, `Some(false)` always the
    /// generic one (for tests).
    pub(crate) octant_kernels: Option<bool>,
    /// The single-ray kernels of this tracer's instruction set and tile bookkeeping
    /// ([`Tracer::kernel_table`]), by query kind (`[closest, any]`) and kernel number
    /// ([`Tracer::walk_on`]): chosen once, so that a ray's walk starts with one indirect
    /// call, not a test of each setting and a jump through a table.
    pub(crate) kernels: [[Kernel; KERNELS]; 2],
    /// The same kernels for a new ray on a tracer whose every tile is checked, each in one
    /// function with its walk's state in registers ([`Tracer::new_ray`]): what
    /// [`Tracer::intersect`] and [`Tracer::occluded`] run. `None` on the baseline instruction
    /// set and where tiles are checked as the walk goes.
    pub(crate) new_ray: Option<[[NewRay; KERNELS]; 2]>,
    /// New rays run the assembly kernel (`asm.rs`): on AVX2 and AVX-512 machines where every
    /// tile is checked (and not in a `stats` build, whose counters it does not keep).
    pub(crate) asm: bool,
    /// How many stack entries the assembly kernel may have below a node whose children it
    /// pushes ([`Kernels::asm_stack`]).
    #[cfg_attr(not(all(target_arch = "x86_64", target_os = "linux")), allow(dead_code))]
    pub(crate) asm_stack: usize,
    /// What [`Tracer::with_kernels`] was asked for.
    pub(crate) choice: Kernels,
    /// The level-of-detail error allowed, in footprints, as `f32` bits
    /// ([`Tracer::with_lod_error`]); 0: full detail.
    pub(crate) lod_px: std::sync::Arc<std::sync::atomic::AtomicU32>,
    /// The levels of detail of each full-detail part, where this tracer chooses them
    /// ([`Tracer::with_lod_error`]); empty: full detail always.
    pub(crate) lod: std::sync::Arc<[crate::lod::LodLevels]>,
    /// The instance layer, for a scene with instances (`inst.rs`): the queries go through
    /// it, and it traces each object with a tracer of its own (which has none).
    pub(crate) layer: Option<Box<crate::inst::Layer<'s>>>,
}

impl<'s> Tracer<'s> {
    /// A tracer of `scene` on the kernels of [`Kernels::chosen`] (the fastest this machine
    /// has, unless the front end chose others).
    pub fn new(scene: &'s Scene) -> Tracer<'s> {
        Tracer::with_kernels(scene, Kernels::chosen())
    }

    /// A tracer of `scene` on the kernels `k` chooses: for tests and benchmarks that compare
    /// the paths. Panics if `k.isa` is not available on this machine.
    pub fn with_kernels(scene: &'s Scene, k: Kernels) -> Tracer<'s> {
        Tracer::bare(scene, k).with_layer()
    }

    /// [`Tracer::with_kernels`] without the instance layer.
    pub(crate) fn bare(scene: &'s Scene, k: Kernels) -> Tracer<'s> {
        assert!(Isa::available().contains(&k.isa), "{:?} is not available on this machine", k.isa);
        let top0 = scene.header().top_nodes_off / NODE_BYTES as u64;
        // Read once: the kernel table must be the one of the settings the tracer records
        // (another thread may finish checking every tile meanwhile).
        let all_checked = scene.all_tiles_checked() && !k.tile_checks;
        Tracer {
            scene,
            pager: None,
            tiles: scene.tiles(),
            nodes: scene.node_pool(),
            isa: k.isa,
            bounds: scene.header().bounds,
            checked: scene.checked_tiles(),
            all_checked,
            octant_kernels: k.octants,
            kernels: Tracer::kernel_table(k.isa, all_checked),
            new_ray: Tracer::new_ray_table(k.isa, all_checked),
            asm: Tracer::asm_kernel(&k, all_checked),
            asm_stack: k.asm_stack.clamp(1, STACK - W),
            choice: k,
            lod_px: std::sync::Arc::new(std::sync::atomic::AtomicU32::new(0)),
            lod: std::sync::Arc::new([]),
            layer: None,
            root: match scene.parts() {
                [p] => Entry::part_root(scene, p),
                _ => Entry { r: ChildRef::inner(top0).0, arr: TOP, t: f32::NEG_INFINITY },
            },
        }
    }

    /// This tracer with the instance layer of its scene, if the scene has instances.
    fn with_layer(mut self) -> Tracer<'s> {
        if let Some(i) = self.scene.instancing() {
            let layer = crate::inst::Layer::new(&self, self.scene, i);
            self.bounds = layer.bounds();
            self.layer = Some(Box::new(layer));
        }
        self
    }

    /// A tracer of the object whose tree starts at `root` (its box `bounds`), with this
    /// tracer's kernels, pager and levels of detail, and no instance layer.
    pub(crate) fn object_tracer(&self, root: Entry, bounds: megaray_base::Aabb) -> Tracer<'s> {
        Tracer {
            scene: self.scene,
            pager: self.pager,
            tiles: self.tiles,
            nodes: self.nodes,
            isa: self.isa,
            root,
            bounds,
            checked: self.checked,
            all_checked: self.all_checked,
            octant_kernels: self.octant_kernels,
            kernels: self.kernels,
            new_ray: self.new_ray,
            asm: self.asm,
            asm_stack: self.asm_stack,
            choice: self.choice,
            lod_px: self.lod_px.clone(),
            lod: self.lod.clone(),
            layer: None,
        }
    }

    /// This tracer with its objects' tracers made again from its settings (after a change
    /// of kernels, pager, tile checks or levels of detail).
    pub(crate) fn rebase(mut self) -> Tracer<'s> {
        if let Some(mut l) = self.layer.take() {
            l.objects = l.objects.iter().map(|o| self.object_tracer(o.root, o.bounds)).collect();
            self.layer = Some(l);
        }
        self
    }

    /// The kernels this tracer was asked to run ([`Tracer::with_kernels`]).
    pub fn kernels(&self) -> Kernels {
        self.choice
    }

    /// Whether new rays run the assembly kernel (`asm.rs`) where they would run the generic
    /// AVX2 kernel.
    pub fn runs_asm_kernel(&self) -> bool {
        self.asm
    }

    /// Whether the single-ray kernel follows links with no tile to check (every tile of
    /// the scene was checked when this unpaged tracer was made: [`Scene::check_all_tiles`]).
    pub fn skips_tile_checks(&self) -> bool {
        self.all_checked
    }

    /// A tracer that reads only the tiles `pager` has made resident.
    pub fn paged(pager: &'s Pager) -> Tracer<'s> {
        let scene: &'s Scene = pager.scene();
        Tracer::with_kernels(scene, Kernels { tile_checks: true, ..Kernels::chosen() }).with_pager(pager)
    }

    /// [`Tracer::paged`] when there is a `pager`, else [`Tracer::new`] of `scene` (the
    /// front ends' choice between a budget and none).
    pub fn paged_or_new(scene: &'s Scene, pager: Option<&'s Pager>) -> Tracer<'s> {
        match pager {
            Some(p) => Tracer::paged(p),
            None => Tracer::new(scene),
        }
    }

    /// This tracer reading through `pager` ([`Tracer::paged`]).
    fn with_pager(self, pager: &'s Pager) -> Tracer<'s> {
        // No tile counted as checked: every crossing into a tile returns to the driver
        // ([`Tracer::enter`]), which asks the pager.
        Tracer { pager: Some(pager), checked: CheckedTiles::NONE, ..self }.rebase()
    }

    /// The pager, for a paged tracer.
    pub fn pager(&self) -> Option<&'s Pager> {
        self.pager
    }

    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// Makes tile `arr` the open one (`*c`); fails with [`Step::Skip`] when that tile is
    /// corrupt and, on a paged tracer, with [`Step::Missing`] when it is not resident (now
    /// requested).
    #[inline(always)]
    pub(crate) fn open(&self, c: &mut u32, arr: u32) -> Result<(), Step<'s>> {
        if *c == arr {
            return Ok(());
        }
        if self.checked.get(arr) {
            // The common crossing, inline: an unpaged tile already checked.
            stats::count(|s| s.tiles_entered += 1);
            *c = arr;
            return Ok(());
        }
        self.enter(c, arr)
    }

    /// [`Tracer::open`] when `arr` is not the open array: the tile is checked (or, paged,
    /// acquired from the pager).
    #[inline(never)]
    pub(crate) fn enter(&self, c: &mut u32, arr: u32) -> Result<(), Step<'s>> {
        if arr != TOP {
            match self.pager {
                None => {
                    if !self.scene.tile_usable(arr) {
                        return Err(Step::Skip);
                    }
                }
                Some(p) => match p.acquire(arr) {
                    Access::Ready => {}
                    Access::Corrupt => return Err(Step::Skip),
                    Access::Missing => return Err(Step::Missing(arr)),
                },
            }
        }
        stats::count(|s| s.tiles_entered += 1);
        *c = arr;
        Ok(())
    }

    /// Resolves a popped entry (for the packet kernel): opens the tile it lives in and says
    /// what it is.
    #[inline(always)]
    pub(crate) fn step(&self, c: &mut u32, e: &Entry) -> Step<'s> {
        // `ChildRef::decode`, written out, its kind's two bits tested one at a time in order
        // of frequency (as a `match`, the compiler jumps through a table, an indirect branch
        // that predicts worse). An empty slot has kind 3 and is caught with the parts.
        let r = e.r;
        let leaf_or_part = r & (1 << 62) != 0;
        let (arr, node) = if (r as i64) >= 0 {
            if let Err(s) = self.open(c, e.arr) {
                return s;
            }
            if leaf_or_part {
                return Step::Leaf { unit: r & ChildRef::MAX_UNIT, count: ((r >> 40) & 0xff) as u32 };
            }
            (e.arr, r & ChildRef::MAX_NODE)
        } else if !leaf_or_part {
            (((r >> 36) as u32) & ChildRef::MAX_TILE, r & ChildRef::MAX_NODE)
        } else {
            // An empty slot (the top-level tree links to part roots).
            return Step::Skip;
        };
        if let Err(s) = self.open(c, arr) {
            return s;
        }
        // In range: node positions were checked with the tile (`Scene::check_tile`).
        Step::Node(&self.nodes[node as usize], arr)
    }

    /// Starts loading the node or leaf that child reference `r` names (a whole node, 256
    /// bytes; a leaf's one or two blocks, 144 or 288), as Embree's traversal does
    /// for the children it hits. Called for the children pushed (the nearest is loaded next
    /// anyway): they are popped later and find their data in cache, so an incoherent ray's
    /// misses overlap instead of queueing.
    /// Only the address is computed: a prefetch never faults and needs no bounds (an absent
    /// tile's pages are not touched, so a paged tracer never waits for one).
    #[inline(always)]
    pub(crate) fn prefetch(&self, r: u64) {
        let base = self.nodes.as_ptr() as *const u8;
        // Inner nodes and links (bit 62 clear) by node, leaves by block; parts not.
        let at = if r & (1 << 62) == 0 {
            (r & ChildRef::MAX_NODE) as usize * NODE_BYTES
        } else if (r as i64) >= 0 {
            let at = (r & ChildRef::MAX_UNIT) as usize * 16;
            if (r >> 40) & 0xff > 4 {
                // Two blocks, 288 bytes: the lines past the first 256 bytes too.
                let p = base.wrapping_add(at);
                megaray_base::prefetch_addr(p.wrapping_add(256));
                megaray_base::prefetch_addr(p.wrapping_add(2 * std::mem::size_of::<Tri4>() - 1));
            }
            at
        } else {
            return;
        };
        let p = base.wrapping_add(at);
        for line in 0..4 {
            megaray_base::prefetch_addr(p.wrapping_add(64 * line));
        }
    }

    /// The [`Hit`] of what a kernel found (single-ray or packet): its part, slot and corners.
    #[inline(always)]
    pub(crate) fn hit_of(&self, f: Option<Found>) -> Option<Hit> {
        let f = f?;
        let (part, slot0) = self.slots(f.arr, f.unit);
        let tri = corners(self.block_at(f.unit), f.lane as usize);
        Some(Hit { t: f.t, u: f.u, v: f.v, part, prim: slot0 + f.lane, tri, placed: None })
    }

    /// The part of tile `arr` and the slot of lane 0 of its block at `unit` (lane `l` of the
    /// tile's block `b` is slot `first_slot + 4 b + l`).
    #[inline]
    pub(crate) fn slots(&self, arr: u32, unit: u64) -> (u32, u32) {
        if arr == TOP {
            // A hit of a walk that kept no tile ([`Tracer::walk`]): the tile whose blocks
            // hold it (tiles lie in file order).
            return self.scene.slot_of_unit(unit);
        }
        let e = &self.tiles[arr as usize];
        (e.part, e.first_slot + 4 * ((unit - e.unit0()) / 9) as u32)
    }

    /// The triangle block at `unit` (`offset / 16`).
    #[inline(always)]
    pub(crate) fn block_at(&self, unit: u64) -> &'s Block {
        let s = unit as usize;
        // The nodes as 16-byte units: the same pointer, 16 times the length (no copy).
        let units: &'s [[f32; 4]] = bytemuck::cast_slice(self.nodes);
        units[s..s + 9].try_into().expect("nine units")
    }

    /// [`Tracer::block_at`] without its bounds check, for the hot loop ([`Tracer::walk`]):
    /// `unit` must be a block of a leaf reference read from a checked tile.
    #[inline(always)]
    pub(crate) fn walk_block_at(&self, unit: u64) -> &'s Block {
        let s = unit as usize;
        debug_assert!((s + 9) * 16 <= std::mem::size_of_val(self.nodes), "block {s} beyond the file");
        // SAFETY: the walk reads blocks only through leaf references of checked tiles (or of
        // a tile entered through `Tracer::enter`, which checks it), and `Scene::check_tile`
        // verified that all blocks of each such leaf lie inside its tile, which
        // `Scene::open` verified to lie inside the file, all of which `nodes` covers (but a
        // tail shorter than a node, which no tile reaches into: tiles end on pages). A
        // `Block` is nine `[f32; 4]` units: the pointer is aligned for it.
        unsafe { &*(self.nodes.as_ptr().cast::<[f32; 4]>().add(s).cast::<Block>()) }
    }

    /// The node at position `node` without a bounds check, for the hot loop
    /// ([`Tracer::walk`]): `node` must come from a checked reference.
    #[inline(always)]
    pub(crate) fn walk_node_at(&self, node: u64) -> &'s Node8 {
        debug_assert!((node as usize) < self.nodes.len(), "node {node} beyond the file");
        // SAFETY: the walk follows only references of checked tiles (`Scene::check_tile`:
        // inner nodes and links point at nodes inside their tiles), of the top-level tree
        // and the root (both checked by `Scene::open`), and `Scene::open` verified every tile
        // to lie inside the file, which `nodes` covers. (A debug build asserts it.)
        unsafe { self.nodes.get_unchecked(node as usize) }
    }
}
