//! The `Geometry` contract (`src/geometry/mod.rs`), checked once for every representation
//! (closed form, analytic SDF, relaxed SDF, dense grid, narrow-band grid, one narrow band
//! shared by the scene's objects, tessellated mesh)
//! on every test scene (single primitives, CSG, a union of 9 primitives, a mesh read from a
//! file, a scene of several objects with an infinite plane, and repetition and repeated
//! objects, instanced and shared in the mesh representation): each object's geometry and the scene aggregate
//! (`SceneGeometry`). `contract_tests!` writes one `#[test]` per scene x representation.
//!
//! For deterministic pseudo-random rays aimed at the objects, grazing rays, rays starting
//! inside and axis-aligned rays (zero direction components):
//! - a hit's `t` lies in `[t_min, t_max]` (exactly), and for bounded geometry its point lies
//!   in `bounds()` grown by `1e-4 * size + hit.error`;
//! - `any_hit` agrees exactly with `closest_hit().is_some()` on the same interval;
//! - `normal` and `shading_normal` are unit length within `1e-3`;
//! - `surface_distance(hit.point)` is within the representation's accuracy (`accuracy`): f32
//!   rounding for closed forms and meshes, plus the pixel footprint for marches;
//! - `hit.point` is `ray.at(hit.t)` within `1e-4 * (1 + t + size)` (f32 rounding of a
//!   point computed in an object's frame and transformed back);
//! - an interval ending before a hit or starting after it never returns that hit;
//! - `bytes_used()` is positive and the same before and after tracing;
//! - batches: `closest_hits` over 1 to 300 of these rays gives every ray exactly the hit
//!   `closest_hit` gives for that ray alone, and `any_hits` the answer of `any_hit`
//!   (marched fields march batches eight rays at a time, refilling lanes as marches end;
//!   the aggregate gathers the objects a packet reaches).
//!
//! For the aggregate, its closest hit is also the nearest of its objects' closest hits.

use std::path::Path;

use glam::{Vec3, Vec3A};
use sdfmesh::convert::tessellate::tessellate;
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::geometry::{Aabb, Geometry, Hit, Ray, RayStats};
use sdfmesh::mesh::save_mesh;
use sdfmesh::plan::{GridFill, GridStorage, MeshMethod, ObjectPlan, Representation, build_scene_with_plans};
use sdfmesh::scene::shape::{CsgOp, Object, ObjectKind, Primitive, Shading};
use sdfmesh::scene::transform::TransformDesc;
use sdfmesh::scene::{Scene, parse_scene};

use crate::util::{Lcg, lit_scene, object};

/// Camera height of the test scenes, pixels: sets the marches' pixel footprint
/// (`2 tan(20 deg) / 256 = 2.8e-3` radians).
const PIXELS: u32 = 256;

// ---------------------------------------------------------------- representations

fn analytic() -> Representation {
    Representation::Analytic { march: MarchParams::default() }
}

fn sdf() -> Representation {
    Representation::Sdf { march: MarchParams::default() }
}

fn sdf_relaxed() -> Representation {
    Representation::Sdf { march: MarchParams { relaxation: 1.6, ..MarchParams::default() } }
}

fn grid_dense() -> Representation {
    Representation::Grid {
        resolution: 48,
        fill: GridFill::Sample,
        storage: GridStorage::Dense,
        march: MarchParams::default(),
    }
}

fn grid_band() -> Representation {
    Representation::Grid {
        resolution: 48,
        fill: GridFill::Sample,
        storage: GridStorage::Band { cells: 2 },
        march: MarchParams::default(),
    }
}

fn grid_scene() -> Representation {
    Representation::Grid {
        resolution: 48,
        fill: GridFill::Sample,
        storage: GridStorage::Scene { cells: 2 },
        march: MarchParams::default(),
    }
}

fn mesh() -> Representation {
    Representation::Mesh {
        resolution: 48,
        shading: Shading::Smooth,
        method: MeshMethod::Parametric,
        plane: sdfmesh::plan::MeshPlane::ClosedForm,
        march: MarchParams::default(),
    }
}

