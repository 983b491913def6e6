//! Shading with levels of detail: a surface drawn from a stand-in does not shadow itself, and
//! the budget steers the error (up when a frame's working set does not fit, back when it
//! does).

mod common;

use std::path::{Path, PathBuf};

use common::*;
use megaray_base::Vec3;
use megaray_page::{Pager, PagerOptions};
use megaray_render::*;
use megaray_scene::Scene;
use megaray_trace::Tracer;

/// A gently rolling field of `n` x `n` squares, 1 unit each: at full detail no part of it
/// shadows another under a high sun.
fn field(dir: &Path, n: usize) -> std::path::PathBuf {
    let h = |x: usize, y: usize| 0.4 * ((x as f32 * 0.11).sin() + (y as f32 * 0.07).cos());
    let mut obj = Obj::default();
    for y in 0..n {
        for x in 0..n {
            let p = |x: usize, y: usize| Vec3::new(x as f32, h(x, y), y as f32);
            obj.quad([p(x, y), p(x, y + 1), p(x + 1, y + 1), p(x + 1, y)]);
        }
    }
    obj.build(dir, "field", None)
}

fn luminance_of(img: &Image) -> Vec<f32> {
    img.pixels.iter().map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]).collect()
}

#[test]
fn stand_ins_do_not_shadow_themselves() {
    let dir = tempfile::tempdir().unwrap();
    let path = field(dir.path(), 260);
    let scene = Scene::open(&path).unwrap();
    assert!(scene.header().lod_part_count > 0);
    let b = scene.header().bounds;
    let cam = Camera::look_at(b.center() + Vec3::new(0.0, 150.0, 260.0), b.center(), Vec3::Y, 50.0, 96, 72);
    let mut s = RenderSettings::new(cam);
    s.shader = Builtin::Diffuse;
    s.light = Vec3::new(0.3, 1.0, 0.2);
    s.ambient = 0.1;
    let r = Renderer::new(s, &b);
    let full = render_frame(&r, &Tracer::new(&scene), 0).image;
    let coarse_tracer = Tracer::new(&scene).with_lod_error(40.0);
    let coarse = render_frame(&r, &coarse_tracer, 0).image;
    let (lf, lc) = (luminance_of(&full), luminance_of(&coarse));
    let lit = lf.iter().filter(|&&l| l > 0.3).count();
    assert!(lit > 3000, "the field is lit at full detail ({lit} pixels)");
    // The stand-ins were used: the coarse picture differs somewhere.
    assert!(lf.iter().zip(&lc).any(|(a, b)| a != b), "no stand-in was traced");
    // No lit pixel of the full-detail field falls to the ambient term in the coarse one.
    let dark = lf.iter().zip(&lc).filter(|(&a, &b)| a > 0.3 && b < 0.5 * a).count();
    assert_eq!(dark, 0, "{dark} pixels of stand-in surface shadow themselves");
}

/// Generated plant `spec` built into `dir` with levels of detail, and a 160x120 view of it.
fn plant(dir: &Path, spec: &str) -> (PathBuf, Scene, Camera) {
    let ply = dir.join("plant.ply");
    megaray_gen::write_ply(&spec.parse().unwrap(), &ply, &megaray_base::NoProgress).unwrap();
    let path = build_file(dir, &ply, "plant");
    let scene = Scene::open(&path).unwrap();
    let cam = Camera::framing(&scene.header().bounds, Vec3::new(0.1, 0.3, 0.45), 160, 120);
    (path, scene, cam)
}

#[test]
fn the_budget_steers_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let (path, scene, cam) = plant(dir.path(), "plant:200k");
    let b = scene.header().bounds;
    let mut s = RenderSettings::new(cam);
    s.stand_in = true;
    let r = Renderer::new(s, &b);
    let stop = Stop { frames: Some(8), time: None };
    // Far below the working set: the error rises, resident bytes stay within the budget.
    let small = Pager::min_budget(&scene) + 256 * 1024;
    let pager = Pager::open(&path, PagerOptions { budget: small, fetchers: 2 }).unwrap();
    let tracer = Tracer::paged(&pager).with_lod_error(1.0);
    let acc = render_progressive(&r, &tracer, stop, |_| {});
    assert_eq!(acc.unfinished(), 0);
    let st = pager.stats();
    assert!(st.peak_resident <= st.tile_budget, "{st:?}");
    assert!(tracer.lod_error() > 1.0, "the error stayed at {} under a budget of {small}", tracer.lod_error());
    // A budget that holds the whole scene: the error stays as asked.
    let pager = Pager::open(&path, PagerOptions { budget: 1 << 30, fetchers: 2 }).unwrap();
    let tracer = Tracer::paged(&pager).with_lod_error(1.0);
    render_progressive(&r, &tracer, stop, |_| {});
    assert_eq!(tracer.lod_error(), 1.0);
}

/// Two governors over one pager (two pages of `serve`): the newer steers, by the working set
/// of what was looked up; the older follows the error it finds and leaves the working set
/// alone (beginning a new one would cut the other's frame short).
#[test]
fn of_two_governors_over_one_pager_the_newer_steers() {
    let dir = tempfile::tempdir().unwrap();
    let (path, scene, cam) = plant(dir.path(), "plant:100k");
    let r = Renderer::new(RenderSettings::new(cam), &scene.header().bounds);
    let pager =
        Pager::open(&path, PagerOptions { budget: Pager::min_budget(&scene) + 64 * 1024, fetchers: 2 }).unwrap();
    let tracer = Tracer::paged(&pager).with_lod_error(1.0);
    let mut older = LodGovernor::new(&tracer);
    let mut newer = LodGovernor::new(&tracer);
    render_frame(&r, &tracer, 0);
    let looked_up = pager.working_set_bytes();
    assert!(looked_up > pager.stats().tile_budget, "{looked_up} bytes looked up fit the budget");
    tracer.set_lod_error(3.0);
    assert_eq!(older.after_frame(&tracer), 3.0);
    assert_eq!(pager.working_set_bytes(), looked_up);
    assert_eq!(newer.after_frame(&tracer), 1.5);
    assert_eq!((tracer.lod_error(), pager.working_set_bytes()), (1.5, 0));
}
