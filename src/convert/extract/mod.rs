//! Extraction of triangle meshes from signed distance functions (issue 4: SDF -> mesh).
//!
//! [`extract`] samples a function once per corner of a regular grid (in parallel over
//! z-slices) and extracts its zero isosurface with one of three methods. For a signed
//! distance or a Lipschitz-1 bound of one ([`Field::DistanceBound`], every scene object's
//! [`SdfTree`]) only blocks of the grid near the zero set are evaluated: a box of blocks
//! whose centre value exceeds its half-diagonal holds no surface ([`Blocks`]).
//!
//! - [`ExtractMethod::MarchingCubes`] (the default): classic marching cubes, one vertex per
//!   sign-changing cube edge, each cube's configuration triangulated from a case table
//!   generated at first use ([`McTable`]). Ambiguous faces are resolved by the asymptotic
//!   decider, from the face's four samples only, so both cells sharing a face cut it
//!   alike; diagonals between two edges of one face are used only by the cell below the
//!   face. So the output is watertight and edge-manifold by construction (checked over
//!   every pair of neighbouring configurations in the unit tests). Quadrilaterals and
//!   polygons up to 7 vertices take the triangulation that folds least on the actual
//!   vertices; the rare cycle that cannot avoid a diagonal on a lower face gets a vertex
//!   of its own at the mean of its crossings.
//! - [`ExtractMethod::MarchingTetrahedra`]: every cube is split into six tetrahedra around
//!   its main diagonal (the Kuhn / Freudenthal split, the same in every cell, so
//!   neighbouring cells cut their shared faces along the same diagonal) and each
//!   tetrahedron is triangulated on its own. There is no ambiguous case, so the result is
//!   always watertight and edge-manifold. Vertices lie on the grid's edges (the 12 cube
//!   edges, 6 face diagonals and the main diagonal of each cell), one per sign-changing
//!   edge; about three times marching cubes' triangles.
//! - [`ExtractMethod::DualContouring`]: one vertex per surface component of each
//!   sign-changing cell, placed by minimising a quadratic error function built from the
//!   crossing points on the component's cell edges and the function's gradient there
//!   (central differences, step 0.01 cell), regularised towards the crossings' mass point
//!   by truncating eigenvalues below 5% of the largest. Where
//!   fewer than three eigenvalues remain (no corner), the vertex is then moved halfway to
//!   the surface along the crossings' mean normal ([`SMOOTH_PULL`]): on a curved sheet the
//!   QEF puts it on the tangent planes, about a facet's largest sag off the surface, and
//!   halfway back the facets straddle the surface (on the thesis CSG scene this lowered
//!   the mean distance by about 40%; projecting all the way onto the surface raised it).
//!   A vertex may lie up to half a cell ([`DC_REACH`]) outside its cell: a thin wedge
//!   (the rim of a bite, the edge of a lens) can pass between the grid points of the cell
//!   its crease crosses, which then has no vertex, and the neighbours' vertices must reach
//!   it. A vertex beyond that is replaced by the QEF's minimiser within reach
//!   ([`Qef::solve_in_box`]), which slides along a crease instead of leaving it (clamping
//!   each coordinate would). On the thesis CSG scene these took the largest distance at
//!   equal triangle count from 0.57 to 0.21 of mcubes'.
//!   Each sign-changing cube edge gives a quad over the four cells around it, split into
//!   two triangles along a diagonal whose triangles face outwards, of those the one whose
//!   midpoint is closer to the surface (one evaluation of `f` per diagonal). Sharp edges
//!   and corners of the surface are reproduced.
//!
//!   A cell's components are the cycles formed by pairing the crossings on each of its
//!   faces; on a face with four crossings the pairing follows the asymptotic decider
//!   (the sign of the bilinear interpolant's saddle), which both cells sharing the face
//!   agree on. Where both cells would join the face's two sheets into one component (the
//!   dual edge between them would then be used four times), both flip that face's pairing.
//!   With this the output was closed and edge-manifold in every test (random blobs, CSG,
//!   gyroids at 4 cells per period), but unlike marching cubes and tetrahedra this is not
//!   proven: on value noise at the cell scale a cell's one component can still touch
//!   both sheets of an ambiguous face after the flip (joined through its other faces), and
//!   when its neighbour's does too, the dual edge between them is used four times (one
//!   mesh in ten of the noise fields of `tests/integration/extract_mc.rs`);
//!   check with [`TriangleMesh::is_closed`] where it matters.
//!
//! Only cells with corners of both signs are visited: the samples' signs are packed 64
//! to a word per x-row ([`Signs`]), and a cell row's active cells are a few word
//! operations over its four corner rows. The sign-changing grid edges are bit rows too
//! ([`Crossings`]), numbered by slice, row, direction and x, so the vertex on an edge is
//! the count of crossings before it in its word plus the word's start: vertices are
//! shared between cells without hashing, sorting or per-point index arrays.
//!
//! Crossing points on grid edges start from linear interpolation of the two sampled values
//! and are refined by [`REFINE_STEPS`] Illinois (regula falsi) steps on `f` along the edge,
//! then kept at least [`EDGE_MARGIN`] of the edge's length away from its ends, so that no
//! two vertices coincide and no triangle degenerates when a sample is exactly zero.
//!
//! A corner is inside when its sample is `< 0` (zero and NaN count as outside). Samples on
//! the outermost layer of the grid are forced positive, so the surface is always closed:
//! where `f` is negative on the padded box's boundary the surface is capped just inside it.
//!
//! Triangles are counter-clockwise seen from outside: `(b - a) × (c - a)` points towards
//! positive `f`. The meshes have no normals (see [`TriangleMesh::compute_vertex_normals`]).

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::geometry::Aabb;
use crate::geometry::sdf::SdfTree;
use crate::mesh::{TriangleMesh, is_degenerate};
use crate::scene::shape::Object;