// ---------------------------------------------------------------- scenes

fn with(kind: ObjectKind, translate: Vec3, rotate_deg: Vec3) -> Object {
    Object {
        kind,
        transform: TransformDesc { translate, rotate_deg, scale: Vec3::ONE },
        material: 1,
        label: "x".into(),
    }
}

fn sphere() -> Scene {
    let o = object(Primitive::Sphere { radius: 1.0 }, Vec3::new(0.3, -0.2, 0.1), Vec3::ZERO, Vec3::ONE);
    lit_scene(vec![o], PIXELS)
}

fn rotated_box() -> Scene {
    let b = Primitive::Box { half: Vec3::new(1.0, 0.5, 0.75) };
    lit_scene(vec![object(b, Vec3::new(0.1, 0.2, 0.0), Vec3::new(20.0, 30.0, 0.0), Vec3::ONE)], PIXELS)
}

fn torus() -> Scene {
    let t = Primitive::Torus { major: 1.0, minor: 0.3 };
    lit_scene(vec![object(t, Vec3::ZERO, Vec3::new(60.0, 0.0, 0.0), Vec3::ONE)], PIXELS)
}

/// A cylinder (non-uniformly scaled) and a cone: scaled transforms and flat caps.
fn cylinder_and_cone() -> Scene {
    let c = Primitive::Cylinder { radius: 0.5, half_height: 0.8 };
    let k = Primitive::Cone { radius_bottom: 0.6, radius_top: 0.1, half_height: 0.7 };
    lit_scene(
        vec![
            object(c, Vec3::new(-0.9, 0.0, 0.0), Vec3::new(0.0, 0.0, 30.0), Vec3::new(1.0, 1.5, 0.7)),
            object(k, Vec3::new(1.0, 0.0, 0.2), Vec3::new(10.0, 0.0, 0.0), Vec3::ONE),
        ],
        PIXELS,
    )
}

/// A box with a sphere subtracted: no closed form, so every representation marches or
/// extracts it.
fn csg() -> Scene {
    let b = object(Primitive::Box { half: Vec3::splat(0.8) }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
    let s = object(Primitive::Sphere { radius: 1.0 }, Vec3::new(0.4, 0.4, -0.4), Vec3::ZERO, Vec3::ONE);
    let kind = ObjectKind::Csg { op: CsgOp::Subtraction, children: vec![b, s] };
    lit_scene(vec![with(kind, Vec3::new(0.0, 0.1, 0.0), Vec3::new(0.0, 25.0, 0.0))], PIXELS)
}

/// A sharp union of 9 primitives, some overlapping, under a rotation: the SDF side traces
/// it as one part per child under a BVH (`sdf_geometry`), which must be the same surface.
fn big_union() -> Scene {
    let children: Vec<Object> = (0..9)
        .map(|i| {
            let (x, z) = ((i % 3) as f32 * 0.7 - 0.7, (i / 3) as f32 * 0.7 - 0.7);
            let prim = if i % 2 == 0 {
                Primitive::Sphere { radius: 0.4 }
            } else {
                Primitive::Box { half: Vec3::new(0.3, 0.25, 0.35) }
            };
            object(
                prim,
                Vec3::new(x, 0.1 * i as f32 - 0.4, z),
                Vec3::new(0.0, 10.0 * i as f32, 0.0),
                Vec3::ONE,
            )
        })
        .collect();
    let kind = ObjectKind::Csg { op: CsgOp::Union, children };
    lit_scene(vec![with(kind, Vec3::new(0.1, 0.0, 0.0), Vec3::new(15.0, 20.0, 0.0))], PIXELS)
}

/// A smooth union of 40 small spheres spread through a box, minus a box: sphere traced
/// with its tape shortened per region (`prune::TapeRegions`), which single rays and packet
/// lanes must look up alike, and which must keep the closed form's surface.
pub(crate) fn blobs() -> Scene {
    let mut seed = 11u32;
    let mut next = || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    };
    let spheres: Vec<Object> = (0..40)
        .map(|_| {
            let c = Vec3::new(next(), next() * 0.8, next());
            object(Primitive::Sphere { radius: 0.18 + 0.06 * next() }, c, Vec3::ZERO, Vec3::ONE)
        })
        .collect();
    let blend = Object {
        kind: ObjectKind::Csg { op: CsgOp::SmoothUnion { k: 0.12 }, children: spheres },
        transform: TransformDesc::default(),
        material: 1,
        label: "blend".into(),
    };
    let cut =
        object(Primitive::Box { half: Vec3::splat(0.45) }, Vec3::new(0.6, 0.5, -0.6), Vec3::ZERO, Vec3::ONE);
    let kind = ObjectKind::Csg { op: CsgOp::Subtraction, children: vec![blend, cut] };
    lit_scene(vec![with(kind, Vec3::ZERO, Vec3::new(0.0, 20.0, 0.0))], PIXELS)
}

