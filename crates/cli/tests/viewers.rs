//! `megaray view` and `megaray serve` as a person uses them: a script replayed headless, the
//! window under Xvfb driven by xdotool, the page in headless Chromium driven through its
//! DevTools protocol.
//!
//! The window and browser tests need Xvfb, xdotool, xwd and Chromium; without them they say so
//! and pass, unless MEGARAY_GUI_TESTS=require (as `.ci/run` sets after installing them).

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::*;
use serde_json::{json, Value};

/// A small paged scene: plant:20k in parts of at most 2,000 triangles.
fn scene(dir: &Path) -> PathBuf {
    let ply = gen(dir, "plant:20k");
    build(dir, &[ply], "plant", Some(2000)).0
}

/// Whether the tools a GUI test needs are here; if not, the test is skipped (or fails, when
/// MEGARAY_GUI_TESTS=require).
fn have(tools: &[&str]) -> bool {
    let missing: Vec<&&str> = tools
        .iter()
        .filter(|t| {
            !Command::new("sh").arg("-c").arg(format!("command -v {t}")).output().is_ok_and(|o| o.status.success())
        })
        .collect();
    if missing.is_empty() {
        return true;
    }
    if std::env::var("MEGARAY_GUI_TESTS").as_deref() == Ok("require") {
        panic!("MEGARAY_GUI_TESTS=require but {missing:?} missing");
    }
    eprintln!("skipped: {missing:?} not installed");
    false
}

/// Kills the child when dropped (a failing test leaves no process behind).
struct Proc(Child);
impl Drop for Proc {
    fn drop(&mut self) {
        self.0.kill().ok();
        self.0.wait().ok();
    }
}

/// The window and browser tests one at a time: on 2 cores, three Chromiums starting beside
/// the window kept it from appearing within its wait.
static GUI: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn gui_turn() -> std::sync::MutexGuard<'static, ()> {
    GUI.lock().unwrap_or_else(|e| e.into_inner())
}

