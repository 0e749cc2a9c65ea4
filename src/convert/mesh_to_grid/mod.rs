//! Mesh (and distance function) -> signed distance grid: filling an
//! [`SdfGrid`] or a narrow-band
//! [`BandGrid`](crate::geometry::grid::band::BandGrid) ([`band`]) from a triangle mesh,
//! by exact sampling or by voxelizing ([`voxelize`]), or from a distance function
//! ([`sample_function`]).
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
//!
//! The sign rule, for every mesh: a sample is inside (negative) iff the generalized winding
//! number `w` of the mesh's triangles at it is `>= 0.5`. How exactly `w` is known depends
//! on the path: by regions (at most `MAX_CAP_TRIANGLES` = 4096 boundary edges), `w` is the
//! integer `W` less the caps' exact winding number, so the sign is exact up to `f32`
//! rounding of the caps' sum; with more boundary edges (soups, very broken scans) it is
//! [`FastWinding::winding_for_sign`] (error about `1e-3` near `0.5`) and reused signs, so
//! samples with `|w - 0.5|` below about `1e-3` may take either side. Measured against a
//! brute-force `f64` winding number at 64^3 on every sample farther than one voxel from
//! the surface (`tests/integration/winding_sign.rs`, `full_disagreement_at_64`): none of
//! 97094 differ on camelhead (one hole) nor of 242316 on the Stanford bunny (holes in the
//! base); 1 of 97102 on camelhead without every 8th triangle (8412 boundary edges) and 2
//! of 97094 on camelhead as a soup, all three within `4e-4` of `0.5`.

pub mod band;
pub mod closest;
pub mod voxelize;
pub mod winding;

use std::time::{Duration, Instant};

use glam::{Vec3, Vec3A};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::grid::SdfGrid;
use crate::mesh::TriangleMesh;

use closest::{GroupStack, NodeStack, TriangleBvh};
use winding::{Caps, FastWinding};

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
/// [`DEFAULT_MAX_GRID_BYTES`](crate::geometry::grid::DEFAULT_MAX_GRID_BYTES) (checked before
/// anything is allocated or built).
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
            crate::base::progress::advance(1);
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
            crate::base::progress::advance(1);
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
