//! Mesh -> SDF grid by voxelization: a fast, voxel-accurate alternative to
//! [`super::sample_mesh`]'s exact distances.
//!
//! The grid has the same layout and placement as [`super::sample_mesh`]'s (see
//! [`SdfGrid::for_bounds`]). Each sample `(i, j, k)` owns the cubic voxel of edge `voxel`
//! centred on it (the dual cell). The algorithm:
//!
//! 1. **Conservative rasterization**: every triangle marks each voxel it overlaps (the
//!    exact triangle/box separating-axis test of Akenine-Möller, on a box inflated by a
//!    tiny relative epsilon), in parallel over triangles. These are the *surface voxels*;
//!    they form a 6-separating shell around the solid, so holes narrower than a voxel are
//!    closed.
//! 2. **Flood fill** (6-connected) from every non-surface voxel on the grid's boundary
//!    through non-surface voxels: the *exterior*. The rest (neither surface nor exterior)
//!    is the *interior*.
//! 3. **Exact Euclidean distance transform** (Felzenszwalb & Huttenlocher's separable
//!    lower envelope of parabolas, one pass per axis, parallel over lines with rayon):
//!    the distance from every sample to the nearest surface voxel centre.
//! 4. The value is that distance, negative for interior samples; surface samples are 0.
//!
//! **Accuracy**: the true surface passes through every surface voxel and every surface
//! point lies in one, so the stored distance differs from the exact unsigned distance by
//! at most half a voxel diagonal (`0.87 voxel`), and the zero level set is the shell of
//! surface voxels (about one voxel thick) rather than the surface itself: expect errors
//! of about one voxel near the surface, against [`super::sample_mesh`]'s exact distances
//! (only the trilinear interpolation's error). In exchange it needs no distance queries,
//! no winding numbers and no BVH, and its cost is linear in the voxel count.
//!
//! **Open meshes**: a hole wider than a voxel lets the flood fill leak into the inside,
//! which then comes out (partly) outside: wrong signs, errors of many voxels. A mesh whose
//! every edge is shared by an even number of triangles has no hole (it separates space);
//! for any other mesh, [`voxelize_mesh`] also rasterizes caps over its holes (a fan from
//! the centroid of each loop of boundary edges, which makes the mesh closed) into a second
//! label grid and floods that too. The caps block every path through a hole, so a voxel
//! that the plain fill reaches and the capped one does not (and that no triangle or cap
//! touches) was reached through a hole: the fill leaked, and voxelizing refuses with an
//! error that says so and suggests exact sampling. Holes that the rasterized shell closes
//! anyway (narrower than a voxel) leak nothing and pass. A mesh with no inside at all at
//! this resolution (thinner than a voxel) is refused too.

use std::sync::atomic::{AtomicU8, Ordering};

use glam::{UVec3, Vec3};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::grid::{DEFAULT_MAX_GRID_BYTES, SdfGrid};
use crate::mesh::TriangleMesh;

/// The limit on the grid's own `f32` samples when voxelizing: voxelizing holds about 13
/// bytes per sample (the grid, two distance-transform buffers, the voxel labels), so this
/// is 4/13 of [`DEFAULT_MAX_GRID_BYTES`] to keep the total within it.
pub const MAX_VOXELIZE_GRID_BYTES: u64 = DEFAULT_MAX_GRID_BYTES / 13 * 4;

const SURFACE: u8 = 1;
const EXTERIOR: u8 = 2;

/// Counters and timings of [`voxelize_mesh_with_stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VoxelizeStats {
    /// Surface voxels (samples whose voxel a triangle overlaps).
    pub surface: u64,
    /// Exterior voxels reached by the flood fill.
    pub exterior: u64,
    /// Interior voxels (the rest).
    pub interior: u64,
    /// Voxels that the flood fill reached through a hole (0: it did not leak; then the
    /// mesh is voxelized).
    pub leaked: u64,
    /// Seconds spent rasterizing the triangles.
    pub raster_s: f64,
    /// Seconds spent in the flood fill.
    pub flood_s: f64,
    /// Seconds spent in the distance transform and writing the values.
    pub edt_s: f64,
}

