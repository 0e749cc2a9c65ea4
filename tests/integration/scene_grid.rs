//! Grids shared between objects.
//!
//! One narrow band shared by a scene's objects (`GridStorage::Scene`,
//! `geometry::grid::scene`): with one object it is that object's own band; its field is a
//! lower bound of the union's distance everywhere (the per-brick candidate lists cap the
//! far objects, never drop a near one) and the union's distance within the band; hit
//! materials are the nearest object's; a scene counts the shared grid once.
//!
//! Objects of one primitive share one grid sampled in its own frame (`Build::LocalGrid`,
//! `Build::SharedGrid`), as the mesh representation shares one mesh: placed by rigid
//! transforms with uniform scale, hits where the analytic ones are, counted once.

use glam::{DVec3, Vec3};
use sdfmesh::convert::mesh_to_grid::band::{BandMember, band_from_function, band_from_members};
use sdfmesh::geometry::grid::scene::SceneGrid;
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::geometry::{Geometry, Ray, RayStats, aabb};
use sdfmesh::plan::{Build, GridFill, GridStorage, Representation, build_scene_with_plans};
use sdfmesh::scene::shape::ObjectKind;
use sdfmesh::scene::shape::Primitive;

use crate::util::{Lcg, lit_scene, object};

fn scene_grid(cells: u32) -> Representation {
    Representation::Grid {
        resolution: 32,
        fill: GridFill::Sample,
        storage: GridStorage::Scene { cells },
        march: MarchParams::default(),
    }
}

fn range(rng: &mut Lcg, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * rng.unit()
}

/// Sphere `i` of a row of `n` spheres of radius 0.3, 0.05 apart.
fn row_centre(i: usize, n: usize) -> Vec3 {
    Vec3::new((i as f32 - 0.5 * (n - 1) as f32) * 0.65, 0.0, 0.0)
}

#[test]
fn one_object_gives_its_own_band() {
    let f = |p: DVec3| p.length() - 0.7;
    let (lo, hi) = (Vec3::splat(-0.7), Vec3::splat(0.7));
    let own = band_from_function(&f, lo, hi, 40, 2, 2).unwrap();
    let member = BandMember { bounds: aabb(lo, hi), distance: &f, material: 0 };
    let (shared, materials) = band_from_members(&[member], 1.4 / 40.0, 2, 2).unwrap();
    assert_eq!((shared.origin, shared.voxel, shared.dims), (own.origin, own.voxel, own.dims));
    assert_eq!(shared.stored_bricks(), own.stored_bricks());
    assert_eq!(materials.len(), shared.stored_bricks());
    let mut rng = Lcg(7);
    for _ in 0..2000 {
        let p = Vec3::new(range(&mut rng, -1.0, 1.0), range(&mut rng, -1.0, 1.0), range(&mut rng, -1.0, 1.0));
        if (p.length() - 0.7).abs() < 2.0 * own.voxel {
            // Equal but for 16-bit quantization: the shared band caps far samples, so a
            // brick's range (and its rounding) can differ.
            assert!((shared.trilinear(p) - own.trilinear(p)).abs() < 1e-3 * own.voxel, "{p}");
        }
    }
}

#[test]
fn union_field_is_a_lower_bound_and_exact_in_the_band() {
    // 27 spheres on a lattice: each brick sees only its nearby spheres.
    let centres: Vec<DVec3> =
        (0..27).map(|i| DVec3::new((i % 3) as f64, ((i / 3) % 3) as f64, (i / 9) as f64) * 0.9).collect();
    let fields: Vec<Box<dyn Fn(DVec3) -> f64 + Sync>> = centres
        .iter()
        .map(|&c| -> Box<dyn Fn(DVec3) -> f64 + Sync> { Box::new(move |p: DVec3| (p - c).length() - 0.25) })
        .collect();
    let members: Vec<BandMember<'_>> = centres
        .iter()
        .zip(&fields)
        .enumerate()
        .map(|(i, (c, f))| BandMember {
            bounds: aabb(c.as_vec3() - 0.25, c.as_vec3() + 0.25),
            distance: f.as_ref(),
            material: (i % 3) as u16,
        })
        .collect();
    let (band, bricks) = band_from_members(&members, 0.5 / 24.0, 2, 2).unwrap();
    let union = |p: DVec3| fields.iter().map(|f| f(p)).fold(f64::INFINITY, f64::min);
    let grid = SceneGrid::new(band, vec![10, 11, 12], bricks, members.len());
    let b = grid.band();
    let mut rng = Lcg(3);
    let (lo, hi) = b.bounds();
    let mut in_band = 0;
    for _ in 0..20_000 {
        let p =
            Vec3::new(range(&mut rng, lo.x, hi.x), range(&mut rng, lo.y, hi.y), range(&mut rng, lo.z, hi.z));
        let exact = union(p.as_dvec3()) as f32;
        let marched = b.march_distance(p);
        // Trilinear interpolation of exact samples lies within a cell's curvature error.
        let slack = 0.05 * b.voxel;
        assert!(marched.signum() == exact.signum() || exact.abs() < b.voxel, "{p}: {marched} vs {exact}");
        assert!(marched.abs() <= exact.abs() + slack, "{p}: marched {marched} above the union's {exact}");
        if exact.abs() < b.voxel {
            in_band += 1;
            assert!((marched - exact).abs() < 0.05 * b.voxel, "{p}: {marched} vs {exact}");
            // The nearest sphere's material (the sample nearest p can belong to a
            // neighbour only where two spheres are about equally near, 0.4 apart here).
            let nearest =
                (0..27).min_by(|&i, &j| fields[i](p.as_dvec3()).total_cmp(&fields[j](p.as_dvec3())));
            assert_eq!(grid.material(p), 10 + (nearest.unwrap() % 3) as u32, "{p}");
        }
    }
    assert!(in_band > 100, "{in_band} points near the surface");
}

