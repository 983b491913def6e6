//! Writing a scene file: header and top-level tree first, parts appended as they are
//! built (from any thread, through a mutex the caller holds), tables and header at the end,
//! then an atomic rename into place. A writer dropped before [`SceneWriter::finish`] removes
//! its temporary file, so no half-written scene ever carries the output's name.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use megaray_base::Aabb;

use crate::error::{SceneError, SceneErrorKind};
use crate::format::*;

/// A child reference as a builder writes it into a [`TileBlob`] or the top-level tree,
/// by positions within what it builds: a node by its index in the tile (or in the top-level
/// tree), a leaf by its first block's index in the tile, a link by the tile's index in the
/// part and the node's index in that tile. The writer turns them into the file's absolute
/// [`ChildRef`]s. Same tags as a [`ChildRef`]; all ones is an empty slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlobRef(pub u64);

/// What a [`BlobRef`] points at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlobChild {
    Empty,
    Inner(u32),
    Leaf { first: u32, count: u32 },
    Link { tile: u32, node: u32 },
    Part(u32),
}

impl BlobRef {
    pub const EMPTY: BlobRef = BlobRef(u64::MAX);

    pub fn inner(node: u32) -> BlobRef {
        BlobRef(node as u64)
    }
    pub fn leaf(first: u32, count: u32) -> BlobRef {
        debug_assert!((1..=255).contains(&count));
        BlobRef((1 << 62) | ((count as u64) << 32) | first as u64)
    }
    pub fn link(tile: u32, node: u32) -> BlobRef {
        debug_assert!(node < (1 << 30));
        BlobRef((2 << 62) | ((node as u64) << 32) | tile as u64)
    }
    pub fn part(part: u32) -> BlobRef {
        BlobRef((3 << 62) | part as u64)
    }

    pub fn decode(self) -> BlobChild {
        if self.0 == u64::MAX {
            return BlobChild::Empty;
        }
        let lo = self.0 as u32;
        match self.0 >> 62 {
            0 => BlobChild::Inner(lo),
            1 => BlobChild::Leaf { first: lo, count: ((self.0 >> 32) & 0xff) as u32 },
            2 => BlobChild::Link { tile: lo, node: ((self.0 >> 32) & 0x3fff_ffff) as u32 },
            _ => BlobChild::Part(lo),
        }
    }
}

/// One tile as the builder produces it (its nodes' children are [`BlobRef`]s).
#[derive(Clone, Debug, Default)]
pub struct TileBlob {
    pub nodes: Vec<Node8>,
    pub blocks: Vec<Tri4>,
}

impl TileBlob {
    /// Bytes of the tile's payload (nodes then triangle blocks), without page padding.
    pub fn bytes(&self) -> u64 {
        (self.nodes.len() * NODE_BYTES + self.blocks.len() * 144) as u64
    }
}

/// One part as the builder produces it. Links in its nodes name tiles by their index
/// in `tiles` ([`BlobRef`]; the writer turns them into file-wide tile numbers and absolute
/// positions). Attribute arrays have one entry per triangle slot (4 per block).
#[derive(Clone, Debug, Default)]
pub struct PartBlob {
    pub bounds: Aabb,
    /// Triangles in the part (not counting padding lanes).
    pub tri_count: u64,
    pub depth: u32,
    pub tiles: Vec<TileBlob>,
    pub root_tile: u32,
    pub root_node: u32,
    pub normals: Option<Vec<PackedNormals>>,
    pub uvs: Option<Vec<[[f32; 2]; 3]>>,
    pub colors: Option<Vec<[[u8; 4]; 3]>>,
    pub materials: Option<Vec<u32>>,
    /// The part's component runs, `(first_slot, component)` in slot order
    /// ([`crate::components::runs_of`]); empty when the scene names no components.
    pub components: Vec<(u32, u32)>,
}

impl PartBlob {
    /// Triangle slots: 4 per block.
    pub fn slot_count(&self) -> u64 {
        self.tiles.iter().map(|t| 4 * t.blocks.len() as u64).sum()
    }
}

/// A material as it goes into the table.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MaterialDesc {
    pub name: String,
    pub diffuse: Option<[f32; 3]>,
    pub specular: Option<[f32; 3]>,
    pub shininess: Option<f32>,
    pub opacity: Option<f32>,
    pub metallic: Option<f32>,
    pub roughness: Option<f32>,
    pub texture: Option<String>,
}

