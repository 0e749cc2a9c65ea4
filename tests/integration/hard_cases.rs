//! Numerically hard cases, run against every representation: grazing rays, the
//! radius-5000 ground sphere, rays starting inside objects, rays along box faces, the cone
//! apex, a torus seen edge-on, and self-shadowing speckles ("acne").

use glam::Vec3;
use image::RgbImage;
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::geometry::sdf::SdfTree;
use sdfmesh::geometry::{Geometry, Ray, RayStats};
use sdfmesh::plan::{GridFill, GridStorage, Representation, build_objects, build_scene};
use sdfmesh::render::report::render_scene;
use sdfmesh::scene::Scene;
use sdfmesh::scene::shape::Primitive;

use crate::util::{fraction_within, lit_scene, object};

/// Resolution of the grid representations here, as in the hard-case suite (`data/hard`).
const GRID_RESOLUTION: u32 = 64;

fn reprs() -> [Representation; 6] {
    let m = MarchParams::default();
    let grid = |storage| Representation::Grid {
        resolution: GRID_RESOLUTION,
        fill: GridFill::Sample,
        storage,
        march: m,
    };
    [
        Representation::Analytic { march: m },
        Representation::Sdf { march: m },
        Representation::Sdf { march: MarchParams { relaxation: 1.6, ..m } },
        Representation::Mesh {
            resolution: 512,
            shading: sdfmesh::scene::shape::Shading::Smooth,
            method: sdfmesh::plan::MeshMethod::Parametric,
            plane: sdfmesh::plan::MeshPlane::ClosedForm,
            march: m,
        },
        grid(GridStorage::Dense),
        grid(GridStorage::Band { cells: 2 }),
    ]
}

fn name(r: &Representation) -> String {
    match r {
        Representation::Sdf { march } if march.relaxation > 1.0 => {
            format!("sdf relaxed {}", march.relaxation)
        }
        Representation::Mesh { resolution, .. } => format!("mesh at {resolution}"),
        Representation::Grid { resolution, storage: GridStorage::Dense, .. } => {
            format!("dense grid at {resolution}")
        }
        Representation::Grid { resolution, storage: GridStorage::Band { cells }, .. } => {
            format!("band grid ({cells} cells) at {resolution}")
        }
        _ => r.name().to_string(),
    }
}

/// The cell size of an object with a bounding box of largest side `extent` gridded at
/// `GRID_RESOLUTION` (the grid's box is the object's, plus margins: this is a lower bound
/// within a few percent).
fn cell(extent: f32) -> f32 {
    extent / GRID_RESOLUTION as f32
}

/// Distance accuracy of `r` for an object of largest side `extent`: 1e-3 for the analytic
/// representations and fine meshes (as these tests always asked), and for grids half a
/// cell (a trilinear field's zero set can be that far from the surface at edges, corners
/// and apexes, where the distance is not linear across a cell).
fn tol(r: &Representation, extent: f32) -> f32 {
    match r {
        Representation::Grid { .. } => 1e-3f32.max(0.5 * cell(extent)),
        _ => 1e-3,
    }
}

/// The cell size a grid geometry states in its description (`..., voxel 0.05372, ...`).
fn voxel(describe: &str) -> f32 {
    let at =
        describe.find("voxel ").unwrap_or_else(|| panic!("no voxel size in {describe:?}")) + "voxel ".len();
    let digits: String = describe[at..].chars().take_while(|c| c.is_ascii_digit() || *c == '.').collect();
    digits.parse().unwrap_or_else(|_| panic!("no voxel size in {describe:?}"))
}

fn one(prim: Primitive, at: Vec3) -> Scene {
    lit_scene(vec![object(prim, at, Vec3::ZERO, Vec3::ONE)], 64)
}

/// Isolated pixels: differ from all 8 neighbours by more than `tol` in some channel.
fn speckles(img: &RgbImage, tol: u8) -> usize {
    let (w, h) = img.dimensions();
    let mut n = 0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let p = img.get_pixel(x, y).0;
            let isolated = (-1i32..=1).all(|dy| {
                (-1i32..=1).all(|dx| {
                    (dx == 0 && dy == 0) || {
                        let q = img.get_pixel((x as i32 + dx) as u32, (y as i32 + dy) as u32).0;
                        p.iter().zip(q.iter()).any(|(a, b)| a.abs_diff(*b) > tol)
                    }
                })
            });
            n += isolated as usize;
        }
    }
    n
}

