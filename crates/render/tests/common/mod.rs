//! Small scenes written as OBJ and built into scene files, for the render tests.
#![allow(dead_code)]

use std::f32::consts::PI;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use megaray_base::{NoProgress, Vec3};
use megaray_build::{build_scene, BuildOptions};

/// An OBJ under construction: positions, optional normals, faces grouped by material.
#[derive(Default)]
pub struct Obj {
    text: String,
    verts: usize,
    normals: usize,
}

/// The balls scene, built in `dir`: a floor 8 units square, a smooth sphere of radius 1 on
/// it (`bands` bands) and a faceted one of radius 0.5 (`small_bands`) beside it.
pub fn balls(dir: &Path, bands: u32, small_bands: u32) -> PathBuf {
    let mut obj = Obj::default();
    obj.quad([
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(-4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, -4.0),
    ]);
    obj.sphere(Vec3::new(0.0, 1.0, 0.0), 1.0, bands, true);
    obj.sphere(Vec3::new(1.8, 0.5, 1.0), 0.5, small_bands, false);
    obj.build(dir, "balls", None)
}

impl Obj {
    pub fn material(&mut self, name: &str) {
        writeln!(self.text, "usemtl {name}").unwrap();
    }

    /// A quad a, b, c, d (two triangles).
    pub fn quad(&mut self, q: [Vec3; 4]) {
        for v in q {
            writeln!(self.text, "v {} {} {}", v.x, v.y, v.z).unwrap();
        }
        let b = self.verts + 1;
        writeln!(self.text, "f {} {} {}\nf {} {} {}", b, b + 1, b + 2, b, b + 2, b + 3).unwrap();
        self.verts += 4;
    }

    /// A UV sphere, outward winding, `bands` x `2 * bands` quads, with vertex normals when
    /// `smooth`.
    pub fn sphere(&mut self, c: Vec3, r: f32, bands: u32, smooth: bool) {
        let segs = 2 * bands;
        let at = |i: u32, j: u32| {
            let (theta, phi) = (PI * i as f32 / bands as f32, 2.0 * PI * j as f32 / segs as f32);
            Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin())
        };
        let base_v = self.verts + 1;
        let base_n = self.normals + 1;
        for i in 0..=bands {
            for j in 0..=segs {
                let n = at(i, j);
                let p = c + n * r;
                writeln!(self.text, "v {} {} {}", p.x, p.y, p.z).unwrap();
                if smooth {
                    writeln!(self.text, "vn {} {} {}", n.x, n.y, n.z).unwrap();
                }
            }
        }
        let idx = |i: u32, j: u32| (i * (segs + 1) + j) as usize;
        let corner = |k: usize| {
            if smooth {
                format!("{}//{}", base_v + k, base_n + k)
            } else {
                format!("{}", base_v + k)
            }
        };
        for i in 0..bands {
            for j in 0..segs {
                let (a, b, cc, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
                // Outward winding: (a, d, cc) and (a, cc, b) seen from outside.
                if i != 0 {
                    writeln!(self.text, "f {} {} {}", corner(a), corner(d), corner(cc)).unwrap();
                }
                if i != bands - 1 {
                    writeln!(self.text, "f {} {} {}", corner(a), corner(cc), corner(b)).unwrap();
                }
            }
        }
        let n = ((bands + 1) * (segs + 1)) as usize;
        self.verts += n;
        if smooth {
            self.normals += n;
        }
    }

    /// Writes `name.obj` (and `name.mtl` when `mtl` is given) into `dir`; builds
    /// `name.mray`.
    pub fn build(&self, dir: &Path, name: &str, mtl: Option<&str>) -> PathBuf {
        let obj = dir.join(format!("{name}.obj"));
        let mut text = String::new();
        if let Some(m) = mtl {
            std::fs::write(dir.join(format!("{name}.mtl")), m).unwrap();
            text.push_str(&format!("mtllib {name}.mtl\n"));
        }
        text.push_str(&self.text);
        std::fs::write(&obj, text).unwrap();
        build_file(dir, &obj, name)
    }
}

/// Builds one model file into `dir/name.mray`.
pub fn build_file(dir: &Path, model: &Path, name: &str) -> PathBuf {
    let out = dir.join(format!("{name}.mray"));
    let opts = BuildOptions { build_mem: 256 << 20, tile_target: 64 << 10, threads: 2, ..BuildOptions::default() };
    build_scene(&[model.to_path_buf()], &out, &opts, &NoProgress).unwrap();
    out
}
