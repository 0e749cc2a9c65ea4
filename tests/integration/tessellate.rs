//! Parametric tessellation: every primitive's mesh is closed, outward, free of duplicate
//! vertices and degenerate triangles, inscribed in the exact surface, and converges to the
//! closed-form volume and area as O(1 / resolution^2); object transforms are applied.

use std::collections::HashSet;
use std::f64::consts::PI;
use std::sync::Arc;

use glam::{DVec3, Vec3};
use sdfmesh::convert::tessellate::{tessellate, tessellate_object, tessellate_with};
use sdfmesh::geometry::sdf::{primitive_distance, primitive_distance_f64};
use sdfmesh::geometry::{Aabb, aabb};
use sdfmesh::mesh::{TriangleMesh, is_degenerate};
use sdfmesh::scene::shape::{CsgOp, Object, ObjectKind, Primitive, Shading};
use sdfmesh::scene::transform::TransformDesc;

use crate::util::signed_volume;

const RESOLUTIONS: [u32; 5] = [8, 16, 32, 64, 128];

/// A solid primitive with its closed-form volume and (where one exists) surface area.
struct Case {
    name: &'static str,
    prim: Primitive,
    volume: f64,
    area: Option<f64>,
    /// Whether the surface is smooth (the mesh then carries exact normals).
    smooth: bool,
}

fn cases() -> Vec<Case> {
    let frustum = |r0: f64, r1: f64, h: f64| {
        let slant = ((r0 - r1).powi(2) + 4.0 * h * h).sqrt();
        (
            PI * 2.0 * h * (r0 * r0 + r0 * r1 + r1 * r1) / 3.0,
            PI * (r0 + r1) * slant + PI * (r0 * r0 + r1 * r1),
        )
    };
    let cyl = frustum(0.8, 0.8, 1.1);
    let cone_a = frustum(1.0, 0.4, 0.9);
    let cone_b = frustum(1.0, 0.0, 1.0);
    let cone_c = frustum(0.0, 0.7, 0.6);
    let (ca, cb, cr) = (Vec3::new(-0.5, -0.3, 0.2), Vec3::new(0.6, 0.5, -0.4), 0.35f64);
    let cl = (cb - ca).as_dvec3().length();
    vec![
        Case {
            name: "sphere",
            prim: Primitive::Sphere { radius: 1.3 },
            volume: 4.0 / 3.0 * PI * 1.3f64.powi(3),
            area: Some(4.0 * PI * 1.3 * 1.3),
            smooth: true,
        },
        Case {
            name: "ellipsoid",
            prim: Primitive::Ellipsoid { radii: Vec3::new(1.5, 0.8, 1.0) },
            volume: 4.0 / 3.0 * PI * 1.5 * 0.8 * 1.0,
            area: None,
            smooth: true,
        },
        Case {
            name: "box",
            prim: Primitive::Box { half: Vec3::new(1.0, 0.7, 0.8) },
            volume: 8.0 * 1.0 * 0.7 * 0.8,
            area: Some(8.0 * (0.7 + 0.7 * 0.8 + 0.8)),
            smooth: false,
        },
        Case {
            name: "cylinder",
            prim: Primitive::Cylinder { radius: 0.8, half_height: 1.1 },
            volume: cyl.0,
            area: Some(cyl.1),
            smooth: false,
        },
        Case {
            name: "frustum",
            prim: Primitive::Cone { radius_bottom: 1.0, radius_top: 0.4, half_height: 0.9 },
            volume: cone_a.0,
            area: Some(cone_a.1),
            smooth: false,
        },
        Case {
            name: "cone (apex up)",
            prim: Primitive::Cone { radius_bottom: 1.0, radius_top: 0.0, half_height: 1.0 },
            volume: cone_b.0,
            area: Some(cone_b.1),
            smooth: false,
        },
        Case {
            name: "cone (apex down)",
            prim: Primitive::Cone { radius_bottom: 0.0, radius_top: 0.7, half_height: 0.6 },
            volume: cone_c.0,
            area: Some(cone_c.1),
            smooth: false,
        },
        Case {
            name: "torus",
            prim: Primitive::Torus { major: 1.0, minor: 0.3 },
            volume: 2.0 * PI * PI * 1.0 * 0.09,
            area: Some(4.0 * PI * PI * 1.0 * 0.3),
            smooth: true,
        },
        Case {
            name: "capsule",
            prim: Primitive::Capsule { a: ca, b: cb, radius: cr as f32 },
            volume: PI * cr * cr * cl + 4.0 / 3.0 * PI * cr.powi(3),
            area: Some(2.0 * PI * cr * cl + 4.0 * PI * cr * cr),
            smooth: true,
        },
    ]
}

