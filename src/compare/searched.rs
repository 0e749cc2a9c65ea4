//! `compare --search` of one input ([`search_input`]): the knob families of an input
//! ([`families`]: each grid and mesh resolution, the decimation fraction, the hit tolerance per
//! relaxation), each searched to the quality levels by [`super::search::search`], every
//! candidate run and written as an ordinary row ([`run_one`]), then the raster twins of the
//! chosen runs. The search logic itself is in [`super::search`]; this is compare's side of it.

use super::*;
/// One knob family of `--search` ([`search`]): how a run is made from the knob, how the
/// knob is searched, and whether the family's chosen runs get a raster twin.
pub(super) struct Family {
    /// `repr/method` (`sdf/sphere-trace@relax1.6` for a relaxation's tolerance search).
    name: String,
    spec: search::Spec,
    /// Whether each level's chosen run is run again with rasterized primary visibility
    /// (the families whose runs have a raster twin in the fixed plan).
    twin: bool,
    /// The run of a knob (also how `--duel` finds a searched label's run).
    pub(super) make: Box<dyn Fn(u32) -> Run>,
}

/// The coarsest hit tolerance of `--search`'s SDF families, pixels: knob `k` is
/// `SEARCH_TOLERANCE_PX / k`, halved from here.
pub(super) const SEARCH_TOLERANCE_PX: f64 = 2.0;

/// The finest hit tolerance `--search` tries: [`SEARCH_TOLERANCE_PX`] / this (1/16 px,
/// still coarser than [`REFERENCE_TOLERANCE_PX`]).
const SEARCH_TOLERANCE_STEPS: u32 = 32;

/// The first resolution of `--search`'s resolution families.
pub const SEARCH_START_RES: u32 = 8;

/// Decimation fractions are searched in basis points (1/10000 of the triangles): from 1%
/// up to 50% (the original is the 100% candidate, a run of its own).
const DECIMATE_START_BP: u32 = 100;
const DECIMATE_CAP_BP: u32 = 5000;

/// The knob families of an input for `--search` (see [`plan`] for the runs they make; the
/// same families as its fixed lists, with the knob searched instead).
pub(super) fn families(scene: &Scene, opts: &CompareOptions, max_res: u32) -> Vec<Family> {
    let march = opts.march;
    let band = GridStorage::Band { cells: opts.band_cells };
    let res = |cap: u32| search::Spec { start: SEARCH_START_RES, cap, bisect: true, min_gap: 4 };
    let trace = |repr, method, resolution, build| Run {
        primary: PrimaryVisibility::Trace,
        repr,
        method,
        resolution,
        build,
    };
    let grid = |method: &'static str, fill, storage| Family {
        name: format!("grid/{method}"),
        spec: res(max_res),
        twin: false,
        make: Box::new(move |r| {
            trace(
                ReprKind::Grid,
                method,
                Some(r),
                RunGeometry::Scene(Representation::Grid { resolution: r, fill, storage, march }),
            )
        }),
    };
    let mut out = Vec::new();
    if mesh_input(scene).is_some() {
        out.push(grid("sample", GridFill::Sample, GridStorage::Dense));
        out.push(grid("voxelize", GridFill::Voxelize, GridStorage::Dense));
        out.push(grid("sample-band", GridFill::Sample, band));
        for (method, fill) in [("from-sample", GridFill::Sample), ("from-voxelize", GridFill::Voxelize)] {
            out.push(Family {
                name: format!("mesh/{method}"),
                spec: res(max_res),
                twin: false,
                make: Box::new(move |r| {
                    trace(ReprKind::Mesh, method, Some(r), RunGeometry::Reextract { fill, resolution: r })
                }),
            });
        }
        if !opts.decimate.is_empty() {
            out.push(Family {
                name: "mesh/decimated".into(),
                spec: search::Spec {
                    start: DECIMATE_START_BP,
                    cap: DECIMATE_CAP_BP,
                    bisect: true,
                    min_gap: 1,
                },
                twin: true,
                make: Box::new(move |bp| {
                    let target = DecimateTarget::Ratio(f64::from(bp) / 1e4);
                    trace(ReprKind::Mesh, "decimated", None, RunGeometry::Decimate { target })
                }),
            });
        }
    } else {
        for &relaxation in &opts.sdf_relaxations {
            out.push(Family {
                name: format!("sdf/sphere-trace@relax{relaxation}"),
                spec: search::Spec { start: 1, cap: SEARCH_TOLERANCE_STEPS, bisect: false, min_gap: 1 },
                twin: false,
                make: Box::new(move |k| {
                    let tolerance_px = SEARCH_TOLERANCE_PX / f64::from(k);
                    trace(
                        ReprKind::Sdf,
                        "sphere-trace",
                        None,
                        RunGeometry::Scene(Representation::Sdf {
                            march: MarchParams { tolerance_px, relaxation, ..march },
                        }),
                    )
                }),
            });
        }
        // Extraction stops at MAX_EXTRACT_RESOLUTION: a larger knob would repeat its run.
        let extract_cap = max_res.min(crate::plan::MAX_EXTRACT_RESOLUTION);
        for (method, mesh_method, cap) in [
            ("parametric", MeshMethod::Parametric, max_res),
            ("extracted", MeshMethod::Extracted(ExtractMethod::MarchingCubes), extract_cap),
        ] {
            out.push(Family {
                name: format!("mesh/{method}"),
                spec: res(cap),
                twin: true,
                make: Box::new(move |r| {
                    trace(
                        ReprKind::Mesh,
                        method,
                        Some(r),
                        RunGeometry::Scene(Representation::Mesh {
                            resolution: sweep_mesh_resolution(r),
                            shading: Shading::Smooth,
                            method: mesh_method,
                            plane: MeshPlane::ClosedForm,
                            march,
                        }),
                    )
                }),
            });
        }
        out.push(grid("dense", GridFill::Sample, GridStorage::Dense));
        out.push(grid("band", GridFill::Sample, band));
        if scene.objects.len() > 1 {
            out.push(grid("scene-band", GridFill::Sample, GridStorage::Scene { cells: opts.band_cells }));
        }
    }
    out
}

