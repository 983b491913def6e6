//! The messages between ranks, as bytes: little-endian fields one after another, read back
//! with every length checked (a short or malformed message is an error naming the rank, never
//! a panic or an allocation sized by an unchecked count).

use megaray_base::{Camera, Vec3};
use std::sync::Arc;

use megaray_render::{Builtin, Piece, Rect, Section, Visibility};
use megaray_trace::jobs::JobStats;

use crate::ClusterError;

/// A message's kind, sent as the transport's tag.
pub type Tag = u8;

/// Worker → root: `Hello` (the first message: scene checksum, threads).
pub const HELLO: Tag = 1;
/// Root → worker: the verdict on the hellos (`Start`).
pub const START: Tag = 2;
/// Root → worker: a frame begins (`Frame`).
pub const FRAME: Tag = 3;
/// Root → worker: tiles to render, or none (the lane ends).
pub const WORK: Tag = 4;
/// Worker → root: rendered tiles.
pub const DONE: Tag = 5;
/// Root → worker: the session ends.
pub const STOP: Tag = 6;
/// Worker → root: the tiles its frame looked up (`Seen`).
pub const SEEN: Tag = 7;

/// What the root tells a worker.
#[derive(Clone, Debug, PartialEq)]
pub enum ToWorker {
    /// Whether to start: `None`, or the rank whose scene file differs.
    Start(Option<u32>),
    /// Frame `frame` begins, seen by `camera`, with `lod_error` pixels allowed to levels of
    /// detail, shaded by `shader` (with AOVs when `aovs`, under the environment map when
    /// `env`), the component `highlight`ed and what `shown` (hidden, X-rayed, sections):
    /// what a view changes from frame to frame.
    Frame {
        frame: u32,
        lod_error: f32,
        camera: Camera,
        shader: Builtin,
        aovs: bool,
        env: bool,
        highlight: Option<u32>,
        shown: Option<Arc<Visibility>>,
    },
    /// Tiles of frame `frame` to render; none ends one of the worker's lanes.
    Work { frame: u32, rects: Vec<Rect> },
    /// The session ends.
    Stop,
}

/// What a worker tells the root.
#[derive(Clone, Debug, PartialEq)]
pub enum ToRoot {
    /// The worker's scene file checksum and render threads.
    Hello { checksum: u64, threads: u32 },
    /// The tiles of one `Work` message of frame `frame`, rendered.
    Done { frame: u32, pieces: Vec<Piece>, stats: JobStats },
    /// After frame `frame`'s lanes have closed: the tiles the worker's rays looked up in it
    /// (its pager's working set; none when it does not page), which the root adds to its
    /// own, so that the level of detail it steers by is the whole frame's.
    Seen { frame: u32, tiles: Vec<u32> },
}

/// Appends little-endian fields.
#[derive(Default)]
struct Out(Vec<u8>);

impl Out {
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.u32(v.to_bits());
    }
    fn vec3(&mut self, v: Vec3) {
        v.to_array().into_iter().for_each(|c| self.f32(c));
    }
    fn bytes(&mut self, b: &[u8]) {
        self.0.extend_from_slice(b);
    }
    fn rect(&mut self, r: &Rect) {
        [r.x0, r.y0, r.x1, r.y1].into_iter().for_each(|v| self.u32(v));
    }
    /// Per-component flags: their count, then bits packed 32 to a word.
    fn flags(&mut self, f: &[bool]) {
        self.u32(f.len() as u32);
        for w in f.chunks(32) {
            self.u32(w.iter().enumerate().fold(0, |a, (k, &b)| a | (b as u32) << k));
        }
    }
    fn visibility(&mut self, v: Option<&Visibility>) {
        let Some(v) = v else { return self.u32(0) };
        self.u32(1);
        self.flags(&v.hidden);
        self.flags(&v.xray);
        self.u32(v.sections.len() as u32);
        for s in &v.sections {
            self.vec3(s.normal);
            self.f32(s.offset);
            self.u32(s.only.is_some() as u32);
            if let Some(o) = &s.only {
                self.flags(o);
            }
        }
    }
}

/// Reads little-endian fields, every read checked against the message's length.
struct In<'a> {
    b: &'a [u8],
    from: usize,
}

