//! `megaray`: the command-line front end. Thin: it parses arguments into the library's
//! option structs, draws progress bars and prints results. Everything else lives in the
//! crates (`megaray-gen`, `-import`, `-build`, `-scene`, `-trace`, `-render`).

mod animate;
mod bench;
mod cluster;
mod cmd;
mod fault;
mod info;
mod inputs;
mod jpeg;
mod open;
mod paging;
mod pick;
mod progress;
mod serve;
mod show;
mod view;

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
    /// Generate a procedural model as a binary PLY (streamed, bounded memory)
    ///
    /// SPEC is one of:
    ///   grid:N              height field, 2*N*N triangles (as the Embree peer harness)
    ///   sphereflake:L[:S]   Haines sphere flake, L levels, S bands (as the peer harness)
    ///   plant:T             a CAD-like power plant of about T triangles (k/M/G suffixes)
    ///   forest:T[:U[:S]]    the seed's forest as a pbrt-v4 scene (-o forest.pbrt) with its
    ///                       S tree species (default 4; about U triangles each, default
    ///                       100k) as PLY files beside it: groves instanced level upon level
    ///                       until at least T triangles are shown (1e14, 500G, 2T), S x U
    ///                       unique; build it with megaray build
    ///   sky[:KEY=V,...]     a procedural sky and sun as a lat-long .hdr (or .exr) environment
    ///                       map, for --env. Keys (defaults):
    ///                         sun_elev   sun elevation, degrees (35)
    ///                         sun_azim   sun azimuth, degrees from +X toward +Z (120)
    ///                         turbidity  haze, 1.7 clear .. 10 hazy (3)
    ///                         sun        the sun disk's irradiance on a surface facing it (3)
    ///                         sun_size   the sun disk's angular diameter, degrees (2)
    ///                         width      map width in pixels, height is half (512)
    ///
    /// Examples:
    ///   megaray gen plant:10M -o plant.ply
    ///   megaray gen forest:1e14 -o forest.pbrt
    ///   megaray gen forest:1e14:10M:100 -o forest.pbrt      (a billion unique triangles)
    ///   megaray gen sky:sun_elev=20,sun_azim=60,turbidity=4 -o sky.hdr
    #[command(verbatim_doc_comment)]
    Gen(cmd::GenArgs),
    /// Build model files into one .mray scene file, out of core, in bounded memory.
    ///
    /// Inputs (merged into one scene): PLY (ascii/binary), OBJ (+ .mtl), STL (ascii/binary),
    /// glTF/GLB. A gen SPEC (e.g. grid:1000) is accepted as an input too.
    ///
    /// Scenes keep their structure (objects and instances, never flattened; their camera and
    /// lights become the scene's defaults): a pbrt-v4 scene (.pbrt, .pbrt.gz), or a glTF file
    /// given alone. See docs/INPUT.md for what is read and what is skipped.
    ///
    /// Example: megaray build plant.ply -o plant.mray --build-mem 1G
    ///
    /// Example: megaray build scene.pbrt -o scene.mray
    Build(cmd::BuildArgs),
    /// Render a scene file to a PNG or OpenEXR image, progressively
    ///
    /// Shaders (--shader): normal, diffuse (lights, shadows), phong (highlights), mirror and
    /// glass (recursive, --max-depth), ao (ambient occlusion), env (diffuse under the
    /// environment), path (global illumination: bounces, next-event estimation from the
    /// environment, multiple importance sampling), auto (by material; the default). Lights:
    /// the directional --light, or an environment (--env map or --sky procedural sky) turned
    /// into --env-lights virtual directional lights, split into --light-subsets subsets over
    /// 4x4 pixel tiles (interleaved sampling), --light-samples shadow rays per hit. --frames /
    /// --time accumulate frames progressively (new sample positions each).
    ///
    /// Examples:
    ///   megaray render plant.mray -o plant.png --res 1920x1080 --spp 4
    ///   megaray render plant.mray -o plant.png --sky sky:sun_elev=30 --shader env --frames 16
    ///   megaray render plant.mray -o plant.exr --env sky.hdr --env-rotate 90 --time 10 --aov depth,normal,albedo
    #[command(verbatim_doc_comment)]
    Render(Box<cmd::RenderArgs>),
    /// Describe a scene file: triangles, bounds, parts, tree depths, tiles, bytes per triangle.
    Info(info::InfoArgs),
    /// Generate a power plant, build it out of core, render it: the whole pipeline.
    Demo(cmd::DemoArgs),
    /// Measure ray and build throughput, in lines comparable with the Embree peer harness
    ///
    /// Same scenes, camera, ray sets, timing and checksums as shared/peers/embree (definitions
    /// in shared/BENCH.md): rays through pixel centres of a 60 degree camera looking at the
    /// bounding-box centre; per figure a warm-up pass, then --reps repetitions lasting at least
    /// --min-ms each, median reported. Figures on stdout, progress and notes on stderr.
    ///
    /// Kinds:
    ///   primary_1    one camera ray per pixel, one at a time (32x32 pixel tiles per thread)
    ///   primary_16   4x4 pixel packets (primary_8: 8x1; not measured unless asked for)
    ///   shadow_1     one any-hit ray per primary hit toward the light normalize(0.5, 1, 0.8)
    ///   diffuse_1    one cosine-distributed ray per primary hit (the peer's random numbers)
    ///   build        the in-core builder on the triangles in memory (pairs with the peer's
    ///                build_medium); median of 3 builds after a warm-up
    /// hits and sum_t are checksums: they must agree with the peer's for the speeds to compare.
    ///
    /// Examples:
    ///   megaray bench grid:1000                               all default kinds, 1 and 2 threads
    ///   megaray bench ../shared/models/stanford-bunny.obj --cam close --kinds primary_1,shadow_1
    ///   megaray bench scene.mray --threads 2 --reps 3 --min-ms 100
    ///   megaray bench sphereflake:4 --json >> megaray.jsonl
    ///
    /// Comparing with the peer (its figures in ../shared/peers/embree/results):
    ///   megaray bench ../shared/models/stanford-bunny.obj --name stanford-bunny.obj --json > megaray.jsonl
    ///   python3 ../shared/bench/compare.py ../shared/peers/embree/results/*.jsonl -- megaray.jsonl
    /// bench/vs_peer.sh runs the whole standard suite against the peer, the two harnesses in
    /// turn row by row, seconds apart (--stored: megaray alone against the peer's stored
    /// figures). Quote ratios, not absolute figures.
    #[command(verbatim_doc_comment)]
    Bench(bench::BenchArgs),
    /// Look around a scene (or a model file) in a window: fly with the keys, look with the
    /// mouse; frames keep up while moving and sharpen when still
    ///
    /// The scene is paged within --mem if given (rays whose tiles are missing are answered by
    /// levels of detail while they load). With no SCENE, the demo's plant.
    ///
    /// Examples:
    ///   megaray view plant.mray --mem 2G
    ///   megaray view model.glb
    ///   megaray view plant.mray --script tour.txt --out frames/     # no window: replay and write frames
    #[command(verbatim_doc_comment)]
    View(view::ViewArgs),
    /// Look around a scene from a web browser: serves one page whose canvas shows the view
    /// and sends the keys and mouse back (the window's controls)
    ///
    /// Each page (tab) has its own camera over the one scene and budget. Listens on loopback
    /// unless --bind says otherwise. With no SCENE, the demo's plant.
    ///
    /// Examples:
    ///   megaray serve plant.mray --mem 2G              # then open http://127.0.0.1:8080/
    ///   megaray serve model.glb --bind 0.0.0.0:8080    # other machines may view it
    #[command(verbatim_doc_comment)]
    Serve(serve::ServeArgs),
    /// What lies under a pixel, exactly: one ray through the full-detail index (loading only
    /// the tiles along it when paged); the component's name (input file, OBJ group, glTF
    /// node path), part, triangle, position, normal, distance, and the wall's thickness (or
    /// the clearance) behind it; with --to, a second pixel and the distance between the two
    ///
    /// Examples:
    ///   megaray pick plant.mray --pixel 512,300 --cam-offset 0,0.3,0.6
    ///   megaray pick car.mray --pixel 100,200 --to 400,220
    ///   megaray pick plant.mray --mem 2G --eye 10,5,3 --at 0,0,0 --res 640x480 --pixel 320,240 --json
    #[command(verbatim_doc_comment)]
    Pick(pick::PickArgs),
}

