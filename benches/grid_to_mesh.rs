//! SDF -> grid -> triangle mesh (issue 4, item 7): our extraction (`sdfmesh::convert::extract`,
//! marching cubes, marching tetrahedra and dual contouring) against `fast-surface-nets`
//! (naive surface nets) and `mcubes` (classic Lorensen marching cubes, Bourke's tables).
//!
//! * Speed: a unit sphere (`|p| - 1`) and the thesis CSG scene (`thesis_sdf_csg.toml`,
//!   every object on its own grid as `toolkit convert --to mesh` does) at 128 cells along
//!   each grid's longest axis. Per contender, the time to sample the SDF on the grid and
//!   the time to extract, separately (wall and process CPU time, median of several
//!   repetitions, contenders interleaved round by round), on rayon pools of 1 and 2
//!   threads. Every contender samples the same lattice points (ours through
//!   `sample_grid`, the peers into their own array, in parallel over z-slices the same
//!   way). Ours evaluates the SDF only in blocks of the lattice near the surface, as
//!   `toolkit convert` does for scene objects (`Field::DistanceBound`: every SDF here is
//!   exact or a Lipschitz-1 bound); the row "ours MC, every point sampled" evaluates every
//!   point like the peers (same mesh). The peers' extraction is single-threaded, ours runs on the pool and also
//!   evaluates the SDF while extracting (crossing refinement, gradients). The peers'
//!   extract time includes turning their output into a world-space `TriangleMesh`.
//! * Geometric error of each mesh: distance to the true surface from every vertex and
//!   from 7 points on every triangle (centroid, three points at barycentric (4, 1, 1) / 6
//!   and the edge midpoints); max and mean. Vertices at the same position count once
//!   (mcubes does not share vertices between triangles). Where the object's SDF is exact (the sphere,
//!   the boxes, the disjoint sphere/torus union) the distance is `|f|`. Where it is only a
//!   Lipschitz bound (CSG subtraction and intersection), the exact distance lies between
//!   `|f|` (a lower bound) and the distance to the surface point that Newton projection
//!   on `f` converges to (an upper bound); the upper bound is reported, and the largest
//!   gap between the two bounds is printed so the bracket's tightness can be judged.
//! * Error at equal triangle count on `thesis_sdf_boxes.toml` (as is, where the grid's
//!   planes fall on the boxes' faces since the faces bound the grid, and with the bounds
//!   grown a little so that they do not) and `thesis_sdf_csg.toml`:
//!   each method swept over resolutions, the plain methods' error interpolated on log-log
//!   axes at the triangle counts of our dual contouring, and the ratio printed. The plain
//!   baselines: `mcubes` (classic marching cubes, linear interpolation) and
//!   fast-surface-nets (with `--features peers`), and our marching cubes and tetrahedra.
//!
//! `cargo bench --features peers --bench grid_to_mesh` runs it all (`-- --only WORD`: only
//! the parts whose label, such as `speed sphere` or `sweep csg`, contains WORD); without `peers` only
//! our methods are measured. Without `--bench` in the arguments (as under `cargo test
//! --all-targets`) it runs a quick smoke check at a small resolution instead.

use sdfmesh::metrics::median;
use std::path::Path;
use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::ThreadPool;
use rayon::prelude::*;
use sdfmesh::convert::extract::{ExtractMethod, Field, SampleGrid, extract_sampled, sample_grid};
use sdfmesh::geometry::sdf::SdfTree;
use sdfmesh::geometry::{Aabb, aabb};
use sdfmesh::mesh::TriangleMesh;
use sdfmesh::scene::load_scene;

/// What one run measures.
#[derive(Clone, Copy, Debug)]
struct Plan {
    /// Cells along each grid's longest axis for the speed comparison.
    res: u32,
    /// Timed repetitions per contender (after one warm-up).
    reps: usize,
    /// Thread counts of the pools the speed comparison runs on.
    threads: &'static [usize],
    /// Resolutions of the equal-triangle-count sweep.
    sweep: &'static [u32],
}

const FULL: Plan = Plan { res: 128, reps: 7, threads: &[1, 2], sweep: &[8, 12, 16, 24, 32, 48, 64, 96, 128] };

