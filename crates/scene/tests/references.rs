//! The checks of a tile's child references (format v4: absolute positions): a scene written
//! by `SceneWriter` passes them; each kind of out-of-range reference, patched into a tile
//! whose checksums are then made right again, is refused with the tile named.

use megaray_base::Aabb;
use megaray_scene::format::{ChildRef, Header, Node8, TileEntry, Tri4, NODE_BYTES};
use megaray_scene::{BlobRef, PartBlob, Scene, SceneErrorKind, SceneWriter, TileBlob};
use std::path::Path;

fn tri(x: f32) -> [[f32; 3]; 3] {
    [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]
}

fn block(x: f32) -> Tri4 {
    let mut b = Tri4 { v: [[0.0; 4]; 9] };
    b.set(0, &tri(x));
    b
}

/// [`write_scene`] as `good.mray` in `dir`.
fn good_scene(dir: &Path) -> std::path::PathBuf {
    let good = dir.join("good.mray");
    write_scene(&good);
    good
}

/// One part of two tiles: tile 0 holds the root (a leaf of one triangle and a link to tile
/// 1) and an inner node below it (a leaf of its own); tile 1 holds one node with a leaf.
fn write_scene(path: &Path) {
    let bx = Aabb { min: [0.0, 0.0, 0.0], max: [4.0, 1.0, 0.0] };
    let mut top = Node8::EMPTY;
    top.set(0, &bx, BlobRef::part(0).0);
    let mut w = SceneWriter::create(path, vec![top], 1, 1, 0, 1 << 16).unwrap();
    let mut root = Node8::EMPTY;
    root.set(0, &bx, BlobRef::leaf(0, 1).0);
    root.set(1, &bx, BlobRef::inner(1).0);
    root.set(2, &bx, BlobRef::link(1, 0).0);
    let mut below = Node8::EMPTY;
    below.set(0, &bx, BlobRef::leaf(1, 1).0);
    let mut other = Node8::EMPTY;
    other.set(0, &bx, BlobRef::leaf(0, 1).0);
    let part = PartBlob {
        bounds: bx,
        tri_count: 3,
        depth: 2,
        tiles: vec![
            TileBlob { nodes: vec![root, below], blocks: vec![block(0.0), block(1.0)] },
            TileBlob { nodes: vec![other], blocks: vec![block(2.0)] },
        ],
        root_tile: 0,
        root_node: 0,
        ..Default::default()
    };
    w.append_part(0, &part).unwrap();
    w.finish(bx, 0, &[]).unwrap();
}

/// Sets child `slot` of node `node` of tile `tile` (`None`: of the top-level tree) to `r`,
/// then makes the tile's checksum, the tables' checksum and the header's right again (so that
/// only the reference is wrong).
fn patch(path: &Path, tile: Option<usize>, node: usize, slot: usize, r: u64) {
    let mut b = std::fs::read(path).unwrap();
    let h: Header = bytemuck::pod_read_unaligned(&b[..256]);
    let base = match tile {
        Some(tile) => {
            let te = h.tiles_off as usize + 40 * tile;
            let e: TileEntry = bytemuck::pod_read_unaligned(&b[te..te + 40]);
            e.offset as usize
        }
        None => h.top_nodes_off as usize,
    };
    let at = base + NODE_BYTES * node + 192 + 8 * slot;
    b[at..at + 8].copy_from_slice(&r.to_le_bytes());
    if let Some(tile) = tile {
        let te = h.tiles_off as usize + 40 * tile;
        let mut e: TileEntry = bytemuck::pod_read_unaligned(&b[te..te + 40]);
        e.checksum = xxhash_rust::xxh3::xxh3_64(&b[e.offset as usize..e.offset as usize + e.bytes as usize]);
        b[te..te + 40].copy_from_slice(bytemuck::bytes_of(&e));
    }
    fix_checksums(&mut b);
    std::fs::write(path, b).unwrap();
}

