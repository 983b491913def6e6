//! pbrt-v4 scenes: every statement megaray reads, on small files written here, and
//! malformed input answered by one line naming file, line and column.

use std::path::Path;

use megaray_base::{Affine, Vec3};
use megaray_import::pbrt::{read_scene, ShapeKind};

/// The triangles an object's shapes give, as the build reads them.
struct Tris(Vec<[[f32; 3]; 3]>);

impl megaray_import::TriangleSink for Tris {
    fn triangle(&mut self, p: [[f32; 3]; 3], _: &megaray_import::TriAttr) -> Result<(), megaray_import::ImportError> {
        self.0.push(p);
        Ok(())
    }
    fn material(&mut self, _: megaray_import::Material) -> u32 {
        0
    }
}

/// Reads object `o`'s shapes into `t`.
fn feed(o: &megaray_import::pbrt::ObjectDesc, t: &mut Tris) -> Result<(), megaray_import::ImportError> {
    megaray_import::pbrt::feed_object(o, &megaray_import::ImportOptions::default(), t, &megaray_base::NoProgress)
        .map(|_| ())
}

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).length() < 1e-4
}

#[test]
fn statements_build_objects_instances_materials_and_camera() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "part.pbrt",
        r#"# included
AttributeBegin
  Translate 0 0 5
  Shape "bilinearmesh" "point3 P" [0 0 0  1 0 0  0 1 0  1 1 0]
AttributeEnd
"#,
    );
    write(dir.path(), "wood.tga", "");
    let main = write(
        dir.path(),
        "scene.pbrt",
        r#"LookAt 0 0 -10  0 0 0  0 1 0
Camera "perspective" "float fov" [ 45 ]
Film "rgb" "integer xresolution" [ 640 ] "integer yresolution" 480
Sampler "sobol" "integer pixelsamples" 16
WorldBegin
LightSource "distant" "point3 from" [0 10 0] "point3 to" [0 0 0] "rgb L" [1 0.5 0.25] "float scale" 2
LightSource "infinite" "string filename" "sky.exr"
Texture "wood" "spectrum" "imagemap" "string filename" "wood.tga"
MakeNamedMaterial "Wood" "string type" "coateddiffuse" "texture reflectance" "wood" "float roughness" 0.2
Texture "gone" "spectrum" "imagemap" "string filename" "missing.tga"
MakeNamedMaterial "Gone" "string type" "diffuse" "texture reflectance" "gone"
Material "conductor" "rgb reflectance" [0.9 0.6 0.2]
ObjectBegin "tri"
  Shape "trianglemesh" "point3 P" [0 0 0 1 0 0 0 1 0] "integer indices" [0 1 2]
ObjectEnd
ObjectBegin "pair"
  ObjectInstance "tri"
  Translate 2 0 0
  ObjectInstance "tri"
ObjectEnd
AttributeBegin
  NamedMaterial "Wood"
  Rotate 90 0 0 1
  Scale 2 2 2
  ObjectInstance "pair"
  CoordinateSystem "here"
AttributeEnd
CoordSysTransform "here"
ConcatTransform [1 0 0 0  0 1 0 0  0 0 1 0  3 0 0 1]
ReverseOrientation
Shape "trianglemesh" "point3 P" [0 0 0 1 0 0 0 1 0]
Transform [1 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1]
Shape "sphere" "float radius" 1
Shape "sphere"
Shape "curve" "point3 P" [0 0 0 1 1 1 2 2 2 3 3 3]
Include "part.pbrt"
Import "part.pbrt"
"#,
    );
    let s = read_scene(&main).unwrap();
    // Objects: the world, "tri", "pair".
    assert_eq!(s.objects.len(), 3);
    assert_eq!(s.objects[1].name, "tri");
    assert_eq!(s.objects[1].shapes.len(), 1);
    assert_eq!(s.objects[2].instances.len(), 2, "pair places tri twice (nested instancing)");
    assert!(close(s.objects[2].instances[1].1.point(Vec3::ZERO), Vec3::new(2.0, 0.0, 0.0)));
    let world = &s.objects[0];
    assert_eq!(world.instances.len(), 1);
    let (o, xf) = world.instances[0];
    assert_eq!(o, 2);
    assert!(close(xf.point(Vec3::X), Vec3::new(0.0, 2.0, 0.0)), "Rotate then Scale: {xf:?}");
    // World shapes: the triangle (reversed, moved by the saved system and the concat), and
    // the two includes' bilinear patches (two triangles each); spheres and curves skipped.
    assert_eq!(world.shapes.len(), 3);
    let tri = &world.shapes[0];
    assert!(tri.reverse);
    // The saved system (Rotate, then Scale), then the translation concatenated to it.
    let want = Affine::rotation(90.0, Vec3::Z)
        .then_after(&Affine::scale(Vec3::splat(2.0)))
        .then_after(&Affine::translation(Vec3::new(3.0, 0.0, 0.0)));
    assert!(close(tri.xform.point(Vec3::new(1.0, 2.0, 3.0)), want.point(Vec3::new(1.0, 2.0, 3.0))));
    match &world.shapes[1].kind {
        ShapeKind::Mesh { indices, .. } => assert_eq!(indices.len(), 6),
        k => panic!("{k:?}"),
    }
    assert!(close(world.shapes[1].xform.point(Vec3::ZERO), Vec3::new(0.0, 0.0, 5.0)), "AttributeEnd restores");
    assert_eq!(s.skipped.get("Shape sphere"), Some(&2));
    assert_eq!(s.skipped.get("Shape curve"), Some(&1));
    // Materials: the named coated one with its texture, the conductor current after it.
    assert_eq!(s.materials.len(), 3);
    assert!(s.materials[0].texture.as_ref().unwrap().ends_with("wood.tga"));
    assert_eq!(s.materials[0].diffuse, Some([1.0; 3]), "the texture is the reflectance");
    // A texture whose file is missing: pbrt's grey, and a note.
    assert_eq!((s.materials[1].texture.as_ref(), s.materials[1].diffuse), (None, Some([0.5; 3])));
    assert_eq!(s.skipped.get("Texture imagemap whose file is missing (drawn in the material's colour)"), Some(&1));
    assert_eq!(s.materials[2].metallic, Some(1.0));
    assert_eq!(tri.material, Some(2));
    // Camera, film, lights.
    let c = s.camera.unwrap();
    assert!(close(c.eye, Vec3::new(0.0, 0.0, -10.0)) && close(c.at, Vec3::new(0.0, 0.0, -9.0)) && c.fov == 45.0);
    assert!(close(c.up, Vec3::Y));
    assert_eq!(s.resolution, Some((640, 480)));
    let (dir, l) = s.sun.unwrap();
    assert!(close(dir, Vec3::Y) && l == [2.0, 1.0, 0.5]);
    assert!(s.environment.unwrap().0.ends_with("sky.exr"));
}

