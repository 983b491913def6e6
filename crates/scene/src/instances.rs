//! Objects, groups and instances: the scene file's second level of indirection
//! (`docs/FORMAT.md`, "Instances").
//!
//! An *object* is a run of full-detail parts with a tree of its own in the top-level node
//! array; a *group* is a list of *instances*, each an object or a later group placed by a
//! 3x4 affine transform, with an optional material. Group 0 is the scene. Groups name only
//! later groups, so that the graph has no cycles, and nest up to `MAX_NESTING` levels (the
//! tracer recurses through them); a few objects placed a few times at each of several levels
//! make scenes of trillions of triangles that take bytes per instance, not per triangle.

use bytemuck::{Pod, Zeroable};
use megaray_base::{Aabb, Affine};

/// An object on disk. 64 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ObjectRecord {
    pub bounds: Aabb,
    pub first_part: u32,
    pub part_count: u32,
    /// Its tree's root: a node index into the top-level tree.
    pub root: u32,
    /// Its tree's nodes: `root .. root + node_count` of the top-level tree.
    pub node_count: u32,
    pub tri_count: u64,
    pub name_off: u32,
    pub name_len: u32,
    pub reserved: u64,
}
const _: () = assert!(std::mem::size_of::<ObjectRecord>() == 64);

/// A group on disk: instances `first .. first + count`. 16 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GroupRecord {
    pub first: u32,
    pub count: u32,
    pub name_off: u32,
    pub name_len: u32,
}
const _: () = assert!(std::mem::size_of::<GroupRecord>() == 16);

/// An instance on disk. 64 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct InstanceRecord {
    /// Object space to the group's space, row-major 3x4 ([`Affine`]).
    pub xform: [[f32; 4]; 3],
    /// An object index, or a group index with bit 31 set ([`GROUP_BIT`]).
    pub target: u32,
    /// A material index overriding the object's, or `0xFFFF_FFFF`.
    pub material: u32,
    pub name_off: u32,
    pub name_len: u32,
}
const _: () = assert!(std::mem::size_of::<InstanceRecord>() == 64);

/// Marks an instance's target as a group.
pub const GROUP_BIT: u32 = 1 << 31;

#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub name: String,
    pub bounds: Aabb,
    pub first_part: u32,
    pub part_count: u32,
    pub root: u32,
    pub node_count: u32,
    pub tri_count: u64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Group {
    pub name: String,
    pub first: u32,
    pub count: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    Object(u32),
    Group(u32),
}

#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    pub name: String,
    pub xform: Affine,
    pub target: Target,
    pub material: Option<u32>,
}

/// A scene's objects, groups and instances, as read from a file or about to be written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Instancing {
    pub objects: Vec<Object>,
    pub groups: Vec<Group>,
    pub instances: Vec<Instance>,
}

impl Instancing {
    /// The section's bytes: objects, groups, instances, then their names.
    pub fn encode(&self) -> Vec<u8> {
        let mut strings = Vec::new();
        let mut name = |s: &str| {
            let off = strings.len() as u32;
            strings.extend_from_slice(s.as_bytes());
            (off, s.len() as u32)
        };
        let mut out = Vec::new();
        for o in &self.objects {
            let (name_off, name_len) = name(&o.name);
            let r = ObjectRecord {
                bounds: o.bounds,
                first_part: o.first_part,
                part_count: o.part_count,
                root: o.root,
                node_count: o.node_count,
                tri_count: o.tri_count,
                name_off,
                name_len,
                reserved: 0,
            };
            out.extend_from_slice(bytemuck::bytes_of(&r));
        }
        for g in &self.groups {
            let (name_off, name_len) = name(&g.name);
            let r = GroupRecord { first: g.first, count: g.count, name_off, name_len };
            out.extend_from_slice(bytemuck::bytes_of(&r));
        }
        for i in &self.instances {
            let (name_off, name_len) = name(&i.name);
            let target = match i.target {
                Target::Object(o) => o,
                Target::Group(g) => g | GROUP_BIT,
            };
            let material = i.material.unwrap_or(u32::MAX);
            let r = InstanceRecord { xform: i.xform.0, target, material, name_off, name_len };
            out.extend_from_slice(bytemuck::bytes_of(&r));
        }
        out.extend_from_slice(&strings);
        out
    }

