//! What a unit holds: its structure, equipment, piping, cabling and small parts, within the
//! unit's share of the triangle budget. See the module documentation of `plant`.

use super::layout::*;
use super::objects::{Head, Obj, Pipe};
use super::rng::Rng;
use crate::GenError;
use megaray_base::Vec3;

/// One unit: structure, equipment, piping and cables within its budget, then small parts
/// until fewer than [`MIN_OBJ`] triangles are left.
pub(super) fn unit(rng: &mut Rng, fill: &mut Fill, u: &UnitPlan) -> Result<(), GenError> {
    let q = rng.pick(&[0.5f32, 0.75, 1.0, 1.0, 1.5, 2.0, 3.0]);
    let b = u.budget as f64;
    let mut anchors: Vec<Anchor> = Vec::new();
    // Levels (elevations) pipes run under, and horizontal lines for bundles and trays.
    let mut levels: Vec<f32> = Vec::new();
    let mut racks: Vec<RackPlan> = Vec::new();
    match u.style {
        Style::Process => {
            let hf = rng.range(4.5, 6.5);
            let floors = structure(rng, fill, u, hf, q, (0.3 * b) as u64)?;
            levels = (1..=floors).map(|l| l as f32 * hf).collect();
        }
        Style::TankFarm => {
            let h = rng.range(0.8, 1.5);
            let t = 0.3;
            let (x0, z0, x1, z1) = (u.lo.x, u.lo.z, u.lo.x + u.w, u.lo.z + u.d);
            for (lo, hi) in [
                (Vec3::new(x0, 0.0, z0), Vec3::new(x1, h, z0 + t)),
                (Vec3::new(x0, 0.0, z1 - t), Vec3::new(x1, h, z1)),
                (Vec3::new(x0, 0.0, z0 + t), Vec3::new(x0 + t, h, z1 - t)),
                (Vec3::new(x1 - t, 0.0, z0 + t), Vec3::new(x1, h, z1 - t)),
            ] {
                fill.put(&Obj::Block { lo, hi })?;
            }
            levels.push(rng.range(1.0, 2.0));
        }
        Style::Equipment => {
            let along_x = u.w >= u.d;
            let rp = if along_x {
                RackPlan {
                    a: u.lo + Vec3::new(0.0, 0.0, 0.5 * u.d),
                    dir: Vec3::X,
                    len: u.w,
                    width: 6.0,
                    tiers: 2,
                    y0: 4.5,
                    dy: 2.5,
                }
            } else {
                RackPlan {
                    a: u.lo + Vec3::new(0.5 * u.w, 0.0, 0.0),
                    dir: Vec3::Z,
                    len: u.d,
                    width: 6.0,
                    tiers: 2,
                    y0: 4.5,
                    dy: 2.5,
                }
            };
            // Portal frames cost about 6 beams of 44 triangles per span.
            let frame_cost = 6 * 44 * (rp.len / 6.0 + 2.0) as u64;
            if frame_cost < fill.left / 4 {
                rack_frames(rng, fill, &rp)?;
                racks.push(rp);
            }
            levels.extend([4.5, 7.0]);
        }
    }
    // What is left is shared by equipment, pipes and cables.
    let rest = fill.left as f64;
    let (we, wp, wc) = match u.style {
        Style::Process => (rng.range(0.3, 0.45), rng.range(0.35, 0.5), rng.range(0.05, 0.15)),
        Style::TankFarm => (rng.range(0.5, 0.65), rng.range(0.25, 0.4), rng.range(0.0, 0.05)),
        Style::Equipment => (rng.range(0.3, 0.4), rng.range(0.45, 0.55), rng.range(0.05, 0.1)),
    };
    let wt = (we + wp + wc) as f64;
    let eq_budget = (rest * we as f64 / wt) as u64;
    let pipe_budget = (rest * wp as f64 / wt) as u64;
    let cable_budget = (rest * wc as f64 / wt) as u64;
    equipment(rng, fill, u, q, &levels, eq_budget, &mut anchors)?;
    piping(rng, fill, u, q, &levels, &racks, &anchors, pipe_budget)?;
    cabling(rng, fill, u, q, &levels, &racks, cable_budget)?;
    small_parts(rng, fill, u, q, &levels)
}