/// A triangle mesh read from an OBJ file through the scene parser (a mesh object: traced
/// as triangles in every representation but the grid, which samples it).
fn mesh_file() -> Scene {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let mut m = tessellate(&Primitive::Torus { major: 0.9, minor: 0.4 }, 24, None);
    m.normals = None;
    save_mesh(&m, &dir.join("torus.obj")).unwrap();
    let text = format!(
        "[camera]\nposition = [0, 1.5, -6]\nlook_at = [0, 0, 0]\nwidth = {PIXELS}\nheight = {PIXELS}\n\n\
         [[objects]]\ntype = \"mesh\"\npath = \"torus.obj\"\nshading = \"smooth\"\n\
         rotate = [50, 10, 0]\ntranslate = [0.2, 0, 0]\n"
    );
    parse_scene(&text, &dir.join("scene.toml")).unwrap()
}

/// Several objects and an infinite plane (unbounded: the aggregate has no bounds), read
/// from TOML.
fn several_with_plane() -> Scene {
    let text = format!(
        r#"
[camera]
position = [0, 1.5, -6]
look_at = [0, 0, 0]
width = {PIXELS}
height = {PIXELS}

[[objects]]
type = "plane"
normal = [0, 1, 0]
offset = -1.2

[[objects]]
type = "sphere"
radius = 0.7
translate = [-1.2, -0.3, 0.5]

[[objects]]
type = "box"
half_size = [0.4, 0.6, 0.4]
rotate = [0, 35, 0]
translate = [0.9, -0.5, 0]

[[objects]]
type = "torus"
major_radius = 0.6
minor_radius = 0.2
rotate = [70, 0, 0]
translate = [0, 0.6, 1]

[[objects]]
type = "union"
translate = [0, -0.6, -1.3]
children = [
    {{ type = "sphere", radius = 0.35 }},
    {{ type = "cylinder", radius = 0.15, height = 1.2, rotate = [0, 0, 90] }},
]
"#
    );
    parse_scene(&text, Path::new("several.toml")).unwrap()
}

/// Repetition and repeated geometry: a finite repetition of spheres and one of a CSG
/// child (instanced in the mesh representation: one mesh placed per copy), and two boxes
/// of the same size (sharing one mesh there).
fn repeated() -> Scene {
    let text = format!(
        r#"
[camera]
position = [0, 1.5, -6]
look_at = [0, 0, 0]
width = {PIXELS}
height = {PIXELS}

[[objects]]
type = "repeat"
period = [0.8, 0, 0.7]
count = [3, 1, 2]
rotate = [0, 25, 0]
translate = [-0.6, -0.6, 0.2]
child = {{ type = "sphere", radius = 0.3 }}

[[objects]]
type = "repeat"
period = [0.9, 0.9, 0]
count = [2, 2, 1]
translate = [0.9, 0.5, 0.3]
child = {{ type = "subtraction", children = [{{ type = "box", half_size = [0.3, 0.3, 0.3] }}, {{ type = "sphere", radius = 0.25, translate = [0, 0, -0.3] }}] }}

[[objects]]
type = "box"
half_size = [0.25, 0.4, 0.25]
rotate = [0, 35, 0]
translate = [-1.3, 0.6, -0.5]

[[objects]]
type = "box"
half_size = [0.25, 0.4, 0.25]
rotate = [20, 0, 10]
translate = [0.2, 0.9, -0.8]
"#
    );
    parse_scene(&text, Path::new("repeated.toml")).unwrap()
}

