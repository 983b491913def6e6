//! The on-disk structs of the `.mray` scene file. `docs/FORMAT.md` describes the same bytes
//! for readers in other languages; keep the two in step (and bump [`VERSION`] on any change).
//!
//! Everything is little-endian, `#[repr(C)]` and [`Pod`], with its size asserted at compile
//! time, so that the reader can cast mapped bytes without copying.

use bytemuck::{Pod, Zeroable};
use megaray_base::Aabb;

/// The first eight bytes of every scene file.
pub const MAGIC: [u8; 8] = *b"MRAYSCN\x1a";
/// The format version this code writes and reads.
pub const VERSION: u32 = 8;
/// The oldest version this code reads: version 5 is version 6 without instances, 6 is 7
/// without components, and 7 is 8 never compact (their fields were reserved zeros).
pub const MIN_VERSION: u32 = 5;
/// Page size: tiles and sections start on multiples of it.
pub const PAGE: u64 = 4096;
/// Bytes of the header page (the header struct is followed by zeros up to it).
pub const HEADER_PAGE: u64 = PAGE;

/// Header attribute flags: which attribute kinds some part carries.
pub const ATTR_NORMAL: u32 = 1;
pub const ATTR_UV: u32 = 2;
pub const ATTR_COLOR: u32 = 4;
pub const ATTR_MATERIAL: u32 = 8;

/// The file header, at byte 0. 256 bytes; the rest of the first page is zero.
///
/// | bytes | field |
/// |---|---|
/// | 0..8 | `magic` = `MRAYSCN\x1a` |
/// | 8..12 | `version` |
/// | 12..16 | `header_bytes` = 256 |
/// | 16..24 | `file_bytes`: the file's exact length |
/// | 24..32 | `tri_count`: triangles in the scene (full detail; levels of detail not counted) |
/// | 32..40 | `degenerate_dropped`: zero-area triangles the build dropped |
/// | 40..64 | `bounds`: scene bounding box (min xyz, max xyz) |
/// | 64..68 | `part_count`: full-detail parts, then `lod_part_count` levels of detail |
/// | 68..72 | `tile_count` |
/// | 72..76 | `tile_target`: the tile size the build aimed at, bytes |
/// | 76..80 | `attr_flags`: `ATTR_*` bits |
/// | 80..88 | `top_nodes_off`: offset of the top-level tree ([`Node8`] array, page aligned) |
/// | 88..92 | `top_node_count` |
/// | 92..96 | `top_depth`: depth of the top-level tree (root = 1) |
/// | 96..104 | `parts_off`: offset of the part directory ([`PartEntry`] array) |
/// | 104..112 | `tiles_off`: offset of the tile directory ([`TileEntry`] array) |
/// | 112..120 | `materials_off`: offset of the material table ([`MaterialRecord`] array + names) |
/// | 120..128 | `materials_bytes` |
/// | 128..132 | `material_count` |
/// | 132..136 | `lod_part_count`: the parts at the end of the directory that are levels of detail |
/// | 136..144 | `meta_checksum`: XXH3-64 of top-level tree, part, tile and material tables, the instance section, the settings and the component section, in that order |
/// | 144..152 | `instances_off`: offset of the instance section (`instances.rs`), or 0 |
/// | 152..160 | `instances_bytes` |
/// | 160..164 | `object_count` |
/// | 164..168 | `group_count` (0: no instances; the scene is its parts) |
/// | 168..172 | `instance_count` |
/// | 172..176 | reserved, zero |
/// | 176..184 | `settings_off`: offset of the settings (UTF-8 JSON: camera, lights), or 0 |
/// | 184..192 | `settings_bytes` |
/// | 192..200 | `components_off`: offset of the component section (`components.rs`), or 0 |
/// | 200..208 | `components_bytes` |
/// | 208..212 | `component_count` |
/// | 212..216 | `component_run_count` |
/// | 216..224 | `image_bytes`: 0 for a file that is its own image; else the file is *compact* (`compact.rs`): every offset above, and every reference, is a position in an image of this many bytes, which the [`Extent`] table maps onto the file |
/// | 224..232 | `extents_off`: file offset of the extent table (8-aligned), or 0 |
/// | 232..240 | `extent_count` |
/// | 240..248 | `extents_checksum`: XXH3-64 of the extent table |
/// | 248..256 | `header_checksum`: XXH3-64 of bytes 0..248 |
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct Header {
    pub magic: [u8; 8],
    pub version: u32,
    pub header_bytes: u32,
    pub file_bytes: u64,
    pub tri_count: u64,
    pub degenerate_dropped: u64,
    pub bounds: Aabb,
    pub part_count: u32,
    pub tile_count: u32,
    pub tile_target: u32,
    pub attr_flags: u32,
    pub top_nodes_off: u64,
    pub top_node_count: u32,
    pub top_depth: u32,
    pub parts_off: u64,
    pub tiles_off: u64,
    pub materials_off: u64,
    pub materials_bytes: u64,
    pub material_count: u32,
    pub lod_part_count: u32,
    pub meta_checksum: u64,
    pub instances_off: u64,
    pub instances_bytes: u64,
    pub object_count: u32,
    pub group_count: u32,
    pub instance_count: u32,
    pub reserved0: u32,
    pub settings_off: u64,
    pub settings_bytes: u64,
    pub components_off: u64,
    pub components_bytes: u64,
    pub component_count: u32,
    pub component_run_count: u32,
    pub image_bytes: u64,
    pub extents_off: u64,
    pub extent_count: u64,
    pub extents_checksum: u64,
    pub header_checksum: u64,
}
const _: () = assert!(std::mem::size_of::<Header>() == 256);

