//! The memory budget: how many bytes a request may use (`--max-memory`, by default half of
//! the machine's physical memory), and upper estimates of what grids, extractions and
//! scene representations need, checked before any work so that an oversized request fails
//! at once with a clear message instead of being killed by the operating system.
//!
//! The estimates are deliberately on the high side (they count working memory as well as
//! the result), so a request that passes fits; one near the limit may be refused although
//! it would just have fitted.

use std::fmt;
use std::str::FromStr;

use bytesize::ByteSize;
use glam::UVec3;

use crate::convert::extract::ExtractMethod;
use crate::error::{Error, Result};
use crate::geometry::sdf::tape::{Op, ops_bound};
use crate::geometry::sdf::{MAX_TAPE_OPS, SdfTree};
use crate::plan::{
    Build, GridFill, InstanceMesh, ObjectPlan, Representation, grid_samples_per_axis, plan_object,
};
use crate::scene::Scene;
use crate::scene::shape::{Object, ObjectKind};

/// Used when the machine's memory cannot be read: 8 GiB.
pub const FALLBACK_BYTES: u64 = 8 << 30;

/// Fraction of physical memory the default budget allows.
pub const DEFAULT_FRACTION: f64 = 0.5;

/// Bytes per triangle of a traced mesh (positions, indices and BVH; measured on the
/// armadillo with the 8-wide BVH grouped by the surface area heuristic: 7.74 MB for 86k
/// triangles is 90 bytes, rounded up with room to spare).
pub const BYTES_PER_TRACED_TRIANGLE: u64 = 100;

/// Bytes per placed instance of a shared mesh (its record with transform and bounds,
/// about 300 bytes, and its share of the scene's top-level BVH and leaf lists), rounded up.
pub const BYTES_PER_INSTANCE: u64 = 512;

/// Bytes per grid sample while extracting a surface (f32 sample plus working memory, see
/// [`crate::convert::extract::extract`]): marching cubes.
pub const EXTRACT_BYTES_PER_SAMPLE_MC: u64 = 9;
/// As [`EXTRACT_BYTES_PER_SAMPLE_MC`], for dual contouring.
pub const EXTRACT_BYTES_PER_SAMPLE_DC: u64 = 13;
/// Bytes per sample while voxelizing (the f32 result, the voxel labels and the distance
/// transform's working rows: see [`crate::convert::mesh_to_grid::voxelize`]).
pub const VOXELIZE_BYTES_PER_SAMPLE: u64 = 13;
/// Bytes per triangle of the closest-point BVH and the fast winding number tree used when
/// sampling a mesh exactly (an upper estimate).
pub const SAMPLE_BYTES_PER_TRIANGLE: u64 = 256;

/// The most primitives one distance evaluation of an object's SDF may evaluate
/// ([`object_evaluations`]): nested repetitions multiply their copies (40 levels of 2 copies
/// are 2^40 primitives per distance, a 3 KB scene that would never finish), so an object
/// above this is refused before anything is built. 2^20 is far above every scene of
/// `data/` (the most, a Menger sponge of level 3, evaluates a few hundred).
pub const MAX_EVALUATIONS_PER_DISTANCE: f64 = (1u64 << 20) as f64;

/// How many bytes a request may use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryBudget {
    /// The limit, bytes, > 0.
    pub bytes: u64,
}

impl MemoryBudget {
    /// [`DEFAULT_FRACTION`] of the machine's physical memory (`MemTotal` in
    /// `/proc/meminfo`), or [`FALLBACK_BYTES`] where that cannot be read.
    pub fn machine_default() -> Self {
        let total = machine_total();
        MemoryBudget { bytes: total.map_or(FALLBACK_BYTES, |t| (t as f64 * DEFAULT_FRACTION) as u64) }
    }

    /// Fails with a clear message when `scene` in `repr` would need more memory than the
    /// budget ([`scene_bytes`]), or when one of its objects would evaluate more than
    /// [`MAX_EVALUATIONS_PER_DISTANCE`] primitives per distance (an evaluation budget:
    /// such an object would not finish building or rendering). `what` names the request.
    pub fn check_scene(&self, what: &str, scene: &Scene, repr: Representation) -> Result<()> {
        for (i, o) in scene.objects.iter().enumerate() {
            check_evaluations(what, i, o, object_evaluations(o, &plan_object(scene, o, repr)))?;
        }
        self.check(what, scene_bytes(scene, repr))
    }

    /// Fails with a clear message when `what` would need more than the budget.
    pub fn check(&self, what: &str, bytes: u64) -> Result<()> {
        if bytes <= self.bytes {
            return Ok(());
        }
        Err(Error::Usage(format!(
            "{what} would need about {} of memory, more than the budget of {} (--max-memory); \
             lower the resolution or raise --max-memory",
            ByteSize::b(bytes).display().iec(),
            ByteSize::b(self.bytes).display().iec()
        )))
    }
}

