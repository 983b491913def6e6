//! `mpirun -n N megaray render ...`: one image rendered by N processes (`megaray-cluster`
//! over MPI, with the `mpi` feature). Every rank parses the same arguments and opens the same
//! scene file; rank 0 renders and writes the image, the other ranks render the tiles it hands
//! out and say nothing.

use anyhow::Result;
use megaray_scene::Scene;

/// The rank an MPI launcher gave this process, when it started it as one of several (read
/// from the variables launchers set, before MPI is touched).
pub(crate) fn launched_rank() -> Option<usize> {
    let var = |names: &[&str]| names.iter().find_map(|v| std::env::var(v).ok()?.trim().parse::<usize>().ok());
    let size = var(&["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"])?;
    (size > 1).then(|| var(&["OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK"]).unwrap_or(0))
}

/// An error already told (by rank 0): the process exits non-zero saying nothing more.
#[derive(Debug)]
pub(crate) struct Quiet;

impl std::fmt::Display for Quiet {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("stopped by rank 0")
    }
}

impl std::error::Error for Quiet {}

/// Refuses what a cluster run cannot do, before any rank has started working: `what`
/// names the options given that run in one process only.
pub(crate) fn refuse_single_process_options(what: &[(&str, bool)]) -> Result<()> {
    if launched_rank().is_none() {
        return Ok(());
    }
    if let Some((name, _)) = what.iter().find(|(_, given)| *given) {
        anyhow::bail!("{name} runs in one process; under mpirun, render renders still images (--frames, --time)");
    }
    Ok(())
}

/// A rank's part in a cluster session (over MPI; without the `mpi` feature there is never
/// one, and a process started by mpirun refuses rather than render the whole image once per
/// rank).
pub(crate) type Session = megaray_cluster::Cluster<Box<dyn megaray_cluster::Transport>>;

/// The session this process is part of, if an MPI launcher started it as one of several
/// ranks: MPI initialised, every rank checked to have opened the same scene file.
#[cfg(feature = "mpi")]
pub(crate) fn session(scene: &Scene, threads: usize, timeout_secs: f64) -> Result<Option<Session>> {
    use megaray_cluster::{mpi::MpiTransport, Cluster, ClusterError, ClusterOptions};
    if launched_rank().is_none() {
        return Ok(None);
    }
    let t: Box<dyn megaray_cluster::Transport> =
        Box::new(MpiTransport::init().ok_or_else(|| anyhow::anyhow!("MPI could not be initialised"))?);
    let opts =
        ClusterOptions { timeout: std::time::Duration::from_secs_f64(timeout_secs), ..ClusterOptions::default() };
    match Cluster::join(t, scene.header().header_checksum, threads, opts) {
        Ok(c) => Ok(Some(c)),
        Err(ClusterError::Refused(_)) => {
            // Rank 0 says why. A launcher ends the job when the first rank exits, which could
            // cut rank 0 off before its line: let it go first.
            std::thread::sleep(std::time::Duration::from_secs(2));
            Err(Quiet.into())
        }
        Err(e) => Err(e.into()),
    }
}

#[cfg(not(feature = "mpi"))]
pub(crate) fn session(_scene: &Scene, _threads: usize, _timeout_secs: f64) -> Result<Option<Session>> {
    match launched_rank() {
        Some(_) => anyhow::bail!(
            "this megaray was built without MPI, so under mpirun every rank would render the whole image; build it with `cargo build --release --features mpi`"
        ),
        None => Ok(None),
    }
}

/// The session's communication, per frame, for `--json`.
pub(crate) fn stats_json(c: &Session, frames: u32) -> serde_json::Value {
    let t = &c.total;
    let per = |v: f64| v / frames.max(1) as f64;
    serde_json::json!({
        "ranks": c.size(),
        "lost": c.lost(),
        "bytes_sent_per_frame": per(t.bytes_out as f64),
        "bytes_received_per_frame": per(t.bytes_in as f64),
        "messages_per_frame": per(t.messages as f64),
        "root_wait_seconds_per_frame": per(t.root_wait),
        "root_tile_share": t.root_tiles as f64 / t.tiles.max(1) as f64,
    })
}

/// The session's communication, per frame, on one line.
pub(crate) fn print_stats(c: &Session, frames: u32) {
    let t = &c.total;
    let per = |v: f64| v / frames.max(1) as f64;
    eprintln!(
        "on {} ranks, per frame: rank 0 sent {:.1} KB and received {:.1} KB in {:.0} messages, rendered {:.0}% of the tiles, and its render thread waited {:.1} ms",
        c.size(),
        per(t.bytes_out as f64) / 1e3,
        per(t.bytes_in as f64) / 1e3,
        per(t.messages as f64),
        100.0 * t.root_tiles as f64 / t.tiles.max(1) as f64,
        1e3 * per(t.root_wait)
    );
}

