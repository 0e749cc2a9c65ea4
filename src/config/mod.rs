//! The toolkit's configuration, validated once. As ripgrep's low-level arguments become
//! high-level ones: clap parses the command line into raw values ([`args`]); [`Task::new`]
//! checks every flag against its range, stated once below as a named constant, and returns
//! the validated options the commands take ([`RenderOptions`], [`ConvertTarget`],
//! [`CompareOptions`], [`ScalingOptions`], [`Overrides`]). Nothing downstream checks a
//! flag again; what is left to the commands depends on the inputs (memory budgets, a
//! grid's size over a mesh's bounding box, the files themselves).
//!
//! `--res` has one range per use ([`FlagRange::check`] is the one validation function):
//! [`MESH_RESOLUTION`] (render and gallery `--repr mesh`), [`GRID_RESOLUTION`] (render and
//! gallery `--repr grid`, compare's sweep), [`EXTRACTION_RESOLUTION`] (`convert --to
//! mesh`), [`SAMPLING_RESOLUTION`] (`convert --to grid`, bounded by memory) and
//! [`CASE_RESOLUTION`] (a hard-case manifest's `resolution`). Two stated rules map an asked
//! resolution to the one used: [`crate::plan::extract_resolution`] (the mesh
//! representation extracts at most at [`crate::plan::MAX_EXTRACT_RESOLUTION`]) and
//! [`sweep_mesh_resolution`] (compare's mesh runs start at the mesh range's minimum).

pub mod args;

use std::path::PathBuf;

use crate::convert::extract::ExtractMethod;
use crate::error::{Error, Result};
use crate::geometry::grid::DEFAULT_MAX_GRID_BYTES;
use crate::geometry::march::MarchParams;
use crate::mesh::simplify::DecimateTarget;
use crate::plan::budget::MemoryBudget;
use crate::plan::{
    GRID_MARGIN_CELLS, GridFill, GridStorage, MAX_EXTRACT_RESOLUTION, MeshMethod, ReprKind, Representation,
};
use crate::render::PrimaryVisibility;
use crate::scene::Scene;
use crate::scene::shape::{MeshLayout, Shading};
use args::{Command, MarchArgs, MeshArgs, Primary, SettingArgs, Target};

/// The accepted values of an integer flag, `min..=max`, and what the range is for (named
/// in the error).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FlagRange {
    /// Smallest accepted value.
    pub min: u32,
    /// Largest accepted value; [`u32::MAX`]: no limit here (memory decides).
    pub max: u32,
    /// What the range is for, appended to the bounds in the error (`" for grids"`), or
    /// empty.
    pub of: &'static str,
}

impl FlagRange {
    /// `value` when it lies in the range; otherwise [`Error::Usage`] naming `flag`, the
    /// range and `value` (one line).
    ///
    /// # Errors
    /// `value` outside `min..=max`.
    pub fn check(&self, flag: &str, value: u32) -> Result<u32> {
        if (self.min..=self.max).contains(&value) {
            return Ok(value);
        }
        let (min, max, of) = (self.min, self.max, self.of);
        Err(Error::Usage(if max == u32::MAX {
            format!("{flag} must be at least {min}{of}, got {value}")
        } else if min == 0 {
            format!("{flag} must be at most {max}{of}, got {value}")
        } else {
            format!("{flag} must be between {min} and {max}{of}, got {value}")
        }))
    }
}

/// `--res` of the mesh representation: segments around a tessellated primitive's largest
/// circle (objects extracted from their SDF stop at
/// [`crate::plan::MAX_EXTRACT_RESOLUTION`], see [`crate::plan::extract_resolution`]).
pub const MESH_RESOLUTION: FlagRange = FlagRange { min: 3, max: 8192, of: "" };

/// `--res` of the grid representation (and compare's sweep): cells along each gridded
/// object's longest axis.
pub const GRID_RESOLUTION: FlagRange = FlagRange { min: 2, max: 1024, of: " for grids" };

