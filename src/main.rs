//! `toolkit`: parses the command line, has the library validate it once
//! ([`sdfmesh::config::Task::new`]), runs the command, maps errors to exit codes.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Parser;
use sdfmesh::base::heap::{INSTRUMENTED_SYSTEM, PeakMemAlloc};
use sdfmesh::cli::commands;
use sdfmesh::config::Task;
use sdfmesh::config::args::{Cli, Command};
use sdfmesh::plan::budget::MemoryBudget;

/// The system allocator with a count of live and peak heap bytes, which `compare` reads per
/// run ([`sdfmesh::base::heap`]).
#[global_allocator]
static ALLOCATOR: &PeakMemAlloc<std::alloc::System> = &INSTRUMENTED_SYSTEM;

fn main() -> ExitCode {
    sdfmesh::base::heap::install(&INSTRUMENTED_SYSTEM);
    let mut cli = match Cli::try_parse() {
        Ok(cli) => cli,
        // Help and version go to stdout as clap writes them; a usage error is one line, as
        // every other error (clap's own adds the usage and a hint on further lines).
        Err(e) if !e.use_stderr() => e.exit(),
        Err(e) => {
            let text = e.to_string();
            let first = text.lines().next().unwrap_or("error: invalid command line").trim_end();
            eprintln!("{first} (see --help)");
            return ExitCode::from(2);
        }
    };
    // The SIMD backend switch (SDFMESH_SIMD) is read once; an unknown value is refused.
    if let Err(e) = sdfmesh::simd::check_env() {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    let budget = cli.max_memory.unwrap_or_else(MemoryBudget::machine_default);
    // `compare` without inputs (and without --scaling or --summarize, which read none) runs
    // every bundled scene: found once, here, so that the checks below see them.
    if let Command::Compare { inputs, scaling: false, summarize: false, .. } = &mut cli.command
        && inputs.is_empty()
    {
        match sdfmesh::compare::default_inputs() {
            Ok(found) => *inputs = found,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(e.exit_code() as u8);
            }
        }
    }
    // No output may be one of the command's inputs: checked once, before any work.
    let (inputs, outputs) = cli.command.files();
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    if let Err(e) = sdfmesh::files::check_outputs(&inputs, &outputs) {
        eprintln!("error: {e}");
        return ExitCode::from(e.exit_code() as u8);
    }
    // And none of the files the inputs name (a scene's meshes, a glTF file's buffers).
    sdfmesh::files::protect_inputs();
    // Every flag checked once, before any work: the commands take validated options.
    let task = match Task::new(cli.command, budget) {
        Ok(task) => task,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(e.exit_code() as u8);
        }
    };
    let result = match task {
        Task::Render(opts) => commands::render_command(&opts).map(|r| print!("{}", r.text)),
        Task::Convert { input, output, target } => {
            commands::convert_command(&input, &output, target, budget).map(|t| print!("{t}"))
        }
        Task::Scaling { options, csv } => {
            sdfmesh::compare::scaling::scaling_command(&options, &csv).map(|t| print!("{t}"))
        }
        Task::Compare(opts) => sdfmesh::compare::compare_command(&opts).map(|t| print!("{t}")),
        Task::Summarize(opts) => sdfmesh::compare::summarize_command(&opts).map(|t| print!("{t}")),
        Task::CheckReference(options) => {
            sdfmesh::compare::refcheck::check_reference_command(&options).map(|t| print!("{t}"))
        }
        Task::Duel { options, duel } => {
            sdfmesh::compare::duel::duel_command(&options, &duel).map(|t| print!("{t}"))
        }
        Task::Hard { manifest, table } => {
            match sdfmesh::compare::hard::hard_command(&manifest, table.as_deref(), &budget) {
                Ok((text, as_expected)) => {
                    print!("{text}");
                    if !as_expected {
                        return ExitCode::from(1);
                    }
                    Ok(())
                }
                Err(e) => Err(e),
            }
        }
        Task::Gallery { scenes, output, reprs, overrides } => {
            commands::gallery_command(&scenes, &output, &reprs, overrides, budget).map(|t| print!("{t}"))
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if let sdfmesh::error::Error::Batch { output, .. } = &e {
                print!("{output}");
            }
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}