impl Header {
    /// Whether the file is compact: its image ([`Header::image_len`]) differs from its bytes.
    pub fn is_compact(&self) -> bool {
        self.version >= 8 && self.image_bytes != 0
    }

    /// The length of the scene's image, where every offset of the tables points.
    pub fn image_len(&self) -> u64 {
        if self.is_compact() {
            self.image_bytes
        } else {
            self.file_bytes
        }
    }
}

/// An extent kind: the image's bytes stored as they are.
pub const EXTENT_RAW: u32 = 0;
/// An extent kind: a tile stored by the compact tile codec (`compact.rs`).
pub const EXTENT_TILE: u32 = 1;

/// One run of a compact file's image and where its bytes are stored. 40 bytes. The table
/// lists extents in image order, none overlapping; image bytes no extent covers are zero.
///
/// | bytes | field |
/// |---|---|
/// | 0..8 | `image_off` |
/// | 8..16 | `image_len` |
/// | 16..24 | `stored_off`: file offset of the stored bytes |
/// | 24..32 | `stored_len` (equal to `image_len` for [`EXTENT_RAW`]) |
/// | 32..36 | `kind`: [`EXTENT_RAW`] or [`EXTENT_TILE`] |
/// | 36..40 | reserved, zero |
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Extent {
    pub image_off: u64,
    pub image_len: u64,
    pub stored_off: u64,
    pub stored_len: u64,
    pub kind: u32,
    pub reserved: u32,
}
const _: () = assert!(std::mem::size_of::<Extent>() == 40);

/// Children per BVH node.
pub const NODE_WIDTH: usize = 8;
/// Bytes of a [`Node8`].
pub const NODE_BYTES: usize = 256;

/// An 8-wide BVH node: the boxes of its eight children (structure of arrays, so one 8-wide
/// SIMD register, or two 4-wide ones, holds one plane of all eight) and their [`ChildRef`]s.
/// 256 bytes, four cache lines, 256-byte aligned in the file (node arrays start on pages).
/// Unused slots have an empty box (`lo = +inf`, `hi = -inf`) and the child
/// [`ChildRef::EMPTY`].
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct Node8 {
    pub lo_x: [f32; NODE_WIDTH],
    pub hi_x: [f32; NODE_WIDTH],
    pub lo_y: [f32; NODE_WIDTH],
    pub hi_y: [f32; NODE_WIDTH],
    pub lo_z: [f32; NODE_WIDTH],
    pub hi_z: [f32; NODE_WIDTH],
    pub child: [u64; NODE_WIDTH],
}
const _: () = assert!(std::mem::size_of::<Node8>() == NODE_BYTES);

impl Node8 {
    /// A node with eight empty slots.
    pub const EMPTY: Node8 = Node8 {
        lo_x: [f32::INFINITY; NODE_WIDTH],
        hi_x: [f32::NEG_INFINITY; NODE_WIDTH],
        lo_y: [f32::INFINITY; NODE_WIDTH],
        hi_y: [f32::NEG_INFINITY; NODE_WIDTH],
        lo_z: [f32::INFINITY; NODE_WIDTH],
        hi_z: [f32::NEG_INFINITY; NODE_WIDTH],
        child: [ChildRef::EMPTY.0; NODE_WIDTH],
    };

    /// Sets slot `i` to `child` (the bits of a [`ChildRef`], or, in a builder's blob, of a
    /// [`crate::writer::BlobRef`]) with bounds `b`.
    pub fn set(&mut self, i: usize, b: &Aabb, child: u64) {
        self.lo_x[i] = b.min[0];
        self.lo_y[i] = b.min[1];
        self.lo_z[i] = b.min[2];
        self.hi_x[i] = b.max[0];
        self.hi_y[i] = b.max[1];
        self.hi_z[i] = b.max[2];
        self.child[i] = child;
    }

