//! The error measures of `toolkit compare` schema 2 (`sdfmesh::metrics`): geometric error in
//! pixels on spheres a known number of pixel footprints apart, silhouette mismatch on known
//! hit masks, FLIP on identical and different images, the quality grade, the bounded-object
//! scale of relative surface errors, the input class and the shuffled run order.

use std::path::Path;

use glam::{DVec3, Vec3};
use image::RgbImage;
use sdfmesh::compare::{input_class, run_order};
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::geometry::scene::SceneGeometry;
use sdfmesh::metrics::{
    GATE_SIZES, GATE_TABLE, Probe, QUALITY_LEVELS, bounded_diagonal, flip_mean, pixel_angle, pixel_error,
    probe, quality_levels, quality_px, silhouette_mismatch_pct,
};
use sdfmesh::plan::{Representation, build_scene};
use sdfmesh::scene::shape::Primitive;

use crate::util::{lit_scene, object};

fn sphere(r: f32) -> sdfmesh::scene::shape::Object {
    object(Primitive::Sphere { radius: r }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE)
}

/// The pixel angle is the footprint the marcher gets from the plan.
#[test]
fn pixel_angle_is_the_plans_footprint() {
    let scene = lit_scene(vec![sphere(1.0)], 96);
    let march = Representation::Sdf { march: MarchParams::default() }.with_pixel_footprint(&scene).march();
    assert!((pixel_angle(&scene.camera) - march.pixel_footprint).abs() < 1e-15);
}

/// A surface against itself is 0 pixels off (closed form exactly; sphere traced within its
/// tolerance), and spheres of radius 1 and 1 + delta, with delta k pixel footprints at the
/// sphere's distance, are about k pixels apart at every pixel: between delta over the footprint
/// at the farthest and at the nearest visible point.
#[test]
fn pixel_error_is_the_shift_in_pixel_footprints() {
    let size = 96;
    let inner = lit_scene(vec![sphere(1.0)], size);
    let analytic = Representation::Analytic { march: MarchParams::default() };
    let gi = build_scene(&inner, analytic);
    let pi = probe(&inner.camera, &gi, 1e5);
    let origin = inner.camera.position.as_dvec3();
    let angle = pixel_angle(&inner.camera);
    let same = pixel_error(&gi, &pi, &gi, &pi, origin, angle).unwrap();
    assert!(same.max < 1e-3 && same.pixels == pi.points.len(), "{same:?}");
    // Sphere tracing at a quarter-pixel tolerance stays within it.
    let sdf = Representation::Sdf { march: MarchParams { epsilon: 0.5, ..MarchParams::default() } };
    let gs = build_scene(&inner, sdf);
    let ps = probe(&inner.camera, &gs, 1e5);
    let traced = pixel_error(&gs, &ps, &gi, &pi, origin, angle).unwrap();
    assert!(traced.p95 < 0.3 && traced.mean < 0.2, "{traced:?}");
    let distance = origin.length();
    for k in [0.5, 2.0, 8.0] {
        let delta = k * angle * distance;
        let outer = lit_scene(vec![sphere(1.0 + delta as f32)], size);
        let go = build_scene(&outer, analytic);
        let po = probe(&outer.camera, &go, 1e5);
        let e = pixel_error(&go, &po, &gi, &pi, origin, angle).unwrap();
        // Depths of the inner sphere's visible points: from distance - 1 to the tangent.
        let (near, far) = (distance - 1.0, (distance * distance - 1.0).sqrt());
        let (lo, hi) = (delta / (far * angle), delta / (near * angle));
        assert!(e.pixels == pi.points.len(), "{e:?}");
        assert!(
            e.max <= hi * 1.01 && e.mean >= lo * 0.99 && e.mean <= hi,
            "k {k}: {e:?} not in [{lo}, {hi}]"
        );
        assert!((e.mean - k).abs() < 0.2 * k, "k {k}: {e:?}");
        assert!(e.p95 >= e.mean && e.max >= e.p95, "{e:?}");
        // The outer sphere covers every pixel of the inner one and a ring more: the ring is
        // the silhouette mismatch.
        let ring = po.hits.iter().zip(&pi.hits).filter(|(o, i)| **o && !**i).count();
        assert!(pi.hits.iter().zip(&po.hits).all(|(i, o)| !*i || *o));
        let pct = silhouette_mismatch_pct(&po, &pi);
        assert!((pct - 100.0 * ring as f64 / (size * size) as f64).abs() < 1e-12);
        assert!(ring > 0 || k < 1.0, "k {k}: no ring");
    }
}

