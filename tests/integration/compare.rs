//! `toolkit compare`: the CSV header is the documented schema, reruns give the same
//! non-timing columns, surface distances are right on concentric spheres, an interrupted
//! run keeps its rows and `--resume` completes it without duplicates, and the scaling
//! experiment writes its rows.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use glam::Vec3;
use sdfmesh::compare::{COLUMNS, Row, read_rows};
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::metrics::{probe, surface_distance};
use sdfmesh::plan::{Representation, build_scene};
use sdfmesh::scene::shape::Primitive;

use crate::util::{temp_dir, toolkit};

const SCENE: &str = r#"
[camera]
position = [0, 1, -5]
look_at = [0, 0, 0]
width = 48
height = 40

[settings]
max_depth = 1

[[lights]]
type = "ambient"
intensity = 0.3

[[lights]]
type = "point"
position = [2, 3, -3]
intensity = 0.8

[[objects]]
type = "sphere"
radius = 1

[[objects]]
type = "box"
half_size = [0.5, 0.5, 0.5]
translate = [1.5, 0, 0.5]
"#;

fn run_compare(scene: &Path, csv: &Path, extra: &[&str]) -> std::process::Output {
    let res = if extra.contains(&"--res") { &[][..] } else { &["--res", "8,12"][..] };
    let mut args = vec![
        "compare",
        scene.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
        "--frames",
        "2",
        "--surface-samples",
        "2000",
        "--quiet",
    ];
    args.extend_from_slice(res);
    args.extend_from_slice(extra);
    toolkit(&args)
}

/// The README documents the schema: its column table lists exactly [`COLUMNS`] in order.
#[test]
fn csv_header_is_the_documented_schema() {
    let dir = temp_dir("header");
    let scene = dir.join("two.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let csv = dir.join("out.csv");
    let out = run_compare(&scene, &csv, &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().next().unwrap(), COLUMNS.join(","));
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    let documented: Vec<&str> = readme
        .lines()
        .skip_while(|l| !l.contains("<!-- compare-schema:start -->"))
        .take_while(|l| !l.contains("<!-- compare-schema:end -->"))
        .filter_map(|l| l.strip_prefix("| `")?.split('`').next())
        .collect();
    assert_eq!(documented, COLUMNS.to_vec(), "README's compare schema table differs from the CSV columns");
    // Every representation and method of a scene input, and the reference named.
    let rows = read_rows(&csv).unwrap();
    let kinds: Vec<String> = rows.iter().map(|r| format!("{}/{}", r.repr, r.method)).collect();
    for k in [
        "analytic/closed-form",
        "sdf/sphere-trace",
        "mesh/parametric",
        "mesh/extracted",
        "grid/dense",
        "grid/band",
    ] {
        assert!(kinds.iter().any(|x| x == k), "{k} missing from {kinds:?}");
    }
    assert_eq!(rows.len(), 2 + 4 * 2);
    assert!(rows.iter().all(|r| r.reference == "analytic/closed-form"));
    let reference = &rows[0];
    assert_eq!((reference.image_rmse, reference.chamfer_rel), (0.0, Some(0.0)));
    // The summary names the input and a fastest run.
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("two (reference analytic/closed-form)") && stdout.contains("fastest"),
        "{stdout}"
    );
    // Errors fall as resolution grows, for meshes and grids alike.
    for kind in ["mesh/extracted", "grid/dense"] {
        let c: Vec<f64> = rows
            .iter()
            .filter(|r| format!("{}/{}", r.repr, r.method) == kind)
            .map(|r| r.chamfer_rel.unwrap())
            .collect();
        assert!(c[1] < c[0], "{kind}: {c:?}");
    }
}

fn without_timings(mut r: Row) -> Row {
    r.build_ms = 0.0;
    r.frame_ms_median = 0.0;
    r.frame_ms_min = 0.0;
    r.frame_ms_max = 0.0;
    r.mrays_per_s = 0.0;
    r.peak_rss_bytes = None;
    r.timestamp.clear();
    r.frame_ms_samples.clear();
    r
}

