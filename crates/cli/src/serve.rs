//! `megaray serve`: the view core behind a web page. One page and one WebSocket, nothing else:
//! `GET /` answers the page embedded in the binary (`page.html`), `GET /ws` upgrades to a
//! socket that carries JPEG frames to the page and small JSON input messages back. Each
//! connection has its own camera (its own `ViewCore`) over the one scene, tracer and budget.
//!
//! Thin and defensive: a request head is read up to 16 KiB, a socket message up to 4 KiB; a
//! malformed or oversized message closes that connection with a log line; no path from a
//! request ever reaches the file system.

use std::io::{Cursor, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use image::ImageEncoder;
use megaray_render::ToneMap;
use megaray_trace::Tracer;
use megaray_view::{Event, Key, PartOp, ViewCore, Viewpoint};
use serde_json::{json, Value};
use tungstenite::protocol::WebSocketConfig;
use tungstenite::{Message, WebSocket};

use crate::progress::Bars;
use crate::view::ViewerArgs;

/// The page, embedded.
const PAGE: &str = include_str!("page.html");
/// The longest request head read.
const MAX_HEAD: usize = 16 << 10;
/// The longest socket message (and frame) a page may send: input messages are tens of bytes.
const MAX_MESSAGE: usize = 4 << 10;
/// Frames sent and not yet acknowledged by the page: more waits (a slow link gets fewer
/// frames, not a queue of old ones).
const MAX_UNACKED: u32 = 3;
/// The largest view a page may ask for.
const MAX_SIDE: u32 = 2560;
/// JPEG quality of the frames.
const JPEG_QUALITY: u8 = 85;

/// `megaray serve`.
#[derive(Args)]
#[command(after_help = crate::view::CONTROLS)]
pub struct ServeArgs {
    #[command(flatten)]
    pub viewer: ViewerArgs,
    /// The address to listen on. The default answers this machine only; another address (for
    /// example 0.0.0.0:8080) lets other machines view the scene, and the log says so.
    #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:8080")]
    pub bind: String,
    /// The most pages viewing at once (each has its own camera and frame buffers).
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub max_clients: usize,
}

pub fn serve(a: ServeArgs, bars: &Bars) -> Result<()> {
    if a.max_clients == 0 {
        bail!("--max-clients must be 1 or more");
    }
    let opened = crate::open::scene_for(a.viewer.scene.as_deref(), &a.viewer.open, bars)?;
    let (scene, pager) = a.viewer.paging.open(&opened.path)?;
    let tracer = Tracer::paged_or_new(&scene, pager.as_ref()).with_lod_error(a.viewer.lod_error);
    let pool = crate::cmd::pool(a.viewer.threads)?;
    a.viewer.options(640, 480)?; // the options' errors before listening
    crate::view::scene_options(&mut a.viewer.options(640, 480)?, &a.viewer, &scene)?;
    // Under mpirun rank 0 serves the pages and the other ranks render their frames' tiles.
    let mut cluster = crate::cluster::session(&scene, pool.current_num_threads(), a.viewer.mpi_timeout)?;
    if let Some(c) = cluster.as_mut().filter(|c| !c.is_root()) {
        return crate::cluster::serve_view(c, &a.viewer.options(640, 480)?, &tracer, &pool);
    }
    let listener = TcpListener::bind(&a.bind).with_context(|| format!("--bind {}: cannot listen", a.bind))?;
    let addr = listener.local_addr().context("cannot read the listening address")?;
    let name = opened.path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    eprintln!("megaray serve: {name} at http://{addr}/ (Ctrl-C to stop)");
    if !addr.ip().is_loopback() {
        eprintln!(
            "megaray serve: warning: listening on {addr}, not loopback: other machines that reach it can view the scene"
        );
    }
    let (requests_tx, requests) = std::sync::mpsc::channel();
    let clients = AtomicUsize::new(0);
    let log = std::sync::Mutex::new(crate::view::FrameLog::create(a.viewer.log.as_deref())?);
    let server = Server {
        tracer: &tracer,
        pool: &pool,
        viewer: &a.viewer,
        name: &name,
        clients: &clients,
        max_clients: a.max_clients,
        log: &log,
        next_client: AtomicUsize::new(1),
        views: Default::default(),
        frames: cluster.is_some().then_some(requests_tx),
    };
    std::thread::scope(|s| {
        let listen = || {
            for conn in listener.incoming() {
                let Ok(stream) = conn else { continue };
                let server = &server;
                s.spawn(move || {
                    let peer = stream.peer_addr().map_or("?".into(), |p: SocketAddr| p.to_string());
                    if let Err(e) = server.connection(stream) {
                        eprintln!("megaray serve: {peer}: {e}");
                    }
                });
            }
        };
        match cluster.as_mut() {
            // This thread talks MPI: the pages' frames come to it.
            Some(c) => {
                s.spawn(listen);
                let sky = a.viewer.options(640, 480).ok().and_then(|o| o.sky);
                crate::cluster::serve_requests(c, requests, sky, &tracer, &pool);
            }
            None => listen(),
        }
    });
    Ok(())
}

/// What every connection shares.
struct Server<'a, 's> {
    tracer: &'a Tracer<'s>,
    pool: &'a rayon::ThreadPool,
    viewer: &'a ViewerArgs,
    name: &'a str,
    clients: &'a AtomicUsize,
    max_clients: usize,
    /// `--log`: the frames sent, of every page.
    log: &'a std::sync::Mutex<crate::view::FrameLog>,
    next_client: AtomicUsize,
    /// Each page's current view (its [`megaray_view::Viewpoint`] as JSON), for the pages that
    /// follow it.
    views: std::sync::Mutex<std::collections::HashMap<u64, String>>,
    /// Under mpirun: where the pages ask for their frames (rank 0's main thread).
    frames: Option<std::sync::mpsc::Sender<crate::cluster::FrameRequest>>,
}

impl Server<'_, '_> {
    /// One connection: its request head, then the page, a socket or an error status.
    fn connection(&self, mut stream: TcpStream) -> Result<()> {
        stream.set_read_timeout(Some(Duration::from_secs(10)))?;
        stream.set_write_timeout(Some(Duration::from_secs(10)))?;
        let head = read_head(&mut stream)?;
        let text = String::from_utf8_lossy(&head);
        let mut first = text.lines().next().unwrap_or("").split(' ');
        let (method, target) = (first.next().unwrap_or(""), first.next().unwrap_or(""));
        let path = target.split('?').next().unwrap_or("");
        match (method, path) {
            ("GET", "/" | "/index.html") => respond(&mut stream, "200 OK", "text/html; charset=utf-8", PAGE.as_bytes()),
            ("GET", "/ws") => {
                if self.clients.fetch_add(1, Ordering::SeqCst) >= self.max_clients {
                    self.clients.fetch_sub(1, Ordering::SeqCst);
                    return respond(&mut stream, "503 Service Unavailable", "text/plain", b"too many viewers\n");
                }
                let res = self.socket(stream, head);
                self.clients.fetch_sub(1, Ordering::SeqCst);
                res
            }
            ("GET" | "HEAD", _) => respond(&mut stream, "404 Not Found", "text/plain", b"not found\n"),
            _ => respond(&mut stream, "405 Method Not Allowed", "text/plain", b"only GET\n"),
        }
    }

    /// A viewer: the handshake, then input in, frames out, until the page goes or misbehaves.
    fn socket(&self, stream: TcpStream, head: Vec<u8>) -> Result<()> {
        let config = WebSocketConfig::default().max_message_size(Some(MAX_MESSAGE)).max_frame_size(Some(MAX_MESSAGE));
        let replay = Replayed { head: Cursor::new(head), stream };
        let mut ws = tungstenite::accept_with_config(replay, Some(config)).context("WebSocket handshake failed")?;
        // Reads wait 15 ms when there is nothing to render or send, else they only look: the
        // socket is then non-blocking (a read timeout of a microsecond would wait a whole
        // kernel tick, about 4 ms, on every look). Sends happen blocking (`blocking`).
        ws.get_mut().stream.set_read_timeout(Some(Duration::from_millis(15)))?;
        let mut waiting = true;
        let mut busy = true; // the last step rendered a frame
        let mut view: Option<ViewCore> = None;
        let mut unacked = 0u32;
        let mut fresh = false; // a frame rendered and not sent
        let mut last = Instant::now();
        let client = self.next_client.fetch_add(1, Ordering::Relaxed) as u64;
        let mut sent = 0u64;
        // A view asked for before the page's size made the core; the page this one follows,
        // and the last view taken from it. The page's own view is shared while it is open.
        let mut pending: Option<String> = None;
        let (mut follow, mut followed) = (None::<u64>, String::new());
        let _shared = Shared(&self.views, client);
        loop {
            // Every message waiting, then a frame.
            let wait_now = view.is_none() || (!busy && !fresh) || unacked >= MAX_UNACKED;
            if wait_now != waiting {
                ws.get_mut().stream.set_nonblocking(!wait_now)?;
                waiting = wait_now;
            }
            loop {
                let msg = match ws.read() {
                    Ok(m) => m,
                    Err(tungstenite::Error::Io(e))
                        if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) =>
                    {
                        break
                    }
                    Err(tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed) => return Ok(()),
                    Err(e) => return close(&mut ws, format!("closed: {e}")),
                };
                if waiting {
                    // Something came: read on without waiting.
                    ws.get_mut().stream.set_nonblocking(true)?;
                    waiting = false;
                }
                let input = match msg {
                    Message::Text(t) => match parse_input(t.as_str()) {
                        Ok(i) => i,
                        Err(e) => return close(&mut ws, format!("closed: bad message: {e}")),
                    },
                    Message::Ping(_) | Message::Pong(_) | Message::Frame(_) => continue,
                    Message::Close(_) => return Ok(()),
                    Message::Binary(_) => return close(&mut ws, "closed: bad message: binary".into()),
                };
                match input {
                    Input::Ack => unacked = unacked.saturating_sub(1),
                    Input::Size(w, h) => match &mut view {
                        Some(v) => v.handle(Event::Resize(w, h)),
                        None => {
                            view = Some(self.view(w, h)?);
                            blocking(&mut ws, &mut waiting)?;
                            ws.send(Message::text(self.parts_message()))?;
                        }
                    },
                    Input::Part(name, op) => {
                        let Some(v) = &mut view else { continue };
                        let comps = self.tracer.scene().components();
                        match comps.names.iter().position(|n| *n == name) {
                            Some(c) => v.set_part(c as u32, op),
                            None => return close(&mut ws, format!("closed: bad message: no part {name:?}")),
                        }
                    }
                    Input::View(text) => pending = Some(text),
                    Input::Follow(leader) => {
                        (follow, followed) = (Some(leader), String::new());
                    }
                    Input::Event(ev) => {
                        let Some(v) = &mut view else { continue };
                        v.handle(ev);
                        if ev == Event::Key(Key::Screenshot, true) {
                            blocking(&mut ws, &mut waiting)?;
                            ws.send(Message::text(json!({"kind": "screenshot"}).to_string()))?;
                            ws.send(Message::Binary(png(v)?.into()))?;
                        }
                        if v.quit_requested() {
                            ws.close(None).ok();
                            return Ok(());
                        }
                    }
                }
            }
            let Some(v) = &mut view else { continue };
            if let Some(text) = pending.take() {
                match Viewpoint::from_json(&text, self.tracer.scene().components()) {
                    Ok(vp) => v.set_viewpoint(&vp),
                    Err(e) => return close(&mut ws, format!("closed: bad view: {e}")),
                }
            }
            // Following another page: its view, whenever it changes.
            if let Some(leader) = follow {
                let now = self.views.lock().ok().and_then(|m| m.get(&leader).cloned());
                if let Some(text) = now.filter(|t| *t != followed) {
                    if let Ok(vp) = Viewpoint::from_json(&text, self.tracer.scene().components()) {
                        v.set_viewpoint(&vp);
                    }
                    followed = text;
                }
            }
            let dt = last.elapsed().as_secs_f32().min(0.25);
            last = Instant::now();
            busy = v.step(dt);
            if let Some(e) = crate::paging::fault(self.tracer) {
                // The scene is damaged for every page: the server ends, with one line.
                eprintln!("megaray: error: {e}");
                std::process::exit(1);
            }
            fresh |= busy;
            // The page's view (for its address and its followers) changes only with a frame.
            let current = (busy || fresh).then(|| v.viewpoint().to_value(self.tracer.scene().components()));
            if let (Some(c), Ok(mut views)) = (&current, self.views.lock()) {
                let text = c.to_string();
                if views.get(&client) != Some(&text) {
                    views.insert(client, text);
                }
            }
            if fresh && unacked < MAX_UNACKED {
                let s = v.stats();
                let stats = json!({
                    "kind": "stats", "scene": self.name, "line": v.stats_line(), "fps": s.fps,
                    "mrays_s": s.mrays_s, "width": s.width, "height": s.height, "frames": s.frames,
                    "resident_bytes": s.resident, "budget": s.budget, "tiles_in_flight": s.in_flight,
                    "moving": s.moving, "eye": v.pose().eye.to_array(), "yaw": v.pose().yaw,
                    "pitch": v.pose().pitch, "pick": v.pick_lines(), "client": client,
                    "view": current.unwrap_or(Value::Null),
                });
                blocking(&mut ws, &mut waiting)?;
                ws.send(Message::text(stats.to_string()))?;
                ws.send(Message::Binary(jpeg(v)?.into()))?;
                unacked += 1;
                fresh = false;
                sent += 1;
                if let Ok(mut log) = self.log.lock() {
                    log.write(&crate::view::frame_line(v, sent, Some(client)));
                }
            }
        }
    }

    /// The page's part list: the scene's components (the first [`MAX_LISTED`]) and their
    /// triangle counts.
    fn parts_message(&self) -> String {
        let c = self.tracer.scene().components();
        let parts: Vec<Value> =
            c.names.iter().zip(&c.tri_counts).take(MAX_LISTED).map(|(n, t)| json!([n, t])).collect();
        json!({"kind": "parts", "parts": parts, "total": c.names.len()}).to_string()
    }

    /// A new viewer's core, at the page's size.
    fn view(&self, w: u32, h: u32) -> Result<ViewCore<'_, '_>> {
        let mut opts = self.viewer.options(w, h)?;
        crate::view::scene_options(&mut opts, self.viewer, self.tracer.scene())?;
        let source = self.frames.clone().map(crate::cluster::request_source);
        Ok(crate::view::with_source(ViewCore::new(self.tracer, self.pool, opts), source))
    }
}

