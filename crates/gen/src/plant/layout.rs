//! Where everything goes: the site plan, the pipe racks and the triangle budget; the units'
//! contents are `unit.rs`'s.
//! See the module documentation of `plant` for the overview.

use super::geo::Geo;
use super::objects::{Obj, Pipe, ValveKind};
use super::rng::{cbrt, sin_cos, Rng};
use super::unit::unit;
use crate::GenError;
use megaray_base::Vec3;

/// Receives each object with its exact `(vertices, triangles)`.
pub(crate) type Put<'a> = dyn FnMut(&Obj, u32, u32) -> Result<(), GenError> + 'a;

/// The smallest object (a box).
pub(super) const MIN_OBJ: u64 = 12;

/// Places objects while a triangle budget lasts.
pub(super) struct Fill<'p, 'q> {
    pub(super) left: u64,
    pub(super) g: Geo,
    pub(super) put: &'p mut Put<'q>,
}

impl Fill<'_, '_> {
    /// Triangles `o` would have.
    pub(super) fn tris(&mut self, o: &Obj) -> u64 {
        self.g.clear();
        o.build(&mut self.g);
        self.g.nt as u64
    }

    /// Emits `o` if it fits in what is left; returns its triangles (0 when it did not fit).
    pub(super) fn put(&mut self, o: &Obj) -> Result<u64, GenError> {
        self.g.clear();
        o.build(&mut self.g);
        let (nv, nt) = (self.g.nv, self.g.nt);
        if nt as u64 > self.left || nt == 0 {
            return Ok(0);
        }
        (self.put)(o, nv, nt)?;
        self.left -= nt as u64;
        Ok(nt as u64)
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Style {
    Process,
    TankFarm,
    Equipment,
}

#[derive(Clone, Copy, Debug)]
pub(super) struct UnitPlan {
    /// Corner with the smallest x and z, on the ground.
    pub(super) lo: Vec3,
    /// Extent along x.
    pub(super) w: f32,
    /// Extent along z.
    pub(super) d: f32,
    pub(super) style: Style,
    pub(super) budget: u64,
}

/// A straight pipe rack: portal frames every span from `a` along `dir` (`X` or `Z`).
#[derive(Clone, Copy, Debug)]
pub(super) struct RackPlan {
    pub(super) a: Vec3,
    pub(super) dir: Vec3,
    pub(super) len: f32,
    pub(super) width: f32,
    pub(super) tiers: u32,
    /// Height of the lowest tier and distance between tiers.
    pub(super) y0: f32,
    pub(super) dy: f32,
}

/// Where a pipe can start: a nozzle's end and its outward direction, and a pipe radius.
#[derive(Clone, Copy, Debug)]
pub(super) struct Anchor {
    pub(super) p: Vec3,
    pub(super) d: Vec3,
    pub(super) r: f32,
}

/// Nominal pipe radii (m) and how common they are.
pub(super) const PIPE_R: [f32; 10] = [0.03, 0.045, 0.06, 0.085, 0.11, 0.16, 0.22, 0.3, 0.4, 0.5];
pub(super) const PIPE_W: [f64; 10] = [10.0, 12.0, 12.0, 10.0, 9.0, 7.0, 5.0, 3.0, 2.0, 1.0];

pub(super) fn pipe_r(rng: &mut Rng) -> f32 {
    PIPE_R[rng.weighted(&PIPE_W)]
}

/// An even segment count `2·round(x / 2)` clamped to `lo..=hi`.
pub(super) fn even(x: f32, lo: u32, hi: u32) -> u32 {
    ((2.0 * (x * 0.5).round()) as u32).clamp(lo, hi)
}

/// Segments around a pipe of radius `r` at quality `q`.
pub(super) fn pipe_n(r: f32, q: f32) -> u32 {
    even(q * (8.0 + 20.0 * r.sqrt()), 8, 64)
}

/// Segments around a vessel of radius `r` at quality `q`.
pub(super) fn vessel_n(r: f32, q: f32) -> u32 {
    even(q * (12.0 + 12.0 * r.sqrt()), 12, 256)
}

/// The horizontal unit vector at angle `a` from +x towards +z.
pub(super) fn dir(a: f64) -> Vec3 {
    let (s, c) = sin_cos(a);
    Vec3::new(c as f32, 0.0, s as f32)
}

pub(super) fn axis_vec(axis: usize, s: f32) -> Vec3 {
    let mut v = [0.0; 3];
    v[axis] = s;
    Vec3::from(v)
}

/// A pipe from `start` through axis-aligned `moves` (axis, signed length): moves along the
/// same axis in a row are merged, negligible ones dropped, and segments lengthened where
/// elbows (and flanges) need room. `None` if nothing is left.
pub(super) fn make_pipe(
    rng: &mut Rng,
    start: Vec3,
    moves: &[(usize, f32)],
    r: f32,
    q: f32,
    flange_p: f64,
) -> Option<Pipe> {
    let mut segs: Vec<(usize, f32)> = Vec::with_capacity(moves.len());
    for &(axis, len) in moves {
        if len.abs() < 1e-3 {
            continue;
        }
        match segs.last_mut() {
            Some(last) if last.0 == axis => {
                last.1 += len;
                if last.1.abs() < 1e-3 {
                    segs.pop();
                }
            }
            _ => segs.push((axis, len)),
        }
    }
    // Merging may have left equal axes next to each other; merge again.
    let mut i = 1;
    while i < segs.len() {
        if segs[i].0 == segs[i - 1].0 {
            segs[i - 1].1 += segs[i].1;
            segs.remove(i);
            if segs[i - 1].1.abs() < 1e-3 {
                segs.remove(i - 1);
                i = i.max(2) - 1;
            }
        } else {
            i += 1;
        }
    }
    segs.truncate(16);
    if segs.is_empty() {
        return None;
    }
    let n = pipe_n(r, q);
    let mut pipe =
        Pipe { pts: vec![start; segs.len() + 1], r, n, m: (n / 4).clamp(2, 12), rb: (3.0 * r).max(0.06), flanges: 0 };
    let mut at = start;
    for (i, &(axis, len)) in segs.iter().enumerate() {
        let want_flange = rng.chance(flange_p);
        let l = len.abs().max(pipe.min_len(i, false));
        if want_flange && l >= pipe.min_len(i, true) {
            pipe.flanges |= 1 << i;
        }
        // Lengthened (or long) drops that would go underground turn up instead.
        let sign = if axis == 1 && len < 0.0 && at.y - l < r + 0.1 { 1.0 } else { len };
        at += axis_vec(axis, l.copysign(sign));
        pipe.pts[i + 1] = at;
    }
    Some(pipe)
}

/// Puts valves on the long straight parts of `pipe`.
pub(super) fn valves_on(rng: &mut Rng, fill: &mut Fill, pipe: &Pipe, p: f64) -> Result<(), GenError> {
    let k = pipe.pts.len() - 1;
    let lh = 1.6 * pipe.r + 0.05;
    for i in 0..k {
        if pipe.flanges & (1 << i) != 0 || !rng.chance(p) {
            continue;
        }
        let (a, b) = (pipe.pts[i], pipe.pts[i + 1]);
        let len = (b - a).length();
        let d = (b - a) / len;
        let s0 = if i > 0 { pipe.rb } else { 0.0 } + lh + 0.1;
        let s1 = len - if i + 1 < k { pipe.rb } else { 0.0 } - lh - 0.1;
        if s1 <= s0 {
            continue;
        }
        let at = a + d * rng.range(s0, s1);
        let up = if d.y.abs() > 0.5 {
            if rng.chance(0.5) {
                Vec3::X
            } else {
                Vec3::Z
            }
        } else if rng.chance(0.75) {
            Vec3::Y
        } else {
            Vec3::Y.cross(d)
        };
        let kind = [ValveKind::Wheel, ValveKind::Wheel, ValveKind::Lever, ValveKind::Actuator][rng.int(0, 3) as usize];
        let n = pipe.n.clamp(12, 48);
        fill.put(&Obj::Valve { p: at, dir: d, up, r: pipe.r, n, kind })?;
    }
    Ok(())
}

/// Site plan and all objects, in order, to `put`.
pub(crate) fn run(total: u64, seed: u64, put: &mut Put<'_>) -> Result<(), GenError> {
    let mut rng = Rng::derive(seed, 0);
    // Units: count, budget weights, styles, footprints.
    let n_units = ((cbrt(total as f64) / 6.0).round() as u64).clamp(1, (total / 3000).max(1)) as usize;
    let weights: Vec<f64> = (0..n_units)
        .map(|_| {
            let u = 0.3 + rng.unit();
            u * u * u
        })
        .collect();
    let styles: Vec<Style> = (0..n_units)
        .map(|i| match (i, rng.weighted(&[0.6, 0.15, 0.25])) {
            (0, _) | (_, 0) => Style::Process,
            (_, 1) => Style::TankFarm,
            _ => Style::Equipment,
        })
        .collect();
    let wsum: f64 = weights.iter().sum();
    let sides: Vec<(f32, f32)> = (0..n_units)
        .map(|i| {
            let b = total as f64 * weights[i] / wsum;
            let scale = match styles[i] {
                Style::Process => 1.0,
                Style::TankFarm => 1.8,
                Style::Equipment => 1.25,
            };
            let side = ((10.0 + 0.42 * cbrt(b)) * scale).clamp(12.0, 250.0) as f32;
            let aspect = rng.range(0.6, 1.6);
            (side * aspect.sqrt(), side / aspect.sqrt())
        })
        .collect();
    // Placement: largest first, at random, without overlap; the site grows when crowded.
    let gap = 8.0;
    let area: f32 = sides.iter().map(|&(w, d)| (w + gap) * (d + gap)).sum();
    let mut site = (area * 2.2).sqrt();
    let mut order: Vec<usize> = (0..n_units).collect();
    order.sort_by(|&a, &b| (sides[b].0 * sides[b].1).total_cmp(&(sides[a].0 * sides[a].1)).then(a.cmp(&b)));
    let mut placed: Vec<(f32, f32, f32, f32)> = Vec::with_capacity(n_units);
    let mut lo = vec![Vec3::ZERO; n_units];
    for &i in &order {
        let (w, d) = sides[i];
        loop {
            let mut ok = None;
            for _ in 0..60 {
                let x = rng.range(-0.5 * site, (0.5 * site - w).max(-0.5 * site));
                let z = rng.range(-0.5 * site, (0.5 * site - d).max(-0.5 * site));
                if placed.iter().all(|&(px, pz, pw, pd)| {
                    x + w + gap <= px || px + pw + gap <= x || z + d + gap <= pz || pz + pd + gap <= z
                }) {
                    ok = Some((x, z));
                    break;
                }
            }
            if let Some((x, z)) = ok {
                placed.push((x, z, w, d));
                lo[i] = Vec3::new(x, 0.0, z);
                break;
            }
            site *= 1.1;
        }
    }
    let half = 0.5 * site;
    // Site racks across the whole site, natural size, counted first.
    let mut racks = Vec::new();
    if total >= 200_000 {
        let n_racks = 1 + n_units / 10;
        for _ in 0..n_racks {
            let along_x = rng.chance(0.5);
            let c = rng.range(-0.4 * half, 0.4 * half);
            let (a, dir) = if along_x {
                (Vec3::new(-half - 10.0, 0.0, c), Vec3::X)
            } else {
                (Vec3::new(c, 0.0, -half - 10.0), Vec3::Z)
            };
            racks.push(RackPlan {
                a,
                dir,
                len: site + 20.0,
                width: rng.range(5.0, 9.0),
                tiers: rng.int(1, 3),
                y0: rng.range(4.5, 6.5),
                dy: rng.range(2.0, 3.0),
            });
        }
    }
    let rack_cap = total / 8 / racks.len().max(1) as u64;
    let mut rack_tris = 0u64;
    for (j, rp) in racks.iter().enumerate() {
        let mut noop = |_: &Obj, _: u32, _: u32| Ok(());
        let mut fill = Fill { left: rack_cap, g: Geo::new(true), put: &mut noop };
        site_rack(&mut Rng::derive(seed, 1 << 40 | j as u64), &mut fill, rp)?;
        rack_tris += rack_cap - fill.left;
    }
    // Unit budgets add up to what the racks leave.
    let unit_total = total - rack_tris;
    let mut budgets: Vec<u64> = weights.iter().map(|w| (unit_total as f64 * w / wsum) as u64).collect();
    let short = unit_total - budgets.iter().sum::<u64>();
    budgets[0] += short;
    for i in 0..n_units {
        let plan = UnitPlan { lo: lo[i], w: sides[i].0, d: sides[i].1, style: styles[i], budget: budgets[i] };
        let mut fill = Fill { left: plan.budget, g: Geo::new(true), put };
        unit(&mut Rng::derive(seed, 1 + i as u64), &mut fill, &plan)?;
    }
    for (j, rp) in racks.iter().enumerate() {
        let mut fill = Fill { left: rack_cap, g: Geo::new(true), put };
        site_rack(&mut Rng::derive(seed, 1 << 40 | j as u64), &mut fill, rp)?;
    }
    Ok(())
}

/// A site rack: portal frames, long pipes on every tier, cable trays with cables on top.
pub(super) fn site_rack(rng: &mut Rng, fill: &mut Fill, rp: &RackPlan) -> Result<(), GenError> {
    let q = rng.pick(&[0.5f32, 0.75, 1.0, 1.5, 2.0]);
    rack_frames(rng, fill, rp)?;
    for t in 0..rp.tiers {
        let count = rng.int(6, 30);
        rack_pipes(rng, fill, rp, t, count, q, 0.3)?;
    }
    let trays = rng.int(1, 2);
    for k in 0..trays {
        let count = rng.int(4, 24);
        rack_tray(rng, fill, rp, k, q, count)?;
    }
    Ok(())
}

/// Portal frames of a rack, with longitudinal girders at every tier.
pub(super) fn rack_frames(rng: &mut Rng, fill: &mut Fill, rp: &RackPlan) -> Result<(), GenError> {
    let spans = ((rp.len / rng.range(5.5, 7.5)).round() as u32).max(1);
    let span = rp.len / spans as f32;
    let side = Vec3::Y.cross(rp.dir);
    let top = rp.y0 + rp.dy * (rp.tiers - 1) as f32;
    let hw = 0.5 * rp.width;
    for i in 0..=spans {
        let p = rp.a + rp.dir * (span * i as f32);
        for s in [-hw, hw] {
            fill.put(&Obj::IBeam {
                a: p + side * s,
                b: p + side * s + Vec3::Y * (top + 0.3),
                up: rp.dir,
                w: 0.3,
                h: 0.3,
            })?;
        }
        for t in 0..rp.tiers {
            let y = Vec3::Y * (rp.y0 + rp.dy * t as f32);
            fill.put(&Obj::IBeam { a: p - side * hw + y, b: p + side * hw + y, up: Vec3::Y, w: 0.2, h: 0.3 })?;
        }
        if i < spans {
            let q = p + rp.dir * span;
            let y = Vec3::Y * top;
            for s in [-hw, hw] {
                fill.put(&Obj::IBeam { a: p + side * s + y, b: q + side * s + y, up: Vec3::Y, w: 0.2, h: 0.3 })?;
            }
        }
    }
    Ok(())
}

/// `count` pipes side by side on tier `t` of a rack, running (most of) its length; some drop
/// down or turn aside at their ends.
pub(super) fn rack_pipes(
    rng: &mut Rng,
    fill: &mut Fill,
    rp: &RackPlan,
    t: u32,
    count: u32,
    q: f32,
    valve_p: f64,
) -> Result<(), GenError> {
    let along = if rp.dir.x != 0.0 { 0 } else { 2 };
    let across = 2 - along;
    let side = Vec3::Y.cross(rp.dir);
    let y = rp.y0 + rp.dy * t as f32;
    let mut off = -0.5 * rp.width + 0.2;
    for _ in 0..count {
        let r = pipe_r(rng);
        off += r + 0.05;
        if off + r > 0.5 * rp.width {
            break;
        }
        let s0 = if rng.chance(0.7) { 0.0 } else { rng.range(0.0, 0.6) * rp.len };
        let s1 = if rng.chance(0.7) { rp.len } else { rng.range(s0 + 0.2 * rp.len, rp.len) };
        let base = rp.a + side * off + Vec3::Y * (y + r + 0.15);
        let mut moves = Vec::new();
        let mut start = base + rp.dir * s0;
        if rng.chance(0.5) {
            let drop = rng.range(1.5, y);
            start -= Vec3::Y * drop;
            moves.push((1, drop));
        }
        moves.push((along, s1 - s0));
        match rng.int(0, 2) {
            0 => moves.push((1, -rng.range(1.5, y))),
            1 => moves.push((across, rng.range(1.0, 6.0).copysign(off))),
            _ => {}
        }
        if let Some(pipe) = make_pipe(rng, start, &moves, r, q, 0.15) {
            if fill.put(&Obj::Pipe(pipe.clone()))? > 0 {
                valves_on(rng, fill, &pipe, valve_p)?;
            }
        }
        off += r + 0.1;
    }
    Ok(())
}

/// A cable tray above the top tier of a rack (`k`-th, side by side) with `count` cables
/// hanging between the portals.
pub(super) fn rack_tray(
    rng: &mut Rng,
    fill: &mut Fill,
    rp: &RackPlan,
    k: u32,
    q: f32,
    count: u32,
) -> Result<(), GenError> {
    let side = Vec3::Y.cross(rp.dir);
    let top = rp.y0 + rp.dy * (rp.tiers - 1) as f32 + 1.0 + 0.5 * k as f32;
    let tw = rng.range(0.4, 0.8);
    let off = side * (rng.range(-0.25, 0.25) * rp.width);
    let a = rp.a + off + Vec3::Y * top;
    fill.put(&Obj::Tray { a, b: a + rp.dir * rp.len, w: tw, h: 0.1 })?;
    let spans = ((rp.len / 6.0).round() as u32).clamp(1, 40);
    let span = rp.len / spans as f32;
    let n = if q < 1.0 { 6 } else { 8 };
    let per = even(6.0 * q, 4, 24);
    for _ in 0..count {
        let r = rng.range(0.008, 0.03);
        let o = side * rng.range(-0.4 * tw, 0.4 * tw) + Vec3::Y * (r + 0.01);
        let first = rng.int(0, spans / 3);
        let last = rng.int((2 * spans / 3).max(first + 1), spans);
        let pts: Vec<Vec3> = (first..=last).map(|i| a + o + rp.dir * (span * i as f32)).collect();
        let sag = rng.range(0.01, 0.12).min(0.05 * span);
        fill.put(&Obj::Cable { pts, sag, r, n, q: per })?;
    }
    Ok(())
}