/// Makes the tables' checksum and the header's right again for the file `b`.
fn fix_checksums(b: &mut [u8]) {
    let mut h: Header = bytemuck::pod_read_unaligned(&b[..256]);
    let mut meta = Vec::new();
    for (off, len) in [
        (h.top_nodes_off, h.top_node_count as u64 * 256),
        (h.parts_off, h.part_count as u64 * 128),
        (h.tiles_off, h.tile_count as u64 * 40),
        (h.materials_off, h.materials_bytes),
    ] {
        meta.extend_from_slice(&b[off as usize..(off + len) as usize]);
    }
    h.meta_checksum = xxhash_rust::xxh3::xxh3_64(&meta);
    b[..256].copy_from_slice(bytemuck::bytes_of(&h));
    h.header_checksum = xxhash_rust::xxh3::xxh3_64(&b[..248]);
    b[..256].copy_from_slice(bytemuck::bytes_of(&h));
}

/// A copy of `good` named `name` beside it, with child `slot` of node `node` of `tile`
/// patched to `r` ([`patch`]).
fn patched_copy(good: &Path, name: &str, tile: Option<usize>, node: usize, slot: usize, r: u64) -> std::path::PathBuf {
    let p = good.with_file_name(name);
    std::fs::copy(good, &p).unwrap();
    patch(&p, tile, node, slot, r);
    p
}

#[test]
fn out_of_range_references_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let good = good_scene(dir.path());
    let scene = Scene::open(&good).unwrap();
    scene.verify_all().unwrap();
    let t = scene.tiles();
    let (node0, unit0) = (t[0].node0(), t[0].unit0());
    let (node1, tiles) = (t[1].node0(), t.len() as u32);
    // What the writer made of the blob's references: the top-level tree links to the part's
    // root; the part's nodes hold absolute positions.
    assert_eq!(scene.top_nodes()[0].child[0], ChildRef::link(0, node0).0);
    let n: &Node8 = &scene.node_pool()[node0 as usize];
    assert_eq!(n.child[0], ChildRef::leaf(unit0, 1).0);
    assert_eq!(n.child[1], ChildRef::inner(node0 + 1).0);
    assert_eq!(n.child[2], ChildRef::link(1, node1).0);
    drop(scene);
    let bad = [
        ("inner node pointing back at its own node", ChildRef::inner(node0).0),
        ("inner node past the tile's nodes", ChildRef::inner(node0 + 2).0),
        ("inner node in another tile", ChildRef::inner(node1).0),
        ("leaf off a block boundary", ChildRef::leaf(unit0 + 1, 1).0),
        ("leaf before the tile's blocks", ChildRef::leaf(unit0 - 9, 1).0),
        ("leaf longer than the tile's blocks", ChildRef::leaf(unit0 + 9, 5).0),
        ("link into its own tile", ChildRef::link(0, node0 + 1).0),
        ("link to no tile", ChildRef::link(tiles, node1).0),
        ("link past the target tile's nodes", ChildRef::link(1, node1 + 1).0),
        ("part inside a part", ChildRef::part(0).0),
    ];
    for (what, r) in bad {
        let p = patched_copy(&good, "bad.mray", Some(0), 0, 1, r);
        let scene = Scene::open(&p).unwrap_or_else(|e| panic!("{what}: the tables should still open: {e}"));
        let e = scene.check_tile(0).expect_err(what);
        assert_eq!(e.kind, SceneErrorKind::CorruptTile(0), "{what}: {e}");
        let msg = e.to_string();
        assert!(msg.contains("bad.mray") && msg.contains("tile 0") && msg.contains("out-of-range"), "{what}: {msg}");
        assert!(scene.check_tile(1).is_ok(), "{what}: tile 1 is sound");
    }
}

#[test]
fn the_top_level_tree_links_only_to_part_roots() {
    let dir = tempfile::tempdir().unwrap();
    let good = good_scene(dir.path());
    let scene = Scene::open(&good).unwrap();
    let t = scene.tiles();
    let (node0, node1, unit0) = (t[0].node0(), t[1].node0(), t[0].unit0());
    drop(scene);
    let bad = [
        ("link to a node that is not the part's root", ChildRef::link(0, node0 + 1).0),
        ("link into the part's other tile", ChildRef::link(1, node1).0),
        ("link to no tile", ChildRef::link(7, node0).0),
        ("leaf", ChildRef::leaf(unit0, 1).0),
        ("part reference", ChildRef::part(0).0),
        ("inner node not after the referring one", ChildRef::inner(16).0),
    ];
    for (what, r) in bad {
        let p = patched_copy(&good, "top.mray", None, 0, 0, r);
        let e = Scene::open(&p).err().unwrap_or_else(|| panic!("{what}: opened"));
        let msg = e.to_string();
        assert!(msg.contains("top.mray") && msg.contains("top-level node 0"), "{what}: {msg}");
    }
}