/// A stream that first gives back the request head already read, for the handshake to read it
/// again.
struct Replayed {
    head: Cursor<Vec<u8>>,
    stream: TcpStream,
}

impl Read for Replayed {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.head.read(buf)?;
        if n > 0 {
            return Ok(n);
        }
        self.stream.read(buf)
    }
}

impl Write for Replayed {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.stream.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.stream.flush()
    }
}

/// The socket made blocking (for a send: a non-blocking one could fail a frame halfway with
/// `WouldBlock`), its reads waiting again (`waiting`).
fn blocking(ws: &mut tungstenite::WebSocket<Replayed>, waiting: &mut bool) -> std::io::Result<()> {
    if !*waiting {
        ws.get_mut().stream.set_nonblocking(false)?;
        *waiting = true;
    }
    Ok(())
}

/// The request head, through its blank line; longer than [`MAX_HEAD`] is an error.
fn read_head(stream: &mut TcpStream) -> Result<Vec<u8>> {
    let mut head = Vec::with_capacity(1024);
    let mut buf = [0u8; 1024];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
        if head.len() > MAX_HEAD {
            bail!("request head over {} KiB", MAX_HEAD >> 10);
        }
        let n = stream.read(&mut buf).context("cannot read the request")?;
        if n == 0 {
            bail!("connection closed before the request ended");
        }
        head.extend_from_slice(&buf[..n]);
    }
    Ok(head)
}

