//! Narrow-band grid builders ([`BandGrid`], stored near the surface only): from a distance
//! function ([`band_from_function`]), from a mesh ([`band_from_mesh`], exact distances and
//! winding-number signs as [`super::sample_mesh`]) and from a dense grid
//! ([`BandGrid::from_dense`]), all through one brick classifier and quantizer (`build`;
//! see [`crate::geometry::grid::band`] for the storage and the tests that skip bricks).

use glam::{UVec3, Vec3};
use rayon::prelude::*;

use super::MeshSampler;
use super::closest::TriangleBvh;
use super::winding::{self, FastWinding};
use crate::error::{Error, Result};
use crate::geometry::grid::band::{BRICK, BRICK_SAMPLES, BS, BandGrid, HALF_CELL_DIAGONAL, NONE};
use crate::geometry::grid::{DEFAULT_MAX_GRID_BYTES, SdfGrid, grid_layout};
use crate::mesh::TriangleMesh;

/// A brick's samples before quantization, or its bound.
enum Brick {
    Skipped(f32),
    Stored,
}

impl BandGrid {
    /// The band of `dense` within `cells` cells of the surface (`cells >= 1`), with the
    /// dense grid's lattice.
    ///
    /// # Errors
    /// [`Error::Usage`] for `cells == 0`.
    pub fn from_dense(dense: &SdfGrid, cells: u32) -> Result<BandGrid> {
        let max = dense.dims - UVec3::ONE;
        build(
            dense.origin,
            dense.voxel,
            dense.dims,
            cells,
            || (),
            None::<fn(&mut (), Vec3) -> f32>,
            |_, first, out| {
                for c in 0..BS as u32 {
                    for b in 0..BS as u32 {
                        for a in 0..BS as u32 {
                            let s = (first + UVec3::new(a, b, c)).min(max);
                            out[a as usize + BS * (b as usize + BS * c as usize)] = dense.get(s.x, s.y, s.z);
                        }
                    }
                }
            },
        )
    }
}

/// The band (`cells` cells wide) of the 1-Lipschitz signed distance `f` (world space) on
/// the lattice [`super::sample_function`] would use for `lo`..`hi`, `res`, `margin_cells`,
/// without building the dense grid.
///
/// # Errors
/// As [`SdfGrid::for_bounds`] (except that the limit applies to the band's memory), and
/// [`Error::Usage`] for `cells == 0`.
pub fn band_from_function(
    f: &(impl Fn(glam::DVec3) -> f64 + Sync),
    lo: Vec3,
    hi: Vec3,
    res: u32,
    margin_cells: u32,
    cells: u32,
) -> Result<BandGrid> {
    let (origin, voxel, dims) = grid_layout(lo, hi, res, margin_cells)?;
    let (o, v) = (origin.as_dvec3(), voxel as f64);
    build(
        origin,
        voxel,
        dims,
        cells,
        || (),
        Some(|_: &mut (), p: Vec3| f(p.as_dvec3()) as f32),
        |_, first, out| {
            for c in 0..BS as u32 {
                for b in 0..BS as u32 {
                    for a in 0..BS as u32 {
                        let s = (first + UVec3::new(a, b, c)).as_dvec3();
                        out[a as usize + BS * (b as usize + BS * c as usize)] = f(o + s * v) as f32;
                    }
                }
            }
        },
    )
}

/// The band (`cells` cells wide) of `mesh`'s signed distance (exact distances, winding
/// number signs, as [`super::sample_mesh`]) on the lattice `sample_mesh` would use,
/// without building the dense grid.
///
/// # Errors
/// As [`super::sample_mesh`], and [`Error::Usage`] for `cells == 0`.
pub fn band_from_mesh(mesh: &TriangleMesh, res: u32, margin_cells: u32, cells: u32) -> Result<BandGrid> {
    let Some((lo, hi)) = mesh.bounds().filter(|_| !mesh.triangles.is_empty()) else {
        return Err(Error::Usage("cannot sample the distance field of a mesh without triangles".into()));
    };
    let (origin, voxel, dims) = grid_layout(lo, hi, res, margin_cells)?;
    let tree = TriangleBvh::new(mesh);
    let wind = FastWinding::new(&tree);
    let closed = winding::is_closed(mesh);
    build(
        origin,
        voxel,
        dims,
        cells,
        || MeshSampler::new(&tree, &wind, closed),
        Some(|s: &mut MeshSampler, p: Vec3| s.sample(p)),
        |s, first, out| {
            // Serpentine order keeps consecutive queries adjacent.
            for c in 0..BS as u32 {
                for b in 0..BS as u32 {
                    for step in 0..BS as u32 {
                        let a = if (b + c) % 2 == 0 { step } else { BS as u32 - 1 - step };
                        let p = origin + voxel * (first + UVec3::new(a, b, c)).as_vec3();
                        out[a as usize + BS * (b as usize + BS * c as usize)] = s.sample(p);
                    }
                }
            }
        },
    )
}

