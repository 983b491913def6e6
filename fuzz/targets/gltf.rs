//! glTF: GLB when the input starts with its magic, JSON glTF otherwise.
fn main() {
    afl::fuzz!(|data: &[u8]| {
        let name = if data.starts_with(b"glTF") { "input.glb" } else { "input.gltf" };
        megaray_fuzz::import(name, data);
    });
}
