//! The coursework's scaling experiment: frame time against the number of primitives
//! (spheres, cubes, cylinders or cones of unit size on a square grid with spacing 2 along x
//! and z, seen from above at a fixed camera) for each representation, with the primitives
//! as separate objects ([`Layout::Objects`]: under the top-level BVH; in the mesh
//! representation they share one mesh) and as the children of one SDF union object
//! ([`Layout::Union`]: the coursework's own case, where every distance evaluation visits
//! every primitive).

use std::path::Path;
use std::time::Instant;

use glam::Vec3;
use serde::Serialize;

use crate::config::ScalingOptions;
use crate::error::{Error, Result};
use crate::geometry::Geometry;
use crate::plan::{GridFill, GridStorage, MeshMethod, MeshPlane, Representation, build_scene};
use crate::scene::shape::{CsgOp, Object, ObjectKind, Primitive, Shading};
use crate::scene::transform::TransformDesc;
use crate::scene::{Camera, Light, Material, Scene, Settings};

use super::commit_id;

/// Schema version of the scaling CSV: 2 added `layout` (version 1 was the compare CSV's).
pub const SCALING_SCHEMA_VERSION: u32 = 2;

/// How the experiment's primitives make up the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// One top-level object per primitive.
    Objects,
    /// One object: the union (CSG) of the primitives.
    Union,
}

impl Layout {
    /// The CSV's `layout` value.
    pub fn name(self) -> &'static str {
        match self {
            Layout::Objects => "objects",
            Layout::Union => "union",
        }
    }
}

/// Columns of the scaling CSV, in order.
pub const SCALING_COLUMNS: [&str; 24] = [
    "primitive",
    "repr",
    "method",
    "count",
    "triangles",
    "total_bytes",
    "build_ms",
    "frame_ms_median",
    "frame_ms_min",
    "frame_ms_max",
    "frames",
    "fps_median",
    "mrays_per_s",
    "steps_per_ray",
    "nodes_per_ray",
    "threads",
    "width",
    "height",
    "depth",
    "commit",
    "timestamp",
    "frame_ms_samples",
    "layout",
    "schema_version",
];

/// One row of the scaling CSV (field order is [`SCALING_COLUMNS`]).
#[derive(Clone, Debug, Serialize)]
pub struct ScalingRow {
    /// `sphere`, `cube`, `cylinder` or `cone`.
    pub primitive: &'static str,
    /// Representation name ([`Representation::name`]).
    pub repr: &'static str,
    /// Method within the representation (with its resolution, e.g. `parametric-32`),
    /// prefixed `union-` in the union layout (so that tools grouping rows by
    /// representation and method keep the layouts apart).
    pub method: String,
    /// Number of primitives.
    pub count: u32,
    /// Triangles stored.
    pub triangles: u64,
    /// Bytes of the geometry and its acceleration structures.
    pub total_bytes: u64,
    /// Build time, ms.
    pub build_ms: f64,
    /// Median frame time, ms.
    pub frame_ms_median: f64,
    /// Fastest frame, ms.
    pub frame_ms_min: f64,
    /// Slowest frame, ms.
    pub frame_ms_max: f64,
    /// Timed frames.
    pub frames: u32,
    /// Frames per second at the median frame time.
    pub fps_median: f64,
    /// Rays per second at the median, millions.
    pub mrays_per_s: f64,
    /// Distance evaluations per ray.
    pub steps_per_ray: f64,
    /// BVH nodes per ray.
    pub nodes_per_ray: f64,
    /// Rendering threads.
    pub threads: usize,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Recursion depth.
    pub depth: u32,
    /// Toolkit commit.
    pub commit: String,
    /// RFC 3339 UTC.
    pub timestamp: String,
    /// Every timed frame, ms, space-separated.
    pub frame_ms_samples: String,
    /// `objects` (one object per primitive) or `union` (one union object of them all).
    pub layout: &'static str,
    /// [`SCALING_SCHEMA_VERSION`].
    pub schema_version: u32,
}

/// The primitive types of the experiment.
pub const PRIMITIVES: [&str; 4] = ["sphere", "cube", "cylinder", "cone"];

fn primitive(name: &str) -> Primitive {
    match name {
        "sphere" => Primitive::Sphere { radius: 0.5 },
        "cube" => Primitive::Box { half: Vec3::splat(0.5) },
        "cylinder" => Primitive::Cylinder { radius: 0.5, half_height: 0.5 },
        _ => Primitive::Cone { radius_bottom: 0.5, radius_top: 0.0, half_height: 0.5 },
    }
}

/// [`scaling_scene`] with its primitives laid out as `layout` says: as they are, or as the
/// children (same transforms and materials) of one union object.
pub fn scaling_scene_as(kind: &str, count: u32, width: u32, height: u32, layout: Layout) -> Scene {
    let mut scene = scaling_scene(kind, count, width, height);
    if layout == Layout::Union {
        let children = std::mem::take(&mut scene.objects);
        scene.objects = vec![Object {
            kind: ObjectKind::Csg { op: CsgOp::Union, children },
            transform: TransformDesc::default(),
            material: 0,
            label: format!("union of {count} {kind}"),
        }];
    }
    scene
}

