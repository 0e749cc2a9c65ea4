//! Malformed input and absurd requests through every `toolkit` command (issue 7, items 3
//! and 4): truncated files, wrong magic numbers, headers claiming absurd counts, NaN and
//! infinity, unreadable and missing files, output paths in missing folders, resolutions of
//! 0 or 100000, negative depths, requests over the memory budget. Each one must give one
//! clear line on stderr naming the file or the option, exit code 2, no panic, no output
//! file, no temporary file left behind, and an existing output file untouched. Each
//! request must also fail fast (well under the time the work itself would take).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::util::{temp_dir, toolkit};

/// [`put`](crate::util::put), returning the path as a command-line argument.
fn put(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> String {
    crate::util::put(dir, name, bytes).to_str().unwrap().to_owned()
}

const SCENE: &str = r#"
[camera]
position = [0, 0, -4]
look_at = [0, 0, 0]
width = 32
height = 32

[[objects]]
type = "sphere"
radius = 1
"#;

const TETRA: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

/// A `.sdf` header (see `sdfmesh::geometry::grid::io`) with the given fields, then `samples`.
fn sdf_file(magic: &[u8; 8], version: u32, dims: [u32; 3], voxel: f32, samples: &[f32]) -> Vec<u8> {
    let mut b = magic.to_vec();
    b.extend(version.to_le_bytes());
    for d in dims {
        b.extend(d.to_le_bytes());
    }
    for o in [0.0f32; 3] {
        b.extend(o.to_le_bytes());
    }
    b.extend(voxel.to_le_bytes());
    b.extend(0.0f32.to_le_bytes());
    for s in samples {
        b.extend(s.to_le_bytes());
    }
    b
}

/// A `.npy` file with the given header dictionary and payload.
fn npy_file(dict: &str, payload: &[u8]) -> Vec<u8> {
    let mut header = dict.to_owned();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((header.len() as u16).to_le_bytes());
    b.extend(header.as_bytes());
    b.extend(payload);
    b
}

/// Runs `args`, expects a clean failure whose one stderr line contains every needle, and
/// that `out` still holds what it held.
fn fails(args: &[&str], needles: &[&str], out: &Path, what: &str) {
    let start = Instant::now();
    let o = toolkit(args);
    let took = start.elapsed();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{what}: {args:?}: exit {:?}: {err}", o.status.code());
    assert!(!err.contains("panicked"), "{what}: {err}");
    let line = err.trim();
    // Every error, clap's usage errors included, is exactly one line.
    assert_eq!(line.lines().count(), 1, "{what}: one line: {err}");
    assert!(line.starts_with("error: "), "{what}: {err}");
    for n in needles {
        assert!(err.contains(n), "{what}: expected {n:?} in: {err}");
    }
    assert_eq!(std::fs::read(out).unwrap(), b"precious", "{what}: the existing output was touched");
    assert!(took < Duration::from_secs(20), "{what}: took {took:?} to fail");
}

fn no_leftovers(dir: &Path) {
    let left: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp") || n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "temporary files left behind: {left:?}");
}

#[test]
fn malformed_files_fail_cleanly_in_every_command() {
    let dir = temp_dir("files");
    let png = put(&dir, "out.png", "precious");
    let sdf_out = put(&dir, "out.sdf", "precious");
    let obj_out = put(&dir, "out.obj", "precious");
    let one = [0.5f32; 8];
    let cases: Vec<(String, Vec<&str>)> = vec![
        // Grid files.
        (
            put(&dir, "truncated.sdf", &sdf_file(b"SDFGRID\0", 1, [2, 2, 2], 1.0, &one)[..50]),
            vec!["truncated.sdf"],
        ),
        (put(&dir, "magic.sdf", sdf_file(b"NOTAGRID", 1, [2, 2, 2], 1.0, &one)), vec!["magic.sdf", "magic"]),
        (
            put(&dir, "version.sdf", sdf_file(b"SDFGRID\0", 99, [2, 2, 2], 1.0, &one)),
            vec!["version.sdf", "version"],
        ),
        (
            put(&dir, "huge.sdf", sdf_file(b"SDFGRID\0", 1, [1 << 20, 1 << 20, 1 << 20], 1.0, &one)),
            vec!["huge.sdf"],
        ),
        (put(&dir, "voxel.sdf", sdf_file(b"SDFGRID\0", 1, [2, 2, 2], f32::NAN, &one)), vec!["voxel.sdf"]),
        (
            put(
                &dir,
                "nan.sdf",
                sdf_file(b"SDFGRID\0", 1, [2, 2, 2], 1.0, &[0.5, 0.5, f32::NAN, 0.5, 0.5, 0.5, 0.5, 0.5]),
            ),
            vec!["nan.sdf", "NaN"],
        ),
        (put(&dir, "magic.npy", b"\x93NUMPZ\x01\x00garbage"), vec!["magic.npy"]),
        (
            put(
                &dir,
                "huge.npy",
                npy_file(
                    "{'descr': '<f4', 'fortran_order': False, 'shape': (1099511627776, 2, 2), }",
                    &[0; 16],
                ),
            ),
            vec!["huge.npy"],
        ),
        (put(&dir, "empty.npy", b""), vec!["empty.npy"]),
        // Mesh files.
        (
            put(
                &dir,
                "huge.ply",
                "ply\nformat binary_little_endian 1.0\nelement vertex 1099511627776\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
            ),
            vec!["huge.ply"],
        ),
        (
            put(
                &dir,
                "truncated.ply",
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n",
            ),
            vec!["truncated.ply"],
        ),
        (put(&dir, "nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), vec!["nan.obj"]),
        (put(&dir, "inf.obj", "v inf 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), vec!["inf.obj"]),
        (put(&dir, "empty.obj", ""), vec!["empty.obj"]),
        (
            put(&dir, "huge.stl", {
                let mut b = vec![0u8; 80];
                b.extend(u32::MAX.to_le_bytes());
                b.extend([0u8; 50]);
                b
            }),
            vec!["huge.stl"],
        ),
        (put(&dir, "magic.glb", b"glTX\x02\x00\x00\x00\x0c\x00\x00\x00"), vec!["magic.glb"]),
        (
            put(&dir, "truncated.glb", b"glTF\x02\x00\x00\x00\xff\xff\x00\x00{\"asset\""),
            vec!["truncated.glb"],
        ),
        // Scene files.
        (put(&dir, "nan.toml", SCENE.replace("radius = 1", "radius = nan")), vec!["nan.toml:"]),
        (put(&dir, "inf.toml", SCENE.replace("radius = 1", "radius = inf")), vec!["inf.toml:"]),
        (put(&dir, "truncated.toml", &SCENE[..40]), vec!["truncated.toml:"]),
        (put(&dir, "binary.toml", [0xffu8, 0xfe, 0x00, 0x41]), vec!["binary.toml"]),
        (
            put(
                &dir,
                "meshless.toml",
                format!("{SCENE}\n[[objects]]\ntype = \"mesh\"\npath = \"gone.obj\"\n"),
            ),
            vec!["gone.obj"],
        ),
        (
            put(
                &dir,
                "gridless.toml",
                format!("{SCENE}\n[[objects]]\ntype = \"grid\"\npath = \"magic.sdf\"\n"),
            ),
            vec!["magic.sdf"],
        ),
        // Missing and unreadable inputs.
        (dir.join("missing.obj").to_str().unwrap().to_owned(), vec!["missing.obj"]),
        (dir.join("missing.toml").to_str().unwrap().to_owned(), vec!["missing.toml"]),
        (
            {
                let d = dir.join("folder.obj");
                std::fs::create_dir_all(&d).unwrap();
                d.to_str().unwrap().to_owned()
            },
            vec!["folder.obj"],
        ),
    ];
    for (input, needles) in &cases {
        let name = Path::new(input).file_name().unwrap().to_string_lossy().into_owned();
        fails(&["render", input, "-o", &png], needles, Path::new(&png), &format!("render {name}"));
        let is_mesh = [".obj", ".ply", ".stl", ".glb"].iter().any(|e| name.ends_with(e));
        if is_mesh {
            fails(
                &["convert", input, "--to", "grid", "--res", "8", "-o", &sdf_out],
                needles,
                Path::new(&sdf_out),
                &format!("convert {name}"),
            );
        }
        if name.ends_with(".toml") {
            fails(
                &["convert", input, "--to", "mesh", "--res", "8", "-o", &obj_out],
                needles,
                Path::new(&obj_out),
                &format!("convert {name}"),
            );
        }
    }
    no_leftovers(&dir);
}

#[test]
fn absurd_requests_fail_at_once() {
    let dir = temp_dir("absurd");
    let scene = put(&dir, "scene.toml", SCENE);
    let mesh = put(&dir, "tetra.obj", TETRA);
    let png = put(&dir, "out.png", "precious");
    let sdf = put(&dir, "out.sdf", "precious");
    let obj = put(&dir, "out.obj", "precious");
    let csv = put(&dir, "out.csv", "precious");
    let xyz = format!("{sdf}.xyz");
    let p = |s: &String| Path::new(s).to_path_buf();
    let cases: Vec<(Vec<&str>, Vec<&str>, PathBuf)> = vec![
        // A 100000^3 grid: over every limit, refused before any allocation.
        (vec!["convert", &mesh, "--to", "grid", "--res", "100000", "-o", &sdf], vec!["memory"], p(&sdf)),
        (vec!["convert", &mesh, "--to", "grid", "--res", "0", "-o", &sdf], vec!["--res"], p(&sdf)),
        (vec!["convert", &scene, "--to", "mesh", "--res", "100000", "-o", &obj], vec!["--res"], p(&obj)),
        (vec!["convert", &scene, "--to", "mesh", "--res", "0", "-o", &obj], vec!["--res"], p(&obj)),
        (vec!["render", &scene, "--repr", "grid", "--res", "100000", "-o", &png], vec!["--res"], p(&png)),
        (vec!["render", &scene, "--repr", "grid", "--res", "0", "-o", &png], vec!["--res"], p(&png)),
        (vec!["render", &scene, "--depth", "-1", "-o", &png], vec!["--depth"], p(&png)),
        (vec!["render", &scene, "--width", "-5", "-o", &png], vec!["--width"], p(&png)),
        (vec!["render", &scene, "--height", "0", "-o", &png], vec!["--height"], p(&png)),
        (vec!["render", &scene, "--max-steps", "100000000", "-o", &png], vec!["--max-steps"], p(&png)),
        (vec!["render", &scene, "--epsilon", "nan", "-o", &png], vec!["--epsilon"], p(&png)),
        (vec!["render", &scene, "--relax", "inf", "-o", &png], vec!["--relax"], p(&png)),
        // Over an explicit memory budget: the grid, the extraction and the mesh.
        (
            vec!["render", &scene, "--repr", "grid", "--res", "256", "--max-memory", "16MiB", "-o", &png],
            vec!["--max-memory", "16.0 MiB", "scene.toml"],
            p(&png),
        ),
        (
            vec!["render", &scene, "--repr", "mesh", "--res", "4096", "--max-memory", "1GiB", "-o", &png],
            vec!["--max-memory"],
            p(&png),
        ),
        (
            vec!["convert", &mesh, "--to", "grid", "--res", "512", "--max-memory", "100MB", "-o", &sdf],
            vec!["--max-memory", "tetra.obj", "517x517x517"],
            p(&sdf),
        ),
        (
            vec!["convert", &scene, "--to", "mesh", "--res", "1000", "--max-memory", "1GiB", "-o", &obj],
            vec!["--max-memory", "1000 cells"],
            p(&obj),
        ),
        (vec!["render", &scene, "--max-memory", "lots", "-o", &png], vec!["lots"], p(&png)),
        (vec!["render", &scene, "--max-memory", "0", "-o", &png], vec!["0"], p(&png)),
        // compare checks its sweep before any run and never replaces an existing CSV.
        (vec!["compare", &scene, "--csv", &csv, "--res", "0"], vec!["--res"], p(&csv)),
        (vec!["compare", &scene, "--csv", &csv, "--frames", "0", "--overwrite"], vec!["--frames"], p(&csv)),
        (vec!["compare", &scene, "--csv", &csv, "--res", "8"], vec!["out.csv"], p(&csv)),
        // Outputs in folders that do not exist, and outputs of an unknown kind.
        (
            vec!["convert", &mesh, "--to", "grid", "--res", "4", "-o", "/nonexistent/dir/x.sdf"],
            vec!["/nonexistent/dir"],
            p(&sdf),
        ),
        (vec!["convert", &mesh, "--to", "grid", "--res", "4", "-o", &xyz], vec![".xyz"], p(&sdf)),
        (
            vec!["convert", &scene, "--to", "mesh", "--res", "4", "-o", "/nonexistent/dir/x.obj"],
            vec!["/nonexistent/dir"],
            p(&obj),
        ),
        (vec!["render", &scene, "-o", "/nonexistent/dir/x.png"], vec!["/nonexistent/dir"], p(&png)),
    ];
    for (args, needles, out) in &cases {
        fails(args, needles, out, &args.join(" "));
    }
    no_leftovers(&dir);
}

/// Every flag range (`sdfmesh::config`, where each is stated once) refuses the values just
/// outside it, with one line naming the flag and the range, exit code 2, before any file
/// is read and without touching the output.
#[test]
fn every_flag_range_refuses_its_edges() {
    let dir = temp_dir("ranges");
    let scene = put(&dir, "scene.toml", SCENE);
    let mesh = put(&dir, "tetra.obj", TETRA);
    let png = put(&dir, "out.png", "precious");
    let csv = put(&dir, "out.csv", "precious");
    let obj = put(&dir, "out.obj", "precious");
    let sdf = put(&dir, "out.sdf", "precious");
    let missing = dir.join("missing.toml").to_str().unwrap().to_owned();
    let folder = dir.to_str().unwrap().to_owned();
    let gallery = dir.join("g").to_str().unwrap().to_owned();
    let p = |s: &String| Path::new(s).to_path_buf();
    let render = |args: &[&'static str], needles: Vec<&'static str>| {
        let mut all = vec!["render", scene.as_str(), "-o", png.as_str()];
        all.extend(args);
        (all, needles, p(&png))
    };
    let cases: Vec<(Vec<&str>, Vec<&str>, PathBuf)> = vec![
        // The mesh representation's --res: 3..=8192.
        render(&["--repr", "mesh", "--res", "2"], vec!["--res must be between 3 and 8192, got 2"]),
        render(&["--repr", "mesh", "--res", "8193"], vec!["--res must be between 3 and 8192, got 8193"]),
        // The grid representation's --res: 2..=1024.
        render(&["--repr", "grid", "--res", "1"], vec!["--res must be between 2 and 1024 for grids, got 1"]),
        render(&["--repr", "grid", "--res", "1025"], vec!["between 2 and 1024 for grids, got 1025"]),
        // Sphere tracing.
        render(&["--relax", "0.99"], vec!["--relax must be in [1, 2), got 0.99"]),
        render(&["--relax", "2"], vec!["--relax must be in [1, 2), got 2"]),
        render(&["--tolerance-px", "0"], vec!["--tolerance-px must be in (0, 16], got 0"]),
        render(&["--tolerance-px", "16.5"], vec!["--tolerance-px"]),
        render(&["--epsilon", "1"], vec!["--epsilon must be in (0, 1), got 1"]),
        render(&["--max-steps", "1000001"], vec!["--max-steps must be between 1 and 1000000"]),
        // Overrides.
        render(&["--width", "16385"], vec!["--width must be between 1 and 16384, got 16385"]),
        render(&["--height", "0"], vec!["--height must be between 1 and 16384, got 0"]),
        render(&["--depth", "101"], vec!["--depth must be at most 100, got 101"]),
        // gallery checks every representation: --res 2 is a grid resolution, not a mesh one.
        (
            vec!["gallery", &folder, "-o", &gallery, "--res", "2"],
            vec!["--res must be between 3 and 8192, got 2"],
            p(&png),
        ),
        // convert: --to mesh 2..=1024, --to grid at least 1 (then memory).
        (
            vec!["convert", &scene, "--to", "mesh", "--res", "1", "-o", &obj],
            vec!["between 2 and 1024, got 1"],
            p(&obj),
        ),
        (
            vec!["convert", &scene, "--to", "mesh", "--res", "1025", "-o", &obj],
            vec!["between 2 and 1024"],
            p(&obj),
        ),
        (
            vec!["convert", &mesh, "--to", "grid", "--res", "0", "-o", &sdf],
            vec!["--res must be at least 1, got 0"],
            p(&sdf),
        ),
        // compare: the sweep in the grid range, frames, band, the SDF sweep.
        (
            vec!["compare", &scene, "--csv", &csv, "--res", "1"],
            vec!["--res must be between 2 and 1024 for grids"],
            p(&csv),
        ),
        (vec!["compare", &scene, "--csv", &csv, "--res", "8,1025"], vec!["got 1025"], p(&csv)),
        (
            vec!["compare", &scene, "--csv", &csv, "--frames", "1001"],
            vec!["--frames must be between 1 and 1000"],
            p(&csv),
        ),
        (
            vec!["compare", &scene, "--csv", &csv, "--band", "0"],
            vec!["--band must be at least 1, got 0"],
            p(&csv),
        ),
        (
            vec!["compare", &scene, "--csv", &csv, "--sdf-relax", "1,2"],
            vec!["--sdf-tolerance-px/--sdf-relax: --relax"],
            p(&csv),
        ),
        (
            vec!["compare", &scene, "--csv", &csv, "--sdf-tolerance-px", "17"],
            vec!["--tolerance-px must be in (0, 16]"],
            p(&csv),
        ),
        // compare --scaling: both representations' ranges, counts, frames.
        (
            vec!["compare", "--scaling", "--csv", &csv, "--scaling-res", "2"],
            vec!["--scaling-res must be between 3 and 8192"],
            p(&csv),
        ),
        (
            vec!["compare", "--scaling", "--csv", &csv, "--scaling-res", "1025"],
            vec!["--scaling-res must be between 2 and 1024"],
            p(&csv),
        ),
        (
            vec!["compare", "--scaling", "--csv", &csv, "--counts", "0"],
            vec!["--counts must be between 1 and 10000, got 0"],
            p(&csv),
        ),
        (vec!["compare", "--scaling", "--csv", &csv, "--counts", "10,10001"], vec!["got 10001"], p(&csv)),
        (
            vec!["compare", "--scaling", "--csv", &csv, "--frames", "0"],
            vec!["--frames must be between 1 and 1000"],
            p(&csv),
        ),
        // Flags are checked before any input is read: a missing scene is not reached.
        (vec!["render", &missing, "--width", "0", "-o", &png], vec!["--width"], p(&png)),
        (vec!["compare", &missing, "--csv", &csv, "--res", "0"], vec!["--res"], p(&csv)),
    ];
    for (args, needles, out) in &cases {
        fails(args, needles, out, &args.join(" "));
    }
    assert!(!dir.join("g").exists(), "gallery wrote its folder");
    no_leftovers(&dir);
}
