//! The import end of the build: a [`TriangleSink`] that writes the positions stream and the
//! attribute streams, drops zero-area triangles (counting them) and collects materials.

use std::path::Path;

use megaray_import::{ImportError, Material, TriAttr, TriangleSink};
use megaray_scene::MaterialDesc;

use crate::attrs::AttrStreams;
use crate::behind::WriteBehind;
use crate::stream::{Ids, StreamFile, StreamTri, StreamWriter};
use crate::{BuildError, BuildOptions};

pub struct BuildSink<'a> {
    /// The current object's positions stream (`s{objects}` in `dir`).
    stream: StreamWriter,
    dir: std::path::PathBuf,
    /// Objects finished so far ([`BuildSink::end_object`]).
    objects: usize,
    /// Triangle ids of earlier objects' streams: ids run on across objects, as attributes do.
    id_base: u64,
    attrs: AttrStreams,
    materials: Vec<MaterialDesc>,
    dropped: u64,
    error: Option<BuildError>,
    opts: &'a BuildOptions,
    seen: u64,
    /// The input being imported (for error messages).
    input: std::path::PathBuf,
    /// Components named so far ([`TriangleSink::component`]).
    components: ComponentIds,
    /// The thread that writes the positions streams while the reader parses.
    wb: std::sync::Arc<WriteBehind>,
}

/// The components of an import and which triangle ids belong to each: runs of ids in import
/// order, `(first id, component)`.
#[derive(Debug, Default)]
pub struct ComponentIds {
    pub names: Vec<String>,
    pub tri_counts: Vec<u64>,
    index: std::collections::HashMap<String, u32>,
    runs: Vec<(u64, u32)>,
    /// The current input's file name: the first segment of its components' names.
    file: String,
    /// The name given for the triangles that follow, until one comes.
    pending: Option<String>,
}

impl ComponentIds {
    /// Makes `name` current for the triangles that follow (a component gets its number
    /// when its first triangle comes, so that names without triangles are not kept).
    fn begin(&mut self, name: String) {
        self.pending = Some(name);
    }

    /// Counts triangle `id` into the current component.
    fn triangle(&mut self, id: u64) {
        if let Some(name) = self.pending.take() {
            let c = match self.index.get(&name) {
                Some(&c) => c,
                None => {
                    let c = self.names.len() as u32;
                    self.index.insert(name.clone(), c);
                    self.names.push(name);
                    self.tri_counts.push(0);
                    c
                }
            };
            if self.runs.last().is_none_or(|r| r.1 != c) {
                self.runs.push((id, c));
            }
        }
        if let Some(&(_, c)) = self.runs.last() {
            self.tri_counts[c as usize] += 1;
        }
    }

    /// The component of triangle id `id` (ids count from the first import).
    pub fn of(&self, id: u64) -> u32 {
        let i = self.runs.partition_point(|r| r.0 <= id);
        self.runs[i.saturating_sub(1)].1
    }

    /// Whether triangles of different components were imported (split streams must then
    /// keep their ids).
    pub fn several(&self) -> bool {
        self.names.len() > 1
    }
}

