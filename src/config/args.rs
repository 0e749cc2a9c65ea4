//! The command line as clap parses it: raw values, unchecked (ripgrep's low-level
//! arguments). [`super::Task::new`] turns a [`Command`] into the validated options the
//! commands take; nothing else reads these types but `main.rs`, which parses them and
//! checks the files they name.

use std::path::{Path, PathBuf};

use clap::{Args, Parser, Subcommand, ValueEnum};

use crate::convert::extract::ExtractMethod;
use crate::mesh::simplify::DecimateTarget;
use crate::plan::budget::MemoryBudget;
use crate::plan::{GridFill, MeshPlane, ReprKind};
use crate::scene::shape::MeshLayout;

/// The `toolkit` command line.
#[derive(Parser)]
#[command(
    name = "toolkit",
    version,
    about = "Ray marching SDFs versus ray tracing meshes: render, convert, compare"
)]
pub struct Cli {
    /// The subcommand and its arguments.
    #[command(subcommand)]
    pub command: Command,
    /// Memory a request may use, e.g. 4GiB or 512MB (default: half of physical memory; at
    /// most all of it).
    /// Grids, extractions and meshes that would need more fail at once, before any work.
    #[arg(long, global = true, value_name = "SIZE")]
    pub max_memory: Option<MemoryBudget>,
}

