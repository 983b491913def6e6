//! The budget steers the level of detail ([`LodGovernor`]): when a frame's working set at the
//! error asked for does not fit the pager's budget, the error allowed rises until it does, so
//! that frames stop re-reading the disk; when there is room again it falls back toward the
//! error asked for.
//!
//! The working set is what the frame's rays looked up ([`Pager::begin_working_set`]), not
//! what the pager loaded or evicted: the same rays ask for the same tiles however many
//! threads or processes trace them and whatever was resident, so the errors chosen, and the
//! images, are the same (a cluster's ranks add their lookups to the root's pager,
//! `megaray-cluster`).
//!
//! [`Pager::begin_working_set`]: megaray_page::Pager::begin_working_set

use megaray_trace::Tracer;

/// How far the error may rise above the one asked for.
const MAX_RISE: f32 = 256.0;
/// The factor of one step up or down.
const STEP: f32 = 1.5;
/// The share of the budget under which a working set lets the error fall a step: below
/// what a step finer would need (about `STEP` squared as many tiles, for surfaces seen
/// face on), so that the error does not swing back and forth between two steps.
const ROOM: f64 = 0.4;

/// Per-frame control of a paged tracer's level-of-detail error. Call
/// [`LodGovernor::after_frame`] after each frame.
#[derive(Clone, Debug)]
pub struct LodGovernor {
    requested: f32,
    effective: f32,
}

impl LodGovernor {
    /// A governor for `tracer`, whose error asked for is its current one. Starts the first
    /// frame's working set.
    pub fn new(tracer: &Tracer) -> LodGovernor {
        if let Some(p) = tracer.pager() {
            p.begin_working_set();
        }
        let e = tracer.lod_error();
        LodGovernor { requested: e, effective: e }
    }

    /// The error in force (footprints).
    pub fn effective(&self) -> f32 {
        self.effective
    }

    /// After a frame: raises the error when the frame's working set exceeded the budget for
    /// tiles, lowers it toward the error asked for when it took less than [`ROOM`] of it.
    /// Sets it on `tracer`, starts the next frame's working set, and returns the error.
    /// No-op without a pager or levels of detail.
    pub fn after_frame(&mut self, tracer: &Tracer) -> f32 {
        let Some(p) = tracer.pager() else { return self.effective };
        let working = p.working_set_bytes();
        p.begin_working_set();
        if self.requested <= 0.0 || tracer.scene().header().lod_part_count == 0 {
            return self.effective;
        }
        let budget = p.stats().tile_budget;
        if working > budget {
            self.effective = (self.effective * STEP).min(self.requested * MAX_RISE);
        } else if (working as f64) < ROOM * budget as f64 {
            self.effective = (self.effective / STEP).max(self.requested);
        }
        tracer.set_lod_error(self.effective);
        self.effective
    }
}