/// The primitive's size: the largest extent of its bounds (for relative tolerances).
fn size(prim: &Primitive) -> f32 {
    let b = prim.local_bounds().unwrap();
    (b.max - b.min).max_element()
}

/// Measurements of a mesh against its primitive.
#[derive(Debug)]
struct Measure {
    triangles: usize,
    /// Largest |distance| of a vertex to the exact surface.
    vertex_distance: f64,
    /// Largest |distance| of a triangle centroid to the exact surface.
    centroid_distance: f64,
    /// Signed volume by the divergence theorem.
    volume: f64,
    area: f64,
}

fn measure(prim: &Primitive, m: &TriangleMesh) -> Measure {
    let mut out = Measure {
        triangles: m.triangles.len(),
        vertex_distance: 0.0,
        centroid_distance: 0.0,
        volume: 0.0,
        area: 0.0,
    };
    for &p in &m.positions {
        let d = primitive_distance_f64(prim, p.as_dvec3()).abs();
        out.vertex_distance = out.vertex_distance.max(d);
    }
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize].as_dvec3());
        out.volume += a.dot(b.cross(c)) / 6.0;
        out.area += (b - a).cross(c - a).length() / 2.0;
        let d = primitive_distance_f64(prim, (a + b + c) / 3.0).abs();
        out.centroid_distance = out.centroid_distance.max(d);
    }
    out
}

/// The mesh invariants, edge closure (when `closed`), no degenerate triangle and no two
/// vertices at the same position (bit for bit, with -0 and +0 the same).
fn check_structure(what: &str, m: &TriangleMesh, closed: bool) {
    m.validate().unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(!m.triangles.is_empty(), "{what}: no triangles");
    if closed {
        assert!(m.is_closed(), "{what}: not closed");
        assert_eq!(m.boundary_edge_count(), 0, "{what}");
    }
    for (i, t) in m.triangles.iter().enumerate() {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        assert!(!is_degenerate(a, b, c), "{what}: triangle {i} {t:?} degenerate");
    }
    let mut seen = HashSet::with_capacity(m.positions.len());
    for (i, p) in m.positions.iter().enumerate() {
        let p = *p + Vec3::ZERO;
        let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
        assert!(seen.insert(key), "{what}: vertex {i} at {p} repeats a position");
    }
    let used: HashSet<u32> = m.triangles.iter().flatten().copied().collect();
    assert_eq!(used.len(), m.positions.len(), "{what}: unused vertices");
}

/// The exact outward unit normal of a smooth primitive at (or next to) its surface.
fn analytic_normal(prim: &Primitive, p: DVec3) -> DVec3 {
    match *prim {
        Primitive::Sphere { .. } => p.normalize(),
        Primitive::Ellipsoid { radii } => {
            let r = radii.as_dvec3();
            (p / (r * r)).normalize()
        }
        Primitive::Torus { major, .. } => {
            let ring = DVec3::new(p.x, 0.0, p.z).normalize() * major as f64;
            (p - ring).normalize()
        }
        Primitive::Capsule { a, b, .. } => {
            let (a, b) = (a.as_dvec3(), b.as_dvec3());
            let ba = b - a;
            let h = ((p - a).dot(ba) / ba.dot(ba)).clamp(0.0, 1.0);
            (p - (a + ba * h)).normalize()
        }
        _ => unreachable!("not a smooth primitive"),
    }
}

#[test]
fn every_solid_is_closed_outward_and_inscribed() {
    for case in cases() {
        let s = size(&case.prim);
        for res in RESOLUTIONS {
            let what = format!("{} at {res}", case.name);
            let m = tessellate(&case.prim, res, None);
            check_structure(&what, &m, true);
            let me = measure(&case.prim, &m);
            assert!(
                me.vertex_distance < 1e-5 * s as f64,
                "{what}: vertex {} off the surface",
                me.vertex_distance
            );
            // Also through the public f32 distance.
            for &p in &m.positions {
                assert!(primitive_distance(&case.prim, p).abs() < 1e-5 * s, "{what}");
            }
            assert!(me.volume > 0.0, "{what}: inward orientation");
            assert_eq!(m.normals.is_some(), case.smooth, "{what}: normals");
        }
    }
}

