//! Builds the geometry an [`ObjectPlan`] names, and returns the realised plan: the one
//! that was built, with the fallbacks found while building (voxelizing finds a mesh open,
//! an extraction yields no triangles, a grid cannot be built). Meshes that objects share
//! ([`Build::SharedMesh`]) are built once, at the first object, and placed at the others;
//! an instanced repetition ([`Build::Instanced`]) builds its child's mesh once and places
//! it per copy.

use std::sync::Arc;

use glam::{DVec3, Vec3};

use super::{
    Build, Fallback, GRID_MARGIN_CELLS, GridFill, GridStorage, InstanceMesh, MAX_INSTANCES, MeshMethod,
    ObjectPlan, Representation, plan_object,
};
use crate::convert::extract::{ExtractMethod, Field, extract, extract_object};
use crate::convert::mesh_to_grid::MeshSampler;
use crate::convert::mesh_to_grid::band::{BandMember, band_from_function, band_from_members, band_from_mesh};
use crate::convert::mesh_to_grid::closest::TriangleBvh;
use crate::convert::mesh_to_grid::voxelize::voxelize_mesh;
use crate::convert::mesh_to_grid::winding::{FastWinding, is_closed};
use crate::convert::mesh_to_grid::{sample_function, sample_mesh};
use crate::convert::tessellate::{plane_view_mesh, tessellate};
use crate::error::Result;
use crate::geometry::analytic::AnalyticObject;
use crate::geometry::grid::SdfGrid;
use crate::geometry::grid::band::BandGrid;
use crate::geometry::grid::object::{ClippedGrid, GridObject, GridStore};
use crate::geometry::grid::scene::{SceneGrid, SceneGridObject};
use crate::geometry::implicit::ImplicitObject;
use crate::geometry::march::MarchParams;
use crate::geometry::mesh::MeshGeometry;
use crate::geometry::mesh::instance::{InstancedMesh, compose, repeat_offsets};
use crate::geometry::scene::SceneGeometry;
use crate::geometry::sdf::{SdfObject, SdfTree, sdf_geometry};
use crate::geometry::{Aabb, Geometry, MaterialId, aabb};
use crate::mesh::TriangleMesh;
use crate::scene::Scene;
use crate::scene::shape::{Object, ObjectKind, Primitive, Shading};
use crate::scene::transform::{Transform, TransformDesc};

/// Builds the geometry of every top-level object of `scene` in representation `repr`.
/// Sphere tracing takes its pixel footprint from the scene's camera.
pub fn build_objects(scene: &Scene, repr: Representation) -> Vec<Box<dyn Geometry>> {
    build_with_plans(scene, repr).0
}

/// Builds the scene geometry in representation `repr`.
pub fn build_scene(scene: &Scene, repr: Representation) -> SceneGeometry {
    build_scene_with_plans(scene, repr).0
}

/// Builds the scene geometry in representation `repr`, with the realised plan of each
/// object (in scene order, as [`SceneGeometry::objects`]): what was built and, where it is
/// not as asked, why.
pub fn build_scene_with_plans(scene: &Scene, repr: Representation) -> (SceneGeometry, Vec<ObjectPlan>) {
    let (objects, plans) = build_with_plans(scene, repr);
    (SceneGeometry::new(objects), plans)
}

