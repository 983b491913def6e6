//! Opening a scene file: map it (or, for a pager, read its tables into memory of its own),
//! check the header and every table, and hand out typed views. Tiles are checked lazily, the first time traversal enters them (checksum and
//! every reference in range), so opening a file of any size reads only its tables.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, AtomicU8, Ordering};
use std::sync::{Mutex, OnceLock};

use memmap2::Mmap;

use crate::backing::{Backing, Region};

use crate::error::{SceneError, SceneErrorKind};
use crate::format::*;
use crate::writer::{decode_materials, MaterialDesc};

/// Drops `len` bytes of `file` at `off` (0: to the end) from the page cache
/// (posix_fadvise DONTNEED); pages mapped by a process stay. Advice: its outcome is not
/// reported. (The project's one wrapper: [`Scene::reread_in_huge_pages`] and the pager use it.)
pub fn drop_page_cache(file: &File, off: u64, len: u64) {
    use std::os::fd::AsRawFd;
    // SAFETY: posix_fadvise only takes integers and a file descriptor that `file` keeps
    // open; it reads no memory of ours.
    unsafe {
        libc::posix_fadvise(file.as_raw_fd(), off as libc::off_t, len as libc::off_t, libc::POSIX_FADV_DONTNEED);
    }
}

const TILE_UNCHECKED: u8 = 0;
const TILE_OK: u8 = 1;

mod checked;
mod image;
pub use checked::CheckedTiles;
pub use image::{fits_in_memory, physical_memory};

const TILE_CORRUPT: u8 = 2;

/// An open, checked scene file: mapped, or owned by a pager ([`Scene::open_owned`]).
pub struct Scene {
    path: PathBuf,
    backing: Backing,
    header: Header,
    tile_state: Vec<AtomicU8>,
    /// How many of `tile_state` are [`TILE_OK`] ([`Scene::all_tiles_checked`]).
    tiles_ok: AtomicU32,
    /// Every tile checked but the root tiles of parts with levels of detail
    /// ([`Scene::checked_but_lod_roots`]), made when first asked for.
    lod_stops: OnceLock<Vec<AtomicU8>>,
    first_error: Mutex<Option<SceneError>>,
    materials: Vec<MaterialDesc>,
    /// Which tile a triangle block lies in ([`Scene::tile_of_unit`]): made at the first
    /// lookup, so that a scene that never needs one (a paged tracer keeps its tile) holds
    /// none.
    tile_index: OnceLock<TileIndex>,
    /// Objects, groups and instances, when the scene has them ([`Scene::instancing`]).
    instancing: Option<crate::Instancing>,
    /// The scene's settings (JSON), empty when it has none.
    settings: String,
    /// Named components and the runs of slots that belong to them ([`Scene::components`]).
    components: crate::Components,
}

/// The tiles by position in the file, for [`Scene::tile_of_unit`]: the file cut into
/// buckets of `1 << shift` 16-byte units, and for each the last tile whose blocks start at or
/// before the bucket's start (tiles lie in file order, [`Scene::open`] checks), and per tile
/// where its blocks start, its part and its first slot ([`Placed`], read here rather than
/// through the mapped directory). The buckets are as many as four per tile (and at least
/// 4 KiB each): 32 bytes per tile at most, and a tile's lookup one load and, mostly, one
/// comparison.
struct TileIndex {
    shift: u32,
    first: Vec<u32>,
    tiles: Vec<Placed>,
}

/// What a hit needs of its tile ([`Scene::slot_of_unit`]). 16 bytes.
#[derive(Clone, Copy, Debug)]
struct Placed {
    /// `TileEntry::unit0`: where its blocks start.
    unit0: u64,
    part: u32,
    first_slot: u32,
}

const _: () = assert!(std::mem::size_of::<Placed>() == 16);

impl TileIndex {
    fn new(tiles: &[TileEntry], file_bytes: u64) -> TileIndex {
        let units = file_bytes / 16 + 1;
        let most = 4 * tiles.len() as u64 + 64;
        let mut shift = 8; // 4 KiB
        while units >> shift > most {
            shift += 1;
        }
        let buckets = (units >> shift) + 1;
        let mut first = Vec::with_capacity(buckets as usize);
        let mut t = 0;
        for b in 0..buckets {
            while t + 1 < tiles.len() && tiles[t + 1].unit0() <= b << shift {
                t += 1;
            }
            first.push(t as u32);
        }
        let tiles = tiles.iter().map(|e| Placed { unit0: e.unit0(), part: e.part, first_slot: e.first_slot }).collect();
        TileIndex { shift, first, tiles }
    }

    /// [`Scene::tile_of_unit`].
    #[inline]
    fn tile_of(&self, unit: u64) -> u32 {
        let TileIndex { shift, first, tiles } = self;
        let b = ((unit >> shift) as usize).min(first.len().saturating_sub(1));
        // The tile holding `unit` is one of those from the last to start before its bucket
        // to the last to start before the next bucket: mostly the first of them.
        let Some(&lo) = first.get(b) else { return 0 };
        let lo = lo as usize;
        match tiles.get(lo + 1) {
            Some(next) if next.unit0 <= unit => {}
            _ => return lo as u32,
        }
        let hi = first.get(b + 1).map_or(tiles.len(), |&h| h as usize + 1);
        let Some(starts) = tiles.get(lo..hi.max(lo + 1)) else { return 0 };
        (lo + starts.partition_point(|t| t.unit0 <= unit).saturating_sub(1)) as u32
    }

