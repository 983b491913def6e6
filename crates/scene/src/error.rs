use std::path::{Path, PathBuf};

/// What kind of fault a [`SceneError`] reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneErrorKind {
    /// The operating system refused (open, read, write, map).
    Io,
    /// The file does not start with the megaray magic number.
    NotAScene,
    /// A version this code does not read.
    Version,
    /// The file is shorter (or longer) than its header says.
    Truncated,
    /// A table or field holds an impossible value.
    Corrupt,
    /// A tile failed its checksum or holds references out of range.
    CorruptTile(u32),
    /// A scene beyond what the format can address (writing).
    TooLarge,
}

/// A scene file fault: which file, what kind, and a one-line description.
#[derive(Clone, Debug, thiserror::Error)]
#[error("{}: {msg}", path.display())]
pub struct SceneError {
    pub path: PathBuf,
    pub kind: SceneErrorKind,
    pub msg: String,
}

impl SceneError {
    pub fn new(path: &Path, kind: SceneErrorKind, msg: impl Into<String>) -> SceneError {
        SceneError { path: path.to_path_buf(), kind, msg: msg.into() }
    }
    pub fn io(path: &Path, what: &str, e: &std::io::Error) -> SceneError {
        SceneError::new(path, SceneErrorKind::Io, format!("cannot {what}: {e}"))
    }
    pub fn corrupt(path: &Path, msg: impl Into<String>) -> SceneError {
        SceneError::new(path, SceneErrorKind::Corrupt, msg)
    }
}