// ---------------------------------------------------------------- the contract

/// How closely a hit point of `g` lies on its own surface (`surface_distance`), scene
/// units, for a hit at `t` in a scene of size `size`: f32 rounding (`1e-4 * (size + t)`)
/// for closed forms and triangle meshes; for anything marched (analytic SDFs, grids
/// through their trilinear field, and objects without a closed form, such as CSG, in
/// every representation) also the pixel footprint times `t`: a march stops within
/// `epsilon * t` of the surface, or, when it runs out of steps near a tangent, within
/// `2 tan(fov / 2) / height` times `t` (documented in `MarchParams::pixel_footprint`).
fn accuracy(marched: bool, t: f32, size: f32) -> f64 {
    let rounding = 1e-4 * (size + t) as f64;
    if marched { rounding + footprint() * t as f64 } else { rounding }
}

/// Whether the realised plan marches the object (analytic SDF or grid, entirely or in
/// part) rather than intersecting it in closed form or as triangles.
fn marched(plan: &ObjectPlan) -> bool {
    plan.marches()
}

fn footprint() -> f64 {
    2.0 * 20f64.to_radians().tan() / PIXELS as f64
}

/// The rays a geometry is checked with, aimed at `b` (centre and size of the region of
/// interest): `(ray, t_min, t_max)`.
fn rays(centre: Vec3, size: f32, seed: u64) -> Vec<(Ray, f32, f32)> {
    let mut rng = Lcg(seed);
    let mut out = Vec::new();
    // Aimed at random points of the region from all around, at 3 sizes.
    for _ in 0..300 {
        let target = centre + (Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.0 - 1.0) * size * 0.6;
        let origin = centre + rng.dir() * size * 3.0;
        let dir = (target - origin).normalize();
        let t_min = if rng.unit() < 0.2 { rng.unit() * size } else { 0.0 };
        let t_max = if rng.unit() < 0.2 { size * (1.0 + 4.0 * rng.unit()) } else { 1e5 };
        out.push((Ray::new(origin, dir), t_min, t_max));
    }
    // Axis-aligned and diagonal directions: zero direction components.
    let axes = [
        Vec3::X,
        Vec3::Y,
        Vec3::Z,
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(0.0, 1.0, -1.0),
        Vec3::new(1.0, 0.0, 1.0),
    ];
    for axis in axes {
        for sign in [1.0, -1.0] {
            let dir = (axis * sign).normalize();
            for _ in 0..12 {
                let off = (Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.0 - 1.0) * size * 0.5;
                let off = off - dir * off.dot(dir);
                out.push((Ray::new(centre + off - dir * size * 3.0, dir), 0.0, 1e5));
            }
        }
    }
    out
}

/// Rays derived from a hit on the surface: grazing (tangent, just above, on and just
/// below the surface) and starting inside (just behind the hit, in random directions).
fn rays_from_hit(hit: &Hit, size: f32, rng: &mut Lcg) -> Vec<(Ray, f32, f32)> {
    let n = hit.normal;
    let tangent = n.cross(rng.dir()).normalize_or(n.any_orthonormal_vector());
    let mut out = Vec::new();
    for lift in [1e-3, 1e-5, 0.0, -1e-5, -1e-3] {
        let through = hit.point + n * lift * size;
        out.push((Ray::new(through - tangent * size * 2.0, tangent), 0.0, 1e5));
    }
    for _ in 0..2 {
        let inside = hit.point - n * 0.02 * size;
        out.push((Ray::new(inside, rng.dir()), 0.0, 1e5));
    }
    out
}

