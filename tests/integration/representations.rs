//! One shared suite run against every representation: for each primitive, the closed-form
//! and the sphere-traced renders agree pixel for pixel (silhouettes, shading, shadows).

use glam::Vec3;
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::plan::Representation;
use sdfmesh::render::report::render_scene;
use sdfmesh::scene::shape::Primitive;

use crate::util::{covered, fraction_within, lit_scene, object};

fn primitives() -> Vec<(Primitive, Vec3, Vec3)> {
    let r = Vec3::new(20.0, 35.0, 10.0);
    vec![
        (Primitive::Sphere { radius: 1.2 }, Vec3::ZERO, Vec3::ONE),
        (Primitive::Box { half: Vec3::new(1.0, 0.7, 0.8) }, r, Vec3::ONE),
        (Primitive::Ellipsoid { radii: Vec3::new(1.5, 0.8, 1.0) }, r, Vec3::ONE),
        (Primitive::Cylinder { radius: 0.8, half_height: 1.0 }, r, Vec3::ONE),
        (
            Primitive::Cone { radius_bottom: 1.0, radius_top: 0.0, half_height: 1.0 },
            Vec3::new(-20.0, 0.0, 0.0),
            Vec3::ONE,
        ),
        (Primitive::Cone { radius_bottom: 1.0, radius_top: 0.4, half_height: 0.8 }, r, Vec3::ONE),
        (Primitive::Torus { major: 1.2, minor: 0.35 }, Vec3::new(-60.0, 0.0, 15.0), Vec3::ONE),
        (
            Primitive::Triangle {
                a: Vec3::new(-1.5, -1.0, 0.0),
                b: Vec3::new(1.5, -1.0, 0.5),
                c: Vec3::new(0.0, 1.5, 0.0),
            },
            Vec3::ZERO,
            Vec3::ONE,
        ),
        (
            Primitive::Capsule { a: Vec3::new(-1.0, -0.5, 0.0), b: Vec3::new(1.0, 0.5, 0.3), radius: 0.5 },
            Vec3::ZERO,
            Vec3::ONE,
        ),
        // Non-uniform scale: the SDF is only a bound there.
        (Primitive::Sphere { radius: 1.0 }, r, Vec3::new(1.5, 0.7, 1.0)),
    ]
}

