//! The compare summary: per input and quality level ([`crate::metrics::quality_levels`] of its image size:
//! 0.5, 1 and 2 pixels of geometric error with their silhouette and FLIP bounds), the fastest
//! and the smallest run that meets it (`quality_px <= level`), the time and memory ratio of
//! the best ray-marched run (SDF or grid) to the best mesh run, and the resolutions at which
//! the fastest representation changes. Rows of several replicates of a run (same input,
//! asked repr, method, resolution, tolerance and relaxation) count as one run: its median
//! frame time over the replicates and its worst quality.
//!
//! A run counts for a side ([`side`]) only when it was asked in that side's representation
//! and traced by that side alone: a mesh run whose extraction came out empty and was sphere
//! traced (`repr` `sdf`, `asked_repr` `mesh`) is neither a mesh run nor a marched one.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use super::Row;
use crate::metrics::{median, quality_levels};
use crate::plan::ReprKind;

/// A run named in the summary.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Pick {
    /// `repr/method`.
    pub run: String,
    /// Resolution, if the run has one.
    pub resolution: Option<u32>,
    /// Hit tolerance of its sphere tracing, pixels, if it marches.
    pub tolerance_px: Option<f64>,
    /// Over-relaxation of its sphere tracing, if it marches.
    pub relaxation: Option<f64>,
    /// Median frame time, ms (the median over replicates of each replicate's median).
    pub frame_ms_median: f64,
    /// Total bytes.
    pub total_bytes: u64,
    /// The finest quality level met (the worst over replicates), pixels; `None`: none.
    pub quality_px: Option<f64>,
    /// 95th percentile of the geometric error, pixels (the worst over replicates).
    pub px_err_p95: Option<f64>,
    /// Mean FLIP (the worst over replicates).
    pub flip_mean: f64,
}

/// The answer at one quality level.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct AtLevel {
    /// The level: largest `px_err_p95`, pixels; runs with `quality_px <= quality_px` meet it.
    pub quality_px: f64,
    /// The level's largest `silhouette_mismatch_pct`.
    pub max_silhouette_pct: f64,
    /// The level's largest `flip_mean`.
    pub max_flip_mean: f64,
    /// The fastest run that meets it.
    pub fastest: Option<Pick>,
    /// The smallest run that meets it.
    pub smallest: Option<Pick>,
    /// The fastest ray-marched run (`sdf` or `grid`) that meets it.
    pub best_marched: Option<Pick>,
    /// The fastest mesh run that meets it.
    pub best_mesh: Option<Pick>,
    /// `best_marched` frame time over `best_mesh` frame time (< 1: marching is faster).
    pub marched_over_mesh_time: Option<f64>,
    /// Bytes of the smallest marched run over the smallest mesh run that meet it.
    pub marched_over_mesh_bytes: Option<f64>,
}

/// The fastest run at one resolution of the sweep.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Winner {
    /// Resolution.
    pub resolution: u32,
    /// The fastest run at it.
    pub fastest: Pick,
}

/// The summary of one input.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct InputSummary {
    /// Input name.
    pub input: String,
    /// The reference run.
    pub reference: String,
    /// Distinct replicates among the input's rows.
    pub replicates: usize,
    /// Per quality level, finest first.
    pub levels: Vec<AtLevel>,
    /// Fastest run per resolution of the sweep.
    pub winners: Vec<Winner>,
    /// Resolutions at which the fastest run changes from the one at the previous resolution.
    pub crossovers: Vec<u32>,
}

/// The whole summary.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    /// CSV schema version of the rows summarised.
    pub schema_version: u32,
    /// Per input, in first-seen order.
    pub inputs: Vec<InputSummary>,
}

fn pick(r: &Row) -> Pick {
    let asked = if r.asked_repr == r.repr { String::new() } else { format!(" (asked {})", r.asked_repr) };
    Pick {
        run: format!("{}/{}{asked}", r.repr, r.method),
        resolution: r.resolution,
        tolerance_px: r.tolerance_px,
        relaxation: r.relaxation,
        frame_ms_median: r.frame_ms_median,
        total_bytes: r.total_bytes,
        quality_px: r.quality_px,
        px_err_p95: r.px_err_p95,
        flip_mean: r.flip_mean,
    }
}