#[test]
fn volume_area_and_distance_converge_quadratically() {
    println!(
        "{:16} {:>4} {:>8} {:>10} {:>10} {:>10}",
        "primitive", "res", "tris", "max dist", "vol err", "area err"
    );
    for case in cases() {
        let s = size(&case.prim) as f64;
        let mut previous: Option<(f64, f64)> = None;
        for res in RESOLUTIONS {
            let what = format!("{} at {res}", case.name);
            let m = tessellate(&case.prim, res, None);
            let me = measure(&case.prim, &m);
            let vol_err = (me.volume - case.volume).abs() / case.volume;
            let area_err = case.area.map(|a| (me.area - a).abs() / a);
            let dist = me.centroid_distance / s;
            println!(
                "{:16} {res:>4} {:>8} {dist:>10.3e} {vol_err:>10.3e} {:>10}",
                case.name,
                me.triangles,
                area_err.map_or("-".into(), |e| format!("{e:.3e}"))
            );
            if matches!(case.prim, Primitive::Box { .. }) {
                assert!(vol_err < 1e-6 && area_err.unwrap() < 1e-6, "{what}");
                assert!(dist < 1e-7, "{what}");
                continue;
            }
            // Errors bounded by C / res^2; measured C: volume 6.5 (cylinder) to 35
            // (torus, whose thin tube gets sqrt(0.3 / 1.3) of the segments), centroid
            // distance / size up to 4.4, area up to 11.1.
            let r2 = (res * res) as f64;
            assert!(vol_err < 40.0 / r2, "{what}: volume error {vol_err}");
            assert!(dist < 6.0 / r2, "{what}: centroid distance {dist}");
            if let Some(e) = area_err {
                assert!(e < 15.0 / r2, "{what}: area error {e}");
            }
            if res == 64 {
                assert!(vol_err < 1e-2, "{what}: volume error {vol_err}");
            }
            if let Some((prev_dist, prev_vol)) = previous {
                // Each doubling divides the errors by about 4 (2.25 from 8 to 16 for the
                // icosphere, whose frequency rounds up from 1.4 to 2 at resolution 8).
                let low = if res == 16 { 2.0 } else { 2.5 };
                assert!(
                    prev_dist / dist > low && prev_dist / dist < 6.0,
                    "{what}: centroid distance {prev_dist} -> {dist}"
                );
                assert!(
                    prev_vol / vol_err > low && prev_vol / vol_err < 6.0,
                    "{what}: volume error {prev_vol} -> {vol_err}"
                );
            }
            previous = Some((dist, vol_err));
        }
    }
}

#[test]
fn sphere_volume_error_targets() {
    let sphere = Primitive::Sphere { radius: 2.0 };
    let v = 4.0 / 3.0 * PI * 8.0;
    let err = |res| (v - measure(&sphere, &tessellate(&sphere, res, None)).volume) / v;
    let (e64, e128) = (err(64), err(128));
    assert!(e64 > 0.0 && e64 < 0.005, "volume error at 64: {e64}");
    assert!(e128 < e64 / 2.5, "volume error at 128: {e128} (64: {e64})");
}

#[test]
fn smooth_normals_are_unit_and_exact() {
    for case in cases().iter().filter(|c| c.smooth) {
        for res in [8, 64] {
            let m = tessellate(&case.prim, res, None);
            let normals = m.normals.as_ref().unwrap();
            for (p, n) in m.positions.iter().zip(normals) {
                let want = analytic_normal(&case.prim, p.as_dvec3());
                assert!((n.length() - 1.0).abs() < 1e-5, "{}: |n| {}", case.name, n);
                assert!(
                    (n.as_dvec3() - want).length() < 1e-3,
                    "{} at {res}: normal {n} at {p}, want {want}",
                    case.name
                );
            }
        }
    }
}

