//! Progress bars for the library's [`Progress`] reports: indicatif on a terminal, nothing
//! otherwise (or with `--quiet`).

use std::io::IsTerminal;
use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use megaray_base::Progress;

pub struct Bars {
    bar: Mutex<Option<ProgressBar>>,
    enabled: bool,
}

impl Bars {
    pub fn new(quiet: bool) -> Bars {
        Bars { bar: Mutex::new(None), enabled: !quiet && std::io::stderr().is_terminal() }
    }
}

impl Bars {
    /// Whether bars are drawn (a terminal, no `--quiet`).
    pub fn visible(&self) -> bool {
        self.enabled
    }

    /// Replaces the current bar's message (e.g. the frame count and error estimate).
    pub fn message(&self, msg: &str) {
        if let Some(b) = self.bar.lock().unwrap().as_ref() {
            b.set_message(msg.to_string());
        }
    }
}

impl Progress for Bars {
    fn stage(&self, what: &str, total: u64) {
        if !self.enabled {
            return;
        }
        let bar = if total > 0 { ProgressBar::new(total) } else { ProgressBar::new_spinner() };
        bar.set_draw_target(ProgressDrawTarget::stderr_with_hz(8));
        let style = if total > 0 {
            ProgressStyle::with_template("{msg:>16} [{bar:40}] {percent:>3}% {elapsed_precise} eta {eta}")
        } else {
            ProgressStyle::with_template("{msg:>16} {spinner} {pos} {elapsed_precise}")
        };
        bar.set_style(style.unwrap_or_else(|_| ProgressStyle::default_bar()).progress_chars("=> "));
        bar.set_message(what.to_string());
        if let Some(old) = self.bar.lock().unwrap().replace(bar) {
            old.finish_and_clear();
        }
    }

    fn inc(&self, n: u64) {
        if let Some(b) = self.bar.lock().unwrap().as_ref() {
            b.inc(n);
        }
    }

    fn finish(&self) {
        if let Some(b) = self.bar.lock().unwrap().take() {
            b.finish_and_clear();
        }
    }

    fn note(&self, msg: &str) {
        match self.bar.lock().unwrap().as_ref() {
            Some(b) => b.println(format!("note: {msg}")),
            None => eprintln!("note: {msg}"),
        }
    }
}
