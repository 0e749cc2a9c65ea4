//! The object plan: how each scene object is built for tracing in a [`Representation`].
//!
//! One place decides. [`plan_object`] looks at an object and the asked representation and
//! returns an [`ObjectPlan`]; the builder ([`build_scene_with_plans`], [`build_objects`],
//! [`scene_mesh`]) builds exactly that, and the memory estimate
//! ([`budget::scene_bytes`]) counts exactly that, so the two cannot disagree.
//!
//! The plans ([`Build`]):
//! - [`Build::ClosedForm`]: closed-form ray/primitive intersection (primitives, analytic;
//!   infinite planes in every representation).
//! - [`Build::Marched`]: sphere tracing of the analytic SDF (the sdf representation, and
//!   every fallback below that says "sphere traced").
//! - [`Build::MeshTriangles`]: a loaded mesh traced as its own triangles.
//! - [`Build::Tessellated`]: a primitive tessellated parametrically.
//! - [`Build::PlaneDisc`]: an infinite plane as a disc around the camera (the mesh
//!   representation with [`MeshPlane::Disc`]).
//! - [`Build::Extracted`]: a bounded object's surface extracted from its SDF.
//! - [`Build::Instanced`]: a repetition's child made into one mesh (tessellated or
//!   extracted) with one BVH, placed once per copy under the scene's top-level BVH, as a
//!   polygon renderer instances repeated geometry: every copy of a finite repetition (up
//!   to [`MAX_INSTANCES`]), the copies in view out to `max_distance` of an infinite one.
//!   Repetition inside CSG (a box minus repeated crosses) cannot be instanced: that
//!   object is extracted whole.
//! - [`Build::SharedMesh`]: a top-level object with the same geometry (kind and
//!   parameters) as an earlier one placed from that one's mesh and BVH (not a copy).
//! - [`Build::Grid`]: an object sampled (or a mesh voxelized) into an SDF grid, dense or
//!   narrow band, possibly clipped to the view region, or into the one narrow band the
//!   scene's objects share ([`GridStorage::Scene`]).
//! - [`Build::LocalGrid`], [`Build::SharedGrid`]: primitives of the same kind and
//!   parameters share one grid sampled in the first one's frame and placed by each one's
//!   transform (rigid, uniform scale), as meshes share one mesh.
//! - [`Build::InstancedGrid`]: a repetition's child gridded once and placed per copy (the
//!   copies of [`Build::Instanced`]).
//! - [`Build::ImplicitMarched`], [`Build::ImplicitExtracted`]: an implicit `.vm` model
//!   traced by its safe marcher (the sdf representation; the analytic and grid ones too,
//!   saying why), or its surface extracted from its samples (the mesh representation).
//! - [`Build::GridFileMarched`], [`Build::GridFileExtracted`]: a grid file ray marched,
//!   or its surface extracted.
//!
//! Fallbacks are typed: [`ObjectPlan::fallback`] says why an object is not in the asked
//! representation ([`Fallback`]). Some are known only while building (voxelizing finds a
//! mesh open, an extraction yields no triangles, a grid cannot be built): the builder
//! returns the realised plan, with the fallback that actually happened, beside the
//! geometry ([`build_scene_with_plans`]).

pub mod budget;
mod build;

use std::fmt;

use glam::Vec3;

pub use crate::geometry::mesh::instance::MAX_INSTANCES;
pub use build::{
    build_objects, build_scene, build_scene_with_plans, grid_file_mesh, implicit_surface,
    implicit_world_mesh, reextract_mesh, scene_mesh,
};

use crate::convert::extract::ExtractMethod;
use crate::geometry::Aabb;
use crate::geometry::grid::object::{VIEW_CLIP_FRACTION, view_region};
use crate::geometry::march::MarchParams;
use crate::geometry::mesh::instance::repeat_offsets;
use crate::geometry::sdf::SdfTree;
use crate::scene::Scene;
use crate::scene::shape::{Object, ObjectKind, Primitive, Shading};

/// Which representation, without its parameters: the one list of representations, from
/// which the command line's `--repr` values (a [`clap::ValueEnum`]), the names in reports
/// and file names, and the compare CSV's `repr` column all come.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum ReprKind {
    /// Closed-form intersection where it exists (CSG and repetition are sphere traced).
    Analytic,
    /// Sphere tracing of the analytic signed distance functions.
    Sdf,
    /// Primitives tessellated at --res and ray traced as triangle meshes.
    Mesh,
    /// Objects sampled into signed distance grids of --res cells and ray marched.
    Grid,
}

impl ReprKind {
    /// Every representation, in the order of the command line's list.
    pub const ALL: [ReprKind; 4] = [ReprKind::Analytic, ReprKind::Sdf, ReprKind::Mesh, ReprKind::Grid];

    /// The command-line name (`analytic`, `sdf`, `mesh`, `grid`): also the compare CSV's
    /// `repr` column and the `NAME.REPR.png` of `toolkit gallery`.
    pub fn name(self) -> &'static str {
        match self {
            ReprKind::Analytic => "analytic",
            ReprKind::Sdf => "sdf",
            ReprKind::Mesh => "mesh",
            ReprKind::Grid => "grid",
        }
    }
}

impl fmt::Display for ReprKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How the scene's objects are represented for tracing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Representation {
    /// Closed-form ray/primitive intersection; objects without one (CSG, repetition) are
    /// sphere traced with `march`.
    Analytic {
        /// Sphere tracing parameters of the objects without a closed form.
        march: MarchParams,
    },
    /// Sphere tracing of the analytic signed distance functions.
    Sdf {
        /// Sphere tracing parameters.
        march: MarchParams,
    },
    /// Primitives tessellated parametrically at `resolution` (segments around the largest
    /// circle) and ray traced as triangle meshes through a BVH; infinite planes are
    /// intersected in closed form, as in every representation ([`MeshPlane::ClosedForm`]),
    /// or made a disc around the camera out to the scene's `max_distance` when asked
    /// ([`MeshPlane::Disc`]); repetition is instanced
    /// (its child made into one mesh, placed per copy: [`Build::Instanced`]); bounded CSG
    /// is extracted from its SDF (marching cubes, `resolution` cells along the
    /// longest axis, at most [`MAX_EXTRACT_RESOLUTION`]: [`extract_resolution`]); unbounded
    /// CSG is sphere traced with `march` (the render says so). Objects of the same geometry
    /// share one mesh ([`Build::SharedMesh`]).
    Mesh {
        /// Segments around the largest circle of a tessellated primitive; cells along the
        /// longest axis of an extracted object (at most [`MAX_EXTRACT_RESOLUTION`]).
        resolution: u32,
        /// Shading of tessellated primitives and mesh files (extracted surfaces are flat).
        shading: Shading,
        /// Parametric tessellation, or extraction of every bounded object.
        method: MeshMethod,
        /// How infinite planes are traced.
        plane: MeshPlane,
        /// Sphere tracing parameters of the objects that stay marched.
        march: MarchParams,
    },
    /// Every bounded object (primitive, CSG, repetition, mesh) sampled into a signed
    /// distance grid of `resolution` cells along its longest axis (exact distances at cell
    /// corners) and ray marched through the trilinear interpolation with `march`; unbounded
    /// objects and triangles (unsigned) are sphere traced analytically (the render says so).
    Grid {
        /// Cells along the longest axis of each gridded object's box.
        resolution: u32,
        /// How mesh objects' grids are filled.
        fill: GridFill,
        /// How the samples are stored.
        storage: GridStorage,
        /// Ray marching parameters of the grids (and sphere tracing of what is not gridded).
        march: MarchParams,
    },
}

