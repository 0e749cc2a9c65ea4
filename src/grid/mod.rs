//! Discrete signed distance grids as data, as the `mesh` module holds triangle meshes: the
//! dense [`SdfGrid`] (with its layout, [`grid_layout`], and size check, [`check_size`]) and
//! its file formats ([`io`]). Tracing grids (the narrow-band grid, grids as scene objects,
//! one grid shared by a scene's objects) is the geometry module's `geometry::grid`; filling
//! a grid from a mesh or a distance function is a conversion (`convert::mesh_to_grid`).
//!
//! An [`SdfGrid`] stores signed distances (negative inside) at the CORNERS of a regular
//! grid of cubic cells: sample `(i, j, k)` sits at `origin + voxel * (i, j, k)`, so a grid
//! of `dims` samples spans `dims - 1` cells per axis and its box is
//! `[origin, origin + voxel * (dims - 1)]`. Between samples [`SdfGrid::trilinear`]
//! interpolates; `SdfGrid::trilinear8` (defined with the tracing, in `geometry::grid`)
//! interpolates at eight points at once (for packets of marched rays, AVX2 where the CPU
//! has it, bit-identical lane by lane).

pub mod io;

use glam::{UVec3, Vec3};

use crate::error::{Error, Result};

/// The default limit on a grid's sample memory (8 GiB) used by [`SdfGrid::for_bounds`]
/// and by sampling a mesh into a grid (`convert::mesh_to_grid::sample_mesh`).
pub const DEFAULT_MAX_GRID_BYTES: u64 = 8 << 30;

/// A regular grid of signed distance samples (see the module documentation for the
/// layout).
#[derive(Clone, Debug, PartialEq)]
pub struct SdfGrid {
    /// Position of sample `(0, 0, 0)`, scene units.
    pub origin: Vec3,
    /// Spacing of the samples (the cells' edge length), `> 0`.
    pub voxel: f32,
    /// Samples per axis, each `>= 2`.
    pub dims: UVec3,
    /// Signed distances, negative inside; `x` fastest, then `y`, then `z`;
    /// `values.len() == dims.x * dims.y * dims.z`.
    pub values: Vec<f32>,
}

/// Checks that a grid of `dims` samples has at least 2 samples per axis and that its
/// `f32` values fit in `max_bytes`, without allocating anything.
///
/// # Errors
/// [`Error::Usage`] naming the dimensions and the memory they would need.
pub fn check_size(dims: UVec3, max_bytes: u64) -> Result<()> {
    if dims.min_element() < 2 {
        return Err(Error::Usage(format!(
            "an SDF grid needs at least 2 samples per axis, not {}x{}x{}",
            dims.x, dims.y, dims.z
        )));
    }
    let bytes = dims.x as u128 * dims.y as u128 * dims.z as u128 * std::mem::size_of::<f32>() as u128;
    if bytes > max_bytes as u128 || bytes > isize::MAX as u128 {
        return Err(Error::Usage(format!(
            "an SDF grid of {}x{}x{} samples would need {} of memory, more than the limit of {}; \
             use a lower resolution",
            dims.x,
            dims.y,
            dims.z,
            human_bytes(bytes),
            human_bytes(max_bytes as u128)
        )));
    }
    Ok(())
}

/// The field at a point `d >= 0` outside a grid's box whose nearest box point has the
/// interpolated value `value` (see [`SdfGrid::trilinear`]): `sqrt(d^2 + value^2)` when
/// `value >= 0`, `value + d` otherwise; `value` itself at `d == 0`.
#[inline]
pub(crate) fn continue_outside(value: f32, d: f32) -> f32 {
    if d == 0.0 {
        value
    } else if value >= 0.0 {
        (d * d + value * value).sqrt()
    } else {
        value + d
    }
}

fn human_bytes(b: u128) -> String {
    const GIB: f64 = (1u64 << 30) as f64;
    const MIB: f64 = (1u64 << 20) as f64;
    let f = b as f64;
    if f >= GIB { format!("{:.1} GiB", f / GIB) } else { format!("{:.1} MiB", f / MIB) }
}