fn respond(stream: &mut TcpStream, status: &str, kind: &str, body: &[u8]) -> Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(body)?;
    stream.flush()?;
    Ok(())
}

/// Closes a socket after a fault of the page's, and reports it.
fn close(ws: &mut WebSocket<Replayed>, why: String) -> Result<()> {
    ws.close(None).ok();
    ws.flush().ok();
    bail!(why)
}

/// Shares a page's view with the pages that follow it while the page is open.
struct Shared<'a>(&'a std::sync::Mutex<std::collections::HashMap<u64, String>>, u64);

impl Drop for Shared<'_> {
    fn drop(&mut self) {
        if let Ok(mut m) = self.0.lock() {
            m.remove(&self.1);
        }
    }
}

/// A message from the page.
#[derive(Debug, PartialEq)]
enum Input {
    Event(Event),
    Size(u32, u32),
    Ack,
    /// Go to this saved view (JSON, from the page's address).
    View(String),
    /// Follow page N's view.
    Follow(u64),
    /// Hide, show, X-ray or isolate the part named so.
    Part(String, PartOp),
}

/// Parts the page's list holds at most (it searches within them).
const MAX_LISTED: usize = 20_000;

/// Reads a page's message: `{"k":"down"|"up","key":CODE}`, `{"k":"drag","dx":X,"dy":Y}`,
/// `{"k":"wheel","d":N}`, `{"k":"size","w":W,"h":H}`, `{"k":"click","x":X,"y":Y,"measure":B}`,
/// `{"k":"view","view":{...}}` (a saved view, [`Viewpoint`]), `{"k":"part","name":N,"op":OP}`, `{"k":"follow","client":N}`,
/// `{"k":"ack"}`.
fn parse_input(text: &str) -> Result<Input, String> {
    let v: Value = serde_json::from_str(text).map_err(|e| format!("not JSON ({e})"))?;
    let num =
        |f: &str| v.get(f).and_then(Value::as_f64).filter(|x| x.is_finite()).ok_or_else(|| format!("no number {f:?}"));
    let kind = v.get("k").and_then(Value::as_str).ok_or("no \"k\"")?;
    Ok(match kind {
        "down" | "up" => {
            let code = v.get("key").and_then(Value::as_str).ok_or("no \"key\"")?;
            let key = key_of_code(code).ok_or_else(|| format!("unknown key {code:?}"))?;
            Input::Event(Event::Key(key, kind == "down"))
        }
        "drag" => Input::Event(Event::Drag(
            num("dx")?.clamp(-4096.0, 4096.0) as f32,
            num("dy")?.clamp(-4096.0, 4096.0) as f32,
        )),
        "wheel" => Input::Event(Event::Wheel(num("d")?.signum() as f32)),
        "click" => Input::Event(Event::Click(
            num("x")?.clamp(0.0, MAX_SIDE as f64) as f32,
            num("y")?.clamp(0.0, MAX_SIDE as f64) as f32,
            v.get("measure").and_then(Value::as_bool).unwrap_or(false),
        )),
        "size" => {
            let side = |f: &str| num(f).map(|x| (x as u32).clamp(16, MAX_SIDE));
            Input::Size(side("w")?, side("h")?)
        }
        "ack" => Input::Ack,
        "view" => Input::View(v.get("view").filter(|x| x.is_object()).ok_or("no \"view\" object")?.to_string()),
        "part" => {
            let name = v.get("name").and_then(Value::as_str).ok_or("no \"name\"")?.to_string();
            let op = match v.get("op").and_then(Value::as_str) {
                Some("hide") => PartOp::Hide,
                Some("show") => PartOp::Show,
                Some("xray") => PartOp::XRay,
                Some("solid") => PartOp::Solid,
                Some("isolate") => PartOp::Isolate,
                _ => return Err("\"op\" must be hide, show, xray, solid or isolate".into()),
            };
            Input::Part(name, op)
        }
        "follow" => {
            Input::Follow(v.get("client").and_then(Value::as_u64).filter(|&c| c > 0).ok_or("no \"client\" number")?)
        }
        other => return Err(format!("unknown kind {other:?}")),
    })
}

