//! The library's error type: every failure a user can cause names the file, the place
//! (line and column where known) and the problem in one line, and maps to an exit code.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in an input file a problem is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Location {
    /// 1-based line.
    pub line: usize,
    /// 1-based column.
    pub column: usize,
}

/// Every error the toolkit reports to a user.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An input file is malformed or holds an invalid value.
    #[error("{}", fmt_input(path, location, message))]
    Input {
        /// The file.
        path: PathBuf,
        /// Line and column, where known.
        location: Option<Location>,
        /// What is wrong, without the file name.
        message: String,
    },
    /// A file could not be read or written.
    #[error("{}: {message}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The command line asks for something impossible (e.g. a resolution of 0).
    #[error("{0}")]
    Usage(String),
    /// Some inputs of a batch command (`compare`, `gallery`) failed, each reported on
    /// stderr when it did; the others ran, and `output` is their report (printed before
    /// this error's one line).
    #[error("{message}")]
    Batch {
        /// The report of the inputs that ran.
        output: String,
        /// Which inputs failed.
        message: String,
    },
}

fn fmt_input(path: &Path, location: &Option<Location>, message: &str) -> String {
    match location {
        Some(l) => format!("{}:{}:{}: {message}", path.display(), l.line, l.column),
        None => format!("{}: {message}", path.display()),
    }
}

impl Error {
    /// An input error at an optional location.
    pub fn input(path: impl Into<PathBuf>, location: Option<Location>, message: impl fmt::Display) -> Self {
        Error::Input { path: path.into(), location, message: single_line(message.to_string()) }
    }

    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, err: impl fmt::Display) -> Self {
        Error::Io { path: path.into(), message: single_line(err.to_string()) }
    }

    /// The process exit code for this error: 2 for everything a user can cause (bad input,
    /// usage, unreadable or unwritable files).
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Input { .. } | Error::Usage(_) => 2,
            Error::Io { .. } | Error::Batch { .. } => 2,
        }
    }
}

/// `message` with every control character (a newline above all) escaped as Rust writes it
/// in a string literal: text quoted from an input file (a JSON key, a version string, a
/// parser's message) must not break the one-line contract.
fn single_line(message: String) -> String {
    if !message.chars().any(char::is_control) {
        return message;
    }
    let mut out = String::with_capacity(message.len() + 8);
    for c in message.chars() {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Runs `f`, turning a panic into an error (`Err` only for a panic): the batch commands
/// run each input through this, so that a bug one input meets is reported as that input's
/// failure (the panic message has already gone to stderr) and the inputs after it still run.
pub fn catch_panic<T>(f: impl FnOnce() -> T) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|p| {
        let what = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic".into());
        Error::Usage(single_line(format!("internal error (a bug; please report it): {what}")))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catch_panic_turns_a_panic_into_one_error_line() {
        assert_eq!(catch_panic(|| 7).unwrap(), 7);
        let e = catch_panic(|| -> u32 { panic!("index {} out of\nbounds", 18) }).unwrap_err().to_string();
        assert!(e.contains("internal error") && e.contains("index 18 out of"), "{e}");
        assert_eq!(e.lines().count(), 1, "{e}");
        let e = catch_panic(|| -> u32 { std::panic::panic_any(3u8) }).unwrap_err();
        assert_eq!(e.exit_code(), 2);
    }
}
