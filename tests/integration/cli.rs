//! The `toolkit` binary end to end: a render writes a PNG and reports its work; bad
//! input gives one clear line, exit code 2, and no output file; an existing file is
//! never overwritten by a failed run.

use std::path::PathBuf;

use crate::util::{put, temp_dir, toolkit};

const GOOD: &str = r#"
[camera]
position = [0, 0, -4]
look_at = [0, 0, 0]
width = 64
height = 48

[[lights]]
type = "ambient"
intensity = 0.3

[[lights]]
type = "point"
position = [2, 3, -3]
intensity = 0.8

[materials.red]
color = [1, 0, 0]

[[objects]]
type = "sphere"
radius = 1
material = "red"
"#;

#[test]
fn render_writes_png_and_reports_statistics() {
    let dir = temp_dir("ok");
    let s = put(&dir, "s.toml", GOOD);
    let out = dir.join("out.png");
    for repr in ["analytic", "sdf", "mesh"] {
        let o = toolkit(&["render", s.to_str().unwrap(), "-o", out.to_str().unwrap(), "--repr", repr]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(text.contains("Mrays/s") && text.contains("steps/ray"), "{text}");
        let img = image::open(&out).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (64, 48));
        // The red sphere is in the middle, the background is black.
        assert!(img.get_pixel(32, 24).0[0] > 100);
        assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0]);
    }
}

#[test]
fn bad_input_fails_cleanly_without_touching_the_output() {
    let dir = temp_dir("bad");
    let out = dir.join("keep.png");
    std::fs::write(&out, b"precious").unwrap();
    let cases: Vec<(PathBuf, &str)> = vec![
        (put(&dir, "neg.toml", GOOD.replace("radius = 1", "radius = -1")), "neg.toml:"),
        (put(&dir, "nan.toml", GOOD.replace("radius = 1", "radius = nan")), "nan.toml:"),
        (put(&dir, "unknown.toml", GOOD.replace("radius = 1", "radius = 1\ncolour = 3")), "unknown.toml:"),
        (put(&dir, "syntax.toml", "[camera\nposition = [0,0,0]"), "syntax.toml:"),
        (dir.join("missing.toml"), "missing.toml"),
    ];
    for (path, expect) in cases {
        let o = toolkit(&["render", path.to_str().unwrap(), "-o", out.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{}: {err}", path.display());
        assert!(err.contains(expect), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(std::fs::read(&out).unwrap(), b"precious");
    }
    // Absurd options and an output folder that does not exist.
    let good = put(&dir, "good.toml", GOOD);
    for args in [
        vec!["--width", "0"],
        vec!["--width", "100000"],
        vec!["--depth", "1000"],
        vec!["--relax", "2.5"],
        vec!["--epsilon", "0"],
        vec!["--max-steps", "0"],
        vec!["--repr", "mesh", "--res", "0"],
        vec!["--repr", "mesh", "--res", "1000000"],
    ] {
        let mut all = vec!["render", good.to_str().unwrap(), "-o", out.to_str().unwrap()];
        all.extend(args.iter());
        let o = toolkit(&all);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert_eq!(std::fs::read(&out).unwrap(), b"precious");
    }
    let nowhere = dir.join("no/such/dir/out.png");
    let o = toolkit(&["render", good.to_str().unwrap(), "-o", nowhere.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("does not exist"));
    // No temporary files were left behind.
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn a_mesh_file_renders_without_a_scene_and_broken_meshes_fail_cleanly() {
    let dir = temp_dir("mesh");
    let obj = dir.join("tet.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n").unwrap();
    let out = dir.join("tet.png");
    let o = toolkit(&[
        "render",
        obj.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--width",
        "80",
        "--height",
        "60",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("4 triangles"));
    let img = image::open(&out).unwrap().to_rgb8();
    // The framed tetrahedron covers the middle of the image.
    assert_ne!(img.get_pixel(40, 30).0, [0, 0, 0]);
    let bad = dir.join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let o = toolkit(&["render", bad.to_str().unwrap(), "-o", dir.join("bad.png").to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("bad.obj") && err.contains("out of range"), "{err}");
    assert!(!dir.join("bad.png").exists());
}

#[test]
fn convert_mesh_to_grid_and_scene_to_mesh() {
    let dir = temp_dir("convert");
    let obj = dir.join("tet.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n").unwrap();
    let grid = dir.join("tet.sdf");
    let o = toolkit(&[
        "convert",
        obj.to_str().unwrap(),
        "--to",
        "grid",
        "--res",
        "16",
        "-o",
        grid.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let g = sdfmesh::geometry::grid::io::load_grid(&grid).unwrap();
    // Inside the tetrahedron the distance is negative, far outside positive.
    let (lo, hi) = g.bounds();
    assert!(g.trilinear(glam::Vec3::splat(0.15)) < 0.0);
    assert!(g.trilinear(hi) > 0.0 && g.trilinear(lo) > 0.0);

    let scene = put(&dir, "s.toml", GOOD);
    let out = dir.join("sphere.obj");
    for method in ["mc", "dc"] {
        let o = toolkit(&[
            "convert",
            scene.to_str().unwrap(),
            "--to",
            "mesh",
            "--res",
            "24",
            "--method",
            method,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let (m, _) = sdfmesh::mesh::load_mesh(&out).unwrap();
        assert!(m.is_closed(), "{method}");
        // Vertices near the unit sphere (within a few cells of 2/24).
        assert!(m.positions.iter().all(|p| (p.length() - 1.0).abs() < 0.2), "{method}");
    }

    // Absurd or impossible requests fail at once, with exit code 2 and no output.
    let nothing = dir.join("nothing.obj");
    for args in [
        vec![
            "convert",
            scene.to_str().unwrap(),
            "--to",
            "mesh",
            "--res",
            "100000",
            "-o",
            nothing.to_str().unwrap(),
        ],
        vec!["convert", obj.to_str().unwrap(), "--to", "grid", "--res", "0", "-o", nothing.to_str().unwrap()],
        vec![
            "convert",
            obj.to_str().unwrap(),
            "--to",
            "grid",
            "--res",
            "100000",
            "-o",
            nothing.to_str().unwrap(),
        ],
        vec!["convert", scene.to_str().unwrap(), "--to", "grid", "-o", nothing.to_str().unwrap()],
    ] {
        let o = toolkit(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(!nothing.exists());
    }
}