/// A browser's key code (`KeyboardEvent.code`) as the core's key.
fn key_of_code(code: &str) -> Option<Key> {
    Some(match code {
        "KeyW" | "ArrowUp" => Key::Forward,
        "KeyS" | "ArrowDown" => Key::Back,
        "KeyA" | "ArrowLeft" => Key::Left,
        "KeyD" | "ArrowRight" => Key::Right,
        "KeyE" => Key::Up,
        "KeyQ" => Key::Down,
        "KeyR" => Key::Reset,
        "KeyF" => Key::Frame,
        "KeyP" => Key::Screenshot,
        "KeyC" => Key::NextShader,
        "KeyK" => Key::ToggleSky,
        "KeyH" => Key::Help,
        "KeyI" => Key::Info,
        "KeyX" => Key::XRay,
        "KeyV" => Key::Hide,
        "KeyB" => Key::Isolate,
        "KeyN" => Key::Section,
        "BracketRight" => Key::CutMore,
        "BracketLeft" => Key::CutLess,
        "KeyU" => Key::ShowAll,
        "Escape" => Key::Quit,
        _ => return None,
    })
}

/// The display (with its overlays) as a JPEG (jpeg-encoder: with AVX2, a 640x480 frame in
/// under 2 ms, several times faster than the image crate's encoder), in strips on every
/// thread of the global pool (`crate::jpeg`).
fn jpeg(v: &ViewCore) -> Result<Vec<u8>> {
    let (w, h, rgb) = v.display();
    crate::jpeg::encode(rgb, w, h, JPEG_QUALITY, rayon::current_num_threads() as u32)
}

