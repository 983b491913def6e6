//! glTF scenes with their structure kept: each mesh one object, each node a group (its mesh
//! placed as is, its children by their transforms), the scene's root nodes placed in the
//! world; a mesh used by several nodes is one object with several instances. The result is
//! the scene description pbrt scenes read into ([`PbrtScene`]), built the same way; the
//! first node with a perspective camera gives the scene's camera.

use std::fs::File;
use std::path::Path;

use ::gltf::mesh::Mode;
use glam::Mat4;
use megaray_base::{Affine, Vec3};

use crate::gltf::{convert_material, guarded, open_doc, plan, read_primitive, triangle_corners, triangle_count};
use crate::pbrt::{CameraDesc, ObjectDesc, PbrtScene, ShapeDesc, ShapeKind};
use crate::ImportError;

/// Reads the glTF or GLB file `path` as a scene of objects and instances.
pub fn read_scene(path: &Path) -> Result<PbrtScene, ImportError> {
    let err = |loc: Option<String>, msg: String| ImportError::new(path, loc, msg);
    let mut file = File::open(path).map_err(|e| err(None, format!("cannot open: {e}")))?;
    let (doc, buffers) = open_doc(path, &mut file)?;
    let base = path.parent().unwrap_or(Path::new("."));
    // The hierarchy must be a tree (checked as the flattening reader does).
    match guarded(|| plan(&doc, base).map(|_| ())) {
        Ok(Ok(())) => {}
        Ok(Err((loc, msg))) => return Err(err(loc, msg)),
        Err(p) => return Err(err(None, format!("malformed glTF (the reader failed: {p})"))),
    }
    let mut s = PbrtScene {
        objects: vec![ObjectDesc { name: "world".into(), ..Default::default() }],
        materials: doc.materials().map(|m| convert_material(&doc, &m, base)).collect(),
        ..Default::default()
    };
    // Meshes first (objects place only objects defined before them).
    let mut mesh_obj = Vec::new();
    for m in doc.meshes() {
        let name = m.name().map(str::to_string).unwrap_or_else(|| format!("mesh {}", m.index()));
        let mut o = ObjectDesc { name: format!("mesh \"{name}\""), ..Default::default() };
        for (pi, p) in m.primitives().enumerate() {
            let loc = || Some(format!("mesh \"{name}\" primitive {pi}"));
            let mode = p.mode();
            if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                *s.skipped.entry("point or line primitive".into()).or_default() += 1;
                continue;
            }
            let d = match guarded(|| read_primitive(&doc, m.index(), pi, &buffers)) {
                Ok(Ok(d)) => d,
                Ok(Err(msg)) => return Err(err(loc(), msg)),
                Err(e) => return Err(err(loc(), format!("malformed primitive (the glTF reader failed: {e})"))),
            };
            let n = d.positions.len();
            let count = d.indices.as_ref().map_or(n, Vec::len);
            let at = |k: usize| d.indices.as_ref().map_or(k as u32, |ix| ix[k]);
            let mut indices = Vec::new();
            for t in 0..triangle_count(mode, count) {
                for k in triangle_corners(mode, t) {
                    let i = at(k);
                    if i as usize >= n {
                        return Err(err(loc(), format!("index {i} out of range ({n} vertices)")));
                    }
                    indices.push(i);
                }
            }
            let kind = ShapeKind::Mesh { p: d.positions, indices, n: d.normals, uv: d.uvs, color: d.colors };
            let material = p.material().index().map(|i| i as u32);
            o.shapes.push(ShapeDesc {
                kind,
                xform: Affine::IDENTITY,
                reverse: false,
                material,
                place: name.clone(),
                declared: (path.to_path_buf(), format!("mesh \"{name}\" primitive {pi}")),
                emitting: false,
            });
        }
        mesh_obj.push(s.objects.len() as u32);
        s.objects.push(o);
    }
    // Nodes, children before parents.
    let scene = doc.default_scene().or_else(|| doc.scenes().next()).ok_or_else(|| err(None, "no scene".into()))?;
    let mut node_obj = vec![None; doc.nodes().count()];
    let local = |n: &::gltf::Node| affine(Mat4::from_cols_array_2d(&n.transform().matrix()));
    fn post_order<'a>(n: ::gltf::Node<'a>, out: &mut Vec<::gltf::Node<'a>>) {
        for c in n.children() {
            post_order(c, out);
        }
        out.push(n);
    }
    let mut order = Vec::new();
    for root in scene.nodes() {
        post_order(root, &mut order);
    }
    for node in &order {
        let name = node.name().map(str::to_string).unwrap_or_else(|| format!("node {}", node.index()));
        let mut o = ObjectDesc { name, ..Default::default() };
        if let Some(m) = node.mesh() {
            o.instances.push((mesh_obj[m.index()], Affine::IDENTITY));
        }
        for c in node.children() {
            if let Some(k) = node_obj[c.index()] {
                o.instances.push((k, local(&c)));
            }
        }
        node_obj[node.index()] = Some(s.objects.len() as u32);
        s.objects.push(o);
    }
    for root in scene.nodes() {
        if let Some(k) = node_obj[root.index()] {
            s.objects[0].instances.push((k, local(&root)));
        }
    }
    s.camera = camera(&scene);
    Ok(s)
}

fn affine(m: Mat4) -> Affine {
    Affine::from_cols4(m.to_cols_array_2d())
}

/// The first node with a perspective camera, depth first: its place in the world.
fn camera(scene: &::gltf::Scene) -> Option<CameraDesc> {
    fn find(n: ::gltf::Node, parent: Mat4) -> Option<CameraDesc> {
        let world = parent * Mat4::from_cols_array_2d(&n.transform().matrix());
        let yfov = n.camera().and_then(|c| match c.projection() {
            ::gltf::camera::Projection::Perspective(p) => Some(p.yfov()),
            _ => None,
        });
        if let Some(yfov) = yfov {
            let a = affine(world);
            return Some(CameraDesc {
                eye: a.point(Vec3::ZERO),
                at: a.point(-Vec3::Z),
                up: a.vector(Vec3::Y).normalize_or_zero(),
                fov: yfov.to_degrees(),
            });
        }
        n.children().find_map(|c| find(c, world))
    }
    scene.nodes().find_map(|n| find(n, Mat4::IDENTITY))
}
