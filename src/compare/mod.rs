//! `toolkit compare`: renders each input in every representation across a resolution
//! sweep under one camera, lights, materials, image size and depth, and writes one CSV row
//! per run (schema [`COLUMNS`], version [`SCHEMA_VERSION`], documented in the README): image
//! and geometric error against the input's reference, frame time (median of K frames after
//! a warm-up frame, build time separate), bytes, rays per second, steps and nodes per ray.
//!
//! Rows are appended and flushed as each run finishes, so an interrupted run keeps every
//! finished row and `--resume` skips them. [`summary`] answers, per input and error
//! threshold, which representation is fastest and which is smallest; [`scaling`] is the
//! coursework's frame time against primitive count experiment.

pub mod hard;
pub mod scaling;
pub mod summary;

use std::collections::HashSet;
use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use image::RgbImage;
use serde::{Deserialize, Serialize};

use crate::cli::commands::{Overrides, check_repr, load_scene_or_mesh};
use crate::convert::extract::{ExtractMethod, Field, extract};
use crate::convert::mesh_to_grid::sample_mesh;
use crate::error::{Error, Result};
use crate::geometry::grid::SdfGrid;
use crate::geometry::march::MarchParams;
use crate::geometry::scene::SceneGeometry;
use crate::geometry::{Geometry, aabb};
use crate::mesh::{TriangleMesh, save_mesh};
use crate::metrics::{self, Probe};
use crate::plan::budget::{MemoryBudget, extraction_bytes, mesh_to_grid_bytes, scene_bytes};
use crate::plan::{GridFill, GridStorage, MeshMethod, Representation, build_scene};
use crate::render::{Frame, render, write_png};
use crate::scene::Scene;
use crate::scene::shape::{ObjectKind, Shading};

/// Version of the CSV schema; bumped whenever a column changes meaning or order.
pub const SCHEMA_VERSION: u32 = 1;

/// The CSV columns, in order (units in the names; see the README).
pub const COLUMNS: [&str; 34] = [
    "input",
    "repr",
    "method",
    "resolution",
    "reference",
    "triangles",
    "grid_cells_stored",
    "geometry_bytes",
    "accel_bytes",
    "total_bytes",
    "build_ms",
    "frame_ms_median",
    "frame_ms_min",
    "frame_ms_max",
    "frames",
    "mrays_per_s",
    "steps_per_ray",
    "nodes_per_ray",
    "image_rmse",
    "image_psnr_db",
    "image_ssim",
    "hit_mismatch_pct",
    "chamfer_rel",
    "hausdorff_rel",
    "peak_rss_bytes",
    "threads",
    "width",
    "height",
    "depth",
    "commit",
    "timestamp",
    "frame_ms_samples",
    "schema_version",
    "note",
];

