//! Narrow-band grid builders ([`BandGrid`], stored near the surface only): from a distance
//! function ([`band_from_function`]), from a mesh ([`band_from_mesh`], exact distances and
//! winding-number signs as [`super::sample_mesh`]) and from a dense grid
//! ([`BandGrid::from_dense`]), and the union of a scene's objects on one world lattice
//! ([`band_from_members`], the parts of a [`crate::geometry::grid::scene::SceneGrid`]), all through one brick classifier and quantizer (`build`;
//! see [`crate::geometry::grid::band`] for the storage and the tests that skip bricks).

use glam::{DVec3, UVec3, Vec3};
use rayon::prelude::*;

use super::MeshSampler;
use super::closest::TriangleBvh;
use super::winding::{self, FastWinding};
use crate::error::{Error, Result};
use crate::geometry::Aabb;
use crate::geometry::grid::band::{BRICK, BRICK_SAMPLES, BS, BandGrid, HALF_CELL_DIAGONAL, NONE};
use crate::geometry::grid::scene::BrickMaterial;
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

/// One object sampled into a scene's shared band ([`band_from_members`]).
pub struct BandMember<'a> {
    /// The object's world-space box: its surface lies inside.
    pub bounds: Aabb,
    /// Its signed distance, world space, 1-Lipschitz (exact or a lower bound).
    pub distance: &'a (dyn Fn(DVec3) -> f64 + Sync),
    /// Index of its material in the scene grid's materials.
    pub material: u16,
}

