//! Packet traversal: 16 coherent rays (a 4x4 pixel block) walk the tree together. Each node's
//! eight boxes are tested against all 16 rays, one box at a time across the rays, so a node is
//! fetched and decoded once for the packet and the box arithmetic runs 16 rays wide.
//!
//! The kernel is written once, as plain loops over the 16 lanes ([`traverse`]), and compiled
//! three times: for AVX-512, for AVX2 and for the baseline (SSE2 on x86-64), which the compiler
//! vectorizes to its widest registers. [`Isa::detect`] picks one at run time, once; the tests
//! check every path the machine supports against single-ray traversal.

use std::sync::OnceLock;

use crate::{corners, fmax, fmin, Entry, Hit, RayTri4, Step, Tracer, BOX_EPS, W};
use megaray_base::Ray;

/// Rays in a packet.
pub const WIDTH: usize = 16;

/// The instruction sets the packet kernel is compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// Whatever the target guarantees (SSE2 on x86-64).
    Baseline,
    Avx2,
    Avx512,
}

impl Isa {
    /// The best instruction set this machine has (decided once, then cached).
    pub fn detect() -> Isa {
        static ISA: OnceLock<Isa> = OnceLock::new();
        *ISA.get_or_init(|| {
            #[cfg(target_arch = "x86_64")]
            {
                if std::arch::is_x86_feature_detected!("avx512f") {
                    return Isa::Avx512;
                }
                if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
                    return Isa::Avx2;
                }
            }
            Isa::Baseline
        })
    }

    /// Every instruction set this machine can run (the tests compare them all).
    pub fn available() -> Vec<Isa> {
        let mut v = vec![Isa::Baseline];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
                v.push(Isa::Avx2);
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                v.push(Isa::Avx512);
            }
        }
        v
    }
}

/// The packet's rays, structure of arrays.
struct Packet {
    ox: [f32; WIDTH],
    oy: [f32; WIDTH],
    oz: [f32; WIDTH],
    ix: [f32; WIDTH],
    iy: [f32; WIDTH],
    iz: [f32; WIDTH],
    t_min: [f32; WIDTH],
    /// Current closest hit distance per ray (the ray's `t_max` at first).
    t_max: [f32; WIDTH],
}