mod cubes;
mod dual_contouring;
mod lattice;
mod qef;
mod tetrahedra;

use cubes::*;
use dual_contouring::*;
pub use lattice::SampleGrid;
use lattice::*;
use qef::*;
use tetrahedra::*;

/// How [`extract`] turns samples into triangles; the command line's `--method` values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum ExtractMethod {
    /// Classic marching cubes: one vertex per sign-changing cube edge, each cube's
    /// configuration triangulated from a generated case table whose ambiguous faces are
    /// resolved by the asymptotic decider (the face's corner samples alone, so both cells
    /// sharing a face agree): watertight and edge-manifold in every case, sharp features
    /// cut off.
    #[value(
        name = "mc",
        help = "Marching cubes (asymptotic decider on ambiguous faces): always closed and manifold"
    )]
    MarchingCubes,
    /// Marching tetrahedra on a consistent six-tetrahedron split of each cube: watertight
    /// and manifold in every case, about three times marching cubes' triangles.
    #[value(
        name = "mt",
        help = "Marching tetrahedra: always closed and manifold, about three times the triangles"
    )]
    MarchingTetrahedra,
    /// Dual contouring: one QEF-placed vertex per surface component of a sign-changing
    /// cell, quads across sign-changing edges; keeps sharp features; about as many
    /// triangles as marching cubes.
    #[value(name = "dc", help = "Dual contouring with a QEF: keeps sharp edges")]
    DualContouring,
}

/// Illinois steps that refine a crossing point along its grid edge after the initial
/// linear interpolation of the samples (each costs one evaluation of `f`).
pub const REFINE_STEPS: u32 = 2;

/// Crossing points are kept in `[EDGE_MARGIN, 1 - EDGE_MARGIN]` of their edge.
pub const EDGE_MARGIN: f64 = 1e-3;

/// Edge directions from a grid point: the three axes, the three face diagonals and the
/// main diagonal, all towards increasing coordinates. Dual contouring uses the first three.
const DIRS: [[usize; 3]; 7] = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 1, 1]];