#[test]
fn spindle_and_horn_tori_are_their_outer_surface() {
    for (major, minor) in [(0.5f32, 0.8f32), (0.6, 0.6), (1.0, 0.999), (1.0, 0.01)] {
        let prim = Primitive::Torus { major, minor };
        for res in [8, 64, 256] {
            let what = format!("torus {major}/{minor} at {res}");
            let m = tessellate(&prim, res, None);
            check_structure(&what, &m, true);
            let me = measure(&prim, &m);
            assert!(me.vertex_distance < 1e-5 * size(&prim) as f64, "{what}");
            assert!(me.volume > 0.0, "{what}");
            for n in m.normals.as_ref().unwrap() {
                assert!((n.length() - 1.0).abs() < 1e-5, "{what}");
            }
        }
    }
    // The spindle torus's volume: the solid of revolution of the outer arc, by Pappus
    // on thin slices (numerically), against the mesh.
    let (major, minor) = (0.5f64, 0.8f64);
    let apex = (minor * minor - major * major).sqrt();
    let slices = 200_000;
    let mut volume = 0.0;
    for i in 0..slices {
        let y = -minor + 2.0 * minor * (i as f64 + 0.5) / slices as f64;
        let rho = major + (minor * minor - y * y).sqrt();
        let hole = if y.abs() < apex { 0.0 } else { 0.0f64.max(major - (minor * minor - y * y).sqrt()) };
        volume += PI * (rho * rho - hole * hole) * 2.0 * minor / slices as f64;
    }
    let prim = Primitive::Torus { major: major as f32, minor: minor as f32 };
    let me = measure(&prim, &tessellate(&prim, 256, None));
    assert!((me.volume - volume).abs() / volume < 1e-3, "{} vs {volume}", me.volume);
}

#[test]
fn awkward_shapes_stay_valid() {
    let cases = [
        // A sphere-like capsule (a == b), a long thin one, a thin needle cylinder, a flat
        // disc, a nearly pointed frustum, a long thin cone, a flat ellipsoid.
        Primitive::Capsule { a: Vec3::new(0.3, 0.2, 0.1), b: Vec3::new(0.3, 0.2, 0.1), radius: 0.5 },
        Primitive::Capsule { a: Vec3::new(0.0, 0.0, -20.0), b: Vec3::new(0.0, 0.0, 20.0), radius: 0.05 },
        Primitive::Cylinder { radius: 0.001, half_height: 50.0 },
        Primitive::Cylinder { radius: 30.0, half_height: 0.01 },
        Primitive::Cone { radius_bottom: 1.0, radius_top: 1e-4, half_height: 1.0 },
        Primitive::Cone { radius_bottom: 0.01, radius_top: 0.0, half_height: 10.0 },
        Primitive::Ellipsoid { radii: Vec3::new(5.0, 0.01, 1.0) },
        Primitive::Sphere { radius: 5000.0 },
    ];
    for prim in cases {
        for res in [3, 8, 100, 512] {
            let what = format!("{prim:?} at {res}");
            let m = tessellate(&prim, res, None);
            check_structure(&what, &m, true);
            let me = measure(&prim, &m);
            assert!(me.vertex_distance < 1e-5 * size(&prim) as f64, "{what}: {me:?}");
            assert!(me.volume > 0.0, "{what}");
        }
    }
}

#[test]
fn minimal_aspect_gives_fan_caps_and_one_side_band() {
    let n = 40;
    let cyl = Primitive::Cylinder { radius: 1.0, half_height: 2.0 };
    let m = tessellate_with(&cyl, n, f32::INFINITY, None);
    check_structure("minimal cylinder", &m, true);
    assert_eq!(m.positions.len() as u32, 2 * n + 2);
    assert_eq!(m.triangles.len() as u32, 4 * n);
    let cone = Primitive::Cone { radius_bottom: 1.0, radius_top: 0.0, half_height: 2.0 };
    let m = tessellate_with(&cone, n, f32::INFINITY, None);
    check_structure("minimal cone", &m, true);
    assert_eq!(m.positions.len() as u32, n + 2);
    assert_eq!(m.triangles.len() as u32, 2 * n);
    // The default splits the side and the caps into bounded-aspect triangles.
    let m = tessellate(&cyl, n, None);
    let seg = 2.0 * std::f32::consts::PI / n as f32;
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        let longest = (b - a).length().max((c - b).length()).max((a - c).length());
        assert!(longest < 4.0 * seg * 1.5, "edge {longest} vs segment {seg}");
    }
}

#[test]
fn high_resolution_is_fast_enough() {
    let start = std::time::Instant::now();
    for prim in [
        Primitive::Sphere { radius: 1.0 },
        Primitive::Torus { major: 1.0, minor: 0.25 },
        Primitive::Capsule { a: Vec3::ZERO, b: Vec3::Y, radius: 0.5 },
        Primitive::Cylinder { radius: 1.0, half_height: 1.0 },
    ] {
        let t0 = std::time::Instant::now();
        let m = tessellate(&prim, 2048, None);
        println!("{} at 2048: {} triangles in {:?}", prim.kind_name(), m.triangles.len(), t0.elapsed());
        assert!(m.triangles.len() > 1_000_000, "{prim:?}");
        assert!(m.is_closed(), "{prim:?}");
    }
    assert!(start.elapsed().as_secs() < 60, "{:?}", start.elapsed());
}

