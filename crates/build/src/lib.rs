//! # megaray-build: the out-of-core streaming builder
//!
//! Turns model files of any size into one `.mray` scene file in bounded memory, following
//! the streaming approach of Dietrich and Slusallek's massive-model tutorial (EG 2006), with
//! BVHs instead of k-d trees:
//!
//! 1. **Import** ([`sink`]): every input streams into one positions-only triangle stream file
//!    ([`stream::StreamTri`], 48 bytes a triangle) plus attribute streams keyed by triangle id
//!    ([`attrs`]); bounds are gathered on the way, zero-area triangles dropped and counted.
//! 2. **Split** ([`split`]): while a stream holds more triangles than one part may, plan a
//!    multi-level split on a sample of its triangles (binned SAH over centroids, longest-axis
//!    midpoint when the SAH finds nothing) and route each triangle by its centroid into one of
//!    up to 256 child files in one pass; children still too large are split again.
//! 3. **Parts** ([`bvh`], [`tiles`]): each stream small enough is loaded and built in core
//!    (binned SAH, collapsed to an 8-wide BVH), cut into page-aligned tiles and appended to the
//!    scene file with its attributes. Parts build in parallel, as many at once as threads, each
//!    sized so that all of them fit `build_mem` together, and are appended in order (the same
//!    file whatever the threads' timing). The builder's largest arrays pass
//!    from one part to the next ([`recycle_part`]) rather than being faulted in afresh, and
//!    are freed when the build ends ([`release_spare`]).
//! 4. **Top level**: a BVH over the parts' boxes, written first in the file.
//!
//! Temporary files live in a folder next to the output and are removed on success, on error
//! and on cancellation (see [`BuildOptions::cancel`]).
//!
//! ```no_run
//! use megaray_build::{build_scene, BuildOptions};
//! let opts = BuildOptions { build_mem: 1 << 30, ..BuildOptions::default() };
//! let summary = build_scene(&["model.ply".into()], "model.mray".as_ref(), &opts, &megaray_base::NoProgress).unwrap();
//! println!("{} triangles in {} parts", summary.triangles, summary.parts);
//! ```

pub mod attrs;
pub mod behind;
pub mod bvh;
pub mod lod;
pub mod objects;
pub mod sink;
pub mod space;
pub mod split;
pub mod stream;
pub mod tiles;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use megaray_base::{Aabb, Progress};
use megaray_scene::format::{Node8, PackedNormals, NODE_WIDTH};
use megaray_scene::{BlobRef, PartBlob, SceneWriter};

pub use crate::bvh::Quality;
use crate::bvh::{build_bvh, build_bvh_of, BvhConfig, Kid};
pub use crate::objects::{pbrt_input, InstancePlan, ObjectInput, ObjectSource, SceneInput};
pub use crate::space::check_space;
use crate::stream::{StreamFile, StreamReader};

/// The most triangles a leaf holds: two blocks of four, when the SAH finds that cheaper than
/// a split (a traversal step and the blocks of both sides, weighted by area). Such leaves
/// make fewer, fuller nodes, so smaller files and less memory per ray; the single-ray kernel
/// tests their two blocks in one 8-wide pass, so they cost little more than one
/// (docs/PERF.md, "Leaf size").
pub const MAX_LEAF: usize = 8;

/// Estimated peak bytes per triangle of an in-core part build (stream records, boxes, the
/// binary and 8-wide trees, the tiles and attribute arrays being assembled).
pub const INCORE_BYTES_PER_TRI: u64 = 256;
/// Memory set aside from `build_mem` for I/O buffers and bookkeeping.
pub const FIXED_RESERVE: u64 = 64 << 20;

