//! Classic marching cubes (`ExtractMethod::MarchingCubes`) against marching tetrahedra
//! and dual contouring: closed, edge-manifold, outward, no duplicate vertices on random
//! fields full of ambiguous faces; one vertex per sign-changing grid edge (plus the rare
//! vertex of a cycle that needs its own); about a third of marching tetrahedra's triangles for
//! the same surface; `toolkit convert --method mt` still gives marching tetrahedra.

use std::collections::HashSet;

use glam::{DVec3, Vec3};
use proptest::prelude::*;
use sdfmesh::convert::extract::{ExtractMethod, Field, extract, extract_sampled, sample_grid};
use sdfmesh::geometry::Aabb;
use sdfmesh::mesh::{TriangleMesh, is_degenerate};

use crate::util::{cube, non_manifold_edges, signed_volume};

/// The methods that are closed and manifold by construction (dual contouring is only
/// checked on smoother fields, in `tests/extract.rs`: on this noise a dual edge between two
/// cells can be used four times, see `src/convert/extract/mod.rs`).
const PROVEN: [ExtractMethod; 2] = [ExtractMethod::MarchingCubes, ExtractMethod::MarchingTetrahedra];

/// Closed, edge-manifold, valid, no duplicate positions, no degenerate triangles.
fn assert_clean(m: &TriangleMesh, what: &str) {
    assert!(!m.triangles.is_empty(), "{what}: empty");
    m.validate().unwrap_or_else(|e| panic!("{what}: invalid: {e}"));
    let mut seen = HashSet::new();
    assert!(
        m.positions.iter().all(|p| seen.insert((*p + Vec3::ZERO).to_array().map(f32::to_bits))),
        "{what}: duplicate positions"
    );
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        assert!(!is_degenerate(a, b, c), "{what}: degenerate triangle {t:?}");
    }
    assert!(m.is_closed(), "{what}: {} boundary edges", m.boundary_edge_count());
    assert_eq!(non_manifold_edges(m), 0, "{what}: not edge-manifold");
}

/// Fraction of triangles whose normal points towards decreasing `f`.
fn inward_fraction(m: &TriangleMesh, f: impl Fn(DVec3) -> f64, step: f64) -> f64 {
    let wrong = m
        .triangles
        .iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize].as_dvec3());
            let n = (b - a).cross(c - a).normalize();
            let g = (a + b + c) / 3.0;
            f(g + n * step) < f(g - n * step)
        })
        .count();
    wrong as f64 / m.triangles.len() as f64
}

/// Value noise: random values in [-1, 1] on a lattice of spacing `s` (hashed from the
/// lattice point and `seed`), trilinearly interpolated, clipped to a ball of radius 0.9.
/// At spacings near the extraction cell it gives many ambiguous faces and thin tunnels.
fn noise(seed: u64, s: f64, bias: f64) -> impl Fn(DVec3) -> f64 + Sync {
    let hash = move |i: i64, j: i64, k: i64| -> f64 {
        let mut h = seed ^ (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        h ^= (j as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f);
        h ^= (k as u64).wrapping_mul(0x1656_67b1_9e37_79f9);
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        (h >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    };
    move |p: DVec3| {
        let q = p / s;
        let b = q.floor();
        let t = q - b;
        let (i, j, k) = (b.x as i64, b.y as i64, b.z as i64);
        let mut v = 0.0;
        for c in 0..8 {
            let (dx, dy, dz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
            let w = if dx == 1 { t.x } else { 1.0 - t.x }
                * if dy == 1 { t.y } else { 1.0 - t.y }
                * if dz == 1 { t.z } else { 1.0 - t.z };
            v += w * hash(i + dx, j + dy, k + dz);
        }
        (v * s + bias).max(p.length() - 0.9)
    }
}

/// Sign-changing axis edges of `f`'s extraction grid at `res` over `bounds`.
fn crossing_edges(f: &(impl Fn(DVec3) -> f64 + Sync), bounds: &Aabb, res: u32) -> usize {
    let grid = sample_grid(f, Field::Arbitrary, bounds, res).expect("bounded");
    let (n, v) = (grid.dims(), grid.values());
    let idx = |x: usize, y: usize, z: usize| x + n[0] * (y + n[1] * z);
    let mut count = 0;
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let inside = v[idx(x, y, z)] < 0.0;
                for (dx, dy, dz) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                    let (a, b, c) = (x + dx, y + dy, z + dz);
                    if a < n[0] && b < n[1] && c < n[2] && (v[idx(a, b, c)] < 0.0) != inside {
                        count += 1;
                    }
                }
            }
        }
    }
    count
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
    /// Both proven methods are clean on value noise; marching cubes has exactly one vertex per
    /// sign-changing grid edge apart from the cycles' own vertices.
    #[test]
    fn noise_fields_are_closed_and_manifold(
        seed in any::<u64>(),
        spacing in 0.04f64..0.3,
        bias in -0.05f64..0.05,
        res in 10u32..36,
    ) {
        let f = noise(seed, spacing, bias);
        let bounds = cube(1.0);
        let edges = crossing_edges(&f, &bounds, res);
        prop_assume!(edges > 0);
        for method in PROVEN {
            let m = extract(&f, Field::Arbitrary, &bounds, res, method);
            let what = format!("{method:?} seed {seed} spacing {spacing} bias {bias} res {res}");
            assert_clean(&m, &what);
            if method == ExtractMethod::MarchingCubes {
                prop_assert!(m.positions.len() >= edges, "{what}: {} vertices, {edges} edges", m.positions.len());
                // A cycle's own vertex is rare: at most one per 20 crossings here.
                prop_assert!(m.positions.len() <= edges + edges / 20 + 1, "{what}");
            }
        }
    }
}

