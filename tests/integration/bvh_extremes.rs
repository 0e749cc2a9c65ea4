//! BVH construction at extreme extents (issue #32, classes 1 to 3): meshes from 1e-30 to
//! 1e30 across build without panicking and walk exactly as brute force does; a tiny mesh
//! builds as fast and as shallow as the same mesh at unit scale; and the scenes that
//! crashed `render --repr mesh` (a plane with `max_distance = 1e20`, planes under scales
//! of 1e30 and 1e-30, CSG of spheres of radius 1e-30) render.

use std::time::{Duration, Instant};

use glam::{DVec3, Vec3, Vec3A};
use proptest::prelude::*;
use sdfmesh::geometry::mesh::triangle::{ShearedRay, closest_point_on_triangle};
use sdfmesh::geometry::mesh::{MeshGeometry, Shading};
use sdfmesh::geometry::{Geometry, Ray, RayStats};
use sdfmesh::mesh::{TriangleMesh, is_degenerate};
use sdfmesh::scene::transform::Transform;

use crate::util::{Lcg, covered, put, temp_dir, toolkit};

fn geometry(mesh: TriangleMesh) -> MeshGeometry {
    MeshGeometry::new(mesh, Shading::Flat, Transform::IDENTITY, 0, "test".into())
}

/// `count` random triangles of about `scale` across in a cluster `4 * scale` across,
/// centred at `offset`; degenerate ones (a far offset rounds small ones away) dropped.
fn random_mesh(rng: &mut Lcg, count: usize, scale: f32, offset: Vec3) -> TriangleMesh {
    let mut m = TriangleMesh::default();
    for _ in 0..count {
        let c = offset + (Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 4.0 - 2.0) * scale;
        let mut v = || c + (Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5) * scale;
        let (a, b, d) = (v(), v(), v());
        if a.is_finite() && b.is_finite() && d.is_finite() && !is_degenerate(a, b, d) {
            let i = m.positions.len() as u32;
            m.positions.extend([a, b, d]);
            m.triangles.push([i, i + 1, i + 2]);
        }
    }
    m
}

/// The BVH depth from [`Geometry::describe`] ("... (depth N) ...").
fn depth(g: &MeshGeometry) -> usize {
    let d = g.describe();
    let at = d.find("(depth ").expect("depth in the description") + 7;
    d[at..].split(')').next().unwrap().parse().unwrap()
}

/// `mesh` with every position times `s` (a power of two: exact).
fn scaled(mesh: &TriangleMesh, s: f32) -> TriangleMesh {
    TriangleMesh { positions: mesh.positions.iter().map(|&p| p * s).collect(), ..mesh.clone() }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    /// Over random triangles at random offsets (up to a million times their size), and
    /// the same triangles scaled by 2^-100 to 2^100 (about 1e-30 to 1e30), the BVH builds
    /// without panicking, and closest hit, any hit and nearest distance equal
    /// brute-force loops over every triangle. The reference at an extreme scale is the
    /// brute force at unit scale times the scale: scaling by a power of two is exact, and
    /// so is every step of the triangle test and the closest point under it where no
    /// number overflows or underflows (at extreme scales the f32 test itself would, which
    /// is why such meshes are traced in a frame of ordinary size).
    #[test]
    fn walks_equal_brute_force_at_any_scale(
        exponent in -100i32..=100,
        offset_exponent in -3i32..=6,
        count in 1usize..400,
        seed in any::<u64>(),
    ) {
        let mut rng = Lcg(seed);
        let offset = (Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.0 - 1.0) * 10f32.powi(offset_exponent);
        let mesh = random_mesh(&mut rng, count, 1.0, offset);
        let s = 2f32.powi(exponent);
        let tris: Vec<[Vec3; 3]> =
            mesh.triangles.iter().map(|t| t.map(|i| mesh.positions[i as usize])).collect();
        let (unit, far) = (geometry(mesh.clone()), geometry(scaled(&mesh, s)));
        for g in [&unit, &far] {
            prop_assert!(tris.is_empty() || depth(g) <= 12, "depth {} for {} triangles", depth(g), tris.len());
        }
        for _ in 0..24 {
            let origin = offset + Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 8.0 - 4.0;
            let target = offset + Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 4.0 - 2.0;
            let dir = (target - origin).normalize_or_zero();
            if dir == Vec3::ZERO {
                continue;
            }
            let t_max = 16.0;
            let sheared = ShearedRay::new(origin, dir);
            let brute = tris
                .iter()
                .filter_map(|[a, b, c]| sheared.intersect(*a, *b, *c, 0.0, t_max).map(|h| h.t))
                .min_by(f32::total_cmp);
            let p = origin.as_dvec3();
            let brute_near = tris
                .iter()
                .map(|&[a, b, c]| {
                    let x = closest_point_on_triangle(Vec3A::from(origin), a.into(), b.into(), c.into());
                    (Vec3::from(x).as_dvec3() - p).length()
                })
                .fold(f64::INFINITY, f64::min);
            let mut stats = RayStats::default();
            for (g, s) in [(&unit, 1.0), (&far, s)] {
                let ray = Ray::new(origin * s, dir);
                let hit = g.closest_hit(&ray, 0.0, t_max * s, &mut stats).map(|h| h.t);
                prop_assert_eq!(hit, brute.map(|t| t * s), "closest hit at scale {}", s);
                prop_assert_eq!(g.any_hit(&ray, 0.0, t_max * s, &mut stats), brute.is_some());
                prop_assert_eq!(g.surface_distance(p * s as f64), brute_near * s as f64);
            }
        }
    }
}

