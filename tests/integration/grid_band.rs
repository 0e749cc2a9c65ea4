//! Narrow-band grids: equal to the dense grid inside the band, a conservative bound
//! outside it, much smaller, and rendering like the dense grid.

use std::sync::Arc;

use glam::{DVec3, UVec3, Vec3};
use proptest::prelude::*;
use sdfmesh::convert::mesh_to_grid::band::{band_from_function, band_from_mesh};
use sdfmesh::convert::mesh_to_grid::voxelize::voxelize_mesh;
use sdfmesh::convert::mesh_to_grid::{sample_function, sample_mesh};
use sdfmesh::convert::tessellate::tessellate;
use sdfmesh::geometry::Geometry;
use sdfmesh::geometry::grid::SdfGrid;
use sdfmesh::geometry::grid::band::BandGrid;
use sdfmesh::geometry::grid::object::GridObject;
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::plan::{GridFill, GridStorage, Representation};
use sdfmesh::render::report::render_scene;
use sdfmesh::scene::shape::{Object, ObjectKind, Primitive, Shading};
use sdfmesh::scene::transform::TransformDesc;

use crate::util::{fraction_within, lit_scene, object};

const R: f64 = 1.0;

fn sphere(p: DVec3) -> f64 {
    p.length() - R
}

fn sphere_grids(res: u32, cells: u32) -> (SdfGrid, BandGrid) {
    let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
    let dense = sample_function(&sphere, lo, hi, res, 2).unwrap();
    let band = band_from_function(&sphere, lo, hi, res, 2, cells).unwrap();
    (dense, band)
}

fn cell_of(g: &BandGrid, p: Vec3) -> UVec3 {
    ((p - g.origin) / g.voxel).floor().as_uvec3().min(g.dims - UVec3::splat(2))
}

fn unit(theta: f64, phi: f64) -> DVec3 {
    DVec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn band_equals_dense_inside_the_band(theta in 0.0..std::f64::consts::PI, phi in 0.0..6.3f64, s in -2.0..2.0f64) {
        let (dense, band) = &*SPHERE_64;
        let p = (unit(theta, phi) * (R + s * dense.voxel as f64)).as_vec3();
        prop_assert!(band.is_stored(cell_of(band, p)), "{p} is in the band");
        let (a, b) = (band.trilinear(p), dense.trilinear(p));
        prop_assert!((a - b).abs() <= 1e-3 * dense.voxel, "{p}: band {a} dense {b}");
    }

    #[test]
    fn band_bound_is_conservative_everywhere(x in -1.6..1.6f64, y in -1.6..1.6f64, z in -1.6..1.6f64) {
        let (dense, band) = &*SPHERE_64;
        let p = DVec3::new(x, y, z);
        let exact = sphere(p);
        let v = band.trilinear(p.as_vec3()) as f64;
        let inside_box = band.bounds().0.as_dvec3().cmple(p).all() && p.cmple(band.bounds().1.as_dvec3()).all();
        // Outside the box, the cell is the one nearest `p` on the box's boundary.
        if band.is_stored(cell_of(band, p.as_vec3())) {
            // Samples, not a bound (trilinear interpolation of the convex sphere distance
            // lies above it), continued outside the box as the dense grid's are.
            let d = dense.trilinear(p.as_vec3()) as f64;
            prop_assert!((v - d).abs() <= 1e-3 * dense.voxel as f64, "{p}: band {v} dense {d}");
        } else {
            prop_assert!(v.abs() <= exact.abs() + 1e-5, "{p}: bound {v} exact {exact}");
            prop_assert!(v.signum() == exact.signum(), "{p}: bound {v} exact {exact}");
            prop_assert!(v.abs() >= 2.0 * band.voxel as f64 - 1e-6 || !inside_box, "steps of at least the band");
        }
    }
}

/// A point proptest found: just outside the grid's box, its nearest boundary cell in the
/// band, where the band's value (samples continued by the distance to the box) lies above
/// the exact distance, as the dense grid's does.
#[test]
fn outside_the_box_next_to_the_band_is_the_dense_value() {
    let (dense, band) = &*SPHERE_64;
    let p = DVec3::new(1.062634303772659, -0.17575025619207976, -0.24004034968572172);
    assert!(!(band.bounds().0.as_dvec3().cmple(p).all() && p.cmple(band.bounds().1.as_dvec3()).all()));
    assert!(band.is_stored(cell_of(band, p.as_vec3())));
    let (v, d) = (band.trilinear(p.as_vec3()), dense.trilinear(p.as_vec3()));
    assert!((v - d).abs() <= 1e-3 * dense.voxel, "band {v} dense {d}");
    assert!(v as f64 > sphere(p), "samples, not a bound: {v} against {}", sphere(p));
}

