//! The compare summary: per input and geometric-error threshold, the fastest and the
//! smallest run that meets it, the time and memory ratio of the best ray-marched run (SDF
//! or grid) to the best mesh run, and the resolutions at which the fastest representation
//! changes.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use super::{Row, RunRepr};

/// Thresholds on `chamfer_rel` the summary reports.
pub const THRESHOLDS: [f64; 3] = [1e-2, 3e-3, 1e-3];

/// A run named in the summary.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Pick {
    /// `repr/method`.
    pub run: String,
    /// Resolution, if the run has one.
    pub resolution: Option<u32>,
    /// Median frame time, ms.
    pub frame_ms_median: f64,
    /// Total bytes.
    pub total_bytes: u64,
    /// Relative Chamfer distance.
    pub chamfer_rel: f64,
}

/// The answer at one error threshold.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct AtThreshold {
    /// Largest `chamfer_rel` accepted.
    pub max_chamfer_rel: f64,
    /// The fastest run within it.
    pub fastest: Option<Pick>,
    /// The smallest run within it.
    pub smallest: Option<Pick>,
    /// The fastest ray-marched run (`sdf` or `grid`) within it.
    pub best_marched: Option<Pick>,
    /// The fastest mesh run within it.
    pub best_mesh: Option<Pick>,
    /// `best_marched` frame time over `best_mesh` frame time (< 1: marching is faster).
    pub marched_over_mesh_time: Option<f64>,
    /// Bytes of the smallest marched run over the smallest mesh run within the threshold.
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
    /// Per threshold.
    pub thresholds: Vec<AtThreshold>,
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
    Pick {
        run: format!("{}/{}", r.repr, r.method),
        resolution: r.resolution,
        frame_ms_median: r.frame_ms_median,
        total_bytes: r.total_bytes,
        chamfer_rel: r.chamfer_rel.unwrap_or(f64::NAN),
    }
}

fn min_by<'a>(rows: impl Iterator<Item = &'a Row>, key: impl Fn(&Row) -> f64) -> Option<&'a Row> {
    rows.min_by(|a, b| key(a).total_cmp(&key(b)))
}

fn is_marched(r: &Row) -> bool {
    r.repr == RunRepr::Sdf.as_str() || r.repr == RunRepr::Grid.as_str()
}

/// Summarises rows (any order; several inputs).
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
            let rows = &by_input[name];
            let thresholds = THRESHOLDS
                .iter()
                .map(|&t| {
                    let ok = || rows.iter().copied().filter(move |r| r.chamfer_rel.is_some_and(|c| c <= t));
                    let time = |r: &Row| r.frame_ms_median;
                    let bytes = |r: &Row| r.total_bytes as f64;
                    let fastest = min_by(ok(), time);
                    let smallest = min_by(ok(), bytes);
                    let best_marched = min_by(ok().filter(|r| is_marched(r)), time);
                    let best_mesh = min_by(ok().filter(|r| r.repr == RunRepr::Mesh.as_str()), time);
                    let small_marched = min_by(ok().filter(|r| is_marched(r)), bytes);
                    let small_mesh = min_by(ok().filter(|r| r.repr == RunRepr::Mesh.as_str()), bytes);
                    AtThreshold {
                        max_chamfer_rel: t,
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
                thresholds,
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
            format!("{}{res} ({:.1} ms, {} bytes)", p.run, p.frame_ms_median, p.total_bytes)
        }
        None => "none".into(),
    }
}

/// The summary as text for the terminal.
pub fn to_text(s: &Summary) -> String {
    let mut t = String::new();
    for i in &s.inputs {
        let _ = writeln!(t, "{} (reference {}):", i.input, i.reference);
        for th in &i.thresholds {
            let _ = writeln!(
                t,
                "  chamfer_rel <= {:.0e}: fastest {}; smallest {}",
                th.max_chamfer_rel,
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
