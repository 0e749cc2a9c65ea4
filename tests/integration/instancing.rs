//! Instancing in the mesh representation (`plan::Build::Instanced`, `Build::SharedMesh`):
//! a finite repetition is one mesh placed per copy and hits what the SDF hits, its bytes
//! growing by a placement per copy only; objects of the same geometry share one mesh (and
//! the scene counts it once); an infinite repetition hits what the SDF hits out to
//! `max_distance`.

use std::path::Path;

use sdfmesh::convert::extract::ExtractMethod;
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::geometry::scene::SceneGeometry;
use sdfmesh::geometry::{Geometry, RayStats};
use sdfmesh::plan::budget::{BYTES_PER_INSTANCE, scene_bytes};
use sdfmesh::plan::{
    Build, GridFill, GridStorage, InstanceMesh, MeshMethod, Representation, build_scene,
    build_scene_with_plans,
};
use sdfmesh::scene::camera::RayGenerator;
use sdfmesh::scene::shape::Shading;
use sdfmesh::scene::{Scene, parse_scene};

fn mesh(method: MeshMethod) -> Representation {
    Representation::Mesh {
        resolution: 32,
        shading: Shading::Smooth,
        method,
        plane: sdfmesh::plan::MeshPlane::ClosedForm,
        march: MarchParams::default(),
    }
}

fn sdf() -> Representation {
    Representation::Sdf { march: MarchParams::default() }
}

/// `objects` (TOML) seen by a 96 x 72 camera above and in front, looking down at the origin.
fn scene(objects: &str, max_distance: f32) -> Scene {
    let text = format!(
        "[camera]\nposition = [0, 4, -9]\nlook_at = [0, 0, 0]\nwidth = 96\nheight = 72\n\n\
         [settings]\nmax_distance = {max_distance}\n\n{objects}"
    );
    parse_scene(&text, Path::new("instancing.toml")).unwrap_or_else(|e| panic!("{e}"))
}

fn repeat(period: &str, count: Option<&str>, child: &str) -> String {
    let count = count.map_or(String::new(), |c| format!("count = {c}\n"));
    format!(
        "[[objects]]\ntype = \"repeat\"\nperiod = {period}\n{count}rotate = [0, 20, 0]\n[objects.child]\n{child}\n"
    )
}

const SPHERE: &str = "type = \"sphere\"\nradius = 0.3\ntranslate = [0.1, 0, 0]";

/// Primary-ray hits of `a` and `b` over every pixel of `scene`'s camera: the fraction of
/// rays on which they agree (both miss, or both hit within `tol` of each other), counting
/// only rays whose hit in `b` is nearer than `within`, and the number of such hits.
fn agreement(scene: &Scene, a: &SceneGeometry, b: &SceneGeometry, tol: f32, within: f32) -> (f64, usize) {
    let rays = RayGenerator::new(&scene.camera);
    let mut stats = RayStats::default();
    let (mut agree, mut total, mut hits) = (0usize, 0usize, 0usize);
    for y in 0..scene.camera.height {
        for x in 0..scene.camera.width {
            let ray = rays.ray(x, y);
            let hb = b.closest_hit(&ray, 0.0, within, &mut stats).map(|h| h.t);
            let ha = a.closest_hit(&ray, 0.0, within, &mut stats).map(|h| h.t);
            total += 1;
            hits += hb.is_some() as usize;
            agree += match (ha, hb) {
                (Some(s), Some(t)) => ((s - t).abs() <= tol) as usize,
                (None, None) => 1,
                _ => 0,
            };
        }
    }
    (agree as f64 / total as f64, hits)
}

