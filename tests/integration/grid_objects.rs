//! Signed distance grid files as scene objects (`type = "grid"`): a grid written by the
//! toolkit, placed with translate, rotate and uniform scale, renders like the shape it was
//! sampled from in every representation; bad grid objects get one clear error; `toolkit
//! render GRID_FILE` previews a grid and `toolkit convert SCENE --to mesh` extracts it.

use std::path::{Path, PathBuf};

use sdfmesh::convert::extract::ExtractMethod;
use sdfmesh::convert::mesh_to_grid::sample_mesh;
use sdfmesh::convert::tessellate::tessellate;
use sdfmesh::geometry::grid::io::save_grid;
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::plan::{GridFill, GridStorage, MeshMethod, Representation};
use sdfmesh::render::report::render_scene;
use sdfmesh::scene::parse_scene;
use sdfmesh::scene::shape::Primitive;

use crate::util::{temp_dir, toolkit};

/// A unit box (half size 0.5) sampled into `dir/box.sdf` at 40 cells.
fn box_grid(dir: &Path) -> PathBuf {
    let mesh = tessellate(&Primitive::Box { half: glam::Vec3::splat(0.5) }, 8, None);
    let grid = sample_mesh(&mesh, 40, 2).unwrap();
    let path = dir.join("box.sdf");
    save_grid(&grid, &path).unwrap();
    path
}

/// A scene whose one object is `object` (TOML lines), camera in front, two lights.
fn scene_text(object: &str) -> String {
    format!(
        r#"
[camera]
position = [0, 1, -5]
look_at = [0.3, 0, 0]
fov = 40
width = 96
height = 96

[[lights]]
type = "ambient"
intensity = 0.2

[[lights]]
type = "point"
position = [2, 3, -4]
intensity = 0.8

[materials.red]
color = [0.9, 0.2, 0.1]

[[objects]]
material = "red"
translate = [0.3, 0, 0]
rotate = [0, 30, 10]
{object}
"#
    )
}

fn reprs() -> [(&'static str, Representation); 4] {
    [
        ("sdf", Representation::Sdf { march: MarchParams::default() }),
        ("analytic", Representation::Analytic { march: MarchParams::default() }),
        (
            "mesh",
            Representation::Mesh {
                resolution: 48,
                shading: sdfmesh::scene::shape::Shading::Flat,
                method: MeshMethod::Extracted(ExtractMethod::DualContouring),
                plane: sdfmesh::plan::MeshPlane::ClosedForm,
                march: MarchParams::default(),
            },
        ),
        (
            "grid-band",
            Representation::Grid {
                resolution: 32,
                fill: GridFill::Sample,
                storage: GridStorage::Band { cells: 3 },
                march: MarchParams::default(),
            },
        ),
    ]
}

#[test]
fn a_placed_grid_renders_like_the_box_it_was_sampled_from() {
    let dir = temp_dir("placed");
    box_grid(&dir);
    let scene_path = dir.join("scene.toml");
    let grid_scene =
        parse_scene(&scene_text("type = \"grid\"\npath = \"box.sdf\"\nscale = 1.5"), &scene_path).unwrap();
    let box_scene =
        parse_scene(&scene_text("type = \"box\"\nhalf_size = [0.75, 0.75, 0.75]"), &scene_path).unwrap();
    let reference = render_scene(&box_scene, Representation::Analytic { march: Default::default() });
    let bg = [0, 0, 0];
    let ref_cover = crate::util::covered(&reference.frame.image, bg);
    assert!(ref_cover > 1500, "the box covers {ref_cover} pixels");
    for (name, repr) in reprs() {
        let r = render_scene(&grid_scene, repr);
        crate::util::dump(&format!("grid_object_{name}"), &[&reference.frame.image, &r.frame.image]);
        let cover = crate::util::covered(&r.frame.image, bg);
        // Silhouettes agree to about a cell of the 40-cell grid (scaled by 1.5): at most 4%
        // of the box's pixels differ in coverage, and 90% of all pixels are within 24/255
        // (edges of the sampled box are rounded by the trilinear interpolation).
        let diff = cover.abs_diff(ref_cover) as f64 / ref_cover as f64;
        assert!(diff < 0.04, "{name}: covers {cover} pixels, the box {ref_cover}");
        let near = crate::util::fraction_within(&reference.frame.image, &r.frame.image, 24);
        assert!(near > 0.9, "{name}: only {near:.3} of pixels within 24/255 of the box");
    }
}

#[test]
fn grid_objects_reject_bad_placement_and_missing_files() {
    let dir = temp_dir("bad");
    box_grid(&dir);
    let scene_path = dir.join("scene.toml");
    let err =
        |object: &str| parse_scene(&scene_text(object), &scene_path).expect_err("must fail").to_string();
    let e = err("type = \"grid\"\npath = \"box.sdf\"\nscale = [1, 2, 1]");
    assert!(e.contains("scale must be the same on every axis") && e.contains("scene.toml:"), "{e}");
    let e = err("type = \"grid\"\npath = \"nowhere.sdf\"");
    assert!(e.contains("nowhere.sdf"), "{e}");
    let e = err("type = \"grid\"");
    assert!(e.contains("needs `path`"), "{e}");
    let e = err("type = \"union\"\n[[objects.children]]\ntype = \"grid\"\npath = \"box.sdf\"");
    assert!(e.contains("top-level"), "{e}");
    let e = err("type = \"grid\"\npath = \"box.sdf\"\nshading = \"smooth\"");
    assert!(e.contains("not valid for a grid"), "{e}");
}

#[test]
fn toolkit_previews_a_grid_file_and_extracts_grid_objects() {
    let dir = temp_dir("cli");
    let grid = box_grid(&dir);
    let png = dir.join("preview.png");
    let o = toolkit(&[
        "render",
        grid.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--width",
        "64",
        "--height",
        "64",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = image::open(&png).unwrap().to_rgb8();
    assert!(crate::util::covered(&img, [0, 0, 0]) > 300, "the preview shows the box");

    std::fs::write(dir.join("scene.toml"), scene_text("type = \"grid\"\npath = \"box.sdf\"")).unwrap();
    let obj = dir.join("box.obj");
    let scene = dir.join("scene.toml");
    let (scene, obj_arg) = (scene.to_str().unwrap(), obj.to_str().unwrap());
    let o = toolkit(&["convert", scene, "--to", "mesh", "--res", "24", "--method", "dc", "-o", obj_arg]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains("closed: true"), "{out}");
    let (mesh, _) = sdfmesh::mesh::load_mesh(&obj).unwrap();
    // The box's corners are placed by the transform: a vertex lies near the rotated corner.
    let t = sdfmesh::scene::transform::Transform::new(&sdfmesh::scene::transform::TransformDesc {
        translate: glam::Vec3::new(0.3, 0.0, 0.0),
        rotate_deg: glam::Vec3::new(0.0, 30.0, 10.0),
        scale: glam::Vec3::ONE,
    });
    let corner = t.to_world.transform_point3(glam::Vec3::splat(0.5));
    let nearest = mesh.positions.iter().map(|p| p.distance(corner)).fold(f32::MAX, f32::min);
    assert!(nearest < 0.06, "nearest vertex to the placed corner is {nearest} away");
}
