//! glTF scenes keep their structure: a mesh used by several nodes is one object placed
//! several times, node hierarchies are nested objects, the camera node is the camera.

use megaray_base::Vec3;
use megaray_import::gltf_scene::read_scene;

const DOC: &str = r#"{
  "asset": {"version": "2.0"},
  "scene": 0,
  "scenes": [{"nodes": [0, 3]}],
  "nodes": [
    {"name": "assembly", "children": [1, 2], "translation": [0, 0, -5]},
    {"name": "left", "mesh": 0, "translation": [-2, 0, 0]},
    {"name": "right", "mesh": 0, "scale": [-1, 1, 1], "translation": [2, 0, 0]},
    {"name": "eye", "camera": 0, "translation": [0, 1, 10]}
  ],
  "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
  "meshes": [{"name": "tri", "primitives": [{"attributes": {"POSITION": 0}}]}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [0, 0, 0], "max": [1, 1, 0]}],
  "bufferViews": [{"buffer": 0, "byteLength": 36}],
  "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]
}"#;

#[test]
fn a_mesh_of_several_nodes_is_one_object_placed_several_times() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("scene.gltf");
    std::fs::write(&p, DOC).unwrap();
    let s = read_scene(&p).unwrap();
    // The world, the mesh, then the nodes children first: left, right, assembly, eye.
    let names: Vec<&str> = s.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["world", "mesh \"tri\"", "left", "right", "assembly", "eye"]);
    assert_eq!(s.objects[1].shapes.len(), 1, "the mesh's triangles once");
    assert!(s.objects[2..4].iter().all(|o| o.instances == vec![(1, megaray_base::Affine::IDENTITY)]));
    let assembly = &s.objects[4];
    assert_eq!(assembly.instances.len(), 2);
    assert_eq!((assembly.instances[0].0, assembly.instances[1].0), (2, 3));
    assert!((assembly.instances[1].1.point(Vec3::X) - Vec3::new(1.0, 0.0, 0.0)).length() < 1e-6, "mirrored and moved");
    assert_eq!(s.objects[0].instances.iter().map(|i| i.0).collect::<Vec<_>>(), [4, 5]);
    assert!((s.objects[0].instances[0].1.point(Vec3::ZERO) - Vec3::new(0.0, 0.0, -5.0)).length() < 1e-6);
    let c = s.camera.unwrap();
    assert!((c.eye - Vec3::new(0.0, 1.0, 10.0)).length() < 1e-6 && (c.at - Vec3::new(0.0, 1.0, 9.0)).length() < 1e-6);
    assert!((c.fov - 0.8f32.to_degrees()).abs() < 1e-4);
}
