//! The compact tile codec: a tile's nodes and triangle blocks in fewer bytes, decoded back
//! to exactly the same bytes when a reader loads the tile (`docs/FORMAT.md`, "Compact
//! files"). Lossless, so traversal, hits and checksums are those of the uncompressed tile.
//!
//! - Nodes: a byte saying which of the eight slots are used, then per used slot its box
//!   (six `f32`) and its child as a 32-bit code: an inner node by its index in the tile, a
//!   leaf by its first block and count, anything else (links) as the full 64-bit reference.
//! - Triangles: the tile's distinct corners once (`f32` x, y, z, bit for bit), then per
//!   block how many lanes hold a triangle (the rest are zero) and per triangle three
//!   indices into the corners (16-bit when the tile has at most 65,536 of them, else
//!   32-bit). Meshes share each corner among about six triangles, so a triangle costs about
//!   12-14 bytes instead of 36.
//!
//! [`encode`] checks its own output by decoding it, and answers `None` (store the tile as it
//! is) whenever the compact form would not be smaller or would not give the same bytes.
//! [`decode`] checks every count and index against the bytes it has, so a damaged stored
//! tile is an error, never a panic or a write out of bounds.

use crate::format::{Child, ChildRef, Node8, NODE_BYTES, NODE_WIDTH};

/// Bytes of a stored tile's header: node count, block count, corner count, flags.
const HEAD: usize = 16;
/// Flag: indices are 32-bit.
const WIDE: u32 = 1;
const TRI4_BYTES: usize = 144;

const KIND_INNER: u32 = 0;
const KIND_LEAF: u32 = 1;
const KIND_RAW: u32 = 3;
const PAYLOAD: u32 = (1 << 30) - 1;
/// A leaf code: block index in bits 0..22, count in bits 22..30.
const LEAF_BLOCK_BITS: u32 = 22;

/// Where a tile lies in the image: its node 0's position (`offset / 256`) and its block
/// 0's unit position (`offset / 16`), which the tile's references are relative to.
#[derive(Clone, Copy, Debug)]
pub struct TilePlace {
    pub node0: u64,
    pub unit0: u64,
}

impl TilePlace {
    /// The place of a tile of `node_count` nodes at image offset `offset`.
    pub fn at(offset: u64, node_count: u32) -> TilePlace {
        TilePlace { node0: offset / NODE_BYTES as u64, unit0: (offset + node_count as u64 * NODE_BYTES as u64) / 16 }
    }
}

