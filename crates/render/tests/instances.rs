//! A scene of instances renders as the same scene flattened into triangles: spheres placed
//! by rotations, non-uniform scales and a mirror, in nested groups, through the `normal` and
//! `diffuse` (shadowed) shaders.

use megaray_base::{Affine, Camera, Vec3};
use megaray_build::InstancePlan;
use megaray_render::{render, Builtin, RenderSettings};
use megaray_scene::{Group, Instance, Scene, Target};
use megaray_testkit::*;
use megaray_trace::Tracer;

fn inst(target: Target, xform: Affine) -> Instance {
    Instance { name: String::new(), xform, target, material: None }
}

#[test]
fn instances_render_as_their_flattened_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let objects = vec![sphere([0.0; 3], 1.0, 20), sphere([0.0; 3], 0.6, 12)];
    let t = |x: f32, y: f32, z: f32| Affine::translation(Vec3::new(x, y, z));
    let plan = InstancePlan {
        groups: vec![
            Group { name: "scene".into(), first: 0, count: 3 },
            Group { name: "pair".into(), first: 3, count: 2 },
        ],
        instances: vec![
            inst(
                Target::Object(0),
                t(-2.0, 0.0, 0.0)
                    .then_after(&Affine::rotation(40.0, Vec3::new(1.0, 0.5, 0.0)))
                    .then_after(&Affine::scale(Vec3::new(1.0, 1.8, 0.6))),
            ),
            inst(Target::Group(1), t(1.5, 0.5, 0.0).then_after(&Affine::scale(Vec3::new(-1.0, 1.0, 1.0)))),
            inst(Target::Group(1), t(0.0, -2.0, 1.0).then_after(&Affine::rotation(-70.0, Vec3::Z))),
            inst(Target::Object(1), t(0.8, 0.0, 0.0)),
            inst(Target::Object(0), Affine::scale(Vec3::new(0.5, 0.4, 0.5))),
        ],
    };
    let opts = test_options();
    let (ipath, _) = build_instanced(dir.path(), "inst", &objects, &plan, opts.clone());
    let (fpath, _) = build_tris(dir.path(), "flat", expand(&objects, &plan), opts);
    let (is, fs) = (Scene::open(&ipath).unwrap(), Scene::open(&fpath).unwrap());
    let b = fs.header().bounds;
    // The instanced scene's box is made of its objects' boxes moved: it holds the flattened one.
    assert!(is.header().bounds.contains(&b), "{:?} holds {b:?}", is.header().bounds);
    let cam = Camera::look_at(b.center() + Vec3::new(1.0, 1.5, 6.0), b.center(), Vec3::Y, 50.0, 160, 120);
    for shader in [Builtin::Normal, Builtin::Diffuse] {
        let mut s = RenderSettings::new(cam);
        s.shader = shader;
        let (a, f) = (render(&Tracer::new(&is), &s), render(&Tracer::new(&fs), &s));
        let mut differ = 0;
        let mut covered = 0;
        for (p, q) in a.pixels.iter().zip(&f.pixels) {
            let d = (0..3).map(|k| (p[k] - q[k]).abs()).fold(0.0, f32::max);
            differ += (d > 2e-3) as usize;
            covered += (q != &f.pixels[0]) as usize;
        }
        assert!(covered > 3000, "{shader:?}: the spheres fill the view ({covered} pixels)");
        // Only pixels where a ray grazes an edge may differ (the instanced ray and the
        // moved triangles round differently).
        assert!(differ * 500 <= a.pixels.len(), "{shader:?}: {differ} of {} pixels differ", a.pixels.len());
    }
}