const SMOKE: Plan = Plan { res: 16, reps: 1, threads: &[1], sweep: &[8, 16] };

/// A signed distance function.
type Sdf = Box<dyn Fn(DVec3) -> f64 + Sync + Send>;

/// One object to mesh: its SDF, bounds and whether the SDF is the exact distance.
struct Part {
    sdf: Sdf,
    bounds: Aabb,
    exact: bool,
    /// Bounds diagonal, for tolerances.
    size: f64,
}

/// A named set of objects, each meshed on its own grid.
struct Case {
    name: String,
    parts: Vec<Part>,
}

fn sphere_case() -> Case {
    let bounds = aabb(Vec3::splat(-1.0), Vec3::splat(1.0));
    let part = Part { sdf: Box::new(|p: DVec3| p.length() - 1.0), bounds, exact: true, size: 12f64.sqrt() };
    Case { name: "sphere r=1".into(), parts: vec![part] }
}

fn scene_case(file: &str) -> Case {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes").join(file);
    let scene = load_scene(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let parts = scene
        .objects
        .iter()
        .filter_map(|o| {
            let tree = SdfTree::new(o)?;
            let bounds = o.bounds()?;
            let exact = tree.exact;
            let size = bounds.diagonal().length() as f64;
            Some(Part { sdf: Box::new(move |p| tree.distance(p)), bounds, exact, size })
        })
        .collect();
    Case { name: file.trim_end_matches(".toml").into(), parts }
}

/// `case` with every object's bounds grown at their max corner by `frac` of their longest
/// extent, so that grid planes no longer fall on the faces of axis-aligned boxes.
fn off_grid(mut case: Case, frac: f32) -> Case {
    for p in &mut case.parts {
        let ext = p.bounds.diagonal();
        let grow = frac * ext.max_element();
        p.bounds = aabb(p.bounds.min.into(), Vec3::from(p.bounds.max) + Vec3::splat(grow));
    }
    case.name = format!(
        "{} (bounds grown {:.2}% at the max corner: box faces off the grid planes)",
        case.name,
        frac * 100.0
    );
    case
}

/// Who extracts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Method {
    /// Our marching cubes (`ExtractMethod::MarchingCubes`, the default `--method mc`).
    Mc,
    /// The same, sampling every grid point (`Field::Arbitrary`) instead of only the blocks
    /// near the surface: the same mesh, to show what the sparse sampling saves.
    McDense,
    /// Our marching tetrahedra (`ExtractMethod::MarchingTetrahedra`).
    Mt,
    /// Our dual contouring.
    Dc,
    /// fast-surface-nets' `surface_nets`.
    #[cfg(feature = "peers")]
    Fsn,
    /// mcubes' classic marching cubes.
    #[cfg(feature = "peers")]
    Mcubes,
}

impl Method {
    fn all() -> Vec<Method> {
        #[allow(unused_mut)]
        let mut v = vec![Method::Mc, Method::McDense, Method::Mt, Method::Dc];
        #[cfg(feature = "peers")]
        v.extend([Method::Fsn, Method::Mcubes]);
        v
    }

    fn name(self) -> &'static str {
        match self {
            Method::Mc => "ours marching cubes",
            Method::McDense => "ours MC, every point sampled",
            Method::Mt => "ours marching tetrahedra",
            Method::Dc => "ours dual contouring",
            #[cfg(feature = "peers")]
            Method::Fsn => "fast-surface-nets 0.2",
            #[cfg(feature = "peers")]
            Method::Mcubes => "mcubes 0.1 (Lorensen MC)",
        }
    }
}

/// CPU time of the whole process (all threads), seconds, where the platform tells.
fn process_cpu_secs() -> f64 {
    #[cfg(unix)]
    {
        let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: a valid clock id and a valid out-pointer.
        let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
        if rc == 0 { t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9 } else { f64::NAN }
    }
    #[cfg(not(unix))]
    {
        f64::NAN
    }
}

/// Wall and CPU seconds of one phase.
#[derive(Clone, Copy, Debug, Default)]
struct Secs {
    wall: f64,
    cpu: f64,
}

impl std::ops::AddAssign for Secs {
    fn add_assign(&mut self, o: Secs) {
        self.wall += o.wall;
        self.cpu += o.cpu;
    }
}

