//! glTF: node transforms, instancing, strips and fans, materials, errors.

mod common;

use common::{assert_error, collect, import_error, Collect, Notes};
use megaray_import::{import_file, ImportOptions, Material, NO_MATERIAL};
use std::path::Path;

fn f32s(out: &mut Vec<u8>, v: &[f32]) {
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

const QUAD: [f32; 12] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0];
const NORMALS: [f32; 12] = [0.6, 0.0, 0.8, 0.6, 0.0, 0.8, 0.6, 0.0, 0.8, 0.6, 0.0, 0.8];
const UV: [f32; 8] = [0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0];
const STRIP: [f32; 12] = [0.0, 0.0, 2.0, 1.0, 0.0, 2.0, 0.0, 1.0, 2.0, 1.0, 1.0, 2.0];
const FAN: [f32; 15] = [0.0, 0.0, 3.0, 1.0, 0.0, 3.0, 1.0, 1.0, 3.0, 0.0, 1.0, 3.0, -1.0, 0.5, 3.0];

/// Writes `scene.gltf` + `scene.bin` into `dir`; `indices` are the quad's triangle indices.
fn write_scene(dir: &Path, indices: [u16; 6]) -> std::path::PathBuf {
    let mut bin = Vec::new();
    f32s(&mut bin, &QUAD); // 0..48
    f32s(&mut bin, &NORMALS); // 48..96
    f32s(&mut bin, &UV); // 96..128
    for i in indices {
        bin.extend_from_slice(&i.to_le_bytes()); // 128..140
    }
    f32s(&mut bin, &STRIP); // 140..188
    f32s(&mut bin, &FAN); // 188..248
    std::fs::write(dir.join("scene.bin"), &bin).unwrap();
    let view = |off: usize, len: usize| format!(r#"{{"buffer":0,"byteOffset":{off},"byteLength":{len}}}"#);
    let acc = |view: usize, count: usize, ty: &str, comp: u32, minmax: &str| {
        format!(r#"{{"bufferView":{view},"count":{count},"type":"{ty}","componentType":{comp}{minmax}}}"#)
    };
    let mm = |min: [f32; 3], max: [f32; 3]| format!(r#","min":{min:?},"max":{max:?}"#);
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0, 1]}}],
  "nodes": [
    {{"mesh": 0, "translation": [10, 0, 0]}},
    {{"mesh": 0, "scale": [-1, 1, 1], "children": [2]}},
    {{"mesh": 1, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,5,0,1]}}
  ],
  "meshes": [
    {{"name": "quad", "primitives": [
      {{"attributes": {{"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}}, "indices": 3, "material": 0}},
      {{"attributes": {{"POSITION": 0}}, "mode": 1}}
    ]}},
    {{"name": "strips", "primitives": [
      {{"attributes": {{"POSITION": 4}}, "mode": 5, "material": 0}},
      {{"attributes": {{"POSITION": 5}}, "mode": 6}}
    ]}}
  ],
  "materials": [{{"name": "paint", "pbrMetallicRoughness": {{"baseColorFactor": [0.5, 0.25, 1, 0.5],
      "metallicFactor": 0.125, "roughnessFactor": 0.75, "baseColorTexture": {{"index": 0}}}}}}],
  "textures": [{{"source": 0}}],
  "images": [{{"uri": "tex%20a.png"}}],
  "buffers": [{{"uri": "scene.bin", "byteLength": {len}}}],
  "bufferViews": [{v0}, {v1}, {v2}, {v3}, {v4}, {v5}],
  "accessors": [{a0}, {a1}, {a2}, {a3}, {a4}, {a5}]
}}"#,
        len = bin.len(),
        v0 = view(0, 48),
        v1 = view(48, 48),
        v2 = view(96, 32),
        v3 = view(128, 12),
        v4 = view(140, 48),
        v5 = view(188, 60),
        a0 = acc(0, 4, "VEC3", 5126, &mm([0.0; 3], [1.0, 1.0, 0.0])),
        a1 = acc(1, 4, "VEC3", 5126, ""),
        a2 = acc(2, 4, "VEC2", 5126, ""),
        a3 = acc(3, 6, "SCALAR", 5123, ""),
        a4 = acc(4, 4, "VEC3", 5126, &mm([0.0, 0.0, 2.0], [1.0, 1.0, 2.0])),
        a5 = acc(5, 5, "VEC3", 5126, &mm([-1.0, 0.0, 3.0], [1.0, 1.0, 3.0])),
    );
    let path = dir.join("scene.gltf");
    std::fs::write(&path, json).unwrap();
    path
}