/// A torus of `160 x 80` quads (25,600 triangles) with radii `scale` and `0.4 * scale`.
fn torus(scale: f64) -> TriangleMesh {
    let (n, m) = (160u32, 80u32);
    let mut positions = Vec::new();
    for i in 0..n {
        let a = i as f64 * std::f64::consts::TAU / n as f64;
        for j in 0..m {
            let b = j as f64 * std::f64::consts::TAU / m as f64;
            let r = 1.0 + 0.4 * b.cos();
            positions.push((DVec3::new(r * a.cos(), 0.4 * b.sin(), r * a.sin()) * scale).as_vec3());
        }
    }
    let at = |i: u32, j: u32| (i % n) * m + (j % m);
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in 0..m {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    TriangleMesh { positions, triangles, normals: None }
}

/// The fastest of three builds of `mesh`, and the BVH depth.
fn build_time(mesh: &TriangleMesh) -> (Duration, usize) {
    let mut best = Duration::MAX;
    let mut d = 0;
    for _ in 0..3 {
        let start = Instant::now();
        let g = geometry(mesh.clone());
        best = best.min(start.elapsed());
        d = depth(&g);
    }
    (best, d)
}

/// Class 3: a 25,600-triangle mesh 1e-30 across (whose f32 box areas underflow to zero,
/// which made the builder chain every node: 20 s and a BVH as deep as the triangle
/// count) builds about as fast as, and no deeper than, the same mesh at unit scale; so
/// do the same mesh 1e19 and 1e30 across (whose areas overflow).
#[test]
fn tiny_and_huge_meshes_build_like_unit_ones() {
    let (unit, unit_depth) = build_time(&torus(1.0));
    for scale in [1e-30, 1e-19, 1e19, 1e30] {
        let mesh = torus(scale);
        assert_eq!(mesh.triangles.len(), 25_600);
        let (t, d) = build_time(&mesh);
        eprintln!(
            "torus at {scale:e}: {:.1} ms, depth {d} (unit: {:.1} ms, depth {unit_depth})",
            t.as_secs_f64() * 1e3,
            unit.as_secs_f64() * 1e3
        );
        assert!(d <= unit_depth + 1, "scale {scale:e}: depth {d} against {unit_depth} at unit scale");
        assert!(
            t <= unit * 3 + Duration::from_millis(100),
            "scale {scale:e}: built in {t:?} against {unit:?} at unit scale"
        );
    }
}

/// Renders `scene` with `--repr mesh` (and `extra` arguments) to a 16 x 16 PNG, expecting
/// success within `limit`; returns the image.
fn render_mesh(name: &str, scene: &str, extra: &[&str], limit: Duration) -> image::RgbImage {
    let dir = temp_dir(name);
    let path = put(&dir, "scene.toml", scene);
    let out = dir.join("out.png");
    let start = Instant::now();
    let mut args = vec!["render", path.to_str().unwrap(), "--repr", "mesh", "-o", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    if !extra.iter().any(|a| a.starts_with("--res")) {
        args.push("--res=16");
    }
    let o = toolkit(&args);
    let elapsed = start.elapsed();
    assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
    assert!(elapsed < limit, "{name}: took {elapsed:?}");
    image::open(&out).unwrap().to_rgb8()
}

const CAMERA: &str = "[camera]\nposition = [0, 1, -5]\nlook_at = [0, 0, 0]\nwidth = 16\nheight = 16\n\
    [settings]\nbackground = [0, 0, 1]\n%SETTINGS%\n[[lights]]\ntype = \"ambient\"\nintensity = 1\n";

fn scene(settings: &str, objects: &str) -> String {
    CAMERA.replace("%SETTINGS%", settings) + objects
}

/// Class 1 (`--plane disc`): a plane with `max_distance = 1e20` is a disc 2e20 across, whose f32 box
/// areas overflowed and left the wide BVH's grouping without slots (a panic in `cover`).
#[test]
fn plane_disc_1e20_renders() {
    let s = scene("max_distance = 1e20", "[[objects]]\ntype = \"plane\"\nnormal = [0, 1, 0]\n");
    let img = render_mesh("plane-far", &s, &["--plane=disc"], Duration::from_secs(60));
    // The camera looks down at the plane: most pixels show it rather than the background.
    assert!(covered(&img, [0, 0, 255]) > 16 * 16 / 2, "{} pixels", covered(&img, [0, 0, 255]));
}

/// Class 2 (`--plane disc`): a plane under a scale of 1e30 or 1e-30 on one axis got a NaN world normal
/// (its f32 length underflowed or overflowed), hence NaN triangles, on which obvhs's
/// builder indexed out of its node array. Its normal is now found in f64.
#[test]
fn planes_under_extreme_scales_render() {
    for (name, normal, scale) in
        [("plane-y", "[0, 1, 0]", "[1, 1e30, 1]"), ("plane-x", "[0, 1, 0]", "[1e-30, 1, 1]")]
    {
        let o = format!("[[objects]]\ntype = \"plane\"\nnormal = {normal}\nscale = {scale}\n");
        let img = render_mesh(name, &scene("", &o), &["--plane=disc"], Duration::from_secs(60));
        assert!(covered(&img, [0, 0, 255]) > 16 * 16 / 2, "{name}: {} pixels", covered(&img, [0, 0, 255]));
    }
    // An oblique normal under 1e-30 on one axis: the plane turns to face x; no panic.
    let o = "[[objects]]\ntype = \"plane\"\nnormal = [1, 1, 1]\nscale = [1e-30, 1, 1]\n";
    render_mesh("plane-oblique", &scene("", o), &["--plane=disc"], Duration::from_secs(60));
}

/// Class 3 through the command line: CSG of spheres 1e-30 across, extracted at 64 cells
/// (it overflowed the stack after 49 s: a BVH chain walked by recursion).
#[test]
fn tiny_csg_renders_in_time() {
    let objects = "[[objects]]\ntype = \"union\"\n\
        [[objects.children]]\ntype = \"sphere\"\nradius = 1e-30\n\
        [[objects.children]]\ntype = \"sphere\"\nradius = 1e-30\ntranslate = [1e-30, 0, 0]\n";
    let s = scene("", objects).replace("position = [0, 1, -5]", "position = [0, 1e-30, -5e-30]");
    render_mesh("tiny-csg", &s, &["--res=64"], Duration::from_secs(60));
}

/// A mesh sphere renders the same image 1e-30 and 1e19 across as 1 across (camera and
/// light scaled alike): the BVH, the triangle test (in the shape's unit frame) and the
/// normals (through the placement, not the unit scale's f32 inverse, which is NaN there)
/// are exact under the scale. Before, the tiny sphere's BVH was a chain and both showed
/// nothing.
#[test]
fn sphere_images_equal_across_scales() {
    let image = |r: &str| {
        let s = format!(
            "[camera]\nposition = [0, 0, -3{e}]\nlook_at = [0, 0, 0]\nwidth = 24\nheight = 24\n\
             [settings]\nmax_distance = 1e38\n\
             [[lights]]\ntype = \"ambient\"\nintensity = 0.3\n\
             [[lights]]\ntype = \"directional\"\ndirection = [1, -1, 1]\nintensity = 0.7\n\
             [[objects]]\ntype = \"sphere\"\nradius = 1{e}\n",
            e = r
        );
        render_mesh(&format!("sphere{r}"), &s, &["--res=48"], Duration::from_secs(60))
    };
    let unit = image("");
    assert!(covered(&unit, [0, 0, 0]) > 24 * 24 / 4);
    for e in ["e-30", "e19"] {
        assert!(image(e) == unit, "sphere 1{e} across renders differently");
    }
}
