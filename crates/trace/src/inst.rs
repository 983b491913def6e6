//! Instances: the layer above the objects' trees (`docs/ARCHITECTURE.md`, "Instances").
//!
//! A scene with instances is traced group by group from group 0: each group's tree
//! ([`InstTree`], built here, in core) is walked nearest first; a ray entering an instance
//! is moved into its target's space by the instance's inverse transform (the direction not
//! renormalised, so that distances along it stay those of the world ray) and traced through
//! the target: a nested group the same way, an object by a tracer whose root is the
//! object's tree ([`Tracer::object_tracer`]), with every kernel and the paging of a scene
//! without instances. Tiles belong to objects, so every instance of an object shares them.
//!
//! A ray that meets an absent tile inside an object stops ([`Traced::Pending`]) with the
//! closest hit found so far, the instances down to that object and its state inside it.
//! Resumed, it walks the groups' trees again with its interval cut at that hit, which visits
//! the objects it visited before in the same order (or fewer: none farther than the cut),
//! skips them up to the one it stopped in, and resumes inside that one: so a ray needs one
//! tile at a time, as without instances.

use megaray_base::{Aabb, Affine, Ray, Vec3};
use megaray_scene::format::{ChildRef, NODE_BYTES};
use megaray_scene::{Instancing, Scene, Target};

use crate::inst_bvh::InstTree;
use crate::lod::LodRay;
use crate::tracer::{Entry, Tracer, TOP};
use crate::{Hit, Pending, Placement, Traced};

/// One instance as the tracer keeps it.
#[derive(Clone, Copy, Debug)]
struct Inst {
    /// The target's space to the group's, and back.
    to_parent: Affine,
    to_local: Affine,
    target: Target,
    /// A material override, or `u32::MAX`.
    material: u32,
    /// Its scale: the cube root of the transform's determinant's size (what lengths in the
    /// target become in the group, for the choice of a level of detail).
    scale: f32,
}

/// The instance layer of a [`Tracer`]: a tracer per object, a tree per group.
pub(crate) struct Layer<'s> {
    pub(crate) objects: Vec<Tracer<'s>>,
    inst: Vec<Inst>,
    groups: Vec<InstTree>,
    /// Each group's instances (`first .. first + count` of `inst`).
    members: Vec<(u32, u32)>,
    /// Arrays kept from one rebuild to the next.
    boxes: Vec<Aabb>,
    scratch: crate::inst_bvh::Scratch,
}