fn p(a: &[f32], i: usize) -> [f32; 3] {
    [a[3 * i], a[3 * i + 1], a[3 * i + 2]]
}

#[test]
fn transforms_instancing_strips_fans_materials() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_scene(dir.path(), [0, 1, 2, 0, 2, 3]);
    let notes = Notes::default();
    let mut c = Collect::default();
    let s = import_file(&path, &ImportOptions::default(), &mut c, &notes).unwrap();
    assert_eq!(s.triangles, 9);
    assert_eq!(c.tris.len(), 9);

    // One material, declared once although used by three primitive instances.
    assert_eq!(
        c.materials,
        [Material {
            name: "paint".into(),
            diffuse: Some([0.5, 0.25, 1.0]),
            opacity: Some(0.5),
            metallic: Some(0.125),
            roughness: Some(0.75),
            texture: Some(dir.path().join("tex a.png")),
            ..Material::default()
        }]
    );

    let t = |x: [f32; 3], dx: f32, sx: f32, dy: f32| [x[0] * sx + dx, x[1] + dy, x[2]];
    // Node 0: translated quad with normals and uvs.
    assert_eq!(
        c.tris[0].0,
        [t(p(&QUAD, 0), 10.0, 1.0, 0.0), t(p(&QUAD, 1), 10.0, 1.0, 0.0), t(p(&QUAD, 2), 10.0, 1.0, 0.0)]
    );
    assert_eq!(
        c.tris[1].0,
        [t(p(&QUAD, 0), 10.0, 1.0, 0.0), t(p(&QUAD, 2), 10.0, 1.0, 0.0), t(p(&QUAD, 3), 10.0, 1.0, 0.0)]
    );
    assert_eq!(c.tris[0].1.material, 0);
    assert_eq!(c.tris[0].1.uv, Some([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]));
    assert_eq!(c.tris[0].1.normal, Some([[0.6, 0.0, 0.8]; 3]));
    // Node 1: mirrored in x, corners 1 and 2 swapped to keep the orientation; normals
    // through the inverse transpose.
    assert_eq!(
        c.tris[2].0,
        [t(p(&QUAD, 0), 0.0, -1.0, 0.0), t(p(&QUAD, 2), 0.0, -1.0, 0.0), t(p(&QUAD, 1), 0.0, -1.0, 0.0)]
    );
    assert_eq!(c.tris[2].1.uv, Some([[0.0, 0.0], [1.0, 1.0], [1.0, 0.0]]));
    assert_eq!(c.tris[2].1.normal, Some([[-0.6, 0.0, 0.8]; 3]));
    // Node 2 (child of node 1): strip and fan, translated by 5 in y, mirrored by the parent.
    let m = |x: [f32; 3]| t(x, 0.0, -1.0, 5.0);
    assert_eq!(c.tris[4].0, [m(p(&STRIP, 0)), m(p(&STRIP, 2)), m(p(&STRIP, 1))]);
    assert_eq!(c.tris[5].0, [m(p(&STRIP, 2)), m(p(&STRIP, 3)), m(p(&STRIP, 1))]);
    assert_eq!(c.tris[4].1.material, 0);
    assert_eq!(c.tris[6].0, [m(p(&FAN, 1)), m(p(&FAN, 0)), m(p(&FAN, 2))]);
    assert_eq!(c.tris[8].0, [m(p(&FAN, 3)), m(p(&FAN, 0)), m(p(&FAN, 4))]);
    assert_eq!(c.tris[8].1.material, NO_MATERIAL);
    assert!(c.tris[4].1.normal.is_none());

    assert!(notes.0.lock().unwrap().iter().any(|n| n.contains("skipped 2 point or line primitives")), "{:?}", notes.0);
}

#[test]
fn gltf_index_out_of_range() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_scene(dir.path(), [0, 1, 2, 0, 2, 7]);
    assert_error(&import_error(&path), "scene.gltf", &["mesh \"quad\" primitive 0: index 7 out of range (4 vertices)"]);
}

