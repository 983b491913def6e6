//! glTF: GLB when the input starts with its magic, JSON glTF otherwise; read flattened, then
//! with its structure kept (meshes as objects, nodes as groups, as `megaray build` reads a
//! glTF scene).
fn main() {
    afl::fuzz!(|data: &[u8]| {
        let name = if data.starts_with(b"glTF") { "input.glb" } else { "input.gltf" };
        megaray_fuzz::import(name, data);
        megaray_fuzz::gltf_scene(name);
    });
}
