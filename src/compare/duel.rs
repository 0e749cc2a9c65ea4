//! `toolkit compare INPUT --duel A,B,...`: paired, interleaved re-timing of runs chosen
//! elsewhere (issue #37, "select, then measure").
//!
//! A study chooses each side's configuration on the selection pass (the compare CSVs of
//! its replicates) and then re-times only the chosen ones here, in separate processes: the
//! verdict uses these duel times, not the minimum of the noisy selection timings. Within
//! one process every round renders each named run once, in an order that alternates
//! between rounds (A B C, then C B A, ...), so that a drift of the machine's speed (another
//! process, the clock, the caches) falls on every run alike; the ratio of two runs is taken
//! within a round.
//!
//! The runs are planned exactly as `compare` plans them with the same flags (the one place
//! that decides how an input becomes a representation, [`super::plan`]) and picked by
//! [`run_label`]; a label that names no planned run is an error. Nothing is measured but
//! frame time: the duel does not judge error or bytes, which the selection pass measured and
//! which do not vary between processes.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::{Built, Run, build, commit_id, load_single, plan, write_csv_whole};
use crate::config::{CompareOptions, DuelOptions};
use crate::error::{Error, Result, catch_panic};
use crate::plan::ReprKind;
use crate::render::PrimaryVisibility;
use crate::render::render_with;

/// Version of the duel CSV's schema.
pub const DUEL_SCHEMA_VERSION: u32 = 1;

/// One timed frame of a duel: a row of the duel CSV.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct DuelRow {
    /// Input name (the file's stem, as `compare`'s `input`).
    pub input: String,
    /// Class of the input ([`input_class`]).
    pub class: String,
    /// Which process of the duel (`--replicate`): the processes are the replication.
    pub process: u32,
    /// Round number, from 0.
    pub round: u32,
    /// Position of this frame in its round, from 0.
    pub slot: u32,
    /// The run ([`run_label`]).
    pub run: String,
    /// What traced it (`compare`'s `repr` column).
    pub repr: String,
    /// The frame's time, ms.
    pub frame_ms: f64,
    /// Rendering threads.
    pub threads: usize,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Commit of the toolkit.
    pub commit: String,
    /// [`DUEL_SCHEMA_VERSION`].
    pub schema_version: u32,
}

/// The label that names a planned run in `--duel`: `asked_repr/method`, then `/resolution`
/// where the run has one, then `@tolerance_px:relaxation` for the sphere tracing sweep's runs
/// (`sdf/sphere-trace@1:1.6`, `mesh/extracted/32`, `grid/band/48`, `mesh/decimated-25%`).
/// The study writes the same label from a CSV row's columns.
fn run_label(run: &Run) -> String {
    let mut s = format!("{}/{}", run.repr, run.method());
    if let Some(r) = run.resolution {
        s += &format!("/{r}");
    }
    if run.repr == ReprKind::Sdf
        && let Some((t, r)) = run.knob()
    {
        s += &format!("@{t}:{r}");
    }
    s
}

/// Whether `label` names `run`: the same text, or the same run with the knob's numbers
/// written otherwise (`@1.0:1.60` for `@1:1.6`, as a CSV writes them).
fn names(label: &str, run: &Run) -> bool {
    let own = run_label(run);
    if label == own {
        return true;
    }
    let (Some((a, ka)), Some((b, kb))) = (label.split_once('@'), own.split_once('@')) else {
        return false;
    };
    let knob = |k: &str| -> Option<(f64, f64)> {
        let (t, r) = k.split_once(':')?;
        Some((t.parse().ok()?, r.parse().ok()?))
    };
    a == b && knob(ka).is_some() && knob(ka) == knob(kb)
}

/// The run `label` names among those `compare --search` can make of `scene` (its knob
/// families, [`super::searched::families`], traced or rasterized): the knob is read off the label
/// (the resolution, the decimation's percentage, the hit tolerance), so a duel re-times
/// the runs a search chose with the same flags.
fn searched_run(
    scene: &crate::scene::Scene,
    opts: &CompareOptions,
    max_res: u32,
    label: &str,
) -> Option<Run> {
    let (main, knob) = label.split_once('@').map_or((label, None), |(a, b)| (a, Some(b)));
    let mut knobs = Vec::new();
    if let Some(r) = main.rsplit('/').next().and_then(|s| s.parse::<u32>().ok()) {
        knobs.push(r);
    }
    let percent = main.split("decimated-").nth(1).and_then(|s| s.split('%').next());
    if let Some(p) = percent.and_then(|s| s.parse::<f64>().ok()).filter(|p| p.is_finite() && *p > 0.0) {
        knobs.push((p * 100.0).round() as u32);
    }
    let tolerance = knob.and_then(|k| k.split(':').next()).and_then(|t| t.parse::<f64>().ok());
    if let Some(t) = tolerance.filter(|t| t.is_finite() && *t > 0.0) {
        knobs.push((super::searched::SEARCH_TOLERANCE_PX / t).round() as u32);
    }
    for family in super::searched::families(scene, opts, max_res) {
        for &k in &knobs {
            for primary in [PrimaryVisibility::Trace, PrimaryVisibility::Raster] {
                let run = Run { primary, ..(family.make)(k) };
                if names(label, &run) {
                    return Some(run);
                }
            }
        }
    }
    None
}

