//! The plant's object kinds. An [`Obj`] is a complete description (no randomness left), so
//! building it twice gives the same mesh, and counting it gives the exact counts.

use super::geo::{perp, Geo, Station};
use super::rng::sin_cos;
use megaray_base::Vec3;
use std::f64::consts::FRAC_PI_2;

/// Shape of a vessel's end.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Head {
    Flat,
    /// 2:1 semi-ellipsoidal head.
    Ellip,
    Hemi,
    Cone,
}

/// A pipe run: axis-aligned straight segments between `pts`, consecutive segments at right
/// angles joined by elbows (torus segments of bend radius `rb`, `m` rings each).
#[derive(Clone, Debug)]
pub(crate) struct Pipe {
    pub pts: Vec<Vec3>,
    pub r: f32,
    pub n: u32,
    pub m: u32,
    pub rb: f32,
    /// Bit `i`: a pair of flanges in the middle of segment `i`.
    pub flanges: u32,
}

/// Which valve.
#[derive(Clone, Copy, Debug)]
pub(crate) enum ValveKind {
    /// Gate or globe valve with a handwheel.
    Wheel,
    /// Ball valve with a lever.
    Lever,
    /// Control valve with a domed actuator.
    Actuator,
}

#[derive(Clone, Debug)]
pub(crate) enum Obj {
    /// A structural I-beam.
    IBeam {
        a: Vec3,
        b: Vec3,
        up: Vec3,
        w: f32,
        h: f32,
    },
    /// A rectangular bar (bracing, rails, supports).
    Bar {
        a: Vec3,
        b: Vec3,
        up: Vec3,
        w: f32,
        h: f32,
    },
    /// An axis-aligned block (foundations, skids, walls).
    Block {
        lo: Vec3,
        hi: Vec3,
    },
    Pipe(Pipe),
    /// A vessel (tank, drum, column, exchanger shell) along `axis` from `base`: straight shell of
    /// length `len`, `body` rings along it, `head` rings per curved head.
    Vessel {
        base: Vec3,
        axis: Vec3,
        r: f32,
        len: f32,
        n: u32,
        body: u32,
        head: u32,
        ends: (Head, Head),
    },
    /// A valve sitting on a pipe of radius `r` at `p`, pipe along `dir`, stem along `up`.
    Valve {
        p: Vec3,
        dir: Vec3,
        up: Vec3,
        r: f32,
        n: u32,
        kind: ValveKind,
    },
    /// A grating panel: top at `lo.y`, `lx × lz`, bearing bars along x (or z) every `sb`,
    /// cross bars every `sc`.
    Grating {
        lo: Vec3,
        lx: f32,
        lz: f32,
        along_x: bool,
        sb: f32,
        sc: f32,
    },
    /// A straight stair flight from `base` (bottom, centre of width) along horizontal `d`.
    Stair {
        base: Vec3,
        d: Vec3,
        rise: f32,
        width: f32,
    },
    /// A cable hanging between supports, sagging `sag` in each span, `q` rings per span.
    Cable {
        pts: Vec<Vec3>,
        sag: f32,
        r: f32,
        n: u32,
        q: u32,
    },
    /// A cable tray (U channel) from `a` to `b`, `w` wide and `h` high.
    Tray {
        a: Vec3,
        b: Vec3,
        w: f32,
        h: f32,
    },
    /// A vertical ladder of `height` at `base`, rungs across `side`.
    Ladder {
        base: Vec3,
        side: Vec3,
        height: f32,
    },
    /// A circular platform around a vertical vessel: annulus `ri..ro` at `c`, with railing.
    Ring {
        c: Vec3,
        ri: f32,
        ro: f32,
        n: u32,
    },
    /// A nozzle: short flanged pipe of radius `r` from `a` along `d`, length `l`.
    Nozzle {
        a: Vec3,
        d: Vec3,
        r: f32,
        l: f32,
        n: u32,
    },
    /// A pump and motor on a skid at `base`, shaft along horizontal `d`, size `s` (~1 m).
    Pump {
        base: Vec3,
        d: Vec3,
        s: f32,
        n: u32,
    },
}

