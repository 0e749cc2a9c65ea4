//! Representations of scene objects behind the [`Geometry`] interface: closed-form
//! primitives, sphere-traced analytic SDFs, and the scene's top-level BVH over objects
//! (itself a `Geometry`, so the tracer sees one geometry whatever the representation).

pub mod budget;

use glam::{DVec3, Vec3};

use crate::convert::extract::{ExtractMethod, Field, extract_object};
use crate::convert::mesh_to_grid::band::{band_from_function, band_from_mesh};
use crate::convert::mesh_to_grid::voxelize::voxelize_mesh;
use crate::convert::mesh_to_grid::{sample_function, sample_mesh};
use crate::convert::tessellate::plane_view_mesh;
use crate::convert::tessellate::tessellate;
use crate::geometry::Geometry;
use crate::geometry::analytic::AnalyticObject;
use crate::geometry::grid::SdfGrid;
use crate::geometry::grid::band::BandGrid;
use crate::geometry::grid::object::{ClippedGrid, GridObject, GridStore, VIEW_CLIP_FRACTION, view_region};
use crate::geometry::march::MarchParams;
use crate::geometry::mesh::MeshGeometry;
use crate::geometry::scene::SceneGeometry;
use crate::geometry::sdf::SdfObject;
use crate::geometry::sdf::SdfTree;
use crate::mesh::TriangleMesh;
use crate::scene::Scene;
use crate::scene::shape::{Object, ObjectKind, Primitive, Shading};
use crate::scene::transform::Transform;

/// How the scene's objects are represented for tracing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Representation {
    /// Closed-form ray/primitive intersection; objects without one (CSG, repetition) are
    /// sphere traced with `march`.
    Analytic { march: MarchParams },
    /// Sphere tracing of the analytic signed distance functions.
    Sdf { march: MarchParams },
    /// Primitives tessellated parametrically at `resolution` (segments around the largest
    /// circle) and ray traced as triangle meshes through a BVH; infinite planes become a
    /// disc around the camera out to the scene's `max_distance`; bounded CSG and repetition
    /// are extracted from their SDF (marching cubes, `resolution` cells along the
    /// longest axis, at most 512); unbounded ones are sphere traced with `march` (the
    /// render says so).
    Mesh { resolution: u32, shading: Shading, method: MeshMethod, march: MarchParams },
    /// Every bounded object (primitive, CSG, repetition, mesh) sampled into a signed
    /// distance grid of `resolution` cells along its longest axis (exact distances at cell
    /// corners) and ray marched through the trilinear interpolation with `march`; unbounded
    /// objects and triangles (unsigned) are sphere traced analytically (the render says so).
    Grid { resolution: u32, fill: GridFill, storage: GridStorage, march: MarchParams },
}

/// How the mesh representation turns primitives into triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MeshMethod {
    /// Parametric tessellation of each primitive (CSG and repetition are extracted).
    Parametric,
    /// Every bounded object extracted from its SDF with the given method.
    Extracted(ExtractMethod),
}

/// How a mesh object's grid is filled (analytic objects are always sampled exactly).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GridFill {
    /// Exact distance to the nearest triangle at every sample, sign from the winding number.
    Sample,
    /// Surface voxels rasterised, inside found by flood fill, distances from a Euclidean
    /// distance transform (voxel-accurate).
    Voxelize,
}

/// How a grid's samples are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GridStorage {
    /// Every sample of the box.
    Dense,
    /// Only bricks within `cells` cells of the surface; elsewhere a conservative bound.
    Band {
        /// Half-width of the stored band, in cells, `>= 1`.
        cells: u32,
    },
}

impl Representation {
    /// The command-line name.
    pub fn name(&self) -> &'static str {
        match self {
            Representation::Analytic { .. } => "analytic",
            Representation::Sdf { .. } => "sdf",
            Representation::Mesh { .. } => "mesh",
            Representation::Grid { .. } => "grid",
        }
    }
}

