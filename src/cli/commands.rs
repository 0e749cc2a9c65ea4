//! The toolkit's commands as library functions: `render` (one scene, one representation),
//! `gallery` (every scene of a folder in every representation) and `convert` (mesh to SDF
//! grid, scene to mesh). They take options already validated ([`crate::config`] checks
//! every flag, once); `main.rs` parses arguments, has them validated and maps errors to
//! exit codes.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::cli::progress::Stage;
use crate::config::{ConvertTarget, Overrides, RenderOptions};
use crate::convert::extract::extract_object;
use crate::convert::mesh_to_grid::sample_mesh;
use crate::convert::mesh_to_grid::voxelize::voxelize_mesh;
use crate::error::{Error, Result, catch_panic};
use crate::geometry::grid::band::{BRICK, BandGrid};
use crate::geometry::grid::grid_layout;
use crate::geometry::grid::io::save_grid;
use crate::mesh::{TriangleMesh, load_mesh, save_mesh};
use crate::plan::GridFill;
use crate::plan::budget::{MemoryBudget, check_evaluations, extraction_bytes, mesh_to_grid_bytes};
use crate::plan::{MeshMethod, Representation, grid_file_mesh, implicit_world_mesh};
use crate::render::report::{RenderReport, render_scene, render_scene_with};
use crate::render::write_png;
use crate::scene::{Scene, load_input, load_scene};

/// `toolkit render`: loads, renders and writes one PNG.
pub fn render_command(opts: &RenderOptions) -> Result<RenderReport> {
    if is_vm(&opts.scene) {
        return render_vm(opts);
    }
    let mut scene = load_input(&opts.scene, opts.shading)?;
    opts.overrides.apply(&mut scene);
    check_budget(&opts.budget, &scene, opts.repr, &opts.scene)?;
    let report = render_scene_with(&scene, opts.repr, opts.primary);
    write_png(&report.frame.image, &opts.output)?;
    Ok(report)
}

/// Whether `path` names a `.vm` implicit model.
fn is_vm(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("vm"))
}

/// `toolkit render MODEL.vm`: a model without `var-z` as the Prospero challenge's image
/// (white where negative), default 1024 x 1024; a 3D model as a scene ([`render_vm_3d`]).
fn render_vm(opts: &RenderOptions) -> Result<RenderReport> {
    use crate::geometry::RayStats;
    use crate::implicit::image2d::render_2d;
    use crate::render::Frame;
    let ssa = crate::implicit::load_vm(&opts.scene)?;
    if let Some(depth) = &opts.heightmap {
        return render_vm_heightmap(opts, ssa, depth);
    }
    if ssa.uses_z() {
        return render_vm_3d(opts, ssa);
    }
    let width = opts.overrides.width().unwrap_or(1024) as usize;
    let height = opts.overrides.height().unwrap_or(1024) as usize;
    let start = Instant::now();
    let (mask, census) = render_2d(&ssa, width, height);
    let time = start.elapsed();
    let mut image = image::RgbImage::new(width as u32, height as u32);
    for (p, &inside) in image.pixels_mut().zip(&mask.inside) {
        *p = image::Rgb([255 * inside; 3]);
    }
    write_png(&image, &opts.output)?;
    let total = (width * height) as f64;
    let text = format!(
        "  implicit 2D model, {} clauses (its value is not a distance: only its sign is used)\n  \
         {width}x{height} in {:.1} ms; {:.1}% of pixels settled by interval tiles, {:.1}% evaluated \
         ({} blocks, {:.0} clauses per block after shortening)\n",
        ssa.clauses.len(),
        time.as_secs_f64() * 1e3,
        100.0 * census.filled as f64 / total,
        100.0 * census.evaluated as f64 / total,
        census.blocks,
        census.clauses_evaluated as f64 / census.blocks.max(1) as f64,
    );
    Ok(RenderReport {
        frame: Frame { image, time, primary: None, raster: None, stats: RayStats::default() },
        geometry_bytes: 0,
        text,
    })
}

/// `toolkit render MODEL.vm` of a 3D model: the preview scene framing the cube [-1, 1]^3
/// ([`crate::scene::implicit_preview_scene`]) rendered as any scene, with the work of the
/// safe marcher per ray.
fn render_vm_3d(opts: &RenderOptions, ssa: crate::implicit::Ssa) -> Result<RenderReport> {
    use crate::implicit::field3d::{CELLS, Field3};
    let start = Instant::now();
    let field = std::sync::Arc::new(Field3::new(ssa, CELLS));
    let prepared = start.elapsed();
    let mut scene = crate::scene::implicit_preview_scene(field, opts.scene.clone());
    opts.overrides.apply(&mut scene);
    check_budget(&opts.budget, &scene, opts.repr, &opts.scene)?;
    let mut report = render_scene_with(&scene, opts.repr, opts.primary);
    write_png(&report.frame.image, &opts.output)?;
    let s = &report.frame.stats;
    if s.marched_rays > 0 {
        let _ = writeln!(
            report.text,
            "implicit model: cells prepared in {:.1} ms; {:.2} point evaluations and {:.2} interval \
             evaluations per marched ray ({} marched rays)",
            prepared.as_secs_f64() * 1e3,
            s.march_steps as f64 / s.marched_rays as f64,
            s.interval_evals as f64 / s.marched_rays as f64,
            s.marched_rays
        );
    }
    Ok(report)
}