/// Where `compare` puts its rows: the locked CSV, the rows so far (those of an earlier run
/// with `--resume` first) and the keys finished before this run.
pub(super) struct Sink<'a> {
    pub(super) file: &'a mut File,
    pub(super) rows: &'a mut Vec<Row>,
    pub(super) done: &'a HashSet<RowKey>,
    pub(super) opts: &'a CompareOptions,
    pub(super) commit: &'a str,
}

/// What became of one run of [`run_one`].
enum Ran {
    /// Measured (or finished in an earlier run, with `--resume`): its row.
    Row(Box<Row>),
    /// Skipped with a message (over the memory budget, a build error).
    Skipped,
    /// A panic (a bug), or the reference failed: the input fails.
    Failed,
}

/// Runs `run` of input `input` (name, class), appending its row with
/// `note(`[`counted_quality`]`)` added to its note, unless the CSV has it already (`--resume`: that row is answered).
fn run_one(
    sink: &mut Sink<'_>,
    input: (&str, &str),
    scene: &Scene,
    run: &Run,
    reference: &mut Option<Reference>,
    note: &dyn Fn(Option<f64>) -> String,
) -> Result<Ran> {
    let (opts, commit) = (sink.opts, sink.commit);
    let name = input.0;
    let key = RowKey {
        input: name.to_string(),
        replicate: opts.replicate,
        repr: run.repr.to_string(),
        method: run.method(),
        resolution: run.resolution,
        knob: run.knob().map(|(t, r)| (t.to_bits(), r.to_bits())),
    };
    let is_reference = reference.is_none();
    if !is_reference && key.is_done(sink.done) {
        let stripped = RowKey { knob: None, ..key.clone() };
        if let Some(row) = sink.rows.iter().find(|r| r.key() == key || r.key() == stripped) {
            return Ok(Ran::Row(Box::new(row.clone())));
        }
    }
    let measured = catch_panic(|| measure(input, scene, run, opts, commit, reference));
    let mut row = match measured {
        Ok(Ok(row)) => row,
        Ok(Err(e)) | Err(e) if is_reference => {
            eprintln!("error: {name}: {}/{} (the reference): {e}", run.repr, run.method());
            return Ok(Ran::Failed);
        }
        Err(e) => {
            eprintln!("error: {name}: {}/{}: {e}", run.repr, run.method());
            return Ok(Ran::Failed);
        }
        Ok(Err(e)) => {
            eprintln!("{name}: {}/{} skipped: {e}", run.repr, run.method());
            return Ok(Ran::Skipped);
        }
    };
    let extra = note(counted_quality(&row));
    if !extra.is_empty() {
        row.note = if row.note.is_empty() { extra } else { format!("{}; {extra}", row.note) };
    }
    if !key.is_done(sink.done) {
        write_row(sink.file, &opts.csv, &row)?;
        sink.rows.push(row.clone());
    }
    Ok(Ran::Row(Box::new(row)))
}

/// The quality a search counts for `row`: its `quality_px` where the run counts for the side
/// it was asked on; `None` for a run traced in whole or in part by another representation
/// (an empty extraction sphere traced), which meets no level of its family, so the search
/// goes on to finer knobs. Also what a candidate's `note` is written from.
fn counted_quality(row: &Row) -> Option<f64> {
    summary::side(row).and(row.quality_px)
}