/// The placement [`SdfGrid::for_bounds`] gives a grid around `[lo, hi]` with `res` cells
/// along the longest axis and `margin_cells` more on every side: `(origin, voxel, dims)`,
/// without checking the memory it would need or allocating anything.
///
/// # Errors
/// [`Error::Usage`] for `res == 0`, a box that is empty, flat in every direction or not
/// finite, or more than `u32::MAX` samples along an axis.
pub fn grid_layout(lo: Vec3, hi: Vec3, res: u32, margin_cells: u32) -> Result<(Vec3, f32, UVec3)> {
    if res == 0 {
        return Err(Error::Usage("the SDF grid resolution must be at least 1 cell".into()));
    }
    let ext = hi - lo;
    let longest = ext.max_element();
    if !lo.is_finite() || !hi.is_finite() || !(ext.min_element() >= 0.0) || !(longest > 0.0) {
        return Err(Error::Usage(format!("cannot build an SDF grid around the box {lo} .. {hi}")));
    }
    let voxel = longest as f64 / res as f64;
    let mut cells = [0u64; 3];
    let mut dims = [0u32; 3];
    for a in 0..3 {
        // The tolerance keeps the longest axis at exactly `res` cells.
        let c = ((ext[a] as f64 / voxel) - 1e-6).ceil().max(1.0) as u64 + 2 * margin_cells as u64;
        cells[a] = c;
        dims[a] = u32::try_from(c + 1).map_err(|_| {
            Error::Usage(format!("an SDF grid of {} samples along one axis is too large", c + 1))
        })?;
    }
    let dims = UVec3::from_array(dims);
    if dims.min_element() < 2 {
        return Err(Error::Usage("an SDF grid needs at least 2 samples per axis".into()));
    }
    let centre = (lo.as_dvec3() + hi.as_dvec3()) * 0.5;
    let half = glam::DVec3::new(cells[0] as f64, cells[1] as f64, cells[2] as f64) * (voxel * 0.5);
    let origin = (centre - half).as_vec3();
    Ok((origin, voxel as f32, dims))
}

impl SdfGrid {
    /// A zero-filled grid around the box `[lo, hi]` with `res` cells along the box's
    /// longest axis (so `voxel = longest extent / res`), as many cells as cover each other
    /// axis, and `margin_cells` more cells on every side; samples = cells + 1 per axis.
    /// The box is centred in the grid. Checks the size against
    /// [`DEFAULT_MAX_GRID_BYTES`] before allocating.
    ///
    /// # Errors
    /// [`Error::Usage`] for `res == 0`, a box that is empty, flat in every direction
    /// or not finite, or a grid too large (see [`check_size`]).
    pub fn for_bounds(lo: Vec3, hi: Vec3, res: u32, margin_cells: u32) -> Result<Self> {
        Self::for_bounds_with_limit(lo, hi, res, margin_cells, DEFAULT_MAX_GRID_BYTES)
    }

    /// [`SdfGrid::for_bounds`] with an explicit memory limit in bytes.
    ///
    /// # Errors
    /// As [`SdfGrid::for_bounds`].
    pub fn for_bounds_with_limit(
        lo: Vec3,
        hi: Vec3,
        res: u32,
        margin_cells: u32,
        max_bytes: u64,
    ) -> Result<Self> {
        let (origin, voxel, dims) = grid_layout(lo, hi, res, margin_cells)?;
        check_size(dims, max_bytes)?;
        let n = dims.x as usize * dims.y as usize * dims.z as usize;
        Ok(SdfGrid { origin, voxel, dims, values: vec![0.0; n] })
    }

    /// Index into `values` of sample `(i, j, k)`.
    #[inline]
    pub fn index(&self, i: u32, j: u32, k: u32) -> usize {
        debug_assert!(i < self.dims.x && j < self.dims.y && k < self.dims.z);
        i as usize + self.dims.x as usize * (j as usize + self.dims.y as usize * k as usize)
    }

    /// The value of sample `(i, j, k)`.
    ///
    /// # Panics
    /// When the index is out of range.
    #[inline]
    pub fn get(&self, i: u32, j: u32, k: u32) -> f32 {
        assert!(i < self.dims.x && j < self.dims.y && k < self.dims.z, "sample ({i}, {j}, {k}) out of range");
        self.values[self.index(i, j, k)]
    }

    /// The position of sample `(i, j, k)`.
    #[inline]
    pub fn position(&self, i: u32, j: u32, k: u32) -> Vec3 {
        self.origin + self.voxel * Vec3::new(i as f32, j as f32, k as f32)
    }