fn rotate(e: Vec3, k: Vec3, s: f32, c: f32) -> Vec3 {
    e * c + k.cross(e) * s + k * (k.dot(e) * (1.0 - c))
}

impl Pipe {
    /// Number of rings of the sweep.
    pub(crate) fn stations(&self) -> u32 {
        let k = self.pts.len() as u32 - 1;
        2 + 4 * (self.flanges & ((1 << k) - 1)).count_ones() + (k - 1) * (self.m + 1)
    }

    /// Flange radius and width.
    fn flange(&self) -> (f32, f32) {
        (self.r * 1.6 + 0.01, self.r * 0.35 + 0.02)
    }

    /// Shortest legal length of segment `i` (elbows at inner ends, a flange if asked).
    pub(crate) fn min_len(&self, i: usize, flange: bool) -> f32 {
        let k = self.pts.len() - 1;
        let ends = (i > 0) as u32 + (i + 1 < k) as u32;
        ends as f32 * self.rb + if flange { self.flange().1 + 0.1 } else { 0.02 }
    }

    fn build(&self, g: &mut Geo) {
        let st = self.stations();
        if g.count_only {
            g.sweep_count(st, self.n, false, true);
            return;
        }
        let k = self.pts.len() - 1;
        let dirs: Vec<Vec3> = self.pts.windows(2).map(|w| (w[1] - w[0]).normalize()).collect();
        let mut e1 = perp(dirs[0]);
        let mut e2 = dirs[0].cross(e1);
        let (rf, fw) = self.flange();
        let r = self.r;
        let mut out = Vec::with_capacity(st as usize);
        out.push(Station { c: self.pts[0], e1, e2, r });
        for i in 0..k {
            let d = dirs[i];
            let start = if i > 0 { self.pts[i] + d * self.rb } else { self.pts[i] };
            let end = if i + 1 < k { self.pts[i + 1] - d * self.rb } else { self.pts[i + 1] };
            if self.flanges & (1 << i) != 0 {
                let mid = (start + end) * 0.5;
                let (f0, f1) = (mid - d * (fw * 0.5), mid + d * (fw * 0.5));
                for (c, r) in [(f0, r), (f0, rf), (f1, rf), (f1, r)] {
                    out.push(Station { c, e1, e2, r });
                }
            }
            out.push(Station { c: end, e1, e2, r });
            if i + 1 < k {
                let dn = dirs[i + 1];
                let axis = d.cross(dn);
                let centre = self.pts[i + 1] - d * self.rb + dn * self.rb;
                let (b1, b2) = (e1, e2);
                for t in 1..=self.m {
                    let (s, c) = sin_cos(FRAC_PI_2 * t as f64 / self.m as f64);
                    let (s, c) = (s as f32, c as f32);
                    e1 = rotate(b1, axis, s, c);
                    e2 = rotate(b2, axis, s, c);
                    let pos = centre - dn * (self.rb * c) + d * (self.rb * s);
                    out.push(Station { c: pos, e1, e2, r });
                }
            }
        }
        debug_assert_eq!(out.len() as u32, st);
        g.sweep(&out, self.n, false, true);
    }
}

/// Profile of a vessel: `(radius, height)` from the bottom pole to the top pole.
fn vessel_profile(r: f32, len: f32, body: u32, head: u32, ends: (Head, Head), out: &mut Vec<(f32, f32)>) {
    out.clear();
    let curve = |h: Head| match h {
        Head::Ellip => Some(0.5 * r),
        Head::Hemi => Some(r),
        _ => None,
    };
    match ends.0 {
        Head::Flat => out.push((0.0, 0.0)),
        Head::Cone => out.push((0.0, -0.6 * r)),
        h => {
            let hb = curve(h).unwrap_or(r);
            out.push((0.0, -hb));
            for j in 1..head {
                let (s, c) = sin_cos(-FRAC_PI_2 + FRAC_PI_2 * j as f64 / head as f64);
                out.push((r * c as f32, hb * s as f32));
            }
        }
    }
    for j in 0..=body {
        out.push((r, len * j as f32 / body as f32));
    }
    match ends.1 {
        Head::Flat => out.push((0.0, len)),
        Head::Cone => out.push((0.0, len + 0.6 * r)),
        h => {
            let ht = curve(h).unwrap_or(r);
            for j in 1..head {
                let (s, c) = sin_cos(FRAC_PI_2 * j as f64 / head as f64);
                out.push((r * c as f32, len + ht * s as f32));
            }
            out.push((0.0, len + ht));
        }
    }
}