/// Samples `f` on a grid of `res` cells along the longest axis of `bounds` (padded by one
/// cell on each side so the surface is closed) and extracts the zero isosurface.
///
/// Output: closed, consistently outward-oriented (`(b - a) × (c - a)` points to positive
/// `f`), edge-manifold, no duplicate vertices (vertices on grid edges are shared between
/// cells through the edges' numbering), no degenerate triangles (any that slip through are
/// dropped after welding), for any `f` that is negative inside a region strictly inside
/// the padded bounds. Marching cubes guarantees closed and edge-manifold output; dual
/// contouring gave it in every test (see the module documentation).
///
/// Cells are cubes of side `longest extent / res`; the other axes get as many cells as
/// cover them, centred. `res` 0 counts as 1. Bounds with a non-finite or zero longest
/// extent give an empty mesh. The grid holds `(res + 3)^3` samples at most (f32, plus
/// under 1 byte per sample of working memory, 9 for dual contouring). With
/// [`Field::DistanceBound`], `f` is evaluated only in blocks of the grid near its zero set
/// (the mesh is the same as with [`Field::Arbitrary`], which evaluates every point).
///
/// # Panics
/// When the grid has `u32::MAX` points or more (`res` above about 1600).
pub fn extract(
    f: &(impl Fn(DVec3) -> f64 + Sync),
    field: Field,
    bounds: &Aabb,
    res: u32,
    method: ExtractMethod,
) -> TriangleMesh {
    match sample_grid(f, field, bounds, res) {
        Some(grid) => extract_sampled(f, &grid, method),
        None => TriangleMesh::default(),
    }
}

/// The first half of [`extract`]: samples `f` on its grid (see there). `None` when the
/// bounds' longest extent is zero or not finite.
///
/// # Panics
/// When the grid has `u32::MAX` points or more.
pub fn sample_grid(
    f: &(impl Fn(DVec3) -> f64 + Sync),
    field: Field,
    bounds: &Aabb,
    res: u32,
) -> Option<SampleGrid> {
    SampleGrid::sample(f, bounds, res.max(1), field)
}

/// The second half of [`extract`]: extracts the zero isosurface of `f` from `grid`, which
/// must have been sampled from the same `f` by [`sample_grid`] (crossings are refined and
/// gradients taken on `f` itself).
pub fn extract_sampled(
    f: &(impl Fn(DVec3) -> f64 + Sync),
    grid: &SampleGrid,
    method: ExtractMethod,
) -> TriangleMesh {
    let (mesh, unique) = match method {
        // Crossings on two different grid edges are at least 0.5 EDGE_MARGIN h apart (they
        // are kept that far from the edges' ends; edges that share no end are far apart).
        // A cycle's own vertex (rare) is not on a grid edge: then the check runs.
        ExtractMethod::MarchingCubes => {
            let (mesh, on_edges) = marching_cubes(f, grid);
            (mesh, on_edges && grid.separated_in_f32(0.5 * EDGE_MARGIN * grid.h))
        }
        ExtractMethod::MarchingTetrahedra => {
            (marching_tetrahedra(f, grid), grid.separated_in_f32(0.5 * EDGE_MARGIN * grid.h))
        }
        // Vertices may leave their cells (DC_REACH), so two can coincide: always checked.
        ExtractMethod::DualContouring => (dual_contouring(f, grid), false),
    };
    clean_up(mesh, unique)
}

/// Extracts `object`'s surface through its [`SdfTree`] within its bounds (see [`extract`]).
///
/// `None` when the object holds a mesh, a triangle primitive (unsigned distance: no
/// inside) or is unbounded.
pub fn extract_object(object: &Object, res: u32, method: ExtractMethod) -> Option<TriangleMesh> {
    let tree = SdfTree::new(object)?;
    if !tree.signed {
        return None;
    }
    let bounds = object.bounds()?;
    Some(extract(&|p| tree.distance(p), Field::DistanceBound, &bounds, res, method))
}

