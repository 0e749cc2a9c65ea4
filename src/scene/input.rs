//! Loading any input file into a scene, by its extension: a scene file (TOML), or a mesh
//! or signed distance grid file shown in a preview scene (one object framed by a camera,
//! lights and a grey material). The command line's `render` and `convert` and the study's
//! runs and hard cases all load their inputs through [`load_input`].

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;

use crate::base::transform::TransformDesc;
use crate::error::Result;
use crate::grid::SdfGrid;
use crate::grid::io::load_grid;
use crate::implicit::field3d::{Field3, Preparation, PreparedHeap};
use crate::mesh::{MeshFormat, TriangleMesh, load_mesh};
use crate::scene::shape::{Object, ObjectKind, Shading};
use crate::scene::{Camera, Light, Material, Scene, Settings, load_scene};

/// Loads a scene file, or a mesh file, a signed distance grid file (`.sdf`, `.npy`) or an
/// implicit model (`.vm`) into a preview scene ([`mesh_preview_scene`],
/// [`grid_preview_scene`], [`implicit_preview_scene`]), by the file's
/// extension; `shading` is the preview mesh's. A `.vti` grid goes to the grid loader too,
/// which says that it cannot read one (rather than the scene parser failing on its bytes).
/// A mesh's dropped degenerate triangles are reported on stderr.
///
/// # Errors
/// The loaders' errors: the file cannot be read, or is not a valid scene, mesh or grid.
pub fn load_input(path: &Path, shading: Shading) -> Result<Scene> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    if matches!(ext.as_deref(), Some("sdf" | "npy" | "vti")) {
        let grid = load_grid(path)?;
        return Ok(grid_preview_scene(Arc::new(grid), path.to_path_buf()));
    }
    if ext.as_deref() == Some("vm") {
        let field = crate::implicit::load_field(path)?;
        return Ok(implicit_preview_scene(field, path.to_path_buf()));
    }
    if MeshFormat::from_path(path).is_some() {
        let (mesh, report) = load_mesh(path)?;
        if report.degenerate_dropped > 0 {
            eprintln!("{}: dropped {} degenerate triangles", path.display(), report.degenerate_dropped);
        }
        return Ok(mesh_preview_scene(Arc::new(mesh), path.to_path_buf(), shading));
    }
    load_scene(path)
}

/// A scene that shows one mesh: a camera framing its bounding box from the front and a
/// little above (+z towards the viewer, +y up), an ambient light, a key point light near the
/// camera and a directional fill light, and one grey Phong material. Used by
/// `toolkit render MESH_FILE` so a mesh can be seen without writing a scene file.
pub fn mesh_preview_scene(mesh: Arc<TriangleMesh>, source: PathBuf, shading: Shading) -> Scene {
    let (lo, hi) = mesh.bounds().unwrap_or((Vec3::splat(-1.0), Vec3::ONE));
    preview_scene(ObjectKind::Mesh { mesh, source, shading }, lo, hi)
}

/// The preview scene of [`mesh_preview_scene`] for a signed distance grid file (`toolkit
/// render GRID_FILE`), framing the grid's box.
pub fn grid_preview_scene(grid: Arc<SdfGrid>, source: PathBuf) -> Scene {
    let (lo, hi) = grid.bounds();
    preview_scene(ObjectKind::Grid { grid, source }, lo, hi)
}

/// The preview scene of [`mesh_preview_scene`] for an implicit `.vm` model (`toolkit render
/// MODEL.vm`), framing the cube [-1, 1]^3 it is seen in, as Fidget frames it.
pub fn implicit_preview_scene(field: Arc<Field3>, source: PathBuf) -> Scene {
    let e = crate::implicit::field3d::EXTENT as f32;
    preview_scene(ObjectKind::Implicit { field, source }, Vec3::splat(-e), Vec3::splat(e))
}

/// One object of `kind` within `lo..hi`, seen by the preview camera and lights.
fn preview_scene(kind: ObjectKind, lo: Vec3, hi: Vec3) -> Scene {
    let centre = 0.5 * (lo + hi);
    let radius = (0.5 * (hi - lo).length()).max(1e-6);
    let fov_y_deg: f32 = 40.0;
    let distance = radius / (0.5 * fov_y_deg).to_radians().sin() * 1.05;
    let view = Vec3::new(0.35, 0.3, 1.0).normalize();
    let position = centre + view * distance;
    let source = match &kind {
        ObjectKind::Mesh { source, .. }
        | ObjectKind::Grid { source, .. }
        | ObjectKind::Implicit { source, .. } => Some(source),
        _ => None,
    };
    let label = source
        .and_then(|s| s.file_name())
        .map_or_else(|| "preview".into(), |n| n.to_string_lossy().into_owned());
    Scene {
        camera: Camera { position, forward: -view, up: Vec3::Y, fov_y_deg, width: 500, height: 500 },
        settings: Settings { max_distance: 4.0 * distance + 4.0 * radius, ..Settings::default() },
        lights: vec![
            Light::Ambient { intensity: 0.15 },
            Light::Point {
                position: centre + Vec3::new(-0.6, 0.9, 0.8).normalize() * distance,
                intensity: 0.7,
                color: Vec3::ONE,
            },
            Light::Directional {
                direction: Vec3::new(0.5, -0.3, -0.6).normalize(),
                intensity: 0.25,
                color: Vec3::ONE,
            },
        ],
        materials: vec![Material {
            name: "preview".into(),
            color: Vec3::new(0.75, 0.72, 0.68),
            ks: 0.3,
            shininess: Some(40.0),
            ..Material::default()
        }],
        objects: vec![Object { kind, transform: TransformDesc::default(), material: 0, label }],
    }
}

/// What preparing the scene's implicit models took (each model once, one after the other:
/// the times added, the largest heap peak over what the earlier ones keep, the sum of what
/// they keep), `None` where the scene has none or one was not measured. The runs of an input
/// share its prepared models, so `compare` counts this in each run: build time + `ms`, heap
/// peak `max(peak, live + the run's own)`.
pub fn preparation(scene: &Scene) -> Option<Preparation> {
    let mut seen: Vec<*const Field3> = Vec::new();
    let mut out: Option<Preparation> = None;
    for o in &scene.objects {
        let ObjectKind::Implicit { field, .. } = &o.kind else { continue };
        if seen.contains(&Arc::as_ptr(field)) {
            continue;
        }
        seen.push(Arc::as_ptr(field));
        let p = field.preparation?;
        out = Some(match out {
            None => p,
            Some(o) => Preparation {
                ms: o.ms + p.ms,
                heap: o
                    .heap
                    .zip(p.heap)
                    .map(|(a, b)| PreparedHeap { peak: a.peak.max(a.live + b.peak), live: a.live + b.live }),
            },
        });
    }
    out
}
