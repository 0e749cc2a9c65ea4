//! `toolkit`: parses the command line, calls the library, maps errors to exit codes.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand, ValueEnum};
use sdfmesh::cli::commands::{self, ConvertTarget, Overrides};
use sdfmesh::convert::extract::ExtractMethod;
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::plan::budget::MemoryBudget;
use sdfmesh::plan::{GridFill, GridStorage, MeshMethod, Representation};
use sdfmesh::scene::shape::Shading;

#[derive(Parser)]
#[command(
    name = "toolkit",
    version,
    about = "Ray marching SDFs versus ray tracing meshes: render, convert, compare"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Memory a request may use, e.g. 4GiB or 512MB (default: half of physical memory; at
    /// most all of it).
    /// Grids, extractions and meshes that would need more fail at once, before any work.
    #[arg(long, global = true, value_name = "SIZE")]
    max_memory: Option<MemoryBudget>,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene file, or a mesh file (OBJ, glTF, GLB, PLY, STL) or a signed distance
    /// grid file (.sdf, .npy) framed by a default camera and lights, to a PNG with one
    /// representation.
    #[command(allow_negative_numbers = true)]
    Render {
        /// Scene file (TOML, see docs/scene-format.md) or mesh file.
        scene: PathBuf,
        /// Output PNG.
        #[arg(short, long)]
        output: PathBuf,
        /// Representation of the objects.
        #[arg(long, value_enum, default_value_t = Repr::Analytic)]
        repr: Repr,
        #[command(flatten)]
        mesh: MeshArgs,
        #[command(flatten)]
        settings: SettingArgs,
        #[command(flatten)]
        march: MarchArgs,
    },
    /// Convert a mesh file (OBJ, glTF, GLB, PLY, STL) to a signed distance grid (.sdf, .npy,
    /// .vti), or a scene file's SDF objects to a triangle mesh (.obj, .ply, .glb).
    #[command(allow_negative_numbers = true)]
    Convert {
        /// Mesh file (--to grid) or scene file (--to mesh).
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
        #[arg(long, value_enum, default_value_t = Method::Mc)]
        method: Method,
        /// How the grid is filled (--to grid).
        #[arg(long, value_enum, default_value_t = Fill::Sample)]
        fill: Fill,
        /// Also report the memory a narrow band of K cells would take against the dense
        /// grid (--to grid; 0 = no report). The written file is always dense.
        #[arg(long, default_value_t = 0)]
        band: u32,
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
        #[arg(long, value_delimiter = ',', default_values_t = sdfmesh::compare::DEFAULT_RESOLUTIONS)]
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
        #[arg(long, value_delimiter = ',', default_values_t = sdfmesh::compare::DEFAULT_SDF_TOLERANCES_PX)]
        sdf_tolerance_px: Vec<f64>,
        /// Over-relaxation factors of the SDF sweep, comma-separated, each in [1, 2).
        #[arg(long, value_delimiter = ',', default_values_t = sdfmesh::compare::DEFAULT_SDF_RELAXATIONS)]
        sdf_relax: Vec<f64>,
        /// Replicate number written to every row (part of the --resume key): run the whole
        /// experiment K times into one CSV to see run-to-run variation.
        #[arg(long, default_value_t = 0)]
        replicate: u32,
        /// Shuffle each input's runs after the reference with this seed (deterministic), so
        /// that replicates interleave the representations differently.
        #[arg(long)]
        order_seed: Option<u64>,
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
        #[command(flatten)]
        settings: SettingArgs,
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
        #[command(flatten)]
        mesh: MeshArgs,
        #[command(flatten)]
        settings: SettingArgs,
        #[command(flatten)]
        march: MarchArgs,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum Repr {
    /// Closed-form intersection where it exists (CSG and repetition are sphere traced).
    Analytic,
    /// Sphere tracing of the analytic signed distance functions.
    Sdf,
    /// Primitives tessellated at --res and ray traced as triangle meshes.
    Mesh,
    /// Objects sampled into signed distance grids of --res cells and ray marched.
    Grid,
}

#[derive(Clone, Copy, ValueEnum)]
enum Target {
    /// A signed distance grid sampled from a mesh (exact distances, winding-number signs).
    Grid,
    /// A triangle mesh extracted from a scene's signed distance functions.
    Mesh,
}

#[derive(Clone, Copy, ValueEnum)]
enum Method {
    /// Marching cubes (asymptotic decider on ambiguous faces): always closed and manifold.
    Mc,
    /// Marching tetrahedra: always closed and manifold, about three times the triangles.
    Mt,
    /// Dual contouring with a QEF: keeps sharp edges.
    Dc,
}

#[derive(Clone, Copy, ValueEnum)]
enum Fill {
    /// Exact distance to the nearest triangle at every sample, sign from the winding number.
    Sample,
    /// Rasterize the surface, flood fill the outside, Euclidean distance transform
    /// (fast, about one voxel of error; closed meshes only).
    Voxelize,
}

impl Fill {
    fn grid_fill(self) -> GridFill {
        match self {
            Fill::Sample => GridFill::Sample,
            Fill::Voxelize => GridFill::Voxelize,
        }
    }
}

/// `--band K`: 0 is dense storage, else a narrow band of K cells.
fn grid_storage(band: u32) -> GridStorage {
    if band == 0 { GridStorage::Dense } else { GridStorage::Band { cells: band } }
}

#[derive(Args)]
struct MeshArgs {
    /// Resolution for --repr mesh (segments around the largest circle) and --repr grid
    /// (cells along each object's longest axis).
    #[arg(long, default_value_t = 64)]
    res: u32,
    /// Interpolate vertex normals of meshes (tessellated primitives and mesh files given
    /// instead of a scene); default flat.
    #[arg(long)]
    smooth: bool,
    /// How --repr grid fills mesh objects' grids (analytic objects are always sampled).
    #[arg(long, value_enum, default_value_t = Fill::Sample)]
    fill: Fill,
    /// --repr grid storage: 0 stores every sample (dense); K > 0 stores only 8x8x8-cell
    /// bricks within K cells of the surface (a distance bound elsewhere).
    #[arg(long, default_value_t = 0)]
    band: u32,
    /// --repr grid with --band K: one narrow band shared by every object gridded whole, on
    /// one world lattice at the median of the objects' own voxel sizes.
    #[arg(long, requires = "band")]
    scene_grid: bool,
}

impl MeshArgs {
    fn shading(&self) -> Shading {
        if self.smooth { Shading::Smooth } else { Shading::Flat }
    }
}

fn representation(repr: Repr, mesh: &MeshArgs, march: MarchParams) -> Representation {
    match repr {
        Repr::Analytic => Representation::Analytic { march },
        Repr::Sdf => Representation::Sdf { march },
        Repr::Mesh => Representation::Mesh {
            resolution: mesh.res,
            shading: mesh.shading(),
            method: MeshMethod::Parametric,
            march,
        },
        Repr::Grid => Representation::Grid {
            resolution: mesh.res,
            fill: mesh.fill.grid_fill(),
            storage: match grid_storage(mesh.band) {
                GridStorage::Band { cells } if mesh.scene_grid => GridStorage::Scene { cells },
                s => s,
            },
            march,
        },
    }
}

#[derive(Args)]
struct SettingArgs {
    /// Image width in pixels (overrides the scene).
    #[arg(long)]
    width: Option<u32>,
    /// Image height in pixels (overrides the scene).
    #[arg(long)]
    height: Option<u32>,
    /// Maximum reflection/refraction depth (overrides the scene).
    #[arg(long)]
    depth: Option<u32>,
}

#[derive(Args)]
struct MarchArgs {
    /// Over-relaxation factor for sphere tracing, in [1, 2); 1 = plain sphere tracing.
    #[arg(long, default_value_t = 1.0)]
    relax: f64,
    /// Relative hit tolerance of sphere tracing (times the distance travelled; the tolerance
    /// is the smaller of this and --tolerance-px) [default: 1e-4; compare: 0.5, so that the
    /// pixel tolerance is the knob]
    #[arg(long)]
    epsilon: Option<f64>,
    /// Largest hit tolerance of sphere tracing, in pixels at the hit's distance (the SDF
    /// side's quality knob).
    #[arg(long, default_value_t = 0.25)]
    tolerance_px: f64,
    /// Step limit per sphere-traced ray.
    #[arg(long, default_value_t = 512)]
    max_steps: u32,
}

impl SettingArgs {
    fn overrides(&self) -> Overrides {
        Overrides { width: self.width, height: self.height, depth: self.depth }
    }
}

impl MarchArgs {
    fn params(&self) -> MarchParams {
        self.params_or_epsilon(MarchParams::default().epsilon)
    }

    /// The parameters, with `epsilon` where --epsilon is not given.
    fn params_or_epsilon(&self, epsilon: f64) -> MarchParams {
        MarchParams {
            epsilon: self.epsilon.unwrap_or(epsilon),
            tolerance_px: self.tolerance_px,
            max_steps: self.max_steps,
            relaxation: self.relax,
            ..MarchParams::default()
        }
    }
}

impl Command {
    /// The files this command reads and the files it writes, as the command line names
    /// them (`compare`'s default inputs where it names none; `gallery` writes
    /// `NAME.REPR.png` files of its own naming and has none here).
    fn files(&self) -> (Vec<PathBuf>, Vec<&Path>) {
        match self {
            Command::Render { scene, output, .. } => (vec![scene.clone()], vec![output]),
            Command::Convert { input, output, .. } => (vec![input.clone()], vec![output]),
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

fn main() -> ExitCode {
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
    // `compare` without inputs (and without --scaling) runs every bundled scene: found once,
    // here, so that the checks below see them.
    if let Command::Compare { inputs, scaling: false, .. } = &mut cli.command
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
    let result = match cli.command {
        Command::Render { scene, output, repr, mesh, settings, march } => {
            let opts = commands::RenderOptions {
                scene,
                output,
                repr: representation(repr, &mesh, march.params()),
                overrides: settings.overrides(),
                shading: mesh.shading(),
                budget,
            };
            commands::render_command(&opts).map(|r| print!("{}", r.text))
        }
        Command::Convert { input, output, to, res, margin, method, fill, band } => {
            let target = match to {
                Target::Grid => ConvertTarget::Grid { res, margin, fill: fill.grid_fill(), band },
                Target::Mesh => ConvertTarget::Mesh {
                    res,
                    method: match method {
                        Method::Mc => ExtractMethod::MarchingCubes,
                        Method::Mt => ExtractMethod::MarchingTetrahedra,
                        Method::Dc => ExtractMethod::DualContouring,
                    },
                },
            };
            commands::convert_command(&input, &output, target, budget).map(|t| print!("{t}"))
        }
        Command::Compare {
            inputs,
            csv,
            res,
            frames,
            resume,
            overwrite,
            band,
            summary_json,
            artifacts,
            surface_samples,
            sdf_tolerance_px,
            sdf_relax,
            replicate,
            order_seed,
            scaling,
            counts,
            scaling_res,
            quiet,
            settings,
            march,
        } => {
            if scaling {
                let opts = sdfmesh::compare::scaling::ScalingOptions {
                    counts,
                    frames,
                    resolution: scaling_res,
                    overrides: settings.overrides(),
                    march: march.params(),
                };
                sdfmesh::compare::scaling::scaling_command(&opts, &csv).map(|t| print!("{t}"))
            } else {
                sdfmesh::compare::compare_command(&sdfmesh::compare::CompareOptions {
                    inputs,
                    csv,
                    resolutions: res,
                    frames,
                    resume,
                    overwrite,
                    overrides: settings.overrides(),
                    march: march.params_or_epsilon(sdfmesh::compare::COMPARE_EPSILON),
                    sdf_tolerances_px: sdf_tolerance_px,
                    sdf_relaxations: sdf_relax,
                    replicate,
                    order_seed,
                    band_cells: band,
                    summary_json,
                    artifacts,
                    surface_samples,
                    progress: !quiet,
                    budget,
                })
                .map(|t| print!("{t}"))
            }
        }
        Command::Hard { manifest, table } => {
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
        Command::Gallery { scenes, output, mesh, settings, march } => {
            let reprs: Vec<Representation> = [Repr::Analytic, Repr::Sdf, Repr::Mesh, Repr::Grid]
                .map(|r| representation(r, &mesh, march.params()))
                .into();
            commands::gallery_command(&scenes, &output, &reprs, settings.overrides(), budget)
                .map(|t| print!("{t}"))
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
