//! Narrow-band storage of a signed distance grid: samples only near the surface.
//!
//! A [`BandGrid`] has the lattice of an [`SdfGrid`](super::SdfGrid) (same `origin`, `voxel`, `dims`),
//! split into bricks of [`BRICK`]³ cells. A brick with a cell within `cells` cells of the
//! surface stores its `9 x 9 x 9` corner samples (the borders are shared with, i.e.
//! duplicated in, the neighbouring bricks, so interpolation never looks outside one
//! brick). Every other brick stores one `f32`: a conservative signed lower bound of the
//! distance anywhere in it (`|bound| <=` the true distance, same sign), which is what
//! [`BandGrid::trilinear`] returns there, so sphere tracing through it stays safe (and
//! takes steps of at least the band's width).
//!
//! Stored samples are quantized to 16 bits per brick (`value = offset + scale * q`, `q`
//! in `0..=65535`, over the brick's own range of values): the error is at most
//! `range / 131070`, about `1e-4` voxel for an exact distance field (a brick's values span
//! at most its diagonal, `8 √3` voxels). This halves the memory against `f32`; with
//! 9³-sample bricks it is what makes the band pay off for surfaces that fill their box.
//!
//! The builders live with the conversions
//! ([`crate::convert::mesh_to_grid::band`]), and never allocate the dense grid where they
//! can avoid it: `band_from_function` and `band_from_mesh` first evaluate each brick's centre and
//! skip the brick when `|d(centre)|` exceeds the brick's half diagonal plus the band
//! (the bound is then `|d(centre)| -` half diagonal); the remaining bricks are sampled
//! and dropped again when every sample is farther than the band plus half a cell
//! diagonal (bound: the smallest `|sample| -` half a cell diagonal). Both need a
//! 1-Lipschitz distance (exact or a lower bound), which exact distances and the
//! scene's SDFs are. [`BandGrid::from_dense`] applies the second test to a dense grid.

use glam::{UVec3, Vec3};

/// Cells along each edge of a brick.
pub const BRICK: u32 = 8;
/// Samples along each edge of a stored brick (`BRICK + 1`).
pub(crate) const BS: usize = BRICK as usize + 1;
/// Samples in a stored brick.
pub const BRICK_SAMPLES: usize = BS * BS * BS;
/// `slots` entry of a brick that stores no samples.
pub(crate) const NONE: u32 = u32::MAX;
/// Half the diagonal of a cell, in voxels.
pub(crate) const HALF_CELL_DIAGONAL: f32 = 0.866_025_4;

/// A narrow-band signed distance grid (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct BandGrid {
    /// Position of sample `(0, 0, 0)`, scene units.
    pub origin: Vec3,
    /// Spacing of the samples, `> 0`.
    pub voxel: f32,
    /// Samples per axis of the equivalent dense grid, each `>= 2`.
    pub dims: UVec3,
    /// Bricks per axis: `ceil((dims - 1) / BRICK)`.
    pub bricks: UVec3,
    /// Half-width of the stored band, in cells.
    pub band_cells: u32,
    /// Per brick (x fastest): index of its samples in `ranges` / `data`, or `NONE`.
    slots: Vec<u32>,
    /// Per brick: the signed lower bound of the distance in it (meaningful for bricks
    /// without samples).
    bounds: Vec<f32>,
    /// Per stored brick: `(offset, scale)` of its quantized samples.
    ranges: Vec<[f32; 2]>,
    /// Quantized samples, [`BRICK_SAMPLES`] per stored brick, x fastest within a brick.
    data: Vec<u16>,
}