/// Voxelizes `mesh` into a signed distance grid with `res` cells along the longest axis of
/// its bounding box and `margin_cells` extra cells on every side (the same layout as
/// [`super::sample_mesh`]); see the module documentation for the algorithm and its
/// accuracy (about one voxel).
///
/// # Errors
/// [`Error::Usage`] for a mesh without triangles, `res == 0`, a grid that is too large,
/// or a mesh with no inside at this resolution (open, so that the flood fill leaks, or
/// thinner than a voxel everywhere).
pub fn voxelize_mesh(mesh: &TriangleMesh, res: u32, margin_cells: u32) -> Result<SdfGrid> {
    voxelize_mesh_with_stats(mesh, res, margin_cells).map(|(g, _)| g)
}

/// [`voxelize_mesh`], also returning counts and timings.
///
/// # Errors
/// As [`voxelize_mesh`].
pub fn voxelize_mesh_with_stats(
    mesh: &TriangleMesh,
    res: u32,
    margin_cells: u32,
) -> Result<(SdfGrid, VoxelizeStats)> {
    let Some((lo, hi)) = mesh.bounds().filter(|_| !mesh.triangles.is_empty()) else {
        return Err(Error::Usage("cannot voxelize a mesh without triangles".into()));
    };
    let mut grid = SdfGrid::for_bounds_with_limit(lo, hi, res, margin_cells, MAX_VOXELIZE_GRID_BYTES)?;
    let mut stats = VoxelizeStats::default();
    let t = std::time::Instant::now();
    let mut state =
        rasterize(&grid, mesh.triangles.len(), |t| mesh.triangles[t].map(|i| mesh.positions[i as usize]));
    // The holes' caps, rasterized into a copy of the labels (none for a mesh without holes).
    let boundary = mesh.odd_edges();
    let mut capped = (!boundary.is_empty()).then(|| {
        let caps = hole_caps(mesh, &boundary);
        let marks = rasterize(&grid, caps.len(), |t| caps[t]);
        state.iter().zip(marks).map(|(&a, b)| a | b).collect::<Vec<u8>>()
    });
    stats.raster_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    flood_exterior(&mut state, grid.dims);
    if let Some(capped) = capped.as_mut() {
        flood_exterior(capped, grid.dims);
        stats.leaked =
            state.iter().zip(capped.iter()).filter(|&(&a, &b)| a == EXTERIOR && b == 0).count() as u64;
    }
    stats.flood_s = t.elapsed().as_secs_f64();
    if stats.leaked > 0 {
        return Err(Error::Usage(format!(
            "voxelizing at resolution {res} leaks: the mesh is open ({} boundary edges) and the flood fill \
             from outside reached {} voxels inside through a hole wider than a voxel; use exact sampling \
             (--fill sample), which signs open meshes by their winding number",
            boundary.len(),
            stats.leaked
        )));
    }
    for &s in &state {
        match s {
            SURFACE => stats.surface += 1,
            EXTERIOR => stats.exterior += 1,
            _ => stats.interior += 1,
        }
    }
    if stats.interior == 0 {
        return Err(Error::Usage(format!(
            "voxelizing found no inside at resolution {res}: the mesh is open (the flood fill leaked \
             through a hole wider than a voxel) or thinner than a voxel; use exact sampling \
             (--fill sample), which signs open meshes by their winding number"
        )));
    }
    let t = std::time::Instant::now();
    signed_distance_transform(&state, &mut grid);
    stats.edt_s = t.elapsed().as_secs_f64();
    Ok((grid, stats))
}