static SPHERE_64: std::sync::LazyLock<(SdfGrid, BandGrid)> = std::sync::LazyLock::new(|| sphere_grids(64, 2));

#[test]
fn from_dense_and_from_mesh_agree_with_dense_in_the_band() {
    let (dense, band) = &*SPHERE_64;
    let from_dense = BandGrid::from_dense(dense, 2).unwrap();
    assert_eq!(from_dense.dims, band.dims);
    let mesh = tessellate(&Primitive::Sphere { radius: 1.0 }, 128, None);
    let dense_mesh = sample_mesh(&mesh, 32, 2).unwrap();
    let band_mesh = band_from_mesh(&mesh, 32, 2, 2).unwrap();
    assert_eq!((band_mesh.origin, band_mesh.dims), (dense_mesh.origin, dense_mesh.dims));
    for i in 0..400 {
        let (theta, phi) = (i as f64 * 0.37 % std::f64::consts::PI, i as f64 * 1.13);
        let s = (i % 7) as f64 / 3.5 - 1.0;
        let p = (unit(theta, phi) * (R + s * dense.voxel as f64)).as_vec3();
        assert!((from_dense.trilinear(p) - dense.trilinear(p)).abs() <= 1e-3 * dense.voxel, "{p}");
        let q = (unit(theta, phi) * (R + s * dense_mesh.voxel as f64)).as_vec3();
        let (a, b) = (band_mesh.trilinear(q), dense_mesh.trilinear(q));
        assert!((a - b).abs() <= 1e-3 * dense_mesh.voxel, "{q}: {a} vs {b}");
    }
    // A voxelized grid converts too.
    let vox = voxelize_mesh(&mesh, 32, 2).unwrap();
    let vb = BandGrid::from_dense(&vox, 2).unwrap();
    assert!(vb.stored_bricks() < vb.brick_count());
    let centre = vb.trilinear(Vec3::ZERO);
    assert!(
        centre < -0.2 && centre >= vox.trilinear(Vec3::ZERO),
        "{centre} vs {}",
        vox.trilinear(Vec3::ZERO)
    );
}

#[test]
fn band_is_much_smaller_than_dense_at_128() {
    let (dense, band) = sphere_grids(128, 2);
    let (db, bb) = (dense.bytes_used(), band.bytes_used());
    eprintln!(
        "sphere at 128: dense {db} bytes, band {bb} bytes ({:.1}%), {} of {} bricks stored",
        100.0 * bb as f64 / db as f64,
        band.stored_bricks(),
        band.brick_count()
    );
    assert!(bb * 3 < db, "band {bb} vs dense {db}");
    let a = GridObject::new(dense, 1, MarchParams::default(), "dense".into());
    let b = GridObject::new(band, 1, MarchParams::default(), "band".into());
    // 9^3 samples per stored brick (shared borders duplicated), 16 bits each.
    assert!(b.census().grid_samples * 3 < a.census().grid_samples * 2);
    assert!(b.bytes_used() * 3 < a.bytes_used());
    assert!(b.describe().contains("narrow band"), "{}", b.describe());
    // Surface distances near the surface agree.
    for p in [DVec3::new(1.02, 0.0, 0.0), DVec3::new(0.0, -0.97, 0.1)] {
        let (da, db) = (a.surface_distance(p), b.surface_distance(p));
        assert!((da - db).abs() < 1e-3, "{p}: {da} vs {db}");
    }
}

