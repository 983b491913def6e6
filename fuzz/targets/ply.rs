//! PLY: ascii and binary, any header.
fn main() {
    afl::fuzz!(|data: &[u8]| megaray_fuzz::import("input.ply", data));
}
