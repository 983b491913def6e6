//! Disk space a build needs, checked before it starts ([`check_space`]), so that a build
//! that cannot fit says so at once instead of failing an hour in.
//!
//! The estimate, per triangle (a floor: attribute streams come on top): the import writes
//! one positions stream (36 bytes, [`crate::stream::Ids`]); a split pass reads a stream and writes its
//! children, giving the parent's blocks back as it reads them on Linux (a hole punched,
//! [`crate::stream::StreamReader::release`]), so that temporary files peak at one stream
//! (plus [`SLACK`]); elsewhere, or on a file system that cannot punch holes, parent and
//! children coexist: two streams. The scene file takes at least 20 bytes compact, 46 plain
//! (measured on plant:100M with levels of detail, `docs/PERF.md`); it is written part by part, each
//! part's stream removed once the part is in it, so that on one file system the two together
//! peak at the larger of the temporary peak and the scene file (plus the parts in flight,
//! within [`SLACK`]).

use std::path::{Path, PathBuf};

use crate::{BuildError, BuildOptions};

/// Bytes per triangle of a positions stream (48 for the split streams of a model with
/// attributes).
pub const STREAM_BYTES_PER_TRI: u64 = 36;
/// The fewest bytes per triangle a plain scene file has taken (levels of detail included).
pub const SCENE_BYTES_PER_TRI: u64 = 46;
/// The same for a compact one ([`BuildOptions::compact`]).
pub const COMPACT_BYTES_PER_TRI: u64 = 20;
/// Room for what a split pass holds beyond one stream (blocks read and not yet given back,
/// the children's last blocks).
pub const SLACK: u64 = 64 << 20;

/// What a build of `tris` triangles needs: (peak bytes of temporary files, bytes of the
/// scene file, peak bytes of both when they share a file system).
pub fn space_needed(tris: u64, opts: &BuildOptions) -> (u64, u64, u64) {
    let stream = tris.saturating_mul(STREAM_BYTES_PER_TRI);
    let split = tris > opts.part_limit();
    let temp = match (split, cfg!(target_os = "linux")) {
        (false, _) => stream,
        (true, true) => stream.saturating_add(SLACK),
        (true, false) => stream.saturating_mul(2),
    };
    let scene = tris.saturating_mul(if opts.compact { COMPACT_BYTES_PER_TRI } else { SCENE_BYTES_PER_TRI });
    (temp, scene, temp.max(scene.saturating_add(SLACK)))
}

/// The folder a build of `out` keeps its temporary files in: [`BuildOptions::tmp_dir`], or
/// the output's folder.
pub fn temp_dir_for(out: &Path, opts: &BuildOptions) -> PathBuf {
    match &opts.tmp_dir {
        Some(d) => d.clone(),
        None => out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_path_buf(),
    }
}

/// Refuses a build of about `tris` triangles into `out` whose files cannot fit the free space
/// of their file systems (where the system says how much is free).
pub fn check_space(tris: u64, out: &Path, opts: &BuildOptions) -> Result<(), BuildError> {
    let tmp = temp_dir_for(out, opts);
    let out_dir = temp_dir_for(out, &BuildOptions { tmp_dir: None, ..opts.clone() });
    let (temp, scene, both) = space_needed(tris, opts);
    let fs = |d: &Path| std::fs::metadata(d).ok().map(|m| file_system(&m));
    let shared = fs(&tmp).is_some() && fs(&tmp) == fs(&out_dir);
    let needs: Vec<(&Path, u64, &str)> = if shared {
        vec![(&tmp, both, "the temporary files and the scene file")]
    } else {
        vec![(&tmp, temp, "the temporary files"), (&out_dir, scene, "the scene file")]
    };
    for (dir, need, what) in needs {
        let Some(free) = megaray_base::temp::free_space(dir) else { continue };
        if need > free {
            return Err(BuildError::NoSpace {
                dir: std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf()),
                what,
                tris,
                need,
                free,
            });
        }
    }
    Ok(())
}

#[cfg(unix)]
fn file_system(m: &std::fs::Metadata) -> u64 {
    std::os::unix::fs::MetadataExt::dev(m)
}

#[cfg(not(unix))]
fn file_system(_: &std::fs::Metadata) -> u64 {
    0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_larger_than_a_part_needs_its_stream_and_slack() {
        let opts = BuildOptions { max_part_tris: Some(1000), compact: false, ..BuildOptions::default() };
        assert_eq!(space_needed(1000, &opts), (36_000, 46_000, 46_000 + SLACK));
        let split = if cfg!(target_os = "linux") { 36_036 + SLACK } else { 72_072 };
        assert_eq!(space_needed(1001, &opts), (split, 46_046, split.max(46_046 + SLACK)));
        // A compact scene file: 20 bytes a triangle at least.
        let opts = BuildOptions { compact: true, ..opts };
        assert_eq!(space_needed(1001, &opts), (split, 20_020, split.max(20_020 + SLACK)));
    }

    #[test]
    fn a_build_larger_than_the_disk_is_refused_naming_the_space() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("x.mray");
        let opts = BuildOptions::default();
        assert!(check_space(1000, &out, &opts).is_ok());
        let e = check_space(u64::MAX / 64, &out, &opts).unwrap_err().to_string();
        assert!(e.contains(&dir.path().display().to_string()) && e.contains("needs about"), "{e}");
    }
}
