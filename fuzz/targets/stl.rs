//! STL: ascii and binary.
fn main() {
    afl::fuzz!(|data: &[u8]| megaray_fuzz::import("input.stl", data));
}
