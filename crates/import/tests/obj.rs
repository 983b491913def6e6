//! OBJ: index forms, negative indices, polygons, materials and groups.

mod common;

use common::{assert_error, collect, import_error, positions, Collect, Notes};
use megaray_import::{import_file, ImportOptions, Material, NO_MATERIAL};

fn write(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const V: [[f32; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];

#[test]
fn index_forms_and_negative_indices() {
    let dir = tempfile::tempdir().unwrap();
    let text = "# a comment\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
                vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nvn 0 0 -1\n\
                f 1 2 3\n\
                f 1/1 2/2 3/3\n\
                f 1//1 2//1 3//2\n\
                f 1/1/1 2/2/1 3/3/1 # trailing comment\n\
                f -4/-4/-2 -3/-3/-2 -2/-2/-2\n\
                s off\nl 1 2\n";
    let path = write(dir.path(), "forms.obj", text);
    let (c, s) = collect(&path).unwrap();
    assert_eq!(s.vertices, 4);
    let tri = [V[0], V[1], V[2]];
    assert_eq!(positions(&c), vec![tri; 5]);
    let attrs: Vec<_> = c.tris.iter().map(|t| (t.1.uv.is_some(), t.1.normal.is_some())).collect();
    assert_eq!(attrs, [(false, false), (true, false), (false, true), (true, true), (true, true)]);
    assert_eq!(c.tris[1].1.uv, Some([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]));
    assert_eq!(c.tris[2].1.normal, Some([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]));
    assert_eq!(c.tris[4].1.normal, Some([[0.0, 0.0, 1.0]; 3]));
    assert!(c.tris.iter().all(|t| t.1.material == NO_MATERIAL));
    assert!(c.materials.is_empty());
}

#[test]
fn polygons_are_fan_triangulated() {
    let dir = tempfile::tempdir().unwrap();
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv -1 0.5 0\nf 1 2 3 4 5\nf 4 3 2 1\n";
    let path = write(dir.path(), "poly.obj", text);
    let (c, _) = collect(&path).unwrap();
    let p = |i: usize| if i < 4 { V[i] } else { [-1.0, 0.5, 0.0] };
    let want = vec![[p(0), p(1), p(2)], [p(0), p(2), p(3)], [p(0), p(3), p(4)], [p(3), p(2), p(1)], [p(3), p(1), p(0)]];
    assert_eq!(positions(&c), want);
}

#[test]
fn vertex_colors() {
    let dir = tempfile::tempdir().unwrap();
    let text = "v 0 0 0\nv 1 0 0 1 0 0\nv 1 1 0 0 0.5 1\nf 1 2 3\nf 3 2 1\n";
    let path = write(dir.path(), "colors.obj", text);
    let (c, _) = collect(&path).unwrap();
    let white = [1.0, 1.0, 1.0, 1.0];
    assert_eq!(c.tris[0].1.color, Some([white, [1.0, 0.0, 0.0, 1.0], [0.0, 0.5, 1.0, 1.0]]));
    assert_eq!(c.tris.len(), 2);
}

#[test]
fn usemtl_and_mtllib_materials() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "mats.mtl",
        "# materials\nnewmtl red\nKd 1 0 0\nKs 0.5 0.5 0.5\nNs 32\nd 0.75\nmap_Kd -s 1 1 1 textures/red.png\n\n\
         newmtl glass\nKd 0.9 0.9 1.0\nTr 0.8\n",
    );
    let text = "mtllib mats.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
                f 1 2 3\nusemtl red\nf 1 2 3\nf 1 3 4\nusemtl glass\nf 1 2 3\nusemtl red\nf 2 3 4\nusemtl unknown\nf 1 2 4\n";
    let path = write(dir.path(), "mats.obj", text);
    let notes = Notes::default();
    let mut c = Collect::default();
    import_file(&path, &ImportOptions::default(), &mut c, &notes).unwrap();
    let names: Vec<&str> = c.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["red", "glass", "unknown"], "each usemtl name is declared once");
    let red = &c.materials[0];
    assert_eq!(
        *red,
        Material {
            name: "red".into(),
            diffuse: Some([1.0, 0.0, 0.0]),
            specular: Some([0.5, 0.5, 0.5]),
            shininess: Some(32.0),
            opacity: Some(0.75),
            texture: Some(dir.path().join("textures/red.png")),
            ..Material::default()
        }
    );
    assert_eq!(c.materials[1].diffuse, Some([0.9, 0.9, 1.0]));
    assert!((c.materials[1].opacity.unwrap() - 0.2).abs() < 1e-6, "Tr 0.8 is opacity 0.2");
    assert_eq!(c.materials[2], Material { name: "unknown".into(), ..Material::default() });
    let ids: Vec<u32> = c.tris.iter().map(|t| t.1.material).collect();
    assert_eq!(ids, [NO_MATERIAL, 0, 0, 1, 0, 2]);
    assert!(notes.0.lock().unwrap().iter().any(|n| n.contains("unknown")));
}

