//! `megaray pick`: what lies under a pixel, exactly. One ray through the full-detail index
//! (no level of detail, whatever a viewer showed there), loading only the tiles along it when
//! the scene is paged ([`megaray_view::pick`]); the closest hit's component name, part,
//! triangle, world position (in double precision, from the triangle's corners and the hit's
//! barycentrics), normal, distance and what lies behind; with `--to`, a second pick and the
//! distance between the two.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use megaray_base::{Camera, Progress, Vec3, DEFAULT_OFFSET};
use megaray_trace::Tracer;
use serde_json::json;

use crate::cmd::{parse_res, parse_vec3};

/// `megaray pick`.
#[derive(Args)]
pub struct PickArgs {
    /// Scene file (.mray) or model file (built into the cache first).
    scene: PathBuf,
    /// The pixel, `X,Y` from the top left (its centre unless fractions are given: `10.25,4.5`).
    #[arg(long, value_name = "X,Y", value_parser = parse_pixel)]
    pixel: (f32, f32),
    /// A second pixel: pick there too and measure the distance between the two points.
    #[arg(long, value_name = "X,Y", value_parser = parse_pixel)]
    to: Option<(f32, f32)>,
    /// Image size the pixel is in.
    #[arg(long, value_name = "WxH", default_value = "1024x1024", value_parser = parse_res)]
    res: (u32, u32),
    /// Camera position (default: from --cam-offset).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    eye: Option<Vec3>,
    /// Point looked at (default: the scene's centre).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    at: Option<Vec3>,
    /// World up direction.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, default_value = "0,1,0", allow_hyphen_values = true)]
    up: Vec3,
    /// Vertical field of view, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 60.0)]
    fov: f32,
    /// Camera at centre + offset * diagonal (as `render`).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    cam_offset: Option<Vec3>,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    paging: crate::paging::PagingArgs,
    #[command(flatten)]
    open: crate::open::OpenArgs,
}

fn parse_pixel(s: &str) -> Result<(f32, f32), String> {
    let v: Vec<f32> =
        s.split(',').map(|t| t.trim().parse::<f32>()).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
    match v[..] {
        [x, y] if x.is_finite() && y.is_finite() => Ok((x, y)),
        _ => Err(format!("expected X,Y, got '{s}'")),
    }
}

/// One pick as `--json` gives it.
fn pick_json(pk: &Option<megaray_view::Picked>, secs: f64, loaded: Option<u64>) -> serde_json::Value {
    match pk {
        None => json!({ "hit": false, "seconds": secs, "tiles_loaded": loaded }),
        Some(pk) => json!({
            "hit": true, "component": pk.name, "part": pk.part, "triangle": pk.triangle,
            "position": pk.position, "normal": pk.normal, "distance": pk.distance, "t": pk.t,
            "front": pk.front, "behind": pk.behind, "seconds": secs, "tiles_loaded": loaded,
        }),
    }
}

/// Runs `megaray pick`.
pub fn pick(a: PickArgs, bars: &dyn Progress) -> Result<()> {
    let opened = crate::open::scene_for(Some(&a.scene), &a.open, bars)?;
    let (scene, pager) = a.paging.open(&opened.path)?;
    let b = scene.header().bounds;
    let (w, h) = a.res;
    let at = a.at.unwrap_or(b.center());
    let eye = a.eye.unwrap_or_else(|| b.center() + a.cam_offset.unwrap_or(DEFAULT_OFFSET) * b.diagonal());
    if (at - eye).length() == 0.0 || (at - eye).normalize().cross(a.up.normalize_or_zero()).length() < 1e-6 {
        bail!("--eye, --at and --up do not make a camera (eye equals at, or up is parallel to the view)");
    }
    let cam = Camera::look_at(eye, at, a.up, a.fov, w, h);
    let tracer = Tracer::paged_or_new(&scene, pager.as_ref());
    let mut picks = Vec::new();
    for (px, py) in std::iter::once(a.pixel).chain(a.to) {
        if !(px >= 0.0 && py >= 0.0 && px < w as f32 && py < h as f32) {
            bail!("pixel {px},{py} lies outside the {w}x{h} image");
        }
        // Integer pixels mean their centres.
        let (sx, sy) = if px.fract() == 0.0 && py.fract() == 0.0 { (px + 0.5, py + 0.5) } else { (px, py) };
        let loaded0 = pager.as_ref().map_or(0, |p| p.stats().loaded);
        let t0 = Instant::now();
        let found = megaray_view::pick(&tracer, &cam.ray(sx, sy));
        let secs = t0.elapsed().as_secs_f64();
        if let Some(e) = crate::paging::fault(&tracer) {
            return Err(e.into());
        }
        let loaded = pager.as_ref().map(|p| p.stats().loaded - loaded0);
        picks.push(((px, py), found, secs, loaded));
    }
    let measured = match (picks.first(), picks.get(1)) {
        (Some((_, Some(p), ..)), Some((_, Some(q), ..))) => Some(p.distance_to(q)),
        _ => None,
    };
    if a.json {
        let mut objs: Vec<serde_json::Value> =
            picks.iter().map(|(_, pk, secs, loaded)| pick_json(pk, *secs, *loaded)).collect();
        let out = if objs.len() == 1 { objs.remove(0) } else { json!({ "picks": objs, "measured": measured }) };
        println!("{out}");
        return Ok(());
    }
    for ((px, py), pk, secs, _) in &picks {
        let Some(pk) = pk else {
            println!("nothing under pixel {px},{py}");
            continue;
        };
        let [x, y, z] = pk.position;
        let [nx, ny, nz] = pk.normal;
        println!("{}", pk.name.as_deref().unwrap_or("(the scene names no components)"));
        println!(
            "  part {} triangle {} at ({x:.9}, {y:.9}, {z:.9}), normal ({nx:.4}, {ny:.4}, {nz:.4}), distance {:.9} ({:.3} ms)",
            pk.part,
            pk.triangle,
            pk.distance,
            secs * 1e3
        );
        match pk.behind {
            Some(b) if pk.front => println!("  behind it: the next surface at {b:.9} (the wall's thickness)"),
            Some(b) => println!("  behind it: the next surface at {b:.9} (the clearance)"),
            None => println!("  behind it: nothing"),
        }
    }
    if let Some(d) = measured {
        println!("distance between the two points: {d:.9}");
    }
    Ok(())
}
