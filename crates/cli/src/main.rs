//! `megaray`: the command-line front end. Thin: it parses arguments into the library's
//! option structs, draws progress bars and prints results. Everything else lives in the
//! crates (`megaray-gen`, `-import`, `-build`, `-scene`, `-trace`, `-render`).

mod cmd;
mod progress;

use clap::{Parser, Subcommand};

/// megaray: ray tracing of models far larger than memory.
///
/// The pipeline: `gen` (or your own PLY/OBJ/STL/glTF files) -> `build` (out-of-core index
/// into one .mray scene file) -> `render` (from the memory-mapped scene file).
/// `megaray demo` runs all of it on a generated power-plant model.
#[derive(Parser)]
#[command(name = "megaray", version, about, long_about, propagate_version = true)]
struct Cli {
    /// No progress bars.
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    cmd: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate a procedural model as a binary PLY (streamed, bounded memory).
    ///
    /// SPEC is one of:
    ///   grid:N              height field, 2*N*N triangles (as the Embree peer harness)
    ///   sphereflake:L[:S]   Haines sphere flake, L levels, S bands (as the peer harness)
    ///   plant:T             a CAD-like power plant of about T triangles (k/M/G suffixes)
    ///
    /// Example: megaray gen plant:10M -o plant.ply
    #[command(verbatim_doc_comment)]
    Gen(cmd::GenArgs),
    /// Build model files into one .mray scene file, out of core, in bounded memory.
    ///
    /// Inputs (merged into one scene): PLY (ascii/binary), OBJ (+ .mtl), STL (ascii/binary),
    /// glTF/GLB. A gen SPEC (e.g. grid:1000) is accepted as an input too.
    ///
    /// Example: megaray build plant.ply -o plant.mray --build-mem 1G
    Build(cmd::BuildArgs),
    /// Render a scene file to a PNG: Lambertian shading, one light, hard shadows.
    ///
    /// Example: megaray render plant.mray -o plant.png --res 1920x1080 --spp 4
    Render(cmd::RenderArgs),
    /// Describe a scene file: triangles, bounds, parts, tree depths, tiles, bytes per triangle.
    Info(cmd::InfoArgs),
    /// Generate a power plant, build it out of core, render it: the whole pipeline.
    Demo(cmd::DemoArgs),
}

fn main() {
    let cli = Cli::parse();
    let bars = progress::Bars::new(cli.quiet);
    let res = match cli.cmd {
        Command::Gen(a) => cmd::gen(a, &bars),
        Command::Build(a) => cmd::build(a, &bars),
        Command::Render(a) => cmd::render(a, &bars),
        Command::Info(a) => cmd::info(a),
        Command::Demo(a) => cmd::demo(a, &bars),
    };
    if let Err(e) = res {
        use megaray_base::Progress;
        bars.finish();
        eprintln!("megaray: error: {}", one_line(&e));
        std::process::exit(1);
    }
}

/// The error and its causes on one line.
fn one_line(e: &anyhow::Error) -> String {
    let mut s = e.to_string();
    for c in e.chain().skip(1) {
        let c = c.to_string();
        if !s.contains(&c) {
            s.push_str(": ");
            s.push_str(&c);
        }
    }
    s.replace('\n', " ")
}
