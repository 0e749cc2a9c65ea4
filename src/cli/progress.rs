//! Progress of long conversions on the terminal: a bar on stderr (indicatif) for the stage
//! a command is in, shown only when the command asked for it ([`Stage::start`] with
//! `show`) and stderr is a terminal; nothing otherwise.
//!
//! Work loops deep in the library report with [`crate::base::progress::advance`] (a few
//! calls per z-slice or chunk, never per sample), so they need no progress parameter: a
//! shown stage installs its bar as the [`progress::Sink`] they report to; while none is
//! shown, their reports are a relaxed atomic load and a return.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use indicatif::{ProgressBar, ProgressStyle};

use crate::base::progress;

/// Whether a bar is shown (checked before taking the lock).
static ACTIVE: AtomicBool = AtomicBool::new(false);
/// The bar of the current stage.
static BAR: Mutex<Option<ProgressBar>> = Mutex::new(None);

/// The bar receives the library's reports of work done.
impl progress::Sink for ProgressBar {
    fn advance(&self, n: u64) {
        self.inc(n);
    }
}

/// A stage of a command whose progress is shown while it lives; the bar is cleared when it
/// is dropped.
pub struct Stage {
    shown: bool,
}

impl Stage {
    /// Starts a stage of `total` units of work called `label`; a bar is drawn when `show`
    /// is true and stderr is a terminal.
    pub fn start(label: &str, total: u64, show: bool) -> Stage {
        if !show || !std::io::stderr().is_terminal() {
            return Stage { shown: false };
        }
        let bar = ProgressBar::new(total);
        if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:30}] {percent:>3}% {elapsed} ETA {eta}")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(label.to_owned());
        if let Ok(mut b) = BAR.lock() {
            progress::install(Arc::new(bar.clone()));
            *b = Some(bar);
            ACTIVE.store(true, Ordering::Release);
        }
        Stage { shown: true }
    }
}

impl Drop for Stage {
    fn drop(&mut self) {
        if !self.shown {
            return;
        }
        ACTIVE.store(false, Ordering::Release);
        progress::remove();
        if let Ok(mut b) = BAR.lock()
            && let Some(bar) = b.take()
        {
            bar.finish_and_clear();
        }
    }
}

/// Sets the current stage's progress to `done` units (no-op when no bar is shown); for
/// stages whose parts report fewer units than they were estimated at.
pub fn set(done: u64) {
    if !ACTIVE.load(Ordering::Relaxed) {
        return;
    }
    if let Ok(b) = BAR.lock()
        && let Some(bar) = b.as_ref()
    {
        bar.set_position(done);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hidden_stages_cost_nothing_and_never_draw() {
        // Under the test harness stderr is not a terminal: nothing is shown.
        let stage = Stage::start("sampling", 10, true);
        assert!(!stage.shown);
        assert!(!ACTIVE.load(Ordering::Relaxed));
        progress::advance(5);
        set(7);
        drop(stage);
        assert!(BAR.lock().unwrap().is_none());
    }
}