impl<'a> In<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], ClusterError> {
        if self.b.len() < n {
            return Err(ClusterError::Protocol { rank: self.from, what: "a message ended early".into() });
        }
        let (h, t) = self.b.split_at(n);
        self.b = t;
        Ok(h)
    }
    fn u32(&mut self) -> Result<u32, ClusterError> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    fn u64(&mut self) -> Result<u64, ClusterError> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    fn f32(&mut self) -> Result<f32, ClusterError> {
        Ok(f32::from_bits(self.u32()?))
    }
    fn vec3(&mut self) -> Result<Vec3, ClusterError> {
        Ok(Vec3::new(self.f32()?, self.f32()?, self.f32()?))
    }
    fn rect(&mut self) -> Result<Rect, ClusterError> {
        Ok(Rect { x0: self.u32()?, y0: self.u32()?, x1: self.u32()?, y1: self.u32()? })
    }
    fn flags(&mut self) -> Result<Vec<bool>, ClusterError> {
        let n = self.u32()? as usize;
        let words: Vec<u32> = self.pods(n.div_ceil(32))?;
        Ok((0..n).map(|k| words[k / 32] >> (k % 32) & 1 != 0).collect())
    }
    fn visibility(&mut self) -> Result<Option<Visibility>, ClusterError> {
        if self.u32()? == 0 {
            return Ok(None);
        }
        let (hidden, xray) = (self.flags()?, self.flags()?);
        let n = self.u32()? as usize;
        // A section takes at least 20 bytes: no more of them than the bytes left allow.
        if n > self.b.len() / 20 {
            return Err(ClusterError::Protocol { rank: self.from, what: "a count past the message's end".into() });
        }
        let mut sections = Vec::with_capacity(n);
        for _ in 0..n {
            let (normal, offset) = (self.vec3()?, self.f32()?);
            let only = if self.u32()? != 0 { Some(self.flags()?) } else { None };
            sections.push(Section { normal, offset, only });
        }
        Ok(Some(Visibility { hidden, xray, sections }))
    }
    /// `n` values of `T` (checked against the bytes left before anything is allocated).
    fn pods<T: bytemuck::Pod>(&mut self, n: usize) -> Result<Vec<T>, ClusterError> {
        let len = n.checked_mul(std::mem::size_of::<T>()).filter(|&l| l <= self.b.len());
        let len = len
            .ok_or_else(|| ClusterError::Protocol { rank: self.from, what: "a count past the message's end".into() })?;
        Ok(bytemuck::pod_collect_to_vec(self.take(len)?))
    }
    fn end(&self) -> Result<(), ClusterError> {
        match self.b.is_empty() {
            true => Ok(()),
            false => Err(ClusterError::Protocol { rank: self.from, what: "a message longer than its fields".into() }),
        }
    }
}

impl ToWorker {
    /// Its tag and bytes.
    pub fn encode(&self) -> (Tag, Vec<u8>) {
        let mut o = Out::default();
        let tag = match self {
            ToWorker::Start(differs) => {
                o.u32(differs.map_or(u32::MAX, |r| r));
                START
            }
            ToWorker::Frame { frame, lod_error, camera: c, shader, aovs, env, highlight, shown } => {
                o.u32(*frame);
                o.f32(*lod_error);
                [c.eye, c.fwd, c.right, c.up].into_iter().for_each(|v| o.vec3(v));
                o.f32(c.tan_half);
                o.u32(c.width);
                o.u32(c.height);
                o.u32(Builtin::ALL.iter().position(|(_, b)| b == shader).unwrap_or(0) as u32);
                o.u32(*aovs as u32 | (*env as u32) << 1);
                o.u32(highlight.unwrap_or(u32::MAX));
                o.visibility(shown.as_deref());
                FRAME
            }
            ToWorker::Work { frame, rects } => {
                o.u32(*frame);
                o.u32(rects.len() as u32);
                rects.iter().for_each(|r| o.rect(r));
                WORK
            }
            ToWorker::Stop => STOP,
        };
        (tag, o.0)
    }

    /// The message of `tag` and `bytes` from rank `from`.
    pub fn decode(from: usize, tag: Tag, bytes: &[u8]) -> Result<ToWorker, ClusterError> {
        let mut i = In { b: bytes, from };
        let m = match tag {
            START => ToWorker::Start(Some(i.u32()?).filter(|&r| r != u32::MAX)),
            FRAME => {
                let (frame, lod_error) = (i.u32()?, i.f32()?);
                let (eye, fwd, right, up) = (i.vec3()?, i.vec3()?, i.vec3()?, i.vec3()?);
                let camera = Camera { eye, fwd, right, up, tan_half: i.f32()?, width: i.u32()?, height: i.u32()? };
                let shader = Builtin::ALL.get(i.u32()? as usize).map(|(_, b)| *b);
                let shader =
                    shader.ok_or_else(|| ClusterError::Protocol { rank: from, what: "an unknown shader".into() })?;
                let flags = i.u32()?;
                let highlight = Some(i.u32()?).filter(|&c| c != u32::MAX);
                let shown = i.visibility()?.map(Arc::new);
                let (aovs, env) = (flags & 1 != 0, flags & 2 != 0);
                ToWorker::Frame { frame, lod_error, camera, shader, aovs, env, highlight, shown }
            }
            WORK => {
                let frame = i.u32()?;
                let n = i.u32()? as usize;
                if n > i.b.len() / 16 {
                    return Err(ClusterError::Protocol { rank: from, what: "a count past the message's end".into() });
                }
                let rects = (0..n).map(|_| i.rect()).collect::<Result<_, _>>()?;
                ToWorker::Work { frame, rects }
            }
            STOP => ToWorker::Stop,
            t => return Err(ClusterError::Protocol { rank: from, what: format!("unknown message tag {t}") }),
        };
        i.end()?;
        Ok(m)
    }
}

