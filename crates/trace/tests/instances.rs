//! Instances: a scene of objects placed by transforms (rotation, non-uniform scale,
//! mirroring), in groups nested three deep, gives the hits of its triangles expanded into
//! the world, mapped, paged and after instances move.

use megaray_base::{Affine, Ray, Vec3, WatertightRay};
use megaray_build::InstancePlan;
use megaray_page::{Pager, PagerOptions};
use megaray_scene::{Group, Instance, Scene, Target};
use megaray_testkit::*;
use megaray_trace::jobs::{self, JobOptions};
use megaray_trace::{RayCaster, Tracer};

fn inst(target: Target, xform: Affine) -> Instance {
    Instance { name: String::new(), xform, target, material: None }
}

/// Three objects (two spheres and a small plant) and groups 3 deep:
/// group 0 = {A rotated and stretched, A mirrored, group 1 twice};
/// group 1 = {B, group 2}; group 2 = {A mirrored and squashed, C}.
fn model(dir: &std::path::Path) -> (Vec<Vec<Tri>>, InstancePlan) {
    let ply = gen(dir, "plant:6k");
    let mut c = Vec::new();
    let mut sink = Collect(&mut c);
    let opts = megaray_import::ImportOptions { mem_limit: 64 << 20, temp_dir: dir.to_path_buf() };
    megaray_import::import_file(&ply, &opts, &mut sink, &megaray_base::NoProgress).unwrap();
    let objects = vec![sphere([0.0; 3], 1.0, 24), sphere([0.5, 0.0, 0.0], 0.7, 10), c];
    let cb = megaray_base::Aabb::from_points(&objects[2].iter().flatten().copied().collect::<Vec<_>>());
    let fit = 2.0 / cb.diagonal();
    let (o, g) = (Target::Object, Target::Group);
    let t = |x: f32, y: f32, z: f32| Affine::translation(Vec3::new(x, y, z));
    let plan = InstancePlan {
        groups: vec![
            Group { name: "scene".into(), first: 0, count: 4 },
            Group { name: "pair".into(), first: 4, count: 2 },
            Group { name: "inner".into(), first: 6, count: 2 },
        ],
        instances: vec![
            inst(
                o(0),
                t(-3.0, 0.0, 0.0)
                    .then_after(&Affine::rotation(30.0, Vec3::new(1.0, 1.0, 0.0)))
                    .then_after(&Affine::scale(Vec3::new(1.0, 2.0, 0.5))),
            ),
            inst(o(0), t(3.0, 0.0, 1.0).then_after(&Affine::scale(Vec3::new(-1.0, 1.0, 1.0)))),
            inst(g(1), t(0.0, 3.0, 0.0)),
            inst(
                g(1),
                t(0.0, -3.0, 0.5)
                    .then_after(&Affine::rotation(-60.0, Vec3::Z))
                    .then_after(&Affine::scale(Vec3::splat(0.8))),
            ),
            inst(o(1), t(-1.0, 0.0, 0.0)),
            inst(g(2), t(1.5, 0.0, 0.0).then_after(&Affine::rotation(45.0, Vec3::Y))),
            inst(o(0), Affine::scale(Vec3::new(0.5, -0.3, 0.5))),
            inst(
                o(2),
                t(0.0, 0.0, 1.2)
                    .then_after(&Affine::scale(Vec3::splat(fit)))
                    .then_after(&Affine::translation(-cb.center())),
            ),
        ],
    };
    (objects, plan)
}

struct Collect<'a>(&'a mut Vec<Tri>);
impl megaray_import::TriangleSink for Collect<'_> {
    fn triangle(&mut self, p: Tri, _: &megaray_import::TriAttr) -> Result<(), megaray_import::ImportError> {
        self.0.push(p);
        Ok(())
    }
    fn material(&mut self, _: megaray_import::Material) -> u32 {
        0
    }
}

/// Rays from around the scene toward points in its box.
fn rays(bounds: &megaray_base::Aabb, n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng(seed);
    let (lo, ext) = (bounds.lo(), bounds.extent());
    let at = |rng: &mut Rng, s: f32| lo - ext * (s - 1.0) / 2.0 + ext * s * Vec3::new(rng.f32(), rng.f32(), rng.f32());
    (0..n)
        .map(|_| {
            let o = at(&mut rng, 2.0);
            let d = at(&mut rng, 0.8) - o;
            Ray::new(o, d)
        })
        .collect()
}

