//! `toolkit compare`: renders each input in every representation across a resolution
//! sweep (and sphere tracing across a sweep of hit tolerances and over-relaxation factors)
//! under one camera, lights, materials, image size and depth, and writes one CSV row per run
//! (schema [`COLUMNS`], version [`SCHEMA_VERSION`], documented in the README): image error
//! (RMSE, PSNR, SSIM, FLIP), silhouette mismatch, geometric error in pixels and relative to
//! the visible bounded objects, all against the input's reference, the quality level met
//! ([`crate::metrics::QUALITY_LEVELS`]), frame time (median of K frames after a warm-up
//! frame, build time separate), bytes, rays per second, steps and nodes per ray.
//!
//! Rows are appended and flushed as each run finishes, so an interrupted run keeps every
//! finished row and `--resume` skips them (matched by [`RowKey`]). [`summary`] answers, per
//! input and quality level, which representation is fastest and which is smallest;
//! [`scaling`] is the coursework's frame time against primitive count experiment.

pub mod duel;
pub mod hard;
pub mod refcheck;
pub mod scaling;
pub mod search;
mod searched;
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

use crate::base::heap;
use crate::config::{CompareOptions, sweep_mesh_resolution};
use crate::convert::extract::ExtractMethod;
use crate::error::{Error, Result, catch_panic};
use crate::geometry::Geometry;
use crate::geometry::grid::SdfGrid;
use crate::geometry::march::MarchParams;
use crate::geometry::scene::SceneGeometry;
use crate::mesh::simplify::{DecimateTarget, NO_ERROR_LIMIT, SCRATCH_FACTOR, decimate};
use crate::mesh::{TriangleMesh, save_mesh};
use crate::metrics::{self, Probe};
use crate::plan::budget::{MemoryBudget, reextract_bytes};
use crate::plan::{
    Build, Fallback, GridFill, GridStorage, MeshMethod, MeshPlane, ObjectPlan, ReprKind, Representation,
    build_scene_with_plans, reextract_mesh, traced_repr,
};
use crate::render::{Frame, PrimaryVisibility, render_with, write_png};
use crate::scene::shape::{MeshLayout, ObjectKind, Shading};
use crate::scene::{Scene, load_input, preparation};

/// Version of the CSV schema; bumped whenever a column changes meaning or order.
pub const SCHEMA_VERSION: u32 = 5;

/// The CSV columns, in order (units in the names; see the README).
pub const COLUMNS: [&str; 47] = [
    "input",
    "class",
    "replicate",
    "repr",
    "asked_repr",
    "method",
    "resolution",
    "tolerance_px",
    "relaxation",
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
    "flip_mean",
    "silhouette_mismatch_pct",
    "px_err_mean",
    "px_err_p95",
    "px_err_max",
    "quality_px",
    "chamfer_rel",
    "hausdorff_rel",
    "peak_rss_bytes",
    "peak_heap_bytes",
    "threads",
    "width",
    "height",
    "depth",
    "commit",
    "timestamp",
    "frame_ms_samples",
    "schema_version",
    "note",
    "primary_ms",
    "shading_ms",
];

/// One CSV row. Field order is [`COLUMNS`]; `None` is an empty cell (not applicable).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Row {
    /// Input name: the scene or mesh file's stem (unique among the inputs).
    pub input: String,
    /// Kind of input ([`input_class`]): the scene's folder under `data/scenes` (`scenes`
    /// for a scene directly in it), `scan` for a mesh file.
    pub class: String,
    /// Replicate number (`--replicate`): which repetition of the whole experiment.
    pub replicate: u32,
    /// What traced the run ([`crate::plan::TracedRepr::name`]): `analytic`, `sdf`, `mesh`
    /// or `grid` when one representation traced every object, else those that traced some
    /// joined by `+` (`sdf+mesh`). Equal to `asked_repr` unless an object fell back to
    /// another representation (see the README's column table).
    pub repr: String,
    /// The representation asked for: `analytic`, `sdf`, `mesh` or `grid`.
    pub asked_repr: String,
    /// How the representation was made (see the README's schema).
    pub method: String,
    /// Cells along the longest axis (grids, extraction) or segments (parametric meshes).
    pub resolution: Option<u32>,
    /// The largest hit tolerance of the run's sphere tracing, pixels
    /// ([`MarchParams::tolerance_px`]); empty when the run marches nothing.
    pub tolerance_px: Option<f64>,
    /// The over-relaxation factor of the run's sphere tracing ([`MarchParams::relaxation`],
    /// 1 = plain); empty when the run marches nothing.
    pub relaxation: Option<f64>,
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
    /// Mean FLIP error against the reference image ([`metrics::flip_mean`]), [0, 1].
    pub flip_mean: f64,
    /// Pixels where exactly one of this run and the reference hits a surface with the
    /// primary ray, percent of all pixels.
    pub silhouette_mismatch_pct: f64,
    /// Mean geometric error in pixels over the pixels both hit ([`metrics::pixel_error`]);
    /// empty when no pixel is hit by both.
    pub px_err_mean: Option<f64>,
    /// 95th percentile of the same, pixels.
    pub px_err_p95: Option<f64>,
    /// Largest of the same, pixels.
    pub px_err_max: Option<f64>,
    /// The finest quality level met ([`metrics::quality_px`]: 0.5, 1 or 2 pixels); empty
    /// when none is.
    pub quality_px: Option<f64>,
    /// Chamfer distance to the reference surface over the bounding-box diagonal of what the
    /// camera sees of the reference's bounded objects ([`metrics::bounded_diagonal`]); empty
    /// when no bounded object is visible.
    pub chamfer_rel: Option<f64>,
    /// Hausdorff distance likewise.
    pub hausdorff_rel: Option<f64>,
    /// Peak resident memory of the process during this run (build and frames), bytes;
    /// empty where the OS does not say.
    pub peak_rss_bytes: Option<u64>,
    /// The most heap this run held at once (build and frames) on top of what was live
    /// before it, bytes, counted by the toolkit's allocator ([`crate::base::heap`]); reset
    /// per run, unlike the kernel's peak RSS, which only resets where the kernel allows.
    /// Empty where no counting allocator is installed (the library used from elsewhere).
    pub peak_heap_bytes: Option<u64>,
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
    /// Of `frame_ms_median`, primary visibility (every pixel's primary hit: the primary
    /// rays traced or marched, or for a `raster` run the visibility buffer and the hit
    /// records made from it; [`crate::render::Frame::primary`]), ms: the median frame split
    /// in the proportion primary visibility took of all timed frames. Empty in rows of
    /// schema 4 and older.
    pub primary_ms: Option<f64>,
    /// `frame_ms_median - primary_ms`: shading (shadow, reflection and refraction rays), ms.
    pub shading_ms: Option<f64>,
}