/// What extraction may assume of the function it samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Field {
    /// A signed distance or a lower bound of one that is Lipschitz-1 (`|f(p) - f(q)| <=
    /// |p - q|`), like [`SdfTree::distance`]. Then a box of the grid whose centre value is
    /// farther from zero than the box's half-diagonal holds no sign change and no surface,
    /// and its points are not evaluated (see [`Blocks`]).
    DistanceBound,
    /// Anything else (for example a trilinearly interpolated grid, noise): every grid point
    /// is evaluated.
    Arbitrary,
}

/// The crossing on the edge `p0`-`p1` whose samples `v0`, `v1` have different signs
/// (`< 0` inside), as the edge parameter in `[EDGE_MARGIN, 1 - EDGE_MARGIN]`.
fn crossing(f: &impl Fn(DVec3) -> f64, p0: DVec3, v0: f64, p1: DVec3, v1: f64) -> f64 {
    let (mut a, mut fa, mut b, mut fb) = (0.0f64, v0, 1.0f64, v1);
    let mut t = interp(a, fa, b, fb);
    let mut last_side = 0i8;
    for _ in 0..REFINE_STEPS {
        let ft = f(p0.lerp(p1, t));
        if !ft.is_finite() {
            break;
        }
        if (ft < 0.0) == (fa < 0.0) {
            (a, fa) = (t, ft);
            if last_side == -1 {
                fb *= 0.5; // Illinois: keep the stale end from stalling the bracket.
            }
            last_side = -1;
        } else {
            (b, fb) = (t, ft);
            if last_side == 1 {
                fa *= 0.5;
            }
            last_side = 1;
        }
        t = interp(a, fa, b, fb);
    }
    t.clamp(EDGE_MARGIN, 1.0 - EDGE_MARGIN)
}

#[inline]
fn interp(a: f64, fa: f64, b: f64, fb: f64) -> f64 {
    let s = fa / (fa - fb);
    if s.is_finite() { a + (b - a) * s.clamp(0.0, 1.0) } else { 0.5 * (a + b) }
}

/// A crossing point on the edge `p0`-`p1` with samples `v0`, `v1` (see [`crossing`]).
#[inline]
fn crossing_point(f: &impl Fn(DVec3) -> f64, p0: DVec3, v0: f64, p1: DVec3, v1: f64) -> DVec3 {
    p0.lerp(p1, crossing(f, p0, v0, p1, v1))
}

/// Unit gradient of `f` at `p` by central differences with step `eps`.
fn gradient(f: &impl Fn(DVec3) -> f64, p: DVec3, eps: f64) -> DVec3 {
    let g = DVec3::new(
        f(p + DVec3::X * eps) - f(p - DVec3::X * eps),
        f(p + DVec3::Y * eps) - f(p - DVec3::Y * eps),
        f(p + DVec3::Z * eps) - f(p - DVec3::Z * eps),
    );
    let g = g.normalize_or_zero();
    if g.is_finite() { g } else { DVec3::ZERO }
}