fn timed<T>(f: impl FnOnce() -> T) -> (T, Secs) {
    let cpu0 = process_cpu_secs();
    let start = Instant::now();
    let out = f();
    let wall = start.elapsed().as_secs_f64();
    (out, Secs { wall, cpu: process_cpu_secs() - cpu0 })
}

#[cfg(feature = "peers")]
/// Samples `f` on `lattice`'s points (the same points, same layout, in parallel over
/// z-slices) into a plain array for the peers.
fn sample_plain(f: &Sdf, lattice: &SampleGrid) -> Vec<f32> {
    let (origin, h, n) = (lattice.origin(), lattice.cell(), lattice.dims());
    let mut values = vec![0.0f32; n[0] * n[1] * n[2]];
    values.par_chunks_mut(n[0] * n[1]).enumerate().for_each(|(z, vals)| {
        for y in 0..n[1] {
            for x in 0..n[0] {
                vals[x + n[0] * y] = f(origin + h * DVec3::new(x as f64, y as f64, z as f64)) as f32;
            }
        }
    });
    values
}

/// Grid-local (cell units) positions to world space.
#[cfg(feature = "peers")]
fn to_world(lattice: &SampleGrid, p: [f32; 3]) -> Vec3 {
    (lattice.origin() + lattice.cell() * DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)).as_vec3()
}

#[cfg(feature = "peers")]
fn fsn_extract(values: &[f32], lattice: &SampleGrid) -> TriangleMesh {
    use fast_surface_nets::ndshape::RuntimeShape;
    use fast_surface_nets::{SurfaceNetsBuffer, surface_nets};
    let n = lattice.dims().map(|v| v as u32);
    let shape = RuntimeShape::<u32, 3>::new(n);
    let mut buf = SurfaceNetsBuffer::default();
    surface_nets(values, &shape, [0; 3], n.map(|v| v - 1), &mut buf);
    TriangleMesh {
        positions: buf.positions.iter().map(|&p| to_world(lattice, p)).collect(),
        triangles: buf.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        normals: None,
    }
}

#[cfg(feature = "peers")]
fn mcubes_extract(values: Vec<f32>, lattice: &SampleGrid) -> TriangleMesh {
    use mcubes::{MarchingCubes, MeshSide};
    let n = lattice.dims();
    let mc = MarchingCubes::new(
        (n[0], n[1], n[2]),
        (1.0, 1.0, 1.0),
        (1.0, 1.0, 1.0),
        [0.0f32; 3].into(),
        values,
        0.0,
    )
    .expect("grid size matches");
    let out = mc.generate(MeshSide::OutsideOnly);
    TriangleMesh {
        positions: out
            .vertices
            .iter()
            .map(|v| to_world(lattice, [v.posit.x, v.posit.y, v.posit.z]))
            .collect(),
        triangles: out.indices.chunks_exact(3).map(|t| [t[0] as u32, t[1] as u32, t[2] as u32]).collect(),
        normals: None,
    }
}

/// Samples and extracts `part` at `res` with `method`; returns the mesh and the sample and
/// extract times. `lattice` is the part's grid from `sample_grid` (its points only are used
/// by the peers).
#[cfg_attr(not(feature = "peers"), allow(unused_variables))]
fn run(method: Method, part: &Part, lattice: &SampleGrid, res: u32) -> (TriangleMesh, Secs, Secs) {
    let f = &part.sdf;
    match method {
        Method::Mc | Method::McDense | Method::Mt | Method::Dc => {
            let how = match method {
                Method::Mc | Method::McDense => ExtractMethod::MarchingCubes,
                Method::Mt => ExtractMethod::MarchingTetrahedra,
                _ => ExtractMethod::DualContouring,
            };
            // Every part's SDF is exact or a Lipschitz-1 bound (`SdfTree::distance`).
            let field = if method == Method::McDense { Field::Arbitrary } else { Field::DistanceBound };
            let (grid, s) = timed(|| sample_grid(f, field, &part.bounds, res).expect("bounded part"));
            let (mesh, e) = timed(|| extract_sampled(f, &grid, how));
            (mesh, s, e)
        }
        #[cfg(feature = "peers")]
        Method::Fsn => {
            let (values, s) = timed(|| sample_plain(f, lattice));
            let (mesh, e) = timed(|| fsn_extract(&values, lattice));
            (mesh, s, e)
        }
        #[cfg(feature = "peers")]
        Method::Mcubes => {
            let (values, s) = timed(|| sample_plain(f, lattice));
            let (mesh, e) = timed(|| mcubes_extract(values, lattice));
            (mesh, s, e)
        }
    }
}

