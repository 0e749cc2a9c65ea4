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
//!   mesh in ten of the noise fields of `tests/extract_mc.rs`);
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

/// How [`extract`] turns samples into triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ExtractMethod {
    /// Classic marching cubes: one vertex per sign-changing cube edge, each cube's
    /// configuration triangulated from a generated case table whose ambiguous faces are
    /// resolved by the asymptotic decider (the face's corner samples alone, so both cells
    /// sharing a face agree): watertight and edge-manifold in every case, sharp features
    /// cut off.
    MarchingCubes,
    /// Marching tetrahedra on a consistent six-tetrahedron split of each cube: watertight
    /// and manifold in every case, about three times marching cubes' triangles.
    MarchingTetrahedra,
    /// Dual contouring: one QEF-placed vertex per surface component of a sign-changing
    /// cell, quads across sign-changing edges; keeps sharp features; about as many
    /// triangles as marching cubes.
    DualContouring,
}

/// Illinois steps that refine a crossing point along its grid edge after the initial
/// linear interpolation of the samples (each costs one evaluation of `f`).
pub const REFINE_STEPS: u32 = 2;

/// Crossing points are kept in `[EDGE_MARGIN, 1 - EDGE_MARGIN]` of their edge.
pub const EDGE_MARGIN: f64 = 1e-3;

/// Eigenvalues of the QEF matrix below this fraction of the largest one are truncated
/// (the solution moves only in the well-determined directions from the mass point).
const QEF_TRUNCATION: f64 = 0.05;

/// A dual contouring vertex outside its cell is replaced by the minimiser within the cell
/// of its QEF plus this fraction of the QEF matrix's trace times the squared distance to
/// it ([`Qef::solve_in_box`]): small, so that the error decides and the vertex only slides
/// along directions the error leaves free (a crease line).
const QEF_BOX_REGULARISATION: f64 = 1e-3;

/// How far (in cells) a dual contouring vertex may leave its cell.
const DC_REACH: f64 = 0.5;

/// Dual contouring moves the QEF's vertex of a cell without a corner (rank below 3) this
/// fraction of `f` at the vertex along the crossings' mean normal. On a curved sheet the
/// QEF's minimiser lies on the crossings' tangent planes, so outside a convex surface
/// (inside a concave one) by about the largest sag of the facets between such vertices;
/// halfway back the facets straddle the surface instead of lying wholly on one side. On
/// flat faces and straight creases `f` is 0 there and nothing moves.
const SMOOTH_PULL: f64 = 0.5;

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

/// Samples of a function on the corners of a regular grid of cubic cells (from
/// [`sample_grid`]); point `(x, y, z)` is at `origin + cell * (x, y, z)` and its sample is
/// `values[x + n[0] * (y + n[1] * z)]`. Samples on the outermost layer are positive. For a
/// [`Field::DistanceBound`] function, points in blocks far from the surface hold a bound
/// `b` of their value instead (`f`'s sign, `0 < |b| <= |f|`; see [`Blocks`]).
pub struct SampleGrid {
    origin: DVec3,
    /// Cell size.
    h: f64,
    /// Points per axis (cells + 1).
    n: [usize; 3],
    values: Vec<f32>,
}

impl SampleGrid {
    /// Position of grid point (0, 0, 0).
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// Cell side.
    pub fn cell(&self) -> f64 {
        self.h
    }

    /// Grid points per axis (cells + 1).
    pub fn dims(&self) -> [usize; 3] {
        self.n
    }

