//! `grid:N` and `sphereflake:L[:S]`, bit for bit as the Embree peer harness makes them.
//!
//! The peer (`shared/peers/embree/embree_bench.cpp`, `gen_grid`, `add_sphere`, `flake`) is
//! compiled with `g++ -O3 -march=native`, and GCC contracts `a * b + c` into fused
//! multiply-adds (its default `-ffp-contract=fast` for C++) wherever the target has them. The
//! vertex coordinates it produces, and so the checksums of the benchmark, depend on exactly
//! which products were fused. The code below spells out those fusions with [`f32::mul_add`]
//! (read from GCC's `-fdump-tree-widening_mul` output of the harness and checked byte for byte
//! against the PLY files that `embree_bench --dump-ply` writes); every other operation is the
//! plain `f32` operation in the source's order. `sinf`/`cosf` are the C library's, as in the
//! peer.

use crate::sink::Emitter;
use crate::GenError;

/// `const float PI = 3.14159265358979f;` of the peer: the same `f32` as `std`'s PI.
const PI: f32 = std::f32::consts::PI;

/// Emits `grid:n` row by row: chunk `j` holds vertex row `j` and (for `j > 0`) the `2n`
/// triangles of the strip between rows `j - 1` and `j`, which reference the previous chunk.
pub(crate) fn grid(n: u32, out: &mut Emitter<'_>) -> Result<(), GenError> {
    let nf = n as f32;
    let row = n as usize + 1;
    let mut verts = Vec::with_capacity(row);
    let mut tris = Vec::with_capacity(2 * n as usize);
    // Everything that depends on x only, per column.
    let cols: Vec<(f32, f32, f32)> = (0..=n)
        .map(|i| {
            let x = -1.0 + (2.0 * i as f32) / nf;
            let t1 = (x * (3.0 * PI)).sin() * 0.10;
            let t3 = (x * 37.0).sin() * 0.02;
            (x, t1, t3)
        })
        .collect();
    for j in 0..=n {
        let z = -1.0 + (2.0 * j as f32) / nf;
        let c1 = (z * (2.0 * PI)).cos();
        let z7 = z * 7.0;
        let s4 = (z * 41.0).sin();
        verts.clear();
        for &(x, t1, t3) in &cols {
            // 0.10f*sin(3PI x)*cos(2PI z) + 0.05f*sin(11x + 7z) + 0.02f*sin(37x)*sin(41z)
            let t2 = x.mul_add(11.0, z7).sin() * 0.05;
            let y = t3.mul_add(s4, t1.mul_add(c1, t2));
            verts.push([x, y, z]);
        }
        tris.clear();
        if j > 0 {
            let first = out.next_vertex() - row as u64;
            let first = u32::try_from(first).map_err(|_| out.too_many())?;
            for i in 0..n {
                let a = first + i;
                let b = a + 1;
                let c = a + n + 1;
                let d = c + 1;
                tris.push([a, c, b]);
                tris.push([b, c, d]);
            }
        }
        out.chunk(&verts, &tris)?;
    }
    Ok(())
}

/// `cos(PI / 3)` and `sin(PI / 3)` as GCC folded them at compile time (correctly rounded).
const COS_EL: f32 = 0.499_999_97; // bits 0x3effffff
const SIN_EL: f32 = 0.866_025_45; // bits 0x3f5db3d8

type V3 = [f32; 3];

/// `normalize` of the peer: `len` is `sqrt(z*z + (x*x + y*y))` with both additions fused.
fn normalize(a: V3) -> V3 {
    let l = a[2].mul_add(a[2], a[0].mul_add(a[0], a[1] * a[1])).sqrt();
    if l > 0.0 {
        let s = 1.0 / l;
        [a[0] * s, a[1] * s, a[2] * s]
    } else {
        a
    }
}

/// `cross` of the peer, first product of each component fused.
fn cross(a: V3, b: V3) -> V3 {
    [a[1].mul_add(b[2], -(a[2] * b[1])), a[2].mul_add(b[0], -(a[0] * b[2])), a[0].mul_add(b[1], -(a[1] * b[0]))]
}

/// One UV sphere as one chunk: what `add_sphere` appends, with its trigonometry precomputed.
struct SphereTemplate {
    bands: u32,
    /// `(sin th, cos th)` per latitude ring `1..bands`.
    lat: Vec<(f32, f32)>,
    /// `(cos ph, sin ph)` per longitude `0..2*bands`.
    lon: Vec<(f32, f32)>,
    verts: Vec<V3>,
    tris: Vec<[u32; 3]>,
}

