//! Tape pruning ([`sdfmesh::geometry::sdf::prune`]) on the random trees of [`crate::sdf_tape`]:
//! the interval bound over a box holds every value the tape takes in it, and a region's
//! shortened tape gives the whole tape's value at every point of the region (but for f32
//! rounding in the blends it decided), its 8-wide lanes equal to its scalar values bit for
//! bit. The marcher's use of regions (single rays against packets, and the same surface as
//! the closed form) is checked by the contract suite's `blobs` scene.

use glam::Vec3;
use proptest::prelude::*;
use sdfmesh::geometry::sdf::prune::{Bounds, TapeRegions};
use sdfmesh::geometry::sdf::tape::{Ops, Tape, TapeScratch};

use crate::sdf_tape::{case, sample};

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// The interval of the tape over a random box contains the tape's value at points in
    /// the box, up to twice the tape's f32 error bound (the interval is exact arithmetic
    /// around an f32 value at the box's centre; the tape's values are f32 too).
    #[test]
    fn intervals_contain_the_tape((o, unit) in case(), corner in prop::array::uniform2(0usize..56)) {
        let tape = Tape::from_object(&o).unwrap();
        let pts = sample(&o, &unit);
        let (a, b) = (pts[corner[0]], pts[corner[1]]);
        let (lo, hi) = (a.min(b), a.max(b));
        let mut bounds = Bounds::new(&tape);
        let iv = bounds.eval(&tape, lo, hi);
        prop_assert!(iv.lo <= iv.hi, "{iv:?}");
        let mut scratch = TapeScratch::new(&tape);
        let slack = 2.0 * tape.error_bound(lo.abs().max(hi.abs()).length() as f64) as f32;
        for u in &unit {
            let p = lo + (hi - lo) * (*u * 0.5 + Vec3::splat(0.5));
            let d = tape.eval(p, &mut scratch);
            prop_assert!(
                d >= iv.lo - slack && d <= iv.hi + slack,
                "tape {d} at {p} outside [{}, {}] over box {lo}..{hi}",
                iv.lo,
                iv.hi
            );
        }
    }

    /// Over a grid of 64 regions on the object's bounds, each point's shortened tape agrees
    /// with the whole tape within twice the error bound, and its lanes with its scalar path.
    #[test]
    fn shortened_tapes_match_the_whole_tape((o, unit) in case()) {
        let Some(bounds) = o.bounds() else { return Ok(()) };
        let tape = Tape::from_object(&o).unwrap();
        let Some(regions) = TapeRegions::with_cells(&tape, bounds, 64) else { return Ok(()) };
        let mut scratch = TapeScratch::new(&tape);
        let (bmin, bmax) = (Vec3::from(bounds.min), Vec3::from(bounds.max));
        let centre = tape.origin.as_vec3();
        let rel: Vec<Vec3> = unit
            .iter()
            .map(|u| (bmin + (bmax - bmin) * (*u * 0.5 + Vec3::splat(0.5))) - centre)
            .collect();
        for chunk in rel.chunks_exact(8) {
            let xs = std::array::from_fn(|l| chunk[l].x);
            let ys = std::array::from_fn(|l| chunk[l].y);
            let zs = std::array::from_fn(|l| chunk[l].z);
            for (l, &p) in chunk.iter().enumerate() {
                let Some(cell) = regions.cell(p) else { continue };
                let ops = regions.ops(cell);
                let short = tape.eval_ops(ops, p, &mut scratch);
                let lanes = tape.eval8_ops(ops, &xs, &ys, &zs, &mut scratch);
                prop_assert_eq!(short.to_bits(), lanes[l].to_bits(), "lane {} at {}", l, p);
                let whole = tape.eval_ops(Ops::All(tape.ops()), p, &mut scratch);
                let bound = 2.0 * tape.error_bound(p.length() as f64);
                prop_assert!(
                    ((short - whole) as f64).abs() <= bound,
                    "shortened {short} vs whole {whole} at {p}: more than {bound:e} apart"
                );
            }
        }
    }
}

/// A smooth union of 64 small spheres spread through a box: most regions see a few of
/// them, so the shortened tapes average well under the whole tape, and regions are kept.
#[test]
fn regions_shorten_a_spread_smooth_union() {
    use sdfmesh::scene::shape::{CsgOp, Object, ObjectKind, Primitive};
    use sdfmesh::scene::transform::TransformDesc;
    let mut seed = 7u32;
    let mut next = || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32 * 4.0 - 2.0
    };
    let children = (0..64)
        .map(|_| Object {
            kind: ObjectKind::Primitive(Primitive::Sphere { radius: 0.2 }),
            transform: TransformDesc { translate: Vec3::new(next(), next(), next()), ..Default::default() },
            material: 0,
            label: "s".into(),
        })
        .collect();
    let o = Object {
        kind: ObjectKind::Csg { op: CsgOp::SmoothUnion { k: 0.1 }, children },
        transform: TransformDesc::default(),
        material: 0,
        label: "blobs".into(),
    };
    let tape = Tape::from_object(&o).unwrap();
    let regions = TapeRegions::build(&tape, o.bounds().unwrap()).expect("regions pay here");
    assert!(regions.mean_ratio() < 0.25, "mean shortened length {}", regions.mean_ratio());
    assert!(regions.distinct() > 1);
}

/// The contract suite's `blobs` scene is marched with regions, so that the suite checks
/// them (single rays against packets, the surface against the closed form).
#[test]
fn the_contract_scene_blobs_has_regions() {
    use sdfmesh::geometry::sdf::SdfField;
    let scene = crate::contract::blobs();
    let o = &scene.objects[0];
    let field = SdfField::new(o, o.bounds()).unwrap();
    let regions = field.regions.expect("regions kept");
    assert!(regions.mean_ratio() < 0.5, "{}", regions.mean_ratio());
}
