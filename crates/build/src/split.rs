//! The out-of-core split: stream files are divided, by the SAH over triangle centroids,
//! until every file fits the in-core part limit, reading and writing each triangle as few
//! times as possible.
//!
//! Each pass *plans* a multi-level split on the stream's sample (a reservoir sample of its
//! triangle boxes, gathered while the stream was written): binned SAH splits, largest
//! estimated piece first, until every piece is estimated to fit or the plan has `fanout`
//! pieces. Then one pass routes every triangle down the planned tree by its centroid into
//! one of up to `fanout` child files, each gathering its own sample. Children still too large
//! (sampling error, or more pieces needed than `fanout`) are split again the same way, in
//! parallel. With the default fanout of 256 a model of up to about 200 parts costs one
//! read and one write of the stream.
//!
//! When the SAH finds no split (all sampled centroids equal), the longest-axis midpoint is
//! used; when even that separates nothing, triangles are dealt alternately.

use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use megaray_base::{Aabb, Progress};

use crate::behind::WriteBehind;
use crate::stream::{disk_usage, Ids, StreamFile, StreamReader, StreamTri, StreamWriter, RELEASE_STEP};
use crate::{check_cancel, BuildError, BuildOptions};

/// What the split passes did.
#[derive(Default)]
pub struct IoCount {
    pub read: AtomicU64,
    pub written: AtomicU64,
    /// Routing passes over stream files.
    pub passes: AtomicU32,
    /// The most disk the temporary files took at any look (after each release of a parent's
    /// blocks, [`StreamReader::release`]).
    pub peak: AtomicU64,
}

/// Boxes sampled from the input stream.
pub const ROOT_SAMPLE: usize = 1 << 18;
/// Boxes sampled from each child stream.
pub const CHILD_SAMPLE: usize = 1 << 12;
/// Write buffer of each child stream during routing.
const CHILD_BUF: usize = 128 << 10;
/// Child buffers queued for the writing thread at most (8 MiB).
const WRITE_DEPTH: usize = 64;
/// Records read at a time.
const CHUNK: usize = 1 << 15;
/// Plan pieces to this fraction of the limit, leaving room for sampling error.
const FILL: f64 = 0.8;
/// SAH bins per axis for planning.
const BINS: usize = 32;

/// A node of a split plan.
#[derive(Clone, Copy, Debug)]
enum Plan {
    /// Doubled centroid coordinate on `axis` below `at`: `kids[0]`, else `kids[1]`.
    Split { axis: usize, at: f32, kids: [u32; 2] },
    /// Triangles alternate between the two kids (all centroids coincide).
    Alternate { kids: [u32; 2] },
    /// Output file number.
    Leaf(u32),
}

/// Splits `s` recursively; returns the streams that fit `limit`, in depth-first order,
/// and the deepest level of the split hierarchy.
pub fn split(
    s: StreamFile,
    limit: u64,
    ids: Ids,
    opts: &BuildOptions,
    io: &IoCount,
    progress: &dyn Progress,
) -> Result<Vec<StreamFile>, BuildError> {
    if s.count <= limit {
        return Ok(vec![s]);
    }
    check_cancel(opts)?;
    let (plan, leaves, depth) = make_plan(&s, limit, opts.split_fanout.max(2));
    let children = route(&s, &plan, leaves, depth, ids, opts, io, progress)?;
    std::fs::remove_file(&s.path).map_err(|e| BuildError::io(&s.path, "remove", e))?;
    use rayon::prelude::*;
    let parts: Vec<Vec<StreamFile>> = children
        .into_par_iter()
        .with_max_len(1)
        .map(|c| split(c, limit, ids, opts, io, progress))
        .collect::<Result<_, _>>()?;
    Ok(parts.into_iter().flatten().collect())
}

