//! A rank's side of a frame: take batches of tiles, render them, send them back, until the
//! root has closed every lane. The loop runs inside the rank's thread pool, on a thread of
//! its own (so that a batch waiting in its queue starts at once, with no hand-over to the
//! pool), talking over channels: on the root to the queue, on the other ranks to the thread
//! that talks MPI ([`relay`]).

use std::collections::VecDeque;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use megaray_render::{render_pieces, Renderer};
use megaray_trace::Tracer;

use crate::wire::{ToRoot, ToWorker};
use crate::{ClusterError, Transport, LANES};

/// A worker's line to the root.
pub(crate) trait Link {
    fn send(&mut self, m: ToRoot);
    /// The next message, waiting for one up to `wait` (not at all when zero).
    fn recv(&mut self, wait: Duration) -> Result<Option<ToWorker>, ClusterError>;
    /// This worker's rank (for errors).
    fn rank(&self) -> usize;
}

/// What a worker did in a frame.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct WorkerFrame {
    /// Seconds spent rendering.
    pub busy: f64,
}

/// Runs frame `frame` on this worker: renders each batch that arrives, sends it back, and
/// returns when [`LANES`] empty batches have closed its lanes. Gives up after `silence`
/// without a message from the root. Call it inside the rank's pool.
pub(crate) fn run_frame(
    link: &mut dyn Link,
    r: &Renderer,
    tracer: &Tracer,
    frame: u32,
    poll: Duration,
    silence: Duration,
) -> Result<WorkerFrame, ClusterError> {
    let mut out = WorkerFrame::default();
    let mut lanes = LANES;
    let mut queue: VecDeque<Vec<megaray_render::Rect>> = VecDeque::new();
    let mut heard = Instant::now();
    // How long the next look at the messages may wait: only when there is nothing to render
    // (a message ends the wait at once).
    let mut wait = Duration::ZERO;
    loop {
        // Nothing more comes for this frame once every lane is closed (and the channel to
        // the root's render thread is then dropped).
        while lanes > 0 {
            let Some(m) = link.recv(std::mem::take(&mut wait))? else { break };
            heard = Instant::now();
            match m {
                ToWorker::Work { frame: f, rects } if f == frame => match rects.is_empty() {
                    true => lanes -= 1,
                    false => queue.push_back(rects),
                },
                other => {
                    let what = format!("{other:?} in the middle of frame {frame}");
                    return Err(ClusterError::Protocol { rank: 0, what });
                }
            }
        }
        if let Some(rects) = queue.pop_front() {
            let t = Instant::now();
            let (pieces, stats) = render_pieces(r, tracer, frame, &rects);
            out.busy += t.elapsed().as_secs_f64();
            link.send(ToRoot::Done { frame, pieces, stats });
            continue;
        }
        if lanes == 0 {
            return Ok(out);
        }
        if heard.elapsed() > silence {
            return Err(ClusterError::RootSilent { rank: link.rank(), secs: silence.as_secs_f64() });
        }
        wait = poll * 20;
    }
}

/// A render thread's link: channels.
pub(crate) struct ChannelLink {
    pub tx: mpsc::Sender<ToRoot>,
    pub rx: mpsc::Receiver<ToWorker>,
    pub rank: usize,
}

impl Link for ChannelLink {
    fn send(&mut self, m: ToRoot) {
        let _ = self.tx.send(m);
    }
    fn recv(&mut self, wait: Duration) -> Result<Option<ToWorker>, ClusterError> {
        let got = match wait.is_zero() {
            true => self.rx.try_recv().map_err(|e| e == mpsc::TryRecvError::Disconnected),
            false => self.rx.recv_timeout(wait).map_err(|e| e == mpsc::RecvTimeoutError::Disconnected),
        };
        match got {
            Ok(m) => Ok(Some(m)),
            Err(false) => Ok(None),
            Err(true) => Err(ClusterError::Protocol { rank: 0, what: "the frame's messages stopped".into() }),
        }
    }
    fn rank(&self) -> usize {
        self.rank
    }
}

/// Runs frame `frame` on a worker rank: [`run_frame`] on a thread in `pool`, while this
/// thread (the one that talks MPI) relays the root's batches to it and its pieces back,
/// until the root has closed every lane and the last pieces have gone.
pub(crate) fn relay<T: Transport>(
    t: &T,
    r: &Renderer,
    tracer: &Tracer,
    pool: &rayon::ThreadPool,
    frame: u32,
    poll: Duration,
    silence: Duration,
) -> Result<WorkerFrame, ClusterError> {
    let (to_render, rx) = mpsc::channel();
    let (tx, from_render) = mpsc::channel();
    let rank = t.rank();
    std::thread::scope(|s| {
        let render = s.spawn(move || {
            let mut link = ChannelLink { tx, rx, rank };
            pool.install(|| run_frame(&mut link, r, tracer, frame, poll, silence))
        });
        let pump = || -> Result<(), ClusterError> {
            // Lanes open, and batches the render thread holds (given and not sent back).
            let (mut open, mut held, mut nap) = (LANES, 0u32, poll);
            loop {
                let mut got = false;
                // This frame's messages only: after its lanes close comes the next frame's.
                while open > 0 {
                    let Some((from, tag, bytes)) = t.try_recv() else { break };
                    got = true;
                    if from != 0 {
                        return Err(ClusterError::Protocol { rank: from, what: "a message to a worker".into() });
                    }
                    let m = ToWorker::decode(0, tag, &bytes)?;
                    match &m {
                        ToWorker::Work { rects, .. } if rects.is_empty() => open -= 1,
                        _ => held += 1,
                    }
                    let _ = to_render.send(m);
                }
                let done = render.is_finished();
                let back = |m: ToRoot| {
                    let (tag, b) = m.encode();
                    t.send(0, tag, &b);
                };
                while let Ok(m) = from_render.try_recv() {
                    (got, held) = (true, held.saturating_sub(1));
                    back(m);
                }
                if done {
                    return Ok(());
                }
                if got {
                    nap = poll;
                    continue;
                }
                // Nothing came. While the render thread holds a batch beyond the one it
                // renders (or the lanes are closed), the root has nothing urgent to say:
                // wait for the render thread alone. While it holds none, its core is free
                // and the next batch is what it waits for: look at MPI often. Otherwise,
                // soon.
                let wait = match (open == 0 || held >= 2, held == 0) {
                    (true, _) => poll * 20,
                    (false, true) => poll,
                    (false, false) => nap,
                };
                nap = (nap * 2).min(poll * 4);
                match from_render.recv_timeout(wait) {
                    Ok(m) => {
                        (nap, held) = (poll, held.saturating_sub(1));
                        back(m);
                    }
                    Err(mpsc::RecvTimeoutError::Timeout) => {}
                    // The render thread has ended: `is_finished` says so next time round.
                    Err(mpsc::RecvTimeoutError::Disconnected) => std::thread::yield_now(),
                }
            }
        };
        let res = pump();
        // An error here leaves the render thread without messages: closing its channel ends it.
        drop(to_render);
        let frame = render.join().expect("a render thread panicked");
        res.and(frame)
    })
}
