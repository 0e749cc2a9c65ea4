//! Mesh -> SDF grid sampling: closest points, nearest-triangle queries, winding numbers and
//! `sample_mesh` against brute-force and analytic references.

use std::path::Path;
use std::time::Instant;

use glam::{UVec3, Vec3, Vec3A};
use proptest::prelude::*;
use sdfmesh::convert::mesh_to_grid::closest::{NodeStack, TriangleBvh};
use sdfmesh::convert::mesh_to_grid::winding::{
    BETA, FastWinding, REFINE_BETA, exact_winding_number, is_closed,
};
use sdfmesh::convert::mesh_to_grid::{sample_mesh, sample_mesh_with_stats};
use sdfmesh::error::Error;
use sdfmesh::geometry::grid::{DEFAULT_MAX_GRID_BYTES, SdfGrid, check_size};
use sdfmesh::geometry::mesh::triangle::closest_point_on_triangle;
use sdfmesh::mesh::{TriangleMesh, load_mesh};

use crate::util::{Lcg, box_sdf};

// ---------------------------------------------------------------- test meshes

/// The box `[-h, h]`, 12 triangles, counter-clockwise seen from outside.
fn box_mesh(h: Vec3) -> TriangleMesh {
    let positions = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { -h.x } else { h.x },
                if i & 2 == 0 { -h.y } else { h.y },
                if i & 4 == 0 { -h.z } else { h.z },
            )
        })
        .collect();
    // Quads as (a, b, c, d) counter-clockwise from outside.
    let quads = [
        [0, 4, 6, 2], // -x
        [1, 3, 7, 5], // +x
        [0, 1, 5, 4], // -y
        [2, 6, 7, 3], // +y
        [0, 2, 3, 1], // -z
        [4, 5, 7, 6], // +z
    ];
    let triangles = quads.iter().flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]]).collect();
    TriangleMesh { positions, triangles, normals: None }
}

/// A UV sphere of radius `r` with `rings` latitude bands and `segments` longitudes;
/// `rings_kept < rings` keeps only the top bands (an open dome).
fn uv_sphere(r: f32, rings: u32, segments: u32, rings_kept: u32) -> TriangleMesh {
    let mut positions = vec![Vec3::new(0.0, 0.0, r)];
    for i in 1..rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segments {
            let phi = 2.0 * std::f32::consts::PI * j as f32 / segments as f32;
            positions.push(r * Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()));
        }
    }
    positions.push(Vec3::new(0.0, 0.0, -r));
    let south = positions.len() as u32 - 1;
    let ring = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let mut triangles = Vec::new();
    for j in 0..segments {
        triangles.push([0, ring(1, j), ring(1, j + 1)]);
    }
    for i in 1..rings - 1 {
        if i >= rings_kept {
            break;
        }
        for j in 0..segments {
            let (a, b, c, d) = (ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    if rings_kept >= rings {
        for j in 0..segments {
            triangles.push([south, ring(rings - 1, j + 1), ring(rings - 1, j)]);
        }
    }
    TriangleMesh { positions, triangles, normals: None }
}

fn bunny() -> Option<TriangleMesh> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes/stanford-bunny.obj");
    if !path.exists() {
        eprintln!("note: {} is absent; skipping the bunny checks", path.display());
        return None;
    }
    Some(load_mesh(&path).expect("bunny loads").0)
}

// ------------------------------------------------------------ references

/// Exact winding number in f64, computed independently of the library (Van Oosterom and
/// Strackee over every triangle).
fn brute_winding(mesh: &TriangleMesh, q: Vec3) -> f64 {
    let q = q.as_dvec3();
    let mut omega = 0.0;
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize].as_dvec3() - q);
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let num = a.dot(b.cross(c));
        let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
        omega += 2.0 * num.atan2(den);
    }
    omega / (4.0 * std::f64::consts::PI)
}