/// `count` primitives of one kind on a square grid with spacing 2 along x and z (row-major,
/// as square as possible), centred on the origin, seen from above and in front by a camera
/// that frames 100 of them.
pub fn scaling_scene(kind: &str, count: u32, width: u32, height: u32) -> Scene {
    let cols = (count as f32).sqrt().ceil().max(1.0) as u32;
    let rows = count.div_ceil(cols);
    let objects = (0..count)
        .map(|i| {
            let (c, r) = (i % cols, i / cols);
            let x = 2.0 * c as f32 - (cols - 1) as f32;
            let z = 2.0 * r as f32 - (rows - 1) as f32;
            Object {
                kind: ObjectKind::Primitive(primitive(kind)),
                transform: TransformDesc { translate: Vec3::new(x, 0.0, z), ..TransformDesc::default() },
                material: i % 3,
                label: format!("{kind} {i}"),
            }
        })
        .collect();
    let position = Vec3::new(0.0, 14.0, -16.0);
    let material = |color: Vec3| Material { color, ks: 0.5, shininess: Some(50.0), ..Material::default() };
    Scene {
        camera: Camera {
            position,
            forward: (-position).normalize(),
            up: Vec3::Y,
            fov_y_deg: 50.0,
            width,
            height,
        },
        settings: Settings { max_depth: 1, ..Settings::default() },
        lights: vec![
            Light::Ambient { intensity: 0.2 },
            Light::Point { position: Vec3::new(-6.0, 10.0, -8.0), intensity: 0.7, color: Vec3::ONE },
            Light::Directional {
                direction: Vec3::new(0.3, -1.0, 0.4).normalize(),
                intensity: 0.2,
                color: Vec3::ONE,
            },
        ],
        materials: vec![
            material(Vec3::new(0.9, 0.3, 0.2)),
            material(Vec3::new(0.3, 0.8, 0.3)),
            material(Vec3::new(0.3, 0.4, 0.9)),
        ],
        objects,
    }
}

/// Runs the experiment and writes the CSV (through a temporary file: all rows or none).
///
/// # Errors
/// Bad options, an unwritable CSV.
pub fn scaling_command(opts: &ScalingOptions, csv_path: &Path) -> Result<String> {
    let march = opts.march;
    let res = opts.resolution;
    let reprs: [(String, Representation); 4] = [
        ("closed-form".into(), Representation::Analytic { march }),
        ("sphere-trace".into(), Representation::Sdf { march }),
        (
            format!("parametric-{res}"),
            Representation::Mesh {
                resolution: res,
                shading: Shading::Smooth,
                method: MeshMethod::Parametric,
                plane: MeshPlane::ClosedForm,
                march,
            },
        ),
        (
            format!("dense-{res}"),
            Representation::Grid {
                resolution: res,
                fill: GridFill::Sample,
                storage: GridStorage::Dense,
                march,
            },
        ),
    ];
    let commit = commit_id();
    let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(Vec::new());
    w.write_record(SCALING_COLUMNS).map_err(|e| Error::io(csv_path, e))?;
    let mut text = String::new();
    for kind in PRIMITIVES {
        for &count in &opts.counts {
            for layout in [Layout::Objects, Layout::Union] {
                let mut scene = scaling_scene_as(kind, count, 320, 240, layout);
                opts.overrides.apply(&mut scene);
                for (method, r) in &reprs {
                    let repr = r.name();
                    let method = match layout {
                        Layout::Objects => method.clone(),
                        Layout::Union => format!("union-{method}"),
                    };
                    let start = Instant::now();
                    let geometry = build_scene(&scene, *r);
                    let build_ms = start.elapsed().as_secs_f64() * 1e3;
                    let (timing, _) = super::time_frames(
                        &scene,
                        &geometry,
                        crate::render::PrimaryVisibility::Trace,
                        opts.frames,
                    );
                    let row = ScalingRow {
                        primitive: kind,
                        repr,
                        method: method.clone(),
                        count,
                        triangles: geometry.census().triangles,
                        total_bytes: geometry.bytes_used() as u64,
                        build_ms,
                        frame_ms_median: timing.median,
                        frame_ms_min: timing.min,
                        frame_ms_max: timing.max,
                        frames: opts.frames,
                        fps_median: 1e3 / timing.median,
                        mrays_per_s: timing.mrays_per_s,
                        steps_per_ray: timing.steps_per_ray,
                        nodes_per_ray: timing.nodes_per_ray,
                        threads: rayon::current_num_threads(),
                        width: scene.camera.width,
                        height: scene.camera.height,
                        depth: scene.settings.max_depth,
                        commit: commit.clone(),
                        timestamp: timing.timestamp,
                        frame_ms_samples: timing.samples,
                        layout: layout.name(),
                        schema_version: SCALING_SCHEMA_VERSION,
                    };
                    use std::fmt::Write as _;
                    let _ = writeln!(
                        text,
                        "{kind:>8} x{count:<4} {repr:>8}/{method:<20} {:8.1} ms  {:6.1} fps",
                        row.frame_ms_median, row.fps_median
                    );
                    w.serialize(&row).map_err(|e| Error::io(csv_path, e))?;
                }
            }
        }
    }
    let bytes = w.into_inner().map_err(|e| Error::io(csv_path, e))?;
    crate::files::write_atomic_bytes(csv_path, &bytes)?;
    Ok(text)
}
