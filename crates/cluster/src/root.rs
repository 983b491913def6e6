//! [`Cluster`]: the session every rank joins; the root's frame loop (the tile queue) and the
//! workers' service loop.

use std::collections::VecDeque;
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use megaray_render::{Accumulator, Environment, Frame, Piece, Rect, Renderer, TILE};
use megaray_trace::jobs::JobStats;
use megaray_trace::Tracer;

use crate::wire::{ToRoot, ToWorker};
use crate::worker::{relay, run_frame, ChannelLink};
use crate::{ClusterError, ClusterOptions, Transport, LANES};

/// What one frame cost in communication, seen from the root.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameComm {
    /// Bytes the root sent to other ranks.
    pub bytes_out: u64,
    /// Bytes the root received from other ranks.
    pub bytes_in: u64,
    /// Messages both ways.
    pub messages: u64,
    /// Seconds the frame took at the root.
    pub seconds: f64,
    /// Seconds of it the root's render thread did not render (waiting for tiles or for the
    /// other ranks' last ones).
    pub root_wait: f64,
    /// Tiles rendered by the root.
    pub root_tiles: u64,
    /// Tiles in the frame.
    pub tiles: u64,
}

/// A rank's part in a session; see the crate documentation.
pub struct Cluster<T: Transport> {
    t: T,
    opts: ClusterOptions,
    /// Render threads per rank (known at the root).
    threads: Vec<u32>,
    /// Ranks lost (known at the root).
    lost: Vec<bool>,
    /// The last frame's communication (at the root).
    pub last: FrameComm,
    /// All frames' communication so far (at the root).
    pub total: FrameComm,
    /// The next frame, begun on the other ranks (at the root).
    ahead: Option<Ahead>,
    /// What each tile cost in the last frame finished (at the root).
    costs: Option<TileCosts>,
    /// Whether the render threads run at `opts.render_nice` yet.
    niced: bool,
}

/// What each tile of a `w` x `h` frame cost to render: seconds of one thread, by tile index
/// (rows of tiles, as [`Rect::tiles`]). The next frame of the same size hands out the
/// costliest tiles first and sizes batches by cost, so that the frame ends on cheap tiles
/// spread over every rank instead of on one rank's batch of costly ones.
struct TileCosts {
    w: u32,
    h: u32,
    secs: Vec<f32>,
}

/// A batch's least predicted cost for another rank, per thread: enough work to hide the
/// round trip of its pieces and its next batch.
const MIN_REMOTE_BATCH_SECS: f64 = 1e-3;

/// Pieces added to the frame between two looks at the messages.
const SINK_AT_ONCE: usize = 4;

/// A tile's index in the rows of tiles of a frame `cols` tiles wide.
fn tile_index(r: &Rect, cols: u32) -> usize {
    ((r.y0 / TILE) * cols + r.x0 / TILE) as usize
}

/// A frame begun on the other ranks while the caller was busy with the one before
/// ([`Cluster::render_frame`] with `next`): its queue, and its message, to check that the
/// call for it asks for the same frame.
struct Ahead {
    frame: u32,
    message: (crate::Tag, Vec<u8>),
    q: Queue,
}

/// The root's view of one rank during a frame.
struct Peer {
    /// Batches sent and not yet back, oldest first.
    outstanding: VecDeque<Vec<Rect>>,
    /// Lanes waiting for tiles (the queue was empty while others still held some).
    parked: u32,
    /// When it last sent something back, or was given work while idle.
    since: Instant,
}