/// One CSV row. Field order is [`COLUMNS`]; `None` is an empty cell (not applicable).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Row {
    /// Input name: the scene or mesh file's stem.
    pub input: String,
    /// `analytic`, `sdf`, `mesh` or `grid`.
    pub repr: String,
    /// How the representation was made (see the README's schema).
    pub method: String,
    /// Cells along the longest axis (grids, extraction) or segments (parametric meshes).
    pub resolution: Option<u32>,
    /// `repr/method` of the reference row.
    pub reference: String,
    /// Triangles stored.
    pub triangles: u64,
    /// Grid samples stored.
    pub grid_cells_stored: u64,
    /// Bytes of geometry (vertices, triangles, grid samples, SDF trees), excluding `accel_bytes`.
    pub geometry_bytes: u64,
    /// Bytes of acceleration structures (BVHs).
    pub accel_bytes: u64,
    /// `geometry_bytes + accel_bytes`.
    pub total_bytes: u64,
    /// Wall-clock time to build the representation (conversion, BVH), ms.
    pub build_ms: f64,
    /// Median frame time, ms.
    pub frame_ms_median: f64,
    /// Fastest frame, ms.
    pub frame_ms_min: f64,
    /// Slowest frame, ms.
    pub frame_ms_max: f64,
    /// Timed frames (after one warm-up frame).
    pub frames: u32,
    /// Rays of all kinds per second at the median frame time, millions.
    pub mrays_per_s: f64,
    /// Distance evaluations per ray (all rays).
    pub steps_per_ray: f64,
    /// BVH nodes visited per ray (all rays).
    pub nodes_per_ray: f64,
    /// RMSE against the reference image, [0, 1] scale.
    pub image_rmse: f64,
    /// PSNR against the reference image, dB (`inf` when identical).
    pub image_psnr_db: f64,
    /// SSIM against the reference image.
    pub image_ssim: f64,
    /// Pixels where exactly one of this run and the reference hits a surface, percent.
    pub hit_mismatch_pct: f64,
    /// Chamfer distance to the reference surface over the bounding-box diagonal of what the
    /// camera sees of it; empty when nothing is visible.
    pub chamfer_rel: Option<f64>,
    /// Hausdorff distance likewise.
    pub hausdorff_rel: Option<f64>,
    /// Peak resident memory of the process during this run (build and frames), bytes;
    /// empty where the OS does not say.
    pub peak_rss_bytes: Option<u64>,
    /// Rendering threads.
    pub threads: usize,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Recursion depth.
    pub depth: u32,
    /// Commit of the toolkit (`-dirty` with uncommitted changes).
    pub commit: String,
    /// When the run finished, RFC 3339 UTC.
    pub timestamp: String,
    /// Every timed frame, ms, space-separated.
    pub frame_ms_samples: String,
    /// [`SCHEMA_VERSION`].
    pub schema_version: u32,
    /// What was not represented as asked (e.g. unbounded objects sphere traced), or empty.
    pub note: String,
}

impl Row {
    /// The key that `--resume` matches rows by.
    pub fn key(&self) -> RowKey {
        (self.input.clone(), self.repr.clone(), self.method.clone(), self.resolution)
    }
}

/// What identifies a run: input, repr, method, resolution.
pub type RowKey = (String, String, String, Option<u32>);

/// Options of `toolkit compare`.
#[derive(Clone, Debug)]
pub struct CompareOptions {
    /// Scene files and mesh files.
    pub inputs: Vec<PathBuf>,
    /// Output CSV.
    pub csv: PathBuf,
    /// Resolution sweep.
    pub resolutions: Vec<u32>,
    /// Timed frames per run (after one warm-up frame), `>= 1`.
    pub frames: u32,
    /// Skip runs already in the CSV.
    pub resume: bool,
    /// Replace an existing CSV.
    pub overwrite: bool,
    /// Image size and depth overrides (the same for every run of an input).
    pub overrides: Overrides,
    /// Sphere tracing parameters.
    pub march: MarchParams,
    /// Half-width of narrow-band grids, cells.
    pub band_cells: u32,
    /// Also write the summary as JSON here.
    pub summary_json: Option<PathBuf>,
    /// Write renders, meshes and grids of the runs here.
    pub artifacts: Option<PathBuf>,
    /// Largest number of surface samples per side for Chamfer and Hausdorff distances.
    pub surface_samples: usize,
    /// Show a progress bar on stderr.
    pub progress: bool,
    /// Runs whose estimated memory exceeds this are skipped with a message.
    pub budget: MemoryBudget,
}

/// The default inputs: every scene in `data/scenes` (sorted) and the Stanford bunny from
/// `../shared/meshes` where it exists, relative to the working directory.
///
/// # Errors
/// When `data/scenes` cannot be read.
pub fn default_inputs() -> Result<Vec<PathBuf>> {
    let dir = Path::new("data/scenes");
    let mut inputs: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, format!("{e} (run from the repository root or name the inputs)")))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    inputs.sort();
    let bunny = Path::new("../shared/meshes/stanford-bunny.obj");
    if bunny.exists() {
        inputs.push(bunny.to_path_buf());
    }
    Ok(inputs)
}

/// The default resolution sweep.
pub const DEFAULT_RESOLUTIONS: [u32; 6] = [8, 16, 32, 64, 128, 256];

/// Largest resolution written as a mesh or grid artifact.
const ARTIFACT_MAX_RES: u32 = 64;

