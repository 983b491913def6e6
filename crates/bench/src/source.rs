//! What to benchmark: the SCENE argument ([`Source`]) and the scene it opens ([`Loaded`]).

use std::path::{Path, PathBuf};
use std::time::Instant;

use megaray_base::{tri_is_degenerate, Progress, TriVerts};
use megaray_build::{build_scene, BuildOptions};
use megaray_gen::GenSpec;
use megaray_import::{import_file, ImportError, ImportOptions, Material, TriAttr, TriangleSink};
use megaray_scene::Scene;
use std::sync::Arc;

use crate::BenchError;

/// Model file extensions that are built into a temporary scene file.
const MESH_EXTS: [&str; 5] = ["ply", "obj", "stl", "gltf", "glb"];
/// Gen spec families (the part before the first `:`).
const GEN_KINDS: [&str; 3] = ["grid", "sphereflake", "plant"];
/// Build memory budget for the temporary scene: generous, so the standard scenes are one part.
const BUILD_MEM: u64 = 4 << 30;

/// The SCENE argument of `megaray bench`.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// A `.mray` scene file, opened as it is.
    Scene(PathBuf),
    /// A model file (PLY, OBJ, STL, glTF), built into a temporary scene file.
    Mesh(PathBuf),
    /// A gen spec (`grid:1000`): generated as PLY, then built like a model file. `text` is the
    /// spec as given (trimmed), which is the scene's name, as in the peer harness.
    Gen { spec: GenSpec, text: String },
}

impl Source {
    /// Reads a SCENE argument: an existing `.mray` or model file, or a gen spec.
    pub fn parse(s: &str) -> Result<Source, BenchError> {
        let path = Path::new(s);
        let head = s.trim().split(':').next().unwrap_or("").to_ascii_lowercase();
        if s.contains(':') && GEN_KINDS.contains(&head.as_str()) && !path.exists() {
            let spec: GenSpec = s.parse()?;
            return Ok(Source::Gen { spec, text: s.trim().to_string() });
        }
        if !path.exists() {
            return Err(BenchError::NoSuchScene(s.to_string()));
        }
        let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).unwrap_or_default();
        if !path.is_file() {
            return Err(BenchError::UnknownType(path.to_path_buf()));
        }
        if ext == "mray" {
            Ok(Source::Scene(path.to_path_buf()))
        } else if MESH_EXTS.contains(&ext.as_str()) {
            Ok(Source::Mesh(path.to_path_buf()))
        } else {
            Err(BenchError::UnknownType(path.to_path_buf()))
        }
    }

    /// The scene's name in the output lines: the gen spec as given, or the file's name.
    pub fn name(&self) -> String {
        match self {
            Source::Scene(p) | Source::Mesh(p) => {
                p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| p.display().to_string())
            }
            Source::Gen { text, .. } => text.clone(),
        }
    }
}

/// An open scene, with what is needed to get its triangles back into memory.
pub struct Loaded {
    /// The scene file, memory-mapped. (Declared before `tmp`, so it is closed first.)
    pub scene: Arc<Scene>,
    /// The default scene name (see [`Source::name`]).
    pub name: String,
    /// How the scene was obtained, for the user: `opened x.mray`, `built from x.obj in 0.4 s`.
    pub origin: String,
    /// The model file the scene was built from (`None` for a `.mray` source).
    mesh: Option<PathBuf>,
    /// The temporary folder holding generated and built files, removed on drop.
    tmp: Option<tempfile::TempDir>,
}

/// `scene` with every tile checked (and in 2 MiB pages where the kernel can,
/// [`Scene::reread_in_huge_pages`]), as the benchmark traces in core (its tracers then take
/// the kernel that skips tile bookkeeping, [`Scene::all_tiles_checked`]); a corrupt tile is
/// the scene's error.
fn in_core(scene: Scene) -> Result<Arc<Scene>, BenchError> {
    // In 2 MiB pages where the kernel can (the check reads the file back into them); advice
    // only: a kernel that cannot leaves the scene as it was.
    let _ = scene.reread_in_huge_pages();
    scene.verify_all()?;
    Ok(Arc::new(scene))
}