/// Runs `method` on every part of `case` (each on its own grid); the merged mesh of each
/// part is returned per part, times summed.
fn run_case(
    method: Method,
    case: &Case,
    lattices: &[SampleGrid],
    res: u32,
) -> (Vec<TriangleMesh>, Secs, Secs) {
    let (mut s, mut e) = (Secs::default(), Secs::default());
    let mut meshes = Vec::with_capacity(case.parts.len());
    for (part, lattice) in case.parts.iter().zip(lattices) {
        let (m, ps, pe) = run(method, part, lattice, res);
        s += ps;
        e += pe;
        meshes.push(m);
    }
    (meshes, s, e)
}

fn lattices(case: &Case, res: u32) -> Vec<SampleGrid> {
    case.parts
        .iter()
        .map(|p| sample_grid(&p.sdf, Field::Arbitrary, &p.bounds, res).expect("bounded part"))
        .collect()
}

/// Distance from `p` to the zero set of `f` by Newton projection with central differences
/// of step `h`: `|p - q|` for the point `q` it converges to (`|f(q)| <= tol`), or `None`.
fn project(f: &Sdf, p: DVec3, h: f64, tol: f64) -> Option<f64> {
    let mut q = p;
    for _ in 0..64 {
        let d = f(q);
        if d.abs() <= tol {
            return Some((p - q).length());
        }
        let g = DVec3::new(
            f(q + DVec3::X * h) - f(q - DVec3::X * h),
            f(q + DVec3::Y * h) - f(q - DVec3::Y * h),
            f(q + DVec3::Z * h) - f(q - DVec3::Z * h),
        ) / (2.0 * h);
        let g2 = g.length_squared();
        if g2.is_nan() || g2 <= 1e-12 || g2.is_infinite() {
            return None;
        }
        q -= g * (d / g2);
    }
    None
}

/// Distance statistics over points of a mesh.
#[derive(Clone, Copy, Debug, Default)]
struct ErrStats {
    vert_max: f64,
    vert_sum: f64,
    verts: u64,
    tri_max: f64,
    tri_sum: f64,
    tri_points: u64,
    /// Largest upper - lower bound where the distance was bracketed.
    gap_max: f64,
    /// Points where projection did not converge (counted with the lower bound `|f|`).
    unconverged: u64,
}

impl ErrStats {
    fn merge(mut self, o: ErrStats) -> ErrStats {
        self.vert_max = self.vert_max.max(o.vert_max);
        self.vert_sum += o.vert_sum;
        self.verts += o.verts;
        self.tri_max = self.tri_max.max(o.tri_max);
        self.tri_sum += o.tri_sum;
        self.tri_points += o.tri_points;
        self.gap_max = self.gap_max.max(o.gap_max);
        self.unconverged += o.unconverged;
        self
    }

    fn max(&self) -> f64 {
        self.vert_max.max(self.tri_max)
    }

    fn mean(&self) -> f64 {
        (self.vert_sum + self.tri_sum) / (self.verts + self.tri_points).max(1) as f64
    }

    fn vert_mean(&self) -> f64 {
        self.vert_sum / self.verts.max(1) as f64
    }

    fn tri_mean(&self) -> f64 {
        self.tri_sum / self.tri_points.max(1) as f64
    }
}

/// Distance of `p` to `part`'s surface: (reported distance, bracket gap, converged).
fn distance(part: &Part, p: DVec3) -> (f64, f64, bool) {
    let lower = (part.sdf)(p).abs();
    if part.exact {
        return (lower, 0.0, true);
    }
    let h = 1e-7 * part.size.max(p.abs().max_element());
    match project(&part.sdf, p, h, 1e-10 * part.size) {
        Some(upper) => (upper, (upper - lower).max(0.0), true),
        None => (lower, 0.0, false),
    }
}

