//! STL: binary (also with a header starting with `solid`), ascii, lying counts.

mod common;

use common::{assert_error, collect, import_error, positions, Notes};

fn tris() -> Vec<[[f32; 3]; 3]> {
    vec![
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        [[1.5, -2.25, 3.0], [4.0, 5.0, -6.5], [7.0, 8.0, 9.0]],
        [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]],
    ]
}

fn binary(header: &[u8], count: u32, tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
    let mut out = header.to_vec();
    out.resize(80, b' ');
    out.extend_from_slice(&count.to_le_bytes());
    for t in tris {
        // A wrong normal: it must be ignored.
        for c in [9.0f32, 9.0, 9.0] {
            out.extend_from_slice(&c.to_le_bytes());
        }
        for v in t {
            for c in v {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        out.extend_from_slice(&[0, 0]);
    }
    out
}

#[test]
fn binary_stl() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.stl");
    std::fs::write(&path, binary(b"made by a test", 3, &tris())).unwrap();
    let (c, s) = collect(&path).unwrap();
    assert_eq!(positions(&c), tris());
    assert_eq!(s.triangles, 3);
    assert!(c.tris.iter().all(|t| t.1.normal.is_none()), "the facet normal is ignored");
}

#[test]
fn binary_stl_whose_header_starts_with_solid() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("solid_header.stl");
    std::fs::write(&path, binary(b"solid exported by a CAD tool", 3, &tris())).unwrap();
    let (c, _) = collect(&path).unwrap();
    assert_eq!(positions(&c), tris());
}

#[test]
fn ascii_stl() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ascii.stl");
    let mut text = String::from("  solid part\n");
    for t in tris() {
        text += "  facet normal 0 0 1\n    outer loop\n";
        for v in t {
            text += &format!("      vertex {} {} {}\n", v[0], v[1], v[2]);
        }
        text += "    endloop\n  endfacet\n";
    }
    text += "endsolid part\r\nsolid second\r\nfacet normal 0 0 0\r\nouter loop\r\nvertex 0 0 0\r\nvertex 1e0 0 0\r\n\
             vertex 0 -1.5E1 0\r\nendloop\r\nendfacet\r\nendsolid\r\n";
    std::fs::write(&path, text).unwrap();
    let (c, _) = collect(&path).unwrap();
    let mut want = tris();
    want.push([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, -15.0, 0.0]]);
    assert_eq!(positions(&c), want);
}

#[test]
fn binary_stl_with_a_lying_count_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("liar.stl");
    std::fs::write(&path, binary(b"binary", 5, &tris())).unwrap();
    let msg = import_error(&path);
    assert_error(&msg, "liar.stl", &["header says 5 triangles (334 bytes) but file is 234 bytes"]);
}

#[test]
fn solid_header_with_a_lying_count_is_read_as_ascii_and_fails() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("solid_liar.stl");
    std::fs::write(&path, binary(b"solid x", 4, &tris())).unwrap();
    let msg = import_error(&path);
    assert_error(&msg, "solid_liar.stl", &["no ascii facets"]);
    assert_error(&msg, "solid_liar.stl", &["header says 4 triangles (284 bytes) but file is 234 bytes"]);
    // With a newline in the binary part, the ascii reader trips over the garbage.
    let mut data = binary(
        b"solid x
",
        4,
        &tris(),
    );
    data[100] = b'\n';
    data[101] = b'q';
    std::fs::write(&path, data).unwrap();
    assert_error(&import_error(&path), "solid_liar.stl", &["unexpected"]);
}

#[test]
fn ascii_stl_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.stl");
    std::fs::write(&path, "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 x 0\n").unwrap();
    assert_error(&import_error(&path), "bad.stl", &["line 5: bad number 'x'"]);
    std::fs::write(&path, "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n").unwrap();
    assert_error(&import_error(&path), "bad.stl", &["truncated"]);
    // A facet of two vertices (a line) is skipped; a file of nothing else holds no triangles.
    std::fs::write(&path, "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\n").unwrap();
    assert_error(&import_error(&path), "bad.stl", &["no triangles"]);
    std::fs::write(&path, "solid s\nendsolid s\n").unwrap();
    assert_error(&import_error(&path), "bad.stl", &["no triangles"]);
}

#[test]
fn stl_nan_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nan.stl");
    let mut t = tris();
    t[1][2][1] = f32::NAN;
    std::fs::write(&path, binary(b"x", 3, &t)).unwrap();
    assert_error(&import_error(&path), "nan.stl", &["triangle 1: vertex 2 of the triangle has a NaN"]);
}

/// An ascii facet of fewer than three vertices is skipped with one note giving the count.
#[test]
fn ascii_short_facets_are_skipped_with_a_count() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lines.stl");
    let facet = |vs: &[&str]| {
        let v: String = vs.iter().map(|v| format!("vertex {v}\n")).collect();
        format!("facet normal 0 0 1\nouter loop\n{v}endloop\nendfacet\n")
    };
    let text = format!(
        "solid s\n{}{}{}{}endsolid s\n",
        facet(&["0 0 0", "1 0 0"]),
        facet(&["0 0 0", "1 0 0", "0 1 0"]),
        facet(&["0 0 0"]),
        facet(&["0 0 1", "1 0 1", "0 1 1"]),
    );
    std::fs::write(&path, text).unwrap();
    let notes = Notes::default();
    let mut c = common::Collect::default();
    let s = megaray_import::import_file(&path, &megaray_import::ImportOptions::default(), &mut c, &notes).unwrap();
    assert_eq!((s.triangles, c.tris.len()), (2, 2));
    let notes = notes.0.into_inner().unwrap();
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert!(notes[0].contains("lines.stl") && notes[0].contains("skipped 2 facets"), "{}", notes[0]);
}