#[test]
fn a_finite_repetition_is_one_mesh_placed_per_copy_and_hits_what_the_sdf_hits() {
    let csg = "type = \"subtraction\"\nchildren = [{ type = \"box\", half_size = [0.35, 0.3, 0.35] }, \
               { type = \"sphere\", radius = 0.3, translate = [0, 0.35, 0] }]";
    for (child, shape) in [(SPHERE, "tessellated"), (csg, "extracted")] {
        let s = scene(&repeat("[1, 0, 1]", Some("[10, 1, 10]"), child), 100.0);
        let (g, plans) = build_scene_with_plans(&s, mesh(MeshMethod::Parametric));
        let Build::Instanced { mesh: how, copies: 100, reach: None } = plans[0].build else {
            panic!("{shape}: not instanced: {:?}", plans[0])
        };
        assert_eq!(matches!(how, InstanceMesh::Tessellated { .. }), shape == "tessellated");
        assert_eq!(g.objects()[0].instances().len(), 100);
        let d = g.objects()[0].describe();
        assert!(d.contains("10x1x10 copies") && d.contains(shape), "{d}");
        let reference = build_scene(&s, sdf());
        let (agree, hits) = agreement(&s, &g, &reference, 0.02, 1e5);
        eprintln!("{shape}: {hits} hits, {agree} agree");
        assert!(hits > 1000, "{shape}: {hits} hits");
        assert!(agree > 0.96, "{shape}: {agree} of the rays agree with the SDF");
    }
}

/// The grid representation instances repetition too: the child's grid once, placed per copy.
#[test]
fn a_repetition_is_one_grid_placed_per_copy_and_hits_what_the_sdf_hits() {
    let grid = Representation::Grid {
        resolution: 24,
        fill: GridFill::Sample,
        storage: GridStorage::Band { cells: 2 },
        march: MarchParams::default(),
    };
    for (count, copies) in [(Some("[10, 1, 10]"), 100), (None, 0)] {
        let s = scene(&repeat("[1, 0, 1]", count, SPHERE), 12.0);
        let (g, plans) = build_scene_with_plans(&s, grid);
        let Build::InstancedGrid { copies: n, reach, .. } = plans[0].build else {
            panic!("not instanced: {:?}", plans[0])
        };
        assert_eq!(reach.is_some(), count.is_none());
        if copies > 0 {
            assert_eq!(n, copies);
        }
        let d = g.objects()[0].describe();
        assert!(d.contains(&format!("{n} placements of one grid")), "{d}");
        // One grid's samples, however many copies.
        let one = build_scene(&scene(&repeat("[1, 0, 1]", Some("[1, 1, 1]"), SPHERE), 12.0), grid);
        assert_eq!(g.census().grid_samples, one.census().grid_samples);
        let reference = build_scene(&s, sdf());
        let (agree, hits) = agreement(&s, &g, &reference, 0.02, 11.0);
        eprintln!("{count:?}: {hits} hits, {agree} agree");
        assert!(hits > 1000, "{hits} hits");
        assert!(agree > 0.96, "{agree} of the rays agree with the SDF");
    }
}

#[test]
fn copies_cost_a_placement_each_not_a_mesh() {
    let bytes = |count: &str| {
        let s = scene(&repeat("[1, 0, 1]", Some(count), SPHERE), 100.0);
        let g = build_scene(&s, mesh(MeshMethod::Parametric));
        assert_eq!(g.census().triangles, g.objects()[0].census().triangles);
        (g.bytes_used() as u64, g.census(), scene_bytes(&s, mesh(MeshMethod::Parametric)))
    };
    let (one, c1, e1) = bytes("[1, 1, 1]");
    let (hundred, c100, e100) = bytes("[10, 1, 10]");
    eprintln!("1 copy: {one} bytes, 100 copies: {hundred} bytes");
    assert!(hundred > one && hundred < one + 100 * BYTES_PER_INSTANCE, "{one} {hundred}");
    // One mesh, however many copies.
    assert_eq!(c1.triangles, c100.triangles);
    assert!(c1.triangles > 500);
    // The estimate grows the same way and stays above the bytes used.
    assert_eq!(e100 - e1, 99 * BYTES_PER_INSTANCE);
    assert!(e100 >= hundred, "estimate {e100} under {hundred}");
}