/// Barycentric weights of the points measured on each triangle.
const TRI_POINTS: [[f64; 3]; 7] = [
    [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
    [4.0 / 6.0, 1.0 / 6.0, 1.0 / 6.0],
    [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0],
    [1.0 / 6.0, 1.0 / 6.0, 4.0 / 6.0],
    [0.5, 0.5, 0.0],
    [0.0, 0.5, 0.5],
    [0.5, 0.0, 0.5],
];

fn mesh_error(part: &Part, mesh: &TriangleMesh) -> ErrStats {
    // Each distinct vertex once: mcubes repeats a vertex in every triangle that uses it
    // (about six times), which would weight its vertices (on the surface up to the
    // interpolation error) six times as much as those of the meshes that share them.
    let mut unique: Vec<[u32; 3]> =
        mesh.positions.iter().map(|p| (*p + Vec3::ZERO).to_array().map(f32::to_bits)).collect();
    unique.par_sort_unstable();
    unique.dedup();
    let verts = unique
        .par_iter()
        .map(|b| Vec3::from_array(b.map(f32::from_bits)))
        .fold(ErrStats::default, |mut e, v| {
            let (d, gap, ok) = distance(part, v.as_dvec3());
            e.vert_max = e.vert_max.max(d);
            e.vert_sum += d;
            e.verts += 1;
            e.gap_max = e.gap_max.max(gap);
            e.unconverged += u64::from(!ok);
            e
        })
        .reduce(ErrStats::default, ErrStats::merge);
    let pos = &mesh.positions;
    let tris = mesh
        .triangles
        .par_iter()
        .fold(ErrStats::default, |mut e, t| {
            let [a, b, c] = t.map(|i| pos[i as usize].as_dvec3());
            for w in TRI_POINTS {
                let (d, gap, ok) = distance(part, a * w[0] + b * w[1] + c * w[2]);
                e.tri_max = e.tri_max.max(d);
                e.tri_sum += d;
                e.tri_points += 1;
                e.gap_max = e.gap_max.max(gap);
                e.unconverged += u64::from(!ok);
            }
            e
        })
        .reduce(ErrStats::default, ErrStats::merge);
    verts.merge(tris)
}

fn case_error(case: &Case, meshes: &[TriangleMesh]) -> ErrStats {
    case.parts.iter().zip(meshes).map(|(p, m)| mesh_error(p, m)).fold(ErrStats::default(), ErrStats::merge)
}

fn count(meshes: &[TriangleMesh]) -> (usize, usize) {
    meshes.iter().fold((0, 0), |(t, v), m| (t + m.triangles.len(), v + m.positions.len()))
}

/// Timings of one contender in one pool.
#[derive(Default)]
struct Timings {
    sample: Vec<Secs>,
    extract: Vec<Secs>,
}

impl Timings {
    fn med(&self, pick: impl Fn(&Timings) -> &Vec<Secs>, cpu: bool) -> f64 {
        median(&pick(self).iter().map(|s| if cpu { s.cpu } else { s.wall }).collect::<Vec<_>>())
    }
}

fn pool(threads: usize) -> ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool")
}