#[test]
fn closed_form_and_sphere_traced_renders_agree_for_every_primitive() {
    let march = MarchParams::default();
    for (prim, rot, scale) in primitives() {
        // A ground plane under the object catches its shadow.
        let ground =
            object(Primitive::Plane { normal: Vec3::Y, offset: -1.6 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
        let mut ground = ground;
        ground.material = 0;
        let scene = lit_scene(vec![object(prim, Vec3::ZERO, rot, scale), ground], 200);
        let a = render_scene(&scene, Representation::Analytic { march });
        let s = render_scene(&scene, Representation::Sdf { march });
        let agree = fraction_within(&a.frame.image, &s.frame.image, 2);
        crate::util::dump(&format!("{}-{}", prim.kind_name(), rot.x), &[&a.frame.image, &s.frame.image]);
        assert!(agree >= 0.995, "{}: only {:.3}% of pixels agree", prim.kind_name(), agree * 100.0);
        // Finely tessellated, the polygon representation agrees too (a little less: facets).
        let mesh = Representation::Mesh {
            resolution: 512,
            shading: sdfmesh::scene::shape::Shading::Smooth,
            method: sdfmesh::plan::MeshMethod::Parametric,
            plane: sdfmesh::plan::MeshPlane::ClosedForm,
            march,
        };
        let m = render_scene(&scene, mesh);
        let agree = fraction_within(&a.frame.image, &m.frame.image, 2);
        crate::util::dump(&format!("{}-{}-mesh", prim.kind_name(), rot.x), &[&a.frame.image, &m.frame.image]);
        eprintln!("{}: mesh at 512 agrees on {:.3}% of pixels", prim.kind_name(), agree * 100.0);
        assert!(agree >= 0.99, "{} as a mesh: only {:.3}% of pixels agree", prim.kind_name(), agree * 100.0);
        // Sampled into a grid and ray marched: silhouettes and shading follow the trilinear
        // field, so agreement is lower; the object must still be there and mostly alike.
        if !matches!(prim, Primitive::Triangle { .. }) {
            let g = render_scene(
                &scene,
                Representation::Grid {
                    resolution: 128,
                    fill: sdfmesh::plan::GridFill::Sample,
                    storage: sdfmesh::plan::GridStorage::Dense,
                    march,
                },
            );
            let agree = fraction_within(&a.frame.image, &g.frame.image, 8);
            crate::util::dump(
                &format!("{}-{}-grid", prim.kind_name(), rot.x),
                &[&a.frame.image, &g.frame.image],
            );
            eprintln!(
                "{}: grid at 128 agrees within 8/255 on {:.3}% of pixels",
                prim.kind_name(),
                agree * 100.0
            );
            assert!(
                agree >= 0.97,
                "{} as a grid: only {:.3}% of pixels agree",
                prim.kind_name(),
                agree * 100.0
            );
        }
        // The object is really there (not an empty image agreeing with an empty image).
        let bg = [26u8, 26, 38];
        assert!(covered(&a.frame.image, bg) > 2000, "{}: nothing rendered", prim.kind_name());
        assert!(s.frame.stats.march_steps > 0);
    }
}

#[test]
fn over_relaxation_reduces_steps_and_keeps_the_image() {
    let objects = primitives()
        .into_iter()
        .take(4)
        .enumerate()
        .map(|(i, (p, r, s))| object(p, Vec3::new(i as f32 * 2.5 - 3.75, 0.0, 2.0), r, s));
    let scene = lit_scene(objects.collect(), 160);
    let plain = render_scene(&scene, Representation::Sdf { march: MarchParams::default() });
    let relaxed = render_scene(
        &scene,
        Representation::Sdf { march: MarchParams { relaxation: 1.6, ..MarchParams::default() } },
    );
    assert!(relaxed.frame.stats.march_steps < plain.frame.stats.march_steps);
    assert!(fraction_within(&plain.frame.image, &relaxed.frame.image, 2) >= 0.995);
}

/// The renderer hands the tracer a tile's primary rays as one batch, which marched
/// geometry marches eight lanes at a time, refilling lanes as marches end: every pixel is
/// still exactly what the tracer gives for its ray alone (hits, shadows, reflections).
#[test]
fn batched_tiles_render_every_pixel_as_its_ray_alone() {
    use sdfmesh::plan::build_scene;
    use sdfmesh::render::tracer::Tracer;
    use sdfmesh::render::{render, to_rgb8};
    use sdfmesh::scene::camera::RayGenerator;
    let objects =
        primitives().into_iter().take(5).enumerate().map(|(i, (p, r, s))| {
            object(p, Vec3::new(i as f32 * 1.8 - 3.6, (i % 2) as f32 * 0.6, 1.0), r, s)
        });
    let mut scene = lit_scene(objects.collect(), 72);
    scene.materials[1].reflectivity = 0.4;
    for o in scene.objects.iter_mut().skip(1).step_by(2) {
        o.material = 1;
    }
    // One marched object (the union) and several (each under the top-level BVH).
    let union = sdfmesh::scene::shape::Object {
        kind: sdfmesh::scene::shape::ObjectKind::Csg {
            op: sdfmesh::scene::shape::CsgOp::Union,
            children: scene.objects.clone(),
        },
        transform: Default::default(),
        material: 0,
        label: "all".into(),
    };
    let mut single = scene.clone();
    single.objects = vec![union];
    for scene in [scene, single] {
        let geometry = build_scene(&scene, Representation::Sdf { march: MarchParams::default() });
        let frame = render(&scene, &geometry);
        let tracer = Tracer::new(&scene, &geometry);
        let rays = RayGenerator::new(&scene.camera);
        let mut stats = Default::default();
        let mut hits = 0;
        for y in 0..scene.camera.height {
            for x in 0..scene.camera.width {
                let alone = to_rgb8(tracer.trace(&rays.ray(x, y), &mut stats));
                assert_eq!(frame.image.get_pixel(x, y).0, alone, "pixel {x} {y}");
                hits += usize::from(alone != to_rgb8(scene.settings.background));
            }
        }
        assert!(hits > 500, "{hits} pixels hit");
    }
}

#[test]
fn rendering_is_deterministic() {
    let (p, r, s) = primitives()[6];
    let scene = lit_scene(vec![object(p, Vec3::ZERO, r, s)], 96);
    for repr in [
        Representation::Analytic { march: MarchParams::default() },
        Representation::Sdf { march: MarchParams::default() },
    ] {
        let a = render_scene(&scene, repr);
        let b = render_scene(&scene, repr);
        assert_eq!(a.frame.image.as_raw(), b.frame.image.as_raw());
        assert_eq!(a.frame.stats, b.frame.stats);
    }
}

#[test]
fn finely_tessellated_sphere_renders_like_the_closed_form_sphere() {
    let sphere = object(Primitive::Sphere { radius: 1.2 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
    let mut ground =
        object(Primitive::Plane { normal: Vec3::Y, offset: -1.6 }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
    ground.material = 0;
    let scene = lit_scene(vec![sphere, ground], 200);
    let march = MarchParams::default();
    let reference = render_scene(&scene, Representation::Analytic { march });
    let mut previous = 0.0;
    for resolution in [32, 128, 512] {
        let mesh = Representation::Mesh {
            resolution,
            shading: sdfmesh::scene::shape::Shading::Smooth,
            method: sdfmesh::plan::MeshMethod::Parametric,
            plane: sdfmesh::plan::MeshPlane::ClosedForm,
            march,
        };
        let m = render_scene(&scene, mesh);
        let agree = fraction_within(&reference.frame.image, &m.frame.image, 2);
        crate::util::dump(
            &format!("tessellated-sphere-{resolution}"),
            &[&reference.frame.image, &m.frame.image],
        );
        eprintln!("tessellated sphere at {resolution}: {:.3}% of pixels within 2/255", agree * 100.0);
        assert!(agree >= previous - 0.002, "agreement fell from {previous} to {agree} at {resolution}");
        previous = agree;
    }
    assert!(previous >= 0.99, "only {:.2}% of pixels agree at resolution 512", previous * 100.0);
}

#[test]
fn top_level_bvh_keeps_per_ray_work_logarithmic_in_the_object_count() {
    // n x n spheres on a grid in the xz plane, seen from above: work per ray (BVH nodes
    // plus intersection tests) must grow far slower than n^2.
    let work = |n: i32| {
        let objects = (0..n * n)
            .map(|i| {
                let at = Vec3::new((i % n - n / 2) as f32 * 2.0, 0.0, (i / n - n / 2) as f32 * 2.0);
                object(Primitive::Sphere { radius: 0.8 }, at, Vec3::ZERO, Vec3::ONE)
            })
            .collect();
        let mut scene = lit_scene(objects, 64);
        scene.camera.position = Vec3::new(0.0, 3.0 * n as f32, -0.5);
        scene.camera.forward = -Vec3::Y;
        scene.camera.up = Vec3::Z;
        let r = render_scene(&scene, Representation::Analytic { march: MarchParams::default() });
        let s = r.frame.stats;
        (s.bvh_nodes + s.prim_tests) as f64 / s.rays as f64
    };
    let (small, large) = (work(4), work(32));
    eprintln!("work per ray: {small:.2} with 16 spheres, {large:.2} with 1024");
    // 64x the objects; a linear scan would cost ~64x per ray.
    assert!(large < 4.0 * small, "work per ray {small:.1} with 16 objects, {large:.1} with 1024");
}
