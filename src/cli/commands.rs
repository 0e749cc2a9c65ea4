//! The toolkit's commands as library functions: `render` (one scene, one representation),
//! `gallery` (every scene of a folder in every representation) and `convert` (mesh to SDF
//! grid, scene to mesh). `main.rs` only parses arguments into these options and maps errors
//! to exit codes.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::UVec3;

use crate::cli::progress::Stage;
use crate::convert::extract::{ExtractMethod, extract_object};
use crate::convert::mesh_to_grid::sample_mesh;
use crate::convert::mesh_to_grid::voxelize::voxelize_mesh;
use crate::error::{Error, Result, catch_panic};
use crate::geometry::Geometry;
use crate::geometry::grid::band::{BRICK, BandGrid};
use crate::geometry::grid::io::save_grid;
use crate::geometry::grid::{DEFAULT_MAX_GRID_BYTES, check_size, grid_layout};
use crate::mesh::{TriangleMesh, load_mesh, save_mesh};
use crate::plan::GridFill;
use crate::plan::budget::{MemoryBudget, check_evaluations, extraction_bytes, mesh_to_grid_bytes};
use crate::plan::{MeshMethod, Representation, build_scene, grid_file_mesh, grid_samples_per_axis};
use crate::render::{Frame, render, write_png};
use crate::scene::shape::Shading;
use crate::scene::{Scene, load_input, load_scene};

/// Overrides of a scene's settings from the command line.
#[derive(Clone, Copy, Debug, Default)]
pub struct Overrides {
    /// Image width, pixels.
    pub width: Option<u32>,
    /// Image height, pixels.
    pub height: Option<u32>,
    /// Maximum recursion depth.
    pub depth: Option<u32>,
}

/// Largest image edge accepted, pixels (the same limit as in scene files).
pub const MAX_IMAGE_EDGE: u32 = crate::scene::file::MAX_IMAGE_SIZE;
/// Largest recursion depth accepted (the same limit as in scene files).
pub const MAX_DEPTH: u32 = crate::scene::file::MAX_RECURSION_DEPTH;

impl Overrides {
    /// Applies the overrides to `scene`, rejecting absurd values.
    pub fn apply(&self, scene: &mut Scene) -> Result<()> {
        for (name, v) in [("--width", self.width), ("--height", self.height)] {
            if let Some(v) = v
                && (v == 0 || v > MAX_IMAGE_EDGE)
            {
                return Err(Error::Usage(format!("{name} must be between 1 and {MAX_IMAGE_EDGE}, got {v}")));
            }
        }
        if let Some(d) = self.depth
            && d > MAX_DEPTH
        {
            return Err(Error::Usage(format!("--depth must be at most {MAX_DEPTH}, got {d}")));
        }
        if let Some(w) = self.width {
            scene.camera.width = w;
        }
        if let Some(h) = self.height {
            scene.camera.height = h;
        }
        if let Some(d) = self.depth {
            scene.settings.max_depth = d;
        }
        Ok(())
    }
}

/// Largest tessellation resolution accepted.
pub const MAX_RESOLUTION: u32 = 8192;

/// Checks a representation's parameters given on the command line.
pub fn check_repr(repr: &Representation) -> Result<()> {
    let p = match repr {
        Representation::Analytic { march } | Representation::Sdf { march } => march,
        Representation::Grid { resolution, march, .. } => {
            if *resolution < 2 || *resolution > MAX_CONVERT_MESH_RESOLUTION {
                return Err(Error::Usage(format!(
                    "--res must be between 2 and {MAX_CONVERT_MESH_RESOLUTION} for grids, got {resolution}"
                )));
            }
            check_size(UVec3::splat(grid_samples_per_axis(*resolution)), DEFAULT_MAX_GRID_BYTES)?;
            march
        }
        Representation::Mesh { resolution, march, .. } => {
            if *resolution < 3 || *resolution > MAX_RESOLUTION {
                return Err(Error::Usage(format!(
                    "--res must be between 3 and {MAX_RESOLUTION}, got {resolution}"
                )));
            }
            march
        }
    };
    if !(1.0..2.0).contains(&p.relaxation) {
        return Err(Error::Usage(format!("--relax must be in [1, 2), got {}", p.relaxation)));
    }
    if !(p.tolerance_px > 0.0 && p.tolerance_px <= 16.0) {
        return Err(Error::Usage(format!("--tolerance-px must be in (0, 16], got {}", p.tolerance_px)));
    }
    if !(p.epsilon > 0.0 && p.epsilon < 1.0) {
        return Err(Error::Usage(format!("--epsilon must be in (0, 1), got {}", p.epsilon)));
    }
    if p.max_steps == 0 || p.max_steps > 1_000_000 {
        return Err(Error::Usage(format!("--max-steps must be between 1 and 1000000, got {}", p.max_steps)));
    }
    Ok(())
}