/// The speed comparison on one case at `plan.res`.
fn speed(case: &Case, plan: &Plan) {
    let methods = Method::all();
    let lat = lattices(case, plan.res);
    let dims: Vec<String> =
        lat.iter().map(|l| format!("{}x{}x{}", l.dims()[0], l.dims()[1], l.dims()[2])).collect();
    println!(
        "\n== {}: {} object(s), {} cells along each grid's longest axis; grid points {}",
        case.name,
        case.parts.len(),
        plan.res,
        dims.join(" + ")
    );
    let exact = case.parts.iter().filter(|p| p.exact).count();
    println!(
        "   error reference: {exact} object(s) with an exact SDF (|f|), {} bracketed by |f| and Newton projection",
        case.parts.len() - exact
    );
    for &threads in plan.threads {
        let pool = pool(threads);
        let mut timings: Vec<Timings> = methods.iter().map(|_| Timings::default()).collect();
        let mut last: Vec<Vec<TriangleMesh>> = methods.iter().map(|_| Vec::new()).collect();
        pool.install(|| {
            // One warm-up round, then `reps` timed rounds, contenders interleaved.
            for round in 0..=plan.reps {
                for (k, &m) in methods.iter().enumerate() {
                    let (meshes, s, e) = run_case(m, case, &lat, plan.res);
                    if round > 0 {
                        timings[k].sample.push(s);
                        timings[k].extract.push(e);
                    }
                    last[k] = meshes;
                }
            }
        });
        println!(
            "\n-- {threads} thread(s) (peers' extraction is single-threaded), median of {} (wall; process CPU)",
            plan.reps
        );
        println!(
            "{:<28} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8}",
            "method", "sample ms", "cpu", "extr ms", "cpu", "total ms", "cpu", "tris", "verts"
        );
        let mut totals = Vec::new();
        for (k, &m) in methods.iter().enumerate() {
            let t = &timings[k];
            let (sw, sc) = (t.med(|t| &t.sample, false), t.med(|t| &t.sample, true));
            let (ew, ec) = (t.med(|t| &t.extract, false), t.med(|t| &t.extract, true));
            let tot: Vec<f64> = t.sample.iter().zip(&t.extract).map(|(a, b)| a.wall + b.wall).collect();
            let totc: Vec<f64> = t.sample.iter().zip(&t.extract).map(|(a, b)| a.cpu + b.cpu).collect();
            let (tw, tc) = (median(&tot), median(&totc));
            let (tris, verts) = count(&last[k]);
            println!(
                "{:<28} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9} {:>8}",
                m.name(),
                sw * 1e3,
                sc * 1e3,
                ew * 1e3,
                ec * 1e3,
                tw * 1e3,
                tc * 1e3,
                tris,
                verts
            );
            totals.push((m, ew, tw));
        }
        #[cfg(feature = "peers")]
        if let Some(&(_, pe, pt)) = totals.iter().find(|(m, _, _)| *m == Method::Fsn) {
            for &(m, e, t) in totals
                .iter()
                .filter(|(m, _, _)| matches!(m, Method::Mc | Method::McDense | Method::Mt | Method::Dc))
            {
                println!(
                    "   {} / fast-surface-nets: extract {:.2}x, sample + extract {:.2}x (below 1: ours faster)",
                    m.name(),
                    e / pe,
                    t / pt
                );
            }
        }
        #[cfg(not(feature = "peers"))]
        let _ = totals;
        if threads == plan.threads[plan.threads.len() - 1] {
            println!(
                "\n   geometric error (scene units; cell {:.4e} on the first grid), vertices | 7 points per triangle",
                lat[0].cell()
            );
            println!(
                "{:<28} {:>10} {:>10} {:>10} {:>10} {:>10} {:>7}",
                "method", "vert max", "vert mean", "tri max", "tri mean", "bracket", "unconv"
            );
            for (k, &m) in methods.iter().enumerate() {
                let e = case_error(case, &last[k]);
                println!(
                    "{:<28} {:>10.3e} {:>10.3e} {:>10.3e} {:>10.3e} {:>10.1e} {:>7}",
                    m.name(),
                    e.vert_max,
                    e.vert_mean(),
                    e.tri_max,
                    e.tri_mean(),
                    e.gap_max,
                    e.unconverged
                );
            }
        }
    }
}

/// One point of the sweep.
#[derive(Clone, Copy, Debug)]
struct Point {
    res: u32,
    tris: usize,
    max: f64,
    mean: f64,
}

/// `y(x)` of the polyline `pts` (sorted by x) interpolated linearly in log-log, `None`
/// outside its range.
fn loglog(pts: &[(f64, f64)], x: f64) -> Option<f64> {
    let lx = x.ln();
    pts.windows(2).find(|w| w[0].0 <= x && x <= w[1].0).map(|w| {
        let (x0, y0, x1, y1) = (w[0].0.ln(), w[0].1.ln(), w[1].0.ln(), w[1].1.ln());
        let s = if x1 > x0 { (lx - x0) / (x1 - x0) } else { 0.0 };
        (y0 + s * (y1 - y0)).exp()
    })
}

