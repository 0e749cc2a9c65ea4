//! Mesh -> signed distance grid: our exact sampler (`sdfmesh::convert::mesh_to_grid::sample_mesh`) side by
//! side with the `mesh_to_sdf` crate (`generate_grid_sdf`), and our voxelizer
//! (`sdfmesh::convert::mesh_to_grid::voxelize::voxelize_mesh`) against our exact samples.
//!
//! * Meshes: the Stanford bunny (open: holes in its base) and the armadillo (closed), from
//!   `../shared/meshes`, at 128 cells along the longest axis plus
//!   `sdfmesh::plan::GRID_MARGIN_CELLS` on every side.
//! * Both tools fill the same grid points: `mesh_to_sdf`'s `Grid` gets our grid's origin as
//!   its first cell centre, our spacing and our sample counts (our samples sit at cell
//!   corners, its at cell centres, so the points coincide), and its x-slowest output is
//!   reordered to our x-fastest layout outside the timed region.
//! * `mesh_to_sdf` runs with both of its sign methods (`Raycast`, its default, a best of
//!   three parity count along the grid axes, meant for watertight meshes; and `Normal`,
//!   the nearest triangle's normal). Its best-faith setting for a mesh is the one with the
//!   fewest wrong signs (ties: the faster), and the headline ratio is against it.
//! * Timing: wall clock of the whole call (BVH and winding data builds included for ours;
//!   input conversion excluded for both), median of `rounds` runs, interleaved round by
//!   round across tools so background load affects all alike, on a rayon pool of all
//!   available threads (`mesh_to_sdf` also spawns `rayon::current_num_threads()` scoped
//!   threads of its own for its propagation step).
//! * Accuracy against an independent brute-force reference: on random grid points (some
//!   uniform over the grid, some among points within a few voxels of the surface), the
//!   exact distance (closest point over all triangles) and the exact winding number (a
//!   plain `f64` solid-angle sum over all triangles, inside at `>= 0.5`). Reported: max
//!   and mean absolute distance error, and wrong signs. Besides, over the whole grid,
//!   every sample where a tool's sign disagrees with another's is judged by the exact
//!   winding number (up to a cap, then a random subset scaled up), which counts wrong
//!   signs grid-wide. Points closer to the surface than `1e-3` voxel have no meaningful
//!   sign and are not counted.
//! * `voxelize_mesh` at the same resolution against our `sample_mesh` grid: max and mean
//!   absolute difference in voxels, sign disagreements (surface voxels, stored as 0, not
//!   counted), and time. An open mesh may have no inside for it (it then refuses).
//!
//! `cargo bench --bench mesh_to_grid [--features peers] [MESH-SUBSTRING]` runs it and
//! writes its output to `reports/bench/mesh_to_grid.txt` as well; without `--bench` (as
//! under `cargo test --all-targets`) it runs a quick smoke check on a small generated mesh
//! instead. Without the `peers` feature it measures ours only.

mod common;

use common::{Out, Rng, header};
use sdfmesh::metrics::median;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use glam::{DVec3, Vec3, Vec3A};
use rayon::ThreadPool;
use rayon::prelude::*;
use sdfmesh::convert::mesh_to_grid::sample_mesh_with_stats;
use sdfmesh::convert::mesh_to_grid::voxelize::voxelize_mesh;
use sdfmesh::geometry::grid::SdfGrid;
use sdfmesh::geometry::mesh::triangle::closest_point_on_triangle;
use sdfmesh::mesh::{TriangleMesh, load_mesh};
use sdfmesh::plan::GRID_MARGIN_CELLS;

/// What one run measures.
#[derive(Clone, Copy, Debug)]
struct Plan {
    /// Cells along the longest axis.
    res: u32,
    /// Timed runs per tool (interleaved).
    rounds: usize,
    /// Reference points drawn uniformly over the grid.
    uniform: usize,
    /// Reference points drawn among samples within `NEAR_VOXELS` of the surface.
    near: usize,
    /// Most grid-wide sign disagreements judged by the exact winding number.
    judge_cap: usize,
    /// Extra (coarser) resolutions for voxelize against sample.
    extra_voxelize: &'static [u32],
    /// Whether to run the peer crates (when built with them).
    peers: bool,
}

