//! The compiled SDF tape ([`sdfmesh::geometry::sdf::tape`]) against the f64 object tree it
//! is compiled from: random trees of every primitive kind under random transforms
//! (rotation, uniform and non-uniform scale), every CSG operation including the smooth
//! ones, finite and infinite repetition, nested. The tape is f32, so the tolerance is
//! relative to the f32 precision of the magnitudes involved: `Tape::error_bound(|p_rel|)`,
//! i.e. `ERROR_FACTOR * f32::EPSILON * (|p_rel| + K)` with `K` the largest coordinate
//! magnitude inside the tape. The 8-wide evaluation must equal the scalar one bit for bit.

use glam::{DVec3, UVec3, Vec3};
use proptest::prelude::*;
use sdfmesh::geometry::sdf::SdfTree;
use sdfmesh::geometry::sdf::tape::{ERROR_FACTOR, Op, Tape, TapeScratch};
use sdfmesh::scene::shape::{CsgOp, Object, ObjectKind, Primitive};
use sdfmesh::scene::transform::TransformDesc;

fn vec3(lo: f32, hi: f32) -> impl Strategy<Value = Vec3> {
    (lo..hi, lo..hi, lo..hi).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// Identity, a translation, or translation + rotation with uniform or non-uniform scale.
fn transform() -> impl Strategy<Value = TransformDesc> {
    prop_oneof![
        Just(TransformDesc::default()),
        vec3(-3.0, 3.0).prop_map(|translate| TransformDesc { translate, ..Default::default() }),
        (vec3(-3.0, 3.0), vec3(-180.0, 180.0), 0.5f32..2.0).prop_map(|(translate, rotate_deg, s)| {
            TransformDesc { translate, rotate_deg, scale: Vec3::splat(s) }
        }),
        (vec3(-3.0, 3.0), vec3(-180.0, 180.0), vec3(0.4, 2.5))
            .prop_map(|(translate, rotate_deg, scale)| TransformDesc { translate, rotate_deg, scale }),
    ]
}

fn primitive() -> impl Strategy<Value = Primitive> {
    prop_oneof![
        (0.1f32..2.0).prop_map(|radius| Primitive::Sphere { radius }),
        ((-3.0f32..3.0, -1.5f32..1.5), -1.0f32..1.0).prop_map(|((lon, lat), offset)| Primitive::Plane {
            normal: Vec3::new(lat.cos() * lon.cos(), lat.sin(), lat.cos() * lon.sin()).normalize(),
            offset
        }),
        vec3(0.1, 1.5).prop_map(|half| Primitive::Box { half }),
        vec3(0.1, 1.5).prop_map(|radii| Primitive::Ellipsoid { radii }),
        (0.1f32..1.0, 0.1f32..1.5)
            .prop_map(|(radius, half_height)| Primitive::Cylinder { radius, half_height }),
        (0.0f32..1.0, 0.0f32..1.0, 0.1f32..1.5).prop_map(|(b, t, half_height)| Primitive::Cone {
            radius_bottom: b + 0.05,
            radius_top: t,
            half_height
        }),
        (0.3f32..1.5, 0.05f32..0.4).prop_map(|(major, minor)| Primitive::Torus { major, minor }),
        (vec3(-1.0, 1.0), vec3(-1.0, 1.0), vec3(-1.0, 1.0))
            .prop_filter("non-degenerate triangle", |(a, b, c)| (*b - *a).cross(*c - *a).length() > 0.05)
            .prop_map(|(a, b, c)| Primitive::Triangle { a, b, c }),
        (vec3(-1.0, 1.0), vec3(-1.0, 1.0), 0.05f32..0.5).prop_map(|(a, b, radius)| Primitive::Capsule {
            a,
            b,
            radius
        }),
    ]
}

fn object(kind: ObjectKind, transform: TransformDesc) -> Object {
    Object { kind, transform, material: 0, label: "t".into() }
}

fn csg_op() -> impl Strategy<Value = CsgOp> {
    prop_oneof![
        Just(CsgOp::Union),
        Just(CsgOp::Intersection),
        Just(CsgOp::Subtraction),
        (0.05f32..1.0).prop_map(|k| CsgOp::SmoothUnion { k }),
        (0.05f32..1.0).prop_map(|k| CsgOp::SmoothIntersection { k }),
        (0.05f32..1.0).prop_map(|k| CsgOp::SmoothSubtraction { k }),
    ]
}

/// Repetition of `child` along the axes marked in `axes` (at least the first, so something
/// repeats), with a period that keeps the child inside its own cell (so the tree's distance
/// is continuous: near a cell centre the tree and the tape may pick different neighbours),
/// `count` copies per axis or infinitely many. An unbounded child is returned as it is.
fn repeat(child: Object, axes: [bool; 3], gap: f32, count: Option<UVec3>, t: TransformDesc) -> Object {
    let Some(b) = child.bounds() else { return child };
    let mut period = Vec3::ZERO;
    for axis in 0..3 {
        if axes[axis] || axis == 0 {
            period[axis] = 2.0 * b.min[axis].abs().max(b.max[axis].abs()) + gap;
        }
    }
    object(ObjectKind::Repeat { period, count, child: Box::new(child) }, t)
}

fn tree() -> impl Strategy<Value = Object> {
    let leaf = (primitive(), transform()).prop_map(|(p, t)| object(ObjectKind::Primitive(p), t));
    leaf.prop_recursive(3, 24, 4, |inner| {
        prop_oneof![
            (csg_op(), prop::collection::vec(inner.clone(), 2..5), transform())
                .prop_map(|(op, children, t)| object(ObjectKind::Csg { op, children }, t)),
            (
                inner,
                prop::array::uniform3(any::<bool>()),
                0.0f32..1.0,
                prop::option::of((1u32..5, 1u32..5, 1u32..5)),
                transform()
            )
                .prop_map(|(child, axes, gap, count, t)| {
                    repeat(child, axes, gap, count.map(|(x, y, z)| UVec3::new(x, y, z)), t)
                }),
        ]
    })
}

/// What [`check`] saw.
#[derive(Clone, Copy, Debug, Default)]
struct Seen {
    /// The worst `|tape - tree|` in units of `f32::EPSILON * (|p_rel| + K)`, over the points
    /// not at a jump.
    worst: f64,
    /// Points checked.
    points: usize,
    /// Points where the tree jumps: the tape equals the tree at a point within the error
    /// bound of `p`, not at `p` itself.
    jumps: usize,
}

/// Checks the tape against the tree at `points` (relative to the tape origin), and every
/// group of eight against the scalar path.
///
/// The tree is discontinuous where a repetition's child is only a Lipschitz bound: at a cell
/// centre it takes the neighbouring cell on the side of the point, so the two sides of the
/// centre see different neighbours. Within rounding of a cell centre, f32 and f64 may pick
/// different sides; there the tape must equal the tree at a point at most `bound` away (one
/// of 14 nudges along the axes and diagonals), within twice the bound, and the point is
/// counted as a jump.
fn check(o: &Object, points: &[Vec3]) -> Result<Seen, TestCaseError> {
    let tree = SdfTree::for_marching(o).unwrap();
    let tape = Tape::from_object(o).unwrap();
    let mut scratch = TapeScratch::new(&tape);
    let mut seen = Seen::default();
    for chunk in points.chunks_exact(8) {
        let xs = std::array::from_fn(|l| chunk[l].x);
        let ys = std::array::from_fn(|l| chunk[l].y);
        let zs = std::array::from_fn(|l| chunk[l].z);
        let wide = tape.eval8(&xs, &ys, &zs, &mut scratch);
        let portable = tape.eval8_portable(&xs, &ys, &zs, &mut scratch);
        for (l, &p) in chunk.iter().enumerate() {
            let d = tape.eval(p, &mut scratch);
            prop_assert_eq!(d.to_bits(), wide[l].to_bits(), "lane {} at {}: {} vs {}", l, p, d, wide[l]);
            prop_assert_eq!(d.to_bits(), portable[l].to_bits(), "portable lane {} at {}", l, p);
            // The tree at exactly the point the tape sees (no rounding of the input).
            let world = tape.origin + p.as_dvec3();
            let reference = tree.distance(world);
            let err = (d as f64 - reference).abs();
            let bound = tape.error_bound(p.length() as f64);
            seen.points += 1;
            if err > bound {
                let nudges = (0..6)
                    .map(|i| {
                        let mut v = DVec3::ZERO;
                        v[i % 3] = if i < 3 { bound } else { -bound };
                        v
                    })
                    .chain((0..8).map(|c| {
                        let s = |bit: u32| if c & bit == 0 { bound } else { -bound };
                        DVec3::new(s(1), s(2), s(4)) / 3f64.sqrt()
                    }));
                if nudges.into_iter().any(|v| (d as f64 - tree.distance(world + v)).abs() <= 2.0 * bound) {
                    seen.jumps += 1;
                    continue;
                }
            }
            prop_assert!(
                err <= bound,
                "tape {} vs tree {} at p_rel {} (origin {}): error {:e} > bound {:e}",
                d,
                reference,
                p,
                tape.origin,
                err,
                bound
            );
            seen.worst = seen.worst.max(err / (bound / ERROR_FACTOR));
        }
    }
    Ok(seen)
}

/// Points around the tape's origin: within 1.5 times the bounds (or a radius of 8 for an
/// unbounded object), plus a few far away.
pub(crate) fn sample(o: &Object, unit: &[Vec3]) -> Vec<Vec3> {
    let tape = Tape::from_object(o).unwrap();
    let r = if tape.reach > 0.0 { 1.5 * tape.reach as f32 } else { 8.0 };
    let mut pts: Vec<Vec3> = unit.iter().map(|&u| u * r).collect();
    pts.extend(unit.iter().take(8).map(|&u| u * 50.0 * r));
    pts
}

/// A random tree, near the world origin or up to 1000 units away from it (the tape is
/// relative to the object's centre), and 56 points in the unit cube.
pub(crate) fn case() -> impl Strategy<Value = (Object, Vec<Vec3>)> {
    (tree(), prop::collection::vec(vec3(-1.0, 1.0), 56), prop_oneof![Just(Vec3::ZERO), vec3(-1000.0, 1000.0)])
        .prop_map(|(mut o, unit, offset)| {
            o.transform.translate += offset;
            (o, unit)
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]
    #[test]
    fn tape_matches_the_tree((o, unit) in case()) {
        check(&o, &sample(&o, &unit))?;
    }

    /// The marching tree (repetitions whose child fits its cell bounded by the cell's faces)
    /// against the tree grids and meshes are built from: the same sign everywhere (so the
    /// same surface), and, where every copy's value is its exact distance (exact primitives under
    /// rigid transforms, unions and repetitions only), at most the same value outside: a
    /// bound a march may step by. (Where a copy's value is only a bound, the sampling tree
    /// can go below the true distance of a neighbour copy, and the face bound above it.)
    /// Inside, the marching tree may be the deeper one (see the assertion).
    #[test]
    fn marching_tree_bounds_the_sampling_tree((o, unit) in case()) {
        let (sampling, marching) = (SdfTree::new(&o).unwrap(), SdfTree::for_marching(&o).unwrap());
        let tape = Tape::from_object(&o).unwrap();
        let exact = exact_copies(&o);
        for p in sample(&o, &unit) {
            let w = tape.origin + p.as_dvec3();
            let (a, m) = (sampling.distance(w), marching.distance(w));
            let slack = 1e-9 * (1.0 + w.abs().max_element());
            // Outside only: inside, a repetition of overlapping boxes merged into one
            // stretched box (`merged_box`) is its exact depth, deeper than the copies' minimum.
            prop_assert!(!exact || a <= 0.0 || m <= a + slack, "marching {m} above sampling {a} at {w}");
            prop_assert!(a * m >= 0.0 || a.abs() <= slack, "marching {m} and sampling {a} differ in sign at {w}");
        }
    }
}

/// Whether every value in `o`'s tree is an exact distance: exact primitives under
/// translations, rotations and uniform scales, combined by unions and repetitions only.
fn exact_copies(o: &Object) -> bool {
    let s = o.transform.scale;
    let rigid = s.x == s.y && s.y == s.z;
    rigid
        && match &o.kind {
            ObjectKind::Primitive(p) => sdfmesh::geometry::sdf::primitive_is_exact(p),
            ObjectKind::Csg { op: CsgOp::Union, children } => children.iter().all(exact_copies),
            ObjectKind::Repeat { child, .. } => exact_copies(child),
            _ => false,
        }
}

/// The worst error ratio over many random trees, printed for calibrating `ERROR_FACTOR`
/// (`cargo test --test integration sdf_tape::calibrate -- --ignored --nocapture`).
#[test]
#[ignore]
fn calibrate() {
    let mut runner =
        proptest::test_runner::TestRunner::new(ProptestConfig { cases: 20000, ..Default::default() });
    let total = std::cell::Cell::new(Seen::default());
    runner
        .run(&case(), |(o, unit)| {
            let s = check(&o, &sample(&o, &unit))?;
            let t = total.get();
            total.set(Seen {
                worst: t.worst.max(s.worst),
                points: t.points + s.points,
                jumps: t.jumps + s.jumps,
            });
            Ok(())
        })
        .unwrap();
    let t = total.get();
    println!(
        "worst |tape - tree| / (f32::EPSILON * (|p_rel| + K)) = {:.3} over {} points; {} at a jump of the tree",
        t.worst, t.points, t.jumps
    );
    assert!(t.jumps * 10_000 < t.points, "{t:?}");
}

/// 512 points spread over the cube [-1, 1]^3 (a fixed hash, no randomness).
fn spread_points() -> Vec<Vec3> {
    (0..512)
        .map(|i| {
            let f = |k: u32| ((i * 7919 + k * 104729).wrapping_mul(2654435761) % 1000) as f32 / 500.0 - 1.0;
            Vec3::new(f(1), f(2), f(3))
        })
        .collect()
}

/// The bundled scenes' analytic objects compile, and their tapes agree with the trees.
#[test]
fn bundled_scenes() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes");
    let unit = spread_points();
    let mut objects = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        // The bundled scenes; the generated families in subfolders are parse-tested by
        // `every_scene_in_data_parses` and rendered by the study.
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let scene = sdfmesh::scene::load_scene(&path).unwrap();
        for o in &scene.objects {
            if SdfTree::new(o).is_none() {
                continue;
            }
            objects += 1;
            check(o, &sample(o, &unit)).unwrap_or_else(|e| panic!("{}: {}: {e}", path.display(), o.label));
        }
    }
    assert!(objects > 20, "{objects}");
    // The hard case: the ground sphere seen from 6 units away needs f64.
    let ground = sdfmesh::scene::load_scene(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/hard/ground_5000.toml"),
    )
    .unwrap();
    let tape = Tape::from_object(&ground.objects[0]).unwrap();
    assert_eq!(tape.origin, DVec3::new(0.0, -5001.0, 0.0));
    assert!(!tape.f32_is_enough(1e-4 * 6.0));
    assert!(Tape::from_object(&ground.objects[1]).unwrap().f32_is_enough(1e-4 * 6.0));
}

