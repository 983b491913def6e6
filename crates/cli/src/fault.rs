//! Signals that would otherwise kill the process without a word.
//!
//! - **SIGBUS**: a scene file truncated in place under a running render or viewer. Its
//!   mapped pages past the new end fault on the next access, and the default action kills
//!   the process with no message. [`watch`] installs a handler that writes one line naming
//!   the file and exits with status 1. (Chosen over reading every tile with `pread`: the
//!   mapped file is the tracer's fast path, and a handler costs nothing until the fault. A
//!   scene replaced by rename, the way builds land, needs nothing: the mapping keeps the old
//!   file.)
//! - **SIGXFSZ**: a write past the file-size limit (`ulimit -f`). Ignored, so the write
//!   fails with `EFBIG` and the writer's error path (one line, temporary removed) runs.
//! - **SIGPIPE**: Rust ignores it, so a command whose reader went away (`megaray info X |
//!   head -3`) got `EPIPE` from its next `println!`, which panics. Commands that print for
//!   other programs take the default action again ([`end_quietly_on_closed_pipe`]): they end
//!   silently, as `cat` does. Not the server, the viewer nor MPI ranks, whose sockets must
//!   see `EPIPE` as an error instead.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

/// The line the SIGBUS handler writes, made before any fault (the handler only writes it).
static MESSAGE: OnceLock<Vec<u8>> = OnceLock::new();

/// Ignores SIGXFSZ for the whole process (see the module documentation).
pub fn ignore_file_size_signal() {
    // SAFETY: setting a signal's disposition to SIG_IGN has no preconditions.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

/// A closed standard output (or any pipe) ends the process silently, as it ends `cat`
/// (see the module documentation).
pub fn end_quietly_on_closed_pipe() {
    // SAFETY: setting a signal's disposition to SIG_DFL has no preconditions.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// From now on, a SIGBUS ends the process with one line naming `scene` (exit status 1).
/// The first call's file is named; later calls change nothing.
pub fn watch(scene: &Path) {
    let first = MESSAGE
        .set(
            format!(
                "megaray: error: {}: the scene file changed under this process (truncated in place?): \
                 a mapped page is gone (SIGBUS); stopping\n",
                scene.display()
            )
            .into_bytes(),
        )
        .is_ok();
    if !first {
        return;
    }
    // SAFETY: sigaction with a zeroed struct, an empty mask and a handler that only does
    // async-signal-safe things (a lock-free atomic swap, write, pause, _exit) on data
    // initialised before installation.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_sigbus as extern "C" fn(libc::c_int) as usize;
        libc::sigemptyset(&mut sa.sa_mask);
        libc::sigaction(libc::SIGBUS, &sa, std::ptr::null_mut());
    }
}

/// Whether a thread has taken the fault: several render threads may fault at once, and the
/// line is written once.
static FIRED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_sigbus(_sig: libc::c_int) {
    if FIRED.swap(true, Ordering::SeqCst) {
        // Another thread is writing the line and ends the process: wait for it (an exit
        // here could cut its line off).
        loop {
            // SAFETY: pause is async-signal-safe.
            unsafe { libc::pause() };
        }
    }
    if let Some(m) = MESSAGE.get() {
        // SAFETY: write(2) of a live, immutable buffer; _exit skips handlers and destructors.
        unsafe {
            libc::write(2, m.as_ptr().cast(), m.len());
        }
    }
    // SAFETY: _exit is async-signal-safe.
    unsafe { libc::_exit(1) }
}
