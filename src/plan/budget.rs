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
        let total = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| mem_total(&s));
        MemoryBudget { bytes: total.map_or(FALLBACK_BYTES, |t| (t as f64 * DEFAULT_FRACTION) as u64) }
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

    /// Parses sizes such as `4GiB`, `512 MB`, `1.5G` or a plain byte count.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let b: ByteSize = s.trim().parse().map_err(|e| format!("not a memory size ({e}): '{s}'"))?;
        if b.as_u64() == 0 {
            return Err(format!("a memory budget must be more than 0 bytes, got '{s}'"));
        }
        Ok(MemoryBudget { bytes: b.as_u64() })
    }
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

/// An upper estimate of the bytes building `o` as `plan` says, and tracing it, needs: a
/// grid's samples (each grid has at most [`grid_samples_per_axis`] samples per axis; a
/// narrow band never holds more than the dense grid) with what sampling or voxelizing a
/// mesh needs ([`mesh_to_grid_bytes`]); triangles (parametric primitives have at most
/// `2 res^2`, extracted objects as [`extraction_bytes`]); loaded meshes and grid files
/// count as what they hold; a shared mesh counts once, where it is built, and every
/// placement of it [`BYTES_PER_INSTANCE`] (an instanced repetition: its one mesh and
/// `copies` placements). Sphere tracing and closed forms count nothing.
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
        Build::ClosedForm | Build::Marched { .. } | Build::PlaneDisc { .. } => 0,
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