/// Options of `toolkit render`.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Scene file.
    pub scene: PathBuf,
    /// Output PNG.
    pub output: PathBuf,
    /// Representation.
    pub repr: Representation,
    /// Setting overrides.
    pub overrides: Overrides,
    /// Shading of a mesh given instead of a scene file.
    pub shading: Shading,
    /// Memory the geometry may need (checked before it is built).
    pub budget: MemoryBudget,
}

/// A rendered scene with a printable summary.
pub struct RenderReport {
    /// The frame.
    pub frame: Frame,
    /// Bytes used by the geometry (objects, BVH).
    pub geometry_bytes: usize,
    /// Human-readable report: how each object is traced, time, rays/s, steps per ray.
    pub text: String,
}

/// Renders a loaded scene in a representation and describes the result.
pub fn render_scene(scene: &Scene, repr: Representation) -> RenderReport {
    let geometry = build_scene(scene, repr);
    let frame = render(scene, &geometry);
    let mut text = String::new();
    for o in geometry.objects() {
        let _ = writeln!(text, "  {}", o.describe());
    }
    let s = &frame.stats;
    let _ = writeln!(
        text,
        "{}x{} depth {} repr {}: frame {:.1} ms, {} rays ({} shadow), {:.2} Mrays/s, {:.2} march steps/ray, \
         {:.2} steps/marched ray, {:.2} BVH nodes/ray, {:.2} primitive tests/ray, {} step-limit misses, \
         geometry {} bytes",
        scene.camera.width,
        scene.camera.height,
        scene.settings.max_depth,
        repr.name(),
        frame.time.as_secs_f64() * 1e3,
        s.rays,
        s.shadow_rays,
        frame.mrays_per_s(),
        frame.steps_per_ray(),
        s.march_steps as f64 / s.marched_rays.max(1) as f64,
        frame.nodes_per_ray(),
        s.prim_tests as f64 / s.rays.max(1) as f64,
        s.step_limit_hits,
        geometry.bytes_used(),
    );
    RenderReport { geometry_bytes: geometry.bytes_used(), frame, text }
}

/// `toolkit render`: loads, renders and writes one PNG.
pub fn render_command(opts: &RenderOptions) -> Result<RenderReport> {
    check_repr(&opts.repr)?;
    let mut scene = load_input(&opts.scene, opts.shading)?;
    opts.overrides.apply(&mut scene)?;
    check_budget(&opts.budget, &scene, opts.repr, &opts.scene)?;
    let report = render_scene(&scene, opts.repr);
    write_png(&report.frame.image, &opts.output)?;
    Ok(report)
}

/// Fails when `scene` in `repr` would need more memory than `budget` allows.
fn check_budget(budget: &MemoryBudget, scene: &Scene, repr: Representation, path: &Path) -> Result<()> {
    let what = format!("the {} representation of {}", repr.name(), path.display());
    budget.check_scene(&what, scene, repr)
}