#[test]
fn gltf_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("noscene.gltf");
    std::fs::write(&path, r#"{"asset": {"version": "2.0"}}"#).unwrap();
    assert_error(&import_error(&path), "noscene.gltf", &["no scene"]);
    let path = dir.path().join("junk.gltf");
    std::fs::write(&path, "{ not json").unwrap();
    assert_error(&import_error(&path), "junk.gltf", &["invalid glTF"]);
    let path = dir.path().join("magic.glb");
    std::fs::write(&path, b"glTX\x02\0\0\0\x0c\0\0\0").unwrap();
    assert_error(&import_error(&path), "magic.glb", &["bad magic"]);
    let path = dir.path().join("short.glb");
    std::fs::write(&path, b"glTF\x02\0\0\0\x02\0\0\0").unwrap();
    assert_error(&import_error(&path), "short.glb", &["byte 8: truncated or bad GLB"]);
    let path = dir.path().join("v1.glb");
    std::fs::write(&path, b"glTF\x01\0\0\0\x14\0\0\0\0\0\0\0JSON").unwrap();
    assert_error(&import_error(&path), "v1.glb", &["unsupported GLB version 1"]);
    let path = dir.path().join("dag.gltf");
    std::fs::write(
        &path,
        r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0,1]}],"nodes":[{"children":[2]},{"children":[2]},{}]}"#,
    )
    .unwrap();
    assert_error(&import_error(&path), "dag.gltf", &["node 2: node has several parents"]);
    let path = dir.path().join("cycle.gltf");
    std::fs::write(
        &path,
        r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"children":[1]},{"children":[0]}]}"#,
    )
    .unwrap();
    assert_error(&import_error(&path), "cycle.gltf", &["node 0: a root node of the scene is also a child"]);
    let path = dir.path().join("nobin.gltf");
    std::fs::write(
        &path,
        r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[]}],"buffers":[{"uri":"missing.bin","byteLength":4}]}"#,
    )
    .unwrap();
    assert_error(&import_error(&path), "nobin.gltf", &["invalid glTF"]);
}

#[test]
fn glb_of_the_shared_models_has_materials_once() {
    let path = common::models_dir().join("2CylinderEngine.glb");
    let (c, _) = collect(&path).unwrap();
    let doc = gltf::Gltf::open(&path).unwrap();
    let used: std::collections::BTreeSet<usize> =
        doc.meshes().flat_map(|m| m.primitives()).filter_map(|p| p.material().index()).collect();
    assert_eq!(c.materials.len(), used.len(), "each glTF material is declared once");
    assert!(c.tris.iter().all(|t| t.1.material == NO_MATERIAL || (t.1.material as usize) < c.materials.len()));
    assert!(c.materials.iter().all(|m| m.diffuse.is_some() && m.roughness.is_some()));
}

#[test]
fn gltf_absurd_sparse_accessor_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.bin"), [0u8; 16]).unwrap();
    let path = dir.path().join("sparse.gltf");
    std::fs::write(
        &path,
        r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
  "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
  "buffers":[{"uri":"s.bin","byteLength":16}],
  "bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":4},{"buffer":0,"byteOffset":4,"byteLength":12}],
  "accessors":[{"count":1000000000000,"type":"VEC3","componentType":5126,"min":[0,0,0],"max":[1,1,1],
    "sparse":{"count":1,"indices":{"bufferView":0,"componentType":5125},"values":{"bufferView":1}}}]}"#,
    )
    .unwrap();
    assert_error(&import_error(&path), "sparse.gltf", &["implausible"]);
}

#[test]
fn mutated_gltf_never_panics() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_scene(dir.path(), [0, 1, 2, 0, 2, 3]);
    let json = std::fs::read(&path).unwrap();
    let bin = std::fs::read(dir.path().join("scene.bin")).unwrap();
    let mut x = 0x853c49e6748fea9bu64;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for round in 0..300 {
        let (target, mut d) = if round % 2 == 0 { ("scene.gltf", json.clone()) } else { ("scene.bin", bin.clone()) };
        for _ in 0..1 + rnd() % 3 {
            let at = (rnd() % d.len() as u64) as usize;
            d[at] = if target == "scene.gltf" { b"0123456789-,:[]{}"[(rnd() % 17) as usize] } else { rnd() as u8 };
        }
        std::fs::write(dir.path().join(target), &d).unwrap();
        if let Err(e) = collect(&path) {
            assert!(e.to_string().contains("scene.gltf"), "{e}");
        }
        std::fs::write(dir.path().join("scene.gltf"), &json).unwrap();
        std::fs::write(dir.path().join("scene.bin"), &bin).unwrap();
    }
}