#[test]
fn same_input_gives_the_same_non_timing_columns() {
    let dir = temp_dir("repeat");
    let scene = dir.join("two.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let (a, b) = (dir.join("a.csv"), dir.join("b.csv"));
    for csv in [&a, &b] {
        let out = run_compare(&scene, csv, &[]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let ra: Vec<Row> = read_rows(&a).unwrap().into_iter().map(without_timings).collect();
    let rb: Vec<Row> = read_rows(&b).unwrap().into_iter().map(without_timings).collect();
    assert_eq!(ra, rb);
}

#[test]
fn existing_csv_is_never_overwritten_without_asking() {
    let dir = temp_dir("exists");
    let scene = dir.join("two.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let csv = dir.join("out.csv");
    std::fs::write(&csv, "precious\n").unwrap();
    let out = run_compare(&scene, &csv, &[]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("out.csv") && err.contains("--resume"), "{err}");
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), "precious\n");
    // A CSV of another schema is not resumed.
    let out = run_compare(&scene, &csv, &["--resume"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("out.csv:1:1"));
}

#[test]
fn interrupted_run_keeps_its_rows_and_resume_completes_it() {
    let dir = temp_dir("resume");
    let scene = dir.join("two.toml");
    // A bigger image so that the run takes long enough to be interrupted.
    std::fs::write(&scene, SCENE.replace("width = 48", "width = 320").replace("height = 40", "height = 240"))
        .unwrap();
    let csv = dir.join("out.csv");
    let mut child = Command::new(env!("CARGO_BIN_EXE_toolkit"))
        .args(["compare", scene.to_str().unwrap(), "--csv", csv.to_str().unwrap()])
        .args(["--res", "8,12,16,24", "--frames", "3", "--quiet"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kill it once at least three rows (header + 3) are on disk.
    let start = Instant::now();
    loop {
        let lines = std::fs::read_to_string(&csv).map(|t| t.lines().count()).unwrap_or(0);
        if lines >= 4 || start.elapsed() > Duration::from_secs(120) {
            break;
        }
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let finished_early = child.try_wait().unwrap().is_some();
    let _ = child.kill();
    let _ = child.wait();
    let kept = read_rows(&csv).map(|r| r.len()).unwrap_or_else(|_| {
        // Killed in the middle of a row: resume drops that partial line.
        std::fs::read_to_string(&csv).unwrap().lines().count().saturating_sub(2)
    });
    assert!(kept >= 3, "{kept} rows kept");
    assert!(!finished_early && kept < 2 + 4 * 4, "the run was not interrupted ({kept} rows)");
    let out = run_compare(&scene, &csv, &["--res", "8,12,16,24", "--resume"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = read_rows(&csv).unwrap();
    assert_eq!(rows.len(), 2 + 4 * 4, "finished early: {finished_early}");
    let mut keys: Vec<_> = rows.iter().map(Row::key).collect();
    keys.sort();
    keys.dedup();
    assert_eq!(keys.len(), rows.len(), "duplicate rows after --resume");
}

/// Chamfer and Hausdorff distances between concentric spheres of radius 1 and 1.25 both
/// equal the radius difference (each sample of one sphere is exactly 0.25 from the other).
#[test]
fn concentric_spheres_are_their_radius_difference_apart() {
    let sphere = |r| crate::util::object(Primitive::Sphere { radius: r }, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
    let march = MarchParams::default();
    let mut results = Vec::new();
    for repr in [Representation::Analytic { march }, Representation::Sdf { march }] {
        let (inner, outer) =
            (crate::util::lit_scene(vec![sphere(1.0)], 64), crate::util::lit_scene(vec![sphere(1.25)], 64));
        let (gi, go) = (build_scene(&inner, repr), build_scene(&outer, repr));
        let pi = probe(&inner.camera, &gi, 1e5);
        let po = probe(&outer.camera, &go, 1e5);
        assert!(pi.points.len() > 500 && po.points.len() > pi.points.len());
        let d = surface_distance(&gi, &pi.points, &go, &po.points).unwrap();
        results.push(d);
        let tol = if matches!(repr, Representation::Analytic { .. }) { 1e-5 } else { 1e-3 };
        assert!((d.chamfer - 0.25).abs() < tol, "{d:?}");
        assert!((d.hausdorff - 0.25).abs() < tol, "{d:?}");
        assert!(d.diagonal > 1.0 && d.diagonal < 2.0 * 1.25 * 3f64.sqrt() + 1e-6, "{d:?}");
    }
    // A surface against itself is 0 apart.
    let scene = crate::util::lit_scene(vec![sphere(1.0)], 48);
    let g = build_scene(&scene, Representation::Analytic { march });
    let p = probe(&scene.camera, &g, 1e5);
    let d = surface_distance(&g, &p.points, &g, &p.points).unwrap();
    assert!(d.hausdorff < 1e-5, "{d:?}");
}

#[test]
fn scaling_experiment_writes_a_row_per_primitive_count_and_representation() {
    let dir = temp_dir("scaling");
    let csv = dir.join("scaling.csv");
    let out = toolkit(&[
        "compare",
        "--scaling",
        "--counts",
        "2,5",
        "--frames",
        "1",
        "--width",
        "40",
        "--height",
        "30",
        "--scaling-res",
        "8",
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut reader = csv::Reader::from_path(&csv).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(header, sdfmesh::compare::scaling::SCALING_COLUMNS.to_vec());
    let rows: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
    // Primitives x counts x layouts x representations.
    assert_eq!(rows.len(), 4 * 2 * 2 * 4);
    let col = |name: &str| header.iter().position(|c| c == name).unwrap();
    let (layout, method, bytes) = (col("layout"), col("method"), col("total_bytes"));
    let mesh = |count: &str, prim: &str, l: &str| {
        rows.iter().find(|r| &r[0] == prim && &r[1] == "mesh" && &r[3] == count && &r[layout] == l).unwrap()
    };
    let num = |r: &csv::StringRecord, i: usize| -> u64 { r[i].parse().unwrap() };
    for prim in ["sphere", "cube", "cylinder", "cone"] {
        // Separate objects share one mesh: more primitives, more placements, not more
        // triangles.
        let (two, five) = (mesh("2", prim, "objects"), mesh("5", prim, "objects"));
        assert_eq!(num(two, 4), num(five, 4), "{prim}");
        assert!(num(five, bytes) > num(two, bytes), "{prim}");
        assert!(!two[method].starts_with("union"), "{prim}");
        // One union object: extracted whole.
        let union = mesh("5", prim, "union");
        assert!(union[method].starts_with("union-") && num(union, 4) > 0, "{prim}");
    }
    assert!(rows.iter().all(|r| r[col("schema_version")] == *"2"));
}
