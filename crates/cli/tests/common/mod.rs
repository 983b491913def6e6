//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use megaray_base::NoProgress;
use megaray_build::{build_scene, BuildOptions, BuildSummary};

/// The folder of real test models (`shared/models` beside the repository).
pub fn models_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/models");
    assert!(d.is_dir(), "test models not found at {} (shared/ must sit beside the repository)", d.display());
    d
}

pub fn model(name: &str) -> PathBuf {
    models_dir().join(name)
}

/// Generates `spec` as PLY into `dir`.
pub fn gen(dir: &Path, spec: &str) -> PathBuf {
    let s: megaray_gen::GenSpec = spec.parse().unwrap();
    let p = dir.join(format!("{}.ply", spec.replace(':', "_")));
    megaray_gen::write_ply(&s, &p, &NoProgress).unwrap();
    p
}

/// Builds `inputs` into `dir/name.mray`, with at most `max_part` triangles a part.
pub fn build(dir: &Path, inputs: &[PathBuf], name: &str, max_part: Option<u64>) -> (PathBuf, BuildSummary) {
    let out = dir.join(format!("{name}.mray"));
    let opts = BuildOptions {
        max_part_tris: max_part,
        build_mem: 512 << 20,
        tile_target: 64 << 10,
        threads: 2,
        ..BuildOptions::default()
    };
    let s = build_scene(inputs, &out, &opts, &NoProgress).unwrap();
    (out, s)
}

/// Path of the megaray binary built for these tests.
pub fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_megaray"))
}

/// Runs megaray with `args`; returns (exit code, stdout, stderr).
pub fn run(args: &[&str]) -> (i32, String, String) {
    let out = std::process::Command::new(bin()).args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A small deterministic random number generator (splitmix64).
pub struct Rng(pub u64);
impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    pub fn f32(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}