/// `convert --to mesh --res`: cells along each object's longest axis (its sample grid,
/// `res + 3` samples a side, is held in memory).
pub const EXTRACTION_RESOLUTION: FlagRange = FlagRange { min: 2, max: 1024, of: "" };

/// `convert --to grid --res`: cells along the mesh's longest axis; the grid's size over
/// the mesh's bounding box is checked against the memory limits once the mesh is read.
pub const SAMPLING_RESOLUTION: FlagRange = FlagRange { min: 1, max: u32::MAX, of: "" };

/// A hard case's `resolution` (`data/hard/cases.toml`): within both the mesh and the grid
/// range, and extracted whole.
pub const CASE_RESOLUTION: FlagRange = FlagRange { min: 3, max: MAX_EXTRACT_RESOLUTION, of: "" };

// The largest grids of these ranges fit under the grid size limit: no resolution in range
// can fail `crate::geometry::grid::check_size`.
const _: () = {
    let grid = GRID_RESOLUTION.max as u64 + 1 + 2 * GRID_MARGIN_CELLS as u64;
    assert!(grid * grid * grid * 4 <= DEFAULT_MAX_GRID_BYTES);
    let extraction = EXTRACTION_RESOLUTION.max as u64 + 3;
    assert!(extraction * extraction * extraction * 4 <= DEFAULT_MAX_GRID_BYTES);
    assert!(CASE_RESOLUTION.min >= MESH_RESOLUTION.min && CASE_RESOLUTION.max <= GRID_RESOLUTION.max);
};

/// The mesh resolution of compare's sweep at `resolution` (the one rule, stated here): the
/// sweep is checked against [`GRID_RESOLUTION`], which starts below [`MESH_RESOLUTION`], so
/// its mesh runs start at the mesh range's minimum (`--res 2` makes mesh runs at 3; their
/// CSV `resolution` column still says 2, the sweep's value).
pub fn sweep_mesh_resolution(resolution: u32) -> u32 {
    resolution.max(MESH_RESOLUTION.min)
}

/// `--width` and `--height`, pixels (the same limit as in scene files).
pub const IMAGE_EDGE: FlagRange = FlagRange { min: 1, max: crate::scene::file::MAX_IMAGE_SIZE, of: "" };

/// `--depth`, the maximum recursion depth (the same limit as in scene files).
pub const DEPTH: FlagRange = FlagRange { min: 0, max: crate::scene::file::MAX_RECURSION_DEPTH, of: "" };

/// `--max-steps`, per sphere-traced ray.
pub const MAX_STEPS: FlagRange = FlagRange { min: 1, max: 1_000_000, of: "" };

/// `--frames`, timed frames per compare run.
pub const FRAMES: FlagRange = FlagRange { min: 1, max: 1000, of: "" };

/// `--counts`, primitives per scene of the scaling experiment.
pub const COUNTS: FlagRange = FlagRange { min: 1, max: 10_000, of: "" };

/// `compare --band`, half-width of narrow-band grids in cells.
pub const BAND_CELLS: FlagRange = FlagRange { min: 1, max: u32::MAX, of: "" };

/// `--relax`, the over-relaxation factor: `[RELAXATION.start, RELAXATION.end)`.
pub const RELAXATION: std::ops::Range<f64> = 1.0..2.0;

/// `--tolerance-px`: in `(0, MAX_TOLERANCE_PX]` pixels.
pub const MAX_TOLERANCE_PX: f64 = 16.0;

/// `--epsilon`: in `(0, MAX_EPSILON)`.
pub const MAX_EPSILON: f64 = 1.0;

/// The default resolution sweep of `compare --res`.
pub const DEFAULT_RESOLUTIONS: [u32; 6] = [8, 16, 32, 64, 128, 256];

