//! glTF 2.0 reader (`.gltf` with external or embedded buffers, and binary `.glb`), built on
//! the [`gltf`] crate.
//!
//! Unlike the other readers this one is **not streaming**: the JSON document and every
//! buffer it references are loaded into memory (images are not decoded). glTF files are
//! delivery formats and rarely massive, so this is accepted; the triangles themselves are
//! still handed to the sink one at a time.
//!
//! The default scene (or the first one) is walked from its root nodes, composing node
//! transforms (matrix or translation/rotation/scale). Every primitive of mode `TRIANGLES`,
//! `TRIANGLE_STRIP` or `TRIANGLE_FAN` is emitted once per node that references its mesh:
//! positions transformed by the node's world matrix, normals by its inverse transpose (and
//! normalised), `TEXCOORD_0` as uv, `COLOR_0` as colour. Corners are swapped under mirroring
//! transforms so faces keep their orientation. Point and line primitives are skipped with a
//! note. Each glTF material is declared once: base colour factor as diffuse and opacity,
//! metallic and roughness factors, and the base colour texture's URI (resolved against the
//! file's folder; embedded images have none).
//!
//! Everything that touches the [`gltf`] crate runs under [`guarded`] (the sink does not): a
//! malformed file that makes the crate panic (fuzzing found index and `unreachable!` panics in
//! its validation and accessors) becomes an [`ImportError`] of one line, and the panic hook
//! stays silent for it (no message, no backtrace). The node hierarchy must be a tree (no node
//! with two parents, no cycles).

use std::cell::Cell;
use std::fs::File;
use std::io::Read;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use ::gltf::mesh::Mode;
use glam::{Mat3, Mat4, Vec3};
use megaray_base::Progress;

use crate::{ImportError, ImportSummary, Material, TriAttr, TriangleSink, NO_MATERIAL};

thread_local! {
    /// Set while this thread runs [`guarded`] code: its panics are ours to report.
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

/// Runs `f` (code that calls into the gltf crate), catching a panic: `Err` holds its message.
/// The process's panic hook is wrapped once so that it says nothing for a panic caught here
/// (and everything, as before, for any other).
pub(crate) fn guarded<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    static WRAP: std::sync::Once = std::sync::Once::new();
    WRAP.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(Cell::get) {
                previous(info)
            }
        }));
    });
    QUIET.with(|q| q.set(true));
    let r = catch_unwind(AssertUnwindSafe(f));
    QUIET.with(|q| q.set(false));
    r.map_err(|p| {
        let msg = p.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| p.downcast_ref::<String>().cloned());
        msg.unwrap_or_else(|| "a panic".into()).chars().take(120).collect()
    })
}

/// The vertex data of one primitive, read from the buffers.
pub(crate) struct PrimData {
    pub(crate) positions: Vec<[f32; 3]>,
    pub(crate) normals: Option<Vec<[f32; 3]>>,
    pub(crate) uvs: Option<Vec<[f32; 2]>>,
    pub(crate) colors: Option<Vec<[f32; 4]>>,
    pub(crate) indices: Option<Vec<u32>>,
}

/// Reads a glTF or GLB file into `sink`.
pub(crate) fn import(
    path: &Path,
    mut file: File,
    len: u64,
    sink: &mut dyn TriangleSink,
    progress: &dyn Progress,
) -> Result<ImportSummary, ImportError> {
    let err = |loc: Option<String>, msg: String| ImportError::new(path, loc, msg);
    let (doc, buffers) = open_doc(path, &mut file)?;
    progress.inc(len);
    let base = path.parent().unwrap_or(Path::new("."));

    // Phase 1, all under `catch_unwind`: where each mesh goes, the materials.
    let plan = match guarded(|| plan(&doc, base)) {
        Ok(Ok(p)) => p,
        Ok(Err((loc, msg))) => return Err(err(loc, msg)),
        Err(p) => return Err(err(None, format!("malformed glTF (the reader failed: {p})"))),
    };

    // Phase 2: read and emit each mesh instance.
    let mut declared: Vec<Option<u32>> = vec![None; plan.materials.len()];
    let mut summary = ImportSummary { bytes: len, ..ImportSummary::default() };
    let mut skipped = 0u64;
    for (world, mi, node_path) in &plan.instances {
        let (world, mi) = (*world, *mi);
        let mesh = &plan.meshes[mi];
        sink.component(&format!("{node_path}: {}", mesh.name));
        for (pi, &(mode, material)) in mesh.prims.iter().enumerate() {
            let loc = || Some(format!("mesh \"{}\" primitive {pi}", mesh.name));
            if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                skipped += 1;
                continue;
            }
            let d = match guarded(|| read_primitive(&doc, mi, pi, &buffers)) {
                Ok(Ok(d)) => d,
                Ok(Err(msg)) => return Err(err(loc(), msg)),
                Err(p) => return Err(err(loc(), format!("malformed primitive (the glTF reader failed: {p})"))),
            };
            let material = match material {
                Some(i) if i < declared.len() => {
                    *declared[i].get_or_insert_with(|| sink.material(plan.materials[i].clone()))
                }
                _ => NO_MATERIAL,
            };
            emit(path, &d, mode, world, material, sink, &mut summary).map_err(|mut e| {
                let l = loc().unwrap_or_default();
                e.location = Some(match &e.location {
                    None => l,
                    Some(inner) => format!("{l} {inner}"),
                });
                e
            })?;
        }
    }
    if skipped > 0 {
        progress.note(&format!("{}: skipped {skipped} point or line primitives", path.display()));
    }
    Ok(summary)
}