/// How the mesh representation turns primitives into triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MeshMethod {
    /// Parametric tessellation of each primitive (CSG and repetition are extracted).
    Parametric,
    /// Every bounded object extracted from its SDF with the given method.
    Extracted(ExtractMethod),
}

/// How the mesh representation traces an infinite plane; the command line's `--plane`
/// values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum MeshPlane {
    /// Intersected in closed form ([`Build::ClosedForm`], the analytic representation's
    /// primitive), as every other representation does: the study compares the objects, not
    /// a tessellation of the ground.
    #[default]
    ClosedForm,
    /// Tessellated into a flat disc around the camera out to the scene's `max_distance`
    /// ([`Build::PlaneDisc`]), traced as triangles like the rest.
    Disc,
}

/// How a mesh object's grid is filled (analytic objects are always sampled exactly); the
/// command line's `--fill` values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum GridFill {
    /// Exact distance to the nearest triangle at every sample, sign from the winding number.
    Sample,
    /// Rasterize the surface, flood fill the outside, Euclidean distance transform
    /// (fast, about one voxel of error; closed meshes only).
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
    /// One narrow band of `cells` cells shared by every object of the scene gridded whole
    /// ([`crate::geometry::grid::scene::SceneGrid`]): one world-space lattice whose voxel is
    /// the median of the objects' own voxels at the asked resolution, so that bytes follow
    /// the surface, not the number of objects. Meshes in it are sampled exactly
    /// (voxelizing works on an object's own lattice); an object clipped to the view region
    /// and a grid file keep a band of their own.
    Scene {
        /// Half-width of the stored band, in cells, `>= 1`.
        cells: u32,
    },
}

impl GridStorage {
    /// The storage of a grid of one object's own: a [`GridStorage::Scene`] band becomes a
    /// [`GridStorage::Band`] of the same width.
    pub fn own(self) -> GridStorage {
        match self {
            GridStorage::Scene { cells } => GridStorage::Band { cells },
            s => s,
        }
    }
}

impl Representation {
    /// Which representation this is.
    pub fn kind(&self) -> ReprKind {
        match self {
            Representation::Analytic { .. } => ReprKind::Analytic,
            Representation::Sdf { .. } => ReprKind::Sdf,
            Representation::Mesh { .. } => ReprKind::Mesh,
            Representation::Grid { .. } => ReprKind::Grid,
        }
    }

    /// The command-line name ([`ReprKind::name`]).
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    /// The sphere tracing parameters (used by every object that is marched).
    pub fn march(&self) -> MarchParams {
        match *self {
            Representation::Analytic { march }
            | Representation::Sdf { march }
            | Representation::Mesh { march, .. }
            | Representation::Grid { march, .. } => march,
        }
    }

    /// This representation with its sphere tracing's pixel footprint taken from the
    /// scene's camera (the angle one pixel subtends at unit distance).
    pub fn with_pixel_footprint(self, scene: &Scene) -> Representation {
        let footprint = 2.0 * ((scene.camera.fov_y_deg as f64).to_radians() * 0.5).tan()
            / scene.camera.height.max(1) as f64;
        let with_footprint = |march: MarchParams| MarchParams { pixel_footprint: footprint, ..march };
        match self {
            Representation::Analytic { march } => Representation::Analytic { march: with_footprint(march) },
            Representation::Sdf { march } => Representation::Sdf { march: with_footprint(march) },
            Representation::Mesh { resolution, shading, method, plane, march } => {
                Representation::Mesh { resolution, shading, method, plane, march: with_footprint(march) }
            }
            Representation::Grid { resolution, fill, storage, march } => {
                Representation::Grid { resolution, fill, storage, march: with_footprint(march) }
            }
        }
    }
}

impl MeshMethod {
    /// The extraction method used for objects extracted from their SDF (marching cubes
    /// under [`MeshMethod::Parametric`], for the objects that cannot be tessellated).
    pub fn extract_method(self) -> ExtractMethod {
        match self {
            MeshMethod::Extracted(m) => m,
            MeshMethod::Parametric => ExtractMethod::MarchingCubes,
        }
    }
}

/// Largest resolution SDF-to-mesh extraction is run at in the mesh representation.
pub const MAX_EXTRACT_RESOLUTION: u32 = 512;

/// The resolution an object is extracted at in the mesh representation asked at
/// `resolution` (the one rule, stated here): `resolution`, at most
/// [`MAX_EXTRACT_RESOLUTION`]. The mesh representation's `resolution` also counts the
/// segments of tessellated primitives, which may go higher
/// (the command line's `MESH_RESOLUTION`); an extraction's sample grid is held in memory, so
/// the objects extracted from their SDFs (CSG, repetition, grid files, and every object
/// under [`MeshMethod::Extracted`]) stop at this cap. The render report names the
/// resolution each object was extracted at.
pub fn extract_resolution(resolution: u32) -> u32 {
    resolution.min(MAX_EXTRACT_RESOLUTION)
}

/// Margin of grids around an object's bounds, in cells: keeps the surface off the grid's
/// boundary so the interpolated field is closed.
pub const GRID_MARGIN_CELLS: u32 = 2;

/// Samples along the longest axis of a grid of `resolution` cells there (cell corners,
/// plus [`GRID_MARGIN_CELLS`] on each side): `resolution + 1 + 2 margin`, saturating. The
/// other axes have at most as many.
pub fn grid_samples_per_axis(resolution: u32) -> u32 {
    resolution.saturating_add(1 + 2 * GRID_MARGIN_CELLS)
}

/// How one object is built for tracing, and why it is not as asked when it is not.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectPlan {
    /// What is built.
    pub build: Build,
    /// Why `build` is not (entirely) the asked representation; `None` when it is.
    pub fallback: Option<Fallback>,
}