#[test]
fn all_tiles_checked_counts_sound_tiles_only() {
    let dir = tempfile::tempdir().unwrap();
    let good = good_scene(dir.path());
    let scene = Scene::open(&good).unwrap();
    assert!(!scene.all_tiles_checked(), "tiles are checked on first use, not at open");
    assert!(scene.tile_usable(1));
    assert!(!scene.all_tiles_checked(), "one of two tiles checked");
    assert!(scene.check_all_tiles());
    assert!(scene.all_tiles_checked());
    // A tile with a wrong reference: the others are checked, the scene never all sound.
    let node1 = scene.tiles()[1].node0();
    drop(scene);
    let p = patched_copy(&good, "bad.mray", Some(0), 0, 1, ChildRef::inner(node1).0);
    let scene = Scene::open(&p).unwrap();
    assert!(!scene.check_all_tiles());
    assert!(!scene.all_tiles_checked());
    assert!(scene.tile_checked(1) && !scene.tile_usable(0));
    let e = scene.first_error().expect("the fault is recorded");
    assert_eq!(e.kind, SceneErrorKind::CorruptTile(0), "{e}");
}

/// A scene advised to 2 MiB pages ([`Scene::reread_in_huge_pages`]: written back and dropped from
/// the page cache, the advice given) reads back the same, whether the kernel makes them or
/// not.
#[test]
fn huge_page_advice_keeps_the_scene_intact() {
    let dir = tempfile::tempdir().unwrap();
    let good = good_scene(dir.path());
    let scene = Scene::open(&good).unwrap();
    let before = scene.bytes().to_vec();
    // A kernel without transparent huge pages refuses the advice (an error the callers
    // ignore); where it has them, the advice and the re-read succeed.
    let thp = Path::new("/sys/kernel/mm/transparent_hugepage/enabled").exists();
    let advised = scene.advise_huge_pages();
    assert!(advised.is_ok() || !thp, "{advised:?}");
    assert_eq!(scene.bytes(), &before[..]);
    let reread = scene.reread_in_huge_pages();
    assert!(reread.is_ok() || !thp, "{reread:?}");
    assert!(scene.check_all_tiles());
    assert_eq!(scene.bytes(), &before[..]);
}

/// A scene opened for a pager holds its tables only: a tile reads as zeros (and is not judged
/// corrupt) until loaded, then as the file, and as zeros again once released.
#[test]
fn an_owned_scene_holds_what_was_loaded() {
    let dir = tempfile::tempdir().unwrap();
    let good = good_scene(dir.path());
    let file = std::fs::read(&good).unwrap();
    let scene = Scene::open_owned(&good).unwrap();
    assert!(scene.is_owned() && !Scene::open(&good).unwrap().is_owned());
    assert_eq!(scene.tiles().len(), 2);
    for t in 0..2u32 {
        let e = scene.tiles()[t as usize];
        let r = e.offset as usize..e.offset as usize + e.bytes as usize;
        assert!(scene.bytes()[r.clone()].iter().all(|&b| b == 0), "tile {t} resident before a load");
        assert!(!scene.tile_usable(t));
        for (o, l) in scene.tile_ranges(t).unwrap() {
            scene.load(o, l).unwrap();
        }
        assert_eq!(&scene.bytes()[r.clone()], &file[r.clone()]);
        scene.check_tile(t).unwrap();
        for (o, l) in scene.tile_ranges(t).unwrap() {
            scene.release(o, l).unwrap();
        }
        assert!(scene.bytes()[r].iter().all(|&b| b == 0), "tile {t} resident after its release");
    }
    assert!(scene.first_error().is_none(), "a tile not loaded was judged corrupt");
}