/// Marks with [`SURFACE`] the voxel of every sample that one of the `count` triangles
/// `triangle(0..count)` overlaps.
fn rasterize(grid: &SdfGrid, count: usize, triangle: impl Fn(usize) -> [Vec3; 3] + Sync) -> Vec<u8> {
    let dims = grid.dims;
    let n = dims.x as usize * dims.y as usize * dims.z as usize;
    let marks: Vec<AtomicU8> = (0..n).map(|_| AtomicU8::new(0)).collect();
    let (origin, voxel) = (grid.origin, grid.voxel);
    let inv = 1.0 / voxel;
    let half = Vec3::splat(0.5 * voxel * (1.0 + 1e-4));
    let max = (dims - UVec3::ONE).as_vec3();
    let (sx, sy) = (dims.x as usize, dims.x as usize * dims.y as usize);
    (0..count).into_par_iter().for_each(|t| {
        let [a, b, c] = triangle(t);
        // Samples whose voxel [i - 0.5, i + 0.5] (grid units) meets the triangle's box.
        let g = |p: Vec3| (p - origin) * inv;
        let (ga, gb, gc) = (g(a), g(b), g(c));
        let lo = (ga.min(gb).min(gc) - Vec3::splat(0.5 + 1e-4)).ceil().clamp(Vec3::ZERO, max);
        let hi = (ga.max(gb).max(gc) + Vec3::splat(0.5 + 1e-4)).floor().clamp(Vec3::ZERO, max);
        let (lo, hi) = (lo.as_uvec3(), hi.as_uvec3());
        for k in lo.z..=hi.z {
            for j in lo.y..=hi.y {
                for i in lo.x..=hi.x {
                    let centre = origin + voxel * Vec3::new(i as f32, j as f32, k as f32);
                    if triangle_box_overlap(a - centre, b - centre, c - centre, half) {
                        marks[i as usize + sx * j as usize + sy * k as usize]
                            .store(SURFACE, Ordering::Relaxed);
                    }
                }
            }
        }
    });
    marks.into_iter().map(AtomicU8::into_inner).collect()
}

/// Triangles that cap the holes bounded by `boundary` (see [`TriangleMesh::odd_edges`]): per
/// connected set of boundary edges (a loop), a fan from the centroid of its vertices
/// over each of its edges. With them every edge is shared by an even number of triangles.
fn hole_caps(mesh: &TriangleMesh, boundary: &[(u32, u32)]) -> Vec<[Vec3; 3]> {
    let mut verts: Vec<u32> = boundary.iter().flat_map(|&(a, b)| [a, b]).collect();
    verts.sort_unstable();
    verts.dedup();
    let id = |v: u32| verts.binary_search(&v).expect("a boundary vertex");
    let mut parent: Vec<usize> = (0..verts.len()).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for &(a, b) in boundary {
        let (ra, rb) = (find(&mut parent, id(a)), find(&mut parent, id(b)));
        parent[ra.max(rb)] = ra.min(rb);
    }
    let mut sum = vec![(glam::DVec3::ZERO, 0u32); verts.len()];
    for (v, &vertex) in verts.iter().enumerate() {
        let r = find(&mut parent, v);
        sum[r].0 += mesh.positions[vertex as usize].as_dvec3();
        sum[r].1 += 1;
    }
    boundary
        .iter()
        .map(|&(a, b)| {
            let (s, count) = sum[find(&mut parent, id(a))];
            let centre = (s / count as f64).as_vec3();
            [centre, mesh.positions[a as usize], mesh.positions[b as usize]]
        })
        .collect()
}

/// Whether the triangle `a, b, c` (relative to the box centre) overlaps the box of
/// half-extents `h` centred at the origin: Akenine-Möller's separating-axis test (the
/// box's three axes, the triangle's normal, and the nine edge cross products).
#[inline]
pub fn triangle_box_overlap(a: Vec3, b: Vec3, c: Vec3, h: Vec3) -> bool {
    // Box axes.
    let (mn, mx) = (a.min(b).min(c), a.max(b).max(c));
    if mn.cmpgt(h).any() || mx.cmplt(-h).any() {
        return false;
    }
    let edges = [b - a, c - b, a - c];
    // Triangle normal.
    let n = edges[0].cross(edges[1]);
    let r = h.dot(n.abs());
    let s = n.dot(a);
    if s > r || s < -r {
        return false;
    }
    // Edge cross products with the box axes.
    for e in edges {
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            let l = axis.cross(e);
            let (pa, pb, pc) = (l.dot(a), l.dot(b), l.dot(c));
            let r = h.dot(l.abs());
            if pa.min(pb).min(pc) > r || pa.max(pb).max(pc) < -r {
                return false;
            }
        }
    }
    true
}