impl<T: Transport> Cluster<T> {
    /// Joins the session: every rank calls it with its scene file's header checksum and
    /// its render threads. The root collects every rank's hello and starts the session only
    /// if all opened the same file; otherwise every rank returns an error (the root's
    /// [`ClusterError::SceneDiffers`] names the rank, the others get
    /// [`ClusterError::Refused`]).
    pub fn join(t: T, checksum: u64, threads: usize, opts: ClusterOptions) -> Result<Cluster<T>, ClusterError> {
        let n = t.size();
        let mut c = Cluster {
            threads: vec![threads.max(1) as u32; n],
            lost: vec![false; n],
            t,
            opts,
            last: FrameComm::default(),
            total: FrameComm::default(),
            ahead: None,
            costs: None,
            niced: false,
        };
        if c.t.rank() != 0 {
            let (tag, b) = ToRoot::Hello { checksum, threads: threads as u32 }.encode();
            c.t.send(0, tag, &b);
            return match c.wait_root(Some(2 * opts.timeout))? {
                ToWorker::Start(None) => Ok(c),
                ToWorker::Start(Some(r)) => Err(ClusterError::Refused(r as usize)),
                other => Err(ClusterError::Protocol { rank: 0, what: format!("{other:?} before the start") }),
            };
        }
        let mut sums: Vec<Option<u64>> = vec![None; n];
        sums[0] = Some(checksum);
        let start = Instant::now();
        while sums.iter().any(Option::is_none) {
            match c.t.try_recv() {
                Some((from, tag, bytes)) => match ToRoot::decode(from, tag, &bytes)? {
                    ToRoot::Hello { checksum, threads } => {
                        sums[from] = Some(checksum);
                        c.threads[from] = threads.max(1);
                    }
                    other => {
                        return Err(ClusterError::Protocol { rank: from, what: format!("{other:?} before hello") })
                    }
                },
                None if start.elapsed() > opts.timeout => {
                    let rank = sums.iter().position(Option::is_none).unwrap();
                    return Err(ClusterError::NoHello { rank, secs: opts.timeout.as_secs_f64() });
                }
                None => std::thread::sleep(opts.poll),
            }
        }
        let differs = sums.iter().position(|s| *s != Some(checksum));
        for w in 1..n {
            let (tag, b) = ToWorker::Start(differs.map(|r| r as u32)).encode();
            c.t.send(w, tag, &b);
        }
        match differs {
            Some(rank) => Err(ClusterError::SceneDiffers { rank, ours: checksum, theirs: sums[rank].unwrap() }),
            None => Ok(c),
        }
    }

    /// This rank.
    pub fn rank(&self) -> usize {
        self.t.rank()
    }

    /// The ranks in the session.
    pub fn size(&self) -> usize {
        self.t.size()
    }

    /// Whether this is the root (rank 0), which owns the frames.
    pub fn is_root(&self) -> bool {
        self.t.rank() == 0
    }

    /// Puts `pool`'s threads below this one, once ([`ClusterOptions::render_nice`]).
    fn lower_priority(&mut self, pool: &rayon::ThreadPool) {
        if !self.niced {
            crate::lower_priority(pool, self.opts.render_nice);
            self.niced = true;
        }
    }

    /// The ranks lost so far (at the root).
    pub fn lost(&self) -> Vec<usize> {
        (0..self.lost.len()).filter(|&r| self.lost[r]).collect()
    }

    /// The transport (to end the job: [`Transport::abort`]).
    pub fn transport(&self) -> &T {
        &self.t
    }

    /// The next message from the root, waiting up to `limit` (sleeping between looks: `poll`
    /// for the first 20 ms, as the next frame usually comes at once, then longer and longer
    /// while nothing comes, up to 500 us).
    fn wait_root(&self, limit: Option<Duration>) -> Result<ToWorker, ClusterError> {
        let start = Instant::now();
        let mut nap = self.opts.poll;
        loop {
            if let Some((from, tag, bytes)) = self.t.try_recv() {
                if from != 0 {
                    return Err(ClusterError::Protocol { rank: from, what: "a message to a worker".into() });
                }
                return ToWorker::decode(0, tag, &bytes);
            }
            if limit.is_some_and(|l| start.elapsed() > l) {
                return Err(ClusterError::RootSilent { rank: self.t.rank(), secs: start.elapsed().as_secs_f64() });
            }
            std::thread::sleep(nap);
            if start.elapsed() > Duration::from_millis(20) {
                nap = (nap * 2).min(Duration::from_micros(500));
            }
        }
    }

