//! Measures the import speed of a model file.
//!
//! ```text
//! cargo run --release -p megaray-import --example read_speed -- FILE [--gen SIDE] [--mem BYTES]
//! ```
//! With `--gen SIDE`, first writes FILE as a binary little-endian PLY: a SIDE x SIDE vertex
//! grid (x, y, z, nx, ny, nz floats; `uchar int` faces, two triangles per cell). Then imports
//! FILE (any supported format), counting triangles, and prints the time and the read speed.

use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::time::Instant;

use megaray_base::NoProgress;
use megaray_import::{import_file, ImportError, ImportOptions, Material, TriAttr, TriangleSink};

struct Sum(u64, f64);

impl TriangleSink for Sum {
    fn triangle(&mut self, p: [[f32; 3]; 3], _a: &TriAttr) -> Result<(), ImportError> {
        self.0 += 1;
        self.1 += p[0][0] as f64;
        Ok(())
    }
    fn material(&mut self, _m: Material) -> u32 {
        0
    }
}

fn generate(path: &PathBuf, side: u32) -> std::io::Result<()> {
    let mut w = BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    let nv = side as u64 * side as u64;
    let nf = 2 * (side as u64 - 1) * (side as u64 - 1);
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n\
         property float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face {nf}\n\
         property list uchar int vertex_indices\nend_header\n"
    )?;
    for y in 0..side {
        for x in 0..side {
            for c in [x as f32, y as f32, ((x ^ y) % 17) as f32, 0.0, 0.0, 1.0] {
                w.write_all(&c.to_le_bytes())?;
            }
        }
    }
    for y in 0..side - 1 {
        for x in 0..side - 1 {
            let i = (y * side + x) as i32;
            let s = side as i32;
            for t in [[i, i + 1, i + s + 1], [i, i + s + 1, i + s]] {
                w.write_all(&[3])?;
                for k in t {
                    w.write_all(&k.to_le_bytes())?;
                }
            }
        }
    }
    w.flush()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first().map(PathBuf::from) else {
        eprintln!("usage: read_speed FILE [--gen SIDE] [--mem BYTES]");
        std::process::exit(2);
    };
    let mut opts = ImportOptions::default();
    let mut i = 1;
    while i + 1 < args.len() {
        match args[i].as_str() {
            "--gen" => {
                let side: u32 = args[i + 1].parse().expect("SIDE");
                let t = Instant::now();
                generate(&path, side).expect("write");
                println!("wrote {} in {:.2} s", path.display(), t.elapsed().as_secs_f64());
            }
            "--mem" => opts.mem_limit = megaray_base::parse_size(&args[i + 1]).expect("BYTES"),
            other => panic!("unknown option {other}"),
        }
        i += 2;
    }
    let mut sink = Sum(0, 0.0);
    let t = Instant::now();
    let s = import_file(&path, &opts, &mut sink, &NoProgress).unwrap_or_else(|e| panic!("{e}"));
    let secs = t.elapsed().as_secs_f64();
    println!(
        "{} triangles, {} vertices ({} spilled), {} bytes in {secs:.2} s: {:.0} MB/s, {:.1} M triangles/s (checksum {})",
        s.triangles,
        s.vertices,
        s.spilled,
        s.bytes,
        s.bytes as f64 / secs / 1e6,
        s.triangles as f64 / secs / 1e6,
        sink.1
    );
}
