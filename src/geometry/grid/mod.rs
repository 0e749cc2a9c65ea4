//! Discrete signed distance grids, and sampling a triangle mesh into one.
//!
//! An [`SdfGrid`] stores signed distances (negative inside) at the CORNERS of a regular
//! grid of cubic cells: sample `(i, j, k)` sits at `origin + voxel * (i, j, k)`, so a grid
//! of `dims` samples spans `dims - 1` cells per axis and its box is
//! `[origin, origin + voxel * (dims - 1)]`. Between samples [`SdfGrid::trilinear`]
//! interpolates.
//!
//! [`sample_mesh`] fills a grid from a [`TriangleMesh`]: the exact unsigned distance to
//! the nearest triangle ([`closest`], a BVH closest-point query started from the previous
//! sample's nearest triangle and bounded by its distance plus the step) times the sign
//! from the generalized winding number ([`winding`]; inside where it is `>= 0.5`). The
//! winding number only decides the sign; it never scales the distance. This works for open
//! meshes and soups too (the sign then follows the winding number's `0.5` level set).
//!
//! Signs are found by regions (`fill_by_regions`): the mesh's holes are closed by cap
//! triangles ([`winding::Caps`]), neighbouring samples whose connecting segment provably
//! misses the mesh and the caps are linked, and the (integer) winding number of the capped
//! mesh is evaluated once per linked component; each sample's winding number is that
//! integer minus the caps' exact winding number. Meshes with very many holes (soups) reuse
//! winding numbers along the scan instead (`fill`). Z-slices are filled in parallel with
//! rayon, each in serpentine order; when signing by regions, the distances of each 2x4
//! block (x by y) of a slice come from one group walk ([`TriangleBvh::nearest_group`]),
//! each sample hinted by its nearest sample in the previous block.

pub mod band;
pub mod closest;
pub mod io;
pub mod object;
pub mod voxelize;
pub mod winding;

use std::time::{Duration, Instant};

use glam::{UVec3, Vec3, Vec3A};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::mesh::TriangleMesh;

use closest::{GroupStack, NodeStack, TriangleBvh};
use winding::{Caps, FastWinding};

/// The default limit on a grid's sample memory (8 GiB) used by [`SdfGrid::for_bounds`]
/// and [`sample_mesh`].
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
    /// (the surface then crosses the box boundary, which [`sample_mesh`]'s margin
    /// avoids). Both are continuous across the box boundary and 1-Lipschitz in `d`.
    pub fn trilinear(&self, p: Vec3) -> f32 {
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

/// Work done by [`sample_mesh_with_stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SampleStats {
    /// Samples computed.
    pub samples: u64,
    /// BVH nodes whose boxes the closest-point queries tested.
    pub closest_nodes: u64,
    /// Nodes the winding-number queries visited.
    pub winding_nodes: u64,
    /// Samples whose winding number was evaluated (the others reused a neighbour's sign).
    pub winding_evaluations: u64,
    /// Whether the mesh is closed and consistently oriented ([`winding::is_closed`]).
    pub closed: bool,
    /// Time spent building the BVH and the winding-number node data.
    pub build_time: Duration,
    /// Time spent filling the grid.
    pub fill_time: Duration,
}

/// Samples `mesh`'s signed distance on a grid with `res` cells along the longest axis of
/// its bounding box and `margin_cells` extra cells on every side (see
/// [`SdfGrid::for_bounds`]). Parallel over z-slices.
///
/// # Errors
/// [`Error::Usage`] for a mesh without triangles, `res == 0`, or a grid larger than
/// [`DEFAULT_MAX_GRID_BYTES`] (checked before anything is allocated or built).
pub fn sample_mesh(mesh: &TriangleMesh, res: u32, margin_cells: u32) -> Result<SdfGrid> {
    sample_mesh_with_stats(mesh, res, margin_cells).map(|(g, _)| g)
}

