//! SDF -> triangle mesh extraction: accuracy, topology and orientation.

use std::collections::HashSet;
use std::f64::consts::PI;
use std::time::Instant;

use glam::{DMat3, DVec3, Vec3, Vec3A};
use proptest::prelude::*;
use sdfmesh::convert::extract::{ExtractMethod, Field, extract, extract_object, sample_grid};
use sdfmesh::geometry::Aabb;
use sdfmesh::mesh::{TriangleMesh, is_degenerate};
use sdfmesh::scene::shape::{CsgOp, Object, ObjectKind, Primitive};
use sdfmesh::scene::transform::TransformDesc;

use crate::util::{cube, non_manifold_edges, signed_volume};

const METHODS: [ExtractMethod; 3] =
    [ExtractMethod::MarchingCubes, ExtractMethod::MarchingTetrahedra, ExtractMethod::DualContouring];

/// Every undirected edge is used by exactly two triangles, once in each direction.
fn is_edge_manifold(m: &TriangleMesh) -> bool {
    non_manifold_edges(m) == 0
}

fn has_duplicate_positions(m: &TriangleMesh) -> bool {
    let mut seen = HashSet::new();
    !m.positions.iter().all(|p| seen.insert((*p + Vec3::ZERO).to_array().map(f32::to_bits)))
}

/// Closed, edge-manifold, valid, no duplicate positions, no degenerate triangles.
fn assert_clean(m: &TriangleMesh, what: &str) {
    assert_valid(m, what);
    assert!(m.is_closed(), "{what}: {} boundary edges", m.boundary_edge_count());
    assert!(is_edge_manifold(m), "{what}: not edge-manifold");
}

/// Valid, no duplicate positions, no degenerate triangles.
fn assert_valid(m: &TriangleMesh, what: &str) {
    assert!(!m.triangles.is_empty(), "{what}: empty");
    m.validate().unwrap_or_else(|e| panic!("{what}: invalid: {e}"));
    assert!(!has_duplicate_positions(m), "{what}: duplicate positions");
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        assert!(!is_degenerate(a, b, c), "{what}: degenerate triangle {t:?}");
    }
}

/// Largest |f| over the vertices, and over vertices, edge midpoints and centroids.
fn surface_errors(m: &TriangleMesh, f: impl Fn(DVec3) -> f64) -> (f64, f64) {
    let vert = m.positions.iter().map(|p| f(p.as_dvec3()).abs()).fold(0.0, f64::max);
    let mut all = vert;
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize].as_dvec3());
        for p in [(a + b) * 0.5, (b + c) * 0.5, (a + c) * 0.5, (a + b + c) / 3.0] {
            all = all.max(f(p).abs());
        }
    }
    (vert, all)
}

/// Normals point outwards: towards positive f.
fn assert_outward(m: &TriangleMesh, f: impl Fn(DVec3) -> f64, what: &str) {
    let mut wrong = 0;
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize].as_dvec3());
        let n = (b - a).cross(c - a).normalize();
        let g = (a + b + c) / 3.0;
        let e = 1e-3;
        if f(g + n * e) < f(g - n * e) {
            wrong += 1;
        }
    }
    // Allow a handful of faces that fold at sharp features.
    assert!(
        wrong * 1000 <= m.triangles.len(),
        "{what}: {wrong} of {} faces point inwards",
        m.triangles.len()
    );
}

#[test]
fn sphere_converges_and_is_clean() {
    let f = |p: DVec3| p.length() - 1.0;
    for method in METHODS {
        let mut last = f64::INFINITY;
        for res in [16u32, 32, 64, 128] {
            let h = 2.0 / res as f64;
            let t0 = Instant::now();
            let m = extract(&f, Field::DistanceBound, &cube(1.0), res, method);
            let secs = t0.elapsed().as_secs_f64();
            let what = format!("{method:?} res {res}");
            assert_clean(&m, &what);
            assert_outward(&m, f, &what);
            let (vert, all) = surface_errors(&m, f);
            let vol = signed_volume(&m);
            let rel = (vol - 4.0 / 3.0 * PI) / (4.0 / 3.0 * PI);
            println!(
                "{what}: {} verts, {} tris, max vertex error {vert:.3e} ({:.4} cells), max on faces \
                 {all:.3e} ({:.3} cells), volume error {:+.3}%, {secs:.3} s",
                m.positions.len(),
                m.triangles.len(),
                vert / h,
                all / h,
                rel * 100.0
            );
            assert!(vert <= 0.1 * h, "{what}: vertex error {vert} vs cell {h}");
            assert!(all <= 0.5 * h, "{what}: face error {all} vs cell {h}");
            assert!(all < last, "{what}: error does not shrink");
            last = all;
            assert!(vol > 0.0);
            if res >= 64 {
                assert!(rel.abs() < 0.02, "{what}: volume {vol}");
            }
        }
    }
}