/// Marks with [`EXTERIOR`] every unmarked voxel 6-connected through unmarked voxels to
/// an unmarked voxel on the grid's boundary.
fn flood_exterior(state: &mut [u8], dims: UVec3) {
    let (nx, ny, nz) = (dims.x as usize, dims.y as usize, dims.z as usize);
    let (sy, sz) = (nx, nx * ny);
    let mut stack: Vec<u32> = Vec::with_capacity(4 * (nx * ny + ny * nz + nx * nz));
    let seed = |state: &mut [u8], idx: usize, stack: &mut Vec<u32>| {
        if state[idx] == 0 {
            state[idx] = EXTERIOR;
            stack.push(idx as u32);
        }
    };
    for k in 0..nz {
        for j in 0..ny {
            let edge = j == 0 || k == 0 || j == ny - 1 || k == nz - 1;
            if edge {
                for i in 0..nx {
                    seed(state, i + sy * j + sz * k, &mut stack);
                }
            } else {
                seed(state, sy * j + sz * k, &mut stack);
                seed(state, nx - 1 + sy * j + sz * k, &mut stack);
            }
        }
    }
    while let Some(idx) = stack.pop() {
        let idx = idx as usize;
        let i = idx % nx;
        let j = (idx / nx) % ny;
        let k = idx / sz;
        if i > 0 {
            seed(state, idx - 1, &mut stack);
        }
        if i + 1 < nx {
            seed(state, idx + 1, &mut stack);
        }
        if j > 0 {
            seed(state, idx - sy, &mut stack);
        }
        if j + 1 < ny {
            seed(state, idx + sy, &mut stack);
        }
        if k > 0 {
            seed(state, idx - sz, &mut stack);
        }
        if k + 1 < nz {
            seed(state, idx + sz, &mut stack);
        }
    }
}

/// Scratch buffers of [`edt_1d`], one set per rayon task.
struct Scratch {
    f: Vec<f32>,
    d: Vec<f32>,
    v: Vec<u32>,
    z: Vec<f32>,
}

impl Scratch {
    fn new(n: usize) -> Self {
        Scratch { f: vec![0.0; n], d: vec![0.0; n], v: vec![0; n], z: vec![0.0; n + 1] }
    }
}

/// The squared Euclidean distance transform of the sampled function `f` in one
/// dimension (Felzenszwalb & Huttenlocher): `d[q] = min_p (q - p)² + f[p]`. Entries of
/// `f` that are infinite are not sites; with no site at all `d` is infinite.
fn edt_1d(f: &[f32], d: &mut [f32], v: &mut [u32], z: &mut [f32]) {
    let n = f.len();
    let mut k: isize = -1;
    for q in 0..n {
        let fq = f[q];
        if !fq.is_finite() {
            continue;
        }
        let qf = q as f32;
        let mut s = f32::NEG_INFINITY;
        while k >= 0 {
            let p = v[k as usize] as f32;
            s = ((fq + qf * qf) - (f[v[k as usize] as usize] + p * p)) / (2.0 * (qf - p));
            if s <= z[k as usize] {
                k -= 1;
                s = f32::NEG_INFINITY;
            } else {
                break;
            }
        }
        k += 1;
        v[k as usize] = q as u32;
        z[k as usize] = s;
        z[k as usize + 1] = f32::INFINITY;
    }
    if k < 0 {
        d.fill(f32::INFINITY);
        return;
    }
    let mut k = 0usize;
    for (q, out) in d.iter_mut().enumerate() {
        let qf = q as f32;
        while z[k + 1] < qf {
            k += 1;
        }
        let p = v[k] as f32;
        *out = (qf - p) * (qf - p) + f[v[k] as usize];
    }
}