#[test]
fn ground_sphere_of_radius_5000_has_no_holes_at_grazing_angles() {
    let ground = Primitive::Sphere { radius: 5000.0 };
    let scene = one(ground, Vec3::new(0.0, -5001.0, 0.0));
    let tree = SdfTree::new(&scene.objects[0]).unwrap();
    for repr in reprs() {
        let g = build_scene(&scene, repr);
        let mut stats = RayStats::default();
        let mut loose = 0;
        // A tessellation is inscribed: its surface lies up to the chordal error
        // R (1 - cos(pi / N)) inside the sphere, so its tangent slope is a little steeper.
        let (chord, first_slope) = match repr {
            Representation::Mesh { resolution, .. } => {
                // (Up to twice the edge sagitta in the middle of a facet.)
                let c = 2.0 * 5000.0 * (1.0 - (std::f64::consts::PI / resolution as f64).cos());
                (c, ((2.0 * (1.0 + c) / 5000.0) as f32).sqrt() * 1.01)
            }
            // A grid's trilinear field overestimates the convex distance to a sphere between
            // samples, by up to h^2 / (4 R) for cells of side h (the field's curvature is
            // 1 / R across the two tangent directions, and trilinear interpolation is off
            // by h^2 / 8 per unit of curvature): its surface lies that much inside.
            Representation::Grid { .. } => {
                let g = &build_objects(&scene, repr)[0];
                let h = voxel(&g.describe()) as f64;
                let c = h * h / (4.0 * 5000.0);
                (c, ((2.0 * (1.0 + c) / 5000.0) as f32).sqrt() * 1.01)
            }
            _ => (0.0, 0.0201),
        };
        // From height 1 above the top: the tangent slope is sqrt(2 / 5001) = 0.019998;
        // slopes from just above it (hits ~100 units away, at a grazing angle) to 1.
        for i in 0..200 {
            let slope = first_slope * (1.0 / first_slope).powf(i as f32 / 199.0);
            let ray = Ray::new(Vec3::ZERO, Vec3::new(0.0, -slope, 1.0).normalize());
            let hit = g.closest_hit(&ray, 0.0, 1e5, &mut stats);
            let hit = hit.unwrap_or_else(|| panic!("{}: hole at slope {slope}", name(&repr)));
            let d = tree.distance(hit.point.as_dvec3());
            // Converged marches: within 1e-4 of the distance; near the tangent, marches that
            // run out of steps: within the pixel footprint (documented in MarchParams);
            // meshes: within the chordal error.
            let footprint = 2.0 * (scene.camera.fov_y_deg as f64 / 2.0).to_radians().tan() / 64.0;
            loose += (d.abs() > 2e-4 * hit.t as f64 + chord) as usize;
            assert!(
                d.abs() < footprint * hit.t as f64 + chord,
                "{}: slope {slope}: |d| = {d} at t {}",
                name(&repr),
                hit.t
            );
            assert!(hit.normal.y > 0.9);
        }
        assert!(loose <= 5, "{}: {loose} of 200 hits only within the pixel footprint", name(&repr));
    }
}

#[test]
fn thesis_like_scene_has_no_shadow_acne() {
    let mut scene = lit_scene(
        vec![
            object(Primitive::Sphere { radius: 5000.0 }, Vec3::new(0.0, -5001.0, 0.0), Vec3::ZERO, Vec3::ONE),
            object(Primitive::Sphere { radius: 1.0 }, Vec3::new(0.0, 0.0, 1.0), Vec3::ZERO, Vec3::ONE),
        ],
        160,
    );
    scene.camera.position = Vec3::new(0.0, 0.2, -4.0);
    scene.camera.forward = Vec3::new(0.0, -0.1, 1.0).normalize();
    for repr in reprs() {
        let r = render_scene(&scene, repr);
        let n = speckles(&r.frame.image, 24);
        crate::util::dump(&format!("acne-{}", name(&repr)), &[&r.frame.image]);
        assert!(n == 0, "{}: {n} isolated speckles", name(&repr));
    }
}

