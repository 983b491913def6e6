//! Bad input gives an `ImportError` naming the file and what is wrong, never a panic or an
//! allocation sized by a header.

mod common;

use common::{assert_error, import_error, put, write_ply, Enc, PlySpec};
use std::path::{Path, PathBuf};
use std::time::Instant;

fn write(dir: &Path, name: &str, data: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, data).unwrap();
    p
}

const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

fn ply_header(enc: &str, nv: u64, nf: u64) -> String {
    format!(
        "ply\nformat {enc} 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {nf}\nproperty list uchar int vertex_indices\nend_header\n"
    )
}

#[test]
fn truncated_binary_ply() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.ply");
    let verts: Vec<[f32; 3]> = (0..100).map(|i| [i as f32, 1.0, 2.0]).collect();
    let faces: Vec<Vec<u32>> = (0..98).map(|i| vec![i, i + 1, i + 2]).collect();
    write_ply(&path, &PlySpec::new(Enc::Le), &verts, &faces);
    let full = std::fs::read(&path).unwrap();
    // Cut inside the faces (passes the up-front size check: detected while reading) ...
    std::fs::write(&path, &full[..full.len() - 20]).unwrap();
    assert_error(&import_error(&path), "cut.ply", &["face 96: truncated"]);
    // ... and inside the vertices.
    let header_len = full.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    std::fs::write(&path, &full[..header_len + 12 * 50 + 5]).unwrap();
    assert_error(&import_error(&path), "cut.ply", &["truncated"]);
}

#[test]
fn truncated_ascii_ply() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = ply_header("ascii", 3, 3);
    text += "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n3 0 1\n";
    let path = write(dir.path(), "cut_ascii.ply", text);
    assert_error(&import_error(&path), "cut_ascii.ply", &["face 2: truncated"]);
}

#[test]
fn ply_header_promising_billions_errors_fast() {
    let dir = tempfile::tempdir().unwrap();
    for (enc, name) in
        [("binary_little_endian", "huge_le.ply"), ("binary_big_endian", "huge_be.ply"), ("ascii", "huge_ascii.ply")]
    {
        let mut data = ply_header(enc, 4_000_000_000, 3_000_000_000).into_bytes();
        data.extend(std::iter::repeat_n(0u8, 900));
        let path = write(dir.path(), name, data);
        let t = Instant::now();
        let msg = import_error(&path);
        assert!(t.elapsed().as_secs_f64() < 1.0, "took {:?}", t.elapsed());
        assert_error(&msg, name, &["truncated: the header promises 4000000000 vertex records"]);
    }
    // Counts that pass the size check on their own (the face list is 1 byte at least) but
    // not with the data: found while reading, still without big allocations.
    let mut data = ply_header("binary_little_endian", 3, 200).into_bytes();
    for v in TRI {
        for c in v {
            data.extend_from_slice(&c.to_le_bytes());
        }
    }
    for _ in 0..20 {
        data.push(3);
        data.extend_from_slice(&[0; 12]);
    }
    let path = write(dir.path(), "liar.ply", data);
    assert_error(&import_error(&path), "liar.ply", &["face 20: truncated"]);
    // A list count that lies (int count of 2 billion indices).
    let text = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                property float z\nelement face 1\nproperty list int int vertex_indices\nend_header\n";
    let mut data = text.as_bytes().to_vec();
    data.extend(std::iter::repeat_n(0u8, 36));
    data.extend_from_slice(&2_000_000_000i32.to_le_bytes());
    data.extend(std::iter::repeat_n(0u8, 40));
    let path = write(dir.path(), "longlist.ply", data);
    assert_error(&import_error(&path), "longlist.ply", &["face 0: truncated"]);
}

