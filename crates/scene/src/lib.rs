//! # megaray-scene: the `.mray` scene file
//!
//! One file holds a whole scene, made to be memory-mapped and paged:
//!
//! ```text
//! page 0        Header (magic, version, counts, bounds, offsets, checksums)
//! page 1..      top-level tree (Node8 array) and part directory (PartEntry array)
//! then          for each part: its tiles (page-aligned blocks of Node8s then Tris),
//!               then its attribute arrays (normals, uvs, colours, material ids)
//!               (tiles: Node8s, then Tri4 blocks of four triangles each)
//! then          tile directory (TileEntry array), material table
//! ```
//!
//! The top-level tree's leaves name parts; each part is an 8-wide BVH cut into tiles of
//! about [`Header::tile_target`] bytes, the unit that paging loads and evicts. Nodes refer
//! to nodes of their own tile by index and to other tiles by links, so traversal knows
//! exactly when it is about to enter a tile. `docs/FORMAT.md` gives every byte.
//!
//! - [`SceneWriter`] writes a file part by part (the builder drives it);
//! - [`Scene::open`] maps a file and checks every table into a typed [`SceneError`];
//!   tiles are checked (checksum, references) the first time they are used.
//!
//! ## Safety contract
//! A [`Scene`] maps its file. Do not truncate or rewrite a scene file while a process has
//! it open; replace it by renaming a new file over it (as `megaray build` does).

pub mod error;
pub mod format;
pub mod reader;
pub mod stats;
pub mod writer;

pub use error::{SceneError, SceneErrorKind};
pub use format::{Child, ChildRef, Header, Node8, PartEntry, TileEntry, Tri4};
pub use reader::{drop_page_cache, CheckedTiles, Scene, Tile};
pub use stats::TreeStats;
pub use writer::{BlobChild, BlobRef, MaterialDesc, PartBlob, SceneWriter, TileBlob};
