//! The grid options of the `toolkit` binary end to end: `convert --to grid --fill
//! voxelize`, `convert --band K` (a memory report; the file stays dense) and
//! `render --repr grid --fill voxelize --band K`.

use std::path::Path;
use std::process::Output;

use glam::Vec3;
use sdfmesh::convert::tessellate::tessellate;
use sdfmesh::geometry::grid::io::load_grid;
use sdfmesh::mesh::{TriangleMesh, save_mesh};
use sdfmesh::scene::shape::Primitive;

use crate::util::{temp_dir, toolkit};

fn write_mesh(dir: &Path, name: &str, mesh: &TriangleMesh) -> String {
    let p = dir.join(name);
    save_mesh(mesh, &p).unwrap();
    p.to_str().unwrap().to_string()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn convert_voxelizes_and_reports_the_band() {
    let dir = temp_dir("convert");
    let mesh = write_mesh(&dir, "sphere.obj", &tessellate(&Primitive::Sphere { radius: 1.0 }, 64, None));
    let out = dir.join("sphere.sdf");
    let o = toolkit(&[
        "convert",
        &mesh,
        "--to",
        "grid",
        "--fill",
        "voxelize",
        "--res",
        "48",
        "--band",
        "2",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("voxelized in"), "{t}");
    assert!(
        t.lines().any(|l| l.starts_with("narrow band of 2 cells") && l.ends_with("bytes)")),
        "one line: {t}"
    );
    let g = load_grid(&out).unwrap();
    assert_eq!(g.dims, glam::UVec3::splat(53), "a dense grid of 48 + 2 * 2 cells");
    let c = g.dims / 2;
    assert!(g.get(c.x, c.y, c.z) < -0.8);
    assert!(g.get(0, 0, 0) > 0.0);
    // Exact sampling, no band report.
    let o = toolkit(&["convert", &mesh, "--to", "grid", "--res", "16", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("sampled in") && !text(&o).contains("narrow band"), "{}", text(&o));
}

#[test]
fn voxelizing_an_open_mesh_fails_cleanly() {
    let dir = temp_dir("open");
    let mut open = tessellate(&Primitive::Box { half: Vec3::splat(0.5) }, 8, None);
    open.triangles.truncate(open.triangles.len() - 2);
    let mesh = write_mesh(&dir, "open.obj", &open);
    let out = dir.join("open.npy");
    let o = toolkit(&["convert", &mesh, "--to", "grid", "--fill", "voxelize", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let t = String::from_utf8_lossy(&o.stderr);
    assert!(t.contains("open") && t.contains("--fill sample"), "{t}");
    assert_eq!(t.lines().count(), 1, "{t}");
    assert!(!out.exists());
    // Bad values of the new flags are usage errors.
    let o = toolkit(&["convert", &mesh, "--to", "grid", "--fill", "melt", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let o = toolkit(&["convert", &mesh, "--to", "grid", "--band", "-1", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn render_grid_with_voxelize_and_band() {
    let dir = temp_dir("render");
    let mesh =
        write_mesh(&dir, "torus.obj", &tessellate(&Primitive::Torus { major: 1.0, minor: 0.3 }, 48, None));
    let png = dir.join("torus.png");
    let o = toolkit(&[
        "render",
        &mesh,
        "--repr",
        "grid",
        "--res",
        "48",
        "--fill",
        "voxelize",
        "--band",
        "3",
        "--width",
        "64",
        "--height",
        "48",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("voxelized at 48") && t.contains("narrow band of 3 cells"), "{t}");
    assert!(png.exists());
    // Dense and sampled by default.
    let o = toolkit(&[
        "render",
        &mesh,
        "--repr",
        "grid",
        "--res",
        "24",
        "--width",
        "32",
        "--height",
        "24",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("sampled at 24") && !t.contains("narrow band"), "{t}");
}
