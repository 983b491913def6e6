use crate::GenError;
use megaray_base::{Aabb, Progress, TriVerts};

/// Receives a model as a sequence of indexed chunks, one object (one sphere, one pipe, one grid
/// row) at a time, so that no one ever holds the whole model.
///
/// **Indices are global.** The vertices of a chunk are appended to the model's vertex list: if
/// the earlier chunks had `n` vertices in all, this chunk's `verts[i]` is vertex `n + i`. The
/// indices in `tris` are into that global list (0-based over all vertices emitted so far,
/// this chunk's included). The concatenation of all chunks' `verts` is exactly the model's
/// vertex array (for `grid` and `sphereflake`, the Embree peer's array, vertex for vertex).
///
/// **Locality.** A triangle references only vertices of its own chunk or of the chunk just
/// before it (only `grid` rows use the previous chunk: a strip of triangles joins the previous
/// row to this one). A sink that wants triangle corners therefore never needs to keep more than
/// two chunks; [`TriangleSink`] does exactly that. A chunk may have no triangles (the first grid
/// row) but every vertex is used by some triangle.
pub trait MeshSink {
    /// Takes one chunk. An error stops the generation and is returned by [`generate`](crate::generate).
    fn chunk(&mut self, verts: &[[f32; 3]], tris: &[[u32; 3]]) -> Result<(), GenError>;
}

/// A [`MeshSink`] that only counts and measures: vertices, triangles, chunks and bounds.
#[derive(Clone, Debug, Default)]
pub struct CountingSink {
    /// Vertices received.
    pub verts: u64,
    /// Triangles received.
    pub tris: u64,
    /// Chunks received.
    pub chunks: u64,
    /// Triangles of the largest chunk.
    pub max_chunk_tris: u64,
    /// Bounding box of all vertices.
    pub bounds: Aabb,
}

impl MeshSink for CountingSink {
    fn chunk(&mut self, verts: &[[f32; 3]], tris: &[[u32; 3]]) -> Result<(), GenError> {
        self.verts += verts.len() as u64;
        self.tris += tris.len() as u64;
        self.chunks += 1;
        self.max_chunk_tris = self.max_chunk_tris.max(tris.len() as u64);
        self.bounds.grow(&Aabb::from_points(verts));
        Ok(())
    }
}

/// Adapts a consumer of triangle corners to a [`MeshSink`]: it resolves the global indices of
/// each chunk (keeping only the previous chunk's vertices, see the locality rule of
/// [`MeshSink`]) and hands the chunk's triangles to `f` as corner triples, in order.
///
/// ```
/// use megaray_gen::{generate, GenSpec, TriangleSink};
/// let mut area = 0.0f64;
/// let mut sink = TriangleSink::new(|tris: &[[[f32; 3]; 3]]| {
///     for t in tris {
///         let e1 = [t[1][0] - t[0][0], t[1][2] - t[0][2]];
///         let e2 = [t[2][0] - t[0][0], t[2][2] - t[0][2]];
///         area += 0.5 * (e1[0] * e2[1] - e1[1] * e2[0]).abs() as f64;
///     }
///     Ok(())
/// });
/// generate(&GenSpec::Grid { n: 10 }, &mut sink, &megaray_base::NoProgress).unwrap();
/// drop(sink);
/// assert!((area - 4.0).abs() < 1e-4); // the grid's projection onto y = 0 is [-1, 1]^2
/// ```
pub struct TriangleSink<F> {
    f: F,
    prev: Vec<[f32; 3]>,
    prev_base: u64,
    cur_base: u64,
    corners: Vec<TriVerts>,
}

impl<F> TriangleSink<F>
where
    F: FnMut(&[TriVerts]) -> Result<(), GenError>,
{
    /// Calls `f` once per chunk that has triangles, with that chunk's triangles.
    pub fn new(f: F) -> Self {
        TriangleSink { f, prev: Vec::new(), prev_base: 0, cur_base: 0, corners: Vec::new() }
    }
}

impl<F> MeshSink for TriangleSink<F>
where
    F: FnMut(&[TriVerts]) -> Result<(), GenError>,
{
    fn chunk(&mut self, verts: &[[f32; 3]], tris: &[[u32; 3]]) -> Result<(), GenError> {
        let (prev, prev_base, cur_base) = (&self.prev, self.prev_base, self.cur_base);
        let corner = |i: u32| -> Option<[f32; 3]> {
            let i = i as u64;
            if i >= cur_base {
                verts.get((i - cur_base) as usize).copied()
            } else if i >= prev_base {
                prev.get((i - prev_base) as usize).copied()
            } else {
                None
            }
        };
        self.corners.clear();
        for t in tris {
            match (corner(t[0]), corner(t[1]), corner(t[2])) {
                (Some(a), Some(b), Some(c)) => self.corners.push([a, b, c]),
                _ => {
                    return Err(GenError::sink(
                        "triangle sink",
                        format!(
                            "triangle {t:?} is outside this chunk ({cur_base}..{}) and the previous one",
                            cur_base + verts.len() as u64
                        ),
                    ))
                }
            }
        }
        if !self.corners.is_empty() {
            (self.f)(&self.corners)?;
        }
        self.prev.clear();
        self.prev.extend_from_slice(verts);
        self.prev_base = self.cur_base;
        self.cur_base += verts.len() as u64;
        Ok(())
    }
}

/// What the generators write into: the sink plus the global vertex count, the 32-bit index
/// limit and batched progress.
pub(crate) struct Emitter<'a> {
    sink: &'a mut dyn MeshSink,
    progress: &'a dyn Progress,
    name: String,
    verts: u64,
    tris: u64,
    unreported: u64,
}

/// Progress is reported in steps of at least this many triangles.
const PROGRESS_STEP: u64 = 1 << 16;

impl<'a> Emitter<'a> {
    pub(crate) fn new(sink: &'a mut dyn MeshSink, progress: &'a dyn Progress, name: String) -> Self {
        Emitter { sink, progress, name, verts: 0, tris: 0, unreported: 0 }
    }

    /// The global index the next chunk's first vertex gets.
    #[inline]
    pub(crate) fn next_vertex(&self) -> u64 {
        self.verts
    }

    /// The error for a model that outgrows 32-bit vertex indices.
    pub(crate) fn too_many(&self) -> GenError {
        GenError::spec(&self.name, "more than 2^32 vertices: too large for 32-bit indices")
    }

    pub(crate) fn chunk(&mut self, verts: &[[f32; 3]], tris: &[[u32; 3]]) -> Result<(), GenError> {
        let total = self.verts + verts.len() as u64;
        if total > 1 << 32 {
            return Err(self.too_many());
        }
        self.sink.chunk(verts, tris)?;
        self.verts = total;
        self.tris += tris.len() as u64;
        self.unreported += tris.len() as u64;
        if self.unreported >= PROGRESS_STEP {
            self.progress.inc(self.unreported);
            self.unreported = 0;
        }
        Ok(())
    }

    /// Reports what is left and returns `(vertices, triangles)` emitted.
    pub(crate) fn done(mut self) -> (u64, u64) {
        if self.unreported > 0 {
            self.progress.inc(self.unreported);
            self.unreported = 0;
        }
        (self.verts, self.tris)
    }
}