    /// The node as eight 32-byte rows: rows 0..6 are `lo_x, hi_x, lo_y, hi_y, lo_z, hi_z`
    /// (row `2 * axis` the low planes, `2 * axis + 1` the high ones), rows 6..8 the children.
    #[inline(always)]
    pub fn planes(&self) -> &[[f32; NODE_WIDTH]; 8] {
        bytemuck::cast_ref(self)
    }

    /// The bounds of slot `i`.
    pub fn bounds(&self, i: usize) -> Aabb {
        Aabb { min: [self.lo_x[i], self.lo_y[i], self.lo_z[i]], max: [self.hi_x[i], self.hi_y[i], self.hi_z[i]] }
    }
}

/// A reference from a [`Node8`] slot to a child: one tagged 64-bit integer. Positions are
/// absolute, in units of the file (so that a reader that maps the whole file follows a
/// reference without looking up the tile it lies in): nodes by `offset / 256`, triangle
/// blocks by `offset / 16`.
///
/// | bits 63..62 | meaning | payload |
/// |---|---|---|
/// | `00` | inner node in the same node array | bits 0..36: the node's `offset / 256` |
/// | `01` | leaf: triangles of the same tile | bits 0..40: its first [`Tri4`]'s `offset / 16`, bits 40..48: triangle count (1..=255) |
/// | `10` | link: a node in another tile (from the top-level tree: a part's root) | bits 0..36: the node's `offset / 256`, bits 36..62: tile index |
/// | `11` | part: only in a builder's blobs ([`crate::writer::BlobRef`]); the writer makes it a link | bits 0..32: part index |
///
/// All ones is [`ChildRef::EMPTY`], an unused slot. Files are therefore at most 2^44 bytes
/// (16 TiB) with at most 2^26 tiles.
#[repr(transparent)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Pod, Zeroable)]
pub struct ChildRef(pub u64);

/// What a [`ChildRef`] points at, decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Child {
    Empty,
    /// A node, by `offset / 256`.
    Inner(u64),
    /// `count` triangles from the block at `offset / 16 == unit`.
    Leaf {
        unit: u64,
        count: u32,
    },
    /// A node (by `offset / 256`) of tile `tile`.
    Link {
        tile: u32,
        node: u64,
    },
    Part(u32),
}

impl ChildRef {
    pub const EMPTY: ChildRef = ChildRef(u64::MAX);
    const KIND_SHIFT: u32 = 62;
    /// Largest node position (`offset / 256`) a reference holds.
    pub const MAX_NODE: u64 = (1 << 36) - 1;
    /// Largest block position (`offset / 16`) a reference holds.
    pub const MAX_UNIT: u64 = (1 << 40) - 1;
    /// Largest tile index a link holds.
    pub const MAX_TILE: u32 = (1 << 26) - 1;

    pub fn inner(node: u64) -> ChildRef {
        debug_assert!(node <= Self::MAX_NODE);
        ChildRef(node)
    }
    pub fn leaf(unit: u64, count: u32) -> ChildRef {
        debug_assert!((1..=255).contains(&count) && unit <= Self::MAX_UNIT);
        ChildRef((1 << Self::KIND_SHIFT) | ((count as u64) << 40) | unit)
    }
    pub fn link(tile: u32, node: u64) -> ChildRef {
        debug_assert!(node <= Self::MAX_NODE && tile <= Self::MAX_TILE);
        ChildRef((2 << Self::KIND_SHIFT) | ((tile as u64) << 36) | node)
    }
    pub fn part(part: u32) -> ChildRef {
        ChildRef((3 << Self::KIND_SHIFT) | part as u64)
    }

    #[inline(always)]
    pub fn decode(self) -> Child {
        if self.0 == u64::MAX {
            return Child::Empty;
        }
        match self.0 >> Self::KIND_SHIFT {
            0 => Child::Inner(self.0 & Self::MAX_NODE),
            1 => Child::Leaf { unit: self.0 & Self::MAX_UNIT, count: ((self.0 >> 40) & 0xff) as u32 },
            2 => Child::Link { tile: ((self.0 >> 36) & Self::MAX_TILE as u64) as u32, node: self.0 & Self::MAX_NODE },
            _ => Child::Part(self.0 as u32),
        }
    }
}