/// Plans the split of `s` into at most `fanout` pieces; returns the plan (node 0 is the
/// root), the number of leaves, and the plan's depth.
fn make_plan(s: &StreamFile, limit: u64, fanout: usize) -> (Vec<Plan>, u32, u32) {
    let target = ((limit as f64 * FILL) as u64).max(1);
    let sample = &s.sample.boxes;
    let scale = s.count as f64 / sample.len().max(1) as f64;
    // Pieces: (plan node, sample boxes in it, estimated triangles, depth).
    let mut nodes = vec![Plan::Leaf(0)];
    let mut pieces: Vec<(u32, Vec<Aabb>, u64, u32)> = vec![(0, sample.clone(), s.count, 0)];
    let mut done: Vec<(u32, u32)> = Vec::new(); // (node, depth) of pieces that will not split
    while pieces.len() + done.len() < fanout {
        // The largest piece still over the target.
        let Some(i) = (0..pieces.len()).filter(|&i| pieces[i].2 > target).max_by_key(|&i| pieces[i].2) else {
            break;
        };
        let (node, boxes, est, depth) = pieces.swap_remove(i);
        let first = nodes.len() as u32;
        let kids = [first, first + 1];
        nodes.push(Plan::Leaf(0));
        nodes.push(Plan::Leaf(0));
        let (split, l, r) = match choose(&boxes) {
            Some((axis, at)) => {
                let (l, r): (Vec<Aabb>, Vec<Aabb>) = boxes.iter().partition(|b| b.min[axis] + b.max[axis] < at);
                (Plan::Split { axis, at, kids }, l, r)
            }
            None => {
                let (l, r) = (boxes[..boxes.len() / 2].to_vec(), boxes[boxes.len() / 2..].to_vec());
                (Plan::Alternate { kids }, l, r)
            }
        };
        let lest = if matches!(split, Plan::Alternate { .. }) {
            est / 2
        } else {
            ((l.len() as f64 * scale).round() as u64).min(est)
        };
        nodes[node as usize] = split;
        let small_sample = l.len() < 2 || r.len() < 2;
        for (k, b, e) in [(kids[0], l, lest), (kids[1], r, est - lest)] {
            if small_sample && matches!(split, Plan::Split { .. }) {
                // Too few samples to plan further: let the next pass (with its own sample) do it.
                done.push((k, depth + 1));
            } else {
                pieces.push((k, b, e, depth + 1));
            }
        }
    }
    done.extend(pieces.iter().map(|p| (p.0, p.3)));
    // Number leaves in depth-first order, so that output files sort spatially.
    let mut leaf = 0u32;
    let mut stack = vec![0u32];
    while let Some(n) = stack.pop() {
        match nodes[n as usize] {
            Plan::Split { kids, .. } | Plan::Alternate { kids } => {
                stack.push(kids[1]);
                stack.push(kids[0]);
            }
            Plan::Leaf(_) => {
                nodes[n as usize] = Plan::Leaf(leaf);
                leaf += 1;
            }
        }
    }
    let depth = done.iter().map(|d| d.1).max().unwrap_or(0);
    (nodes, leaf, depth)
}