#[test]
fn area_lights_get_their_own_material_and_world_triangles_wound_to_emit() {
    let dir = tempfile::tempdir().unwrap();
    let main = write(
        dir.path(),
        "scene.pbrt",
        r#"WorldBegin
Material "diffuse" "rgb reflectance" [0.2 0.3 0.4]
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [3 2 1] "float scale" 2
  Translate 0 5 0
  # Wound to face +y, its normals -y: it emits downward.
  Shape "trianglemesh" "point3 P" [0 0 0  0 0 1  1 0 0] "normal N" [0 -1 0 0 -1 0 0 -1 0]
  # No normals: the winding (+y) emits; two-sided light.
  AreaLightSource "diffuse" "rgb L" [1 1 1] "bool twosided" true
  Shape "trianglemesh" "point3 P" [0 0 0  0 0 1  1 0 0]
AttributeEnd
Shape "trianglemesh" "point3 P" [0 0 0  1 0 0  0 1 0]
ObjectBegin "lamp"
  AreaLightSource "diffuse" "rgb L" [1 1 1]
  Shape "trianglemesh" "point3 P" [0 0 0  1 0 0  0 1 0]
ObjectEnd
"#,
    );
    let s = read_scene(&main).unwrap();
    assert_eq!(s.area_lights.len(), 2);
    let (a, b) = (&s.area_lights[0], &s.area_lights[1]);
    assert_eq!((a.radiance, a.two_sided), ([6.0, 4.0, 2.0], false));
    assert_eq!((b.radiance, b.two_sided), ([1.0, 1.0, 1.0], true));
    // Each its own material, a copy of the shape's with a name that says so.
    assert_eq!(s.materials.len(), 3);
    assert_ne!(a.material, b.material);
    assert_eq!(s.materials[a.material as usize].diffuse, Some([0.2, 0.3, 0.4]));
    assert!(s.materials[a.material as usize].name.contains("area light"));
    let world = &s.objects[0];
    assert_eq!(
        world.shapes.iter().map(|s| s.material).collect::<Vec<_>>(),
        [Some(a.material), Some(b.material), Some(0)]
    );
    assert!(world.shapes[0].emitting && !world.shapes[2].emitting);
    // World space, and wound so that the front emits: down for the first, up for the second.
    let normal = |t: &[[f32; 3]; 3]| {
        let c = |i: usize| Vec3::from(t[i]);
        (c(1) - c(0)).cross(c(2) - c(0)).normalize()
    };
    assert_eq!(a.triangles.len(), 1);
    assert!(a.triangles[0].iter().all(|p| p[1] == 5.0));
    assert!(close(normal(&a.triangles[0]), -Vec3::Y), "{:?}", a.triangles);
    assert!(close(normal(&b.triangles[0]), Vec3::Y));
    // The build winds the shape's own triangles the same way.
    let mut t = Tris(Vec::new());
    feed(world, &mut t).unwrap();
    assert_eq!(t.0[0], a.triangles[0]);
    // An area light inside an object is drawn but does not emit.
    assert_eq!(s.skipped.get("AreaLightSource inside ObjectBegin (drawn, but emits nothing)"), Some(&1));
}