impl SphereTemplate {
    fn new(bands: u32) -> SphereTemplate {
        let s = bands as f32;
        let m = 2 * bands;
        let lat = (1..bands)
            .map(|i| {
                let th = (PI * i as f32) / s;
                (th.sin(), th.cos())
            })
            .collect();
        let lon = (0..m)
            .map(|k| {
                let ph = (2.0 * PI * k as f32) / m as f32;
                (ph.cos(), ph.sin())
            })
            .collect();
        SphereTemplate { bands, lat, lon, verts: Vec::new(), tris: Vec::new() }
    }

    fn emit(&mut self, c: V3, r: f32, out: &mut Emitter<'_>) -> Result<(), GenError> {
        let s = self.bands;
        let m = 2 * s;
        self.verts.clear();
        self.verts.push([c[0], c[1] + r, c[2]]);
        for &(st, ct) in &self.lat {
            let a = r * st;
            let y = r.mul_add(ct, c[1]);
            for &(cp, sp) in &self.lon {
                self.verts.push([a.mul_add(cp, c[0]), y, a.mul_add(sp, c[2])]);
            }
        }
        self.verts.push([c[0], c[1] - r, c[2]]);
        let base = u32::try_from(out.next_vertex()).map_err(|_| out.too_many())?;
        if base.checked_add(self.verts.len() as u32).is_none() {
            return Err(out.too_many());
        }
        let south = base + 1 + (s - 1) * m;
        let ring = |i: u32, k: u32| base + 1 + (i - 1) * m + (k % m);
        self.tris.clear();
        for k in 0..m {
            self.tris.push([base, ring(1, k + 1), ring(1, k)]);
        }
        for i in 1..s - 1 {
            for k in 0..m {
                self.tris.push([ring(i, k), ring(i, k + 1), ring(i + 1, k)]);
                self.tris.push([ring(i, k + 1), ring(i + 1, k + 1), ring(i + 1, k)]);
            }
        }
        for k in 0..m {
            self.tris.push([south, ring(s - 1, k), ring(s - 1, k + 1)]);
        }
        out.chunk(&self.verts, &self.tris)
    }
}

/// Emits `sphereflake:levels:bands`, one sphere per chunk, in the peer's depth-first order.
pub(crate) fn sphereflake(levels: u32, bands: u32, out: &mut Emitter<'_>) -> Result<(), GenError> {
    let mut sphere = SphereTemplate::new(bands);
    flake(&mut sphere, [0.0; 3], 1.0, [0.0, 1.0, 0.0], levels, out)
}

fn flake(sphere: &mut SphereTemplate, c: V3, r: f32, w: V3, level: u32, out: &mut Emitter<'_>) -> Result<(), GenError> {
    sphere.emit(c, r, out)?;
    if level == 0 {
        return Ok(());
    }
    let a = if w[0].abs() > 0.9 { [0.0, 1.0, 0.0] } else { [1.0, 0.0, 0.0] };
    let u = normalize(cross(a, w));
    let v = cross(w, u);
    for i in 0..9 {
        let (cel, sel, az) = if i < 6 {
            (1.0, 0.0, (2.0 * PI * i as f32) / 6.0)
        } else {
            (COS_EL, SIN_EL, (2.0 * PI * (i - 6) as f32) / 3.0 + PI / 6.0)
        };
        let ca = az.cos() * cel;
        let sa = az.sin() * cel;
        // u * (cos el cos az) + v * (cos el sin az) + w * sin el, fused as GCC fused it.
        let d = normalize([
            sa.mul_add(v[0], ca * u[0]) + w[0] * sel,
            sa.mul_add(v[1], ca * u[1]) + w[1] * sel,
            w[2].mul_add(sel, sa.mul_add(v[2], ca * u[2])),
        ]);
        let rc = r / 3.0;
        let k = r + rc;
        let cc = [k.mul_add(d[0], c[0]), k.mul_add(d[1], c[1]), k.mul_add(d[2], c[2])];
        flake(sphere, cc, rc, d, level - 1, out)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folded_constants_are_the_right_floats() {
        assert_eq!(COS_EL.to_bits(), 0x3eff_ffff);
        assert_eq!(SIN_EL.to_bits(), 0x3f5d_b3d8);
        assert_eq!(PI.to_bits(), 0x4049_0fdb); // 3.14159265358979f
    }
}