impl Row {
    /// The key that `--resume` matches rows by (the asked representation: what was traced
    /// is known only once the run is built).
    pub fn key(&self) -> RowKey {
        RowKey {
            input: self.input.clone(),
            replicate: self.replicate,
            repr: self.asked_repr.clone(),
            method: self.method.clone(),
            resolution: self.resolution,
            knob: self.tolerance_px.zip(self.relaxation).map(|(t, r)| (t.to_bits(), r.to_bits())),
        }
    }
}

/// What identifies a run: input, replicate, asked repr, method, resolution and the march knob.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RowKey {
    /// Input name.
    pub input: String,
    /// Replicate number.
    pub replicate: u32,
    /// `asked_repr` column.
    pub repr: String,
    /// `method` column.
    pub method: String,
    /// `resolution` column.
    pub resolution: Option<u32>,
    /// Bits of `tolerance_px` and `relaxation`; `None` for a run that marches nothing.
    pub knob: Option<(u64, u64)>,
}

impl RowKey {
    /// Whether a planned run with this key (knob as asked) is among `done`: a finished row
    /// has this key, or the same key without a knob (the run turned out to march nothing, so
    /// its knob changes nothing).
    pub fn is_done(&self, done: &HashSet<RowKey>) -> bool {
        done.contains(self) || done.contains(&RowKey { knob: None, ..self.clone() })
    }
}

/// The reference's hit tolerance, pixels (or the sweep's smallest, if that is smaller), so
/// that the reference marches (CSG, repetition) finer than every run.
pub const REFERENCE_TOLERANCE_PX: f64 = 0.05;

/// The default inputs: every scene under `data/scenes`, searched recursively (sorted by
/// path), and the Stanford bunny from `../shared/meshes` where it exists, relative to the
/// working directory.
///
/// # Errors
/// When `data/scenes` or a folder in it cannot be read.
pub fn default_inputs() -> Result<Vec<PathBuf>> {
    /// Every `.toml` below `dir`; a folder reached twice (a link back up the tree) is
    /// walked once, so a link loop cannot recurse forever.
    fn collect(dir: &Path, out: &mut Vec<PathBuf>, seen: &mut Vec<PathBuf>) -> Result<()> {
        let real = dir.canonicalize().map_err(|e| Error::io(dir, e))?;
        if seen.contains(&real) {
            return Ok(());
        }
        seen.push(real);
        let entries = std::fs::read_dir(dir)
            .map_err(|e| Error::io(dir, format!("{e} (run from the repository root or name the inputs)")))?;
        for entry in entries {
            let path = entry.map_err(|e| Error::io(dir, e))?.path();
            if path.is_dir() {
                collect(&path, out, seen)?;
            } else if path.extension().is_some_and(|e| e == "toml") {
                out.push(path);
            }
        }
        Ok(())
    }
    let mut inputs = Vec::new();
    let scenes = Path::new("data/scenes");
    if !scenes.is_dir() {
        return Err(Error::io(scenes, "not a folder (run from the repository root or name the inputs)"));
    }
    collect(scenes, &mut inputs, &mut Vec::new())?;
    inputs.sort();
    let bunny = Path::new("../shared/meshes/stanford-bunny.obj");
    if bunny.exists() {
        inputs.push(bunny.to_path_buf());
    }
    Ok(inputs)
}

/// Largest resolution written as a mesh or grid artifact.
const ARTIFACT_MAX_RES: u32 = 64;

/// How one run's geometry is made (not [`crate::plan::Build`], how one object is built).
#[derive(Clone, Copy, Debug)]
enum RunGeometry {
    /// `build_scene` in a representation.
    Scene(Representation),
    /// The input mesh sampled or voxelized into a grid at a resolution and re-extracted
    /// with marching cubes.
    Reextract { fill: GridFill, resolution: u32 },
    /// The input mesh decimated by meshoptimizer's quadric-error simplifier.
    Decimate { target: DecimateTarget },
    /// The input mesh (decimated to `target` where given) traced in the compact layout
    /// ([`MeshLayout::Compact`]: quantised nodes, 16-bit vertices).
    Compact { target: Option<DecimateTarget> },
}

/// The `class` column of an input: for a scene file under a `data/scenes` folder, its
/// folder relative to `data/scenes` (`data/scenes/blend/metaballs_16.toml` -> `blend`;
/// `scenes` for a file directly in `data/scenes`); `implicit` for a `.vm` model; `scan` for
/// a mesh file (any other extension but `.toml`); otherwise the name of the file's folder (`scenes` when it has none).
pub fn input_class(path: &Path) -> String {
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("vm")) {
        return "implicit".into();
    }
    if path.extension().is_none_or(|e| e != "toml") {
        return "scan".into();
    }
    let parent = path.parent().unwrap_or(Path::new(""));
    let parts: Vec<String> =
        parent.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    if let Some(i) = parts.windows(2).rposition(|w| w[0] == "data" && w[1] == "scenes") {
        let rest = &parts[i + 2..];
        return if rest.is_empty() { "scenes".into() } else { rest.join("/") };
    }
    parts.last().filter(|p| !p.is_empty() && *p != ".").cloned().unwrap_or_else(|| "scenes".into())
}

