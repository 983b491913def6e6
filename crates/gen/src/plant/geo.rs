//! Mesh primitives of the plant: boxes, I-beams, swept tubes (pipes, elbows, tori, cables) and
//! surfaces of revolution (vessels, valve bodies).
//!
//! A [`Geo`] either builds an object's mesh or, with `count_only`, only counts what it would
//! build: the layout uses the counts to meet its triangle budget, and `counts()` of a plant is
//! the layout run with counting only. Both modes go through the same functions, so the counts
//! are exact by construction (and checked in debug builds).

use super::rng::sin_cos;
use megaray_base::Vec3;

/// One ring of a swept tube: centre, two unit vectors spanning the ring's plane, radius.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Station {
    pub c: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
    pub r: f32,
}

/// `(cos, sin)` of `2πk/n`, `k = 0..n`, per `n`.
#[derive(Default)]
struct TrigCache {
    tables: Vec<Vec<(f32, f32)>>,
}

impl TrigCache {
    fn get(&mut self, n: u32) -> &[(f32, f32)] {
        let n = n as usize;
        if self.tables.len() <= n {
            self.tables.resize(n + 1, Vec::new());
        }
        if self.tables[n].is_empty() {
            self.tables[n] = (0..n)
                .map(|k| {
                    let (s, c) = sin_cos(std::f64::consts::TAU * k as f64 / n as f64);
                    (c as f32, s as f32)
                })
                .collect();
        }
        &self.tables[n]
    }
}

/// An object's mesh under construction (indices local to the object), or just its counts.
pub(crate) struct Geo {
    pub count_only: bool,
    /// Vertices made (or counted) so far.
    pub nv: u32,
    /// Triangles made (or counted) so far.
    pub nt: u32,
    pub verts: Vec<[f32; 3]>,
    pub tris: Vec<[u32; 3]>,
    trig: TrigCache,
    /// Scratch for ring tables (kept to avoid allocations).
    ring: Vec<(f32, f32)>,
}

/// A vertex position as stored.
#[inline]
fn p(v: Vec3) -> [f32; 3] {
    v.to_array()
}

/// Any unit vector perpendicular to unit `d`.
pub(crate) fn perp(d: Vec3) -> Vec3 {
    let a = if d.x.abs() < 0.6 {
        Vec3::X
    } else if d.y.abs() < 0.6 {
        Vec3::Y
    } else {
        Vec3::Z
    };
    d.cross(a).normalize()
}

impl Geo {
    pub(crate) fn new(count_only: bool) -> Geo {
        Geo {
            count_only,
            nv: 0,
            nt: 0,
            verts: Vec::new(),
            tris: Vec::new(),
            trig: TrigCache::default(),
            ring: Vec::new(),
        }
    }

    /// Starts a new object.
    pub(crate) fn clear(&mut self) {
        self.nv = 0;
        self.nt = 0;
        self.verts.clear();
        self.tris.clear();
    }

    #[inline]
    fn count(&mut self, v: u32, t: u32) -> bool {
        self.nv += v;
        self.nt += t;
        self.count_only
    }