    /// [`Scene::slot_of_unit`].
    #[inline]
    fn slot_of(&self, unit: u64) -> (u32, u32) {
        match self.tiles.get(self.tile_of(unit) as usize) {
            Some(t) => (t.part, t.first_slot.wrapping_add(((unit.wrapping_sub(t.unit0) / 9) as u32).wrapping_mul(4))),
            None => (0, 0),
        }
    }
}

/// The nodes and triangle blocks of one tile.
#[derive(Clone, Copy)]
pub struct Tile<'a> {
    pub nodes: &'a [Node8],
    pub blocks: &'a [Tri4],
    /// The position of node 0 (`offset / 256`) and of block 0 (`offset / 16`), to which
    /// the nodes' absolute references ([`ChildRef`]) relate.
    pub node0: u64,
    pub unit0: u64,
}

impl Tile<'_> {
    /// The index in this tile of the block at `unit` (a leaf's [`Child::Leaf::unit`]).
    pub fn block_index(&self, unit: u64) -> u32 {
        ((unit - self.unit0) / 9) as u32
    }

    /// Every triangle of the tile, as (slot within the tile, corners), walking its leaves
    /// (padding lanes are not triangles and are skipped).
    pub fn triangles(&self) -> Vec<(u32, [[f32; 3]; 3])> {
        let mut out = Vec::new();
        for n in self.nodes {
            for c in n.child {
                if let Child::Leaf { unit, count } = ChildRef(c).decode() {
                    let first = self.block_index(unit);
                    for i in 0..count {
                        let slot = 4 * first + i;
                        out.push((slot, self.blocks[(slot / 4) as usize].tri((slot % 4) as usize)));
                    }
                }
            }
        }
        out.sort_by_key(|t| t.0);
        out
    }
}

fn range(off: u64, len: u64, file: u64) -> Option<std::ops::Range<usize>> {
    let end = off.checked_add(len)?;
    (end <= file).then_some(off as usize..end as usize)
}

impl Scene {
    /// Opens and checks `path`, mapped: the operating system pages the file on demand (for
    /// scenes traced in core). Every fault is a [`SceneError`] naming the file and the fault.
    pub fn open(path: &Path) -> Result<Scene, SceneError> {
        Scene::open_as(path, false)
    }

    /// Opens and checks `path` for a pager ([`Scene::is_owned`]): nothing of the file is
    /// mapped; the header page and tables are read now into a region of anonymous memory
    /// that mirrors the file's offsets, and tiles are read into it by [`Scene::load`] and
    /// dropped by [`Scene::release`]. Resident memory is then exactly what was loaded,
    /// whatever state the page cache is in (`docs/ARCHITECTURE.md`, Paging). Also checks
    /// that no two tiles' byte ranges overlap (the region shares only partly covered pages).
    pub fn open_owned(path: &Path) -> Result<Scene, SceneError> {
        Scene::open_as(path, true)
    }