/// The default decimations of compare's mesh inputs (`--decimate`): these fractions of the
/// original's triangles.
pub const DEFAULT_DECIMATIONS: [DecimateTarget; 5] = [
    DecimateTarget::Ratio(0.5),
    DecimateTarget::Ratio(0.25),
    DecimateTarget::Ratio(0.1),
    DecimateTarget::Ratio(0.05),
    DecimateTarget::Ratio(0.02),
];

/// The default hit tolerances of compare's SDF sweep (`--sdf-tolerance-px`), pixels.
pub const DEFAULT_SDF_TOLERANCES_PX: [f64; 3] = [0.25, 1.0, 2.0];

/// The default over-relaxation factors of compare's SDF sweep (`--sdf-relax`).
pub const DEFAULT_SDF_RELAXATIONS: [f64; 2] = [1.0, 1.6];

/// `MarchParams::epsilon` of every compare run unless `--epsilon` says otherwise: large
/// enough that the hit tolerance `min(epsilon, tolerance_px * pixel_footprint) * t` is
/// `tolerance_px` pixels for any camera (the pixel term exceeds 0.5 only for a footprint
/// over 0.5 / tolerance_px radians), so `tolerance_px` alone is the knob. With `render`'s
/// 1e-4 the relative cap binds first at usual image sizes (0.25 px of a 45-degree, 128-pixel
/// camera is 1.6e-3) and the sweep would change nothing.
pub const COMPARE_EPSILON: f64 = 0.5;

/// Checks sphere tracing parameters given on the command line (`--relax`,
/// `--tolerance-px`, `--epsilon`, `--max-steps`).
///
/// # Errors
/// [`Error::Usage`] for the first one out of its range (NaN included).
pub fn check_march(p: &MarchParams) -> Result<()> {
    if !RELAXATION.contains(&p.relaxation) {
        let (lo, hi) = (RELAXATION.start, RELAXATION.end);
        return Err(Error::Usage(format!("--relax must be in [{lo}, {hi}), got {}", p.relaxation)));
    }
    if !(p.tolerance_px > 0.0 && p.tolerance_px <= MAX_TOLERANCE_PX) {
        return Err(Error::Usage(format!(
            "--tolerance-px must be in (0, {MAX_TOLERANCE_PX}], got {}",
            p.tolerance_px
        )));
    }
    if !(p.epsilon > 0.0 && p.epsilon < MAX_EPSILON) {
        return Err(Error::Usage(format!("--epsilon must be in (0, {MAX_EPSILON}), got {}", p.epsilon)));
    }
    MAX_STEPS.check("--max-steps", p.max_steps)?;
    Ok(())
}

/// Checks a representation's parameters given on the command line: `--res` in the
/// representation's range ([`MESH_RESOLUTION`], [`GRID_RESOLUTION`]), then its sphere
/// tracing ([`check_march`]). `flag` names the resolution flag in the error.
///
/// # Errors
/// [`Error::Usage`] for the first parameter out of its range.
pub fn check_representation(repr: &Representation, flag: &str) -> Result<()> {
    match repr {
        Representation::Analytic { .. } | Representation::Sdf { .. } => {}
        Representation::Grid { resolution, .. } => {
            GRID_RESOLUTION.check(flag, *resolution)?;
        }
        Representation::Mesh { resolution, .. } => {
            MESH_RESOLUTION.check(flag, *resolution)?;
        }
    }
    check_march(&repr.march())
}

/// Overrides of a scene's settings from the command line, validated when made
/// ([`Overrides::new`]), so applying them cannot fail.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Overrides {
    width: Option<u32>,
    height: Option<u32>,
    depth: Option<u32>,
    layout: Option<MeshLayout>,
}

impl Overrides {
    /// No override.
    pub const NONE: Overrides = Overrides { width: None, height: None, depth: None, layout: None };