/// The maximum of the two one-sided distances sees a surface the candidate lost in front of
/// another one: the candidate's ray hits the back sphere, which is on the reference too.
#[test]
fn pixel_error_sees_a_lost_front_surface() {
    let back = object(Primitive::Sphere { radius: 1.0 }, Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO, Vec3::ONE);
    let front = object(Primitive::Sphere { radius: 0.3 }, Vec3::new(0.0, 0.0, -1.0), Vec3::ZERO, Vec3::ONE);
    let analytic = Representation::Analytic { march: MarchParams::default() };
    let reference = lit_scene(vec![back.clone(), front], 64);
    let lost = lit_scene(vec![back], 64);
    let (gr, gl) = (build_scene(&reference, analytic), build_scene(&lost, analytic));
    let (pr, pl) = (probe(&reference.camera, &gr, 1e5), probe(&lost.camera, &gl, 1e5));
    let (origin, angle) = (reference.camera.position.as_dvec3(), pixel_angle(&reference.camera));
    let e = pixel_error(&gl, &pl, &gr, &pr, origin, angle).unwrap();
    // Where the front sphere was, the surfaces are about 2 units apart, 5 units from the
    // camera: about 2 / (5 * 0.0114) = 35 pixels.
    assert!(e.max > 20.0, "{e:?}");
    // The reference's distance of the run's hits alone sees nothing: they lie on the back
    // sphere, which the reference holds.
    let one_sided =
        pl.points.iter().map(|&p| sdfmesh::geometry::Geometry::surface_distance(&gr, p)).fold(0.0, f64::max);
    assert!(one_sided < 1e-4, "{one_sided}");
}

#[test]
fn silhouette_mismatch_counts_pixels_where_exactly_one_hits() {
    let p = |hits: &[bool]| Probe {
        hits: hits.to_vec(),
        points: hits.iter().filter(|h| **h).map(|_| DVec3::ZERO).collect(),
    };
    let a = p(&[true, true, false, false, true, false, false, false]);
    let b = p(&[true, false, true, false, true, false, false, false]);
    assert_eq!(silhouette_mismatch_pct(&a, &b), 25.0);
    assert_eq!(silhouette_mismatch_pct(&a, &a), 0.0);
    // Both hit at pixels 0 and 4 only: two pairs measured.
    let scene = lit_scene(vec![sphere(1.0)], 4);
    let g = build_scene(&scene, Representation::Analytic { march: MarchParams::default() });
    let e = pixel_error(&g, &a, &g, &b, DVec3::new(0.0, 0.0, -6.0), 0.01).unwrap();
    assert_eq!(e.pixels, 2);
    // The points are the origin, 1 from the unit sphere, 6 away: 1 / (6 * 0.01) pixels.
    assert!((e.mean - 1.0 / 0.06).abs() < 1e-9, "{e:?}");
}

#[test]
fn flip_is_zero_on_identical_images_and_grows_with_the_difference() {
    let a = RgbImage::from_fn(64, 48, |x, y| image::Rgb([(x * 4) as u8, (y * 5) as u8, 128]));
    assert_eq!(flip_mean(&a, &a), 0.0);
    let mut b = a.clone();
    for y in 20..28 {
        for x in 20..28 {
            b.put_pixel(x, y, image::Rgb([255, 255, 255]));
        }
    }
    let small = flip_mean(&b, &a);
    let c = RgbImage::from_fn(64, 48, |x, y| image::Rgb([255 - (x * 4) as u8, 255 - (y * 5) as u8, 0]));
    let large = flip_mean(&c, &a);
    assert!(small > 0.0 && large > small && large <= 1.0, "{small} {large}");
}

#[test]
fn quality_is_the_finest_level_met() {
    for side in GATE_SIZES.into_iter().chain([32, 200, 700, 4096]) {
        let [fine, mid, coarse] = quality_levels(side, side);
        let q = |p: Option<f64>, s: f64, f: f64| quality_px(p, s, f, side, side);
        assert!(fine.px < mid.px && mid.px < coarse.px);
        assert!(fine.max_silhouette_pct <= mid.max_silhouette_pct && fine.max_flip_mean <= mid.max_flip_mean);
        assert!(
            mid.max_silhouette_pct <= coarse.max_silhouette_pct && mid.max_flip_mean <= coarse.max_flip_mean
        );
        assert_eq!(q(Some(0.0), 0.0, 0.0), Some(fine.px));
        assert_eq!(q(Some(fine.px), fine.max_silhouette_pct, fine.max_flip_mean), Some(fine.px));
        // Any one error just over the fine level's bound drops the run to the next level.
        let over = |v: f64| v * 1.01 + 1e-9;
        assert_eq!(q(Some(over(fine.px)), 0.0, 0.0), Some(mid.px));
        assert_eq!(q(Some(0.0), over(fine.max_silhouette_pct), 0.0), Some(mid.px));
        assert_eq!(q(Some(0.0), 0.0, over(fine.max_flip_mean)), Some(mid.px));
        assert_eq!(q(Some(coarse.px), 0.0, 0.0), Some(coarse.px));
        assert_eq!(q(Some(over(coarse.px)), 0.0, 0.0), None);
        assert_eq!(q(Some(0.0), over(coarse.max_silhouette_pct), 0.0), None);
        assert_eq!(q(Some(0.0), 0.0, over(coarse.max_flip_mean)), None);
        // No pixel hit by both: no level.
        assert_eq!(q(None, 0.0, 0.0), None);
    }
}