    /// The samples, x fastest.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    fn sample(
        f: &(impl Fn(DVec3) -> f64 + Sync),
        bounds: &Aabb,
        res: u32,
        field: Field,
    ) -> Option<SampleGrid> {
        let (lo, hi) = (bounds.min.as_dvec3(), bounds.max.as_dvec3());
        let ext = (hi - lo).max(DVec3::ZERO);
        let longest = ext.max_element();
        if !longest.is_finite() || longest <= 0.0 || !lo.is_finite() {
            return None;
        }
        let h = longest / res as f64;
        let mut n = [0usize; 3];
        let mut origin = DVec3::ZERO;
        for a in 0..3 {
            // Cells covering the extent (the longest axis gets exactly `res`), plus one on
            // each side; the grid is centred on the box.
            let cells = if ext[a] == longest { res as usize } else { (ext[a] / h).ceil() as usize } + 2;
            n[a] = cells + 1;
            origin[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * cells as f64 * h;
        }
        // Grid point indices are stored as u32 (res up to about 1600).
        assert!(n[0] * n[1] * n[2] < u32::MAX as usize, "extraction grid too large: {n:?} points");
        let mut grid = SampleGrid { origin, h, n, values: vec![0.0; n[0] * n[1] * n[2]] };
        let blocks = match field {
            Field::DistanceBound => Blocks::classify(f, &grid),
            Field::Arbitrary => Blocks::all_sampled(),
        };
        let slice = n[0] * n[1];
        let (origin, nn) = (grid.origin, grid.n);
        grid.values.par_chunks_mut(slice).enumerate().for_each_init(
            || vec![0.0f32; blocks.n[0]],
            |row_fill, (z, vals)| {
                for (y, row) in vals.chunks_exact_mut(nn[0]).enumerate() {
                    blocks.row_fill(y, z, row_fill);
                    for (x, v) in row.iter_mut().enumerate() {
                        let (b0, b1) = blocks.along_axis(0, x);
                        let (f0, f1) = (row_fill[b0], row_fill[b1]);
                        *v = if f0.is_nan() || f1.is_nan() {
                            f(origin + h * DVec3::new(x as f64, y as f64, z as f64)) as f32
                        } else {
                            f0
                        };
                    }
                }
                // The outermost layer positive: whole slices at the ends, else the rows at
                // y = 0 and the last y, and both ends of the others.
                let outside = |v: &mut f32| {
                    if !(*v > 0.0) {
                        *v = f32::MIN_POSITIVE;
                    }
                };
                let rows = vals.len() / nn[0];
                for (y, row) in vals.chunks_exact_mut(nn[0]).enumerate() {
                    if z == 0 || z + 1 == nn[2] || y == 0 || y + 1 == rows {
                        row.iter_mut().for_each(outside);
                    } else {
                        outside(&mut row[0]);
                        outside(&mut row[nn[0] - 1]);
                    }
                }
                crate::cli::progress::advance(1);
            },
        );
        Some(grid)
    }

    /// Whether points within the grid that are at least `sep` apart stay distinct when
    /// rounded to f32 (each coordinate moves by at most half an ulp, `2^-24 |x|`).
    fn separated_in_f32(&self, sep: f64) -> bool {
        let far =
            self.pos(self.n[0] - 1, self.n[1] - 1, self.n[2] - 1).abs().max(self.origin.abs()).max_element();
        sep > 8.0 * f32::EPSILON as f64 * far
    }

    #[inline]
    fn idx(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.n[0] * (y + self.n[1] * z)
    }

    #[inline]
    fn pos(&self, x: usize, y: usize, z: usize) -> DVec3 {
        self.origin + self.h * DVec3::new(x as f64, y as f64, z as f64)
    }

    /// Index offsets of a cell's eight corners from its lowest one (see [`corner`]).
    fn corner_offsets(&self) -> [usize; 8] {
        std::array::from_fn(|c| {
            let o = corner(c);
            self.idx(o[0], o[1], o[2])
        })
    }

    #[inline]
    fn inside(&self, i: usize) -> bool {
        self.values[i] < 0.0
    }
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

/// Cells along each axis of the smallest blocks of [`Blocks`].
const BLOCK_CELLS: usize = 4;

/// Which blocks of [`BLOCK_CELLS`]³ cells of a [`SampleGrid`] must be sampled, for a
/// [`Field::DistanceBound`] function.
///
/// Built top-down: starting from the whole grid, a box of blocks (all its cells' corners)
/// is evaluated at its centre `c` only; when `|f(c)|` exceeds the half-diagonal `r` of the
/// box's points, Lipschitz continuity puts every point `q` of the box on the sign of
/// `f(c)`, with `|f(q)| >= |f(c)| - r`, so the box holds no crossing and its points get that
/// bound as their value. Otherwise the box is split in two along each axis longer than one
/// block, down to single blocks, whose points are all sampled. Every grid cell lies in
/// exactly one block and every corner of a cell in a sampled block is sampled, so the cells
/// with a sign change, and the samples extraction reads around them (corners, ambiguous
/// faces), are those of sampling every point; the far points only keep their sign. Around
/// a surface this samples a shell about 2 √3 blocks thick: a sphere of radius 0.9 in a box
/// of side 2 at 128 cells takes 16% of the full grid's evaluations (`tests/extract.rs`).
struct Blocks {
    /// Blocks per axis (the last may be partial).
    n: [usize; 3],
    /// Per block, x fastest: the value of all its points when it is not sampled (`|f|`
    /// bound with `f`'s sign, never zero), NaN when it is.
    fill: Vec<f32>,
}

impl Blocks {
    /// Every block sampled.
    fn all_sampled() -> Blocks {
        Blocks { n: [1; 3], fill: vec![f32::NAN] }
    }

    fn classify(f: &(impl Fn(DVec3) -> f64 + Sync), grid: &SampleGrid) -> Blocks {
        let cells = grid.n.map(|p| p - 1);
        let n = cells.map(|c| c.div_ceil(BLOCK_CELLS));
        let mut fill = vec![f32::NAN; n[0] * n[1] * n[2]];
        // Boxes of blocks, `[lo, hi)` in block indices.
        let mut level = vec![([0usize; 3], n)];
        let mut far = Vec::new();
        while !level.is_empty() {
            let bounds: Vec<Option<f32>> = level
                .par_iter()
                .map(|&(lo, hi)| {
                    let p0 = grid.origin + grid.h * DVec3::from(lo.map(|b| (b * BLOCK_CELLS) as f64));
                    let p1 = grid.origin
                        + grid.h
                            * DVec3::from(std::array::from_fn(|a| {
                                (hi[a] * BLOCK_CELLS).min(cells[a]) as f64
                            }));
                    let r = 0.5 * p0.distance(p1);
                    let v = f(0.5 * (p0 + p1));
                    // A relative margin for rounding in `f` and in the positions.
                    let margin = r * (1.0 + 1e-9) + 1e-12 * p0.abs().max(p1.abs()).max_element();
                    (v.abs() > margin).then(|| {
                        let b = (v.abs() - r) as f32;
                        if v > 0.0 { b.max(f32::MIN_POSITIVE) } else { -b.max(f32::MIN_POSITIVE) }
                    })
                })
                .collect();
            let mut next = Vec::new();
            for (&(lo, hi), bound) in level.iter().zip(bounds) {
                if let Some(b) = bound {
                    far.push((lo, hi, b));
                    continue;
                }
                // Split each axis longer than one block in two.
                let halves: [Vec<(usize, usize)>; 3] = std::array::from_fn(|a| {
                    let mid = lo[a] + (hi[a] - lo[a]) / 2;
                    if hi[a] - lo[a] > 1 { vec![(lo[a], mid), (mid, hi[a])] } else { vec![(lo[a], hi[a])] }
                });
                if halves.iter().all(|h| h.len() == 1) {
                    continue; // A single block near the surface: sampled.
                }
                for &(z0, z1) in &halves[2] {
                    for &(y0, y1) in &halves[1] {
                        for &(x0, x1) in &halves[0] {
                            next.push(([x0, y0, z0], [x1, y1, z1]));
                        }
                    }
                }
            }
            level = next;
        }
        for (lo, hi, b) in far {
            for z in lo[2]..hi[2] {
                for y in lo[1]..hi[1] {
                    let row = n[0] * (y + n[1] * z);
                    fill[row + lo[0]..row + hi[0]].fill(b);
                }
            }
        }
        Blocks { n, fill }
    }

    /// The blocks along one axis whose points include coordinate `i` (two where `i` is on
    /// a boundary between blocks, else the same one twice).
    #[inline]
    fn along_axis(&self, a: usize, i: usize) -> (usize, usize) {
        if self.n[a] == 1 {
            return (0, 0);
        }
        let b = i / BLOCK_CELLS;
        let own = b.min(self.n[a] - 1);
        (own, if i.is_multiple_of(BLOCK_CELLS) && i > 0 { b - 1 } else { own })
    }

    /// Fills `out` (one entry per block along x) for grid row `(y, z)`: NaN where a block
    /// containing points of the row must be sampled, else a valid value for those points.
    fn row_fill(&self, y: usize, z: usize, out: &mut [f32]) {
        let (y0, y1) = self.along_axis(1, y);
        let (z0, z1) = self.along_axis(2, z);
        let rows = [(y0, z0), (y1, z0), (y0, z1), (y1, z1)];
        for (bx, o) in out.iter_mut().enumerate().take(self.n[0]) {
            *o = self.fill[bx + self.n[0] * (y0 + self.n[1] * z0)];
            for &(by, bz) in &rows[1..] {
                if self.fill[bx + self.n[0] * (by + self.n[1] * bz)].is_nan() {
                    *o = f32::NAN;
                }
            }
        }
    }
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

/// The inside bits of a grid's samples (`< 0`), 64 points of an x-row per word.
struct Signs {
    n: [usize; 3],
    /// Words per row.
    words: usize,
    /// Row `(y, z)` is `bits[(y + n[1] z) words ..][..words]`; bit `x % 64` of word `x / 64`
    /// is point `(x, y, z)`.
    bits: Vec<u64>,
}

impl Signs {
    fn new(grid: &SampleGrid) -> Signs {
        let n = grid.n;
        let words = n[0].div_ceil(64);
        let mut bits = vec![0u64; words * n[1] * n[2]];
        bits.par_chunks_mut(words * n[1]).zip(grid.values.par_chunks(n[0] * n[1])).for_each(|(b, v)| {
            for (brow, vrow) in b.chunks_exact_mut(words).zip(v.chunks_exact(n[0])) {
                for (word, vals) in brow.iter_mut().zip(vrow.chunks(64)) {
                    *word = vals.iter().enumerate().fold(0u64, |w, (k, &s)| w | ((s < 0.0) as u64) << k);
                }
            }
        });
        Signs { n, words, bits }
    }

    #[inline]
    fn row(&self, y: usize, z: usize) -> &[u64] {
        let s = (y + self.n[1] * z) * self.words;
        &self.bits[s..s + self.words]
    }

    /// Calls `visit(x, y, config)` for every cell of the z-slab `z` (cells `(x, y, z)`)
    /// whose corners have both signs, with `config` bit `c` set when [`corner`] `c` is
    /// inside. Eight cells per byte of a row are skipped at once when all their corners
    /// share a sign.
    #[inline]
    fn active_cells(&self, z: usize, mut visit: impl FnMut(usize, usize, u8)) {
        let (n, words) = (self.n, self.words);
        for y in 0..n[1] - 1 {
            let r = [self.row(y, z), self.row(y + 1, z), self.row(y, z + 1), self.row(y + 1, z + 1)];
            for w in 0..words {
                let word = |k: usize| -> (u64, u64) {
                    let any = r[0][k] | r[1][k] | r[2][k] | r[3][k];
                    let all = r[0][k] & r[1][k] & r[2][k] & r[3][k];
                    (any, all)
                };
                let (any, all) = word(w);
                // The same for each cell's upper x corner (bit x + 1).
                let (any_hi, all_hi) = if w + 1 < words {
                    let (a, b) = word(w + 1);
                    ((any >> 1) | (a << 63), (all >> 1) | (b << 63))
                } else {
                    (any >> 1, all >> 1)
                };
                // Cells x < n[0] - 1 only.
                let last = n[0] - 1 - 64 * w;
                let valid = if last >= 64 { u64::MAX } else { (1u64 << last) - 1 };
                let mut active = (any | any_hi) & !(all & all_hi) & valid;
                while active != 0 {
                    let b = active.trailing_zeros() as usize;
                    active &= active - 1;
                    let x = 64 * w + b;
                    let pair = |row: &[u64]| -> u8 {
                        let lo = (row[w] >> b) & 1;
                        let hi = if b < 63 { (row[w] >> (b + 1)) & 1 } else { row[w + 1] & 1 };
                        (lo | hi << 1) as u8
                    };
                    let config = pair(r[0]) | pair(r[1]) << 2 | pair(r[2]) << 4 | pair(r[3]) << 6;
                    visit(x, y, config);
                }
            }
        }
    }
}

/// The grid edges whose samples change sign, for the first `ndirs` of [`DIRS`], and the
/// index of the vertex on each: crossings are numbered by z-slice, then row, direction
/// and x of the edge's lower end, so an edge's vertex index is a prefix count of a row's
/// crossing bits (no hashing, no sort).
struct Crossings {
    n: [usize; 3],
    ndirs: usize,
    words: usize,
    /// Word `((y + n[1] z) ndirs + d) words + x / 64`, bit `x % 64`: the edge from point
    /// `(x, y, z)` in direction `d` changes sign.
    bits: Vec<u64>,
    /// Per word of `bits`: the index of its first crossing.
    base: Vec<u32>,
}

impl Crossings {
    /// Finds the crossing edges and numbers them; `make(p0, v0, p1, v1)` turns each (its
    /// end points and their samples, inside end or not) into an output vertex. Returns
    /// the vertices in index order.
    fn new<T: Copy + Default + Send>(
        grid: &SampleGrid,
        signs: &Signs,
        ndirs: usize,
        make: impl Fn(DVec3, f64, DVec3, f64) -> T + Sync,
    ) -> (Crossings, Vec<T>) {
        let (n, words) = (grid.n, signs.words);
        let per_slice = n[1] * ndirs * words;
        let mut bits = vec![0u64; per_slice * n[2]];
        bits.par_chunks_mut(per_slice).enumerate().for_each(|(z, b)| {
            for y in 0..n[1] {
                let a = signs.row(y, z);
                for (d, o) in DIRS.iter().enumerate().take(ndirs) {
                    if y + o[1] >= n[1] || z + o[2] >= n[2] {
                        continue;
                    }
                    let other = signs.row(y + o[1], z + o[2]);
                    let out = &mut b[(y * ndirs + d) * words..][..words];
                    for w in 0..words {
                        let mut v = other[w];
                        if o[0] == 1 {
                            v = (v >> 1) | other.get(w + 1).map_or(0, |&u| u << 63);
                        }
                        out[w] = a[w] ^ v;
                    }
                    // Edges from points x < n[0] - o[0] only.
                    let limit = n[0] - o[0];
                    let lw = limit / 64;
                    if lw < words {
                        out[lw] &= (1u64 << (limit % 64)) - 1;
                        out[lw + 1..].iter_mut().for_each(|v| *v = 0);
                    }
                }
            }
        });
        let mut base = vec![0u32; bits.len()];
        let mut total = 0u64;
        let mut slice_start = Vec::with_capacity(n[2] + 1);
        for (k, (b, c)) in base.iter_mut().zip(&bits).enumerate() {
            if k % per_slice == 0 {
                slice_start.push(total as usize);
            }
            *b = total as u32;
            total += c.count_ones() as u64;
        }
        slice_start.push(total as usize);
        assert!(total < u32::MAX as u64, "too many vertices for u32 indices");
        let cross = Crossings { n, ndirs, words, bits, base };
        let mut out = vec![T::default(); total as usize];
        // Disjoint output ranges per z-slice.
        let mut parts = Vec::with_capacity(n[2]);
        let mut rest = out.as_mut_slice();
        for z in 0..n[2] {
            let (head, tail) = rest.split_at_mut(slice_start[z + 1] - slice_start[z]);
            parts.push(head);
            rest = tail;
        }
        let offsets: [usize; 7] = std::array::from_fn(|d| grid.idx(DIRS[d][0], DIRS[d][1], DIRS[d][2]));
        parts.into_par_iter().enumerate().for_each(|(z, part)| {
            let mut k = 0;
            for y in 0..n[1] {
                for d in 0..ndirs {
                    let row = &cross.bits[((y + n[1] * z) * ndirs + d) * words..][..words];
                    for (w, &word) in row.iter().enumerate() {
                        let mut m = word;
                        while m != 0 {
                            let x = 64 * w + m.trailing_zeros() as usize;
                            m &= m - 1;
                            let i = grid.idx(x, y, z);
                            let o = DIRS[d];
                            let p0 = grid.pos(x, y, z);
                            let p1 = grid.pos(x + o[0], y + o[1], z + o[2]);
                            part[k] = make(p0, grid.values[i] as f64, p1, grid.values[i + offsets[d]] as f64);
                            k += 1;
                        }
                    }
                }
            }
            debug_assert_eq!(k, part.len());
        });
        (cross, out)
    }

    /// The vertex on the sign-changing edge from point `(x, y, z)` in direction `d`.
    #[inline]
    fn vertex(&self, x: usize, y: usize, z: usize, d: usize) -> u32 {
        let k = ((y + self.n[1] * z) * self.ndirs + d) * self.words + x / 64;
        debug_assert!((self.bits[k] >> (x % 64)) & 1 != 0);
        self.base[k] + (self.bits[k] & ((1u64 << (x % 64)) - 1)).count_ones()
    }

    /// Number of crossings on edges from points of z-slice `z`.
    fn in_slice(&self, z: usize) -> usize {
        let per_slice = self.n[1] * self.ndirs * self.words;
        let next = if z + 1 < self.n[2] {
            self.base[(z + 1) * per_slice] as usize
        } else {
            let last = self.bits.len() - 1;
            self.base[last] as usize + self.bits[last].count_ones() as usize
        };
        next - self.base[z * per_slice] as usize
    }
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

// ---------------------------------------------------------------------------------------
// Marching tetrahedra.

/// Cube corner `c` (0..8) offset: bit 0 = x, bit 1 = y, bit 2 = z.
#[inline]
fn corner(c: usize) -> [usize; 3] {
    [c & 1, (c >> 1) & 1, (c >> 2) & 1]
}

/// The six tetrahedra around the diagonal 0-7: corners 0, e_i, e_i + e_j, 7.
const TETS: [[usize; 4]; 6] =
    [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]];

/// A tet edge as (cube corner of its lower end, direction index into [`DIRS`]).
type TetEdge = (u8, u8);

/// Per tetrahedron and inside mask (bit k = tet corner k inside): triangles as tet edges.
type TetTable = [[Vec<[TetEdge; 3]>; 16]; 6];

fn tet_table() -> TetTable {
    let pos = |c: usize| {
        let o = corner(c);
        DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64)
    };
    std::array::from_fn(|t| {
        let tet = TETS[t];
        std::array::from_fn(|m| {
            // Edge between tet corners a and b (either order): lower corner, direction.
            let edge = |a: usize, b: usize| -> (TetEdge, DVec3) {
                let (ca, cb) = (tet[a.min(b)], tet[a.max(b)]);
                let (oa, ob) = (corner(ca), corner(cb));
                let d = [ob[0] - oa[0], ob[1] - oa[1], ob[2] - oa[2]];
                let dir = DIRS.iter().position(|&x| x == d).expect("tet edge along a grid direction");
                ((ca as u8, dir as u8), 0.5 * (pos(ca) + pos(cb)))
            };
            // Orients the triangle so that its normal points away from `inside_ref` (a
            // point never coplanar with it for any crossing parameter in (0, 1)).
            let tri = |e: [(usize, usize); 3], reference: usize, ref_inside: bool| -> [TetEdge; 3] {
                let [(k0, p0), (k1, p1), (k2, p2)] = e.map(|(a, b)| edge(a, b));
                let r = pos(tet[reference]);
                let s = (p1 - p0).cross(p2 - p0).dot(r - p0);
                // Normal towards an outside reference, away from an inside one.
                if (s < 0.0) == ref_inside { [k0, k1, k2] } else { [k0, k2, k1] }
            };
            let ins: Vec<usize> = (0..4).filter(|k| m & (1 << k) != 0).collect();
            let out: Vec<usize> = (0..4).filter(|k| m & (1 << k) == 0).collect();
            match ins.len() {
                1 => {
                    let a = ins[0];
                    vec![tri([(a, out[0]), (a, out[1]), (a, out[2])], a, true)]
                }
                3 => {
                    let d = out[0];
                    vec![tri([(d, ins[0]), (d, ins[1]), (d, ins[2])], d, false)]
                }
                2 => {
                    let (a, b, c, d) = (ins[0], ins[1], out[0], out[1]);
                    // Quad ac, ad, bd, bc split along ac-bd.
                    vec![tri([(a, c), (a, d), (b, d)], a, true), tri([(a, c), (b, d), (b, c)], b, true)]
                }
                _ => Vec::new(),
            }
        })
    })
}

/// Per cube inside mask (bit c = corner c inside): the triangles of all six tetrahedra,
/// as tet edges, in `tris[start[m]..start[m + 1]]`.
struct CubeTable {
    start: [u16; 257],
    tris: Vec<[TetEdge; 3]>,
}

fn cube_table() -> CubeTable {
    let table = tet_table();
    let mut start = [0u16; 257];
    let mut tris = Vec::new();
    for (cm, s) in start.iter_mut().take(256).enumerate() {
        *s = tris.len() as u16;
        for (t, tet) in TETS.iter().enumerate() {
            let m = tet.iter().enumerate().fold(0, |m, (k, &c)| m | (((cm >> c) & 1) << k));
            tris.extend_from_slice(&table[t][m]);
        }
    }
    start[256] = tris.len() as u16;
    CubeTable { start, tris }
}

fn marching_tetrahedra(f: &(impl Fn(DVec3) -> f64 + Sync), grid: &SampleGrid) -> TriangleMesh {
    let signs = Signs::new(grid);
    let (cross, positions) = Crossings::new(grid, &signs, DIRS.len(), |p0, v0, p1, v1| {
        crossing_point(f, p0, v0, p1, v1).as_vec3()
    });
    let table = cube_table();
    let n = grid.n;
    let per_slab: Vec<Vec<[u32; 3]>> = (0..n[2] - 1)
        .into_par_iter()
        .map(|z| {
            // About two triangles per vertex.
            let mut out = Vec::with_capacity(2 * cross.in_slice(z) + 16);
            signs.active_cells(z, |x, y, cm| {
                let (a, b) = (table.start[cm as usize] as usize, table.start[cm as usize + 1] as usize);
                for tri in &table.tris[a..b] {
                    out.push(tri.map(|(c, d)| {
                        let c = c as usize;
                        cross.vertex(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2), d as usize)
                    }));
                }
            });
            out
        })
        .collect();
    TriangleMesh { positions, triangles: concat(per_slab), normals: None }
}