/// [`sample_mesh`], also returning the work counters and timings.
///
/// # Errors
/// As [`sample_mesh`].
pub fn sample_mesh_with_stats(
    mesh: &TriangleMesh,
    res: u32,
    margin_cells: u32,
) -> Result<(SdfGrid, SampleStats)> {
    let Some((lo, hi)) = mesh.bounds().filter(|_| !mesh.triangles.is_empty()) else {
        return Err(Error::Usage("cannot sample the distance field of a mesh without triangles".into()));
    };
    let mut grid = SdfGrid::for_bounds(lo, hi, res, margin_cells)?;
    let start = Instant::now();
    let tree = TriangleBvh::new(mesh);
    let wind = FastWinding::new(&tree);
    let build_time = start.elapsed();
    let start = Instant::now();
    let closed = winding::is_closed(mesh);
    let caps = Caps::new(mesh);
    let stats = if caps.triangles.len() <= MAX_CAP_TRIANGLES {
        fill_by_regions(&mut grid, &tree, &wind, &caps)
    } else {
        fill(&mut grid, &tree, &wind, closed)
    };
    Ok((grid, SampleStats { build_time, fill_time: start.elapsed(), closed, ..stats }))
}

/// A sample reuses the sign of an evaluated sample (its anchor) only when the anchor's
/// winding number is at least this far from `0.5`.
const REUSE_MARGIN: f32 = 0.4;

/// Fills every sample of `grid` with the signed distance to `tree`'s triangles.
///
/// Signs are reused along the (serpentine) scan: a sample closer to the last sample whose
/// winding number `w` was evaluated (the anchor) than `reuse` times the anchor's distance
/// `d` takes the anchor's side when `|w - 0.5| >= REUSE_MARGIN`. The segment between them
/// lies in the empty ball of radius `d`, where the winding number is harmonic. For a
/// closed mesh it is constant there, so `reuse` is just below 1 and exact. For an open
/// mesh the harmonic gradient estimate `|∇w| <= 3 sup|w - 0.5| / r` bounds the change
/// over `d / 8` by `3 M ln(8/7) ≈ 0.4 M`, which stays below the margin (less the fast
/// evaluation's error) as long as `M = sup|w - 0.5| <= 0.75`, i.e. the winding number
/// stays within `[-0.25, 1.25]` near the sample, which holds for surfaces that do not
/// overlap themselves.
fn fill(grid: &mut SdfGrid, tree: &TriangleBvh, wind: &FastWinding, closed: bool) -> SampleStats {
    let (nx, ny) = (grid.dims.x, grid.dims.y);
    let slice = nx as usize * ny as usize;
    let (origin, voxel) = (grid.origin, grid.voxel);
    grid.values
        .par_chunks_mut(slice)
        .enumerate()
        .map(|(k, out)| {
            let mut sampler = MeshSampler::new(tree, wind, closed);
            for j in 0..ny {
                // Serpentine order keeps consecutive samples adjacent.
                for step in 0..nx {
                    let i = if j % 2 == 0 { step } else { nx - 1 - step };
                    let p = origin + voxel * Vec3::new(i as f32, j as f32, k as f32);
                    out[i as usize + nx as usize * j as usize] = sampler.sample(p);
                }
            }
            crate::cli::progress::advance(1);
            sampler.stats
        })
        .reduce(SampleStats::default, |a, b| SampleStats {
            samples: a.samples + b.samples,
            closest_nodes: a.closest_nodes + b.closest_nodes,
            winding_nodes: a.winding_nodes + b.winding_nodes,
            winding_evaluations: a.winding_evaluations + b.winding_evaluations,
            ..SampleStats::default()
        })
}

/// Meshes whose holes need more cap triangles than this are signed by [`fill`]'s reuse of
/// winding numbers instead of [`fill_by_regions`].
const MAX_CAP_TRIANGLES: usize = 4096;

/// Sums the work counters of two partial results.
fn add_stats(a: SampleStats, b: SampleStats) -> SampleStats {
    SampleStats {
        samples: a.samples + b.samples,
        closest_nodes: a.closest_nodes + b.closest_nodes,
        winding_nodes: a.winding_nodes + b.winding_nodes,
        winding_evaluations: a.winding_evaluations + b.winding_evaluations,
        ..SampleStats::default()
    }
}

