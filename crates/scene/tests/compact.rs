//! Compact files (`compact.rs`): the image a reader sees is the plain file's bytes, opened
//! in core or loaded tile by tile; damage is an error at open (header, extent table) or a
//! tile found corrupt when used (a stored tile), never a panic.

use megaray_base::Aabb;
use megaray_scene::format::{self, Extent, Header, Node8, PackedNormals, Tri4};
use megaray_scene::{BlobRef, PartBlob, Scene, SceneWriter, TileBlob};
use std::path::{Path, PathBuf};

/// A grid of `n` x `n` quads, two triangles each, sharing their corners (as meshes do).
fn grid_tri(n: u32, k: u32, x0: f32) -> [[f32; 3]; 3] {
    let (q, second) = (k / 2, k % 2 == 1);
    let (i, j) = ((q % n) as f32, (q / n) as f32);
    let p = |a: f32, b: f32| [x0 + a * 0.25, b * 0.25, (a * 0.7 + b).sin() * 0.1];
    match second {
        false => [p(i, j), p(i + 1.0, j), p(i, j + 1.0)],
        true => [p(i + 1.0, j), p(i + 1.0, j + 1.0), p(i, j + 1.0)],
    }
}

/// One part: a root tile linking to 7 tiles of one node with 8 leaves of 30 triangles each
/// (the last block of each leaf half full), with normals and material ids per slot.
fn write(path: &Path, compact: bool) {
    let bx = Aabb { min: [0.0, 0.0, -1.0], max: [80.0, 8.0, 1.0] };
    let mut top = Node8::EMPTY;
    top.set(0, &bx, BlobRef::part(0).0);
    let mut w = SceneWriter::create(path, vec![top], 1, 1, 0, 1 << 16).unwrap();
    w.set_compact(compact);
    let mut root = Node8::EMPTY;
    let mut tiles = vec![];
    let mut tri_count = 0;
    for t in 0..7u32 {
        root.set(t as usize, &bx, BlobRef::link(t + 1, 0).0);
        let mut node = Node8::EMPTY;
        let mut blocks = vec![];
        for leaf in 0..8u32 {
            node.set(leaf as usize, &bx, BlobRef::leaf(blocks.len() as u32, 30).0);
            for b in 0..8u32 {
                let mut blk = Tri4 { v: [[0.0; 4]; 9] };
                for lane in 0..4u32 {
                    let k = 32 * leaf + 4 * b + lane;
                    if 4 * b + lane < 30 {
                        blk.set(lane as usize, &grid_tri(16, k, 10.0 * t as f32));
                        tri_count += 1;
                    }
                }
                blocks.push(blk);
            }
        }
        tiles.push(TileBlob { nodes: vec![node], blocks });
    }
    tiles.insert(0, TileBlob { nodes: vec![root], blocks: vec![] });
    let slots = 4 * tiles.iter().map(|t| t.blocks.len()).sum::<usize>();
    let part = PartBlob {
        bounds: bx,
        tri_count,
        depth: 2,
        tiles,
        root_tile: 0,
        root_node: 0,
        normals: Some((0..slots as u32).map(|i| PackedNormals([i, i ^ 0x5555, 7])).collect()),
        materials: Some((0..slots as u32).map(|i| i % 3).collect()),
        ..Default::default()
    };
    w.append_part(0, &part).unwrap();
    w.finish(bx, 0, &[Default::default(), Default::default(), Default::default()]).unwrap();
}

fn both(dir: &Path) -> (PathBuf, PathBuf) {
    let (plain, compact) = (dir.join("plain.mray"), dir.join("compact.mray"));
    write(&plain, false);
    write(&compact, true);
    (plain, compact)
}

/// Everything after the header, with the tile directory's `stored_node_bytes` cleared: the
/// fields that say how the file is stored.
fn body(b: &[u8]) -> Vec<u8> {
    let h: Header = bytemuck::pod_read_unaligned(&b[..256]);
    let mut b = b.to_vec();
    for t in 0..h.tile_count as usize {
        let at = h.tiles_off as usize + 40 * t + 28;
        b[at..at + 4].fill(0);
    }
    b.split_off(256)
}