/// The order in which the `n` runs of input `input` are run: the reference (0) first, the
/// rest in plan order without a seed, or shuffled (Fisher-Yates on a SplitMix64 stream seeded
/// by `seed` and the input's name, so inputs get different orders) with one. Deterministic:
/// the same seed gives the same order in every process.
pub fn run_order(n: usize, seed: Option<u64>, input: &str) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    let Some(seed) = seed else { return order };
    // FNV-1a of the name, mixed into the seed.
    let name =
        input.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3));
    let mut state = seed ^ name.rotate_left(17);
    let mut next = || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    for i in (2..n).rev() {
        // Positions 1..=i; the modulo bias (under 2^-50 here) is immaterial.
        let j = 1 + (next() % i as u64) as usize;
        order.swap(i, j);
    }
    order
}

/// One planned run.
#[derive(Clone, Debug)]
struct Run {
    repr: ReprKind,
    /// Primary visibility traced, or rasterized (a `raster` twin of a mesh run).
    primary: PrimaryVisibility,
    method: &'static str,
    resolution: Option<u32>,
    build: RunGeometry,
}

impl Run {
    /// The march knob asked for: `(tolerance_px, relaxation)`; `None` for re-extracted
    /// and decimated meshes, which march nothing.
    fn knob(&self) -> Option<(f64, f64)> {
        match self.build {
            RunGeometry::Scene(r) => Some((r.march().tolerance_px, r.march().relaxation)),
            RunGeometry::Reextract { .. } | RunGeometry::Decimate { .. } | RunGeometry::Compact { .. } => {
                None
            }
        }
    }

    /// The `method` column: `method`, with the target for a decimated mesh
    /// ([`DecimateTarget::method_name`], `decimated-25%`), and `-compact` after it for the
    /// compact layout (`compact` for the original, `decimated-25%-compact`).
    /// A raster twin ([`PrimaryVisibility::Raster`]) is `raster` for the original mesh and
    /// `-raster` after the method otherwise (`decimated-25%-raster`, `parametric-raster`).
    fn method(&self) -> String {
        let method = match self.build {
            RunGeometry::Decimate { target } => target.method_name(),
            RunGeometry::Compact { target: Some(target) } => format!("{}-compact", target.method_name()),
            _ => self.method.to_string(),
        };
        match self.primary {
            PrimaryVisibility::Trace => method,
            PrimaryVisibility::Raster if method == "original" => "raster".into(),
            PrimaryVisibility::Raster => format!("{method}-raster"),
        }
    }
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

/// The `method` of a scene's reference run: `interval-march` for an implicit model (a
/// `.vm` input: every object [`ObjectKind::Implicit`], which has no closed form; the
/// reference is the safe implicit marcher), `closed-form` otherwise (ray-primitive
/// intersection where an object has one).
fn reference_method(scene: &Scene) -> &'static str {
    let implicit = |o: &crate::scene::shape::Object| matches!(o.kind, ObjectKind::Implicit { .. });
    if !scene.objects.is_empty() && scene.objects.iter().all(implicit) {
        "interval-march"
    } else {
        "closed-form"
    }
}

/// The runs for one input: the reference first.
fn plan(scene: &Scene, opts: &CompareOptions) -> Vec<Run> {
    let march = opts.march;
    let finest = opts.sdf_tolerances_px.iter().copied().fold(REFERENCE_TOLERANCE_PX, f64::min);
    let reference_march = MarchParams { tolerance_px: finest, relaxation: 1.0, ..march };
    let band = GridStorage::Band { cells: opts.band_cells };
    let grid = |resolution, fill, storage| {
        RunGeometry::Scene(Representation::Grid { resolution, fill, storage, march })
    };
    let mut runs = Vec::new();
    if mesh_input(scene).is_some() {
        runs.push(Run {
            primary: PrimaryVisibility::Trace,
            repr: ReprKind::Mesh,
            method: "original",
            resolution: None,
            build: RunGeometry::Scene(Representation::Analytic { march: reference_march }),
        });
        for &r in &opts.resolutions {
            let res = Some(r);
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Grid,
                method: "sample",
                resolution: res,
                build: grid(r, GridFill::Sample, GridStorage::Dense),
            });
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Grid,
                method: "voxelize",
                resolution: res,
                build: grid(r, GridFill::Voxelize, GridStorage::Dense),
            });
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Grid,
                method: "sample-band",
                resolution: res,
                build: grid(r, GridFill::Sample, band),
            });
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Mesh,
                method: "from-sample",
                resolution: res,
                build: RunGeometry::Reextract { fill: GridFill::Sample, resolution: r },
            });
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Mesh,
                method: "from-voxelize",
                resolution: res,
                build: RunGeometry::Reextract { fill: GridFill::Voxelize, resolution: r },
            });
        }
        // The original decimated (meshoptimizer), as a polygon pipeline would ship it:
        // mesh-side candidates without a resolution, like the original.
        for &target in &opts.decimate {
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Mesh,
                method: "decimated",
                resolution: None,
                build: RunGeometry::Decimate { target },
            });
        }
        // With `--layout compact`: the original and its decimations in the compact layout
        // too (the runs above stay in the full one).
        if opts.overrides.layout() == Some(MeshLayout::Compact) {
            let targets = std::iter::once(None).chain(opts.decimate.iter().copied().map(Some));
            for target in targets {
                runs.push(Run {
                    primary: PrimaryVisibility::Trace,
                    repr: ReprKind::Mesh,
                    method: "compact",
                    resolution: None,
                    build: RunGeometry::Compact { target },
                });
            }
        }
    } else {
        runs.push(Run {
            primary: PrimaryVisibility::Trace,
            repr: ReprKind::Analytic,
            method: reference_method(scene),
            resolution: None,
            build: RunGeometry::Scene(Representation::Analytic { march: reference_march }),
        });
        for &tolerance_px in &opts.sdf_tolerances_px {
            for &relaxation in &opts.sdf_relaxations {
                runs.push(Run {
                    primary: PrimaryVisibility::Trace,
                    repr: ReprKind::Sdf,
                    method: "sphere-trace",
                    resolution: None,
                    build: RunGeometry::Scene(Representation::Sdf {
                        march: MarchParams { tolerance_px, relaxation, ..march },
                    }),
                });
            }
        }
        for &r in &opts.resolutions {
            let res = Some(r);
            let mesh = |method| {
                RunGeometry::Scene(Representation::Mesh {
                    resolution: sweep_mesh_resolution(r),
                    shading: Shading::Smooth,
                    method,
                    plane: MeshPlane::ClosedForm,
                    march,
                })
            };
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Mesh,
                method: "parametric",
                resolution: res,
                build: mesh(MeshMethod::Parametric),
            });
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Mesh,
                method: "extracted",
                resolution: res,
                build: mesh(MeshMethod::Extracted(ExtractMethod::MarchingCubes)),
            });
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Grid,
                method: "dense",
                resolution: res,
                build: grid(r, GridFill::Sample, GridStorage::Dense),
            });
            runs.push(Run {
                primary: PrimaryVisibility::Trace,
                repr: ReprKind::Grid,
                method: "band",
                resolution: res,
                build: grid(r, GridFill::Sample, band),
            });
            if scene.objects.len() > 1 {
                runs.push(Run {
                    primary: PrimaryVisibility::Trace,
                    repr: ReprKind::Grid,
                    method: "scene-band",
                    resolution: res,
                    build: grid(r, GridFill::Sample, GridStorage::Scene { cells: opts.band_cells }),
                });
            }
        }
    }
    // The raster twins: the original mesh, its decimations and the scene's parametric and
    // extracted meshes again with their primary visibility rasterized (the re-extracted
    // meshes of the grid study and the compact layout, which the rasterizer does not read,
    // have none).
    let twins: Vec<Run> = runs
        .iter()
        .filter(|r| {
            r.repr == ReprKind::Mesh
                && matches!(r.method, "original" | "decimated" | "parametric" | "extracted")
        })
        .map(|r| Run { primary: PrimaryVisibility::Raster, ..r.clone() })
        .collect();
    runs.extend(twins);
    runs
}