/// The picture (no overlays) as a PNG, tone mapped as `megaray render` does.
fn png(v: &ViewCore) -> Result<Vec<u8>> {
    let img = v.image();
    let rgb = img.to_srgb8_with(&ToneMap::default());
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(&rgb, img.width, img.height, image::ExtendedColorType::Rgb8)
        .context("cannot encode a screenshot")?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn input_messages() {
        assert_eq!(parse_input(r#"{"k":"down","key":"KeyW"}"#), Ok(Input::Event(Event::Key(Key::Forward, true))));
        assert_eq!(parse_input(r#"{"k":"up","key":"ArrowLeft"}"#), Ok(Input::Event(Event::Key(Key::Left, false))));
        assert_eq!(parse_input(r#"{"k":"drag","dx":3,"dy":-2.5}"#), Ok(Input::Event(Event::Drag(3.0, -2.5))));
        assert_eq!(parse_input(r#"{"k":"wheel","d":-3}"#), Ok(Input::Event(Event::Wheel(-1.0))));
        assert_eq!(
            parse_input(r#"{"k":"click","x":10.5,"y":1e9,"measure":true}"#),
            Ok(Input::Event(Event::Click(10.5, MAX_SIDE as f32, true)))
        );
        assert!(parse_input(r#"{"k":"click","x":"a","y":2}"#).is_err());
        assert_eq!(parse_input(r#"{"k":"view","view":{"fov":60}}"#), Ok(Input::View(r#"{"fov":60}"#.into())));
        assert_eq!(parse_input(r#"{"k":"follow","client":3}"#), Ok(Input::Follow(3)));
        assert_eq!(
            parse_input(r#"{"k":"part","name":"a/b","op":"xray"}"#),
            Ok(Input::Part("a/b".into(), PartOp::XRay))
        );
        assert!(parse_input(r#"{"k":"part","name":"a/b","op":"melt"}"#).is_err());
        for bad in [r#"{"k":"view","view":3}"#, r#"{"k":"follow","client":0}"#, r#"{"k":"follow"}"#] {
            assert!(parse_input(bad).is_err(), "{bad}");
        }
        assert_eq!(parse_input(r#"{"k":"size","w":100000,"h":1}"#), Ok(Input::Size(MAX_SIDE, 16)));
        assert_eq!(parse_input(r#"{"k":"ack"}"#), Ok(Input::Ack));
        for bad in
            ["", "nonsense", "[]", "{}", r#"{"k":"down","key":"KeyZ"}"#, r#"{"k":"drag","dx":"a"}"#, r#"{"k":"fly"}"#]
        {
            assert!(parse_input(bad).is_err(), "{bad:?} was accepted");
        }
    }
}