/// Traces up to 16 rays as one packet with the given instruction set.
pub(crate) fn intersect16(tracer: &Tracer, rays: &[Ray], hits: &mut [Option<Hit>], isa: Isa) {
    debug_assert!(rays.len() <= WIDTH && rays.len() == hits.len());
    match isa {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx512` is only produced by `detect`/`available` after
        // `is_x86_feature_detected!("avx512f")` said this CPU has it.
        Isa::Avx512 => unsafe { traverse_avx512(tracer, rays, hits) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx2` is only produced after the CPU reported AVX2 and FMA.
        Isa::Avx2 => unsafe { traverse_avx2(tracer, rays, hits) },
        _ => traverse(tracer, rays, hits),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
unsafe fn traverse_avx512(tracer: &Tracer, rays: &[Ray], hits: &mut [Option<Hit>]) {
    traverse(tracer, rays, hits)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn traverse_avx2(tracer: &Tracer, rays: &[Ray], hits: &mut [Option<Hit>]) {
    traverse(tracer, rays, hits)
}

/// The packet kernel. Every result equals [`Tracer::intersect`] on the same ray: the box tests
/// only decide which nodes are visited (conservatively, as in the single-ray kernel), and the
/// triangle tests are the single-ray ones.
#[inline(always)]
fn traverse(tracer: &Tracer, rays: &[Ray], hits: &mut [Option<Hit>]) {
    let n = rays.len();
    crate::stats::count(|s| s.rays += n as u64);
    let fix = |d: f32| if d.abs() < 1e-20 { 1e-20f32.copysign(d) } else { d };
    let mut p = Packet {
        ox: [0.0; WIDTH],
        oy: [0.0; WIDTH],
        oz: [0.0; WIDTH],
        ix: [1.0; WIDTH],
        iy: [1.0; WIDTH],
        iz: [1.0; WIDTH],
        t_min: [0.0; WIDTH],
        t_max: [f32::NEG_INFINITY; WIDTH], // unused lanes never hit anything
    };
    for (i, r) in rays.iter().enumerate() {
        p.ox[i] = r.org.x;
        p.oy[i] = r.org.y;
        p.oz[i] = r.org.z;
        p.ix[i] = 1.0 / fix(r.dir.x);
        p.iy[i] = 1.0 / fix(r.dir.y);
        p.iz[i] = 1.0 / fix(r.dir.z);
        p.t_min[i] = r.t_min;
        p.t_max[i] = r.t_max;
        hits[i] = None;
    }
    let mut tri: [Option<RayTri4>; WIDTH] = [const { None }; WIDTH];
    // Entries with the mask of the rays that entered their box.
    let mut stack: Vec<(Entry, u32)> = Vec::with_capacity(64);
    stack.push((Entry::ROOT, (1u32 << n) - 1));
    let mut c = tracer.top_cursor();
    while let Some((e, rays_in)) = stack.pop() {
        // Skip entries that every ray has passed by.
        let mut live = 0u32;
        for r in 0..WIDTH {
            live |= ((e.t <= p.t_max[r] * BOX_EPS) as u32) << r;
        }
        let live = live & rays_in;
        if live == 0 {
            continue;
        }
        let (node, arr) = match tracer.step(&mut c, &e) {
            Step::Node(node, arr) => (node, arr),
            Step::Leaf { first, count } => {
                // Each ray that entered the box tests the triangles.
                let mut m = live;
                while m != 0 {
                    let r = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let rt = tri[r].get_or_insert_with(|| RayTri4::new(&rays[r]));
                    let mut left = count;
                    let mut blk = first;
                    while left > 0 {
                        let lanes = if left >= 4 { 0b1111 } else { (1u32 << left) - 1 };
                        let b = tracer.block(&c, blk);
                        crate::stats::count(|s| s.blocks += 1);
                        if let Some((lane, h)) = rt.test(b, lanes, p.t_max[r]) {
                            p.t_max[r] = h.t;
                            let prim = c.first_slot + 4 * blk + lane as u32;
                            hits[r] = Some(Hit { t: h.t, u: h.u, v: h.v, part: c.part, prim, tri: corners(b, lane) });
                        }
                        left = left.saturating_sub(4);
                        blk += 1;
                    }
                }
                continue;
            }
            // Packets run on unpaged tracers only: nothing is ever missing.
            Step::Skip | Step::Missing(_) => continue,
        };
        crate::stats::count(|s| s.nodes += 1);
        // Box k against all rays: a ray mask and the nearest entry distance per slot.
        let mut masks = [0u32; W];
        let mut near_min = [f32::INFINITY; W];
        for k in 0..W {
            let (lx, hx) = (node.lo_x[k], node.hi_x[k]);
            let (ly, hy) = (node.lo_y[k], node.hi_y[k]);
            let (lz, hz) = (node.lo_z[k], node.hi_z[k]);
            let mut hit = [false; WIDTH];
            let mut near = [f32::INFINITY; WIDTH];
            for r in 0..WIDTH {
                let ax = (lx - p.ox[r]) * p.ix[r];
                let bx = (hx - p.ox[r]) * p.ix[r];
                let ay = (ly - p.oy[r]) * p.iy[r];
                let by = (hy - p.oy[r]) * p.iy[r];
                let az = (lz - p.oz[r]) * p.iz[r];
                let bz = (hz - p.oz[r]) * p.iz[r];
                let t0 = fmax(fmax(fmax(fmin(ax, bx), fmin(ay, by)), fmin(az, bz)), p.t_min[r]);
                let t1 = fmin(fmin(fmin(fmax(ax, bx), fmax(ay, by)), fmax(az, bz)), p.t_max[r]) * BOX_EPS;
                hit[r] = t0 <= t1;
                near[r] = if t0 <= t1 { t0 } else { f32::INFINITY };
            }
            let mut m = 0u32;
            let mut d = f32::INFINITY;
            for r in 0..WIDTH {
                m |= (hit[r] as u32) << r;
                d = fmin(d, near[r]);
            }
            masks[k] = m & live;
            near_min[k] = d;
        }
        // Children hit by some ray, pushed far to near (the nearest pops first).
        let mut order = [(Entry::ROOT, 0u32); W];
        let mut no = 0;
        for k in 0..W {
            if masks[k] == 0 {
                continue;
            }
            let x = (Entry { r: node.child[k], arr, t: near_min[k] }, masks[k]);
            let mut j = no;
            while j > 0 && order[j - 1].0.t < x.0.t {
                order[j] = order[j - 1];
                j -= 1;
            }
            order[j] = x;
            no += 1;
        }
        stack.extend_from_slice(&order[..no]);
    }
}