/// Streams a scene file to disk. See the module documentation.
pub struct SceneWriter {
    path: PathBuf,
    tmp: PathBuf,
    file: Option<File>,
    cursor: u64,
    part_count: u32,
    parts: Vec<Option<PartEntry>>,
    /// Levels of detail appended so far, in the order they came; numbered in `finish`.
    lods: Vec<PartEntry>,
    lod_capacity: u32,
    tiles: Vec<TileEntry>,
    tri_count: u64,
    tile_target: u32,
    top_nodes: Vec<Node8>,
    top_depth: u32,
    top_off: u64,
    parts_off: u64,
    attr_flags: u32,
    /// Objects, groups and instances ([`SceneWriter::set_instancing`]).
    instancing: Option<crate::Instancing>,
    /// The scene's own settings ([`SceneWriter::set_settings`]).
    settings: String,
    /// Component names and triangle counts ([`SceneWriter::set_components`]).
    components: crate::Components,
    /// Whether the file is written compact ([`SceneWriter::set_compact`]): then `cursor`
    /// is where the next bytes lie in the image, `stored` where they go in the file.
    compact: bool,
    stored: u64,
    /// The compact file's extents after its first (the bytes before `prefix_end`, which
    /// lie in the file where they lie in the image).
    extents: Vec<Extent>,
    prefix_end: u64,
}

fn page_up(x: u64) -> u64 {
    x.div_ceil(PAGE) * PAGE
}

impl SceneWriter {
    /// Starts `path` (written as a temporary file beside it) with the top-level tree, whose
    /// `Part` references name the `part_count` parts to come, and room in the part directory
    /// for up to `lod_capacity` levels of detail ([`SceneWriter::append_lod`]).
    pub fn create(
        path: &Path,
        top_nodes: Vec<Node8>,
        top_depth: u32,
        part_count: u32,
        lod_capacity: u32,
        tile_target: u32,
    ) -> Result<SceneWriter, SceneError> {
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        // `.NAME.tmp-PID` (megaray_base::temp); those of killed builds here go first.
        megaray_base::temp::clean_stale(dir);
        let tmp = megaray_base::temp::temp_path(path)
            .ok_or_else(|| SceneError::new(path, SceneErrorKind::Io, "not a file name".to_string()))?;
        let file = File::create(&tmp).map_err(|e| SceneError::io(path, "create", &e))?;
        let top_off = HEADER_PAGE;
        let parts_off = top_off + (top_nodes.len() * NODE_BYTES) as u64;
        // The top-level tree's inner references, made absolute (node `i` lies at
        // `top_off + 256 i`); its parts become links to their roots in `finish`, once the
        // parts are placed.
        let mut top_nodes = top_nodes;
        for n in &mut top_nodes {
            for c in n.child.iter_mut() {
                *c = match BlobRef(*c).decode() {
                    BlobChild::Empty => ChildRef::EMPTY.0,
                    BlobChild::Inner(k) => ChildRef::inner(top_off / NODE_BYTES as u64 + k as u64).0,
                    BlobChild::Part(p) => {
                        assert!(p < part_count, "top-level tree: part {p} of {part_count}");
                        BlobRef::part(p).0
                    }
                    other => panic!("top-level tree: {other:?} is not a top-level child"),
                };
            }
        }
        let cursor = page_up(parts_off + (part_count as u64 + lod_capacity as u64) * 128);
        let mut w = SceneWriter {
            path: path.to_path_buf(),
            tmp,
            file: Some(file),
            cursor,
            part_count,
            parts: vec![None; part_count as usize],
            lods: Vec::new(),
            lod_capacity,
            tiles: Vec::new(),
            tri_count: 0,
            tile_target,
            top_nodes,
            top_depth,
            top_off,
            parts_off,
            attr_flags: 0,
            instancing: None,
            settings: String::new(),
            components: crate::Components::default(),
            compact: false,
            stored: cursor,
            extents: Vec::new(),
            prefix_end: cursor,
        };
        w.write_at(bytemuck::cast_slice(&w.top_nodes.clone()), top_off)?;
        Ok(w)
    }