/// Settings of a build.
#[derive(Clone, Debug)]
pub struct BuildOptions {
    /// Memory budget in bytes. Peak memory stays within it plus a small fixed overhead.
    pub build_mem: u64,
    /// Worker threads (parts built at once, split passes at once).
    pub threads: usize,
    /// Target tile size in bytes (tiles are the unit of paging).
    pub tile_target: u32,
    /// Largest part, in triangles; `None`: derived from `build_mem` and `threads`.
    pub max_part_tris: Option<u64>,
    /// Most child files one split pass writes (see [`split`]); 2 gives classic binary splits.
    pub split_fanout: usize,
    /// Memory the readers may use for vertex tables (part of `build_mem`).
    pub import_mem: Option<u64>,
    /// How hard each part's builder looks for good splits (the top-level tree over the parts
    /// is always built at [`Quality::High`]: it is small).
    pub quality: Quality,
    /// Levels of detail made for each part ([`lod`]); `None`: none (the scene then holds
    /// exactly the full-detail parts).
    pub lod: Option<lod::LodOptions>,
    /// Where temporary files go (a folder is made in it); `None`: the output's folder.
    pub tmp_dir: Option<PathBuf>,
    /// Write a compact scene file (tiles stored in the compact codec, about half the bytes;
    /// decoded as they load: `megaray_scene::compact`). `false`: tiles stored as traced.
    pub compact: bool,
    /// Set it from another thread (a Ctrl-C handler) to stop the build; it then returns
    /// [`BuildError::Cancelled`] and removes its temporary files.
    pub cancel: Arc<AtomicBool>,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            build_mem: 2 << 30,
            threads: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
            tile_target: 256 << 10,
            max_part_tris: None,
            split_fanout: 256,
            import_mem: None,
            quality: Quality::High,
            lod: Some(lod::LodOptions::default()),
            tmp_dir: None,
            compact: true,
            cancel: Arc::new(AtomicBool::new(false)),
        }
    }
}

impl BuildOptions {
    /// The largest part (in triangles) these options allow.
    pub fn part_limit(&self) -> u64 {
        self.max_part_tris.unwrap_or_else(|| {
            let usable = self.build_mem.saturating_sub(FIXED_RESERVE);
            (usable / (self.threads.max(1) as u64 * INCORE_BYTES_PER_TRI)).max(1024)
        })
    }
}

/// What a build did.
#[derive(Clone, Debug, Default)]
pub struct BuildSummary {
    pub inputs: usize,
    pub triangles: u64,
    pub degenerate_dropped: u64,
    pub parts: u32,
    /// Objects built (1 for a scene without instances), instances placed (0 without), and
    /// the triangles the scene shows, every instance counted.
    pub objects: u32,
    pub instances: u64,
    pub instanced_triangles: u128,
    /// Levels of detail made (parts of their own in the file), and their bytes as stored.
    pub lod_parts: u32,
    pub lod_bytes: u64,
    pub tiles: u32,
    /// Deepest level of the split hierarchy (0: the whole model was one part).
    pub split_levels: u32,
    /// Passes over stream files that the splits took (each reads and writes its stream once).
    pub split_passes: u32,
    pub part_limit: u64,
    pub file_bytes: u64,
    /// Bytes read from inputs.
    pub input_bytes: u64,
    /// Bytes read and written in temporary streams.
    pub temp_read: u64,
    pub temp_written: u64,
    /// The most disk the temporary files took (measured as the split passes went).
    pub temp_peak: u64,
    pub import_s: f64,
    pub split_s: f64,
    pub parts_s: f64,
    pub total_s: f64,
}