/// How one run's geometry is made.
#[derive(Clone, Copy, Debug)]
enum Build {
    /// `build_scene` in a representation.
    Scene(Representation),
    /// The input mesh sampled or voxelized into a grid at a resolution and re-extracted
    /// with marching cubes.
    Reextract { fill: GridFill, resolution: u32 },
}

/// One planned run.
#[derive(Clone, Debug)]
struct Run {
    repr: &'static str,
    method: &'static str,
    resolution: Option<u32>,
    build: Build,
}

fn mesh_input(scene: &Scene) -> Option<&Arc<TriangleMesh>> {
    match scene.objects.as_slice() {
        [o] => match &o.kind {
            ObjectKind::Mesh { mesh, .. } => Some(mesh),
            _ => None,
        },
        _ => None,
    }
}

/// The runs for one input: the reference first.
fn plan(scene: &Scene, opts: &CompareOptions) -> Vec<Run> {
    let march = opts.march;
    let band = GridStorage::Band { cells: opts.band_cells };
    let grid =
        |resolution, fill, storage| Build::Scene(Representation::Grid { resolution, fill, storage, march });
    let mut runs = Vec::new();
    if mesh_input(scene).is_some() {
        runs.push(Run {
            repr: "mesh",
            method: "original",
            resolution: None,
            build: Build::Scene(Representation::Analytic { march }),
        });
        for &r in &opts.resolutions {
            let res = Some(r);
            runs.push(Run {
                repr: "grid",
                method: "sample",
                resolution: res,
                build: grid(r, GridFill::Sample, GridStorage::Dense),
            });
            runs.push(Run {
                repr: "grid",
                method: "voxelize",
                resolution: res,
                build: grid(r, GridFill::Voxelize, GridStorage::Dense),
            });
            runs.push(Run {
                repr: "grid",
                method: "sample-band",
                resolution: res,
                build: grid(r, GridFill::Sample, band),
            });
            runs.push(Run {
                repr: "mesh",
                method: "from-sample",
                resolution: res,
                build: Build::Reextract { fill: GridFill::Sample, resolution: r },
            });
            runs.push(Run {
                repr: "mesh",
                method: "from-voxelize",
                resolution: res,
                build: Build::Reextract { fill: GridFill::Voxelize, resolution: r },
            });
        }
    } else {
        runs.push(Run {
            repr: "analytic",
            method: "closed-form",
            resolution: None,
            build: Build::Scene(Representation::Analytic { march }),
        });
        runs.push(Run {
            repr: "sdf",
            method: "sphere-trace",
            resolution: None,
            build: Build::Scene(Representation::Sdf { march }),
        });
        for &r in &opts.resolutions {
            let res = Some(r);
            let mesh = |method| {
                Build::Scene(Representation::Mesh {
                    resolution: r.max(3),
                    shading: Shading::Smooth,
                    method,
                    march,
                })
            };
            runs.push(Run {
                repr: "mesh",
                method: "parametric",
                resolution: res,
                build: mesh(MeshMethod::Parametric),
            });
            runs.push(Run {
                repr: "mesh",
                method: "extracted",
                resolution: res,
                build: mesh(MeshMethod::Extracted(ExtractMethod::MarchingCubes)),
            });
            runs.push(Run {
                repr: "grid",
                method: "dense",
                resolution: res,
                build: grid(r, GridFill::Sample, GridStorage::Dense),
            });
            runs.push(Run {
                repr: "grid",
                method: "band",
                resolution: res,
                build: grid(r, GridFill::Sample, band),
            });
        }
    }
    runs
}

/// A built run: its geometry, build time and, for meshes and grids, what to save as
/// artifacts.
struct Built {
    geometry: SceneGeometry,
    build_ms: f64,
    mesh: Option<TriangleMesh>,
    grid: Option<SdfGrid>,
}