/// What is built for one object (see the module header).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Build {
    /// Closed-form ray/primitive intersection ([`crate::geometry::analytic::AnalyticObject`]).
    ClosedForm,
    /// Sphere tracing of the object's analytic SDF ([`crate::geometry::sdf::SdfObject`]).
    Marched {
        /// Sphere tracing parameters (pixel footprint from the camera).
        march: MarchParams,
    },
    /// A loaded mesh traced as its triangles under the object's transform.
    MeshTriangles,
    /// A primitive (not a plane) tessellated parametrically and traced as a mesh under the
    /// object's transform.
    Tessellated {
        /// Segments around the largest circle, `>= 3`.
        resolution: u32,
        /// Shading of the triangles: the asked one, or flat for sharp-edged shapes (known
        /// once tessellated: those come without vertex normals).
        shading: Shading,
    },
    /// An infinite plane as a flat disc around the camera out to the scene's
    /// `max_distance`.
    PlaneDisc {
        /// The asked tessellation resolution (named in the description only).
        resolution: u32,
    },
    /// A bounded, signed object's surface extracted from its SDF, traced flat in world
    /// space.
    Extracted {
        /// The extraction method.
        method: ExtractMethod,
        /// Cells along the longest axis of the object's box, at most
        /// [`MAX_EXTRACT_RESOLUTION`].
        resolution: u32,
    },
    /// An object sampled into a world-space SDF grid and ray marched through it.
    Grid {
        /// Cells along the longest axis of the gridded box (the object's, or `clip`).
        resolution: u32,
        /// How the grid is filled: meshes as asked (or [`GridFill::Sample`] when
        /// voxelizing found the mesh open); analytic objects always [`GridFill::Sample`].
        fill: GridFill,
        /// How the samples are stored.
        storage: GridStorage,
        /// Ray marching parameters (pixel footprint from the camera).
        march: MarchParams,
        /// The part of the object's box that is gridded when it is clipped to the view
        /// region (the rest is sphere traced); `None`: the whole box.
        clip: Option<Aabb>,
    },
    /// A repetition's child made into one mesh with one BVH, placed once per copy (the
    /// copies are the leaves of the scene's top-level BVH).
    Instanced {
        /// How the one mesh is made.
        mesh: InstanceMesh,
        /// Copies placed, at most [`MAX_INSTANCES`] (0 when none of an infinite
        /// repetition's copies is in view).
        copies: u32,
        /// An infinite repetition's copies are those in view within this distance of the
        /// camera (scene units: `max_distance`, or less where that would place more than
        /// [`MAX_INSTANCES`] copies); `None` for a finite repetition (every copy).
        reach: Option<f32>,
    },
    /// The mesh and BVH of top-level object `of` (an earlier object of the same kind and
    /// parameters, built [`Build::Tessellated`] or [`Build::MeshTriangles`]) placed under
    /// this object's transform and material, not built again.
    SharedMesh {
        /// Index of that object in the scene's objects.
        of: u32,
    },
    /// A primitive gridded in its own frame (its local box, `resolution` cells along the
    /// longest axis) and placed by its transform (rigid, uniform scale), because later
    /// objects of the same primitive share the grid ([`Build::SharedGrid`]), as a polygon
    /// renderer instances one mesh.
    LocalGrid {
        /// Cells along the longest axis of the primitive's local box.
        resolution: u32,
        /// How the samples are stored ([`GridStorage::Dense`] or [`GridStorage::Band`]).
        storage: GridStorage,
        /// Ray marching parameters (pixel footprint from the camera).
        march: MarchParams,
    },
    /// The grid of top-level object `of` (an earlier primitive of the same kind and
    /// parameters, built [`Build::LocalGrid`]) placed under this object's transform (rigid,
    /// uniform scale) and material, not sampled again.
    SharedGrid {
        /// Index of that object in the scene's objects.
        of: u32,
        /// Ray marching parameters (pixel footprint from the camera).
        march: MarchParams,
    },
    /// A repetition's child gridded once in the repetition's frame (`resolution` cells along
    /// the longest axis of the child's box) and placed once per copy, the copies under a
    /// BVH of their own, as [`Build::Instanced`] places one mesh.
    InstancedGrid {
        /// Cells along the longest axis of the child's box.
        resolution: u32,
        /// How the child's samples are stored ([`GridStorage::Dense`] or
        /// [`GridStorage::Band`]).
        storage: GridStorage,
        /// Ray marching parameters (pixel footprint from the camera).
        march: MarchParams,
        /// Copies placed, as [`Build::Instanced`]'s.
        copies: u32,
        /// As [`Build::Instanced`]'s.
        reach: Option<f32>,
    },
    /// A grid file ray marched.
    GridFileMarched {
        /// How its samples are stored.
        storage: GridStorage,
        /// Ray marching parameters.
        march: MarchParams,
    },
    /// An implicit `.vm` model traced by steps of value / proven Lipschitz bound and
    /// interval root isolation along the ray
    /// ([`crate::geometry::implicit::ImplicitObject`]).
    ImplicitMarched {
        /// Hit tolerance (pixel footprint from the camera).
        march: MarchParams,
    },
    /// An implicit model's zero level set extracted from its samples in the cube [-1, 1]^3
    /// of its frame (every grid point evaluated: the value is not a distance) and traced
    /// flat in world space.
    ImplicitExtracted {
        /// The extraction method.
        method: ExtractMethod,
        /// Cells along the cube's edge, at most [`MAX_EXTRACT_RESOLUTION`].
        resolution: u32,
    },
    /// A grid file's zero level set extracted and traced flat in world space.
    GridFileExtracted {
        /// The extraction method.
        method: ExtractMethod,
        /// Cells along the longest axis of the grid's box, at most
        /// [`MAX_EXTRACT_RESOLUTION`].
        resolution: u32,
    },
}

/// How the one mesh of a [`Build::Instanced`] repetition is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InstanceMesh {
    /// The child primitive (not a plane) tessellated parametrically in its own frame.
    Tessellated {
        /// Segments around the largest circle, `>= 3`.
        resolution: u32,
        /// As [`Build::Tessellated`]'s.
        shading: Shading,
    },
    /// The child (CSG or a finite repetition; any child when extraction is asked for)
    /// extracted from its SDF in the repetition's frame, traced flat.
    Extracted {
        /// The extraction method.
        method: ExtractMethod,
        /// Cells along the longest axis of the child's box, at most
        /// [`MAX_EXTRACT_RESOLUTION`].
        resolution: u32,
    },
}

/// Why an object is not built in the asked representation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Fallback {
    /// Analytic: the object kind (CSG, repetition) has no closed-form intersection; it is
    /// sphere traced.
    NoClosedForm {
        /// The object's kind name.
        kind: &'static str,
    },
    /// Mesh or grid: the object is unbounded (unbounded repetition, CSG around a plane);
    /// it is sphere traced.
    Unbounded,
    /// Mesh (extraction) or grid: the object holds a triangle, whose distance has no sign;
    /// it is sphere traced.
    Unsigned,
    /// Grid: the object's box lies entirely outside the view region; it is sphere traced.
    OutsideViewRegion,
    /// Grid: the object is gridded only inside the view region and sphere traced outside
    /// it.
    ClippedToViewRegion,
    /// Grid with [`GridFill::Voxelize`]: voxelizing found the mesh open, so it was sampled
    /// exactly instead (known while building).
    OpenMeshSampled,
    /// Mesh: extracting the surface at `resolution` cells gave no triangles: no sample of
    /// the extraction's grid fell inside the object (a bounded, signed object), so every
    /// part of it is thinner than a cell there; the object is sphere traced (known while
    /// building).
    EmptyExtraction {
        /// Cells along the longest axis of the extracted box.
        resolution: u32,
    },
    /// Mesh: a plane's view disc could not be made (the plane lies beyond the `f32` range
    /// under its transform, or no part of it is within the view distance); it is sphere
    /// traced (known while building).
    NoPlaneDisc,
    /// Grid: the grid could not be built (see the grid builders' errors); an analytic
    /// object is sphere traced, a mesh traced as triangles (known while building).
    GridNotBuilt,
    /// Mesh: a grid file holds no surface to extract; its grid is ray marched (known while
    /// building).
    NoSurfaceInGridFile,
    /// Grid with [`GridStorage::Scene`]: the scene grid could not be built (too large); the
    /// object has a band grid of its own (known while building).
    OwnGrid,
    /// Grid with [`GridStorage::Band`]: a grid file's narrow band could not be built; it is
    /// stored dense (known while building).
    DenseInsteadOfBand,
    /// Grid: an implicit model is not sampled into a grid (its value is not a distance);
    /// it is traced by its safe marcher.
    ImplicitNotGridded,
}