/// Fills every sample of `grid` with the signed distance to `tree`'s triangles, signing
/// by regions (exact up to the winding number of one point per region):
///
/// 1. Unsigned distances, z-slices in parallel, each in serpentine order.
/// 2. Two neighbouring samples `p`, `q` are linked when the segment between them cannot
///    meet the mesh or its `caps` ([`Caps`]): when the lower bounds of their distances to
///    both sum to more than `|p - q|` (a point of the segment on the surface would be
///    closer to one of them), or else when an exact, conservative segment test
///    ([`TriangleBvh::axis_segment_may_meet`]) finds no triangle near it.
/// 3. The winding number `W` of the mesh with its caps is an integer, constant off both
///    in every connected region (the caps close the mesh as a chain), so it is the same
///    at all samples of a linked component: it is evaluated once per component, at its
///    sample farthest from the mesh, as the fast winding number of the mesh plus the caps'
///    exact one, rounded (a component where that sum is not within `0.25` of an integer
///    falls back to evaluating every sample's fast winding number).
/// 4. Each sample's winding number is `W - w_caps` (exact): inside where it is `>= 0.5`.
///    Away from the holes `|w_caps| < 0.5` is certain from a bound, and then the sample is
///    inside iff `W >= 1`.
///
/// For a closed mesh there are no caps and the signs are those of `W` per component.
fn fill_by_regions(grid: &mut SdfGrid, tree: &TriangleBvh, wind: &FastWinding, caps: &Caps) -> SampleStats {
    let (nx, ny, nz) = (grid.dims.x as usize, grid.dims.y as usize, grid.dims.z as usize);
    let slice = nx * ny;
    let n = slice * nz;
    let (origin, voxel) = (grid.origin, grid.voxel);
    let position =
        move |i: usize, j: usize, k: usize| origin + voxel * Vec3::new(i as f32, j as f32, k as f32);

    // 1. Unsigned distances, 2x4 blocks of samples at once (see `unsigned_slice`).
    let mut stats = grid
        .values
        .par_chunks_mut(slice)
        .enumerate()
        .map_init(GroupStack::default, |stack, (k, out)| {
            let mut stats = unsigned_slice(tree, out, nx, ny, |i, j| position(i, j, k), stack);
            crate::cli::progress::advance(1);
            stats.samples = slice as u64;
            stats
        })
        .reduce(SampleStats::default, add_stats);

    // 2. Links: bit `a` of `links[s]` links sample `s` to its neighbour along axis `a`.
    let dist = &grid.values;
    // The largest distance between neighbouring samples (rounding of the positions).
    let extent = origin.abs().max(origin.abs() + voxel * grid.dims.as_vec3()).max_element();
    let step = voxel * (1.0 + 1e-3) + 8.0 * f32::EPSILON * extent;
    let eps = 1e-4 * voxel + 8.0 * f32::EPSILON * extent;
    // Lower bound on the distance to the mesh and the caps (shrunk for rounding).
    let lower = |s: usize, p: Vec3A| (dist[s] * (1.0 - 1e-5)).min(caps.lower_distance(p, step));
    let mut links = vec![0u8; n];
    links.par_chunks_mut(slice).enumerate().for_each_init(
        || Vec::with_capacity(64),
        |stack, (k, out)| {
            for j in 0..ny {
                for i in 0..nx {
                    let s = i + nx * j + slice * k;
                    let p = Vec3A::from(position(i, j, k));
                    let dp = lower(s, p);
                    let mut bits = 0u8;
                    for (axis, ok, stride) in
                        [(0, i + 1 < nx, 1), (1, j + 1 < ny, nx), (2, k + 1 < nz, slice)]
                    {
                        if !ok {
                            continue;
                        }
                        let q = Vec3A::from(position(
                            i + (axis == 0) as usize,
                            j + (axis == 1) as usize,
                            k + (axis == 2) as usize,
                        ));
                        let linked = dp + lower(s + stride, q) > step || {
                            let end = q[axis];
                            !tree.axis_segment_may_meet(p, axis, end, eps, stack)
                                && !caps.axis_segment_may_meet(p, axis, end, eps)
                        };
                        bits |= (linked as u8) << axis;
                    }
                    out[i + nx * j] = bits;
                }
            }
        },
    );

    // Union-find with `parent[s] <= s` (roots are their components' smallest samples).
    fn find(parent: &mut [u32], base: usize, mut x: usize) -> usize {
        loop {
            let p = parent[x - base] as usize;
            if p == x {
                return x;
            }
            let gp = parent[p - base];
            parent[x - base] = gp;
            x = gp as usize;
        }
    }
    fn union(parent: &mut [u32], base: usize, a: usize, b: usize) {
        let (ra, rb) = (find(parent, base, a), find(parent, base, b));
        if ra != rb {
            parent[ra.max(rb) - base] = ra.min(rb) as u32;
        }
    }
    let mut parent: Vec<u32> = (0..n as u32).collect();
    parent.par_chunks_mut(slice).zip(links.par_chunks(slice)).enumerate().for_each(|(k, (par, l))| {
        let base = k * slice;
        for (s, &bits) in l.iter().enumerate() {
            if bits & 1 != 0 {
                union(par, base, base + s, base + s + 1);
            }
            if bits & 2 != 0 {
                union(par, base, base + s, base + s + nx);
            }
        }
    });
    for (s, &bits) in links[..n.saturating_sub(slice)].iter().enumerate() {
        if bits & 4 != 0 {
            union(&mut parent, 0, s, s + slice);
        }
    }
    drop(links);
    // Roots, and per root the sample farthest from the mesh.
    let mut far: Vec<u32> = vec![u32::MAX; n];
    for s in 0..n {
        let r = parent[parent[s] as usize];
        parent[s] = r;
        let f = &mut far[r as usize];
        if *f == u32::MAX || dist[s] > dist[*f as usize] {
            *f = s as u32;
        }
    }

    // 3. W per component.
    const FALLBACK: i32 = i32::MIN;
    let coords = |s: usize| (s % nx, (s / nx) % ny, s / slice);
    let roots: Vec<u32> = (0..n as u32).filter(|&s| parent[s as usize] == s).collect();
    let evaluated: Vec<(u32, i32, u64)> = roots
        .par_iter()
        .map_init(
            || Vec::with_capacity(256),
            |stack, &r| {
                let (i, j, k) = coords(far[r as usize] as usize);
                let p = position(i, j, k);
                let mut nodes = 0;
                let w =
                    wind.winding_for_sign(tree, p, stack, &mut nodes) + caps.winding_number(Vec3A::from(p));
                let whole = w.round();
                (r, if (w - whole).abs() <= 0.25 { whole as i32 } else { FALLBACK }, nodes)
            },
        )
        .collect();
    drop(far);
    let mut component = vec![0i32; n];
    for &(r, w, nodes) in &evaluated {
        component[r as usize] = w;
        stats.winding_nodes += nodes;
        stats.winding_evaluations += 1;
    }

    // 4. Signs.
    let extra = grid
        .values
        .par_chunks_mut(slice)
        .enumerate()
        .map_init(
            || Vec::with_capacity(256),
            |stack, (k, out)| {
                let mut extra = SampleStats::default();
                for j in 0..ny {
                    for i in 0..nx {
                        let s = i + nx * j;
                        let w = component[parent[s + slice * k] as usize];
                        let p = position(i, j, k);
                        let inside = if w == FALLBACK {
                            extra.winding_evaluations += 1;
                            wind.winding_for_sign(tree, p, stack, &mut extra.winding_nodes) >= winding::INSIDE
                        } else if caps.is_empty() || caps.winding_bound(Vec3A::from(p)) < 0.49 {
                            w >= 1
                        } else {
                            w as f32 - caps.winding_number(Vec3A::from(p)) >= winding::INSIDE
                        };
                        if inside {
                            out[s] = -out[s];
                        }
                    }
                }
                extra
            },
        )
        .reduce(SampleStats::default, add_stats);
    stats.winding_nodes += extra.winding_nodes;
    stats.winding_evaluations += extra.winding_evaluations;
    stats
}