/// Brute-force nearest triangle: (squared distance, triangle index).
fn brute_nearest(mesh: &TriangleMesh, p: Vec3) -> (f32, u32) {
    let q = Vec3A::from(p);
    let mut best = (f32::INFINITY, u32::MAX);
    for (i, t) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = t.map(|i| Vec3A::from(mesh.positions[i as usize]));
        let d2 = (closest_point_on_triangle(q, a, b, c) - q).length_squared();
        if d2 < best.0 {
            best = (d2, i as u32);
        }
    }
    best
}

fn grid_samples(g: &SdfGrid) -> impl Iterator<Item = (u32, u32, u32)> + '_ {
    (0..g.dims.z).flat_map(move |k| (0..g.dims.y).flat_map(move |j| (0..g.dims.x).map(move |i| (i, j, k))))
}

// ------------------------------------------------------------ closest point

fn v3(r: f32) -> impl Strategy<Value = Vec3> {
    (-r..r, -r..r, -r..r).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn closest_point_matches_dense_sampling(a in v3(1.0), b in v3(1.0), c in v3(1.0), p in v3(2.0)) {
        let n = (b - a).cross(c - a);
        prop_assume!(n.length() > 0.05);
        let (a, b, c, p) = (Vec3A::from(a), Vec3A::from(b), Vec3A::from(c), Vec3A::from(p));
        let x = closest_point_on_triangle(p, a, b, c);
        let d = (x - p).length();
        // The point lies on the triangle: barycentric coordinates in [0, 1].
        let nn = (b - a).cross(c - a);
        let area2 = nn.length_squared();
        let u = (b - x).cross(c - x).dot(nn) / area2;
        let v = (c - x).cross(a - x).dot(nn) / area2;
        let w = 1.0 - u - v;
        prop_assert!(u >= -1e-4 && v >= -1e-4 && w >= -1e-4, "{u} {v} {w}");
        prop_assert!((x - a).dot(nn).abs() / area2.sqrt() < 1e-4);
        // Dense sampling of the triangle: never closer, and at most one step farther.
        const N: u32 = 300;
        let mut dense = f32::INFINITY;
        for i in 0..=N {
            for j in 0..=N - i {
                let (s, t) = (i as f32 / N as f32, j as f32 / N as f32);
                let y = a + (b - a) * s + (c - a) * t;
                dense = dense.min((y - p).length());
            }
        }
        let step = (b - a).length().max((c - a).length()) / N as f32;
        prop_assert!(d <= dense + 1e-5, "exact {d} > dense {dense}");
        prop_assert!(dense <= d + step + 1e-5, "exact {d} vs dense {dense}");
    }

    #[test]
    fn nearest_triangle_matches_brute_force(seed in any::<u64>(), points in prop::collection::vec(v3(1.5), 20)) {
        let mut rng = Lcg(seed);
        let mut mesh = TriangleMesh::default();
        for t in 0..300u32 {
            let centre = Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.0 - 1.0;
            for _ in 0..3 {
                let off = Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.3 - 0.15;
                mesh.positions.push(centre + off);
            }
            mesh.triangles.push([3 * t, 3 * t + 1, 3 * t + 2]);
        }
        mesh.triangles.retain(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            (b - a).cross(c - a).length() > 1e-4
        });
        let tree = TriangleBvh::new(&mesh);
        let mut stack = NodeStack::new();
        let mut visited = 0;
        for p in points {
            let (d2, _) = brute_nearest(&mesh, p);
            let n = tree.nearest(p, f32::INFINITY, &mut stack, &mut visited).unwrap();
            prop_assert!((n.dist2 - d2).abs() <= 1e-6 * d2.max(1e-6), "{} vs {d2}", n.dist2);
            // The reported triangle and point agree with the reported distance.
            let t = mesh.triangles[n.triangle as usize].map(|i| Vec3A::from(mesh.positions[i as usize]));
            let x = closest_point_on_triangle(Vec3A::from(p), t[0], t[1], t[2]);
            prop_assert!((Vec3::from(x) - n.point).length() < 1e-5);
            prop_assert!(((n.point - p).length_squared() - n.dist2).abs() < 1e-5);
            // A bound above the answer finds it; one well below finds nothing.
            let d = d2.sqrt();
            let m = tree.nearest(p, d * 1.001 + 1e-6, &mut stack, &mut visited).unwrap();
            prop_assert!((m.dist2 - d2).abs() <= 1e-6 * d2.max(1e-6));
            if d > 1e-3 {
                prop_assert!(tree.nearest(p, d * 0.99, &mut stack, &mut visited).is_none());
            }
        }
    }
}