#[test]
fn malformed_scenes_give_one_line_with_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &str, &str)] = &[
        ("bad token", "WorldBegin\nShape @oops", "line 2:7"),
        ("unterminated string", "WorldBegin\n  Shape \"trianglemesh", "line 2:9"),
        ("unbalanced AttributeEnd", "WorldBegin\nAttributeEnd", "line 2:1"),
        ("missing Include", "Include \"nowhere.pbrt\"", "line 1:1"),
        ("unknown statement", "WorldBegin\n\n   Frobnicate 3", "line 3:4"),
        (
            "index out of range",
            "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 7]",
            "line 1:1",
        ),
        ("unterminated list", "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0", "line 1:22"),
        ("unknown object", "ObjectInstance \"ghost\"", "line 1:1"),
        ("bad declaration", "Shape \"trianglemesh\" \"P\" [0 0 0]", "line 1:22"),
        (
            "huge count",
            "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [4000000000 0 1]",
            "out of range",
        ),
    ];
    for (what, text, at) in cases {
        let p = write(dir.path(), "bad.pbrt", text);
        let e = read_scene(&p).expect_err(what).to_string();
        assert!(e.contains("bad.pbrt") && e.contains(at), "{what}: {e}");
        assert!(!e.contains('\n'), "{what}: one line: {e}");
    }
    // An Include cycle.
    write(dir.path(), "a.pbrt", "Include \"b.pbrt\"");
    let b = write(dir.path(), "b.pbrt", "Include \"a.pbrt\"");
    let e = read_scene(&b).unwrap_err().to_string();
    assert!(e.contains("cycle"), "{e}");
}

/// A transform that takes finite corners out of range: reading the shapes is one line of
/// error at the shape's statement, never a non-finite triangle (found by fuzzing the glTF
/// scene reader, which shares this path).
#[test]
fn a_transform_overflowing_the_corners_is_an_error_at_the_shape() {
    let dir = tempfile::tempdir().unwrap();
    let text = "WorldBegin\nScale 1e30 1e30 1e30\n  Shape \"trianglemesh\" \"point3 P\" [0 0 0 1e30 0 0 0 1 0] \"integer indices\" [0 1 2]";
    let p = write(dir.path(), "far.pbrt", text);
    let s = read_scene(&p).unwrap();
    let mut t = Tris(Vec::new());
    let e = s.objects.iter().try_for_each(|o| feed(o, &mut t));
    let e = e.expect_err("an infinite corner").to_string();
    assert!(e.contains("far.pbrt") && e.contains("line 3:3") && e.contains("infinite"), "{e}");
    assert!(!e.contains('\n'), "one line: {e}");
    assert!(t.0.iter().flatten().flatten().all(|x| x.is_finite()), "a non-finite corner passed on");
}

/// Objects placing objects nest up to `MAX_NESTING` levels; one more is one line of error at
/// the `ObjectInstance` that goes too deep (the tracer recurses through the levels; a chain of
/// 5,000 overflowed a render thread's stack).
#[test]
fn objects_nested_too_deep_are_an_error_at_the_instance() {
    let dir = tempfile::tempdir().unwrap();
    let chain = |n: u32| {
        let mut t = String::from("WorldBegin\nObjectBegin \"o0\"\n Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 2]\nObjectEnd\n");
        for i in 1..=n {
            t += &format!("ObjectBegin \"o{i}\"\n ObjectInstance \"o{}\"\nObjectEnd\n", i - 1);
        }
        t + &format!("ObjectInstance \"o{n}\"\n")
    };
    // The world's group places o(n), down to o0's: n + 1 levels of groups.
    let max = megaray_base::MAX_NESTING;
    assert!(read_scene(&write(dir.path(), "ok.pbrt", &chain(max - 1))).is_ok());
    let e = read_scene(&write(dir.path(), "deep.pbrt", &chain(5000))).unwrap_err().to_string();
    assert!(e.contains("deep.pbrt") && e.contains("more than 256 levels"), "{e}");
    // At o257, placing o256: line 4 + 3 * 256 + 2.
    assert!(e.contains(&format!("line {}:2", 4 + 3 * 256 + 2)) && !e.contains('\n'), "{e}");
}