/// Many seeds at cell-sized noise: every mesh is clean, and some of them contain cycles
/// that needed a vertex of their own (so that path is exercised).
#[test]
fn cycles_with_their_own_vertex_stay_clean() {
    let mut with_own = 0;
    for seed in 0..60u64 {
        let f = noise(seed * 7919 + 1, 0.09, 0.0);
        let m = extract(&f, Field::Arbitrary, &cube(1.0), 24, ExtractMethod::MarchingCubes);
        assert_clean(&m, &format!("seed {seed}"));
        let edges = crossing_edges(&f, &cube(1.0), 24);
        assert!(m.positions.len() >= edges);
        with_own += (m.positions.len() > edges) as usize;
    }
    println!("{with_own} of 60 meshes have cycles with their own vertex");
    assert!(with_own > 0, "no mesh exercised the cycle vertex");
}

/// The same smooth surface: marching cubes and tetrahedra enclose the same volume,
/// marching cubes with about a third of the triangles; it faces outwards.
#[test]
fn marching_cubes_has_a_third_of_tetrahedra_triangles() {
    let f = |p: DVec3| {
        let q = DVec3::new(p.x, p.y * 1.3, p.z * 0.8);
        q.length() - 0.8 + 0.1 * (3.0 * p.x).sin() * (2.0 * p.y).cos()
    };
    for res in [24u32, 48, 96] {
        let mc = extract(&f, Field::Arbitrary, &cube(1.2), res, ExtractMethod::MarchingCubes);
        let mt = extract(&f, Field::Arbitrary, &cube(1.2), res, ExtractMethod::MarchingTetrahedra);
        assert_clean(&mc, "mc");
        assert_clean(&mt, "mt");
        let (vc, vt) = (signed_volume(&mc), signed_volume(&mt));
        let h = 2.4 / res as f64;
        println!(
            "res {res}: MC {} tris, MT {} tris, volumes {vc:.5} {vt:.5}",
            mc.triangles.len(),
            mt.triangles.len()
        );
        assert!(vc > 0.0 && (vc - vt).abs() < 0.5 * h * vt.abs(), "res {res}: volumes {vc} {vt}");
        let ratio = mc.triangles.len() as f64 / mt.triangles.len() as f64;
        assert!((0.28..0.4).contains(&ratio), "res {res}: MC/MT triangles {ratio}");
        assert_eq!(inward_fraction(&mc, f, 1e-4), 0.0, "res {res}: MC faces inwards");
        // Every vertex on the surface (refined crossings), like marching tetrahedra.
        let worst = mc.positions.iter().map(|p| f(p.as_dvec3()).abs()).fold(0.0, f64::max);
        assert!(worst < 0.01 * h, "res {res}: vertex off the surface by {worst}");
    }
}

/// `extract` is `sample_grid` then `extract_sampled`, for every method.
#[test]
fn sampled_extraction_is_the_same() {
    let f = noise(42, 0.2, 0.02);
    for method in
        [ExtractMethod::MarchingCubes, ExtractMethod::MarchingTetrahedra, ExtractMethod::DualContouring]
    {
        let a = extract(&f, Field::Arbitrary, &cube(1.0), 20, method);
        let grid = sample_grid(&f, Field::Arbitrary, &cube(1.0), 20).unwrap();
        let b = extract_sampled(&f, &grid, method);
        assert_eq!(a.positions, b.positions, "{method:?}");
        assert_eq!(a.triangles, b.triangles, "{method:?}");
    }
}

/// `--method mc` (the default), `mt` and `dc` through the toolkit: marching tetrahedra
/// gives about three times the triangles of the other two.
#[test]
fn convert_offers_every_method() {
    let dir = crate::util::temp_dir("convert");
    let scene = dir.join("s.toml");
    std::fs::write(
        &scene,
        "[camera]\nposition = [0, 0, -4]\nlook_at = [0, 0, 0]\n\n[[objects]]\ntype = \"subtraction\"\n\n\
         [[objects.children]]\ntype = \"sphere\"\nradius = 1\n\n[[objects.children]]\ntype = \"sphere\"\n\
         radius = 0.6\ntranslate = [0.5, 0, 0]\n",
    )
    .unwrap();
    let mut tris = Vec::new();
    for method in ["mc", "mt", "dc"] {
        let out = dir.join(format!("{method}.ply"));
        let run = crate::util::toolkit(&[
            "convert",
            scene.to_str().unwrap(),
            "--to",
            "mesh",
            "--res",
            "24",
            "--method",
            method,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(run.status.success(), "{method}: {}", String::from_utf8_lossy(&run.stderr));
        let mesh = sdfmesh::mesh::load_mesh(&out).expect("written mesh loads").0;
        assert_clean(&mesh, method);
        tris.push(mesh.triangles.len() as f64);
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(tris[1] > 2.5 * tris[0] && tris[1] > 2.5 * tris[2], "triangles mc, mt, dc: {tris:?}");
}
