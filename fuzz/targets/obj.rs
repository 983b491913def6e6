//! OBJ with its material library: the input is the OBJ, then, after a line `#MTL`, the
//! `m.mtl` it may name (`mtllib m.mtl`).
fn main() {
    afl::fuzz!(|data: &[u8]| {
        let split = data.windows(5).position(|w| w == b"#MTL\n");
        let (obj, mtl) = match split {
            Some(i) => (&data[..i], &data[i + 5..]),
            None => (data, &[][..]),
        };
        megaray_fuzz::file("m.mtl", mtl);
        megaray_fuzz::import("input.obj", obj);
    });
}
