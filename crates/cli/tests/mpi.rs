//! `mpirun -n 2 megaray render ...` (the `mpi` feature; run with
//! `cargo test --release -p megaray --features mpi --test mpi`, which needs `mpirun`): the
//! same PNG, byte for byte, as one process (a timed run too); a rank killed or stopped mid-frame ends or
//! finishes the job within the timeout, in one line naming it; a rank with another scene
//! file refuses to start.
#![cfg(feature = "mpi")]

mod common;
use common::*;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// `mpirun` with 2 ranks (oversubscribed: CI machines may have fewer cores; as root if we
/// are), running `args` (an MPMD line when it holds `:`).
fn mpirun(args: &[&str]) -> Command {
    let mut c = Command::new("mpirun");
    c.args(["--oversubscribe", "--allow-run-as-root", "--bind-to", "none"]);
    c.args(args);
    c.stdout(Stdio::piped()).stderr(Stdio::piped());
    c
}

fn scene(dir: &Path) -> String {
    let out = dir.join("s.mray").to_string_lossy().into_owned();
    let model = megaray_testkit::model("stanford-bunny.obj");
    let (code, _, err) = run(&["build", model.to_str().unwrap(), "-o", &out, "--tile-size", "64K"]);
    assert_eq!(code, 0, "{err}");
    out
}

#[test]
fn two_ranks_write_the_same_png_as_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let bin = bin();
    let bin = bin.to_str().unwrap();
    let cases: [&[&str]; 5] = [
        &["--shader", "auto"],
        // The level of detail steered by the budget: the error rises over the frames (checked
        // below), as rank 0 steers by the whole frame's working set, every rank's lookups (by
        // its own alone, the whole frame's would seem to fit: the error stays at 1).
        &["--shader", "env", "--sky", "sky:width=64", "--frames", "6", "--mem", "2400K"],
        &["--shader", "env", "--sky", "sky:width=64", "--frames", "3", "--light-samples", "2"],
        &["--shader", "env", "--sky", "sky:width=64", "--frames", "2", "--denoise", "--mem", "1M", "--lod-error", "0"],
        &["--shader", "ao", "--spp", "2", "--mem", "1M", "--lod-error", "0"],
    ];
    for (k, extra) in cases.iter().enumerate() {
        let one = dir.path().join(format!("one{k}.png")).to_string_lossy().into_owned();
        let two = dir.path().join(format!("two{k}.png")).to_string_lossy().into_owned();
        let common = ["--res", "150x100", "--threads", "1", "-q"];
        let mut args = vec!["render", &s, "-o", &one, "--json"];
        args.extend(common.iter().chain(extra.iter()));
        let (code, out, err) = run(&args);
        assert_eq!(code, 0, "{err}");
        let alone: serde_json::Value = serde_json::from_str(&out).unwrap();
        let mut args = vec!["-n", "2", bin, "render", &s, "-o", &two, "--json"];
        args.extend(common.iter().chain(extra.iter()));
        let out = mpirun(&args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{extra:?}: {err}");
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON document, from rank 0 only");
        assert_eq!(v["cluster"]["ranks"], 2);
        assert!(v["cluster"]["root_tile_share"].as_f64().unwrap() < 1.0, "rank 1 rendered nothing: {v}");
        assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap(), "{extra:?}: the images differ");
        assert_eq!(v["lod_error"], alone["lod_error"], "{extra:?}");
        if extra.contains(&"2400K") {
            assert!(v["lod_error"].as_f64().unwrap() > 1.0, "the error did not rise: {v}");
        }
    }
}