/// The vectors of `parts` one after another.
fn concat<T: Copy + Send + Sync>(parts: Vec<Vec<T>>) -> Vec<T> {
    let total = parts.iter().map(Vec::len).sum();
    let mut out = Vec::with_capacity(total);
    for p in &parts {
        out.extend_from_slice(p);
    }
    out
}

// ---------------------------------------------------------------------------------------
// Marching cubes.

/// The marching cubes case table: per cube configuration (bit `c` set when [`corner`] `c`
/// is inside) and choice on each ambiguous face, the surface's polygons as cube edges
/// (numbered as in [`CubeTopology`]). Generated, not typed in: the crossings on each face
/// are paired into segments (on a face with four, the pairing is a per-face choice), the
/// segments are oriented and chained into cycles, and each cycle is triangulated. Every
/// mesh edge between vertices on one cube face is then either a segment, which the two
/// cells sharing the face produce alike (same choice, from the face's corner values only)
/// and in opposite directions, or a diagonal, which only the cell below the face may use
/// (diagonals on a cell's lower faces, x, y or z = 0, are never used); every other mesh
/// edge is inside one cell. So the output is closed and edge-manifold by construction.
///
/// Polygons of 4 to 7 vertices list every allowed triangulation; [`marching_cubes`] takes
/// the one that folds least on the actual vertices (a fold the wrong way turns triangles
/// inside out at sharp edges). Larger ones have one (the shortest diagonals between the
/// edges' midpoints). The few cycles that cannot be triangulated without a diagonal on a
/// lower face (they pass twice through two or three lower faces, all ambiguous) get a
/// vertex of their own at the mean of their crossings, fanned to the cycle.
struct McTable {
    /// Per configuration: a bit per ambiguous face (four crossings, corners alternating).
    ambiguous: [u8; 256],
    /// Per configuration: the cube edges that change sign.
    crossing: [u16; 256],
    /// Per configuration: its first case; the case is this plus the choices on its
    /// ambiguous faces, packed in face order.
    first_case: [u16; 257],
    /// Per case: its polygons are `polys[case_start[k]..case_start[k + 1]]`.
    case_start: Vec<u16>,
    polys: Vec<McPolygon>,
    /// Triangles as cube edges; `MC_CENTRE + j` stands for the case's `j`-th cycle
    /// vertex.
    tris: Vec<[u8; 3]>,
    /// Per case: the cube edges (a bit each) of the cycles that get a vertex of their
    /// own, `centres[centre_start[k]..centre_start[k + 1]]`.
    centre_start: Vec<u16>,
    centres: Vec<u16>,
}