/// A build failure, naming the file where it happened.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    #[error(transparent)]
    Import(#[from] megaray_import::ImportError),
    #[error(transparent)]
    Scene(#[from] megaray_scene::SceneError),
    #[error("{}: cannot {what}: {err}", path.display())]
    Io { path: PathBuf, what: &'static str, err: std::io::Error },
    #[error("{}: no triangles to build (all inputs empty or degenerate)", .0.display())]
    NoTriangles(PathBuf),
    #[error("{0}")]
    Invalid(String),
    #[error("interrupted; temporary files removed")]
    Cancelled,
    #[error("{}: not enough free space for {what} of about {tris} triangles: needs about {}, has {} (`--tmp DIR` puts the temporary files elsewhere)", dir.display(), megaray_base::format_size(*need), megaray_base::format_size(*free))]
    NoSpace { dir: PathBuf, what: &'static str, tris: u64, need: u64, free: u64 },
}

impl BuildError {
    pub fn io(path: &Path, what: &'static str, err: std::io::Error) -> BuildError {
        BuildError::Io { path: path.to_path_buf(), what, err }
    }
}

pub(crate) fn check_cancel(opts: &BuildOptions) -> Result<(), BuildError> {
    if opts.cancel.load(Ordering::Relaxed) {
        Err(BuildError::Cancelled)
    } else {
        Ok(())
    }
}

/// Builds `inputs` (model files, merged into one scene) into the scene file `out`.
pub fn build_scene(
    inputs: &[PathBuf],
    out: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
) -> Result<BuildSummary, BuildError> {
    if inputs.is_empty() {
        return Err(BuildError::Invalid("no input files".into()));
    }
    let scene = SceneInput::plain(ObjectSource::Files(inputs.to_vec()));
    build_objects(scene, out, opts, progress)
}

/// Builds a scene of objects (and, if given, the groups and instances that place them) into
/// the scene file `out`: each object's triangles are streamed, split and built into parts
/// as [`build_scene`] does for its inputs, and given a tree of its own over its parts.
pub fn build_objects(
    mut scene: SceneInput<'_>,
    out: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
) -> Result<BuildSummary, BuildError> {
    if opts.build_mem < 2 * FIXED_RESERVE && opts.max_part_tris.is_none() {
        return Err(BuildError::Invalid(format!(
            "--build-mem {} is too small: at least {} is needed",
            megaray_base::format_size(opts.build_mem),
            megaray_base::format_size(2 * FIXED_RESERVE)
        )));
    }
    let t0 = Instant::now();
    let tmp_dir = space::temp_dir_for(out, opts);
    // Build folders of killed builds here are removed (megaray_base::temp).
    megaray_base::temp::clean_stale(&tmp_dir);
    let tmp = tempfile::Builder::new()
        .prefix(&megaray_base::temp::build_dir_prefix())
        .tempdir_in(&tmp_dir)
        .map_err(|e| BuildError::io(&tmp_dir, "create a temporary folder in", e))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads.max(1))
        // The in-core builder recurses once per tree level; unbalanced inputs make deep trees.
        .stack_size(256 << 20)
        .build()
        .map_err(|e| BuildError::Invalid(format!("cannot start threads: {e}")))?;

    // 1. Import, one positions stream per object.
    let mut sink = sink::BuildSink::new(tmp.path(), opts)?;
    for m in std::mem::take(&mut scene.materials) {
        megaray_import::TriangleSink::material(&mut sink, m);
    }
    let mut names: Vec<String> = scene.objects.iter().map(|o| o.name.clone()).collect();
    let mut input_bytes = 0;
    let mut inputs = 0;
    let mut roots = Vec::with_capacity(scene.objects.len());
    let first_input = scene.objects.iter().find_map(|o| match &o.source {
        ObjectSource::Files(f) => f.first().cloned(),
        ObjectSource::Fn(_) | ObjectSource::Pbrt(_) => None,
    });
    for obj in std::mem::take(&mut scene.objects) {
        match obj.source {
            ObjectSource::Files(files) => {
                for input in &files {
                    input_bytes += import_one(input, &mut sink, &tmp, opts, progress)?;
                    inputs += 1;
                }
            }
            ObjectSource::Fn(feed) => {
                sink.set_input(Path::new(&obj.name));
                if let Err(e) = feed(&mut sink) {
                    return Err(sink.take_error().unwrap_or(e.into()));
                }
            }
            ObjectSource::Pbrt(desc) => {
                sink.set_input(Path::new(&obj.name));
                let iopts = megaray_import::ImportOptions {
                    mem_limit: opts.import_mem.unwrap_or(opts.build_mem / 4),
                    temp_dir: tmp.path().to_path_buf(),
                };
                match megaray_import::pbrt::feed_object(&desc, &iopts, &mut sink, progress) {
                    Ok(b) => input_bytes += b,
                    Err(e) => return Err(sink.take_error().unwrap_or(e.into())),
                }
                inputs += 1;
            }
        }
        roots.push(sink.end_object()?);
        check_cancel(opts)?;
    }
    // Split streams keep their triangles' ids only when attributes or components need them.
    let has_attributes = sink.has_attributes();
    let (mut attrs, materials, dropped, components) = sink.finish()?;
    let keep_ids = has_attributes || components.several();
    let child_ids = if keep_ids { stream::Ids::Stored } else { stream::Ids::Absent };
    let triangles: u64 = roots.iter().map(|r| r.count).sum();
    let import_bytes: u64 = roots.iter().map(StreamFile::bytes).sum();
    if triangles == 0 {
        return Err(BuildError::NoTriangles(first_input.unwrap_or_else(|| out.to_path_buf())));
    }
    let import_s = t0.elapsed().as_secs_f64();
    attrs.finish_writing()?;
    let import_peak = stream::disk_usage(tmp.path());

    // 2. Split each object's stream into parts (objects left empty are dropped).
    let t1 = Instant::now();
    let limit = opts.part_limit();
    let io = split::IoCount::default();
    let to_split: u64 = roots.iter().filter(|r| r.count > limit).map(StreamFile::bytes).sum();
    progress.stage("split", to_split);
    let mut parts = Vec::new();
    let mut objects = Vec::new();
    let mut kept = Vec::with_capacity(roots.len());
    for (k, root) in roots.into_iter().enumerate() {
        if root.count == 0 {
            let _ = std::fs::remove_file(&root.path);
            kept.push(None);
            continue;
        }
        kept.push(Some(objects.len() as u32));
        let (tri_count, bounds) = (root.count, root.bounds);
        let mut ps = pool.install(|| split::split(root, limit, child_ids, opts, &io, progress))?;
        // Parts in a spatially coherent order (the order the splits produced them).
        ps.sort_by_key(|p| p.path.clone());
        // Its tree (`root`, `node_count`) is placed below.
        let (first_part, part_count) = (parts.len() as u32, ps.len() as u32);
        let name = std::mem::take(&mut names[k]);
        objects.push(megaray_scene::Object { name, bounds, first_part, part_count, root: 0, node_count: 0, tri_count });
        parts.extend(ps);
    }
    progress.finish();
    let split_s = t1.elapsed().as_secs_f64();
    let split_levels = parts.iter().map(|p| p.level).max().unwrap_or(0);

    // 3. Each object's tree over its parts' boxes (one array, objects in order), then the parts.
    let t2 = Instant::now();
    let mut top_nodes = Vec::new();
    let mut top_depth = 0;
    for o in &mut objects {
        let (first, end) = (o.first_part as usize, (o.first_part + o.part_count) as usize);
        let boxes: Vec<Aabb> = parts[first..end].iter().map(|p| p.bounds).collect();
        let (nodes, depth) = top_level(&boxes);
        (o.root, o.node_count) = (top_nodes.len() as u32, nodes.len() as u32);
        top_nodes.extend(objects::placed(nodes, o.root, o.first_part));
        top_depth = top_depth.max(depth);
    }
    let object_count = objects.len() as u32;
    let plain_bounds = objects.iter().fold(Aabb::EMPTY, |b, o| b.union(&o.bounds));
    let instancing = match scene.instancing.take() {
        None => None,
        Some(plan) => Some(objects::instancing(plan, objects, &kept)?),
    };
    let bounds = match &instancing {
        Some(i) => i.group_bounds()[0],
        None => plain_bounds,
    };
    let lod_capacity = opts.lod.map_or(0, |l| l.max_levels as u32) * parts.len() as u32;
    let mut writer =
        SceneWriter::create(out, top_nodes, top_depth, parts.len() as u32, lod_capacity, opts.tile_target)?;
    writer.set_compact(opts.compact);
    if let Some(i) = instancing.clone() {
        writer.set_instancing(i);
    }
    if !scene.settings.is_empty() {
        writer.set_settings(std::mem::take(&mut scene.settings));
    }
    // One component is the whole scene: no table (a gen spec then builds the same file as
    // its PLY).
    if components.several() {
        writer.set_components(components.names.clone(), components.tri_counts.clone());
    }
    let lod_count = std::sync::atomic::AtomicU32::new(0);
    let writer = Mutex::new(writer);
    progress.stage("build parts", triangles);
    let single = parts.len() == 1;
    let (attrs, components) = (&attrs, &components);
    // Parts are taken in order by whichever thread is free and written in order, so the file
    // is the same bytes whatever the threads' timing. A part built ahead of its turn is left
    // for the thread whose turn comes first to write (one such part at a time: docs/PERF.md,
    // "Parts in turn"), and its thread builds the next; with one already left, it waits,
    // running the pending tasks of the parts still building (a part's tree and its levels
    // of detail are rayon tasks when there are several threads).
    let next = AtomicUsize::new(0);
    let turn = InOrder::default();
    let parallel = single || opts.threads > 1;
    let write = |i: usize, (blob, lods): Built| -> Result<(), BuildError> {
        let n = blob.tri_count;
        {
            let mut w = writer.lock().unwrap_or_else(|e| e.into_inner());
            w.append_part(i as u32, &blob)?;
            for (k, (error, lod)) in lods.into_iter().enumerate() {
                w.append_lod(i as u32, k as u32 + 1, error, &lod)?;
                lod_count.fetch_add(1, Ordering::Relaxed);
                recycle_part(lod);
            }
        }
        recycle_part(blob);
        let _ = std::fs::remove_file(&parts[i].path);
        progress.inc(n);
        Ok(())
    };
    let built: Vec<Result<(), BuildError>> = pool.broadcast(|_| loop {
        let i = next.fetch_add(1, Ordering::Relaxed);
        if i >= parts.len() || turn.failed() {
            return Ok(());
        }
        match check_cancel(opts).and_then(|_| build_part(&parts[i], attrs, components, opts, parallel, &io)) {
            Ok(b) => turn.hand_over(i, b, &write)?,
            Err(e) => return Err(turn.fail(e)),
        }
    });
    // The arrays kept from part to part are not kept past the build.
    release_spare();
    built.into_iter().collect::<Result<Vec<()>, BuildError>>()?;
    progress.finish();
    let writer = writer.into_inner().unwrap_or_else(|e| e.into_inner());
    let tiles = writer.tile_count();
    let file_bytes = writer.finish(bounds, dropped, &materials)?;
    // The levels' bytes as stored (their tables only are read back).
    let lod_bytes = megaray_scene::Scene::open_owned(out).map_or(0, |s| s.stored_bytes().lod);
    let parts_s = t2.elapsed().as_secs_f64();
    drop(tmp);
    Ok(BuildSummary {
        inputs,
        triangles,
        degenerate_dropped: dropped,
        parts: parts.len() as u32,
        objects: object_count,
        instances: instancing.as_ref().map_or(0, |i| i.instances.len() as u64),
        instanced_triangles: instancing.as_ref().map_or(triangles as u128, |i| i.instanced_triangles()),
        lod_parts: lod_count.load(Ordering::Relaxed),
        lod_bytes,
        tiles,
        split_levels,
        split_passes: io.passes.load(Ordering::Relaxed),
        part_limit: limit,
        file_bytes,
        input_bytes,
        temp_read: io.read.load(Ordering::Relaxed),
        temp_written: io.written.load(Ordering::Relaxed) + import_bytes,
        temp_peak: io.peak.load(Ordering::Relaxed).max(import_peak),
        import_s,
        split_s,
        parts_s,
        total_s: t0.elapsed().as_secs_f64(),
    })
}

/// A part built: its tree and its levels of detail (error, level).
type Built = (PartBlob, Vec<(f32, PartBlob)>);

/// Whose turn it is to write, for threads that build parts out of order and write them in
/// order; one part built ahead of its turn may be left here for another thread to write. A
/// failure ends every wait.
#[derive(Default)]
struct InOrder {
    state: Mutex<Turns>,
}

#[derive(Default)]
struct Turns {
    /// The next part to write.
    next: usize,
    failed: bool,
    /// A part built ahead of its turn, left to be written.
    ready: Option<(usize, Built)>,
}

impl InOrder {
    /// Part `i` is built: written now by `write` if its turn has come (and then the part left
    /// ready for the turn after, if any); else left ready when no other part is, and the call
    /// returns at once; else the call waits for the turn, running the pool's pending tasks
    /// meanwhile. Nothing is written once any part failed.
    fn hand_over(
        &self,
        i: usize,
        built: Built,
        write: &impl Fn(usize, Built) -> Result<(), BuildError>,
    ) -> Result<(), BuildError> {
        let mine = (i, built);
        loop {
            let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
            if st.failed {
                return Ok(());
            }
            if st.next == mine.0 {
                drop(st);
                return self.write_from(mine, write);
            }
            if st.ready.is_none() {
                st.ready = Some(mine);
                return Ok(());
            }
            drop(st);
            if rayon::yield_now() != Some(rayon::Yield::Executed) {
                std::thread::sleep(std::time::Duration::from_micros(100));
            }
        }
    }

    /// Writes `first` (whose turn it is), then each part left ready for the turn after.
    fn write_from(
        &self,
        first: (usize, Built),
        write: &impl Fn(usize, Built) -> Result<(), BuildError>,
    ) -> Result<(), BuildError> {
        let mut cur = first;
        loop {
            let i = cur.0;
            write(i, cur.1).map_err(|e| self.fail(e))?;
            let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
            st.next = i + 1;
            match st.ready.take_if(|r| r.0 == i + 1) {
                Some(r) => cur = r,
                None => return Ok(()),
            }
        }
    }

    /// Records a failure and gives `e` back.
    fn fail(&self, e: BuildError) -> BuildError {
        self.state.lock().unwrap_or_else(|e| e.into_inner()).failed = true;
        e
    }

    fn failed(&self) -> bool {
        self.state.lock().unwrap_or_else(|e| e.into_inner()).failed
    }
}

/// Imports one model file into the build's sink; returns the bytes read.
fn import_one(
    input: &Path,
    sink: &mut sink::BuildSink<'_>,
    tmp: &tempfile::TempDir,
    opts: &BuildOptions,
    progress: &dyn Progress,
) -> Result<u64, BuildError> {
    let iopts = megaray_import::ImportOptions {
        mem_limit: opts.import_mem.unwrap_or(opts.build_mem / 4),
        temp_dir: tmp.path().to_path_buf(),
    };
    sink.set_input(input);
    let dropped_before = sink.dropped();
    let s = match megaray_import::import_file(input, &iopts, sink, progress) {
        Ok(s) => s,
        // A failure of our own (disk full, cancelled) outranks the reader's view of it.
        Err(e) => return Err(sink.take_error().unwrap_or(e.into())),
    };
    let dropped = sink.dropped() - dropped_before;
    if dropped > 0 {
        progress.note(&format!("{}: skipped {dropped} degenerate (zero-area) triangles", input.display()));
    }
    Ok(s.bytes)
}

/// The top-level tree over part boxes, in file layout; returns nodes and depth.
pub fn top_level(boxes: &[Aabb]) -> (Vec<Node8>, u32) {
    let bvh = build_bvh(boxes, BvhConfig { max_leaf: 1, parallel_above: usize::MAX, quality: Quality::High });
    let nodes = bvh
        .nodes
        .iter()
        .map(|n| {
            let mut out = Node8::EMPTY;
            for k in 0..NODE_WIDTH {
                let r = match n.kids[k] {
                    Kid::Empty => continue,
                    Kid::Inner(c) => BlobRef::inner(c),
                    Kid::Leaf { start, count } => {
                        debug_assert_eq!(count, 1);
                        BlobRef::part(bvh.order[start as usize])
                    }
                };
                out.set(k, &n.bounds[k], r.0);
            }
            out
        })
        .collect();
    let depth = bvh.depth;
    bvh::recycle(bvh);
    (nodes, depth)
}

/// Gives the tile arrays of a part that is written (or no longer needed) to the next
/// part's build, which would otherwise fault in fresh memory for them.
pub fn recycle_part(blob: PartBlob) {
    tiles::recycle(blob.tiles);
}

/// Frees the arrays kept for later builds ([`recycle_part`]; [`build_scene`] does this when
/// it ends). Builds after it start from fresh memory again.
pub fn release_spare() {
    bvh::release_spare();
    tiles::release_spare();
    SPARE_TRIS.clear();
}

/// A part's triangles as loaded from its stream ([`build_part`]), kept from part to part.
static SPARE_TRIS: bvh::spare::Spare<[[f32; 3]; 3]> = bvh::spare::Spare::new(8);

/// Loads one part's stream, builds its tree, cuts it into tiles and gathers its attributes;
/// then its levels of detail ([`lod`]), each with its error and its own tree and tiles
/// (their slots carry the materials and colours of the triangles they stand for).
fn build_part(
    s: &StreamFile,
    attrs: &attrs::AttrStreams,
    components: &sink::ComponentIds,
    opts: &BuildOptions,
    parallel: bool,
    io: &split::IoCount,
) -> Result<Built, BuildError> {
    // The corners into an array kept from the part before (fresh memory costs a page fault
    // per 4 KiB); ids only when the stream has them (attributes or components need them).
    let mut tris = SPARE_TRIS.take();
    let mut ids = Vec::new();
    StreamReader::open(s)?.read_all(&mut tris, &mut ids)?;
    io.read.fetch_add(s.bytes(), Ordering::Relaxed);
    let id_of = |i: u32| ids.get(i as usize).copied().unwrap_or(0);
    // With components, each leaf's triangles by component (fewer runs of slots).
    let keys: Option<Vec<u32>> = components.several().then(|| ids.iter().map(|&id| components.of(id)).collect());
    // The levels of detail (serial work) beside the tree (rayon tasks), so that a thread
    // waiting for its turn to write can take them over.
    let ((mut blob, tri_source), levels) = rayon::join(
        || build_in_core_keyed(&tris, keys.as_deref(), opts.tile_target, parallel, opts.quality),
        || opts.lod.map(|l| lod::levels(&tris, &l)).unwrap_or_default(),
    );
    SPARE_TRIS.give(tris);
    let slot_ids = per_slot(&tri_source, id_of);
    blob.normals = attrs.gather::<PackedNormals>(attrs::NORMAL, &slot_ids)?;
    blob.uvs = attrs.gather::<[[f32; 2]; 3]>(attrs::UV, &slot_ids)?;
    blob.colors = attrs.gather::<[[u8; 4]; 3]>(attrs::COLOR, &slot_ids)?;
    blob.materials = attrs.gather::<u32>(attrs::MATERIAL, &slot_ids)?;
    blob.components = component_runs(&tri_source, &slot_ids, components);
    let mut lods = Vec::with_capacity(levels.len());
    for level in levels {
        let (mut lb, src) = build_in_core(&level.tris, opts.tile_target, parallel, opts.quality);
        let slot_ids = per_slot(&src, |i| id_of(level.source[i as usize]));
        lb.colors = attrs.gather::<[[u8; 4]; 3]>(attrs::COLOR, &slot_ids)?;
        lb.materials = attrs.gather::<u32>(attrs::MATERIAL, &slot_ids)?;
        lb.components = component_runs(&src, &slot_ids, components);
        lods.push((level.error, lb));
    }
    Ok((blob, lods))
}

/// The attribute id of each triangle slot, from the slots' triangles (`source`, as
/// [`build_in_core`] returns it); padding lanes repeat the id of the block's first triangle.
fn per_slot(source: &[u32], id_of: impl Fn(u32) -> u64) -> Vec<u64> {
    let mut last = 0;
    source
        .iter()
        .map(|&i| {
            if i != tiles::PADDING {
                last = id_of(i);
            }
            last
        })
        .collect()
}

/// A part's component runs from its slots' ids (padding slots, [`tiles::PADDING`], join
/// the run before them).
fn component_runs(source: &[u32], slot_ids: &[u64], components: &sink::ComponentIds) -> Vec<(u32, u32)> {
    if !components.several() {
        return Vec::new();
    }
    let slots = source.iter().zip(slot_ids).map(|(&i, &id)| (i != tiles::PADDING).then(|| components.of(id)));
    megaray_scene::components::runs_of(slots)
}

/// Builds one part in core from triangles in memory: its 8-wide BVH, cut into tiles of
/// about `tile_target` bytes (no attributes). Also returns, for each triangle slot in file
/// order (4 per block), the index in `tris` of its triangle or [`tiles::PADDING`]. This is
/// the in-core builder that `megaray bench` times.
pub fn build_in_core(
    tris: &[[[f32; 3]; 3]],
    tile_target: u32,
    parallel: bool,
    quality: Quality,
) -> (PartBlob, Vec<u32>) {
    build_in_core_keyed(tris, None, tile_target, parallel, quality)
}

/// [`build_in_core`], each leaf's triangles in the order of their `keys` (their components:
/// a leaf that holds several then makes fewer runs of slots; the order within a leaf is free).
pub fn build_in_core_keyed(
    tris: &[[[f32; 3]; 3]],
    keys: Option<&[u32]>,
    tile_target: u32,
    parallel: bool,
    quality: Quality,
) -> (PartBlob, Vec<u32>) {
    let cfg = BvhConfig { max_leaf: MAX_LEAF, parallel_above: if parallel { 4096 } else { usize::MAX }, quality };
    let mut bvh = build_bvh_of(tris.len(), |i| Aabb::from_points(&tris[i]), cfg);
    if let Some(keys) = keys {
        for n in &bvh.nodes {
            for kid in &n.kids {
                if let bvh::Kid::Leaf { start, count } = *kid {
                    bvh.order[start as usize..(start + count) as usize].sort_by_key(|&i| keys[i as usize]);
                }
            }
        }
    }
    let tiled = tiles::tile_part(&bvh, tris, tile_target as u64);
    let blob = PartBlob {
        bounds: bvh.bounds,
        tri_count: tris.len() as u64,
        depth: bvh.depth,
        root_tile: tiled.root_tile,
        root_node: tiled.root_node,
        tiles: tiled.tiles,
        ..PartBlob::default()
    };
    bvh::recycle(bvh);
    (blob, tiled.tri_source)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parts handed over out of order by several threads (a part left ready, threads
    /// waiting for their turn) are written once each, in order; after a failed write nothing
    /// more is written and every hand-over returns.
    #[test]
    fn parts_are_written_in_order_whatever_order_they_are_built_in() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
        for round in 0..20u32 {
            let n = 40;
            let fail_at = (round % 4 == 3).then_some(17);
            let turn = InOrder::default();
            let written = Mutex::new(Vec::new());
            let write = |i: usize, _: Built| {
                written.lock().unwrap().push(i);
                match fail_at {
                    Some(f) if i == f => Err(BuildError::Invalid("a failed write".into())),
                    _ => Ok(()),
                }
            };
            let next = AtomicUsize::new(0);
            let results: Vec<Result<(), BuildError>> = pool.broadcast(|_| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n || turn.failed() {
                    return Ok(());
                }
                // Parts take uneven times, so later ones are often built first.
                let us = megaray_base::hash32(i as u32 ^ round.wrapping_mul(0x9e37_79b9)) % 400;
                std::thread::sleep(std::time::Duration::from_micros(us as u64));
                turn.hand_over(i, (PartBlob::default(), Vec::new()), &write)?;
            });
            let written = written.into_inner().unwrap();
            match fail_at {
                None => {
                    assert_eq!(written, (0..n).collect::<Vec<_>>(), "round {round}");
                    assert!(results.iter().all(Result::is_ok));
                }
                Some(f) => {
                    assert_eq!(written, (0..=f).collect::<Vec<_>>(), "round {round}");
                    assert_eq!(results.iter().filter(|r| r.is_err()).count(), 1, "round {round}");
                }
            }
        }
    }

    /// A build into arrays kept from an earlier one ([`recycle_part`], [`bvh::recycle`])
    /// makes exactly the tiles and slots of a build into fresh ones, for a smaller model
    /// after a larger one and the other way round.
    #[test]
    fn recycled_arrays_give_the_same_parts() {
        let model = |n: usize| -> Vec<[[f32; 3]; 3]> {
            (0..n)
                .map(|i| {
                    let (x, y) = ((i % 300) as f32, (i / 300) as f32);
                    [[x, y, (i % 7) as f32], [x + 1.0, y, 0.0], [x, y + 1.0, (i % 5) as f32]]
                })
                .collect()
        };
        let bytes = |p: &PartBlob| -> Vec<(Vec<u8>, Vec<u8>)> {
            p.tiles
                .iter()
                .map(|t| (bytemuck::cast_slice(&t.nodes).to_vec(), bytemuck::cast_slice(&t.blocks).to_vec()))
                .collect()
        };
        let (big, small) = (model(60_000), model(7_000));
        let fresh_big = build_in_core(&big, 16 << 10, true, Quality::High);
        let fresh_small = build_in_core(&small, 16 << 10, true, Quality::High);
        let want = [(bytes(&fresh_big.0), fresh_big.1.clone()), (bytes(&fresh_small.0), fresh_small.1.clone())];
        recycle_part(fresh_big.0);
        recycle_part(fresh_small.0);
        for round in 0..2 {
            for (k, tris) in [&small, &big].into_iter().enumerate() {
                let (blob, src) = build_in_core(tris, 16 << 10, round == 0, Quality::High);
                let w = &want[1 - k];
                assert!(bytes(&blob) == w.0 && src == w.1, "round {round}, model {k}: differs from a fresh build");
                recycle_part(blob);
            }
        }
    }
}