impl Obj {
    /// Builds (or counts) the object into `g` (which the caller has cleared).
    pub(crate) fn build(&self, g: &mut Geo) {
        match *self {
            Obj::IBeam { a, b, up, w, h } => g.ibeam(a, b, up, [w, h, (h * 0.08).max(0.008), (w * 0.07).max(0.006)]),
            Obj::Bar { a, b, up, w, h } => g.bar(a, b, up, w, h),
            Obj::Block { lo, hi } => g.aabox(lo, hi),
            Obj::Pipe(ref pipe) => pipe.build(g),
            Obj::Vessel { base, axis, r, len, n, body, head, ends } => {
                let mut prof = Vec::new();
                vessel_profile(r, len, body, head, ends, &mut prof);
                g.lathe(base, axis, &prof, n);
            }
            Obj::Valve { p, dir, up, r, n, kind } => valve(g, p, dir, up, r, n, kind),
            Obj::Grating { lo, lx, lz, along_x, sb, sc } => grating(g, lo, lx, lz, along_x, sb, sc),
            Obj::Stair { base, d, rise, width } => stair(g, base, d, rise, width),
            Obj::Cable { ref pts, sag, r, n, q } => cable(g, pts, sag, r, n, q),
            Obj::Tray { a, b, w, h } => {
                let d = (b - a).normalize();
                let side = Vec3::Y.cross(d).normalize();
                let t = 0.004;
                g.bar(a, b, Vec3::Y, w, t);
                for s in [-0.5, 0.5] {
                    let o = side * (w * s) + Vec3::Y * (h * 0.5);
                    g.bar(a + o, b + o, Vec3::Y, t, h);
                }
            }
            Obj::Ladder { base, side, height } => {
                let rungs = ((height / 0.3) as u32).max(2);
                for s in [-0.22, 0.22] {
                    let o = base + side * s;
                    g.bar(o, o + Vec3::Y * height, side, 0.06, 0.012);
                }
                for i in 1..=rungs {
                    let y = Vec3::Y * (height * i as f32 / (rungs + 1) as f32);
                    g.bar(base - side * 0.22 + y, base + side * 0.22 + y, Vec3::Y, 0.02, 0.02);
                }
            }
            Obj::Ring { c, ri, ro, n } => {
                let t = 0.04;
                let prof = [(ri, 0.0), (ro, 0.0), (ro, -t), (ri, -t), (ri, 0.0)];
                g.lathe(c, Vec3::Y, &prof, n);
                g.torus(c + Vec3::Y * 1.0, Vec3::Y, ro - 0.05, 0.022, n, 6);
                let posts = (n / 4).max(4);
                for k in 0..posts {
                    let (s, co) = sin_cos(std::f64::consts::TAU * (k as f64 + 0.5) / posts as f64);
                    let radial = Vec3::new(co as f32, 0.0, s as f32);
                    let foot = c + radial * (ro - 0.05);
                    g.bar(foot, foot + Vec3::Y * 1.0, radial, 0.04, 0.04);
                }
            }
            Obj::Nozzle { a, d, r, l, n } => {
                let e1 = perp(d);
                let e2 = d.cross(e1);
                let rf = r * 1.6 + 0.01;
                let b = a + d * l;
                let f = b + d * (r * 0.3 + 0.02);
                let st = [(a, r), (b, r), (b, rf), (f, rf)].map(|(c, r)| Station { c, e1, e2, r });
                g.sweep(&st, n, false, true);
            }
            Obj::Pump { base, d, s, n } => pump(g, base, d, s, n),
        }
    }
}

