//! Materials from the inputs reach the shaders: OBJ `map_Kd` textures through texture
//! coordinates, glTF base colour and metallic factors.

mod common;

use megaray_base::Vec3;
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::Tracer;

/// The albedo AOV of an 8x8 frame looking down -Z at the unit square around the origin.
fn albedo_of(scene: &Scene, shader: Builtin) -> (Vec<[f32; 3]>, Image) {
    let cam = Camera::look_at(Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO, Vec3::Y, 20.0, 8, 8);
    let mut s = RenderSettings::new(cam);
    s.aovs = true;
    s.shader = shader;
    let r = Renderer::new(s, &scene.header().bounds);
    let f = render_frame(&r, &Tracer::new(scene), 0);
    (f.albedo, f.image)
}

#[test]
fn obj_texture_is_looked_up_by_uv() {
    let dir = tempfile::tempdir().unwrap();
    // 2x2 texels: top row red, green; bottom row blue, white (sRGB 0 and 255 are linear 0, 1).
    let tex = image::RgbImage::from_raw(2, 2, vec![255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255]).unwrap();
    tex.save(dir.path().join("tex.png")).unwrap();
    std::fs::write(dir.path().join("q.mtl"), "newmtl t\nKd 1 1 1\nmap_Kd tex.png\n").unwrap();
    let obj = dir.path().join("q.obj");
    std::fs::write(
        &obj,
        "mtllib q.mtl\nusemtl t\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n",
    )
    .unwrap();
    let scene = Scene::open(&common::build_file(dir.path(), &obj, "q")).unwrap();
    let (albedo, _) = albedo_of(&scene, Builtin::Diffuse);
    // v = 0 is the bottom of the texture (OBJ convention); the image's top-left quarter
    // shows the texture's top-left texel.
    let at = |x: usize, y: usize| albedo[y * 8 + x];
    assert_eq!(at(1, 1), [1.0, 0.0, 0.0]);
    assert_eq!(at(6, 1), [0.0, 1.0, 0.0]);
    assert_eq!(at(1, 6), [0.0, 0.0, 1.0]);
    assert_eq!(at(6, 6), [1.0, 1.0, 1.0]);
}

fn base64(b: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in b.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            s.push(if k <= c.len() { T[(n >> (18 - 6 * k) & 63) as usize] as char } else { '=' });
        }
    }
    s
}

#[test]
fn gltf_base_colour_and_metal() {
    let dir = tempfile::tempdir().unwrap();
    let pos: [f32; 12] = [-1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 1.0, 1.0, 0.0, -1.0, 1.0, 0.0];
    let idx: [u16; 6] = [0, 1, 2, 0, 2, 3];
    let mut bytes: Vec<u8> = pos.iter().flat_map(|f| f.to_le_bytes()).collect();
    bytes.extend(idx.iter().flat_map(|i| i.to_le_bytes()));
    let gltf = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"material":0}}]}}],
        "materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[0.2,0.4,0.6,1.0],"metallicFactor":1.0,"roughnessFactor":0.1}}}}],
        "buffers":[{{"byteLength":{len},"uri":"data:application/octet-stream;base64,{b64}"}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":12}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[-1,-1,0],"max":[1,1,0]}},
                     {{"bufferView":1,"componentType":5123,"count":6,"type":"SCALAR"}}]}}"#,
        len = bytes.len(),
        b64 = base64(&bytes)
    );
    let path = dir.path().join("m.gltf");
    std::fs::write(&path, gltf).unwrap();
    let scene = Scene::open(&common::build_file(dir.path(), &path, "m")).unwrap();
    let (albedo, img) = albedo_of(&scene, Builtin::Auto);
    for a in &albedo {
        assert!((Vec3::from(*a) - Vec3::new(0.2, 0.4, 0.6)).abs().max_element() < 1e-6, "{a:?}");
    }
    // Metallic: `auto` makes it a mirror tinted by the base colour. Facing the camera, it
    // reflects the camera's direction back out into the plain sky: the sky times the tint.
    let sky = RenderSettings::new(Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, 20.0, 8, 8)).sky;
    for p in &img.pixels {
        for k in 0..3 {
            assert!((p[k] - sky[k] * [0.2, 0.4, 0.6][k]).abs() < 1e-5, "{p:?}");
        }
    }
}