/// Four triangles as stored in a tile, structure of arrays, so that one ray is tested
/// against all four with 4-wide vectors. 144 bytes.
///
/// `v[3 * corner + axis][lane]`: e.g. `v[0]` holds the x of corner 0 of lanes 0..4, `v[5]`
/// the z of corner 1. A leaf of `count` triangles fills `ceil(count / 4)` consecutive blocks;
/// lanes past `count` in its last block are zero and never tested.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Tri4 {
    pub v: [[f32; 4]; 9],
}
const _: () = assert!(std::mem::size_of::<Tri4>() == 144);

impl Tri4 {
    /// The corners of the triangle in `lane`.
    #[inline]
    pub fn tri(&self, lane: usize) -> [[f32; 3]; 3] {
        let v = &self.v;
        [
            [v[0][lane], v[1][lane], v[2][lane]],
            [v[3][lane], v[4][lane], v[5][lane]],
            [v[6][lane], v[7][lane], v[8][lane]],
        ]
    }

    /// Stores `tri` in `lane`.
    #[inline]
    pub fn set(&mut self, lane: usize, tri: &[[f32; 3]; 3]) {
        for (c, corner) in tri.iter().enumerate() {
            for (k, x) in corner.iter().enumerate() {
                self.v[3 * c + k][lane] = *x;
            }
        }
    }
}

/// A part directory entry: one bottom-level BVH over a spatially coherent set of triangles.
/// 128 bytes.
///
/// A part's triangle *slots* (four per [`Tri4`] block, padding lanes included) are numbered
/// `0..slot_count` in tile order (tile `first_tile` first, blocks in each tile in order, lanes
/// in order); attribute arrays use the same numbering and hold `slot_count` entries. Attribute
/// offsets are zero where the part has no such attribute.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct PartEntry {
    pub bounds: Aabb,
    pub tri_count: u32,
    pub first_tile: u32,
    pub tile_count: u32,
    pub root_tile: u32,
    pub root_node: u32,
    /// Depth of the part's tree (a single leaf node = 1).
    pub depth: u32,
    /// Global number of the part's first triangle (parts number triangles consecutively).
    pub first_prim: u64,
    pub node_count: u64,
    /// Bytes of the part's tiles, padding included.
    pub tile_bytes: u64,
    /// Triangle slots: 4 per block (`tri_count` of them hold triangles).
    pub slot_count: u64,
    /// Offset of `slot_count` [`PackedNormals`], or 0.
    pub normals_off: u64,
    /// Offset of `slot_count` `[[f32; 2]; 3]` texture coordinates, or 0.
    pub uvs_off: u64,
    /// Offset of `slot_count` `[[u8; 4]; 3]` RGBA colours (linear, 0..255), or 0.
    pub colors_off: u64,
    /// Offset of `slot_count` `u32` material ids (`u32::MAX`: none), or 0.
    pub materials_off: u64,
    /// Levels of detail. For a full-detail part: its own index. For a level of detail: the
    /// full-detail part it stands in for.
    pub lod_of: u32,
    /// 0 for full detail; `k` for the `k`-th coarser level of `lod_of`.
    pub lod_level: u32,
    /// Every point of this part's triangles lies within this distance of the triangles of
    /// part `lod_of` (0 at full detail); never smaller than the finer level's.
    pub lod_error: f32,
    /// The next coarser level of `lod_of`, or [`NO_PART`] after the coarsest.
    pub lod_next: u32,
}
const _: () = assert!(std::mem::size_of::<PartEntry>() == 128);

/// No part: the end of a part's chain of levels of detail ([`PartEntry::lod_next`]).
pub const NO_PART: u32 = u32::MAX;

/// A tile directory entry. 40 bytes.
///
/// A tile is the unit of paging: a page-aligned block holding `node_count` [`Node8`]s and
/// then `blocks` [`Tri4`]s (`bytes = 256 * node_count + 144 * blocks`). Its nodes refer
/// to each other by index, to its own blocks, and to other tiles through links.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct TileEntry {
    pub offset: u64,
    pub bytes: u32,
    pub node_count: u32,
    pub blocks: u32,
    pub part: u32,
    /// Number (within the part) of the tile's first triangle slot (4 per block).
    pub first_slot: u32,
    /// In a compact file, the bytes its nodes take as stored (`compact.rs`; for `info`);
    /// otherwise 0.
    pub stored_node_bytes: u32,
    /// XXH3-64 of the tile's `bytes` bytes (as decoded, in a compact file).
    pub checksum: u64,
}
const _: () = assert!(std::mem::size_of::<TileEntry>() == 40);