impl fmt::Display for Fallback {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Fallback::NoClosedForm { kind } => write!(f, "no closed form for {kind}: sphere traced"),
            Fallback::Unbounded => f.write_str("unbounded: sphere traced"),
            Fallback::Unsigned => f.write_str("unsigned distance (holds a triangle): sphere traced"),
            Fallback::OutsideViewRegion => f.write_str("outside the view region: sphere traced"),
            Fallback::ClippedToViewRegion => {
                f.write_str("gridded inside the view region, sphere traced outside it")
            }
            Fallback::OpenMeshSampled => f.write_str("voxelizing found the mesh open: sampled"),
            Fallback::EmptyExtraction { resolution } => write!(
                f,
                "extraction at {resolution} cells gave no triangles (no sample inside: thinner than \
                 a cell): sphere traced"
            ),
            Fallback::NoPlaneDisc => {
                f.write_str("the plane has no disc in f32 range within the view distance: sphere traced")
            }
            Fallback::GridNotBuilt => f.write_str("the grid could not be built"),
            Fallback::OwnGrid => f.write_str("the scene grid could not be built: a grid of its own"),
            Fallback::NoSurfaceInGridFile => f.write_str("no surface in the grid: ray marched"),
            Fallback::DenseInsteadOfBand => f.write_str("the narrow band could not be built: dense"),
            Fallback::ImplicitNotGridded => {
                f.write_str("an implicit model is not gridded (its value is not a distance): marched safely")
            }
        }
    }
}

impl Fallback {
    /// Whether the object stays in the asked representation despite the fallback: a
    /// different storage or fill of a grid ([`Fallback::DenseInsteadOfBand`],
    /// [`Fallback::OwnGrid`], [`Fallback::OpenMeshSampled`]), a grid clipped to the view
    /// region ([`Fallback::ClippedToViewRegion`]: still gridded where it is seen), and the
    /// sphere tracing that defines the analytic representation for objects without a
    /// closed form ([`Fallback::NoClosedForm`]). Every other fallback traces the object in
    /// another representation ([`ObjectPlan::traced`]).
    pub fn stays_in_repr(self) -> bool {
        matches!(
            self,
            Fallback::NoClosedForm { .. }
                | Fallback::ClippedToViewRegion
                | Fallback::OpenMeshSampled
                | Fallback::OwnGrid
                | Fallback::DenseInsteadOfBand
        )
    }
}

impl Build {
    /// The representation whose tracer traces this build: closed form (analytic), sphere
    /// tracing (sdf), triangles (mesh) or a grid (grid).
    pub fn kind(&self) -> ReprKind {
        match self {
            Build::ClosedForm => ReprKind::Analytic,
            Build::Marched { .. } => ReprKind::Sdf,
            Build::ImplicitMarched { .. } => ReprKind::Sdf,
            Build::MeshTriangles
            | Build::ImplicitExtracted { .. }
            | Build::Tessellated { .. }
            | Build::PlaneDisc { .. }
            | Build::Extracted { .. }
            | Build::Instanced { .. }
            | Build::SharedMesh { .. }
            | Build::GridFileExtracted { .. } => ReprKind::Mesh,
            Build::Grid { .. }
            | Build::LocalGrid { .. }
            | Build::SharedGrid { .. }
            | Build::InstancedGrid { .. }
            | Build::GridFileMarched { .. } => ReprKind::Grid,
        }
    }
}

/// What traced a run asked in one representation, from its objects' realised plans
/// ([`traced_repr`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TracedRepr {
    /// Every representation that traced an object of the run, in [`ReprKind::ALL`] order,
    /// without repeats; empty for a run without objects (then the asked one traced it).
    pub kinds: Vec<ReprKind>,
}

impl TracedRepr {
    /// The compare CSV's `repr`: the one representation that traced every object, or the
    /// representations that traced some, joined by `+` in [`ReprKind::ALL`] order
    /// (`sdf+mesh`: some objects sphere traced, the others triangles).
    pub fn name(&self) -> String {
        self.kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join("+")
    }
}

/// What traced a run asked in `asked` whose objects were built as `plans` (realised, in
/// scene order): the set of [`ObjectPlan::traced`] over its objects. When every object is
/// traced as asked this is `asked` alone.
pub fn traced_repr(plans: &[ObjectPlan], asked: ReprKind) -> TracedRepr {
    let mut kinds: Vec<ReprKind> = plans.iter().map(|p| p.traced(asked)).collect();
    if kinds.is_empty() {
        kinds.push(asked);
    }
    let rank = |k: &ReprKind| ReprKind::ALL.iter().position(|x| x == k);
    kinds.sort_by_key(rank);
    kinds.dedup();
    TracedRepr { kinds }
}

impl ObjectPlan {
    /// Which representation traces the object of a run asked in `asked`: `asked` when the
    /// plan is as asked or its fallback stays in the representation
    /// ([`Fallback::stays_in_repr`]); `asked` too for an infinite plane intersected in
    /// closed form (the grid representation's fallback for it), as every representation
    /// intersects planes in closed form (the mesh one unless [`MeshPlane::Disc`]), the
    /// common ground the study does not compare; otherwise the realised build's ([`Build::kind`]): sphere traced is
    /// `sdf`, a grid file marched instead of extracted `grid`, a mesh whose grid could not
    /// be built `mesh`.
    pub fn traced(&self, asked: ReprKind) -> ReprKind {
        match self.fallback {
            None => asked,
            Some(f) if f.stays_in_repr() => asked,
            Some(_) if self.build == Build::ClosedForm => asked,
            Some(_) => self.build.kind(),
        }
    }

    /// `build`, as asked.
    pub fn as_asked(build: Build) -> Self {
        ObjectPlan { build, fallback: None }
    }

    /// `build` instead of the asked representation, because of `fallback`.
    pub fn fallback(build: Build, fallback: Fallback) -> Self {
        ObjectPlan { build, fallback: Some(fallback) }
    }

    /// Whether the object is sphere traced on its analytic SDF, entirely ([`Build::Marched`])
    /// or outside a view-region clip.
    pub fn sphere_traced(&self) -> bool {
        matches!(self.build, Build::Marched { .. } | Build::Grid { clip: Some(_), .. })
    }

    /// Whether the object is ray marched (its analytic SDF or a grid, entirely or in part)
    /// rather than intersected in closed form or as triangles.
    pub fn marches(&self) -> bool {
        matches!(
            self.build,
            Build::Marched { .. }
                | Build::ImplicitMarched { .. }
                | Build::Grid { .. }
                | Build::LocalGrid { .. }
                | Build::SharedGrid { .. }
                | Build::InstancedGrid { .. }
                | Build::GridFileMarched { .. }
        )
    }
}