/// A mesh as the scene walk needs it.
struct MeshInfo {
    /// Its name, or its index.
    name: String,
    /// Per primitive: mode and material index.
    prims: Vec<(Mode, Option<usize>)>,
}

/// What the scene walk produces.
pub(crate) struct Plan {
    /// World matrix, mesh index and node path (names from the root, `/`-separated; an
    /// unnamed node is `node N`) of every node with a mesh, in depth-first order.
    instances: Vec<(Mat4, usize, String)>,
    meshes: Vec<MeshInfo>,
    /// Every material of the document, converted (declared to the sink on first use).
    materials: Vec<Material>,
}

/// Walks the default (or first) scene. The node hierarchy must be a tree: a node with
/// several parents, or a root with a parent, is an error (this also rules out cycles).
pub(crate) fn plan(doc: &::gltf::Document, base: &Path) -> Result<Plan, (Option<String>, String)> {
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| (None, "the glTF file has no scene".to_string()))?;
    let n = doc.nodes().count();
    let mut parents = vec![0u32; n];
    for node in doc.nodes() {
        for c in node.children() {
            parents[c.index()] += 1;
            if parents[c.index()] > 1 {
                let msg = "node has several parents (the node hierarchy must be a tree)";
                return Err((Some(format!("node {}", c.index())), msg.to_string()));
            }
        }
    }
    let mut visited = vec![false; n];
    let mut instances = Vec::new();
    // (node, its parent's world transform, its parent's path, its depth: 1 for a root).
    let mut stack: Vec<(::gltf::Node, Mat4, String, u32)> = Vec::new();
    for root in scene.nodes().collect::<Vec<_>>().into_iter().rev() {
        if parents[root.index()] > 0 {
            let msg = "a root node of the scene is also a child of another node";
            return Err((Some(format!("node {}", root.index())), msg.to_string()));
        }
        stack.push((root, Mat4::IDENTITY, String::new(), 1));
    }
    while let Some((node, parent, above, depth)) = stack.pop() {
        if std::mem::replace(&mut visited[node.index()], true) {
            continue;
        }
        // Each node a level of instancing when the structure is kept (`gltf_scene`: the world,
        // then a group a node, then its mesh's), whose readers recurse through them.
        if depth + 1 > megaray_base::MAX_NESTING {
            let msg = format!("the node hierarchy nests more than {} levels of instancing", megaray_base::MAX_NESTING);
            return Err((Some(format!("node {}", node.index())), msg));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        let name = node.name().map_or_else(|| format!("node {}", node.index()), str::to_string);
        let path = if above.is_empty() { name } else { format!("{above}/{name}") };
        if let Some(mesh) = node.mesh() {
            instances.push((world, mesh.index(), path.clone()));
        }
        for c in node.children().collect::<Vec<_>>().into_iter().rev() {
            stack.push((c, world, path.clone(), depth + 1));
        }
    }
    let meshes = doc
        .meshes()
        .map(|m| MeshInfo {
            name: m.name().map(str::to_string).unwrap_or_else(|| m.index().to_string()),
            prims: m.primitives().map(|p| (p.mode(), p.material().index())).collect(),
        })
        .collect();
    let materials = doc.materials().map(|m| convert_material(doc, &m, base)).collect();
    Ok(Plan { instances, meshes, materials })
}