fn build(scene: &Scene, b: Build, budget: &MemoryBudget) -> Result<Built> {
    let need = match b {
        Build::Scene(repr) => scene_bytes(scene, repr),
        Build::Reextract { fill, resolution } => {
            let dims = glam::UVec3::splat(resolution + 1 + 2 * crate::plan::GRID_MARGIN_CELLS);
            let triangles = mesh_input(scene).map_or(0, |m| m.triangles.len());
            mesh_to_grid_bytes(triangles, dims, fill)
                .saturating_add(extraction_bytes(resolution, ExtractMethod::MarchingCubes))
        }
    };
    budget.check("this run", need)?;
    let start = Instant::now();
    match b {
        Build::Scene(repr) => {
            let geometry = build_scene(scene, repr);
            Ok(Built { geometry, build_ms: ms(start), mesh: None, grid: None })
        }
        Build::Reextract { fill, resolution } => {
            let original = mesh_input(scene).ok_or_else(|| Error::Usage("not a mesh input".into()))?;
            let grid = match fill {
                GridFill::Sample => sample_mesh(original, resolution, crate::plan::GRID_MARGIN_CELLS)?,
                GridFill::Voxelize => crate::convert::mesh_to_grid::voxelize::voxelize_mesh(
                    original,
                    resolution,
                    crate::plan::GRID_MARGIN_CELLS,
                )?,
            };
            let (lo, hi) = grid.bounds();
            let cells = (grid.dims - 1).max_element();
            let mesh = extract(
                &|p: DVec3| grid.trilinear(p.as_vec3()) as f64,
                Field::Arbitrary,
                &aabb(lo, hi),
                cells,
                ExtractMethod::MarchingCubes,
            );
            let mut s = scene.clone();
            s.objects[0].kind = ObjectKind::Mesh {
                mesh: Arc::new(mesh.clone()),
                source: PathBuf::from("re-extracted"),
                shading: Shading::Smooth,
            };
            let geometry = build_scene(&s, Representation::Analytic { march: MarchParams::default() });
            Ok(Built { geometry, build_ms: ms(start), mesh: Some(mesh), grid: Some(grid) })
        }
    }
}

fn ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

/// The timing columns shared by the compare and scaling CSVs.
pub(crate) struct Timing {
    /// Median frame time, ms.
    pub median: f64,
    /// Fastest frame, ms.
    pub min: f64,
    /// Slowest frame, ms.
    pub max: f64,
    /// Rays per second at the median, millions.
    pub mrays_per_s: f64,
    /// Distance evaluations per ray.
    pub steps_per_ray: f64,
    /// BVH nodes per ray.
    pub nodes_per_ray: f64,
    /// Every timed frame, ms, space-separated.
    pub samples: String,
    /// When the frames finished, RFC 3339 UTC.
    pub timestamp: String,
}

/// Renders one warm-up frame and `frames` timed ones; returns their timing and the last
/// frame (work counts are the same in every frame).
pub(crate) fn time_frames(scene: &Scene, geometry: &dyn Geometry, frames: u32) -> (Timing, Frame) {
    let mut last = render(scene, geometry);
    let mut times = Vec::with_capacity(frames as usize);
    for _ in 0..frames {
        last = render(scene, geometry);
        times.push(last.time.as_secs_f64() * 1e3);
    }
    let median = metrics::median(&times);
    let timing = Timing {
        median,
        min: times.iter().copied().fold(f64::INFINITY, f64::min),
        max: times.iter().copied().fold(0.0, f64::max),
        mrays_per_s: last.stats.rays as f64 / (median * 1e-3) / 1e6,
        steps_per_ray: last.steps_per_ray(),
        nodes_per_ray: last.nodes_per_ray(),
        samples: times.iter().map(|t| format!("{t:.3}")).collect::<Vec<_>>().join(" "),
        timestamp: humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string(),
    };
    (timing, last)
}

/// What the reference run leaves for the others to be measured against.
struct Reference {
    name: String,
    image: RgbImage,
    probe: Probe,
    points: Vec<DVec3>,
    geometry: SceneGeometry,
}

/// Resets the kernel's peak-RSS counter of this process (Linux), so the next reading is
/// the peak of what follows. Silently does nothing elsewhere.
fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// Peak resident set size of this process, bytes (Linux `VmHWM`).
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The toolkit's commit, from git where available (`unknown` otherwise).
pub fn commit_id() -> String {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .current_dir(dir)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(c) if !c.is_empty() => {
            let dirty =
                git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
            if dirty { format!("{c}-dirty") } else { c }
        }
        _ => "unknown".into(),
    }
}