fn min_by<'a>(rows: impl Iterator<Item = &'a Row>, key: impl Fn(&Row) -> f64) -> Option<&'a Row> {
    rows.min_by(|a, b| key(a).total_cmp(&key(b)))
}

/// The two sides the summary compares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Ray marching: `sdf` (sphere tracing) and `grid`.
    Marched,
    /// Triangle meshes: `mesh`.
    Mesh,
}

/// The side a representation's name is on (`None`: `analytic`, or an unknown name).
fn side_of(repr: &str) -> Option<Side> {
    match repr {
        r if r == ReprKind::Sdf.name() || r == ReprKind::Grid.name() => Some(Side::Marched),
        r if r == ReprKind::Mesh.name() => Some(Side::Mesh),
        _ => None,
    }
}

/// The side a run counts for: the asked representation's, when every representation that
/// traced it (`repr`, `+`-separated) is on that side too; `None` otherwise (the closed-form
/// reference, a mesh run sphere traced in whole or in part, ...).
pub fn side(r: &Row) -> Option<Side> {
    let asked = side_of(&r.asked_repr)?;
    r.repr.split('+').all(|k| side_of(k) == Some(asked)).then_some(asked)
}

fn is_marched(r: &Row) -> bool {
    side(r) == Some(Side::Marched)
}

fn is_mesh(r: &Row) -> bool {
    side(r) == Some(Side::Mesh)
}

/// One row per run of an input: replicates merged (median frame time, worst errors and
/// quality), in first-seen order.
fn merge_replicates(rows: &[&Row]) -> Vec<Row> {
    let mut order = Vec::new();
    let mut groups: BTreeMap<_, Vec<&Row>> = BTreeMap::new();
    for r in rows {
        let key = super::RowKey { replicate: 0, ..r.key() };
        if !groups.contains_key(&key) {
            order.push(key.clone());
        }
        groups.entry(key).or_default().push(r);
    }
    order
        .iter()
        .map(|k| {
            let g = &groups[k];
            let mut m = g[0].clone();
            let times: Vec<f64> = g.iter().map(|r| r.frame_ms_median).collect();
            m.frame_ms_median = median(&times);
            let worst = |f: fn(&Row) -> Option<f64>| -> Option<f64> {
                g.iter().map(|r| f(r)).try_fold(0.0f64, |acc, v| v.map(|v| acc.max(v)))
            };
            m.quality_px = worst(|r| r.quality_px);
            m.px_err_p95 = worst(|r| r.px_err_p95);
            m.flip_mean = g.iter().map(|r| r.flip_mean).fold(0.0, f64::max);
            m
        })
        .collect()
}