/// One polygon of a case: `options` triangulations of `per` triangles each, one after
/// another in [`McTable`]'s triangles from `first`.
#[derive(Clone, Copy, Debug)]
struct McPolygon {
    first: u32,
    options: u8,
    per: u8,
}

/// Index in [`McTable`]'s triangles of the first cycle vertex (after the 12 cube edges).
const MC_CENTRE: u8 = 12;

/// Faces `x = 0`, `y = 0`, `z = 0` of a cell, a bit per face (numbered as in
/// [`CubeTopology`]: `2 axis + side`).
const LOWER_FACES: u8 = 0b01_0101;

/// Polygons up to this many vertices list all their allowed triangulations (42 for 7).
const MC_OPTIONS_UP_TO: usize = 7;

/// The table, built on first use.
fn mc_table() -> &'static McTable {
    static TABLE: std::sync::OnceLock<McTable> = std::sync::OnceLock::new();
    TABLE.get_or_init(McTable::new)
}

/// Every triangulation of the polygon `0..m` as triangles `[i, j, k]` with `i < j < k`.
fn polygon_triangulations(m: usize) -> Vec<Vec<[usize; 3]>> {
    fn between(i: usize, j: usize) -> Vec<Vec<[usize; 3]>> {
        if j < i + 2 {
            return vec![Vec::new()];
        }
        let mut all = Vec::new();
        for k in i + 1..j {
            for left in between(i, k) {
                for right in between(k, j) {
                    let mut t = vec![[i, k, j]];
                    t.extend(&left);
                    t.extend(&right);
                    all.push(t);
                }
            }
        }
        all
    }
    between(0, m - 1)
}

impl McTable {
    fn new() -> McTable {
        let topo = CubeTopology::new();
        let mut table = McTable {
            ambiguous: [0; 256],
            crossing: [0; 256],
            first_case: [0; 257],
            case_start: Vec::new(),
            polys: Vec::new(),
            tris: Vec::new(),
            centre_start: Vec::new(),
            centres: Vec::new(),
        };
        let triangulations: Vec<Vec<Vec<[usize; 3]>>> = (0..=MC_OPTIONS_UP_TO)
            .map(|m| if m >= 3 { polygon_triangulations(m) } else { Vec::new() })
            .collect();
        for config in 0..256usize {
            let inside = |c: usize| (config >> c) & 1 != 0;
            for (k, &(c, d)) in topo.edges.iter().enumerate() {
                if inside(c) != inside(c | 1 << d) {
                    table.crossing[config] |= 1 << k;
                }
            }
            for (fi, (corners, _)) in topo.faces.iter().enumerate() {
                let s = corners.map(inside);
                if s[0] == s[2] && s[1] == s[3] && s[0] != s[1] {
                    table.ambiguous[config] |= 1 << fi;
                }
            }
            table.first_case[config] = table.case_start.len() as u16;
            let faces: Vec<usize> = (0..6).filter(|fi| table.ambiguous[config] & (1 << fi) != 0).collect();
            for choice in 0..1usize << faces.len() {
                // Bit set: the face's centre counts as inside (its positive corners are cut
                // off), else its negative corners are cut off.
                let centre_inside =
                    faces.iter().enumerate().fold(0u8, |m, (j, &fi)| m | (((choice >> j) & 1) as u8) << fi);
                table.case_start.push(table.polys.len() as u16);
                table.centre_start.push(table.centres.len() as u16);
                for cycle in Self::cycles(&topo, config, centre_inside) {
                    table.add_cycle(&topo, &cycle, &triangulations);
                }
            }
        }
        table.first_case[256] = table.case_start.len() as u16;
        table.case_start.push(table.polys.len() as u16);
        table.centre_start.push(table.centres.len() as u16);
        table
    }

    /// The surface's cycles of `config` with the ambiguous faces' centres inside where
    /// `centre_inside` has their bit, as cube edges in counter-clockwise order seen from
    /// outside.
    fn cycles(topo: &CubeTopology, config: usize, centre_inside: u8) -> Vec<Vec<usize>> {
        let inside = |c: usize| (config >> c) & 1 != 0;
        // Oriented segments: next[a] = b. A segment a -> b on a face with outward normal
        // `nf` that cuts off corner `c` runs so that `(nf x (b - a)) . (c - a)` is negative
        // for an inside `c` (the surface's normal points to positive `f`, and the polygon
        // turns counter-clockwise about it).
        let mut next = [usize::MAX; 12];
        let mut link = |nf: DVec3, a: usize, b: usize, c: usize| {
            let s = nf.cross(edge_mid(topo, b) - edge_mid(topo, a)).dot(corner_pos(c) - edge_mid(topo, a));
            let (a, b) = if (s < 0.0) == inside(c) { (a, b) } else { (b, a) };
            assert_eq!(next[a], usize::MAX, "config {config}: edge {a} starts two segments");
            next[a] = b;
        };
        for (fi, (corners, fe)) in topo.faces.iter().enumerate() {
            let mut nf = DVec3::ZERO;
            nf[fi / 2] = if fi % 2 == 1 { 1.0 } else { -1.0 };
            let on: Vec<usize> =
                (0..4).filter(|&i| inside(corners[i]) != inside(corners[(i + 1) % 4])).collect();
            match on.len() {
                2 => {
                    // Any inside corner of the face lies on the inside of the segment.
                    let c = corners.iter().copied().find(|&c| inside(c)).expect("a face with a crossing");
                    link(nf, fe[on[0]], fe[on[1]], c);
                }
                4 => {
                    // Corner i is cut off by the segment from edge i - 1 to edge i.
                    let cut_inside = centre_inside & (1 << fi) == 0;
                    for i in (0..4).filter(|&i| inside(corners[i]) == cut_inside) {
                        link(nf, fe[(i + 3) % 4], fe[i], corners[i]);
                    }
                }
                _ => {}
            }
        }
        let mut cycles = Vec::new();
        let mut seen = 0u16;
        for start in 0..12 {
            if next[start] == usize::MAX || seen & (1 << start) != 0 {
                continue;
            }
            let mut cycle = Vec::new();
            let mut k = start;
            while seen & (1 << k) == 0 {
                seen |= 1 << k;
                cycle.push(k);
                k = next[k];
                assert_ne!(k, usize::MAX, "config {config}: open chain");
            }
            assert_eq!(k, start, "config {config}: chains merge");
            cycles.push(cycle);
        }
        cycles
    }

