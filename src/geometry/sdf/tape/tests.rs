//! Tests of the tape: the tape against the tree, lanes against the scalar interpreter,
//! compilation shapes.

use super::*;
use crate::scene::shape::ObjectKind;
use crate::scene::transform::TransformDesc;
use glam::UVec3;

fn obj(kind: ObjectKind) -> Object {
    Object { kind, transform: TransformDesc::default(), material: 0, label: "t".into() }
}

fn prim(p: Primitive, translate: Vec3, rotate: Vec3, scale: Vec3) -> Object {
    Object {
        transform: TransformDesc { translate, rotate_deg: rotate, scale },
        ..obj(ObjectKind::Primitive(p))
    }
}

/// Every primitive kind, transformed, in a smooth union (with a subtraction and a
/// repetition inside) placed away from the world origin.
fn zoo() -> Object {
    let tr = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let kids = vec![
        prim(Primitive::Sphere { radius: 0.7 }, tr(0.0, 0.0, 0.0), Vec3::ZERO, Vec3::ONE),
        prim(Primitive::Box { half: tr(0.3, 0.5, 0.2) }, tr(1.0, 0.2, 0.0), tr(10.0, 20.0, 30.0), Vec3::ONE),
        prim(Primitive::Ellipsoid { radii: tr(0.5, 0.2, 0.3) }, tr(-1.0, 0.0, 0.3), Vec3::ZERO, Vec3::ONE),
        prim(
            Primitive::Cylinder { radius: 0.3, half_height: 0.6 },
            tr(0.0, 1.0, 0.0),
            tr(0.0, 0.0, 40.0),
            tr(1.0, 2.0, 0.5),
        ),
        prim(
            Primitive::Cone { radius_bottom: 0.4, radius_top: 0.1, half_height: 0.5 },
            tr(0.0, -1.0, 0.5),
            Vec3::ZERO,
            Vec3::ONE,
        ),
        prim(Primitive::Torus { major: 0.6, minor: 0.1 }, tr(0.5, 0.5, -0.5), tr(60.0, 0.0, 0.0), Vec3::ONE),
        prim(
            Primitive::Triangle { a: Vec3::ZERO, b: Vec3::X, c: tr(0.2, 0.9, 0.1) },
            tr(-1.0, 1.0, 0.0),
            Vec3::ZERO,
            Vec3::splat(0.5),
        ),
        prim(
            Primitive::Capsule { a: tr(-0.3, 0.0, 0.0), b: tr(0.3, 0.2, 0.0), radius: 0.15 },
            tr(1.0, -1.0, 0.0),
            Vec3::ZERO,
            Vec3::ONE,
        ),
        obj(ObjectKind::Csg {
            op: CsgOp::Subtraction,
            children: vec![
                prim(Primitive::Box { half: Vec3::splat(0.4) }, tr(0.0, 0.0, 1.2), Vec3::ZERO, Vec3::ONE),
                prim(Primitive::Sphere { radius: 0.5 }, tr(0.2, 0.2, 1.0), Vec3::ZERO, Vec3::ONE),
            ],
        }),
        Object {
            transform: TransformDesc { translate: tr(0.0, 0.0, -1.5), ..Default::default() },
            ..obj(ObjectKind::Repeat {
                period: tr(0.5, 0.0, 0.5),
                count: Some(UVec3::new(3, 1, 2)),
                child: Box::new(prim(Primitive::Sphere { radius: 0.2 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE)),
            })
        },
    ];
    Object {
        transform: TransformDesc {
            translate: tr(30.0, -20.0, 100.0),
            rotate_deg: tr(5.0, 10.0, 15.0),
            scale: Vec3::splat(1.5),
        },
        ..obj(ObjectKind::Csg { op: CsgOp::SmoothUnion { k: 0.2 }, children: kids })
    }
}

/// Deterministic points around the tape origin within `r`.
fn points(n: usize, r: f32) -> Vec<Vec3> {
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut u = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    (0..n).map(|_| Vec3::new(u(), u(), u()) * r).collect()
}

#[test]
fn tape_matches_tree_and_lanes_match_scalar() {
    let o = zoo();
    let tree = SdfTree::new(&o).unwrap();
    let tape = Tape::from_object(&o).unwrap();
    let mut scratch = TapeScratch::new(&tape);
    let pts = points(4096, 1.2 * tape.reach as f32);
    for chunk in pts.chunks_exact(8) {
        let xs = std::array::from_fn(|l| chunk[l].x);
        let ys = std::array::from_fn(|l| chunk[l].y);
        let zs = std::array::from_fn(|l| chunk[l].z);
        let wide = tape.eval8(&xs, &ys, &zs, &mut scratch);
        let portable = tape.eval8_portable(&xs, &ys, &zs, &mut scratch);
        // The same packet as each of four in a 32-lane evaluation, beside other points.
        let shift = |a: &[f32; 8], g: usize| a.map(|x| x * (1.0 - 0.1 * g as f32));
        let four = |a: &[f32; 8]| std::array::from_fn(|g| if g == 2 { *a } else { shift(a, g) });
        let wider = tape.eval32_ops(Ops::All(tape.ops()), &four(&xs), &four(&ys), &four(&zs), &mut scratch);
        let bits = |a: [f32; 8]| a.map(f32::to_bits);
        assert_eq!(bits(wider[2]), bits(wide), "packet 2 of 4");
        for (l, &p) in chunk.iter().enumerate() {
            let d = tape.eval(p, &mut scratch);
            assert_eq!(d.to_bits(), wide[l].to_bits(), "lane {l} at {p}");
            assert_eq!(d.to_bits(), portable[l].to_bits(), "portable lane {l} at {p}");
            let reference = tree.distance(tape.origin + p.as_dvec3());
            let err = (d as f64 - reference).abs();
            assert!(err <= tape.error_bound(p.length() as f64), "{d} vs {reference} at {p}");
        }
    }
}

#[test]
fn transforms_are_folded_into_one_op_per_primitive() {
    let tape = Tape::from_object(&zoo()).unwrap();
    let moves = tape.ops().iter().filter(|o| matches!(o, Op::Translate { .. } | Op::Affine { .. })).count();
    // Ten children: eight primitives, a subtraction of two and a repetition (one point
    // op for the repetition node, none for the four unrolled copies of its identity child).
    assert_eq!(moves, 8 + 2 + 1);
    assert!(tape.bytes_used() > 0);
    let scratch = TapeScratch::new(&tape);
    assert!(scratch.fits(&tape));
}

#[test]
fn infinite_repetition_far_from_the_origin() {
    let s = obj(ObjectKind::Primitive(Primitive::Sphere { radius: 0.5 }));
    let o = obj(ObjectKind::Repeat { period: Vec3::new(2.0, 0.0, 3.0), count: None, child: Box::new(s) });
    let tree = SdfTree::new(&o).unwrap();
    let tape = Tape::from_object(&o).unwrap();
    assert_eq!(tape.origin, DVec3::ZERO);
    let mut scratch = TapeScratch::new(&tape);
    for p in points(2000, 300.0) {
        let d = tape.eval(p, &mut scratch) as f64;
        let reference = tree.distance(p.as_dvec3());
        assert!((d - reference).abs() <= tape.error_bound(p.length() as f64), "{d} vs {reference} at {p}");
    }
}

#[test]
fn f32_is_not_enough_for_the_ground_sphere() {
    // data/hard/ground_5000.toml: seen from about 6 units away, with the default
    // relative tolerance of 1e-4 (a quarter of the default pixel footprint is larger).
    let tolerance = 1e-4 * 6.0;
    let mut ground = obj(ObjectKind::Primitive(Primitive::Sphere { radius: 5000.0 }));
    ground.transform.translate = Vec3::new(0.0, -5001.0, 0.0);
    assert!(!Tape::from_object(&ground).unwrap().f32_is_enough(tolerance));
    let unit = obj(ObjectKind::Primitive(Primitive::Sphere { radius: 1.0 }));
    assert!(Tape::from_object(&unit).unwrap().f32_is_enough(tolerance));
    // The zoo far from the world origin is fine: its tape is relative to its centre.
    assert!(Tape::from_object(&zoo()).unwrap().f32_is_enough(tolerance));
}

#[test]
fn meshes_have_no_tape() {
    let mesh = crate::mesh::TriangleMesh::default();
    let o = obj(ObjectKind::Mesh {
        mesh: std::sync::Arc::new(mesh),
        source: "m.obj".into(),
        shading: Default::default(),
    });
    assert!(Tape::from_object(&o).is_none());
}