#[test]
fn the_image_is_the_plain_file() {
    let dir = tempfile::tempdir().unwrap();
    let (plain, compact) = both(dir.path());
    let plain_bytes = std::fs::read(&plain).unwrap();
    let stored = std::fs::metadata(&compact).unwrap().len();
    assert!(stored * 2 < plain_bytes.len() as u64, "{stored} bytes against {}", plain_bytes.len());

    // In core: decoded whole at open.
    let s = Scene::open(&compact).unwrap();
    assert!(s.header().is_compact() && !s.is_owned());
    assert_eq!(s.bytes().len(), plain_bytes.len());
    let first = body(s.bytes()).iter().zip(&body(&plain_bytes)).position(|(a, b)| a != b);
    assert!(first.is_none(), "the decoded image differs from the plain file at byte {:?}", first.map(|f| f + 256));
    s.verify_all().unwrap();
    let sb = s.stored_bytes();
    assert_eq!(sb.nodes + sb.triangles + sb.padding + sb.attributes + sb.lod + sb.tables, stored);
    let p = Scene::open(&plain).unwrap();
    let pb = p.stored_bytes();
    assert_eq!(pb.nodes + pb.triangles + pb.padding + pb.attributes + pb.lod + pb.tables, plain_bytes.len() as u64);
    assert!(sb.triangles * 2 < pb.triangles && sb.nodes < pb.nodes);
    for part in 0..1 {
        for prim in [0, 1, 29, 100, 400] {
            assert_eq!(s.normals(part, prim), p.normals(part, prim));
            assert_eq!(s.material_index(part, prim), p.material_index(part, prim));
        }
    }

    // For a pager: tiles (and their attributes) read and decoded as they load, zeros again
    // once released.
    let s = Scene::open_owned(&compact).unwrap();
    assert!(s.is_owned());
    for t in 0..s.tiles().len() as u32 {
        let ranges = s.tile_ranges(t).unwrap();
        for &(o, l) in &ranges {
            s.load(o, l).unwrap();
        }
        s.check_tile(t).unwrap();
        for &(o, l) in &ranges {
            let (o, l) = (o as usize, l as usize);
            assert!(s.bytes()[o..o + l] == plain_bytes[o..o + l], "tile {t}: bytes {o}..{}", o + l);
        }
        for &(o, l) in &ranges {
            s.release(o, l).unwrap();
        }
        let (o, l) = (ranges[0].0 as usize, ranges[0].1 as usize);
        assert!(s.bytes()[o..o + l].iter().all(|&b| b == 0), "tile {t} released");
    }
    // A range cutting through a tile (no pager asks so) reads the same bytes.
    let e = s.tiles()[1];
    let (o, l) = (e.offset + 300, e.bytes as u64 - 700);
    s.load(o, l).unwrap();
    assert!(s.bytes()[o as usize..(o + l) as usize] == plain_bytes[o as usize..(o + l) as usize]);
    s.release(o, l).unwrap();
}

/// Rewrites the header's checksum after a change to it.
fn reseal(b: &mut [u8]) {
    let sum = xxhash_rust::xxh3::xxh3_64(&b[..248]);
    b[248..256].copy_from_slice(&sum.to_le_bytes());
}

#[test]
fn damage_is_an_error_or_a_corrupt_tile() {
    let dir = tempfile::tempdir().unwrap();
    let (_, compact) = both(dir.path());
    let good = std::fs::read(&compact).unwrap();
    let h: Header = bytemuck::pod_read_unaligned(&good[..256]);
    let bad = dir.path().join("bad.mray");
    let open_err = |b: &[u8]| {
        std::fs::write(&bad, b).unwrap();
        let e = Scene::open(&bad).err().expect("refused");
        let o = Scene::open_owned(&bad).err().expect("refused");
        assert_eq!(e.to_string(), o.to_string());
        e.to_string()
    };

    // The extent table damaged, or said to lie past the file.
    let mut b = good.clone();
    b[h.extents_off as usize + 45] ^= 4;
    assert!(open_err(&b).contains("extent table checksum"), "{}", open_err(&b));
    let mut b = good.clone();
    b[224..232].copy_from_slice(&(h.file_bytes - 8).to_le_bytes());
    reseal(&mut b);
    assert!(open_err(&b).contains("outside the file"), "{}", open_err(&b));
    let mut b = good.clone();
    b[232..240].copy_from_slice(&u64::MAX.to_le_bytes());
    reseal(&mut b);
    assert!(open_err(&b).contains("outside the file"), "{}", open_err(&b));
    // An image size that is not whole pages, and one too small for its extents.
    for image in [h.image_bytes + 1, 4096] {
        let mut b = good.clone();
        b[216..224].copy_from_slice(&image.to_le_bytes());
        reseal(&mut b);
        let e = open_err(&b);
        assert!(e.contains("whole pages") || e.contains("extent"), "{e}");
    }
    // Truncated.
    assert!(open_err(&good[..good.len() - 4096]).contains("truncated"));

    // A stored tile damaged: the file opens, and that tile is found corrupt when checked,
    // in core and paged alike; the other tiles are sound.
    let s = Scene::open(&compact).unwrap();
    let t = 3u32;
    let at = {
        let off = s.tiles()[t as usize].offset;
        let e = s.extents().iter().find(|e| e.image_off == off).copied().unwrap();
        (e.stored_off + e.stored_len / 2) as usize
    };
    drop(s);
    for flip in [1u8, 0x80] {
        let mut b = good.clone();
        b[at] ^= flip;
        std::fs::write(&bad, &b).unwrap();
        let s = Scene::open(&bad).unwrap();
        assert!(s.check_tile(t).is_err());
        assert!(s.check_tile(t + 1).is_ok());
        let s = Scene::open_owned(&bad).unwrap();
        for &(o, l) in &s.tile_ranges(t).unwrap() {
            let _ = s.load(o, l);
        }
        assert!(s.check_tile(t).is_err());
    }
}

