//! The kernels: closest and any hits through the scene file equal brute-force ray-triangle
//! tests, and every kernel (instruction set, octant or generic, assembly, packets, with and
//! without tile bookkeeping) gives the same hits, bit for bit.

use megaray_base::{intersect_triangle, Camera, Ray, Vec3, CLOSE_OFFSET, DEFAULT_OFFSET};
use megaray_scene::Scene;
use megaray_testkit::*;
use megaray_trace::{Hit, Isa, Kernels, Tracer};
use rayon::prelude::*;

/// Every triangle of the scene (full detail), read back from its tiles.
fn all_tris(scene: &Scene) -> Vec<[Vec3; 3]> {
    let mut out = Vec::new();
    let full = scene.full_part_count();
    for t in (0..scene.header().tile_count).filter(|&t| scene.tiles()[t as usize].part < full) {
        for (_, tri) in scene.tile(t).expect("tile is sound").triangles() {
            out.push(tri.map(Vec3::from));
        }
    }
    out
}

fn brute(tris: &[[Vec3; 3]], ray: &Ray) -> Option<f32> {
    let mut best = ray.t_max;
    let mut hit = None;
    for t in tris {
        if let Some(h) = intersect_triangle(ray, *t, best) {
            best = h.t;
            hit = Some(h.t);
        }
    }
    hit
}

/// 10,000 rays: half from outside the box toward points inside it (a third of those turned
/// away, missing it), half from inside in random directions (a fifth of those with a
/// negative `t_min`, which counts as 0).
/// Asserts hit/miss, distance, and any-hit agree with brute force.
fn check(scene_path: &std::path::Path, expect_tris: u64) {
    let scene = Scene::open(scene_path).unwrap();
    assert_eq!(scene.header().tri_count, expect_tris);
    let tris = all_tris(&scene);
    assert_eq!(tris.len() as u64, expect_tris);
    // Reading the triangles checked every tile: first the kernel that checks them anyway.
    let tracer = Tracer::with_kernels(&scene, Kernels { tile_checks: true, ..Kernels::best() });
    let b = scene.header().bounds;
    let (lo, ext) = (b.lo(), b.extent());
    let mut rng = Rng(7);
    let rays: Vec<Ray> = (0..10_000)
        .map(|i| {
            let p = lo + ext * Vec3::new(rng.f32(), rng.f32(), rng.f32());
            if i % 2 == 0 {
                let dir = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5).normalize();
                match i % 6 {
                    // Away from the box: a miss of the scene's box among rays that enter it
                    // (which the kernel may leave to the root node to find).
                    4 => Ray::new(p - dir * b.diagonal(), -dir),
                    _ => Ray::new(p - dir * b.diagonal(), dir),
                }
            } else {
                let mut r = Ray::new(p, Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5));
                if i % 10 == 5 {
                    // A negative `t_min` counts as 0: no hit behind the origin.
                    r.t_min = -b.diagonal();
                }
                r
            }
        })
        .collect();
    let want: Vec<Option<f32>> = rays.par_iter().map(|r| brute(&tris, r)).collect();
    // With tile bookkeeping, then without (all tiles checked).
    let compare = |tracer: &Tracer| {
        let bad: Vec<String> = rays
            .par_iter()
            .zip(&want)
            .enumerate()
            .filter_map(|(i, (r, &want))| {
                let got = tracer.intersect(r).map(|h| h.t);
                let occ = tracer.occluded(r);
                (want != got || occ != want.is_some())
                    .then(|| format!("ray {i}: brute {want:?} tracer {got:?} any {occ}"))
            })
            .collect();
        assert!(scene.first_error().is_none());
        let mode = if tracer.skips_tile_checks() { "all tiles checked" } else { "tiles checked on entry" };
        assert!(bad.is_empty(), "{mode}: {} of 10000 rays differ, e.g. {:?}", bad.len(), &bad[..bad.len().min(5)]);
    };
    compare(&tracer);
    assert!(scene.check_all_tiles());
    let tracer = Tracer::new(&scene);
    assert!(tracer.skips_tile_checks());
    compare(&tracer);
}