    /// Writes the file compact (`compact.rs`): tiles in the compact codec, everything after
    /// the part directory packed, and an extent table mapping the image onto the file.
    /// Call before appending parts.
    pub fn set_compact(&mut self, on: bool) {
        assert!(self.tiles.is_empty(), "set_compact after parts were appended");
        self.compact = on;
    }

    /// Writes `bytes` at image offset `off`: there in a plain file; packed at the end of a
    /// compact one, with an extent for them.
    fn put(&mut self, bytes: &[u8], off: u64) -> Result<(), SceneError> {
        if !self.compact {
            return self.write_at(bytes, off);
        }
        self.put_stored(bytes, off, bytes.len() as u64, EXTENT_RAW)
    }

    /// Writes `bytes` (image bytes `off..off + image_len` as `kind`) at the end of a
    /// compact file.
    fn put_stored(&mut self, bytes: &[u8], off: u64, image_len: u64, kind: u32) -> Result<(), SceneError> {
        if bytes.is_empty() {
            return Ok(());
        }
        let at = self.stored;
        self.write_at(bytes, at)?;
        let stored_len = bytes.len() as u64;
        self.extents.push(Extent { image_off: off, image_len, stored_off: at, stored_len, kind, reserved: 0 });
        self.stored = (at + stored_len).next_multiple_of(8);
        Ok(())
    }

    fn write_at(&mut self, bytes: &[u8], off: u64) -> Result<(), SceneError> {
        let f = self.file.as_ref().expect("writer used after finish");
        f.write_all_at(bytes, off).map_err(|e| SceneError::io(&self.path, "write", &e))
    }

    /// Appends part `index`: its tiles (page aligned), then its attribute arrays.
    pub fn append_part(&mut self, index: u32, part: &PartBlob) -> Result<(), SceneError> {
        assert!(index < self.part_count && self.parts[index as usize].is_none());
        let entry = self.append_blob(index, part)?;
        self.tri_count += part.tri_count;
        self.parts[index as usize] = Some(PartEntry { lod_of: index, ..entry });
        Ok(())
    }

    /// Appends level `level` (1 the finest) of detail of part `of`, whose triangles all lie
    /// within `error` of part `of`'s: as a part of its own, numbered after the full-detail
    /// parts, in the order of (`of`, `level`), when the file is finished.
    pub fn append_lod(&mut self, of: u32, level: u32, error: f32, part: &PartBlob) -> Result<(), SceneError> {
        assert!(of < self.part_count && level >= 1 && error.is_finite());
        assert!((self.lods.len() as u32) < self.lod_capacity, "more levels of detail than the room made for them");
        // Numbered provisionally in arrival order (the tiles' `part` says so until `finish`).
        let index = self.part_count + self.lods.len() as u32;
        let entry = self.append_blob(index, part)?;
        self.lods.push(PartEntry { lod_of: of, lod_level: level, lod_error: error, ..entry });
        Ok(())
    }