/// The steel structure of a process unit: columns, girders, bracing, grating floors and
/// stairs within about `cap` triangles. Returns the number of floors.
pub(super) fn structure(
    rng: &mut Rng,
    fill: &mut Fill,
    u: &UnitPlan,
    hf: f32,
    q: f32,
    cap: u64,
) -> Result<u32, GenError> {
    let beam = 44u64;
    let mut floors = rng.int(2, 5);
    let sp = rng.range(5.5, 8.0);
    let mut nx = ((u.w / sp).round() as u32).max(1);
    let mut nz = ((u.d / sp).round() as u32).max(1);
    let frame_cost = |nx: u32, nz: u32, f: u32| {
        let cols = ((nx + 1) * (nz + 1)) as u64;
        let girders = f as u64 * (nx * (nz + 1) + nz * (nx + 1)) as u64;
        (cols + girders) * beam
    };
    while frame_cost(nx, nz, floors) > cap / 2 && (floors > 1 || nx > 1 || nz > 1) {
        if floors > 1 {
            floors -= 1;
        } else if nx >= nz {
            nx -= 1;
        } else {
            nz -= 1;
        }
    }
    let (sx, sz) = (u.w / nx as f32, u.d / nz as f32);
    let top = hf * floors as f32;
    let at = |i: u32, j: u32, y: f32| u.lo + Vec3::new(sx * i as f32, y, sz * j as f32);
    let (cw, gw) = (rng.range(0.3, 0.5), rng.range(0.2, 0.3));
    let start = fill.left;
    for i in 0..=nx {
        for j in 0..=nz {
            fill.put(&Obj::IBeam { a: at(i, j, 0.0), b: at(i, j, top), up: Vec3::X, w: cw, h: cw })?;
        }
    }
    for l in 1..=floors {
        let y = hf * l as f32;
        for i in 0..=nx {
            for j in 0..=nz {
                if i < nx {
                    fill.put(&Obj::IBeam { a: at(i, j, y), b: at(i + 1, j, y), up: Vec3::Y, w: gw, h: gw * 1.6 })?;
                }
                if j < nz {
                    fill.put(&Obj::IBeam { a: at(i, j, y), b: at(i, j + 1, y), up: Vec3::Y, w: gw, h: gw * 1.6 })?;
                }
            }
        }
        // X bracing in some outer bays.
        for i in 0..nx {
            for j in [0, nz] {
                if rng.chance(0.25) {
                    let (y0, y1) = (y - hf, y);
                    fill.put(&Obj::Bar { a: at(i, j, y0), b: at(i + 1, j, y1), up: Vec3::Z, w: 0.12, h: 0.12 })?;
                    fill.put(&Obj::Bar { a: at(i + 1, j, y0), b: at(i, j, y1), up: Vec3::Z, w: 0.12, h: 0.12 })?;
                }
            }
        }
    }
    // Grating floors, bay by bay in random order, within the rest of the cap.
    let frame_used = start - fill.left;
    let mut grating_left = (cap.saturating_sub(frame_used) as f64 * rng.range(0.6, 1.0) as f64) as u64;
    let mut bays: Vec<(u32, u32, u32)> = Vec::new();
    for l in 1..=floors {
        for i in 0..nx {
            for j in 0..nz {
                bays.push((l, i, j));
            }
        }
    }
    for k in (1..bays.len()).rev() {
        let o = rng.int(0, k as u32) as usize;
        bays.swap(k, o);
    }
    let (sb, sc) = if q < 1.0 { (0.06, 0.2) } else { (0.034, 0.1) };
    for &(l, i, j) in &bays {
        if grating_left < 2000 {
            break;
        }
        if (i, j) == (0, 0) || rng.chance(0.15) {
            continue; // stair bay and openings
        }
        let corner = at(i, j, hf * l as f32);
        let along_x = rng.chance(0.5);
        let (lu, lv) = if along_x { (sx, sz) } else { (sz, sx) };
        let panels = (lv / 1.0).ceil().max(1.0) as u32;
        let pw = lv / panels as f32;
        for p in 0..panels {
            let off = pw * p as f32;
            let (lo, lx, lz) = if along_x {
                (corner + Vec3::new(0.0, 0.0, off), lu, pw - 0.01)
            } else {
                (corner + Vec3::new(off, 0.0, 0.0), pw - 0.01, lu)
            };
            let t = fill.put(&Obj::Grating { lo, lx, lz, along_x, sb, sc })?;
            grating_left = grating_left.saturating_sub(t);
        }
    }
    // Switchback stairs in bay (0, 0), two flights and a landing per floor.
    let width = 1.0;
    if sx > 5.0 && sz > 2.8 {
        for l in 0..floors {
            let y = hf * l as f32;
            let z1 = u.lo.z + 0.3 + 0.5 * width;
            let z2 = z1 + width + 0.2;
            let run = 0.26 * ((0.5 * hf / 0.19).ceil());
            let x0 = u.lo.x + 0.4;
            fill.put(&Obj::Stair { base: Vec3::new(x0, y, z1), d: Vec3::X, rise: 0.5 * hf, width })?;
            let ly = y + 0.5 * hf;
            fill.put(&Obj::Block {
                lo: Vec3::new(x0 + run, ly - 0.1, z1 - 0.5 * width),
                hi: Vec3::new(x0 + run + 1.2, ly, z2 + 0.5 * width),
            })?;
            fill.put(&Obj::Stair { base: Vec3::new(x0 + run, ly, z2), d: -Vec3::X, rise: 0.5 * hf, width })?;
        }
    }
    Ok(floors)
}

