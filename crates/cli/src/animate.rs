//! `render --animate N[:spin|:orbit][:NAME]`: rigid motion of instances. Each of N frames
//! moves the chosen instances (those named NAME, else group 0's), rebuilds the instance
//! trees (only they: the objects' trees stay) and renders the frame on its own; `--json`
//! prints each frame's time and the trees' rebuild time.

use std::time::Instant;

use anyhow::{bail, Result};
use megaray_base::{Aabb, Affine, Vec3};
use megaray_render::{render_frame, Renderer};
use megaray_scene::{Instancing, Scene, Target};
use megaray_trace::Tracer;
use serde_json::json;

/// How the chosen instances move.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Motion {
    /// Each turns about the vertical axis through its own centre, a full turn over the frames.
    Spin,
    /// Each circles the centre of its group's box, a full turn over the frames.
    Orbit,
}

/// A parsed `--animate` value.
#[derive(Clone, Debug, PartialEq)]
pub struct Animate {
    pub frames: u32,
    pub motion: Motion,
    /// Instances named so move; `None`: the scene's top-level instances (group 0).
    pub name: Option<String>,
}

pub fn parse_animate(spec: &str) -> Result<Animate> {
    let mut it = spec.split(':');
    let frames = it.next().and_then(|n| n.parse::<u32>().ok()).filter(|&n| n >= 1);
    let motion = match it.next() {
        None | Some("spin") => Some(Motion::Spin),
        Some("orbit") => Some(Motion::Orbit),
        Some(_) => None,
    };
    let name = it.next().map(str::to_string);
    match (frames, motion, it.next()) {
        (Some(frames), Some(motion), None) => Ok(Animate { frames, motion, name }),
        _ => bail!(
            "--animate: expected N[:spin|:orbit][:NAME] with N >= 1 (e.g. 60, 60:orbit, 60:spin:grove), got `{spec}`"
        ),
    }
}

/// The instances to move and, for each, its transform at rest and the point it turns about
/// (in its group's space).
fn chosen(inst: &Instancing, a: &Animate) -> Result<Vec<(usize, Affine, Vec3)>> {
    let groups = inst.group_bounds();
    let group_of: Vec<usize> = {
        let mut g = vec![0; inst.instances.len()];
        for (gi, gr) in inst.groups.iter().enumerate() {
            g[gr.first as usize..(gr.first + gr.count) as usize].fill(gi);
        }
        g
    };
    let mut out = Vec::new();
    for (k, i) in inst.instances.iter().enumerate() {
        let take = match &a.name {
            Some(n) => &i.name == n,
            None => group_of[k] == 0,
        };
        if !take {
            continue;
        }
        let inner: Aabb = match i.target {
            Target::Object(o) => inst.objects[o as usize].bounds,
            Target::Group(h) => groups[h as usize],
        };
        let pivot = match a.motion {
            Motion::Spin => i.xform.aabb(&inner).center(),
            Motion::Orbit => groups[group_of[k]].center(),
        };
        out.push((k, i.xform, pivot));
    }
    if out.is_empty() {
        bail!("--animate: no instance named `{}`", a.name.as_deref().unwrap_or(""));
    }
    Ok(out)
}

/// Renders the animation; returns the last frame's image.
pub fn run(
    a: &Animate,
    scene: &Scene,
    r: &Renderer,
    tracer: &mut Tracer,
    pool: &rayon::ThreadPool,
    json: bool,
) -> Result<megaray_render::Image> {
    let Some(inst) = scene.instancing() else {
        bail!("{}: --animate moves instances, and this scene has none", scene.path().display());
    };
    let moving = chosen(inst, a)?;
    let (mut rebuilds, mut frames) = (Vec::new(), Vec::new());
    let mut last = None;
    let start = Instant::now();
    for f in 0..a.frames {
        let turn = 360.0 * (f + 1) as f32 / a.frames as f32;
        for &(k, rest, pivot) in &moving {
            let spin = Affine::translation(pivot)
                .then_after(&Affine::rotation(turn, Vec3::Y))
                .then_after(&Affine::translation(-pivot));
            tracer.set_instance_transform(k, spin.then_after(&rest));
        }
        let rebuild = tracer.rebuild_instances().as_secs_f64();
        let t = Instant::now();
        let frame = pool.install(|| render_frame(r, tracer, 0));
        let secs = t.elapsed().as_secs_f64();
        if json {
            println!(
                "{}",
                json!({"frame": f, "top_rebuild_ms": rebuild * 1e3, "frame_seconds": secs, "rays": frame.rays,
                       "moved_instances": moving.len()})
            );
        }
        rebuilds.push(rebuild * 1e3);
        frames.push(secs);
        last = Some(frame.image);
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (rb, fs) = (med(&mut rebuilds), med(&mut frames));
    let total = start.elapsed().as_secs_f64();
    if json {
        println!(
            "{}",
            json!({"frames": a.frames, "moved_instances": moving.len(), "seconds": total,
                   "top_rebuild_ms_median": rb, "top_rebuild_ms_max": rebuilds[rebuilds.len() - 1],
                   "frame_seconds_median": fs})
        );
    } else {
        eprintln!(
            "animate: {} frames, {} instances moving, in {total:.2} s; top-level rebuild median {rb:.2} ms (max {:.2}), frame median {fs:.3} s",
            a.frames,
            moving.len(),
            rebuilds[rebuilds.len() - 1]
        );
    }
    Ok(last.expect("at least one frame"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs() {
        assert_eq!(parse_animate("60").unwrap(), Animate { frames: 60, motion: Motion::Spin, name: None });
        let a = parse_animate("8:orbit:grove").unwrap();
        assert_eq!((a.frames, a.motion, a.name.as_deref()), (8, Motion::Orbit, Some("grove")));
        for bad in ["0", "x", "5:wobble", "5:spin:a:b", ""] {
            assert!(parse_animate(bad).is_err(), "{bad}");
        }
    }
}