/// Ends the session at rank 0 once its work is `done` ("x.png written"). Ranks lost on the
/// way can neither be waited for nor finalised: then the whole job is ended (MPI_Abort),
/// saying why.
pub(crate) fn finish(mut c: Session, done: &str) {
    let lost = c.finish();
    if !lost.is_empty() {
        let line = format!("megaray: {done}; ending the job, as rank(s) {lost:?} stopped answering\n");
        eprint!("{line}");
        c.transport().abort(3);
    }
}

/// A worker rank of `view` or `serve`: renders rank 0's frames with the view's settings
/// (`opts`: shader, light samples, sky) until it ends the session.
pub(crate) fn serve_view(
    c: &mut Session,
    opts: &megaray_view::ViewOptions,
    tracer: &megaray_trace::Tracer,
    pool: &rayon::ThreadPool,
) -> Result<()> {
    let bounds = tracer.scene().header().bounds;
    let mut s = megaray_render::RenderSettings::new(megaray_render::Camera::framing(
        &bounds,
        megaray_render::DEFAULT_OFFSET,
        8,
        8,
    ));
    s.shader = opts.shader;
    s.light_samples = opts.light_samples;
    if opts.area.is_some() {
        s.sky = [0.0; 3];
    }
    let mut r = megaray_render::Renderer::new(s, &bounds);
    if let Some(area) = &opts.area {
        r = r.with_area_lights(area.clone());
    }
    c.serve(&mut r, opts.sky.clone(), tracer, pool)?;
    Ok(())
}

/// Rank 0's frames of a view, rendered across the session's ranks.
pub(crate) fn frame_source<'t>(
    c: &'t mut Session,
    tracer: &'t megaray_trace::Tracer,
    pool: &'t rayon::ThreadPool,
) -> megaray_view::FrameSource<'t> {
    Box::new(move |r, i| c.render_frame(r, tracer, pool, i, false).map_err(|e| e.to_string()))
}

/// A frame a page of `serve` asks of rank 0's main thread (the one that talks MPI).
pub(crate) struct FrameRequest {
    settings: megaray_render::RenderSettings,
    env: bool,
    area: Option<std::sync::Arc<megaray_render::AreaLights>>,
    index: u32,
    reply: std::sync::mpsc::Sender<Result<megaray_render::Frame, String>>,
}

/// A page's frames, asked of the main thread through `tx`.
pub(crate) fn request_source<'t>(tx: std::sync::mpsc::Sender<FrameRequest>) -> megaray_view::FrameSource<'t> {
    Box::new(move |r, index| {
        let (reply, answer) = std::sync::mpsc::channel();
        let area = r.world().area_lights().cloned();
        let req = FrameRequest { settings: r.settings.clone(), env: r.has_environment(), area, index, reply };
        tx.send(req).map_err(|_| "the cluster has stopped".to_string())?;
        answer.recv().map_err(|_| "the cluster has stopped".to_string())?
    })
}

/// Rank 0 of `serve`: renders the pages' frames across the ranks, one at a time, in the
/// order asked, until no page can ask any more.
pub(crate) fn serve_requests(
    c: &mut Session,
    requests: std::sync::mpsc::Receiver<FrameRequest>,
    sky: Option<std::sync::Arc<megaray_render::Environment>>,
    tracer: &megaray_trace::Tracer,
    pool: &rayon::ThreadPool,
) {
    let bounds = tracer.scene().header().bounds;
    // The renderer of the last request, kept while shader, light samples and sky stay.
    let mut last: Option<megaray_render::Renderer> = None;
    while let Ok(req) = requests.recv() {
        let s = &req.settings;
        let same = last.as_ref().is_some_and(|r| {
            r.settings.shader == s.shader
                && r.settings.light_samples == s.light_samples
                && r.has_environment() == req.env
                && r.world().area_lights().is_some() == req.area.is_some()
        });
        if !same {
            let mut fresh = megaray_render::Renderer::new(req.settings.clone(), &bounds);
            if let Some(area) = &req.area {
                fresh = fresh.with_area_lights(area.clone());
            }
            last = Some(match (req.env, &sky) {
                (true, Some(env)) => fresh.with_environment(env.clone()),
                _ => fresh,
            });
        }
        let r = last.as_mut().expect("made above");
        r.settings = req.settings;
        let _ = req.reply.send(c.render_frame(r, tracer, pool, req.index, false).map_err(|e| e.to_string()));
    }
}