/// Vessels, towers, drums, exchangers, tanks and pumps with their nozzles, ladders and
/// platforms, until `budget` is spent.
pub(super) fn equipment(
    rng: &mut Rng,
    fill: &mut Fill,
    u: &UnitPlan,
    q: f32,
    levels: &[f32],
    budget: u64,
    anchors: &mut Vec<Anchor>,
) -> Result<(), GenError> {
    let start = fill.left;
    let mut misses = 0;
    let mut weights: [f64; 6] = match u.style {
        // vertical vessel, tower, drum, exchanger, pump, storage tank
        Style::Process => [3.0, 1.0, 2.0, 1.5, 2.5, 0.0],
        Style::TankFarm => [0.5, 0.0, 0.5, 0.0, 1.0, 4.0],
        Style::Equipment => [1.0, 0.3, 1.5, 3.0, 4.0, 0.0],
    };
    // Tank farms: storage tanks on a grid of slots (in random order), the rest along the edges.
    let mut slots: Vec<Vec3> = Vec::new();
    let tank_r = rng.range(4.0, 15.0).min(0.2 * u.w.min(u.d)).max(2.0);
    if u.style == Style::TankFarm {
        let pitch = 2.6 * tank_r;
        let nx = ((u.w / pitch) as u32).max(1);
        let nz = ((u.d / pitch) as u32).max(1);
        let (mx, mz) = (0.5 * (u.w - nx as f32 * pitch), 0.5 * (u.d - nz as f32 * pitch));
        for i in 0..nx {
            for j in 0..nz {
                slots.push(u.lo + Vec3::new(mx + pitch * (i as f32 + 0.5), 0.0, mz + pitch * (j as f32 + 0.5)));
            }
        }
        for k in (1..slots.len()).rev() {
            let o = rng.int(0, k as u32) as usize;
            slots.swap(k, o);
        }
    }
    while start - fill.left < budget && fill.left >= 200 && misses < 20 {
        if slots.is_empty() {
            weights[5] = 0.0;
        }
        let kind = rng.weighted(&weights);
        let floor_y =
            if !levels.is_empty() && u.style == Style::Process && rng.chance(0.4) { rng.pick(levels) } else { 0.0 };
        let p = match (u.style, kind) {
            (Style::TankFarm, 5) => slots.pop().unwrap_or(u.lo),
            (Style::TankFarm, _) => {
                let edge = if rng.chance(0.5) { rng.range(0.01, 0.05) } else { rng.range(0.95, 0.99) };
                u.lo + Vec3::new(rng.range(0.05, 0.95) * u.w, 0.0, edge * u.d)
            }
            _ => u.lo + Vec3::new(rng.range(0.05, 0.95) * u.w, floor_y, rng.range(0.05, 0.95) * u.d),
        };
        let before = fill.left;
        let mut parts: Vec<Obj> = Vec::new();
        match kind {
            0 | 1 | 5 => {
                // Vertical: process vessel, tower or storage tank.
                let (r, len, raise) = match kind {
                    0 => {
                        let r = rng.range(0.5, 2.5);
                        (r, r * rng.range(1.5, 4.0), if rng.chance(0.5) { rng.range(0.5, 2.5) } else { 0.0 })
                    }
                    1 => (rng.range(0.7, 2.5), rng.range(15.0, 45.0), rng.range(2.0, 4.0)),
                    _ => (tank_r * rng.range(0.75, 1.0), rng.range(6.0, 18.0), 0.0),
                };
                let n = vessel_n(r, q);
                let head = ((q * (3.0 + r)).round() as u32).clamp(2, 32);
                let body = 1 + rng.int(0, (len / 2.5) as u32).min(40);
                let ends = if kind == 5 {
                    (Head::Flat, if rng.chance(0.5) { Head::Cone } else { Head::Ellip })
                } else if raise > 0.0 {
                    (Head::Ellip, rng.pick(&[Head::Ellip, Head::Hemi, Head::Ellip]))
                } else {
                    (Head::Flat, rng.pick(&[Head::Ellip, Head::Hemi, Head::Cone]))
                };
                let bottom_h = if let Head::Flat = ends.0 { 0.0 } else { 0.5 * r };
                let base = p + Vec3::Y * (raise + bottom_h);
                parts.push(Obj::Vessel { base, axis: Vec3::Y, r, len, n, body, head, ends });
                if raise > 0.0 {
                    if kind == 1 || rng.chance(0.5) {
                        // Skirt.
                        parts.push(Obj::Vessel {
                            base: p,
                            axis: Vec3::Y,
                            r: r * 0.98,
                            len: raise + bottom_h * 0.5,
                            n,
                            body: 1,
                            head: 1,
                            ends: (Head::Flat, Head::Flat),
                        });
                    } else {
                        for k in 0..4 {
                            let foot = p + dir(std::f64::consts::FRAC_PI_2 * k as f64 + 0.785) * (r * 0.8);
                            parts.push(Obj::IBeam {
                                a: foot,
                                b: foot + Vec3::Y * (raise + bottom_h),
                                up: Vec3::X,
                                w: 0.2,
                                h: 0.2,
                            });
                        }
                    }
                }
                // Nozzles around and on top.
                let nn = rng.int(2, 6) + (len / 6.0) as u32;
                for _ in 0..nn {
                    let radial = dir(rng.unit() * std::f64::consts::TAU);
                    let h = rng.range(0.1, 0.9) * len;
                    let nr = pipe_r(rng).min(0.4 * r);
                    let l = rng.range(0.25, 0.6);
                    let at = base + Vec3::Y * h + radial * (r * 0.97);
                    parts.push(Obj::Nozzle { a: at, d: radial, r: nr, l, n: pipe_n(nr, q) });
                    anchors.push(Anchor { p: at + radial * (l + 0.35 * nr + 0.02), d: radial, r: nr });
                }
                let tall = len > 5.0;
                if tall {
                    let radial = dir(rng.unit() * std::f64::consts::TAU);
                    let foot = p + radial * (r + 0.35);
                    parts.push(Obj::Ladder { base: foot, side: Vec3::Y.cross(radial), height: raise + bottom_h + len });
                }
                if kind == 1 || (kind == 5 && rng.chance(0.7)) {
                    let step = rng.range(4.0, 6.0);
                    let mut h = step;
                    while h < len {
                        let ro = if kind == 5 { r + 0.9 } else { r + rng.range(0.8, 1.5) };
                        parts.push(Obj::Ring { c: base + Vec3::Y * h, ri: r + 0.05, ro, n: vessel_n(ro, q * 0.5) });
                        h += if kind == 5 { len } else { step };
                    }
                }
            }
            2 | 3 => {
                // Horizontal drum or exchanger on saddles.
                let along_x = rng.chance(0.5);
                let axis = if along_x { Vec3::X } else { Vec3::Z };
                let side = Vec3::Y.cross(axis);
                let (r, len) = if kind == 2 {
                    (rng.range(0.5, 1.8), rng.range(3.0, 10.0))
                } else {
                    (rng.range(0.3, 0.8), rng.range(3.0, 7.0))
                };
                let n = vessel_n(r, q);
                let head = ((q * (3.0 + r)).round() as u32).clamp(2, 32);
                let c = p + Vec3::Y * (r + rng.range(0.4, 1.2));
                let base = c - axis * (0.5 * len);
                let ends = if kind == 2 { (Head::Ellip, Head::Ellip) } else { (Head::Flat, Head::Ellip) };
                parts.push(Obj::Vessel { base, axis, r, len, n, body: 1 + rng.int(0, 3), head, ends });
                if kind == 3 {
                    // Channel head and its flange.
                    let rc = r * 1.12;
                    parts.push(Obj::Vessel {
                        base: base - axis * (0.6 * r + 0.1),
                        axis,
                        r: rc,
                        len: 0.6 * r + 0.1,
                        n,
                        body: 1,
                        head,
                        ends: (Head::Hemi, Head::Flat),
                    });
                }
                for t in [0.2, 0.8] {
                    let s = base + axis * (t * len);
                    parts.push(Obj::Block {
                        lo: Vec3::new(s.x, p.y, s.z) - side * (0.8 * r) - axis * 0.15,
                        hi: Vec3::new(s.x, c.y - 0.6 * r, s.z) + side * (0.8 * r) + axis * 0.15,
                    });
                }
                for _ in 0..rng.int(2, 4) {
                    let at = base + axis * (rng.range(0.15, 0.85) * len) + Vec3::Y * (r * 0.97);
                    let nr = pipe_r(rng).min(0.4 * r);
                    let l = rng.range(0.25, 0.5);
                    parts.push(Obj::Nozzle { a: at, d: Vec3::Y, r: nr, l, n: pipe_n(nr, q) });
                    anchors.push(Anchor { p: at + Vec3::Y * (l + 0.35 * nr + 0.02), d: Vec3::Y, r: nr });
                }
            }
            _ => {
                // Pump.
                let d = if rng.chance(0.5) { Vec3::X } else { Vec3::Z };
                let s = rng.range(0.5, 1.4);
                parts.push(Obj::Pump { base: p, d, s, n: even(q * 16.0 * s.sqrt(), 8, 48) });
                let top = p + d * (0.35 * s) + Vec3::Y * (1.37 * s);
                anchors.push(Anchor { p: top, d: Vec3::Y, r: (0.08 * s).max(0.03) });
            }
        }
        // Fix block corners that came out inverted (lo/hi per axis).
        for o in &mut parts {
            if let Obj::Block { lo, hi } = o {
                let (a, b) = (lo.min(*hi), lo.max(*hi));
                *lo = a;
                *hi = b;
            }
        }
        let need: u64 = parts.iter().map(|o| fill.tris(o)).sum();
        if need > fill.left {
            misses += 1;
            continue;
        }
        for o in &parts {
            fill.put(o)?;
        }
        if fill.left == before {
            misses += 1;
        }
    }
    Ok(())
}