/// Summarises rows (any order; several inputs and replicates).
pub fn summarize(rows: &[Row]) -> Summary {
    let mut order: Vec<String> = Vec::new();
    let mut by_input: BTreeMap<String, Vec<&Row>> = BTreeMap::new();
    for r in rows {
        if !by_input.contains_key(&r.input) {
            order.push(r.input.clone());
        }
        by_input.entry(r.input.clone()).or_default().push(r);
    }
    let inputs = order
        .iter()
        .map(|name| {
            let mut replicates: Vec<u32> = by_input[name].iter().map(|r| r.replicate).collect();
            replicates.sort_unstable();
            replicates.dedup();
            let merged = merge_replicates(&by_input[name]);
            let rows: Vec<&Row> = merged.iter().collect();
            let rows = &rows;
            // The gates of the input's image size (every run of an input has the same).
            let (w, h) = rows.first().map_or((256, 256), |r| (r.width, r.height));
            let levels = quality_levels(w, h)
                .iter()
                .map(|level| {
                    let l = level.px;
                    let ok = || rows.iter().copied().filter(move |r| r.quality_px.is_some_and(|q| q <= l));
                    let time = |r: &Row| r.frame_ms_median;
                    let bytes = |r: &Row| r.total_bytes as f64;
                    let fastest = min_by(ok(), time);
                    let smallest = min_by(ok(), bytes);
                    let best_marched = min_by(ok().filter(|r| is_marched(r)), time);
                    let best_mesh = min_by(ok().filter(|r| is_mesh(r)), time);
                    let small_marched = min_by(ok().filter(|r| is_marched(r)), bytes);
                    let small_mesh = min_by(ok().filter(|r| is_mesh(r)), bytes);
                    AtLevel {
                        quality_px: l,
                        max_silhouette_pct: level.max_silhouette_pct,
                        max_flip_mean: level.max_flip_mean,
                        fastest: fastest.map(pick),
                        smallest: smallest.map(pick),
                        marched_over_mesh_time: best_marched
                            .zip(best_mesh)
                            .map(|(a, b)| a.frame_ms_median / b.frame_ms_median),
                        marched_over_mesh_bytes: small_marched
                            .zip(small_mesh)
                            .map(|(a, b)| a.total_bytes as f64 / b.total_bytes.max(1) as f64),
                        best_marched: best_marched.map(pick),
                        best_mesh: best_mesh.map(pick),
                    }
                })
                .collect();
            let mut resolutions: Vec<u32> = rows.iter().filter_map(|r| r.resolution).collect();
            resolutions.sort_unstable();
            resolutions.dedup();
            let winners: Vec<Winner> = resolutions
                .iter()
                .filter_map(|&res| {
                    let at = rows.iter().copied().filter(|r| r.resolution == Some(res));
                    min_by(at, |r| r.frame_ms_median).map(|r| Winner { resolution: res, fastest: pick(r) })
                })
                .collect();
            let crossovers = winners
                .windows(2)
                .filter(|w| w[0].fastest.run != w[1].fastest.run)
                .map(|w| w[1].resolution)
                .collect();
            InputSummary {
                input: name.clone(),
                reference: rows.first().map(|r| r.reference.clone()).unwrap_or_default(),
                replicates: replicates.len(),
                levels,
                winners,
                crossovers,
            }
        })
        .collect();
    Summary { schema_version: super::SCHEMA_VERSION, inputs }
}

fn describe(p: &Option<Pick>) -> String {
    match p {
        Some(p) => {
            let res = p.resolution.map_or(String::new(), |r| format!(" @{r}"));
            let knob = match (p.tolerance_px, p.relaxation) {
                (Some(t), Some(r)) if p.resolution.is_none() => format!(" tol {t} px relax {r}"),
                _ => String::new(),
            };
            format!("{}{res}{knob} ({:.1} ms, {} bytes)", p.run, p.frame_ms_median, p.total_bytes)
        }
        None => "none".into(),
    }
}

/// The summary as text for the terminal.
pub fn to_text(s: &Summary) -> String {
    let mut t = String::new();
    for i in &s.inputs {
        let reps = if i.replicates > 1 { format!(", {} replicates", i.replicates) } else { String::new() };
        let _ = writeln!(t, "{} (reference {}{reps}):", i.input, i.reference);
        for th in &i.levels {
            let _ = writeln!(
                t,
                "  quality {} px (silhouette <= {}%, FLIP <= {}): fastest {}; smallest {}",
                th.quality_px,
                th.max_silhouette_pct,
                th.max_flip_mean,
                describe(&th.fastest),
                describe(&th.smallest)
            );
            if let (Some(time), Some(bytes)) = (th.marched_over_mesh_time, th.marched_over_mesh_bytes) {
                let _ = writeln!(
                    t,
                    "    marched/mesh: time {time:.2}x ({} vs {}), bytes {bytes:.2}x",
                    describe(&th.best_marched),
                    describe(&th.best_mesh)
                );
            }
        }
        if !i.winners.is_empty() {
            let w: Vec<String> =
                i.winners.iter().map(|w| format!("{}: {}", w.resolution, w.fastest.run)).collect();
            let _ = writeln!(t, "  fastest per resolution: {}", w.join(", "));
        }
        if !i.crossovers.is_empty() {
            let c: Vec<String> = i.crossovers.iter().map(|c| c.to_string()).collect();
            let _ = writeln!(t, "  the fastest representation changes at resolution {}", c.join(", "));
        }
    }
    t
}