    /// Image width and height ([`IMAGE_EDGE`]) and maximum recursion depth ([`DEPTH`]),
    /// each where given.
    ///
    /// # Errors
    /// [`Error::Usage`] for a value out of its range.
    pub fn new(width: Option<u32>, height: Option<u32>, depth: Option<u32>) -> Result<Overrides> {
        for (name, v) in [("--width", width), ("--height", height)] {
            if let Some(v) = v {
                IMAGE_EDGE.check(name, v)?;
            }
        }
        if let Some(d) = depth {
            DEPTH.check("--depth", d)?;
        }
        Ok(Overrides { width, height, depth, layout: None })
    }

    /// These overrides with the mesh layout `layout` where given.
    pub fn with_layout(self, layout: Option<MeshLayout>) -> Overrides {
        Overrides { layout, ..self }
    }

    /// The mesh layout, where overridden.
    pub fn layout(&self) -> Option<MeshLayout> {
        self.layout
    }

    /// Image width, pixels, where overridden.
    pub fn width(&self) -> Option<u32> {
        self.width
    }

    /// Image height, pixels, where overridden.
    pub fn height(&self) -> Option<u32> {
        self.height
    }

    /// Maximum recursion depth, where overridden.
    pub fn depth(&self) -> Option<u32> {
        self.depth
    }

    /// Applies the overrides to `scene`.
    pub fn apply(&self, scene: &mut Scene) {
        if let Some(w) = self.width {
            scene.camera.width = w;
        }
        if let Some(h) = self.height {
            scene.camera.height = h;
        }
        if let Some(d) = self.depth {
            scene.settings.max_depth = d;
        }
        if let Some(l) = self.layout {
            scene.settings.mesh_layout = l;
        }
    }
}

/// Options of `toolkit render`.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Scene file.
    pub scene: PathBuf,
    /// Output PNG.
    pub output: PathBuf,
    /// Representation (checked: [`check_representation`]).
    pub repr: Representation,
    /// Primary visibility (rasterized only with the mesh representation).
    pub primary: PrimaryVisibility,
    /// Setting overrides.
    pub overrides: Overrides,
    /// Shading of a mesh given instead of a scene file.
    pub shading: Shading,
    /// Memory the geometry may need (checked before it is built).
    pub budget: MemoryBudget,
    /// `--heightmap`: the 16-bit height image of a 3D implicit model's view from +z.
    pub heightmap: Option<PathBuf>,
}

/// What `toolkit convert` produces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConvertTarget {
    /// A mesh file sampled into a signed distance grid of `res` cells along the longest axis
    /// of its bounding box, padded by `margin` cells: exact distances and winding-number
    /// signs ([`GridFill::Sample`]) or voxelized ([`GridFill::Voxelize`], about one voxel of
    /// error, closed meshes only). With `band > 0` the report also gives the memory a
    /// narrow band of `band` cells would take against the dense grid (the file is dense).
    Grid {
        /// Cells along the longest axis ([`SAMPLING_RESOLUTION`]).
        res: u32,
        /// Padding around the bounding box, cells.
        margin: u32,
        /// How the grid is filled.
        fill: GridFill,
        /// Half-width of the narrow band reported on, cells; 0: no report.
        band: u32,
    },
    /// A scene's bounded objects extracted from their SDFs into one triangle mesh, `res`
    /// cells along each object's longest axis.
    Mesh {
        /// Cells along each object's longest axis ([`EXTRACTION_RESOLUTION`]).
        res: u32,
        /// The extraction method.
        method: ExtractMethod,
    },
    /// A mesh file decimated with meshoptimizer's quadric-error simplifier
    /// ([`crate::mesh::simplify::decimate`]).
    Decimate {
        /// How many triangles to keep.
        target: DecimateTarget,
    },
}

