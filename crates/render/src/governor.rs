//! The budget steers the level of detail ([`LodGovernor`]): when a frame's working set at the
//! error asked for does not fit the pager's budget, the error allowed rises until it does, so
//! that frames stop re-reading the disk; when there is room again it falls back toward the
//! error asked for.
//!
//! The working set is what the frame's rays looked up ([`Pager::begin_working_set`]), not
//! what the pager loaded or evicted: rays traced to the end ask for the same tiles however
//! many threads or processes trace them and whatever was resident, so the errors chosen, and
//! the images, are the same (a cluster's ranks add their lookups to the root's pager,
//! `megaray-cluster`). Frames with stand-ins or a deadline look up what they tried.
//!
//! [`Pager::begin_working_set`]: megaray_page::Pager::begin_working_set

use std::sync::atomic::{AtomicU64, Ordering};

use megaray_trace::Tracer;

/// The governors' ids ([`megaray_page::Pager::steer`]).
static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// How far the error may rise above the one asked for.
const MAX_RISE: f32 = 256.0;
/// The factor of one step up or down.
const STEP: f32 = 1.5;
/// The share of the budget under which a working set lets the error fall a step: below
/// what a step finer would need (about `STEP` squared as many tiles, for surfaces seen
/// face on), so that the error does not swing back and forth between two steps.
const ROOM: f64 = 0.4;

/// Per-frame control of a paged tracer's level-of-detail error. Call
/// [`LodGovernor::after_frame`] after each frame. Of several governors over one pager (the
/// pages of `serve`), one steers and the others follow the error it sets.
#[derive(Debug)]
pub struct LodGovernor {
    requested: f32,
    effective: f32,
    id: u64,
    /// Whether it steered after the last frame (its working set began then).
    steering: bool,
}

impl LodGovernor {
    /// A governor for `tracer`, whose error asked for is its current one: the one that steers
    /// its pager from now on. Starts the first frame's working set.
    pub fn new(tracer: &Tracer) -> LodGovernor {
        let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        let steering = tracer.pager().is_some();
        if let Some(p) = tracer.pager() {
            p.take_steering(id);
            p.begin_working_set();
        }
        let e = tracer.lod_error();
        LodGovernor { requested: e, effective: e, id, steering }
    }

    /// The error in force (footprints).
    pub fn effective(&self) -> f32 {
        self.effective
    }

    /// After a frame: raises the error when the frame's working set exceeded the budget for
    /// tiles, lowers it toward the error asked for when it took less than [`ROOM`] of it.
    /// Sets it on `tracer`, starts the next frame's working set, and returns the error.
    /// No-op without a pager or levels of detail; while another governor steers the pager,
    /// takes the tracer's error as it is.
    pub fn after_frame(&mut self, tracer: &Tracer) -> f32 {
        let Some(p) = tracer.pager() else { return self.effective };
        let was = std::mem::replace(&mut self.steering, p.steer(self.id));
        if !self.steering {
            // Another governor steers this pager: follow it.
            self.effective = tracer.lod_error();
            return self.effective;
        }
        let working = p.working_set_bytes();
        p.begin_working_set();
        if !was {
            // Taken over from a governor gone quiet: its working set began long ago.
            return self.effective;
        }
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