/// The closest hit over `tris` by the scalar reference: distance and the hit's smallest
/// barycentric (how near an edge it lies).
fn brute(tris: &[Tri], ray: &Ray, any_hit: bool) -> Option<(f32, f32)> {
    let wr = WatertightRay::new(ray);
    let mut best: Option<(f32, f32)> = None;
    for t in tris {
        let t_max = best.map_or(ray.t_max, |b| b.0);
        if let Some(h) = wr.intersect(t, t_max) {
            best = Some((h.t, h.u.min(h.v).min(1.0 - h.u - h.v)));
            if any_hit {
                break;
            }
        }
    }
    best
}

/// Hits of `tracer` against the brute force over `tris`: equal distances (to float
/// tolerance, the instance's ray and the moved triangles round differently), and where one
/// hits and the other does not, only at an edge. Returns the rays that hit.
fn check(tracer: &Tracer, tris: &[Tri], rays: &[Ray]) -> usize {
    let mut hits = 0;
    let mut edge = 0;
    for (i, ray) in rays.iter().enumerate() {
        let got = tracer.intersect(ray);
        let want = brute(tris, ray, false);
        match (got, want) {
            (Some(g), Some((t, _))) => {
                hits += 1;
                assert!((g.t - t).abs() <= 1e-4 * t.max(1.0), "ray {i}: t {} against {t}", g.t);
            }
            (None, None) => {}
            (_, w) => {
                // Only a graze of an edge may go either way.
                edge += 1;
                assert!(w.is_none_or(|w| w.1 < 1e-3), "ray {i}: instanced {got:?}, brute force {w:?}");
            }
        }
        assert_eq!(tracer.occluded(ray), got.is_some(), "ray {i}: occlusion");
    }
    assert!(edge * 100 <= rays.len(), "{edge} edge cases of {}", rays.len());
    hits
}

#[test]
fn nested_instances_hit_what_their_expanded_triangles_do() {
    let dir = tempfile::tempdir().unwrap();
    let (objects, plan) = model(dir.path());
    let opts = megaray_build::BuildOptions { max_part_tris: Some(1500), ..test_options() };
    let (path, s) = build_instanced(dir.path(), "inst", &objects, &plan, opts.clone());
    let world = expand(&objects, &plan);
    assert_eq!(s.instanced_triangles, world.len() as u128);
    assert_eq!(s.objects, 3);
    let scene = Scene::open(&path).unwrap();
    let i = scene.instancing().unwrap();
    assert_eq!(i.instanced_triangles(), world.len() as u128);
    assert!(i.objects[2].part_count > 2, "the plant is an object of several parts");
    let tracer = Tracer::new(&scene);
    let rs = rays(&scene.header().bounds, 3000, 1);
    let hits = check(&tracer, &world, &rs);
    assert!(hits > 600, "{hits} rays hit");

    // The same triangles, flattened into a scene without instances: the same hits.
    let (flat, _) = build_tris(dir.path(), "flat", world.clone(), opts);
    let flat = Scene::open(&flat).unwrap();
    let ft = Tracer::new(&flat);
    for ray in &rs {
        let (a, b) = (tracer.intersect(ray), ft.intersect(ray));
        if let (Some(a), Some(b)) = (a, b) {
            assert!((a.t - b.t).abs() <= 1e-4 * a.t.max(1.0));
            let (na, nb) = (a.geometric_normal().normalize(), b.geometric_normal().normalize());
            assert!(na.dot(nb) > 0.999, "normals {na} and {nb}: mirrored instances keep their winding");
        }
    }
}

#[test]
fn paged_instances_give_the_hits_of_mapped_ones() {
    let dir = tempfile::tempdir().unwrap();
    let (objects, plan) = model(dir.path());
    let opts = megaray_build::BuildOptions { max_part_tris: Some(1500), tile_target: 16 << 10, ..test_options() };
    let (path, _) = build_instanced(dir.path(), "inst", &objects, &plan, opts);
    let scene = std::sync::Arc::new(Scene::open(&path).unwrap());
    let rs = rays(&scene.header().bounds, 2000, 2);
    let mapped = Tracer::new(&scene);
    let want: Vec<_> =
        rs.iter().map(|r| (mapped.intersect(r).map(|h| (h.t.to_bits(), h.part, h.prim)), mapped.occluded(r))).collect();
    let budget = Pager::min_budget(&scene) + (32 << 10);
    let pager = Pager::open(scene.path(), PagerOptions { budget, fetchers: 2 }).unwrap();
    let tracer = Tracer::paged(&pager);
    let r = jobs::run(&tracer, rs.len(), &JobOptions::default(), |i, c| {
        let h = c.intersect(&rs[i])?;
        Ok((h.map(|h| (h.t.to_bits(), h.part, h.prim)), c.occluded(&rs[i])?))
    });
    assert!(r.stats.suspended > 0, "rays waited for tiles");
    let got: Vec<_> = r.into_ordered(rs.len()).into_iter().map(|a| a.unwrap()).collect();
    assert_eq!(got, want);
    assert!(pager.stats().peak_resident <= budget);
}