fn build_with_plans(scene: &Scene, repr: Representation) -> (Vec<Box<dyn Geometry>>, Vec<ObjectPlan>) {
    let repr = repr.with_pixel_footprint(scene);
    // The mesh of each object built as a single mesh, which later objects of the same
    // geometry place (an `Arc` each, dropped at the end).
    let mut meshes: Vec<Option<MeshGeometry>> = Vec::with_capacity(scene.objects.len());
    // Likewise the grid of each object built in its own frame ([`Build::LocalGrid`]).
    let mut grids: Vec<Option<Arc<GridStore>>> = Vec::with_capacity(scene.objects.len());
    let mut objects = Vec::with_capacity(scene.objects.len());
    let mut plans = Vec::with_capacity(scene.objects.len());
    let asked: Vec<ObjectPlan> = scene.objects.iter().map(|o| plan_object(scene, o, repr)).collect();
    let shared = SharedGrid::build(scene, &asked);
    for (i, (o, plan)) in scene.objects.iter().zip(asked).enumerate() {
        let mut grid = None;
        let (g, realised, mesh): (Box<dyn Geometry>, _, _) = match plan.build {
            Build::SharedGrid { of, march } => {
                let of_label = scene.objects.get(of as usize).map_or("", |x| x.label.as_str());
                let label = format!("{} '{}' sharing the grid of '{of_label}'", o.kind_name(), o.label);
                match grids.get(of as usize).and_then(Option::clone) {
                    Some(shared) => {
                        let g = GridObject::placed_shared(
                            shared,
                            &o.compiled_transform(),
                            o.material,
                            march,
                            label,
                        );
                        (Box::new(g), plan, None)
                    }
                    // Not reached: the first object of a primitive is built in its own frame.
                    None => {
                        let (g, realised) = build_object(scene, o, repr, plan);
                        (g, realised, None)
                    }
                }
            }
            Build::LocalGrid { resolution, storage, march } => match local_grid(o, resolution, storage) {
                Some(store) => {
                    let label =
                        format!("{} '{}' sampled at {resolution} in its own frame", o.kind_name(), o.label);
                    let g = GridObject::placed_shared(
                        store.clone(),
                        &o.compiled_transform(),
                        o.material,
                        march,
                        label,
                    );
                    grid = Some(store);
                    (Box::new(g) as Box<dyn Geometry>, plan, None)
                }
                None => {
                    let (g, realised) = build_object(scene, o, repr, plan);
                    (g, realised, None)
                }
            },
            Build::Grid { storage: GridStorage::Scene { .. }, clip: None, resolution, march, .. } => {
                match &shared {
                    Some(s) if s.members[i] => {
                        let (g, label) = (&s.grid, &s.label);
                        let voxel = g.band().voxel;
                        let b = o.bounds().expect("members are bounded");
                        let margin = Vec3::splat(GRID_MARGIN_CELLS as f32 * voxel);
                        let bounds = aabb(Vec3::from(b.min) - margin, Vec3::from(b.max) + margin);
                        let text = format!("{} '{}' sampled at {resolution} {label}", o.kind_name(), o.label);
                        (Box::new(SceneGridObject::new(g.clone(), bounds, march, text)), plan, None)
                    }
                    _ => {
                        let Build::Grid { storage, fill, .. } = plan.build else {
                            unreachable!("a grid plan")
                        };
                        let own = ObjectPlan::fallback(
                            Build::Grid { resolution, fill, storage: storage.own(), march, clip: None },
                            Fallback::OwnGrid,
                        );
                        let (g, realised) = build_object(scene, o, repr, own);
                        (g, realised, None)
                    }
                }
            }
            Build::SharedMesh { of } => {
                let source = meshes.get(of as usize).and_then(Option::as_ref);
                let of_label = scene.objects.get(of as usize).map_or("", |x| x.label.as_str());
                let label = format!("{} '{}' sharing the mesh of '{of_label}'", o.kind_name(), o.label);
                match source {
                    Some(m) => (Box::new(m.placed(o.compiled_transform(), o.material, label)), plan, None),
                    // Not reached: the first object of a geometry is built as one mesh.
                    None => {
                        let (m, realised) = own_mesh(scene, o, repr);
                        (Box::new(m), realised, None)
                    }
                }
            }
            Build::MeshTriangles => {
                let m = mesh_triangles(scene, o);
                let keep = m.placed(*m.transform(), o.material, String::new());
                (Box::new(m), plan, Some(keep))
            }
            Build::Tessellated { .. } => match mesh_geometry(scene, o, plan.build) {
                Some((m, build)) => {
                    let keep = m.placed(*m.transform(), o.material, String::new());
                    (Box::new(m), ObjectPlan { build, ..plan }, Some(keep))
                }
                None => unreachable!("a tessellation always has triangles"),
            },
            _ => {
                let (g, realised) = build_object(scene, o, repr, plan);
                (g, realised, None)
            }
        };
        objects.push(g);
        plans.push(realised);
        meshes.push(mesh);
        grids.push(grid);
    }
    (objects, plans)
}

/// The grid that the objects planned [`GridStorage::Scene`] (and gridded whole) share.
struct SharedGrid {
    grid: Arc<SceneGrid>,
    /// Per object of the scene: whether it is in the grid.
    members: Vec<bool>,
    /// How the grid is named in its objects' descriptions.
    label: String,
}

impl SharedGrid {
    /// The shared grid of the objects whose plans ask for one: their signed distances
    /// (analytic objects from their SDF, meshes sampled exactly with winding-number signs)
    /// in one band at the median of their own voxel sizes (longest extent / resolution);
    /// `None` when no object asks or the grid cannot be built (each then gets its own).
    fn build(scene: &Scene, plans: &[ObjectPlan]) -> Option<SharedGrid> {
        enum Source {
            Sdf(SdfTree),
            Mesh { tree: TriangleBvh, wind: FastWinding, closed: bool },
        }
        let mut cells = 0;
        let mut voxels = Vec::new();
        let mut sources = Vec::new();
        for (i, (o, p)) in scene.objects.iter().zip(plans).enumerate() {
            let Build::Grid { storage: GridStorage::Scene { cells: c }, clip: None, resolution, .. } =
                p.build
            else {
                continue;
            };
            let Some(b) = o.bounds() else { continue };
            let source = match &o.kind {
                ObjectKind::Mesh { mesh, .. } => {
                    let mut world = TriangleMesh::clone(mesh);
                    world.transform(&o.compiled_transform().to_world);
                    if world.triangles.is_empty() {
                        continue;
                    }
                    let closed = is_closed(&world);
                    let tree = TriangleBvh::new(&world);
                    let wind = FastWinding::new(&tree);
                    Source::Mesh { tree, wind, closed }
                }
                _ => match SdfTree::new(o) {
                    Some(t) => Source::Sdf(t),
                    None => continue,
                },
            };
            cells = c;
            voxels.push((Vec3::from(b.max) - Vec3::from(b.min)).max_element() / resolution.max(1) as f32);
            sources.push((i, b, o.material, source));
        }
        if sources.is_empty() {
            return None;
        }
        voxels.sort_by(f32::total_cmp);
        let voxel = voxels[voxels.len() / 2];
        let mut materials: Vec<MaterialId> = sources.iter().map(|s| s.2).collect();
        materials.sort_unstable();
        materials.dedup();
        if materials.len() > u16::MAX as usize {
            return None;
        }
        let fields: Vec<Box<dyn Fn(DVec3) -> f64 + Sync + '_>> = sources
            .iter()
            .map(|(_, _, _, s)| -> Box<dyn Fn(DVec3) -> f64 + Sync + '_> {
                match s {
                    Source::Sdf(t) => Box::new(move |p| t.distance(p)),
                    Source::Mesh { tree, wind, closed } => Box::new(move |p: DVec3| {
                        MeshSampler::new(tree, wind, *closed).sample(p.as_vec3()) as f64
                    }),
                }
            })
            .collect();
        let members: Vec<BandMember<'_>> = sources
            .iter()
            .zip(&fields)
            .map(|((_, b, m, _), f)| BandMember {
                bounds: *b,
                distance: f.as_ref(),
                material: materials.binary_search(m).unwrap_or(0) as u16,
            })
            .collect();
        let (band, bricks) = band_from_members(&members, voxel, GRID_MARGIN_CELLS, cells).ok()?;
        let mut flags = vec![false; scene.objects.len()];
        for (i, ..) in &sources {
            flags[*i] = true;
        }
        let n = sources.len();
        let grid = Arc::new(SceneGrid::new(band, materials, bricks, n));
        let label = format!("into the scene grid (voxel {:.5}, {n} objects)", grid.band().voxel);
        Some(SharedGrid { grid, members: flags, label })
    }
}