    /// Writes `part`'s tiles and attributes, its tiles numbered as of part `index`.
    fn append_blob(&mut self, index: u32, part: &PartBlob) -> Result<PartEntry, SceneError> {
        let first_tile = self.tiles.len() as u32;
        let tri_count = part.tri_count;
        let slot_count = part.slot_count();
        for (what, n) in [
            ("normals", part.normals.as_ref().map(|a| a.len())),
            ("uvs", part.uvs.as_ref().map(|a| a.len())),
            ("colors", part.colors.as_ref().map(|a| a.len())),
            ("materials", part.materials.as_ref().map(|a| a.len())),
        ] {
            assert!(n.is_none_or(|n| n as u64 == slot_count), "part {index}: {what} array is not one per slot");
        }
        assert!(
            part.components
                .iter()
                .all(|&(s, c)| u64::from(s) < slot_count.max(1) && (c as usize) < self.components.names.len()),
            "part {index}: a component run outside the part or the table"
        );
        self.components.runs.extend(part.components.iter().map(|&(first_slot, component)| crate::components::Run {
            part: index,
            first_slot,
            component,
        }));
        let mut first_slot = 0u32;
        let start = self.cursor;
        let mut node_count = 0u64;
        let mut buf: Vec<u8> = Vec::new();
        // Where each tile of the part will lie (each starts on a page), for absolute references.
        let mut offsets = Vec::with_capacity(part.tiles.len());
        let mut at = self.cursor;
        for tile in &part.tiles {
            offsets.push(at);
            at += page_up(tile.bytes());
        }
        if at > (ChildRef::MAX_NODE + 1) * NODE_BYTES as u64
            || first_tile as u64 + part.tiles.len() as u64 > ChildRef::MAX_TILE as u64 + 1
        {
            let msg = "the scene is larger than the format can address (16 TiB of file, 2^26 tiles)";
            return Err(SceneError::new(&self.path, SceneErrorKind::TooLarge, msg));
        }
        for (ti, tile) in part.tiles.iter().enumerate() {
            buf.clear();
            let node0 = offsets[ti] / NODE_BYTES as u64;
            let unit0 = (offsets[ti] + (tile.nodes.len() * NODE_BYTES) as u64) / 16;
            for n in &tile.nodes {
                let mut n = *n;
                for c in n.child.iter_mut() {
                    *c = match BlobRef(*c).decode() {
                        BlobChild::Empty => ChildRef::EMPTY,
                        BlobChild::Inner(k) => ChildRef::inner(node0 + k as u64),
                        BlobChild::Leaf { first, count } => ChildRef::leaf(unit0 + 9 * first as u64, count),
                        BlobChild::Link { tile, node } => {
                            ChildRef::link(tile + first_tile, offsets[tile as usize] / NODE_BYTES as u64 + node as u64)
                        }
                        BlobChild::Part(_) => panic!("part {index}: a part reference inside a part"),
                    }
                    .0;
                }
                buf.extend_from_slice(bytemuck::bytes_of(&n));
            }
            buf.extend_from_slice(bytemuck::cast_slice(&tile.blocks));
            let mut entry = TileEntry {
                offset: self.cursor,
                bytes: buf.len() as u32,
                node_count: tile.nodes.len() as u32,
                blocks: tile.blocks.len() as u32,
                part: index,
                first_slot,
                stored_node_bytes: 0,
                checksum: xxhash_rust::xxh3::xxh3_64(&buf),
            };
            node_count += tile.nodes.len() as u64;
            first_slot += 4 * tile.blocks.len() as u32;
            let len = buf.len() as u64;
            let off = self.cursor;
            if self.compact {
                let nodes = tile.nodes.len() as u32;
                match crate::compact::encode(&buf, nodes, crate::compact::TilePlace::at(off, nodes)) {
                    Some((stored, node_bytes)) => {
                        self.put_stored(&stored, off, len, EXTENT_TILE)?;
                        entry.stored_node_bytes = node_bytes;
                    }
                    None => {
                        self.put(&buf, off)?;
                        entry.stored_node_bytes = nodes * NODE_BYTES as u32;
                    }
                }
            } else {
                buf.resize(page_up(len) as usize, 0);
                self.write_at(&buf, off)?;
            }
            self.cursor += page_up(len);
            self.tiles.push(entry);
        }
        let tile_bytes = self.cursor - start;
        let mut entry = PartEntry {
            bounds: part.bounds,
            tri_count: tri_count as u32,
            first_tile,
            tile_count: part.tiles.len() as u32,
            root_tile: first_tile + part.root_tile,
            root_node: part.root_node,
            depth: part.depth,
            first_prim: 0, // set in part order by `finish`
            node_count,
            tile_bytes,
            slot_count,
            normals_off: 0,
            uvs_off: 0,
            colors_off: 0,
            materials_off: 0,
            lod_of: index,
            lod_level: 0,
            lod_error: 0.0,
            lod_next: NO_PART,
        };
        if let Some(a) = &part.normals {
            entry.normals_off = self.append_attr(bytemuck::cast_slice(a))?;
            self.attr_flags |= ATTR_NORMAL;
        }
        if let Some(a) = &part.uvs {
            entry.uvs_off = self.append_attr(bytemuck::cast_slice(a))?;
            self.attr_flags |= ATTR_UV;
        }
        if let Some(a) = &part.colors {
            entry.colors_off = self.append_attr(bytemuck::cast_slice(a))?;
            self.attr_flags |= ATTR_COLOR;
        }
        if let Some(a) = &part.materials {
            entry.materials_off = self.append_attr(bytemuck::cast_slice(a))?;
            self.attr_flags |= ATTR_MATERIAL;
        }
        Ok(entry)
    }