impl fmt::Display for MemoryBudget {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", ByteSize::b(self.bytes).display().iec())
    }
}

impl FromStr for MemoryBudget {
    type Err = String;

    /// Parses sizes such as `4GiB`, `512 MB`, `1.5G` or a plain byte count, refusing more
    /// than the machine's physical memory ([`MemoryBudget::parse_within`]).
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Self::parse_within(s, machine_total())
    }
}

impl MemoryBudget {
    /// Parses a size as [`FromStr`] does, refusing one above `physical` bytes (where
    /// known): a budget the machine cannot give would let a request through that then
    /// fails in the middle (or is killed by the operating system), which is what the
    /// budget is there to prevent. Refused rather than clamped, so that a typo (`1EB` for
    /// `1GB`) is noticed, not silently replaced.
    pub fn parse_within(s: &str, physical: Option<u64>) -> std::result::Result<Self, String> {
        let b: ByteSize = s.trim().parse().map_err(|e| format!("not a memory size ({e}): '{s}'"))?;
        if b.as_u64() == 0 {
            return Err(format!("a memory budget must be more than 0 bytes, got '{s}'"));
        }
        if let Some(total) = physical
            && b.as_u64() > total
        {
            return Err(format!(
                "'{s}' is more than this machine's physical memory ({}); give at most that",
                ByteSize::b(total).display().iec()
            ));
        }
        Ok(MemoryBudget { bytes: b.as_u64() })
    }
}

/// Fails when object `index` (0-based) of a scene, `o`, would evaluate `evaluations`
/// primitives per distance, more than [`MAX_EVALUATIONS_PER_DISTANCE`].
pub fn check_evaluations(what: &str, index: usize, o: &Object, evaluations: f64) -> Result<()> {
    if evaluations <= MAX_EVALUATIONS_PER_DISTANCE {
        return Ok(());
    }
    Err(Error::Usage(format!(
        "{what}: object {} ('{}') would evaluate about 2^{:.0} primitives per distance (nested \
         repetitions multiply their copies), more than the evaluation budget of 2^{:.0}; reduce \
         the nesting or the repeated axes",
        index + 1,
        o.label,
        evaluations.log2(),
        MAX_EVALUATIONS_PER_DISTANCE.log2()
    )))
}

/// The machine's physical memory, bytes (`MemTotal` of `/proc/meminfo`), where it can be read.
pub fn machine_total() -> Option<u64> {
    std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| mem_total(&s))
}

/// `MemTotal` of `/proc/meminfo` text, in bytes.
fn mem_total(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let mut it = line.split_whitespace().skip(1);
    let kib: u64 = it.next()?.parse().ok()?;
    (it.next() == Some("kB")).then(|| kib.saturating_mul(1024))
}

/// Bytes of `dims` f32 samples times `per_sample / 4` (saturating).
fn grid_bytes(dims: UVec3, per_sample: u64) -> u64 {
    (dims.x as u64).saturating_mul(dims.y as u64).saturating_mul(dims.z as u64).saturating_mul(per_sample)
}

/// An upper estimate of the bytes sampling or voxelizing a mesh of `triangles` triangles
/// into a grid of `dims` samples needs (the grid, the search structures or the voxelizer's
/// working memory; a narrow band is built from the dense grid).
pub fn mesh_to_grid_bytes(triangles: usize, dims: UVec3, fill: GridFill) -> u64 {
    match fill {
        GridFill::Sample => {
            grid_bytes(dims, 4).saturating_add((triangles as u64).saturating_mul(SAMPLE_BYTES_PER_TRIANGLE))
        }
        GridFill::Voxelize => grid_bytes(dims, VOXELIZE_BYTES_PER_SAMPLE),
    }
}

/// An upper estimate of the bytes extracting one object's surface at `res` cells along its
/// longest axis needs: the sample grid with its working memory, and the output mesh
/// (at most about 12 triangles per cell of a surface crossing every cell of a face of the
/// box, times the cells along an axis).
pub fn extraction_bytes(res: u32, method: ExtractMethod) -> u64 {
    let per = match method {
        ExtractMethod::MarchingCubes | ExtractMethod::MarchingTetrahedra => EXTRACT_BYTES_PER_SAMPLE_MC,
        ExtractMethod::DualContouring => EXTRACT_BYTES_PER_SAMPLE_DC,
    };
    let r = res as u64 + 3;
    grid_bytes(UVec3::splat(res + 3), per).saturating_add(12 * r * r * BYTES_PER_TRACED_TRIANGLE)
}