/// A [`Build::SharedMesh`] object built as its own mesh (as the first object of its
/// geometry is), with that plan.
fn own_mesh(scene: &Scene, o: &Object, repr: Representation) -> (MeshGeometry, ObjectPlan) {
    match (&o.kind, repr) {
        (ObjectKind::Primitive(_), Representation::Mesh { resolution, shading, .. }) => {
            let (m, build) = mesh_geometry(scene, o, Build::Tessellated { resolution, shading })
                .expect("a tessellation always has triangles");
            (m, ObjectPlan::as_asked(build))
        }
        _ => (mesh_triangles(scene, o), ObjectPlan::as_asked(Build::MeshTriangles)),
    }
}

/// Builds `plan` for `o`, asked in `repr` (which names the sphere tracing used when a
/// fallback found while building turns to it, and words the descriptions); returns the
/// geometry and the realised plan.
fn build_object(
    scene: &Scene,
    o: &Object,
    repr: Representation,
    plan: ObjectPlan,
) -> (Box<dyn Geometry>, ObjectPlan) {
    let march = repr.march();
    let marched = |fallback: Fallback| -> (Box<dyn Geometry>, ObjectPlan) {
        let plan = ObjectPlan::fallback(Build::Marched { march }, fallback);
        (sphere_traced(o, repr, march, plan.fallback), plan)
    };
    match plan.build {
        Build::ClosedForm => {
            let ObjectKind::Primitive(p) = &o.kind else { unreachable!("closed form for primitives only") };
            (Box::new(AnalyticObject::new(*p, o)), plan)
        }
        Build::Marched { march } => (sphere_traced(o, repr, march, plan.fallback), plan),
        Build::MeshTriangles => (Box::new(mesh_triangles(scene, o)), plan),
        Build::Tessellated { .. } | Build::PlaneDisc { .. } | Build::Extracted { .. } => {
            match mesh_geometry(scene, o, plan.build) {
                Some((g, build)) => (Box::new(g), ObjectPlan { build, ..plan }),
                None => match plan.build {
                    Build::Extracted { resolution, .. } => marched(Fallback::EmptyExtraction { resolution }),
                    Build::PlaneDisc { .. } => marched(Fallback::NoPlaneDisc),
                    _ => unreachable!("a tessellation always has triangles"),
                },
            }
        }
        Build::SharedMesh { .. } => {
            let (m, realised) = own_mesh(scene, o, repr);
            (Box::new(m), realised)
        }
        Build::Instanced { .. } => match instanced(scene, o, plan.build) {
            Some((g, build)) => (Box::new(g), ObjectPlan { build, ..plan }),
            // The copies were counted when planning: only the child's extraction can fail.
            None => {
                let resolution = match plan.build {
                    Build::Instanced { mesh: InstanceMesh::Extracted { resolution, .. }, .. }
                    | Build::Instanced { mesh: InstanceMesh::Tessellated { resolution, .. }, .. } => {
                        resolution
                    }
                    _ => unreachable!("an instanced plan"),
                };
                marched(Fallback::EmptyExtraction { resolution })
            }
        },
        Build::GridFileExtracted { method, resolution } => match grid_file_surface(o, resolution, method) {
            Some(mesh) => {
                let label =
                    format!("grid '{}' ({}) extracted at {resolution} cells", o.label, grid_file_name(o));
                let g = MeshGeometry::new(mesh, Shading::Flat, Transform::IDENTITY, o.material, label);
                (Box::new(g), plan)
            }
            // No surface in the grid: march it (it will show nothing, honestly).
            None => {
                let build =
                    Build::GridFileMarched { storage: GridStorage::Dense, march: MarchParams::default() };
                let (g, realised) = grid_file_marched(o, build);
                (g, ObjectPlan::fallback(realised.build, Fallback::NoSurfaceInGridFile))
            }
        },
        Build::ImplicitMarched { march } => (implicit_marched(o, march, plan.fallback), plan),
        Build::ImplicitExtracted { method, resolution } => match implicit_surface(o, resolution, method) {
            Some(mesh) => {
                let label = format!(
                    "implicit '{}' extracted at {resolution} cells (every sample evaluated: not a distance)",
                    o.label
                );
                let g = MeshGeometry::new(mesh, Shading::Flat, o.compiled_transform(), o.material, label);
                (Box::new(g), plan)
            }
            None => {
                let build = Build::ImplicitMarched { march };
                let fallback = Fallback::EmptyExtraction { resolution };
                (implicit_marched(o, march, Some(fallback)), ObjectPlan::fallback(build, fallback))
            }
        },
        Build::GridFileMarched { .. } => {
            let (g, realised) = grid_file_marched(o, plan.build);
            (g, ObjectPlan { fallback: plan.fallback.or(realised.fallback), ..realised })
        }
        // Reached only when a grid could not be shared: the object is gridded on its own.
        Build::LocalGrid { resolution, storage, march } => {
            let own = Build::Grid { resolution, fill: GridFill::Sample, storage, march, clip: None };
            build_object(scene, o, repr, ObjectPlan { build: own, ..plan })
        }
        Build::SharedGrid { march, .. } => {
            let Representation::Grid { resolution, storage, .. } = repr else { unreachable!("a grid plan") };
            let own = Build::Grid { resolution, fill: GridFill::Sample, storage, march, clip: None };
            build_object(scene, o, repr, ObjectPlan { build: own, ..plan })
        }
        Build::InstancedGrid { .. } => match instanced_grid(scene, o, plan.build) {
            Some(g) => (g, plan),
            None => marched(Fallback::GridNotBuilt),
        },
        Build::Grid { .. } => match gridded(o, plan) {
            Some(built) => built,
            None if matches!(o.kind, ObjectKind::Mesh { .. }) => (
                Box::new(mesh_triangles(scene, o)),
                ObjectPlan::fallback(Build::MeshTriangles, Fallback::GridNotBuilt),
            ),
            None => marched(Fallback::GridNotBuilt),
        },
    }
}