#[test]
fn ply_index_out_of_range() {
    let dir = tempfile::tempdir().unwrap();
    for enc in Enc::ALL {
        let name = format!("range_{enc:?}.ply");
        let path = dir.path().join(&name);
        write_ply(&path, &PlySpec::new(enc), &TRI, &[vec![0, 1, 2], vec![0, 2, 3]]);
        assert_error(&import_error(&path), &name, &["face 1: vertex index 3 out of range (the file has 3 vertices)"]);
        write_ply(
            &path,
            &PlySpec::new(enc),
            &TRI,
            &[vec![0, 1, 2], vec![2, 1, 0], vec![0, 1, 2, 1, 0, 2, -1i32 as u32]],
        );
        let msg = import_error(&path);
        assert_error(&msg, &name, &["face 2: vertex index"]);
        assert!(msg.contains("out of range"), "{msg}");
    }
    // A negative index.
    let mut data = ply_header("binary_big_endian", 3, 1).into_bytes();
    for v in TRI {
        for c in v {
            data.extend_from_slice(&c.to_be_bytes());
        }
    }
    data.push(3);
    for i in [0i32, -1, 2] {
        data.extend_from_slice(&i.to_be_bytes());
    }
    let path = write(dir.path(), "negative.ply", data);
    assert_error(&import_error(&path), "negative.ply", &["face 0: vertex index -1 out of range"]);
}

#[test]
fn obj_index_out_of_range() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 3 2 9\n");
    assert_error(&import_error(&path), "range.obj", &["face 2: vertex index 9 out of range"]);
    let path = write(dir.path(), "vn.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//-2\n");
    assert_error(&import_error(&path), "vn.obj", &["normal index -2 out of range"]);
}

#[test]
fn nan_coordinate() {
    let dir = tempfile::tempdir().unwrap();
    let mut verts = TRI.to_vec();
    verts.push([0.5, f32::NAN, 0.0]);
    for enc in Enc::ALL {
        let name = format!("nan_{enc:?}.ply");
        let path = dir.path().join(&name);
        write_ply(&path, &PlySpec::new(enc), &verts, &[vec![0, 1, 2]]);
        assert_error(&import_error(&path), &name, &["vertex 3: vertex coordinate is NaN"]);
    }
    let path = write(dir.path(), "nan.obj", "v 0 0 0\nv NaN 0 0\nv 0 1 0\nf 1 2 3\n");
    assert_error(&import_error(&path), "nan.obj", &["line 2: vertex 2: coordinate is NaN"]);
    let path = write(dir.path(), "nan.stl", "solid\nfacet normal 0 0 1\nouter loop\nvertex 0 0 nan\n");
    assert_error(&import_error(&path), "nan.stl", &["line 4: vertex 0: coordinate is NaN"]);
}

#[test]
fn infinite_coordinate() {
    let dir = tempfile::tempdir().unwrap();
    let mut verts = TRI.to_vec();
    verts[1][2] = f32::NEG_INFINITY;
    for enc in Enc::ALL {
        let name = format!("inf_{enc:?}.ply");
        let path = dir.path().join(&name);
        write_ply(&path, &PlySpec::new(enc), &verts, &[vec![0, 1, 2]]);
        assert_error(&import_error(&path), &name, &["vertex 1: vertex coordinate is infinite"]);
    }
    // A double too large for f32 becomes infinite.
    let path = dir.path().join("big_double.ply");
    write_ply(&path, &PlySpec { coord: "double", ..PlySpec::new(Enc::Le) }, &TRI, &[vec![0, 1, 2]]);
    let mut data = std::fs::read(&path).unwrap();
    let at = data.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    data[at..at + 8].copy_from_slice(&1e300f64.to_le_bytes());
    std::fs::write(&path, data).unwrap();
    assert_error(&import_error(&path), "big_double.ply", &["vertex 0: vertex coordinate is infinite"]);
}

#[test]
fn bad_magic() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "magic.ply", "plyx\nformat ascii 1.0\nend_header\n");
    assert_error(&import_error(&path), "magic.ply", &["bad magic"]);
    let path = write(dir.path(), "binary.ply", [0u8, 159, 146, 150, 7, 8, 9]);
    assert_error(&import_error(&path), "binary.ply", &["bad magic"]);
    let path = write(dir.path(), "magic.stl", [7u8; 60]);
    assert_error(&import_error(&path), "magic.stl", &["not an STL file"]);
    let path = write(dir.path(), "magic.glb", b"GLTF\x02\0\0\0\x0c\0\0\0");
    assert_error(&import_error(&path), "magic.glb", &["bad magic"]);
}