/// An upper estimate of the bytes the geometry of `scene` in `repr` needs while it is
/// built and traced: the sum of [`object_bytes`] over the objects' plans
/// ([`plan_object`]).
pub fn scene_bytes(scene: &Scene, repr: Representation) -> u64 {
    let mut total: u64 = 0;
    for o in &scene.objects {
        total = total.saturating_add(object_bytes(o, &plan_object(scene, o, repr)));
    }
    total
}

/// An upper bound on the primitives one distance of `o` evaluates as `plan` builds it
/// ([`SdfTree::evaluations`]): the marching tree for a sphere traced object, the plain
/// tree for objects sampled into grids or extracted (which evaluates every neighbouring
/// cell), 0 for builds that never evaluate an SDF (closed forms, tessellations, meshes,
/// grid files, shared builds placed from another object's).
pub fn object_evaluations(o: &Object, plan: &ObjectPlan) -> f64 {
    match plan.build {
        Build::ClosedForm
        | Build::MeshTriangles
        | Build::Tessellated { .. }
        | Build::PlaneDisc { .. }
        | Build::SharedMesh { .. }
        | Build::SharedGrid { .. }
        | Build::GridFileMarched { .. }
        | Build::GridFileExtracted { .. } => 0.0,
        Build::Marched { .. } => SdfTree::for_marching(o).map_or(0.0, |t| t.evaluations()),
        _ => SdfTree::new(o).map_or(0.0, |t| t.evaluations()),
    }
}

/// An upper estimate of the bytes of a sphere traced object's compiled tape
/// ([`crate::geometry::sdf::SdfField`]): [`ops_bound`] operations, at most
/// [`MAX_TAPE_OPS`] (a longer tape is abandoned when it gets there), of `size_of::<Op>()`
/// each; 0 for a single primitive (no tape).
pub fn tape_bytes(o: &Object) -> u64 {
    match SdfTree::for_marching(o) {
        Some(t) if t.node_count > 1 => {
            (ops_bound(&t.root).min(MAX_TAPE_OPS as f64) as u64).saturating_mul(size_of::<Op>() as u64)
        }
        _ => 0,
    }
}

/// An upper estimate of the bytes building `o` as `plan` says, and tracing it, needs: a
/// grid's samples (each grid has at most [`grid_samples_per_axis`] samples per axis; a
/// narrow band never holds more than the dense grid) with what sampling or voxelizing a
/// mesh needs ([`mesh_to_grid_bytes`]); triangles (parametric primitives have at most
/// `2 res^2`, extracted objects as [`extraction_bytes`]); loaded meshes and grid files
/// count as what they hold; a shared mesh counts once, where it is built, and every
/// placement of it [`BYTES_PER_INSTANCE`] (an instanced repetition: its one mesh and
/// `copies` placements). Sphere tracing counts its tape ([`tape_bytes`]), closed forms
/// nothing.
pub fn object_bytes(o: &Object, plan: &ObjectPlan) -> u64 {
    let triangles = match &o.kind {
        ObjectKind::Mesh { mesh, .. } => mesh.triangles.len(),
        _ => 0,
    };
    let grid_file = match &o.kind {
        ObjectKind::Grid { grid, .. } => grid_bytes(grid.dims, 4),
        _ => 0,
    };
    match plan.build {
        Build::ClosedForm | Build::PlaneDisc { .. } => 0,
        Build::Marched { .. } => tape_bytes(o),
        Build::MeshTriangles => (triangles as u64).saturating_mul(BYTES_PER_TRACED_TRIANGLE),
        Build::Tessellated { resolution, .. } => tessellation_bytes(resolution),
        Build::SharedMesh { .. } | Build::SharedGrid { .. } => BYTES_PER_INSTANCE,
        Build::LocalGrid { resolution, .. } => {
            mesh_to_grid_bytes(0, UVec3::splat(grid_samples_per_axis(resolution)), GridFill::Sample)
        }
        Build::InstancedGrid { resolution, copies, .. } => {
            mesh_to_grid_bytes(0, UVec3::splat(grid_samples_per_axis(resolution)), GridFill::Sample)
                .saturating_add((copies as u64).saturating_mul(BYTES_PER_INSTANCE))
        }
        Build::Instanced { mesh, copies, .. } => {
            let mesh = match mesh {
                InstanceMesh::Tessellated { resolution, .. } => tessellation_bytes(resolution),
                InstanceMesh::Extracted { method, resolution } => extraction_bytes(resolution, method),
            };
            mesh.saturating_add((copies as u64).saturating_mul(BYTES_PER_INSTANCE))
        }
        Build::Extracted { method, resolution } => extraction_bytes(resolution, method),
        // Analytic objects are sampled (`fill` is `Sample`) and hold no triangles.
        Build::Grid { resolution, fill, .. } => {
            mesh_to_grid_bytes(triangles, UVec3::splat(grid_samples_per_axis(resolution)), fill)
        }
        Build::GridFileMarched { .. } => grid_file,
        Build::ImplicitMarched { .. } => match &o.kind {
            ObjectKind::Implicit { field, .. } => field.bytes_used() as u64,
            _ => 0,
        },
        Build::ImplicitExtracted { method, resolution } => extraction_bytes(resolution, method),
        Build::GridFileExtracted { method, resolution } => {
            extraction_bytes(resolution, method).saturating_add(grid_file)
        }
    }
}