/// Piece flags: AOVs follow the colours; approximate-pixel flags follow.
const AOVS: u32 = 1;
const APPROX: u32 = 2;

impl ToRoot {
    /// Its tag and bytes.
    pub fn encode(&self) -> (Tag, Vec<u8>) {
        let mut o = Out::default();
        let tag = match self {
            ToRoot::Hello { checksum, threads } => {
                o.u64(*checksum);
                o.u32(*threads);
                HELLO
            }
            ToRoot::Done { frame, pieces, stats } => {
                o.u32(*frame);
                o.u32(pieces.len() as u32);
                [stats.finished, stats.unfinished, stats.suspended, stats.rays, stats.wait_secs.to_bits()]
                    .into_iter()
                    .for_each(|v| o.u64(v));
                for p in pieces {
                    o.rect(&p.rect);
                    o.u64(p.rays);
                    o.u32(p.secs.to_bits());
                    let flags = ((!p.depth.is_empty() as u32) * AOVS) | ((!p.approx.is_empty() as u32) * APPROX);
                    o.u32(flags);
                    o.bytes(bytemuck::cast_slice(&p.color));
                    if flags & AOVS != 0 {
                        o.bytes(bytemuck::cast_slice(&p.depth));
                        o.bytes(bytemuck::cast_slice(&p.normal));
                        o.bytes(bytemuck::cast_slice(&p.albedo));
                    }
                    if flags & APPROX != 0 {
                        p.approx.iter().for_each(|&a| o.0.push(a as u8));
                    }
                }
                DONE
            }
            ToRoot::Seen { frame, tiles } => {
                o.u32(*frame);
                o.u32(tiles.len() as u32);
                o.bytes(bytemuck::cast_slice(tiles));
                SEEN
            }
        };
        (tag, o.0)
    }