// ------------------------------------------------------------ winding numbers

#[test]
fn winding_is_one_inside_and_zero_outside_closed_meshes() {
    for mesh in [uv_sphere(1.0, 16, 24, 16), box_mesh(Vec3::new(1.0, 0.6, 0.8))] {
        mesh.validate().unwrap();
        let tree = TriangleBvh::new(&mesh);
        let fast = FastWinding::new(&tree);
        let mut stack = Vec::new();
        let mut rng = Lcg(7);
        let mut inside = 0;
        for _ in 0..400 {
            let p = (Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.0 - 1.0) * 1.6;
            let exact = brute_winding(&mesh, p);
            let lib = exact_winding_number(&tree, p);
            let w = fast.winding_number(&tree, p, BETA, &mut stack, &mut 0);
            let (d2, _) = brute_nearest(&mesh, p);
            if d2 < 1e-6 {
                continue;
            }
            // Exactly an integer away from the surface of a closed mesh.
            let expect = exact.round();
            assert!(expect == 0.0 || expect == 1.0, "{exact} at {p}");
            assert!((exact - expect).abs() < 1e-6, "{exact} at {p}");
            assert!((lib as f64 - expect).abs() < 1e-4, "{lib} at {p}");
            assert!((w as f64 - expect).abs() < 0.06, "fast {w} vs {expect} at {p}");
            assert_eq!(fast.is_inside(&tree, p, &mut stack, &mut 0), expect == 1.0, "{p}");
            inside += (expect == 1.0) as u32;
        }
        assert!(inside > 20 && inside < 350, "{inside}");
        assert!(fast.winding_number(&tree, Vec3::ZERO, BETA, &mut stack, &mut 0) > 0.99);
        assert!(fast.winding_number(&tree, Vec3::splat(30.0), BETA, &mut stack, &mut 0).abs() < 1e-4);
    }
}

#[test]
fn winding_of_an_open_hemisphere() {
    // The top half of a sphere (z >= 0), open at the rim z = 0.
    let dome = uv_sphere(1.0, 32, 48, 16);
    dome.validate().unwrap();
    let tree = TriangleBvh::new(&dome);
    let fast = FastWinding::new(&tree);
    let mut stack = Vec::new();
    let w = |p: Vec3, beta: f32, stack: &mut Vec<u32>| fast.winding_number(&tree, p, beta, stack, &mut 0);
    // The centre of the rim disk sees half of the sphere (up to the faceting).
    let centre = brute_winding(&dome, Vec3::ZERO);
    assert!((centre - 0.5).abs() < 5e-3, "{centre}");
    assert!((w(Vec3::ZERO, REFINE_BETA, &mut stack) as f64 - centre).abs() < 5e-3);
    assert!((w(Vec3::ZERO, BETA, &mut stack) as f64 - centre).abs() < 0.05);
    // Across the rim disk the winding number is continuous and crosses 0.5: inside the
    // dome above, outside below; on the disk it stays near 0.5 away from the rim.
    for r in [0.0, 0.3, 0.6] {
        let above = Vec3::new(r, 0.0, 0.2);
        let below = Vec3::new(r, 0.0, -0.2);
        let on = Vec3::new(r, 0.0, 0.0);
        let (wa, wb, wo) = (
            w(above, REFINE_BETA, &mut stack),
            w(below, REFINE_BETA, &mut stack),
            w(on, REFINE_BETA, &mut stack),
        );
        assert!(wa > 0.5 && wb < 0.5, "{wa} {wb}");
        assert!(wb < wo && wo < wa, "{wb} {wo} {wa}");
        assert!((wo - 0.5).abs() < 0.05, "{wo}");
        assert!(fast.is_inside(&tree, above, &mut stack, &mut 0));
        assert!(!fast.is_inside(&tree, below, &mut stack, &mut 0));
    }
    // Along the axis inside the sphere: 1 minus the rim disk's share of the sphere,
    // (1 - |z| / sqrt(z² + 1)) / 2, above the rim; that share below it.
    for z in [0.9f32, 0.5, -0.5, -0.9, 2.0, -3.0] {
        let p = Vec3::new(0.0, 0.0, z);
        let reference = brute_winding(&dome, p);
        let disk = (1.0 - (z.abs() / (z * z + 1.0).sqrt()) as f64) / 2.0;
        let analytic = if z >= 0.0 { 1.0 - disk } else { disk };
        if z < 1.0 {
            assert!((reference - analytic).abs() < 0.01, "{z}: {reference} vs {analytic}");
        }
        assert!((w(p, BETA, &mut stack) as f64 - reference).abs() < 0.06, "{z}");
        assert!((w(p, REFINE_BETA, &mut stack) as f64 - reference).abs() < 5e-3, "{z}");
    }
    assert!(w(Vec3::new(0.0, 0.0, -20.0), BETA, &mut stack).abs() < 1e-3);
}