/// An upper estimate of the bytes of a primitive tessellated at `resolution` (at most
/// `2 resolution^2` triangles).
fn tessellation_bytes(resolution: u32) -> u64 {
    let r = resolution as u64;
    (2 * r * r).saturating_mul(BYTES_PER_TRACED_TRIANGLE)
}

/// An upper estimate of the bytes [`crate::plan::reextract_mesh`] needs for a mesh of
/// `triangles` triangles at `resolution`: its grid and the extraction.
pub fn reextract_bytes(triangles: usize, fill: GridFill, resolution: u32) -> u64 {
    let dims = UVec3::splat(grid_samples_per_axis(resolution));
    mesh_to_grid_bytes(triangles, dims, fill)
        .saturating_add(extraction_bytes(resolution, ExtractMethod::MarchingCubes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_sizes_and_rejects_nonsense() {
        assert_eq!("4GiB".parse::<MemoryBudget>().unwrap().bytes, 4 << 30);
        assert_eq!("512 MiB".parse::<MemoryBudget>().unwrap().bytes, 512 << 20);
        assert_eq!("1000".parse::<MemoryBudget>().unwrap().bytes, 1000);
        assert_eq!("2 GB".parse::<MemoryBudget>().unwrap().bytes, 2_000_000_000);
        for bad in ["", "lots", "-1GiB", "0", "1.5.2G"] {
            assert!(bad.parse::<MemoryBudget>().is_err(), "{bad:?} parsed");
        }
    }

    #[test]
    fn refuses_more_than_physical_memory() {
        let total = Some(8u64 << 30);
        assert_eq!(MemoryBudget::parse_within("8GiB", total).unwrap().bytes, 8 << 30);
        let e = MemoryBudget::parse_within("9GiB", total).unwrap_err();
        assert!(e.contains("physical memory") && e.contains("8.0 GiB"), "{e}");
        assert!(MemoryBudget::parse_within("1EB", total).is_err());
        // Unknown physical memory: only the size itself is checked.
        assert_eq!(MemoryBudget::parse_within("1EB", None).unwrap().bytes, 1_000_000_000_000_000_000);
        if let Some(t) = machine_total() {
            assert!(format!("{}", t + 1).parse::<MemoryBudget>().is_err());
            assert_eq!(format!("{t}").parse::<MemoryBudget>().unwrap().bytes, t);
        }
    }

    #[test]
    fn reads_mem_total() {
        let text = "MemTotal:       24568320 kB\nMemFree:         1000 kB\n";
        assert_eq!(mem_total(text), Some(24568320 * 1024));
        assert_eq!(mem_total("MemFree: 1 kB\n"), None);
        assert!(MemoryBudget::machine_default().bytes > 0);
    }

    #[test]
    fn check_names_the_request_and_both_sizes() {
        let b = MemoryBudget { bytes: 1 << 30 };
        assert!(b.check("a grid", 1 << 30).is_ok());
        let e = b.check("a 2048^3 grid", 32 << 30).unwrap_err().to_string();
        assert!(e.contains("a 2048^3 grid") && e.contains("32.0 GiB") && e.contains("1.0 GiB"), "{e}");
        assert!(e.contains("--max-memory"), "{e}");
    }

    #[test]
    fn estimates_grow_with_resolution() {
        let a = extraction_bytes(64, ExtractMethod::MarchingCubes);
        let b = extraction_bytes(128, ExtractMethod::MarchingCubes);
        // The grid grows as res^3, the mesh bound as res^2.
        assert!(b > 4 * a && b < 8 * a, "{a} {b}");
        assert!(extraction_bytes(64, ExtractMethod::DualContouring) > a);
        assert_eq!(mesh_to_grid_bytes(0, UVec3::splat(10), GridFill::Sample), 4000);
        assert_eq!(mesh_to_grid_bytes(0, UVec3::splat(10), GridFill::Voxelize), 13000);
        assert_eq!(grid_bytes(UVec3::splat(u32::MAX), 4), u64::MAX);
    }
}