/// Options of `toolkit compare`.
#[derive(Clone, Debug)]
pub struct CompareOptions {
    /// Scene files and mesh files.
    pub inputs: Vec<PathBuf>,
    /// Output CSV.
    pub csv: PathBuf,
    /// Resolution sweep, each in [`GRID_RESOLUTION`].
    pub resolutions: Vec<u32>,
    /// Timed frames per run (after one warm-up frame), in [`FRAMES`].
    pub frames: u32,
    /// Skip runs already in the CSV.
    pub resume: bool,
    /// Replace an existing CSV.
    pub overwrite: bool,
    /// Image size and depth overrides (the same for every run of an input).
    pub overrides: Overrides,
    /// Sphere tracing parameters of the grid and mesh runs (and the defaults of the others:
    /// the reference and the SDF sweep change only `tolerance_px` and `relaxation`).
    pub march: MarchParams,
    /// The SDF sweep's hit tolerances, pixels: one `sdf/sphere-trace` run per pair of these
    /// and `sdf_relaxations`.
    pub sdf_tolerances_px: Vec<f64>,
    /// The SDF sweep's over-relaxation factors.
    pub sdf_relaxations: Vec<f64>,
    /// Written to every row's `replicate` column (and part of the resume key).
    pub replicate: u32,
    /// Shuffle each input's runs after the reference with this seed
    /// (compare's `run_order`); `None`: the planned order.
    pub order_seed: Option<u64>,
    /// Half-width of narrow-band grids, cells, in [`BAND_CELLS`].
    pub band_cells: u32,
    /// Decimations of mesh inputs: one `mesh/decimated-T` run each (deduplicated; empty
    /// with `--no-decimate`).
    pub decimate: Vec<DecimateTarget>,
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
    /// `--search`: the largest resolution the search of each knob family tries (in
    /// [`GRID_RESOLUTION`]); `None`: the fixed lists (`resolutions`, `decimate`,
    /// `sdf_tolerances_px`) instead.
    pub search_max_res: Option<u32>,
}

/// Options of `toolkit compare --duel` (the study's paired, interleaved re-timing).
#[derive(Clone, Debug)]
pub struct DuelOptions {
    /// Labels of the planned runs to re-time (at least one, none empty).
    pub runs: Vec<String>,
    /// Rounds, in [`ROUNDS`].
    pub rounds: u32,
}

/// `--rounds` of a duel.
pub const ROUNDS: FlagRange = FlagRange { min: 1, max: 1000, of: "" };

/// Options of `toolkit compare --scaling`.
#[derive(Clone, Debug)]
pub struct ScalingOptions {
    /// Primitive counts, each in [`COUNTS`].
    pub counts: Vec<u32>,
    /// Timed frames per run, in [`FRAMES`].
    pub frames: u32,
    /// Resolution of the mesh and grid representations (in both ranges).
    pub resolution: u32,
    /// Image size and depth overrides (default 320 x 240, depth 1).
    pub overrides: Overrides,
    /// Sphere tracing parameters.
    pub march: MarchParams,
}

/// A validated command: what `main.rs` runs.
#[derive(Clone, Debug)]
pub enum Task {
    /// `toolkit render`.
    Render(RenderOptions),
    /// `toolkit convert`.
    Convert {
        /// Mesh file (to a grid) or scene file (to a mesh).
        input: PathBuf,
        /// Output file; its extension picks the format.
        output: PathBuf,
        /// What to produce.
        target: ConvertTarget,
    },
    /// `toolkit compare`.
    Compare(CompareOptions),
    /// `toolkit compare --summarize`: the summary of the rows already in `--csv`.
    Summarize(CompareOptions),
    /// `toolkit compare --duel`: the compare flags plan the runs the duel picks from.
    Duel {
        /// The compare options (one input).
        options: CompareOptions,
        /// The runs and rounds.
        duel: DuelOptions,
    },
    /// `toolkit compare --check-reference`: the compare flags plan the reference checked.
    CheckReference(CompareOptions),
    /// `toolkit compare --scaling`.
    Scaling {
        /// The experiment's options.
        options: ScalingOptions,
        /// Output CSV.
        csv: PathBuf,
    },
    /// `toolkit hard`.
    Hard {
        /// The manifest.
        manifest: PathBuf,
        /// Also write the table here.
        table: Option<PathBuf>,
    },
    /// `toolkit gallery`.
    Gallery {
        /// Folder of scene files.
        scenes: PathBuf,
        /// Output folder.
        output: PathBuf,
        /// The representations, in [`ReprKind::ALL`]'s order (each checked).
        reprs: Vec<Representation>,
        /// Setting overrides.
        overrides: Overrides,
    },
}