/// `toolkit render MODEL.vm --heightmap DEPTH.png`: the view of Fidget's voxel renderer
/// ([`crate::implicit::heightmap`]), default 512 x 512; the normals go to `--output`.
fn render_vm_heightmap(
    opts: &RenderOptions,
    ssa: crate::implicit::Ssa,
    depth: &Path,
) -> Result<RenderReport> {
    use crate::geometry::RayStats;
    use crate::implicit::field3d::{CELLS, Field3};
    use crate::implicit::heightmap::render_heightmap;
    use crate::render::Frame;
    if !ssa.uses_z() {
        return Err(Error::input(
            &opts.scene,
            None,
            "--heightmap needs a 3D model (this one has no var-z: render it without --heightmap)".to_string(),
        ));
    }
    let width = opts.overrides.width().unwrap_or(512) as usize;
    let height = opts.overrides.height().unwrap_or(512) as usize;
    let start = Instant::now();
    let field = Field3::new(ssa, CELLS);
    let prepared = start.elapsed();
    let start = Instant::now();
    let map = render_heightmap(&field, width, height);
    let time = start.elapsed();
    let depth_image = map.depth_png();
    let image = map.normal_png();
    let depth_image = image::DynamicImage::ImageLuma16(depth_image);
    crate::files::write_atomic(depth, |w| {
        depth_image.write_with_encoder(image::codecs::png::PngEncoder::new(w)).map_err(std::io::Error::other)
    })?;
    write_png(&image, &opts.output)?;
    let rays = (width * height).max(1) as f64;
    let w = &map.work;
    let text = format!(
        "  {}\n  heightmap {width}x{height} in {:.1} ms (cells prepared in {:.1} ms); {} pixels hit; per ray \
         {:.2} point evaluations, {:.2} interval evaluations, {:.2} Lipschitz steps\n",
        field.summary.describe(),
        time.as_secs_f64() * 1e3,
        prepared.as_secs_f64() * 1e3,
        map.hits(),
        w.point_evals as f64 / rays,
        w.interval_evals as f64 / rays,
        w.lipschitz_steps as f64 / rays,
    );
    Ok(RenderReport {
        frame: Frame { image, time, primary: None, raster: None, stats: RayStats::default() },
        geometry_bytes: field.bytes_used(),
        text,
    })
}

/// The surface of the implicit model `input` extracted with marching cubes at `res` cells
/// along the cube [-1, 1]^3 (the grid of `toolkit convert MODEL.vm --to grid` is the
/// distance to it).
fn implicit_mesh(input: &Path, res: u32, budget: MemoryBudget) -> Result<TriangleMesh> {
    use crate::convert::extract::ExtractMethod;
    budget.check(
        &format!("extracting {} at {res} cells", input.display()),
        extraction_bytes(res, ExtractMethod::MarchingCubes),
    )?;
    let scene = load_input(input, Default::default())?;
    let o = &scene.objects[0];
    crate::plan::implicit_surface(o, res, ExtractMethod::MarchingCubes)
        .ok_or_else(|| Error::input(input, None, format!("no surface in the cube [-1, 1]^3 at {res} cells")))
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
            overrides.apply(&mut scene);
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
            // An implicit model's grid stores the exact signed distance to its surface
            // extracted at `res` cells (its value is not a distance).
            let implicit = if is_vm(input) { Some(implicit_mesh(input, res, budget)?) } else { None };
            let (mesh, report) = match implicit {
                Some(m) => (m, Default::default()),
                None => load_mesh(input)?,
            };
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
                _ if is_vm(input) => sample_mesh(&mesh, res, margin)?,
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
                _ if is_vm(input) => {
                    "sampled as the exact signed distance to the model's surface extracted at the grid's \
                     resolution (marching cubes; the model's value is not a distance)"
                }
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
        ConvertTarget::Decimate { target } => {
            let (mesh, _) = load_mesh(input)?;
            // The simplifier's scratch and the output are smaller than the mesh times this.
            budget.check(
                &format!("decimating {}", input.display()),
                mesh.bytes_used() as u64 * crate::mesh::simplify::SCRATCH_FACTOR,
            )?;
            let load = start.elapsed();
            let d = crate::mesh::simplify::decimate(&mesh, target, crate::mesh::simplify::NO_ERROR_LIMIT)
                .map_err(|m| Error::input(input, None, format!("cannot decimate: {m}")))?;
            let took = start.elapsed() - load;
            save_mesh(&d.mesh, output)?;
            Ok(format!(
                "{}: {} triangles, {} vertices loaded in {:.1} ms\n\
                 decimated to {target} ({} triangles asked): {} triangles, {} vertices, closed: {}, \
                 {} vertices welded by position, border {}, {} folded triangles removed, meshopt error \
                 {:.3e} ({:.3e} of the extent), in {:.1} ms\nwrote {}\n",
                input.display(),
                mesh.triangles.len(),
                mesh.positions.len(),
                load.as_secs_f64() * 1e3,
                d.target,
                d.mesh.triangles.len(),
                d.mesh.positions.len(),
                d.mesh.is_closed(),
                d.vertices_welded,
                if d.border_locked { "locked" } else { "free (closed mesh)" },
                d.folds_removed,
                d.error,
                d.relative_error,
                took.as_secs_f64() * 1e3,
                output.display()
            ))
        }
        ConvertTarget::Mesh { res, method } => {
            budget.check(&format!("extracting at {res} cells"), extraction_bytes(res, method))?;
            let scene =
                if is_vm(input) { load_input(input, Default::default())? } else { load_scene(input)? };
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
                stage.set(per_object * done as u64);
                let extracted = extract_object(o, res, method)
                    .or_else(|| grid_file_mesh(o, res, MeshMethod::Extracted(method)))
                    .or_else(|| implicit_world_mesh(o, res, method));
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
