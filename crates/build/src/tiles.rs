//! Cutting a part's 8-wide BVH into tiles: the conversion from build layout to file layout.
//!
//! A tile holds whole subtrees where it can. Subtrees of at most `target` bytes (nodes at
//! 256 bytes, leaves at 144 bytes per started block of four triangles) are *units*: a unit is never split across tiles. Nodes above
//! the units stand alone. Walking the tree depth-first, units and lone nodes are packed into
//! tiles next-fit, so a tile holds neighbouring geometry. Inside a tile, nodes keep depth-first
//! order (children after parents); a child in another tile is reached through a link.

use megaray_scene::format::{Node8, Tri4, NODE_BYTES};
use megaray_scene::{BlobRef, TileBlob};

use crate::bvh::spare::Spare;
use crate::bvh::{Bvh, Kid};

/// Tile arrays of parts written, for the next part's tiles ([`Spare`]): as many as a few
/// parts' tiles. Every array is made with room for a whole tile of the target size, so that
/// any kept one fits any tile of the next part.
static SPARE_NODES: Spare<Node8> = Spare::new(8192);
static SPARE_BLOCKS: Spare<Tri4> = Spare::new(8192);

/// Frees the tile arrays kept by [`recycle`].
pub fn release_spare() {
    SPARE_NODES.clear();
    SPARE_BLOCKS.clear();
}

/// Keeps the arrays of `tiles` for later parts ([`SPARE_NODES`]).
pub fn recycle(tiles: Vec<TileBlob>) {
    for t in tiles {
        SPARE_NODES.give(t.nodes);
        SPARE_BLOCKS.give(t.blocks);
    }
}

/// The tiles of one part.
pub struct Tiled {
    pub tiles: Vec<TileBlob>,
    pub root_tile: u32,
    pub root_node: u32,
    /// For each triangle slot in file order (tile by tile, 4 per block), the index in the
    /// `tris` given to [`tile_part`] of its triangle, or [`PADDING`] for an empty lane
    /// (attributes are gathered in this order).
    pub tri_source: Vec<u32>,
}

/// The `tri_source` of a padding lane.
pub const PADDING: u32 = u32::MAX;

/// How many primitives ahead (in the BVH's primitive order) the emission of a leaf asks for
/// the triangles it will need.
const PREFETCH_AHEAD: usize = 32;

/// Bytes of a leaf of `count` triangles.
fn leaf_bytes(count: u32) -> u64 {
    144 * count.div_ceil(4) as u64
}

