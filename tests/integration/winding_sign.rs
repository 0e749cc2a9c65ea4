//! The sign rule of the mesh -> grid sampler on open meshes, against a reference computed
//! here, independently of the crate's winding-number code: the exact generalized winding
//! number `w(q) = (1/4π) Σ Ω_t(q)`, each triangle's solid angle `Ω_t` by Van Oosterom and
//! Strackee's formula in `f64`, summed by brute force over every triangle. The documented
//! rule is: a sample is inside (negative) iff `w >= 0.5`.
//!
//! Meshes: `camelhead.obj` (open: one hole, 56 boundary edges) and `stanford-bunny.obj`
//! (holes in its base) from `../shared/meshes`; a test whose file is absent prints a note
//! and passes. Grids: `sample_mesh(mesh, 64, GRID_MARGIN_CELLS)`. Only samples farther
//! than [`AWAY`] voxels from the surface are judged: on the surface the sign is arbitrary,
//! and next to it the exact sum itself loses accuracy.

use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use sdfmesh::convert::mesh_to_grid::sample_mesh;
use sdfmesh::geometry::grid::SdfGrid;
use sdfmesh::mesh::{TriangleMesh, load_mesh};
use sdfmesh::plan::GRID_MARGIN_CELLS;

/// Samples whose unsigned distance to the mesh is at most this many voxels are not judged.
const AWAY: f32 = 1.0;

/// Grid resolution (cells along the longest axis of the mesh's box).
const RES: u32 = 64;

fn shared_mesh(name: &str) -> Option<TriangleMesh> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes").join(name);
    if !path.exists() {
        eprintln!("note: {} is absent; skipping its winding-sign checks", path.display());
        return None;
    }
    Some(load_mesh(&path).unwrap_or_else(|e| panic!("{name} loads: {e}")).0)
}

/// The reference: every triangle's corners in `f64`.
struct Reference {
    corners: Vec<[DVec3; 3]>,
}

impl Reference {
    fn new(mesh: &TriangleMesh) -> Self {
        let corners =
            mesh.triangles.iter().map(|t| t.map(|i| mesh.positions[i as usize].as_dvec3())).collect();
        Reference { corners }
    }

    /// The exact generalized winding number at `q`: `(1/4π) Σ Ω_t`, with
    /// `tan(Ω/2) = a·(b×c) / (|a||b||c| + (a·b)|c| + (a·c)|b| + (b·c)|a|)` for the corners
    /// `a, b, c` relative to `q` (positive seen from the side the counter-clockwise normal
    /// points away from, so 1 inside a closed outward mesh).
    fn winding(&self, q: DVec3) -> f64 {
        let mut omega = 0.0;
        for &[a, b, c] in &self.corners {
            let (a, b, c) = (a - q, b - q, c - q);
            let (la, lb, lc) = (a.length(), b.length(), c.length());
            let num = a.dot(b.cross(c));
            let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
            omega += 2.0 * num.atan2(den);
        }
        omega / (4.0 * std::f64::consts::PI)
    }
}

/// The mesh's boundary: directed edges `a -> b` not cancelled by an edge `b -> a`
/// (counting multiplicities), as segments.
fn boundary(mesh: &TriangleMesh) -> Vec<(DVec3, DVec3)> {
    let mut net: HashMap<(u32, u32), i32> = HashMap::new();
    for &[a, b, c] in &mesh.triangles {
        for (u, v) in [(a, b), (b, c), (c, a)] {
            *net.entry((u.min(v), u.max(v))).or_default() += if u < v { 1 } else { -1 };
        }
    }
    let p = |i: u32| mesh.positions[i as usize].as_dvec3();
    let mut edges: Vec<_> =
        net.into_iter().filter(|&(_, n)| n != 0).map(|((u, v), _)| (p(u), p(v))).collect();
    edges.sort_by(|x, y| x.0.to_array().partial_cmp(&y.0.to_array()).unwrap());
    edges
}