#[test]
fn moved_instances_hit_what_their_moved_triangles_do() {
    let dir = tempfile::tempdir().unwrap();
    let (objects, mut plan) = model(dir.path());
    let (path, _) = build_instanced(dir.path(), "inst", &objects, &plan, test_options());
    let scene = Scene::open(&path).unwrap();
    let mut tracer = Tracer::new(&scene);
    for frame in 1..4 {
        for (k, inst) in plan.instances.iter_mut().enumerate() {
            let spin = Affine::rotation(20.0 * frame as f32 * (k as f32 + 1.0), Vec3::new(0.3, 1.0, 0.2));
            inst.xform =
                Affine::translation(Vec3::new(0.0, 0.3 * frame as f32, 0.0)).then_after(&inst.xform).then_after(&spin);
            assert!(tracer.set_instance_transform(k, inst.xform));
        }
        tracer.rebuild_instances();
        let world = expand(&objects, &plan);
        let b = megaray_base::Aabb::from_points(&world.iter().flatten().copied().collect::<Vec<_>>());
        let hits = check(&tracer, &world, &rays(&b, 1000, frame));
        assert!(hits > 150, "frame {frame}: {hits} rays hit");
    }
    assert!(!tracer.set_instance_transform(0, Affine::scale(Vec3::ZERO)), "a singular transform is refused");
}

/// A caster's view is only of the scene; keep the trait in use for the paged test.
#[allow(dead_code)]
fn _uses(c: &mut dyn RayCaster) -> &Scene {
    c.scene()
}

/// Levels of detail through an instance scaled 4x are chosen as for the same object built at
/// that size: the same levels answer the same pixels (at an error where that is full detail,
/// and at one where it is a coarser level; an error compared in the object's own units would
/// take coarser levels than the world's).
#[test]
fn levels_of_detail_through_a_scaled_instance_are_chosen_in_world_units() {
    let dir = tempfile::tempdir().unwrap();
    let ball = vec![sphere([0.0; 3], 1.0, 80)];
    let grow = Affine::scale(Vec3::splat(4.0));
    let plan = InstancePlan {
        groups: vec![Group { name: "scene".into(), first: 0, count: 1 }],
        instances: vec![inst(Target::Object(0), grow)],
    };
    let (ipath, _) = build_instanced(dir.path(), "big", &ball, &plan, test_options());
    let (fpath, _) = build_tris(dir.path(), "flat", expand(&ball, &plan), test_options());
    let (is, fs) = (Scene::open(&ipath).unwrap(), Scene::open(&fpath).unwrap());
    assert!(fs.header().lod_part_count > 0 && is.header().lod_part_count == fs.header().lod_part_count);
    let b = fs.header().bounds;
    let cam = megaray_base::Camera::framing(&b, Vec3::new(0.0, 0.2, 2.0), 96, 72);
    let cone = megaray_trace::RayCone::camera(cam.pixel_angle());
    let full = fs.full_part_count();
    let mut from_lod = Vec::new();
    for px in [1.0, 2.0] {
        let (ti, tf) = (Tracer::new(&is).with_lod_error(px), Tracer::new(&fs).with_lod_error(px));
        let (mut same, mut lod, mut shown) = (0, 0, 0);
        for i in 0..96 * 72 {
            let r = cam.ray((i % 96) as f32 + 0.5, (i / 96) as f32 + 0.5);
            let (a, f) = (ti.trace_cone(&r, false, &cone), tf.trace_cone(&r, false, &cone));
            if let Some(f) = f {
                shown += 1;
                lod += (f.part >= full) as usize;
                same += a.is_some_and(|a| a.part == f.part && (a.t - f.t).abs() <= 1e-3 * f.t) as usize;
            }
        }
        assert!(shown > 200, "{shown} pixels show the ball");
        assert!(
            same * 100 >= shown * 97,
            "error {px}: {same} of {shown} pixels hit the same level at the same distance"
        );
        from_lod.push(lod * 2 > shown);
    }
    assert_eq!(from_lod, [false, true], "full detail at an error of 1 pixel, a coarser level at 2");
}