/// Fills `out` (an `nx` by `ny` slice of samples, x fastest, at `position(i, j)`) with the
/// unsigned distances to `tree`'s triangles: blocks of `BLOCK_W` by `BLOCK_H` samples go to
/// [`TriangleBvh::nearest_group`] together, in serpentine order over the rows of blocks,
/// each sample hinted by the nearest triangle of its nearest sample in the previous block
/// (the adjacent column or row). Returns the work counters.
fn unsigned_slice(
    tree: &TriangleBvh,
    out: &mut [f32],
    nx: usize,
    ny: usize,
    position: impl Fn(usize, usize) -> Vec3,
    stack: &mut GroupStack,
) -> SampleStats {
    let mut stats = SampleStats::default();
    // The nearest triangles (slots) of the previous block's samples, by place in the block.
    let mut last: [[Option<u32>; BLOCK_W]; BLOCK_H] = [[None; BLOCK_W]; BLOCK_H];
    let mut hints = [None; BLOCK_W * BLOCK_H];
    let mut near = [None; BLOCK_W * BLOCK_H];
    let (cols, rows) = (nx.div_ceil(BLOCK_W), ny.div_ceil(BLOCK_H));
    for row in 0..rows {
        for step in 0..cols {
            let col = if row % 2 == 0 { step } else { cols - 1 - step };
            // The block's samples (the last rows or columns may have fewer).
            let mut at = [(0, 0); BLOCK_W * BLOCK_H];
            let mut points = [Vec3::ZERO; BLOCK_W * BLOCK_H];
            let mut g = 0;
            for dj in 0..BLOCK_H {
                for di in 0..BLOCK_W {
                    let (i, j) = (BLOCK_W * col + di, BLOCK_H * row + dj);
                    if i < nx && j < ny {
                        // The previous block is above (a new row of blocks), or to the
                        // left or right (odd rows of blocks run right to left).
                        let (pi, pj) = match (step, row % 2) {
                            (0, _) => (di, BLOCK_H - 1),
                            (_, 0) => (BLOCK_W - 1, dj),
                            _ => (0, dj),
                        };
                        at[g] = (di, dj);
                        hints[g] = last[pj][pi].or(last[dj][di]);
                        points[g] = position(i, j);
                        g += 1;
                    }
                }
            }
            tree.nearest_group(&points[..g], &hints[..g], &mut near[..g], stack, &mut stats.closest_nodes);
            for (&(di, dj), n) in at[..g].iter().zip(&near[..g]) {
                let (i, j) = (BLOCK_W * col + di, BLOCK_H * row + dj);
                out[i + nx * j] = n.map_or(f32::INFINITY, |n| {
                    last[dj][di] = Some(n.slot);
                    n.dist2.sqrt()
                });
            }
        }
    }
    stats
}