fn wait_until(what: &str, secs: u64, mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < Duration::from_secs(secs), "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_script_replays_to_frames_and_poses() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let script = dir.path().join("tour.txt");
    std::fs::write(
        &script,
        "# still, fly forward, stop, screenshot, resize\nframes 2\nkey forward down\nframes 3\nkey forward up\n\
         key screenshot down\nkey screenshot up\nframes 2\nresize 80 60\nframes 1\nkey quit down\nframes 5\n",
    )
    .unwrap();
    let out = dir.path().join("frames");
    let args = ["view", scene.to_str().unwrap(), "--res", "64x48", "--mem", "4M", "--script"];
    let (code, _, err) = run(&[&args[..], &[script.to_str().unwrap(), "--out", out.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{err}");
    let log = std::fs::read_to_string(out.join("frames.jsonl")).unwrap();
    let f: Vec<Value> = log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(f.len(), 8, "quit ends the replay: {log}");
    for n in 1..=8 {
        assert!(out.join(format!("frame-{n:05}.png")).is_file());
    }
    assert!(out.join("screenshot-1.png").is_file());
    // Still: the pose stays and frames accumulate; flying moves the eye and starts again.
    assert_eq!((&f[0]["eye"], &f[0]["accumulated"], &f[1]["accumulated"]), (&f[1]["eye"], &1.into(), &2.into()));
    assert_ne!(f[2]["eye"], f[1]["eye"]);
    assert_ne!(f[4]["eye"], f[3]["eye"]);
    assert_eq!(f[4]["moving"], true);
    // (A script's frames are at full resolution, moving or not: the last moving frame is the
    // first of the new pose's.)
    assert_eq!((&f[5]["eye"], &f[5]["moving"], &f[6]["accumulated"]), (&f[4]["eye"], &false.into(), &3.into()));
    assert_eq!((&f[7]["width"], &f[7]["height"]), (&80.into(), &60.into()));
    let img = image::open(out.join("frame-00008.png")).unwrap();
    assert_eq!((img.width(), img.height()), (80, 60));
    assert!(f[7]["budget"].as_u64().unwrap() > 0, "paged within --mem");

    // A bad script: one line naming the file and the line.
    std::fs::write(&script, "frames 1\nkey jump down\n").unwrap();
    let (code, _, err) = run(&[&args[..], &[script.to_str().unwrap(), "--out", out.to_str().unwrap()]].concat());
    assert_eq!(code, 1);
    assert!(err.contains("tour.txt") && err.contains("line 2") && err.contains("jump"), "{err}");
}

#[test]
fn view_and_serve_help_list_the_controls() {
    for cmd in ["view", "serve"] {
        let (code, out, _) = run(&[cmd, "--help"]);
        assert_eq!(code, 0);
        for w in ["W / Up", "drag", "wheel", "F          frame", "P          save a screenshot", "Esc", "--mem"] {
            assert!(out.contains(w), "{cmd} --help lacks {w:?}");
        }
    }
    let (_, out, _) = run(&["serve", "--help"]);
    assert!(out.contains("--bind") && out.contains("127.0.0.1:8080"));
}

/// An Xvfb display of its own, closed when dropped.
struct Display {
    name: String,
    _xvfb: Proc,
}

fn display() -> Display {
    // A display is taken while the server named in its lock file runs. Servers killed (as
    // `Proc` kills them) leave their lock and socket behind; Xvfb replaces such stale ones.
    let live = |n: u32| {
        std::fs::read_to_string(format!("/tmp/.X{n}-lock"))
            .ok()
            .and_then(|pid| pid.trim().parse::<u32>().ok())
            .is_some_and(|pid| Path::new(&format!("/proc/{pid}")).exists())
    };
    for n in 40..90 {
        if live(n) {
            continue;
        }
        let _ = std::fs::remove_file(format!("/tmp/.X11-unix/X{n}"));
        let name = format!(":{n}");
        let child = Command::new("Xvfb")
            .args([&name, "-screen", "0", "800x600x24", "-nolisten", "tcp"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let xvfb = Proc(child);
        let sock = format!("/tmp/.X11-unix/X{n}");
        wait_until("Xvfb", 20, || Path::new(&sock).exists());
        // The socket comes before the server answers: wait until it does.
        let answers = || {
            Command::new("xdotool")
                .env("DISPLAY", &name)
                .arg("getdisplaygeometry")
                .output()
                .is_ok_and(|o| o.status.success())
        };
        wait_until("Xvfb to answer", 20, answers);
        return Display { name, _xvfb: xvfb };
    }
    panic!("no free X display number");
}

/// xdotool on `d`.
fn xdotool(d: &Display, args: &[&str]) -> String {
    let out = Command::new("xdotool").env("DISPLAY", &d.name).args(args).output().unwrap();
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

/// A key held long enough for the window's loop to see it go down and up.
fn tap(d: &Display, key: &str) {
    xdotool(d, &["keydown", key]);
    std::thread::sleep(Duration::from_millis(300));
    xdotool(d, &["keyup", key]);
    std::thread::sleep(Duration::from_millis(300));
}

/// The distinct colours of window `id` (from xwd's dump of it).
fn window_colours(d: &Display, id: &str) -> usize {
    let out = Command::new("xwd").env("DISPLAY", &d.name).args(["-id", id, "-silent"]).output().unwrap();
    let x = out.stdout;
    assert!(x.len() > 100, "xwd gave nothing");
    let be = |o: usize| u32::from_be_bytes(x[o..o + 4].try_into().unwrap()) as usize;
    let (header, w, h, bpp, line, ncolors) = (be(0), be(16), be(20), be(44), be(48), be(76));
    assert_eq!(bpp, 32, "a 24-bit display dumps 32-bit pixels");
    let data = &x[header + ncolors * 12..];
    let mut seen = std::collections::HashSet::new();
    for y in 0..h {
        for px in data[y * line..y * line + w * 4].chunks_exact(4) {
            seen.insert([px[0], px[1], px[2]]);
        }
    }
    seen.len()
}

#[test]
fn the_window_opens_draws_reacts_saves_and_quits() {
    if !have(&["Xvfb", "xdotool", "xwd"]) {
        return;
    }
    let _turn = gui_turn();
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let d = display();
    let child = Command::new(bin())
        .current_dir(dir.path())
        .env("DISPLAY", &d.name)
        .args(["view", scene.to_str().unwrap(), "--res", "320x240", "--mem", "4M"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut view = Proc(child);
    let mut id = String::new();
    wait_until("the window", 90, || {
        if let Ok(Some(status)) = view.0.try_wait() {
            let mut err = String::new();
            view.0.stderr.take().unwrap().read_to_string(&mut err).unwrap();
            panic!("megaray view ended ({status}) before its window appeared: {err}");
        }
        id = xdotool(&d, &["search", "--name", "megaray - plant.mray"]);
        !id.is_empty()
    });
    let id = id.lines().next().unwrap().to_string();
    xdotool(&d, &["windowfocus", "--sync", &id]);
    wait_until("a drawn frame", 30, || window_colours(&d, &id) > 20);

    let shot = |n: u32| dir.path().join(format!("plant-{n:03}.png"));
    tap(&d, "p");
    wait_until("the first screenshot", 10, || shot(1).is_file());
    tap(&d, "w");
    std::thread::sleep(Duration::from_millis(500));
    tap(&d, "p");
    wait_until("the second screenshot", 10, || shot(2).is_file());
    std::thread::sleep(Duration::from_millis(200));
    let (a, b) = (image::open(shot(1)).unwrap().to_rgb8(), image::open(shot(2)).unwrap().to_rgb8());
    assert_eq!((a.width(), a.height()), (320, 240));
    assert_ne!(a, b, "W moved the camera");

    tap(&d, "Escape");
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = view.0.try_wait().unwrap() {
            break s;
        }
        assert!(t0.elapsed() < Duration::from_secs(10), "Esc did not quit");
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut err = String::new();
    view.0.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    assert!(status.success(), "{err}");
}

/// `megaray serve` on a free port; returns the process and its address.
fn serve(scene: &Path) -> (Proc, String) {
    let mut cmd = Command::new(bin());
    cmd.args(["serve", scene.to_str().unwrap(), "--bind", "127.0.0.1:0", "--mem", "4M"]);
    spawn_until(cmd, "serve", |line| {
        line.split("http://").nth(1).map(|rest| rest.split('/').next().unwrap().to_string())
    })
}

/// Starts `cmd` and reads its stderr until `found` picks something out of a line (an
/// address); then keeps draining it, so that the process never blocks on its log.
fn spawn_until(mut cmd: Command, name: &str, found: impl Fn(&str) -> Option<String>) -> (Proc, String) {
    let mut child = cmd.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let proc = Proc(child);
    let value = loop {
        let line = lines.next().unwrap_or_else(|| panic!("{name} ended before listening")).unwrap();
        if let Some(v) = found(&line) {
            break v;
        }
    };
    std::thread::spawn(move || lines.for_each(drop));
    (proc, value)
}

fn http_get(addr: &str, path: &str) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    write!(s, "GET {path} HTTP/1.1\r\nHost: {addr}\r\n\r\n").unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    out
}

#[test]
fn the_server_serves_its_page_and_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let (_srv, addr) = serve(&scene);
    let page = http_get(&addr, "/");
    assert!(page.starts_with("HTTP/1.1 200") && page.contains("<canvas"), "{page}");
    for path in ["/etc/passwd", "/../../etc/passwd", "/plant.mray", "/ws/../"] {
        assert!(http_get(&addr, path).starts_with("HTTP/1.1 404"), "{path} served");
    }
    let mut s = TcpStream::connect(&addr).unwrap();
    s.write_all(&vec![b'x'; 64 << 10]).ok();
    drop(s);
    assert!(http_get(&addr, "/").starts_with("HTTP/1.1 200"), "a garbage request left the server serving");
}

/// A DevTools protocol session with headless Chromium.
struct Browser {
    ws: tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>,
    next: u64,
    _proc: Proc,
    _profile: tempfile::TempDir,
}

impl Browser {
    fn launch() -> Browser {
        let profile = tempfile::tempdir().unwrap();
        let mut cmd = Command::new("chromium");
        cmd.args(["--headless", "--no-sandbox", "--disable-gpu", "--remote-debugging-port=0", "--window-size=400,300"])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg("about:blank");
        let (proc, url) = spawn_until(cmd, "chromium", |line| {
            line.strip_prefix("DevTools listening on ").map(|u| u.trim().to_string())
        });
        let (ws, _) = tungstenite::connect(url).unwrap();
        Browser { ws, next: 1, _proc: proc, _profile: profile }
    }

    /// Sends a command (to a page's session, if given) and returns its result.
    fn call(&mut self, session: Option<&str>, method: &str, params: Value) -> Value {
        let id = self.next;
        self.next += 1;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if let Some(s) = session {
            msg["sessionId"] = s.into();
        }
        self.ws.send(tungstenite::Message::text(msg.to_string())).unwrap();
        loop {
            let m = self.ws.read().unwrap();
            let Ok(text) = m.to_text() else { continue };
            let v: Value = serde_json::from_str(text).unwrap();
            if v["id"] == id {
                assert!(v.get("error").is_none(), "{method}: {v}");
                return v["result"].clone();
            }
        }
    }

    /// Opens `url` in a new tab; returns its session.
    fn tab(&mut self, url: &str) -> String {
        let t = self.call(None, "Target.createTarget", json!({"url": url}));
        let s = self.call(None, "Target.attachToTarget", json!({"targetId": t["targetId"], "flatten": true}));
        s["sessionId"].as_str().unwrap().to_string()
    }

    /// The value of `expr` in the tab.
    fn eval(&mut self, tab: &str, expr: &str) -> Value {
        let r = self.call(Some(tab), "Runtime.evaluate", json!({"expression": expr, "returnByValue": true}));
        r["result"]["value"].clone()
    }

    fn key(&mut self, tab: &str, code: &str, down: bool) {
        let kind = if down { "keyDown" } else { "keyUp" };
        self.call(Some(tab), "Input.dispatchKeyEvent", json!({"type": kind, "code": code, "key": code}));
    }
}

/// What the page shows: frames received, the distinct colours of its canvas (copied onto a
/// canvas of the test's own: the page's draws with a bitmap renderer), the eye.
const PAGE_STATE: &str = "(() => { const c = document.getElementById('view'); \
    const t = document.createElement('canvas'); t.width = c.width; t.height = c.height; \
    const g = t.getContext('2d'); if (c.width) g.drawImage(c, 0, 0); \
    const d = c.width ? g.getImageData(0, 0, c.width, c.height).data : []; \
    const seen = new Set(); for (let i = 0; i < d.length; i += 4) seen.add(d[i] << 16 | d[i+1] << 8 | d[i+2]); \
    const m = window.megaray; return { frames: m.frames, colours: seen.size, closed: m.closed, \
    eye: m.stats ? m.stats.eye : null, width: c.width }; })()";

#[test]
fn the_page_in_a_browser_shows_frames_and_flies() {
    if !have(&["chromium"]) {
        return;
    }
    let _turn = gui_turn();
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let (_srv, addr) = serve(&scene);
    let mut b = Browser::launch();
    let url = format!("http://{addr}/");
    let (t1, t2) = (b.tab(&url), b.tab(&url));
    for t in [&t1, &t2] {
        wait_until("frames in a tab", 60, || {
            let s = b.eval(t, PAGE_STATE);
            s["frames"].as_u64() > Some(1) && s["colours"].as_u64() > Some(20)
        });
    }
    let (e1, e2) = (b.eval(&t1, PAGE_STATE)["eye"].clone(), b.eval(&t2, PAGE_STATE)["eye"].clone());
    assert_eq!(e1, e2, "both tabs start at the default view");

    // W in the first tab flies its camera; the second tab's stays.
    b.key(&t1, "KeyW", true);
    std::thread::sleep(Duration::from_millis(400));
    b.key(&t1, "KeyW", false);
    wait_until("the first tab's camera to move", 20, || b.eval(&t1, PAGE_STATE)["eye"] != e1);
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(b.eval(&t2, PAGE_STATE)["eye"], e2, "the second tab has a camera of its own");

    // Garbage, binary and oversized messages close their own connection only.
    for bad in [
        tungstenite::Message::text("not json"),
        tungstenite::Message::text(r#"{"k":"size","w":"wide"}"#),
        tungstenite::Message::Binary(vec![0u8; 100].into()),
        tungstenite::Message::text(format!(r#"{{"k":"ack","pad":"{}"}}"#, "x".repeat(1 << 20))),
    ] {
        let (mut ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).unwrap();
        ws.send(bad).ok();
        let closed = (0..100).any(|_| matches!(ws.read(), Err(_) | Ok(tungstenite::Message::Close(_))));
        assert!(closed, "a bad message left its connection open");
    }
    let before = b.eval(&t2, PAGE_STATE)["frames"].as_u64().unwrap();
    b.key(&t2, "KeyD", true);
    std::thread::sleep(Duration::from_millis(300));
    b.key(&t2, "KeyD", false);
    wait_until("frames after the garbage", 20, || b.eval(&t2, PAGE_STATE)["frames"].as_u64() > Some(before + 1));
    assert_ne!(b.eval(&t2, PAGE_STATE)["eye"], e2, "the server still flies the second tab");
    assert!(http_get(&addr, "/").starts_with("HTTP/1.1 200"));
}

#[test]
fn a_link_opens_the_same_view_and_a_tab_can_follow_another() {
    if !have(&["chromium"]) {
        return;
    }
    let _turn = gui_turn();
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let (_srv, addr) = serve(&scene);
    let mut b = Browser::launch();
    let t1 = b.tab(&format!("http://{addr}/"));
    wait_until("frames in the first tab", 60, || b.eval(&t1, PAGE_STATE)["frames"].as_u64() > Some(1));
    let e0 = b.eval(&t1, PAGE_STATE)["eye"].clone();
    b.key(&t1, "KeyW", true);
    std::thread::sleep(Duration::from_millis(300));
    b.key(&t1, "KeyW", false);
    wait_until("the first tab's camera to move", 20, || b.eval(&t1, PAGE_STATE)["eye"] != e0);
    // Once it is still, its address holds its view; that link opens the same view.
    wait_until("the view in the address", 20, || {
        let href = b.eval(&t1, "location.href");
        href.as_str().is_some_and(|h| h.contains("#view=")) && b.eval(&t1, "window.megaray.stats.moving") == false
    });
    std::thread::sleep(Duration::from_millis(200));
    let (href, e1) = (b.eval(&t1, "location.href"), b.eval(&t1, PAGE_STATE)["eye"].clone());
    let t2 = b.tab(href.as_str().unwrap());
    wait_until("the linked tab at the same eye", 30, || b.eval(&t2, PAGE_STATE)["eye"] == e1);
    // A third tab follows the first: the first flies, the third goes along.
    let id = b.eval(&t1, "window.megaray.stats.client").as_u64().unwrap();
    let t3 = b.tab(&format!("http://{addr}/?follow={id}"));
    wait_until("the follower at the leader's eye", 30, || b.eval(&t3, PAGE_STATE)["eye"] == e1);
    b.key(&t1, "KeyD", true);
    std::thread::sleep(Duration::from_millis(300));
    b.key(&t1, "KeyD", false);
    wait_until("the leader to move", 20, || b.eval(&t1, PAGE_STATE)["eye"] != e1);
    wait_until("the follower to follow", 30, || {
        let (a, c) = (b.eval(&t1, PAGE_STATE)["eye"].clone(), b.eval(&t3, PAGE_STATE)["eye"].clone());
        a == c && a != e1
    });
    assert_eq!(b.eval(&t2, PAGE_STATE)["eye"], e1, "the linked tab does not follow");
    // A view in the address that names nothing of the scene closes that page's socket only.
    let bad = format!("http://{addr}/#view=%7B%22eye%22%3A1%7D");
    let t4 = b.tab(&bad);
    wait_until("the bad view's socket to close", 30, || b.eval(&t4, PAGE_STATE)["closed"] == true);
    assert!(http_get(&addr, "/").starts_with("HTTP/1.1 200"));
}

#[test]
fn the_page_lists_the_parts_and_hides_one() {
    if !have(&["chromium"]) {
        return;
    }
    let _turn = gui_turn();
    let dir = tempfile::tempdir().unwrap();
    // Two named parts: a box (`o wall`) before a plate (`o back`).
    let obj = dir.path().join("box.obj");
    std::fs::write(
        &obj,
        "o wall\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nv -1 -1 0.2\nv 1 -1 0.2\nv 1 1 0.2\nv -1 1 0.2\n\
         f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n\
         o back\nv -3 -3 -1\nv 3 -3 -1\nv 3 3 -1\nv -3 3 -1\nf 9 10 11 12\n",
    )
    .unwrap();
    let scene = dir.path().join("box.mray");
    let (code, _, err) = run(&["build", obj.to_str().unwrap(), "-o", scene.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    let (_srv, addr) = serve(&scene);
    let mut b = Browser::launch();
    let t = b.tab(&format!("http://{addr}/"));
    wait_until("the part list", 60, || b.eval(&t, "window.megaray.parts.length") == 2);
    // Open the list, search, and press the one row's "hide".
    b.eval(&t, "document.getElementById('partsBtn').click()");
    b.eval(&t, "(() => { const s = document.getElementById('search'); s.value = 'BACK'; s.dispatchEvent(new Event('input')); })()");
    assert_eq!(b.eval(&t, "document.querySelectorAll('#list .part').length"), 1);
    assert_eq!(b.eval(&t, "document.querySelector('#list .part button').textContent"), "hide");
    b.eval(&t, "document.querySelector('#list .part button').click()");
    wait_until("the plate hidden", 20, || {
        b.eval(&t, "JSON.stringify(window.megaray.stats.view.hidden)") == "[\"box.obj/back\"]"
    });
    wait_until("its button to say show", 20, || {
        b.eval(&t, "document.querySelector('#list .part button').textContent") == "show"
    });
    // Shown again; then "only" on the wall, from a search for it: the plate hidden again.
    b.eval(&t, "document.querySelector('#list .part button').click()");
    wait_until("the plate shown", 20, || b.eval(&t, "JSON.stringify(window.megaray.stats.view.hidden)") == "[]");
    b.eval(&t, "(() => { const s = document.getElementById('search'); s.value = 'wall'; s.dispatchEvent(new Event('input')); })()");
    assert_eq!(b.eval(&t, "document.querySelector('#list .part span').textContent"), "box.obj/wall (12)");
    b.eval(&t, "document.querySelectorAll('#list .part button')[2].click()");
    wait_until("the wall alone", 20, || {
        b.eval(&t, "JSON.stringify(window.megaray.stats.view.hidden)") == "[\"box.obj/back\"]"
    });
}