#[test]
fn band_renders_like_dense() {
    let s = object(Primitive::Sphere { radius: 1.2 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
    let b = object(
        Primitive::Box { half: Vec3::new(0.5, 0.4, 0.6) },
        Vec3::new(1.8, -0.6, 0.5),
        Vec3::new(10.0, 30.0, 0.0),
        Vec3::ONE,
    );
    let mesh = Object {
        kind: ObjectKind::Mesh {
            mesh: Arc::new(tessellate(&Primitive::Torus { major: 0.6, minor: 0.2 }, 48, None)),
            source: "torus.obj".into(),
            shading: Shading::Flat,
        },
        transform: TransformDesc { translate: Vec3::new(-1.8, 0.2, 0.0), ..TransformDesc::default() },
        material: 1,
        label: "torus".into(),
    };
    let mut ground =
        object(Primitive::Plane { normal: Vec3::Y, offset: -1.3 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
    ground.material = 0;
    let scene = lit_scene(vec![s, b, mesh, ground], 120);
    let march = MarchParams::default();
    for fill in [GridFill::Sample, GridFill::Voxelize] {
        let grid = |storage| Representation::Grid { resolution: 64, fill, storage, march };
        let dense = render_scene(&scene, grid(GridStorage::Dense));
        let band = render_scene(&scene, grid(GridStorage::Band { cells: 2 }));
        let agree = fraction_within(&dense.frame.image, &band.frame.image, 2);
        eprintln!(
            "{fill:?}: band {} bytes vs dense {} bytes, {:.2}% of pixels within 2/255",
            band.geometry_bytes,
            dense.geometry_bytes,
            agree * 100.0
        );
        crate::util::dump(&format!("band-{fill:?}"), &[&dense.frame.image, &band.frame.image]);
        assert!(agree >= 0.995, "{fill:?}: only {:.2}% agree", agree * 100.0);
        assert!(band.geometry_bytes < dense.geometry_bytes);
        assert!(band.text.contains("narrow band"), "{}", band.text);
        if fill == GridFill::Voxelize {
            assert!(band.text.contains("voxelized"), "{}", band.text);
        }
    }
}

#[test]
fn view_clipping_grids_only_the_seen_part_of_a_huge_ground() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/thesis_rt.toml");
    let mut scene = sdfmesh::scene::load_scene(&path).unwrap();
    scene.camera.width = 125;
    scene.camera.height = 125;
    let march = MarchParams::default();
    let analytic = render_scene(&scene, Representation::Analytic { march });
    let resolution = 64;
    let grid = render_scene(
        &scene,
        Representation::Grid { resolution, fill: GridFill::Sample, storage: GridStorage::Dense, march },
    );
    eprintln!("{}", grid.text);
    assert!(grid.text.contains("clipped to the view region"), "{}", grid.text);
    // The ground sphere (radius 5000) unclipped would take a grid over its whole box.
    let ground = scene.objects.iter().find(|o| o.bounds().is_some_and(|b| b.diagonal().x > 1000.0)).unwrap();
    let b = ground.bounds().unwrap();
    let (_, _, dims) =
        sdfmesh::geometry::grid::grid_layout(b.min.into(), b.max.into(), resolution, 2).unwrap();
    let unclipped = dims.x as u64 * dims.y as u64 * dims.z as u64;
    let geometry = sdfmesh::plan::build_scene(
        &scene,
        Representation::Grid { resolution, fill: GridFill::Sample, storage: GridStorage::Dense, march },
    );
    let stored = geometry.census().grid_samples;
    // The three unit spheres share one 69^3 grid (sampled in its own frame, placed thrice).
    let spheres = 69u64 * 69 * 69;
    eprintln!("ground samples: clipped {} vs unclipped {unclipped}", stored - spheres);
    assert!((stored - spheres) * 2 < unclipped, "{stored} samples");
    let agree = fraction_within(&analytic.frame.image, &grid.frame.image, 8);
    crate::util::dump("thesis-rt-clipped", &[&analytic.frame.image, &grid.frame.image]);
    eprintln!(
        "thesis_rt grid {resolution} clipped: {:.2}% of pixels within 8/255 of analytic",
        agree * 100.0
    );
    assert!(agree >= 0.97, "only {:.2}% agree", agree * 100.0);
}

#[test]
fn huge_boxes_are_clipped_to_the_view_or_left_analytic() {
    let s = object(Primitive::Sphere { radius: 1.0 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
    let mut floor = object(
        Primitive::Box { half: Vec3::new(500.0, 1.0, 500.0) },
        Vec3::new(0.0, -2.2, 0.0),
        Vec3::ZERO,
        Vec3::ONE,
    );
    floor.material = 0;
    floor.label = "floor".into();
    // Small and behind the camera: outside the view region.
    let mut behind =
        object(Primitive::Box { half: Vec3::splat(5.0) }, Vec3::new(0.0, 0.0, -40.0), Vec3::ZERO, Vec3::ONE);
    behind.label = "behind".into();
    let scene = lit_scene(vec![s, floor, behind], 100);
    let march = MarchParams::default();
    let analytic = render_scene(&scene, Representation::Analytic { march });
    let grid = render_scene(
        &scene,
        Representation::Grid {
            resolution: 64,
            fill: GridFill::Sample,
            storage: GridStorage::Band { cells: 2 },
            march,
        },
    );
    let line = |label: &str| grid.text.lines().find(|l| l.contains(label)).unwrap_or_default().to_string();
    assert!(line("'floor'").contains("clipped to the view region"), "{}", grid.text);
    assert!(line("'behind'").contains("outside the view region: no grid"), "{}", grid.text);
    assert!(!line("'sphere'").contains("clipped"), "{}", grid.text);
    let agree = fraction_within(&analytic.frame.image, &grid.frame.image, 4);
    crate::util::dump("huge-boxes-clipped", &[&analytic.frame.image, &grid.frame.image]);
    eprintln!("{}\n{:.2}% within 4/255", grid.text, agree * 100.0);
    assert!(agree >= 0.98, "only {:.2}% agree", agree * 100.0);
}