impl BandGrid {
    /// A band grid from its parts, as the builders of
    /// [`crate::convert::mesh_to_grid::band`] make them: the lattice (`origin`, `voxel`,
    /// `dims`), `bricks` per axis (`ceil((dims - 1) / BRICK)`), the band's half-width
    /// `band_cells`, and per brick (x fastest) its slot in `ranges` and `data` (or
    /// [`NONE`]) and its bound; per stored brick its `(offset, scale)` and its
    /// [`BRICK_SAMPLES`] quantized samples.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn from_parts(
        origin: Vec3,
        voxel: f32,
        dims: UVec3,
        bricks: UVec3,
        band_cells: u32,
        slots: Vec<u32>,
        bounds: Vec<f32>,
        ranges: Vec<[f32; 2]>,
        data: Vec<u16>,
    ) -> BandGrid {
        debug_assert_eq!(slots.len(), bounds.len());
        debug_assert_eq!(data.len(), ranges.len() * BRICK_SAMPLES);
        BandGrid { origin, voxel, dims, bricks, band_cells, slots, bounds, ranges, data }
    }

    /// Number of bricks.
    pub fn brick_count(&self) -> usize {
        self.slots.len()
    }

    /// Number of bricks that store samples.
    pub fn stored_bricks(&self) -> usize {
        self.ranges.len()
    }

    /// Values actually stored: [`BRICK_SAMPLES`] per stored brick plus one bound per
    /// other brick.
    pub fn stored_values(&self) -> u64 {
        (self.stored_bricks() * BRICK_SAMPLES + (self.brick_count() - self.stored_bricks())) as u64
    }

    /// Bytes the equivalent dense grid's samples would take (`f32` each).
    pub fn dense_bytes(&self) -> u64 {
        self.dims.x as u64 * self.dims.y as u64 * self.dims.z as u64 * 4
    }

    /// The grid's box, `(min, max)`, as [`SdfGrid::bounds`](super::SdfGrid::bounds).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        (self.origin, self.origin + self.voxel * (self.dims - UVec3::ONE).as_vec3())
    }

    /// Whether the brick holding cell `(i, j, k)` stores samples.
    pub fn is_stored(&self, cell: UVec3) -> bool {
        self.slots[self.brick_index(cell / BRICK)] != NONE
    }

    #[inline]
    fn brick_index(&self, b: UVec3) -> usize {
        b.x as usize + self.bricks.x as usize * (b.y as usize + self.bricks.y as usize * b.z as usize)
    }

    /// Trilinear interpolation of the stored samples at `p` inside stored bricks, the
    /// brick's bound elsewhere; outside the box combined with the distance to it exactly as
    /// [`SdfGrid::trilinear`](super::SdfGrid::trilinear).
    pub fn trilinear(&self, p: Vec3) -> f32 {
        let (lo, hi) = self.bounds();
        let q = p.clamp(lo, hi);
        let d = (p - q).length();
        let f = (q - self.origin) / self.voxel;
        let max_cell = (self.dims - UVec3::splat(2)).as_vec3();
        let c = f.floor().clamp(Vec3::ZERO, max_cell);
        let t = (f - c).clamp(Vec3::ZERO, Vec3::ONE);
        let cell = c.as_uvec3();
        let bi = self.brick_index(cell / BRICK);
        let slot = self.slots[bi];
        let value = if slot == NONE {
            self.bounds[bi]
        } else {
            let l = cell % BRICK;
            let [offset, scale] = self.ranges[slot as usize];
            let base = slot as usize * BRICK_SAMPLES + l.x as usize + BS * (l.y as usize + BS * l.z as usize);
            let v = &self.data;
            let g = |o: usize| v[base + o] as f32;
            let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
            let (sy, sz) = (BS, BS * BS);
            let x00 = lerp(g(0), g(1), t.x);
            let x10 = lerp(g(sy), g(sy + 1), t.x);
            let x01 = lerp(g(sz), g(sz + 1), t.x);
            let x11 = lerp(g(sz + sy), g(sz + sy + 1), t.x);
            offset + scale * lerp(lerp(x00, x10, t.y), lerp(x01, x11, t.y), t.z)
        };
        super::continue_outside(value, d)
    }

    /// Bytes of memory this grid holds: the struct and every allocated array's capacity.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.slots.capacity() * std::mem::size_of::<u32>()
            + self.bounds.capacity() * std::mem::size_of::<f32>()
            + self.ranges.capacity() * std::mem::size_of::<[f32; 2]>()
            + self.data.capacity() * std::mem::size_of::<u16>()
    }
}