impl<'s> Layer<'s> {
    /// The layer of `scene`'s instancing over `base` (the tracer whose settings the
    /// objects' tracers copy).
    pub(crate) fn new(base: &Tracer<'s>, scene: &'s Scene, i: &Instancing) -> Layer<'s> {
        let top0 = scene.header().top_nodes_off / NODE_BYTES as u64;
        let objects = i
            .objects
            .iter()
            .map(|o| {
                let root = match o.part_count {
                    // A single part: start at its root (the object's tree would only test
                    // the part's box again).
                    1 => Entry::part_root(scene, &scene.parts()[o.first_part as usize]),
                    _ => Entry { r: ChildRef::inner(top0 + o.root as u64).0, arr: TOP, t: f32::NEG_INFINITY },
                };
                base.object_tracer(root, o.bounds)
            })
            .collect();
        let inst = i
            .instances
            .iter()
            .map(|k| Inst {
                to_parent: k.xform,
                // Checked invertible when the scene was opened.
                to_local: k.xform.inverse().unwrap_or(Affine::IDENTITY),
                target: k.target,
                material: k.material.unwrap_or(u32::MAX),
                scale: scale_of(&k.xform),
            })
            .collect();
        let members = i.groups.iter().map(|g| (g.first, g.count)).collect();
        let groups = vec![InstTree::default(); i.groups.len()];
        let mut l = Layer { objects, inst, groups, members, boxes: Vec::new(), scratch: Default::default() };
        l.rebuild();
        l
    }

    /// Builds every group's tree over its instances' current boxes (the last group first:
    /// groups hold only later ones).
    pub(crate) fn rebuild(&mut self) {
        let n = self.members.len();
        let mut bounds = vec![Aabb::EMPTY; n];
        let mut boxes = std::mem::take(&mut self.boxes);
        for g in (0..n).rev() {
            let (first, count) = self.members[g];
            let members = &self.inst[first as usize..(first + count) as usize];
            let place = |k: &Inst| {
                let inner = match k.target {
                    Target::Object(o) => self.objects[o as usize].bounds,
                    Target::Group(h) => bounds[h as usize],
                };
                k.to_parent.aabb(&inner)
            };
            boxes.clear();
            if members.len() > 65536 {
                use rayon::prelude::*;
                members.par_iter().with_min_len(16384).map(place).collect_into_vec(&mut boxes);
            } else {
                boxes.extend(members.iter().map(place));
            }
            self.groups[g].rebuild(&boxes, &mut self.scratch);
            bounds[g] = self.groups[g].nodes.first().map_or(Aabb::EMPTY, |n| n.bounds);
        }
        self.boxes = boxes;
    }

    /// Sets instance `k`'s transform (its target's space to its group's); the trees follow
    /// at the next [`Layer::rebuild`]. `false` when `k` does not exist or `xf` is not
    /// invertible.
    pub(crate) fn set_transform(&mut self, k: usize, xf: Affine) -> bool {
        match (self.inst.get_mut(k), xf.inverse()) {
            (Some(i), Some(inv)) => {
                (i.to_parent, i.to_local, i.scale) = (xf, inv, scale_of(&xf));
                true
            }
            _ => false,
        }
    }

    /// The world box of what group 0 shows.
    pub(crate) fn bounds(&self) -> Aabb {
        self.groups.first().and_then(|t| t.nodes.first()).map_or(Aabb::EMPTY, |n| n.bounds)
    }

    /// The closest hit of `ray` (any hit, `any`) through group 0, or the ray pending on a
    /// tile. `from`: a ray pending earlier, which starts again cut at its best hit.
    pub(crate) fn traverse(&self, ray: &Ray, any: bool, from: Option<Box<Pending>>, lod: Option<&LodRay>) -> Traced {
        let (prior, skip_to) = match from {
            Some(p) => (p.hit, p.inside.map(|b| *b)),
            None => (None, None),
        };
        let t_max = prior.map_or(ray.t_max, |h| h.t);
        let mut q = Query { best: prior, t_max, any, missing: None, lod, path: Vec::new(), skip_to };
        let world = Ray { t_max, ..*ray };
        self.group(0, &world, 1.0, &mut q);
        match q.missing {
            Some((path, inner)) => Traced::Pending(Box::new(Pending::inside(q.best, any, path, *inner))),
            None => Traced::Done(q.best),
        }
    }

    /// Traces `ray` (in group `g`'s space, a length of which is `scale` in the world)
    /// through `g`'s instances.
    fn group(&self, g: u32, ray: &Ray, scale: f32, q: &mut Query<'_>) {
        let Some(tree) = self.groups.get(g as usize) else { return };
        let first = self.members[g as usize].0;
        let t_max = std::cell::Cell::new(q.t_max);
        tree.walk(ray, &|| t_max.get(), |k| {
            let inst = &self.inst[(first + k) as usize];
            let local = Ray { t_max: q.t_max, ..inst.to_local.ray(ray) };
            q.path.push(first + k);
            let scale = scale * inst.scale;
            match inst.target {
                Target::Group(h) => self.group(h, &local, scale, q),
                Target::Object(o) => self.object(o, &local, scale, q),
            }
            q.path.pop();
            t_max.set(q.t_max);
            q.missing.is_none() && !(q.any && q.best.is_some())
        });
    }

    /// Traces `ray` (in object `o`'s space) through the object.
    fn object(&self, o: u32, ray: &Ray, scale: f32, q: &mut Query<'_>) {
        let obj = &self.objects[o as usize];
        if q.skip_to.is_none() && q.lod.is_none() && obj.pager.is_none() {
            // Unpaged, full detail: the objects' fastest way in (`Tracer::intersect`).
            let f = if q.any { obj.unpaged::<true>(ray) } else { obj.unpaged::<false>(ray) };
            if let Some(h) = obj.hit_of(f) {
                q.t_max = h.t;
                q.best = Some(self.place(&q.path, h));
            }
            return;
        }
        let mut from = None;
        if let Some((p, _)) = &q.skip_to {
            if *p != q.path {
                // Visited before the ray stopped: its hits are in `best` already.
                return;
            }
            from = q.skip_to.take().map(|(_, inner)| Box::new(inner));
        }
        let scaled = q.lod.filter(|_| scale != 1.0).map(|l| l.scaled(scale));
        let traced = obj.traverse_with(ray, q.any, from, 0, scaled.as_ref().or(q.lod));
        if let (Some(l), Some(s)) = (q.lod, &scaled) {
            l.missed_in(s);
        }
        match traced {
            Traced::Done(Some(h)) if h.t < q.t_max || q.any => {
                q.t_max = h.t;
                q.best = Some(self.place(&q.path, h));
            }
            Traced::Done(_) => {}
            Traced::Pending(p) => q.missing = Some((q.path.clone(), p)),
        }
    }
}