    /// Adds the triangulations of `cycle` to the current case.
    fn add_cycle(&mut self, topo: &CubeTopology, cycle: &[usize], triangulations: &[Vec<Vec<[usize; 3]>>]) {
        let m = cycle.len();
        // Whether the diagonal between cycle vertices i and j may be used (see the type).
        let allowed = |i: usize, j: usize| {
            let adjacent = j == i + 1 || (i == 0 && j == m - 1);
            adjacent || edge_faces(topo, cycle[i]) & edge_faces(topo, cycle[j]) & LOWER_FACES == 0
        };
        let ok =
            |t: &[[usize; 3]]| t.iter().all(|&[i, j, k]| allowed(i, j) && allowed(j, k) && allowed(i, k));
        let first = self.tris.len() as u32;
        let push = |tris: &mut Vec<[u8; 3]>, t: &[[usize; 3]]| {
            tris.extend(t.iter().map(|tri| tri.map(|i| cycle[i] as u8)));
        };
        let options: Vec<&Vec<[usize; 3]>> = if m <= MC_OPTIONS_UP_TO {
            triangulations[m].iter().filter(|t| ok(t)).collect()
        } else {
            Vec::new()
        };
        if !options.is_empty() {
            for t in &options {
                push(&mut self.tris, t);
            }
            self.polys.push(McPolygon { first, options: options.len() as u8, per: (m - 2) as u8 });
            return;
        }
        // One triangulation: the shortest allowed diagonals between the edges' midpoints
        // (dynamic programming over the polygon's sub-chains).
        let chord = |i: usize, j: usize| -> f64 {
            if !allowed(i, j) {
                1e9
            } else if j == i + 1 || (i == 0 && j == m - 1) {
                0.0
            } else {
                (edge_mid(topo, cycle[i]) - edge_mid(topo, cycle[j])).length()
            }
        };
        let mut cost = vec![vec![0.0f64; m]; m];
        let mut split = vec![vec![0usize; m]; m];
        for len in 2..m {
            for i in 0..m - len {
                let j = i + len;
                let (best, at) = (i + 1..j)
                    .map(|k| (cost[i][k] + cost[k][j] + chord(i, k) + chord(k, j), k))
                    .fold((f64::INFINITY, 0), |b, c| if c.0 < b.0 { c } else { b });
                cost[i][j] = best;
                split[i][j] = at;
            }
        }
        if cost[0][m - 1] < 1e9 {
            let mut t = Vec::new();
            let mut stack = vec![(0, m - 1)];
            while let Some((i, j)) = stack.pop() {
                if j >= i + 2 {
                    let k = split[i][j];
                    t.push([i, k, j]);
                    stack.push((i, k));
                    stack.push((k, j));
                }
            }
            push(&mut self.tris, &t);
            self.polys.push(McPolygon { first, options: 1, per: (m - 2) as u8 });
        } else {
            // A fan around a vertex of the cycle's own.
            let case = self.case_start.len() - 1;
            let c = MC_CENTRE + (self.centres.len() - self.centre_start[case] as usize) as u8;
            self.centres.push(cycle.iter().fold(0u16, |mask, &k| mask | 1 << k));
            for i in 0..m {
                self.tris.push([cycle[i] as u8, cycle[(i + 1) % m] as u8, c]);
            }
            self.polys.push(McPolygon { first, options: 1, per: m as u8 });
        }
    }

    /// The case of a cell with inside bits `config` and corner samples `values` (read
    /// only when the configuration has an ambiguous face).
    #[inline]
    fn case(&self, topo: &CubeTopology, config: u8, values: impl FnOnce() -> [f32; 8]) -> usize {
        let c = config as usize;
        let mut case = self.first_case[c] as usize;
        let amb = self.ambiguous[c];
        if amb != 0 {
            let v = values();
            let mut j = 0;
            for (fi, (corners, _)) in topo.faces.iter().enumerate() {
                if amb & (1 << fi) != 0 {
                    let [a, b, c, d] = corners.map(|k| v[k] as f64);
                    if face_centre_inside(a, b, c, d) {
                        case += 1 << j;
                    }
                    j += 1;
                }
            }
        }
        case
    }

    /// The polygons of `case`.
    #[inline]
    fn polygons(&self, case: usize) -> &[McPolygon] {
        &self.polys[self.case_start[case] as usize..self.case_start[case + 1] as usize]
    }

    /// The triangles of option `o` of polygon `p`.
    #[inline]
    fn option(&self, p: McPolygon, o: usize) -> &[[u8; 3]] {
        let start = p.first as usize + o * p.per as usize;
        &self.tris[start..start + p.per as usize]
    }

    /// The cycles of `case` that get a vertex of their own (cube edges, a bit each).
    #[inline]
    fn centres(&self, case: usize) -> &[u16] {
        &self.centres[self.centre_start[case] as usize..self.centre_start[case + 1] as usize]
    }
}

/// Position of cube corner `c` in the unit cube.
fn corner_pos(c: usize) -> DVec3 {
    let o = corner(c);
    DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64)
}

/// Midpoint of cube edge `k` in the unit cube.
fn edge_mid(topo: &CubeTopology, k: usize) -> DVec3 {
    let (c, d) = topo.edges[k];
    corner_pos(c) + 0.5 * corner_pos(1 << d)
}

/// The faces of cube edge `k` (a bit per face; none for a cycle's own vertex).
fn edge_faces(topo: &CubeTopology, k: usize) -> u8 {
    if k >= MC_CENTRE as usize {
        return 0;
    }
    let (c, d) = topo.edges[k];
    let (u, w) = ((d + 1) % 3, (d + 2) % 3);
    1 << (2 * u + ((c >> u) & 1)) | 1 << (2 * w + ((c >> w) & 1))
}

/// How little the triangles `tris` (vertex indices into `pos`) fold: the smallest cosine
/// between two of their normals; -2 when one is degenerate.
#[inline]
fn flatness(pos: &[Vec3], tris: &[[u32; 3]]) -> f64 {
    if let [t0, t1] = tris {
        // A quadrilateral: one cosine, one square root.
        let normal = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|i| pos[i as usize].as_dvec3());
            (b - a).cross(c - a)
        };
        let (n0, n1) = (normal(t0), normal(t1));
        let c = n0.dot(n1) / (n0.length_squared() * n1.length_squared()).sqrt();
        return if c.is_finite() { c } else { -2.0 };
    }
    let mut normals = [DVec3::ZERO; MC_OPTIONS_UP_TO - 2];
    for (n, t) in normals.iter_mut().zip(tris) {
        let [a, b, c] = t.map(|i| pos[i as usize].as_dvec3());
        *n = (b - a).cross(c - a);
        let len = n.length();
        if !(len > 0.0) {
            return -2.0;
        }
        *n /= len;
    }
    let normals = &normals[..tris.len()];
    let mut worst = 1.0f64;
    for (i, a) in normals.iter().enumerate() {
        for b in &normals[i + 1..] {
            worst = worst.min(a.dot(*b));
        }
    }
    worst
}

/// The asymptotic decider: whether the centre of a face with corner samples `a, b, c, d`
/// (in cyclic order, `a`, `c` of one sign and `b`, `d` of the other) is inside, by the
/// sign of the bilinear interpolant at its saddle. Symmetric under rotating and
/// reversing the corners, so both cells sharing the face decide alike.
#[inline]
fn face_centre_inside(a: f64, b: f64, c: f64, d: f64) -> bool {
    let den = a + c - b - d;
    let saddle = if den != 0.0 { (a * c - b * d) / den } else { 0.25 * (a + b + c + d) };
    saddle < 0.0
}