fn valve(g: &mut Geo, p: Vec3, dir: Vec3, up: Vec3, r: f32, n: u32, kind: ValveKind) {
    let up = (up - dir * dir.dot(up)).normalize();
    let lh = 1.6 * r + 0.05;
    let (rf, ft, rb) = (1.6 * r + 0.01, 0.3 * r + 0.015, 1.35 * r);
    let prof = [
        (r, -lh),
        (rf, -lh),
        (rf, -lh + ft),
        (r * 1.05, -lh + ft),
        (rb * 0.85, -0.55 * lh),
        (rb, -0.25 * lh),
        (rb, 0.25 * lh),
        (rb * 0.85, 0.55 * lh),
        (r * 1.05, lh - ft),
        (rf, lh - ft),
        (rf, lh),
        (r, lh),
    ];
    g.lathe(p, dir, &prof, n);
    // Bonnet and stem.
    let e1 = dir;
    let e2 = up.cross(e1);
    let rs = 0.12 * r + 0.006;
    let top = p + up * (rb + 2.0 * r + 0.12);
    let bon = p + up * (rb + 0.4 * r);
    let st =
        [(p + up * (0.5 * rb), 0.6 * r), (bon, 0.6 * r), (bon, rs), (top, rs)].map(|(c, r)| Station { c, e1, e2, r });
    let ns = (n / 2).max(6);
    g.sweep(&st, ns, false, true);
    match kind {
        ValveKind::Wheel => {
            let rw = 1.2 * r + 0.05;
            g.torus(top, up, rw, 0.08 * rw, n.max(12), 6);
            for k in 0..3 {
                let (s, c) = sin_cos(std::f64::consts::TAU * k as f64 / 3.0);
                let radial = e1 * c as f32 + e2 * s as f32;
                g.bar(top, top + radial * rw, up, 0.04 * rw, 0.04 * rw);
            }
        }
        ValveKind::Lever => {
            let l = 3.0 * r + 0.15;
            g.bar(top - e1 * (0.1 * l), top + e1 * l, up, 0.05 * l, 0.03 * l);
        }
        ValveKind::Actuator => {
            let ra = 1.8 * r + 0.08;
            let prof = [(0.0, 0.0), (ra, 0.0), (ra, 0.25 * ra), (ra * 0.7, 0.5 * ra), (0.0, 0.6 * ra)];
            g.lathe(top, up, &prof, n);
        }
    }
}

fn grating(g: &mut Geo, lo: Vec3, lx: f32, lz: f32, along_x: bool, sb: f32, sc: f32) {
    // Work in (long, short) coordinates.
    let (u, v, lu, lv) = if along_x { (Vec3::X, Vec3::Z, lx, lz) } else { (Vec3::Z, Vec3::X, lz, lx) };
    let (bh, bt) = (0.03, 0.005);
    let nb = (lv / sb) as u32 + 1;
    let nc = (lu / sc) as u32 + 1;
    for i in 0..nb {
        let o = lo + v * (bt * 0.5 + (lv - bt) * i as f32 / (nb - 1) as f32);
        g.bar(o, o + u * lu, Vec3::Y, bt, bh);
    }
    for j in 0..nc {
        let o = lo + u * (bt * 0.5 + (lu - bt) * j as f32 / (nc - 1) as f32) + Vec3::Y * 0.002;
        g.bar(o, o + v * lv, Vec3::Y, bt, 0.008);
    }
}