#[test]
fn hits_take_the_nearest_objects_material_and_the_grid_counts_once() {
    let n = 6;
    let objects = (0..n)
        .map(|i| {
            let mut o = object(Primitive::Sphere { radius: 0.3 }, row_centre(i, n), Vec3::ZERO, Vec3::ONE);
            o.material = (i % 2) as u32;
            o
        })
        .collect();
    let scene = lit_scene(objects, 128);
    let (g, plans) = build_scene_with_plans(&scene, scene_grid(2));
    assert!(plans.iter().all(|p| p.fallback.is_none()
        && matches!(p.build, Build::Grid { storage: GridStorage::Scene { cells: 2 }, .. })));
    let mut stats = RayStats::default();
    for i in 0..n {
        // A ray from the camera's side straight at the sphere's centre.
        let c = row_centre(i, n);
        let from = c + Vec3::new(0.0, 0.5, -3.0);
        let ray = Ray::new(from, (c - from).normalize());
        let hit = g.closest_hit(&ray, 0.0, f32::INFINITY, &mut stats).expect("the ray meets the sphere");
        assert_eq!(hit.material, (i % 2) as u32, "sphere {i}");
        let expected = (c - from).length() - 0.3;
        assert!((hit.t - expected).abs() < 0.01, "sphere {i}: t {} vs {expected}", hit.t);
    }
    // Every object's bytes hold the shared grid; the scene counts it once.
    let one = g.objects()[0].bytes_used();
    let shared = g.objects()[0].shared().expect("a shared grid").bytes;
    assert!(shared > one / 2, "the grid is most of an object's bytes");
    assert!(g.bytes_used() < one + n * (one - shared) + 64 * 1024, "{} vs one object {one}", g.bytes_used());
    assert_eq!(g.census().grid_samples, g.objects()[0].census().grid_samples);
}

#[test]
fn clipped_objects_and_grid_files_keep_their_own_band() {
    // A huge sphere is clipped to the view region: its grid is its own band.
    let big = object(Primitive::Sphere { radius: 500.0 }, Vec3::new(0.0, -501.0, 0.0), Vec3::ZERO, Vec3::ONE);
    let small = object(Primitive::Sphere { radius: 0.5 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
    let scene = lit_scene(vec![big, small], 64);
    let (_, plans) = build_scene_with_plans(&scene, scene_grid(2));
    assert!(
        matches!(plans[0].build, Build::Grid { storage: GridStorage::Band { cells: 2 }, clip: Some(_), .. }),
        "{:?}",
        plans[0]
    );
    assert!(matches!(
        plans[1].build,
        Build::Grid { storage: GridStorage::Scene { cells: 2 }, clip: None, .. }
    ));
}

#[test]
fn alike_primitives_share_one_grid_placed_by_their_transforms() {
    let n = 12;
    let mut objects: Vec<_> = (0..n)
        .map(|i| {
            let rotate = Vec3::new(17.0 * i as f32, 40.0 * i as f32, 0.0);
            let scale = if i == 5 { Vec3::splat(1.5) } else { Vec3::ONE };
            let half = Vec3::new(0.2, 0.1, 0.15);
            object(Primitive::Box { half }, row_centre(i, n), rotate, scale)
        })
        .collect();
    // A non-uniform scale cannot be placed exactly: that box gets its own world grid.
    objects[7].transform.scale = Vec3::new(1.0, 2.0, 1.0);
    let scene = lit_scene(objects, 128);
    let repr = Representation::Grid {
        resolution: 24,
        fill: GridFill::Sample,
        storage: GridStorage::Band { cells: 2 },
        march: MarchParams::default(),
    };
    let (g, plans) = build_scene_with_plans(&scene, repr);
    assert!(matches!(plans[0].build, Build::LocalGrid { resolution: 24, .. }), "{:?}", plans[0]);
    for (i, p) in plans.iter().enumerate().skip(1) {
        match i {
            7 => assert!(matches!(p.build, Build::Grid { clip: None, .. }), "{p:?}"),
            _ => assert!(matches!(p.build, Build::SharedGrid { of: 0, .. }), "{i}: {p:?}"),
        }
    }
    // The shared grid counted once: the scene holds two grids' samples, not twelve.
    let own = g.objects()[7].census().grid_samples;
    assert_eq!(g.census().grid_samples, g.objects()[0].census().grid_samples + own);
    // Hits where the closed form's are, within a voxel of the local grid (0.4 / 24).
    let analytic =
        sdfmesh::plan::build_scene(&scene, Representation::Analytic { march: MarchParams::default() });
    let mut stats = RayStats::default();
    let mut rng = Lcg(11);
    let mut hits = 0;
    for i in 0..n {
        let ObjectKind::Primitive(_) = scene.objects[i].kind else { unreachable!() };
        for _ in 0..40 {
            let c = row_centre(i, n) + 0.1 * Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
            let from = c + Vec3::new(0.3 * (rng.unit() - 0.5), 1.0, -3.0);
            let ray = Ray::new(from, (c - from).normalize());
            let a = analytic.closest_hit(&ray, 0.0, f32::INFINITY, &mut stats);
            let b = g.closest_hit(&ray, 0.0, f32::INFINITY, &mut stats);
            if let (Some(a), Some(b)) = (a, b) {
                hits += 1;
                let voxel = 0.4 * scene.objects[i].transform.scale.max_element() / 24.0;
                assert!((a.t - b.t).abs() < voxel, "box {i}: t {} vs analytic {}", b.t, a.t);
            }
        }
    }
    assert!(hits > 300, "{hits} hits");
}