/// Checks `g` (named `what`) with the rays of `rays`/`rays_from_hit`; returns the number
/// of hits.
fn check_geometry(what: &str, g: &dyn Geometry, marched: bool, centre: Vec3, size: f32, seed: u64) -> usize {
    let bytes = g.bytes_used();
    assert!(bytes > 0, "{what}: bytes_used is 0");
    assert_eq!(g.bytes_used(), bytes, "{what}: bytes_used changes between calls");
    assert!(!g.describe().is_empty(), "{what}: empty description");
    let census = g.census();
    let bounds = g.bounds();
    let mut stats = RayStats::default();
    let mut rng = Lcg(seed ^ 0x5eed);
    let mut queue = rays(centre, size, seed);
    let (mut hits, mut worst) = (0, 0.0f64);
    let mut i = 0;
    while i < queue.len() {
        let (ray, t_min, t_max) = queue[i];
        i += 1;
        let ctx = || format!("{what}: ray {:?} dir {:?} in [{t_min}, {t_max}]", ray.origin, ray.dir);
        let closest = g.closest_hit(&ray, t_min, t_max, &mut stats);
        let any = g.any_hit(&ray, t_min, t_max, &mut stats);
        assert_eq!(any, closest.is_some(), "{}: any_hit {any}, closest {closest:?}", ctx());
        let Some(hit) = closest else { continue };
        hits += 1;
        worst = worst.max(check_hit(&ctx(), g, marched, &ray, t_min, t_max, &hit, bounds.as_ref(), size));
        // An interval that ends before the hit, or starts after it, never returns it.
        let before = hit.t - (1e-3 * size).max(hit.t.abs() * 1e-3);
        if before > t_min {
            let h = g.closest_hit(&ray, t_min, before, &mut stats);
            if let Some(h) = &h {
                assert!(h.t >= t_min && h.t <= before, "{}: t_max {before}: hit at {}", ctx(), h.t);
            }
            assert_eq!(g.any_hit(&ray, t_min, before, &mut stats), h.is_some(), "{}: t_max {before}", ctx());
        }
        let after = hit.t + (1e-3 * size).max(hit.t.abs() * 1e-3);
        if after < t_max
            && let Some(h) = g.closest_hit(&ray, after, t_max, &mut stats)
        {
            assert!(h.t >= after && h.t <= t_max, "{}: t_min {after}: hit at {}", ctx(), h.t);
            worst = worst.max(check_hit(&ctx(), g, marched, &ray, after, t_max, &h, bounds.as_ref(), size));
        }
        // Grazing and inside rays from the first 60 primary hits.
        if i <= 300 && hits <= 60 {
            queue.extend(rays_from_hit(&hit, size, &mut rng));
        }
    }
    check_packets(what, g, &queue);
    eprintln!(
        "{what}: {hits} hits of {} rays, worst surface distance {worst:.3} of the tolerance, {} step-limit marches",
        queue.len(),
        stats.step_limit_hits
    );
    assert_eq!(g.bytes_used(), bytes, "{what}: bytes_used changes after tracing");
    assert_eq!(g.census(), census, "{what}: census changes after tracing");
    assert_eq!(g.bounds(), bounds, "{what}: bounds change after tracing");
    hits
}

/// Sizes of the batches [`check_packets`] hands over, in turn: a packet, a lone ray,
/// batches that end part-way through a packet, and one longer than the tracer's tile.
const BATCH_SIZES: [usize; 6] = [8, 1, 23, 64, 5, 300];