fn stair(g: &mut Geo, base: Vec3, d: Vec3, rise: f32, width: f32) {
    let ns = ((rise / 0.19).ceil() as u32).max(2);
    let h = rise / ns as f32;
    let run = 0.26 * ns as f32;
    let side = Vec3::Y.cross(d).normalize();
    for i in 0..ns - 1 {
        let c = base + d * (0.26 * (i as f32 + 1.0)) + Vec3::Y * (h * (i + 1) as f32 - 0.02);
        g.obox(c, [d * 0.145, Vec3::Y * 0.02, side * (width * 0.5)]);
    }
    let top = base + d * run + Vec3::Y * rise;
    for s in [-1.0, 1.0] {
        let o = side * (s * (width * 0.5 + 0.02));
        g.bar(base + o, top + o, Vec3::Y, 0.02, 0.22);
        let rail = Vec3::Y * 0.95;
        g.cylinder(base + o + rail, top + o + rail, 0.022, 8);
        for k in 0..3 {
            let t = (k as f32 + 0.5) / 3.0;
            let foot = base + o + (top - base) * t;
            g.bar(foot, foot + rail, d, 0.04, 0.04);
        }
    }
}

fn cable(g: &mut Geo, pts: &[Vec3], sag: f32, r: f32, n: u32, q: u32) {
    let spans = pts.len() as u32 - 1;
    let count = spans * q + 1;
    if g.count_only {
        g.sweep_count(count, n, false, true);
        return;
    }
    let mut pos = Vec::with_capacity(count as usize);
    pos.push(pts[0]);
    for w in pts.windows(2) {
        for j in 1..=q {
            let x = j as f32 / q as f32;
            pos.push(w[0].lerp(w[1], x) - Vec3::Y * (sag * 4.0 * x * (1.0 - x)));
        }
    }
    let mut st = Vec::with_capacity(pos.len());
    let mut e1 = Vec3::ZERO;
    for i in 0..pos.len() {
        let t = (pos[(i + 1).min(pos.len() - 1)] - pos[i.saturating_sub(1)]).normalize();
        e1 = if i == 0 { perp(t) } else { (e1 - t * t.dot(e1)).normalize() };
        st.push(Station { c: pos[i], e1, e2: t.cross(e1), r });
    }
    g.sweep(&st, n, false, true);
}

fn pump(g: &mut Geo, base: Vec3, d: Vec3, s: f32, n: u32) {
    let side = Vec3::Y.cross(d).normalize();
    // Skid.
    g.obox(base + Vec3::Y * (0.08 * s), [d * (1.1 * s), Vec3::Y * (0.08 * s), side * (0.45 * s)]);
    let axis_h = Vec3::Y * (0.62 * s);
    // Motor: ribbed cylinder.
    let m0 = base - d * (0.95 * s) + axis_h;
    let e2 = Vec3::Y;
    let e1 = side;
    let rm = 0.3 * s;
    let mut st = Vec::new();
    for i in 0..6 {
        let c = m0 + d * (0.15 * s * i as f32);
        st.push(Station { c, e1, e2, r: if i % 2 == 0 { rm } else { rm * 1.06 } });
    }
    g.sweep(&st, n, false, true);
    g.obox(m0 + d * (0.4 * s) - Vec3::Y * (0.27 * s), [d * (0.4 * s), Vec3::Y * (0.12 * s), side * (0.25 * s)]);
    // Coupling and casing (a wheel-shaped volute with its axis along the shaft).
    g.cylinder(m0 + d * (0.75 * s), m0 + d * (1.15 * s), 0.06 * s, (n / 2).max(6));
    let c0 = m0 + d * (1.15 * s);
    let prof =
        [(0.0, 0.0), (0.35 * s, 0.0), (0.42 * s, 0.1 * s), (0.42 * s, 0.3 * s), (0.3 * s, 0.4 * s), (0.0, 0.4 * s)];
    g.lathe(c0, d, &prof, n);
    // Suction along the shaft, discharge up.
    let c1 = c0 + d * (0.4 * s);
    g.cylinder(c1, c1 + d * (0.3 * s), 0.1 * s, (n / 2).max(6));
    let c2 = c0 + d * (0.2 * s) + Vec3::Y * (0.4 * s);
    g.cylinder(c2, c2 + Vec3::Y * (0.35 * s), 0.08 * s, (n / 2).max(6));
}
