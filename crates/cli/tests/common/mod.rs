//! Helpers shared by the command line's tests: the binary and how to run it, and the
//! workspace's test kit.
#![allow(dead_code)]

use std::path::PathBuf;

#[allow(unused_imports)]
pub use megaray_testkit::*;

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