impl Layer<'_> {
    /// The instances `path` (from group 0 down) composed: the object's space to the world
    /// and back, and the outermost material override.
    fn path(&self, path: &[u32]) -> Path {
        path.iter().fold(Path::WORLD, |p, &k| p.then(&self.inst[k as usize]))
    }

    /// An object-space hit reached through `path`, in the world.
    fn place(&self, path: &[u32], h: Hit) -> Hit {
        self.path(path).place(h)
    }
}

/// What a ray through the layer found so far.
struct Query<'a> {
    best: Option<Hit>,
    t_max: f32,
    any: bool,
    /// Where the ray stopped: the instances down to the object, and its state in it.
    missing: Option<(Vec<u32>, Box<Pending>)>,
    lod: Option<&'a LodRay>,
    /// The instances down to the current space.
    path: Vec<u32>,
    /// A resumed ray's stop: objects are skipped up to this one, then resumed in.
    skip_to: Option<(Vec<u32>, Pending)>,
}

/// The instances from the world down to a space: that space to the world, the world to it,
/// and the outermost material override.
struct Path {
    to_world: Affine,
    to_local: Affine,
    material: u32,
}

impl Path {
    const WORLD: Path = Path { to_world: Affine::IDENTITY, to_local: Affine::IDENTITY, material: u32::MAX };

    fn then(&self, inst: &Inst) -> Path {
        Path {
            to_world: self.to_world.then_after(&inst.to_parent),
            to_local: inst.to_local.then_after(&self.to_local),
            // The outermost override wins, as a material bound to a whole assembly.
            material: if self.material != u32::MAX { self.material } else { inst.material },
        }
    }

    /// An object-space hit made a world one: corners moved, and the normals' transform
    /// (the world-to-object map's transpose) kept for the shading normals.
    fn place(&self, mut h: Hit) -> Hit {
        for c in &mut h.tri {
            *c = self.to_world.point(Vec3::from(*c)).into();
        }
        let m = &self.to_local.0;
        h.placed = Some(Placement {
            normal: [[m[0][0], m[1][0], m[2][0]], [m[0][1], m[1][1], m[2][1]], [m[0][2], m[1][2], m[2][2]]],
            material: self.material,
        });
        h
    }
}

/// Rigid motion: instances move between frames and only the groups' trees are rebuilt.
impl Tracer<'_> {
    /// Instances in the scene (0 without an instance layer).
    pub fn instance_count(&self) -> usize {
        self.layer.as_ref().map_or(0, |l| l.inst.len())
    }

    /// Sets instance `k`'s transform (its target's space to its group's), taking effect at
    /// the next [`Tracer::rebuild_instances`]. `false` (nothing changed) when the scene has
    /// no instance `k` or `xf` is not invertible.
    pub fn set_instance_transform(&mut self, k: usize, xf: Affine) -> bool {
        self.layer.as_mut().is_some_and(|l| l.set_transform(k, xf))
    }

    /// Rebuilds the groups' trees over the instances' current places (the objects' trees
    /// stay as they are); returns the time it took.
    pub fn rebuild_instances(&mut self) -> std::time::Duration {
        let t = std::time::Instant::now();
        if let Some(l) = self.layer.as_mut() {
            l.rebuild();
            self.bounds = l.bounds();
        }
        t.elapsed()
    }
}

/// What lengths become under `xf`: the cube root of its determinant's size (exact for a
/// uniform scale, the mean for others).
fn scale_of(xf: &Affine) -> f32 {
    (xf.determinant().abs().cbrt() as f32).max(f32::MIN_POSITIVE)
}