#[test]
fn shared_models_match_brute_force() {
    let dir = tempfile::tempdir().unwrap();
    for (name, tris) in [
        ("spot.obj", 5856),
        ("teapot.obj", 6320),
        ("stanford-bunny.obj", 69451),
        ("dog_ribcage.stl", 73960),
        ("2CylinderEngine.glb", 121496),
        ("horse.ply", 96966),
    ] {
        // Several parts, so the top-level tree and links are exercised too.
        let (scene, s) = build(dir.path(), &[model(name)], name, Some(20_000));
        check(&scene, tris - s.degenerate_dropped);
    }
}

#[test]
fn generated_models_match_brute_force() {
    let dir = tempfile::tempdir().unwrap();
    for spec in ["sphereflake:2", "grid:100", "plant:60k"] {
        let ply = gen(dir.path(), spec);
        let (scene, s) = build(dir.path(), &[ply], spec, Some(5_000));
        assert!(s.parts > 1);
        check(&scene, s.triangles);
    }
}

/// Watertightness: rays from the centre of a closed sphere (the root of a sphere flake)
/// always hit, whether random or aimed exactly at its vertices and edge midpoints.
#[test]
fn rays_from_inside_closed_spheres_always_hit() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "sphereflake:1");
    let (scene_path, _) = build(dir.path(), &[ply], "flake1", Some(500));
    let scene = Scene::open(&scene_path).unwrap();
    let tracer = Tracer::new(&scene);
    // The root sphere: radius 1 at the origin; its triangles are the ones within 1.0001 of it.
    let root: Vec<[Vec3; 3]> =
        all_tris(&scene).into_iter().filter(|t| t.iter().all(|v| (v.length() - 1.0).abs() < 1e-4)).collect();
    assert_eq!(root.len(), 4 * 12 * 11, "the root UV sphere");
    // Points on the sphere's mesh: vertices and edge midpoints, aimed at exactly.
    let mut targets: Vec<Vec3> = Vec::new();
    for t in &root {
        targets.extend([t[0], t[1], t[2], (t[0] + t[1]) * 0.5, (t[1] + t[2]) * 0.5, (t[0] + t[2]) * 0.5]);
    }
    let mut rng = Rng(11);
    let random: Vec<Vec3> = (0..10_000).map(|_| Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5)).collect();
    for org in [Vec3::ZERO, Vec3::new(0.01, -0.02, 0.005), Vec3::new(-0.3, 0.2, 0.1)] {
        let dirs = targets.iter().map(|p| *p - org).chain(random.iter().copied());
        let missed: Vec<usize> =
            dirs.enumerate().filter(|(_, d)| tracer.intersect(&Ray::new(org, *d)).is_none()).map(|(i, _)| i).collect();
        assert!(
            missed.is_empty(),
            "{} rays from inside slipped through, e.g. {:?}",
            missed.len(),
            &missed[..missed.len().min(5)]
        );
    }
}