/// Pipe bundles along the unit's levels and racks, and pipes routed between nozzles, with
/// valves, until `budget` is spent.
#[allow(clippy::too_many_arguments)]
pub(super) fn piping(
    rng: &mut Rng,
    fill: &mut Fill,
    u: &UnitPlan,
    q: f32,
    levels: &[f32],
    racks: &[RackPlan],
    anchors: &[Anchor],
    budget: u64,
) -> Result<(), GenError> {
    let start = fill.left;
    let mut misses = 0;
    let mut rack_tier = 0u32;
    while start - fill.left < budget && fill.left >= 100 && misses < 40 {
        let before = fill.left;
        let choice =
            rng.weighted(&[if racks.is_empty() { 0.0 } else { 2.0 }, 2.0, if anchors.is_empty() { 0.0 } else { 4.0 }]);
        match choice {
            0 => {
                let rp = &racks[(rack_tier as usize / 2) % racks.len()];
                let count = rng.int(4, 16);
                rack_pipes(rng, fill, rp, rack_tier % rp.tiers, count, q, 0.4)?;
                rack_tier += 1;
            }
            1 => {
                // A bundle of parallel pipes under a level, along x or z, with ends turning.
                let y = if levels.is_empty() { 1.0 } else { rng.pick(levels) - rng.range(0.5, 1.0) };
                let along_x = rng.chance(0.5);
                let (along, across) = if along_x { (0, 2) } else { (2, 0) };
                let (len_all, wid) = if along_x { (u.w, u.d) } else { (u.d, u.w) };
                let s0 = rng.range(0.0, 0.3) * len_all;
                let s1 = rng.range(0.7, 1.0) * len_all;
                let c0 = rng.range(0.1, 0.9) * wid;
                let count = rng.int(3, 12);
                let mut off = 0.0;
                for _ in 0..count {
                    let r = pipe_r(rng);
                    off += r + 0.05;
                    let mut at = [0.0f32; 3];
                    at[along] = s0;
                    at[across] = c0 + off;
                    at[1] = y;
                    let start_p = u.lo + Vec3::from(at);
                    let mut moves = vec![(along, s1 - s0)];
                    if rng.chance(0.6) {
                        let axis = rng.pick(&[1usize, across]);
                        let mut delta = rng.range(1.0, 4.0) * if rng.chance(0.5) { 1.0 } else { -1.0 };
                        if axis == 1 && y + delta < 0.3 {
                            delta = -delta;
                        }
                        moves.push((axis, delta));
                        if rng.chance(0.5) {
                            moves.push((along, rng.range(1.0, 8.0)));
                        }
                    }
                    if let Some(pipe) = make_pipe(rng, start_p, &moves, r, q, 0.2) {
                        if fill.put(&Obj::Pipe(pipe.clone()))? > 0 {
                            valves_on(rng, fill, &pipe, 0.3)?;
                        }
                    }
                    off += r + 0.08;
                }
            }
            _ => {
                // From a nozzle out, to a level, across, and to another nozzle (or anywhere).
                let a = anchors[rng.int(0, anchors.len() as u32 - 1) as usize];
                let b = if rng.chance(0.7) {
                    anchors[rng.int(0, anchors.len() as u32 - 1) as usize].p
                } else {
                    u.lo + Vec3::new(rng.range(0.0, 1.0) * u.w, rng.range(0.5, 3.0), rng.range(0.0, 1.0) * u.d)
                };
                let y = if levels.is_empty() { rng.range(1.0, 3.0) } else { rng.pick(levels) - rng.range(0.4, 1.2) };
                let out_axis = if a.d.x.abs() > 0.5 {
                    0
                } else if a.d.y.abs() > 0.5 {
                    1
                } else {
                    2
                };
                let out_len = rng.range(0.4, 1.5).copysign(a.d[out_axis]);
                let first = a.p + a.d * out_len.abs();
                let mut moves = vec![(out_axis, out_len), (1, y - first.y)];
                let (dx, dz) = (b.x - first.x, b.z - first.z);
                if rng.chance(0.5) {
                    moves.extend([(0, dx), (2, dz)]);
                } else {
                    moves.extend([(2, dz), (0, dx)]);
                }
                moves.push((1, b.y - y));
                if let Some(pipe) = make_pipe(rng, a.p, &moves, a.r, q, 0.25) {
                    if fill.put(&Obj::Pipe(pipe.clone()))? > 0 {
                        valves_on(rng, fill, &pipe, 0.35)?;
                    }
                }
            }
        }
        if fill.left == before {
            misses += 1;
        }
    }
    Ok(())
}