    /// On a worker: renders what the root asks for, frame after frame, until the root ends
    /// the session. Each frame's camera, level-of-detail error, shader and AOVs come from
    /// the root, and whether it is lit by `env` (the environment this rank made from the
    /// same arguments as the root). Returns the frames rendered.
    pub fn serve(
        &mut self,
        r: &mut Renderer,
        env: Option<Arc<Environment>>,
        tracer: &Tracer,
        pool: &rayon::ThreadPool,
    ) -> Result<u32, ClusterError> {
        assert!(!self.is_root(), "the root renders with render_frame");
        self.lower_priority(pool);
        let mut frames = 0;
        loop {
            match self.wait_root(None)? {
                ToWorker::Frame { frame, lod_error, camera, shader, aovs, env: lit, highlight, shown } => {
                    if r.settings.shader != shader || r.has_environment() != lit {
                        let mut s = r.settings.clone();
                        s.shader = shader;
                        let mut fresh = Renderer::new(s, &tracer.scene().header().bounds);
                        if let Some(area) = r.world().area_lights() {
                            fresh = fresh.with_area_lights(area.clone());
                        }
                        *r = match (lit, &env) {
                            (false, _) => fresh,
                            (true, Some(env)) => fresh.with_environment(env.clone()),
                            (true, None) => {
                                let what = "a frame lit by an environment this rank has not got".into();
                                return Err(ClusterError::Protocol { rank: 0, what });
                            }
                        };
                    }
                    r.settings.camera = camera;
                    r.settings.aovs = aovs;
                    r.settings.highlight = highlight;
                    r.settings.visibility = shown;
                    tracer.set_lod_error(lod_error);
                    let silence = 2 * self.opts.timeout + Duration::from_secs(10);
                    if let Some(p) = tracer.pager() {
                        p.begin_working_set();
                    }
                    relay(&self.t, r, tracer, pool, frame, self.opts.poll, silence)?;
                    let tiles = tracer.pager().map_or_else(Vec::new, |p| p.working_set());
                    let (tag, b) = ToRoot::Seen { frame, tiles }.encode();
                    self.t.send(0, tag, &b);
                    frames += 1;
                }
                ToWorker::Stop => return Ok(frames),
                other => return Err(ClusterError::Protocol { rank: 0, what: format!("{other:?} between frames") }),
            }
        }
    }

    /// On the root: ends the session (the other ranks' [`Cluster::serve`] return). Returns
    /// the ranks lost; if there are any, the job can only end by [`Transport::abort`].
    pub fn finish(&mut self) -> Vec<usize> {
        if let Some(a) = self.ahead.take() {
            // A frame begun and never asked for: the other ranks finish it first. An error
            // here (a rank lost) shows in the ranks returned.
            let _ = self.drain(a);
        }
        let (tag, b) = ToWorker::Stop.encode();
        for w in 1..self.t.size() {
            if !self.lost[w] {
                self.t.send(w, tag, &b);
            }
        }
        self.lost()
    }

    /// On the root: renders frame `frame` of `r`'s camera across the ranks (this rank's
    /// share on a thread of its own, over `pool`), equal bit for bit to
    /// `render_frame(r, tracer, frame)` without a deadline. The level-of-detail error in
    /// force is `tracer`'s, sent to every rank. With `next`, see
    /// [`Cluster::accumulate_frame`].
    pub fn render_frame(
        &mut self,
        r: &Renderer,
        tracer: &Tracer,
        pool: &rayon::ThreadPool,
        frame: u32,
        next: bool,
    ) -> Result<Frame, ClusterError> {
        let s = &r.settings;
        let mut f = Frame::new(s.camera.width, s.camera.height, s.aovs);
        let jobs = self.run(r, tracer, pool, frame, next, &mut |pc| f.put(pc))?;
        f.jobs = jobs;
        Ok(f)
    }