/// A subcommand and its raw arguments (each variant's doc comment is its `--help`).
// Parsed once per process and moved, never stored in bulk: the size of `Compare` costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
pub enum Command {
    /// Render a scene file, or a mesh file (OBJ, glTF, GLB, PLY, STL) or a signed distance
    /// grid file (.sdf, .npy) framed by a default camera and lights, to a PNG with one
    /// representation; or a 2D implicit model (.vm without var-z) as the Prospero challenge's
    /// image of [-1, 1]^2 (white where negative, 1024 x 1024 unless --width/--height).
    #[command(allow_negative_numbers = true)]
    Render {
        /// Scene file (TOML, see docs/scene-format.md) or mesh file.
        scene: PathBuf,
        /// Output PNG.
        #[arg(short, long)]
        output: PathBuf,
        /// Representation of the objects.
        #[arg(long, value_enum, default_value_t = ReprKind::Analytic)]
        repr: ReprKind,
        /// The mesh and grid representations' flags.
        #[command(flatten)]
        mesh: MeshArgs,
        /// Primary visibility: traced, or (with --repr mesh) the triangle meshes rasterized
        /// by the z-buffer rasterizer and shaded by the same tracer.
        #[arg(long, value_enum, default_value_t = Primary::Trace)]
        primary: Primary,
        /// Overrides of the scene's settings.
        #[command(flatten)]
        settings: SettingArgs,
        /// Sphere tracing flags.
        #[command(flatten)]
        march: MarchArgs,
        /// With a 3D implicit model (.vm): render instead the view Fidget's voxel renderer
        /// makes, the cube [-1, 1]^3 seen from +z (orthographic, pixel centres x = -1 +
        /// (2j+1)/W, y = 1 - (2i+1)/H, 512 x 512 unless --width/--height): the height of the
        /// first surface from above as a 16-bit PNG to this path (0: none, else
        /// round((z+1)/2 * 65535)), its unit normal as RGB (n * 127.5 + 127.5) to --output.
        #[arg(long, value_name = "DEPTH_PNG")]
        heightmap: Option<PathBuf>,
    },
    /// Convert a mesh file (OBJ, glTF, GLB, PLY, STL) to a signed distance grid (.sdf, .npy,
    /// .vti), a scene file's SDF objects to a triangle mesh (.obj, .ply, .glb), or a mesh
    /// file to a decimated mesh (--to mesh --decimate R).
    #[command(allow_negative_numbers = true)]
    Convert {
        /// Mesh file (--to grid, --decimate) or scene file (--to mesh).
        input: PathBuf,
        /// Output file; its extension picks the format.
        #[arg(short, long)]
        output: PathBuf,
        /// What to produce.
        #[arg(long, value_enum)]
        to: Target,
        /// Cells along the longest axis of the bounding box.
        #[arg(long, default_value_t = 128)]
        res: u32,
        /// Grid padding around the mesh's bounding box, in cells (--to grid).
        #[arg(long, default_value_t = 2)]
        margin: u32,
        /// Extraction method (--to mesh): marching cubes, marching tetrahedra (both watertight)
        /// or dual contouring.
        #[arg(long, value_enum, default_value_t = ExtractMethod::MarchingCubes)]
        method: ExtractMethod,
        /// How the grid is filled (--to grid).
        #[arg(long, value_enum, default_value_t = GridFill::Sample)]
        fill: GridFill,
        /// Also report the memory a narrow band of K cells would take against the dense
        /// grid (--to grid; 0 = no report). The written file is always dense.
        #[arg(long, default_value_t = 0)]
        band: u32,
        /// Decimate a mesh file instead (--to mesh) with meshoptimizer's quadric-error
        /// simplifier, keeping R of its triangles: a ratio in (0, 1], a percentage (25%) or
        /// a triangle count (an integer of at least 2).
        #[arg(long, value_name = "R")]
        decimate: Option<DecimateTarget>,
    },
    /// Render scenes and meshes in every representation across a resolution sweep (sphere
    /// tracing across --sdf-tolerance-px and --sdf-relax) and write one CSV row per run
    /// (error, quality level, frame time, build time, bytes; schema in the README), then print
    /// which representation is fastest and smallest at each quality level.
    #[command(allow_negative_numbers = true)]
    Compare {
        /// Scene files and mesh files, with different stems (default: every scene under
        /// data/scenes, recursively, and ../shared/meshes/stanford-bunny.obj where it exists).
        inputs: Vec<PathBuf>,
        /// Output CSV (rows are appended and flushed as each run finishes).
        #[arg(long)]
        csv: PathBuf,
        /// Resolution sweep, comma-separated.
        #[arg(long, value_delimiter = ',', default_values_t = super::DEFAULT_RESOLUTIONS)]
        res: Vec<u32>,
        /// Timed frames per run, after one warm-up frame.
        #[arg(long, default_value_t = 5)]
        frames: u32,
        /// Skip the runs already in the CSV and append the rest. The CSV is locked for the
        /// whole run: with --resume a CSV another compare is writing is waited for, then
        /// appended to; without it such a CSV is refused at once (exit 2).
        #[arg(long)]
        resume: bool,
        /// Replace an existing CSV (never one another process is writing).
        #[arg(long, conflicts_with = "resume")]
        overwrite: bool,
        /// Half-width of narrow-band grids, in cells.
        #[arg(long, default_value_t = 3)]
        band: u32,
        /// Decimations of each mesh input, comma-separated, each a run `mesh/decimated-T`
        /// (meshoptimizer's quadric-error simplifier): ratios in (0, 1], percentages (25%)
        /// or triangle counts (integers of at least 2).
        #[arg(long, value_delimiter = ',', value_name = "R", default_values_t = super::DEFAULT_DECIMATIONS)]
        decimate: Vec<DecimateTarget>,
        /// No decimated runs of mesh inputs.
        #[arg(long, conflicts_with = "decimate")]
        no_decimate: bool,
        /// Also write the summary as JSON.
        #[arg(long)]
        summary_json: Option<PathBuf>,
        /// Save each run's render (and meshes and grids up to resolution 64) in this folder.
        #[arg(long)]
        artifacts: Option<PathBuf>,
        /// Surface points sampled per side for the Chamfer and Hausdorff distances.
        #[arg(long, default_value_t = 20_000)]
        surface_samples: usize,
        /// Hit tolerances of the SDF sweep, pixels, comma-separated: one sdf/sphere-trace run
        /// per tolerance and --sdf-relax factor (grid and mesh runs use --tolerance-px).
        #[arg(long, value_delimiter = ',', default_values_t = super::DEFAULT_SDF_TOLERANCES_PX)]
        sdf_tolerance_px: Vec<f64>,
        /// Over-relaxation factors of the SDF sweep, comma-separated, each in [1, 2).
        #[arg(long, value_delimiter = ',', default_values_t = super::DEFAULT_SDF_RELAXATIONS)]
        sdf_relax: Vec<f64>,
        /// Replicate number written to every row (part of the --resume key): run the whole
        /// experiment K times into one CSV to see run-to-run variation.
        #[arg(long, default_value_t = 0)]
        replicate: u32,
        /// Shuffle each input's runs after the reference with this seed (deterministic), so
        /// that replicates interleave the representations differently.
        #[arg(long)]
        order_seed: Option<u64>,
        /// Search each knob family to the quality levels instead of the fixed lists (--res,
        /// --decimate, --sdf-tolerance-px): resolutions double from 8 until a run meets the
        /// next level, the memory budget or --search-max-res stops them, then bisect; the
        /// decimation fraction likewise; the hit tolerance halves from 2 px, per --sdf-relax.
        #[arg(long, conflicts_with = "scaling")]
        search: bool,
        /// The largest resolution --search tries.
        #[arg(long, requires = "search", default_value_t = super::GRID_RESOLUTION.max)]
        search_max_res: u32,
        /// Run the coursework's scaling experiment instead: frame time against the number of
        /// spheres, cubes, cylinders and cones (image 320x240 unless --width/--height).
        #[arg(long)]
        scaling: bool,
        /// Primitive counts of the scaling experiment, comma-separated.
        #[arg(long, value_delimiter = ',', default_values_t = [10, 20, 30, 40, 50, 60, 70, 80, 90, 100])]
        counts: Vec<u32>,
        /// Resolution of the mesh and grid representations in the scaling experiment.
        #[arg(long, default_value_t = 32)]
        scaling_res: u32,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
        /// Re-time these planned runs of the one input instead, paired and interleaved
        /// (comma-separated labels `repr/method[/resolution][@tolerance:relaxation]`, e.g.
        /// `sdf/sphere-trace@1:1.6,mesh/extracted/32`), --rounds rounds, one frame of each
        /// per round, and write one row per frame to --csv (the duel schema in the README).
        #[arg(long, value_delimiter = ',', value_name = "RUNS", conflicts_with_all = ["scaling", "resume"])]
        duel: Vec<String>,
        /// Rounds of a --duel.
        #[arg(long, default_value_t = 15, requires = "duel")]
        rounds: u32,
        /// Check the one input's reference instead: its primary hits against f64 root finding
        /// on the object trees (no tape, no SIMD, no pruning), one row to --csv.
        #[arg(long, conflicts_with_all = ["scaling", "resume", "duel"])]
        check_reference: bool,
        /// Summarise the rows already in --csv instead (every input and replicate in it: per
        /// quality level the fastest and smallest run, as compare prints at its end), to stdout
        /// and --summary-json; nothing is run, the inputs are not read and --csv is only read.
        #[arg(long, conflicts_with_all = ["scaling", "resume", "duel", "check_reference", "overwrite", "search"])]
        summarize: bool,
        /// Overrides of the scene's settings.
        #[command(flatten)]
        settings: SettingArgs,
        /// Sphere tracing flags.
        #[command(flatten)]
        march: MarchArgs,
    },
    /// Run the hard-case suite: every case of a manifest (default data/hard/cases.toml) in
    /// every representation against the reference; prints a Markdown table and exits 1
    /// when an outcome is not the one the manifest expects or a case fails to run.
    Hard {
        /// The manifest.
        #[arg(default_value = "data/hard/cases.toml")]
        manifest: PathBuf,
        /// Also write the table here.
        #[arg(long)]
        table: Option<PathBuf>,
    },
    /// Render every scene of a folder in every representation into an output folder.
    #[command(allow_negative_numbers = true)]
    Gallery {
        /// Folder of scene files.
        #[arg(default_value = "data/scenes")]
        scenes: PathBuf,
        /// Output folder.
        #[arg(short, long, default_value = "reports/gallery")]
        output: PathBuf,
        /// The mesh and grid representations' flags.
        #[command(flatten)]
        mesh: MeshArgs,
        /// Overrides of the scene's settings.
        #[command(flatten)]
        settings: SettingArgs,
        /// Sphere tracing flags.
        #[command(flatten)]
        march: MarchArgs,
    },
}

