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