    fn open_as(path: &Path, owned: bool) -> Result<Scene, SceneError> {
        let file = File::open(path).map_err(|e| SceneError::io(path, "open", &e))?;
        let len = file.metadata().map_err(|e| SceneError::io(path, "stat", &e))?.len();
        if len < 256 {
            return Err(SceneError::new(
                path,
                if len >= 8 { SceneErrorKind::Truncated } else { SceneErrorKind::NotAScene },
                format!("too short to be a scene file ({len} bytes)"),
            ));
        }
        let mut head = [0u8; 256];
        std::os::unix::fs::FileExt::read_exact_at(&file, &mut head, 0).map_err(|e| SceneError::io(path, "read", &e))?;
        let header: Header = bytemuck::pod_read_unaligned(&head);
        Scene::check_header(path, &header, &head, len)?;
        let reserve = |e: std::io::Error| SceneError::io(path, "reserve memory for", &e);
        let read = |e: std::io::Error| SceneError::io(path, "read", &e);
        let backing = if header.is_compact() {
            let extents = image::read_extents(path, &file, &header, len)?;
            if !owned {
                image::check_fits(path, &header)?;
                image::check_tail(path, &header, &extents)?;
            }
            let r = Region::new(file, header.image_bytes, extents, !owned).map_err(reserve)?;
            if owned {
                r.load(0, 256).map_err(read)?;
                Backing::Owned(r)
            } else {
                r.load_all(std::thread::available_parallelism().map_or(1, |n| n.get())).map_err(read)?;
                Backing::Image(r)
            }
        } else if owned {
            let r = Region::new(file, len, Vec::new(), false).map_err(reserve)?;
            r.load(0, 256).map_err(read)?;
            Backing::Owned(r)
        } else {
            // SAFETY: the map is read-only and private to this process. The contract (stated
            // in the crate docs) is that nobody truncates or rewrites a scene file while it
            // is open: megaray itself only ever replaces scene files by rename, which leaves
            // this mapping intact. Every view handed out is bounds-checked against the
            // mapped length.
            Backing::Mapped(unsafe { Mmap::map(&file) }.map_err(|e| SceneError::io(path, "map", &e))?)
        };
        // Offsets from here on are the image's (the file's own, unless it is compact).
        let len = header.image_len();
        let bad = |what: &str| SceneError::corrupt(path, what.to_string());
        let top = range(header.top_nodes_off, header.top_node_count as u64 * NODE_BYTES as u64, len)
            .filter(|_| header.top_nodes_off.is_multiple_of(NODE_BYTES as u64) && header.top_node_count > 0)
            .ok_or_else(|| bad("top-level tree lies outside the file"))?;
        let parts = range(header.parts_off, header.part_count as u64 * 128, len)
            .filter(|_| header.parts_off.is_multiple_of(8) && header.part_count > 0)
            .ok_or_else(|| bad("part directory lies outside the file"))?;
        let tiles = range(header.tiles_off, header.tile_count as u64 * 40, len)
            .filter(|_| header.tiles_off.is_multiple_of(8))
            .ok_or_else(|| bad("tile directory lies outside the file"))?;
        let mats = range(header.materials_off, header.materials_bytes, len)
            .ok_or_else(|| bad("material table lies outside the file"))?;
        let inst = range(header.instances_off, header.instances_bytes, len)
            .filter(|_| header.instances_off.is_multiple_of(8))
            .ok_or_else(|| bad("instance section lies outside the file"))?;
        let settings = range(header.settings_off, header.settings_bytes, len)
            .ok_or_else(|| bad("settings lie outside the file"))?;
        let comps = range(header.components_off, header.components_bytes, len)
            .filter(|_| header.components_off.is_multiple_of(8))
            .ok_or_else(|| bad("component section lies outside the file"))?;
        if let Backing::Owned(r) = &backing {
            // The tables stay loaded while the scene is open (the header page is).
            for t in [&top, &parts, &tiles, &mats, &inst, &settings, &comps] {
                r.load(t.start as u64, t.len() as u64).map_err(|e| SceneError::io(path, "read", &e))?;
            }
        }
        let map = backing.bytes();
        let mut meta = xxhash_rust::xxh3::Xxh3::new();
        for r in [&top, &parts, &tiles, &mats, &inst, &settings, &comps] {
            meta.update(&map[r.clone()]);
        }
        if !sums_match(meta.digest(), header.meta_checksum) {
            return Err(bad("table checksum mismatch (tree, part, tile or material table damaged)"));
        }
        let materials =
            decode_materials(&map[mats], header.material_count).ok_or_else(|| bad("material table is malformed"))?;
        let instancing = match header.group_count {
            0 => None,
            _ => Some(
                crate::Instancing::decode(&map[inst], header.object_count, header.group_count, header.instance_count)
                    .ok_or_else(|| bad("instance section is malformed"))?,
            ),
        };
        let settings_text = String::from_utf8_lossy(&map[settings]).into_owned();
        let components = match header.component_count {
            0 => crate::Components::default(),
            n => crate::Components::decode(&map[comps], n, header.component_run_count, header.part_count)
                .map_err(|e| bad(&format!("component section: {e}")))?,
        };
        let scene = Scene {
            path: path.to_path_buf(),
            tile_state: (0..header.tile_count).map(|_| AtomicU8::new(TILE_UNCHECKED)).collect(),
            tiles_ok: AtomicU32::new(0),
            lod_stops: OnceLock::new(),
            first_error: Mutex::new(None),
            materials,
            header,
            backing,
            tile_index: OnceLock::new(),
            instancing,
            settings: settings_text,
            components,
        };
        scene.check_tables()?;
        if owned {
            scene.check_disjoint()?;
        }
        Ok(scene)
    }

    /// The header's own checks: magic number, version, checksum, and the length it states.
    fn check_header(path: &Path, header: &Header, head: &[u8; 256], len: u64) -> Result<(), SceneError> {
        if header.magic != MAGIC {
            return Err(SceneError::new(
                path,
                SceneErrorKind::NotAScene,
                "not a megaray scene file (bad magic number)",
            ));
        }
        if !(MIN_VERSION..=VERSION).contains(&header.version) {
            return Err(SceneError::new(
                path,
                SceneErrorKind::Version,
                format!(
                    "scene format version {}, this megaray reads version {VERSION} (rebuild the scene)",
                    header.version
                ),
            ));
        }
        let sum = xxhash_rust::xxh3::xxh3_64(&head[..248]);
        if header.header_bytes != 256 || !sums_match(sum, header.header_checksum) {
            return Err(SceneError::corrupt(path, "header checksum mismatch (the header is damaged)"));
        }
        if header.file_bytes != len {
            return Err(SceneError::new(
                path,
                SceneErrorKind::Truncated,
                format!("header says {} bytes but the file has {len} (truncated or appended to)", header.file_bytes),
            ));
        }
        Ok(())
    }

    /// For an owned scene: no byte belongs to two tiles, or to a tile and a table (a page
    /// may: [`Region`] counts those). Otherwise releasing one tile could drop bytes that
    /// another still uses.
    fn check_disjoint(&self) -> Result<(), SceneError> {
        let mut tiles: Vec<(u64, u64, u32)> = Vec::new();
        for t in 0..self.header.tile_count {
            tiles.extend(self.tile_ranges(t).unwrap_or_default().into_iter().map(|(o, l)| (o, l, t)));
        }
        tiles.retain(|&(_, l, _)| l > 0);
        tiles.sort_unstable();
        let overlap = |a: String, b: u32, at: u64| {
            SceneError::corrupt(&self.path, format!("{a} and tile {b} overlap at byte {at}"))
        };
        for w in tiles.windows(2) {
            if w[0].0 + w[0].1 > w[1].0 {
                return Err(overlap(format!("tile {}", w[0].2), w[1].2, w[1].0));
            }
        }
        // The header itself is 256 bytes (the rest of its page is padding).
        let tables = self.pinned_ranges().into_iter().map(|(o, l)| if o == 0 { (0, 256) } else { (o, l) });
        for (o, l) in tables.filter(|&(_, l)| l > 0) {
            let i = tiles.partition_point(|&(to, tl, _)| to + tl <= o);
            if let Some(&(to, _, t)) = tiles.get(i).filter(|&&(to, _, _)| to < o + l) {
                return Err(overlap("a table".into(), t, to.max(o)));
            }
        }
        Ok(())
    }