/// `--primary`: how `toolkit render` finds what each pixel sees first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Primary {
    /// Primary rays traced through the BVH.
    Trace,
    /// Triangle meshes rasterized (z-buffer), everything else traced (--repr mesh only).
    Raster,
}

/// `--to`: what `toolkit convert` produces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Target {
    /// A signed distance grid sampled from a mesh (exact distances, winding-number signs).
    Grid,
    /// A triangle mesh extracted from a scene's signed distance functions.
    Mesh,
}

/// The mesh and grid representations' flags (render, gallery).
#[derive(Args)]
pub struct MeshArgs {
    /// Resolution for --repr mesh (segments around the largest circle) and --repr grid
    /// (cells along each object's longest axis).
    #[arg(long, default_value_t = 64)]
    pub res: u32,
    /// Interpolate vertex normals of meshes (tessellated primitives and mesh files given
    /// instead of a scene); default flat.
    #[arg(long)]
    pub smooth: bool,
    /// How --repr mesh traces infinite planes: in closed form, as every representation
    /// does, or as a tessellated disc around the camera out to max_distance (the other
    /// representations always use the closed form).
    #[arg(long, value_enum, default_value_t = MeshPlane::ClosedForm)]
    pub plane: MeshPlane,
    /// How --repr grid fills mesh objects' grids (analytic objects are always sampled).
    #[arg(long, value_enum, default_value_t = GridFill::Sample)]
    pub fill: GridFill,
    /// --repr grid storage: 0 stores every sample (dense); K > 0 stores only 8x8x8-cell
    /// bricks within K cells of the surface (a distance bound elsewhere).
    #[arg(long, default_value_t = 0)]
    pub band: u32,
    /// --repr grid with --band K: one narrow band shared by every object gridded whole, on
    /// one world lattice at the median of the objects' own voxel sizes.
    #[arg(long, requires = "band")]
    pub scene_grid: bool,
}