#[test]
fn missing_mtl_is_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "nomtl.obj", "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m\nf 1 2 3\n");
    let notes = Notes::default();
    let mut c = Collect::default();
    import_file(&path, &ImportOptions::default(), &mut c, &notes).unwrap();
    assert_eq!(c.materials, [Material { name: "m".into(), ..Material::default() }]);
    assert_eq!(c.tris[0].1.material, 0);
    assert!(notes.0.lock().unwrap().iter().any(|n| n.contains("gone.mtl")), "{:?}", notes.0);
}

#[test]
fn groups_become_materials_without_usemtl() {
    let dir = tempfile::tempdir().unwrap();
    let text =
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\ng wheel\nf 1 2 3\nf 1 2 3\no body\nf 1 2 3\ng empty\ng wheel\nf 3 2 1\n";
    let path = write(dir.path(), "groups.obj", text);
    let (c, _) = collect(&path).unwrap();
    let names: Vec<&str> = c.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["wheel", "body"]);
    assert!(c.materials.iter().all(|m| m.diffuse.is_none()));
    let ids: Vec<u32> = c.tris.iter().map(|t| t.1.material).collect();
    assert_eq!(ids, [NO_MATERIAL, 0, 0, 1, 0]);
}

#[test]
fn obj_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n");
    assert_error(&import_error(&path), "range.obj", &["line 5: face 2: vertex index 4 out of range"]);
    let path = write(dir.path(), "neg.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n");
    assert_error(&import_error(&path), "neg.obj", &["face 1: vertex index -4 out of range"]);
    let path = write(dir.path(), "zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
    assert_error(&import_error(&path), "zero.obj", &["index 0 out of range"]);
    let path = write(dir.path(), "vt.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n");
    assert_error(&import_error(&path), "vt.obj", &["texture coordinate index 2 out of range"]);
    let path = write(dir.path(), "num.obj", "v 0 0 0\nv 1 zero 0\n");
    assert_error(&import_error(&path), "num.obj", &["line 2: bad number 'zero'"]);
    let path = write(dir.path(), "inf.obj", "v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n");
    assert_error(&import_error(&path), "inf.obj", &["line 3: vertex 3: coordinate is infinite"]);
    let path = write(dir.path(), "none.obj", "v 0 0 0\nv 1 0 0\n# no faces\n");
    assert_error(&import_error(&path), "none.obj", &["no triangles"]);
}

#[test]
fn obj_spills_and_matches() {
    // A long strip of vertices with faces referencing recent ones, under a tiny budget.
    let mut text = String::new();
    let n = 30_000;
    for i in 0..n {
        text += &format!("v {i} {} 0\nvn 0 0 1\nvt {} 0.5\n", i % 2, i as f32 / n as f32);
        if i >= 2 {
            text += &format!("f {}/{}/{} -2/-2/-2 -1/-1/-1\n", i - 1, i - 1, i - 1);
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "strip.obj", &text);
    let small = ImportOptions { mem_limit: 32 << 10, temp_dir: dir.path().to_path_buf() };
    let (a, sa) = common::collect_with(&path, &small).unwrap();
    let (b, sb) = collect(&path).unwrap();
    assert!(sa.spilled > 50_000, "spilled {}", sa.spilled);
    assert_eq!(sb.spilled, 0);
    assert_eq!(a.tris.len(), n - 2);
    assert!(a.tris == b.tris);
    assert_eq!(a.tris[5].0, [[5.0, 1.0, 0.0], [6.0, 0.0, 0.0], [7.0, 1.0, 0.0]]);
}

/// Real exporters write lines as two-vertex faces (and points as one-vertex faces): those are
/// skipped with one note giving the count, and the rest of the model loads.
#[test]
fn short_faces_points_and_lines_are_skipped_with_a_count() {
    let dir = tempfile::tempdir().unwrap();
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 1 2\nf 4\nl 1 2 3\np 1\nf 2 4 3\nf 3/1\n";
    let text = text.replace("f 3/1", "f 3");
    let path = write(dir.path(), "lines.obj", &text);
    let notes = Notes::default();
    let mut c = Collect::default();
    let s = import_file(&path, &ImportOptions::default(), &mut c, &notes).unwrap();
    assert_eq!((s.triangles, c.tris.len()), (2, 2));
    let notes = notes.0.into_inner().unwrap();
    let skipped: Vec<&String> = notes.iter().filter(|n| n.contains("skipped")).collect();
    assert_eq!(skipped.len(), 1, "one note per file: {notes:?}");
    assert!(skipped[0].contains("lines.obj") && skipped[0].contains("skipped 3 faces"), "{}", skipped[0]);
    // A file of nothing but lines is still an error: it holds no triangles.
    let path = write(dir.path(), "only.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n");
    assert_error(&import_error(&path), "only.obj", &["no triangles"]);
}