    /// Reads a section back; `None` when its records do not fit `bytes` or a name lies
    /// outside it. The contents are checked by [`Instancing::check`].
    pub fn decode(bytes: &[u8], objects: u32, groups: u32, instances: u32) -> Option<Instancing> {
        let (ob, gb, ib) = (objects as usize * 64, groups as usize * 16, instances as usize * 64);
        let recs = ob.checked_add(gb)?.checked_add(ib)?;
        if recs > bytes.len() {
            return None;
        }
        let strings = &bytes[recs..];
        let s = |off: u32, len: u32| -> Option<String> {
            let end = (off as usize).checked_add(len as usize)?;
            Some(String::from_utf8_lossy(strings.get(off as usize..end)?).into_owned())
        };
        let mut out = Instancing::default();
        for c in bytes[..ob].chunks_exact(64) {
            let r: ObjectRecord = bytemuck::pod_read_unaligned(c);
            out.objects.push(Object {
                name: s(r.name_off, r.name_len)?,
                bounds: r.bounds,
                first_part: r.first_part,
                part_count: r.part_count,
                root: r.root,
                node_count: r.node_count,
                tri_count: r.tri_count,
            });
        }
        for c in bytes[ob..ob + gb].chunks_exact(16) {
            let r: GroupRecord = bytemuck::pod_read_unaligned(c);
            out.groups.push(Group { name: s(r.name_off, r.name_len)?, first: r.first, count: r.count });
        }
        for c in bytes[ob + gb..recs].chunks_exact(64) {
            let r: InstanceRecord = bytemuck::pod_read_unaligned(c);
            let target = match r.target & GROUP_BIT {
                0 => Target::Object(r.target),
                _ => Target::Group(r.target & !GROUP_BIT),
            };
            out.instances.push(Instance {
                name: s(r.name_off, r.name_len)?,
                xform: Affine(r.xform),
                target,
                material: (r.material != u32::MAX).then_some(r.material),
            });
        }
        Some(out)
    }

    /// What a reader checks (the section's meaning; its bytes were checksummed): objects
    /// cover full-detail parts in order and their trees lie in the top-level tree, groups'
    /// instances exist, instances name existing objects, later groups only (no cycles, at most
    /// [`megaray_base::MAX_NESTING`] levels) and existing materials, with finite, invertible
    /// transforms. Returns what is wrong.
    pub fn check(&self, full_parts: u32, top_nodes: u32, materials: u32) -> Result<(), String> {
        if self.groups.is_empty() {
            return Err("instances without a root group".into());
        }
        let mut next_part = 0u64;
        for (i, o) in self.objects.iter().enumerate() {
            let parts_end = o.first_part as u64 + o.part_count as u64;
            let nodes_end = o.root as u64 + o.node_count as u64;
            if o.first_part as u64 != next_part || o.part_count == 0 || parts_end > full_parts as u64 {
                return Err(format!("object {i}: parts {}..{parts_end} out of order or range", o.first_part));
            }
            if o.node_count == 0 || nodes_end > top_nodes as u64 {
                return Err(format!("object {i}: tree nodes {}..{nodes_end} outside the top-level tree", o.root));
            }
            next_part = parts_end;
        }
        if next_part != full_parts as u64 {
            return Err(format!("objects cover {next_part} parts of {full_parts}"));
        }
        for (g, gr) in self.groups.iter().enumerate() {
            let end = gr.first as u64 + gr.count as u64;
            if end > self.instances.len() as u64 {
                return Err(format!("group {g}: instances {}..{end} of {}", gr.first, self.instances.len()));
            }
            for k in gr.first..end as u32 {
                let inst = &self.instances[k as usize];
                let ok = match inst.target {
                    Target::Object(o) => (o as usize) < self.objects.len(),
                    Target::Group(h) => h as usize > g && (h as usize) < self.groups.len(),
                };
                if !ok {
                    return Err(format!(
                        "instance {k} of group {g}: bad target {:?} (groups name later groups only)",
                        inst.target
                    ));
                }
            }
        }
        // Levels of groups below each (groups name later ones only: from the last), at most
        // `MAX_NESTING`: the tracer recurses through them.
        let mut levels = vec![0u32; self.groups.len()];
        for g in (0..self.groups.len()).rev() {
            let gr = &self.groups[g];
            for inst in &self.instances[gr.first as usize..(gr.first + gr.count) as usize] {
                if let Target::Group(h) = inst.target {
                    levels[g] = levels[g].max(levels[h as usize] + 1);
                }
            }
            if levels[g] > megaray_base::MAX_NESTING {
                return Err(format!("group {g}: groups nest more than {} levels deep", megaray_base::MAX_NESTING));
            }
        }
        for (k, inst) in self.instances.iter().enumerate() {
            if inst.xform.inverse().is_none() {
                return Err(format!("instance {k}: transform not finite or not invertible"));
            }
            if inst.material.is_some_and(|m| m >= materials) {
                return Err(format!("instance {k}: material {:?} of {materials}", inst.material));
            }
        }
        Ok(())
    }

    /// Each group's box in its own space, from the last group to the first (groups name
    /// only later ones).
    pub fn group_bounds(&self) -> Vec<Aabb> {
        let mut out = vec![Aabb::EMPTY; self.groups.len()];
        for g in (0..self.groups.len()).rev() {
            let gr = &self.groups[g];
            let mut b = Aabb::EMPTY;
            for inst in &self.instances[gr.first as usize..(gr.first + gr.count) as usize] {
                let inner = match inst.target {
                    Target::Object(o) => self.objects[o as usize].bounds,
                    Target::Group(h) => out[h as usize],
                };
                b.grow(&inst.xform.aabb(&inner));
            }
            out[g] = b;
        }
        out
    }