/// Builds the geometry of every top-level object of `scene` in representation `repr`.
/// Sphere tracing takes its pixel footprint from the scene's camera.
pub fn build_objects(scene: &Scene, repr: Representation) -> Vec<Box<dyn Geometry>> {
    let footprint =
        2.0 * ((scene.camera.fov_y_deg as f64).to_radians() * 0.5).tan() / scene.camera.height.max(1) as f64;
    let with_footprint = |march: MarchParams| MarchParams { pixel_footprint: footprint, ..march };
    let repr = match repr {
        Representation::Analytic { march } => Representation::Analytic { march: with_footprint(march) },
        Representation::Sdf { march } => Representation::Sdf { march: with_footprint(march) },
        Representation::Mesh { resolution, shading, method, march } => {
            Representation::Mesh { resolution, shading, method, march: with_footprint(march) }
        }
        Representation::Grid { resolution, fill, storage, march } => {
            Representation::Grid { resolution, fill, storage, march: with_footprint(march) }
        }
    };
    scene
        .objects
        .iter()
        .map(|o| -> Box<dyn Geometry> {
            if let ObjectKind::Grid { .. } = &o.kind {
                return grid_file_geometry(o, repr);
            }
            let (march, why) = match repr {
                Representation::Analytic { march } => {
                    if let ObjectKind::Primitive(p) = &o.kind {
                        return Box::new(AnalyticObject::new(*p, o));
                    }
                    let kind = o.kind_name();
                    (march, format!("{kind} '{}': sphere traced (no closed form for {kind})", o.label))
                }
                Representation::Sdf { march } => {
                    (march, format!("{} '{}': sphere traced", o.kind_name(), o.label))
                }
                Representation::Mesh { resolution, shading, method, march } => {
                    if let Some(g) = tessellated(scene, o, resolution, shading, method) {
                        return Box::new(g);
                    }
                    (march, format!("{} '{}': sphere traced (unbounded: no mesh)", o.kind_name(), o.label))
                }
                Representation::Grid { resolution, fill, storage, march } => {
                    if let Some(g) = gridded(scene, o, resolution, fill, storage, march) {
                        return g;
                    }
                    let why = "unbounded or unsigned: no grid";
                    (march, format!("{} '{}': sphere traced ({why})", o.kind_name(), o.label))
                }
            };
            if let ObjectKind::Mesh { mesh, shading, .. } = &o.kind {
                // A mesh is traced as triangles in the other representations.
                return Box::new(MeshGeometry::new(
                    TriangleMesh::clone(mesh),
                    *shading,
                    o.compiled_transform(),
                    o.material,
                    format!("mesh '{}'", o.label),
                ));
            }
            match SdfObject::new(o, march, why) {
                Some(s) => Box::new(s),
                None => unreachable!("only top-level objects hold meshes"),
            }
        })
        .collect()
}

/// A grid-file object ([`ObjectKind::Grid`]) in representation `repr`: its surface
/// extracted at `resolution` cells ([`grid_file_mesh`]) in the mesh representation, the
/// grid itself ray marched in every other one (stored as a narrow band under
/// [`GridStorage::Band`]).
fn grid_file_geometry(o: &Object, repr: Representation) -> Box<dyn Geometry> {
    let ObjectKind::Grid { grid, source } = &o.kind else { unreachable!("called for grid objects only") };
    let file =
        source.file_name().map_or_else(|| source.display().to_string(), |f| f.to_string_lossy().into());
    let transform = o.compiled_transform();
    let (march, storage) = match repr {
        Representation::Mesh { resolution, method, .. } => {
            if let Some(mesh) = grid_file_mesh(o, resolution, method) {
                let res = resolution.min(MAX_EXTRACT_RESOLUTION);
                let label = format!("grid '{}' ({file}) extracted at {res} cells", o.label);
                return Box::new(MeshGeometry::new(
                    mesh,
                    Shading::Flat,
                    Transform::IDENTITY,
                    o.material,
                    label,
                ));
            }
            // No surface in the grid: march it (it will show nothing, honestly).
            (MarchParams::default(), GridStorage::Dense)
        }
        Representation::Grid { storage, march, .. } => (march, storage),
        Representation::Analytic { march } | Representation::Sdf { march } => (march, GridStorage::Dense),
    };
    let label = format!("grid '{}' ({file})", o.label);
    let store: GridStore = match storage {
        GridStorage::Band { cells } => match BandGrid::from_dense(grid, cells) {
            Ok(b) => b.into(),
            Err(_) => SdfGrid::clone(grid).into(),
        },
        GridStorage::Dense => SdfGrid::clone(grid).into(),
    };
    Box::new(GridObject::placed(store, &transform, o.material, march, label))
}