/// An implicit object traced by its safe marcher; the description says why where it is
/// not the asked representation.
fn implicit_marched(o: &Object, march: MarchParams, fallback: Option<Fallback>) -> Box<dyn Geometry> {
    let ObjectKind::Implicit { field, .. } = &o.kind else { unreachable!("called for implicit models only") };
    let label = match fallback {
        None => o.label.clone(),
        Some(Fallback::NoClosedForm { .. }) => format!("{} (no closed form: traced safely)", o.label),
        Some(f) => format!("{} ({f})", o.label),
    };
    Box::new(ImplicitObject::new(field.clone(), o.compiled_transform(), o.material, march, label))
}

/// The surface of an implicit object extracted at `resolution` cells along the cube
/// [-1, 1]^3 of its frame, in that frame; `None` when it has no triangles.
pub fn implicit_surface(o: &Object, resolution: u32, method: ExtractMethod) -> Option<TriangleMesh> {
    let ObjectKind::Implicit { field, .. } = &o.kind else { return None };
    let e = crate::implicit::field3d::EXTENT as f32;
    let cube = aabb(Vec3::splat(-e), Vec3::splat(e));
    // The solid as the marcher sees it: the model within the cube (cut by its faces).
    let f = |p: DVec3| {
        let v = IMPLICIT_SCRATCH.with(|s| field.value(p, &mut s.borrow_mut()));
        v.max(p.abs().max_element() - crate::implicit::field3d::EXTENT)
    };
    let mesh = extract(&f, Field::Arbitrary, &cube, resolution, method);
    (!mesh.triangles.is_empty()).then_some(mesh)
}

/// [`implicit_surface`] placed in world space by the object's transform.
pub fn implicit_world_mesh(o: &Object, resolution: u32, method: ExtractMethod) -> Option<TriangleMesh> {
    let mut m = implicit_surface(o, resolution, method)?;
    m.transform(&o.compiled_transform().to_world);
    Some(m)
}

thread_local! {
    static IMPLICIT_SCRATCH: std::cell::RefCell<crate::implicit::field3d::Scratch> =
        std::cell::RefCell::new(Default::default());
}