/// `closest_hits` on batches of consecutive rays (sharing `t_min`, sizes
/// [`BATCH_SIZES`]) agrees ray by ray, exactly, with `closest_hit`; a batch's rays may
/// start with hits already found (a `t_max` lowered by another geometry), which a farther
/// hit must not replace.
fn check_packets(what: &str, g: &dyn Geometry, queue: &[(Ray, f32, f32)]) {
    let mut stats = RayStats::default();
    let mut start = 0;
    let mut packets = 0;
    while start < queue.len() {
        let t_min = queue[start].1;
        let size = BATCH_SIZES[packets % BATCH_SIZES.len()];
        let mut end = start + 1;
        while end < queue.len() && end - start < size && queue[end].1 == t_min {
            end += 1;
        }
        let chunk = &queue[start..end];
        let rays: Vec<Ray> = chunk.iter().map(|c| c.0).collect();
        let mut t_max: Vec<f32> = chunk.iter().map(|c| c.2).collect();
        let expect: Vec<Option<Hit>> =
            chunk.iter().map(|c| g.closest_hit(&c.0, c.1, c.2, &mut stats)).collect();
        let mut hits = vec![None; chunk.len()];
        // Every third batch: its first ray already holds a nearer hit from elsewhere.
        let sentinel = (packets % 3 == 2).then(|| expect[0].map(|h| Hit { t: h.t * 0.5, ..h })).flatten();
        if let Some(h) = sentinel {
            t_max[0] = h.t;
            hits[0] = Some(h);
        }
        g.closest_hits(&rays, t_min, &mut t_max, &mut hits, &mut stats);
        for (i, (got, want)) in hits.iter().zip(&expect).enumerate() {
            let want = if i == 0 && sentinel.is_some() { &sentinel } else { want };
            assert_eq!(
                got,
                want,
                "{what}: batch ray {i} of {} at {:?} dir {:?}",
                rays.len(),
                rays[i].origin,
                rays[i].dir
            );
            if let Some(h) = got {
                assert_eq!(t_max[i], h.t, "{what}: batch ray {i}: t_max not lowered to the hit");
            }
        }
        // The same batch as shadow rays: any_hits equals any_hit ray by ray, and a ray
        // already occluded (every fourth) stays so and is not traced.
        let reach: Vec<f32> = chunk.iter().map(|c| c.2).collect();
        let want: Vec<bool> = chunk.iter().map(|c| g.any_hit(&c.0, c.1, c.2, &mut stats)).collect();
        let mut occluded: Vec<bool> = (0..chunk.len()).map(|i| (i + packets) % 4 == 3).collect();
        let before = occluded.clone();
        g.any_hits(&rays, t_min, &reach, &mut occluded, &mut stats);
        for i in 0..chunk.len() {
            assert_eq!(occluded[i], want[i] || before[i], "{what}: shadow batch ray {i} of {:?}", rays[i]);
        }
        packets += 1;
        start = end;
    }
}

#[allow(clippy::too_many_arguments)]
#[track_caller]
fn check_hit(
    ctx: &str,
    g: &dyn Geometry,
    marched: bool,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    hit: &Hit,
    bounds: Option<&Aabb>,
    size: f32,
) -> f64 {
    assert!(hit.t >= t_min && hit.t <= t_max, "{ctx}: t = {} outside the interval", hit.t);
    assert!(hit.point.is_finite() && hit.error.is_finite() && hit.error >= 0.0, "{ctx}: {hit:?}");
    if let Some(b) = bounds {
        let slack = Vec3A::splat(1e-4 * size + hit.error);
        let p = Vec3A::from(hit.point);
        assert!(
            p.cmpge(b.min - slack).all() && p.cmple(b.max + slack).all(),
            "{ctx}: hit {} outside bounds {b:?}",
            hit.point
        );
    }
    assert!((hit.normal.length() - 1.0).abs() < 1e-3, "{ctx}: normal {}", hit.normal);
    assert!((hit.shading_normal.length() - 1.0).abs() < 1e-3, "{ctx}: shading normal {}", hit.shading_normal);
    let along = (hit.point - ray.at(hit.t)).length();
    assert!(
        along <= 1e-4 * (1.0 + hit.t.abs() + size),
        "{ctx}: point {} is {along} from ray.at(t)",
        hit.point
    );
    let d = g.surface_distance(hit.point.as_dvec3());
    let tol = accuracy(marched, hit.t, size);
    assert!(d <= tol, "{ctx}: hit at t {} is {d} from the surface (tolerance {tol})", hit.t);
    d / tol
}