    fn check_tables(&self) -> Result<(), SceneError> {
        let h = &self.header;
        let bad = |what: String| SceneError::corrupt(&self.path, what);
        let len = self.bytes().len() as u64;
        let tiles = self.tiles();
        let top0 = h.top_nodes_off / NODE_BYTES as u64;
        for (i, n) in self.top_nodes().iter().enumerate() {
            for c in n.child {
                match ChildRef(c).decode() {
                    Child::Empty => {}
                    Child::Inner(k) if k > top0 + i as u64 && k < top0 + h.top_node_count as u64 => {}
                    // A part's root: the root node of the part its tile belongs to.
                    Child::Link { tile, node }
                        if tiles.get(tile as usize).is_some_and(|t| {
                            self.parts().get(t.part as usize).is_some_and(|p| {
                                p.root_tile == tile
                                    && p.root_node < t.node_count
                                    && node == t.node0() + p.root_node as u64
                            })
                        }) => {}
                    other => return Err(bad(format!("top-level node {i}: bad child {other:?}"))),
                }
            }
        }
        let mut tri_total = 0u64;
        let full = h
            .part_count
            .checked_sub(h.lod_part_count)
            .filter(|&f| f > 0)
            .ok_or_else(|| bad(format!("{} levels of detail but only {} parts", h.lod_part_count, h.part_count)))?;
        let parts = self.parts();
        for (i, p) in parts.iter().enumerate() {
            let tiles_end = p.first_tile as u64 + p.tile_count as u64;
            let is_full = (i as u32) < full;
            if tiles_end > h.tile_count as u64
                || p.root_tile < p.first_tile
                || p.root_tile as u64 >= tiles_end
                || p.root_node >= tiles[p.root_tile as usize].node_count
                || (is_full && p.first_prim != tri_total)
            {
                return Err(bad(format!("part {i}: tile range or root out of bounds")));
            }
            // Levels of detail: a full part is level 0 of itself; each level names the full
            // part it stands in for and chains to the next coarser one, errors not shrinking.
            let lod_ok = match is_full {
                true => p.lod_of == i as u32 && p.lod_level == 0 && p.lod_error == 0.0,
                false => p.lod_of < full && p.lod_level >= 1 && p.lod_error.is_finite(),
            } && (p.lod_next == NO_PART
                || (p.lod_next >= full
                    && parts.get(p.lod_next as usize).is_some_and(|n| {
                        n.lod_of == p.lod_of && n.lod_level == p.lod_level + 1 && n.lod_error >= p.lod_error
                    })));
            if !lod_ok {
                return Err(bad(format!("part {i}: bad level-of-detail chain")));
            }
            let n = p.slot_count;
            if n < p.tri_count as u64 || !n.is_multiple_of(4) {
                return Err(bad(format!("part {i}: {} slots cannot hold {} triangles", n, p.tri_count)));
            }
            for (off, size) in [(p.normals_off, 12), (p.uvs_off, 24), (p.colors_off, 12), (p.materials_off, 4)] {
                let fits = n.checked_mul(size).and_then(|bytes| range(off, bytes, len)).is_some();
                if off != 0 && (!off.is_multiple_of(4) || !fits) {
                    return Err(bad(format!("part {i}: attribute array lies outside the file")));
                }
            }
            if is_full {
                tri_total += p.tri_count as u64;
            }
        }
        if tri_total != h.tri_count {
            return Err(bad(format!("parts hold {tri_total} triangles, header says {}", h.tri_count)));
        }
        if let Some(i) = &self.instancing {
            i.check(full, h.top_node_count, h.material_count).map_err(|e| bad(format!("instances: {e}")))?;
        }
        let mut end = 0;
        for (i, t) in tiles.iter().enumerate() {
            // In file order, none overlapping the one before ([`Scene::tile_of_unit`]).
            if t.offset < end {
                return Err(bad(format!("tile {i}: out of file order (starts before the end of the tile before it)")));
            }
            end = t.offset.saturating_add(t.bytes as u64);
            let expect = t.node_count as u64 * NODE_BYTES as u64 + t.blocks as u64 * 144;
            let part = self.parts().get(t.part as usize);
            if !t.offset.is_multiple_of(PAGE)
                || t.bytes as u64 != expect
                || range(t.offset, expect, len).is_none()
                || part.is_none_or(|p| {
                    (i as u32) < p.first_tile
                        || i as u64 >= p.first_tile as u64 + p.tile_count as u64
                        || t.first_slot as u64 + 4 * t.blocks as u64 > p.slot_count
                })
            {
                return Err(bad(format!("tile {i}: directory entry out of bounds")));
            }
        }
        Ok(())
    }

    /// Full-detail parts: parts `0..full_part_count()`; the levels of detail follow them.
    pub fn full_part_count(&self) -> u32 {
        self.header.part_count - self.header.lod_part_count
    }

