//! A rank's side of a frame: take batches of tiles, render them, send them back, until the
//! root has closed every lane. The same loop runs on the other ranks (over the transport)
//! and on the root's own render thread (over channels).

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use megaray_render::{render_pieces, Renderer};
use megaray_trace::Tracer;

use crate::wire::{ToRoot, ToWorker};
use crate::{ClusterError, LANES};

/// A worker's line to the root.
pub(crate) trait Link {
    fn send(&mut self, m: ToRoot);
    fn try_recv(&mut self) -> Result<Option<ToWorker>, ClusterError>;
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
/// without a message from the root.
pub(crate) fn run_frame(
    link: &mut dyn Link,
    r: &Renderer,
    tracer: &Tracer,
    pool: &rayon::ThreadPool,
    frame: u32,
    poll: Duration,
    silence: Duration,
) -> Result<WorkerFrame, ClusterError> {
    let mut out = WorkerFrame::default();
    let mut lanes = LANES;
    let mut queue: VecDeque<Vec<megaray_render::Rect>> = VecDeque::new();
    let mut heard = Instant::now();
    loop {
        // Nothing more comes for this frame once every lane is closed (and the channel to
        // the root's render thread is then dropped).
        while lanes > 0 {
            let Some(m) = link.try_recv()? else { break };
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
            let (pieces, stats) = pool.install(|| render_pieces(r, tracer, frame, &rects));
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
        std::thread::sleep(poll);
    }
}