fn main() {
    let cli = Cli::parse();
    fault::ignore_file_size_signal();
    // Under mpirun only rank 0 shows progress.
    let rank = cluster::launched_rank();
    let bars = progress::Bars::new(cli.quiet || rank.is_some_and(|r| r > 0));
    // Output piped into `head` and the like: end quietly when it closes (not with sockets).
    if rank.is_none() && !matches!(cli.cmd, Command::View(_) | Command::Serve(_)) {
        fault::end_quietly_on_closed_pipe();
    }
    if let Err(e) = kernels_from_env().and_then(megaray_trace::Kernels::configure) {
        eprintln!("megaray: error: {e}");
        std::process::exit(1);
    }
    let res = match cli.cmd {
        Command::Gen(a) => cmd::gen(a, &bars),
        Command::Build(a) => cmd::build(a, &bars),
        Command::Render(a) => cmd::render(*a, &bars),
        Command::Info(a) => info::info(a),
        Command::Demo(a) => cmd::demo(a, &bars),
        Command::Bench(a) => bench::bench(a, &bars),
        Command::View(a) => view::view(a, &bars),
        Command::Serve(a) => serve::serve(a, &bars),
        Command::Pick(a) => pick::pick(a, &bars),
    };
    if let Err(e) = res {
        use megaray_base::Progress;
        bars.finish();
        if e.downcast_ref::<cluster::Quiet>().is_none() {
            // One write, so that the line stays whole among other ranks' output under mpirun.
            let who = rank.map(|r| format!("rank {r}: ")).unwrap_or_default();
            let line = format!("megaray: error: {who}{}\n", one_line(&e));
            eprint!("{line}");
        }
        std::process::exit(1);
    }
}

/// The kernels the environment asks for, to compare paths: `MEGARAY_ISA` (`avx512`, `avx2`
/// or `baseline`, as Embree's `isa=` chooses its own) and `MEGARAY_ASM` (`0` turns the
/// assembly kernel off). Unset or empty: the fastest this machine has. A bad value is an
/// error naming the variable.
fn kernels_from_env() -> Result<megaray_trace::Kernels, String> {
    let mut k = megaray_trace::Kernels::best();
    let var = |name: &str| std::env::var(name).ok().filter(|v| !v.trim().is_empty());
    if let Some(v) = var("MEGARAY_ISA") {
        k.isa = megaray_trace::Isa::parse(&v).map_err(|e| format!("MEGARAY_ISA: {e}"))?;
    }
    if let Some(v) = var("MEGARAY_ASM") {
        k.asm = match v.trim() {
            "1" | "on" => true,
            "0" | "off" => false,
            other => {
                return Err(format!(
                    "MEGARAY_ASM: unknown value {other:?} (use 0 to turn the assembly kernel off, 1 for on)"
                ))
            }
        };
    }
    Ok(k)
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