    fn append_attr(&mut self, bytes: &[u8]) -> Result<u64, SceneError> {
        let off = self.cursor;
        self.put(bytes, off)?;
        self.cursor = page_up(off + bytes.len() as u64);
        Ok(off)
    }

    /// Makes the scene its instances: `inst`'s objects name the parts (in order, covering
    /// all), their trees lie in the top-level tree given to [`SceneWriter::create`], and
    /// group 0 is what a renderer shows. Checked in [`SceneWriter::finish`].
    pub fn set_instancing(&mut self, inst: crate::Instancing) {
        self.instancing = Some(inst);
    }

    /// Stores `json` (a UTF-8 JSON document: the scene's camera and lights as its source
    /// gave them) after the tables.
    pub fn set_settings(&mut self, json: String) {
        self.settings = json;
    }

    /// Names the scene's components (their triangle counts alongside); parts then give their
    /// runs ([`PartBlob::components`]). Call before appending parts.
    pub fn set_components(&mut self, names: Vec<String>, tri_counts: Vec<u64>) {
        assert_eq!(names.len(), tri_counts.len());
        self.components.names = names;
        self.components.tri_counts = tri_counts;
    }

    /// Tiles appended so far.
    pub fn tile_count(&self) -> u32 {
        self.tiles.len() as u32
    }