impl Task {
    /// Validates `command`'s flags (the one place where they are checked) and returns the
    /// command with its options; `budget` is the memory budget of `--max-memory`.
    ///
    /// # Errors
    /// [`Error::Usage`] (one line, exit code 2) for the first flag out of its range.
    pub fn new(command: Command, budget: MemoryBudget) -> Result<Task> {
        Ok(match command {
            Command::Render { scene, output, repr, mesh, primary, settings, march, heightmap } => {
                let repr = representation(repr, &mesh, march_params(&march, MarchParams::default().epsilon))?;
                let primary = match primary {
                    Primary::Trace => PrimaryVisibility::Trace,
                    Primary::Raster if repr.kind() == ReprKind::Mesh => PrimaryVisibility::Raster,
                    Primary::Raster => {
                        return Err(Error::Usage(format!(
                            "--primary raster needs --repr mesh (the rasterizer draws triangle meshes), not --repr {}",
                            repr.name()
                        )));
                    }
                };
                let is_vm = scene.extension().is_some_and(|e| e.eq_ignore_ascii_case("vm"));
                if heightmap.is_some() && (!is_vm || repr.kind() != ReprKind::Analytic) {
                    return Err(Error::Usage(format!(
                        "--heightmap needs a 3D implicit model (.vm) rendered directly (no --repr), not {} as {}",
                        scene.display(),
                        repr.name()
                    )));
                }
                Task::Render(RenderOptions {
                    scene,
                    output,
                    repr,
                    primary,
                    overrides: overrides(&settings)?,
                    shading: shading(&mesh),
                    budget,
                    heightmap,
                })
            }
            Command::Convert { input, output, to, res, margin, method, fill, band, decimate } => {
                let target = match (to, decimate) {
                    (Target::Grid, Some(r)) => {
                        return Err(Error::Usage(format!(
                            "--decimate {r} needs --to mesh (a mesh file to decimate)"
                        )));
                    }
                    (Target::Mesh, Some(target)) => ConvertTarget::Decimate { target },
                    (Target::Grid, None) => ConvertTarget::Grid {
                        res: SAMPLING_RESOLUTION.check("--res", res)?,
                        margin,
                        fill,
                        band,
                    },
                    (Target::Mesh, None) => {
                        ConvertTarget::Mesh { res: EXTRACTION_RESOLUTION.check("--res", res)?, method }
                    }
                };
                Task::Convert { input, output, target }
            }
            Command::Compare { scaling: true, csv, frames, counts, scaling_res, settings, march, .. } => {
                if counts.is_empty() {
                    return Err(Error::Usage("--counts needs at least one count".into()));
                }
                for &c in &counts {
                    COUNTS.check("--counts", c)?;
                }
                FRAMES.check("--frames", frames)?;
                let march = march_params(&march, MarchParams::default().epsilon);
                check_march(&march)?;
                // Both the mesh and the grid representation are run at `scaling_res`.
                MESH_RESOLUTION.check("--scaling-res", scaling_res)?;
                GRID_RESOLUTION.check("--scaling-res", scaling_res)?;
                let options = ScalingOptions {
                    counts,
                    frames,
                    resolution: scaling_res,
                    overrides: overrides(&settings)?,
                    march,
                };
                Task::Scaling { options, csv }
            }
            Command::Compare {
                inputs,
                csv,
                res,
                frames,
                resume,
                overwrite,
                band,
                decimate,
                no_decimate,
                summary_json,
                artifacts,
                surface_samples,
                sdf_tolerance_px,
                sdf_relax,
                replicate,
                order_seed,
                search,
                search_max_res,
                scaling: false,
                counts: _,
                scaling_res: _,
                quiet,
                duel,
                rounds,
                check_reference,
                summarize,
                settings,
                march,
            } => {
                FRAMES.check("--frames", frames)?;
                if res.is_empty() {
                    return Err(Error::Usage("--res needs at least one resolution".into()));
                }
                for &r in &res {
                    GRID_RESOLUTION.check("--res", r)?;
                }
                let march = march_params(&march, COMPARE_EPSILON);
                check_march(&march)?;
                BAND_CELLS.check("--band", band)?;
                let search_max_res = match search {
                    true => Some(GRID_RESOLUTION.check("--search-max-res", search_max_res)?),
                    false => None,
                };
                if sdf_tolerance_px.is_empty() || sdf_relax.is_empty() {
                    return Err(Error::Usage(
                        "--sdf-tolerance-px and --sdf-relax need at least one value each".into(),
                    ));
                }
                for &tolerance_px in &sdf_tolerance_px {
                    for &relaxation in &sdf_relax {
                        check_march(&MarchParams { tolerance_px, relaxation, ..march })
                            .map_err(|e| Error::Usage(format!("--sdf-tolerance-px/--sdf-relax: {e}")))?;
                    }
                }
                let options = CompareOptions {
                    inputs,
                    csv,
                    resolutions: res,
                    frames,
                    resume,
                    overwrite,
                    overrides: overrides(&settings)?,
                    march,
                    sdf_tolerances_px: sdf_tolerance_px,
                    sdf_relaxations: sdf_relax,
                    replicate,
                    order_seed,
                    band_cells: band,
                    decimate: if no_decimate {
                        Vec::new()
                    } else {
                        let mut unique: Vec<DecimateTarget> = Vec::new();
                        for t in decimate {
                            if !unique.contains(&t) {
                                unique.push(t);
                            }
                        }
                        unique
                    },
                    summary_json,
                    artifacts,
                    surface_samples,
                    progress: !quiet,
                    budget,
                    search_max_res,
                };
                if summarize {
                    Task::Summarize(options)
                } else if check_reference {
                    if options.inputs.len() != 1 {
                        return Err(Error::Usage(format!(
                            "--check-reference checks one input, got {} inputs",
                            options.inputs.len()
                        )));
                    }
                    Task::CheckReference(options)
                } else if duel.is_empty() {
                    Task::Compare(options)
                } else {
                    if options.inputs.len() != 1 {
                        return Err(Error::Usage(format!(
                            "--duel re-times runs of one input, got {} inputs",
                            options.inputs.len()
                        )));
                    }
                    if let Some(bad) = duel.iter().find(|l| l.trim().is_empty()) {
                        return Err(Error::Usage(format!("--duel has an empty run label `{bad}`")));
                    }
                    ROUNDS.check("--rounds", rounds)?;
                    Task::Duel { options, duel: DuelOptions { runs: duel, rounds } }
                }
            }
            Command::Hard { manifest, table } => Task::Hard { manifest, table },
            Command::Gallery { scenes, output, mesh, settings, march } => {
                let march = march_params(&march, MarchParams::default().epsilon);
                let reprs = ReprKind::ALL
                    .iter()
                    .map(|&k| representation(k, &mesh, march))
                    .collect::<Result<Vec<_>>>()?;
                Task::Gallery { scenes, output, reprs, overrides: overrides(&settings)? }
            }
        })
    }
}