/// The zero level set of a grid-file object's trilinear field, in world space, extracted at
/// `resolution` cells (at most [`MAX_EXTRACT_RESOLUTION`]) along the longest axis of its
/// box with marching cubes, or with `method`'s extraction method; `None` for other objects
/// or when the grid holds no surface.
pub fn grid_file_mesh(o: &Object, resolution: u32, method: MeshMethod) -> Option<TriangleMesh> {
    let ObjectKind::Grid { grid, .. } = &o.kind else { return None };
    let how = match method {
        MeshMethod::Extracted(m) => m,
        MeshMethod::Parametric => ExtractMethod::MarchingCubes,
    };
    // The field of `GridObject::placed`: the grid's frame under a rigid transform with
    // uniform scale (checked when the scene is read), so distances scale exactly.
    let t = o.compiled_transform();
    let (to_local, scale) = (t.to_local_f64, t.min_scale as f64);
    let f = |p: DVec3| grid.trilinear(to_local.transform_point3(p).as_vec3()) as f64 * scale;
    let bounds = o.bounds()?;
    let mesh = crate::convert::extract::extract(
        &f,
        Field::Arbitrary,
        &bounds,
        resolution.min(MAX_EXTRACT_RESOLUTION),
        how,
    );
    (!mesh.triangles.is_empty()).then_some(mesh)
}

/// Builds the scene geometry in representation `repr`.
pub fn build_scene(scene: &Scene, repr: Representation) -> SceneGeometry {
    SceneGeometry::new(build_objects(scene, repr))
}

/// Largest resolution SDF-to-mesh extraction is run at in the mesh representation.
pub const MAX_EXTRACT_RESOLUTION: u32 = 512;

/// A primitive object tessellated at `resolution` and traced as a mesh under the object's
/// transform; an infinite plane becomes a disc around the camera; a bounded CSG or
/// repetition node is extracted from its SDF. `None` for unbounded nodes.
fn tessellated(
    scene: &Scene,
    o: &Object,
    resolution: u32,
    shading: Shading,
    method: MeshMethod,
) -> Option<MeshGeometry> {
    let parametric = matches!(
        (&o.kind, method),
        (ObjectKind::Primitive(Primitive::Plane { .. }), _)
            | (ObjectKind::Primitive(_), MeshMethod::Parametric)
    );
    if !parametric {
        // CSG and bounded repetition (and every bounded object when extraction is asked
        // for): extracted from the SDF at most 512 cells along the longest axis (the
        // sample grid is held in memory while extracting).
        let how = match method {
            MeshMethod::Extracted(m) => m,
            MeshMethod::Parametric => ExtractMethod::MarchingCubes,
        };
        let res = resolution.min(MAX_EXTRACT_RESOLUTION);
        let mesh = extract_object(o, res, how)?;
        if mesh.triangles.is_empty() {
            return None;
        }
        let label = format!("{} '{}' extracted from its SDF at {res} cells", o.kind_name(), o.label);
        return Some(MeshGeometry::new(mesh, Shading::Flat, Transform::IDENTITY, o.material, label));
    }
    let ObjectKind::Primitive(prim) = &o.kind else { return None };
    let label = format!("{} '{}' tessellated at {resolution}", prim.kind_name(), o.label);
    if let Primitive::Plane { normal, offset } = *prim {
        let t = o.compiled_transform();
        let n = t.normal_to_world(normal);
        let p0 = t.to_world.transform_point3(normal * offset);
        let mesh = plane_view_mesh(n, n.dot(p0), scene.camera.position, scene.settings.max_distance);
        return Some(MeshGeometry::new(mesh, Shading::Flat, Transform::IDENTITY, o.material, label));
    }
    let mesh = tessellate(prim, resolution, None);
    // Sharp-edged shapes come without vertex normals: they stay flat even when smooth
    // shading is asked for (averaged normals would round their edges off).
    let shading = if mesh.normals.is_some() { shading } else { Shading::Flat };
    Some(MeshGeometry::new(mesh, shading, o.compiled_transform(), o.material, label))
}

/// Every object of `scene` that the mesh representation `repr` turns into triangles, in
/// world space, as one mesh (for artifacts and external checks); `None` when `repr` is not
/// a mesh representation or nothing becomes triangles.
pub fn scene_mesh(scene: &Scene, repr: Representation) -> Option<TriangleMesh> {
    let Representation::Mesh { resolution, shading, method, .. } = repr else { return None };
    let mut all = TriangleMesh::default();
    for o in &scene.objects {
        let mesh = match &o.kind {
            ObjectKind::Mesh { mesh, .. } => {
                let mut m = TriangleMesh::clone(mesh);
                m.transform(&o.compiled_transform().to_world);
                m
            }
            ObjectKind::Grid { .. } => match grid_file_mesh(o, resolution, method) {
                Some(m) => m,
                None => continue,
            },
            _ => match tessellated(scene, o, resolution, shading, method) {
                Some(g) => g.world_mesh(),
                None => continue,
            },
        };
        let base = all.positions.len() as u32;
        all.positions.extend(&mesh.positions);
        all.triangles.extend(mesh.triangles.iter().map(|t| t.map(|i| i + base)));
    }
    (!all.triangles.is_empty()).then_some(all)
}