    /// Writes the tables and the header, syncs, and renames the file into place. Returns the
    /// file's size in bytes.
    pub fn finish(
        mut self,
        bounds: Aabb,
        degenerate_dropped: u64,
        materials: &[MaterialDesc],
    ) -> Result<u64, SceneError> {
        let mut parts = Vec::with_capacity(self.parts.len() + self.lods.len());
        let mut first_prim = 0;
        for (i, p) in self.parts.iter().enumerate() {
            match p {
                Some(p) => parts.push(PartEntry { first_prim, ..*p }),
                None => panic!("part {i} was never appended"),
            }
            first_prim += parts[i].tri_count as u64;
        }
        // Levels of detail after the parts, by (part, level); each chained to the next
        // coarser one, the part to its finest; their tiles renumbered to match.
        let mut order: Vec<usize> = (0..self.lods.len()).collect();
        order.sort_by_key(|&i| (self.lods[i].lod_of, self.lods[i].lod_level));
        let mut final_index = vec![0u32; self.lods.len()];
        for (rank, &i) in order.iter().enumerate() {
            final_index[i] = self.part_count + rank as u32;
        }
        for &i in &order {
            let e = self.lods[i];
            let index = final_index[i];
            let of = e.lod_of as usize;
            let prev = if e.lod_level == 1 { of } else { parts.len() - 1 };
            assert!(
                parts[prev].lod_of == e.lod_of && parts[prev].lod_level + 1 == e.lod_level,
                "the levels of detail of part {of} are not numbered 1, 2, ..."
            );
            parts[prev].lod_next = index;
            parts.push(PartEntry { first_prim: parts[of].first_prim, ..e });
            for t in &mut self.tiles[e.first_tile as usize..(e.first_tile + e.tile_count) as usize] {
                t.part = index;
            }
        }
        // Component runs of levels of detail, renumbered as their parts were.
        let mut comps = std::mem::take(&mut self.components);
        for r in &mut comps.runs {
            if r.part >= self.part_count {
                r.part = final_index[(r.part - self.part_count) as usize];
            }
        }
        comps.runs.sort_unstable();
        // The top-level tree's parts, as links to their roots (traversal then never looks a
        // part up), written over the placeholder `create` wrote.
        for n in &mut self.top_nodes {
            for c in n.child.iter_mut() {
                if let BlobChild::Part(p) = BlobRef(*c).decode() {
                    let e = &parts[p as usize];
                    let root = self.tiles[e.root_tile as usize].node0() + e.root_node as u64;
                    *c = ChildRef::link(e.root_tile, root).0;
                }
            }
        }
        let top_off = self.top_off;
        self.write_at(bytemuck::cast_slice(&self.top_nodes.clone()), top_off)?;
        let tiles_off = self.cursor;
        let tiles = std::mem::take(&mut self.tiles);
        self.put(bytemuck::cast_slice(&tiles), tiles_off)?;
        let materials_off = page_up(tiles_off + (tiles.len() * 40) as u64);
        let mat_bytes = encode_materials(materials);
        self.put(&mat_bytes, materials_off)?;
        let mut end = materials_off + mat_bytes.len() as u64;
        let inst = self.instancing.take();
        let inst_bytes = inst.as_ref().map(|i| i.encode()).unwrap_or_default();
        let mut instances_off = 0;
        if let Some(i) = &inst {
            let bad = |e: String| SceneError::new(&self.path, SceneErrorKind::Corrupt, format!("instances: {e}"));
            i.check(self.part_count, self.top_nodes.len() as u32, materials.len() as u32).map_err(bad)?;
            instances_off = page_up(end);
            self.put(&inst_bytes, instances_off)?;
            end = instances_off + inst_bytes.len() as u64;
        }
        let settings = std::mem::take(&mut self.settings).into_bytes();
        let settings_off = if settings.is_empty() { 0 } else { end };
        if !settings.is_empty() {
            self.put(&settings, settings_off)?;
            end += settings.len() as u64;
        }
        let comp_bytes = if comps.is_empty() { Vec::new() } else { comps.encode() };
        let components_off = if comp_bytes.is_empty() { 0 } else { end.next_multiple_of(8) };
        if !comp_bytes.is_empty() {
            self.put(&comp_bytes, components_off)?;
            end = components_off + comp_bytes.len() as u64;
        }
        let mut file_bytes = page_up(end);
        let (mut image_bytes, mut extents_off, mut extent_count, mut extents_checksum) = (0, 0, 0, 0);
        if self.compact {
            // The image is the plain file's bytes; the file, its first bytes and then
            // what `put` packed, then the extent table.
            image_bytes = file_bytes;
            let first = Extent {
                image_off: 0,
                image_len: self.prefix_end,
                stored_off: 0,
                stored_len: self.prefix_end,
                kind: EXTENT_RAW,
                reserved: 0,
            };
            let mut extents = vec![first];
            extents.append(&mut self.extents);
            extents_off = self.stored;
            let table: &[u8] = bytemuck::cast_slice(&extents);
            self.write_at(table, extents_off)?;
            extents_checksum = xxhash_rust::xxh3::xxh3_64(table);
            extent_count = extents.len() as u64;
            file_bytes = page_up(extents_off + table.len() as u64);
        }
        let parts_off = self.parts_off;
        self.write_at(bytemuck::cast_slice(&parts), parts_off)?;

        let mut meta = Vec::new();
        meta.extend_from_slice(bytemuck::cast_slice(&self.top_nodes));
        meta.extend_from_slice(bytemuck::cast_slice(&parts));
        meta.extend_from_slice(bytemuck::cast_slice(&tiles));
        meta.extend_from_slice(&mat_bytes);
        meta.extend_from_slice(&inst_bytes);
        meta.extend_from_slice(&settings);
        meta.extend_from_slice(&comp_bytes);
        let mut h = Header {
            magic: MAGIC,
            version: VERSION,
            header_bytes: 256,
            file_bytes,
            tri_count: self.tri_count,
            degenerate_dropped,
            bounds,
            part_count: parts.len() as u32,
            tile_count: tiles.len() as u32,
            tile_target: self.tile_target,
            attr_flags: self.attr_flags,
            top_nodes_off: self.top_off,
            top_node_count: self.top_nodes.len() as u32,
            top_depth: self.top_depth,
            parts_off,
            tiles_off,
            materials_off,
            materials_bytes: mat_bytes.len() as u64,
            material_count: materials.len() as u32,
            lod_part_count: self.lods.len() as u32,
            meta_checksum: xxhash_rust::xxh3::xxh3_64(&meta),
            instances_off,
            instances_bytes: inst_bytes.len() as u64,
            object_count: inst.as_ref().map_or(0, |i| i.objects.len() as u32),
            group_count: inst.as_ref().map_or(0, |i| i.groups.len() as u32),
            instance_count: inst.as_ref().map_or(0, |i| i.instances.len() as u32),
            reserved0: 0,
            settings_off,
            settings_bytes: settings.len() as u64,
            components_off,
            components_bytes: comp_bytes.len() as u64,
            component_count: comps.names.len() as u32,
            component_run_count: comps.runs.len() as u32,
            image_bytes,
            extents_off,
            extent_count,
            extents_checksum,
            header_checksum: 0,
        };
        h.header_checksum = xxhash_rust::xxh3::xxh3_64(&bytemuck::bytes_of(&h)[..248]);
        self.write_at(bytemuck::bytes_of(&h), 0)?;
        let file = self.file.take().expect("finish called twice");
        file.set_len(file_bytes).map_err(|e| SceneError::io(&self.path, "write", &e))?;
        file.sync_all().map_err(|e| SceneError::io(&self.path, "sync", &e))?;
        drop(file);
        std::fs::rename(&self.tmp, &self.path).map_err(|e| SceneError::io(&self.path, "rename into place", &e))?;
        Ok(file_bytes)
    }
}