#[test]
fn a_timed_run_across_two_ranks_equals_one_process_with_as_many_frames() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let bin = bin();
    let two = dir.path().join("two.png").to_string_lossy().into_owned();
    let common = ["--res", "96x64", "--threads", "1", "-q", "--shader", "env", "--sky", "sky:width=64"];
    let mut args = vec!["-n", "2", bin.to_str().unwrap(), "render", &s, "-o", &two, "--json", "--time", "0.5"];
    args.extend(common);
    let out = mpirun(&args).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let frames = v["frames"].as_u64().unwrap();
    assert!(frames > 1, "{v}");
    // Rank 0 decided when to stop; one process given that many frames makes the same image.
    let one = dir.path().join("one.png").to_string_lossy().into_owned();
    let n = frames.to_string();
    let mut args = vec!["render", &s, "-o", &one, "--frames", &n];
    args.extend(common);
    let (code, _, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap(), "{frames} frames: the images differ");
}

/// The pid of rank `rank` among the children of the launcher `launcher` (by the rank
/// variable in its environment), once it exists.
fn rank_pid(launcher: u32, rank: usize) -> u32 {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(20) {
        for e in std::fs::read_dir("/proc").unwrap().flatten() {
            let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else { continue };
            let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
            let ppid =
                stat.rsplit(')').next().and_then(|s| s.split_whitespace().nth(1)).and_then(|p| p.parse::<u32>().ok());
            let env = std::fs::read(format!("/proc/{pid}/environ")).unwrap_or_default();
            let want = format!("OMPI_COMM_WORLD_RANK={rank}");
            if ppid == Some(launcher) && env.split(|&b| b == 0).any(|v| v == want.as_bytes()) {
                return pid;
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("rank {rank} of launcher {launcher} not found");
}

/// Runs a long 2-rank render, sends `signal` to rank 1 once it has had time to start
/// rendering, and returns (exit status, stderr, seconds after the signal).
fn signalled_run(dir: &Path, s: &str, signal: &str, out: &str, frames: &str) -> (bool, String, f64) {
    let bin = bin();
    let args = ["-n", "2", bin.to_str().unwrap(), "render", s, "-o", out, "--res", "200x150", "--threads", "1"];
    let mut cmd = mpirun(&args);
    cmd.args(["--shader", "ao", "--spp", "4", "--frames", frames, "--mpi-timeout", "2", "-q"]);
    let child = cmd.current_dir(dir).spawn().unwrap();
    let pid = rank_pid(child.id(), 1);
    std::thread::sleep(Duration::from_millis(1500));
    let status = Command::new("kill").args([signal, &pid.to_string()]).status().unwrap();
    assert!(status.success());
    let t = Instant::now();
    let out = child.wait_with_output().unwrap();
    let secs = t.elapsed().as_secs_f64();
    let _ = Command::new("kill").args(["-KILL", &pid.to_string()]).status();
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned(), secs)
}

#[test]
fn a_rank_killed_mid_frame_ends_the_job_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let out = dir.path().join("k.png").to_string_lossy().into_owned();
    let (ok, err, secs) = signalled_run(dir.path(), &s, "-KILL", &out, "100000");
    assert!(!ok, "the job went on as if nothing happened: {err}");
    assert!(secs < 20.0, "the job took {secs:.1} s to end");
    assert!(err.contains("rank 1"), "no line names rank 1: {err}");
}

#[test]
fn a_rank_stopped_mid_frame_loses_its_tiles_and_the_image_is_still_exact() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    // About 6 s in one process, so that rank 1 is stopped well inside the run.
    let frames = "600";
    let one = dir.path().join("one.png").to_string_lossy().into_owned();
    let common = ["--res", "200x150", "--threads", "1", "--shader", "ao", "--spp", "4", "--frames", frames, "-q"];
    let mut args = vec!["render", &s, "-o", &one];
    args.extend(common);
    let (code, _, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let two = dir.path().join("two.png").to_string_lossy().into_owned();
    let (_, err, secs) = signalled_run(dir.path(), &s, "-STOP", &two, frames);
    assert!(err.contains("rank 1 sent nothing for 2 s"), "{err}");
    assert!(secs < 60.0, "the job took {secs:.1} s to end");
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).expect("no image written"), "the images differ");
}