    /// The grid's box, `(min, max)`: from sample `(0, 0, 0)` to the last sample.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        (self.origin, self.origin + self.voxel * (self.dims - UVec3::ONE).as_vec3())
    }

    /// Trilinear interpolation of the samples at `p`.
    ///
    /// Inside the grid's box this is the usual trilinear interpolation. Outside, the value
    /// `f` at the nearest point of the box is combined with the distance `d` from `p` to
    /// the box: `sqrt(d² + f²)` when `f >= 0`, which is a lower bound on the true
    /// distance whenever the surface lies inside the box and `f` is exact (the nearest
    /// surface point is at least `f` from the box point and the box lies on the far side
    /// of the plane through that point orthogonal to `p`'s offset); `f + d` when `f < 0`
    /// (the surface then crosses the box boundary, which the margin of
    /// `convert::mesh_to_grid::sample_mesh` avoids). Both are continuous across the box boundary and 1-Lipschitz in `d`.
    #[inline]
    pub fn trilinear(&self, p: Vec3) -> f32 {
        self.trilinear_inline(p)
    }

    /// [`SdfGrid::trilinear`], always inlined (into the AVX2 build of the marched field,
    /// `geometry::grid::object::GridStore::march_distance`).
    #[inline(always)]
    pub(crate) fn trilinear_inline(&self, p: Vec3) -> f32 {
        let (lo, hi) = self.bounds();
        let q = p.clamp(lo, hi);
        let d = (p - q).length();
        let f = (q - self.origin) / self.voxel;
        let max_cell = (self.dims - UVec3::splat(2)).as_vec3();
        let c = f.floor().clamp(Vec3::ZERO, max_cell);
        let t = (f - c).clamp(Vec3::ZERO, Vec3::ONE);
        let (i, j, k) = (c.x as u32, c.y as u32, c.z as u32);
        let base = self.index(i, j, k);
        let sx = 1;
        let sy = self.dims.x as usize;
        let sz = self.dims.x as usize * self.dims.y as usize;
        let v = &self.values;
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let x00 = lerp(v[base], v[base + sx], t.x);
        let x10 = lerp(v[base + sy], v[base + sy + sx], t.x);
        let x01 = lerp(v[base + sz], v[base + sz + sx], t.x);
        let x11 = lerp(v[base + sz + sy], v[base + sz + sy + sx], t.x);
        let value = lerp(lerp(x00, x10, t.y), lerp(x01, x11, t.y), t.z);
        continue_outside(value, d)
    }

    /// Bytes of memory this grid holds: the struct and the allocated sample capacity.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.values.capacity() * std::mem::size_of::<f32>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_and_trilinear() {
        let g = SdfGrid::for_bounds(Vec3::ZERO, Vec3::new(2.0, 1.0, 0.5), 4, 1).unwrap();
        assert_eq!(g.voxel, 0.5);
        assert_eq!(g.dims, UVec3::new(7, 5, 4));
        assert_eq!(g.origin, Vec3::new(-0.5, -0.5, -0.5));
        assert_eq!(g.values.len(), 7 * 5 * 4);
        assert_eq!(g.bounds(), (Vec3::splat(-0.5), Vec3::new(2.5, 1.5, 1.0)));
        // A linear field is reproduced exactly by trilinear interpolation.
        let mut g = g;
        let f = |p: Vec3| p.x - 2.0 * p.y + 0.5 * p.z + 3.0;
        for k in 0..g.dims.z {
            for j in 0..g.dims.y {
                for i in 0..g.dims.x {
                    let idx = g.index(i, j, k);
                    g.values[idx] = f(g.position(i, j, k));
                }
            }
        }
        assert_eq!(g.get(1, 2, 3), f(g.position(1, 2, 3)));
        for p in
            [Vec3::new(0.3, 0.7, 0.1), Vec3::new(2.5, 1.5, 1.0), Vec3::splat(-0.5), Vec3::new(1.9, -0.2, 0.6)]
        {
            assert!((g.trilinear(p) - f(p)).abs() < 1e-5, "{p}");
        }
        // Outside: combined with the distance to the box, continuous at the boundary.
        let inside = Vec3::new(2.5, 0.0, 0.0);
        let v = g.trilinear(inside);
        assert!(v > 0.0);
        let out = g.trilinear(inside + Vec3::new(3.0, 0.0, 0.0));
        assert!((out - (9.0 + v * v).sqrt()).abs() < 1e-5);
        assert!(g.bytes_used() >= 7 * 5 * 4 * 4);
    }

    #[test]
    fn size_checks() {
        let e = check_size(UVec3::splat(100_000), DEFAULT_MAX_GRID_BYTES).unwrap_err();
        assert!(matches!(e, Error::Usage(_)));
        assert!(e.to_string().contains("100000x100000x100000"), "{e}");
        assert!(check_size(UVec3::new(2, 1, 2), 1 << 20).is_err());
        assert!(check_size(UVec3::splat(64), 1 << 20).is_ok());
        assert!(SdfGrid::for_bounds(Vec3::ZERO, Vec3::ONE, 0, 0).is_err());
        assert!(SdfGrid::for_bounds(Vec3::ONE, Vec3::ONE, 8, 0).is_err());
        assert!(SdfGrid::for_bounds(Vec3::ZERO, Vec3::ONE, u32::MAX, 0).is_err());
    }
}