/// A built run: its geometry, the realised plan of each object, build time and, for
/// meshes and grids, what to save as artifacts.
struct Built {
    geometry: SceneGeometry,
    plans: Vec<ObjectPlan>,
    build_ms: f64,
    mesh: Option<TriangleMesh>,
    grid: Option<SdfGrid>,
}

/// Refuses a run whose estimated memory exceeds `budget` (the check [`build`] makes first;
/// `--search` asks it before choosing a knob, to tell a budget stop from a cap).
fn check_budget(scene: &Scene, b: RunGeometry, budget: &MemoryBudget) -> Result<()> {
    match b {
        RunGeometry::Scene(repr) => budget.check_scene("this run", scene, repr)?,
        RunGeometry::Reextract { fill, resolution } => budget.check(
            "this run",
            reextract_bytes(mesh_input(scene).map_or(0, |m| m.triangles.len()), fill, resolution),
        )?,
        RunGeometry::Decimate { .. } | RunGeometry::Compact { target: Some(_) } => budget.check(
            "this run",
            mesh_input(scene).map_or(0, |m| m.bytes_used() as u64 * SCRATCH_FACTOR).saturating_add(
                crate::plan::budget::scene_bytes(
                    scene,
                    Representation::Analytic { march: MarchParams::default() },
                ),
            ),
        )?,
        RunGeometry::Compact { target: None } => budget.check_scene(
            "this run",
            scene,
            Representation::Analytic { march: MarchParams::default() },
        )?,
    }
    Ok(())
}

fn build(scene: &Scene, b: RunGeometry, budget: &MemoryBudget) -> Result<Built> {
    check_budget(scene, b, budget)?;
    let start = Instant::now();
    match b {
        RunGeometry::Scene(repr) => {
            let (geometry, plans) = build_scene_with_plans(scene, repr);
            Ok(Built { geometry, plans, build_ms: ms(start), mesh: None, grid: None })
        }
        RunGeometry::Reextract { fill, resolution } => {
            let original = mesh_input(scene).ok_or_else(|| Error::Usage("not a mesh input".into()))?;
            let (grid, mesh) = reextract_mesh(original, fill, resolution)?;
            let mut s = scene.clone();
            s.objects[0].kind = ObjectKind::Mesh {
                mesh: Arc::new(mesh.clone()),
                source: PathBuf::from("re-extracted"),
                shading: Shading::Smooth,
            };
            let (geometry, plans) =
                build_scene_with_plans(&s, Representation::Analytic { march: MarchParams::default() });
            Ok(Built { geometry, plans, build_ms: ms(start), mesh: Some(mesh), grid: Some(grid) })
        }
        // Decimation time is build time, as extraction is.
        RunGeometry::Decimate { target } => {
            let s = decimated_scene(scene, target)?;
            let (geometry, plans) =
                build_scene_with_plans(&s, Representation::Analytic { march: MarchParams::default() });
            Ok(Built { geometry, plans, build_ms: ms(start), mesh: None, grid: None })
        }
        RunGeometry::Compact { target } => {
            let mut s = match target {
                Some(target) => decimated_scene(scene, target)?,
                None => scene.clone(),
            };
            s.settings.mesh_layout = MeshLayout::Compact;
            let (geometry, plans) =
                build_scene_with_plans(&s, Representation::Analytic { march: MarchParams::default() });
            Ok(Built { geometry, plans, build_ms: ms(start), mesh: None, grid: None })
        }
    }
}

/// The scene of the mesh input `scene` with its mesh decimated to `target`.
fn decimated_scene(scene: &Scene, target: DecimateTarget) -> Result<Scene> {
    let original = mesh_input(scene).ok_or_else(|| Error::Usage("not a mesh input".into()))?;
    let decimated = decimate(original, target, NO_ERROR_LIMIT)
        .map_err(|e| Error::Usage(format!("decimating to {target}: {e}")))?;
    let mut s = scene.clone();
    let ObjectKind::Mesh { source, shading, .. } = &scene.objects[0].kind else {
        unreachable!("mesh_input is a mesh object")
    };
    s.objects[0].kind =
        ObjectKind::Mesh { mesh: Arc::new(decimated.mesh), source: source.clone(), shading: *shading };
    Ok(s)
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
    /// Of `median`, primary visibility, ms (the compare CSV's `primary_ms`); `None` where
    /// a frame does not say.
    pub primary_ms: Option<f64>,
    /// When the frames finished, RFC 3339 UTC.
    pub timestamp: String,
}

