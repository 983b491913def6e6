//! What `build` takes: model files and gen SPECs (`plant:1G`). Specs alone are streamed
//! straight into the build, no file written (a billion triangles would be a 20 GB PLY, past
//! what PLY's int indices address); specs among model files are generated first into
//! temporary PLYs beside the output. Before a build starts, its triangles are estimated
//! ([`estimate_tris`]) for the free-space check.

use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use megaray_base::Progress;
use megaray_build::{ObjectInput, ObjectSource, SceneInput};
use megaray_gen::{GenError, GenSpec, TriangleSink};
use megaray_import::{Format, ImportError, TriAttr, NO_MATERIAL};

/// A build's inputs, with the PLYs generated for them removed when this is dropped (after
/// the build, or on its error).
pub(crate) struct BuildInputs {
    /// Model files, the generated PLYs among them.
    pub files: Vec<PathBuf>,
    /// The specs to stream into the build, when every input is one.
    pub streamed: Vec<GenSpec>,
    temps: Vec<PathBuf>,
}

/// The spec `input` names, if it is no file but a gen spec.
fn spec_of(input: &Path) -> Result<Option<GenSpec>> {
    let is_model = Format::detect(input).is_ok();
    match input.to_str() {
        Some(text) if !input.exists() && !is_model && text.contains(':') => match text.parse::<GenSpec>() {
            Ok(spec) => Ok(Some(spec)),
            Err(e) => bail!("{text}: no such model file, nor a gen spec: {e}"),
        },
        _ => Ok(None),
    }
}

impl BuildInputs {
    /// Parses `inputs`; specs among files are generated into PLYs beside `out`.
    pub fn of(inputs: &[PathBuf], out: &Path, bars: &dyn Progress) -> Result<BuildInputs> {
        let specs: Vec<Option<GenSpec>> = inputs.iter().map(|i| spec_of(i)).collect::<Result<_>>()?;
        let mut b = BuildInputs { files: Vec::new(), streamed: Vec::new(), temps: Vec::new() };
        if specs.iter().all(Option::is_some) {
            b.streamed = specs.into_iter().flatten().collect();
            return Ok(b);
        }
        for (input, spec) in inputs.iter().zip(specs) {
            let Some(spec) = spec else {
                b.files.push(input.clone());
                continue;
            };
            let name = format!(
                ".{}.{}.gen.ply",
                out.file_name().unwrap_or_default().to_string_lossy(),
                spec.name().replace(':', "-")
            );
            let ply = out.with_file_name(name);
            b.temps.push(ply.clone());
            megaray_gen::write_ply(&spec, &ply, bars)
                .with_context(|| format!("{}: cannot generate it", spec.name()))?;
            b.files.push(ply);
        }
        Ok(b)
    }

    /// The streamed specs as the build's one object (the triangles a PLY of them gives, in
    /// the same order).
    pub fn streamed_scene<'a>(&self, bars: &'a dyn Progress) -> SceneInput<'a> {
        let specs = self.streamed.clone();
        let name = specs.iter().map(GenSpec::name).collect::<Vec<_>>().join(" + ");
        let source = ObjectSource::Fn(Box::new(move |sink| {
            let attr = TriAttr { material: NO_MATERIAL, ..TriAttr::default() };
            for spec in &specs {
                let at = Path::new(&spec.name()).to_path_buf();
                // The sink's own error (disk full, cancelled) is kept to outrank the
                // generator's view of it.
                let mut failed: Option<ImportError> = None;
                let mut tris = TriangleSink::new(|ts: &[[[f32; 3]; 3]]| {
                    for t in ts {
                        if let Err(e) = sink.triangle(*t, &attr) {
                            let what = e.to_string();
                            failed = Some(e);
                            return Err(GenError::Sink { target: spec.name(), what });
                        }
                    }
                    Ok(())
                });
                let res = megaray_gen::generate(spec, &mut tris, bars);
                drop(tris);
                if let Err(e) = res {
                    return Err(failed.unwrap_or_else(|| ImportError::new(&at, None, e.to_string())));
                }
            }
            Ok(())
        }));
        let mut scene = SceneInput::plain(source);
        scene.objects = vec![ObjectInput { name, ..scene.objects.pop().expect("one object") }];
        scene
    }

    /// About how many triangles the inputs hold (for the free-space check).
    pub fn estimate_tris(&self) -> u64 {
        // A plant's exact count takes a run of its layout (a minute at 10^11): its nominal
        // count is within a fraction of a percent.
        let tris = |s: &GenSpec| match *s {
            GenSpec::Plant { tris, .. } => tris,
            _ => s.counts().1,
        };
        let specs: u64 = self.streamed.iter().map(tris).sum();
        specs + self.files.iter().map(|f| estimate_tris(f)).sum::<u64>()
    }
}

impl Drop for BuildInputs {
    fn drop(&mut self) {
        for t in &self.temps {
            let _ = std::fs::remove_file(t);
        }
    }
}

/// About how many triangles model file `path` holds, erring low: a PLY's face count from
/// its header, a binary STL's from its own count, else from the file's size at a generous
/// number of bytes per triangle (so that the free-space check refuses only what cannot fit).
pub(crate) fn estimate_tris(path: &Path) -> u64 {
    let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let mut head = Vec::new();
    let _ = std::fs::File::open(path).and_then(|f| f.take(64 << 10).read_to_end(&mut head));
    match Format::detect(path) {
        Ok(Format::Ply) => {
            let text = String::from_utf8_lossy(&head);
            let faces = text
                .lines()
                .take_while(|l| l.trim() != "end_header")
                .find_map(|l| l.strip_prefix("element face ").and_then(|n| n.trim().parse::<u64>().ok()));
            // Quads and polygons make more triangles than faces: faces is a floor.
            faces.unwrap_or(size / 64).min(size / 13)
        }
        Ok(Format::Stl) if head.len() >= 84 && !head.starts_with(b"solid") => {
            (u32::from_le_bytes([head[80], head[81], head[82], head[83]]) as u64).min(size / 50)
        }
        _ => size / 64,
    }
}