#[test]
fn triangle_is_itself() {
    let (a, b, c) = (Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.5), Vec3::new(0.2, 1.0, 0.0));
    let m = tessellate(&Primitive::Triangle { a, b, c }, 64, None);
    assert_eq!(m.positions, vec![a, b, c]);
    assert_eq!(m.triangles, vec![[0, 1, 2]]);
    assert_eq!(m.boundary_edge_count(), 3);
}

/// Whether the 2D point `p` lies in the convex quad `q` (counter-clockwise).
fn in_quad(q: &[glam::DVec2; 4], p: glam::DVec2) -> bool {
    (0..4).all(|i| {
        let (a, b) = (q[i], q[(i + 1) % 4]);
        (b - a).perp_dot(p - a) >= 0.0
    })
}

#[test]
fn plane_quad_covers_the_clip_box() {
    let clip = aabb(Vec3::new(-3.0, -1.0, -2.0), Vec3::new(4.0, 2.5, 6.0));
    let normals = [
        Vec3::Y,
        -Vec3::Y,
        Vec3::X,
        Vec3::new(0.3, 0.9, -0.2).normalize(),
        Vec3::new(-1.0, 1.0, 1.0).normalize(),
    ];
    for normal in normals {
        for offset in [0.0f32, 0.7, -1.5, 20.0] {
            let prim = Primitive::Plane { normal, offset };
            let what = format!("plane {normal} {offset}");
            let m = tessellate(&prim, 16, Some(&clip));
            check_structure(&what, &m, false);
            assert_eq!(m.triangles.len(), 2);
            assert_eq!(m.boundary_edge_count(), 4, "{what}");
            for &p in &m.positions {
                assert!(primitive_distance(&prim, p).abs() < 1e-5 * 20.0, "{what}");
            }
            // Both triangles face up the normal.
            for t in &m.triangles {
                let [a, b, c] = t.map(|i| m.positions[i as usize]);
                let n = (b - a).cross(c - a).normalize();
                assert!(n.dot(normal) > 0.9999, "{what}: faces {n}");
            }
            // Every box corner projects into the quad.
            let n = normal.as_dvec3();
            let t1 = (m.positions[1] - m.positions[0]).as_dvec3().normalize();
            let t2 = n.cross(t1);
            let to2 = |p: DVec3| glam::DVec2::new(p.dot(t1), p.dot(t2));
            let q = [0, 1, 2, 3].map(|i| to2(m.positions[i].as_dvec3()));
            for i in 0..8 {
                let c = DVec3::new(
                    if i & 1 == 0 { -3.0 } else { 4.0 },
                    if i & 2 == 0 { -1.0 } else { 2.5 },
                    if i & 4 == 0 { -2.0 } else { 6.0 },
                );
                assert!(in_quad(&q, to2(c)), "{what}: corner {c} outside");
            }
        }
    }
    let plane = Primitive::Plane { normal: Vec3::Y, offset: 0.0 };
    assert!(tessellate(&plane, 16, None).triangles.is_empty());
    assert!(tessellate(&plane, 16, Some(&Aabb::empty())).triangles.is_empty());
    let point = aabb(Vec3::ONE, Vec3::ONE);
    assert!(tessellate(&plane, 16, Some(&point)).triangles.is_empty());
}

fn object(kind: ObjectKind, transform: TransformDesc) -> Object {
    Object { kind, transform, material: 0, label: "test".into() }
}

