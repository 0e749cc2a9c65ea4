//! The command line's library side: one function per `toolkit` subcommand and the progress
//! output they print. `main.rs` only parses arguments and maps errors to exit codes.

pub mod commands;
pub mod progress;