/// Decides how `o` (a top-level object of `scene`) is built in `repr`: the one place that
/// maps representation and object kind to a [`Build`] (see the module header). The plan
/// holds `repr`'s sphere tracing parameters with the camera's pixel footprint. Fallbacks
/// found only while building are not in it (see [`build_scene_with_plans`]).
pub fn plan_object(scene: &Scene, o: &Object, repr: Representation) -> ObjectPlan {
    let repr = repr.with_pixel_footprint(scene);
    let marched = |fallback| ObjectPlan { build: Build::Marched { march: repr.march() }, fallback };
    if let ObjectKind::Implicit { .. } = o.kind {
        let safe = Build::ImplicitMarched { march: repr.march() };
        return match repr {
            Representation::Sdf { .. } => ObjectPlan::as_asked(safe),
            Representation::Analytic { .. } => {
                ObjectPlan::fallback(safe, Fallback::NoClosedForm { kind: o.kind_name() })
            }
            Representation::Mesh { resolution, method, .. } => {
                ObjectPlan::as_asked(Build::ImplicitExtracted {
                    method: method.extract_method(),
                    resolution: extract_resolution(resolution),
                })
            }
            Representation::Grid { .. } => ObjectPlan::fallback(safe, Fallback::ImplicitNotGridded),
        };
    }
    if let ObjectKind::Grid { .. } = o.kind {
        let build = match repr {
            Representation::Mesh { resolution, method, .. } => Build::GridFileExtracted {
                method: method.extract_method(),
                resolution: extract_resolution(resolution),
            },
            Representation::Grid { storage, march, .. } => {
                Build::GridFileMarched { storage: storage.own(), march }
            }
            Representation::Analytic { march } | Representation::Sdf { march } => {
                Build::GridFileMarched { storage: GridStorage::Dense, march }
            }
        };
        return ObjectPlan::as_asked(build);
    }
    let is_mesh = matches!(o.kind, ObjectKind::Mesh { .. });
    match repr {
        _ if is_mesh && !matches!(repr, Representation::Grid { .. }) => match first_alike(scene, o) {
            Some(of) => ObjectPlan::as_asked(Build::SharedMesh { of }),
            None => ObjectPlan::as_asked(Build::MeshTriangles),
        },
        Representation::Analytic { .. } => match o.kind {
            ObjectKind::Primitive(_) => ObjectPlan::as_asked(Build::ClosedForm),
            _ => marched(Some(Fallback::NoClosedForm { kind: o.kind_name() })),
        },
        // Unbounded planes have a closed form in every representation (the mesh one may
        // make them a disc out to the far distance): never marched to the horizon.
        Representation::Sdf { .. } => match o.kind {
            ObjectKind::Primitive(Primitive::Plane { .. }) => ObjectPlan::as_asked(Build::ClosedForm),
            _ => marched(None),
        },
        Representation::Mesh { resolution, shading, method, plane, .. } => match (&o.kind, method) {
            (ObjectKind::Primitive(Primitive::Plane { .. }), _) => match plane {
                MeshPlane::ClosedForm => ObjectPlan::as_asked(Build::ClosedForm),
                MeshPlane::Disc => ObjectPlan::as_asked(Build::PlaneDisc { resolution }),
            },
            (ObjectKind::Primitive(_), MeshMethod::Parametric) => match first_alike(scene, o) {
                Some(of) => ObjectPlan::as_asked(Build::SharedMesh { of }),
                None => ObjectPlan::as_asked(Build::Tessellated { resolution, shading }),
            },
            (ObjectKind::Repeat { child, .. }, _)
                if let Some(mesh) = instance_mesh(child, resolution, shading, method) =>
            {
                match repeat_offsets(scene, o, MAX_INSTANCES) {
                    Some(c) => ObjectPlan::as_asked(Build::Instanced {
                        mesh,
                        copies: c.offsets.len() as u32,
                        reach: c.reach,
                    }),
                    // More copies than may be instanced: extracted whole (finite) or
                    // sphere traced (infinite).
                    None if !signed(o) => marched(Some(Fallback::Unsigned)),
                    None if o.bounds().is_none() => marched(Some(Fallback::Unbounded)),
                    None => ObjectPlan::as_asked(Build::Extracted {
                        method: method.extract_method(),
                        resolution: extract_resolution(resolution),
                    }),
                }
            }
            // CSG, repetition that cannot be instanced (and every bounded object when
            // extraction is asked for): extracted from the SDF.
            _ if !signed(o) => marched(Some(Fallback::Unsigned)),
            _ if o.bounds().is_none() => marched(Some(Fallback::Unbounded)),
            _ => ObjectPlan::as_asked(Build::Extracted {
                method: method.extract_method(),
                resolution: extract_resolution(resolution),
            }),
        },
        Representation::Grid { resolution, fill, storage, march } => {
            let grid = |fill, clip| Build::Grid { resolution, fill, storage, march, clip };
            // Repetition is instanced, as in the mesh representation: the child's grid once,
            // placed per copy.
            if let ObjectKind::Repeat { child, .. } = &o.kind
                && child.bounds().is_some()
                && signed(child)
                && let Some(c) = repeat_offsets(scene, o, MAX_INSTANCES)
            {
                return ObjectPlan::as_asked(Build::InstancedGrid {
                    resolution,
                    storage: storage.own(),
                    march,
                    copies: c.offsets.len() as u32,
                    reach: c.reach,
                });
            }
            let Some(b) = o.bounds() else {
                let build = match o.kind {
                    _ if is_mesh => Build::MeshTriangles,
                    ObjectKind::Primitive(Primitive::Plane { .. }) => Build::ClosedForm,
                    _ => Build::Marched { march },
                };
                return ObjectPlan::fallback(build, Fallback::Unbounded);
            };
            if is_mesh {
                // Meshes are never clipped to the view region; a scene grid samples them.
                let fill = if matches!(storage, GridStorage::Scene { .. }) { GridFill::Sample } else { fill };
                return ObjectPlan::as_asked(grid(fill, None));
            }
            let Some(clip) = view_clip(scene, o, &b) else {
                return marched(Some(Fallback::OutsideViewRegion));
            };
            if !signed(o) {
                return marched(Some(Fallback::Unsigned));
            }
            if clip.is_none()
                && !matches!(storage, GridStorage::Scene { .. })
                && let Some(shared) = grid_share(scene, o, repr)
            {
                return ObjectPlan::as_asked(shared);
            }
            let fallback = clip.map(|_| Fallback::ClippedToViewRegion);
            // A clipped object's grid is its own (the scene grid holds whole objects).
            let storage = if clip.is_some() { storage.own() } else { storage };
            let build = Build::Grid { resolution, fill: GridFill::Sample, storage, march, clip };
            ObjectPlan { build, fallback }
        }
    }
}

/// The plans of every top-level object of `scene` in `repr`, in scene order.
pub fn plan_scene(scene: &Scene, repr: Representation) -> Vec<ObjectPlan> {
    scene.objects.iter().map(|o| plan_object(scene, o, repr)).collect()
}