/// Exact SDF of a box with half-extents `half`, rotated by `rot`.
fn rotated_box(half: DVec3, rot: DMat3) -> impl Fn(DVec3) -> f64 + Sync + Copy {
    let inv = rot.transpose();
    move |p: DVec3| {
        let q = (inv * p).abs() - half;
        q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
    }
}

#[test]
fn dual_contouring_keeps_box_edges() {
    let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.3, 0.5, 0.2);
    let f = rotated_box(DVec3::new(0.6, 0.5, 0.4), rot);
    for res in [24u32, 48] {
        let h = 2.0 / res as f64;
        let mc = extract(&f, Field::DistanceBound, &cube(1.0), res, ExtractMethod::MarchingCubes);
        let dc = extract(&f, Field::DistanceBound, &cube(1.0), res, ExtractMethod::DualContouring);
        assert_clean(&mc, "box mc");
        assert_clean(&dc, "box dc");
        assert_outward(&mc, f, "box mc");
        assert_outward(&dc, f, "box dc");
        let (mc_v, mc_all) = surface_errors(&mc, f);
        let (dc_v, dc_all) = surface_errors(&dc, f);
        println!(
            "box res {res}: max vertex distance MC {:.4} DC {:.4} cells; including edge midpoints and \
             centroids MC {:.4} DC {:.4} cells",
            mc_v / h,
            dc_v / h,
            mc_all / h,
            dc_all / h
        );
        // Marching cubes' vertices lie on the surface (refined along grid edges) but its
        // faces cut the box's edges and corners off; dual contouring's faces follow them.
        assert!(dc_all <= 0.5 * mc_all, "res {res}: DC {dc_all} vs MC {mc_all}");
    }
}

fn prim(p: Primitive, translate: Vec3) -> Object {
    Object {
        kind: ObjectKind::Primitive(p),
        transform: TransformDesc { translate, ..TransformDesc::default() },
        material: 0,
        label: p.kind_name().into(),
    }
}

fn csg(op: CsgOp, children: Vec<Object>, rotate_deg: Vec3) -> Object {
    Object {
        kind: ObjectKind::Csg { op, children },
        transform: TransformDesc { rotate_deg, ..TransformDesc::default() },
        material: 0,
        label: op.name().into(),
    }
}

#[test]
fn csg_objects_are_closed_and_manifold() {
    let sphere = |r: f32, t: Vec3| prim(Primitive::Sphere { radius: r }, t);
    let scenes = [
        (
            "sphere + torus",
            csg(
                CsgOp::SmoothUnion { k: 0.2 },
                vec![
                    sphere(0.8, Vec3::ZERO),
                    prim(Primitive::Torus { major: 1.2, minor: 0.25 }, Vec3::new(0.0, 0.3, 0.0)),
                ],
                Vec3::new(20.0, 0.0, 10.0),
            ),
        ),
        (
            "sphere - sphere",
            csg(
                CsgOp::Subtraction,
                vec![sphere(1.0, Vec3::ZERO), sphere(0.7, Vec3::new(0.6, 0.3, 0.1))],
                Vec3::ZERO,
            ),
        ),
        (
            "sphere & box",
            csg(
                CsgOp::Intersection,
                vec![sphere(1.0, Vec3::ZERO), prim(Primitive::Box { half: Vec3::splat(0.75) }, Vec3::ZERO)],
                Vec3::new(15.0, 25.0, 5.0),
            ),
        ),
    ];
    for (name, obj) in &scenes {
        for method in METHODS {
            for res in [32u32, 48, 64, 96] {
                let m = extract_object(obj, res, method).expect("bounded SDF object");
                let what = format!("{name} {method:?} res {res}");
                assert_valid(&m, &what);
                let bad = non_manifold_edges(&m);
                println!(
                    "{what}: {} tris, volume {:.4}, {bad} non-manifold edges",
                    m.triangles.len(),
                    signed_volume(&m)
                );
                assert!(signed_volume(&m) > 0.0);
                assert_clean(&m, &what);
            }
        }
    }
}