    /// On the root: [`Cluster::render_frame`] added to `acc` as its pieces come
    /// ([`Accumulator::add_piece`]), with no frame put together; the sums equal those of
    /// `acc.add_frame` of the frame. With `next`, the caller says that frame `frame + 1` of
    /// the same renderer and error comes next: the other ranks begin it as soon as this one
    /// is done, while the caller is busy with this one. A call that then asks for
    /// something else is still right, only slower: the frame begun is finished and thrown
    /// away first.
    pub fn accumulate_frame(
        &mut self,
        r: &Renderer,
        tracer: &Tracer,
        pool: &rayon::ThreadPool,
        frame: u32,
        acc: &mut Accumulator,
        next: bool,
    ) -> Result<(), ClusterError> {
        acc.begin_frame(r.settings.aovs);
        let jobs = self.run(r, tracer, pool, frame, next, &mut |pc| acc.add_piece(pc))?;
        acc.end_frame(&jobs);
        Ok(())
    }

    /// Runs frame `frame` across the ranks, each piece to `sink` as it comes; returns the
    /// frame loop's counts.
    fn run(
        &mut self,
        r: &Renderer,
        tracer: &Tracer,
        pool: &rayon::ThreadPool,
        frame: u32,
        next: bool,
        sink: &mut dyn FnMut(&Piece),
    ) -> Result<JobStats, ClusterError> {
        assert!(self.is_root(), "workers render with serve");
        self.lower_priority(pool);
        let start = Instant::now();
        let message = frame_message(r, tracer, frame);
        let mut q = match self.ahead.take() {
            Some(a) if a.frame == frame && a.message == message => a.q,
            Some(a) => {
                self.drain(a)?;
                self.begin(r, frame, &message)
            }
            None => self.begin(r, frame, &message),
        };
        let (to_local, local_rx) = mpsc::channel();
        let (local_tx, from_local) = mpsc::channel();
        let poll = self.opts.poll;
        let (res, busy) = std::thread::scope(|s| {
            let local = s.spawn(move || {
                let mut link = ChannelLink { tx: local_tx, rx: local_rx, rank: 0 };
                pool.install(|| run_frame(&mut link, r, tracer, frame, poll, Duration::MAX))
            });
            let mut send = Sender { t: &self.t, local: Some(&to_local), threads: &self.threads };
            for _ in 0..LANES {
                q.feed(&mut send, 0, frame);
            }
            let res = q.dispatch(&mut send, &from_local, &mut self.lost, frame, self.opts, sink);
            // Closing the channel ends the render thread if an error left it waiting.
            drop(to_local);
            let busy = local.join().expect("the root's render thread panicked");
            (res, busy)
        });
        res?;
        let busy = busy?.busy;
        // The other ranks' lookups join this one's working set before the next frame
        // begins anywhere (they would come behind its pieces otherwise).
        self.take_seen(Some(tracer), frame, &mut q.comm)?;
        let cam = r.settings.camera;
        self.costs = Some(TileCosts { w: cam.width, h: cam.height, secs: std::mem::take(&mut q.measured) });
        if next {
            let message = frame_message(r, tracer, frame + 1);
            let q = self.begin(r, frame + 1, &message);
            self.ahead = Some(Ahead { frame: frame + 1, message, q });
        }
        // The pieces not added yet, once the other ranks have the next frame's work.
        q.unsunk.drain(..).for_each(|pc| sink(&pc));
        q.comm.seconds = start.elapsed().as_secs_f64();
        q.comm.root_wait = (q.comm.seconds - busy).max(0.0);
        self.last = q.comm;
        let t = &mut self.total;
        t.bytes_out += q.comm.bytes_out;
        t.bytes_in += q.comm.bytes_in;
        t.messages += q.comm.messages;
        t.seconds += q.comm.seconds;
        t.root_wait += q.comm.root_wait;
        t.root_tiles += q.comm.root_tiles;
        t.tiles += q.comm.tiles;
        Ok(JobStats { finished: (cam.width * cam.height) as u64, rays: q.rays, ..q.jobs })
    }