/// A mesh with vertex colours used by two nodes: read with its structure kept, it is one
/// object whose triangles carry the colours, as the flattening reader gives them.
#[test]
fn structured_gltf_keeps_vertex_colours() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = Vec::new();
    f32s(&mut bin, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]); // 0..36
    let colours = [1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.5, 0.0, 0.0, 1.0, 0.25];
    f32s(&mut bin, &colours); // 36..84
    std::fs::write(dir.path().join("c.bin"), &bin).unwrap();
    let json = r#"{
  "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
  "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [5, 0, 0]}],
  "meshes": [{"name": "tri", "primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1}}]}],
  "buffers": [{"uri": "c.bin", "byteLength": 84}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 48}],
  "accessors": [
    {"bufferView": 0, "count": 3, "type": "VEC3", "componentType": 5126, "min": [0, 0, 0], "max": [1, 1, 0]},
    {"bufferView": 1, "count": 3, "type": "VEC4", "componentType": 5126}
  ]
}"#;
    let path = dir.path().join("c.gltf");
    std::fs::write(&path, json).unwrap();
    let want = [[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 0.5], [0.0, 0.0, 1.0, 0.25]];

    let mut flat = Collect::default();
    import_file(&path, &ImportOptions::default(), &mut flat, &Notes::default()).unwrap();
    assert_eq!(flat.tris.len(), 2, "flattened: the mesh once per node");
    assert!(flat.tris.iter().all(|t| t.1.color == Some(want)));

    let s = megaray_import::gltf_scene::read_scene(&path).unwrap();
    let meshes: Vec<_> = s.objects.iter().filter(|o| !o.shapes.is_empty()).collect();
    assert_eq!(meshes.len(), 1, "one object for the mesh, placed twice");
    let mut c = Collect::default();
    megaray_import::pbrt::feed_object(meshes[0], &ImportOptions::default(), &mut c, &Notes::default()).unwrap();
    assert_eq!(c.tris.len(), 1);
    assert_eq!(c.tris[0].1.color, Some(want), "the structured reader keeps COLOR_0");
}

/// A node hierarchy nesting more levels of instancing than `MAX_NESTING` is one line of error,
/// flattened or structured (a chain of 200,000 nodes overflowed the structured reader's stack);
/// one level less reads.
#[test]
fn a_node_chain_too_deep_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let chain = |n: u32, name: &str| {
        let mut bin = Vec::new();
        f32s(&mut bin, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        std::fs::write(dir.path().join("t.bin"), &bin).unwrap();
        let nodes: Vec<String> = (0..n)
            .map(|i| if i + 1 < n { format!(r#"{{"children": [{}]}}"#, i + 1) } else { r#"{"mesh": 0}"#.into() })
            .collect();
        let json = format!(
            r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
  "buffers": [{{"uri": "t.bin", "byteLength": 36}}], "bufferViews": [{{"buffer": 0, "byteLength": 36}}],
  "accessors": [{{"bufferView": 0, "count": 3, "type": "VEC3", "componentType": 5126, "min": [0, 0, 0], "max": [1, 1, 0]}}]}}"#,
            nodes.join(",")
        );
        let p = dir.path().join(name);
        std::fs::write(&p, json).unwrap();
        p
    };
    // The world, a group a node, the mesh's: n + 1 levels.
    let max = megaray_base::MAX_NESTING;
    let ok = chain(max - 1, "ok.gltf");
    assert_eq!(collect(&ok).unwrap().0.tris.len(), 1);
    assert!(megaray_import::gltf_scene::read_scene(&ok).is_ok());
    let deep = chain(200_000, "deep.gltf");
    for e in [import_error(&deep), megaray_import::gltf_scene::read_scene(&deep).unwrap_err().to_string()] {
        assert!(e.contains("deep.gltf") && e.contains("more than 256 levels") && !e.contains('\n'), "{e}");
    }
}
