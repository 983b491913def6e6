//! Inputs the fuzzers (fuzz/) found crashing a reader, kept as they were found: each must now
//! load (finite corners only) or give one line of error naming the file, never a panic; glTF
//! files flattened and with their structure kept, pbrt scenes as scenes. `data/fuzz/<target>/`.

mod common;

use megaray_base::NoProgress;
use megaray_import::{ImportError, ImportOptions};
use std::path::Path;

/// A glTF file read with its structure kept, or a pbrt scene, and every object's triangles;
/// `None` for other formats.
fn structured(path: &Path) -> Option<Result<Vec<common::Tri>, ImportError>> {
    let scene = match path.extension().and_then(|e| e.to_str()) {
        Some("gltf" | "glb") => megaray_import::gltf_scene::read_scene(path),
        Some("pbrt") => megaray_import::pbrt::read_scene(path),
        _ => return None,
    };
    Some(scene.and_then(|s| {
        let mut c = common::Collect::default();
        for o in &s.objects {
            megaray_import::pbrt::feed_object(o, &ImportOptions::default(), &mut c, &NoProgress)?;
        }
        Ok(c.tris)
    }))
}

#[test]
fn every_input_the_fuzzers_found_loads_or_is_one_line_of_error() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut seen = 0;
    let (mut ok, mut errors) = (0, 0);
    for target in std::fs::read_dir(&root).unwrap() {
        for f in std::fs::read_dir(target.unwrap().path()).unwrap() {
            let path = f.unwrap().path();
            seen += 1;
            let flat = match path.extension().and_then(|e| e.to_str()) {
                Some("pbrt") => None,
                _ => Some(common::collect(&path).map(|(c, _)| c.tris)),
            };
            for r in flat.into_iter().chain(structured(&path)) {
                match r {
                    Ok(tris) => {
                        assert!(tris.iter().all(|t| t.0.iter().flatten().all(|c| c.is_finite())), "{}", path.display());
                        ok += 1;
                    }
                    Err(e) => {
                        let msg = e.to_string();
                        assert_eq!(msg.lines().count(), 1, "{}: {msg}", path.display());
                        assert!(msg.contains(&*path.to_string_lossy()), "the error does not name the file: {msg}");
                        errors += 1;
                    }
                }
            }
        }
    }
    assert!(seen >= 64, "only {seen} inputs");
    eprintln!("{seen} inputs: {ok} load, {errors} are errors");
}