/// Checks every object of `scene` built in `repr`, then the scene aggregate.
fn check(scene: Scene, repr: Representation) {
    let (aggregate, plans) = build_scene_with_plans(&scene, repr);
    let objects = aggregate.objects();
    let any_marched = plans.iter().any(marched);
    assert_eq!(objects.len(), scene.objects.len());
    // The region the rays aim at: the union of the bounded objects' boxes.
    let mut region = Aabb::empty();
    for g in objects {
        if let Some(b) = g.bounds() {
            // Mesh discs standing in for planes reach out to max_distance: leave them out.
            if (b.max - b.min).max_element() < 100.0 {
                region = region.union(&b);
            }
        }
    }
    assert!(region.valid(), "no bounded object");
    let centre = Vec3::from(region.center());
    let size = (region.max - region.min).max_element();
    let mut total = 0;
    for (k, g) in objects.iter().enumerate() {
        let what = format!("{} '{}' ({})", repr.name(), scene.objects[k].label, g.describe());
        let hits = check_geometry(&what, g.as_ref(), marched(&plans[k]), centre, size, 17 + k as u64);
        total += hits;
    }
    assert!(total > 100, "{}: only {total} hits on the objects", repr.name());
    let hits = check_geometry(&format!("{} scene", repr.name()), &aggregate, any_marched, centre, size, 99);
    assert!(hits > 100, "{}: only {hits} hits on the scene", repr.name());
    // The aggregate's closest hit is the nearest of its objects' closest hits.
    let mut stats = RayStats::default();
    for (ray, t_min, t_max) in rays(centre, size, 5) {
        let all = aggregate.closest_hit(&ray, t_min, t_max, &mut stats).map(|h| h.t);
        let nearest = objects
            .iter()
            .filter_map(|g| g.closest_hit(&ray, t_min, t_max, &mut stats).map(|h| h.t))
            .min_by(f32::total_cmp);
        let agree = match (all, nearest) {
            (Some(a), Some(b)) => (a - b).abs() <= 1e-3 * size + accuracy(any_marched, b, size) as f32,
            (None, None) => true,
            _ => false,
        };
        assert!(agree, "{}: ray {ray:?}: scene {all:?}, nearest object {nearest:?}", repr.name());
    }
}

/// One `#[test]` per scene and representation: `scene::representation`.
macro_rules! contract_tests {
    ($($scene:ident),* $(,)?) => {$(
        mod $scene {
            #[test]
            fn analytic() {
                super::check(super::$scene(), super::analytic());
            }
            #[test]
            fn sdf() {
                super::check(super::$scene(), super::sdf());
            }
            #[test]
            fn sdf_relaxed() {
                super::check(super::$scene(), super::sdf_relaxed());
            }
            #[test]
            fn grid_dense() {
                super::check(super::$scene(), super::grid_dense());
            }
            #[test]
            fn grid_band() {
                super::check(super::$scene(), super::grid_band());
            }
            #[test]
            fn grid_scene() {
                super::check(super::$scene(), super::grid_scene());
            }
            #[test]
            fn mesh() {
                super::check(super::$scene(), super::mesh());
            }
        }
    )*};
}

contract_tests!(
    sphere,
    rotated_box,
    torus,
    cylinder_and_cone,
    csg,
    big_union,
    blobs,
    mesh_file,
    several_with_plane,
    repeated
);

/// The mesh representation's plane as a tessellated disc (`--plane disc`; the default
/// intersects it in closed form, as every representation does), checked as before.
#[test]
fn several_with_plane_mesh_disc() {
    let Representation::Mesh { resolution, shading, method, march, .. } = mesh() else {
        unreachable!("a mesh representation")
    };
    let plane = sdfmesh::plan::MeshPlane::Disc;
    check(several_with_plane(), Representation::Mesh { resolution, shading, method, plane, march });
}