/// An attribute array laid over a tile passes the mapped open's checks (it lies in the
/// file) but not the owned one's: releasing one would drop the other's bytes.
#[test]
fn an_owned_scene_refuses_overlapping_ranges() {
    use megaray_scene::format::PartEntry;
    let dir = tempfile::tempdir().unwrap();
    let good = good_scene(dir.path());
    let mut b = std::fs::read(&good).unwrap();
    let h: Header = bytemuck::pod_read_unaligned(&b[..256]);
    let te = h.tiles_off as usize + 40;
    let tile1: TileEntry = bytemuck::pod_read_unaligned(&b[te..te + 40]);
    let pe = h.parts_off as usize;
    let mut part: PartEntry = bytemuck::pod_read_unaligned(&b[pe..pe + 128]);
    part.materials_off = tile1.offset;
    b[pe..pe + 128].copy_from_slice(bytemuck::bytes_of(&part));
    fix_checksums(&mut b);
    let p = dir.path().join("laid-over.mray");
    std::fs::write(&p, b).unwrap();
    assert!(Scene::open(&p).is_ok());
    let msg = Scene::open_owned(&p).err().expect("overlapping ranges should be refused").to_string();
    assert!(msg.contains("laid-over.mray") && msg.contains("overlap") && msg.contains("tile 1"), "{msg}");
}

/// Tiles out of file order (the directory's second entry moved onto the first's offset,
/// everything else consistent) are refused at open, with the file and the tile named: the tracer finds a
/// hit's tile by its position ([`Scene::tile_of_unit`]), which needs them in order.
#[test]
fn tiles_out_of_file_order_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let good = good_scene(dir.path());
    let scene = Scene::open(&good).unwrap();
    // A hit's tile by its block's position: each block of each tile.
    for (i, t) in scene.tiles().iter().enumerate() {
        for b in 0..t.blocks as u64 {
            assert_eq!(scene.tile_of_unit(t.unit0() + 9 * b), i as u32);
        }
    }
    drop(scene);
    let p = dir.path().join("overlap.mray");
    let mut b = std::fs::read(&good).unwrap();
    let h: Header = bytemuck::pod_read_unaligned(&b[..256]);
    let at = |t: usize| h.tiles_off as usize + 40 * t;
    let e0: TileEntry = bytemuck::pod_read_unaligned(&b[at(0)..at(0) + 40]);
    let mut e1: TileEntry = bytemuck::pod_read_unaligned(&b[at(1)..at(1) + 40]);
    e1.offset = e0.offset;
    b[at(1)..at(1) + 40].copy_from_slice(bytemuck::bytes_of(&e1));
    fix_checksums(&mut b);
    std::fs::write(&p, b).unwrap();
    let e = Scene::open(&p).err().expect("tiles out of order should be refused");
    let msg = e.to_string();
    assert!(msg.contains("overlap.mray") && msg.contains("tile 1") && msg.contains("file order"), "{msg}");
}

/// Scene files the fuzzer (fuzz/, target `scene`, checksums off) found crashing the table
/// checks (an attribute array of 2^62 slots overflowed the size computation), their checksums
/// made right again so that they reach those checks: each is refused with one line.
#[test]
fn scene_files_found_by_fuzzing_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let found = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut n = 0;
    for f in std::fs::read_dir(&found).unwrap() {
        let mut b = std::fs::read(f.unwrap().path()).unwrap();
        if b.len() < 256 {
            continue;
        }
        let h: Header = bytemuck::pod_read_unaligned(&b[..256]);
        let tables = [
            (h.top_nodes_off, h.top_node_count as u64 * 256),
            (h.parts_off, h.part_count as u64 * 128),
            (h.tiles_off, h.tile_count as u64 * 40),
            (h.materials_off, h.materials_bytes),
        ];
        if tables.iter().all(|&(o, l)| o.checked_add(l).is_some_and(|e| e <= b.len() as u64)) {
            fix_checksums(&mut b);
        }
        let path = dir.path().join(format!("found-{n}.mray"));
        std::fs::write(&path, &b).unwrap();
        let e = Scene::open(&path).err().expect("a damaged scene opened");
        assert_eq!(e.to_string().lines().count(), 1, "{e}");
        n += 1;
    }
    assert!(n >= 5);
}