const FULL: Plan = Plan {
    res: 128,
    rounds: 3,
    uniform: 2000,
    near: 2000,
    judge_cap: 3000,
    extra_voxelize: &[64],
    peers: true,
};

const SMOKE: Plan =
    Plan { res: 16, rounds: 1, uniform: 100, near: 100, judge_cap: 100, extra_voxelize: &[], peers: true };

/// Reference points "near the surface" are drawn among samples within this many voxels.
const NEAR_VOXELS: f32 = 3.0;

/// Points closer to the surface than this (in voxels) are not counted for signs.
const SIGN_EPS_VOXELS: f32 = 1e-3;

/// The box `[-h, h]` with a dent-free closed surface (12 triangles) plus a second, open
/// square sheet beside it: a tiny mesh for the smoke check.
fn smoke_mesh() -> TriangleMesh {
    let h = Vec3::new(0.5, 0.4, 0.3);
    let mut positions: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { -h.x } else { h.x },
                if i & 2 == 0 { -h.y } else { h.y },
                if i & 4 == 0 { -h.z } else { h.z },
            )
        })
        .collect();
    let quads = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
    let mut triangles: Vec<[u32; 3]> =
        quads.iter().flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]]).collect();
    positions.extend([
        Vec3::new(0.8, -0.3, -0.3),
        Vec3::new(1.2, -0.3, -0.3),
        Vec3::new(1.2, 0.3, 0.2),
        Vec3::new(0.8, 0.3, 0.2),
    ]);
    triangles.extend([[8, 9, 10], [8, 10, 11]]);
    TriangleMesh { positions, triangles, normals: None }
}

/// Exact unsigned distance from `p` to the mesh: closest point over every triangle.
fn brute_distance(tris: &[[Vec3A; 3]], p: Vec3) -> f32 {
    let q = Vec3A::from(p);
    let mut best = f32::INFINITY;
    for &[a, b, c] in tris {
        best = best.min((closest_point_on_triangle(q, a, b, c) - q).length_squared());
    }
    best.sqrt()
}

/// Exact generalized winding number of `p` (Van Oosterom and Strackee in `f64`, summed
/// over every triangle), written independently of `sdfmesh::convert::mesh_to_grid::winding`.
fn brute_winding(tris: &[[DVec3; 3]], p: Vec3) -> f64 {
    let q = p.as_dvec3();
    let mut omega = 0.0;
    for &[a, b, c] in tris {
        let (a, b, c) = (a - q, b - q, c - q);
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let num = a.dot(b.cross(c));
        let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
        omega += 2.0 * num.atan2(den);
    }
    omega / (4.0 * std::f64::consts::PI)
}

/// CPU time of the whole process (all threads), seconds (0 where the platform does not
/// tell).
fn process_cpu_secs() -> f64 {
    #[cfg(unix)]
    {
        let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: a valid clock id and a valid out-pointer.
        let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
        if rc == 0 { t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9 } else { 0.0 }
    }
    #[cfg(not(unix))]
    {
        0.0
    }
}

/// One tool's grid (our layout) and its run times.
struct ToolRun {
    name: String,
    values: Option<Vec<f32>>,
    times: Vec<f64>,
    /// Process CPU seconds of each run.
    cpu: Vec<f64>,
}

/// Voxelize against sample at one resolution: times, first grids, or voxelize's refusal.
#[derive(Default)]
struct VoxRun {
    res: u32,
    /// `voxelize_mesh` seconds per run.
    vt: Vec<f64>,
    /// `sample_mesh` seconds per run.
    st: Vec<f64>,
    vg: Option<SdfGrid>,
    sg: Option<SdfGrid>,
    err: Option<String>,
}