/// Overrides of the scene's settings (see [`super::Overrides`]).
#[derive(Args)]
pub struct SettingArgs {
    /// Image width in pixels (overrides the scene).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (overrides the scene).
    #[arg(long)]
    pub height: Option<u32>,
    /// Maximum reflection/refraction depth (overrides the scene).
    #[arg(long)]
    pub depth: Option<u32>,
    /// How mesh files (and scene `mesh` objects) traced as triangles store their BVH: full
    /// (f32 boxes and corners, fastest) or compact (quantised nodes, 16-bit vertices).
    #[arg(long, value_enum)]
    pub layout: Option<MeshLayout>,
}

/// Sphere tracing flags (see [`MarchParams`](crate::geometry::march::MarchParams)).
#[derive(Args)]
pub struct MarchArgs {
    /// Over-relaxation factor for sphere tracing, in [1, 2); 1 = plain sphere tracing.
    #[arg(long, default_value_t = 1.0)]
    pub relax: f64,
    /// Relative hit tolerance of sphere tracing (times the distance travelled; the tolerance
    /// is the smaller of this and --tolerance-px) [default: 1e-4; compare: 0.5, so that the
    /// pixel tolerance is the knob]
    #[arg(long)]
    pub epsilon: Option<f64>,
    /// Largest hit tolerance of sphere tracing, in pixels at the hit's distance (the SDF
    /// side's quality knob).
    #[arg(long, default_value_t = 0.25)]
    pub tolerance_px: f64,
    /// Step limit per sphere-traced ray.
    #[arg(long, default_value_t = 512)]
    pub max_steps: u32,
}

impl Command {
    /// The files this command reads and the files it writes, as the command line names
    /// them (`compare`'s default inputs where it names none; `gallery` writes
    /// `NAME.REPR.png` files of its own naming and has none here).
    pub fn files(&self) -> (Vec<PathBuf>, Vec<&Path>) {
        match self {
            Command::Render { scene, output, heightmap, .. } => (
                vec![scene.clone()],
                std::iter::once(output).chain(heightmap).map(PathBuf::as_path).collect(),
            ),
            Command::Convert { input, output, .. } => (vec![input.clone()], vec![output]),
            // --summarize reads the CSV and writes only the summary.
            Command::Compare { csv, summary_json, summarize: true, .. } => {
                (vec![csv.clone()], summary_json.iter().map(PathBuf::as_path).collect())
            }
            Command::Compare { inputs, csv, summary_json, .. } => {
                (inputs.clone(), std::iter::once(csv).chain(summary_json).map(PathBuf::as_path).collect())
            }
            Command::Hard { manifest, table } => {
                (vec![manifest.clone()], table.iter().map(PathBuf::as_path).collect())
            }
            Command::Gallery { .. } => (Vec::new(), Vec::new()),
        }
    }
}
