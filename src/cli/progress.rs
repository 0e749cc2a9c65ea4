//! Progress of long conversions on the terminal: a bar on stderr (indicatif) for the stage
//! a command is in, shown only when the command asked for it ([`Stage::start`] with
//! `show`) and stderr is a terminal; nothing otherwise.
//!
//! Work loops deep in the library report with [`crate::base::progress::advance`] (a few
//! calls per z-slice or chunk, never per sample), so they need no progress parameter: a
//! shown stage installs its bar as the [`progress::Sink`] they report to; while none is
//! shown, their reports are a relaxed atomic load and a return.

use std::io::IsTerminal;
use std::sync::Arc;

use indicatif::{ProgressBar, ProgressStyle};

use crate::base::progress;

/// The bar receives the library's reports of work done.
impl progress::Sink for ProgressBar {
    fn advance(&self, n: u64) {
        self.inc(n);
    }
}

/// A stage of a command whose progress is shown while it lives; the bar is cleared when it
/// is dropped.
pub struct Stage {
    /// The bar, when one is shown (it is also the installed [`progress::Sink`]).
    bar: Option<ProgressBar>,
}

impl Stage {
    /// Starts a stage of `total` units of work called `label`; a bar is drawn when `show`
    /// is true and stderr is a terminal.
    pub fn start(label: &str, total: u64, show: bool) -> Stage {
        if !show || !std::io::stderr().is_terminal() {
            return Stage { bar: None };
        }
        let bar = ProgressBar::new(total);
        if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:30}] {percent:>3}% {elapsed} ETA {eta}")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(label.to_owned());
        progress::install(Arc::new(bar.clone()));
        Stage { bar: Some(bar) }
    }

    /// Sets this stage's progress to `done` units (no-op when no bar is shown); for stages
    /// whose parts report fewer units than they were estimated at.
    pub fn set(&self, done: u64) {
        if let Some(bar) = &self.bar {
            bar.set_position(done);
        }
    }
}

impl Drop for Stage {
    fn drop(&mut self) {
        if let Some(bar) = self.bar.take() {
            progress::remove();
            bar.finish_and_clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hidden_stages_cost_nothing_and_never_draw() {
        // Under the test harness stderr is not a terminal: nothing is shown.
        let stage = Stage::start("sampling", 10, true);
        assert!(stage.bar.is_none());
        progress::advance(5);
        stage.set(7);
        drop(stage);
    }
}