#[test]
fn rays_starting_inside_find_the_inside_surface() {
    let prims = [
        Primitive::Sphere { radius: 2.0 },
        Primitive::Box { half: Vec3::new(1.0, 2.0, 1.5) },
        Primitive::Cylinder { radius: 1.5, half_height: 1.0 },
        Primitive::Torus { major: 2.0, minor: 0.8 },
    ];
    for prim in prims {
        // The torus's inside is around its ring, not at its centre.
        let start =
            if let Primitive::Torus { major, .. } = prim { Vec3::new(major, 0.0, 0.0) } else { Vec3::ZERO };
        let scene = one(prim, Vec3::ZERO);
        for repr in reprs() {
            let g = build_scene(&scene, repr);
            let mut stats = RayStats::default();
            for k in 0..64 {
                let a = k as f32 * 0.7;
                let dir = Vec3::new(a.cos(), (a * 1.3).sin() * 0.5, a.sin()).normalize();
                let hit = g.closest_hit(&Ray::new(start, dir), 0.0, 1e3, &mut stats);
                let hit = hit.unwrap_or_else(|| panic!("{} {}: no exit", prim.kind_name(), name(&repr)));
                // The outward normal points along the ray when leaving.
                assert!(hit.normal.dot(dir) > 0.0, "{} {}", prim.kind_name(), name(&repr));
            }
        }
    }
}

#[test]
fn rays_along_box_faces_and_at_the_cone_apex() {
    let boxed = one(Primitive::Box { half: Vec3::ONE }, Vec3::ZERO);
    let cone = one(Primitive::Cone { radius_bottom: 1.0, radius_top: 0.0, half_height: 1.0 }, Vec3::ZERO);
    for repr in reprs() {
        let mut stats = RayStats::default();
        let g = build_scene(&boxed, repr);
        // Parallel to the faces, inside the slab: hits the x = -1 face at t = 4.
        for y in [-0.999f32, 0.0, 0.5, 0.999] {
            let h =
                g.closest_hit(&Ray::new(Vec3::new(-5.0, y, 0.3), Vec3::X), 0.0, 100.0, &mut stats).unwrap();
            assert!((h.t - 4.0).abs() < tol(&repr, 2.0), "{}: {}", name(&repr), h.t);
            // A grid's normal (the field's gradient) leans within a cell or two of an edge.
            let near_edge = 1.0 - y.abs() < 2.0 * cell(2.0);
            if !matches!(repr, Representation::Grid { .. }) || !near_edge {
                assert!(h.normal.x < -0.99, "{}: normal {} at y {y}", name(&repr), h.normal);
            }
        }
        // Parallel to the faces, outside the slab: a miss (no NaN turned into a hit).
        assert!(
            g.closest_hit(&Ray::new(Vec3::new(-5.0, 1.01, 0.3), Vec3::X), 0.0, 100.0, &mut stats).is_none()
        );
        let g = build_scene(&cone, repr);
        // Straight down onto the apex at (0, 1, 0), and at a slant.
        let h = g.closest_hit(&Ray::new(Vec3::new(0.0, 4.0, 0.0), -Vec3::Y), 0.0, 100.0, &mut stats).unwrap();
        assert!((h.t - 3.0).abs() < tol(&repr, 2.0), "{}: {}", name(&repr), h.t);
        // A grid rounds the apex off (its trilinear field overestimates the distance to a
        // point): aim 3 cells below it, 1.3 cells inside the cone, and expect the hit there.
        // This slanted ray only touches the cone at the apex (it leaves the cone's slope
        // at once), so the marched field sees no sign change there and goes on (the
        // regularised rule of `MarchLane`): aim 0.01 below the apex, inside the cone.
        let (apex, below) = match repr {
            Representation::Grid { .. } => (Vec3::Y * (1.0 - 3.0 * cell(2.0)), 3.0 * cell(2.0)),
            Representation::Sdf { .. } => (Vec3::Y * 0.99, 0.01),
            _ => (Vec3::Y, 0.0),
        };
        let o = Vec3::new(2.0, 3.0, 0.5);
        let d = (apex - o).normalize();
        let h = g.closest_hit(&Ray::new(o, d), 0.0, 100.0, &mut stats);
        let h = h.unwrap_or_else(|| panic!("{}: missed the apex", name(&repr)));
        let off = (h.point - Vec3::Y).length();
        assert!(off < below + 2.0 * tol(&repr, 2.0), "{}: {} is {off} from the apex", name(&repr), h.point);
    }
}