#[test]
fn fast_winding_accuracy_against_the_exact_sum() {
    let mut meshes = vec![uv_sphere(1.0, 24, 32, 10), uv_sphere(1.0, 40, 60, 40)];
    meshes.extend(bunny());
    for mesh in &meshes {
        let tree = TriangleBvh::new(mesh);
        let fast = FastWinding::new(&tree);
        let second = FastWinding::with_order(&tree, true);
        let (lo, hi) = mesh.bounds().unwrap();
        let (c, e) = ((lo + hi) * 0.5, (hi - lo) * 0.75);
        let mut rng = Lcg(11);
        let mut stack = Vec::new();
        let (mut worst, mut mean, mut worst_refined, mut worst_second) = (0.0f64, 0.0, 0.0f64, 0.0f64);
        let n = if mesh.triangles.len() > 10_000 { 100 } else { 400 };
        for _ in 0..n {
            let p = c + (Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.0 - 1.0) * e;
            let reference = brute_winding(mesh, p);
            let mut eval =
                |f: &FastWinding, beta| f.winding_number(&tree, p, beta, &mut stack, &mut 0) as f64;
            let x = eval(&fast, f32::INFINITY);
            assert!((x - reference).abs() < 1e-3, "exact tree sum {x} vs {reference}");
            let err = (eval(&fast, BETA) - reference).abs();
            worst = worst.max(err);
            mean += err / n as f64;
            worst_refined = worst_refined.max((eval(&fast, REFINE_BETA) - reference).abs());
            worst_second = worst_second.max((eval(&second, BETA) - reference).abs());
            if (reference - 0.5).abs() > 0.01 {
                assert_eq!(
                    fast.is_inside(&tree, p, &mut stack, &mut 0),
                    reference >= 0.5,
                    "{p}: {reference}"
                );
            }
        }
        eprintln!(
            "{} triangles: fast winding error at beta {BETA}: mean {mean:.1e}, worst {worst:.1e} \
             (second order: {worst_second:.1e}); at beta {REFINE_BETA}: worst {worst_refined:.1e}",
            mesh.triangles.len()
        );
        assert!(mean < 1e-2, "{mean}");
        assert!(worst < 0.1, "{worst}");
        assert!(worst_refined < 1e-2, "{worst_refined}");
    }
}

// ------------------------------------------------------------ sample_mesh