/// The blocks of samples [`unsigned_slice`] answers with one group walk: `BLOCK_W` by
/// `BLOCK_H` (x by y). Eight points fill the group walk's AVX2 pairs; 2x4 needed a few
/// percent less CPU time than 4x2 on the benchmark meshes (both less than 2x2).
const BLOCK_W: usize = 2;
const BLOCK_H: usize = 4;
const _: () = assert!(BLOCK_W * BLOCK_H <= closest::GROUP_MAX);

/// Signed distance queries against a mesh for a sequence of nearby points (one per
/// thread): each query is bounded by and started from the previous one's nearest
/// triangle, and reuses the sign of the last evaluated winding number where that is safe
/// (see `fill`). Consecutive points should be close (e.g. a serpentine scan).
pub struct MeshSampler<'a> {
    tree: &'a TriangleBvh,
    wind: &'a FastWinding,
    reuse: f32,
    stack: NodeStack,
    wstack: Vec<u32>,
    // (position, unsigned distance, nearest triangle's slot) of the previous sample.
    prev: Option<(Vec3, f32, u32)>,
    // (position, unsigned distance, winding number) of the last evaluated sample.
    anchor: Option<(Vec3, f32, f32)>,
    /// Work done so far.
    pub stats: SampleStats,
}

impl<'a> MeshSampler<'a> {
    /// A sampler over `tree` (which must have triangles) and its winding data; `closed`
    /// is [`winding::is_closed`] of the mesh (it decides how far signs may be reused).
    pub fn new(tree: &'a TriangleBvh, wind: &'a FastWinding, closed: bool) -> Self {
        MeshSampler {
            tree,
            wind,
            reuse: if closed { 0.99 } else { 0.125 },
            stack: NodeStack::with_capacity(128),
            wstack: Vec::with_capacity(256),
            prev: None,
            anchor: None,
            stats: SampleStats::default(),
        }
    }