    /// Starts frame `frame` of `r` on the other ranks: sends them its message and
    /// [`LANES`] batches each. The queue returned has no frame buffer yet.
    fn begin(&mut self, r: &Renderer, frame: u32, message: &(crate::Tag, Vec<u8>)) -> Queue {
        let cam = r.settings.camera;
        let mut tiles = Rect::tiles(cam.width, cam.height);
        let n_tiles = tiles.len();
        // The last frame's costs, if it had this size: costliest tiles first.
        let cost: Vec<f32> = match &self.costs {
            Some(c) if (c.w, c.h) == (cam.width, cam.height) && c.secs.len() == n_tiles => c.secs.clone(),
            _ => Vec::new(),
        };
        if !cost.is_empty() {
            let mut order: Vec<usize> = (0..n_tiles).collect();
            order.sort_by(|&a, &b| cost[b].total_cmp(&cost[a]));
            tiles = order.into_iter().map(|k| tiles[k]).collect();
        }
        let now = Instant::now();
        let mut q = Queue {
            left: cost.iter().map(|&c| c as f64).sum(),
            cols: cam.width.div_ceil(TILE),
            measured: vec![0.0; n_tiles],
            unsunk: VecDeque::new(),
            cost,
            queue: tiles.iter().copied().collect(),
            peers: (0..self.t.size()).map(|_| Peer { outstanding: VecDeque::new(), parked: 0, since: now }).collect(),
            aovs: r.settings.aovs,
            rays: 0,
            jobs: JobStats::default(),
            done: 0,
            comm: FrameComm { tiles: tiles.len() as u64, ..FrameComm::default() },
            total_threads: (0..self.t.size()).filter(|&p| !self.lost[p]).map(|p| self.threads[p]).sum(),
        };
        let mut send = Sender { t: &self.t, local: None, threads: &self.threads };
        for p in (1..self.t.size()).filter(|&p| !self.lost[p]) {
            self.t.send(p, message.0, &message.1);
            q.comm.bytes_out += message.1.len() as u64;
            q.comm.messages += 1;
            for _ in 0..LANES {
                q.feed(&mut send, p, frame);
            }
        }
        q
    }

    /// Finishes a frame begun and not asked for (its pixels thrown away): the other ranks
    /// send back the batches they hold, and their lanes are closed.
    fn drain(&mut self, a: Ahead) -> Result<(), ClusterError> {
        let mut q = a.q;
        q.queue.clear();
        let held: usize = q.peers.iter().flat_map(|p| p.outstanding.iter().map(Vec::len)).sum();
        q.comm.tiles = (q.done + held) as u64;
        // No render thread here: a sender kept, so that waiting on it only times out.
        let (_keep, none) = mpsc::channel();
        let mut send = Sender { t: &self.t, local: None, threads: &self.threads };
        q.dispatch(&mut send, &none, &mut self.lost, a.frame, self.opts, &mut |_| {})?;
        self.take_seen(None, a.frame, &mut q.comm)
    }

    /// Takes every other rank's [`ToRoot::Seen`] of frame `frame` (its lanes closed), adding
    /// the tiles to `tracer`'s working set when it pages. A rank that sends nothing for the
    /// timeout is lost.
    fn take_seen(&mut self, tracer: Option<&Tracer>, frame: u32, comm: &mut FrameComm) -> Result<(), ClusterError> {
        let n = self.t.size();
        let mut waiting: Vec<bool> = (0..n).map(|p| p != 0 && !self.lost[p]).collect();
        let start = Instant::now();
        while waiting.contains(&true) {
            match self.t.try_recv() {
                Some((from, tag, bytes)) if from < n && waiting[from] => {
                    comm.bytes_in += bytes.len() as u64;
                    comm.messages += 1;
                    match ToRoot::decode(from, tag, &bytes)? {
                        ToRoot::Seen { frame: f, tiles } if f == frame => {
                            if let Some(p) = tracer.and_then(|t| t.pager()) {
                                p.note_working_set(&tiles);
                            }
                            waiting[from] = false;
                        }
                        other => {
                            let what = format!("{other:?} after frame {frame}");
                            return Err(ClusterError::Protocol { rank: from, what });
                        }
                    }
                }
                // A lost rank's late message.
                Some(_) => {}
                None if start.elapsed() > self.opts.timeout => {
                    for (p, w) in waiting.iter_mut().enumerate() {
                        if std::mem::take(w) {
                            self.lost[p] = true;
                            let secs = start.elapsed().as_secs_f64();
                            // One write: the line stays whole among other ranks' output.
                            let line =
                                format!("megaray: rank {p} sent nothing for {secs:.0} s after frame {frame}; going on without it\n");
                            eprint!("{line}");
                        }
                    }
                }
                None => std::thread::sleep(self.opts.poll),
            }
        }
        Ok(())
    }
}