/// Reads the attributes of a primitive. Attributes whose length differs from the
/// positions' are dropped.
pub(crate) fn read_primitive(
    doc: &::gltf::Document,
    mesh: usize,
    prim: usize,
    buffers: &[::gltf::buffer::Data],
) -> Result<PrimData, String> {
    let prim = doc.meshes().nth(mesh).and_then(|m| m.primitives().nth(prim)).ok_or("no such primitive")?;
    // Sparse accessors can claim any count with little data: refuse absurd ones before the
    // reader allocates for them.
    let total: usize = buffers.iter().map(|b| b.len()).sum();
    for acc in prim.attributes().map(|(_, a)| a).chain(prim.indices()) {
        if acc.count() > total.saturating_add(1 << 24) {
            return Err(format!(
                "accessor {} claims {} elements, implausible for {total} bytes of buffers",
                acc.index(),
                acc.count()
            ));
        }
    }
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let bad = || "cannot read the primitive's positions or indices (bad accessor?)".to_string();
    let positions: Vec<[f32; 3]> = reader.read_positions().ok_or_else(bad)?.collect();
    let n = positions.len();
    let normals = reader.read_normals().map(|i| i.collect::<Vec<_>>()).filter(|v| v.len() == n);
    let uvs = reader.read_tex_coords(0).map(|i| i.into_f32().collect::<Vec<_>>()).filter(|v| v.len() == n);
    let colors = reader.read_colors(0).map(|i| i.into_rgba_f32().collect::<Vec<_>>()).filter(|v| v.len() == n);
    let indices = match prim.indices() {
        Some(_) => Some(reader.read_indices().ok_or_else(bad)?.into_u32().collect()),
        None => None,
    };
    Ok(PrimData { positions, normals, uvs, colors, indices })
}

/// Emits the triangles of one primitive instance.
fn emit(
    path: &Path,
    d: &PrimData,
    mode: Mode,
    world: Mat4,
    material: u32,
    sink: &mut dyn TriangleSink,
    summary: &mut ImportSummary,
) -> Result<(), ImportError> {
    let n = d.positions.len();
    let mut pos = Vec::with_capacity(n);
    for (i, p) in d.positions.iter().enumerate() {
        let q = world.transform_point3(Vec3::from(*p));
        if !q.is_finite() {
            let what = if q.is_nan() { "NaN" } else { "infinite" };
            return Err(ImportError::new(path, None, format!("vertex {i}: coordinate is {what} (non-finite)")));
        }
        pos.push(q.to_array());
    }
    let m3 = Mat3::from_mat4(world);
    let det = m3.determinant();
    let nm = if det != 0.0 && det.is_finite() { m3.inverse().transpose() } else { m3 };
    let normals: Option<Vec<[f32; 3]>> =
        d.normals.as_ref().map(|v| v.iter().map(|nv| (nm * Vec3::from(*nv)).normalize_or_zero().to_array()).collect());
    let flip = det < 0.0;

    let count = d.indices.as_ref().map_or(n, Vec::len);
    let index = |k: usize| -> Result<usize, ImportError> {
        let i = d.indices.as_ref().map_or(k as u32, |ix| ix[k]) as usize;
        if i >= n {
            return Err(ImportError::new(path, None, format!("index {i} out of range ({n} vertices)")));
        }
        Ok(i)
    };
    let ntris = triangle_count(mode, count);
    let mut attr = TriAttr { material, ..TriAttr::default() };
    for t in 0..ntris {
        let c = triangle_corners(mode, t);
        let mut v = [index(c[0])?, index(c[1])?, index(c[2])?];
        if flip {
            v.swap(1, 2);
        }
        attr.normal = normals.as_ref().map(|a| v.map(|i| a[i]));
        attr.uv = d.uvs.as_ref().map(|a| v.map(|i| a[i]));
        attr.color = d.colors.as_ref().map(|a| v.map(|i| a[i]));
        sink.triangle(v.map(|i| pos[i]), &attr)?;
    }
    summary.triangles += ntris as u64;
    summary.vertices += n as u64;
    Ok(())
}