#[test]
fn objects_of_the_same_geometry_share_one_mesh_counted_once() {
    let sphere = |x: f32, r: f32, m: &str| {
        format!(
            "[[objects]]\ntype = \"sphere\"\nradius = {r}\ntranslate = [{x}, 0, 0]\nmaterial = \"{m}\"\n\n"
        )
    };
    let mut text: String = ["a", "b", "c", "d"]
        .iter()
        .enumerate()
        .map(|(i, m)| format!("[materials.{m}]\ncolor = [{}, 0.5, 0.5]\n\n", 0.2 * i as f32))
        .collect();
    text +=
        &(sphere(-2.0, 0.5, "a") + &sphere(0.0, 0.5, "b") + &sphere(2.0, 0.7, "c") + &sphere(4.0, 0.5, "d"));
    let s = scene(&text, 100.0);
    let (g, plans) = build_scene_with_plans(&s, mesh(MeshMethod::Parametric));
    let builds: Vec<Build> = plans.iter().map(|p| p.build).collect();
    assert!(
        matches!(
            builds[..],
            [
                Build::Tessellated { .. },
                Build::SharedMesh { of: 0 },
                Build::Tessellated { .. },
                Build::SharedMesh { of: 0 }
            ]
        ),
        "{builds:?}"
    );
    let shared: Vec<usize> = g.objects().iter().map(|o| o.shared().unwrap().id).collect();
    assert!(shared[0] == shared[1] && shared[0] == shared[3] && shared[0] != shared[2]);
    let objects: usize = g.objects().iter().map(|o| o.bytes_used()).sum();
    let mesh_bytes = g.objects()[0].shared().unwrap().bytes;
    assert!(g.bytes_used() + 2 * mesh_bytes < objects + 1024, "{} {objects} {mesh_bytes}", g.bytes_used());
    let per_object = g.objects()[0].census().triangles;
    assert_eq!(g.census().triangles, per_object + g.objects()[2].census().triangles);
    // Each keeps its own place and material: the hits match the closed form's.
    let reference = build_scene(&s, Representation::Analytic { march: MarchParams::default() });
    let (agree, hits) = agreement(&s, &g, &reference, 0.02, 1e5);
    assert!(hits > 150 && agree > 0.98, "{agree} of {hits}");
    let rays = RayGenerator::new(&s.camera);
    let mut stats = RayStats::default();
    let mut materials = std::collections::BTreeSet::new();
    for x in 0..s.camera.width {
        let ray = rays.ray(x, s.camera.height / 2);
        if let (Some(a), Some(b)) =
            (g.closest_hit(&ray, 0.0, 1e5, &mut stats), reference.closest_hit(&ray, 0.0, 1e5, &mut stats))
        {
            assert_eq!(a.material, b.material);
            materials.insert(a.material);
        }
    }
    assert_eq!(materials.len(), 4);
}

#[test]
fn an_infinite_repetition_hits_what_the_sdf_hits_within_max_distance() {
    for max_distance in [25.0f32, 1e5] {
        let s = scene(&repeat("[2, 0, 2]", None, SPHERE), max_distance);
        let (g, plans) = build_scene_with_plans(&s, mesh(MeshMethod::Parametric));
        let Build::Instanced { copies, reach: Some(reach), .. } = plans[0].build else {
            panic!("not instanced: {:?}", plans[0])
        };
        let d = g.objects()[0].describe();
        assert!(d.contains(&format!("the {copies} copies in view out to {reach}")), "{d}");
        if max_distance == 25.0 {
            assert_eq!(reach, 25.0);
        } else {
            assert!(reach < max_distance, "{reach}");
        }
        let reference = build_scene(&s, sdf());
        let (agree, hits) = agreement(&s, &g, &reference, 0.05, reach);
        eprintln!("max_distance {max_distance}: {copies} copies out to {reach}: {hits} hits, {agree} agree");
        assert!(hits > 500, "{hits} hits");
        assert!(agree > 0.95, "{agree} of the rays agree with the SDF");
    }
}

#[test]
fn extraction_asked_for_extracts_the_child_once() {
    let s = scene(&repeat("[1, 0, 1]", Some("[4, 1, 3]"), SPHERE), 100.0);
    let mc = ExtractMethod::MarchingCubes;
    let (g, plans) = build_scene_with_plans(&s, mesh(MeshMethod::Extracted(mc)));
    assert_eq!(
        plans[0].build,
        Build::Instanced {
            mesh: InstanceMesh::Extracted { method: mc, resolution: 32 },
            copies: 12,
            reach: None
        }
    );
    let reference = build_scene(&s, sdf());
    let (agree, hits) = agreement(&s, &g, &reference, 0.02, 1e5);
    assert!(hits > 100 && agree > 0.97, "{agree} of {hits}");
}
