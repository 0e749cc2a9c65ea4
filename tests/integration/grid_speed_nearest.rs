//! The fast nearest-triangle paths of `sdfmesh::convert::mesh_to_grid::closest` (bounding cylinders beside
//! the boxes, leaf packets, group walks of up to `GROUP_MAX` points) and `sample_mesh`,
//! which uses them, against an independent `f64` brute force, on smooth meshes (where the
//! cylinders prune most) with points on, near, inside and far from the surface, hints that
//! are right, wrong or out of range, and coordinates far from the origin.

use glam::{DVec3, Vec3};
use proptest::prelude::*;
use sdfmesh::convert::mesh_to_grid::closest::{GROUP_MAX, GroupStack, Nearest, NodeStack, TriangleBvh};
use sdfmesh::convert::mesh_to_grid::sample_mesh;
use sdfmesh::mesh::TriangleMesh;
use sdfmesh::simd::Portable;

use crate::util::Lcg;

/// A bumpy UV sphere: radius `r * (1 + amp * sin(k theta) * sin(m phi))` around `centre`,
/// `rings` x `2 rings` quads; with `open`, the bottom quarter of the rings is left out.
fn bumpy_sphere(centre: Vec3, r: f32, amp: f32, k: f32, m: f32, rings: u32, open: bool) -> TriangleMesh {
    let segments = 2 * rings;
    let point = |i: u32, j: u32| {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        let phi = 2.0 * std::f32::consts::PI * j as f32 / segments as f32;
        let rr = r * (1.0 + amp * (k * theta).sin() * (m * phi).sin());
        centre + rr * Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
    };
    let mut positions = vec![point(0, 0)];
    for i in 1..rings {
        for j in 0..segments {
            positions.push(point(i, j));
        }
    }
    positions.push(point(rings, 0));
    let south = positions.len() as u32 - 1;
    let ring = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let kept = if open { rings * 3 / 4 } else { rings };
    let mut triangles = Vec::new();
    for j in 0..segments {
        triangles.push([0, ring(1, j), ring(1, j + 1)]);
    }
    for i in 1..(rings - 1).min(kept) {
        for j in 0..segments {
            let (a, b, c, d) = (ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    if !open {
        for j in 0..segments {
            triangles.push([south, ring(rings - 1, j + 1), ring(rings - 1, j)]);
        }
    }
    let mut mesh = TriangleMesh { positions, triangles, normals: None };
    mesh.triangles.retain(|t| {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        (b - a).cross(c - a).length() > 1e-7 * r * r
    });
    mesh
}

/// Distance from `p` to the segment `a b`, in `f64`.
fn segment_distance(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
    (p - (a + ab * t)).length()
}

/// Exact distance from `p` to the triangle `a b c` in `f64`, by a method independent of
/// the library's: the plane's foot point if it lies inside (barycentric coordinates), else
/// the nearest of the three edges.
fn triangle_distance(p: DVec3, [a, b, c]: [DVec3; 3]) -> f64 {
    let n = (b - a).cross(c - a);
    let foot = p - n * ((p - a).dot(n) / n.length_squared());
    let area = n.length_squared();
    let u = (b - foot).cross(c - foot).dot(n) / area;
    let v = (c - foot).cross(a - foot).dot(n) / area;
    if u >= 0.0 && v >= 0.0 && u + v <= 1.0 {
        (p - foot).length()
    } else {
        segment_distance(p, a, b).min(segment_distance(p, b, c)).min(segment_distance(p, c, a))
    }
}

/// Brute-force distance from `p` to the mesh, `f64`.
fn brute(mesh: &TriangleMesh, p: Vec3) -> f64 {
    let p = p.as_dvec3();
    mesh.triangles
        .iter()
        .map(|t| triangle_distance(p, t.map(|i| mesh.positions[i as usize].as_dvec3())))
        .fold(f64::INFINITY, f64::min)
}

/// The error allowed for an `f32` distance at `p`: a few units of `f32` rounding of the
/// coordinates involved, far below the `1e-5` of the box size that grids are held to.
fn tolerance(mesh: &TriangleMesh, p: Vec3) -> f64 {
    let (lo, hi) = mesh.bounds().unwrap();
    let size = (hi - lo).max_element() as f64;
    let scale = p.abs().max_element().max(lo.abs().max(hi.abs()).max_element()) as f64;
    1e-6 * size + 8.0 * f32::EPSILON as f64 * scale
}

/// Query points for `mesh`: on triangles, just off them, inside, and up to 60 radii away.
fn query_points(mesh: &TriangleMesh, centre: Vec3, r: f32, rng: &mut Lcg, n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|i| {
            let t =
                mesh.triangles[(rng.unit() * mesh.triangles.len() as f32) as usize % mesh.triangles.len()];
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            let (u, v) = (rng.unit(), rng.unit());
            let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
            let on = a + (b - a) * u + (c - a) * v;
            match i % 5 {
                0 => on,
                1 => on + rng.dir() * r * 0.02 * rng.unit(),
                2 => centre + rng.dir() * r * 0.5 * rng.unit(),
                3 => centre + rng.dir() * r * (1.5 + 3.0 * rng.unit()),
                _ => centre + rng.dir() * r * (5.0 + 55.0 * rng.unit()),
            }
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn nearest_and_group_walks_match_brute_force(
        seed in any::<u64>(),
        far_away in any::<bool>(),
        open in any::<bool>(),
        amp in 0.0f32..0.3,
        k in 1.0f32..6.0,
        m in 1.0f32..6.0,
        r in 0.01f32..10.0,
    ) {
        let mut rng = Lcg(seed);
        let centre = if far_away { Vec3::new(1000.0, -250.0, 40.0) * r } else { Vec3::new(0.1, 0.2, -0.3) * r };
        let mesh = bumpy_sphere(centre, r, amp, k, m, 24, open);
        let tree = TriangleBvh::new(&mesh);
        let (mut stack, mut group_stack, mut visited) = (NodeStack::new(), GroupStack::default(), 0u64);
        let points = query_points(&mesh, centre, r, &mut rng, 60);
        for &p in &points {
            let want = brute(&mesh, p);
            let tol = tolerance(&mesh, p);
            let n = tree.nearest(p, f32::INFINITY, &mut stack, &mut visited).unwrap();
            let got = (n.dist2 as f64).sqrt();
            prop_assert!((got - want).abs() <= tol, "{p}: {got} vs brute force {want}");
            // The reported triangle is at the reported distance.
            let t = mesh.triangles[n.triangle as usize].map(|i| mesh.positions[i as usize].as_dvec3());
            prop_assert!((triangle_distance(p.as_dvec3(), t) - want).abs() <= tol);
            // A bound below the answer (by more than the rounding) finds nothing; a hint
            // changes nothing.
            if want > 4.0 * tol {
                prop_assert!(tree.nearest(p, (want - 2.0 * tol) as f32, &mut stack, &mut visited).is_none());
            }
            let hint = (rng.unit() * mesh.triangles.len() as f32) as u32;
            let h = tree.nearest_with_hint(p, Some(hint), f32::INFINITY, &mut stack, &mut visited).unwrap();
            prop_assert!(((h.dist2 as f64).sqrt() - want).abs() <= tol);
        }
        // Groups of 1..=GROUP_MAX points around a spot (spacing from tiny to large), with
        // hints that are none, arbitrary or out of range.
        for round in 0..8 {
            let g = 1 + round % GROUP_MAX;
            let spot = points[round * 7 % points.len()];
            let spacing = r * [1e-4, 0.02, 0.1, 1.0][round % 4];
            let group: Vec<Vec3> = (0..g).map(|_| spot + rng.dir() * spacing * rng.unit()).collect();
            let hints: Vec<Option<u32>> = (0..g)
                .map(|i| match i % 3 {
                    0 => None,
                    1 => Some((rng.unit() * mesh.triangles.len() as f32) as u32),
                    _ => Some(u32::MAX - 3),
                })
                .collect();
            let mut out: Vec<Option<Nearest>> = vec![None; g];
            let mut group_visited = 0u64;
            tree.nearest_group(&group, &hints, &mut out, &mut group_stack, &mut group_visited);
            // Both backends give the same bits and the same walk (`nearest_group` runs on
            // AVX2 where the CPU has it, unless SDFMESH_SIMD=portable).
            let mut portable_out: Vec<Option<Nearest>> = vec![None; g];
            let mut portable_visited = 0u64;
            tree.nearest_group_on(
                Portable,
                &group,
                &hints,
                &mut portable_out,
                &mut group_stack,
                &mut portable_visited,
            );
            prop_assert_eq!(&out, &portable_out);
            prop_assert_eq!(group_visited, portable_visited);
            if let Some(s) = sdfmesh::simd::avx2() {
                let mut avx2_out: Vec<Option<Nearest>> = vec![None; g];
                let mut avx2_visited = 0u64;
                s.vectorize(|| {
                    tree.nearest_group_on(s, &group, &hints, &mut avx2_out, &mut group_stack, &mut avx2_visited)
                });
                prop_assert_eq!(&out, &avx2_out);
                prop_assert_eq!(group_visited, avx2_visited);
            }
            for (p, n) in group.iter().zip(&out) {
                let want = brute(&mesh, *p);
                let got = (n.unwrap().dist2 as f64).sqrt();
                prop_assert!((got - want).abs() <= tolerance(&mesh, *p), "group of {g}, {p}: {got} vs {want}");
            }
        }
    }
}

/// Where the CPU has AVX2 (and `SDFMESH_SIMD` does not ask for the portable backend), the
/// group walks run on it (so that the comparison of the backends above compares two paths).
#[test]
fn group_walks_use_avx2_where_the_cpu_has_it() {
    #[cfg(target_arch = "x86_64")]
    let has = std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
        && std::arch::is_x86_feature_detected!("popcnt")
        && std::arch::is_x86_feature_detected!("bmi1");
    #[cfg(not(target_arch = "x86_64"))]
    let has = false;
    assert_eq!(sdfmesh::simd::cpu_has_avx2(), has);
    let forced = std::env::var("SDFMESH_SIMD").is_ok_and(|v| v.trim() == "portable");
    assert_eq!(sdfmesh::simd::avx2().is_some(), has && !forced);
}

#[test]
fn sampled_bumpy_spheres_match_brute_force_everywhere() {
    for (open, centre) in [(false, Vec3::ZERO), (true, Vec3::new(30.0, -7.0, 11.0))] {
        let mesh = bumpy_sphere(centre, 1.0, 0.2, 3.0, 4.0, 32, open);
        let g = sample_mesh(&mesh, 20, 2).unwrap();
        let (lo, hi) = mesh.bounds().unwrap();
        let size = (hi - lo).max_element() as f64;
        let mut worst = 0.0f64;
        for k in 0..g.dims.z {
            for j in 0..g.dims.y {
                for i in 0..g.dims.x {
                    let p = g.position(i, j, k);
                    let err = (g.get(i, j, k).abs() as f64 - brute(&mesh, p)).abs();
                    worst = worst.max(err);
                }
            }
        }
        eprintln!("bumpy sphere (open: {open}): max |error| {worst:.3e} = {:.2e} of the box", worst / size);
        assert!(worst <= 1e-5 * size, "max error {worst} against a box of {size}");
    }
}

#[test]
fn empty_groups_and_meshes() {
    let tree = TriangleBvh::new(&TriangleMesh::default());
    let mut out = [None; 2];
    tree.nearest_group(
        &[Vec3::ZERO, Vec3::ONE],
        &[None, Some(0)],
        &mut out,
        &mut GroupStack::default(),
        &mut 0,
    );
    assert_eq!(out, [None, None]);
    let mesh = bumpy_sphere(Vec3::ZERO, 1.0, 0.0, 1.0, 1.0, 8, false);
    let tree = TriangleBvh::new(&mesh);
    tree.nearest_group(&[], &[], &mut [], &mut GroupStack::default(), &mut 0);
}