#[test]
fn box_mesh_samples_match_the_analytic_box_sdf() {
    let h = Vec3::new(1.0, 0.6, 0.8);
    let mesh = box_mesh(h);
    mesh.validate().unwrap();
    let (g, stats) = sample_mesh_with_stats(&mesh, 20, 2).unwrap();
    assert_eq!(stats.samples, g.values.len() as u64);
    assert!(stats.closest_nodes > 0 && stats.winding_nodes > 0);
    assert_eq!(g.dims.x, 25);
    let size = 2.0 * h.max_element() as f64;
    let mut negatives = 0;
    for (i, j, k) in grid_samples(&g) {
        let p = g.position(i, j, k);
        let v = g.get(i, j, k) as f64;
        let exact = box_sdf(p.as_dvec3(), h.as_dvec3());
        assert!((v - exact).abs() <= 1e-5 * size, "({i},{j},{k}) at {p}: {v} vs {exact}");
        if exact.abs() > 1e-6 {
            assert_eq!(v < 0.0, exact < 0.0, "sign at {p}");
        }
        negatives += (v < 0.0) as u32;
    }
    assert!(negatives > 1000, "{negatives}");
    // Interpolation between exact samples is close to the field inside the box too.
    let p = Vec3::new(0.13, -0.21, 0.05);
    assert!((g.trilinear(p) as f64 - box_sdf(p.as_dvec3(), h.as_dvec3())).abs() < 0.05);
}

#[test]
fn sphere_mesh_samples_match_brute_force() {
    let mesh = uv_sphere(1.0, 12, 18, 12);
    mesh.validate().unwrap();
    let g = sample_mesh(&mesh, 16, 2).unwrap();
    let (lo, hi) = g.bounds();
    assert!(lo.cmple(Vec3::splat(-1.0)).all() && hi.cmpge(Vec3::splat(1.0)).all());
    let mut inside = 0;
    for (i, j, k) in grid_samples(&g) {
        let p = g.position(i, j, k);
        let v = g.get(i, j, k);
        let (d2, _) = brute_nearest(&mesh, p);
        let d = d2.sqrt();
        assert!((v.abs() - d).abs() <= 2e-5, "{p}: {v} vs {d}");
        if d > 1e-5 {
            let w = brute_winding(&mesh, p);
            assert_eq!(v < 0.0, w >= 0.5, "sign at {p}: {v}, winding {w}");
            inside += (w >= 0.5) as u32;
        }
    }
    assert!(inside > 500, "{inside}");
}

#[test]
fn bunny_signs_agree_with_brute_force_winding() {
    let Some(mesh) = bunny() else { return };
    let g = sample_mesh(&mesh, 32, 2).unwrap();
    let mut rng = Lcg(3);
    let (mut agree, mut total, mut inside) = (0, 0, 0);
    for _ in 0..300 {
        let (i, j, k) = (
            (rng.next() % g.dims.x as u64) as u32,
            (rng.next() % g.dims.y as u64) as u32,
            (rng.next() % g.dims.z as u64) as u32,
        );
        let p = g.position(i, j, k);
        let v = g.get(i, j, k);
        let w = brute_winding(&mesh, p);
        let (d2, _) = brute_nearest(&mesh, p);
        assert!((v.abs() - d2.sqrt()).abs() <= 1e-6 * g.voxel * 32.0, "{p}: {v} vs {}", d2.sqrt());
        total += 1;
        agree += ((v < 0.0) == (w >= 0.5)) as u32;
        inside += (w >= 0.5) as u32;
    }
    eprintln!("bunny res 32: {agree}/{total} signs agree, {inside} inside");
    assert!(agree * 100 >= total * 99, "{agree}/{total}");
    // Near the surface too: samples within two voxels of it.
    let mut near = 0;
    let mut near_agree = 0;
    for (i, j, k) in grid_samples(&g).step_by(7) {
        let v = g.get(i, j, k);
        if v.abs() > 2.0 * g.voxel || v.abs() < 1e-4 * g.voxel {
            continue;
        }
        let w = brute_winding(&mesh, g.position(i, j, k));
        near += 1;
        near_agree += ((v < 0.0) == (w >= 0.5)) as u32;
        if near >= 300 {
            break;
        }
    }
    eprintln!("bunny res 32 near the surface: {near_agree}/{near} signs agree");
    assert!(near_agree * 100 >= near * 99, "{near_agree}/{near}");
}

