//! pbrt-v4 scenes: the input is `scene.pbrt`; after a line `#INC`, the `inc.pbrt` it may
//! `Include` or `Import`; after a line `#PLY`, the `m.ply` a `plymesh` may name. The scene is
//! parsed and every object's shapes read, as `megaray build scene.pbrt` reads them.
fn main() {
    afl::fuzz!(|data: &[u8]| {
        let (text, ply) = megaray_fuzz::split(data, b"#PLY\n");
        let (scene, inc) = megaray_fuzz::split(text, b"#INC\n");
        megaray_fuzz::file("inc.pbrt", inc);
        megaray_fuzz::file("m.ply", ply);
        megaray_fuzz::pbrt("scene.pbrt", scene);
    });
}