/// The message that starts frame `frame` of `r` on a worker.
fn frame_message(r: &Renderer, tracer: &Tracer, frame: u32) -> (crate::Tag, Vec<u8>) {
    let s = &r.settings;
    let (camera, shader, aovs, env) = (s.camera, s.shader, s.aovs, r.has_environment());
    let (highlight, shown) = (s.highlight, s.visibility.clone());
    ToWorker::Frame { frame, lod_error: tracer.lod_error(), camera, shader, aovs, env, highlight, shown }.encode()
}

/// Sends the root's messages: to its own render thread over a channel, to the others over
/// the transport.
struct Sender<'a, T: Transport> {
    t: &'a T,
    local: Option<&'a mpsc::Sender<ToWorker>>,
    threads: &'a [u32],
}

impl<T: Transport> Sender<'_, T> {
    /// Sends `m` to rank `p`; returns the bytes sent over the transport.
    fn send(&mut self, p: usize, m: ToWorker) -> u64 {
        if p == 0 {
            // A render thread that has already stopped (after an error) needs nothing.
            let _ = self.local.map(|l| l.send(m));
            return 0;
        }
        let (tag, b) = m.encode();
        self.t.send(p, tag, &b);
        b.len() as u64
    }
}

/// The state of one frame at the root.
struct Queue {
    queue: VecDeque<Rect>,
    peers: Vec<Peer>,
    /// Whether pieces carry AOVs.
    aovs: bool,
    /// Rays of the pieces back.
    rays: u64,
    jobs: JobStats,
    /// Tiles back.
    done: usize,
    comm: FrameComm,
    total_threads: u32,
    /// Each tile's predicted cost (the last frame's, by tile index), or empty: then batches
    /// are sized by tile count alone.
    cost: Vec<f32>,
    /// The predicted cost of the tiles in the queue.
    left: f64,
    /// Tiles per row of tiles.
    cols: u32,
    /// Each tile's cost in this frame, as its pieces come back.
    measured: Vec<f32>,
    /// Pieces back and not yet added to the frame.
    unsunk: VecDeque<Piece>,
}