/// A case the random trees found: an infinite repetition, 900 units from the world origin,
/// of a rotated, non-uniformly scaled subtraction (a Lipschitz bound, not a distance),
/// evaluated within rounding of a cell centre, where the tree jumps.
#[test]
fn jump_at_a_cell_centre() {
    let prim = |p: Primitive, translate: Vec3| {
        object(ObjectKind::Primitive(p), TransformDesc { translate, ..Default::default() })
    };
    let child = object(
        ObjectKind::Csg {
            op: CsgOp::Subtraction,
            children: vec![
                prim(
                    Primitive::Ellipsoid { radii: Vec3::new(0.5812042, 1.0833404, 0.87599736) },
                    Vec3::new(0.63452965, -1.2869387, 1.9234862),
                ),
                prim(Primitive::Sphere { radius: 0.1 }, Vec3::ZERO),
            ],
        },
        TransformDesc {
            translate: Vec3::new(2.0796254, 0.0, 0.0),
            rotate_deg: Vec3::new(95.94273, -118.416954, -22.856726),
            scale: Vec3::new(1.9882127, 0.85379636, 0.59514546),
        },
    );
    let o = object(
        ObjectKind::Repeat { period: Vec3::new(8.07347, 0.0, 0.0), count: None, child: Box::new(child) },
        TransformDesc { translate: Vec3::new(-355.05362, 0.0, -861.11633), ..Default::default() },
    );
    let p = Vec3::new(0.17907129, 0.0, 0.0);
    let seen = check(&o, &[p; 8]).unwrap();
    assert_eq!((seen.points, seen.jumps), (8, 8), "{seen:?}");
}

/// Common subexpressions are computed once: the rotated Menger sponge maps its point once
/// for the four children of its subtraction, and each level's bars share their cell
/// lookups (two of the three axes each, three lookups per level instead of six); the tape
/// still agrees with the tree.
#[test]
fn shared_subexpressions_once() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/fractal/menger_3.toml");
    let scene = sdfmesh::scene::load_scene(&path).unwrap();
    let o = &scene.objects[0];
    let tape = Tape::from_object(o).unwrap();
    let count = |f: fn(&Op) -> bool| tape.ops().iter().filter(|op| f(op)).count();
    assert_eq!(count(|op| matches!(op, Op::Affine { .. })), 1, "{:#?}", tape.ops());
    assert_eq!(count(|op| matches!(op, Op::CellFace { .. })), 6, "{:#?}", tape.ops());
    let unit = spread_points();
    check(o, &sample(o, &unit)).unwrap();
}