#[test]
fn empty_files() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["empty.ply", "empty.obj", "empty.stl", "empty.gltf", "empty.glb"] {
        let path = write(dir.path(), name, b"");
        assert_error(&import_error(&path), name, &["empty file"]);
    }
}

#[test]
fn bad_ascii_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = ply_header("ascii", 3, 1);
    text += "0 0 0\n1 0.5.5 0\n0 1 0\n3 0 1 2\n";
    let path = write(dir.path(), "num.ply", text);
    assert_error(&import_error(&path), "num.ply", &["line 11: bad number '0.5.5' for y of vertex 1"]);
    let mut text = ply_header("ascii", 3, 1);
    text += "0 0 0\n1 0 0\n0 1 0\n3 0 one 2\n";
    let path = write(dir.path(), "index.ply", text);
    assert_error(&import_error(&path), "index.ply", &["line 13: bad number 'one'"]);
    let path = write(dir.path(), "num.obj", "v 0 0 0\nv 1 0 0\nv 0 1e 0\nf 1 2 3\n");
    assert_error(&import_error(&path), "num.obj", &["line 3: bad number '1e'"]);
    let path = write(dir.path(), "face.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x3\n");
    assert_error(&import_error(&path), "face.obj", &["line 4: face 1: bad vertex 'x3'"]);
}

#[test]
fn bad_ply_headers() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, String, &str); 9] = [
        ("format.ply", ply_header("binary_middle_endian", 3, 1), "unknown PLY format 'binary_middle_endian'"),
        (
            "type.ply",
            ply_header("ascii", 3, 1).replace("property float y", "property quad y"),
            "line 5: unknown PLY type 'quad'",
        ),
        ("noxyz.ply", ply_header("ascii", 3, 1).replace("property float z", "property float w"), "no x, y, z"),
        (
            "order.ply",
            "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nelement vertex 3\n\
             property float x\nproperty float y\nproperty float z\nend_header\n3 0 1 2\n0 0 0\n1 0 0\n0 1 0\n"
                .into(),
            "the face element comes before the vertex element",
        ),
        (
            "noface.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
             end_header\n0 0 0\n1 0 0\n0 1 0\n"
                .into(),
            "no face element",
        ),
        ("noend.ply", "ply\nformat ascii 1.0\nelement vertex 3\n".into(), "truncated header"),
        ("count.ply", ply_header("ascii", 3, 1).replace("vertex 3", "vertex -3"), "bad element count"),
        ("noformat.ply", ply_header("ascii", 3, 1).replace("format ascii 1.0\n", ""), "no format line"),
        ("nolist.ply", ply_header("ascii", 3, 1).replace("vertex_indices", "corners"), "no vertex_indices list"),
    ];
    for (name, text, what) in cases {
        let data = if name == "noend.ply" { text } else { text + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n" };
        let path = write(dir.path(), name, data);
        assert_error(&import_error(&path), name, &[what]);
    }
}

#[test]
fn no_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nofaces.ply");
    write_ply(&path, &PlySpec::new(Enc::Le), &TRI, &[]);
    assert_error(&import_error(&path), "nofaces.ply", &["no triangles"]);
    let path = dir.path().join("shortfaces.ply");
    write_ply(&path, &PlySpec::new(Enc::Ascii), &TRI, &[vec![0, 1], vec![2]]);
    assert_error(&import_error(&path), "shortfaces.ply", &["no triangles"]);
    let mut stl = vec![b' '; 80];
    stl.extend_from_slice(&0u32.to_le_bytes());
    let path = write(dir.path(), "zero.stl", stl);
    assert_error(&import_error(&path), "zero.stl", &["no triangles"]);
}

#[test]
fn unknown_extension() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "model.fbx", b"Kaydara FBX Binary");
    assert_error(&import_error(&path), "model.fbx", &["unknown model format"]);
    let path = write(dir.path(), "noext", b"ply\n");
    assert_error(&import_error(&path), "noext", &["unknown model format"]);
}

#[test]
fn nonexistent_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("missing.ply");
    assert_error(&import_error(&path), "missing.ply", &["not found"]);
    let sub = dir.path().join("folder.obj");
    std::fs::create_dir(&sub).unwrap();
    assert_error(&import_error(&sub), "folder.obj", &["directory"]);
}

