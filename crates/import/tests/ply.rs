//! PLY round trips: the same mesh written in every encoding and with many scalar types
//! reads back as the same triangles.

mod common;

use common::{collect, collect_with, color_of, fan, normal_of, positions, write_ply, Enc, Notes, PlySpec};
use megaray_import::{ImportOptions, NO_MATERIAL};
use proptest::prelude::*;

/// A small mesh with integer coordinates in 0..=20 (representable in every scalar type),
/// made of triangles, quads and pentagons.
fn mesh() -> (Vec<[f32; 3]>, Vec<Vec<u32>>) {
    let mut verts = Vec::new();
    for y in 0..5 {
        for x in 0..5 {
            verts.push([x as f32 * 5.0, y as f32 * 4.0, ((x * y) % 7) as f32]);
        }
    }
    let id = |x: u32, y: u32| y * 5 + x;
    let faces = vec![
        vec![id(0, 0), id(1, 0), id(1, 1)],
        vec![id(1, 0), id(2, 0), id(2, 1), id(1, 1)],
        vec![id(2, 0), id(3, 0), id(4, 0), id(4, 1), id(3, 1)],
        vec![id(0, 2), id(1, 2), id(1, 3), id(0, 3)],
        vec![id(4, 4), id(3, 4), id(2, 4), id(2, 3), id(3, 3)],
        vec![id(0, 4), id(1, 4), id(0, 3)],
    ];
    (verts, faces)
}

#[test]
fn encodings_and_scalar_types_round_trip() {
    let (verts, faces) = mesh();
    let want = fan(&verts, &faces);
    assert_eq!(want.len(), 1 + 2 + 3 + 2 + 3 + 1);
    let dir = tempfile::tempdir().unwrap();
    let mut n = 0;
    for enc in Enc::ALL {
        for coord in ["uchar", "ushort", "short", "int", "uint", "float", "double", "char", "int8", "float32"] {
            for (count, index) in
                [("uchar", "int"), ("uint8", "uint"), ("int", "int32"), ("ushort", "ushort"), ("uchar", "uchar")]
            {
                for extras in [false, true] {
                    let spec = PlySpec { enc, coord, count, index, extras, attrs: false };
                    let path = dir.path().join(format!("m{n}.ply"));
                    n += 1;
                    write_ply(&path, &spec, &verts, &faces);
                    let (c, s) = collect(&path).unwrap_or_else(|e| panic!("{spec:?}: {e}"));
                    assert_eq!(positions(&c), want, "{spec:?}");
                    assert_eq!(s.vertices, verts.len() as u64);
                    assert!(c.tris.iter().all(|t| t.1.normal.is_none() && t.1.color.is_none() && t.1.uv.is_none()));
                    assert!(c.tris.iter().all(|t| t.1.material == NO_MATERIAL));
                }
            }
        }
    }
}

#[test]
fn normals_and_colors() {
    let (verts, faces) = mesh();
    let dir = tempfile::tempdir().unwrap();
    for enc in Enc::ALL {
        let path = dir.path().join("attrs.ply");
        let spec = PlySpec { attrs: true, extras: true, ..PlySpec::new(enc) };
        write_ply(&path, &spec, &verts, &faces);
        let (c, _) = collect(&path).unwrap();
        assert_eq!(positions(&c), fan(&verts, &faces));
        // The first face is (0, 1, 6).
        let (_, a) = &c.tris[0];
        let normals = a.normal.expect("normals");
        let colors = a.color.expect("colours");
        for (k, &vi) in [0usize, 1, 6].iter().enumerate() {
            assert_eq!(normals[k], normal_of(verts[vi]), "{enc:?}");
            let rgb = color_of(vi);
            let want = [rgb[0] as f32 / 255.0, rgb[1] as f32 / 255.0, rgb[2] as f32 / 255.0, 1.0];
            assert_eq!(colors[k], want, "{enc:?}");
        }
    }
}

#[test]
fn uv_names_and_float_colors() {
    let dir = tempfile::tempdir().unwrap();
    for (u, v) in [("u", "v"), ("s", "t"), ("texture_u", "texture_v")] {
        let path = dir.path().join("uv.ply");
        let text = format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
             property float {u}\nproperty float {v}\nproperty float red\nproperty float green\nproperty float blue\n\
             property float alpha\nelement face 1\nproperty list uchar int vertex_index\nend_header\n\
             0 0 0 0.25 0.5 1 0.5 0 0.5\n1 0 0 1 0 0 0 0 1\n0 1 0 0 1 0.2 0.4 0.6 0.8\n3 0 1 2\n"
        );
        std::fs::write(&path, text).unwrap();
        let (c, _) = collect(&path).unwrap();
        assert_eq!(c.tris.len(), 1);
        let a = &c.tris[0].1;
        assert_eq!(a.uv, Some([[0.25, 0.5], [1.0, 0.0], [0.0, 1.0]]));
        assert_eq!(a.color, Some([[1.0, 0.5, 0.0, 0.5], [0.0, 0.0, 0.0, 1.0], [0.2, 0.4, 0.6, 0.8]]));
    }
}

#[test]
fn degenerate_triangles_pass_through() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("degenerate.ply");
    let verts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
    write_ply(&path, &PlySpec::new(Enc::Le), &verts, &[vec![0, 1, 2], vec![0, 0, 0]]);
    let (c, _) = collect(&path).unwrap();
    assert_eq!(c.tris.len(), 2);
}