/// The packet kernel, on every instruction set this machine has, gives the single-ray
/// kernel's distances: for coherent camera packets and for packets of random rays.
#[test]
fn packet_kernels_equal_single_rays() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:40k");
    let (scene_path, _) = build(dir.path(), &[model("stanford-bunny.obj"), ply], "mixed", Some(15_000));
    let scene = Scene::open(&scene_path).unwrap();
    let tracer = Tracer::new(&scene);
    let b = scene.header().bounds;
    let mut packets: Vec<Vec<Ray>> = Vec::new();
    for off in [DEFAULT_OFFSET, CLOSE_OFFSET, Vec3::new(0.3, -0.2, 0.25)] {
        let cam = Camera::framing(&b, off, 128, 128);
        for py in (0..128).step_by(4) {
            for px in (0..128).step_by(4) {
                let p: Vec<Ray> =
                    (0..16).map(|i| cam.ray((px + i % 4) as f32 + 0.5, (py + i / 4) as f32 + 0.5)).collect();
                packets.push(p);
            }
        }
    }
    let mut rng = Rng(5);
    let (lo, ext) = (b.lo(), b.extent());
    for k in 0..400 {
        // Incoherent packets, some shorter than 16, some with limited t_max.
        let n = 1 + k % 16;
        packets.push(
            (0..n)
                .map(|_| {
                    let o = lo + ext * Vec3::new(rng.f32(), rng.f32(), rng.f32());
                    let mut r = Ray::new(o, Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5));
                    if k % 3 == 0 {
                        r.t_max = rng.f32() * 0.3;
                    }
                    r
                })
                .collect(),
        );
    }
    let isas = Isa::available();
    assert!(isas.contains(&Isa::Baseline));
    // The whole hit, not only its distance: barycentrics, part, slot and corners are looked
    // up by the packet kernel after its walk, from what it recorded per ray.
    let same = |h: Option<Hit>, want: Option<Hit>, what: &dyn Fn() -> String| {
        let key = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.part, h.prim, h.tri));
        assert_eq!(key(h), key(want), "{}", what());
    };
    let mut compared = 0;
    for &isa in isas {
        let packed = Tracer::with_kernels(&scene, Kernels { isa, ..Kernels::best() });
        for p in &packets {
            let mut hits = vec![None; p.len()];
            packed.intersect_packet(p, &mut hits);
            for (r, h) in p.iter().zip(&hits) {
                same(*h, tracer.intersect(r), &|| format!("{isa:?}: ray {r:?}"));
                compared += 1;
            }
        }
        // Camera packets made in structure of arrays, as the bench traces them.
        let cam = Camera::framing(&b, CLOSE_OFFSET, 128, 128);
        for py in (0..128).step_by(4) {
            for px in (0..128).step_by(4) {
                let sx: [f32; 16] = std::array::from_fn(|i| (px + i % 4) as f32 + 0.5);
                let sy: [f32; 16] = std::array::from_fn(|i| (py + i / 4) as f32 + 0.5);
                let rays = cam.rays16(&sx, &sy);
                let mut hits = [None; 16];
                packed.intersect16(&rays, &mut hits);
                for (i, h) in hits.iter().enumerate() {
                    same(*h, tracer.intersect(&rays.ray(i)), &|| format!("{isa:?}: camera ray {i} of ({px}, {py})"));
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 40_000);
}

/// The single-ray kernel on every instruction set this machine has (the box test in AVX2 or
/// in baseline SSE; on AVX2 the kernels for one octant of directions and the generic one,
/// and the assembly kernel that runs in the generic one's place, alone and handing its walk
/// to the driver at a stack cut short) gives the same closest hits, bit for bit, and the same
/// any-hit answers: on random rays, camera rays, and rays aimed exactly at vertices and edge
/// midpoints (whose edges on the ray the kernels leave to the driver); and again with the
/// traversal stack overflowing into its spill; each with and without its tile bookkeeping
/// (which a tracer skips when every tile is checked).
#[test]
fn single_ray_kernels_agree_across_isas() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "sphereflake:2");
    let (scene_path, _) = build(dir.path(), &[model("stanford-bunny.obj"), ply], "mixed", Some(20_000));
    let scene = Scene::open(&scene_path).unwrap();
    let b = scene.header().bounds;
    let (lo, ext) = (b.lo(), b.extent());
    let mut rng = Rng(23);
    let mut rays: Vec<Ray> = Vec::new();
    for _ in 0..20_000 {
        let o = lo + ext * Vec3::new(rng.f32(), rng.f32(), rng.f32());
        rays.push(Ray::new(o, Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5)));
    }
    let cam = Camera::framing(&b, CLOSE_OFFSET, 96, 96);
    for py in 0..96 {
        for px in 0..96 {
            rays.push(cam.ray(px as f32 + 0.5, py as f32 + 0.5));
        }
    }
    let eye = lo + ext * Vec3::new(0.5, 1.5, 1.2);
    for t in all_tris(&scene).iter().step_by(7) {
        for p in [t[0], t[1], t[2], (t[0] + t[1]) * 0.5, (t[1] + t[2]) * 0.5] {
            rays.push(Ray::new(eye, p - eye));
        }
    }
    let key = |h: Option<megaray_trace::Hit>| h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.part, h.prim));
    let reference = Tracer::with_kernels(&scene, Kernels { isa: Isa::Baseline, tile_checks: true, ..Kernels::best() });
    // An any-hit query's hit (whichever it finds first: the same for every kernel, which
    // visit in the same order), as `try_occluded` makes it.
    let any_hit = |t: &Tracer, r: &Ray| match t.try_occluded(r) {
        megaray_trace::Traced::Done(h) => key(h),
        megaray_trace::Traced::Pending(_) => unreachable!("unpaged"),
    };
    let want: Vec<_> = rays.par_iter().map(|r| (key(reference.intersect(r)), reference.occluded(r))).collect();
    let want_any: Vec<_> = rays.par_iter().map(|r| any_hit(&reference, r)).collect();
    assert!(want.iter().filter(|w| w.0.is_some()).count() > rays.len() / 4, "enough hits to compare");
    // Every tile checked: the kernels without tile bookkeeping, and those with it.
    assert!(scene.check_all_tiles());
    assert!(Tracer::new(&scene).skips_tile_checks());
    // The assembly kernel (where this machine runs it: AVX2 and AVX-512 kernels alike) as it
    // runs, with its stack cut to one and to three entries below a node's children, and not
    // at all (the compiled generic kernel then).
    let asm_here = Isa::available().contains(&Isa::Avx2)
        && Tracer::with_kernels(&scene, Kernels { isa: Isa::Avx2, ..Kernels::best() }).runs_asm_kernel();
    let asm_cases: &[Option<usize>] = if asm_here { &[None, Some(1), Some(3), Some(0)] } else { &[None] };
    let kernels = Isa::available().iter().flat_map(|&isa| [(isa, None), (isa, Some(true)), (isa, Some(false))]);
    let kernels = kernels.flat_map(|(isa, oct)| asm_cases.iter().map(move |&a| (isa, oct, a)));
    for ((isa, octants, asm), checks) in kernels.flat_map(|k| [(k, false), (k, true)]) {
        if asm.is_some() && (isa == Isa::Baseline || octants != Some(false) || checks) {
            continue;
        }
        let k = Kernels {
            isa,
            octants,
            tile_checks: checks,
            asm: asm != Some(0),
            asm_stack: asm.filter(|&n| n > 0).unwrap_or(Kernels::best().asm_stack),
        };
        let tracer = Tracer::with_kernels(&scene, k);
        assert_eq!(tracer.skips_tile_checks(), !checks);
        assert_eq!(tracer.runs_asm_kernel(), asm_here && isa != Isa::Baseline && !checks && asm != Some(0));
        let isa = format!("{isa:?} (octant kernels {octants:?}, tile checks {checks}, assembly kernel {asm:?})");
        let got: Vec<_> = rays.par_iter().map(|r| (key(tracer.intersect(r)), tracer.occluded(r))).collect();
        let bad = (0..rays.len()).filter(|&i| got[i] != want[i]).count();
        assert_eq!(bad, 0, "{isa}: {bad} of {} rays differ from the baseline kernel", rays.len());
        let got_any: Vec<_> = rays.par_iter().map(|r| any_hit(&tracer, r)).collect();
        let bad = (0..rays.len()).filter(|&i| got_any[i] != want_any[i]).count();
        assert_eq!(bad, 0, "{isa}: {bad} of {} any-hit hits differ from the baseline kernel's", rays.len());
        // The same by the way `occluded` goes (new-ray kernels, the assembly one).
        let got_any: Vec<_> = rays.par_iter().map(|r| key(tracer.any_hit(r))).collect();
        let bad = (0..rays.len()).filter(|&i| got_any[i] != want_any[i]).count();
        assert_eq!(bad, 0, "{isa}: {bad} of {} new rays' any-hit hits differ from the baseline's", rays.len());
        // The same with the stack full at the first node, so that entries spill to the heap
        // and come back (as a tree deeper than the fixed stack would make them).
        for pad in [60, 300] {
            let got: Vec<_> = rays
                .par_iter()
                .step_by(5)
                .map(|r| (key(tracer.trace_padded(r, false, pad)), tracer.trace_padded(r, true, pad).is_some()))
                .collect();
            let bad = want.iter().step_by(5).zip(&got).filter(|(w, g)| w != g).count();
            assert_eq!(bad, 0, "{isa}, {pad} entries padded: {bad} rays differ from the unpadded kernel");
        }
    }
}