/// `o` sphere traced on its analytic SDF, described by why (from `repr` and `fallback`).
fn sphere_traced(
    o: &Object,
    repr: Representation,
    march: MarchParams,
    fallback: Option<Fallback>,
) -> Box<dyn Geometry> {
    let kind = o.kind_name();
    // The descriptions of the render report (`toolkit render`), naming the true cause. The
    // first three `format!`s are written as they always were: the string's capacity counts
    // in `bytes_used` (the compare CSV's bytes), so those rows keep their bytes.
    let no = if matches!(repr, Representation::Mesh { .. }) { "no mesh" } else { "no grid" };
    let why = match fallback {
        None => format!("{kind} '{}': sphere traced", o.label),
        Some(Fallback::NoClosedForm { kind }) => {
            format!("{kind} '{}': sphere traced (no closed form for {kind})", o.label)
        }
        Some(Fallback::OutsideViewRegion) => {
            format!("{kind} '{}': sphere traced (outside the view region: no grid)", o.label)
        }
        Some(Fallback::Unbounded) => format!("{kind} '{}': sphere traced (unbounded: {no})", o.label),
        Some(Fallback::Unsigned) => {
            format!("{kind} '{}': sphere traced (unsigned distance, it holds a triangle: {no})", o.label)
        }
        Some(Fallback::EmptyExtraction { resolution }) => format!(
            "{kind} '{}': sphere traced (extraction at {resolution} cells gave no triangles: no sample \
             inside, thinner than a cell)",
            o.label
        ),
        Some(Fallback::NoPlaneDisc) => {
            format!("{kind} '{}': sphere traced (no disc of the plane in f32 range: {no})", o.label)
        }
        Some(f) => format!("{kind} '{}': sphere traced ({f})", o.label),
    };
    match sdf_geometry(o, march, why) {
        Some(s) => s,
        None => unreachable!("meshes and grid files are never sphere traced"),
    }
}

/// A loaded mesh traced as its triangles, in the scene's mesh layout
/// ([`crate::scene::Settings::mesh_layout`]).
fn mesh_triangles(scene: &Scene, o: &Object) -> MeshGeometry {
    let ObjectKind::Mesh { mesh, shading, .. } = &o.kind else { unreachable!("called for meshes only") };
    MeshGeometry::with_layout(
        TriangleMesh::clone(mesh),
        *shading,
        o.compiled_transform(),
        o.material,
        format!("mesh '{}'", o.label),
        scene.settings.mesh_layout,
    )
}

/// The triangles of a [`Build::Tessellated`], [`Build::PlaneDisc`] or [`Build::Extracted`]
/// plan, with the realised build (the shading a tessellation got); `None` when an
/// extraction gives no triangles.
fn mesh_geometry(scene: &Scene, o: &Object, build: Build) -> Option<(MeshGeometry, Build)> {
    let prim = || match &o.kind {
        ObjectKind::Primitive(p) => *p,
        _ => unreachable!("tessellation of primitives only"),
    };
    match build {
        Build::Extracted { method, resolution } => {
            // The sample grid is held in memory while extracting.
            let mesh = extract_object(o, resolution, method)?;
            if mesh.triangles.is_empty() {
                return None;
            }
            let mut label =
                format!("{} '{}' extracted from its SDF at {resolution} cells", o.kind_name(), o.label);
            if let ObjectKind::Repeat { .. } = o.kind {
                label += &format!(" (more than {MAX_INSTANCES} copies: not instanced)");
            } else if holds_repeat(o) {
                label += " (its repetition is inside CSG: extracted whole, not instanced)";
            }
            Some((MeshGeometry::new(mesh, Shading::Flat, Transform::IDENTITY, o.material, label), build))
        }
        Build::PlaneDisc { resolution } => {
            let prim = prim();
            let Primitive::Plane { normal, offset } = prim else { unreachable!("discs of planes only") };
            let label = format!("{} '{}' tessellated at {resolution}", prim.kind_name(), o.label);
            let (n, d) = world_plane(&o.compiled_transform(), normal, offset)?;
            let mesh = plane_view_mesh(n, d, scene.camera.position, scene.settings.max_distance);
            if mesh.triangles.is_empty() {
                return None;
            }
            Some((MeshGeometry::new(mesh, Shading::Flat, Transform::IDENTITY, o.material, label), build))
        }
        Build::Tessellated { resolution, shading } => {
            let prim = prim();
            let label = format!("{} '{}' tessellated at {resolution}", prim.kind_name(), o.label);
            let mesh = tessellate(&prim, resolution, None);
            // Sharp-edged shapes come without vertex normals: they stay flat even when
            // smooth shading is asked for (averaged normals would round their edges off).
            let shading = if mesh.normals.is_some() { shading } else { Shading::Flat };
            let g = MeshGeometry::new(mesh, shading, o.compiled_transform(), o.material, label);
            Some((g, Build::Tessellated { resolution, shading }))
        }
        _ => unreachable!("not a triangle plan"),
    }
}

/// The world plane `n . p = d` (unit `n`) of the local plane `normal . p = offset` under
/// `t`. The normal is [`Transform::normal_to_world`]'s where that is a unit vector; under
/// scales far from 1 (`scale = [1, 1e30, 1]`) its `f32` length underflows or overflows
/// and the normal comes out NaN or zero, so then it is computed in `f64` (the transpose
/// of the inverse). `None` where the plane lies beyond the `f32` range.
fn world_plane(t: &Transform, normal: Vec3, offset: f32) -> Option<(Vec3, f32)> {
    let n = t.normal_to_world(normal);
    let n = if n.is_finite() && (n.length() - 1.0).abs() <= 1e-4 {
        n
    } else {
        let n = (t.to_local_f64.matrix3.transpose() * normal.as_dvec3()).normalize_or_zero().as_vec3();
        if n == Vec3::ZERO {
            return None;
        }
        n.normalize()
    };
    let p0 = t.to_world.transform_point3(normal * offset);
    let d = n.dot(p0);
    (p0.is_finite() && d.is_finite()).then_some((n, d))
}

