//! `megaray info`: what a scene file holds (counts, bounds, bytes per triangle by kind,
//! levels of detail, instances, the trees' statistics).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use megaray_base::format_size;
use megaray_scene::Scene;

#[derive(Args)]
pub struct InfoArgs {
    /// The scene file.
    scene: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Also check every tile's checksum (reads the whole file).
    #[arg(long)]
    verify: bool,
    /// List the model's components (the parts as its user knows them: input files, OBJ
    /// objects and groups, glTF node paths), with their triangle counts.
    #[arg(long)]
    parts: bool,
    /// Also walk every part's tree: node and leaf counts, child-slot fill and the SAH cost
    /// as Embree's `verbose=2` statistics measure it (reads every node of the file).
    #[arg(long)]
    tree: bool,
}

pub fn info(a: InfoArgs) -> Result<()> {
    // The tables suffice (a compact file is then not decoded); walking trees reads them in
    // core, and so does checking tiles when the scene fits in memory (else tile by tile).
    let probe = Scene::open_owned(&a.scene)?;
    let in_core = a.tree || (a.verify && megaray_scene::fits_in_memory(probe.bytes().len() as u64));
    let scene = if in_core { Scene::open(&a.scene)? } else { probe };
    if a.verify {
        match scene.is_owned() {
            true => scene.verify_tile_by_tile()?,
            false => scene.verify_all()?,
        }
    }
    let h = *scene.header();
    // The full-detail parts (the levels of detail after them are reported on their own).
    let full = scene.full_part_count();
    let parts = &scene.parts()[..full as usize];
    let tiles: Vec<_> = scene.tiles().iter().filter(|t| t.part < full).copied().collect();
    let stored = scene.stored_bytes();
    let lod_bytes = stored.lod;
    let lod_errors: Vec<f32> = scene.parts()[full as usize..].iter().map(|p| p.lod_error).collect();
    let lod_levels = parts.iter().enumerate().map(|(i, _)| scene.lod_chain(i as u32).count() - 1).max().unwrap_or(0);
    let n = h.tri_count.max(1) as f64;
    let (node_bytes, tri_bytes, padding) = (stored.nodes, stored.triangles, stored.padding);
    let slots: u64 = parts.iter().map(|p| p.slot_count).sum();
    let fill = h.tri_count as f64 / slots.max(1) as f64;
    let (attr_bytes, meta) = (stored.attributes, stored.tables);
    let depths: Vec<u32> = parts.iter().map(|p| p.depth).collect();
    let (dmin, dmax) = (depths.iter().min().copied().unwrap_or(0), depths.iter().max().copied().unwrap_or(0));
    let tile_sizes: Vec<u32> = tiles.iter().map(|t| t.bytes).collect();
    let tmean = tile_sizes.iter().map(|&b| b as f64).sum::<f64>() / tile_sizes.len().max(1) as f64;
    let tree = a.tree.then(|| scene.tree_stats());
    let comps = scene.components();
    if a.json {
        let tree = tree.map(|t| {
            serde_json::json!({
                "inner_nodes": t.inner_nodes, "child_slots": t.child_slots, "leaves": t.leaves,
                "blocks": t.blocks, "sah": t.sah(), "sah_nodes": t.sah_nodes, "sah_leaves": t.sah_leaves,
            })
        });
        println!(
            "{}",
            serde_json::json!({
                "file": a.scene, "format_version": h.version, "file_bytes": h.file_bytes,
                "compact": h.is_compact(), "image_bytes": h.image_len(),
                "triangles": h.tri_count, "degenerate_dropped": h.degenerate_dropped,
                "bounds": {"min": h.bounds.min, "max": h.bounds.max},
                "parts": full, "tiles": tiles.len(), "tile_target": h.tile_target,
                "lod": {"parts": h.lod_part_count, "levels_max": lod_levels, "bytes": lod_bytes,
                        "fraction_of_file": lod_bytes as f64 / h.file_bytes as f64,
                        "error_min": lod_errors.iter().copied().fold(f32::INFINITY, f32::min),
                        "error_max": lod_errors.iter().copied().fold(0.0, f32::max)},
                "tile_bytes_mean": tmean, "materials": h.material_count, "block_fill": fill,
                "top_depth": h.top_depth, "top_nodes": h.top_node_count,
                "part_depth_min": dmin, "part_depth_max": dmax,
                "attributes": {"normals": h.attr_flags & 1 != 0, "uvs": h.attr_flags & 2 != 0,
                               "colors": h.attr_flags & 4 != 0, "materials": h.attr_flags & 8 != 0},
                "bytes_per_triangle": {
                    "total": h.file_bytes as f64 / n, "nodes": node_bytes as f64 / n,
                    "triangle_blocks": tri_bytes as f64 / n, "tile_padding": padding as f64 / n,
                    "attributes": attr_bytes as f64 / n, "tables": meta as f64 / n,
                    "levels_of_detail": lod_bytes as f64 / n,
                },
                "verified": a.verify,
                "tree": tree,
                "instances": instances_json(&scene),
                "components": {"count": comps.names.len(), "runs": comps.runs.len(),
                               "section_bytes": h.components_bytes},
                "component_list": a.parts.then(|| comps.names.iter().zip(&comps.tri_counts)
                    .map(|(n, t)| serde_json::json!({"name": n, "triangles": t})).collect::<Vec<_>>()),
            })
        );
        return Ok(());
    }
    println!("{} (scene format version {})", a.scene.display(), h.version);
    println!("  triangles        {} ({} degenerate dropped at build)", h.tri_count, h.degenerate_dropped);
    println!("  bounds           {:?} .. {:?}", h.bounds.min, h.bounds.max);
    println!("  parts            {} (top-level tree: {} nodes, depth {})", full, h.top_node_count, h.top_depth);
    println!("  part tree depth  {dmin} .. {dmax}");
    println!(
        "  tiles            {} (target {}, mean payload {})",
        tiles.len(),
        format_size(h.tile_target as u64),
        format_size(tmean as u64)
    );
    println!("  materials        {}", h.material_count);
    if comps.is_empty() {
        println!("  components       none named (the scene was built from one input with no groups)");
    } else {
        println!(
            "  components       {} ({} runs, {} = {:.1} bytes a component; --parts lists them)",
            comps.names.len(),
            comps.runs.len(),
            format_size(h.components_bytes),
            h.components_bytes as f64 / comps.names.len() as f64
        );
    }
    if let Some(i) = scene.instancing() {
        let shown = i.instanced_triangles();
        println!(
            "  instances        {} objects, {} groups, {} instances ({} placed with every group expanded)",
            i.objects.len(),
            i.groups.len(),
            i.instances.len(),
            i.expanded_instances()
        );
        println!(
            "  instanced tris   {shown} ({:.3e}; {:.0} bytes per instance in the file)",
            shown as f64,
            h.instances_bytes as f64 / i.instances.len().max(1) as f64
        );
    }
    let kind = match h.is_compact() {
        true => format!("compact, {} once loaded", format_size(h.image_len())),
        false => "plain".to_string(),
    };
    println!(
        "  file             {} = {:.1} bytes/triangle ({kind}):",
        format_size(h.file_bytes),
        h.file_bytes as f64 / n
    );
    println!("    nodes          {:.1}", node_bytes as f64 / n);
    println!("    triangles      {:.1} (blocks of 4, {:.0}% of lanes used)", tri_bytes as f64 / n, 100.0 * fill);
    println!("    tile padding   {:.1}", padding as f64 / n);
    println!("    attributes     {:.1}", attr_bytes as f64 / n);
    println!("    tables, header {:.1}", meta as f64 / n);
    if h.lod_part_count > 0 {
        println!(
            "    levels of detail {:.1} ({}, {:.1}% of the file: {} parts, up to {} levels a part, errors {:.3e} .. {:.3e})",
            lod_bytes as f64 / n,
            format_size(lod_bytes),
            100.0 * lod_bytes as f64 / h.file_bytes as f64,
            h.lod_part_count,
            lod_levels,
            lod_errors.iter().copied().fold(f32::INFINITY, f32::min),
            lod_errors.iter().copied().fold(0.0, f32::max)
        );
    } else {
        println!("    levels of detail none (built with --no-lod)");
    }
    if let Some(t) = tree {
        println!(
            "  tree             {} inner nodes ({:.0}% of child slots used), {} leaves, {} blocks",
            t.inner_nodes,
            100.0 * t.child_slots as f64 / (8 * t.inner_nodes.max(1)) as f64,
            t.leaves,
            t.blocks
        );
        println!("    SAH cost       {:.3} = nodes {:.3} + leaves {:.3}", t.sah(), t.sah_nodes, t.sah_leaves);
    }
    if a.verify {
        println!("  every tile's checksum verified");
    }
    if a.parts {
        println!("components:");
        for (name, tris) in comps.names.iter().zip(&comps.tri_counts) {
            println!("  {tris:>12}  {name}");
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------

/// The scene's objects, groups and instances for `--json` (`null` without instances).
fn instances_json(scene: &Scene) -> serde_json::Value {
    let Some(i) = scene.instancing() else { return serde_json::Value::Null };
    serde_json::json!({
        "objects": i.objects.len(), "groups": i.groups.len(), "instances": i.instances.len(),
        "expanded_instances": i.expanded_instances().to_string(),
        "instanced_triangles": i.instanced_triangles().to_string(),
        "instanced_triangles_f64": i.instanced_triangles() as f64,
        "section_bytes": scene.header().instances_bytes,
        "object_names": i.objects.iter().take(64).map(|o| o.name.clone()).collect::<Vec<_>>(),
    })
}