/// Accuracy of one tool on a set of reference points.
#[derive(Default, Clone, Copy)]
struct Accuracy {
    max_err: f64,
    sum_err: f64,
    count: usize,
    wrong_signs: usize,
    signed_points: usize,
}

impl Accuracy {
    fn add(&mut self, value: f32, d: f32, w: f64, eps: f32) {
        let err = (value.abs() - d).abs() as f64;
        self.max_err = self.max_err.max(err);
        self.sum_err += err;
        self.count += 1;
        if d > eps {
            self.signed_points += 1;
            if value.is_sign_negative() != (w >= 0.5) {
                self.wrong_signs += 1;
            }
        }
    }

    fn describe(&self, voxel: f32) -> String {
        let v = voxel as f64;
        format!(
            "max |err| {:.3e} ({:.4} voxel), mean {:.3e} ({:.5} voxel); wrong signs {} of {}",
            self.max_err,
            self.max_err / v,
            self.sum_err / self.count.max(1) as f64,
            self.sum_err / self.count.max(1) as f64 / v,
            self.wrong_signs,
            self.signed_points
        )
    }
}

#[cfg(feature = "peers")]
mod peer {
    use mesh_to_sdf::{Grid, SignMethod, Topology, generate_grid_sdf};
    use sdfmesh::geometry::grid::SdfGrid;
    use sdfmesh::mesh::TriangleMesh;

    /// `mesh_to_sdf`'s input: vertices and a flat index list.
    pub struct Input {
        vertices: Vec<[f32; 3]>,
        indices: Vec<u32>,
        grid: Grid<[f32; 3]>,
        dims: [usize; 3],
    }

    /// The sign methods compared.
    pub const METHODS: [(&str, SignMethod); 2] =
        [("mesh_to_sdf Raycast", SignMethod::Raycast), ("mesh_to_sdf Normal", SignMethod::Normal)];

    impl Input {
        /// The mesh and a `mesh_to_sdf` grid whose cell centres are `layout`'s samples.
        pub fn new(mesh: &TriangleMesh, layout: &SdfGrid) -> Self {
            let vertices = mesh.positions.iter().map(|p| p.to_array()).collect();
            let indices = mesh.triangles.iter().flatten().copied().collect();
            let dims = layout.dims.to_array().map(|d| d as usize);
            let grid = Grid::new(layout.origin.to_array(), [layout.voxel; 3], dims);
            Input { vertices, indices, grid, dims }
        }

        /// Runs `generate_grid_sdf`; the output is in its own (x slowest) order.
        pub fn run(&self, method: SignMethod) -> Vec<f32> {
            generate_grid_sdf(&self.vertices, Topology::TriangleList(Some(&self.indices)), &self.grid, method)
        }

        /// Reorders `generate_grid_sdf`'s output to our layout (x fastest).
        pub fn to_ours(&self, theirs: &[f32]) -> Vec<f32> {
            let [nx, ny, nz] = self.dims;
            let mut out = vec![0.0; nx * ny * nz];
            for k in 0..nz {
                for j in 0..ny {
                    for i in 0..nx {
                        out[i + nx * (j + ny * k)] = theirs[self.grid.get_cell_idx(&[i, j, k])];
                    }
                }
            }
            out
        }

        /// Position of cell `(i, j, k)` as `mesh_to_sdf` computes it.
        pub fn cell_centre(&self, i: usize, j: usize, k: usize) -> [f32; 3] {
            self.grid.get_cell_center(&[i, j, k])
        }
    }
}

