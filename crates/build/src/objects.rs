//! What a build of objects and instances is given ([`SceneInput`]), and how its objects'
//! trees and instances are placed in the scene file (`docs/FORMAT.md`, "Instances").

use std::path::PathBuf;

use megaray_base::Aabb;
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
}

impl<'a> SceneInput<'a> {
    /// One object, no instances.
    pub fn plain(source: ObjectSource<'a>) -> SceneInput<'a> {
        SceneInput {
            objects: vec![ObjectInput { name: String::new(), source }],
            instancing: None,
            materials: Vec::new(),
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

/// The scene file's instance section: the built objects (`(input index, first part, part
/// count, bounds, triangles)`), their trees (`(root, nodes)`), and the plan with its
/// instances of objects that were empty dropped (`kept`: each input object's new index).
pub(crate) fn instancing(
    plan: InstancePlan,
    objects: &[(usize, u32, u32, Aabb, u64)],
    trees: &[(u32, u32)],
    kept: &[Option<u32>],
    names: &[String],
) -> Result<Instancing, BuildError> {
    let mut out = Instancing {
        objects: objects
            .iter()
            .zip(trees)
            .zip(names)
            .map(|((o, t), name)| Object {
                name: name.clone(),
                bounds: o.3,
                first_part: o.1,
                part_count: o.2,
                root: t.0,
                node_count: t.1,
                tri_count: o.4,
            })
            .collect(),
        ..Instancing::default()
    };
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
