//! What a build of objects and instances is given ([`SceneInput`]), and how its objects'
//! trees and instances are placed in the scene file (`docs/FORMAT.md`, "Instances").

use std::path::PathBuf;

use megaray_import::{ImportError, Material, TriangleSink};
use megaray_scene::format::Node8;
use megaray_scene::{BlobChild, BlobRef, Group, Instance, Instancing, Object, Target};

use crate::BuildError;

/// A scene to build: objects, and the groups and instances that place them.
pub struct SceneInput<'a> {
    pub objects: Vec<ObjectInput<'a>>,
    /// `None`: the scene is its one object's triangles, with no instance section (what
    /// [`crate::build_scene`] makes). `Some`: group 0 is the scene; instance targets index
    /// `objects` (and `groups`).
    pub instancing: Option<InstancePlan>,
    /// Materials declared before any object's, so that instances' material overrides can
    /// name them by their index here.
    pub materials: Vec<Material>,
    /// Stored as the scene file's settings (JSON: camera, lights), if not empty.
    pub settings: String,
}

impl<'a> SceneInput<'a> {
    /// One object, no instances.
    pub fn plain(source: ObjectSource<'a>) -> SceneInput<'a> {
        SceneInput {
            objects: vec![ObjectInput { name: String::new(), source }],
            instancing: None,
            materials: Vec::new(),
            settings: String::new(),
        }
    }
}

/// One object: a name and where its triangles come from.
pub struct ObjectInput<'a> {
    pub name: String,
    pub source: ObjectSource<'a>,
}

/// Where an object's triangles come from.
pub enum ObjectSource<'a> {
    /// Model files, merged.
    Files(Vec<PathBuf>),
    /// A function that hands them to the build (a scene file's own meshes, generated ones).
    #[allow(clippy::type_complexity)]
    Fn(Box<dyn FnOnce(&mut dyn TriangleSink) -> Result<(), ImportError> + 'a>),
    /// The shapes of an object of a pbrt scene ([`megaray_import::pbrt`]).
    Pbrt(megaray_import::pbrt::ObjectDesc),
}

/// A pbrt scene as a build's input: each object's shapes an object, group 0 the world,
/// each named object a group (its shapes' object and the objects placed in it), numbered
/// from the last defined, so that groups name only later groups; and the scene's camera
/// and lights as the scene file's settings.
pub fn pbrt_input<'a>(mut p: megaray_import::pbrt::PbrtScene) -> SceneInput<'a> {
    use megaray_base::Affine;
    let settings = settings_json(&p);
    let n = p.objects.len();
    // pbrt object k's group: 0 for the world, else counted down from the last defined.
    let group_of = |k: usize| if k == 0 { 0 } else { (n - k) as u32 };
    let mut objects = Vec::new();
    let mut mesh_of = vec![None; n];
    for (k, o) in p.objects.iter_mut().enumerate() {
        if !o.shapes.is_empty() {
            mesh_of[k] = Some(objects.len() as u32);
            // The shapes move to the build (a scene's inline meshes are not held twice).
            let shapes = std::mem::take(&mut o.shapes);
            let desc = megaray_import::pbrt::ObjectDesc { name: o.name.clone(), shapes, instances: Vec::new() };
            objects.push(ObjectInput { name: o.name.clone(), source: ObjectSource::Pbrt(desc) });
        }
    }
    let mut by_group: Vec<usize> = (0..n).collect();
    by_group.sort_by_key(|&k| group_of(k));
    let mut plan = InstancePlan::default();
    for &k in &by_group {
        let first = plan.instances.len() as u32;
        let o = &p.objects[k];
        if let Some(m) = mesh_of[k] {
            plan.instances.push(Instance {
                name: o.name.clone(),
                xform: Affine::IDENTITY,
                target: Target::Object(m),
                material: None,
            });
        }
        for &(t, xf) in &o.instances {
            let name = p.objects[t as usize].name.clone();
            plan.instances.push(Instance {
                name,
                xform: xf,
                target: Target::Group(group_of(t as usize)),
                material: None,
            });
        }
        plan.groups.push(Group { name: o.name.clone(), first, count: plan.instances.len() as u32 - first });
    }
    SceneInput { objects, instancing: Some(plan), materials: p.materials, settings }
}

