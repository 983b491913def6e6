use std::path::PathBuf;

/// Why a benchmark could not run. Every variant names the scene, file or option at fault.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// The SCENE argument is neither an existing file nor a gen spec.
    #[error("{0}: no such file, and not a gen spec (grid:N, sphereflake:L[:S], plant:T)")]
    NoSuchScene(String),
    /// The SCENE argument is a file of a type megaray cannot read.
    #[error("{}: unknown scene type (expected .mray, .ply, .obj, .stl, .gltf, .glb or a gen spec)", .0.display())]
    UnknownType(PathBuf),
    /// A gen spec that does not parse, or generating its model failed.
    #[error(transparent)]
    Gen(#[from] megaray_gen::GenError),
    /// Reading a model file failed.
    #[error(transparent)]
    Import(#[from] megaray_import::ImportError),
    /// Opening or reading a scene file failed (also: a corrupt tile met while tracing).
    #[error(transparent)]
    Scene(#[from] megaray_scene::SceneError),
    /// Building the temporary scene file failed.
    #[error(transparent)]
    Build(#[from] megaray_build::BuildError),
    /// An option value that cannot be used (`--kinds`, `--threads`, `--reps`, ...).
    #[error("{0}")]
    Option(String),
    /// A file system operation failed.
    #[error("cannot {what}: {err}")]
    Io { what: String, err: std::io::Error },
    /// A thread pool could not be started.
    #[error("cannot start {threads} threads: {msg}")]
    Threads { threads: usize, msg: String },
}