fn marching_cubes(f: &(impl Fn(DVec3) -> f64 + Sync), grid: &SampleGrid) -> (TriangleMesh, bool) {
    let signs = Signs::new(grid);
    let (cross, mut positions) =
        Crossings::new(grid, &signs, 3, |p0, v0, p1, v1| crossing_point(f, p0, v0, p1, v1).as_vec3());
    let table = mc_table();
    let topo = CubeTopology::new();
    let n = grid.n;
    let corner_offsets = grid.corner_offsets();
    // Cycle vertices get indices from `CYCLE_VERTEX` up in their slab until the end.
    const CYCLE_VERTEX: u32 = 1 << 31;
    assert!(positions.len() < CYCLE_VERTEX as usize, "too many vertices");
    let per_slab: Vec<(Vec<[u32; 3]>, Vec<Vec3>)> = (0..n[2] - 1)
        .into_par_iter()
        .map(|z| {
            // About two triangles per vertex.
            let mut out = Vec::with_capacity(2 * cross.in_slice(z) + 16);
            let mut extra = Vec::new();
            let mut scratch = [[0u32; 3]; MC_OPTIONS_UP_TO - 2];
            signs.active_cells(z, |x, y, config| {
                let mut ids = [0u32; 12 + 4];
                let mut m = table.crossing[config as usize];
                while m != 0 {
                    let k = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let (c, d) = topo.edges[k];
                    ids[k] = cross.vertex(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2), d);
                }
                let values = || {
                    let i = grid.idx(x, y, z);
                    corner_offsets.map(|o| grid.values[i + o])
                };
                let case = table.case(&topo, config, values);
                for (j, &cycle) in table.centres(case).iter().enumerate() {
                    let mut sum = DVec3::ZERO;
                    let mut m = cycle;
                    while m != 0 {
                        sum += positions[ids[m.trailing_zeros() as usize] as usize].as_dvec3();
                        m &= m - 1;
                    }
                    ids[MC_CENTRE as usize + j] = CYCLE_VERTEX + extra.len() as u32;
                    extra.push((sum / cycle.count_ones() as f64).as_vec3());
                }
                for &p in table.polygons(case) {
                    let mut best = 0;
                    if p.options > 1 {
                        let mut top = f64::NEG_INFINITY;
                        let tris = &mut scratch[..p.per as usize];
                        for o in 0..p.options as usize {
                            for (t, e) in tris.iter_mut().zip(table.option(p, o)) {
                                *t = e.map(|k| ids[k as usize]);
                            }
                            let s = flatness(&positions, tris);
                            if s > top {
                                (top, best) = (s, o);
                            }
                        }
                    }
                    out.extend(table.option(p, best).iter().map(|t| t.map(|k| ids[k as usize])));
                }
            });
            (out, extra)
        })
        .collect();
    let mut next = positions.len() as u32;
    let mut parts = Vec::with_capacity(per_slab.len());
    let cycle_vertices = per_slab.iter().any(|(_, e)| !e.is_empty());
    for (mut tris, extra) in per_slab {
        if !extra.is_empty() {
            for t in &mut tris {
                t.iter_mut().filter(|i| **i >= CYCLE_VERTEX).for_each(|i| *i = *i - CYCLE_VERTEX + next);
            }
            next += extra.len() as u32;
            positions.extend(extra);
        }
        parts.push(tris);
    }
    (TriangleMesh { positions, triangles: concat(parts), normals: None }, !cycle_vertices)
}

// ---------------------------------------------------------------------------------------
// Dual contouring.

/// The cube's 12 edges and 6 faces, for splitting a cell's surface into components.
struct CubeTopology {
    /// Edge `k` as (lower corner, axis); `k = 4 * axis + bit_u + 2 * bit_w` where
    /// `u = (axis + 1) % 3`, `w = (axis + 2) % 3` and the bits are the corner's offsets.
    edges: [(usize, usize); 12],
    /// Per face: its corners in cyclic order and the edges between consecutive corners
    /// (`edges[i]` joins `corners[i]` and `corners[(i + 1) % 4]`).
    faces: [([usize; 4], [usize; 4]); 6],
}

impl CubeTopology {
    fn new() -> Self {
        let edges: [(usize, usize); 12] = std::array::from_fn(|k| {
            let d = k / 4;
            let (u, w) = ((d + 1) % 3, (d + 2) % 3);
            (((k & 1) << u) | (((k >> 1) & 1) << w), d)
        });
        let faces = std::array::from_fn(|fi| {
            let (a, side) = (fi / 2, fi % 2);
            let (u, w) = ((a + 1) % 3, (a + 2) % 3);
            let corners: [usize; 4] =
                [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(bu, bw)| (side << a) | (bu << u) | (bw << w));
            let face_edges = std::array::from_fn(|i| {
                let (c0, c1) = (corners[i], corners[(i + 1) % 4]);
                let (lo, d) = (c0 & c1, (c0 ^ c1).trailing_zeros() as usize);
                edges.iter().position(|&e| e == (lo, d)).expect("face edge is a cube edge")
            });
            (corners, face_edges)
        });
        CubeTopology { edges, faces }
    }

    /// Labels the cell's sign-changing edges by surface component (0, 1, ...; `u8::MAX`
    /// for edges without a crossing) and returns the number of components. Crossings on a
    /// face are paired; on a face with four crossings the pairing follows the sign of the
    /// bilinear interpolant's saddle (the asymptotic decider), which both cells sharing
    /// the face agree on.
    ///
    /// Faces whose bit is set in `flip` take the other pairing. Also returns a bit per face
    /// with four crossings whose two pairs ended up in the same component.
    fn components(&self, values: &[f32; 8], crossing: u16, flip: u8) -> ([u8; 12], u8, u8) {
        let mut parent: [u8; 12] = std::array::from_fn(|k| k as u8);
        fn find(p: &mut [u8; 12], mut k: u8) -> u8 {
            while p[k as usize] != k {
                p[k as usize] = p[p[k as usize] as usize];
                k = p[k as usize];
            }
            k
        }
        let union = |p: &mut [u8; 12], a: usize, b: usize| {
            let (ra, rb) = (find(p, a as u8), find(p, b as u8));
            p[ra as usize] = rb;
        };
        let mut ambiguous = [None; 6];
        for (fi, (corners, fe)) in self.faces.iter().enumerate() {
            let (mut on, mut len) = ([0usize; 4], 0);
            for (i, &e) in fe.iter().enumerate() {
                if crossing & (1 << e) != 0 {
                    on[len] = i;
                    len += 1;
                }
            }
            match len {
                2 => union(&mut parent, fe[on[0]], fe[on[1]]),
                4 => {
                    let [a, b, c, d] = corners.map(|k| values[k] as f64);
                    let den = a + c - b - d;
                    let saddle = if den != 0.0 { (a * c - b * d) / den } else { 0.25 * (a + b + c + d) };
                    // Corner i is cut off by the segment joining edges i - 1 and i. Cut off
                    // the corners on the side the saddle is not on.
                    let centre_inside = saddle < 0.0;
                    let first_inside = a < 0.0;
                    // Cut off corners 0 and 2 when they are the lone side, else 1 and 3.
                    let cut_even = (first_inside != centre_inside) != (flip & (1 << fi) != 0);
                    let s = if cut_even { 0 } else { 1 };
                    union(&mut parent, fe[(s + 3) % 4], fe[s]);
                    union(&mut parent, fe[s + 1], fe[s + 2]);
                    ambiguous[fi] = Some((fe[s], fe[s + 1]));
                }
                _ => {}
            }
        }
        let mut merged = 0u8;
        for (fi, a) in ambiguous.iter().enumerate() {
            if let Some((e0, e1)) = *a
                && find(&mut parent, e0 as u8) == find(&mut parent, e1 as u8)
            {
                merged |= 1 << fi;
            }
        }
        let mut labels = [u8::MAX; 12];
        let mut root_label = [u8::MAX; 12];
        let mut count = 0u8;
        for (k, label) in labels.iter_mut().enumerate() {
            if crossing & (1 << k) != 0 {
                let r = find(&mut parent, k as u8) as usize;
                if root_label[r] == u8::MAX {
                    root_label[r] = count;
                    count += 1;
                }
                *label = root_label[r];
            }
        }
        (labels, count, merged)
    }
}