/// A pbrt scene's camera and lights as the scene file's settings (JSON).
fn settings_json(p: &megaray_import::pbrt::PbrtScene) -> String {
    use serde_json::{json, Map, Value};
    let v = |v: megaray_base::Vec3| json!([v.x, v.y, v.z]);
    let mut m = Map::new();
    if let Some(c) = &p.camera {
        m.insert("camera".into(), json!({"eye": v(c.eye), "at": v(c.at), "up": v(c.up), "fov": c.fov}));
    }
    if let Some((w, h)) = p.resolution {
        m.insert("resolution".into(), json!([w, h]));
    }
    if let Some((path, scale)) = &p.environment {
        m.insert("environment".into(), json!({"file": path.to_string_lossy(), "scale": scale}));
    }
    if let Some((dir, l)) = &p.sun {
        m.insert("sun".into(), json!({"dir": v(*dir), "radiance": l}));
    }
    if !p.area_lights.is_empty() {
        let lights: Vec<Value> = p
            .area_lights
            .iter()
            .map(|a| {
                let tris: Vec<Value> = a.triangles.iter().map(|t| json!(t.concat())).collect();
                json!({"material": a.material, "radiance": a.radiance, "two_sided": a.two_sided, "triangles": tris})
            })
            .collect();
        m.insert("area_lights".into(), Value::Array(lights));
    }
    Value::Object(m).to_string()
}

/// Groups and instances as a scene file describes them: targets index the input's objects.
#[derive(Clone, Debug, Default)]
pub struct InstancePlan {
    pub groups: Vec<Group>,
    pub instances: Vec<Instance>,
}

/// An object's tree as [`crate::top_level`] made it, placed at node `node_base` of the
/// top-level array with its parts numbered from `part_base`.
pub(crate) fn placed(nodes: Vec<Node8>, node_base: u32, part_base: u32) -> impl Iterator<Item = Node8> {
    nodes.into_iter().map(move |mut n| {
        for c in n.child.iter_mut() {
            *c = match BlobRef(*c).decode() {
                BlobChild::Inner(k) => BlobRef::inner(k + node_base).0,
                BlobChild::Part(p) => BlobRef::part(p + part_base).0,
                _ => *c,
            };
        }
        n
    })
}

/// The scene file's instance section: the built objects, and the plan with its instances
/// of objects that were empty dropped (`kept`: each input object's index among `objects`).
pub(crate) fn instancing(
    plan: InstancePlan,
    objects: Vec<Object>,
    kept: &[Option<u32>],
) -> Result<Instancing, BuildError> {
    let mut out = Instancing { objects, ..Instancing::default() };
    if plan.groups.is_empty() {
        return Err(BuildError::Invalid("an instanced scene needs a root group".into()));
    }
    for (g, gr) in plan.groups.iter().enumerate() {
        let first = out.instances.len() as u32;
        let end = gr.first as usize + gr.count as usize;
        let members = plan.instances.get(gr.first as usize..end).ok_or_else(|| {
            BuildError::Invalid(format!(
                "group {g} ({}): instances {}..{end} of {}",
                gr.name,
                gr.first,
                plan.instances.len()
            ))
        })?;
        for inst in members {
            let target = match inst.target {
                Target::Object(o) => match kept.get(o as usize) {
                    Some(Some(k)) => Target::Object(*k),
                    Some(None) => continue,
                    None => {
                        return Err(BuildError::Invalid(format!("instance {}: object {o} does not exist", inst.name)))
                    }
                },
                t => t,
            };
            out.instances.push(Instance { target, ..inst.clone() });
        }
        out.groups.push(Group { name: gr.name.clone(), first, count: out.instances.len() as u32 - first });
    }
    Ok(out)
}