impl<'a> BuildSink<'a> {
    pub fn new(dir: &Path, opts: &'a BuildOptions) -> Result<BuildSink<'a>, BuildError> {
        let wb = std::sync::Arc::new(WriteBehind::new(2));
        Ok(BuildSink {
            stream: Self::object_stream(dir, 0, 0, &wb)?,
            dir: dir.to_path_buf(),
            objects: 0,
            id_base: 0,
            attrs: AttrStreams::new(dir),
            materials: Vec::new(),
            dropped: 0,
            error: None,
            opts,
            seen: 0,
            input: std::path::PathBuf::from("(input)"),
            components: ComponentIds::default(),
            wb,
        })
    }

    /// Degenerate triangles dropped so far (the build notes each input's share).
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Names the input whose triangles come next (and the component they belong to, until
    /// the input names others).
    pub fn set_input(&mut self, path: &Path) {
        self.input = path.to_path_buf();
        let file = path.file_name().map_or_else(|| path.to_string_lossy(), |f| f.to_string_lossy()).into_owned();
        self.components.file = file.clone();
        self.components.begin(file);
    }

    /// The sink's own failure (disk full, cancelled), if it had one.
    pub fn take_error(&mut self) -> Option<BuildError> {
        self.error.take()
    }

    /// Object `k`'s import stream, its ids implicit from `id_base`.
    fn object_stream(
        dir: &Path,
        k: usize,
        id_base: u64,
        wb: &std::sync::Arc<WriteBehind>,
    ) -> Result<StreamWriter, BuildError> {
        let (path, ids) = (dir.join(format!("s{k}")), Ids::Implicit(id_base));
        StreamWriter::create(&path, crate::split::ROOT_SAMPLE, crate::stream::IO_BUF, 0, ids, wb)
    }

    /// Whether any triangle came with attributes (split streams must then keep their ids).
    pub fn has_attributes(&self) -> bool {
        (0..crate::attrs::KINDS).any(|k| self.attrs.has(k))
    }

    /// Closes the current object's positions stream and starts the next object's.
    pub fn end_object(&mut self) -> Result<StreamFile, BuildError> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        self.objects += 1;
        let base = self.id_base + self.stream.count();
        let next = Self::object_stream(&self.dir, self.objects, base, &self.wb)?;
        let done = std::mem::replace(&mut self.stream, next).finish()?;
        self.id_base = base;
        Ok(done)
    }

    /// Closes the streams (the positions stream of an object not ended is dropped): the
    /// attribute streams, the materials, and the number of degenerate triangles dropped.
    pub fn finish(self) -> Result<(AttrStreams, Vec<MaterialDesc>, u64, ComponentIds), BuildError> {
        if let Some(e) = self.error {
            return Err(e);
        }
        let rest = self.stream.finish()?;
        let _ = std::fs::remove_file(&rest.path);
        Ok((self.attrs, self.materials, self.dropped, self.components))
    }
}

impl TriangleSink for BuildSink<'_> {
    fn triangle(&mut self, p: [[f32; 3]; 3], attr: &TriAttr) -> Result<(), ImportError> {
        self.seen += 1;
        if self.seen.is_multiple_of(65536) && self.opts.cancel.load(std::sync::atomic::Ordering::Relaxed) {
            self.error = Some(BuildError::Cancelled);
            return Err(ImportError::new(&self.input, None, "interrupted"));
        }
        if !megaray_base::tri_is_finite(&p) {
            return Err(ImportError::new(
                &self.input,
                Some(format!("triangle {}", self.seen - 1)),
                "non-finite coordinate",
            ));
        }
        if megaray_base::tri_is_degenerate(&p) {
            self.dropped += 1;
            return Ok(());
        }
        let id = self.id_base + self.stream.count();
        self.components.triangle(id);
        let r = self.stream.push(&StreamTri { v: p, reserved: 0, id }).and_then(|_| self.attrs.push(attr));
        if let Err(e) = r {
            let msg = e.to_string();
            self.error = Some(e);
            return Err(ImportError::new(&self.input, None, msg));
        }
        Ok(())
    }

    fn material(&mut self, m: Material) -> u32 {
        self.materials.push(MaterialDesc {
            name: m.name,
            diffuse: m.diffuse,
            specular: m.specular,
            shininess: m.shininess,
            opacity: m.opacity,
            metallic: m.metallic,
            roughness: m.roughness,
            texture: m.texture.map(|t| t.to_string_lossy().into_owned()),
        });
        (self.materials.len() - 1) as u32
    }

    fn component(&mut self, name: &str) {
        let c = &mut self.components;
        let full = if name.is_empty() { c.file.clone() } else { format!("{}/{name}", c.file) };
        c.begin(full);
    }
}