    #[inline]
    fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        self.tris.push([a, b, c]);
        self.tris.push([a, c, d]);
    }

    /// A box with centre `c` and half-axis vectors `h` (pairwise perpendicular, non-zero):
    /// 8 vertices, 12 triangles.
    pub(crate) fn obox(&mut self, c: Vec3, h: [Vec3; 3]) {
        let b = self.nv;
        if self.count(8, 12) {
            return;
        }
        for i in 0..8 {
            let s = |bit: u32| if i & bit != 0 { 1.0 } else { -1.0 };
            self.verts.push(p(c + h[0] * s(1) + h[1] * s(2) + h[2] * s(4)));
        }
        for f in [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]] {
            self.quad(b + f[0], b + f[1], b + f[2], b + f[3]);
        }
    }

    /// An axis-aligned box from `lo` to `hi` (every extent positive).
    pub(crate) fn aabox(&mut self, lo: Vec3, hi: Vec3) {
        let h = (hi - lo) * 0.5;
        self.obox(lo + h, [Vec3::new(h.x, 0.0, 0.0), Vec3::new(0.0, h.y, 0.0), Vec3::new(0.0, 0.0, h.z)]);
    }

    /// A box of cross-section `w × h` (`h` along `up`) from `p0` to `p1`.
    pub(crate) fn bar(&mut self, p0: Vec3, p1: Vec3, up: Vec3, w: f32, h: f32) {
        let d = p1 - p0;
        let len = d.length();
        let a = d / len;
        let up = (up - a * a.dot(up)).normalize();
        let side = a.cross(up);
        self.obox((p0 + p1) * 0.5, [a * (len * 0.5), up * (h * 0.5), side * (w * 0.5)]);
    }

    /// An I-beam from `p0` to `p1`, `[b, h, tf, tw]` = flange width, height (along `up`),
    /// flange thickness, web thickness: 24 vertices, 44 triangles.
    pub(crate) fn ibeam(&mut self, p0: Vec3, p1: Vec3, up: Vec3, [b, h, tf, tw]: [f32; 4]) {
        let base = self.nv;
        if self.count(24, 44) {
            return;
        }
        let a = (p1 - p0).normalize();
        let up = (up - a * a.dot(up)).normalize();
        let s = a.cross(up);
        let (x, y, t, y1, y2) = (b * 0.5, h * 0.5, tw * 0.5, -h * 0.5 + tf, h * 0.5 - tf);
        let prof = [
            (-x, -y),
            (x, -y),
            (x, y1),
            (t, y1),
            (t, y2),
            (x, y2),
            (x, y),
            (-x, y),
            (-x, y2),
            (-t, y2),
            (-t, y1),
            (-x, y1),
        ];
        for end in [p0, p1] {
            for &(px, py) in &prof {
                self.verts.push(p(end + s * px + up * py));
            }
        }
        for i in 0..12 {
            let j = (i + 1) % 12;
            self.quad(base + i, base + 12 + i, base + 12 + j, base + j);
        }
        const CAP: [[u32; 3]; 10] = [
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 10],
            [0, 10, 11],
            [10, 3, 4],
            [10, 4, 9],
            [6, 7, 8],
            [6, 8, 9],
            [6, 9, 4],
            [6, 4, 5],
        ];
        for t in CAP {
            self.tris.push([base + t[2], base + t[1], base + t[0]]);
            self.tris.push([base + 12 + t[0], base + 12 + t[1], base + 12 + t[2]]);
        }
    }

    /// Counts what [`Geo::sweep`] would make with `rings` stations (counting mode only).
    pub(crate) fn sweep_count(&mut self, rings: u32, n: u32, closed: bool, caps: bool) {
        debug_assert!(self.count_only);
        let joins = if closed { rings } else { rings - 1 };
        let cap = if caps && !closed { 2 * (n - 2) } else { 0 };
        self.count(rings * n, 2 * n * joins + cap);
    }

    /// A tube of `n` segments around through `st` (at least 2 stations, consecutive ones
    /// distinct in centre or radius). `closed` joins the last ring to the first (a torus);
    /// otherwise `caps` closes both ends with flat fans.
    pub(crate) fn sweep(&mut self, st: &[Station], n: u32, closed: bool, caps: bool) {
        let rings = st.len() as u32;
        let joins = if closed { rings } else { rings - 1 };
        let cap = if caps && !closed { 2 * (n - 2) } else { 0 };
        let base = self.nv;
        if self.count(rings * n, 2 * n * joins + cap) {
            return;
        }
        let table = self.trig.get(n);
        self.ring.clear();
        self.ring.extend_from_slice(table);
        for s in st {
            let (e1, e2) = (s.e1 * s.r, s.e2 * s.r);
            for &(c, sn) in &self.ring {
                self.verts.push(p(s.c + e1 * c + e2 * sn));
            }
        }
        for i in 0..joins {
            let r0 = base + i * n;
            let r1 = base + ((i + 1) % rings) * n;
            for k in 0..n {
                let k1 = (k + 1) % n;
                self.quad(r0 + k, r1 + k, r1 + k1, r0 + k1);
            }
        }
        if cap > 0 {
            let last = base + (rings - 1) * n;
            for k in 1..n - 1 {
                self.tris.push([base, base + k + 1, base + k]);
                self.tris.push([last, last + k, last + k + 1]);
            }
        }
    }

    /// A closed cylinder of radius `r` and `n` segments from `a` to `b`.
    pub(crate) fn cylinder(&mut self, a: Vec3, b: Vec3, r: f32, n: u32) {
        let d = (b - a).normalize();
        let e1 = perp(d);
        let e2 = d.cross(e1);
        self.sweep(&[Station { c: a, e1, e2, r }, Station { c: b, e1, e2, r }], n, false, true);
    }

    /// A torus around `axis` (unit) at `c`: major radius `rr`, tube radius `r`,
    /// `nmaj × nmin` quads.
    pub(crate) fn torus(&mut self, c: Vec3, axis: Vec3, rr: f32, r: f32, nmaj: u32, nmin: u32) {
        if self.count_only {
            self.sweep_count(nmaj, nmin, true, false);
            return;
        }
        let u = perp(axis);
        let v = axis.cross(u);
        let st: Vec<Station> = self
            .trig
            .get(nmaj)
            .iter()
            .map(|&(co, s)| {
                let radial = u * co + v * s;
                Station { c: c + radial * rr, e1: radial, e2: axis, r }
            })
            .collect();
        self.sweep(&st, nmin, true, false);
    }

    /// A surface of revolution around unit `axis` through `o`: profile points `(radius,
    /// height)`, `n` segments. A radius of 0 (first or last point only) is a pole.
    pub(crate) fn lathe(&mut self, o: Vec3, axis: Vec3, prof: &[(f32, f32)], n: u32) {
        let pole = |r: f32| r == 0.0;
        let nv: u32 = prof.iter().map(|&(r, _)| if pole(r) { 1 } else { n }).sum();
        let nt: u32 = prof.windows(2).map(|w| if pole(w[0].0) || pole(w[1].0) { n } else { 2 * n }).sum();
        let base = self.nv;
        if self.count(nv, nt) {
            return;
        }
        let e1 = perp(axis);
        let e2 = axis.cross(e1);
        let table = self.trig.get(n);
        self.ring.clear();
        self.ring.extend_from_slice(table);
        let mut starts = [0u32; 2];
        let mut at = base;
        for (j, &(r, h)) in prof.iter().enumerate() {
            let c = o + axis * h;
            let start = at;
            if pole(r) {
                self.verts.push(p(c));
                at += 1;
            } else {
                for &(co, s) in &self.ring {
                    self.verts.push(p(c + e1 * (r * co) + e2 * (r * s)));
                }
                at += n;
            }
            if j > 0 {
                let (a, b) = (starts[(j - 1) % 2], start);
                let (pa, pb) = (pole(prof[j - 1].0), pole(r));
                for k in 0..n {
                    let k1 = (k + 1) % n;
                    match (pa, pb) {
                        (true, _) => self.tris.push([a, b + k1, b + k]),
                        (_, true) => self.tris.push([a + k, a + k1, b]),
                        _ => self.quad(a + k, a + k1, b + k1, b + k),
                    }
                }
            }
            starts[j % 2] = start;
        }
    }
}