/// Margin of grids around an object's bounds, in cells: keeps the surface off the grid's
/// boundary so the interpolated field is closed.
pub const GRID_MARGIN_CELLS: u32 = 2;

/// A bounded object sampled into a world-space SDF grid, or `None` when it is unbounded,
/// unsigned (holds a triangle primitive) or its grid cannot be built.
///
/// `fill` applies to mesh objects only: [`GridFill::Voxelize`] voxelizes them
/// ([`crate::convert::mesh_to_grid::voxelize`], about one voxel of error; a mesh that voxelizing finds open
/// falls back to exact sampling and its label says so). Analytic objects (primitives, CSG,
/// repetition) are always sampled exactly from their SDF. `storage`
/// [`GridStorage::Band`] keeps only the bricks near the surface
/// ([`crate::geometry::grid::band`]); it is built without a dense grid except for voxelized meshes
/// (the distance transform needs the whole grid).
///
/// View clipping: an analytic object whose box is much larger than the region the camera
/// sees ([`view_region`]: the view frustum out to twice the other objects' farthest
/// corner; used when it cuts the object's longest extent by more than
/// [`VIEW_CLIP_FRACTION`]) is gridded only inside that region, `resolution` cells along
/// the clipped box's longest axis, and sphere traced on its analytic SDF outside it
/// ([`ClippedGrid`]); entirely outside the region it is only sphere traced. Mesh objects
/// are never clipped.
fn gridded(
    scene: &Scene,
    o: &Object,
    resolution: u32,
    fill: GridFill,
    storage: GridStorage,
    march: MarchParams,
) -> Option<Box<dyn Geometry>> {
    let b = o.bounds()?;
    let (mut lo, mut hi) = (Vec3::from(b.min), Vec3::from(b.max));
    let kind = o.kind_name();
    let is_mesh = matches!(o.kind, ObjectKind::Mesh { .. });
    let clip = if is_mesh { None } else { view_region(scene, o) };
    let mut clipped = false;
    if let Some(region) = clip {
        let c = region.intersection(&b);
        let (clo, chi) = (Vec3::from(c.min), Vec3::from(c.max));
        if !(chi - clo).cmpge(Vec3::ZERO).all() {
            let why = format!("{kind} '{}': sphere traced (outside the view region: no grid)", o.label);
            return Some(Box::new(SdfObject::new(o, march, why)?));
        }
        if (chi - clo).max_element() < VIEW_CLIP_FRACTION * (hi - lo).max_element() {
            (lo, hi, clipped) = (clo, chi, true);
        }
    }
    let band = |g: SdfGrid| -> Option<GridStore> {
        Some(match storage {
            GridStorage::Dense => g.into(),
            GridStorage::Band { cells } => BandGrid::from_dense(&g, cells).ok()?.into(),
        })
    };
    let mut how = "sampled";
    let grid: GridStore = if let ObjectKind::Mesh { mesh, .. } = &o.kind {
        let mut world = TriangleMesh::clone(mesh);
        world.transform(&o.compiled_transform().to_world);
        let voxelized = match fill {
            GridFill::Voxelize => match voxelize_mesh(&world, resolution, GRID_MARGIN_CELLS) {
                Ok(g) => {
                    how = "voxelized";
                    Some(g)
                }
                Err(_) => {
                    how = "sampled (voxelizing found it open)";
                    None
                }
            },
            GridFill::Sample => None,
        };
        match (voxelized, storage) {
            (Some(g), _) => band(g)?,
            (None, GridStorage::Dense) => sample_mesh(&world, resolution, GRID_MARGIN_CELLS).ok()?.into(),
            (None, GridStorage::Band { cells }) => {
                band_from_mesh(&world, resolution, GRID_MARGIN_CELLS, cells).ok()?.into()
            }
        }
    } else {
        let tree = SdfTree::new(o)?;
        if !tree.signed {
            return None;
        }
        let f = |p| tree.distance(p);
        match storage {
            GridStorage::Dense => sample_function(&f, lo, hi, resolution, GRID_MARGIN_CELLS).ok()?.into(),
            GridStorage::Band { cells } => {
                band_from_function(&f, lo, hi, resolution, GRID_MARGIN_CELLS, cells).ok()?.into()
            }
        }
    };
    let label = format!("{kind} '{}' {how} at {resolution}", o.label);
    let grid = GridObject::new(grid, o.material, march, label);
    if clipped {
        let why = format!("{kind} '{}' outside the view region", o.label);
        return Some(Box::new(ClippedGrid::new(grid, Box::new(SdfObject::new(o, march, why)?))));
    }
    Some(Box::new(grid))
}