impl Queue {
    /// Runs the frame's queue until every tile is back (every rank given its first
    /// batches already): gives a rank a new batch for each one back, adds pieces to `sink`
    /// between (the last ones are left in `unsunk`), and requeues the tiles of ranks lost.
    fn dispatch<T: Transport>(
        &mut self,
        send: &mut Sender<T>,
        from_local: &mpsc::Receiver<ToRoot>,
        lost: &mut [bool],
        frame: u32,
        opts: ClusterOptions,
        sink: &mut dyn FnMut(&Piece),
    ) -> Result<(), ClusterError> {
        let (poll, timeout) = (opts.poll, opts.timeout);
        let total = self.comm.tiles as usize;
        // The sleep when nothing came: from `poll`, doubling while nothing comes, to 16x.
        let mut nap = poll;
        while self.done < total {
            let mut got = false;
            // One message from another rank and one from this rank's render thread a pass:
            // taking either in a burst starves the other (adding a batch to the frame can
            // take longer than rendering the next, so a burst may never end).
            if let Some((from, tag, bytes)) = send.t.try_recv() {
                got = true;
                self.comm.bytes_in += bytes.len() as u64;
                self.comm.messages += 1;
                if from >= lost.len() || lost[from] {
                    continue;
                }
                match ToRoot::decode(from, tag, &bytes)? {
                    ToRoot::Done { frame: f, pieces, stats } if f == frame => {
                        self.take(send, from, frame, pieces, stats)?;
                    }
                    other => {
                        return Err(ClusterError::Protocol { rank: from, what: format!("{other:?} in frame {frame}") })
                    }
                }
            }
            if let Ok(m) = from_local.try_recv() {
                got = true;
                self.take_local(send, m, frame)?;
            }
            for p in 1..self.peers.len() {
                let peer = &mut self.peers[p];
                if lost[p] || peer.outstanding.is_empty() || peer.since.elapsed() <= timeout {
                    continue;
                }
                lost[p] = true;
                let secs = peer.since.elapsed().as_secs_f64();
                // One write: the line stays whole among other ranks' output.
                let line = format!(
                    "megaray: rank {p} sent nothing for {secs:.0} s while rendering; its tiles go to the other ranks\n"
                );
                eprint!("{line}");
                for batch in peer.outstanding.drain(..).rev() {
                    for t in batch.into_iter().rev() {
                        self.left += self.cost.get(tile_index(&t, self.cols)).map_or(0.0, |&c| c as f64);
                        self.queue.push_front(t);
                    }
                }
                peer.parked = 0;
                self.total_threads -= send.threads[p];
                // Lanes left waiting take the requeued tiles.
                for (q, &gone) in lost.iter().enumerate() {
                    while !gone && self.peers[q].parked > 0 && !self.queue.is_empty() {
                        self.peers[q].parked -= 1;
                        self.feed(send, q, frame);
                    }
                }
            }
            // Pieces are added a few at a time between looks at the messages: adding is
            // the longest thing this thread does, and a rank waiting for its next batch
            // should not wait behind it.
            for pc in self.unsunk.drain(..self.unsunk.len().min(SINK_AT_ONCE)) {
                got = true;
                sink(&pc);
            }
            if got {
                nap = poll;
                continue;
            }
            // Nothing came: wait for this rank's render thread (which ends the wait at once)
            // or until the other ranks may have sent something. The longer the batches they
            // hold, the longer until one needs its next: from `poll`, doubling while nothing
            // comes, to 4x, or 16x while every rank holds a batch of 32 tiles or more.
            let shortest = (1..self.peers.len())
                .filter(|&p| !lost[p])
                .filter_map(|p| self.peers[p].outstanding.back().map(Vec::len))
                .min()
                .unwrap_or(0);
            let most = if shortest >= 32 { 16 } else { 4 };
            // This rank's render thread idle (the frame's end): its core is free, so look
            // often, as what comes now is what the frame waits for.
            if self.peers[0].outstanding.is_empty() {
                nap = poll;
            }
            match from_local.recv_timeout(nap) {
                Ok(m) => {
                    self.take_local(send, m, frame)?;
                    nap = poll;
                }
                Err(e) => {
                    // A render thread that has stopped (after an error) cannot end the wait.
                    if e == mpsc::RecvTimeoutError::Disconnected {
                        std::thread::sleep(nap);
                    }
                    nap = (nap * 2).min(poll * most);
                }
            }
        }
        // Every tile is back: close every lane (the caller adds the pieces not added yet).
        for (p, &gone) in lost.iter().enumerate() {
            while !gone && self.peers[p].parked > 0 {
                self.peers[p].parked -= 1;
                self.send_counted(send, p, ToWorker::Work { frame, rects: Vec::new() });
            }
        }
        Ok(())
    }

    /// Takes a message from this rank's own render thread.
    fn take_local<T: Transport>(&mut self, send: &mut Sender<T>, m: ToRoot, frame: u32) -> Result<(), ClusterError> {
        if let ToRoot::Done { pieces, stats, .. } = m {
            self.comm.root_tiles += pieces.len() as u64;
            self.take(send, 0, frame, pieces, stats)?;
        }
        Ok(())
    }