/// The quality levels, coarsest first (the order [`search::search`] goes through them).
fn levels_coarse_first() -> Vec<f64> {
    metrics::QUALITY_LEVELS.iter().rev().map(|l| l.px).collect()
}

/// `compare --search` of one input: the reference and the original mesh's runs (the
/// fixed runs without a knob), then each knob family searched ([`families`]), then the raster
/// twins of the chosen runs. Returns the line that counts its runs, or `None` when the input
/// failed (its reference, or a panic).
pub(super) fn search_input(
    sink: &mut Sink<'_>,
    input: (&str, &str),
    scene: &Scene,
    max_res: u32,
) -> Result<Option<String>> {
    let opts = sink.opts;
    let mut reference = None;
    let none = |_: Option<f64>| String::new();
    // The fixed runs: the reference, and for a mesh input the original's raster twin.
    let fixed: Vec<Run> = plan(scene, opts)
        .into_iter()
        .filter(|r| {
            r.resolution.is_none() && matches!(r.build, RunGeometry::Scene(Representation::Analytic { .. }))
        })
        .collect();
    let mut counts: Vec<(String, usize)> = Vec::new();
    let mut failed = false;
    for run in &fixed {
        if let Ran::Failed = run_one(sink, input, scene, run, &mut reference, &none)? {
            if reference.is_none() {
                return Ok(None);
            }
            failed = true;
        }
    }
    let (mut sdf_side, mut mesh_side, mut raster_side) = (0usize, 0usize, 0usize);
    let mut unmet: Vec<String> = Vec::new();
    let levels = levels_coarse_first();
    for family in families(scene, opts, max_res) {
        let fits = |k: u32| check_budget(scene, (family.make)(k).build, &opts.budget).is_ok();
        let mut failed_here = false;
        let outcome = search::search(family.spec, &levels, fits, |probe| {
            let run = (family.make)(probe.knob);
            let note = |q: Option<f64>| probe.note(q);
            match run_one(sink, input, scene, &run, &mut reference, &note) {
                Ok(Ran::Row(row)) => counted_quality(&row),
                Ok(Ran::Skipped) => None,
                Ok(Ran::Failed) | Err(_) => {
                    failed_here = true;
                    None
                }
            }
        });
        failed |= failed_here;
        let n = outcome.tried.len();
        match family.name.split('/').next() {
            Some("mesh") => mesh_side += n,
            _ => sdf_side += n,
        }
        counts.push((family.name.clone(), n));
        for (level, found) in &outcome.levels {
            if let search::Found::Unmet { stop, largest } = found {
                let largest = match largest {
                    None => "none fits".to_string(),
                    // The SDF families' knob is the inverse of the hit tolerance.
                    Some(k) if family.name.starts_with("sdf/") => {
                        format!("finest tolerance tried {} px", SEARCH_TOLERANCE_PX / f64::from(*k))
                    }
                    Some(k) => format!("largest tried {k}"),
                };
                unmet.push(format!("{} {level} px: {stop} ({largest})", family.name));
            }
        }
        if family.twin {
            // One raster twin per distinct chosen knob, noting the levels it was chosen for.
            let mut chosen: Vec<(u32, Vec<f64>)> = Vec::new();
            for (level, found) in &outcome.levels {
                if let search::Found::Met(k) = found {
                    match chosen.iter_mut().find(|(c, _)| c == k) {
                        Some((_, ls)) => ls.push(*level),
                        None => chosen.push((*k, vec![*level])),
                    }
                }
            }
            for (k, ls) in chosen {
                let run = Run { primary: PrimaryVisibility::Raster, ..(family.make)(k) };
                let ls: Vec<String> = ls.iter().map(|l| format!("{l}px")).collect();
                let text = format!("search=twin level={}", ls.join(","));
                let note = |_: Option<f64>| text.clone();
                match run_one(sink, input, scene, &run, &mut reference, &note)? {
                    Ran::Failed => failed = true,
                    Ran::Row(_) => raster_side += 1,
                    Ran::Skipped => {}
                }
            }
        }
    }
    if failed {
        return Ok(None);
    }
    let families: Vec<String> = counts.iter().map(|(f, n)| format!("{f} {n}")).collect();
    let mut line = format!(
        "search: {}: {} candidates searched (sdf side {sdf_side}, mesh side {mesh_side}; {}), \
         {raster_side} raster twins, {} fixed runs",
        input.0,
        sdf_side + mesh_side,
        families.join(", "),
        fixed.len()
    );
    if !unmet.is_empty() {
        line += &format!("; unmet: {}", unmet.join("; "));
    }
    Ok(Some(line))
}
