use std::io;
use std::path::{Path, PathBuf};

/// What went wrong while parsing a model spec, generating a model or writing it.
///
/// Every variant says which spec or file it is about, e.g.
/// `` `plant:abc`: not a triangle count `` or `out.ply: cannot write: No space left on device`.
#[derive(Debug, thiserror::Error)]
pub enum GenError {
    /// A model spec string (`grid:1000`, `plant:100M`, ...) that cannot be used.
    #[error("`{spec}`: {what}")]
    Spec {
        /// The spec as given.
        spec: String,
        /// What is wrong with it.
        what: String,
    },
    /// A file operation failed (the OS error is part of the message).
    #[error("{}: {what}: {err}", path.display())]
    Io {
        /// The file the operation was for (the output file, not its temporary file).
        path: PathBuf,
        /// What was being done: `cannot create`, `cannot write`, ...
        what: &'static str,
        /// The error the OS reported.
        err: io::Error,
    },
    /// A [`MeshSink`](crate::MeshSink) was fed something it cannot store (an index out of range,
    /// more vertices than its format can index, ...), or failed for a reason of its own.
    #[error("{target}: {what}")]
    Sink {
        /// The sink's output (a file name) or the sink's kind when it has no file.
        target: String,
        /// What is wrong.
        what: String,
    },
}

impl GenError {
    pub(crate) fn spec(spec: &str, what: impl Into<String>) -> GenError {
        GenError::Spec { spec: spec.to_string(), what: what.into() }
    }

    pub(crate) fn io(path: &Path, what: &'static str, err: io::Error) -> GenError {
        GenError::Io { path: path.to_path_buf(), what, err }
    }

    pub(crate) fn sink(target: impl Into<String>, what: impl Into<String>) -> GenError {
        GenError::Sink { target: target.into(), what: what.into() }
    }
}