/// One pass of the separable transform along lines of length `n`: line `l` of the output
/// (contiguous) is the transform of the input values `src[index(l, 0..n)]`.
fn pass(src: &[f32], out: &mut [f32], n: usize, index: impl Fn(usize, usize) -> usize + Sync) {
    out.par_chunks_mut(n).enumerate().for_each_init(
        || Scratch::new(n),
        |s, (line, dst)| {
            for (t, x) in s.f.iter_mut().enumerate() {
                *x = src[index(line, t)];
            }
            edt_1d(&s.f, &mut s.d, &mut s.v, &mut s.z);
            dst.copy_from_slice(&s.d);
        },
    );
}

/// Fills `grid.values` with the distance (scene units) from each sample to the nearest
/// surface voxel centre, negative for interior samples.
fn signed_distance_transform(state: &[u8], grid: &mut SdfGrid) {
    let (nx, ny, nz) = (grid.dims.x as usize, grid.dims.y as usize, grid.dims.z as usize);
    let n = nx * ny * nz;
    // Pass along x, in the grid's layout (x fastest).
    let mut a: Vec<f32> = state.par_iter().map(|&s| if s == SURFACE { 0.0 } else { f32::INFINITY }).collect();
    let b = a.clone();
    pass(&b, &mut a, nx, |line, t| line * nx + t);
    // Along y: output line (k, i), layout y fastest, then x, then z.
    let mut b = b;
    pass(&a, &mut b, ny, |line, t| {
        let (k, i) = (line / nx, line % nx);
        i + nx * (t + ny * k)
    });
    // Along z: output line (j, i), layout z fastest, then x, then y.
    pass(&b, &mut a, nz, |line, t| {
        let (j, i) = (line / nx, line % nx);
        (t * nx + i) * ny + j
    });
    debug_assert_eq!(a.len(), n);
    let voxel = grid.voxel;
    grid.values.par_chunks_mut(nx * ny).enumerate().for_each(|(k, slice)| {
        for j in 0..ny {
            for i in 0..nx {
                let idx = i + nx * j;
                let d = a[(j * nx + i) * nz + k].sqrt() * voxel;
                let interior = state[idx + nx * ny * k] == 0;
                slice[idx] = if interior { -d } else { d };
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edt_1d_matches_brute_force() {
        let inf = f32::INFINITY;
        let f = [inf, 0.0, inf, inf, inf, 4.0, inf, 0.0, inf, inf];
        let n = f.len();
        let (mut d, mut v, mut z) = (vec![0.0; n], vec![0; n], vec![0.0; n + 1]);
        edt_1d(&f, &mut d, &mut v, &mut z);
        for (q, &dq) in d.iter().enumerate() {
            let want = f
                .iter()
                .enumerate()
                .map(|(p, fp)| (q as f32 - p as f32).powi(2) + fp)
                .fold(f32::INFINITY, f32::min);
            assert_eq!(dq, want, "{q}");
        }
        edt_1d(&[inf; 4], &mut d[..4], &mut v, &mut z);
        assert!(d[..4].iter().all(|x| x.is_infinite()));
    }

    #[test]
    fn triangle_box_cases() {
        let h = Vec3::splat(0.5);
        // Crossing the box.
        assert!(triangle_box_overlap(
            Vec3::new(-2.0, 0.1, -2.0),
            Vec3::new(2.0, 0.1, -2.0),
            Vec3::new(0.0, 0.1, 3.0),
            h
        ));
        // Plane misses the box.
        assert!(!triangle_box_overlap(
            Vec3::new(-2.0, 0.6, -2.0),
            Vec3::new(2.0, 0.6, -2.0),
            Vec3::new(0.0, 0.6, 3.0),
            h
        ));
        // The boxes overlap but the triangle's plane separates.
        assert!(!triangle_box_overlap(
            Vec3::new(1.2, 0.0, 0.0),
            Vec3::new(0.0, 1.2, 0.0),
            Vec3::new(0.0, 0.0, 1.2),
            Vec3::splat(0.3)
        ));
    }
}
