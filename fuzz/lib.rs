//! What every fuzz target shares: the fuzzer's bytes written to a file (the readers read
//! files, as users' data arrives), and each reader run on it. Every function here must return
//! for any input; an `Err` is a correct answer, a panic, abort, hang or allocation over the
//! limit is a bug (fuzz/README.md).

use std::path::PathBuf;
use std::sync::OnceLock;

use megaray_base::NoProgress;
use megaray_import::{ImportError, Material, TriAttr, TriangleSink};

/// This process's folder for the input file (removed when the fuzzer's process ends is not
/// guaranteed; it lives under the system's temporary folder, named by the process id).
fn dir() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("megaray-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("a temporary folder for fuzz inputs");
        d
    })
}

/// Writes `data` to `<dir>/<name>` and returns its path.
pub fn file(name: &str, data: &[u8]) -> PathBuf {
    let p = dir().join(name);
    std::fs::write(&p, data).expect("writing a fuzz input");
    p
}

/// Counts triangles and checks what a reader hands over.
struct Check(u64);

impl TriangleSink for Check {
    fn triangle(&mut self, p: [[f32; 3]; 3], _a: &TriAttr) -> Result<(), ImportError> {
        // Readers promise finite positions.
        assert!(p.iter().flatten().all(|c| c.is_finite()), "a reader passed a non-finite position");
        self.0 += 1;
        Ok(())
    }
    fn material(&mut self, _m: Material) -> u32 {
        0
    }
}

/// Imports `data` as a model file named `name` (its extension picks the reader), with a
/// small memory limit so that spilling is exercised too.
pub fn import(name: &str, data: &[u8]) {
    let path = file(name, data);
    let opts = megaray_import::ImportOptions { mem_limit: 1 << 20, temp_dir: dir().clone() };
    let _ = megaray_import::import_file(&path, &opts, &mut Check(0), &NoProgress);
}

/// `data` split at the first `marker` (wherever it stands): what comes before it, and after
/// it (empty when there is no marker).
pub fn split<'a>(data: &'a [u8], marker: &[u8]) -> (&'a [u8], &'a [u8]) {
    match data.windows(marker.len()).position(|w| w == marker) {
        Some(i) => (&data[..i], &data[i + marker.len()..]),
        None => (data, &[]),
    }
}

/// Reads `data` as a pbrt-v4 scene named `name`, then every object's shapes (PLY files they
/// name included), with a small memory limit as [`import`] has.
pub fn pbrt(name: &str, data: &[u8]) {
    let path = file(name, data);
    if let Ok(scene) = megaray_import::pbrt::read_scene(&path) {
        feed(&scene);
    }
}

/// Reads the file `name` (written before) as a glTF scene with its structure kept, then every
/// object's shapes.
pub fn gltf_scene(name: &str) {
    if let Ok(scene) = megaray_import::gltf_scene::read_scene(&dir().join(name)) {
        feed(&scene);
    }
}

/// Every object's shapes of a scene description, until one fails.
fn feed(scene: &megaray_import::pbrt::PbrtScene) {
    let opts = megaray_import::ImportOptions { mem_limit: 1 << 20, temp_dir: dir().clone() };
    for o in &scene.objects {
        if megaray_import::pbrt::feed_object(o, &opts, &mut Check(0), &NoProgress).is_err() {
            return;
        }
    }
}