    /// The parts that stand in for full-detail part `part`, finest first: `part` itself
    /// (level 0), then its levels of detail ([`PartEntry::lod_next`]).
    pub fn lod_chain(&self, part: u32) -> impl Iterator<Item = u32> + '_ {
        let parts = self.parts();
        std::iter::successors(Some(part).filter(|&p| (p as usize) < parts.len()), move |&p| {
            Some(parts[p as usize].lod_next).filter(|&n| n != NO_PART)
        })
    }

    /// A compact file's extents (`compact.rs`); empty for a file that is its own image.
    pub fn extents(&self) -> &[Extent] {
        self.backing.extents()
    }

    /// The file this scene was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The whole mapped file.
    #[inline(always)]
    pub fn bytes(&self) -> &[u8] {
        self.backing.bytes()
    }

    /// The top-level tree; node 0 is the root.
    pub fn top_nodes(&self) -> &[Node8] {
        let off = self.header.top_nodes_off as usize;
        bytemuck::cast_slice(&self.bytes()[off..off + self.header.top_node_count as usize * NODE_BYTES])
    }

    pub fn parts(&self) -> &[PartEntry] {
        let off = self.header.parts_off as usize;
        bytemuck::cast_slice(&self.bytes()[off..off + self.header.part_count as usize * 128])
    }

    /// The whole file as an array of [`Node8`]s, 256-byte units from byte 0 (a tail shorter
    /// than one is left out). Every node array in the file starts on a multiple of 256 bytes
    /// (the top-level tree: checked by [`Scene::open`]; tiles: page aligned), so node `i` of a
    /// tile at byte `offset` is `node_pool()[offset / 256 + i]`. The tracer indexes this one
    /// slice instead of making a slice per tile it enters.
    #[inline]
    pub fn node_pool(&self) -> &[Node8] {
        bytemuck::cast_slice(&self.bytes()[..self.bytes().len() / NODE_BYTES * NODE_BYTES])
    }

    pub fn tiles(&self) -> &[TileEntry] {
        let off = self.header.tiles_off as usize;
        bytemuck::cast_slice(&self.bytes()[off..off + self.header.tile_count as usize * 40])
    }

    pub fn materials(&self) -> &[MaterialDesc] {
        &self.materials
    }

    /// Tile `t`, checked on first use. `None` (and the fault recorded, see
    /// [`Scene::first_error`]) when it is corrupt; traversal then skips it.
    #[inline]
    pub fn tile(&self, t: u32) -> Option<Tile<'_>> {
        self.tile_usable(t).then(|| self.tile_unchecked_view(t))
    }

    /// Whether tile `t` has been checked and found sound (no checking here: the fast path
    /// of [`Scene::tile_usable`]).
    #[inline(always)]
    pub fn tile_checked(&self, t: u32) -> bool {
        self.checked_tiles().get(t)
    }

    /// [`Scene::tile_checked`] for all tiles, as a view that a caller keeps (the tracer holds
    /// one, so that its hot loop reads the states without going through the scene).
    #[inline(always)]
    pub fn checked_tiles(&self) -> CheckedTiles<'_> {
        CheckedTiles(&self.tile_state)
    }

    /// Whether tile `t` may be used: checked now if it never was (then `true` from then on),
    /// `false` (and the fault recorded) when it is corrupt or does not exist.
    #[inline]
    pub fn tile_usable(&self, t: u32) -> bool {
        let Some(state) = self.tile_state.get(t as usize) else { return false };
        match state.load(Ordering::Acquire) {
            TILE_OK => true,
            TILE_CORRUPT => false,
            // An owned scene's tiles are checked by its pager as it loads them; one not
            // loaded reads as zeros and must not be judged corrupt here.
            _ if self.is_owned() => false,
            _ => {
                let ok = match self.check_tile(t) {
                    Ok(()) => true,
                    Err(e) => {
                        // Recorded before the state says so: whoever sees the tile corrupt
                        // finds a fault recorded.
                        self.first_error.lock().unwrap_or_else(|p| p.into_inner()).get_or_insert(e);
                        false
                    }
                };
                let to = if ok { TILE_OK } else { TILE_CORRUPT };
                // The first thread to decide counts the tile (others checked it alike).
                if state.compare_exchange(TILE_UNCHECKED, to, Ordering::Release, Ordering::Relaxed).is_ok() && ok {
                    self.tiles_ok.fetch_add(1, Ordering::Release);
                }
                ok
            }
        }
    }

    /// Whether every tile has been checked and found sound: then a reader may follow any
    /// reference without asking ([`Scene::tile_usable`]) first. The single-ray kernel of
    /// an unpaged tracer made then skips its tile bookkeeping.
    #[inline]
    pub fn all_tiles_checked(&self) -> bool {
        self.tiles_ok.load(Ordering::Acquire) == self.header.tile_count
    }

    /// Checks every tile not checked yet (reads the whole file; faults are recorded as
    /// traversal records them, [`Scene::first_error`]) and says whether all are sound
    /// ([`Scene::all_tiles_checked`]). For scenes that fit in memory
    /// and are traced unpaged, such as the benchmark's: their tracers then trace faster.
    pub fn check_all_tiles(&self) -> bool {
        for t in 0..self.header.tile_count {
            self.tile_usable(t);
        }
        self.all_tiles_checked()
    }

    /// The view of tile `t` without checking it. The caller has checked it with
    /// [`Scene::check_tile`] (as the pager does on every load): a corrupt tile's references
    /// are not trusted by anyone else. Panics if `t` is not a tile.
    pub fn tile_view(&self, t: u32) -> Tile<'_> {
        self.tile_unchecked_view(t)
    }

    /// The byte ranges of the file that belong to tile `t`: its nodes and blocks, then the
    /// attributes of its triangle slots in each attribute array of its part. These are what
    /// a pager loads and releases together. `None` if `t` is not a tile.
    pub fn tile_ranges(&self, t: u32) -> Option<Vec<(u64, u64)>> {
        let e = self.tiles().get(t as usize)?;
        let p = &self.parts()[e.part as usize];
        let mut out = vec![(e.offset, e.bytes as u64)];
        let slots = 4 * e.blocks as u64;
        for (off, size) in [(p.normals_off, 12), (p.uvs_off, 24), (p.colors_off, 12), (p.materials_off, 4)] {
            if off != 0 && slots > 0 {
                out.push((off + e.first_slot as u64 * size, slots * size));
            }
        }
        Some(out)
    }

    /// The tile whose triangle blocks hold the block at `unit` (its byte offset / 16), for
    /// a hit's block: the tile that holds `unit` if any does, some tile otherwise. A lookup
    /// in an index made at the first call (from the tile directory, which [`Scene::open`]
    /// checked to be in file order): the first tile of `unit`'s bucket of the file, or, when
    /// more tiles start in the bucket, a binary search of them.
    #[inline]
    pub fn tile_of_unit(&self, unit: u64) -> u32 {
        self.tile_index().tile_of(unit)
    }

    /// The part of the tile that holds the block at `unit` ([`Scene::tile_of_unit`]), and
    /// the slot of the block's lane 0 in that part (lane `l` of a tile's block `b` is slot
    /// `first_slot + 4 b + l`): what a hit is credited to. Some part and slot (no panic) for
    /// a unit that is no block.
    #[inline]
    pub fn slot_of_unit(&self, unit: u64) -> (u32, u32) {
        self.tile_index().slot_of(unit)
    }

    fn tile_index(&self) -> &TileIndex {
        self.tile_index.get_or_init(|| TileIndex::new(self.tiles(), self.bytes().len() as u64))
    }

    /// The tile holding triangle slot `slot` of part `part` (its attributes are counted with
    /// that tile's residency, see [`Scene::tile_ranges`]). `None` if there is no such slot.
    pub fn tile_of_slot(&self, part: u32, slot: u32) -> Option<u32> {
        let p = self.parts().get(part as usize)?;
        let tiles = self.tiles().get(p.first_tile as usize..(p.first_tile + p.tile_count) as usize)?;
        // A part's tiles hold consecutive slot ranges, in order.
        let k = tiles.partition_point(|t| t.first_slot <= slot).checked_sub(1)?;
        let t = &tiles[k];
        (slot < t.first_slot + 4 * t.blocks).then_some(p.first_tile + k as u32)
    }

    /// Whether part `part` has any attribute array (normals, uvs, colours, materials).
    pub fn has_attributes(&self, part: u32) -> bool {
        self.parts().get(part as usize).is_some_and(|p| p.normals_off | p.uvs_off | p.colors_off | p.materials_off != 0)
    }

    /// The byte ranges that stay resident while the scene is open: the header page and the
    /// tables (top-level tree, part and tile directories, materials).
    pub fn pinned_ranges(&self) -> Vec<(u64, u64)> {
        let h = &self.header;
        vec![
            (0, PAGE),
            (h.top_nodes_off, h.top_node_count as u64 * NODE_BYTES as u64),
            (h.parts_off, h.part_count as u64 * 128),
            (h.tiles_off, h.tile_count as u64 * 40),
            (h.materials_off, h.materials_bytes),
            (h.instances_off, h.instances_bytes),
            (h.settings_off, h.settings_bytes),
            (h.components_off, h.components_bytes),
        ]
    }

    /// The settings the scene's source gave (a JSON document: `camera` with `eye`, `at`,
    /// `up`, `fov`; `environment`, `sun`), or `None`.
    pub fn settings(&self) -> Option<&str> {
        (!self.settings.is_empty()).then_some(self.settings.as_str())
    }

    /// The scene's named components (empty for a scene built without names, or before
    /// format version 7).
    pub fn components(&self) -> &crate::Components {
        &self.components
    }

    /// The scene's objects, groups and instances; `None` for a scene that is its parts.
    pub fn instancing(&self) -> Option<&crate::Instancing> {
        self.instancing.as_ref()
    }

    /// Whether this scene was opened for a pager ([`Scene::open_owned`]): its tiles are
    /// resident only between [`Scene::load`] and [`Scene::release`], and read as zeros
    /// otherwise.
    pub fn is_owned(&self) -> bool {
        matches!(self.backing, Backing::Owned(_))
    }

    /// Asks for the mapping to be backed by 2 MiB pages where the kernel can, for a scene
    /// read whole and traced in core: with 4 KiB pages nearly every node visit of a large
    /// scene misses the TLB (docs/PERF.md, "Huge pages"). Linux maps a
    /// file with 2 MiB pages where its page cache holds 2 MiB folios, which it makes when it
    /// reads the file into a mapping advised `HUGEPAGE` (madvise): pages read from now on
    /// (such as by [`Scene::check_all_tiles`]) come so; pages cached before stay as they
    /// were ([`Scene::reread_in_huge_pages`] reads them again). Advice only: where the
    /// kernel cannot, nothing changes. A no-op off Linux and for an owned scene.
    pub fn advise_huge_pages(&self) -> std::io::Result<()> {
        #[cfg(target_os = "linux")]
        if let Backing::Mapped(m) = &self.backing {
            m.advise(memmap2::Advice::HugePage)?;
        }
        Ok(())
    }

    /// [`Scene::advise_huge_pages`], and the file's pages cached before then written back
    /// and dropped from the page cache (`fdatasync`, `posix_fadvise` DONTNEED; pages mapped
    /// already stay), so that the next reads through the map bring the whole file back in
    /// 2 MiB folios: for the benchmark, whose figures should not depend on how the file was
    /// cached before (docs/PERF.md, "Huge pages").
    pub fn reread_in_huge_pages(&self) -> std::io::Result<()> {
        self.advise_huge_pages()?;
        #[cfg(target_os = "linux")]
        if !self.is_owned() {
            let file = File::open(&self.path)?;
            // Dirty pages (a scene just written) cannot be dropped.
            file.sync_data()?;
            drop_page_cache(&file, 0, 0);
        }
        Ok(())
    }

    /// Makes the file's bytes `off..off + len` resident. Owned: reads them (widened to whole
    /// pages) into the region; an error (a file truncated while open) leaves nothing
    /// loaded. Mapped: asks for read-ahead (madvise WILLNEED) and touches every page.
    pub fn load(&self, off: u64, len: u64) -> std::io::Result<()> {
        match &self.backing {
            Backing::Owned(r) => r.load(off, len),
            Backing::Image(_) => Ok(()),
            Backing::Mapped(m) => {
                let (off, len) = self.clamp_pages(off, len);
                if len == 0 {
                    return Ok(());
                }
                m.advise_range(memmap2::Advice::WillNeed, off, len)?;
                let sum = m[off..off + len].iter().step_by(PAGE as usize).fold(0u8, |a, &b| a ^ b);
                std::hint::black_box(sum);
                Ok(())
            }
        }
    }

    /// Starts reading the bytes `off..off + len` from storage without waiting, so that a
    /// [`Scene::load`] of them soon after waits less (posix_fadvise or madvise WILLNEED).
    pub fn prefetch(&self, off: u64, len: u64) {
        match &self.backing {
            Backing::Owned(r) => r.prefetch(off, len),
            Backing::Image(_) => {}
            Backing::Mapped(m) => {
                let (off, len) = self.clamp_pages(off, len);
                if len > 0 {
                    let _ = m.advise_range(memmap2::Advice::WillNeed, off, len);
                }
            }
        }
    }

    /// Drops the bytes `off..off + len` (widened to whole pages) from this process's memory.
    /// Owned: they read as zeros until loaded again (pages shared with another loaded range
    /// stay until it is released too). Mapped: madvise DONTNEED, the next access faults the
    /// file back in. The caller guarantees that no thread is reading those bytes (the pager
    /// waits for a grace period first).
    pub fn release(&self, off: u64, len: u64) -> std::io::Result<()> {
        match &self.backing {
            Backing::Owned(r) => {
                r.release(off, len);
                Ok(())
            }
            // A decoded image is never dropped: nothing would read it back.
            Backing::Image(_) => Ok(()),
            Backing::Mapped(m) => {
                let (off, len) = self.clamp_pages(off, len);
                if len == 0 {
                    return Ok(());
                }
                // SAFETY: DONTNEED on a read-only file mapping only discards this process's
                // page table entries: later reads fault the same file bytes back in. No
                // `&mut` to the map exists, and views handed out stay valid.
                unsafe { m.unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, off, len) }
            }
        }
    }

    /// `(off, len)` widened to whole pages and clamped to the mapping.
    fn clamp_pages(&self, off: u64, len: u64) -> (usize, usize) {
        let file = self.bytes().len() as u64;
        let start = (off / PAGE * PAGE).min(file);
        let end = off.saturating_add(len).div_ceil(PAGE).saturating_mul(PAGE).min(file);
        (start as usize, end.saturating_sub(start) as usize)
    }

    fn tile_unchecked_view(&self, t: u32) -> Tile<'_> {
        let e = &self.tiles()[t as usize];
        let nodes_end = e.offset as usize + e.node_count as usize * NODE_BYTES;
        let blocks_end = nodes_end + e.blocks as usize * 144;
        Tile {
            nodes: bytemuck::cast_slice(&self.bytes()[e.offset as usize..nodes_end]),
            blocks: bytemuck::cast_slice(&self.bytes()[nodes_end..blocks_end]),
            node0: e.node0(),
            unit0: e.unit0(),
        }
    }

    /// Checks tile `t` now: its checksum and that every reference in it is in range.
    pub fn check_tile(&self, t: u32) -> Result<(), SceneError> {
        let tiles = self.tiles();
        let e = tiles.get(t as usize).ok_or_else(|| SceneError::corrupt(&self.path, format!("no tile {t}")))?;
        let corrupt =
            |what: String| SceneError::new(&self.path, SceneErrorKind::CorruptTile(t), format!("tile {t}: {what}"));
        let bytes = &self.bytes()[e.offset as usize..e.offset as usize + e.bytes as usize];
        if !sums_match(xxhash_rust::xxh3::xxh3_64(bytes), e.checksum) {
            return Err(corrupt("checksum mismatch (the file is damaged)".into()));
        }
        let v = self.tile_unchecked_view(t);
        let (node0, unit0) = (v.node0, v.unit0);
        for (i, n) in v.nodes.iter().enumerate() {
            for c in n.child {
                // Absolute positions: inside this tile (inner nodes after the referring one,
                // leaves on a block boundary with all their blocks), or a node of another
                // tile of the same part.
                let ok = match ChildRef(c).decode() {
                    Child::Empty => true,
                    Child::Inner(k) => k > node0 + i as u64 && k < node0 + v.nodes.len() as u64,
                    Child::Leaf { unit, count } => {
                        unit >= unit0
                            && (unit - unit0).is_multiple_of(9)
                            && count > 0
                            && (unit - unit0) / 9 + (count as u64).div_ceil(4) <= v.blocks.len() as u64
                    }
                    Child::Link { tile, node } => tiles.get(tile as usize).is_some_and(|o| {
                        o.part == e.part && tile != t && node >= o.node0() && node < o.node0() + o.node_count as u64
                    }),
                    Child::Part(_) => false,
                };
                if !ok {
                    return Err(corrupt(format!("node {i} has an out-of-range child reference")));
                }
            }
        }
        Ok(())
    }

    /// Checks every tile (reads the whole file, [`Scene::check_all_tiles`]). Returns the
    /// first fault.
    pub fn verify_all(&self) -> Result<(), SceneError> {
        match self.check_all_tiles() {
            true => Ok(()),
            false => Err(self.first_error().expect("a tile found unsound records its fault")),
        }
    }

    /// The first fault met in a tile since opening, if any. Renderers check this after a
    /// frame and report it: a corrupt tile never shows as garbage.
    pub fn first_error(&self) -> Option<SceneError> {
        self.first_error.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    fn attr<T: bytemuck::Pod>(&self, off: u64, prim: u32) -> T {
        let size = std::mem::size_of::<T>();
        let at = off as usize + prim as usize * size;
        bytemuck::pod_read_unaligned(&self.bytes()[at..at + size])
    }

    /// The vertex normals of triangle slot `prim` of `part`, if the part has normals.
    pub fn normals(&self, part: u32, prim: u32) -> Option<[[f32; 3]; 3]> {
        let p = self.parts().get(part as usize)?;
        if p.normals_off == 0 || prim as u64 >= p.slot_count {
            return None;
        }
        let w: PackedNormals = self.attr(p.normals_off, prim);
        Some([decode_normal(w.0[0])?, decode_normal(w.0[1])?, decode_normal(w.0[2])?])
    }

    /// The texture coordinates of triangle `prim` of `part`, if any.
    pub fn uvs(&self, part: u32, prim: u32) -> Option<[[f32; 2]; 3]> {
        let p = self.parts().get(part as usize)?;
        (p.uvs_off != 0 && (prim as u64) < p.slot_count).then(|| self.attr(p.uvs_off, prim))
    }

    /// The RGBA8 vertex colours of triangle `prim` of `part`, if any.
    pub fn colors(&self, part: u32, prim: u32) -> Option<[[u8; 4]; 3]> {
        let p = self.parts().get(part as usize)?;
        (p.colors_off != 0 && (prim as u64) < p.slot_count).then(|| self.attr(p.colors_off, prim))
    }

    /// The material of triangle `prim` of `part`, if any.
    pub fn material(&self, part: u32, prim: u32) -> Option<&MaterialDesc> {
        self.materials.get(self.material_index(part, prim)? as usize)
    }

    /// The index in [`Scene::materials`] of triangle `prim` of `part`'s material, if any.
    pub fn material_index(&self, part: u32, prim: u32) -> Option<u32> {
        let p = self.parts().get(part as usize)?;
        if p.materials_off == 0 || prim as u64 >= p.slot_count {
            return None;
        }
        let id: u32 = self.attr(p.materials_off, prim);
        ((id as usize) < self.materials.len()).then_some(id)
    }
}