#[test]
fn garbage_never_panics() {
    // Random bytes after valid-looking headers: errors (or triangles), never a panic.
    let dir = tempfile::tempdir().unwrap();
    let mut x = 0x9e3779b97f4a7c15u64;
    let mut rnd = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let prefixes: [&[u8]; 7] = [
        b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\nelement face 10\nproperty list uchar int vertex_indices\nend_header\n",
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty uchar x\nproperty uchar y\nproperty uchar z\nelement face 2\nproperty list int uchar vertex_indices\nend_header\n",
        b"solid x\n",
        b"v 1 2 3\nf ",
        b"glTF\x02\0\0\0",
        b"{\"asset\":{\"version\":\"2.0\"},\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],",
        b"",
    ];
    let exts = ["ply", "ply", "stl", "obj", "glb", "gltf", "stl"];
    for round in 0..40 {
        for (k, prefix) in prefixes.iter().enumerate() {
            let mut data = prefix.to_vec();
            let n = (rnd() % 300) as usize;
            for _ in 0..n {
                let b = rnd() as u8;
                data.push(if k == 1 || k == 3 { b"0123456789 -/\n"[b as usize % 14] } else { b });
            }
            let path = write(dir.path(), &format!("g{round}_{k}.{}", exts[k]), &data);
            let _ = common::collect(&path);
        }
    }
}

#[test]
fn mutated_files_never_panic() {
    // Valid files with random bytes overwritten, cut or inserted.
    let dir = tempfile::tempdir().unwrap();
    let verts: Vec<[f32; 3]> = (0..20).map(|i| [i as f32, (i % 3) as f32, 1.0]).collect();
    let faces: Vec<Vec<u32>> = (0..15).map(|i| vec![i, i + 1, i + 2, i + 4]).collect();
    let mut originals: Vec<(&str, Vec<u8>)> = Vec::new();
    for (enc, name) in [(Enc::Le, "le.ply"), (Enc::Be, "be.ply"), (Enc::Ascii, "ascii.ply")] {
        let p = dir.path().join(name);
        write_ply(&p, &PlySpec { extras: true, attrs: true, ..PlySpec::new(enc) }, &verts, &faces);
        originals.push((name, std::fs::read(&p).unwrap()));
    }
    let mut obj = String::new();
    for v in &verts {
        obj += &format!("v {} {} {}\nvt 0.5 0.5\nvn 0 0 1\n", v[0], v[1], v[2]);
    }
    for f in &faces {
        obj += &format!("f {}/{}/{} {}//{} -1/-1 {}\n", f[0] + 1, f[0] + 1, f[0] + 1, f[1] + 1, f[1] + 1, f[2] + 1);
    }
    originals.push(("m.obj", obj.into_bytes()));
    let mut stl = vec![b's'; 80];
    stl.extend_from_slice(&10u32.to_le_bytes());
    for i in 0..10 {
        for k in 0..12 {
            put(&mut stl, Enc::Le, "float", (i * k) as f64);
        }
        stl.extend_from_slice(&[0, 0]);
    }
    originals.push(("b.stl", stl));

    let mut x = 0x2545f4914f6cdd1du64;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for (name, data) in &originals {
        let path = dir.path().join(name);
        std::fs::write(&path, data).unwrap();
        common::collect(&path).unwrap_or_else(|e| panic!("the unmutated {name} fails: {e}"));
        for _ in 0..300 {
            let mut d = data.clone();
            for _ in 0..1 + rnd() % 4 {
                let at = (rnd() % d.len() as u64) as usize;
                match rnd() % 4 {
                    0 => d.truncate(at),
                    1 => d.insert(at, rnd() as u8),
                    2 => d[at] = b"0123456789 -\n/e."[(rnd() % 15) as usize],
                    _ => d[at] = rnd() as u8,
                }
                if d.is_empty() {
                    break;
                }
            }
            std::fs::write(&path, &d).unwrap();
            if let Err(e) = common::collect(&path) {
                assert!(e.to_string().contains(name), "{e}");
            }
        }
    }
}