/// Whether `o` holds a repetition below itself.
fn holds_repeat(o: &Object) -> bool {
    match &o.kind {
        ObjectKind::Csg { children, .. } => {
            children.iter().any(|c| matches!(c.kind, ObjectKind::Repeat { .. }) || holds_repeat(c))
        }
        ObjectKind::Repeat { child, .. } => {
            matches!(child.kind, ObjectKind::Repeat { .. }) || holds_repeat(child)
        }
        _ => false,
    }
}

/// A [`Build::Instanced`] plan built: the repetition `o`'s child made into one mesh and
/// placed at every copy ([`repeat_offsets`]), with the realised build (the shading a
/// tessellation got, the copies placed); `None` when the child's extraction gives no
/// triangles or the copies cannot be placed.
fn instanced(scene: &Scene, o: &Object, build: Build) -> Option<(InstancedMesh, Build)> {
    let Build::Instanced { mesh: how, .. } = build else { unreachable!("an instanced plan") };
    let ObjectKind::Repeat { child, count, .. } = &o.kind else { unreachable!("repetitions only") };
    let copies = repeat_offsets(scene, o, MAX_INSTANCES)?;
    let (mesh, shading, inner, realised, what) = match how {
        InstanceMesh::Tessellated { resolution, shading } => {
            let ObjectKind::Primitive(p) = &child.kind else {
                unreachable!("tessellation of primitives only")
            };
            let mesh = tessellate(p, resolution, None);
            // Sharp-edged shapes stay flat, as in `mesh_geometry`.
            let shading = if mesh.normals.is_some() { shading } else { Shading::Flat };
            let what = format!("{} tessellated at {resolution}", p.kind_name());
            (
                mesh,
                shading,
                child.compiled_transform(),
                InstanceMesh::Tessellated { resolution, shading },
                what,
            )
        }
        InstanceMesh::Extracted { method, resolution } => {
            // In the repetition's frame: the child's own transform is in its SDF.
            let mesh = extract_object(child, resolution, method).filter(|m| !m.triangles.is_empty())?;
            let what = format!("{} extracted from its SDF at {resolution} cells", child.kind_name());
            (mesh, Shading::Flat, Transform::IDENTITY, how, what)
        }
    };
    let one = MeshGeometry::new(mesh, shading, Transform::IDENTITY, child.material, String::new());
    let outer = o.compiled_transform();
    let instances: Vec<MeshGeometry> = copies
        .offsets
        .iter()
        .map(|&offset| one.placed(compose(&outer, offset, &inner), child.material, String::new()))
        .collect();
    drop(one);
    let n = instances.len();
    let which = match (count, copies.reach) {
        (Some(c), _) => format!("{}x{}x{} copies", c.x, c.y, c.z),
        (None, Some(reach)) => format!(
            "infinite, the {n} copies in view out to {reach} (max_distance {})",
            scene.settings.max_distance
        ),
        (None, None) => unreachable!("an infinite repetition has a reach"),
    };
    let label =
        format!("repeat '{}' instanced ({which}): {n} placements of one mesh, the child {what}", o.label);
    let build = Build::Instanced { mesh: realised, copies: n as u32, reach: copies.reach };
    Some((InstancedMesh::new(instances, label), build))
}

/// A [`Build::InstancedGrid`] plan built: the repetition `o`'s child gridded once in the
/// repetition's frame and placed at every copy ([`repeat_offsets`]) under the copies' own
/// BVH; `None` when the child's grid cannot be built or the copies cannot be placed.
fn instanced_grid(scene: &Scene, o: &Object, build: Build) -> Option<Box<dyn Geometry>> {
    let Build::InstancedGrid { resolution, storage, march, .. } = build else {
        unreachable!("an instanced grid")
    };
    let ObjectKind::Repeat { child, count, .. } = &o.kind else { unreachable!("repetitions only") };
    let copies = repeat_offsets(scene, o, MAX_INSTANCES)?;
    // In the repetition's frame: the child's own transform is in its SDF.
    let store = Arc::new(sampled_grid(child, child.bounds()?, resolution, storage)?);
    let outer = o.compiled_transform();
    let placed: Vec<Box<dyn Geometry>> = copies
        .offsets
        .iter()
        .map(|&offset| -> Box<dyn Geometry> {
            let t = compose(&outer, offset, &Transform::IDENTITY);
            Box::new(GridObject::placed_shared(store.clone(), &t, child.material, march, String::new()))
        })
        .collect();
    let n = placed.len();
    let which = match (count, copies.reach) {
        (Some(c), _) => format!("{}x{}x{} copies", c.x, c.y, c.z),
        (None, Some(reach)) => format!("infinite, the {n} copies in view out to {reach}"),
        (None, None) => unreachable!("an infinite repetition has a reach"),
    };
    let d = store.dims();
    let label = format!(
        "repeat '{}' instanced ({which}): {n} placements of one grid of {}x{}x{} samples, the child {} sampled \
         at {resolution}",
        o.label,
        d.x,
        d.y,
        d.z,
        child.kind_name()
    );
    Some(Box::new(SceneGeometry::labelled(placed, label)))
}