/// A mesh whose vertex table is far larger than the memory budget: faces reference both
/// nearby and far-away vertices.
#[test]
fn spills_vertices_beyond_the_memory_limit() {
    let n = 100_000u32;
    let verts: Vec<[f32; 3]> = (0..n).map(|i| [i as f32, (i % 317) as f32 * 0.5, (i % 1009) as f32 * -0.25]).collect();
    let mut faces = Vec::new();
    let mut x = 7u64;
    for i in 0..n - 2 {
        faces.push(vec![i, i + 1, i + 2]);
        if i % 10 == 0 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let far = ((x >> 33) % n as u64) as u32;
            faces.push(vec![i, far, (far + 1) % n, (i + 1) % n]);
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let want = fan(&verts, &faces);
    for enc in [Enc::Le, Enc::Ascii] {
        let path = dir.path().join("big.ply");
        write_ply(&path, &PlySpec::new(enc), &verts, &faces);
        let spill_dir = tempfile::tempdir().unwrap();
        let small = ImportOptions { mem_limit: 64 << 10, temp_dir: spill_dir.path().to_path_buf() };
        let (a, sa) = collect_with(&path, &small).unwrap();
        let (b, sb) = collect_with(&path, &ImportOptions { mem_limit: 1 << 30, ..small.clone() }).unwrap();
        assert!(sa.spilled > 90_000, "{enc:?}: only {} vertices spilled", sa.spilled);
        assert_eq!(sb.spilled, 0);
        assert!(positions(&a) == want, "{enc:?}: spilled import differs from the mesh");
        assert!(positions(&b) == want, "{enc:?}: in-memory import differs from the mesh");
        assert_eq!(std::fs::read_dir(spill_dir.path()).unwrap().count(), 0, "spill files are removed");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, failure_persistence: None, ..ProptestConfig::default() })]

    /// Random polygons written in all three encodings read back as their fan triangulation.
    #[test]
    fn random_polygons_in_all_encodings(
        verts in prop::collection::vec(prop::array::uniform3(-1.0e6f32..1.0e6), 3..40),
        raw_faces in prop::collection::vec(prop::collection::vec(any::<u32>(), 3..9), 1..30),
        count_ty in prop::sample::select(vec!["uchar", "int", "uint", "ushort"]),
        index_ty in prop::sample::select(vec!["int", "uint"]),
    ) {
        let nv = verts.len() as u32;
        let faces: Vec<Vec<u32>> = raw_faces.iter().map(|f| f.iter().map(|i| i % nv).collect()).collect();
        let want = fan(&verts, &faces);
        let dir = tempfile::tempdir().unwrap();
        for enc in Enc::ALL {
            let path = dir.path().join("p.ply");
            let spec = PlySpec { count: count_ty, index: index_ty, ..PlySpec::new(enc) };
            write_ply(&path, &spec, &verts, &faces);
            let (c, _) = collect(&path).unwrap();
            prop_assert_eq!(positions(&c), want.clone(), "{:?}", enc);
        }
    }
}

/// Records progress calls.
#[derive(Default)]
struct Record {
    stages: std::sync::Mutex<Vec<(String, u64)>>,
    done: std::sync::atomic::AtomicU64,
    finished: std::sync::atomic::AtomicBool,
}

impl megaray_base::Progress for Record {
    fn stage(&self, what: &str, total: u64) {
        self.stages.lock().unwrap().push((what.to_string(), total));
    }
    fn inc(&self, n: u64) {
        self.done.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
    }
    fn finish(&self) {
        self.finished.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

#[test]
fn progress_counts_the_file_bytes() {
    let (verts, faces) = mesh();
    let dir = tempfile::tempdir().unwrap();
    for enc in Enc::ALL {
        let path = dir.path().join("progress.ply");
        write_ply(&path, &PlySpec::new(enc), &verts, &faces);
        let len = std::fs::metadata(&path).unwrap().len();
        let rec = Record::default();
        let mut c = common::Collect::default();
        let s = megaray_import::import_file(&path, &ImportOptions::default(), &mut c, &rec).unwrap();
        assert_eq!(*rec.stages.lock().unwrap(), [("import progress.ply".to_string(), len)]);
        assert_eq!(rec.done.load(std::sync::atomic::Ordering::Relaxed), len);
        assert_eq!(s.bytes, len);
        assert!(rec.finished.load(std::sync::atomic::Ordering::Relaxed));
    }
}

/// Points and lines written as faces of one or two vertices (and empty faces) are skipped with
/// one note giving the count, in every encoding; the triangles around them load.
#[test]
fn points_and_lines_are_skipped_with_a_count() {
    let verts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]];
    let faces = vec![vec![0, 1, 2], vec![0, 1], vec![3], vec![], vec![1, 3, 2, 0], vec![2, 3]];
    let dir = tempfile::tempdir().unwrap();
    for enc in Enc::ALL {
        let path = dir.path().join("lines.ply");
        write_ply(&path, &PlySpec::new(enc), &verts, &faces);
        let notes = Notes::default();
        let mut c = common::Collect::default();
        let s = megaray_import::import_file(&path, &ImportOptions::default(), &mut c, &notes).unwrap();
        assert_eq!(s.triangles, 3, "{enc:?}");
        assert_eq!(positions(&c), common::fan(&verts, &faces), "{enc:?}");
        let notes = notes.0.into_inner().unwrap();
        let skipped: Vec<&String> = notes.iter().filter(|n| n.contains("skipped")).collect();
        assert_eq!(skipped.len(), 1, "{notes:?}");
        assert!(skipped[0].contains("lines.ply") && skipped[0].contains("skipped 4 faces"), "{}", skipped[0]);
    }
}
