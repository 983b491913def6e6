//! Tree statistics of a scene file: node and leaf counts, fill, and the SAH cost of each
//! part's BVH, measured the way Embree's `verbose=2` statistics measure theirs, so that the
//! two trees can be compared number for number (see `megaray info`).

use megaray_base::Aabb;

use crate::format::{Child, ChildRef, NODE_BYTES, PAGE};
use crate::reader::Scene;

/// Counts and SAH cost of the part trees (the top-level tree is not counted).
///
/// The SAH cost is Embree's: every inner node costs its surface area, every leaf costs its
/// box's area times its number of four-triangle blocks, all relative to the area of the
/// part's root (traversal and intersection cost 1 each). Over several parts, the costs are
/// weighted by triangle count.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TreeStats {
    pub inner_nodes: u64,
    /// Child slots in use over all inner nodes (fill = `child_slots / (8 * inner_nodes)`).
    pub child_slots: u64,
    pub leaves: u64,
    pub blocks: u64,
    /// SAH cost of the inner nodes.
    pub sah_nodes: f64,
    /// SAH cost of the leaves.
    pub sah_leaves: f64,
}

impl TreeStats {
    pub fn sah(&self) -> f64 {
        self.sah_nodes + self.sah_leaves
    }
}

impl Scene {
    /// Walks every part's tree (reading every node: the whole tree part of the file).
    /// Corrupt tiles are skipped, as traversal skips them.
    pub fn tree_stats(&self) -> TreeStats {
        let mut all = TreeStats::default();
        let total_tris = self.header().tri_count.max(1) as f64;
        let pool = self.node_pool();
        let tiles = self.tiles();
        // Full detail only: the levels of detail are trees of their own, over other triangles.
        for p in &self.parts()[..self.full_part_count() as usize] {
            let mut s = TreeStats::default();
            let Some(root) = self.tile(p.root_tile) else { continue };
            let root_box = (0..8).fold(Aabb::default(), |b, i| b.union(&root.nodes[p.root_node as usize].bounds(i)));
            let norm = f64::from(root_box.half_area()).max(f64::MIN_POSITIVE);
            // (tile, node position in the file)
            let mut stack = vec![(p.root_tile, tiles[p.root_tile as usize].node0() + p.root_node as u64)];
            while let Some((t, k)) = stack.pop() {
                if !self.tile_usable(t) {
                    continue;
                }
                let node = &pool[k as usize];
                let mut own = Aabb::default();
                s.inner_nodes += 1;
                for i in 0..8 {
                    let b = node.bounds(i);
                    match ChildRef(node.child[i]).decode() {
                        Child::Empty => continue,
                        Child::Inner(c) => stack.push((t, c)),
                        Child::Link { tile, node } => stack.push((tile, node)),
                        Child::Leaf { count, .. } => {
                            let blocks = count.div_ceil(4) as u64;
                            s.leaves += 1;
                            s.blocks += blocks;
                            s.sah_leaves += f64::from(b.half_area()) * blocks as f64 / norm;
                        }
                        Child::Part(_) => {}
                    }
                    s.child_slots += 1;
                    own.grow(&b);
                }
                s.sah_nodes += f64::from(own.half_area()) / norm;
            }
            let w = p.tri_count as f64 / total_tris;
            all.inner_nodes += s.inner_nodes;
            all.child_slots += s.child_slots;
            all.leaves += s.leaves;
            all.blocks += s.blocks;
            all.sah_nodes += w * s.sah_nodes;
            all.sah_leaves += w * s.sah_leaves;
        }
        all
    }
}

/// Where a scene file's bytes go, as stored: a compact file's tiles as compacted, a plain
/// file's as traced with their page padding (see `megaray info`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StoredBytes {
    /// The full-detail parts' nodes.
    pub nodes: u64,
    /// The full-detail parts' triangles.
    pub triangles: u64,
    /// Zeros after tiles, up to their next page (a plain file's).
    pub padding: u64,
    /// The full-detail parts' attribute arrays.
    pub attributes: u64,
    /// The levels of detail: their tiles and attributes.
    pub lod: u64,
    /// Everything else: header, tables, the extent table.
    pub tables: u64,
}

impl Scene {
    /// The file's bytes by kind ([`StoredBytes`]).
    pub fn stored_bytes(&self) -> StoredBytes {
        let extents = self.extents();
        let stored = |off: u64, len: u64| -> u64 {
            if extents.is_empty() || len == 0 {
                return len;
            }
            let i = extents.partition_point(|e| e.image_off < off);
            extents.get(i).filter(|e| e.image_off == off).map_or(0, |e| e.stored_len)
        };
        let plain = extents.is_empty();
        let full = self.full_part_count();
        let mut s = StoredBytes::default();
        for t in self.tiles() {
            let total = stored(t.offset, t.bytes as u64);
            let nodes = match plain {
                true => t.node_count as u64 * NODE_BYTES as u64,
                false => (t.stored_node_bytes as u64).min(total),
            };
            let pad = if plain { (t.bytes as u64).div_ceil(PAGE) * PAGE - t.bytes as u64 } else { 0 };
            if t.part < full {
                s.nodes += nodes;
                s.triangles += total - nodes;
                s.padding += pad;
            } else {
                s.lod += total + pad;
            }
        }
        for (i, p) in self.parts().iter().enumerate() {
            let n = p.slot_count;
            for (off, size) in [(p.normals_off, 12), (p.uvs_off, 24), (p.colors_off, 12), (p.materials_off, 4)] {
                if off == 0 {
                    continue;
                }
                let bytes = if plain { (n * size).div_ceil(PAGE) * PAGE } else { stored(off, n * size) };
                match (i as u32) < full {
                    true => s.attributes += bytes,
                    false => s.lod += bytes,
                }
            }
        }
        let kinds = s.nodes + s.triangles + s.padding + s.attributes + s.lod;
        s.tables = self.header().file_bytes.saturating_sub(kinds);
        s
    }
}