/// The tile `image` (`node_count` nodes, then triangle blocks) in compact form, and the bytes
/// its nodes take in it; `None` when storing it as it is is as small, or it does not
/// round-trip.
pub fn encode(image: &[u8], node_count: u32, place: TilePlace) -> Option<(Vec<u8>, u32)> {
    let node_bytes = node_count as usize * NODE_BYTES;
    let tri_bytes = image.len().checked_sub(node_bytes)?;
    if !tri_bytes.is_multiple_of(TRI4_BYTES) {
        return None;
    }
    let blocks = tri_bytes / TRI4_BYTES;
    let mut out = Vec::with_capacity(image.len() / 3);
    out.extend_from_slice(&node_count.to_le_bytes());
    out.extend_from_slice(&(blocks as u32).to_le_bytes());
    out.extend_from_slice(&[0; 8]); // corners and flags, below
    for k in 0..node_count as usize {
        let n: Node8 = bytemuck::pod_read_unaligned(&image[k * NODE_BYTES..(k + 1) * NODE_BYTES]);
        encode_node(&n, node_count, blocks as u64, place, &mut out);
    }
    let node_stored = out.len() - HEAD;
    // Lanes used per block, then indices; the corners go last.
    let tris = &image[node_bytes..];
    let lane = |b: usize, l: usize| -> [[u32; 3]; 3] {
        let blk = &tris[b * TRI4_BYTES..(b + 1) * TRI4_BYTES];
        let f = |i: usize| u32::from_le_bytes(blk[4 * i..4 * i + 4].try_into().expect("4 bytes"));
        // SoA: corner c, axis a, lane l at float index 12 c + 4 a + l.
        std::array::from_fn(|c| std::array::from_fn(|a| f(12 * c + 4 * a + l)))
    };
    let mut used = Vec::with_capacity(blocks);
    for b in 0..blocks {
        let n = (0..4).rev().find(|&l| lane(b, l) != [[0; 3]; 3]).map_or(0, |l| l + 1);
        used.push(n as u8);
    }
    out.extend_from_slice(&used);
    let mut corners = Corners::new(4 * 3 * blocks);
    let mut idx: Vec<u32> = Vec::with_capacity(3 * 4 * blocks);
    for (b, &n) in used.iter().enumerate() {
        for l in 0..n as usize {
            for c in lane(b, l) {
                idx.push(corners.index(c));
            }
        }
    }
    let wide = corners.list.len() > 1 << 16;
    for i in idx {
        match wide {
            true => out.extend_from_slice(&i.to_le_bytes()),
            false => out.extend_from_slice(&(i as u16).to_le_bytes()),
        }
    }
    for c in &corners.list {
        for a in c {
            out.extend_from_slice(&a.to_le_bytes());
        }
    }
    out[8..12].copy_from_slice(&(corners.list.len() as u32).to_le_bytes());
    out[12..16].copy_from_slice(&(if wide { WIDE } else { 0 }).to_le_bytes());
    if out.len() >= image.len() {
        return None;
    }
    let mut back = vec![0u8; image.len()];
    match decode(&out, &mut back, place) {
        Ok(()) if back == image => Some((out, node_stored as u32)),
        _ => None,
    }
}

fn encode_node(n: &Node8, node_count: u32, blocks: u64, place: TilePlace, out: &mut Vec<u8>) {
    let empty = Node8::EMPTY;
    let is_empty = |i: usize| {
        let planes = |m: &Node8| [m.lo_x[i], m.hi_x[i], m.lo_y[i], m.hi_y[i], m.lo_z[i], m.hi_z[i]].map(f32::to_bits);
        n.child[i] == ChildRef::EMPTY.0 && planes(n) == planes(&empty)
    };
    let mask = (0..NODE_WIDTH).filter(|&i| !is_empty(i)).fold(0u8, |m, i| m | 1 << i);
    out.push(mask);
    for i in (0..NODE_WIDTH).filter(|&i| mask & 1 << i != 0) {
        for v in [n.lo_x[i], n.hi_x[i], n.lo_y[i], n.hi_y[i], n.lo_z[i], n.hi_z[i]] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        let c = n.child[i];
        let code = match ChildRef(c).decode() {
            Child::Inner(k) if k >= place.node0 && k - place.node0 < node_count as u64 && ChildRef::inner(k).0 == c => {
                Some((KIND_INNER << 30) | (k - place.node0) as u32)
            }
            Child::Leaf { unit, count }
                if unit >= place.unit0
                    && (unit - place.unit0).is_multiple_of(9)
                    && (unit - place.unit0) / 9 < blocks.min(1 << LEAF_BLOCK_BITS)
                    && (1..=255).contains(&count)
                    && ChildRef::leaf(unit, count).0 == c =>
            {
                Some((KIND_LEAF << 30) | (count << LEAF_BLOCK_BITS) | ((unit - place.unit0) / 9) as u32)
            }
            _ => None,
        };
        match code {
            Some(code) => out.extend_from_slice(&code.to_le_bytes()),
            None => {
                out.extend_from_slice(&(KIND_RAW << 30).to_le_bytes());
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
}

/// Distinct corners in order of first use, by their bits.
struct Corners {
    list: Vec<[u32; 3]>,
    /// Open addressing: index + 1 into `list`, 0 for free.
    table: Vec<u32>,
    mask: usize,
}

impl Corners {
    fn new(most: usize) -> Corners {
        let cap = (2 * most).next_power_of_two().max(16);
        Corners { list: Vec::with_capacity(most / 4), table: vec![0; cap], mask: cap - 1 }
    }

    fn index(&mut self, c: [u32; 3]) -> u32 {
        let h = (c[0].wrapping_mul(0x9E37_79B1) ^ c[1].wrapping_mul(0x85EB_CA77) ^ c[2].wrapping_mul(0xC2B2_AE3D))
            .wrapping_mul(0x27D4_EB2F);
        let mut at = (h as usize ^ (h as usize >> 15)) & self.mask;
        loop {
            match self.table[at] {
                0 => {
                    self.list.push(c);
                    self.table[at] = self.list.len() as u32;
                    return self.list.len() as u32 - 1;
                }
                k if self.list[k as usize - 1] == c => return k - 1,
                _ => at = (at + 1) & self.mask,
            }
        }
    }
}

/// Reads a stored tile's bytes, each read checked.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| format!("ends at byte {} of {} (needs {n} more)", self.at, self.bytes.len()))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes")))
    }
    fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().expect("8 bytes")))
    }
    fn f32(&mut self) -> Result<f32, String> {
        Ok(f32::from_bits(self.u32()?))
    }
}