/// The band (`cells` cells wide) of the union of `members` on one world-space lattice with
/// cells of about `voxel` (the union box's longest axis gets `ceil(extent / voxel)` cells,
/// `margin_cells` more on every side, as [`grid_layout`] places them), with the material
/// of every stored brick ([`BrickMaterial`], in slot order): a
/// [`crate::geometry::grid::scene::SceneGrid`]'s parts.
///
/// Each brick evaluates only the members whose box lies within `R` = half the brick's
/// diagonal + the band + one brick edge of its centre; every other member is farther than
/// the band + one brick edge from all of its samples, so its samples are capped there
/// (`min(candidates, band + brick edge)`): a lower bound of the union's distance
/// everywhere, exact within the band.
///
/// # Errors
/// [`Error::Usage`] for no members, `cells == 0`, a `voxel` that is not positive and
/// finite, or a lattice too large (as [`band_from_function`]).
pub fn band_from_members(
    members: &[BandMember<'_>],
    voxel: f32,
    margin_cells: u32,
    cells: u32,
) -> Result<(BandGrid, Vec<BrickMaterial>)> {
    let Some(first) = members.first() else {
        return Err(Error::Usage("a scene grid needs at least one object".into()));
    };
    if !(voxel > 0.0 && voxel.is_finite()) {
        return Err(Error::Usage(format!("a scene grid needs a positive voxel size, not {voxel}")));
    }
    let union = members.iter().fold(first.bounds, |b, m| b.union(&m.bounds));
    let (lo, hi) = (Vec3::from(union.min), Vec3::from(union.max));
    let cells_long = ((hi - lo).max_element() as f64 / voxel as f64 - 1e-6).ceil().max(1.0);
    if cells_long > u32::MAX as f64 {
        return Err(Error::Usage(format!(
            "a scene grid with voxel {voxel} around {lo} .. {hi} is too large"
        )));
    }
    let (origin, voxel, dims) = grid_layout(lo, hi, cells_long as u32, margin_cells)?;
    let (bricks, count) = brick_lattice(dims, "scene grid")?;
    let count = count as u64;
    // The members each brick evaluates (compressed rows: `starts[b]..starts[b + 1]` of
    // `list`), from the bricks whose centres lie in a member's box grown by `reach`.
    let edge = BRICK as f32 * voxel;
    let cap = cells as f32 * voxel + edge;
    let reach = 0.5 * edge * 3f32.sqrt() + cap;
    let brick_range = |m: &BandMember<'_>| -> Option<(UVec3, UVec3)> {
        // Brick `b`'s centre is `origin + edge * (b + 0.5)`.
        let a = ((Vec3::from(m.bounds.min) - reach - origin) / edge - 0.5).ceil().max(Vec3::ZERO);
        let z = ((Vec3::from(m.bounds.max) + reach - origin) / edge - 0.5).floor();
        let top = (bricks - UVec3::ONE).as_vec3();
        let z = z.min(top);
        (a.cmple(z).all()).then(|| (a.as_uvec3(), z.as_uvec3()))
    };
    let index =
        |b: UVec3| b.x as usize + bricks.x as usize * (b.y as usize + bricks.y as usize * b.z as usize);
    let mut starts = vec![0u32; count as usize + 1];
    let mut total = 0u64;
    for m in members {
        if let Some((a, z)) = brick_range(m) {
            let n = (z - a + UVec3::ONE).as_u64vec3();
            total += n.x * n.y * n.z;
            for_bricks(a, z, |b| starts[index(b) + 1] += 1);
        }
    }
    if total * 4 > DEFAULT_MAX_GRID_BYTES {
        return Err(Error::Usage(
            "a scene grid's objects overlap too many bricks; use a lower resolution".into(),
        ));
    }
    for i in 0..count as usize {
        starts[i + 1] += starts[i];
    }
    let mut fill_at = starts.clone();
    let mut list = vec![0u32; total as usize];
    for (k, m) in members.iter().enumerate() {
        if let Some((a, z)) = brick_range(m) {
            for_bricks(a, z, |b| {
                let i = index(b);
                list[fill_at[i] as usize] = k as u32;
                fill_at[i] += 1;
            });
        }
    }
    drop(fill_at);
    let near = |b: UVec3| &list[starts[index(b)] as usize..starts[index(b) + 1] as usize];
    let union_at = |b: UVec3, p: DVec3| -> f32 {
        near(b).iter().fold(cap, |v, &k| v.min((members[k as usize].distance)(p) as f32))
    };
    let (o, v) = (origin.as_dvec3(), voxel as f64);
    let band = build(
        origin,
        voxel,
        dims,
        cells,
        || (),
        Some(|_: &mut (), c: Vec3| {
            let b = ((c - origin) / edge).floor().max(Vec3::ZERO).as_uvec3().min(bricks - UVec3::ONE);
            union_at(b, c.as_dvec3())
        }),
        |_, first, out| {
            let b = first / BRICK;
            for c in 0..BS as u32 {
                for bb in 0..BS as u32 {
                    for a in 0..BS as u32 {
                        let s = (first + UVec3::new(a, bb, c)).as_dvec3();
                        out[a as usize + BS * (bb as usize + BS * c as usize)] = union_at(b, o + s * v);
                    }
                }
            }
        },
    )?;
    // Materials of the stored bricks, in slot order: one where every nearby member has the
    // same, else the nearest member's per sample.
    let stored: Vec<(usize, UVec3)> = (0..count as usize)
        .filter_map(|i| {
            let b = UVec3::new(
                (i % bricks.x as usize) as u32,
                ((i / bricks.x as usize) % bricks.y as usize) as u32,
                (i / (bricks.x as usize * bricks.y as usize)) as u32,
            );
            band.slot(b).map(|s| (s, b))
        })
        .collect();
    let mut materials: Vec<(usize, BrickMaterial)> = stored
        .par_iter()
        .map(|&(slot, b)| {
            let ks = near(b);
            let m0 = ks.first().map_or(first.material, |&k| members[k as usize].material);
            if ks.iter().all(|&k| members[k as usize].material == m0) {
                return (slot, BrickMaterial::One(m0));
            }
            // The nearest member's material at every sample; only samples within the band
            // (plus half a cell diagonal) of the surface can be hit points' nearest.
            let first = b * BRICK;
            let mut table = vec![m0; BRICK_SAMPLES];
            let mut near_surface = vec![false; BRICK_SAMPLES];
            let limit = (cells as f32 + 2.0 * HALF_CELL_DIAGONAL) as f64 * v;
            for c in 0..BS as u32 {
                for bb in 0..BS as u32 {
                    for a in 0..BS as u32 {
                        let p = o + (first + UVec3::new(a, bb, c)).as_dvec3() * v;
                        let (mut best, mut m) = (f64::INFINITY, m0);
                        for &k in ks {
                            let d = (members[k as usize].distance)(p);
                            if d < best {
                                (best, m) = (d, members[k as usize].material);
                            }
                        }
                        let s = a as usize + BS * (bb as usize + BS * c as usize);
                        table[s] = m;
                        near_surface[s] = best.abs() <= limit;
                    }
                }
            }
            (slot, BrickMaterial::compact(&table, &near_surface))
        })
        .collect();
    materials.sort_unstable_by_key(|(s, _)| *s);
    Ok((band, materials.into_iter().map(|(_, m)| m).collect()))
}

/// Bricks per axis of a lattice of `dims` samples, and their number, checked against
/// [`DEFAULT_MAX_GRID_BYTES`] at 8 bytes per brick (its slot and bound).
///
/// # Errors
/// [`Error::Usage`] naming `what` when the bricks alone would pass the limit.
fn brick_lattice(dims: UVec3, what: &str) -> Result<(UVec3, usize)> {
    let bricks = (dims - UVec3::ONE + UVec3::splat(BRICK - 1)) / BRICK;
    let count = bricks.x as u64 * bricks.y as u64 * bricks.z as u64;
    if count * 8 > DEFAULT_MAX_GRID_BYTES {
        return Err(Error::Usage(format!(
            "a {what} of {}x{}x{} bricks is too large; use a lower resolution",
            bricks.x, bricks.y, bricks.z
        )));
    }
    Ok((bricks, count as usize))
}

/// Calls `f` for every brick of the inclusive range `a..=z`.
fn for_bricks(a: UVec3, z: UVec3, mut f: impl FnMut(UVec3)) {
    for k in a.z..=z.z {
        for j in a.y..=z.y {
            for i in a.x..=z.x {
                f(UVec3::new(i, j, k));
            }
        }
    }
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
    let (bricks, count) = brick_lattice(dims, "narrow-band grid")?;
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