    /// The message of `tag` and `bytes` from rank `from`.
    pub fn decode(from: usize, tag: Tag, bytes: &[u8]) -> Result<ToRoot, ClusterError> {
        let mut i = In { b: bytes, from };
        let m = match tag {
            HELLO => ToRoot::Hello { checksum: i.u64()?, threads: i.u32()? },
            DONE => {
                let frame = i.u32()?;
                let n = i.u32()? as usize;
                let stats = JobStats {
                    finished: i.u64()?,
                    unfinished: i.u64()?,
                    suspended: i.u64()?,
                    rays: i.u64()?,
                    wait_secs: f64::from_bits(i.u64()?),
                };
                if n > i.b.len() / 32 {
                    return Err(ClusterError::Protocol { rank: from, what: "a count past the message's end".into() });
                }
                let mut pieces = Vec::with_capacity(n);
                for _ in 0..n {
                    let rect = i.rect()?;
                    let area =
                        (rect.x1 as u64).checked_sub(rect.x0 as u64).zip((rect.y1 as u64).checked_sub(rect.y0 as u64));
                    if !matches!(area, Some((w, h)) if w * h <= i.b.len() as u64) {
                        return Err(ClusterError::Protocol {
                            rank: from,
                            what: format!("a tile {rect:?} past the message's end"),
                        });
                    }
                    let (rays, secs, flags) = (i.u64()?, f32::from_bits(i.u32()?), i.u32()?);
                    let a = rect.area();
                    let mut p = Piece { rect, rays, secs, color: i.pods(a)?, ..Piece::default() };
                    if flags & AOVS != 0 {
                        (p.depth, p.normal, p.albedo) = (i.pods(a)?, i.pods(a)?, i.pods(a)?);
                    }
                    if flags & APPROX != 0 {
                        p.approx = i.take(a)?.iter().map(|&b| b != 0).collect();
                    }
                    pieces.push(p);
                }
                ToRoot::Done { frame, pieces, stats }
            }
            SEEN => {
                let frame = i.u32()?;
                let n = i.u32()? as usize;
                ToRoot::Seen { frame, tiles: i.pods(n)? }
            }
            t => return Err(ClusterError::Protocol { rank: from, what: format!("unknown message tag {t}") }),
        };
        i.end()?;
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn piece(aovs: bool, approx: bool) -> Piece {
        let rect = Rect { x0: 3, y0: 5, x1: 6, y1: 7 };
        let n = rect.area();
        let f = |k: usize| k as f32 * 0.5 - 1.0;
        Piece {
            rect,
            color: (0..n).map(|k| [f(k), f(k + 1), f(k + 2)]).collect(),
            depth: if aovs { (0..n).map(f).collect() } else { Vec::new() },
            normal: if aovs { (0..n).map(|k| [f(k), 0.0, 1.0]).collect() } else { Vec::new() },
            albedo: if aovs { (0..n).map(|k| [0.5, f(k), 0.25]).collect() } else { Vec::new() },
            approx: if approx { (0..n).map(|k| k % 2 == 0).collect() } else { Vec::new() },
            rays: 1234,
            secs: 0.25,
        }
    }

    #[test]
    fn messages_round_trip() {
        let camera = Camera::look_at(Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO, Vec3::Y, 50.0, 640, 480);
        for m in [
            ToWorker::Start(None),
            ToWorker::Start(Some(3)),
            ToWorker::Frame {
                frame: 7,
                lod_error: 1.5,
                camera,
                shader: Builtin::Env,
                aovs: true,
                env: false,
                highlight: None,
                shown: None,
            },
            ToWorker::Frame {
                frame: 8,
                lod_error: 0.0,
                camera,
                shader: Builtin::Ao,
                aovs: false,
                env: true,
                highlight: Some(3),
                shown: Some(Arc::new(Visibility {
                    hidden: (0..70).map(|k| k % 3 == 0).collect(),
                    xray: vec![false, true],
                    sections: vec![
                        Section::new(Vec3::X, Vec3::Y),
                        Section { only: Some(vec![true; 33]), ..Section::new(Vec3::ZERO, -Vec3::Z) },
                    ],
                })),
            },
            ToWorker::Work { frame: 2, rects: vec![Rect { x0: 0, y0: 32, x1: 32, y1: 64 }; 3] },
            ToWorker::Work { frame: 2, rects: Vec::new() },
            ToWorker::Stop,
        ] {
            let (tag, bytes) = m.encode();
            assert_eq!(ToWorker::decode(1, tag, &bytes).unwrap(), m);
        }
        let stats = JobStats { finished: 1, unfinished: 2, suspended: 3, rays: 4, wait_secs: 0.25 };
        for m in [
            ToRoot::Hello { checksum: 0xdead_beef_0123, threads: 4 },
            ToRoot::Done { frame: 9, pieces: vec![piece(false, false), piece(true, true), piece(false, true)], stats },
            ToRoot::Seen { frame: 3, tiles: vec![0, 7, 1 << 30] },
            ToRoot::Seen { frame: 4, tiles: Vec::new() },
        ] {
            let (tag, bytes) = m.encode();
            assert_eq!(ToRoot::decode(1, tag, &bytes).unwrap(), m);
        }
    }

    #[test]
    fn damaged_messages_are_errors() {
        let stats = JobStats::default();
        let (tag, bytes) = ToRoot::Done { frame: 1, pieces: vec![piece(true, true)], stats }.encode();
        // Every truncation, and one byte too many, is an error naming the rank.
        for n in 0..bytes.len() {
            let e = ToRoot::decode(2, tag, &bytes[..n]).unwrap_err();
            assert!(e.to_string().contains("rank 2"), "{e}");
        }
        let mut long = bytes.clone();
        long.push(0);
        assert!(ToRoot::decode(2, tag, &long).is_err());
        // A lying count.
        let mut lying = bytes.clone();
        lying[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(ToRoot::decode(2, tag, &lying).is_err());
        let (tag, bytes) = ToRoot::Seen { frame: 1, tiles: vec![5, 6] }.encode();
        for n in 0..bytes.len() {
            assert!(ToRoot::decode(2, tag, &bytes[..n]).is_err());
        }
        let mut lying = bytes.clone();
        lying[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(ToRoot::decode(2, tag, &lying).is_err());
        let (tag, mut bytes) = ToWorker::Work { frame: 1, rects: vec![Rect::default()] }.encode();
        bytes[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(ToWorker::decode(0, tag, &bytes).is_err());
        assert!(ToWorker::decode(0, 99, &[]).is_err());
    }
}