/// Reads the rows of an existing CSV, checking its header against [`COLUMNS`].
///
/// # Errors
/// [`Error::Input`] naming the file and line when the header or a row does not match.
pub fn read_rows(path: &Path) -> Result<Vec<Row>> {
    let mut reader = csv::Reader::from_path(path).map_err(|e| Error::io(path, e))?;
    let header = reader.headers().map_err(|e| Error::input(path, None, e))?.clone();
    if header.iter().ne(COLUMNS.iter().copied()) {
        return Err(Error::input(
            path,
            Some(crate::error::Location { line: 1, column: 1 }),
            format!("the header is not compare schema version {SCHEMA_VERSION}; write a new file"),
        ));
    }
    let mut rows = Vec::new();
    for (i, r) in reader.deserialize::<Row>().enumerate() {
        match r {
            Ok(row) => rows.push(row),
            Err(e) => {
                // A row cut off by a crash is the only one that can be incomplete: the last.
                let line = i + 2;
                return Err(Error::input(path, Some(crate::error::Location { line, column: 1 }), e));
            }
        }
    }
    Ok(rows)
}

/// Opens the CSV for appending rows: new (header written) or, with `resume`, existing
/// (header checked). Returns the rows already there.
fn open_csv(opts: &CompareOptions) -> Result<(File, Vec<Row>)> {
    let path = &opts.csv;
    let exists = path.exists() && std::fs::metadata(path).map(|m| m.len() > 0).unwrap_or(false);
    if exists && opts.resume {
        drop_partial_row(path)?;
        let rows = read_rows(path)?;
        let file = OpenOptions::new().append(true).open(path).map_err(|e| Error::io(path, e))?;
        return Ok((file, rows));
    }
    if exists && !opts.overwrite {
        return Err(Error::io(
            path,
            "already exists; pass --resume to continue it or --overwrite to replace it",
        ));
    }
    let mut file = File::create(path).map_err(|e| Error::io(path, format!("cannot write: {e}")))?;
    writeln!(file, "{}", COLUMNS.join(",")).map_err(|e| Error::io(path, e))?;
    file.flush().map_err(|e| Error::io(path, e))?;
    Ok((file, Vec::new()))
}

/// Cuts a last line left incomplete by a crash (no final newline) off the file.
fn drop_partial_row(path: &Path) -> Result<()> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    if bytes.last().is_none_or(|&b| b == b'\n') {
        return Ok(());
    }
    let keep = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    let f = OpenOptions::new().write(true).open(path).map_err(|e| Error::io(path, e))?;
    f.set_len(keep as u64).map_err(|e| Error::io(path, e))?;
    eprintln!("{}: dropped an incomplete last row", path.display());
    Ok(())
}

fn write_row(file: &mut File, path: &Path, row: &Row) -> Result<()> {
    let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(Vec::new());
    w.serialize(row).map_err(|e| Error::io(path, e))?;
    let bytes = w.into_inner().map_err(|e| Error::io(path, e))?;
    // One write per row, flushed and synced: a crash leaves whole rows only (or a last
    // partial row, which `--resume` reports).
    file.write_all(&bytes).and_then(|_| file.sync_data()).map_err(|e| Error::io(path, e))
}

fn stem(path: &Path) -> String {
    path.file_stem().map_or_else(|| "input".into(), |s| s.to_string_lossy().into_owned())
}

/// What the run did not represent as asked, from the objects' descriptions.
fn note(geometry: &SceneGeometry, repr: &str) -> String {
    if repr != "mesh" && repr != "grid" {
        return String::new();
    }
    let fallbacks: Vec<String> = geometry
        .objects()
        .iter()
        .map(|o| o.describe())
        .filter(|d| d.contains("sphere traced") || d.contains("found it open"))
        .collect();
    if fallbacks.is_empty() {
        String::new()
    } else {
        format!(
            "{} of {} objects not as asked: {}",
            fallbacks.len(),
            geometry.objects().len(),
            fallbacks.join("; ")
        )
    }
}