/// Runs the duel of `duel.runs` on `opts`' single input and writes its rows to `opts.csv`
/// (atomically, when every round is done); returns a summary: each run's median frame time.
///
/// # Errors
/// The input does not load, a label names no planned run (the error lists the planned
/// ones), a run cannot be built (its memory budget), the CSV cannot be written.
pub fn duel_command(opts: &CompareOptions, duel: &DuelOptions) -> Result<String> {
    let (path, name, class, scene) = load_single(opts, "--duel")?;
    let planned = plan(&scene, opts);
    let mut chosen: Vec<(String, Run)> = Vec::new();
    for label in &duel.runs {
        let searched = || opts.search_max_res.and_then(|max| searched_run(&scene, opts, max, label));
        let found = planned.iter().find(|r| names(label, r)).cloned().or_else(searched);
        let run = found.as_ref().ok_or_else(|| {
            let known: Vec<String> = planned.iter().map(run_label).collect();
            Error::Usage(format!(
                "{}: --duel run `{label}` is not planned with these flags (planned: {})",
                path.display(),
                known.join(", ")
            ))
        })?;
        if !chosen.iter().any(|(l, _)| *l == run_label(run)) {
            chosen.push((run_label(run), run.clone()));
        }
    }
    let mut built: Vec<(String, String, Built, PrimaryVisibility)> = Vec::with_capacity(chosen.len());
    for (label, run) in &chosen {
        let b = catch_panic(|| build(&scene, run.build, &opts.budget))
            .and_then(|r| r)
            .map_err(|e| Error::Usage(format!("{}: --duel run `{label}`: {e}", path.display())))?;
        let repr = crate::plan::traced_repr(&b.plans, run.repr).name();
        built.push((label.clone(), repr, b, run.primary));
    }
    // One warm-up frame of each run, then the rounds.
    for (_, _, b, primary) in &built {
        render_with(&scene, &b.geometry, *primary);
    }
    let commit = commit_id();
    let threads = rayon::current_num_threads();
    let n = built.len();
    let mut rows = Vec::with_capacity(n * duel.rounds as usize);
    let start = Instant::now();
    for round in 0..duel.rounds {
        for slot in 0..n {
            // Forward in even rounds, backward in odd ones.
            let i = if round % 2 == 0 { slot } else { n - 1 - slot };
            let (label, repr, b, primary) = &built[i];
            let frame = render_with(&scene, &b.geometry, *primary);
            rows.push(DuelRow {
                input: name.clone(),
                class: class.clone(),
                process: opts.replicate,
                round,
                slot: slot as u32,
                run: label.clone(),
                repr: repr.clone(),
                frame_ms: frame.time.as_secs_f64() * 1e3,
                threads,
                width: scene.camera.width,
                height: scene.camera.height,
                commit: commit.clone(),
                schema_version: DUEL_SCHEMA_VERSION,
            });
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    write_csv_whole(&opts.csv, &rows)?;
    let mut text = format!(
        "{name}: {} runs x {} rounds interleaved in {seconds:.1} s (process {})\n",
        n, duel.rounds, opts.replicate
    );
    for (label, repr, _, _) in &built {
        let times: Vec<f64> = rows.iter().filter(|r| r.run == *label).map(|r| r.frame_ms).collect();
        text +=
            &format!("  {label:<32} traced as {repr:<8} median {:.3} ms\n", crate::metrics::median(&times));
    }
    Ok(text)
}

/// Reads a duel CSV.
///
/// # Errors
/// The file cannot be read or a row does not parse (its line in the error).
pub fn read_duel_rows(path: &std::path::Path) -> Result<Vec<DuelRow>> {
    let mut reader = csv::Reader::from_path(path).map_err(|e| Error::io(path, e))?;
    reader
        .deserialize()
        .enumerate()
        .map(|(i, r)| r.map_err(|e| Error::Usage(format!("{}: line {}: {e}", path.display(), i + 2))))
        .collect()
}