#[test]
fn torus_edge_on_and_grazing_sphere_silhouettes_agree() {
    let m = MarchParams::default();
    let mut edge_on = one(Primitive::Torus { major: 1.5, minor: 0.3 }, Vec3::ZERO);
    edge_on.camera.position = Vec3::new(0.0, 0.0, -6.0);
    edge_on.camera.forward = Vec3::Z;
    edge_on.camera.width = 200;
    edge_on.camera.height = 200;
    let a = render_scene(&edge_on, Representation::Analytic { march: m });
    let s = render_scene(&edge_on, Representation::Sdf { march: m });
    crate::util::dump("torus-edge-on", &[&a.frame.image, &s.frame.image]);
    assert!(fraction_within(&a.frame.image, &s.frame.image, 2) >= 0.995);
    // Rays tangent to a unit sphere: just inside hits, just outside misses, for both.
    let sphere = one(Primitive::Sphere { radius: 1.0 }, Vec3::ZERO);
    for repr in reprs() {
        let g = build_scene(&sphere, repr);
        let mut stats = RayStats::default();
        let inside = g.closest_hit(&Ray::new(Vec3::new(0.999, 0.0, -5.0), Vec3::Z), 0.0, 100.0, &mut stats);
        let outside = g.closest_hit(&Ray::new(Vec3::new(1.001, 0.0, -5.0), Vec3::Z), 0.0, 100.0, &mut stats);
        assert!(inside.is_some() && outside.is_none(), "{}", name(&repr));
    }
}

#[test]
fn mirror_and_glass_spheres_have_no_speckles_in_any_representation() {
    let mut scene = lit_scene(
        vec![
            object(Primitive::Sphere { radius: 1.0 }, Vec3::new(-1.1, 0.0, 0.0), Vec3::ZERO, Vec3::ONE),
            object(Primitive::Sphere { radius: 1.0 }, Vec3::new(1.1, 0.0, 0.0), Vec3::ZERO, Vec3::ONE),
            object(Primitive::Plane { normal: Vec3::Y, offset: -1.0 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE),
        ],
        128,
    );
    scene.materials[1].reflectivity = 0.9;
    scene.materials.push(sdfmesh::scene::Material {
        name: "glass".into(),
        transparency: 0.9,
        ior: 1.5,
        ..scene.materials[1].clone()
    });
    scene.objects[1].material = 2;
    scene.objects[2].material = 0;
    scene.settings.max_depth = 4;
    // Single-pixel features are legitimate here (a highlight seen in a mirror); compare
    // with the closed form, which has no self-intersection noise.
    let mut reference = None;
    // A coarse smooth mesh too: its shading normals lean far from its facets.
    let coarse = Representation::Mesh {
        resolution: 24,
        shading: sdfmesh::scene::shape::Shading::Smooth,
        method: sdfmesh::plan::MeshMethod::Parametric,
        plane: sdfmesh::plan::MeshPlane::ClosedForm,
        march: MarchParams::default(),
    };
    for repr in reprs().into_iter().chain([coarse]) {
        let r = render_scene(&scene, repr);
        crate::util::dump(&format!("glass-{}", name(&repr)), &[&r.frame.image]);
        let n = speckles(&r.frame.image, 40);
        eprintln!("{}: {n} isolated pixels", name(&repr));
        let reference = *reference.get_or_insert(n);
        assert!(n <= reference + 3, "{}: {n} isolated speckles, closed form {reference}", name(&repr));
    }
}
