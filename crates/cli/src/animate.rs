//! `render --animate N[:spin|:orbit|:path=X,Y,Z/X,Y,Z...][:NAME]`: rigid motion of instances.
//! Each of N frames moves the chosen instances (those named NAME, else group 0's), rebuilds
//! the instance trees (only they: the objects' trees stay) and renders the frame on its own;
//! `--json` prints each frame's time and the trees' rebuild time. Each frame goes to the
//! caller as it is made (`render -o name_####.png` writes them all).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Result};
use megaray_base::{Aabb, Affine, Vec3};
use megaray_render::{render_frame, Renderer};
use megaray_scene::{Instancing, Scene, Target};
use megaray_trace::Tracer;
use serde_json::json;

/// How the chosen instances move.
#[derive(Clone, Debug, PartialEq)]
pub enum Motion {
    /// Each turns about the vertical axis through its own centre, a full turn over the frames.
    Spin,
    /// Each circles the centre of its group's box, a full turn over the frames.
    Orbit,
    /// Each moves along a polyline of displacements from where it rests (in its group's
    /// space), at an even speed: the first frame at the first point, the last at the last.
    Path(Vec<Vec3>),
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
        Some(m) => m.strip_prefix("path=").and_then(parse_path).map(Motion::Path),
    };
    let name = it.next().map(str::to_string);
    match (frames, motion, it.next()) {
        (Some(frames), Some(motion), None) => Ok(Animate { frames, motion, name }),
        _ => bail!(
            "--animate: expected N[:spin|:orbit|:path=X,Y,Z/X,Y,Z...][:NAME] with N >= 1 and a path of two \
             points or more (e.g. 60, 60:orbit, 60:spin:grove, 60:path=0,0,0/10,0,0:grove), got `{spec}`"
        ),
    }
}

/// `X,Y,Z/X,Y,Z/...`: two points or more, finite, and a finite length.
fn parse_path(s: &str) -> Option<Vec<Vec3>> {
    let point = |p: &str| -> Option<Vec3> {
        let v: Vec<f32> =
            p.split(',').map(|x| x.trim().parse::<f32>().ok().filter(|x| x.is_finite())).collect::<Option<_>>()?;
        (v.len() == 3).then(|| Vec3::new(v[0], v[1], v[2]))
    };
    let pts: Vec<Vec3> = s.split('/').map(point).collect::<Option<_>>()?;
    (pts.len() >= 2 && length(&pts).is_finite()).then_some(pts)
}

/// The length of polyline `pts`.
fn length(pts: &[Vec3]) -> f32 {
    pts.windows(2).map(|w| (w[1] - w[0]).length()).sum()
}

/// The point a fraction `s` (0..=1) of the way along polyline `pts` by length (the first
/// point for a path of no length).
fn along(pts: &[Vec3], s: f32) -> Vec3 {
    let total = length(pts);
    let mut left = s.clamp(0.0, 1.0) * total;
    for w in pts.windows(2) {
        let len = (w[1] - w[0]).length();
        if left <= len && len > 0.0 {
            return w[0] + (w[1] - w[0]) * (left / len);
        }
        left -= len;
    }
    if total > 0.0 {
        pts[pts.len() - 1]
    } else {
        pts[0]
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
            Motion::Path(_) => Vec3::ZERO,
        };
        out.push((k, i.xform, pivot));
    }
    if out.is_empty() {
        bail!("--animate: no instance named `{}`", a.name.as_deref().unwrap_or(""));
    }
    Ok(out)
}

