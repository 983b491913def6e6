//! Never lose work: builds killed at any moment, writes cut by a file-size limit, and scene
//! files that change under a running render.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;
use megaray_scene::Scene;

/// The names in `dir` that are temporaries (`.NAME.tmp-PID`, `.megaray-build-PID-*`).
fn temporaries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.contains(".tmp-") || n.starts_with(".megaray-build-"))
        .collect();
    v.sort();
    v
}

/// Whether `path` opens as a scene whose every tile passes its check.
fn sound(path: &Path) -> Result<usize, String> {
    let s = Scene::open(path).map_err(|e| e.to_string())?;
    for t in 0..s.tiles().len() as u32 {
        s.check_tile(t).map_err(|e| e.to_string())?;
    }
    Ok(s.tiles().len())
}

/// Runs megaray under `ulimit -f BLOCKS` (512-byte blocks); returns (code, stderr).
fn run_limited(blocks: u64, args: &[&str]) -> (i32, String) {
    let mut script = format!("ulimit -f {blocks}; exec \"$0\"");
    for i in 1..=args.len() {
        script.push_str(&format!(" \"${i}\""));
    }
    let out = Command::new("sh").arg("-c").arg(script).arg(bin()).args(args).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// `kill -9` of `build` at 10 moments spread over a build: the output is always the earlier
/// scene or the new one, whole; temporaries left by the killed builds are removed by the
/// next build into that folder, which succeeds.
#[test]
fn a_build_killed_at_any_moment_leaves_the_old_scene_or_the_new_one() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:1M");
    let out = dir.path().join("plant.mray");
    let args = ["build", ply.to_str().unwrap(), "-o", out.to_str().unwrap(), "--build-mem", "128M", "-q"];
    let t0 = Instant::now();
    let (code, _, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let full = t0.elapsed();
    let tiles = sound(&out).unwrap();
    // Moments from the start to a little past the end, in a fixed pseudo-random order.
    let mut killed_mid_build = 0;
    for i in 0..10u32 {
        let at = full.mul_f64(megaray_base::hash32(i) as f64 / u32::MAX as f64 * 1.1);
        let mut child = Command::new(bin()).args(args).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
        std::thread::sleep(at);
        killed_mid_build += child.try_wait().unwrap().is_none() as u32;
        child.kill().ok();
        child.wait().unwrap();
        assert_eq!(sound(&out), Ok(tiles), "after a kill at {at:?}");
    }
    assert!(killed_mid_build >= 5, "only {killed_mid_build} of the kills caught a build running");
    let (code, _, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    assert_eq!(sound(&out), Ok(tiles));
    assert_eq!(temporaries(dir.path()), Vec::<String>::new(), "temporaries left after the next build");
}

/// A file-size limit that cuts the scene or the image: one line, exit 1, no output, no
/// temporary left (SIGXFSZ is ignored, so the write fails instead of killing the process).
#[test]
fn a_write_cut_by_a_file_size_limit_is_one_line_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:100k");
    let out = dir.path().join("cut.mray");
    let (code, err) = run_limited(64, &["build", ply.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("building") && err.contains("cut.mray") && err.contains("File too large"), "{err}");
    assert!(!out.exists());
    assert_eq!(temporaries(dir.path()), Vec::<String>::new());

    let (code, _, err) = run(&["build", ply.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    let png = dir.path().join("cut.exr");
    let (code, err) =
        run_limited(8, &["render", out.to_str().unwrap(), "-o", png.to_str().unwrap(), "--res", "256x256"]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("cut.exr"), "{err}");
    assert!(!png.exists());
    assert_eq!(temporaries(dir.path()), Vec::<String>::new());
}

/// Waits until `child` has been running for `d`; false if it ended before.
fn still_running_after(child: &mut std::process::Child, d: Duration) -> bool {
    std::thread::sleep(d);
    child.try_wait().unwrap().is_none()
}

/// A scene truncated in place under a render ends it with one line naming the file and
/// exit 1 (not death by SIGBUS), mapped (a plain file) or paged (a paged render notices when
/// it reads a tile again, so the budget is below the working set); a compact file rendered in
/// core was decoded whole at open and goes on; one replaced by rename is not noticed: the
/// render finishes with the old file's picture.
#[test]
fn a_scene_changed_under_a_render() {
    let dir = tempfile::tempdir().unwrap();
    let ply = gen(dir.path(), "plant:200k");
    let (scene, _) = build(dir.path(), std::slice::from_ref(&ply), "plant", Some(20_000));
    let plain_opts = megaray_build::BuildOptions { max_part_tris: Some(20_000), compact: false, ..test_options() };
    let (plain, _) = build_with(dir.path(), &[ply], "plain", plain_opts);
    let other = dir.path().join("other.mray");
    let (code, _, err) = run(&["build", &model("spot.obj").to_string_lossy(), "-o", other.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    let small = (megaray_page::Pager::min_budget(&Scene::open(&scene).unwrap()) + 65536).to_string();
    for (budget, source) in [(None, &plain), (Some(small.as_str()), &scene), (None, &scene)] {
        let len = std::fs::metadata(source).unwrap().len();
        let live = dir.path().join("live.mray");
        std::fs::copy(source, &live).unwrap();
        let png = dir.path().join("t.png");
        let mut args = vec!["render", live.to_str().unwrap(), "-o", png.to_str().unwrap(), "--res", "128x128"];
        args.extend(["--frames", "1000000", "--threads", "2", "-q"]);
        if let Some(b) = budget {
            // Full detail under a budget below the working set: tiles are read again and again.
            args.extend(["--mem", b, "--lod-error", "0"]);
        }
        let mut child = Command::new(bin()).args(&args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
        if !still_running_after(&mut child, Duration::from_millis(500)) {
            let out = child.wait_with_output().unwrap();
            panic!("the render ended before the truncation: {}", String::from_utf8_lossy(&out.stderr));
        }
        std::fs::OpenOptions::new().write(true).open(&live).unwrap().set_len(len / 3).unwrap();
        if budget.is_none() && source == &scene {
            // In core, compact: nothing is read after the open.
            assert!(still_running_after(&mut child, Duration::from_millis(500)), "the in-core render stopped");
            child.kill().ok();
            child.wait().unwrap();
            continue;
        }
        let t0 = Instant::now();
        while child.try_wait().unwrap().is_none() && t0.elapsed() < Duration::from_secs(60) {
            std::thread::sleep(Duration::from_millis(20));
        }
        child.kill().ok();
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "budget {budget:?}: {:?} {err}", out.status);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains("live.mray"), "{err}");
        assert!(!png.exists());
    }

    // Replaced by rename: the render goes on with the old file and gives its picture.
    let live = dir.path().join("live.mray");
    std::fs::copy(&scene, &live).unwrap();
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let common = ["--res", "128x128", "--frames", "3000", "--threads", "2", "-q"];
    let (code, _, err) = run(&[&["render", live.to_str().unwrap(), "-o", a.to_str().unwrap()], &common[..]].concat());
    assert_eq!(code, 0, "{err}");
    let args = [&["render", live.to_str().unwrap(), "-o", b.to_str().unwrap()], &common[..]].concat();
    let mut child = Command::new(bin()).args(&args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let renamed_while_running = still_running_after(&mut child, Duration::from_millis(300));
    std::fs::rename(&other, &live).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(renamed_while_running, "the render ended before the rename: make it longer");
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

/// A real-world OBJ with lines written as faces and a zero-area triangle builds; the notes
/// give each count, once, naming the file.
#[test]
fn odd_faces_are_skipped_with_counted_notes() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("odd.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2\nf 3 1\nf 1 2 4\nl 1 3\n").unwrap();
    let out = dir.path().join("odd.mray");
    let (code, _, err) = run(&["build", obj.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let notes: Vec<&str> = err.lines().filter(|l| l.contains("skipped")).collect();
    assert_eq!(notes.len(), 2, "{err}");
    assert!(notes.iter().any(|n| n.contains("odd.obj: skipped 2 faces with fewer than 3 vertices")), "{err}");
    assert!(notes.iter().any(|n| n.contains("odd.obj: skipped 1 degenerate (zero-area) triangles")), "{err}");
}

/// Output read by a program that stops early (`megaray info X | head -1`): the command ends
/// quietly, as `cat` does, instead of panicking on the closed pipe.
#[test]
fn a_closed_output_pipe_ends_the_command_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bunny.mray");
    let (code, _, err) =
        run(&["build", model("stanford-bunny.obj").to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    for args in [vec!["info", out.to_str().unwrap()], vec!["info", out.to_str().unwrap(), "--json"]] {
        let mut child = Command::new(bin()).args(&args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
        // The reader goes away before the first line is written.
        drop(child.stdout.take());
        let done = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&done.stderr);
        assert!(!err.contains("panicked") && err.trim().is_empty(), "{args:?}: {err}");
        assert!(done.status.success() || done.status.signal() == Some(libc::SIGPIPE), "{args:?}: {:?}", done.status);
    }
}