/// The binned-SAH split of sampled boxes, as (axis, doubled-centroid threshold); the
/// longest-axis midpoint when the SAH finds none; `None` when all centroids coincide.
fn choose(boxes: &[Aabb]) -> Option<(usize, f32)> {
    let mut cb = Aabb::EMPTY;
    for b in boxes {
        cb.grow_point([b.min[0] + b.max[0], b.min[1] + b.max[1], b.min[2] + b.max[2]]);
    }
    let mut best = (f32::INFINITY, 0usize, 0f32);
    for axis in 0..3 {
        let (lo, ext) = (cb.min[axis], cb.max[axis] - cb.min[axis]);
        if ext.is_nan() || ext <= 0.0 {
            continue;
        }
        let mut cnt = [0u64; BINS];
        let mut bb = [Aabb::EMPTY; BINS];
        for b in boxes {
            let i = (((b.min[axis] + b.max[axis] - lo) / ext * BINS as f32) as usize).min(BINS - 1);
            cnt[i] += 1;
            bb[i].grow(b);
        }
        let mut right = [(0f32, 0u64); BINS];
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for i in (1..BINS).rev() {
            acc.grow(&bb[i]);
            n += cnt[i];
            right[i] = (acc.half_area(), n);
        }
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for i in 1..BINS {
            acc.grow(&bb[i - 1]);
            n += cnt[i - 1];
            if n == 0 || right[i].1 == 0 {
                continue;
            }
            let cost = acc.half_area() * n as f32 + right[i].0 * right[i].1 as f32;
            if cost < best.0 {
                best = (cost, axis, lo + ext * i as f32 / BINS as f32);
            }
        }
    }
    if best.0.is_finite() {
        return Some((best.1, best.2));
    }
    let axis = cb.longest_axis();
    let ext = cb.max[axis] - cb.min[axis];
    (ext > 0.0).then(|| (axis, cb.min[axis] + ext * 0.5))
}

/// One pass: every triangle of `s` down the plan into its leaf's file (records keeping
/// their ids as `ids` says).
#[allow(clippy::too_many_arguments)]
fn route(
    s: &StreamFile,
    plan: &[Plan],
    leaves: u32,
    depth: u32,
    ids: Ids,
    opts: &BuildOptions,
    io: &IoCount,
    progress: &dyn Progress,
) -> Result<Vec<StreamFile>, BuildError> {
    let name = s.path.file_name().unwrap_or_default().to_string_lossy().into_owned();
    let dir = s.path.parent().expect("stream files live in a folder");
    // The children are written by a thread of their own while this one reads and routes.
    let wb = std::sync::Arc::new(WriteBehind::new(WRITE_DEPTH));
    let mut outs = (0..leaves)
        .map(|i| {
            let path = dir.join(format!("{name}_{i:03}"));
            StreamWriter::create(&path, CHILD_SAMPLE, CHILD_BUF, s.level + depth, ids, &wb)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut r = StreamReader::open_consuming(s)?;
    let mut buf = vec![StreamTri { v: [[0.0; 3]; 3], reserved: 0, id: 0 }; CHUNK];
    let (mut k, mut since) = (0u64, 0u64);
    loop {
        check_cancel(opts)?;
        let n = r.read(&mut buf)?;
        if n == 0 {
            break;
        }
        for t in &buf[..n] {
            let b = t.bounds();
            let mut node = 0usize;
            let leaf = loop {
                match plan[node] {
                    Plan::Leaf(i) => break i,
                    Plan::Split { axis, at, kids } => {
                        node = kids[(b.min[axis] + b.max[axis] >= at) as usize] as usize;
                    }
                    Plan::Alternate { kids } => {
                        node = kids[(k & 1) as usize] as usize;
                    }
                }
            };
            k += 1;
            outs[leaf as usize].push(t)?;
        }
        let (read, written) = (n as u64 * s.ids.record_bytes(), n as u64 * ids.record_bytes());
        io.read.fetch_add(read, Ordering::Relaxed);
        io.written.fetch_add(written, Ordering::Relaxed);
        progress.inc(read);
        since += read;
        if since >= RELEASE_STEP {
            since = 0;
            r.release();
            io.peak.fetch_max(disk_usage(dir), Ordering::Relaxed);
        }
    }
    io.passes.fetch_add(1, Ordering::Relaxed);
    let mut files = Vec::with_capacity(outs.len());
    let outs: Vec<StreamFile> = outs.into_iter().map(|w| w.finish()).collect::<Result<_, _>>()?;
    // The children whole, beside what is left of the parent.
    io.peak.fetch_max(disk_usage(dir), Ordering::Relaxed);
    for f in outs {
        if f.count == 0 {
            std::fs::remove_file(&f.path).map_err(|e| BuildError::io(&f.path, "remove", e))?;
        } else {
            files.push(f);
        }
    }
    Ok(files)
}