/// How the one mesh of a repetition of `child` is made in the mesh representation, or
/// `None` when it cannot be (an unbounded child; an unsigned one that would need
/// extraction).
fn instance_mesh(
    child: &Object,
    resolution: u32,
    shading: Shading,
    method: MeshMethod,
) -> Option<InstanceMesh> {
    match (&child.kind, method) {
        (ObjectKind::Primitive(Primitive::Plane { .. }), _) => None,
        (ObjectKind::Primitive(_), MeshMethod::Parametric) => {
            Some(InstanceMesh::Tessellated { resolution, shading })
        }
        _ if child.bounds().is_none() || !signed(child) => None,
        _ => Some(InstanceMesh::Extracted {
            method: method.extract_method(),
            resolution: extract_resolution(resolution),
        }),
    }
}

/// The index of the first top-level object of `scene` before `o` with the same geometry
/// (a primitive, not a plane, of the same kind and parameters; a mesh of the same file
/// and data with the same shading), whose mesh `o` then shares; `None` when there is none
/// or `o` is not one of `scene`'s objects.
fn first_alike(scene: &Scene, o: &Object) -> Option<u32> {
    let me = scene.objects.iter().position(|x| std::ptr::eq(x, o))?;
    scene.objects[..me].iter().position(|x| alike(x, o)).map(|i| i as u32)
}

/// Whether `x` and `o` have one geometry (see [`first_alike`]).
fn alike(x: &Object, o: &Object) -> bool {
    match (&x.kind, &o.kind) {
        (ObjectKind::Primitive(p), ObjectKind::Primitive(q)) => {
            p == q && !matches!(p, Primitive::Plane { .. })
        }
        (
            ObjectKind::Mesh { mesh: m, source: a, shading: s },
            ObjectKind::Mesh { mesh: n, source: b, shading: t },
        ) => s == t && (std::sync::Arc::ptr_eq(m, n) || (a == b && m == n)),
        _ => false,
    }
}

/// How a primitive `o` (gridded whole, not into a scene grid, under the grid
/// representation `repr`) shares its grid with the other objects of the same primitive:
/// [`Build::SharedGrid`] when an earlier one is built [`Build::LocalGrid`],
/// [`Build::LocalGrid`] when it is the first of several; `None` when it shares nothing
/// (the grid is then sampled in world space, fitted to the object's world box). Sharing
/// needs a transform that keeps distances exact up to one factor (rigid, uniform scale).
fn grid_share(scene: &Scene, o: &Object, repr: Representation) -> Option<Build> {
    let Representation::Grid { resolution, storage, march, .. } = repr.with_pixel_footprint(scene) else {
        return None;
    };
    // Gridded whole (inside the view region, not clipped to it) under such a transform.
    let shareable = |x: &Object| {
        matches!(x.kind, ObjectKind::Primitive(p) if !matches!(p, Primitive::Plane { .. }))
            && x.compiled_transform().is_uniform()
            && x.bounds().is_some_and(|b| view_clip(scene, x, &b) == Some(None))
    };
    if !shareable(o) {
        return None;
    }
    if let Some(of) = first_alike(scene, o).filter(|&of| shareable(&scene.objects[of as usize])) {
        return Some(Build::SharedGrid { of, march });
    }
    let me = scene.objects.iter().position(|x| std::ptr::eq(x, o))?;
    let later = scene.objects[me + 1..].iter().any(|x| alike(x, o) && shareable(x));
    later.then_some(Build::LocalGrid { resolution, storage, march })
}

/// The part of `o`'s box `b` that a grid covers: `Some(None)` the whole box;
/// `Some(Some(clip))` only `clip`, the view region's part of a box much larger than it
/// (less than [`VIEW_CLIP_FRACTION`] of its longest extent, see [`view_region`]); `None`
/// when the box lies outside the view region.
fn view_clip(scene: &Scene, o: &Object, b: &Aabb) -> Option<Option<Aabb>> {
    let Some(region) = view_region(scene, o) else { return Some(None) };
    let c = region.intersection(b);
    let (clo, chi) = (Vec3::from(c.min), Vec3::from(c.max));
    let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
    if !(chi - clo).cmpge(Vec3::ZERO).all() {
        return None;
    }
    Some(((chi - clo).max_element() < VIEW_CLIP_FRACTION * (hi - lo).max_element()).then_some(c))
}

