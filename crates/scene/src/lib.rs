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
//! about [`Header::tile_target`] bytes, the unit that paging loads and evicts. Child
//! references hold absolute positions in the file; a reference into another tile is a link
//! that names that tile, so traversal knows exactly when it is about to enter one.
//! `docs/FORMAT.md` gives every byte.
//!
//! - [`SceneWriter`] writes a file part by part (the builder drives it);
//! - [`Scene::open`] maps a file and checks every table into a typed [`SceneError`];
//!   tiles are checked (checksum, references) the first time they are used;
//! - [`Scene::open_owned`] reads only the tables, into anonymous memory, for a pager that
//!   then reads tiles in and drops them ([`Scene::load`], [`Scene::release`]);
//! - a *compact* file ([`compact`]) stores its tiles in fewer bytes and an extent table
//!   that maps them back: readers see its *image*, the bytes of the same scene stored
//!   plainly, decoded into anonymous memory as tiles load (whole, when opened in core).
//!
//! ## Safety contract
//! A mapped [`Scene`] maps its file: do not truncate or rewrite a scene file while a process
//! has it open; replace it by renaming a new file over it (as `megaray build` does). An
//! owned scene reads with `pread`, so a truncated file makes a load fail with an error.

mod backing;
pub mod compact;
pub mod components;
pub mod error;
pub mod format;
pub mod instances;
pub mod reader;
pub mod stats;
pub mod writer;

pub use components::Components;
pub use error::{SceneError, SceneErrorKind};
pub use format::{Child, ChildRef, Header, Node8, PartEntry, TileEntry, Tri4};
pub use instances::{Group, Instance, Instancing, Object, Target};
pub use reader::{drop_page_cache, fits_in_memory, physical_memory, CheckedTiles, Scene, Tile};
pub use stats::{StoredBytes, TreeStats};
pub use writer::{BlobChild, BlobRef, MaterialDesc, PartBlob, SceneWriter, TileBlob};