/// Extent tables a writer never makes, each made consistent again (checksums), refused at
/// open: two tiles stored in the same bytes, a tile stored no smaller than itself, a tile
/// sharing its last page, an image past 2^44 bytes.
#[test]
fn crafted_extent_tables_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (_, compact) = both(dir.path());
    let good = std::fs::read(&compact).unwrap();
    let h: Header = bytemuck::pod_read_unaligned(&good[..256]);
    let at = |i: usize| h.extents_off as usize + 40 * i;
    let extent = |b: &[u8], i: usize| -> Extent { bytemuck::pod_read_unaligned(&b[at(i)..at(i) + 40]) };
    let tiles: Vec<usize> =
        (0..h.extent_count as usize).filter(|&i| extent(&good, i).kind == format::EXTENT_TILE).collect();
    assert!(tiles.len() >= 2);
    let seal = |b: &mut Vec<u8>| {
        let table = h.extents_off as usize..at(h.extent_count as usize);
        let sum = xxhash_rust::xxh3::xxh3_64(&b[table]);
        b[240..248].copy_from_slice(&sum.to_le_bytes());
        reseal(b);
    };
    let refused = |b: &[u8], why: &str| {
        let bad = dir.path().join("crafted.mray");
        std::fs::write(&bad, b).unwrap();
        let e = Scene::open_owned(&bad).err().unwrap_or_else(|| panic!("{why}: opened")).to_string();
        assert!(e.contains("extent") || e.contains("image"), "{why}: {e}");
    };
    let (t0, t1) = (tiles[0], tiles[1]);
    let mut b = good.clone();
    let mut e = extent(&b, t1);
    e.stored_off = extent(&b, t0).stored_off;
    b[at(t1)..at(t1) + 40].copy_from_slice(bytemuck::bytes_of(&e));
    seal(&mut b);
    refused(&b, "two tiles in the same stored bytes");
    let mut b = good.clone();
    let mut e = extent(&b, t0);
    e.image_len = e.stored_len / 16 * 16;
    b[at(t0)..at(t0) + 40].copy_from_slice(bytemuck::bytes_of(&e));
    seal(&mut b);
    refused(&b, "a tile stored no smaller");
    let mut b = good.clone();
    let mut e = extent(&b, t1);
    e.image_off = extent(&b, t0).image_off + extent(&b, t0).image_len.next_multiple_of(256);
    if e.image_off % 4096 == 0 {
        e.image_off += 256;
    }
    b[at(t1)..at(t1) + 40].copy_from_slice(bytemuck::bytes_of(&e));
    seal(&mut b);
    refused(&b, "a tile off a page, in another's last page");
    let mut b = good.clone();
    b[216..224].copy_from_slice(&((1u64 << 44) + 4096).to_le_bytes());
    seal(&mut b);
    refused(&b, "an image past 2^44 bytes");
    // A few bytes of file claiming a large image (a fuzzer's 12 KiB file claimed 880 MiB of
    // uncovered image and put a section in it): an image past its last extent (refused
    // where the image is allocated, in core), a gap between two extents, a tile said to grow
    // more than the codec can.
    let mut b = good.clone();
    b[216..224].copy_from_slice(&(h.image_bytes + (1 << 30)).to_le_bytes());
    seal(&mut b);
    let bad = dir.path().join("tail.mray");
    std::fs::write(&bad, &b).unwrap();
    let e = Scene::open(&bad).err().expect("an image 1 GiB past its last extent: opened in core").to_string();
    assert!(e.contains("past its last extent"), "{e}");
    let last = h.extent_count as usize - 1;
    let mut b = good.clone();
    let mut e = extent(&b, last);
    e.image_off += 1 << 20;
    b[at(last)..at(last) + 40].copy_from_slice(bytemuck::bytes_of(&e));
    b[216..224].copy_from_slice(&(h.image_bytes + (1 << 20)).to_le_bytes());
    seal(&mut b);
    refused(&b, "a gap of 1 MiB before the last extent");
    let mut b = good.clone();
    let mut e = extent(&b, t0);
    let grown = (e.stored_len * 256 + 16).next_multiple_of(16);
    let shift = (grown - e.image_len).next_multiple_of(4096);
    e.image_len = grown;
    b[at(t0)..at(t0) + 40].copy_from_slice(bytemuck::bytes_of(&e));
    for i in t0 + 1..=last {
        let mut f = extent(&b, i);
        f.image_off += shift;
        b[at(i)..at(i) + 40].copy_from_slice(bytemuck::bytes_of(&f));
    }
    b[216..224].copy_from_slice(&(h.image_bytes + shift).to_le_bytes());
    seal(&mut b);
    refused(&b, "a tile said to grow more than 256 times");
}
