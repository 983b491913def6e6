//! The output lines: one JSON object per figure, keys in the peer harness's order and numbers
//! in its precision, or a row of a readable table.

use crate::Kind;

/// The figure of one tracing kind at one thread count.
#[derive(Clone, Debug, PartialEq)]
pub struct TraceLine {
    pub scene: String,
    pub tris: u64,
    pub kind: Kind,
    pub threads: usize,
    pub width: u32,
    pub height: u32,
    /// Rays in one pass.
    pub rays: u64,
    /// Million rays per second, median repetition.
    pub mrays_s: f64,
    /// Million rays per second, best repetition.
    pub mrays_s_best: f64,
    /// Milliseconds per pass, median repetition.
    pub ms_median: f64,
    pub cpu_util: f64,
    pub reps: u32,
    /// Passes per repetition.
    pub iters: u32,
    /// Rays that hit (`shadow_1`: rays occluded).
    pub hits: u64,
    /// Sum of hit distances (0 for `shadow_1`).
    pub sum_t: f64,
}

/// The figure of the in-core build at one thread count.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildLine {
    pub scene: String,
    pub tris: u64,
    /// [`Kind::Build`] or [`Kind::BuildHigh`].
    pub kind: Kind,
    pub threads: usize,
    /// Milliseconds, median build.
    pub build_ms: f64,
    /// Milliseconds, best build.
    pub build_ms_best: f64,
    /// Million triangles per second, median build.
    pub mtris_s: f64,
    /// Median over the builds of CPU seconds per wall second.
    pub cpu_util: f64,
    /// Builds timed (after one warm-up build).
    pub reps: u32,
}

/// One output line.
#[derive(Clone, Debug, PartialEq)]
pub enum Record {
    Trace(TraceLine),
    Build(BuildLine),
}

/// `x` with `prec` decimals, or `null` when it is not finite (JSON has no NaN).
fn num(x: f64, prec: usize) -> String {
    if x.is_finite() {
        format!("{x:.prec$}")
    } else {
        "null".into()
    }
}

fn string(s: &str) -> String {
    serde_json::Value::from(s).to_string()
}

impl Record {
    /// The JSON line (no newline), e.g.
    /// `{"peer":"megaray","scene":"grid:1000","tris":2000000,"kind":"primary_1","threads":1,...}`.
    pub fn json(&self) -> String {
        match self {
            Record::Trace(r) => format!(
                "{{\"peer\":\"megaray\",\"scene\":{},\"tris\":{},\"kind\":\"{}\",\"threads\":{},\"width\":{},\"height\":{},\
                 \"rays\":{},\"mrays_s\":{},\"mrays_s_best\":{},\"ms_median\":{},\"cpu_util\":{},\"reps\":{},\"iters\":{},\
                 \"hits\":{},\"sum_t\":{}}}",
                string(&r.scene),
                r.tris,
                r.kind.name(),
                r.threads,
                r.width,
                r.height,
                r.rays,
                num(r.mrays_s, 3),
                num(r.mrays_s_best, 3),
                num(r.ms_median, 3),
                num(r.cpu_util, 2),
                r.reps,
                r.iters,
                r.hits,
                num(r.sum_t, 6)
            ),
            Record::Build(r) => format!(
                "{{\"peer\":\"megaray\",\"scene\":{},\"tris\":{},\"kind\":\"{}\",\"threads\":{},\"build_ms\":{},\
                 \"build_ms_best\":{},\"mtris_s\":{},\"cpu_util\":{},\"reps\":{}}}",
                string(&r.scene),
                r.tris,
                r.kind.name(),
                r.threads,
                num(r.build_ms, 2),
                num(r.build_ms_best, 2),
                num(r.mtris_s, 3),
                num(r.cpu_util, 2),
                r.reps
            ),
        }
    }

    /// The header of the table that [`Record::table_row`] fills.
    pub fn table_header() -> String {
        format!(
            "{:<28} {:<10} {:>3} {:>14} {:>9} {:>9} {:>10} {:>4} {:>5} {:>9} {:>16}",
            "scene", "kind", "thr", "work", "M/s", "best M/s", "ms", "cpu", "iters", "hits", "sum_t"
        )
    }

    /// One row of the table: rays per second for tracing kinds, triangles per second for builds.
    pub fn table_row(&self) -> String {
        match self {
            Record::Trace(r) => format!(
                "{:<28} {:<10} {:>3} {:>14} {:>9.2} {:>9.2} {:>10.3} {:>4.2} {:>5} {:>9} {:>16.6}",
                r.scene,
                r.kind.name(),
                r.threads,
                format!("{} rays", r.rays),
                r.mrays_s,
                r.mrays_s_best,
                r.ms_median,
                r.cpu_util,
                r.iters,
                r.hits,
                r.sum_t
            ),
            Record::Build(r) => format!(
                "{:<28} {:<10} {:>3} {:>14} {:>9.2} {:>9.2} {:>10.2} {:>4.2} {:>5} {:>9} {:>16}",
                r.scene,
                r.kind.name(),
                r.threads,
                format!("{} tris", r.tris),
                r.mtris_s,
                r.tris as f64 / r.build_ms_best * 1e-3,
                r.build_ms,
                r.cpu_util,
                "-",
                "-",
                "-"
            ),
        }
    }
}