/// The shared builder: classifies every brick (by `centre` first when given, then by its
/// samples from `fill`, which writes the [`BRICK_SAMPLES`] samples of the brick whose
/// first sample is `first`), then quantizes and packs the stored bricks.
#[allow(clippy::too_many_arguments)]
fn build<S>(
    origin: Vec3,
    voxel: f32,
    dims: UVec3,
    cells: u32,
    init: impl Fn() -> S + Sync + Send,
    centre: Option<impl Fn(&mut S, Vec3) -> f32 + Sync>,
    fill: impl Fn(&mut S, UVec3, &mut [f32]) + Sync,
) -> Result<BandGrid> {
    if cells == 0 {
        return Err(Error::Usage("the narrow band must be at least 1 cell wide".into()));
    }
    let bricks = (dims - UVec3::ONE + UVec3::splat(BRICK - 1)) / BRICK;
    let count = bricks.x as u64 * bricks.y as u64 * bricks.z as u64;
    if count * 8 > DEFAULT_MAX_GRID_BYTES {
        return Err(Error::Usage(format!(
            "a narrow-band grid of {}x{}x{} bricks is too large; use a lower resolution",
            bricks.x, bricks.y, bricks.z
        )));
    }
    let count = count as usize;
    let band = cells as f32 * voxel;
    let brick_of = |b: usize| {
        let (bx, by) = (bricks.x as usize, bricks.y as usize);
        UVec3::new((b % bx) as u32, ((b / bx) % by) as u32, (b / (bx * by)) as u32)
    };
    // Pass 1: the brick centres.
    let half_diagonal = 0.5 * BRICK as f32 * voxel * 3f32.sqrt();
    let first: Vec<Brick> = match &centre {
        Some(centre) => (0..count)
            .into_par_iter()
            .map_init(&init, |s, b| {
                let c = origin + voxel * (brick_of(b) * BRICK + UVec3::splat(BRICK / 2)).as_vec3();
                let d = centre(s, c);
                if d.abs() > half_diagonal + band {
                    Brick::Skipped(d.signum() * (d.abs() - half_diagonal))
                } else {
                    Brick::Stored
                }
            })
            .collect(),
        None => (0..count).map(|_| Brick::Stored).collect(),
    };
    let candidates: Vec<u32> =
        (0..count as u32).filter(|&b| matches!(first[b as usize], Brick::Stored)).collect();
    let candidate_bytes = candidates.len() as u64 * (BRICK_SAMPLES as u64 * 2 + 16);
    if candidate_bytes > DEFAULT_MAX_GRID_BYTES {
        return Err(Error::Usage(format!(
            "a narrow-band grid of {} bricks near the surface would need more than {} MiB; \
             use a lower resolution",
            candidates.len(),
            DEFAULT_MAX_GRID_BYTES >> 20
        )));
    }
    // Pass 2: sample the candidates, quantize, and drop those farther than the band.
    let mut samples = vec![0u16; candidates.len() * BRICK_SAMPLES];
    let verdict: Vec<(Option<[f32; 2]>, f32)> = samples
        .par_chunks_mut(BRICK_SAMPLES)
        .zip(candidates.par_iter())
        .map_init(
            || (init(), vec![0f32; BRICK_SAMPLES]),
            |(s, buf), (out, &b)| {
                fill(s, brick_of(b as usize) * BRICK, buf);
                let (mut lo, mut hi, mut near) = (f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY);
                for &x in buf.iter() {
                    lo = lo.min(x);
                    hi = hi.max(x);
                    near = near.min(x.abs());
                }
                let slack = HALF_CELL_DIAGONAL * voxel;
                let one_sign = lo > 0.0 || hi < 0.0;
                if one_sign && near > band + slack && lo.is_finite() && hi.is_finite() {
                    return (None, lo.signum() * (near - slack));
                }
                let scale = if hi > lo { (hi - lo) / 65535.0 } else { 0.0 };
                let inv = if scale > 0.0 { 1.0 / scale } else { 0.0 };
                for (q, &x) in out.iter_mut().zip(buf.iter()) {
                    *q = ((x - lo) * inv).round().clamp(0.0, 65535.0) as u16;
                }
                (Some([lo, scale]), near)
            },
        )
        .collect();
    // Pass 3: pack.
    let mut slots = vec![NONE; count];
    let mut bounds: Vec<f32> =
        first.iter().map(|b| if let Brick::Skipped(x) = b { *x } else { 0.0 }).collect();
    let kept = verdict.iter().filter(|v| v.0.is_some()).count();
    let mut ranges = Vec::with_capacity(kept);
    let mut data = Vec::with_capacity(kept * BRICK_SAMPLES);
    for (n, (&b, (range, bound))) in candidates.iter().zip(&verdict).enumerate() {
        match range {
            Some(r) => {
                slots[b as usize] = ranges.len() as u32;
                ranges.push(*r);
                data.extend_from_slice(&samples[n * BRICK_SAMPLES..(n + 1) * BRICK_SAMPLES]);
            }
            None => bounds[b as usize] = *bound,
        }
    }
    Ok(BandGrid::from_parts(origin, voxel, dims, bricks, cells, slots, bounds, ranges, data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_band_matches_dense() {
        let f = |p: glam::DVec3| p.y - 0.3;
        let dense = super::super::sample_function(&f, Vec3::splat(-1.0), Vec3::ONE, 40, 2).unwrap();
        let band = band_from_function(&f, Vec3::splat(-1.0), Vec3::ONE, 40, 2, 2).unwrap();
        assert_eq!(band.dims, dense.dims);
        assert!(band.stored_bricks() < band.brick_count());
        for p in [Vec3::new(0.1, 0.31, -0.2), Vec3::new(-0.9, 0.25, 0.7)] {
            assert!((band.trilinear(p) - dense.trilinear(p)).abs() < 1e-4, "{p}");
        }
        for p in [Vec3::new(0.1, -0.9, -0.2), Vec3::new(-0.9, 1.0, 0.7), Vec3::new(0.0, 3.0, 0.0)] {
            let b = band.trilinear(p);
            let exact = (p.y - 0.3).abs();
            assert!(b.abs() <= exact + 1e-5 && b.signum() == (p.y - 0.3).signum(), "{p}: {b}");
        }
        assert!(BandGrid::from_dense(&dense, 0).is_err());
    }
}