/// Whether `o` has a signed analytic distance (false when it holds a triangle, a mesh or a
/// grid file).
fn signed(o: &Object) -> bool {
    SdfTree::new(o).is_some_and(|t| t.signed)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::plan::budget::BYTES_PER_TRACED_TRIANGLE;
    use crate::scene::load_scene;

    fn scene(name: &str) -> Scene {
        load_scene(&Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes").join(name))
            .unwrap_or_else(|e| panic!("{e}"))
    }

    fn mesh(method: MeshMethod) -> Representation {
        Representation::Mesh {
            resolution: 16,
            shading: Shading::Smooth,
            method,
            plane: MeshPlane::ClosedForm,
            march: MarchParams::default(),
        }
    }

    fn grid(fill: GridFill) -> Representation {
        Representation::Grid {
            resolution: 16,
            fill,
            storage: GridStorage::Dense,
            march: MarchParams::default(),
        }
    }

    fn kind(o: &Object) -> &'static str {
        match &o.kind {
            ObjectKind::Primitive(Primitive::Plane { .. }) => "plane",
            ObjectKind::Primitive(Primitive::Triangle { .. }) => "triangle",
            ObjectKind::Primitive(_) => "primitive",
            ObjectKind::Repeat { .. } => "repeat",
            _ => "other",
        }
    }

    #[test]
    fn one_table_decides_every_object() {
        let s = scene("showcase.toml");
        let repr = Representation::Analytic { march: MarchParams::default() };
        let march = repr.with_pixel_footprint(&s).march();
        assert!(march.pixel_footprint > 0.0);
        for (o, p) in s.objects.iter().zip(plan_scene(&s, repr)) {
            let expect = match kind(o) {
                "other" | "repeat" => ObjectPlan::fallback(
                    Build::Marched { march },
                    Fallback::NoClosedForm { kind: o.kind_name() },
                ),
                _ => ObjectPlan::as_asked(Build::ClosedForm),
            };
            assert_eq!(p, expect, "{}", o.label);
        }
        for (o, p) in
            s.objects.iter().zip(plan_scene(&s, Representation::Sdf { march: MarchParams::default() }))
        {
            let build = if kind(o) == "plane" { Build::ClosedForm } else { Build::Marched { march } };
            assert_eq!(p, ObjectPlan::as_asked(build), "{}", o.label);
        }
        let mc = ExtractMethod::MarchingCubes;
        // The 4 x 1 x 2 sphere grid.
        let copies = |mesh| Build::Instanced { mesh, copies: 8, reach: None };
        for (o, p) in s.objects.iter().zip(plan_scene(&s, mesh(MeshMethod::Parametric))) {
            let build = match kind(o) {
                "plane" => Build::ClosedForm,
                "repeat" => copies(InstanceMesh::Tessellated { resolution: 16, shading: Shading::Smooth }),
                "other" => Build::Extracted { method: mc, resolution: 16 },
                _ => Build::Tessellated { resolution: 16, shading: Shading::Smooth },
            };
            assert_eq!(p, ObjectPlan::as_asked(build), "{}", o.label);
        }
        for (o, p) in s.objects.iter().zip(plan_scene(&s, mesh(MeshMethod::Extracted(mc)))) {
            let expect = match kind(o) {
                "plane" => ObjectPlan::as_asked(Build::ClosedForm),
                "triangle" => ObjectPlan::fallback(Build::Marched { march }, Fallback::Unsigned),
                "repeat" => {
                    ObjectPlan::as_asked(copies(InstanceMesh::Extracted { method: mc, resolution: 16 }))
                }
                _ => ObjectPlan::as_asked(Build::Extracted { method: mc, resolution: 16 }),
            };
            assert_eq!(p, expect, "{}", o.label);
        }
        // The disc, when asked for.
        let Representation::Mesh { resolution, shading, method, march: m, .. } = mesh(MeshMethod::Parametric)
        else {
            unreachable!("a mesh representation")
        };
        let discs = Representation::Mesh { resolution, shading, method, plane: MeshPlane::Disc, march: m };
        let planes: Vec<Build> = s
            .objects
            .iter()
            .zip(plan_scene(&s, discs))
            .filter(|(o, _)| kind(o) == "plane")
            .map(|(_, p)| p.build)
            .collect();
        assert!(!planes.is_empty() && planes.iter().all(|b| *b == Build::PlaneDisc { resolution: 16 }));
        for (o, p) in s.objects.iter().zip(plan_scene(&s, grid(GridFill::Voxelize))) {
            let expect = match kind(o) {
                "plane" => ObjectPlan::fallback(Build::ClosedForm, Fallback::Unbounded),
                "triangle" => ObjectPlan::fallback(Build::Marched { march }, Fallback::Unsigned),
                // The child's grid placed per copy, as the mesh representation instances.
                "repeat" => ObjectPlan::as_asked(Build::InstancedGrid {
                    resolution: 16,
                    storage: GridStorage::Dense,
                    march,
                    copies: 8,
                    reach: None,
                }),
                // Analytic objects are always sampled.
                _ => ObjectPlan::as_asked(Build::Grid {
                    resolution: 16,
                    fill: GridFill::Sample,
                    storage: GridStorage::Dense,
                    march,
                    clip: None,
                }),
            };
            assert_eq!(p, expect, "{}", o.label);
        }
    }

    #[test]
    fn huge_objects_are_clipped_to_the_view_region() {
        let s = scene("thesis_rt.toml");
        let plans = plan_scene(&s, grid(GridFill::Sample));
        let clipped: Vec<&str> = s
            .objects
            .iter()
            .zip(&plans)
            .filter(|(_, p)| matches!(p.build, Build::Grid { clip: Some(_), .. }))
            .map(|(o, p)| {
                assert_eq!(p.fallback, Some(Fallback::ClippedToViewRegion));
                assert!(p.sphere_traced());
                o.label.as_str()
            })
            .collect();
        assert_eq!(clipped, ["yellow ground sphere"]);
    }

    #[test]
    fn the_builder_returns_the_plans_it_realised() {
        let s = scene("showcase.toml");
        for repr in [
            Representation::Analytic { march: MarchParams::default() },
            mesh(MeshMethod::Parametric),
            grid(GridFill::Sample),
        ] {
            let (g, realised) = build_scene_with_plans(&s, repr);
            assert_eq!(g.objects().len(), realised.len());
            let mut planned = plan_scene(&s, repr);
            // Tessellations of sharp-edged shapes are shaded flat.
            for (p, r) in planned.iter_mut().zip(&realised) {
                if let (Build::Tessellated { shading, .. }, Build::Tessellated { shading: got, .. }) =
                    (&mut p.build, r.build)
                {
                    *shading = got;
                }
                if let (
                    Build::Instanced { mesh: InstanceMesh::Tessellated { shading, .. }, .. },
                    Build::Instanced { mesh: InstanceMesh::Tessellated { shading: got, .. }, .. },
                ) = (&mut p.build, r.build)
                {
                    *shading = got;
                }
            }
            assert_eq!(planned, realised, "{}", repr.name());
        }
    }

    #[test]
    fn a_run_is_recorded_as_what_traced_it() {
        let march = MarchParams::default();
        let marched = |f| ObjectPlan::fallback(Build::Marched { march }, f);
        let tess = ObjectPlan::as_asked(Build::Tessellated { resolution: 16, shading: Shading::Smooth });
        let empty = marched(Fallback::EmptyExtraction { resolution: 16 });
        let name = |plans: &[ObjectPlan], asked| traced_repr(plans, asked).name();
        assert_eq!(empty.traced(ReprKind::Mesh), ReprKind::Sdf);
        assert_eq!(name(&[tess, tess], ReprKind::Mesh), "mesh");
        assert_eq!(name(&[empty], ReprKind::Mesh), "sdf");
        assert_eq!(name(&[tess, empty, tess], ReprKind::Mesh), "sdf+mesh");
        assert_eq!(name(&[], ReprKind::Grid), "grid");
        // Fallbacks that stay in the representation.
        let b = crate::geometry::aabb(Vec3::ZERO, Vec3::ONE);
        let grid =
            |storage, clip| Build::Grid { resolution: 16, fill: GridFill::Sample, storage, march, clip };
        let clipped = ObjectPlan::fallback(grid(GridStorage::Dense, Some(b)), Fallback::ClippedToViewRegion);
        let own = ObjectPlan::fallback(grid(GridStorage::Band { cells: 2 }, None), Fallback::OwnGrid);
        assert_eq!(name(&[clipped, own], ReprKind::Grid), "grid");
        let csg = marched(Fallback::NoClosedForm { kind: "union" });
        assert_eq!(name(&[csg, ObjectPlan::as_asked(Build::ClosedForm)], ReprKind::Analytic), "analytic");
        // A plane in closed form is the common ground of every representation.
        let plane = ObjectPlan::fallback(Build::ClosedForm, Fallback::Unbounded);
        assert_eq!(name(&[plane, own], ReprKind::Grid), "grid");
        // The others leave it.
        assert_eq!(name(&[plane, own, marched(Fallback::Unbounded)], ReprKind::Grid), "sdf+grid");
        let triangles = ObjectPlan::fallback(Build::MeshTriangles, Fallback::GridNotBuilt);
        assert_eq!(name(&[triangles], ReprKind::Grid), "mesh");

        // Built: the thin shell has no triangles at 16 cells, and the description says why.
        let s = scene("thin/thin_shell.toml");
        let (g, realised) = build_scene_with_plans(&s, mesh(MeshMethod::Parametric));
        let got: Vec<_> = realised.iter().map(|p| (p.build.kind(), p.fallback)).collect();
        assert_eq!(got, [(ReprKind::Sdf, empty.fallback)]);
        let text = g.objects()[0].describe();
        assert!(
            text.contains("extraction at 16 cells gave no triangles") && text.contains("thinner"),
            "{text}"
        );
    }

    #[test]
    fn estimates_follow_the_plan() {
        let s = scene("showcase.toml");
        // Sphere tracing counts the tapes of the compound objects, at most MAX_TAPE_OPS each.
        let analytic = budget::scene_bytes(&s, Representation::Analytic { march: MarchParams::default() });
        let sdf = budget::scene_bytes(&s, Representation::Sdf { march: MarchParams::default() });
        let tapes: u64 = s.objects.iter().map(budget::tape_bytes).sum();
        assert!(tapes > 0 && analytic == tapes && sdf == tapes, "{analytic} {sdf} {tapes}");
        let compound = s.objects.iter().filter(|o| budget::tape_bytes(o) > 0).count() as u64;
        let op = std::mem::size_of::<crate::geometry::sdf::tape::Op>() as u64;
        assert!(tapes <= compound * crate::geometry::sdf::MAX_TAPE_OPS as u64 * op);
        let plans = plan_scene(&s, grid(GridFill::Sample));
        let gridded = plans.iter().filter(|p| matches!(p.build, Build::Grid { .. })).count() as u64;
        // The repetition's one grid and a placement per copy.
        let copies: u64 = plans
            .iter()
            .map(|p| if let Build::InstancedGrid { copies, .. } = p.build { copies as u64 } else { 0 })
            .sum();
        assert_eq!(copies, 8);
        let samples = grid_samples_per_axis(16) as u64;
        assert_eq!(
            budget::scene_bytes(&s, grid(GridFill::Sample)),
            (gridded + 1) * samples.pow(3) * 4 + copies * budget::BYTES_PER_INSTANCE
        );
        assert_eq!(grid_samples_per_axis(8), 13);
        assert_eq!(grid_samples_per_axis(u32::MAX), u32::MAX);
    }

    /// A scene of `objects` (TOML tables) before a camera at the origin looking down +z.
    fn scene_of(objects: &str, max_distance: f32) -> Scene {
        let text = format!(
            "[camera]\nposition = [0, 1, -5]\nlook_at = [0, 0, 5]\nwidth = 64\nheight = 48\n\n\
             [settings]\nmax_distance = {max_distance}\n\n{objects}"
        );
        crate::scene::parse_scene(&text, Path::new("instancing.toml")).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn identical_objects_share_the_first_ones_mesh() {
        let sphere = |x: f32, r: f32| {
            format!("[[objects]]\ntype = \"sphere\"\nradius = {r}\ntranslate = [{x}, 0, 3]\n\n")
        };
        let s =
            scene_of(&(sphere(-2.0, 0.5) + &sphere(0.0, 0.5) + &sphere(2.0, 0.7) + &sphere(4.0, 0.5)), 100.0);
        let tess = Build::Tessellated { resolution: 16, shading: Shading::Smooth };
        let builds: Vec<Build> =
            plan_scene(&s, mesh(MeshMethod::Parametric)).iter().map(|p| p.build).collect();
        assert_eq!(builds, [tess, Build::SharedMesh { of: 0 }, tess, Build::SharedMesh { of: 0 }]);
        // Extraction works in world space: nothing is shared.
        let mc = ExtractMethod::MarchingCubes;
        for p in plan_scene(&s, mesh(MeshMethod::Extracted(mc))) {
            assert_eq!(p.build, Build::Extracted { method: mc, resolution: 16 });
        }
        // A shared mesh is estimated as one placement.
        let one = budget::object_bytes(
            &s.objects[0],
            &plan_object(&s, &s.objects[0], mesh(MeshMethod::Parametric)),
        );
        let all = budget::scene_bytes(&s, mesh(MeshMethod::Parametric));
        assert_eq!(all, 2 * one + 2 * budget::BYTES_PER_INSTANCE);
    }

    #[test]
    fn repetition_is_instanced_unless_inside_csg_or_over_the_cap() {
        let repeat = |count: &str, child: &str| {
            format!(
                "[[objects]]\ntype = \"repeat\"\nperiod = [1, 0, 1]\n{count}translate = [0, -1, 0]\n[objects.child]\n{child}\n\n"
            )
        };
        let sphere = "type = \"sphere\"\nradius = 0.2";
        let s = scene_of(&repeat("count = [10, 1, 7]\n", sphere), 100.0);
        let p = plan_object(&s, &s.objects[0], mesh(MeshMethod::Parametric));
        let tess = InstanceMesh::Tessellated { resolution: 16, shading: Shading::Smooth };
        assert_eq!(p, ObjectPlan::as_asked(Build::Instanced { mesh: tess, copies: 70, reach: None }));
        let bytes = budget::object_bytes(&s.objects[0], &p);
        assert_eq!(bytes, 2 * 16 * 16 * BYTES_PER_TRACED_TRIANGLE + 70 * budget::BYTES_PER_INSTANCE);
        // Over the cap: extracted whole.
        let s = scene_of(&repeat("count = [300, 1, 300]\n", sphere), 100.0);
        let p = plan_object(&s, &s.objects[0], mesh(MeshMethod::Parametric));
        assert_eq!(p.build, Build::Extracted { method: ExtractMethod::MarchingCubes, resolution: 16 });
        // A CSG child is extracted once, in the repetition's frame.
        let csg = "type = \"subtraction\"\nchildren = [{ type = \"box\", half_size = [0.3, 0.3, 0.3] }, { type = \"sphere\", radius = 0.4 }]";
        let s = scene_of(&repeat("count = [3, 1, 3]\n", csg), 100.0);
        let p = plan_object(&s, &s.objects[0], mesh(MeshMethod::Parametric));
        let mc = InstanceMesh::Extracted { method: ExtractMethod::MarchingCubes, resolution: 16 };
        assert_eq!(p.build, Build::Instanced { mesh: mc, copies: 9, reach: None });
        // Infinite: the copies in view out to max_distance, fewer for a shorter one, and a
        // shorter reach where max_distance would place too many.
        let s = scene_of(&repeat("", sphere), 40.0);
        let Build::Instanced { copies: far, reach: Some(r), .. } =
            plan_object(&s, &s.objects[0], mesh(MeshMethod::Parametric)).build
        else {
            panic!("not instanced")
        };
        assert_eq!(r, 40.0);
        let s = scene_of(&repeat("", sphere), 20.0);
        let Build::Instanced { copies: near, .. } =
            plan_object(&s, &s.objects[0], mesh(MeshMethod::Parametric)).build
        else {
            panic!("not instanced")
        };
        assert!(near > 100 && 3 * near < far && far as u64 <= MAX_INSTANCES, "{near} {far}");
        let s = scene_of(&repeat("", sphere), 1e5);
        let Build::Instanced { copies, reach: Some(r), .. } =
            plan_object(&s, &s.objects[0], mesh(MeshMethod::Parametric)).build
        else {
            panic!("not instanced")
        };
        assert!(
            r < 1e5 && copies as u64 <= MAX_INSTANCES && copies as u64 > MAX_INSTANCES / 4,
            "{r} {copies}"
        );
        // Repetition inside CSG cannot be instanced: the CSG is extracted whole.
        let text = format!(
            "[[objects]]\ntype = \"subtraction\"\nchildren = [{{ type = \"box\", half_size = [3, 0.3, 3] }}, \
             {{ type = \"repeat\", period = [1, 0, 1], count = [5, 1, 5], child = {{ {} }} }}]\n",
            "type = \"sphere\", radius = 0.3"
        );
        let s = scene_of(&text, 100.0);
        let p = plan_object(&s, &s.objects[0], mesh(MeshMethod::Parametric));
        assert_eq!(p.build, Build::Extracted { method: ExtractMethod::MarchingCubes, resolution: 16 });
        let (g, _) = build_scene_with_plans(&s, mesh(MeshMethod::Parametric));
        assert!(g.objects()[0].describe().contains("inside CSG"), "{}", g.objects()[0].describe());
    }
}