/// The gates per image size: at 256 x 256 the bounds chosen there, at the calibrated sides
/// the table, in between between their neighbours, beyond the ends clamped; as calibrated,
/// the silhouette bound shrinks as the image grows (an outline error is a smaller share).
#[test]
fn gates_follow_the_image_size_as_calibrated() {
    assert_eq!(quality_levels(256, 256), QUALITY_LEVELS);
    for (i, level) in QUALITY_LEVELS.iter().enumerate() {
        for (k, &side) in GATE_SIZES.iter().enumerate() {
            let at = quality_levels(side, side)[i];
            let (sil, flip) = GATE_TABLE[i][k];
            assert!((at.max_silhouette_pct - sil).abs() < 1e-9 && (at.max_flip_mean - flip).abs() < 1e-9);
            assert_eq!(at.px, level.px);
        }
        for k in 1..GATE_SIZES.len() {
            let (a, b) = (GATE_SIZES[k - 1], GATE_SIZES[k]);
            assert!(GATE_TABLE[i][k].0 < GATE_TABLE[i][k - 1].0, "level {}: {a} -> {b}", level.px);
            let mid = quality_levels((a + b) / 2, (a + b) / 2)[i];
            let (lo, hi) = (
                GATE_TABLE[i][k].0.min(GATE_TABLE[i][k - 1].0),
                GATE_TABLE[i][k].0.max(GATE_TABLE[i][k - 1].0),
            );
            assert!(mid.max_silhouette_pct > lo && mid.max_silhouette_pct < hi);
        }
        assert_eq!(quality_levels(16, 16)[i], quality_levels(128, 128)[i]);
        assert_eq!(quality_levels(8192, 8192)[i], quality_levels(1024, 1024)[i]);
    }
    // A non-square image: the geometric mean of its sides.
    assert_eq!(quality_levels(128, 512), quality_levels(256, 256));
}

/// The scale of relative surface errors ignores infinite planes and a radius-5000 ground
/// sphere: the visible part of a unit sphere has a diagonal under that of its box.
#[test]
fn relative_scale_is_the_visible_bounded_objects() {
    let ground =
        object(Primitive::Sphere { radius: 5000.0 }, Vec3::new(0.0, -5001.0, 0.0), Vec3::ZERO, Vec3::ONE);
    let plane = object(Primitive::Plane { normal: Vec3::Y, offset: -1.5 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
    let analytic = Representation::Analytic { march: MarchParams::default() };
    let diagonal = |objects| {
        let scene = lit_scene(objects, 64);
        let g: SceneGeometry = build_scene(&scene, analytic);
        let p = probe(&scene.camera, &g, 1e5);
        bounded_diagonal(g.objects(), &p.points)
    };
    let alone = diagonal(vec![sphere(1.0)]).unwrap();
    assert!(alone > 1.5 && alone < 2.0 * 3f64.sqrt(), "{alone}");
    let with_ground = diagonal(vec![sphere(1.0), ground.clone(), plane.clone()]).unwrap();
    assert!((with_ground - alone).abs() < 0.1 * alone, "{with_ground} vs {alone}");
    // Nothing bounded in view: no scale.
    assert_eq!(diagonal(vec![plane]), None);
}

#[test]
fn input_class_is_the_scene_folder() {
    let c = |p: &str| input_class(Path::new(p));
    assert_eq!(c("data/scenes/blend/metaballs_16.toml"), "blend");
    assert_eq!(c("/repo/data/scenes/repeat/menger.toml"), "repeat");
    assert_eq!(c("data/scenes/thesis_rt.toml"), "scenes");
    assert_eq!(c("../shared/meshes/stanford-bunny.obj"), "scan");
    assert_eq!(c("/tmp/x/mine/two.toml"), "mine");
    assert_eq!(c("two.toml"), "scenes");
}

#[test]
fn order_seed_keeps_the_reference_first_and_permutes_the_rest() {
    assert_eq!(run_order(6, None, "a"), vec![0, 1, 2, 3, 4, 5]);
    let a = run_order(20, Some(7), "a");
    assert_eq!(a[0], 0);
    let mut sorted = a.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..20).collect::<Vec<_>>());
    assert_eq!(a, run_order(20, Some(7), "a"), "not deterministic");
    assert_ne!(a, run_order(20, Some(8), "a"), "the seed changes nothing");
    assert_ne!(a, run_order(20, Some(7), "b"), "every input gets the same order");
    assert_ne!(a, (0..20).collect::<Vec<_>>());
    assert_eq!(run_order(1, Some(3), "a"), vec![0]);
}
