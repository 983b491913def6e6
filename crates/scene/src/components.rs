//! Components: the pieces of a model as its user knows them (an input file, an OBJ group, a
//! glTF node, a pbrt shape), so that a picked triangle can be named. ("Part" stays the
//! build's word for its spatial pieces; a component may span many parts and a part hold
//! many components.)
//!
//! Nothing is stored per triangle: the build knows each triangle slot's component and
//! writes, per part, the *runs* of slots that share one ([`Run`]: 12 bytes each; BVH leaves
//! are spatially coherent and so are components, so runs are few). The section, in
//! `docs/FORMAT.md` ("Components"): `component_count` [`ComponentRecord`]s (16 bytes),
//! `run_count` [`Run`]s sorted by (part, first slot), then the UTF-8 names.

use bytemuck::{Pod, Zeroable};

/// One component in the file. 16 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ComponentRecord {
    /// Full-detail triangles of the component.
    pub tri_count: u64,
    /// Its name: bytes `name_off .. name_off + name_len` of the names after the runs.
    pub name_off: u32,
    pub name_len: u32,
}
const _: () = assert!(std::mem::size_of::<ComponentRecord>() == 16);

/// Slots `first_slot ..` (up to the next run of the same part, or the part's end) of part
/// `part` belong to component `component`. 12 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Pod, Zeroable)]
pub struct Run {
    pub part: u32,
    pub first_slot: u32,
    pub component: u32,
}
const _: () = assert!(std::mem::size_of::<Run>() == 12);

/// The component table of a scene: names, triangle counts, and the runs that map a
/// (part, slot) to its component.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Components {
    pub names: Vec<String>,
    pub tri_counts: Vec<u64>,
    /// Sorted by (part, first_slot), no two with the same (part, first_slot).
    pub runs: Vec<Run>,
}

impl Components {
    /// Whether the scene has no component table.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// The component of slot `slot` of part `part`, if the table covers it.
    pub fn of(&self, part: u32, slot: u32) -> Option<u32> {
        let key = (part, slot);
        let i = self.runs.partition_point(|r| (r.part, r.first_slot) <= key);
        let r = self.runs.get(i.checked_sub(1)?)?;
        (r.part == part).then_some(r.component)
    }

    /// The name of component `c`.
    pub fn name(&self, c: u32) -> &str {
        self.names.get(c as usize).map_or("", String::as_str)
    }

    /// The section's bytes: records, runs, names.
    pub fn encode(&self) -> Vec<u8> {
        let mut names = Vec::new();
        let mut records = Vec::with_capacity(self.names.len());
        for (n, &tri_count) in self.names.iter().zip(&self.tri_counts) {
            records.push(ComponentRecord { tri_count, name_off: names.len() as u32, name_len: n.len() as u32 });
            names.extend_from_slice(n.as_bytes());
        }
        let mut out = Vec::with_capacity(records.len() * 16 + self.runs.len() * 12 + names.len());
        out.extend_from_slice(bytemuck::cast_slice(&records));
        out.extend_from_slice(bytemuck::cast_slice(&self.runs));
        out.extend_from_slice(&names);
        out
    }