/// `toolkit compare`: runs every input in every representation and resolution, appending
/// rows to the CSV; returns the summary text.
///
/// # Errors
/// Unreadable inputs (checked before anything runs), an existing CSV without `--resume` or
/// `--overwrite`, unwritable outputs.
pub fn compare_command(opts: &CompareOptions) -> Result<String> {
    if opts.frames == 0 || opts.frames > 1000 {
        return Err(Error::Usage(format!("--frames must be between 1 and 1000, got {}", opts.frames)));
    }
    if opts.resolutions.is_empty() {
        return Err(Error::Usage("--res needs at least one resolution".into()));
    }
    for &r in &opts.resolutions {
        check_repr(&Representation::Grid {
            resolution: r,
            fill: GridFill::Sample,
            storage: GridStorage::Dense,
            march: opts.march,
        })?;
    }
    if opts.band_cells == 0 {
        return Err(Error::Usage("--band must be at least 1 cell".into()));
    }
    let mut opts = opts.clone();
    opts.resolutions.sort_unstable();
    opts.resolutions.dedup();
    let opts = &opts;
    // Load every input first: a bad file fails before any run.
    let mut inputs = Vec::new();
    for path in &opts.inputs {
        let mut scene = load_scene_or_mesh(path, Shading::Smooth)?;
        opts.overrides.apply(&mut scene)?;
        inputs.push((stem(path), scene));
    }
    if let Some(dir) = &opts.artifacts {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let (mut file, mut rows) = open_csv(opts)?;
    let done: HashSet<RowKey> = rows.iter().map(Row::key).collect();
    let plans: Vec<Vec<Run>> = inputs.iter().map(|(_, s)| plan(s, opts)).collect();
    let total: usize = plans.iter().map(Vec::len).sum();
    let bar = progress_bar(total as u64, opts.progress);
    let commit = commit_id();
    for ((name, scene), runs) in inputs.iter().zip(&plans) {
        let mut reference: Option<Reference> = None;
        for run in runs {
            let key = (name.clone(), run.repr.to_string(), run.method.to_string(), run.resolution);
            let is_reference = reference.is_none();
            bar.set_message(format!(
                "{name} {}/{} {}",
                run.repr,
                run.method,
                run.resolution.map_or(String::new(), |r| r.to_string())
            ));
            if done.contains(&key) && !is_reference {
                bar.inc(1);
                continue;
            }
            let row = match measure(name, scene, run, opts, &commit, &mut reference) {
                Ok(row) => row,
                // Without its reference an input cannot be measured at all.
                Err(e) if is_reference => return Err(e),
                Err(e) => {
                    bar.suspend(|| eprintln!("{name}: {}/{} skipped: {e}", run.repr, run.method));
                    bar.inc(1);
                    continue;
                }
            };
            if !done.contains(&key) {
                write_row(&mut file, &opts.csv, &row)?;
                rows.push(row);
            }
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    let summary = summary::summarize(&rows);
    if let Some(path) = &opts.summary_json {
        let json = serde_json::to_string_pretty(&summary).map_err(|e| Error::io(path, e))?;
        crate::mesh::write::atomic_write(path, json.as_bytes())?;
    }
    Ok(summary::to_text(&summary))
}

fn progress_bar(total: u64, show: bool) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !show || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(total);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} ETA {eta} {msg}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// Builds, times and measures one run (and keeps the reference's images and samples when
/// it is the first run of the input).
fn measure(
    name: &str,
    scene: &Scene,
    run: &Run,
    opts: &CompareOptions,
    commit: &str,
    reference: &mut Option<Reference>,
) -> Result<Row> {
    reset_peak_rss();
    let built = build(scene, run.build, &opts.budget)?;
    let (timing, frame) = time_frames(scene, &built.geometry, opts.frames);
    let peak = peak_rss_bytes();
    let probe = metrics::probe(&scene.camera, &built.geometry, scene.settings.max_distance);
    let points = metrics::subsample(&probe.points, opts.surface_samples);
    let label = format!("{}/{}", run.repr, run.method);
    let r = reference.get_or_insert_with(|| Reference {
        name: label.clone(),
        image: frame.image.clone(),
        probe: Probe { hits: probe.hits.clone(), points: Vec::new() },
        points: points.clone(),
        geometry: SceneGeometry::new(Vec::new()),
    });
    let is_reference = r.name == label && run.resolution.is_none();
    let (chamfer, hausdorff) = if is_reference {
        (Some(0.0), Some(0.0))
    } else {
        match metrics::surface_distance(&built.geometry, &points, &r.geometry, &r.points) {
            Some(d) => (Some(d.chamfer_rel()), Some(d.hausdorff_rel())),
            None => (None, None),
        }
    };
    let census = built.geometry.census();
    let total = built.geometry.bytes_used() as u64;
    let row = Row {
        input: name.to_string(),
        repr: run.repr.to_string(),
        method: run.method.to_string(),
        resolution: run.resolution,
        reference: r.name.clone(),
        triangles: census.triangles,
        grid_cells_stored: census.grid_samples,
        geometry_bytes: total - census.accel_bytes.min(total),
        accel_bytes: census.accel_bytes,
        total_bytes: total,
        build_ms: built.build_ms,
        frame_ms_median: timing.median,
        frame_ms_min: timing.min,
        frame_ms_max: timing.max,
        frames: opts.frames,
        mrays_per_s: timing.mrays_per_s,
        steps_per_ray: timing.steps_per_ray,
        nodes_per_ray: timing.nodes_per_ray,
        image_rmse: metrics::rmse(&frame.image, &r.image),
        image_psnr_db: metrics::psnr_db(&frame.image, &r.image),
        image_ssim: metrics::ssim(&frame.image, &r.image),
        hit_mismatch_pct: metrics::hit_mismatch_pct(&probe, &r.probe),
        chamfer_rel: chamfer,
        hausdorff_rel: hausdorff,
        peak_rss_bytes: peak,
        threads: rayon::current_num_threads(),
        width: scene.camera.width,
        height: scene.camera.height,
        depth: scene.settings.max_depth,
        commit: commit.to_string(),
        timestamp: timing.timestamp,
        frame_ms_samples: timing.samples,
        schema_version: SCHEMA_VERSION,
        note: note(&built.geometry, run.repr),
    };
    if let Some(dir) = &opts.artifacts {
        save_artifacts(&dir.join(name), run, scene, &built, &frame.image, is_reference)?;
    }
    if is_reference {
        r.geometry = built.geometry;
    }
    Ok(row)
}

fn save_artifacts(
    dir: &Path,
    run: &Run,
    scene: &Scene,
    built: &Built,
    image: &RgbImage,
    is_reference: bool,
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let base = match run.resolution {
        Some(r) => format!("{}-{}-{r}", run.repr, run.method),
        None => format!("{}-{}", run.repr, run.method),
    };
    write_png(image, &dir.join(format!("{base}.png")))?;
    if is_reference && let Some(mesh) = mesh_input(scene) {
        save_mesh(mesh, &dir.join("reference.ply"))?;
    }
    if run.resolution.is_some_and(|r| r <= ARTIFACT_MAX_RES) {
        let mesh = built.mesh.clone().or_else(|| {
            (run.repr == "mesh").then(|| crate::plan::scene_mesh(scene, run_repr(run))).flatten()
        });
        if let Some(mesh) = mesh.filter(|m| !m.triangles.is_empty()) {
            save_mesh(&mesh, &dir.join(format!("{base}.ply")))?;
        }
        if let Some(grid) = &built.grid {
            crate::geometry::grid::io::save_grid(
                grid,
                &dir.join(format!("{}-{}-grid-{}.vti", run.repr, run.method, run.resolution.unwrap_or(0))),
            )?;
        }
    }
    Ok(())
}

fn run_repr(run: &Run) -> Representation {
    match run.build {
        Build::Scene(r) => r,
        Build::Reextract { .. } => Representation::Analytic { march: MarchParams::default() },
    }
}
