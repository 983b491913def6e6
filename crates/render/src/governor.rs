//! The budget steers the level of detail ([`LodGovernor`]): when a frame's working set at the
//! error asked for does not fit the pager's budget (the frame evicts what it loads), the
//! error allowed rises until it does, so that frames stop re-reading the disk; when there is
//! room again it falls back toward the error asked for.

use megaray_trace::Tracer;

/// How far the error may rise above the one asked for.
const MAX_RISE: f32 = 256.0;
/// The factor of one step up or down.
const STEP: f32 = 1.5;

/// Per-frame control of a paged tracer's level-of-detail error. Call
/// [`LodGovernor::after_frame`] after each frame.
#[derive(Clone, Debug)]
pub struct LodGovernor {
    requested: f32,
    effective: f32,
    loaded: u64,
    evicted: u64,
}

impl LodGovernor {
    /// A governor for `tracer`, whose error asked for is its current one.
    pub fn new(tracer: &Tracer) -> LodGovernor {
        let s = tracer.pager().map(|p| p.stats()).unwrap_or_default();
        let e = tracer.lod_error();
        LodGovernor { requested: e, effective: e, loaded: s.bytes_loaded, evicted: s.evicted }
    }

    /// The error in force (footprints).
    pub fn effective(&self) -> f32 {
        self.effective
    }

    /// After a frame: raises the error when the frame evicted tiles while loading more than a
    /// quarter of the budget (its working set does not fit), lowers it toward the error asked
    /// for when the frame evicted nothing and the resident tiles fill less than 60% of the
    /// budget. Sets it on `tracer` and returns it. No-op without a pager or levels of detail.
    pub fn after_frame(&mut self, tracer: &Tracer) -> f32 {
        let Some(p) = tracer.pager() else { return self.effective };
        if self.requested <= 0.0 || tracer.scene().header().lod_part_count == 0 {
            return self.effective;
        }
        let s = p.stats();
        let (loaded, evicted) = (s.bytes_loaded - self.loaded, s.evicted - self.evicted);
        (self.loaded, self.evicted) = (s.bytes_loaded, s.evicted);
        if evicted > 0 && loaded > s.tile_budget / 4 {
            self.effective = (self.effective * STEP).min(self.requested * MAX_RISE);
        } else if evicted == 0 && (s.resident as f64) < 0.6 * s.tile_budget as f64 {
            self.effective = (self.effective / STEP).max(self.requested);
        }
        tracer.set_lod_error(self.effective);
        self.effective
    }
}