/// The node count a stored tile declares (to size its image), or an error.
pub fn stored_counts(stored: &[u8]) -> Result<(u32, u32), String> {
    let mut r = Cursor { bytes: stored, at: 0 };
    Ok((r.u32()?, r.u32()?))
}

/// Decodes the stored tile `stored` into `out`, which must be exactly its image's length
/// (`256 * node_count + 144 * blocks`). An error says what is wrong with the stored bytes;
/// `out` then holds something unspecified.
pub fn decode(stored: &[u8], out: &mut [u8], place: TilePlace) -> Result<(), String> {
    let mut r = Cursor { bytes: stored, at: 0 };
    let (node_count, blocks, corners, flags) = (r.u32()? as usize, r.u32()? as usize, r.u32()? as usize, r.u32()?);
    let node_bytes = node_count.checked_mul(NODE_BYTES);
    let len = node_bytes.and_then(|n| blocks.checked_mul(TRI4_BYTES).and_then(|b| n.checked_add(b)));
    if len != Some(out.len()) {
        return Err(format!("{node_count} nodes and {blocks} blocks do not make {} bytes", out.len()));
    }
    for k in 0..node_count {
        let mut n = Node8::EMPTY;
        let mask = r.take(1)?[0];
        for i in (0..NODE_WIDTH).filter(|&i| mask & 1 << i != 0) {
            for plane in [&mut n.lo_x, &mut n.hi_x, &mut n.lo_y, &mut n.hi_y, &mut n.lo_z, &mut n.hi_z] {
                plane[i] = r.f32()?;
            }
            let code = r.u32()?;
            n.child[i] = match code >> 30 {
                KIND_INNER => place.node0 + u64::from(code & PAYLOAD),
                KIND_LEAF => {
                    let block = code & ((1 << LEAF_BLOCK_BITS) - 1);
                    let count = (code >> LEAF_BLOCK_BITS) & 0xff;
                    if count == 0 {
                        return Err(format!("node {k}: a leaf of no triangles"));
                    }
                    ChildRef::leaf(place.unit0 + 9 * u64::from(block), count).0
                }
                KIND_RAW => r.u64()?,
                _ => return Err(format!("node {k}: unknown child code {code:#x}")),
            };
        }
        out[k * NODE_BYTES..(k + 1) * NODE_BYTES].copy_from_slice(bytemuck::bytes_of(&n));
    }
    let used = r.take(blocks)?;
    let lanes: usize = used.iter().map(|&n| n as usize).sum();
    if let Some(b) = used.iter().position(|&n| n > 4) {
        return Err(format!("block {b}: {} lanes", used[b]));
    }
    let width = if flags & WIDE != 0 { 4 } else { 2 };
    let idx = r.take(lanes.checked_mul(3 * width).ok_or("too many lanes")?)?;
    let pos = r.take(corners.checked_mul(12).ok_or("too many corners")?)?;
    if r.at != stored.len() {
        return Err(format!("{} bytes left over", stored.len() - r.at));
    }
    let index = |i: usize| -> usize {
        match width {
            4 => u32::from_le_bytes(idx[4 * i..4 * i + 4].try_into().expect("4 bytes")) as usize,
            _ => u16::from_le_bytes(idx[2 * i..2 * i + 2].try_into().expect("2 bytes")) as usize,
        }
    };
    let pos: Vec<[u32; 3]> = pos
        .chunks_exact(12)
        .map(|c| std::array::from_fn(|a| u32::from_le_bytes(c[4 * a..4 * a + 4].try_into().expect("4 bytes"))))
        .collect();
    let tris = &mut out[node_count * NODE_BYTES..];
    let mut t = 0;
    for (b, &n) in used.iter().enumerate() {
        // The block's 36 floats (corner c, axis a, lane l at 12 c + 4 a + l), then its bytes
        // (the format is little-endian, as is every machine megaray runs on).
        let mut blk = [0u32; 36];
        for l in 0..n as usize {
            for c in 0..3 {
                let v = index(3 * t + c);
                let p = pos.get(v).ok_or_else(|| format!("block {b}: corner {v} of {corners}"))?;
                blk[12 * c + l] = p[0];
                blk[12 * c + 4 + l] = p[1];
                blk[12 * c + 8 + l] = p[2];
            }
            t += 1;
        }
        tris[b * TRI4_BYTES..(b + 1) * TRI4_BYTES].copy_from_slice(bytemuck::cast_slice(&blk[..]));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::Tri4;

    fn rng(seed: &mut u64) -> u64 {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        *seed
    }

    /// A tile as a build makes them: nodes referring to later nodes, leaves, links and empty
    /// slots; blocks of triangles over a small grid of shared corners, the last lanes of
    /// some blocks empty.
    fn tile(seed: &mut u64, nodes: usize, blocks: usize, offset: u64) -> Vec<u8> {
        let place = TilePlace::at(offset, nodes as u32);
        let mut out = Vec::new();
        for k in 0..nodes {
            let mut n = Node8::EMPTY;
            for i in 0..(1 + rng(seed) % 8) as usize {
                let lo = (rng(seed) % 1000) as f32 * 0.37 - 100.0;
                for (pl, ph) in [(&mut n.lo_x, &mut n.hi_x), (&mut n.lo_y, &mut n.hi_y), (&mut n.lo_z, &mut n.hi_z)] {
                    pl[i] = lo;
                    ph[i] = lo + (rng(seed) % 50) as f32 * 0.1;
                }
                n.child[i] = match rng(seed) % 4 {
                    0 if k + 1 < nodes => ChildRef::inner(place.node0 + (k + 1) as u64).0,
                    1 => ChildRef::link(7, 123_456).0,
                    _ if blocks > 0 => {
                        ChildRef::leaf(place.unit0 + 9 * (rng(seed) % blocks as u64), 1 + (rng(seed) % 255) as u32).0
                    }
                    _ => ChildRef::link(3, 99).0,
                };
            }
            out.extend_from_slice(bytemuck::bytes_of(&n));
        }
        for _ in 0..blocks {
            let mut t: Tri4 = bytemuck::Zeroable::zeroed();
            let lanes = if rng(seed).is_multiple_of(5) { 1 + rng(seed) % 4 } else { 4 };
            for l in 0..lanes as usize {
                let base = rng(seed) % 200;
                for c in 0..3 {
                    let v = base + rng(seed) % 3;
                    let p = [v as f32 * 0.5, (v % 17) as f32, -(v as f32) / 3.0];
                    for (a, x) in p.into_iter().enumerate() {
                        bytemuck::cast_slice_mut::<Tri4, f32>(std::slice::from_mut(&mut t))[12 * c + 4 * a + l] = x;
                    }
                }
            }
            out.extend_from_slice(bytemuck::bytes_of(&t));
        }
        out
    }

    /// Tiles of every shape come back byte for byte, and smaller.
    #[test]
    fn tiles_round_trip_exactly() {
        let mut seed = 0x1234_5678_9abc_def1;
        for (nodes, blocks) in [(1, 0), (1, 1), (3, 10), (40, 700), (1, 20_000)] {
            let offset = 4096 * (1 + rng(&mut seed) % 1000);
            let img = tile(&mut seed, nodes, blocks, offset);
            let place = TilePlace::at(offset, nodes as u32);
            let Some((enc, node_bytes)) = encode(&img, nodes as u32, place) else {
                assert!(blocks < 4, "{nodes} nodes, {blocks} blocks not compacted");
                continue;
            };
            assert!(enc.len() < img.len() && (node_bytes as usize) < enc.len());
            let mut back = vec![0xAB; img.len()];
            decode(&enc, &mut back, place).unwrap();
            assert!(back == img, "{nodes} nodes, {blocks} blocks");
            assert_eq!(stored_counts(&enc).unwrap(), (nodes as u32, blocks as u32));
        }
    }

    /// More than 65,536 distinct corners take 32-bit indices.
    #[test]
    fn wide_indices() {
        let blocks = 20_000;
        let mut img = vec![0u8; 256 + 144 * blocks];
        img[..256].copy_from_slice(bytemuck::bytes_of(&Node8::EMPTY));
        for (i, f) in bytemuck::cast_slice_mut::<u8, f32>(&mut img[256..]).iter_mut().enumerate() {
            *f = i as f32 * 0.25 + 1.0;
        }
        let place = TilePlace::at(8192, 1);
        let (enc, _) = encode(&img, 1, place).map_or((Vec::new(), 0), |e| e);
        // Every corner distinct: 12 bytes each plus 4 of index: no smaller than 36, so stored as it is.
        assert!(enc.is_empty());
        let mut img2 = img.clone();
        // One corner a triangle (all three equal): 80,000 of them, over 65,536.
        let f = bytemuck::cast_slice_mut::<u8, f32>(&mut img2[256..]);
        for b in 0..blocks {
            for a in 0..3 {
                for l in 0..4 {
                    f[b * 36 + 12 + 4 * a + l] = f[b * 36 + 4 * a + l];
                    f[b * 36 + 24 + 4 * a + l] = f[b * 36 + 4 * a + l];
                }
            }
        }
        let (enc, _) = encode(&img2, 1, place).expect("compacted");
        assert_eq!(u32::from_le_bytes(enc[12..16].try_into().unwrap()), WIDE);
        let mut back = vec![0; img2.len()];
        decode(&enc, &mut back, place).unwrap();
        assert!(back == img2);
    }

    /// Damaged stored tiles: every truncation and many flipped bytes give an error or other
    /// bytes, never a panic.
    #[test]
    fn damaged_tiles_are_errors() {
        let mut seed = 99;
        let offset = 4096 * 5;
        let img = tile(&mut seed, 6, 60, offset);
        let place = TilePlace::at(offset, 6);
        let (enc, _) = encode(&img, 6, place).unwrap();
        let mut out = vec![0; img.len()];
        for cut in 0..enc.len() {
            assert!(decode(&enc[..cut], &mut out, place).is_err(), "cut at {cut}");
        }
        assert!(decode(&enc, &mut out[1..], place).is_err());
        for _ in 0..3000 {
            let mut bad = enc.clone();
            let at = (rng(&mut seed) % bad.len() as u64) as usize;
            bad[at] ^= 1 << (rng(&mut seed) % 8);
            let _ = decode(&bad, &mut out, place);
        }
        let mut huge = enc.clone();
        huge[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode(&huge, &mut out, place).is_err());
    }
}
