//! OBJ with its material library: the input is the OBJ, then, after a line `#MTL`, the
//! `m.mtl` it may name (`mtllib m.mtl`).
fn main() {
    afl::fuzz!(|data: &[u8]| {
        let (obj, mtl) = megaray_fuzz::split(data, b"#MTL\n");
        megaray_fuzz::file("m.mtl", mtl);
        megaray_fuzz::import("input.obj", obj);
    });
}