/// Cable trays with sagging cables under the levels and on the racks, until `budget` is spent.
pub(super) fn cabling(
    rng: &mut Rng,
    fill: &mut Fill,
    u: &UnitPlan,
    q: f32,
    levels: &[f32],
    racks: &[RackPlan],
    budget: u64,
) -> Result<(), GenError> {
    let start = fill.left;
    let mut misses = 0;
    let mut k = 0;
    while start - fill.left < budget && fill.left >= 500 && misses < 20 {
        let before = fill.left;
        if !racks.is_empty() && rng.chance(0.4) {
            let rp = &racks[k % racks.len()];
            let count = rng.int(3, 16);
            rack_tray(rng, fill, rp, (k / racks.len()) as u32 % 3, q, count)?;
            k += 1;
        } else {
            // A tray under a level along x or z, cables hanging from hangers every few metres.
            let y = if levels.is_empty() { rng.range(1.5, 3.0) } else { rng.pick(levels) - rng.range(0.3, 0.6) };
            let along_x = rng.chance(0.5);
            let (dir, len, wid) = if along_x { (Vec3::X, u.w, u.d) } else { (Vec3::Z, u.d, u.w) };
            let side = Vec3::Y.cross(dir);
            let s0 = rng.range(0.0, 0.4) * len;
            let l = rng.range(0.4, 0.6) * len;
            let c = rng.range(0.1, 0.9) * wid;
            let a = u.lo + dir * s0 + side.abs() * c + Vec3::Y * y;
            let rp = RackPlan { a, dir, len: l.max(2.0), width: 1.0, tiers: 1, y0: y, dy: 1.0 };
            let tw = rng.range(0.3, 0.6);
            fill.put(&Obj::Tray { a, b: a + dir * rp.len, w: tw, h: 0.08 })?;
            let spans = ((rp.len / rng.range(1.5, 3.0)).round() as u32).clamp(1, 40);
            let span = rp.len / spans as f32;
            let n = if q < 1.0 { 6 } else { 8 };
            let per = even(4.0 * q, 4, 16);
            for _ in 0..rng.int(2, 12) {
                let r = rng.range(0.006, 0.025);
                let o = side * rng.range(-0.4 * tw, 0.4 * tw) - Vec3::Y * rng.range(0.05, 0.2);
                let pts: Vec<Vec3> = (0..=spans).map(|i| a + o + dir * (span * i as f32)).collect();
                let sag = rng.range(0.02, 0.15).min(0.1 * span);
                fill.put(&Obj::Cable { pts, sag, r, n, q: per })?;
            }
        }
        if fill.left == before {
            misses += 1;
        }
    }
    Ok(())
}