    /// Reads a section of `count` components and `runs` runs, checking every field against
    /// `part_count`: `Err` says what is wrong.
    pub fn decode(bytes: &[u8], count: u32, runs: u32, part_count: u32) -> Result<Components, String> {
        let rec_bytes = count as usize * 16;
        let run_end = rec_bytes + runs as usize * 12;
        if bytes.len() < run_end {
            return Err(format!("{count} components and {runs} runs do not fit in {} bytes", bytes.len()));
        }
        let records: Vec<ComponentRecord> = bytemuck::pod_collect_to_vec(&bytes[..rec_bytes]);
        let run_list: Vec<Run> = bytemuck::pod_collect_to_vec(&bytes[rec_bytes..run_end]);
        let text = &bytes[run_end..];
        let mut names = Vec::with_capacity(records.len());
        for (i, r) in records.iter().enumerate() {
            let end = r.name_off as usize + r.name_len as usize;
            let name = text
                .get(r.name_off as usize..end)
                .and_then(|b| std::str::from_utf8(b).ok())
                .ok_or_else(|| format!("component {i}: name outside the section or not UTF-8"))?;
            names.push(name.to_string());
        }
        for (i, r) in run_list.iter().enumerate() {
            if r.part >= part_count || r.component >= count {
                return Err(format!(
                    "run {i} names part {} / component {} (of {part_count} / {count})",
                    r.part, r.component
                ));
            }
            if i > 0 && run_list[i - 1] >= *r {
                return Err(format!("run {i} is out of order"));
            }
        }
        Ok(Components { names, tri_counts: records.iter().map(|r| r.tri_count).collect(), runs: run_list })
    }
}

/// Runs of one part from its slots' components (`None` for padding slots, which join the
/// run before them): `(first_slot, component)`, a new one wherever the component changes.
pub fn runs_of(slots: impl IntoIterator<Item = Option<u32>>) -> Vec<(u32, u32)> {
    let mut out: Vec<(u32, u32)> = Vec::new();
    for (s, c) in slots.into_iter().enumerate() {
        let Some(c) = c else { continue };
        if out.last().is_none_or(|&(_, last)| last != c) {
            out.push((if out.is_empty() { 0 } else { s as u32 }, c));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> Components {
        Components {
            names: vec!["a.obj".into(), "a.obj/g wheel".into(), "b.ply".into()],
            tri_counts: vec![3, 5, 7],
            runs: vec![
                Run { part: 0, first_slot: 0, component: 0 },
                Run { part: 0, first_slot: 8, component: 1 },
                Run { part: 2, first_slot: 0, component: 2 },
            ],
        }
    }

    #[test]
    fn a_slot_finds_its_run() {
        let t = table();
        assert_eq!(t.of(0, 0), Some(0));
        assert_eq!(t.of(0, 7), Some(0));
        assert_eq!(t.of(0, 8), Some(1));
        assert_eq!(t.of(0, 1000), Some(1));
        assert_eq!(t.of(1, 3), None, "part 1 has no runs");
        assert_eq!(t.of(2, 5), Some(2));
        assert_eq!(t.of(3, 0), None);
        assert_eq!(t.name(1), "a.obj/g wheel");
    }

    #[test]
    fn the_section_round_trips_and_lies_are_refused() {
        let t = table();
        let bytes = t.encode();
        assert_eq!(bytes.len(), 3 * 16 + 3 * 12 + "a.obja.obj/g wheelb.ply".len());
        assert_eq!(Components::decode(&bytes, 3, 3, 3).unwrap(), t);
        assert!(Components::decode(&bytes, 3, 3, 2).unwrap_err().contains("run 2"), "a part out of range");
        assert!(Components::decode(&bytes, 4, 3, 3).is_err(), "a count the bytes cannot hold");
        assert!(Components::decode(&bytes, 3, 1_000_000_000, 3).is_err(), "a lying run count");
        let mut swapped = t.clone();
        swapped.runs.swap(0, 1);
        assert!(Components::decode(&swapped.encode(), 3, 3, 3).unwrap_err().contains("order"));
        let mut long = bytes.clone();
        long[12..16].copy_from_slice(&1000u32.to_le_bytes());
        assert!(Components::decode(&long, 3, 3, 3).unwrap_err().contains("component 0"));
    }

    #[test]
    fn runs_start_where_the_component_changes() {
        let slots = [Some(4), Some(4), None, Some(4), Some(1), None, None, Some(4)];
        assert_eq!(runs_of(slots), vec![(0, 4), (4, 1), (7, 4)]);
        assert_eq!(runs_of([None, Some(2), Some(2)]), vec![(0, 2)], "the first run covers the part's start");
        assert!(runs_of([None; 4]).is_empty());
    }
}