#[test]
fn objects_are_transformed() {
    let transform = TransformDesc {
        translate: Vec3::new(1.5, -2.0, 0.5),
        rotate_deg: Vec3::new(30.0, -50.0, 75.0),
        scale: Vec3::new(2.0, 0.5, 1.25),
    };
    for prim in [
        Primitive::Box { half: Vec3::new(1.0, 0.7, 0.8) },
        Primitive::Sphere { radius: 1.2 },
        Primitive::Torus { major: 1.0, minor: 0.3 },
    ] {
        let obj = object(ObjectKind::Primitive(prim), transform);
        let t = obj.compiled_transform();
        let local = tessellate(&prim, 32, None);
        let world = tessellate_object(&obj, 32, None).unwrap();
        check_structure(prim.kind_name(), &world, true);
        assert_eq!(world.triangles, local.triangles);
        for (w, l) in world.positions.iter().zip(&local.positions) {
            assert_eq!(*w, t.to_world.transform_point3(*l));
            // On the transformed surface.
            let d = primitive_distance(&prim, t.point_to_local(*w));
            assert!(d.abs() < 1e-5, "{}: {d}", prim.kind_name());
        }
        match (&world.normals, &local.normals) {
            (Some(wn), Some(ln)) => {
                for ((w, l), p) in wn.iter().zip(ln).zip(&world.positions) {
                    assert_eq!(*w, t.normal_to_world(*l));
                    assert!((w.length() - 1.0).abs() < 1e-5);
                    // Perpendicular to the world surface: the world gradient of the
                    // local distance.
                    let q = t.point_to_local(*p);
                    let e = 1e-3;
                    let grad = Vec3::new(
                        primitive_distance(&prim, t.point_to_local(*p + Vec3::X * e))
                            - primitive_distance(&prim, q),
                        primitive_distance(&prim, t.point_to_local(*p + Vec3::Y * e))
                            - primitive_distance(&prim, q),
                        primitive_distance(&prim, t.point_to_local(*p + Vec3::Z * e))
                            - primitive_distance(&prim, q),
                    );
                    assert!(grad.normalize().dot(*w) > 0.99, "{}", prim.kind_name());
                }
            }
            (None, None) => {}
            _ => panic!("normals kept or dropped"),
        }
        // Volume scales by the determinant (1.25 here).
        let (lv, wv) = (signed_volume(&local), signed_volume(&world));
        assert!((wv / lv - 1.25).abs() < 1e-4, "{}: {wv} / {lv}", prim.kind_name());
    }
}

#[test]
fn plane_objects_clip_in_the_parent_frame() {
    let obj = object(
        ObjectKind::Primitive(Primitive::Plane { normal: Vec3::Y, offset: 0.25 }),
        TransformDesc {
            translate: Vec3::new(0.0, -1.0, 0.0),
            rotate_deg: Vec3::new(10.0, 0.0, 20.0),
            scale: Vec3::ONE,
        },
    );
    let clip = aabb(Vec3::splat(-5.0), Vec3::splat(5.0));
    let m = tessellate_object(&obj, 8, Some(&clip)).unwrap();
    check_structure("plane object", &m, false);
    let t = obj.compiled_transform();
    let world_normal = t.normal_to_world(Vec3::Y);
    for tri in &m.triangles {
        let [a, b, c] = tri.map(|i| m.positions[i as usize]);
        assert!((b - a).cross(c - a).normalize().dot(world_normal) > 0.9999);
    }
    // Rays straight down inside the box hit the quad: its projection covers the box's.
    for &(x, z) in &[(-5.0f32, -5.0f32), (5.0, -5.0), (5.0, 5.0), (-5.0, 5.0)] {
        let p = Vec3::new(x, 0.0, z);
        let covered = m.triangles.iter().any(|tri| {
            let [a, b, c] = tri.map(|i| m.positions[i as usize]);
            let s = |u: Vec3, v: Vec3| (v - u).cross(p - u).y;
            let (d0, d1, d2) = (s(a, b), s(b, c), s(c, a));
            (d0 >= 0.0 && d1 >= 0.0 && d2 >= 0.0) || (d0 <= 0.0 && d1 <= 0.0 && d2 <= 0.0)
        });
        assert!(covered, "({x}, {z}) not covered");
    }
    assert!(tessellate_object(&obj, 8, None).is_none());
}

#[test]
fn only_primitive_objects_are_tessellated() {
    let sphere = object(ObjectKind::Primitive(Primitive::Sphere { radius: 1.0 }), TransformDesc::default());
    let csg = object(
        ObjectKind::Csg { op: CsgOp::Union, children: vec![sphere.clone()] },
        TransformDesc::default(),
    );
    let repeat = object(
        ObjectKind::Repeat { period: Vec3::ONE * 3.0, count: None, child: Box::new(sphere.clone()) },
        TransformDesc::default(),
    );
    let mesh = object(
        ObjectKind::Mesh {
            mesh: Arc::new(tessellate(&Primitive::Sphere { radius: 1.0 }, 8, None)),
            source: "sphere.obj".into(),
            shading: Shading::Smooth,
        },
        TransformDesc::default(),
    );
    assert!(tessellate_object(&sphere, 8, None).is_some());
    assert_eq!(
        tessellate_object(&sphere, 8, None).unwrap(),
        tessellate(&Primitive::Sphere { radius: 1.0 }, 8, None)
    );
    for o in [csg, repeat, mesh] {
        assert!(tessellate_object(&o, 8, None).is_none(), "{}", o.kind_name());
    }
}