fn bench_mesh(out: &mut Out, pool: &ThreadPool, name: &str, mesh: &TriangleMesh, plan: &Plan) {
    let res = plan.res;
    let margin = GRID_MARGIN_CELLS;
    let closed = sdfmesh::convert::mesh_to_grid::winding::is_closed(mesh);
    out.line(format!(
        "\n== {name}: {} triangles, {} vertices, {}; grid {res} cells along the longest axis + {margin} margin",
        mesh.triangles.len(),
        mesh.positions.len(),
        if closed { "closed and consistently oriented" } else { "open (not closed)" }
    ));

    // Our grid, once untimed (warm-up; also the layout both tools fill).
    let (ours, stats) = pool.install(|| sample_mesh_with_stats(mesh, res, margin)).expect("sample_mesh");
    let (dims, voxel) = (ours.dims, ours.voxel);
    let n = ours.values.len();
    out.line(format!(
        "grid {}x{}x{} = {n} samples, voxel {voxel:.5e}, origin {:.5}; ours: build {:.1} ms, fill {:.1} ms; \
         per sample {:.1} BVH nodes, {:.1} winding nodes, winding evaluated at {:.1}% of samples",
        dims.x,
        dims.y,
        dims.z,
        ours.origin,
        stats.build_time.as_secs_f64() * 1e3,
        stats.fill_time.as_secs_f64() * 1e3,
        stats.closest_nodes as f64 / stats.samples as f64,
        stats.winding_nodes as f64 / stats.samples as f64,
        100.0 * stats.winding_evaluations as f64 / stats.samples as f64,
    ));

    #[cfg(feature = "peers")]
    let input = {
        let input = peer::Input::new(mesh, &ours);
        // The points coincide: check a few.
        let mut worst = 0.0f32;
        for (i, j, k) in [(0, 0, 0), (dims.x - 1, dims.y - 1, dims.z - 1), (dims.x / 2, 3, dims.z / 3)] {
            let theirs = Vec3::from_array(input.cell_centre(i as usize, j as usize, k as usize));
            worst = worst.max((theirs - ours.position(i, j, k)).abs().max_element());
        }
        out.line(format!(
            "mesh_to_sdf grid: first cell centre = our origin, cell size = our voxel, cell count = our dims; \
             largest coordinate difference of checked points {worst:e}"
        ));
        input
    };

    let mut tools: Vec<ToolRun> =
        vec![ToolRun { name: "ours (sample_mesh)".into(), values: None, times: vec![], cpu: vec![] }];
    #[cfg(feature = "peers")]
    for (label, _) in peer::METHODS.iter().filter(|_| plan.peers) {
        tools.push(ToolRun { name: label.to_string(), values: None, times: vec![], cpu: vec![] });
    }
    // Voxelize at `res` and the extra resolutions, with our sample at the same resolution.
    let mut vox_res = vec![res];
    vox_res.extend(plan.extra_voxelize.iter().copied().filter(|&r| r != res));
    let mut vox_runs: Vec<VoxRun> = vox_res.iter().map(|&r| VoxRun { res: r, ..VoxRun::default() }).collect();

    for round in 0..plan.rounds {
        for tool in tools.iter_mut() {
            let t = Instant::now();
            let c = process_cpu_secs();
            let values = if tool.name.starts_with("ours") {
                pool.install(|| sample_mesh_with_stats(mesh, res, margin)).expect("sample_mesh").0.values
            } else {
                #[cfg(feature = "peers")]
                {
                    let method = peer::METHODS.iter().find(|(l, _)| *l == tool.name).expect("method").1;
                    let raw = pool.install(|| input.run(method));
                    tool.times.push(t.elapsed().as_secs_f64());
                    tool.cpu.push(process_cpu_secs() - c);
                    if tool.values.is_none() {
                        tool.values = Some(input.to_ours(&raw));
                    }
                    continue;
                }
                #[cfg(not(feature = "peers"))]
                unreachable!()
            };
            tool.times.push(t.elapsed().as_secs_f64());
            tool.cpu.push(process_cpu_secs() - c);
            if tool.values.is_none() {
                tool.values = Some(values);
            }
        }
        for VoxRun { res: r, vt, st, vg, sg, err } in vox_runs.iter_mut() {
            if err.is_some() {
                continue;
            }
            let t = Instant::now();
            match pool.install(|| voxelize_mesh(mesh, *r, margin)) {
                Ok(g) => {
                    vt.push(t.elapsed().as_secs_f64());
                    if vg.is_none() {
                        *vg = Some(g);
                    }
                }
                Err(e) => {
                    *err = Some(e.to_string());
                    continue;
                }
            }
            let t = Instant::now();
            let g = pool.install(|| sample_mesh_with_stats(mesh, *r, margin)).expect("sample_mesh").0;
            st.push(t.elapsed().as_secs_f64());
            if sg.is_none() {
                *sg = Some(g);
            }
        }
        let times: Vec<String> = tools
            .iter()
            .map(|t| {
                format!("{} {:.3} s ({:.3} s CPU)", t.name, t.times.last().unwrap(), t.cpu.last().unwrap())
            })
            .collect();
        out.line(format!("round {}: {}", round + 1, times.join(", ")));
    }
    let ours_values = tools[0].values.as_ref().expect("ours ran");
    assert_eq!(ours_values, &ours.values, "sample_mesh is deterministic");

    // Reference points.
    let tris: Vec<[Vec3A; 3]> =
        mesh.triangles.iter().map(|t| t.map(|i| Vec3A::from(mesh.positions[i as usize]))).collect();
    let dtris: Vec<[DVec3; 3]> =
        mesh.triangles.iter().map(|t| t.map(|i| mesh.positions[i as usize].as_dvec3())).collect();
    let mut rng = Rng(0x5eed ^ n as u64);
    let near_pool: Vec<usize> = (0..n).filter(|&i| ours.values[i].abs() <= NEAR_VOXELS * voxel).collect();
    let uniform: Vec<usize> = (0..plan.uniform).map(|_| rng.below(n)).collect();
    let near: Vec<usize> =
        (0..plan.near.min(near_pool.len())).map(|_| near_pool[rng.below(near_pool.len())]).collect();
    let coords = |idx: usize| {
        let (nx, ny) = (dims.x as usize, dims.y as usize);
        ((idx % nx) as u32, ((idx / nx) % ny) as u32, (idx / (nx * ny)) as u32)
    };
    let position = |idx: usize| {
        let (i, j, k) = coords(idx);
        ours.position(i, j, k)
    };
    let t = Instant::now();
    let reference = |set: &[usize]| -> Vec<(f32, f64)> {
        pool.install(|| {
            set.par_iter()
                .map(|&idx| {
                    let p = position(idx);
                    (brute_distance(&tris, p), brute_winding(&dtris, p))
                })
                .collect()
        })
    };
    let ref_uniform = reference(&uniform);
    let ref_near = reference(&near);
    out.line(format!(
        "reference: {} uniform and {} near-surface (|d| <= {NEAR_VOXELS} voxels, {} such samples) grid points, \
         brute force over all triangles in {:.1} s",
        uniform.len(),
        near.len(),
        near_pool.len(),
        t.elapsed().as_secs_f64()
    ));
    let eps = SIGN_EPS_VOXELS * voxel;
    let borderline =
        |refs: &[(f32, f64)]| refs.iter().filter(|(d, w)| *d > eps && (w - 0.5).abs() < 0.05).count();
    out.line(format!(
        "exact winding numbers within 0.05 of 0.5 (ambiguous): {} uniform, {} near-surface points",
        borderline(&ref_uniform),
        borderline(&ref_near)
    ));

    // Grid-wide sign disagreements between any two tools, judged by the exact winding number.
    let mut disagree: Vec<usize> = (0..n)
        .filter(|&i| {
            let s0 = tools[0].values.as_ref().unwrap()[i].is_sign_negative();
            tools.iter().any(|t| t.values.as_ref().unwrap()[i].is_sign_negative() != s0)
        })
        .collect();
    let total_disagree = disagree.len();
    if disagree.len() > plan.judge_cap {
        for s in 0..plan.judge_cap {
            let r = s + rng.below(disagree.len() - s);
            disagree.swap(s, r);
        }
        disagree.truncate(plan.judge_cap);
    }
    let t = Instant::now();
    let judged = reference(&disagree);
    let scale = total_disagree as f64 / disagree.len().max(1) as f64;
    out.line(format!(
        "grid-wide: {total_disagree} samples where some tool's sign differs from another's; {} judged by the \
         exact winding number in {:.1} s{}",
        disagree.len(),
        t.elapsed().as_secs_f64(),
        if scale > 1.0 {
            format!(" (a random subset: counts below scaled by {scale:.2})")
        } else {
            String::new()
        }
    ));

    // Per-tool table.
    let ours_median = median(&tools[0].times);
    let ours_cpu = median(&tools[0].cpu);
    let mut best_peer: Option<(usize, usize, f64)> = None; // (tool, wrong grid-wide, median)
    for (ti, tool) in tools.iter().enumerate() {
        let values = tool.values.as_ref().unwrap();
        let mut acc_u = Accuracy::default();
        for (&idx, &(d, w)) in uniform.iter().zip(&ref_uniform) {
            acc_u.add(values[idx], d, w, eps);
        }
        let mut acc_n = Accuracy::default();
        for (&idx, &(d, w)) in near.iter().zip(&ref_near) {
            acc_n.add(values[idx], d, w, eps);
        }
        let wrong_grid = disagree
            .iter()
            .zip(&judged)
            .filter(|&(&idx, &(d, w))| d > eps && values[idx].is_sign_negative() != (w >= 0.5))
            .count();
        let wrong_scaled = (wrong_grid as f64 * scale).round() as usize;
        let inside = values.iter().filter(|v| v.is_sign_negative()).count();
        let med = median(&tool.times);
        let cpu = median(&tool.cpu);
        let times: Vec<String> = tool.times.iter().map(|t| format!("{t:.3}")).collect();
        out.line(format!(
            "{:<22} median {med:.3} s wall (runs {} s), {cpu:.3} s CPU{}",
            tool.name,
            times.join(", "),
            if ti == 0 {
                String::new()
            } else {
                format!(
                    "; ours is {:.2}x faster by wall clock, {:.2}x by CPU time",
                    med / ours_median,
                    cpu / ours_cpu
                )
            }
        ));
        out.line(format!("    uniform points:      {}", acc_u.describe(voxel)));
        out.line(format!("    near-surface points: {}", acc_n.describe(voxel)));
        out.line(format!(
            "    grid-wide: {inside} samples inside ({:.2}%); wrong signs {wrong_scaled} ({:.4}% of the grid)",
            100.0 * inside as f64 / n as f64,
            100.0 * wrong_scaled as f64 / n as f64
        ));
        if ti > 0 {
            let better = match best_peer {
                None => true,
                Some((_, w, m)) => wrong_scaled < w || (wrong_scaled == w && med < m),
            };
            if better {
                best_peer = Some((ti, wrong_scaled, med));
            }
        }
    }
    if let Some((ti, wrong, med)) = best_peer {
        let cpu = median(&tools[ti].cpu);
        out.line(format!(
            "=> {name}: ours {ours_median:.3} s ({ours_cpu:.3} s CPU) vs {} {med:.3} s ({cpu:.3} s CPU) (its \
             best-faith sign method here: fewest wrong signs grid-wide, {wrong}): ours is {:.2}x faster by wall \
             clock, {:.2}x by CPU time",
            tools[ti].name,
            med / ours_median,
            cpu / ours_cpu
        ));
    }

    // Voxelize against sample.
    for VoxRun { res: r, vt, st, vg, sg, err } in &vox_runs {
        if let Some(e) = err {
            out.line(format!("voxelize_mesh at {r}: refused: {e}"));
            continue;
        }
        let (vg, sg) = (vg.as_ref().unwrap(), sg.as_ref().unwrap());
        assert_eq!((vg.dims, vg.origin, vg.voxel), (sg.dims, sg.origin, sg.voxel), "same layout");
        let mut max_err = 0.0f64;
        let mut sum_err = 0.0f64;
        let mut sign = 0usize;
        let mut surface = 0usize;
        for (&v, &s) in vg.values.iter().zip(&sg.values) {
            let e = ((v - s).abs() / sg.voxel) as f64;
            max_err = max_err.max(e);
            sum_err += e;
            if v == 0.0 {
                surface += 1;
            } else if (v < 0.0) != s.is_sign_negative() {
                sign += 1;
            }
        }
        let (vm, sm) = (median(vt), median(st));
        out.line(format!(
            "voxelize_mesh at {r} ({} samples) vs sample_mesh: |voxelize - sample| max {max_err:.3} voxel, mean \
             {:.4} voxel; sign disagreements {sign} (of {} non-surface samples; {surface} surface samples are 0); \
             time {vm:.3} s vs {sm:.3} s (medians): voxelize is {:.2}x faster",
            vg.values.len(),
            sum_err / vg.values.len() as f64,
            vg.values.len() - surface,
            sm / vm
        ));
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let full = args.iter().any(|a| a == "--bench");
    let mut plan = if full { FULL } else { SMOKE };
    if args.iter().any(|a| a == "--quick") {
        // For development: one run of ours only, few reference points.
        plan = Plan { rounds: 1, uniform: 300, near: 300, extra_voxelize: &[], peers: false, ..plan };
    }
    let filters: Vec<&String> = args.iter().filter(|a| !a.starts_with('-')).collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool");
    let mut out = Out::default();
    if full {
        out.line(header());
    } else {
        out.line(
            "smoke mode (run with `cargo bench --bench mesh_to_grid [--features peers]` for the benchmark)",
        );
    }
    out.line(format!(
        "mesh -> SDF grid: {} cells along the longest axis (+{GRID_MARGIN_CELLS} margin), {threads} rayon threads, \
         {} timed runs per tool interleaved; peers: {}",
        plan.res,
        plan.rounds,
        if cfg!(feature = "peers") { "mesh_to_sdf 0.4 (generate_grid_sdf)" } else { "none (build with --features peers)" }
    ));
    if full {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes");
        for name in ["stanford-bunny.obj", "armadillo.obj"] {
            if !filters.is_empty() && !filters.iter().any(|f| name.contains(f.as_str())) {
                continue;
            }
            let path = dir.join(name);
            if !path.exists() {
                out.line(format!("note: skipping {name}: {} not found", path.display()));
                continue;
            }
            let (mesh, report) = load_mesh(&path).expect("mesh loads");
            out.line(format!(
                "\n{name}: {} triangles read, {} degenerate dropped",
                report.triangles_read, report.degenerate_dropped
            ));
            bench_mesh(&mut out, &pool, name.trim_end_matches(".obj"), &mesh, &plan);
        }
    } else {
        bench_mesh(&mut out, &pool, "smoke (box + open sheet)", &smoke_mesh(), &plan);
    }
    let mut notes = String::new();
    let _ = write!(
        notes,
        "\nTimes: wall clock of one call, median of the runs. ours: sample_mesh_with_stats (BVH and \
         winding builds included). mesh_to_sdf: generate_grid_sdf on the same points. err: |tool's \
         |value| - exact distance|. Wrong signs: the tool's sign against the exact winding number \
         (inside at >= 0.5), points within {SIGN_EPS_VOXELS} voxel of the surface excluded."
    );
    out.line(notes);
    if full && filters.is_empty() && plan.peers == FULL.peers && plan.rounds == FULL.rounds {
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("reports/bench/mesh_to_grid.txt");
        match std::fs::write(&path, &out.text) {
            Ok(()) => println!("written to {}", path.display()),
            Err(e) => println!("could not write {}: {e}", path.display()),
        }
    }
}
