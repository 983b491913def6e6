//! The environment map loader: OpenEXR when the input starts with its magic, Radiance HDR
//! otherwise.
fn main() {
    afl::fuzz!(|data: &[u8]| {
        let name = if data.starts_with(&[0x76, 0x2f, 0x31, 0x01]) { "env.exr" } else { "env.hdr" };
        let path = megaray_fuzz::file(name, data);
        let _ = megaray_render::EnvMap::load(&path);
    });
}