    fn send_counted<T: Transport>(&mut self, send: &mut Sender<T>, p: usize, m: ToWorker) {
        let n = send.send(p, m);
        if p != 0 {
            self.comm.bytes_out += n;
            self.comm.messages += 1;
        }
    }

    /// Gives rank `p` its next batch: a share of the work left in proportion to its threads
    /// (a quarter of its share, so that batches shrink toward the frame's end), at least one
    /// tile and at most 32 per thread (long batches hide the round trip, see `docs/PERF.md`).
    /// The work is the tiles' predicted cost when the last frame measured it (another rank's
    /// batch then costs at least [`MIN_REMOTE_BATCH_SECS`] a thread), else their count.
    /// With none left, the lane is parked.
    fn feed<T: Transport>(&mut self, send: &mut Sender<T>, p: usize, frame: u32) {
        if self.queue.is_empty() {
            self.peers[p].parked += 1;
            return;
        }
        let th = send.threads[p] as usize;
        let total = self.total_threads.max(1) as usize;
        let most = (32 * th).min(self.queue.len());
        let n = if self.cost.is_empty() {
            (self.queue.len() * th / (4 * total)).clamp(1, most)
        } else {
            let mut want = self.left * th as f64 / (4 * total) as f64;
            if p != 0 {
                want = want.max(MIN_REMOTE_BATCH_SECS * th as f64);
            }
            let (mut n, mut got) = (0, 0.0);
            while n < most && (n == 0 || got < want) {
                got += self.cost[tile_index(&self.queue[n], self.cols)] as f64;
                n += 1;
            }
            self.left = (self.left - got).max(0.0);
            n
        };
        let rects: Vec<Rect> = self.queue.drain(..n).collect();
        let peer = &mut self.peers[p];
        if peer.outstanding.is_empty() {
            peer.since = Instant::now();
        }
        peer.outstanding.push_back(rects.clone());
        self.send_counted(send, p, ToWorker::Work { frame, rects });
    }

    /// Takes rank `p`'s pieces (they must be its oldest batch, in order) and gives it its
    /// next batch; the pieces wait in `unsunk` to be added to the frame.
    fn take<T: Transport>(
        &mut self,
        send: &mut Sender<T>,
        p: usize,
        frame: u32,
        pieces: Vec<Piece>,
        stats: JobStats,
    ) -> Result<(), ClusterError> {
        let peer = &mut self.peers[p];
        let batch = peer.outstanding.pop_front().unwrap_or_default();
        if batch.len() != pieces.len() || batch.iter().zip(&pieces).any(|(r, pc)| *r != pc.rect) {
            return Err(ClusterError::Protocol { rank: p, what: "tiles it was not given".into() });
        }
        let aovs = self.aovs;
        for pc in &pieces {
            let n = pc.rect.area();
            let sizes_ok = pc.color.len() == n
                && (!aovs || (pc.depth.len() == n && pc.normal.len() == n && pc.albedo.len() == n))
                && (aovs || pc.depth.is_empty())
                && (pc.approx.is_empty() || pc.approx.len() == n);
            if !sizes_ok {
                return Err(ClusterError::Protocol {
                    rank: p,
                    what: format!("a tile {:?} of the wrong size", pc.rect),
                });
            }
        }
        peer.since = Instant::now();
        self.done += batch.len();
        self.jobs.suspended += stats.suspended;
        self.jobs.wait_secs += stats.wait_secs;
        self.feed(send, p, frame);
        for pc in &pieces {
            self.rays += pc.rays;
            if let Some(m) = self.measured.get_mut(tile_index(&pc.rect, self.cols)) {
                // A worker's figure, trusted only as far as it is a duration.
                *m = if pc.secs.is_finite() { pc.secs.clamp(0.0, 1e3) } else { 0.0 };
            }
        }
        self.unsunk.extend(pieces);
        Ok(())
    }
}