/// Whether a checksum matches. Fuzzing builds (`--cfg fuzzing`, set by cargo-afl) accept every
/// checksum, so that mutated files reach the structural checks behind them instead of all
/// stopping at the first hash (fuzz/README.md).
#[inline]
fn sums_match(computed: u64, stored: u64) -> bool {
    cfg!(fuzzing) || computed == stored
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tiles of random sizes, page-aligned one after another (some of a single page, many
    /// in a bucket when the buckets are large): every block unit of every tile is found in
    /// its tile, as a search of the whole directory finds it.
    #[test]
    fn tile_index_finds_the_tile_of_every_block() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rand = |n: u64| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed % n
        };
        for count in [1usize, 2, 7, 100, 1000] {
            let mut tiles = Vec::new();
            let mut offset = PAGE;
            for _ in 0..count {
                // Mostly small tiles, now and then a large one (buckets then hold many small).
                let (nodes, blocks) = match rand(10) {
                    0 => (1 + rand(400) as u32, 1 + rand(20_000) as u32),
                    _ => (1 + rand(3) as u32, 1 + rand(40) as u32),
                };
                let bytes = nodes * NODE_BYTES as u32 + blocks * 144;
                tiles.push(TileEntry {
                    offset,
                    bytes,
                    node_count: nodes,
                    blocks,
                    part: rand(5) as u32,
                    first_slot: rand(1 << 20) as u32,
                    stored_node_bytes: 0,
                    checksum: 0,
                });
                offset = (offset + bytes as u64).div_ceil(PAGE) * PAGE;
            }
            let index = TileIndex::new(&tiles, offset);
            assert!(index.first.len() <= 4 * count + 66, "{} buckets for {count} tiles", index.first.len());
            for (t, e) in tiles.iter().enumerate() {
                for b in [0, 1, e.blocks / 2, e.blocks - 1] {
                    let unit = e.unit0() + 9 * b as u64;
                    let want = tiles.partition_point(|x| x.unit0() <= unit) - 1;
                    assert_eq!(want, t);
                    assert_eq!(index.tile_of(unit), t as u32, "{count} tiles: block {b} of tile {t}");
                    assert_eq!(
                        index.slot_of(unit),
                        (e.part, e.first_slot + 4 * b),
                        "{count} tiles: block {b} of tile {t}"
                    );
                }
            }
            // Outside every tile's blocks (the header page, past the end): some tile, no panic.
            for unit in [0, 1, offset / 16, u64::MAX] {
                assert!((index.tile_of(unit) as usize) < count);
                index.slot_of(unit);
            }
        }
    }
}