/// Renders one warm-up frame and `frames` timed ones; returns their timing and the last
/// frame (work counts are the same in every frame).
pub(crate) fn time_frames(
    scene: &Scene,
    geometry: &SceneGeometry,
    primary: PrimaryVisibility,
    frames: u32,
) -> (Timing, Frame) {
    let mut last = render_with(scene, geometry, primary);
    let mut times = Vec::with_capacity(frames as usize);
    let mut primary_s = Some(0.0);
    let mut total_s = 0.0;
    for _ in 0..frames {
        last = render_with(scene, geometry, primary);
        times.push(last.time.as_secs_f64() * 1e3);
        primary_s = primary_s.zip(last.primary).map(|(a, p)| a + p.as_secs_f64());
        total_s += last.time.as_secs_f64();
    }
    let median = metrics::median(&times);
    let primary_ms = primary_s.filter(|_| total_s > 0.0).map(|p| median * (p / total_s).min(1.0));
    let timing = Timing {
        median,
        min: times.iter().copied().fold(f64::INFINITY, f64::min),
        max: times.iter().copied().fold(0.0, f64::max),
        mrays_per_s: last.stats.rays as f64 / (median * 1e-3) / 1e6,
        steps_per_ray: last.steps_per_ray(),
        nodes_per_ray: last.nodes_per_ray(),
        samples: times.iter().map(|t| format!("{t:.3}")).collect::<Vec<_>>().join(" "),
        primary_ms,
        timestamp: humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string(),
    };
    (timing, last)
}

/// What the reference run leaves for the others to be measured against.
struct Reference {
    name: String,
    image: RgbImage,
    /// Every primary ray's hit.
    probe: Probe,
    /// A subsample of the hit points for the Chamfer and Hausdorff distances.
    points: Vec<DVec3>,
    /// The bounding-box diagonal of the visible bounded objects ([`metrics::bounded_diagonal`]).
    diagonal: Option<f64>,
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

/// Columns that later schema versions added, and how a row of an older CSV fills them:
/// `asked_repr` (version 3) from `repr` (version 2 wrote the asked representation there),
/// `peak_heap_bytes` (version 4), `primary_ms` and `shading_ms` (version 5) empty.
const ADDED_COLUMNS: [(&str, Option<&str>); 4] =
    [("asked_repr", Some("repr")), ("peak_heap_bytes", None), ("primary_ms", None), ("shading_ms", None)];

/// Reads the rows of an existing CSV, checking its header against [`COLUMNS`]. A CSV of an
/// older schema version (2, 3 or 4: [`COLUMNS`] without some of [`ADDED_COLUMNS`]) is read too,
/// the missing columns filled as that list says.
///
/// # Errors
/// [`Error::Input`] naming the file and line when the header or a row does not match.
pub fn read_rows(path: &Path) -> Result<Vec<Row>> {
    read_rows_of(path, true)
}

/// [`read_rows`]; an older schema is refused unless `old_too`.
fn read_rows_of(path: &Path, old_too: bool) -> Result<Vec<Row>> {
    let mut reader = csv::Reader::from_path(path).map_err(|e| Error::io(path, e))?;
    let header = reader.headers().map_err(|e| Error::input(path, None, e))?.clone();
    let added = |c: &str| ADDED_COLUMNS.iter().any(|(a, _)| *a == c);
    // The header must be COLUMNS in order, less (in an older CSV) some added columns.
    let present: Vec<&str> = header.iter().collect();
    let matches = {
        let mut h = present.iter().peekable();
        COLUMNS.iter().all(|c| {
            if h.peek() == Some(&c) {
                h.next();
                true
            } else {
                old_too && added(c)
            }
        }) && h.next().is_none()
    };
    if !matches {
        return Err(Error::input(
            path,
            Some(crate::error::Location { line: 1, column: 1 }),
            format!("the header is not compare schema version {SCHEMA_VERSION}; write a new file"),
        ));
    }
    let old = present.len() < COLUMNS.len();
    let columns = csv::StringRecord::from(COLUMNS.to_vec());
    let mut rows = Vec::new();
    for (i, r) in reader.records().enumerate() {
        // A row cut off by a crash is the only one that can be incomplete: the last.
        let at = Some(crate::error::Location { line: i + 2, column: 1 });
        let mut record = r.map_err(|e| Error::input(path, at, e))?;
        if old {
            let cell = |name: &str| present.iter().position(|h| *h == name).and_then(|k| record.get(k));
            let fields: Option<Vec<&str>> = COLUMNS
                .iter()
                .map(|c| match ADDED_COLUMNS.iter().find(|(a, _)| a == c) {
                    Some((_, from)) if !present.contains(c) => Some(from.map_or(Some(""), cell)?),
                    _ => cell(c),
                })
                .collect();
            let fields = fields.ok_or_else(|| Error::input(path, at, "the row has too few fields"))?;
            record = csv::StringRecord::from(fields);
        }
        rows.push(record.deserialize::<Row>(Some(&columns)).map_err(|e| Error::input(path, at, e))?);
    }
    Ok(rows)
}

/// Opens the CSV for appending rows, holding an exclusive advisory lock on it
/// ([`File::lock`], `flock`) until the returned file is dropped, at the end of the run: of
/// two `compare` processes on one CSV, one writes at a time, so no row is lost or torn.
///
/// A missing CSV is created with exclusive creation (`create_new`, never truncating one
/// that appeared meanwhile) and gets the header from whoever locks it first while it is
/// empty. An existing one:
/// - with `--resume`: a CSV another process is writing is waited for (with a note on
///   stderr); then an incomplete last row a crash left is cut off and the rows are read
///   (header checked), and this run appends its own after them;
/// - with `--overwrite`: truncated under the lock; one another process holds is refused;
/// - otherwise refused; one another process holds is refused at once as well.
///
/// Returns the rows already there.
fn open_csv(opts: &CompareOptions) -> Result<(File, Vec<Row>)> {
    let path = &opts.csv;
    crate::files::check_not_read(path)?;
    let open = |o: &mut OpenOptions| o.read(true).append(true).open(path);
    let mut file = match open(OpenOptions::new().create_new(true)) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            open(&mut OpenOptions::new()).map_err(|e| Error::io(path, format!("cannot write: {e}")))?
        }
        Err(e) => return Err(Error::io(path, format!("cannot write: {e}"))),
    };
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) if opts.resume => {
            eprintln!("{}: another process is writing it; waiting for it to finish", path.display());
            file.lock().map_err(|e| Error::io(path, format!("cannot lock: {e}")))?;
        }
        Err(std::fs::TryLockError::WouldBlock) => {
            return Err(Error::io(
                path,
                "another process is writing it (it is locked); wait for it to finish, or pass \
                 --resume to add this run's rows after it",
            ));
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(Error::io(path, format!("cannot lock: {e}"))),
    }
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    if len > 0 && opts.resume {
        drop_partial_row(&file, path)?;
        // Rows are appended under this header: an older schema is refused.
        return Ok((file, read_rows_of(path, false)?));
    }
    if len > 0 && !opts.overwrite {
        return Err(Error::io(
            path,
            "already exists; pass --resume to continue it or --overwrite to replace it",
        ));
    }
    file.set_len(0).map_err(|e| Error::io(path, format!("cannot write: {e}")))?;
    writeln!(file, "{}", COLUMNS.join(",")).map_err(|e| Error::io(path, e))?;
    file.flush().map_err(|e| Error::io(path, e))?;
    Ok((file, Vec::new()))
}