/// Lays out `bvh` (whose leaves index `tris` through `bvh.order`) in tiles of about `target` bytes.
pub fn tile_part(bvh: &Bvh, tris: &[[[f32; 3]; 3]], target: u64) -> Tiled {
    let nodes = &bvh.nodes;
    // Subtree sizes, bottom-up (children have larger indices than their parent).
    let mut size = vec![0u64; nodes.len()];
    for i in (0..nodes.len()).rev() {
        let mut s = NODE_BYTES as u64;
        for kid in nodes[i].kids {
            s += match kid {
                Kid::Inner(c) => size[c as usize],
                Kid::Leaf { count, .. } => leaf_bytes(count),
                Kid::Empty => 0,
            };
        }
        size[i] = s;
    }
    let own = |i: usize| -> u64 {
        NODE_BYTES as u64
            + nodes[i]
                .kids
                .iter()
                .map(|k| if let Kid::Leaf { count, .. } = k { leaf_bytes(*count) } else { 0 })
                .sum::<u64>()
    };

    // Pack: tile and local index of every node, in depth-first item order.
    let mut tile_of = vec![u32::MAX; nodes.len()];
    let mut local_of = vec![0u32; nodes.len()];
    let mut tile_nodes: Vec<Vec<u32>> = Vec::new();
    let mut fill = u64::MAX; // bytes in the current tile; MAX forces a first tile
    let mut stack = vec![0u32];
    let mut unit = Vec::new();
    while let Some(n) = stack.pop() {
        let n = n as usize;
        let is_unit = size[n] <= target;
        let cost = if is_unit { size[n] } else { own(n) };
        if fill == u64::MAX || (fill > 0 && fill + cost > target) {
            tile_nodes.push(Vec::new());
            fill = 0;
        }
        let t = tile_nodes.len() - 1;
        fill += cost;
        if is_unit {
            // The whole subtree, depth-first.
            unit.clear();
            unit.push(n as u32);
            while let Some(m) = unit.pop() {
                tile_of[m as usize] = t as u32;
                local_of[m as usize] = tile_nodes[t].len() as u32;
                tile_nodes[t].push(m);
                for kid in nodes[m as usize].kids.iter().rev() {
                    if let Kid::Inner(c) = kid {
                        unit.push(*c);
                    }
                }
            }
        } else {
            tile_of[n] = t as u32;
            local_of[n] = tile_nodes[t].len() as u32;
            tile_nodes[t].push(n as u32);
            for kid in nodes[n].kids.iter().rev() {
                if let Kid::Inner(c) = kid {
                    stack.push(*c);
                }
            }
        }
    }

    // Emit file-layout nodes and triangles, tile by tile in parallel (each tile's own
    // triangle sources, concatenated in tile order afterwards).
    use rayon::prelude::*;
    let emit = |(t, list): (usize, &Vec<u32>)| {
        // Sized up front: each tile's arrays are allocated once, never regrown.
        let nblocks: usize = list
            .iter()
            .flat_map(|&n| nodes[n as usize].kids)
            .map(|k| if let Kid::Leaf { count, .. } = k { count.div_ceil(4) as usize } else { 0 })
            .sum();
        let (mut tn, mut tb) = (SPARE_NODES.take(), SPARE_BLOCKS.take());
        tn.reserve(list.len().max(target as usize / NODE_BYTES));
        tb.reserve(nblocks.max(target as usize / std::mem::size_of::<Tri4>()));
        let mut blob = TileBlob { nodes: tn, blocks: tb };
        let mut src = Vec::with_capacity(4 * nblocks);
        for &n in list {
            let mut out = Node8::EMPTY;
            for (k, kid) in nodes[n as usize].kids.iter().enumerate() {
                let r = match *kid {
                    Kid::Empty => continue,
                    Kid::Inner(c) => {
                        if tile_of[c as usize] == t as u32 {
                            BlobRef::inner(local_of[c as usize])
                        } else {
                            BlobRef::link(tile_of[c as usize], local_of[c as usize])
                        }
                    }
                    Kid::Leaf { start, count } => {
                        let first = blob.blocks.len() as u32;
                        let prims = &bvh.order[start as usize..(start + count) as usize];
                        // The triangles of the leaves that come next (they mostly follow in
                        // `order`) start loading now: they lie all over `tris` (in input
                        // order), and fetching them one miss at a time was most of this pass
                        // (docs/PERF.md, "Tile emission prefetch").
                        for &p in bvh.order.iter().skip(start as usize + PREFETCH_AHEAD).take(count as usize) {
                            megaray_base::prefetch(&tris[p as usize]);
                        }
                        for chunk in prims.chunks(4) {
                            let mut b = Tri4 { v: [[0.0; 4]; 9] };
                            for lane in 0..4 {
                                match chunk.get(lane) {
                                    Some(&p) => {
                                        b.set(lane, &tris[p as usize]);
                                        src.push(p);
                                    }
                                    None => src.push(PADDING),
                                }
                            }
                            blob.blocks.push(b);
                        }
                        BlobRef::leaf(first, count)
                    }
                };
                out.set(k, &nodes[n as usize].bounds[k], r.0);
            }
            blob.nodes.push(out);
        }
        (blob, src)
    };
    let emitted: Vec<(TileBlob, Vec<u32>)> = tile_nodes.par_iter().enumerate().map(emit).collect();
    let mut tiles = Vec::with_capacity(emitted.len());
    let mut tri_source = Vec::with_capacity(tris.len());
    for (blob, src) in emitted {
        tiles.push(blob);
        tri_source.extend_from_slice(&src);
    }
    Tiled { tiles, root_tile: tile_of[0], root_node: local_of[0], tri_source }
}