fn segment_distance(q: DVec3, (a, b): (DVec3, DVec3)) -> f64 {
    let ab = b - a;
    let t = ((q - a).dot(ab) / ab.length_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
    (a + ab * t - q).length()
}

/// Samples closer than this many voxels to the mesh's boundary count as near a hole, where
/// the winding number of an open mesh takes fractional values.
const NEAR_HOLE: f64 = 4.0;

/// Every sample of `g` farther than [`AWAY`] voxels from the surface: (index, position,
/// whether it lies within [`NEAR_HOLE`] voxels of one of the boundary `edges`).
fn away_samples(g: &SdfGrid, edges: &[(DVec3, DVec3)]) -> Vec<(usize, DVec3, bool)> {
    let (origin, voxel) = (g.origin.as_dvec3(), g.voxel as f64);
    let mut near = vec![false; g.values.len()];
    let dims = g.dims.as_ivec3();
    for &(a, b) in edges {
        let lo = ((a.min(b) - origin) / voxel - NEAR_HOLE).floor().as_ivec3().max(glam::IVec3::ZERO);
        let hi = ((a.max(b) - origin) / voxel + NEAR_HOLE).ceil().as_ivec3().min(dims - 1);
        for k in lo.z..=hi.z {
            for j in lo.y..=hi.y {
                for i in lo.x..=hi.x {
                    let (i, j, k) = (i as u32, j as u32, k as u32);
                    let q = g.position(i, j, k).as_dvec3();
                    if segment_distance(q, (a, b)) <= NEAR_HOLE * voxel {
                        near[g.index(i, j, k)] = true;
                    }
                }
            }
        }
    }
    let mut out = Vec::new();
    for k in 0..g.dims.z {
        for j in 0..g.dims.y {
            for i in 0..g.dims.x {
                let s = g.index(i, j, k);
                if g.values[s].abs() > AWAY * g.voxel {
                    out.push((s, g.position(i, j, k).as_dvec3(), near[s]));
                }
            }
        }
    }
    out
}

/// The result of judging samples: samples, of which with `|w - 0.5| < 0.05`;
/// disagreements, of which with `|w - 0.5| < 0.05`, `< 0.01`, `>=` [`AMBIGUOUS`]; the
/// largest `|w - 0.5|` of a disagreement.
#[derive(Debug, Default)]
struct Tally {
    samples: usize,
    level_set: usize,
    differ: usize,
    within_005: usize,
    within_001: usize,
    clear: usize,
    worst: f64,
}

fn judge(g: &SdfGrid, reference: &Reference, samples: &[(usize, DVec3, bool)], verbose: bool) -> Tally {
    let judged: Vec<(usize, DVec3, bool, f64)> =
        samples.par_iter().map(|&(s, q, near)| (s, q, near, reference.winding(q))).collect();
    let mut t = Tally { samples: judged.len(), ..Tally::default() };
    for &(s, q, near, w) in &judged {
        let v = g.values[s];
        t.level_set += ((w - 0.5).abs() < 0.05) as usize;
        if (v < 0.0) != (w >= 0.5) {
            t.differ += 1;
            let off = (w - 0.5).abs();
            t.within_005 += (off < 0.05) as usize;
            t.within_001 += (off < 0.01) as usize;
            t.clear += (off >= AMBIGUOUS) as usize;
            t.worst = t.worst.max(off);
            if verbose {
                eprintln!(
                    "  differs at {q:.5} (sample {s}): grid {:.4} voxels, exact w = {w:.6}, near a hole: {near}",
                    v / g.voxel
                );
            }
        }
    }
    t
}

/// The grid's sign may differ from the reference only where `|w - 0.5| <` this. Such a
/// sample lies next to the `0.5` level set of an open mesh's winding number, which is where
/// the sign flips: there the side of `0.5` is not resolved by computing in `f32`, nor by the
/// fast approximation the sampler uses for meshes with very many holes (error about `1e-3`,
/// see `winding.rs`), and moving the sample by a rounding error of its position may flip
/// it. (Measured at 64^3: every disagreement lies within `4e-4` of `0.5`.)
const AMBIGUOUS: f64 = 0.01;

/// Up to `per_kind` samples near a hole and as many elsewhere, evenly spread over each
/// kind in scan order (deterministic).
fn subset(samples: &[(usize, DVec3, bool)], per_kind: usize) -> Vec<(usize, DVec3, bool)> {
    let mut out = Vec::new();
    for near in [true, false] {
        let kind: Vec<_> = samples.iter().filter(|s| s.2 == near).collect();
        let stride = kind.len().div_ceil(per_kind).max(1);
        out.extend(kind.into_iter().step_by(stride).copied());
    }
    out
}

/// On open meshes (camelhead: one hole; the bunny: holes in its base) and on a mesh with
/// thousands of holes (camelhead without every 8th triangle, signed by the sampler's
/// other path), the grid's sign agrees with the exact `w >= 0.5` at 4000 samples farther
/// than [`AWAY`] voxel from the surface, half of them within [`NEAR_HOLE`] voxels of a
/// hole, except where `|w - 0.5| <` [`AMBIGUOUS`].
#[test]
fn grid_signs_follow_the_exact_winding_number_on_open_meshes() {
    let mut meshes = Vec::new();
    for name in ["camelhead.obj", "stanford-bunny.obj"] {
        let Some(mesh) = shared_mesh(name) else { continue };
        if name == "camelhead.obj" {
            meshes.push(("camelhead without every 8th triangle".to_string(), perforated(&mesh, 8)));
        }
        meshes.push((name.to_string(), mesh));
    }
    for (name, mesh) in &meshes {
        let start = Instant::now();
        let g = sample_mesh(mesh, RES, GRID_MARGIN_CELLS).unwrap();
        let edges = boundary(mesh);
        assert!(!edges.is_empty(), "{name} is open");
        let samples = subset(&away_samples(&g, &edges), 2000);
        let near = samples.iter().filter(|s| s.2).count();
        let t = judge(&g, &Reference::new(mesh), &samples, true);
        eprintln!(
            "{name}: {} of {} samples ({near} near a hole, {} with |w - 0.5| < 0.05) differ from the exact \
             w >= 0.5, {} of them with |w - 0.5| >= {AMBIGUOUS} [{:.1?}]",
            t.differ,
            t.samples,
            t.level_set,
            t.clear,
            start.elapsed()
        );
        assert!(near >= 500 && t.samples >= 2500, "{name}: {near} of {} samples near a hole", t.samples);
        // The subset reaches the fractional winding numbers near the holes.
        assert!(t.level_set >= 10, "{name}: {} samples near w = 0.5", t.level_set);
        assert_eq!(t.clear, 0, "{name}: signs differ from the exact winding number away from 0.5");
        assert!(t.differ <= 2, "{name}: {} ambiguous disagreements", t.differ);
    }
}

/// The full disagreement at 64^3: every sample away from the surface, for both meshes and
/// for camelhead perforated and as a soup (both signed by the sampler's many-holes path).
/// Slow (about 7 minutes of brute force on one core, most of it the bunny):
/// `cargo test --test integration winding_sign -- --ignored --nocapture`.
#[test]
#[ignore = "measurement: brute force over every sample"]
fn full_disagreement_at_64() {
    let mut meshes = Vec::new();
    for name in ["camelhead.obj", "stanford-bunny.obj"] {
        let Some(mesh) = shared_mesh(name) else { continue };
        if name == "camelhead.obj" {
            meshes.push(("camelhead, every 8th triangle removed".to_string(), perforated(&mesh, 8)));
            meshes.push(("camelhead as a soup".to_string(), soup(&mesh)));
        }
        meshes.push((name.to_string(), mesh));
    }
    for (name, mesh) in &meshes {
        let start = Instant::now();
        let g = sample_mesh(mesh, RES, GRID_MARGIN_CELLS).unwrap();
        let edges = boundary(mesh);
        let samples = away_samples(&g, &edges);
        let t = judge(&g, &Reference::new(mesh), &samples, true);
        eprintln!(
            "{name}: {} triangles, {} boundary edges, grid {}x{}x{}: {} of {} samples farther than {AWAY} voxel \
             ({} within 0.05 of 0.5) differ from the exact w >= 0.5 ({} within 0.05 of 0.5, {} within 0.01; worst |w - 0.5| {:.3e}) [{:.1?}]",
            mesh.triangles.len(),
            edges.len(),
            g.dims.x,
            g.dims.y,
            g.dims.z,
            t.differ,
            t.samples,
            t.level_set,
            t.within_005,
            t.within_001,
            t.worst,
            start.elapsed()
        );
    }
}

/// `mesh` without every `n`th triangle: a mesh with many small holes.
fn perforated(mesh: &TriangleMesh, n: usize) -> TriangleMesh {
    let triangles =
        mesh.triangles.iter().enumerate().filter(|(i, _)| i % n != n - 1).map(|(_, &t)| t).collect();
    TriangleMesh { positions: mesh.positions.clone(), triangles, normals: None }
}

/// `mesh` with no shared vertices (the same triangles, so the same winding number): every
/// edge is a boundary edge.
fn soup(mesh: &TriangleMesh) -> TriangleMesh {
    let positions = mesh.triangles.iter().flat_map(|t| t.map(|i| mesh.positions[i as usize])).collect();
    let triangles = (0..mesh.triangles.len() as u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    TriangleMesh { positions, triangles, normals: None }
}