/// Welds bit-identical positions (none by construction; checked by sorting unless
/// `unique` says the construction proves it), drops triangles that repeat a vertex or have
/// zero area, and removes unused vertices (every vertex is used by construction, so only
/// after welding or dropping).
fn clean_up(mut mesh: TriangleMesh, unique: bool) -> TriangleMesh {
    let mut changed = false;
    if !unique {
        let mut keys: Vec<[u32; 3]> =
            mesh.positions.par_iter().map(|p| (*p + Vec3::ZERO).to_array().map(f32::to_bits)).collect();
        keys.par_sort_unstable();
        let duplicates = keys.par_windows(2).any(|w| w[0] == w[1]);
        drop(keys);
        if duplicates {
            mesh.weld();
            changed = true;
        }
    }
    let pos = &mesh.positions;
    let bad = |t: &[u32; 3]| {
        t[0] == t[1]
            || t[1] == t[2]
            || t[0] == t[2]
            || is_degenerate(pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize])
    };
    if mesh.triangles.par_iter().any(bad) {
        let tris = std::mem::take(&mut mesh.triangles);
        mesh.triangles = tris.into_iter().filter(|t| !bad(t)).collect();
        changed = true;
    }
    if !changed {
        debug_assert!(
            {
                let mut used = vec![false; mesh.positions.len()];
                mesh.triangles.iter().flatten().for_each(|&i| used[i as usize] = true);
                used.iter().all(|&u| u)
            },
            "a vertex no triangle uses"
        );
        return mesh;
    }
    // Remove vertices no triangle uses.
    let mut used = vec![false; mesh.positions.len()];
    for t in &mesh.triangles {
        for &i in t {
            used[i as usize] = true;
        }
    }
    if used.iter().all(|&u| u) {
        return mesh;
    }
    let mut remap = vec![u32::MAX; used.len()];
    let mut positions = Vec::new();
    for (i, &u) in used.iter().enumerate() {
        if u {
            remap[i] = positions.len() as u32;
            positions.push(mesh.positions[i]);
        }
    }
    for t in &mut mesh.triangles {
        *t = t.map(|i| remap[i as usize]);
    }
    mesh.positions = positions;
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_reconstructs() {
        let a = [[4.0, 1.0, 0.5], [1.0, 3.0, -0.7], [0.5, -0.7, 1.0]];
        let (vals, vecs) = sym_eigen(a);
        for k in 0..3 {
            let v = vecs[k];
            let av = DVec3::new(
                a[0][0] * v.x + a[0][1] * v.y + a[0][2] * v.z,
                a[1][0] * v.x + a[1][1] * v.y + a[1][2] * v.z,
                a[2][0] * v.x + a[2][1] * v.y + a[2][2] * v.z,
            );
            assert!((av - v * vals[k]).length() < 1e-12, "{k}: {av} vs {}", v * vals[k]);
            assert!((v.length() - 1.0).abs() < 1e-12);
        }
    }

    /// Directed edges of `tris` with their number of uses.
    fn directed(tris: &[[u8; 3]]) -> std::collections::HashMap<(u8, u8), u32> {
        let mut uses = std::collections::HashMap::new();
        for t in tris {
            for k in 0..3 {
                *uses.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        uses
    }

    /// The triangles of `case` with the first option of every polygon.
    fn first_options(t: &McTable, case: usize) -> Vec<[u8; 3]> {
        t.polygons(case).iter().flat_map(|&p| t.option(p, 0).to_vec()).collect()
    }

    /// Every option of every polygon of every case: each directed edge used once; edges
    /// between two vertices on one lower face used one way only (segments), inner edges
    /// both ways; all the configuration's crossing edges used; the normals point from the
    /// inside ends of the vertices' cube edges to the outside ends (summed over a case).
    #[test]
    fn mc_cases_are_closed_inside_the_cell() {
        let t = mc_table();
        let topo = CubeTopology::new();
        let faces = |k: u8| edge_faces(&topo, k as usize);
        let (mut cases, mut options, mut own) = (0, 0, 0);
        for config in 0..256 {
            let (first, last) = (t.first_case[config] as usize, t.first_case[config + 1] as usize);
            assert_eq!(last - first, 1 << t.ambiguous[config].count_ones(), "config {config}");
            for case in first..last {
                cases += 1;
                own += t.centres(case).len();
                let mut used = 0u16;
                for &p in t.polygons(case) {
                    for o in 0..p.options as usize {
                        options += 1;
                        let tris = t.option(p, o);
                        used |=
                            tris.iter().flatten().filter(|&&k| k < MC_CENTRE).fold(0u16, |m, &k| m | 1 << k);
                        let uses = directed(tris);
                        for (&(a, b), &n) in &uses {
                            assert_eq!(n, 1, "config {config}: directed edge {a}->{b} used {n} times");
                            let back = uses.get(&(b, a)).copied().unwrap_or(0);
                            let shared = faces(a) & faces(b);
                            if shared & LOWER_FACES != 0 {
                                assert_eq!(
                                    back, 0,
                                    "config {config}: lower face edge {a}-{b} used both ways"
                                );
                            } else if shared == 0 {
                                assert_eq!(back, 1, "config {config}: inner edge {a}-{b} not closed");
                            }
                        }
                    }
                }
                assert_eq!(used, t.crossing[config], "config {config} case {case}: edges used");
                // Orientation, with vertices at the edges' midpoints (a triangle across a
                // tunnel may point either way, so summed over the case).
                let mid = |k: u8| {
                    if k < MC_CENTRE {
                        return edge_mid(&topo, k as usize);
                    }
                    let cycle = t.centres(case)[(k - MC_CENTRE) as usize];
                    let ks: Vec<usize> = (0..12).filter(|e| cycle & (1 << e) != 0).collect();
                    ks.iter().map(|&e| edge_mid(&topo, e)).sum::<DVec3>() / ks.len() as f64
                };
                let tris = first_options(t, case);
                let mut outwards = 0.0;
                for tri in &tris {
                    let [a, b, c] = tri.map(mid);
                    let nrm = (b - a).cross(c - a);
                    for &k in tri.iter().filter(|&&k| k < MC_CENTRE) {
                        let (c, d) = topo.edges[k as usize];
                        let dir = if config >> c & 1 != 0 { corner_pos(1 << d) } else { -corner_pos(1 << d) };
                        outwards += nrm.dot(dir);
                    }
                }
                assert!(tris.is_empty() || outwards > 0.0, "config {config} case {case}: faces inwards");
            }
        }
        assert!(cases > 256 && options > cases, "{cases} cases, {options} options");
        println!("{cases} cases, {options} polygon triangulations, {own} cycles with a vertex of their own");
    }

    /// Two cells sharing a face with the same samples on it, whatever the rest of their
    /// corners and choices: the segments on the face are the same, in opposite directions.
    #[test]
    fn mc_cells_agree_across_every_face() {
        let t = mc_table();
        let topo = CubeTopology::new();
        let faces = |k: u8| edge_faces(&topo, k as usize);
        let mut checked = 0u64;
        for a in 0..3 {
            let (lo_face, hi_face) = (2 * a, 2 * a + 1);
            // The segments a case puts on `face` (edges on it used one way only; the cell
            // below a face may also use its diagonals, both ways), in the upper cell's
            // edge numbering when `shift` (the edge's lower corner moved across the face).
            let segments = |case: usize, face: usize, shift: bool| -> Vec<(u8, u8)> {
                let uses = directed(&first_options(t, case));
                let map = |k: u8| -> u8 {
                    if !shift {
                        return k;
                    }
                    let (c, d) = topo.edges[k as usize];
                    topo.edges.iter().position(|&e| e == (c ^ 1 << a, d)).unwrap() as u8
                };
                let mut s: Vec<(u8, u8)> = uses
                    .keys()
                    .copied()
                    .filter(|&(p, q)| faces(p) & faces(q) & (1 << face) != 0 && !uses.contains_key(&(q, p)))
                    .map(|(p, q)| (map(p), map(q)))
                    .collect();
                s.sort_unstable();
                s
            };
            let choice_bit = |config: usize, face: usize| -> Option<usize> {
                let amb = t.ambiguous[config];
                (amb & (1 << face) != 0).then(|| (amb & ((1 << face) - 1)).count_ones() as usize)
            };
            for lower in 0..256usize {
                for upper in 0..256usize {
                    // `upper`'s corners with bit a clear are `lower`'s with bit a set.
                    if (0..8)
                        .filter(|c| c & (1 << a) == 0)
                        .any(|c| (upper >> c) & 1 != (lower >> (c | 1 << a)) & 1)
                    {
                        continue;
                    }
                    let (fl, ll) = (t.first_case[lower] as usize, t.first_case[lower + 1] as usize);
                    let (fu, lu) = (t.first_case[upper] as usize, t.first_case[upper + 1] as usize);
                    let (bl, bu) = (choice_bit(lower, hi_face), choice_bit(upper, lo_face));
                    assert_eq!(bl.is_some(), bu.is_some());
                    for cl in fl..ll {
                        for cu in fu..lu {
                            if let (Some(bl), Some(bu)) = (bl, bu)
                                && ((cl - fl) >> bl) & 1 != ((cu - fu) >> bu) & 1
                            {
                                continue;
                            }
                            let mut mine = segments(cl, hi_face, true);
                            mine.iter_mut().for_each(|e| *e = (e.1, e.0));
                            mine.sort_unstable();
                            assert_eq!(mine, segments(cu, lo_face, false), "axis {a}: {lower} | {upper}");
                            checked += 1;
                        }
                    }
                }
            }
        }
        assert!(checked > 3 * 256 * 16, "{checked} pairs");
    }

    #[test]
    fn polygon_triangulations_are_catalan() {
        for (m, count) in [(3, 1), (4, 2), (5, 5), (6, 14), (7, 42)] {
            let all = polygon_triangulations(m);
            assert_eq!(all.len(), count);
            for t in &all {
                assert_eq!(t.len(), m - 2);
                // Each inner diagonal twice, each side once.
                let mut sides = std::collections::HashMap::new();
                for &[i, j, k] in t {
                    assert!(i < j && j < k);
                    for e in [(i, j), (j, k), (i, k)] {
                        *sides.entry(e).or_insert(0) += 1;
                    }
                }
                for (&(i, j), &n) in &sides {
                    let side = j == i + 1 || (i == 0 && j == m - 1);
                    assert_eq!(n, if side { 1 } else { 2 }, "{m}-gon {t:?}");
                }
            }
        }
    }

    /// A grid of random samples (some exactly zero) with its outer layer positive.
    fn random_grid(n: [usize; 3], seed: u64) -> SampleGrid {
        let mut state = seed | 1;
        let mut values = vec![0.0f32; n[0] * n[1] * n[2]];
        for (i, v) in values.iter_mut().enumerate() {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let (x, y, z) = (i % n[0], (i / n[0]) % n[1], i / (n[0] * n[1]));
            let boundary = x == 0 || y == 0 || z == 0 || x + 1 == n[0] || y + 1 == n[1] || z + 1 == n[2];
            *v = match state % 16 {
                _ if boundary => 1.0,
                0 => 0.0,
                r => r as f32 / 8.0 - 1.0,
            };
        }
        SampleGrid { origin: DVec3::new(-1.0, 0.5, 2.0), h: 0.25, n, values }
    }

    #[test]
    fn bit_scans_match_plain_loops() {
        for (s, n) in
            [[5, 4, 3], [64, 3, 4], [65, 4, 5], [130, 5, 4], [129, 3, 3], [200, 6, 3]].into_iter().enumerate()
        {
            let grid = random_grid(n, 0x9e37_79b9 + s as u64);
            let signs = Signs::new(&grid);
            let mut fast = Vec::new();
            for z in 0..n[2] - 1 {
                signs.active_cells(z, |x, y, c| fast.push((x, y, z, c)));
            }
            let mut slow = Vec::new();
            for z in 0..n[2] - 1 {
                for y in 0..n[1] - 1 {
                    for x in 0..n[0] - 1 {
                        let c = (0..8).fold(0u8, |m, c| {
                            let o = corner(c);
                            m | ((grid.values[grid.idx(x + o[0], y + o[1], z + o[2])] < 0.0) as u8) << c
                        });
                        if c != 0 && c != 0xff {
                            slow.push((x, y, z, c));
                        }
                    }
                }
            }
            assert!(slow.len() > 10, "{n:?}: {} active cells", slow.len());
            assert_eq!(fast, slow, "{n:?}");
            let (cross, ends) = Crossings::new(&grid, &signs, DIRS.len(), |p0, _, p1, _| (p0, p1));
            let mut k = 0;
            for z in 0..n[2] {
                for y in 0..n[1] {
                    for (d, o) in DIRS.iter().enumerate() {
                        for x in 0..n[0] {
                            if x + o[0] >= n[0] || y + o[1] >= n[1] || z + o[2] >= n[2] {
                                continue;
                            }
                            let (i0, i1) = (grid.idx(x, y, z), grid.idx(x + o[0], y + o[1], z + o[2]));
                            if grid.inside(i0) != grid.inside(i1) {
                                assert_eq!(
                                    cross.vertex(x, y, z, d) as usize,
                                    k,
                                    "{n:?} ({x}, {y}, {z}) dir {d}"
                                );
                                assert_eq!(
                                    ends[k],
                                    (grid.pos(x, y, z), grid.pos(x + o[0], y + o[1], z + o[2]))
                                );
                                k += 1;
                            }
                        }
                    }
                }
                let first = if z == 0 { 0 } else { (0..z).map(|s| cross.in_slice(s)).sum() };
                assert!(cross.in_slice(z) <= k - first);
            }
            assert_eq!(ends.len(), k, "{n:?}");
        }
    }

    #[test]
    fn tet_table_is_complete() {
        let t = tet_table();
        for tet in &t {
            assert!(tet[0].is_empty() && tet[15].is_empty());
            for (m, tris) in tet.iter().enumerate() {
                let expected = match (m as u8).count_ones() {
                    1 | 3 => 1,
                    2 => 2,
                    _ => 0,
                };
                assert_eq!(tris.len(), expected);
            }
        }
    }

    #[test]
    fn truncated_solve_matches_jacobi() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let mut fast = 0;
        for i in 0..20_000 {
            // Sums of 1 to 6 normals spread around one direction: rank one to three.
            let base = DVec3::new(rnd(), rnd(), rnd()).normalize();
            let spread = [0.0, 1e-6, 1e-3, 0.05, 0.2, 0.5, 2.0][i % 7];
            let mut q = Qef::default();
            for _ in 0..1 + i % 6 {
                let n = (base + DVec3::new(rnd(), rnd(), rnd()) * spread).normalize();
                q.add(DVec3::new(rnd(), rnd(), rnd()) * 0.01, n);
            }
            let c = q.points / q.count as f64;
            let a = q.ata;
            let rhs = q.atb - DVec3::from_array(a.map(|row| DVec3::from_array(row).dot(c)));
            let (vals, vecs) = sym_eigen(a);
            let max = vals.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let kept = (0..3).filter(|&k| vals[k] > QEF_TRUNCATION * max);
            let reference: DVec3 = kept.clone().map(|k| vecs[k] * (vecs[k].dot(rhs) / vals[k])).sum();
            if let Some((x, rank)) = truncated_solve(a, rhs) {
                fast += 1;
                assert_eq!(rank as usize, kept.count(), "{a:?}");
                assert!(
                    (x - reference).length() <= 1e-8 * reference.length().max(1e-12),
                    "{a:?}: {x} vs {reference}"
                );
            }
        }
        assert!(fast > 18_000, "fast path taken {fast} times of 20000");
    }

    #[test]
    fn qef_finds_a_box_corner() {
        let mut q = Qef::default();
        q.add(DVec3::new(0.3, 1.0, 0.2), DVec3::Y);
        q.add(DVec3::new(1.0, 0.1, 0.4), DVec3::X);
        q.add(DVec3::new(0.5, 0.6, 1.0), DVec3::Z);
        assert!((q.solve().0 - DVec3::ONE).length() < 1e-12);
        assert_eq!(q.solve().1, 3);
    }
}