/// The mesh, and whether every active cell got exactly one vertex.
fn dual_contouring(f: &(impl Fn(DVec3) -> f64 + Sync), grid: &SampleGrid) -> TriangleMesh {
    let signs = Signs::new(grid);
    let eps = 0.01 * grid.h;
    let (cross, crossings) = Crossings::new(grid, &signs, 3, |p0, v0, p1, v1| {
        let p = crossing_point(f, p0, v0, p1, v1);
        (p, gradient(f, p, eps))
    });
    let n = grid.n;
    let nc = [n[0] - 1, n[1] - 1, n[2] - 1];
    let cidx = |x: usize, y: usize, z: usize| x + nc[0] * (y + nc[1] * z);
    let cslice = nc[0] * nc[1];
    let corner_offsets = grid.corner_offsets();
    let topo = CubeTopology::new();
    // A cell's corner samples and which of its 12 edges change sign.
    let config = |i0: usize| -> ([f32; 8], u16) {
        let values = corner_offsets.map(|o| grid.values[i0 + o]);
        let mut crossing = 0u16;
        for (k, &(c, d)) in topo.edges.iter().enumerate() {
            if (values[c] < 0.0) != (values[c | 1 << d] < 0.0) {
                crossing |= 1 << k;
            }
        }
        (values, crossing)
    };
    // Per cell: index of its first vertex and its edges' component labels (2 bits each).
    let mut cell_vertex = vec![u32::MAX; nc[0] * nc[1] * nc[2]];
    let mut cell_labels = vec![0u32; cell_vertex.len()];
    let per_slab: Vec<(Vec<DVec3>, usize)> = cell_vertex
        .par_chunks_mut(cslice)
        .zip(cell_labels.par_chunks_mut(cslice))
        .enumerate()
        .map(|(z, (cv, cl))| {
            let mut verts = Vec::new();
            let mut cells = 0;
            signs.active_cells(z, |x, y, _| {
                cells += 1;
                let i0 = grid.idx(x, y, z);
                let (values, crossing) = config(i0);
                let (mut labels, mut count, merged) = topo.components(&values, crossing, 0);
                if merged != 0 {
                    // An ambiguous face whose two sheets this cell joins into one
                    // component: if the neighbour across it joins them too, the dual edge
                    // between the two cells would be used four times. Both cells then
                    // flip that face's pairing (each decides from the default pairings of
                    // both, so they agree), which splits the components.
                    let mut flip = 0u8;
                    for fi in (0..6).filter(|fi| merged & (1 << fi) != 0) {
                        let stride = [1, n[0], n[0] * n[1]][fi / 2];
                        let nb = if fi % 2 == 1 { i0 + stride } else { i0 - stride };
                        let (nv, nc) = config(nb);
                        if topo.components(&nv, nc, 0).2 & (1 << (fi ^ 1)) != 0 {
                            flip |= 1 << fi;
                        }
                    }
                    if flip != 0 {
                        (labels, count, _) = topo.components(&values, crossing, flip);
                    }
                }
                let mut qefs = [Qef::default(), Qef::default(), Qef::default(), Qef::default()];
                let mut packed = 0u32;
                for (k, &(c, d)) in topo.edges.iter().enumerate() {
                    if labels[k] != u8::MAX {
                        let v = cross.vertex(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2), d) as usize;
                        let (p, nrm) = crossings[v];
                        qefs[labels[k] as usize].add(p, nrm);
                        packed |= (labels[k] as u32) << (2 * k);
                    }
                }
                let lo = grid.pos(x, y, z);
                let margin = DVec3::splat(EDGE_MARGIN * grid.h);
                cv[x + nc[0] * y] = verts.len() as u32;
                cl[x + nc[0] * y] = packed;
                for q in &qefs[..count as usize] {
                    let (mut v, rank) = q.solve();
                    if rank < 3 {
                        // Curved sheet or crease: halfway to the surface along the mean
                        // normal (see SMOOTH_PULL).
                        let d = f(v);
                        if d.is_finite() {
                            v -= q.normals.normalize_or_zero() * (SMOOTH_PULL * d);
                        }
                    }
                    let reach = DVec3::splat(DC_REACH * grid.h);
                    let (vlo, vhi) = (lo - reach + margin, lo + DVec3::splat(grid.h) + reach - margin);
                    if v.cmplt(vlo).any() || v.cmpgt(vhi).any() {
                        // Far outside the cell (a sharp feature through cells without a
                        // sign change): the best QEF point within reach instead of the
                        // nearest one, which leaves a crease line.
                        v = q.solve_in_box(v, vlo, vhi);
                    }
                    verts.push(v.clamp(vlo, vhi));
                }
            });
            (verts, cells)
        })
        .collect();
    drop(crossings);
    let mut offsets = Vec::with_capacity(per_slab.len());
    let mut total = 0usize;
    let mut cells = 0usize;
    for (v, c) in &per_slab {
        offsets.push(total as u32);
        total += v.len();
        cells += c;
    }
    assert!(total < u32::MAX as usize, "too many vertices for u32 indices");
    cell_vertex.par_chunks_mut(cslice).zip(offsets.par_iter()).for_each(|(cv, &off)| {
        cv.iter_mut().filter(|v| **v != u32::MAX).for_each(|v| *v += off);
    });
    let positions: Vec<Vec3> = per_slab.into_iter().flat_map(|(v, _)| v).map(|p| p.as_vec3()).collect();

    // A quad across every sign-changing cube edge, over the four cells around it.
    let per_slice: Vec<Vec<[u32; 3]>> = (0..n[2])
        .into_par_iter()
        .map(|z| {
            let mut out = Vec::with_capacity(2 * cross.in_slice(z));
            for y in 0..n[1] {
                for d in 0..3 {
                    let row = &cross.bits[((y + n[1] * z) * 3 + d) * cross.words..][..cross.words];
                    for (w, &word) in row.iter().enumerate() {
                        let mut m = word;
                        while m != 0 {
                            let x = 64 * w + m.trailing_zeros() as usize;
                            m &= m - 1;
                            let p = [x, y, z];
                            // Cells around the edge, counter-clockwise about +d; in each,
                            // the edge's local index is 4 d + (1 - du) + 2 (1 - dw). Edges
                            // on the grid's faces never change sign, so all four exist.
                            let (u, w) = ((d + 1) % 3, (d + 2) % 3);
                            let cell = |du: usize, dw: usize| {
                                let mut c = p;
                                c[u] -= 1 - du;
                                c[w] -= 1 - dw;
                                let ci = cidx(c[0], c[1], c[2]);
                                let k = 4 * d + (1 - du) + 2 * (1 - dw);
                                debug_assert!(cell_vertex[ci] != u32::MAX);
                                cell_vertex[ci] + ((cell_labels[ci] >> (2 * k)) & 3)
                            };
                            let mut q = [cell(0, 0), cell(1, 0), cell(1, 1), cell(0, 1)];
                            let mut axis = DVec3::ZERO;
                            axis[d] = 1.0;
                            if !grid.inside(grid.idx(x, y, z)) {
                                q.reverse();
                                axis = -axis;
                            }
                            out.extend(split_quad(f, &positions, q, axis, 1e-4 * grid.h));
                        }
                    }
                }
            }
            out
        })
        .collect();
    TriangleMesh { positions, triangles: concat(per_slice), normals: None }
}

/// Splits the quad `q` (counter-clockwise about `axis`, the outward direction) into two
/// triangles: along a diagonal whose triangles face outwards (never a degenerate triangle
/// when the other diagonal avoids one), of those the one whose midpoint is closer to the
/// surface (`|f|` smaller by more than `tol`), else the one that folds least.
fn split_quad(f: &impl Fn(DVec3) -> f64, pos: &[Vec3], q: [u32; 4], axis: DVec3, tol: f64) -> [[u32; 3]; 2] {
    let options = [[[q[0], q[1], q[2]], [q[0], q[2], q[3]]], [[q[0], q[1], q[3]], [q[1], q[2], q[3]]]];
    let score = |tris: &[[u32; 3]; 2]| -> (u8, f64) {
        let mut normals = [DVec3::ZERO; 2];
        let mut facing = 0u8;
        for (k, t) in tris.iter().enumerate() {
            let [a, b, c] = t.map(|i| pos[i as usize]);
            if is_degenerate(a, b, c) {
                return (0, f64::NEG_INFINITY);
            }
            let [a, b, c] = [a, b, c].map(|v| v.as_dvec3());
            normals[k] = (b - a).cross(c - a).normalize_or_zero();
            facing += (normals[k].dot(axis) > 0.0) as u8;
        }
        (1 + facing, normals[0].dot(normals[1]))
    };
    let (s0, s1) = (score(&options[0]), score(&options[1]));
    if s0.0 != s1.0 {
        return if s1.0 > s0.0 { options[1] } else { options[0] };
    }
    let mid = |a: u32, b: u32| f(0.5 * (pos[a as usize].as_dvec3() + pos[b as usize].as_dvec3())).abs();
    let (m0, m1) = (mid(q[0], q[2]), mid(q[1], q[3]));
    if m1 + tol < m0 {
        options[1]
    } else if m0 + tol < m1 {
        options[0]
    } else if s1.1 > s0.1 {
        options[1]
    } else {
        options[0]
    }
}

/// Accumulated quadratic error `sum (n_i . (x - p_i))^2` and the crossings' mass point.
#[derive(Default)]
struct Qef {
    ata: [[f64; 3]; 3],
    atb: DVec3,
    count: u32,
    /// Sum of the crossing points (a zero normal adds to the mass point only).
    points: DVec3,
    /// Sum of the normals.
    normals: DVec3,
}

impl Qef {
    fn add(&mut self, p: DVec3, n: DVec3) {
        self.points += p;
        self.normals += n;
        self.count += 1;
        for r in 0..3 {
            for c in 0..3 {
                self.ata[r][c] += n[r] * n[c];
            }
        }
        self.atb += n * n.dot(p);
    }

    /// The minimiser closest to the mass point, with eigenvalues below
    /// [`QEF_TRUNCATION`] times the largest treated as zero, and the number of
    /// eigenvalues kept (the rank: 1 on a smooth sheet, 2 along a crease, 3 at a corner).
    fn solve(&self) -> (DVec3, u8) {
        let c = self.points / self.count.max(1) as f64;
        let a = self.ata;
        let ac = DVec3::new(
            a[0][0] * c.x + a[0][1] * c.y + a[0][2] * c.z,
            a[1][0] * c.x + a[1][1] * c.y + a[1][2] * c.z,
            a[2][0] * c.x + a[2][1] * c.y + a[2][2] * c.z,
        );
        let rhs = self.atb - ac;
        let mut x = c;
        let mut rank = 0u8;
        if let Some((dx, r)) = truncated_solve(a, rhs) {
            x += dx;
            rank = r;
        } else {
            let (vals, vecs) = sym_eigen(a);
            let max = vals.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if max > 0.0 {
                for k in 0..3 {
                    if vals[k] > QEF_TRUNCATION * max {
                        x += vecs[k] * (vecs[k].dot(rhs) / vals[k]);
                        rank += 1;
                    }
                }
            }
        }
        if x.is_finite() { (x, rank) } else { (c, 0) }
    }
}