impl Loaded {
    /// Opens `src`: a `.mray` file directly; a model file or gen spec by building it (all
    /// threads, a generous memory budget) into a scene file in a temporary folder of the
    /// system's temporary directory.
    pub fn open(src: &Source, progress: &dyn Progress) -> Result<Loaded, BenchError> {
        let t0 = Instant::now();
        let (mesh, tmp) = match src {
            Source::Scene(p) => {
                let scene = in_core(Scene::open(p)?)?;
                let origin = format!("opened {}", p.display());
                return Ok(Loaded { scene, name: src.name(), origin, mesh: None, tmp: None });
            }
            Source::Mesh(p) => (p.clone(), temp_dir()?),
            Source::Gen { spec, .. } => {
                let tmp = temp_dir()?;
                let ply = tmp.path().join(format!("{}.ply", spec.name().replace(':', "_")));
                megaray_gen::write_ply(spec, &ply, progress)?;
                progress.finish();
                (ply, tmp)
            }
        };
        let out = tmp.path().join("bench.mray");
        let opts = BuildOptions { build_mem: BUILD_MEM, ..BuildOptions::default() };
        build_scene(std::slice::from_ref(&mesh), &out, &opts, progress)?;
        progress.finish();
        let scene = in_core(Scene::open(&out)?)?;
        let what = match src {
            Source::Gen { text, .. } => format!("generated {text} and built it"),
            _ => format!("built from {}", mesh.display()),
        };
        let origin = format!("{what} in {:.1} s", t0.elapsed().as_secs_f64());
        Ok(Loaded { scene, name: src.name(), origin, mesh: Some(mesh), tmp: Some(tmp) })
    }

    /// The scene's triangles in memory, for timing the in-core builder: for a model file or
    /// gen spec, the file's triangles in file order without the zero-area ones (exactly those
    /// the builder keeps); for a `.mray` file, the triangles of its tiles in file order.
    pub fn triangles(&self, progress: &dyn Progress) -> Result<Vec<TriVerts>, BenchError> {
        let expect = self.scene.header().tri_count;
        let tris = match &self.mesh {
            Some(mesh) => {
                let mut sink = Collect(Vec::with_capacity(expect as usize));
                let opts = ImportOptions {
                    temp_dir: self.tmp.as_ref().map(|t| t.path().to_path_buf()).unwrap_or_else(std::env::temp_dir),
                    ..ImportOptions::default()
                };
                import_file(mesh, &opts, &mut sink, progress)?;
                sink.0
            }
            None => {
                let mut tris = Vec::with_capacity(expect as usize);
                for t in 0..self.scene.header().tile_count {
                    let tile = self.scene.tile(t).ok_or_else(|| match self.scene.first_error() {
                        Some(e) => BenchError::Scene(e),
                        None => BenchError::Option(format!("{}: tile {t} unreadable", self.scene.path().display())),
                    })?;
                    tris.extend(tile.triangles().into_iter().map(|(_, t)| t));
                }
                tris
            }
        };
        if tris.len() as u64 != expect {
            return Err(BenchError::Option(format!(
                "{}: {} triangles read back, but the scene holds {expect}",
                self.name,
                tris.len()
            )));
        }
        Ok(tris)
    }
}

fn temp_dir() -> Result<tempfile::TempDir, BenchError> {
    tempfile::Builder::new()
        .prefix("megaray-bench-")
        .tempdir()
        .map_err(|err| BenchError::Io { what: "create a temporary folder".into(), err })
}

/// Collects triangle corners, dropping zero-area triangles as the builder does.
struct Collect(Vec<TriVerts>);

impl TriangleSink for Collect {
    fn triangle(&mut self, p: TriVerts, _attr: &TriAttr) -> Result<(), ImportError> {
        if !tri_is_degenerate(&p) {
            self.0.push(p);
        }
        Ok(())
    }

    fn material(&mut self, _m: Material) -> u32 {
        0
    }
}
