//! `plant:T`: a CAD-like stand-in for an industrial plant of about `T` triangles.
//!
//! **Site.** The triangle budget `T` is split between a few site-wide pipe racks (only for
//! `T ≥ 200k`; they run across the whole site) and `≈ T^(1/3) / 6` process units. Unit budgets
//! are drawn from a heavy-tailed distribution (the largest ~100× the smallest), unit footprints
//! grow with the cube root of their budget, and units are placed at random, without overlap, on
//! a square site that grows with them: dense units, sparse tank farms, empty ground between.
//!
//! **Units.** Three styles: *process structures* (a steel frame of I-beam columns and girders on
//! several floors with X bracing, grating floors, switchback stairs, vessels, drums, columns with
//! platforms and ladders, exchangers, pumps, bundles of pipes under every floor, routed pipes
//! between equipment nozzles, valves, cable trays with sagging cables), *tank farms* (big tanks,
//! bund walls, low pipes) and *equipment areas* (pumps and exchangers along a pipe rack). Every
//! unit draws its own tessellation quality (coarse to very fine CAD export), so triangle
//! density varies by an order of magnitude between units and by several between object kinds.
//!
//! **Meeting T.** Site racks have a natural size (counted first). The rest is split into unit
//! budgets that add up exactly; a unit builds its bounded parts (frame, floors, stairs) within a
//! share of its budget, then adds equipment, pipes and cables (unbounded: more and more
//! objects) until their shares are spent, and closes the gap with small parts (valves, short
//! pipes, pipe supports) until fewer than 12 triangles are left. The plant therefore has
//! `T − 12·units ≤ count ≤ T` triangles. [`counts`] runs the same layout with counting only.

mod geo;
mod layout;
mod objects;
mod rng;
mod unit;

use crate::sink::Emitter;
use crate::GenError;
use geo::Geo;

/// The exact `(vertices, triangles)` of `plant:tris` with `seed`.
pub(crate) fn counts(tris: u64, seed: u64) -> (u64, u64) {
    let (mut v, mut t) = (0u64, 0u64);
    layout::run(tris, seed, &mut |_, nv, nt| {
        v += nv as u64;
        t += nt as u64;
        Ok(())
    })
    .expect("counting cannot fail");
    (v, t)
}

/// Generates `plant:tris` with `seed`, one object per chunk.
pub(crate) fn generate(tris: u64, seed: u64, out: &mut Emitter<'_>) -> Result<(), GenError> {
    let mut g = Geo::new(false);
    layout::run(tris, seed, &mut |obj, nv, nt| {
        g.clear();
        obj.build(&mut g);
        debug_assert_eq!((g.nv, g.nt), (nv, nt), "{obj:?}");
        debug_assert_eq!((g.verts.len(), g.tris.len()), (nv as usize, nt as usize), "{obj:?}");
        let base = out.next_vertex();
        if base + nv as u64 > 1 << 32 {
            return Err(out.too_many());
        }
        let base = base as u32;
        for t in &mut g.tris {
            t[0] += base;
            t[1] += base;
            t[2] += base;
        }
        out.chunk(&g.verts, &g.tris)
    })
}