/// Cuts a last line left incomplete by a crash (no final newline) off `file` (the locked
/// CSV at `path`); a file without one complete line (not a CSV this wrote) is left as it
/// is, for [`read_rows`] to refuse.
fn drop_partial_row(file: &File, path: &Path) -> Result<()> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    if bytes.last().is_none_or(|&b| b == b'\n') {
        return Ok(());
    }
    let Some(keep) = bytes.iter().rposition(|&b| b == b'\n').map(|i| i + 1) else { return Ok(()) };
    file.set_len(keep as u64).map_err(|e| Error::io(path, e))?;
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

/// What a run did not represent as asked, from the objects' realised plans (in the order
/// of `scene`'s objects): every object with a fallback, named with its typed cause and what
/// was done instead ([`Fallback`]'s text), whether it left the representation (then `repr`
/// says so too) or stayed in it (a dense grid for a band, a grid clipped to the view
/// region, ...); empty when there is none. Two fallbacks that belong to the asked
/// representation are not named: the analytic representation's sphere tracing of objects
/// without a closed form (its definition) and an infinite plane intersected in closed form
/// (as every representation does; the mesh one unless asked for discs).
fn note(scene: &Scene, plans: &[ObjectPlan]) -> String {
    let fallbacks: Vec<String> = scene
        .objects
        .iter()
        .zip(plans)
        .filter_map(|(o, p)| match p.fallback? {
            Fallback::NoClosedForm { .. } => None,
            _ if p.build == Build::ClosedForm => None,
            f => Some(format!("{} '{}': {f}", o.kind_name(), o.label)),
        })
        .collect();
    if fallbacks.is_empty() {
        String::new()
    } else {
        format!("{} of {} objects not as asked: {}", fallbacks.len(), plans.len(), fallbacks.join("; "))
    }
}

/// An input as `compare` measures it: loaded, the command's overrides applied, meshes in the
/// full layout (`--layout compact` adds compact runs, [`plan`]; the others keep the full one).
fn load_for_compare(path: &Path, opts: &CompareOptions) -> Result<Scene> {
    let mut scene = load_input(path, Shading::Smooth)?;
    opts.overrides.apply(&mut scene);
    scene.settings.mesh_layout = MeshLayout::Full;
    Ok(scene)
}

/// The one input of a single-input mode of `compare` (`flag`: `--duel`, `--check-reference`),
/// loaded by [`load_for_compare`]: its path, name and class, and the scene. Refuses more than
/// one input, and an existing `--csv` without `--overwrite` (these modes write their CSV whole).
fn load_single<'a>(opts: &'a CompareOptions, flag: &str) -> Result<(&'a Path, String, String, Scene)> {
    let [path] = opts.inputs.as_slice() else {
        return Err(Error::Usage(format!("{flag} takes one input, got {}", opts.inputs.len())));
    };
    if !opts.overwrite && std::fs::symlink_metadata(&opts.csv).is_ok() {
        return Err(Error::Usage(format!("{}: the CSV exists; --overwrite replaces it", opts.csv.display())));
    }
    Ok((path, stem(path), input_class(path), load_for_compare(path, opts)?))
}

/// Writes `rows` as a CSV with a header to `path`, atomically (all of them or nothing).
fn write_csv_whole<T: Serialize>(path: &Path, rows: &[T]) -> Result<()> {
    crate::files::write_atomic(path, |w| {
        let mut csv = csv::Writer::from_writer(w);
        for row in rows {
            csv.serialize(row).map_err(std::io::Error::other)?;
        }
        csv.flush()
    })
}