/// Triangles in a primitive of `count` corners (indices, or vertices without them).
pub(crate) fn triangle_count(mode: Mode, count: usize) -> usize {
    match mode {
        Mode::Triangles => count / 3,
        _ => count.saturating_sub(2),
    }
}

/// The corners (positions in the index list) of triangle `t` of a list, strip or fan,
/// strips alternating so that every triangle keeps the winding.
pub(crate) fn triangle_corners(mode: Mode, t: usize) -> [usize; 3] {
    match mode {
        Mode::Triangles => [3 * t, 3 * t + 1, 3 * t + 2],
        Mode::TriangleStrip if t.is_multiple_of(2) => [t, t + 1, t + 2],
        Mode::TriangleStrip => [t + 1, t, t + 2],
        _ => [t + 1, t + 2, 0],
    }
}

/// Converts a glTF material.
pub(crate) fn convert_material(doc: &::gltf::Document, m: &::gltf::Material, base: &Path) -> Material {
    let pbr = m.pbr_metallic_roughness();
    let c = pbr.base_color_factor();
    // Read the image's URI from the JSON (the crate's `Image::source` panics on an image
    // with neither a URI nor a buffer view).
    let texture = pbr.base_color_texture().and_then(|info| {
        let image = doc.as_json().images.get(info.texture().source().index())?;
        match (&image.uri, &image.buffer_view) {
            (Some(uri), None) if !uri.starts_with("data:") => Some(base.join(percent_decode(uri))),
            _ => None,
        }
    });
    Material {
        name: m.name().map(str::to_string).unwrap_or_else(|| format!("material {}", m.index().unwrap_or(0))),
        diffuse: Some([c[0], c[1], c[2]]),
        opacity: Some(c[3]),
        metallic: Some(pbr.metallic_factor()),
        roughness: Some(pbr.roughness_factor()),
        texture,
        ..Material::default()
    }
}

/// Decodes `%XX` escapes of a relative URI into a path.
fn percent_decode(uri: &str) -> PathBuf {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    PathBuf::from(String::from_utf8_lossy(&out).into_owned())
}

/// Reads and parses a glTF or GLB file with its buffers (its header checked first, the
/// parser's panics turned into errors).
pub(crate) fn open_doc(
    path: &Path,
    file: &mut File,
) -> Result<(::gltf::Document, Vec<::gltf::buffer::Data>), ImportError> {
    let err = |loc: Option<String>, msg: String| ImportError::new(path, loc, msg);
    let mut data = Vec::new();
    file.read_to_end(&mut data).map_err(|e| err(None, format!("read error: {e}")))?;
    let is_glb = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    if is_glb && !data.starts_with(b"glTF") {
        return Err(err(Some("byte 0".into()), "not a GLB file (bad magic: it does not start with 'glTF')".into()));
    }
    if data.starts_with(b"glTF") {
        // Check the GLB header here: the gltf crate trusts its length field.
        let word = |i: usize| data.get(i..i + 4).map(|b| u32::from_le_bytes(b.try_into().unwrap()));
        let (version, length) = (word(4).unwrap_or(0), word(8).unwrap_or(0));
        if version != 2 {
            return Err(err(Some("byte 4".into()), format!("unsupported GLB version {version} (expected 2)")));
        }
        if (length as usize) < 20 || length as usize > data.len() {
            return Err(err(
                Some("byte 8".into()),
                format!("truncated or bad GLB: the header says {length} bytes, the file has {}", data.len()),
            ));
        }
    }
    let base = path.parent().unwrap_or(Path::new("."));
    let loaded = guarded(|| {
        let g = ::gltf::Gltf::from_slice(&data)?;
        let buffers = ::gltf::import_buffers(&g.document, Some(base), g.blob)?;
        Ok::<_, ::gltf::Error>((g.document, buffers))
    });
    let (doc, buffers) = match loaded {
        Ok(Ok(x)) => x,
        Ok(Err(e)) => return Err(err(None, format!("invalid glTF: {e}"))),
        Err(p) => return Err(err(None, format!("malformed glTF (the parser failed: {p})"))),
    };
    Ok((doc, buffers))
}

#[cfg(test)]
mod tests {
    use super::percent_decode;

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.png").to_str(), Some("a b.png"));
        assert_eq!(percent_decode("a%2").to_str(), Some("a%2"));
        assert_eq!(percent_decode("tex/x.png").to_str(), Some("tex/x.png"));
    }
}
