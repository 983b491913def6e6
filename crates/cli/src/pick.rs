//! `megaray pick`: what lies under a pixel, exactly. One ray through the full-detail index
//! (no level of detail, whatever a viewer showed there), loading only the tiles along it when
//! the scene is paged; the closest hit's part, triangle, world position (in double precision,
//! from the triangle's corners and the hit's barycentrics), normal and distance.

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

/// Runs `megaray pick`.
pub fn pick(a: PickArgs, bars: &dyn Progress) -> Result<()> {
    let opened = crate::open::scene_for(Some(&a.scene), &a.open, bars)?;
    let (scene, pager) = a.paging.open(&opened.path)?;
    let b = scene.header().bounds;
    let (w, h) = a.res;
    let (px, py) = a.pixel;
    if !(px >= 0.0 && py >= 0.0 && px < w as f32 && py < h as f32) {
        bail!("--pixel {px},{py} lies outside the {w}x{h} image");
    }
    let at = a.at.unwrap_or(b.center());
    let eye = a.eye.unwrap_or_else(|| b.center() + a.cam_offset.unwrap_or(DEFAULT_OFFSET) * b.diagonal());
    if (at - eye).length() == 0.0 || (at - eye).normalize().cross(a.up.normalize_or_zero()).length() < 1e-6 {
        bail!("--eye, --at and --up do not make a camera (eye equals at, or up is parallel to the view)");
    }
    let cam = Camera::look_at(eye, at, a.up, a.fov, w, h);
    // Integer pixels mean their centres.
    let (sx, sy) = if px.fract() == 0.0 && py.fract() == 0.0 { (px + 0.5, py + 0.5) } else { (px, py) };
    let ray = cam.ray(sx, sy);
    let tracer = Tracer::paged_or_new(&scene, pager.as_ref());
    let t0 = Instant::now();
    let hit = tracer.intersect(&ray);
    let secs = t0.elapsed().as_secs_f64();
    if let Some(e) = crate::paging::fault(&tracer) {
        return Err(e.into());
    }
    let loaded = pager.as_ref().map(|p| p.stats().loaded);
    let Some(hit) = hit else {
        if a.json {
            println!("{}", json!({ "hit": false, "seconds": secs, "tiles_loaded": loaded }));
        } else {
            println!("nothing under pixel {px},{py}");
        }
        return Ok(());
    };
    // The point from the corners and barycentrics, in f64.
    let (u, v) = (hit.u as f64, hit.v as f64);
    let c = hit.tri.map(|p| p.map(|x| x as f64));
    let pos: [f64; 3] = std::array::from_fn(|k| (1.0 - u - v) * c[0][k] + u * c[1][k] + v * c[2][k]);
    let n = hit.geometric_normal().normalize_or_zero();
    let n = if n.dot(ray.dir) > 0.0 { -n } else { n };
    let dist = {
        let o = ray.org;
        ((pos[0] - o.x as f64).powi(2) + (pos[1] - o.y as f64).powi(2) + (pos[2] - o.z as f64).powi(2)).sqrt()
    };
    if a.json {
        println!(
            "{}",
            json!({
                "hit": true, "part": hit.part, "triangle": hit.prim, "position": pos,
                "normal": [n.x, n.y, n.z], "distance": dist, "t": hit.t, "u": hit.u, "v": hit.v,
                "seconds": secs, "tiles_loaded": loaded,
            })
        );
    } else {
        println!(
            "part {} triangle {} at ({:.9}, {:.9}, {:.9}), normal ({:.4}, {:.4}, {:.4}), distance {:.9} ({:.3} ms)",
            hit.part,
            hit.prim,
            pos[0],
            pos[1],
            pos[2],
            n.x,
            n.y,
            n.z,
            dist,
            secs * 1e3
        );
    }
    Ok(())
}