/// `toolkit compare`: runs every input in every representation and resolution, appending
/// rows to the CSV; returns the summary text.
///
/// # Errors
/// No input can be loaded (nothing is written), an existing CSV without `--resume` or
/// `--overwrite`, a CSV another process is writing (without `--resume`), unwritable outputs;
/// [`Error::Batch`] (with the summary) when some inputs failed and the others ran.
pub fn compare_command(opts: &CompareOptions) -> Result<String> {
    let mut opts = opts.clone();
    opts.resolutions.sort_unstable();
    opts.resolutions.dedup();
    let opts = &opts;
    // Load every input first. An input that cannot be loaded is reported and left out
    // (the others run, and the command fails at the end); when none can, nothing is written.
    let mut inputs: Vec<(String, String, Scene)> = Vec::new();
    let mut failed: Vec<String> = Vec::new();
    for (i, path) in opts.inputs.iter().enumerate() {
        let name = stem(path);
        if let Some(other) = opts.inputs[..i].iter().find(|p| stem(p) == name) {
            return Err(Error::Usage(format!(
                "{} and {} share the name `{name}` (the input column); rename one",
                other.display(),
                path.display()
            )));
        }
        let loaded = catch_panic(|| load_for_compare(path, opts)).and_then(|r| r);
        match loaded {
            Ok(scene) => inputs.push((name, input_class(path), scene)),
            // With one input its error is the command's one line; with several, each
            // failed input gets its line here and the command's line counts them.
            Err(e) if opts.inputs.len() == 1 => return Err(e),
            Err(e) => {
                eprintln!("error: {e}");
                failed.push(path.display().to_string());
            }
        }
    }
    if inputs.is_empty() {
        return Err(Error::Usage(format!("all {} inputs failed to load; nothing was written", failed.len())));
    }
    if let Some(dir) = &opts.artifacts {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let (mut file, mut rows) = open_csv(opts)?;
    let done: HashSet<RowKey> = rows.iter().map(Row::key).collect();
    let plans: Vec<Vec<Run>> = inputs
        .iter()
        .map(|(name, _, s)| {
            let runs = plan(s, opts);
            run_order(runs.len(), opts.order_seed, name).into_iter().map(|i| runs[i].clone()).collect()
        })
        .collect();
    let input_path = |name: &str| {
        opts.inputs
            .iter()
            .find(|p| stem(p) == name)
            .map_or_else(|| name.to_string(), |p| p.display().to_string())
    };
    let total: usize = plans.iter().map(Vec::len).sum();
    let commit = commit_id();
    if let Some(max_res) = opts.search_max_res {
        // The search decides each run from the ones before it: no plan, no shuffled order,
        // no progress bar (the total is not known ahead).
        let mut lines = Vec::new();
        for (name, class, scene) in &inputs {
            let mut sink =
                searched::Sink { file: &mut file, rows: &mut rows, done: &done, opts, commit: &commit };
            let searched = catch_panic(|| searched::search_input(&mut sink, (name, class), scene, max_res));
            match searched {
                Ok(Ok(Some(line))) => lines.push(line),
                Ok(Ok(None)) | Err(_) => failed.push(input_path(name)),
                Ok(Err(e)) => return Err(e),
            }
        }
        drop(file);
        return finish(opts, &rows, lines, failed);
    }
    let bar = progress_bar(total as u64, opts.progress);
    'inputs: for ((name, class, scene), runs) in inputs.iter().zip(&plans) {
        let mut reference: Option<Reference> = None;
        for (at, run) in runs.iter().enumerate() {
            let key = RowKey {
                input: name.clone(),
                replicate: opts.replicate,
                repr: run.repr.to_string(),
                method: run.method(),
                resolution: run.resolution,
                knob: run.knob().map(|(t, r)| (t.to_bits(), r.to_bits())),
            };
            let done_already = key.is_done(&done);
            let is_reference = reference.is_none();
            bar.set_message(format!(
                "{name} {}/{} {}",
                run.repr,
                run.method(),
                run.resolution.map_or(String::new(), |r| r.to_string())
            ));
            if done_already && !is_reference {
                bar.inc(1);
                continue;
            }
            // A panic (a bug) in one run fails the input, not the batch.
            let measured = catch_panic(|| measure((name, class), scene, run, opts, &commit, &mut reference));
            let row = match measured {
                Ok(Ok(row)) => row,
                // Without its reference an input cannot be measured at all: it fails, and
                // the next input runs.
                Ok(Err(e)) | Err(e) if is_reference => {
                    bar.suspend(|| {
                        eprintln!("error: {name}: {}/{} (the reference): {e}", run.repr, run.method())
                    });
                    failed.push(input_path(name));
                    bar.inc((runs.len() - at) as u64);
                    continue 'inputs;
                }
                Err(e) => {
                    bar.suspend(|| eprintln!("error: {name}: {}/{}: {e}", run.repr, run.method()));
                    failed.push(input_path(name));
                    bar.inc(1);
                    continue;
                }
                Ok(Err(e)) => {
                    bar.suspend(|| eprintln!("{name}: {}/{} skipped: {e}", run.repr, run.method()));
                    bar.inc(1);
                    continue;
                }
            };
            if !done_already {
                write_row(&mut file, &opts.csv, &row)?;
                rows.push(row);
            }
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    drop(file);
    finish(opts, &rows, Vec::new(), failed)
}

/// `compare --summarize`: the summary of every row already in `opts.csv` (all inputs and
/// replicates: [`summary::summarize`] merges replicates), printed and written to
/// `--summary-json`. The study's merge step makes its summary.json this way.
pub fn summarize_command(opts: &CompareOptions) -> Result<String> {
    let rows = read_rows(&opts.csv)?;
    finish(opts, &rows, Vec::new(), Vec::new())
}

/// The end of `compare`: the summary of `rows` (after `lines`, `--search`'s counts), its
/// JSON where asked, and the batch error naming the `failed` inputs.
fn finish(
    opts: &CompareOptions,
    rows: &[Row],
    lines: Vec<String>,
    mut failed: Vec<String>,
) -> Result<String> {
    let summary = summary::summarize(rows);
    if let Some(path) = &opts.summary_json {
        let json = serde_json::to_string_pretty(&summary).map_err(|e| Error::io(path, e))?;
        crate::files::write_atomic_bytes(path, json.as_bytes())?;
    }
    let mut text = summary::to_text(&summary);
    if !lines.is_empty() {
        text = format!("{}\n{text}", lines.join("\n"));
    }
    failed.dedup();
    if failed.is_empty() {
        return Ok(text);
    }
    Err(Error::Batch {
        output: text,
        message: format!(
            "{} of {} inputs failed ({}); the others' rows are in {}",
            failed.len(),
            opts.inputs.len(),
            failed.join(", "),
            opts.csv.display()
        ),
    })
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

/// Whether any object of a built run is ray marched (sphere traced or a grid).
fn marches(plans: &[ObjectPlan]) -> bool {
    plans.iter().any(ObjectPlan::marches)
}

/// Builds, times and measures one run (and keeps the reference's images and samples when
/// it is the first run of the input). `input` is the input's name and class.
fn measure(
    input: (&str, &str),
    scene: &Scene,
    run: &Run,
    opts: &CompareOptions,
    commit: &str,
    reference: &mut Option<Reference>,
) -> Result<Row> {
    let (name, class) = input;
    reset_peak_rss();
    heap::reset();
    let built = build(scene, run.build, &opts.budget)?;
    let (timing, frame) = time_frames(scene, &built.geometry, run.primary, opts.frames);
    let peak = peak_rss_bytes();
    // The input's prepared implicit models count as if this run had prepared them.
    let prep = preparation(scene);
    let peak_heap = heap::peak().map(|p| prep.and_then(|q| q.heap).map_or(p, |h| h.peak.max(h.live + p)));
    let probe = metrics::probe(&scene.camera, &built.geometry, scene.settings.max_distance);
    let points = metrics::subsample(&probe.points, opts.surface_samples);
    let origin = scene.camera.position.as_dvec3();
    let angle = metrics::pixel_angle(&scene.camera);
    let label = format!("{}/{}", run.repr, run.method());
    let is_reference = reference.is_none();
    let r = match reference {
        Some(r) => r,
        None => reference.insert(Reference {
            name: label.clone(),
            image: frame.image.clone(),
            diagonal: metrics::bounded_diagonal(built.geometry.objects(), &probe.points),
            probe: Probe { hits: probe.hits.clone(), points: probe.points.clone() },
            points: points.clone(),
            geometry: SceneGeometry::new(Vec::new()),
        }),
    };
    // The reference is measured against itself (its geometry is kept only after this run).
    let reference_geometry: &dyn Geometry = if is_reference { &built.geometry } else { &r.geometry };
    let px = metrics::pixel_error(&built.geometry, &probe, reference_geometry, &r.probe, origin, angle);
    let (chamfer, hausdorff) = match r.diagonal {
        None => (None, None),
        Some(_) if is_reference => (Some(0.0), Some(0.0)),
        Some(diagonal) => match metrics::surface_distance(&built.geometry, &points, &r.geometry, &r.points) {
            Some(d) => {
                let scale = diagonal.max(f64::MIN_POSITIVE);
                (Some(d.chamfer / scale), Some(d.hausdorff / scale))
            }
            None => (None, None),
        },
    };
    let silhouette = metrics::silhouette_mismatch_pct(&probe, &r.probe);
    let flip = metrics::flip_mean(&frame.image, &r.image);
    let px_p95 = px.map(|p| p.p95);
    let quality = if is_reference {
        Some(metrics::QUALITY_LEVELS[0].px)
    } else {
        metrics::quality_px(px_p95, silhouette, flip, frame.image.width(), frame.image.height())
    };
    let knob = run.knob().filter(|_| marches(&built.plans));
    let census = built.geometry.census();
    let total = built.geometry.bytes_used() as u64;
    let row = Row {
        input: name.to_string(),
        class: class.to_string(),
        replicate: opts.replicate,
        repr: traced_repr(&built.plans, run.repr).name(),
        asked_repr: run.repr.to_string(),
        method: run.method(),
        resolution: run.resolution,
        tolerance_px: knob.map(|k| k.0),
        relaxation: knob.map(|k| k.1),
        reference: r.name.clone(),
        triangles: census.triangles,
        grid_cells_stored: census.grid_samples,
        geometry_bytes: total - census.accel_bytes.min(total),
        accel_bytes: census.accel_bytes,
        total_bytes: total,
        build_ms: built.build_ms + prep.map_or(0.0, |q| q.ms),
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
        flip_mean: flip,
        silhouette_mismatch_pct: silhouette,
        px_err_mean: px.map(|p| p.mean),
        px_err_p95: px_p95,
        px_err_max: px.map(|p| p.max),
        quality_px: quality,
        chamfer_rel: chamfer,
        hausdorff_rel: hausdorff,
        peak_rss_bytes: peak,
        peak_heap_bytes: peak_heap,
        threads: rayon::current_num_threads(),
        width: scene.camera.width,
        height: scene.camera.height,
        depth: scene.settings.max_depth,
        commit: commit.to_string(),
        timestamp: timing.timestamp,
        frame_ms_samples: timing.samples,
        schema_version: SCHEMA_VERSION,
        note: note(scene, &built.plans),
        primary_ms: timing.primary_ms,
        shading_ms: timing.primary_ms.map(|p| timing.median - p),
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
    let mut base = match run.resolution {
        Some(r) => format!("{}-{}-{r}", run.repr, run.method()),
        None => format!("{}-{}", run.repr, run.method()),
    };
    // The SDF sweep's runs differ only in their knob.
    if let (ReprKind::Sdf, Some((t, r))) = (run.repr, run.knob()) {
        base = format!("{base}-tol{t}-relax{r}");
    }
    write_png(image, &dir.join(format!("{base}.png")))?;
    if is_reference && let Some(mesh) = mesh_input(scene) {
        save_mesh(mesh, &dir.join("reference.ply"))?;
    }
    if run.resolution.is_some_and(|r| r <= ARTIFACT_MAX_RES) {
        let mesh = built.mesh.clone().or_else(|| {
            (run.repr == ReprKind::Mesh)
                .then(|| crate::plan::scene_mesh(scene, representation(run)))
                .flatten()
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

/// The representation a run's [`crate::plan::scene_mesh`] artifact is made in.
fn representation(run: &Run) -> Representation {
    match run.build {
        RunGeometry::Scene(r) => r,
        RunGeometry::Reextract { .. } | RunGeometry::Decimate { .. } | RunGeometry::Compact { .. } => {
            Representation::Analytic { march: MarchParams::default() }
        }
    }
}
