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
//! Empty-space skipping: every empty brick also knows how far (in bricks, the chessboard
//! distance) the nearest brick lies that could hold the surface: a stored brick, an empty
//! brick of the other sign (or with a zero bound), and for a brick inside the surface
//! (negative bound) the outside of the grid's box. The cube of bricks centred on it within
//! one less than that distance holds no surface of the interpolated field (all its bricks
//! are empty and of one sign), so [`BandGrid::march_distance`] answers there the larger of
//! the brick's bound and the distance from the point to that cube's boundary (sign kept):
//! still a lower bound of the true distance (the true surface lies in stored bricks), and
//! rays through empty space take steps of up to the whole empty region. The distance lives
//! in the low bits of the empty brick's `slots` entry (no extra memory).
//!
//! The builders live with the conversions
//! (`convert::mesh_to_grid::band`), and never allocate the dense grid where they
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
/// `slots` entry of a brick that stores no samples, as the builders give it to
/// [`BandGrid::from_parts`] (which replaces it by [`EMPTY`] and the brick's skip distance).
pub(crate) const NONE: u32 = u32::MAX;
/// Bit of a `slots` entry set for a brick that stores no samples; the low bits hold the
/// chessboard distance in bricks to the nearest brick that may hold the surface (see the
/// module documentation), `0` when the brick's bound is zero or not finite (no skipping).
pub(crate) const EMPTY: u32 = 1 << 31;
/// Largest skip distance stored, in bricks.
const MAX_SKIP: u32 = 1 << 16;
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
    /// Per brick (x fastest): index of its samples in `ranges` / `data` (`< EMPTY`), or
    /// `EMPTY | skip distance` for a brick without samples.
    pub(super) slots: Vec<u32>,
    /// Per brick: the signed lower bound of the distance in it (meaningful for bricks
    /// without samples).
    pub(super) bounds: Vec<f32>,
    /// Per stored brick: `(offset, scale)` of its quantized samples.
    pub(super) ranges: Vec<[f32; 2]>,
    /// Quantized samples, [`BRICK_SAMPLES`] per stored brick, x fastest within a brick.
    pub(super) data: Vec<u16>,
}