    /// Triangles the scene shows, every instance counted (saturating at `u128::MAX`).
    pub fn instanced_triangles(&self) -> u128 {
        let mut tris = vec![0u128; self.groups.len()];
        for g in (0..self.groups.len()).rev() {
            let gr = &self.groups[g];
            let mut n = 0u128;
            for inst in &self.instances[gr.first as usize..(gr.first + gr.count) as usize] {
                n = n.saturating_add(match inst.target {
                    Target::Object(o) => self.objects[o as usize].tri_count as u128,
                    Target::Group(h) => tris[h as usize],
                });
            }
            tris[g] = n;
        }
        tris.first().copied().unwrap_or(0)
    }

    /// Instances the scene places, every nesting expanded (saturating).
    pub fn expanded_instances(&self) -> u128 {
        let mut n = vec![0u128; self.groups.len()];
        for g in (0..self.groups.len()).rev() {
            let gr = &self.groups[g];
            n[g] = self.instances[gr.first as usize..(gr.first + gr.count) as usize]
                .iter()
                .map(|i| match i.target {
                    Target::Object(_) => 1,
                    Target::Group(h) => n[h as usize],
                })
                .fold(0u128, |a, b| a.saturating_add(b));
        }
        n.first().copied().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use megaray_base::Vec3;

    fn sample() -> Instancing {
        let obj = |name: &str, first_part, root| Object {
            name: name.into(),
            bounds: Aabb { min: [0.0; 3], max: [1.0; 3] },
            first_part,
            part_count: 1,
            root,
            node_count: 1,
            tri_count: 10,
        };
        let inst = |target, x: f32| Instance {
            name: format!("at {x}"),
            xform: Affine::translation(Vec3::new(x, 0.0, 0.0)),
            target,
            material: None,
        };
        Instancing {
            objects: vec![obj("tree", 0, 0), obj("rock", 1, 1)],
            groups: vec![
                Group { name: "scene".into(), first: 0, count: 2 },
                Group { name: "grove".into(), first: 2, count: 3 },
            ],
            instances: vec![
                inst(Target::Group(1), 0.0),
                inst(Target::Group(1), 10.0),
                inst(Target::Object(0), 0.0),
                inst(Target::Object(0), 2.0),
                Instance { material: Some(0), ..inst(Target::Object(1), 4.0) },
            ],
        }
    }

    #[test]
    fn round_trip_and_counts() {
        let s = sample();
        let b = s.encode();
        let back = Instancing::decode(&b, 2, 2, 5).unwrap();
        assert_eq!(back, s);
        assert!(s.check(2, 2, 1).is_ok());
        assert_eq!(s.instanced_triangles(), 60);
        assert_eq!(s.expanded_instances(), 6);
        let gb = s.group_bounds();
        // Moved boxes are widened by a few ulps (rounding never leaves a corner out).
        let want = Aabb { min: [0.0; 3], max: [15.0, 1.0, 1.0] };
        assert!(
            gb[0].contains(&want) && (0..3).all(|k| (gb[0].max[k] - want.max[k]).abs() < 1e-4 && gb[0].min[k] > -1e-4)
        );
        assert!(Instancing::decode(&b[..100], 2, 2, 5).is_none());
    }

    #[test]
    fn bad_sections_are_refused() {
        let mut s = sample();
        s.instances[2].target = Target::Group(0);
        assert!(s.check(2, 2, 1).unwrap_err().contains("later groups"));
        let mut s = sample();
        s.instances[0].xform = Affine::scale(Vec3::ZERO);
        assert!(s.check(2, 2, 1).is_err());
        assert!(sample().check(3, 2, 1).is_err(), "parts left out of every object");
        assert!(sample().check(2, 1, 1).is_err(), "a tree beyond the top-level nodes");
        assert!(sample().check(2, 2, 0).is_err(), "a material that does not exist");
    }

    /// Groups nested `MAX_NESTING` levels below the scene are read; one more is refused (the
    /// tracer recurses through them).
    #[test]
    fn nesting_deeper_than_the_limit_is_refused() {
        let chain = |levels: u32| {
            let mut s = sample();
            // Group g places group g + 1, the last the tree.
            let n = levels + 1;
            s.groups = (0..n).map(|g| Group { name: format!("g{g}"), first: g, count: 1 }).collect();
            s.instances = (0..n)
                .map(|g| Instance {
                    name: String::new(),
                    xform: Affine::IDENTITY,
                    target: if g + 1 < n { Target::Group(g + 1) } else { Target::Object(0) },
                    material: None,
                })
                .collect();
            s.objects.truncate(1);
            s
        };
        assert!(chain(megaray_base::MAX_NESTING).check(1, 2, 1).is_ok());
        let e = chain(megaray_base::MAX_NESTING + 1).check(1, 2, 1).unwrap_err();
        assert!(e.contains("more than 256 levels"), "{e}");
    }
}
