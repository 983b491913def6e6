//! # megaray-render: images from a scene
//!
//! [`render`] shoots camera rays through a [`Tracer`] in 32x32 pixel tiles spread over
//! threads (rayon), shades each hit and writes an [`Image`]:
//! Lambertian surfaces under one directional light with pixel-accurate hard shadows (one
//! shadow ray per hit), a plain sky where rays miss, `spp` jittered samples per pixel.
//!
//! ```no_run
//! use megaray_scene::Scene;
//! use megaray_trace::Tracer;
//! use megaray_render::{render, Camera, RenderSettings, DEFAULT_OFFSET};
//! let scene = Scene::open("model.mray".as_ref()).unwrap();
//! let cam = Camera::framing(&scene.header().bounds, DEFAULT_OFFSET, 1024, 768);
//! let img = render(&Tracer::new(&scene), &RenderSettings::new(cam));
//! img.save_png("out.png".as_ref()).unwrap();
//! ```

mod camera;
mod image_out;

pub use camera::{Camera, CLOSE_OFFSET, DEFAULT_OFFSET};
pub use image_out::{Image, ImageError};

use megaray_base::{hash32, u01, Ray, Vec3};
use megaray_trace::{Hit, Tracer};
use rayon::prelude::*;

/// The direction toward the benchmark light, normalize(0.5, 1, 0.8).
pub fn default_light() -> Vec3 {
    Vec3::new(0.5, 1.0, 0.8).normalize()
}

/// How to render.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub camera: Camera,
    /// Direction toward the light (normalised by [`render`]).
    pub light: Vec3,
    /// Samples per pixel: 1 is the pixel centre; more are jittered (stratified) in the pixel.
    pub spp: u32,
    /// Radiance of the sky seen where camera rays miss.
    pub sky: [f32; 3],
    /// Light reaching surfaces that the light does not (a constant ambient term).
    pub ambient: f32,
    /// Offset of secondary-ray origins along the normal, as a fraction of the scene diagonal.
    pub eps_scale: f32,
}

impl RenderSettings {
    pub fn new(camera: Camera) -> RenderSettings {
        RenderSettings { camera, light: default_light(), spp: 1, sky: [0.55, 0.7, 0.9], ambient: 0.12, eps_scale: 1e-4 }
    }
}

/// Renders one image. Uses the current rayon pool (install one to choose the thread count).
pub fn render(tracer: &Tracer, s: &RenderSettings) -> Image {
    let cam = &s.camera;
    let (w, h) = (cam.width, cam.height);
    let mut img = Image::new(w, h);
    const TS: u32 = 32;
    let tiles_x = w.div_ceil(TS);
    let tiles: Vec<(u32, u32)> = (0..h.div_ceil(TS)).flat_map(|ty| (0..tiles_x).map(move |tx| (tx, ty))).collect();
    let bounds = tracer.scene().header().bounds;
    let eps = s.eps_scale * bounds.diagonal();
    let light = s.light.normalize();
    let results: Vec<Vec<[f32; 3]>> = tiles
        .par_iter()
        .map(|&(tx, ty)| {
            let mut out = Vec::with_capacity((TS * TS) as usize);
            for y in ty * TS..((ty + 1) * TS).min(h) {
                for x in tx * TS..((tx + 1) * TS).min(w) {
                    out.push(pixel(tracer, s, x, y, light, eps));
                }
            }
            out
        })
        .collect();
    for ((tx, ty), px) in tiles.iter().zip(results) {
        let mut it = px.into_iter();
        for y in ty * TS..((ty + 1) * TS).min(h) {
            for x in tx * TS..((tx + 1) * TS).min(w) {
                img.pixels[(y * w + x) as usize] = it.next().expect("tile pixel count");
            }
        }
    }
    img
}

fn pixel(tracer: &Tracer, s: &RenderSettings, x: u32, y: u32, light: Vec3, eps: f32) -> [f32; 3] {
    let spp = s.spp.max(1);
    let mut acc = Vec3::ZERO;
    // Stratify spp samples over a near-square grid of strata.
    let gx = (spp as f32).sqrt().ceil() as u32;
    let gy = spp.div_ceil(gx);
    for k in 0..spp {
        let (jx, jy) = if spp == 1 {
            (0.5, 0.5)
        } else {
            let seed = hash32((y * s.camera.width + x).wrapping_mul(9781) ^ hash32(k));
            let (sx, sy) = (k % gx, k / gx);
            ((sx as f32 + u01(seed)) / gx as f32, (sy as f32 + u01(hash32(seed))) / gy as f32)
        };
        let ray = s.camera.ray(x as f32 + jx, y as f32 + jy);
        acc += Vec3::from(shade(tracer, s, &ray, light, eps));
    }
    (acc / spp as f32).into()
}

/// The colour seen along a camera ray.
pub fn shade(tracer: &Tracer, s: &RenderSettings, ray: &Ray, light: Vec3, eps: f32) -> [f32; 3] {
    let Some(hit) = tracer.intersect(ray) else { return s.sky };
    let scene = tracer.scene();
    let mut ng = hit.geometric_normal().normalize_or_zero();
    if ng.dot(ray.dir) > 0.0 {
        ng = -ng;
    }
    let n = shading_normal(tracer, &hit, ng);
    let albedo = albedo(tracer, &hit);
    let p = ray.org + ray.dir * hit.t;
    let mut lit = 0.0;
    let cos = n.dot(light);
    if cos > 0.0 && ng.dot(light) > 0.0 {
        let shadow = Ray { org: p + ng * eps, dir: light, t_min: 0.0, t_max: f32::INFINITY };
        if !tracer.occluded(&shadow) {
            lit = cos;
        }
    }
    let _ = scene;
    let k = s.ambient + (1.0 - s.ambient) * lit;
    [albedo[0] * k, albedo[1] * k, albedo[2] * k]
}

fn shading_normal(tracer: &Tracer, hit: &Hit, ng: Vec3) -> Vec3 {
    if let Some(ns) = tracer.scene().normals(hit.part, hit.prim) {
        let w = 1.0 - hit.u - hit.v;
        let n = Vec3::from(ns[0]) * w + Vec3::from(ns[1]) * hit.u + Vec3::from(ns[2]) * hit.v;
        let n = n.normalize_or_zero();
        if n != Vec3::ZERO {
            return if n.dot(ng) < 0.0 { -n } else { n };
        }
    }
    ng
}

fn albedo(tracer: &Tracer, hit: &Hit) -> [f32; 3] {
    let scene = tracer.scene();
    if let Some(c) = scene.colors(hit.part, hit.prim) {
        let w = [1.0 - hit.u - hit.v, hit.u, hit.v];
        let mut a = [0.0; 3];
        for (k, ak) in a.iter_mut().enumerate() {
            *ak = (0..3).map(|i| c[i][k] as f32 / 255.0 * w[i]).sum();
        }
        return a;
    }
    if let Some(d) = scene.material(hit.part, hit.prim).and_then(|m| m.diffuse) {
        return d;
    }
    [0.8, 0.8, 0.8]
}