#[test]
fn a_rank_with_another_scene_file_refuses_to_start() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let other = dir.path().join("t.mray").to_string_lossy().into_owned();
    let model = megaray_testkit::model("stanford-bunny.obj");
    let (code, _, err) = run(&["build", model.to_str().unwrap(), "-o", &other, "--tile-size", "128K"]);
    assert_eq!(code, 0, "{err}");
    let bin = bin();
    let bin = bin.to_str().unwrap();
    let png = dir.path().join("x.png").to_string_lossy().into_owned();
    let r = ["-o", &png, "--res", "64x48", "-q"];
    let mut args = vec!["-n", "1", bin, "render", &s];
    args.extend(r);
    args.extend([":", "-n", "1", bin, "render", &other]);
    args.extend(r);
    let out = mpirun(&args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    let ours: Vec<&str> = err.lines().filter(|l| l.starts_with("megaray")).collect();
    assert_eq!(ours.len(), 1, "{err}");
    assert!(ours[0].contains("rank 1's scene file differs from rank 0's"), "{err}");
    assert!(!Path::new(&png).exists());
}

#[test]
fn a_view_script_across_two_ranks_gives_the_frames_of_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let script = dir.path().join("s.txt");
    // Still frames, a move, another shader, the sky on: each reaches rank 1 with its frame.
    let text = "frames 2\nkey forward down\nframes 2\nkey forward up\nframes 1\nkey nextshader down\nkey nextshader up\nframes 2\nkey togglesky down\nkey togglesky up\nframes 2\n";
    std::fs::write(&script, text).unwrap();
    let script = script.to_string_lossy().into_owned();
    let out = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    let common = ["--script", &script, "--res", "96x64", "--threads", "1", "-q"];
    let one = out("one");
    let mut args = vec!["view", &s, "--out", &one];
    args.extend(common);
    let (code, _, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let bin = bin();
    let two = out("two");
    let mut args = vec!["-n", "2", bin.to_str().unwrap(), "view", &s, "--out", &two];
    args.extend(common);
    let o = mpirun(&args).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for k in 1..=9 {
        let f = format!("frame-{k:05}.png");
        let a = std::fs::read(Path::new(&one).join(&f)).unwrap();
        let b = std::fs::read(Path::new(&two).join(&f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(a == b, "{f} differs");
    }
}

#[test]
fn serve_across_two_ranks_sends_frames_to_a_page() {
    use std::io::{BufRead, BufReader};
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let bin = bin();
    let args = ["-n", "2", bin.to_str().unwrap(), "serve", &s, "--bind", "127.0.0.1:0", "--threads", "1"];
    let mut child = mpirun(&args).spawn().unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let addr = loop {
        let line = lines.next().expect("serve ended before listening").unwrap();
        if let Some(rest) = line.split("http://").nth(1) {
            break rest.split('/').next().unwrap().to_string();
        }
    };
    let log = std::thread::spawn(move || lines.map_while(Result::ok).collect::<Vec<_>>().join("\n"));
    let (mut ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).unwrap();
    ws.send(tungstenite::Message::text(r#"{"k":"size","w":64,"h":48}"#)).unwrap();
    let (mut pictures, start) = (0, Instant::now());
    while pictures < 4 && start.elapsed() < Duration::from_secs(60) {
        if let tungstenite::Message::Binary(b) = ws.read().unwrap() {
            // A JPEG of the view.
            assert_eq!(&b[..2], &[0xff, 0xd8]);
            pictures += 1;
            ws.send(tungstenite::Message::text(r#"{"k":"ack"}"#)).unwrap();
        }
    }
    // Kill the launcher: it ends both ranks.
    let _ = Command::new("kill").args(["-INT", &child.id().to_string()]).status();
    let _ = child.wait();
    let log = log.join().unwrap();
    assert_eq!(pictures, 4, "{log}");
    assert!(!log.contains("error"), "{log}");
}