impl Drop for SceneWriter {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

fn encode_materials(mats: &[MaterialDesc]) -> Vec<u8> {
    let mut recs = Vec::with_capacity(mats.len());
    let mut strings: Vec<u8> = Vec::new();
    for m in mats {
        let mut r = MaterialRecord {
            diffuse: m.diffuse.unwrap_or([0.8; 3]),
            specular: m.specular.unwrap_or([0.0; 3]),
            shininess: m.shininess.unwrap_or(0.0),
            opacity: m.opacity.unwrap_or(1.0),
            metallic: m.metallic.unwrap_or(0.0),
            roughness: m.roughness.unwrap_or(1.0),
            flags: 0,
            name_off: strings.len() as u32,
            name_len: m.name.len() as u32,
            texture_off: 0,
            texture_len: 0,
            reserved: 0,
        };
        strings.extend_from_slice(m.name.as_bytes());
        let bits = [
            (m.diffuse.is_some(), MAT_HAS_DIFFUSE),
            (m.specular.is_some(), MAT_HAS_SPECULAR),
            (m.shininess.is_some(), MAT_HAS_SHININESS),
            (m.opacity.is_some(), MAT_HAS_OPACITY),
            (m.metallic.is_some(), MAT_HAS_METALLIC),
            (m.roughness.is_some(), MAT_HAS_ROUGHNESS),
            (m.texture.is_some(), MAT_HAS_TEXTURE),
        ];
        for (has, bit) in bits {
            if has {
                r.flags |= bit;
            }
        }
        if let Some(t) = &m.texture {
            r.texture_off = strings.len() as u32;
            r.texture_len = t.len() as u32;
            strings.extend_from_slice(t.as_bytes());
        }
        recs.push(r);
    }
    let mut out = bytemuck::cast_slice::<MaterialRecord, u8>(&recs).to_vec();
    out.extend_from_slice(&strings);
    out
}

/// Reads a material table back (used by the reader; kept beside the encoder).
pub(crate) fn decode_materials(bytes: &[u8], count: u32) -> Option<Vec<MaterialDesc>> {
    let rec_bytes = (count as usize).checked_mul(64)?;
    if rec_bytes > bytes.len() {
        return None;
    }
    let (recs, strings) = bytes.split_at(rec_bytes);
    let recs: Vec<MaterialRecord> = recs.chunks_exact(64).map(bytemuck::pod_read_unaligned).collect();
    let s = |off: u32, len: u32| -> Option<String> {
        let end = (off as usize).checked_add(len as usize)?;
        Some(String::from_utf8_lossy(strings.get(off as usize..end)?).into_owned())
    };
    let mut out = Vec::with_capacity(recs.len());
    for r in recs {
        let f = |bit: u32| r.flags & bit != 0;
        out.push(MaterialDesc {
            name: s(r.name_off, r.name_len)?,
            diffuse: f(MAT_HAS_DIFFUSE).then_some(r.diffuse),
            specular: f(MAT_HAS_SPECULAR).then_some(r.specular),
            shininess: f(MAT_HAS_SHININESS).then_some(r.shininess),
            opacity: f(MAT_HAS_OPACITY).then_some(r.opacity),
            metallic: f(MAT_HAS_METALLIC).then_some(r.metallic),
            roughness: f(MAT_HAS_ROUGHNESS).then_some(r.roughness),
            texture: if f(MAT_HAS_TEXTURE) { Some(s(r.texture_off, r.texture_len)?) } else { None },
        });
    }
    Some(out)
}