/// `toolkit gallery`: renders every `*.toml` scene in `scenes` in each of `reprs` into `out`
/// as `NAME.REPR.png`. Returns the report text.
pub fn gallery_command(
    scenes: &Path,
    out: &Path,
    reprs: &[Representation],
    overrides: Overrides,
    budget: MemoryBudget,
) -> Result<String> {
    for r in reprs {
        check_repr(r)?;
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(scenes)
        .map_err(|e| Error::io(scenes, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(Error::io(scenes, "no .toml scene files in this folder"));
    }
    // Each scene on its own: one that cannot be loaded, is refused by the budget, or fails
    // (a panic included) is reported on stderr and the others still render; the command
    // fails at the end, naming them. A scene's pictures are written only once all its
    // representations are checked.
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let mut text = String::new();
    let mut failed = Vec::new();
    for f in &files {
        let stem = f.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let done = catch_panic(|| -> Result<String> {
            let mut scene = load_scene(f)?;
            overrides.apply(&mut scene)?;
            for &repr in reprs {
                check_budget(&budget, &scene, repr, f)?;
            }
            let mut text = String::new();
            for &repr in reprs {
                let report = render_scene(&scene, repr);
                let path = out.join(format!("{stem}.{}.png", repr.name()));
                write_png(&report.frame.image, &path)?;
                let _ = write!(text, "{}\n{}", path.display(), report.text);
            }
            Ok(text)
        })
        .and_then(|r| r);
        match done {
            Ok(t) => text.push_str(&t),
            Err(e) => {
                eprintln!("error: {e}");
                failed.push(f.display().to_string());
            }
        }
    }
    if failed.is_empty() {
        return Ok(text);
    }
    Err(Error::Batch {
        message: format!("{} of {} scenes failed ({})", failed.len(), files.len(), failed.join(", ")),
        output: text,
    })
}

/// What `toolkit convert` produces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConvertTarget {
    /// A mesh file sampled into a signed distance grid of `res` cells along the longest axis
    /// of its bounding box, padded by `margin` cells: exact distances and winding-number
    /// signs ([`GridFill::Sample`]) or voxelized ([`GridFill::Voxelize`], about one voxel of
    /// error, closed meshes only). With `band > 0` the report also gives the memory a
    /// narrow band of `band` cells would take against the dense grid (the file is dense).
    Grid { res: u32, margin: u32, fill: GridFill, band: u32 },
    /// A scene's bounded objects extracted from their SDFs into one triangle mesh, `res`
    /// cells along each object's longest axis.
    Mesh { res: u32, method: ExtractMethod },
}

/// Largest resolution `toolkit convert --to mesh` accepts (its sample grid is held in memory).
pub const MAX_CONVERT_MESH_RESOLUTION: u32 = 1024;

/// `toolkit convert`: a mesh file to an SDF grid (`.sdf`, `.npy`, `.vti`), or a scene file to
/// a triangle mesh (`.obj`, `.ply`, `.glb`). Checks the request before any work, writes the
/// output through a temporary file, and returns a report.
pub fn convert_command(
    input: &Path,
    output: &Path,
    target: ConvertTarget,
    budget: MemoryBudget,
) -> Result<String> {
    let start = Instant::now();
    match target {
        ConvertTarget::Grid { res, margin, fill, band } => {
            if res == 0 {
                return Err(Error::Usage("--res must be at least 1".into()));
            }
            let (mesh, report) = load_mesh(input)?;
            // Checked before any work: the grid's size against the memory budget.
            let layout = match mesh.bounds() {
                Some((lo, hi)) => Some(grid_layout(lo, hi, res, margin)?),
                None => None,
            };
            if let Some((_, _, dims)) = layout {
                let what =
                    format!("a grid of {}x{}x{} samples for {}", dims.x, dims.y, dims.z, input.display());
                budget.check(&what, mesh_to_grid_bytes(mesh.triangles.len(), dims, fill))?;
            }
            let load = start.elapsed();
            // One unit per z-slice of exact sampling (voxelizing is quick and shows none).
            let stage = Stage::start(
                &format!("sampling {}", input.display()),
                layout.map_or(0, |(_, _, d)| d.z as u64),
                fill == GridFill::Sample,
            );
            let grid = match fill {
                GridFill::Sample => sample_mesh(&mesh, res, margin)?,
                // Voxelizing fails on meshes it finds open: name the file.
                GridFill::Voxelize => voxelize_mesh(&mesh, res, margin).map_err(|e| match e {
                    Error::Usage(m) => Error::input(input, None, m),
                    other => other,
                })?,
            };
            drop(stage);
            let sample = start.elapsed() - load;
            let how = match fill {
                GridFill::Sample => "sampled",
                GridFill::Voxelize => "voxelized",
            };
            let band_text = if band > 0 {
                let b = BandGrid::from_dense(&grid, band)?;
                format!(
                    "narrow band of {band} cells: {} of {} bricks of {}^3 cells stored, {} bytes \
                     ({:.1}% of the dense grid's {} bytes)\n",
                    b.stored_bricks(),
                    b.brick_count(),
                    BRICK,
                    b.bytes_used(),
                    100.0 * b.bytes_used() as f64 / grid.bytes_used() as f64,
                    grid.bytes_used()
                )
            } else {
                String::new()
            };
            save_grid(&grid, output)?;
            let d = grid.dims;
            Ok(format!(
                "{}: {} triangles ({} degenerate dropped) loaded in {:.1} ms\n\
                 grid {}x{}x{} samples (cell corners), voxel {:.6}, origin {}, {} bytes dense; \
                 {how} in {:.1} ms\n{band_text}wrote {}\n",
                input.display(),
                mesh.triangles.len(),
                report.degenerate_dropped,
                load.as_secs_f64() * 1e3,
                d.x,
                d.y,
                d.z,
                grid.voxel,
                grid.origin,
                grid.bytes_used(),
                sample.as_secs_f64() * 1e3,
                output.display()
            ))
        }
        ConvertTarget::Mesh { res, method } => {
            if !(2..=MAX_CONVERT_MESH_RESOLUTION).contains(&res) {
                return Err(Error::Usage(format!(
                    "--res must be between 2 and {MAX_CONVERT_MESH_RESOLUTION}, got {res}"
                )));
            }
            check_size(UVec3::splat(res + 3), DEFAULT_MAX_GRID_BYTES)?;
            budget.check(&format!("extracting at {res} cells"), extraction_bytes(res, method))?;
            let scene = load_scene(input)?;
            for (i, o) in scene.objects.iter().enumerate() {
                let n = crate::geometry::sdf::SdfTree::new(o).map_or(0.0, |t| t.evaluations());
                check_evaluations(&format!("extracting {}", input.display()), i, o, n)?;
            }
            let mut out = TriangleMesh::default();
            let mut text = String::new();
            // One unit per z-slice sampled; each object has at most res + 3 slices.
            let per_object = res as u64 + 3;
            let stage = Stage::start(
                &format!("extracting {}", input.display()),
                per_object * scene.objects.len() as u64,
                true,
            );
            for (done, o) in scene.objects.iter().enumerate() {
                crate::cli::progress::set(per_object * done as u64);
                let extracted = extract_object(o, res, method)
                    .or_else(|| grid_file_mesh(o, res, MeshMethod::Extracted(method)));
                match extracted {
                    Some(m) => {
                        let _ = writeln!(
                            text,
                            "  {} '{}': {} triangles",
                            o.kind_name(),
                            o.label,
                            m.triangles.len()
                        );
                        out.merge(&m);
                    }
                    None => {
                        let _ = writeln!(
                            text,
                            "  {} '{}': skipped (unbounded, a mesh, or a triangle: no closed SDF to extract)",
                            o.kind_name(),
                            o.label
                        );
                    }
                }
            }
            drop(stage);
            if out.triangles.is_empty() {
                return Err(Error::input(input, None, "no bounded SDF object to extract a mesh from"));
            }
            save_mesh(&out, output)?;
            let _ = writeln!(
                text,
                "{} triangles, {} vertices, closed: {}, in {:.1} ms\nwrote {}",
                out.triangles.len(),
                out.positions.len(),
                out.is_closed(),
                start.elapsed().as_secs_f64() * 1e3,
                output.display()
            );
            Ok(text)
        }
    }
}