    /// The unsigned distance from `p` to the mesh (no sign), using the previous query as a
    /// bound and hint; `f32::INFINITY` for a mesh without triangles.
    pub fn unsigned(&mut self, p: Vec3) -> f32 {
        let (hint, bound) = match self.prev {
            // Distance is 1-Lipschitz; pad for rounding.
            Some((q, d, slot)) => (Some(slot), (d + (p - q).length()) * (1.0 + 1e-5) + 1e-30),
            None => (None, f32::INFINITY),
        };
        let tree = self.tree;
        let near = tree
            .nearest_with_hint(p, hint, bound, &mut self.stack, &mut self.stats.closest_nodes)
            .or_else(|| tree.nearest(p, f32::INFINITY, &mut self.stack, &mut self.stats.closest_nodes));
        let Some(near) = near else { return f32::INFINITY };
        let d = near.dist2.sqrt();
        self.prev = Some((p, d, near.slot));
        d
    }

    /// The signed distance at `p` (negative inside).
    pub fn sample(&mut self, p: Vec3) -> f32 {
        let d = self.unsigned(p);
        self.stats.samples += 1;
        // The sign of the last directly evaluated sample holds within `reuse` times its
        // distance (see `fill`'s documentation).
        let inside = match self.anchor {
            Some((a, da, wa))
                if (wa - winding::INSIDE).abs() >= REUSE_MARGIN && (p - a).length() < da * self.reuse =>
            {
                wa >= winding::INSIDE
            }
            _ => {
                let w =
                    self.wind.winding_for_sign(self.tree, p, &mut self.wstack, &mut self.stats.winding_nodes);
                self.stats.winding_evaluations += 1;
                self.anchor = Some((p, d, w));
                w >= winding::INSIDE
            }
        };
        if inside { -d } else { d }
    }
}

/// Samples the distance function `f` (world space) on a grid of `res` cells along the
/// longest axis of the box `lo`..`hi`, padded by `margin_cells`, in parallel over z-slices.
///
/// # Errors
/// As [`SdfGrid::for_bounds`].
pub fn sample_function(
    f: &(impl Fn(glam::DVec3) -> f64 + Sync),
    lo: Vec3,
    hi: Vec3,
    res: u32,
    margin_cells: u32,
) -> Result<SdfGrid> {
    use rayon::prelude::*;
    let mut grid = SdfGrid::for_bounds(lo, hi, res, margin_cells)?;
    let (nx, ny) = (grid.dims.x as usize, grid.dims.y as usize);
    let (origin, voxel) = (grid.origin.as_dvec3(), grid.voxel as f64);
    grid.values.par_chunks_mut(nx * ny).enumerate().for_each(|(k, slice)| {
        for j in 0..ny {
            for i in 0..nx {
                let p = origin + glam::DVec3::new(i as f64, j as f64, k as f64) * voxel;
                slice[j * nx + i] = f(p) as f32;
            }
        }
    });
    Ok(grid)
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