/// Renders the animation, each frame's image to `on_frame` (its index, the image) as it is
/// made; returns the last frame's image.
pub fn run(
    a: &Animate,
    scene: &Scene,
    r: &Renderer,
    tracer: &mut Tracer,
    pool: &rayon::ThreadPool,
    json: bool,
    on_frame: &mut dyn FnMut(u32, &megaray_render::Image) -> Result<()>,
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
            let moved = match &a.motion {
                Motion::Path(pts) => {
                    let s = if a.frames > 1 { f as f32 / (a.frames - 1) as f32 } else { 1.0 };
                    Affine::translation(along(pts, s))
                }
                Motion::Spin | Motion::Orbit => Affine::translation(pivot)
                    .then_after(&Affine::rotation(turn, Vec3::Y))
                    .then_after(&Affine::translation(-pivot)),
            };
            tracer.set_instance_transform(k, moved.then_after(&rest));
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
        on_frame(f, &frame.image)?;
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

/// The file of frame `f` of an image sequence named `out`: the last run of `#` in its file
/// name replaced by the frame's number, zero-padded to the run's length (`a_####.png`, frame 7:
/// `a_0007.png`), as Blender names frames. `None` when the name has no `#`.
pub(crate) fn frame_path(out: &Path, f: u32) -> Option<PathBuf> {
    let name = out.file_name()?.to_str()?;
    let end = name.rfind('#')? + 1;
    let start = name[..end].trim_end_matches('#').len();
    let numbered = format!("{}{:0width$}{}", &name[..start], f, &name[end..], width = end - start);
    Some(out.with_file_name(numbered))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs() {
        assert_eq!(parse_animate("60").unwrap(), Animate { frames: 60, motion: Motion::Spin, name: None });
        let a = parse_animate("8:orbit:grove").unwrap();
        assert_eq!((a.frames, a.motion, a.name.as_deref()), (8, Motion::Orbit, Some("grove")));
        let a = parse_animate("3:path=0,0,0/10, 0,0/10,10,0:grove").unwrap();
        let pts = vec![Vec3::ZERO, Vec3::new(10.0, 0.0, 0.0), Vec3::new(10.0, 10.0, 0.0)];
        assert_eq!((a.frames, a.motion, a.name.as_deref()), (3, Motion::Path(pts), Some("grove")));
        for bad in [
            "0",
            "x",
            "5:wobble",
            "5:spin:a:b",
            "",
            "5:path=",
            "5:path=1,2,3",
            "5:path=1,2/3,4",
            "5:path=1,2,3/a,b,c",
            "5:path=1,2,3/4,5,inf",
            "5:path=0,0,0/3e38,0,0/-3e38,0,0",
            "5:path 1,2,3/4,5,6",
        ] {
            assert!(parse_animate(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn frame_files() {
        let f = |out: &str, k: u32| frame_path(Path::new(out), k).map(|p| p.to_string_lossy().into_owned());
        assert_eq!(f("out/a_####.png", 7).as_deref(), Some("out/a_0007.png"));
        assert_eq!(f("a#.exr", 12).as_deref(), Some("a12.exr"), "wider than the run: all digits");
        assert_eq!(f("#x_##_y.png", 3).as_deref(), Some("#x_03_y.png"), "the last run only");
        assert_eq!(f("dir#/a.png", 3), None, "only the file name counts");
        assert_eq!(f("a.png", 0), None);
    }

    /// Points along a polyline by length: its corners, between them, and its ends.
    #[test]
    fn points_along_a_path() {
        let pts = [Vec3::ZERO, Vec3::new(10.0, 0.0, 0.0), Vec3::new(10.0, 10.0, 0.0)];
        for (s, want) in [
            (0.0, Vec3::ZERO),
            (0.25, Vec3::new(5.0, 0.0, 0.0)),
            (0.5, Vec3::new(10.0, 0.0, 0.0)),
            (0.75, Vec3::new(10.0, 5.0, 0.0)),
            (1.0, Vec3::new(10.0, 10.0, 0.0)),
            (2.0, Vec3::new(10.0, 10.0, 0.0)),
        ] {
            assert!((along(&pts, s) - want).length() < 1e-5, "{s}: {:?}", along(&pts, s));
        }
        // No length: the first point throughout.
        assert_eq!(along(&[Vec3::ONE, Vec3::ONE], 0.5), Vec3::ONE);
    }
}