/// A grid file's name for descriptions.
fn grid_file_name(o: &Object) -> String {
    let ObjectKind::Grid { source, .. } = &o.kind else { unreachable!("called for grid objects only") };
    source.file_name().map_or_else(|| source.display().to_string(), |f| f.to_string_lossy().into())
}

/// A grid-file object ray marched ([`Build::GridFileMarched`]), stored as a narrow band
/// when asked and possible; returns the realised plan.
fn grid_file_marched(o: &Object, build: Build) -> (Box<dyn Geometry>, ObjectPlan) {
    let ObjectKind::Grid { grid, .. } = &o.kind else { unreachable!("called for grid objects only") };
    let Build::GridFileMarched { storage, march } = build else { unreachable!("a marched grid file") };
    let label = format!("grid '{}' ({})", o.label, grid_file_name(o));
    let (store, plan): (GridStore, _) = match storage {
        GridStorage::Band { cells } | GridStorage::Scene { cells } => match BandGrid::from_dense(grid, cells)
        {
            Ok(b) => (b.into(), ObjectPlan::as_asked(build)),
            Err(_) => (
                SdfGrid::clone(grid).into(),
                ObjectPlan::fallback(
                    Build::GridFileMarched { storage: GridStorage::Dense, march },
                    Fallback::DenseInsteadOfBand,
                ),
            ),
        },
        GridStorage::Dense => (SdfGrid::clone(grid).into(), ObjectPlan::as_asked(build)),
    };
    let transform = o.compiled_transform();
    (Box::new(GridObject::placed(store, &transform, o.material, march, label)), plan)
}

/// The zero level set of a grid-file object's trilinear field, in world space, extracted at
/// `resolution` cells (at most [`super::MAX_EXTRACT_RESOLUTION`]: [`super::extract_resolution`]) along the longest axis
/// of its box with marching cubes, or with `method`'s extraction method; `None` for other
/// objects or when the grid holds no surface.
pub fn grid_file_mesh(o: &Object, resolution: u32, method: MeshMethod) -> Option<TriangleMesh> {
    grid_file_surface(o, super::extract_resolution(resolution), method.extract_method())
}

/// [`grid_file_mesh`] at `resolution` cells with `method`.
fn grid_file_surface(o: &Object, resolution: u32, method: ExtractMethod) -> Option<TriangleMesh> {
    let ObjectKind::Grid { grid, .. } = &o.kind else { return None };
    // The field of `GridObject::placed`: the grid's frame under a rigid transform with
    // uniform scale (checked when the scene is read), so distances scale exactly.
    let t = o.compiled_transform();
    let (to_local, scale) = (t.to_local_f64, t.min_scale as f64);
    let f = |p: DVec3| grid.trilinear(to_local.transform_point3(p).as_vec3()) as f64 * scale;
    let bounds = o.bounds()?;
    let mesh = extract(&f, Field::Arbitrary, &bounds, resolution, method);
    (!mesh.triangles.is_empty()).then_some(mesh)
}

/// Every object of `scene` that the mesh representation `repr` turns into triangles, in
/// world space, as one mesh (for artifacts and external checks); `None` when `repr` is not
/// a mesh representation or nothing becomes triangles.
pub fn scene_mesh(scene: &Scene, repr: Representation) -> Option<TriangleMesh> {
    if !matches!(repr, Representation::Mesh { .. }) {
        return None;
    }
    let mut all = TriangleMesh::default();
    for o in &scene.objects {
        let mesh = match plan_object(scene, o, repr).build {
            Build::MeshTriangles => {
                let ObjectKind::Mesh { mesh, .. } = &o.kind else { continue };
                let mut m = TriangleMesh::clone(mesh);
                m.transform(&o.compiled_transform().to_world);
                m
            }
            Build::GridFileExtracted { method, resolution } => match grid_file_surface(o, resolution, method)
            {
                Some(m) => m,
                None => continue,
            },
            build @ (Build::Tessellated { .. } | Build::PlaneDisc { .. } | Build::Extracted { .. }) => {
                match mesh_geometry(scene, o, build) {
                    Some((g, _)) => g.world_mesh(),
                    None => continue,
                }
            }
            Build::ImplicitExtracted { method, resolution } => {
                match implicit_world_mesh(o, resolution, method) {
                    Some(m) => m,
                    None => continue,
                }
            }
            Build::SharedMesh { .. } => own_mesh(scene, o, repr).0.world_mesh(),
            build @ Build::Instanced { .. } => match instanced(scene, o, build) {
                Some((g, _)) => g.world_mesh(),
                None => continue,
            },
            _ => continue,
        };
        let base = all.positions.len() as u32;
        all.positions.extend(&mesh.positions);
        all.triangles.extend(mesh.triangles.iter().map(|t| t.map(|i| i + base)));
    }
    (!all.triangles.is_empty()).then_some(all)
}

/// The grid of primitive `o` in its own frame (its local box, `resolution` cells along the
/// longest axis, with [`GRID_MARGIN_CELLS`]), stored as `storage` says; `None` when it
/// cannot be built.
fn local_grid(o: &Object, resolution: u32, storage: GridStorage) -> Option<Arc<GridStore>> {
    let local = Object { transform: TransformDesc::default(), ..o.clone() };
    sampled_grid(&local, local.bounds()?, resolution, storage).map(Arc::new)
}

