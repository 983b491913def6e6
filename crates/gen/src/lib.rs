//! # megaray-gen: procedural models and a streaming PLY writer
//!
//! Three families of models, named by spec strings ([`GenSpec`], parsed with [`str::parse`]):
//! - `grid:N`, a wavy height field, and `sphereflake:L[:S]`, Haines' sphere flake: exactly the
//!   meshes of the Embree peer harness (`shared/peers/embree`), same vertices bit for bit, same
//!   order and winding, so that ray checksums can be compared with the peer's;
//! - `plant:T[:SEED]`: a CAD-like industrial plant of about `T` triangles (steel frames, pipes
//!   with elbows and flanges, vessels, towers, tanks, gratings, stairs, valves, cables) for
//!   out-of-core tests at any size, deterministic for a given `T` and seed.
//!
//! [`generate`] streams a model into a [`MeshSink`] one object (chunk) at a time, in memory
//! bounded by the largest object, whatever the model's size. [`PlyWriter`] is a sink that
//! writes a binary PLY file through temporary files and renames it into place when complete;
//! [`write_ply`] does both. [`CountingSink`] and [`TriangleSink`] are small sinks for counting
//! and for consumers of triangle corners.
//!
//! ```
//! use megaray_gen::{generate, CountingSink, GenSpec};
//! let spec: GenSpec = "sphereflake:1".parse().unwrap();
//! let mut sink = CountingSink::default();
//! generate(&spec, &mut sink, &megaray_base::NoProgress).unwrap();
//! assert_eq!((sink.verts, sink.tris), spec.counts());
//! assert_eq!(sink.chunks, 10); // one chunk per sphere
//!
//! // A plant, written as PLY:
//! let dir = tempfile::tempdir().unwrap();
//! let out = dir.path().join("plant.ply");
//! let spec: GenSpec = "plant:20k".parse().unwrap();
//! let (verts, tris) = megaray_gen::write_ply(&spec, &out, &megaray_base::NoProgress).unwrap();
//! assert_eq!((verts, tris), spec.counts());
//! assert!(tris.abs_diff(20_000) <= 400);
//! ```

#![warn(missing_docs)]

mod error;
pub mod forest;
mod peer;
mod plant;
mod ply;
mod sink;
mod spec;

pub use error::GenError;
pub use ply::{write_ply, PlyWriter};
pub use sink::{CountingSink, MeshSink, TriangleSink};
pub use spec::GenSpec;

use megaray_base::Progress;
use sink::Emitter;

/// Generates `spec` into `sink`, chunk by chunk (see [`MeshSink`] for what a chunk is and how
/// its indices work), reporting triangles as progress units in a stage named `generate SPEC`.
///
/// Emits exactly [`GenSpec::counts`] vertices and triangles. Fails before emitting anything if
/// the model has more than 2³² vertices (too many for 32-bit indices), and with the sink's
/// error if the sink fails.
pub fn generate(spec: &GenSpec, sink: &mut dyn MeshSink, progress: &dyn Progress) -> Result<(), GenError> {
    generate_counted(spec, spec.counts(), sink, progress)
}

/// [`generate`] when `spec.counts()` is already known (a plant's takes a layout pass).
pub(crate) fn generate_counted(
    spec: &GenSpec,
    (verts, tris): (u64, u64),
    sink: &mut dyn MeshSink,
    progress: &dyn Progress,
) -> Result<(), GenError> {
    let name = spec.name();
    let mut out = Emitter::new(sink, progress, name.clone());
    if verts > 1 << 32 {
        return Err(out.too_many());
    }
    progress.stage(&format!("generate {name}"), tris);
    match *spec {
        GenSpec::Grid { n } => peer::grid(n, &mut out)?,
        GenSpec::Sphereflake { levels, bands } => peer::sphereflake(levels, bands, &mut out)?,
        GenSpec::Plant { tris, seed } => plant::generate(tris, seed, &mut out)?,
    }
    let made = out.done();
    debug_assert_eq!(made, (verts, tris), "{name}: counts() disagrees with the generator");
    progress.finish();
    Ok(())
}
