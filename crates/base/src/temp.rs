//! Temporary outputs: every file megaray writes is written under a temporary name in the
//! output's folder and renamed into place when complete, so a reader never sees half a file.
//! The temporary name carries the writer's process id; a process killed mid-write (`kill -9`,
//! power loss) leaves its temporary behind, and the next write into that folder removes it
//! once no process of that id is alive ([`clean_stale`]).

use std::path::{Path, PathBuf};

/// The prefix of build folders (`.megaray-build-<pid>-<random>`).
pub const BUILD_DIR_PREFIX: &str = ".megaray-build-";

/// The temporary name `path` is written under: `.<name>.tmp-<pid>` beside it.
pub fn temp_path(path: &Path) -> Option<PathBuf> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name()?.to_string_lossy();
    Some(dir.join(format!(".{name}.tmp-{}", std::process::id())))
}

/// Bytes free for an unprivileged writer on the file system that holds `dir`, if the
/// system says (`statvfs`).
pub fn free_space(dir: &Path) -> Option<u64> {
    #[cfg(unix)]
    {
        let s = rustix::fs::statvfs(dir).ok()?;
        Some(s.f_bavail.saturating_mul(s.f_frsize))
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        None
    }
}

/// The prefix for this process's build folders: `.megaray-build-<pid>-`.
pub fn build_dir_prefix() -> String {
    format!("{BUILD_DIR_PREFIX}{}-", std::process::id())
}

/// The writer's process id in a temporary name made by [`temp_path`] or [`build_dir_prefix`].
fn owner(name: &str) -> Option<u32> {
    if let Some(rest) = name.strip_prefix(BUILD_DIR_PREFIX) {
        return rest.split('-').next()?.parse().ok();
    }
    let (_, pid) = name.strip_prefix('.')?.rsplit_once(".tmp-")?;
    pid.parse().ok()
}

/// Whether a process of id `pid` is alive (on systems without `/proc`, always: nothing is
/// removed that might be in use).
fn alive(pid: u32) -> bool {
    if !Path::new("/proc/self").exists() {
        return true;
    }
    Path::new("/proc").join(pid.to_string()).exists()
}

/// Removes the temporary outputs in `dir` whose writing process is gone; returns how many.
/// Errors (a folder that cannot be listed, a file another user owns) are ignored: cleaning
/// is a courtesy, never a reason to fail the write at hand.
pub fn clean_stale(dir: &Path) -> usize {
    let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    let me = std::process::id();
    let mut removed = 0;
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name.to_str().and_then(owner) else { continue };
        if pid == me || alive(pid) {
            continue;
        }
        let path = e.path();
        let gone = match e.file_type() {
            Ok(t) if t.is_dir() => std::fs::remove_dir_all(&path).is_ok(),
            Ok(_) => std::fs::remove_file(&path).is_ok(),
            Err(_) => false,
        };
        removed += gone as usize;
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn owners_are_read_from_both_kinds_of_name() {
        assert_eq!(owner(".plant.mray.tmp-1234"), Some(1234));
        assert_eq!(owner(".a.tmp-b.png.tmp-77"), Some(77));
        assert_eq!(owner(".megaray-build-991-Xa3k"), Some(991));
        assert_eq!(owner("plant.mray"), None);
        assert_eq!(owner(".plant.mray.tmp-x"), None);
        assert_eq!(owner(".hidden"), None);
    }

    /// Temporaries of a dead process go, those of live ones (this one) and other files stay.
    #[test]
    fn only_the_temporaries_of_dead_processes_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        // A pid that is not running: the largest ids are never reached on a test machine.
        let dead = (4_194_000..4_194_304).find(|p| !alive(*p)).unwrap();
        std::fs::write(d.join(format!(".s.mray.tmp-{dead}")), b"partial").unwrap();
        std::fs::create_dir(d.join(format!("{BUILD_DIR_PREFIX}{dead}-abc"))).unwrap();
        std::fs::write(d.join(format!("{BUILD_DIR_PREFIX}{dead}-abc/stream")), b"x").unwrap();
        let mine = temp_path(&d.join("t.png")).unwrap();
        std::fs::write(&mine, b"in use").unwrap();
        std::fs::write(d.join("s.mray"), b"done").unwrap();
        assert_eq!(clean_stale(d), 2);
        let mut left: Vec<String> =
            std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        left.sort();
        assert_eq!(left, [format!(".t.png.tmp-{}", std::process::id()), "s.mray".to_string()]);
    }
}