impl TileEntry {
    /// The position (`offset / 256`) of the tile's node 0.
    #[inline(always)]
    pub fn node0(&self) -> u64 {
        self.offset / NODE_BYTES as u64
    }
    /// The position (`offset / 16`) of the tile's block 0 (right after its nodes).
    #[inline(always)]
    pub fn unit0(&self) -> u64 {
        (self.offset + self.node_count as u64 * NODE_BYTES as u64) / 16
    }
}

/// Three vertex normals, each octahedron-encoded into two snorm16 (x in the low half). 12 bytes.
/// A zero word means "no normal here: use the geometric one".
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct PackedNormals(pub [u32; 3]);
const _: () = assert!(std::mem::size_of::<PackedNormals>() == 12);

/// A material table entry. 64 bytes; names and texture paths are UTF-8 in the bytes that
/// follow the `material_count` records (offsets relative to the end of the records).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct MaterialRecord {
    pub diffuse: [f32; 3],
    pub specular: [f32; 3],
    pub shininess: f32,
    pub opacity: f32,
    pub metallic: f32,
    pub roughness: f32,
    /// `MAT_HAS_*` bits: which of the fields above the input gave.
    pub flags: u32,
    pub name_off: u32,
    pub name_len: u32,
    pub texture_off: u32,
    pub texture_len: u32,
    pub reserved: u32,
}
const _: () = assert!(std::mem::size_of::<MaterialRecord>() == 64);

pub const MAT_HAS_DIFFUSE: u32 = 1;
pub const MAT_HAS_SPECULAR: u32 = 2;
pub const MAT_HAS_SHININESS: u32 = 4;
pub const MAT_HAS_OPACITY: u32 = 8;
pub const MAT_HAS_METALLIC: u32 = 16;
pub const MAT_HAS_ROUGHNESS: u32 = 32;
pub const MAT_HAS_TEXTURE: u32 = 64;

/// Encodes a unit vector into the octahedral snorm16x2 word of [`PackedNormals`]
/// (never returns 0 for a valid vector, 0 stands for "none").
pub fn encode_normal(n: [f32; 3]) -> u32 {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if l1.is_nan() || l1 <= 0.0 || !l1.is_finite() {
        return 0;
    }
    let (mut x, mut y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * if ox >= 0.0 { 1.0 } else { -1.0 };
        y = (1.0 - ox.abs()) * if oy >= 0.0 { 1.0 } else { -1.0 };
    }
    let q = |v: f32| ((v.clamp(-1.0, 1.0) * 32767.0).round() as i16) as u16 as u32;
    let w = q(x) | (q(y) << 16);
    if w == 0 {
        // (0, 0) is +z; nudge so that 0 stays "none".
        1
    } else {
        w
    }
}

/// Decodes a [`PackedNormals`] word; `None` for 0.
pub fn decode_normal(w: u32) -> Option<[f32; 3]> {
    if w == 0 {
        return None;
    }
    let x = (w as u16 as i16) as f32 / 32767.0;
    let y = ((w >> 16) as u16 as i16) as f32 / 32767.0;
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 {
        ((1.0 - y.abs()) * if x >= 0.0 { 1.0 } else { -1.0 }, (1.0 - x.abs()) * if y >= 0.0 { 1.0 } else { -1.0 })
    } else {
        (x, y)
    };
    let l = (x * x + y * y + z * z).sqrt();
    Some([x / l, y / l, z / l])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn child_refs_round_trip() {
        for c in [
            Child::Inner(0),
            Child::Inner(ChildRef::MAX_NODE),
            Child::Leaf { unit: 123_456, count: 1 },
            Child::Leaf { unit: ChildRef::MAX_UNIT, count: 255 },
            Child::Link { tile: 77, node: ChildRef::MAX_NODE },
            Child::Link { tile: ChildRef::MAX_TILE, node: 16 },
            Child::Part(9),
        ] {
            let r = match c {
                Child::Inner(n) => ChildRef::inner(n),
                Child::Leaf { unit, count } => ChildRef::leaf(unit, count),
                Child::Link { tile, node } => ChildRef::link(tile, node),
                Child::Part(p) => ChildRef::part(p),
                Child::Empty => ChildRef::EMPTY,
            };
            assert_eq!(r.decode(), c);
        }
        assert_eq!(ChildRef::EMPTY.decode(), Child::Empty);
    }

    #[test]
    fn normals_round_trip() {
        for n in [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.6, -0.8, 0.0], [0.267, 0.535, -0.802]] {
            let d = decode_normal(encode_normal(n)).unwrap();
            for k in 0..3 {
                assert!((d[k] - n[k]).abs() < 1e-3, "{n:?} -> {d:?}");
            }
        }
        assert_eq!(decode_normal(encode_normal([0.0; 3])), None);
    }
}