#[test]
fn reused_signs_match_direct_winding_numbers() {
    assert!(is_closed(&box_mesh(Vec3::ONE)) && is_closed(&uv_sphere(1.0, 8, 8, 8)));
    assert!(!is_closed(&uv_sphere(1.0, 8, 8, 4)));
    let mut flipped = box_mesh(Vec3::ONE);
    flipped.triangles[0].swap(1, 2);
    assert!(!is_closed(&flipped));
    let Some(mesh) = bunny() else { return };
    let (g, stats) = sample_mesh_with_stats(&mesh, 32, 2).unwrap();
    assert!(!stats.closed);
    assert!(stats.winding_evaluations < stats.samples);
    let tree = TriangleBvh::new(&mesh);
    let fast = FastWinding::new(&tree);
    let mut stack = Vec::new();
    let (mut differ, mut total) = (0, 0);
    for (i, j, k) in grid_samples(&g) {
        let v = g.get(i, j, k);
        if v.abs() < 1e-6 {
            continue;
        }
        total += 1;
        let p = g.position(i, j, k);
        if (v < 0.0) != fast.is_inside(&tree, p, &mut stack, &mut 0) {
            differ += 1;
            let w = brute_winding(&mesh, p);
            eprintln!("reused sign differs at {p}: {v}, exact winding {w}");
        }
    }
    eprintln!(
        "bunny res 32: {differ} of {total} reused signs differ from direct evaluation \
         (winding evaluated at {} samples)",
        stats.winding_evaluations
    );
    assert!(differ * 1000 <= total, "{differ}/{total}");
}

#[test]
fn huge_grids_are_refused_before_allocating() {
    let e = check_size(UVec3::splat(100_000), DEFAULT_MAX_GRID_BYTES).unwrap_err();
    assert!(matches!(e, Error::Usage(_)));
    let msg = e.to_string();
    assert!(msg.contains("100000x100000x100000") && msg.contains("lower resolution"), "{msg}");
    let e = sample_mesh(&box_mesh(Vec3::ONE), 100_000, 1).unwrap_err();
    assert!(matches!(e, Error::Usage(_)), "{e}");
    assert!(e.to_string().contains("100003x100003x100003"), "{e}");
    assert!(sample_mesh(&TriangleMesh::default(), 8, 1).is_err());
    assert!(sample_mesh(&box_mesh(Vec3::ONE), 0, 1).is_err());
}

/// User + system CPU time of this process so far (Linux; 0 elsewhere), to read timings
/// taken beside other loads.
fn process_cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // Fields after the parenthesised command name; utime and stime are the 14th and 15th.
    let rest = &stat[stat.rfind(')').map_or(0, |i| i + 2)..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

/// Timings (not asserted): `cargo test --release --test grid_sample -- --ignored --nocapture`.
#[test]
#[ignore = "timing report"]
fn bunny_sampling_timings() {
    let Some(mesh) = bunny() else { return };
    for res in [64, 128] {
        let cpu0 = process_cpu_seconds();
        let start = Instant::now();
        let (g, s) = sample_mesh_with_stats(&mesh, res, 2).unwrap();
        let total = start.elapsed();
        let cpu = process_cpu_seconds() - cpu0;
        eprintln!(
            "bunny ({} triangles) res {res}: {}x{}x{} samples in {total:.3?} wall, {cpu:.2} s CPU (build {:.3?}, fill {:.3?}), \
             {:.1} closest nodes and {:.1} winding nodes per sample, winding evaluated at {:.1}% \
             of the samples (closed: {}), {} threads",
            mesh.triangles.len(),
            g.dims.x,
            g.dims.y,
            g.dims.z,
            s.build_time,
            s.fill_time,
            s.closest_nodes as f64 / s.samples as f64,
            s.winding_nodes as f64 / s.samples as f64,
            100.0 * s.winding_evaluations as f64 / s.samples as f64,
            s.closed,
            rayon::current_num_threads()
        );
    }
}
