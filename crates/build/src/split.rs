//! The out-of-core split: recursive two-way partitioning of triangle stream files by a
//! binned SAH over triangle centroids, until every file fits the in-core part limit.

use std::sync::atomic::{AtomicU64, Ordering};

use megaray_base::{Aabb, Progress};

use crate::stream::{Bins, StreamFile, StreamReader, StreamTri, StreamWriter, BINS};
use crate::{check_cancel, BuildError, BuildOptions};

/// Bytes the split passes read and wrote.
#[derive(Default)]
pub struct IoCount {
    pub read: AtomicU64,
    pub written: AtomicU64,
}

/// Levels of splitting a stream of `n` triangles needs to get under `limit` (a guess for
/// progress reporting: one read+write per level, plus one binning read).
pub fn estimate_levels(n: u64, limit: u64) -> u32 {
    let mut levels = 0;
    let mut m = n;
    while m > limit {
        m = m.div_ceil(2);
        levels += 1;
    }
    levels + (levels > 0) as u32
}

const CHUNK: usize = 1 << 16;

/// How a stream is divided.
#[derive(Clone, Copy, Debug)]
enum Plane {
    /// Left: centroid bin (of `bins`, on `axis`) below `bin`.
    Bin { axis: usize, bin: usize },
    /// Left: centroid coordinate below `at` (the longest-axis midpoint).
    Mid { axis: usize, at: f32 },
    /// All centroids coincide: alternate.
    Alternate,
}

/// Splits `s` recursively; returns the streams that fit `limit`.
pub fn split(
    s: StreamFile,
    limit: u64,
    opts: &BuildOptions,
    io: &IoCount,
    progress: &dyn Progress,
) -> Result<Vec<StreamFile>, BuildError> {
    if s.count <= limit {
        return Ok(vec![s]);
    }
    check_cancel(opts)?;
    let bins = match &s.bins {
        Some(b) => b.clone(),
        None => bin_pass(&s, io, progress)?,
    };
    let plane = choose(&s, &bins);
    let (l, r) = route(&s, plane, &bins, io, progress)?;
    std::fs::remove_file(&s.path).map_err(|e| BuildError::io(&s.path, "remove", e))?;
    let (a, b) = rayon::join(|| split(l, limit, opts, io, progress), || split(r, limit, opts, io, progress));
    let mut a = a?;
    a.extend(b?);
    Ok(a)
}

fn bin_pass(s: &StreamFile, io: &IoCount, progress: &dyn Progress) -> Result<Bins, BuildError> {
    let mut bins = Bins::new(s.cbounds);
    let mut r = StreamReader::open(s)?;
    let mut buf = vec![StreamTri { v: [[0.0; 3]; 3], reserved: 0, id: 0 }; CHUNK];
    loop {
        let n = r.read(&mut buf)?;
        if n == 0 {
            break;
        }
        for t in &buf[..n] {
            bins.add(t.centroid(), &t.bounds());
        }
        io.read.fetch_add(n as u64 * 48, Ordering::Relaxed);
        progress.inc(n as u64 * 48);
    }
    Ok(bins)
}

fn choose(s: &StreamFile, bins: &Bins) -> Plane {
    let mut best = (f32::INFINITY, 0, 0);
    for axis in 0..3 {
        let mut right_area = [0f32; BINS];
        let mut right_cnt = [0u64; BINS];
        let (mut acc, mut n) = (Aabb::EMPTY, 0u64);
        for b in (1..BINS).rev() {
            acc.grow(&bins.bounds[axis][b]);
            n += bins.count[axis][b];
            right_area[b] = acc.half_area();
            right_cnt[b] = n;
        }
        let (mut acc, mut n) = (Aabb::EMPTY, 0u64);
        for b in 1..BINS {
            acc.grow(&bins.bounds[axis][b - 1]);
            n += bins.count[axis][b - 1];
            if n == 0 || right_cnt[b] == 0 {
                continue;
            }
            let cost = acc.half_area() * n as f32 + right_area[b] * right_cnt[b] as f32;
            if cost < best.0 {
                best = (cost, axis, b);
            }
        }
    }
    if best.0.is_finite() {
        return Plane::Bin { axis: best.1, bin: best.2 };
    }
    let axis = s.cbounds.longest_axis();
    if s.cbounds.extent()[axis] > 0.0 {
        Plane::Mid { axis, at: s.cbounds.center()[axis] }
    } else {
        Plane::Alternate
    }
}

fn route(
    s: &StreamFile,
    plane: Plane,
    bins: &Bins,
    io: &IoCount,
    progress: &dyn Progress,
) -> Result<(StreamFile, StreamFile), BuildError> {
    // Each child's bins cover the part of the parent's centroid box on its side.
    let (mut lr, mut rr) = (s.cbounds, s.cbounds);
    match plane {
        Plane::Bin { axis, bin } => {
            let at = bins.range.min[axis] + (bins.range.max[axis] - bins.range.min[axis]) * bin as f32 / BINS as f32;
            lr.max[axis] = lr.max[axis].min(at);
            rr.min[axis] = rr.min[axis].max(at);
        }
        Plane::Mid { axis, at } => {
            lr.max[axis] = at;
            rr.min[axis] = at;
        }
        Plane::Alternate => {}
    }
    let name = s.path.file_name().unwrap_or_default().to_string_lossy().into_owned();
    let dir = s.path.parent().expect("stream files live in a folder");
    let mut left = StreamWriter::create(&dir.join(format!("{name}0")), Some(lr), s.level + 1)?;
    let mut right = StreamWriter::create(&dir.join(format!("{name}1")), Some(rr), s.level + 1)?;
    let mut r = StreamReader::open(s)?;
    let mut buf = vec![StreamTri { v: [[0.0; 3]; 3], reserved: 0, id: 0 }; CHUNK];
    let mut k = 0u64;
    loop {
        let n = r.read(&mut buf)?;
        if n == 0 {
            break;
        }
        for t in &buf[..n] {
            let c = t.centroid();
            let go_left = match plane {
                Plane::Bin { axis, bin } => bins.bin_of(axis, c[axis]) < bin,
                Plane::Mid { axis, at } => c[axis] < at,
                Plane::Alternate => k.is_multiple_of(2),
            };
            k += 1;
            if go_left {
                left.push(t)?;
            } else {
                right.push(t)?;
            }
        }
        io.read.fetch_add(n as u64 * 48, Ordering::Relaxed);
        io.written.fetch_add(n as u64 * 48, Ordering::Relaxed);
        progress.inc(n as u64 * 48);
    }
    Ok((left.finish()?, right.finish()?))
}