impl Qef {
    /// The minimiser within the box `[lo, hi]` of the quadratic error plus
    /// [`QEF_BOX_REGULARISATION`] times the trace times `|x - target|²` (strictly convex, so
    /// the minimiser is unique and near `target` along directions the error leaves free,
    /// such as a crease line). Exact: every assignment of each coordinate to free, `lo` or
    /// `hi` (27) is solved for its free coordinates, and the feasible candidate with the
    /// least value is the minimiser. `target` clamped when nothing better is found.
    fn solve_in_box(&self, target: DVec3, lo: DVec3, hi: DVec3) -> DVec3 {
        let a = self.ata;
        let mu = QEF_BOX_REGULARISATION * (a[0][0] + a[1][1] + a[2][2]);
        if !(mu > 0.0) {
            return target.clamp(lo, hi);
        }
        // Value up to a constant: x'Ax - 2 b'x + mu |x - t|², with b the QEF's right side.
        let value = |x: DVec3| {
            let ax = DVec3::new(
                a[0][0] * x.x + a[0][1] * x.y + a[0][2] * x.z,
                a[1][0] * x.x + a[1][1] * x.y + a[1][2] * x.z,
                a[2][0] * x.x + a[2][1] * x.y + a[2][2] * x.z,
            );
            x.dot(ax) - 2.0 * self.atb.dot(x) + mu * (x - target).length_squared()
        };
        let mut best = target.clamp(lo, hi);
        let mut best_value = value(best);
        for combo in 0..27u32 {
            // Per coordinate: 0 free, 1 at lo, 2 at hi.
            let state = [combo % 3, combo / 3 % 3, combo / 9];
            let mut x = DVec3::ZERO;
            let mut free = [0usize; 3];
            let mut nfree = 0;
            for i in 0..3 {
                match state[i] {
                    0 => {
                        free[nfree] = i;
                        nfree += 1;
                    }
                    1 => x[i] = lo[i],
                    _ => x[i] = hi[i],
                }
            }
            // (A + mu I) x = b + mu t on the free coordinates, the fixed ones moved right.
            let mut m = [[0.0f64; 3]; 3];
            let mut r = [0.0f64; 3];
            for (u, &i) in free[..nfree].iter().enumerate() {
                r[u] = self.atb[i] + mu * target[i];
                for j in 0..3 {
                    if state[j] != 0 {
                        r[u] -= a[i][j] * x[j];
                    }
                }
                for (w, &j) in free[..nfree].iter().enumerate() {
                    m[u][w] = a[i][j] + if i == j { mu } else { 0.0 };
                }
            }
            let Some(sol) = solve_small(&m, &r, nfree) else { continue };
            for (u, &i) in free[..nfree].iter().enumerate() {
                x[i] = sol[u];
            }
            if x.cmpge(lo).all() && x.cmple(hi).all() {
                let v = value(x);
                if v < best_value {
                    (best, best_value) = (x, v);
                }
            }
        }
        best
    }
}

/// Solves the leading `n`×`n` block of `m` (symmetric positive definite) for `r` by
/// Gaussian elimination; `None` when a pivot is not positive.
fn solve_small(m: &[[f64; 3]; 3], r: &[f64; 3], n: usize) -> Option<[f64; 3]> {
    let (mut m, mut r) = (*m, *r);
    for k in 0..n {
        if !(m[k][k] > 0.0) {
            return None;
        }
        for i in k + 1..n {
            let (f, mk) = (m[i][k] / m[k][k], m[k]);
            for (mij, mkj) in m[i][k..n].iter_mut().zip(&mk[k..n]) {
                *mij -= f * mkj;
            }
            r[i] -= f * r[k];
        }
    }
    let mut x = [0.0f64; 3];
    for k in (0..n).rev() {
        let s: f64 = (k + 1..n).map(|j| m[k][j] * x[j]).sum();
        x[k] = (r[k] - s) / m[k][k];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// `A⁺ rhs` of the symmetric positive semi-definite `a` with eigenvalues at or below
/// [`QEF_TRUNCATION`] times the largest treated as zero, by closed-form eigenvalues
/// (trigonometric method) and eigenvectors of isolated eigenvalues (cross products of
/// the rows of `a - lambda I`). `None` when an eigenvalue is within 20% of the threshold
/// or the matrix is not positive (then [`sym_eigen`] decides). The same result as the
/// truncated sum over [`sym_eigen`]'s eigenpairs up to rounding, at under half the cost.
fn truncated_solve(a: [[f64; 3]; 3], rhs: DVec3) -> Option<(DVec3, u8)> {
    let p1 = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    let q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
    let (d0, d1, d2) = (a[0][0] - q, a[1][1] - q, a[2][2] - q);
    let p = ((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1) / 6.0).sqrt();
    if !(q > 0.0) || !p.is_finite() {
        return None;
    }
    if p <= 1e-12 * q {
        // A multiple of the identity (up to rounding): every eigenvalue is kept.
        return Some((rhs / q, 3));
    }
    // B = (A - q I) / p; r = det(B) / 2.
    let b = [
        [d0 / p, a[0][1] / p, a[0][2] / p],
        [a[0][1] / p, d1 / p, a[1][2] / p],
        [a[0][2] / p, a[1][2] / p, d2 / p],
    ];
    let det = b[0][0] * (b[1][1] * b[2][2] - b[1][2] * b[2][1])
        - b[0][1] * (b[1][0] * b[2][2] - b[1][2] * b[2][0])
        + b[0][2] * (b[1][0] * b[2][1] - b[1][1] * b[2][0]);
    let phi = (0.5 * det).clamp(-1.0, 1.0).acos() / 3.0;
    let l1 = q + 2.0 * p * phi.cos();
    let l3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let l2 = 3.0 * q - l1 - l3;
    let max = l1.abs().max(l3.abs());
    let t = QEF_TRUNCATION * max;
    let (lo, hi) = (0.8 * t, 1.2 * t);
    if [l1, l2, l3].iter().any(|&l| l > lo && l < hi) || !(l1 > hi) {
        return None;
    }
    // Unit eigenvector of an eigenvalue `l` well apart from the others.
    let eigenvector = |l: f64| -> Option<DVec3> {
        let r = [
            DVec3::new(a[0][0] - l, a[0][1], a[0][2]),
            DVec3::new(a[1][0], a[1][1] - l, a[1][2]),
            DVec3::new(a[2][0], a[2][1], a[2][2] - l),
        ];
        let c = [r[0].cross(r[1]), r[0].cross(r[2]), r[1].cross(r[2])];
        let best = c.into_iter().max_by(|x, y| x.length_squared().total_cmp(&y.length_squared()))?;
        let n2 = best.length_squared();
        (n2 > 0.0 && n2.is_finite()).then(|| best / n2.sqrt())
    };
    let solve3 = |m: [[f64; 3]; 3], v: DVec3| -> Option<DVec3> {
        let (c0, c1, c2) = (
            DVec3::new(m[0][0], m[1][0], m[2][0]),
            DVec3::new(m[0][1], m[1][1], m[2][1]),
            DVec3::new(m[0][2], m[1][2], m[2][2]),
        );
        let det = c0.dot(c1.cross(c2));
        (det != 0.0 && det.is_finite()).then(|| {
            // Cramer's rule.
            DVec3::new(v.dot(c1.cross(c2)), c0.dot(v.cross(c2)), c0.dot(c1.cross(v))) / det
        })
    };
    if l2 <= lo {
        // Rank one: only the largest eigenvalue is kept.
        let v = eigenvector(l1)?;
        Some((v * (v.dot(rhs) / l1), 1))
    } else if l3 <= lo {
        // Rank two: drop the smallest eigenvalue's direction, lift it to l1 to invert.
        let v = eigenvector(l3)?;
        let mut m = a;
        for (r, row) in m.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x += (l1 - l3) * v[r] * v[c];
            }
        }
        solve3(m, rhs - v * v.dot(rhs)).map(|x| (x, 2))
    } else {
        solve3(a, rhs).map(|x| (x, 3))
    }
}

/// Eigenvalues and unit eigenvectors of a symmetric 3x3 matrix (cyclic Jacobi).
fn sym_eigen(mut a: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for _ in 0..12 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-15 * scale {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() <= 1e-18 * scale {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut a {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * row_p[k] - s * row_q[k];
                a[q][k] = s * row_p[k] + c * row_q[k];
            }
            for row in &mut v {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
        }
    }
    let vals = [a[0][0], a[1][1], a[2][2]];
    let vecs = std::array::from_fn(|k| DVec3::new(v[0][k], v[1][k], v[2][k]));
    (vals, vecs)
}

// ---------------------------------------------------------------------------------------
// Clean-up.

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