impl BandGrid {
    /// A band grid from its parts, as the builders of
    /// `convert::mesh_to_grid::band` make them: the lattice (`origin`, `voxel`,
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
        let slots = with_skip_distances(bricks, slots, &bounds);
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
        self.slots[self.brick_index(cell / BRICK)] & EMPTY == 0
    }

    /// The skip distance of the brick holding cell `(i, j, k)`, in bricks: for a brick
    /// without samples the chessboard distance to the nearest brick that may hold the
    /// surface (see the module documentation; `0`: no skipping), `0` for a stored brick.
    pub fn skip_bricks(&self, cell: UVec3) -> u32 {
        let s = self.slots[self.brick_index(cell / BRICK)];
        if s & EMPTY == 0 { 0 } else { s & !EMPTY }
    }

    /// The slot (index among the stored bricks) of brick `b` (bricks per axis), `None` for a
    /// brick without samples.
    #[inline]
    pub fn slot(&self, b: UVec3) -> Option<usize> {
        let s = self.slots[self.brick_index(b)];
        (s & EMPTY == 0).then_some(s as usize)
    }

    #[inline]
    pub(crate) fn brick_index(&self, b: UVec3) -> usize {
        b.x as usize + self.bricks.x as usize * (b.y as usize + self.bricks.y as usize * b.z as usize)
    }

    /// Trilinear interpolation of the stored samples at `p` inside stored bricks, the
    /// brick's bound elsewhere; outside the box combined with the distance to it exactly as
    /// [`SdfGrid::trilinear`](super::SdfGrid::trilinear).
    pub fn trilinear(&self, p: Vec3) -> f32 {
        self.eval(p, false)
    }

    /// The distance sphere tracing steps by at `p`: [`BandGrid::trilinear`] in stored
    /// bricks; in an empty brick the larger of its bound and the distance from `p` to the
    /// boundary of the surface-free cube of bricks around it (see the module
    /// documentation), sign kept, so a step never crosses the interpolated surface;
    /// continued outside the box as [`BandGrid::trilinear`].
    #[inline]
    pub fn march_distance(&self, p: Vec3) -> f32 {
        self.eval(p, true)
    }

    /// [`BandGrid::trilinear`] (`skip == false`) or [`BandGrid::march_distance`]. The
    /// eight-lane kernel of [`super::packet`] repeats these operations in this order.
    #[inline(always)]
    fn eval(&self, p: Vec3, skip: bool) -> f32 {
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
        let value = if slot & EMPTY != 0 {
            let bound = self.bounds[bi];
            if skip { self.skip_value(bound, slot & !EMPTY, cell, f) } else { bound }
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

    /// The skipping value in an empty brick with bound `bound` and skip distance `k`
    /// (bricks), at lattice coordinates `f` (cells) in cell `cell`: `sign(bound) *
    /// max(|bound|, voxel * r)` with `r` the distance from `f` to the boundary of the cube
    /// of bricks within `k - 1` of the brick (clipped to the grid's box for a negative
    /// bound); `bound` itself when `k == 0`.
    #[inline]
    pub(crate) fn skip_value(&self, bound: f32, k: u32, cell: UVec3, f: Vec3) -> f32 {
        if k == 0 {
            return bound;
        }
        let k = k as i32;
        let b = (cell / BRICK).as_ivec3();
        let mut lo = ((b - glam::IVec3::splat(k - 1)) * BRICK as i32).as_vec3();
        let mut hi = ((b + glam::IVec3::splat(k)) * BRICK as i32).as_vec3();
        if bound < 0.0 {
            lo = lo.max(Vec3::ZERO);
            hi = hi.min((self.dims - UVec3::ONE).as_vec3());
        }
        let (a, z) = (f - lo, hi - f);
        let r = min(min(min(a.x, z.x), min(a.y, z.y)), min(a.z, z.z));
        let s = r * self.voxel;
        let m = bound.abs();
        let v = if m > s { m } else { s };
        if bound < 0.0 { -v } else { v }
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

/// `if a < b { a } else { b }` (the operand order of `_mm256_min_ps`).
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `slots` with every [`NONE`] entry replaced by [`EMPTY`] and the brick's skip distance:
/// the chessboard distance in bricks (capped at [`MAX_SKIP`]) to the nearest brick that is
/// stored, has a zero or non-finite bound, or has a bound of the other sign, and for a
/// negative bound also to the outside of the grid; `0` for a brick whose own bound is zero
/// or not finite. Two raster passes over the 26-neighbourhood (exact for the chessboard
/// metric), one per sign.
fn with_skip_distances(bricks: UVec3, mut slots: Vec<u32>, bounds: &[f32]) -> Vec<u32> {
    let (nx, ny, nz) = (bricks.x as i64, bricks.y as i64, bricks.z as i64);
    if slots.len() as i64 != nx * ny * nz {
        // Inconsistent parts: no skipping, every empty brick answers its bound.
        for s in &mut slots {
            if *s == NONE {
                *s = EMPTY;
            }
        }
        return slots;
    }
    let class = |i: usize| -> i8 {
        let b = bounds[i];
        if slots[i] != NONE || !b.is_finite() || b == 0.0 {
            0
        } else if b > 0.0 {
            1
        } else {
            -1
        }
    };
    let classes: Vec<i8> = (0..slots.len()).map(class).collect();
    let idx = |x: i64, y: i64, z: i64| (x + nx * (y + ny * z)) as usize;
    let mut dist = vec![0u32; slots.len()];
    for sign in [1i8, -1] {
        for (d, &c) in dist.iter_mut().zip(&classes) {
            if c == sign {
                *d = MAX_SKIP;
            }
        }
        for pass in 0..2 {
            let forward = pass == 0;
            for n in 0..nx * ny * nz {
                let n = if forward { n } else { nx * ny * nz - 1 - n };
                let (x, y, z) = (n % nx, (n / nx) % ny, n / (nx * ny));
                let i = n as usize;
                if classes[i] != sign {
                    continue;
                }
                let mut best = dist[i];
                for dz in -1..=1i64 {
                    for dy in -1..=1i64 {
                        for dx in -1..=1i64 {
                            // The neighbours before this brick in the pass's raster order.
                            let before = (dz, dy, dx) < (0, 0, 0);
                            if before != forward || (dx, dy, dz) == (0, 0, 0) {
                                continue;
                            }
                            let (a, b, c) = (x + dx, y + dy, z + dz);
                            if a < 0 || b < 0 || c < 0 || a >= nx || b >= ny || c >= nz {
                                continue;
                            }
                            let j = idx(a, b, c);
                            // A brick of the other sign is a source (distance 0) too.
                            let dj = if classes[j] == sign { dist[j] } else { 0 };
                            best = best.min(dj + 1);
                        }
                    }
                }
                dist[i] = best;
            }
        }
        for n in 0..nx * ny * nz {
            let i = n as usize;
            if classes[i] != sign {
                continue;
            }
            if sign < 0 {
                // The outside of the box is a source for bricks inside the surface.
                let (x, y, z) = (n % nx, (n / nx) % ny, n / (nx * ny));
                let edge = (x + 1).min(nx - x).min(y + 1).min(ny - y).min(z + 1).min(nz - z);
                dist[i] = dist[i].min(edge as u32);
            }
            slots[i] = EMPTY | dist[i].min(MAX_SKIP);
        }
    }
    for s in &mut slots {
        if *s == NONE {
            *s = EMPTY;
        }
    }
    slots
}
