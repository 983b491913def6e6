//! The PLY writer: files parse back to what was generated, temporary files never stay behind,
//! errors name the file.

use megaray_base::NoProgress;
use megaray_gen::{generate, write_ply, GenError, GenSpec, MeshSink, PlyWriter};
use std::path::Path;

/// The Embree peer's `--dump-ply` header, for `{V}` vertices and `{F}` faces.
fn peer_header(v: u64, f: u64) -> String {
    format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {v}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {f}\nproperty list uchar int vertex_indices\nend_header\n"
    )
}

/// A tiny parser for exactly this layout.
fn read_ply(path: &Path) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let bytes = std::fs::read(path).unwrap();
    let end = b"end_header\n";
    let hlen = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = std::str::from_utf8(&bytes[..hlen]).unwrap();
    let count = |what: &str| -> u64 {
        let line = header.lines().find(|l| l.starts_with(what)).unwrap();
        line[what.len()..].trim().parse().unwrap()
    };
    let (nv, nf) = (count("element vertex"), count("element face"));
    assert_eq!(header, peer_header(nv, nf));
    let mut at = hlen;
    let f32_at = |i: usize| f32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
    let i32_at = |i: usize| i32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
    let mut verts = Vec::new();
    for _ in 0..nv {
        verts.push([f32_at(at), f32_at(at + 4), f32_at(at + 8)]);
        at += 12;
    }
    let mut faces = Vec::new();
    for _ in 0..nf {
        assert_eq!(bytes[at], 3);
        let t = [i32_at(at + 1), i32_at(at + 5), i32_at(at + 9)];
        assert!(t.iter().all(|&i| i >= 0 && (i as u64) < nv));
        faces.push(t.map(|i| i as u32));
        at += 13;
    }
    assert_eq!(at, bytes.len(), "trailing bytes");
    (verts, faces)
}

#[derive(Default)]
struct Collect(Vec<[f32; 3]>, Vec<[u32; 3]>);

impl MeshSink for Collect {
    fn chunk(&mut self, verts: &[[f32; 3]], tris: &[[u32; 3]]) -> Result<(), GenError> {
        self.0.extend_from_slice(verts);
        self.1.extend_from_slice(tris);
        Ok(())
    }
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn writes_what_was_generated() {
    for spec in ["grid:17", "sphereflake:1:6", "plant:20k:3"] {
        let spec: GenSpec = spec.parse().unwrap();
        let mut mem = Collect::default();
        generate(&spec, &mut mem, &NoProgress).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("model.ply");
        let counts = write_ply(&spec, &out, &NoProgress).unwrap();
        assert_eq!(counts, (mem.0.len() as u64, mem.1.len() as u64));
        assert_eq!(read_ply(&out), (mem.0.clone(), mem.1.clone()), "{spec}");
        assert_eq!(files_in(dir.path()), ["model.ply"], "temporary files left");

        // The same through the writer for unknown counts.
        let out2 = dir.path().join("model2.ply");
        let mut w = PlyWriter::create(&out2).unwrap();
        generate(&spec, &mut w, &NoProgress).unwrap();
        assert_eq!(w.finish().unwrap(), counts);
        assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&out2).unwrap());
        assert_eq!(files_in(dir.path()), ["model.ply", "model2.ply"]);
    }
}

#[test]
fn chunks_may_reference_the_previous_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("strip.ply");
    let mut w = PlyWriter::create(&out).unwrap();
    w.chunk(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], &[]).unwrap();
    w.chunk(&[[0.0, 1.0, 0.0], [1.0, 1.0, 0.0]], &[[0, 2, 1], [1, 2, 3]]).unwrap();
    assert_eq!(w.finish().unwrap(), (4, 2));
    let (v, f) = read_ply(&out);
    assert_eq!(v.len(), 4);
    assert_eq!(f, [[0, 2, 1], [1, 2, 3]]);
}

#[test]
fn nothing_stays_behind_without_finish_or_on_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.ply");
    {
        let mut w = PlyWriter::create(&out).unwrap();
        w.chunk(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[0, 1, 2]]).unwrap();
        assert_eq!(files_in(dir.path()).len(), 2, "two temporary files while writing");
    }
    assert!(files_in(dir.path()).is_empty(), "{:?}", files_in(dir.path()));
    {
        let mut w = PlyWriter::with_counts(&out, 3, 1).unwrap();
        w.chunk(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[0, 1, 2]]).unwrap();
    }
    assert!(files_in(dir.path()).is_empty());

    // An index beyond the vertices so far.
    let mut w = PlyWriter::create(&out).unwrap();
    let e = w.chunk(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[0, 1, 3]]).unwrap_err();
    assert!(e.to_string().contains("x.ply: vertex index 3 out of range"), "{e}");
    drop(w);
    assert!(files_in(dir.path()).is_empty());

    // Fewer than declared: finish fails, and nothing appears.
    let mut w = PlyWriter::with_counts(&out, 4, 1).unwrap();
    w.chunk(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[0, 1, 2]]).unwrap();
    let e = w.finish().unwrap_err();
    assert!(e.to_string().contains("got 3 vertices and 1 triangles, but 4 and 1 were declared"), "{e}");
    assert!(files_in(dir.path()).is_empty());

    // More than declared: the chunk is refused.
    let mut w = PlyWriter::with_counts(&out, 2, 0).unwrap();
    assert!(w.chunk(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[]).is_err());
}

#[test]
fn missing_directory_is_a_clean_error_naming_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("no/such/dir/out.ply");
    let e = PlyWriter::create(&out).err().unwrap();
    let msg = e.to_string();
    assert!(msg.starts_with(&format!("{}: cannot create: ", out.display())), "{msg}");
    assert!(matches!(e, GenError::Io { .. }));
    let e = write_ply(&"grid:2".parse().unwrap(), &out, &NoProgress).unwrap_err();
    assert!(e.to_string().starts_with(&format!("{}: cannot create: ", out.display())), "{e}");
}

#[test]
fn replaces_an_existing_file_atomically() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.ply");
    std::fs::write(&out, b"old").unwrap();
    let w = PlyWriter::create(&out).unwrap();
    assert_eq!(std::fs::read(&out).unwrap(), b"old", "untouched until finish");
    w.finish().unwrap();
    assert_eq!(std::fs::read(&out).unwrap(), peer_header(0, 0).as_bytes());
}

#[test]
fn io_errors_read_well() {
    let e = GenError::Io { path: "out.ply".into(), what: "cannot write", err: std::io::Error::from_raw_os_error(28) };
    assert!(e.to_string().starts_with("out.ply: cannot write: No space left on device"), "{e}");
}