#[test]
fn extract_object_rejects_unbounded_and_unsigned() {
    let plane = prim(Primitive::Plane { normal: Vec3::Y, offset: 0.0 }, Vec3::ZERO);
    assert!(extract_object(&plane, 16, ExtractMethod::MarchingCubes).is_none());
    let tri = prim(Primitive::Triangle { a: Vec3::ZERO, b: Vec3::X, c: Vec3::Y }, Vec3::ZERO);
    assert!(extract_object(&tri, 16, ExtractMethod::MarchingCubes).is_none());
}

#[test]
fn degenerate_input_gives_empty_or_capped_mesh() {
    // Zero-size bounds: nothing to sample.
    let f = |p: DVec3| p.length() - 1.0;
    let empty = Aabb::new(Vec3A::ZERO, Vec3A::ZERO);
    assert!(extract(&f, Field::Arbitrary, &empty, 16, ExtractMethod::MarchingCubes).triangles.is_empty());
    // Negative everywhere: the surface is capped inside the padded box, still closed.
    for method in METHODS {
        let m = extract(&|_| -1.0, Field::Arbitrary, &cube(1.0), 8, method);
        assert_clean(&m, &format!("all inside {method:?}"));
        // Samples exactly zero on grid points.
        let m = extract(
            &|p: DVec3| p.x.abs().max(p.y.abs()).max(p.z.abs()) - 0.5,
            Field::Arbitrary,
            &cube(1.0),
            8,
            method,
        );
        assert_clean(&m, &format!("grid-aligned cube {method:?}"));
    }
}

/// Polynomial smooth minimum.
fn smin(a: f64, b: f64, k: f64) -> f64 {
    let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
    b + (a - b) * h - k * h * (1.0 - h)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]
    #[test]
    fn random_blobs_are_closed_and_manifold(
        spheres in prop::collection::vec(((-0.8f64..0.8, -0.8f64..0.8, -0.8f64..0.8), 0.15f64..0.7), 3),
        k in 0.05f64..0.4,
    ) {
        let s: Vec<(DVec3, f64)> = spheres.iter().map(|&((x, y, z), r)| (DVec3::new(x, y, z), r)).collect();
        let f = |p: DVec3| s.iter().map(|&(c, r)| (p - c).length() - r).reduce(|a, b| smin(a, b, k)).unwrap();
        let m = extract(&f, Field::Arbitrary, &cube(1.6), 24, ExtractMethod::MarchingCubes);
        assert_clean(&m, "blob mc");
        prop_assert!(signed_volume(&m) > 0.0);
        let dc = extract(&f, Field::Arbitrary, &cube(1.6), 24, ExtractMethod::DualContouring);
        // Dual contouring is edge-manifold here too thanks to the ambiguous-face flip
        // (without it 2 of these 24 cases had a non-manifold edge).
        assert_clean(&dc, "blob dc");
        prop_assert!(signed_volume(&dc) > 0.0);
    }
}

/// Random smooth-min blobs (Lipschitz 1) at random resolutions: skipping the blocks that
/// the distance bound rules out gives the same mesh, for every method.
#[test]
fn distance_bound_gives_the_same_meshes() {
    let mut runner =
        proptest::test_runner::TestRunner::new(ProptestConfig { cases: 16, ..ProptestConfig::default() });
    let blobs = (
        prop::collection::vec(((-0.8f64..0.8, -0.8f64..0.8, -0.8f64..0.8), 0.05f64..0.5), 1..5),
        0.01f64..0.3,
        4u32..48,
    );
    runner
        .run(&blobs, |(spheres, k, res)| {
            let s: Vec<(DVec3, f64)> =
                spheres.iter().map(|&((x, y, z), r)| (DVec3::new(x, y, z), r)).collect();
            let f =
                |p: DVec3| s.iter().map(|&(c, r)| (p - c).length() - r).reduce(|a, b| smin(a, b, k)).unwrap();
            for method in METHODS {
                let dense = extract(&f, Field::Arbitrary, &cube(1.0), res, method);
                let sparse = extract(&f, Field::DistanceBound, &cube(1.0), res, method);
                prop_assert_eq!(&dense.positions, &sparse.positions, "{:?} res {}", method, res);
                prop_assert_eq!(&dense.triangles, &sparse.triangles, "{:?} res {}", method, res);
            }
            Ok(())
        })
        .unwrap();
}