/// The equal-triangle-count comparison on one case.
fn sweep(case: &Case, plan: &Plan) {
    // The dense row gives the same meshes as `Mc`.
    let methods: Vec<Method> = Method::all().into_iter().filter(|&m| m != Method::McDense).collect();
    println!("\n== error vs triangles: {} ({} object(s), each on its own grid)", case.name, case.parts.len());
    println!("{:<28} {:>5} {:>9} {:>10} {:>10}", "method", "res", "tris", "max", "mean");
    let mut curves: Vec<Vec<Point>> = Vec::new();
    for &m in &methods {
        let mut curve = Vec::new();
        for &res in plan.sweep {
            let lat = lattices(case, res);
            let (meshes, _, _) = run_case(m, case, &lat, res);
            let e = case_error(case, &meshes);
            let p = Point { res, tris: count(&meshes).0, max: e.max(), mean: e.mean() };
            println!("{:<28} {:>5} {:>9} {:>10.3e} {:>10.3e}", m.name(), p.res, p.tris, p.max, p.mean);
            curve.push(p);
        }
        curves.push(curve);
    }
    let dc = methods.iter().position(|&m| m == Method::Dc).expect("dc");
    for (b, &base) in methods.iter().enumerate() {
        if b == dc {
            continue;
        }
        let mut pts = curves[b].clone();
        pts.sort_by_key(|p| p.tris);
        let maxes: Vec<(f64, f64)> = pts.iter().map(|p| (p.tris as f64, p.max)).collect();
        let means: Vec<(f64, f64)> = pts.iter().map(|p| (p.tris as f64, p.mean)).collect();
        println!(
            "\n   ours dual contouring / {} at equal triangle count ({} interpolated log-log)",
            base.name(),
            base.name()
        );
        println!("   {:>5} {:>9} {:>10} {:>10}", "res", "tris", "max ratio", "mean ratio");
        let (mut rmax, mut rmean) = (Vec::new(), Vec::new());
        for p in &curves[dc] {
            let x = p.tris as f64;
            match (loglog(&maxes, x), loglog(&means, x)) {
                (Some(bm), Some(bn)) => {
                    rmax.push(p.max / bm);
                    rmean.push(p.mean / bn);
                    println!("   {:>5} {:>9} {:>10.3} {:>10.3}", p.res, p.tris, p.max / bm, p.mean / bn);
                }
                _ => println!("   {:>5} {:>9} {:>10} {:>10}", p.res, p.tris, "out of range", ""),
            }
        }
        println!(
            "   median ratio over the matched counts: max {:.3}, mean {:.3} (target <= 0.5)",
            median(&rmax),
            median(&rmean)
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let plan = if args.iter().any(|a| a == "--bench") {
        FULL
    } else {
        println!(
            "smoke mode (run with `cargo bench --features peers --bench grid_to_mesh` for the benchmark)"
        );
        SMOKE
    };
    let peers =
        if cfg!(feature = "peers") { "fast-surface-nets, mcubes" } else { "none (no `peers` feature)" };
    println!(
        "grid to mesh: {} cells along the longest axis, {} timed repetitions after 1 warm-up, interleaved; \
         threads {:?}; peers: {peers}; {} CPUs available",
        plan.res,
        plan.reps,
        plan.threads,
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    // `--only WORD`: only the parts whose label ("speed sphere", "sweep csg", ...) contains WORD.
    let only = args.iter().position(|a| a == "--only").and_then(|i| args.get(i + 1)).cloned();
    let run = |label: &str| only.as_deref().is_none_or(|w| label.contains(w));
    let (sphere, csg, boxes) =
        (sphere_case(), scene_case("thesis_sdf_csg.toml"), scene_case("thesis_sdf_boxes.toml"));
    if run("speed sphere") {
        speed(&sphere, &plan);
    }
    if run("speed csg") {
        speed(&csg, &plan);
    }
    if run("sweep boxes") {
        sweep(&boxes, &plan);
    }
    if run("sweep boxes off-grid") {
        sweep(&off_grid(scene_case("thesis_sdf_boxes.toml"), 0.0137), &plan);
    }
    if run("sweep csg") {
        sweep(&csg, &plan);
    }
}