/// The sphere tracing parameters of the flags, with `epsilon` where `--epsilon` is not
/// given (unchecked: [`check_march`]).
fn march_params(m: &MarchArgs, epsilon: f64) -> MarchParams {
    MarchParams {
        epsilon: m.epsilon.unwrap_or(epsilon),
        tolerance_px: m.tolerance_px,
        max_steps: m.max_steps,
        relaxation: m.relax,
        ..MarchParams::default()
    }
}

/// `--smooth`: the shading of meshes.
fn shading(mesh: &MeshArgs) -> Shading {
    if mesh.smooth { Shading::Smooth } else { Shading::Flat }
}

/// `--width`, `--height`, `--depth`, checked.
fn overrides(s: &SettingArgs) -> Result<Overrides> {
    Ok(Overrides::new(s.width, s.height, s.depth)?.with_layout(s.layout))
}

/// `--repr KIND` with the mesh flags and `march`, checked ([`check_representation`]).
fn representation(kind: ReprKind, mesh: &MeshArgs, march: MarchParams) -> Result<Representation> {
    let resolution = mesh.res;
    let repr = match kind {
        ReprKind::Analytic => Representation::Analytic { march },
        ReprKind::Sdf => Representation::Sdf { march },
        ReprKind::Mesh => Representation::Mesh {
            resolution,
            shading: shading(mesh),
            method: MeshMethod::Parametric,
            plane: mesh.plane,
            march,
        },
        // `--band K`: 0 stores every sample, else a narrow band of K cells; with
        // `--scene-grid` (clap makes it need `--band`) one band shared by the objects.
        ReprKind::Grid => Representation::Grid {
            resolution,
            fill: mesh.fill,
            storage: match (mesh.band, mesh.scene_grid) {
                (0, _) => GridStorage::Dense,
                (cells, false) => GridStorage::Band { cells },
                (cells, true) => GridStorage::Scene { cells },
            },
            march,
        },
    };
    check_representation(&repr, "--res")?;
    Ok(repr)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_name_the_flag_and_the_bounds() {
        assert_eq!(GRID_RESOLUTION.check("--res", 2).unwrap(), 2);
        assert_eq!(GRID_RESOLUTION.check("--res", 1024).unwrap(), 1024);
        let e = GRID_RESOLUTION.check("--res", 1025).unwrap_err().to_string();
        assert!(e.contains("--res must be between 2 and 1024 for grids, got 1025"), "{e}");
        let e = MESH_RESOLUTION.check("--res", 2).unwrap_err().to_string();
        assert!(e.contains("--res must be between 3 and 8192, got 2"), "{e}");
        let e = SAMPLING_RESOLUTION.check("--res", 0).unwrap_err().to_string();
        assert!(e.contains("--res must be at least 1, got 0"), "{e}");
        let e = DEPTH.check("--depth", 101).unwrap_err().to_string();
        assert!(e.contains("--depth must be at most 100, got 101"), "{e}");
        assert!(matches!(FRAMES.check("--frames", 0), Err(Error::Usage(_))));
    }

    #[test]
    fn the_stated_rules_map_valid_resolutions() {
        assert_eq!(sweep_mesh_resolution(GRID_RESOLUTION.min), MESH_RESOLUTION.min);
        assert_eq!(sweep_mesh_resolution(64), 64);
        assert_eq!(crate::plan::extract_resolution(MESH_RESOLUTION.max), MAX_EXTRACT_RESOLUTION);
        assert_eq!(crate::plan::extract_resolution(100), 100);
    }

    #[test]
    fn overrides_are_checked_when_made_and_applied_as_given() {
        assert!(Overrides::new(Some(0), None, None).is_err());
        assert!(Overrides::new(None, Some(IMAGE_EDGE.max + 1), None).is_err());
        assert!(Overrides::new(None, None, Some(DEPTH.max + 1)).is_err());
        let o = Overrides::new(Some(64), None, Some(0)).unwrap();
        assert_eq!((o.width(), o.height(), o.depth()), (Some(64), None, Some(0)));
        assert_eq!(Overrides::default(), Overrides::NONE);
    }
}