/// Closes the budget with small parts: valves, short pipes, supports.
pub(super) fn small_parts(
    rng: &mut Rng,
    fill: &mut Fill,
    u: &UnitPlan,
    q: f32,
    levels: &[f32],
) -> Result<(), GenError> {
    let mut guard = 0u32;
    while fill.left >= MIN_OBJ {
        guard += 1;
        let y = if levels.is_empty() || rng.chance(0.5) { 0.0 } else { rng.pick(levels) };
        let p = u.lo + Vec3::new(rng.range(0.05, 0.95) * u.w, y, rng.range(0.05, 0.95) * u.d);
        let left = fill.left;
        let r = pipe_r(rng);
        let axis = rng.pick(&[0usize, 2]);
        if left >= 4000 && guard < 10_000 {
            // A short pipe with a valve.
            let len = rng.range(2.0, 6.0);
            let start = p + Vec3::Y * rng.range(0.5, 2.5);
            let rise = rng.range(1.0, 2.0);
            if let Some(pipe) = make_pipe(rng, start, &[(axis, len), (1, rise)], r, q, 0.0) {
                if fill.put(&Obj::Pipe(pipe.clone()))? > 0 {
                    valves_on(rng, fill, &pipe, 0.8)?;
                }
            }
        } else if left >= 28 && guard < 20_000 {
            // A straight pipe piece, its segment count cut to fit.
            let mut n = pipe_n(r, q);
            // 2 rings: 2n side triangles + 2(n - 2) cap triangles.
            while n > 3 && 4 * n as u64 - 4 > left {
                n -= 1;
            }
            let a = p + Vec3::Y * rng.range(0.3, 3.0);
            let mut b = a;
            b[axis] += rng.range(0.3, 3.0);
            fill.put(&Obj::Pipe(Pipe { pts: vec![a, b], r, n, m: 2, rb: 0.1, flanges: 0 }))?;
        } else {
            // A pipe support block.
            let h = rng.range(0.3, 1.0);
            fill.put(&Obj::Block { lo: p, hi: p + Vec3::new(0.3, h, 0.3) })?;
        }
    }
    Ok(())
}