/// The analytic object `o` sampled exactly from its SDF into a grid over the box `b` (in
/// the frame `o`'s transform maps into: its bounds, or a view-region clip of them),
/// `resolution` cells along the longest axis with [`GRID_MARGIN_CELLS`], dense or as a
/// narrow band as `storage` says (a scene grid's width when the object has a grid of its
/// own); `None` when it cannot be built.
fn sampled_grid(o: &Object, b: Aabb, resolution: u32, storage: GridStorage) -> Option<GridStore> {
    let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
    let tree = SdfTree::new(o)?;
    let f = |p| tree.distance(p);
    Some(match storage {
        GridStorage::Dense => sample_function(&f, lo, hi, resolution, GRID_MARGIN_CELLS).ok()?.into(),
        GridStorage::Band { cells } | GridStorage::Scene { cells } => {
            band_from_function(&f, lo, hi, resolution, GRID_MARGIN_CELLS, cells).ok()?.into()
        }
    })
}

/// A [`Build::Grid`] plan built: `o` sampled into a world-space SDF grid, or `None` when
/// its grid cannot be built. Returns the realised plan.
///
/// `fill` applies to mesh objects only: [`GridFill::Voxelize`] voxelizes them
/// ([`crate::convert::mesh_to_grid::voxelize`], about one voxel of error; a mesh that voxelizing
/// finds open is sampled exactly instead, [`Fallback::OpenMeshSampled`]). Analytic objects
/// (primitives, CSG, repetition) are always sampled exactly from their SDF. `storage`
/// [`GridStorage::Band`] keeps only the bricks near the surface
/// ([`crate::geometry::grid::band`]); it is built without a dense grid except for voxelized
/// meshes (the distance transform needs the whole grid).
///
/// View clipping ([`plan_object`] decides it): an object with a `clip` box is gridded
/// only inside it, `resolution` cells along the clipped box's longest axis, and sphere
/// traced on its analytic SDF outside it ([`ClippedGrid`]).
fn gridded(o: &Object, plan: ObjectPlan) -> Option<(Box<dyn Geometry>, ObjectPlan)> {
    let Build::Grid { resolution, fill, storage, march, clip } = plan.build else {
        unreachable!("a grid plan")
    };
    let b = clip.or_else(|| o.bounds())?;
    let kind = o.kind_name();
    // A scene grid that could not take the object: a band of its own.
    let storage = storage.own();
    let band = |g: SdfGrid| -> Option<GridStore> {
        Some(match storage {
            GridStorage::Dense => g.into(),
            GridStorage::Band { cells } | GridStorage::Scene { cells } => {
                BandGrid::from_dense(&g, cells).ok()?.into()
            }
        })
    };
    let mut realised = plan;
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
                    realised = ObjectPlan::fallback(
                        Build::Grid { resolution, fill: GridFill::Sample, storage, march, clip },
                        Fallback::OpenMeshSampled,
                    );
                    None
                }
            },
            GridFill::Sample => None,
        };
        match (voxelized, storage) {
            (Some(g), _) => band(g)?,
            (None, GridStorage::Dense) => sample_mesh(&world, resolution, GRID_MARGIN_CELLS).ok()?.into(),
            (None, GridStorage::Band { cells } | GridStorage::Scene { cells }) => {
                band_from_mesh(&world, resolution, GRID_MARGIN_CELLS, cells).ok()?.into()
            }
        }
    } else {
        sampled_grid(o, b, resolution, storage)?
    };
    let label = format!("{kind} '{}' {how} at {resolution}", o.label);
    let grid = GridObject::new(grid, o.material, march, label);
    if clip.is_some() {
        let why = format!("{kind} '{}' outside the view region", o.label);
        let outside = Box::new(SdfObject::new(o, march, why)?);
        return Some((Box::new(ClippedGrid::new(grid, outside)), realised));
    }
    Some((Box::new(grid), realised))
}

/// The compare experiment's mesh round trip: `mesh` sampled or voxelized into a grid of
/// `resolution` cells along its longest axis (with [`GRID_MARGIN_CELLS`]), and that grid's
/// zero level set extracted back with marching cubes at its own cell count. Returns the
/// grid and the extracted mesh (both in `mesh`'s frame).
///
/// # Errors
/// When the grid cannot be built (a mesh without triangles, one that voxelizing finds
/// open, a grid over the size limit).
pub fn reextract_mesh(
    mesh: &TriangleMesh,
    fill: GridFill,
    resolution: u32,
) -> Result<(SdfGrid, TriangleMesh)> {
    let grid = match fill {
        GridFill::Sample => sample_mesh(mesh, resolution, GRID_MARGIN_CELLS)?,
        GridFill::Voxelize => voxelize_mesh(mesh, resolution, GRID_MARGIN_CELLS)?,
    };
    let (lo, hi) = grid.bounds();
    let cells = (grid.dims - 1).max_element();
    let surface = extract(
        &|p: DVec3| grid.trilinear(p.as_vec3()) as f64,
        Field::Arbitrary,
        &aabb(lo, hi),
        cells,
        ExtractMethod::MarchingCubes,
    );
    Ok((grid, surface))
}