/// The sparse samples of a distance bound: sampled points hold `f`, the others a bound with
/// `f`'s sign and at most `|f|`; far fewer evaluations than the full grid.
#[test]
fn distance_bound_samples_a_shell() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.3, 0.5, 0.2);
    let boxed = rotated_box(DVec3::new(0.6, 0.5, 0.4), rot);
    let sphere = |p: DVec3| p.length() - 0.9;
    type Field3 = dyn Fn(DVec3) -> f64 + Sync;
    let cases: [(&str, &Field3, f64); 2] = [("sphere", &sphere, 0.25), ("box", &boxed, 0.3)];
    for (name, f, most) in cases {
        let calls = AtomicUsize::new(0);
        let counted = |p: DVec3| {
            calls.fetch_add(1, Ordering::Relaxed);
            f(p)
        };
        let grid = sample_grid(&counted, Field::DistanceBound, &cube(1.0), 128).unwrap();
        let n = grid.dims();
        let points = n[0] * n[1] * n[2];
        let evaluated = calls.load(Ordering::Relaxed);
        println!(
            "{name}: {evaluated} evaluations for {points} points ({:.1}%)",
            100.0 * evaluated as f64 / points as f64
        );
        assert!((evaluated as f64) < most * points as f64, "{name}: {evaluated} of {points}");
        let (mut exact, mut bounded) = (0usize, 0usize);
        for z in 1..n[2] - 1 {
            for y in 1..n[1] - 1 {
                for x in 1..n[0] - 1 {
                    let p = grid.origin() + grid.cell() * DVec3::new(x as f64, y as f64, z as f64);
                    let (v, want) = (grid.values()[x + n[0] * (y + n[1] * z)], f(p) as f32);
                    if v == want {
                        exact += 1;
                    } else {
                        bounded += 1;
                        assert!(
                            v != 0.0 && (v < 0.0) == (want < 0.0) && v.abs() <= want.abs(),
                            "{name} at {p}: {v} for {want}"
                        );
                    }
                }
            }
        }
        assert!(exact > 0 && bounded > points / 2, "{name}: {exact} exact, {bounded} bounded");
    }
}

/// `cargo test --release --test extract timing -- --ignored --nocapture`
#[test]
#[ignore]
fn timing_sphere() {
    let f = |p: DVec3| p.length() - 1.0;
    for res in [128u32, 256] {
        for method in METHODS {
            let mut best = f64::INFINITY;
            let mut tris = 0;
            for _ in 0..5 {
                let t0 = Instant::now();
                let m = extract(&f, Field::Arbitrary, &cube(1.0), res, method);
                best = best.min(t0.elapsed().as_secs_f64());
                tris = m.triangles.len();
            }
            println!("sphere res {res} {method:?}: {tris} triangles, best of 5 {:.4} s", best);
        }
    }
}

/// A gyroid clipped by a sphere, at frequencies up to about one period per 4-5 cells:
/// many ambiguous faces and thin sheets. Both methods stay closed and edge-manifold.
#[test]
fn gyroid_is_closed_and_manifold() {
    for freq in [3.0f64, 8.0, 13.0] {
        for res in [16u32, 24, 40] {
            let f = |p: DVec3| {
                let q = p * freq;
                let g = (q.x.sin() * q.y.cos() + q.y.sin() * q.z.cos() + q.z.sin() * q.x.cos()) / freq;
                g.max(p.length() - 1.0)
            };
            for method in METHODS {
                let m = extract(&f, Field::Arbitrary, &cube(1.0), res, method);
                assert_clean(&m, &format!("gyroid freq {freq} res {res} {method:?}"));
            }
        }
    }
}
