//! `toolkit compare`: the CSV header is the documented schema and rows round-trip through
//! it, reruns give the same non-timing columns, surface distances are right on concentric
//! spheres, an interrupted run keeps its rows and `--resume` completes it without duplicates
//! (keyed by replicate and march tolerance too), `--order-seed` shuffles the runs after the
//! reference deterministically, two inputs of one name are refused, and the scaling
//! experiment writes its rows; every row splits its frame into primary visibility and
//! shading, and the meshes' raster twins have their traced runs' errors.

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
        "grid/scene-band",
    ] {
        assert!(kinds.iter().any(|x| x == k), "{k} missing from {kinds:?}");
    }
    // The reference, 3 x 2 SDF sweep runs and 7 runs per resolution (4, the scene grid of
    // its two objects and the two meshes' raster twins).
    assert_eq!(rows.len(), 1 + 6 + 7 * 2);
    assert!(rows.iter().all(|r| r.reference == "analytic/closed-form"));
    let class = dir.file_name().unwrap().to_string_lossy().into_owned();
    assert!(rows.iter().all(|r| r.class == class && r.replicate == 0 && r.schema_version == 5));
    // Every frame splits into primary visibility and shading.
    for r in &rows {
        let (p, s) = (r.primary_ms.unwrap(), r.shading_ms.unwrap());
        assert!(p > 0.0 && s >= 0.0 && p + s <= r.frame_ms_median * (1.0 + 1e-9), "{r:?}");
    }
    // The raster twins: the same mesh as the traced run of their resolution, so the same
    // triangles and about the same errors.
    for method in ["parametric", "extracted"] {
        let twin = format!("{method}-raster");
        let rasters: Vec<&Row> = rows.iter().filter(|r| r.repr == "mesh" && r.method == twin).collect();
        assert_eq!(rasters.len(), 2, "{twin}");
        for r in rasters {
            let t = rows.iter().find(|t| t.method == method && t.resolution == r.resolution).unwrap();
            assert_eq!(r.triangles, t.triangles, "{twin}");
            assert!(
                (r.image_rmse - t.image_rmse).abs() < 0.01,
                "{twin}: {} vs {}",
                r.image_rmse,
                t.image_rmse
            );
            assert!(
                (r.silhouette_mismatch_pct - t.silhouette_mismatch_pct).abs() < 0.5,
                "{twin}: {} vs {}",
                r.silhouette_mismatch_pct,
                t.silhouette_mismatch_pct
            );
            let (a, b) = (r.px_err_p95.unwrap(), t.px_err_p95.unwrap());
            assert!((a - b).abs() < 0.1, "{twin}: p95 {a} vs {b}");
        }
    }
    let reference = &rows[0];
    assert_eq!((reference.image_rmse, reference.chamfer_rel), (0.0, Some(0.0)));
    assert_eq!((reference.flip_mean, reference.silhouette_mismatch_pct), (0.0, 0.0));
    assert!(reference.px_err_max.unwrap() < 1e-3, "{reference:?}");
    assert_eq!(reference.quality_px, Some(0.5));
    // The closed form of a sphere and a box marches nothing.
    assert_eq!((reference.tolerance_px, reference.relaxation), (None, None));
    // The sweep: every pair of tolerance and relaxation once; parametric meshes march nothing,
    // grids march at the default knob.
    let mut sweep: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.repr == "sdf")
        .map(|r| (r.tolerance_px.unwrap(), r.relaxation.unwrap()))
        .collect();
    sweep.sort_by(|a, b| a.partial_cmp(b).unwrap());
    assert_eq!(sweep, vec![(0.25, 1.0), (0.25, 1.6), (1.0, 1.0), (1.0, 1.6), (2.0, 1.0), (2.0, 1.6)]);
    for r in &rows {
        match (r.repr.as_str(), r.method.as_str()) {
            ("mesh", "parametric") => assert_eq!(r.tolerance_px, None),
            ("grid", _) => assert_eq!((r.tolerance_px, r.relaxation), (Some(0.25), Some(1.0))),
            _ => {}
        }
        // Sphere tracing within 2 pixels of tolerance stays about that close.
        if r.repr == "sdf" {
            assert!(r.px_err_p95.unwrap() <= r.tolerance_px.unwrap() + 0.1, "{r:?}");
        }
    }
    // Rows round-trip: written again they are the file's lines.
    let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(Vec::new());
    for r in &rows {
        w.serialize(r).unwrap();
    }
    let again = String::from_utf8(w.into_inner().unwrap()).unwrap();
    assert_eq!(again, text.lines().skip(1).map(|l| format!("{l}\n")).collect::<String>());
    // The summary names the input and a fastest run.
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("two (reference analytic/closed-form)") && stdout.contains("fastest"),
        "{stdout}"
    );
    // Errors fall as resolution grows, for meshes and grids alike.
    for kind in ["mesh/extracted", "grid/dense"] {
        let of = |f: fn(&Row) -> f64| -> Vec<f64> {
            rows.iter().filter(|r| format!("{}/{}", r.repr, r.method) == kind).map(f).collect()
        };
        let c = of(|r| r.chamfer_rel.unwrap());
        assert!(c[1] < c[0], "{kind}: {c:?}");
        let px = of(|r| r.px_err_mean.unwrap());
        assert!(px[1] < px[0], "{kind}: {px:?}");
    }
}

fn without_timings(mut r: Row) -> Row {
    r.build_ms = 0.0;
    r.frame_ms_median = 0.0;
    r.frame_ms_min = 0.0;
    r.frame_ms_max = 0.0;
    r.mrays_per_s = 0.0;
    r.peak_rss_bytes = None;
    r.peak_heap_bytes = None;
    r.timestamp.clear();
    r.frame_ms_samples.clear();
    r.primary_ms = None;
    r.shading_ms = None;
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
    assert!(!finished_early && kept < 7 + 7 * 4, "the run was not interrupted ({kept} rows)");
    let out = run_compare(&scene, &csv, &["--res", "8,12,16,24", "--resume"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = read_rows(&csv).unwrap();
    assert_eq!(rows.len(), 7 + 7 * 4, "finished early: {finished_early}");
    let mut keys: Vec<_> = rows.iter().map(Row::key).collect();
    keys.sort();
    keys.dedup();
    assert_eq!(keys.len(), rows.len(), "duplicate rows after --resume");
}

/// `--resume` keys rows by replicate and by the SDF sweep's tolerance and relaxation: a new
/// tolerance adds only its run, a new replicate the whole set again.
#[test]
fn resume_key_includes_replicate_and_march_knob() {
    let dir = temp_dir("resume_key");
    let scene = dir.join("two.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let csv = dir.join("out.csv");
    let sweep = |tol: &str| ["--res", "8", "--sdf-tolerance-px", tol, "--sdf-relax", "1"].map(String::from);
    fn args(extra: &[String]) -> Vec<&str> {
        extra.iter().map(String::as_str).collect()
    }
    let first = sweep("1");
    let out = run_compare(&scene, &csv, &args(&first));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(read_rows(&csv).unwrap().len(), 1 + 1 + 7);
    let mut more = sweep("1,2").to_vec();
    more.push("--resume".into());
    let out = run_compare(&scene, &csv, &args(&more));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = read_rows(&csv).unwrap();
    assert_eq!(rows.len(), 1 + 1 + 7 + 1);
    assert_eq!(rows.last().unwrap().tolerance_px, Some(2.0));
    more.extend(["--replicate".into(), "1".into()]);
    let out = run_compare(&scene, &csv, &args(&more));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = read_rows(&csv).unwrap();
    assert_eq!(rows.len(), 2 * 10);
    assert_eq!(rows.iter().filter(|r| r.replicate == 1).count(), 10);
    let mut keys: Vec<_> = rows.iter().map(Row::key).collect();
    keys.sort();
    keys.dedup();
    assert_eq!(keys.len(), rows.len(), "duplicate rows after --resume");
    // The summary counts the two replicates as one run each.
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("2 replicates") && stdout.contains("quality 0.5 px"), "{stdout}");
}

/// `--order-seed` runs the reference first and the rest in an order fixed by the seed.
#[test]
fn order_seed_shuffles_the_runs_after_the_reference() {
    let dir = temp_dir("order_seed");
    let scene = dir.join("two.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let order = |seed: &str, name: &str| -> Vec<String> {
        let csv = dir.join(name);
        let out = run_compare(&scene, &csv, &["--res", "8", "--order-seed", seed]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        read_rows(&csv).unwrap().iter().map(|r| format!("{:?}", r.key())).collect()
    };
    let (a, b, c) = (order("3", "a.csv"), order("3", "b.csv"), order("4", "c.csv"));
    assert_eq!(a, b);
    assert!(a[0].contains("closed-form") && c[0].contains("closed-form"), "{a:?}");
    assert_ne!(a, c);
    let (mut sa, mut sc) = (a.clone(), c.clone());
    sa.sort();
    sc.sort();
    assert_eq!(sa, sc);
}

/// Two inputs with one stem would share the `input` column: refused before any run.
#[test]
fn inputs_sharing_a_name_are_refused() {
    let dir = temp_dir("same_stem");
    let (a, b) = (dir.join("a"), dir.join("b"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    std::fs::write(a.join("two.toml"), SCENE).unwrap();
    std::fs::write(b.join("two.toml"), SCENE).unwrap();
    let csv = dir.join("out.csv");
    let out = toolkit(&[
        "compare",
        a.join("two.toml").to_str().unwrap(),
        b.join("two.toml").to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("a/two.toml") && err.contains("b/two.toml") && err.contains("`two`"), "{err}");
    assert!(!csv.exists());
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

/// Without inputs, compare runs every scene under `data/scenes` (relative to the working
/// folder), class folders included (a link loop among them walked once), each row naming
/// its class; two scenes of one stem in different folders are refused.
#[test]
fn default_inputs_are_searched_recursively_with_their_class() {
    // One level down, so that `../shared` (where compare also looks for the bunny) is the
    // test's own empty folder, never a `shared` beside the system's temporary folder.
    let dir = temp_dir("default_inputs").join("work");
    let scenes = dir.join("data/scenes");
    std::fs::create_dir_all(scenes.join("blend")).unwrap();
    std::fs::write(scenes.join("top.toml"), SCENE).unwrap();
    std::fs::write(scenes.join("blend/inner.toml"), SCENE).unwrap();
    // A link back up the tree is walked once, not followed round and round.
    std::os::unix::fs::symlink(&scenes, scenes.join("blend/loop")).unwrap();
    let run = |csv: &str| {
        Command::new(env!("CARGO_BIN_EXE_toolkit"))
            .current_dir(&dir)
            .args(["compare", "--csv", csv, "--res", "8", "--frames", "1", "--quiet"])
            .args(["--sdf-tolerance-px", "1", "--sdf-relax", "1"])
            .output()
            .unwrap()
    };
    let out = run("a.csv");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = read_rows(&dir.join("a.csv")).unwrap();
    let mut classes: Vec<(String, String)> =
        rows.iter().map(|r| (r.input.clone(), r.class.clone())).collect();
    classes.dedup();
    assert_eq!(classes, vec![("inner".into(), "blend".into()), ("top".into(), "scenes".into())]);
    std::fs::write(scenes.join("blend/top.toml"), SCENE).unwrap();
    let out = run("b.csv");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("`top`"));
}

/// The toolkit counts heap bytes per run (its allocator, `sdfmesh::base::heap`): every row
/// has a peak, reset per run, and a run that built a BVH or a grid held at least the bytes it
/// declares for it while it rendered.
#[test]
fn heap_peak_is_measured_per_run_and_covers_the_declared_bytes() {
    let dir = temp_dir("heap_peak");
    let scene = dir.join("two.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let csv = dir.join("rows.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_toolkit"))
        .args(["compare", "--csv"])
        .arg(&csv)
        .arg(&scene)
        .args(["--res", "16,32", "--frames", "1", "--quiet", "--no-decimate"])
        .args(["--sdf-tolerance-px", "1", "--sdf-relax", "1"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = read_rows(&csv).unwrap();
    assert!(rows.len() > 3);
    for r in &rows {
        let heap = r.peak_heap_bytes.unwrap_or_else(|| panic!("{}: no heap peak", r.method));
        assert!(heap > 0, "{}/{}", r.repr, r.method);
        if r.repr == "mesh" || r.repr == "grid" {
            let declared = r.accel_bytes + r.geometry_bytes;
            assert!(
                heap >= declared,
                "{}/{} at {:?}: heap peak {heap} below the declared {declared} bytes",
                r.repr,
                r.method,
                r.resolution
            );
        }
    }
    // Reset per run: a run at resolution 16 does not inherit the peak of an earlier run at 32.
    let peaks: Vec<u64> = rows.iter().filter_map(|r| r.peak_heap_bytes).collect();
    let smallest = *peaks.iter().min().unwrap();
    let largest = *peaks.iter().max().unwrap();
    assert!(smallest < largest, "every run reports the same heap peak {smallest}");
}

/// `compare --search`: each family's knob is searched to the levels, so the smallest mesh
/// resolution meeting a level is at most (here, for some level, below) what the quick
/// study's fixed list 16,32,48 finds; every candidate's row says which step ran it; the
/// candidate counts are reported; a budget stop is recorded as such.
#[test]
fn search_finds_smaller_meshes_than_a_fixed_list() {
    let dir = temp_dir("search");
    let scene = dir.join("two.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let (searched, fixed) = (dir.join("search.csv"), dir.join("fixed.csv"));
    let out = run_compare(&scene, &searched, &["--search"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let out = run_compare(&scene, &fixed, &["--res", "16,32,48"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (s, f) = (read_rows(&searched).unwrap(), read_rows(&fixed).unwrap());
    // The smallest resolution of `method` meeting `level` among `rows`.
    let smallest = |rows: &[Row], method: &str, level: f64| {
        rows.iter()
            .filter(|r| r.method == method && r.quality_px.is_some_and(|q| q <= level))
            .filter_map(|r| r.resolution)
            .min()
    };
    let mut below = 0;
    for method in ["parametric", "extracted"] {
        for level in [2.0, 1.0, 0.5] {
            let (a, b) = (smallest(&s, method, level), smallest(&f, method, level));
            if let Some(b) = b {
                let a =
                    a.unwrap_or_else(|| panic!("{method} {level} px: the search found none, the list {b}"));
                assert!(a <= b, "{method} {level} px: search {a}, fixed list {b}");
                below += usize::from(a < b);
            }
        }
    }
    assert!(below > 0, "the search found no smaller mesh than the fixed list");
    // Every searched candidate notes its step and level; no knob is run twice.
    let candidates: Vec<&Row> =
        s.iter().filter(|r| r.note.contains("search=double") || r.note.contains("search=bisect")).collect();
    assert!(candidates.iter().any(|r| r.note.contains("search=bisect level=")));
    let mut keys: Vec<_> = s.iter().map(Row::key).collect();
    keys.sort();
    keys.dedup();
    assert_eq!(keys.len(), s.len(), "a configuration ran twice");
    // The count is reported and matches the rows.
    let line = stdout.lines().find(|l| l.starts_with("search: two: ")).expect("the search's count line");
    let n: usize = line["search: two: ".len()..].split(' ').next().unwrap().parse().unwrap();
    assert_eq!(n, candidates.len(), "{line}");
    // Raster twins of the chosen mesh runs.
    assert!(s.iter().any(|r| r.method == "parametric-raster" && r.note.contains("search=twin")));
    // A tight budget stops the mesh search: the report and the last row say so. (At 48x40
    // the gates are the 128x128 ones, looser than 256x256's: with 100 KiB a 12-segment mesh
    // fits and meets 0.5 px; with 80 KiB only 8 segments do.)
    let tight = dir.join("tight.csv");
    let out = toolkit(&[
        "--max-memory",
        "80KiB",
        "compare",
        scene.to_str().unwrap(),
        "--csv",
        tight.to_str().unwrap(),
        "--search",
        "--frames",
        "1",
        "--surface-samples",
        "2000",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("mesh/parametric 0.5 px: budget"));
    let rows = read_rows(&tight).unwrap();
    // The last knob the budget allowed: `unmet=budget`, or `last=budget` where it met its own
    // level (here 8 segments meet 1 px).
    assert!(
        rows.iter().any(|r| r.method == "parametric"
            && (r.note.contains("unmet=budget") || r.note.contains("last=budget"))),
        "{rows:?}"
    );
    // A cap stops it likewise.
    let capped = dir.join("capped.csv");
    let out = run_compare(&scene, &capped, &["--search", "--search-max-res", "10"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("mesh/parametric 0.5 px: cap (largest tried 10)"));
    // A duel re-times searched runs by their labels.
    let duel = dir.join("duel.csv");
    let out = run_compare(
        &scene,
        &duel,
        &[
            "--search",
            "--duel",
            "mesh/parametric/20,sdf/sphere-trace@0.5:1.6,mesh/extracted-raster/12",
            "--rounds",
            "1",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// A mesh candidate whose extraction came out empty is sphere traced and counts for no side,
/// so it meets no level of its family: the search goes on to finer resolutions, where the
/// thin shell (0.02 thick) is extracted and traced as a mesh, instead of stopping at the
/// sphere-traced stand-in's quality.
#[test]
fn search_does_not_stop_at_a_fallback() {
    let dir = temp_dir("search-fallback");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/thin/thin_shell.toml");
    let csv = dir.join("s.csv");
    let out =
        run_compare(&scene, &csv, &["--search", "--search-max-res", "64", "--width", "48", "--height", "48"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = read_rows(&csv).unwrap();
    let extracted: Vec<&Row> =
        rows.iter().filter(|r| r.asked_repr == "mesh" && r.method == "extracted").collect();
    assert!(extracted.iter().any(|r| r.repr != "mesh"), "no fallback at a coarse resolution: {extracted:?}");
    assert!(
        extracted.iter().any(|r| r.repr == "mesh" && r.resolution > Some(16)),
        "the search stopped at the fallback: {extracted:?}"
    );
}

/// `compare --summarize` summarises every row already in the CSV: two replicates written by
/// two processes give one summary over both (`replicates: 2`), and a missing CSV is a one-line
/// error naming it.
#[test]
fn summarize_covers_every_replicate_in_the_csv() {
    let dir = temp_dir("summarize");
    let scene = dir.join("two.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let csv = dir.join("c.csv");
    for rep in ["0", "1"] {
        let out = run_compare(&scene, &csv, &["--replicate", rep, "--resume"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let json = dir.join("s.json");
    let out = toolkit(&[
        "compare",
        "--summarize",
        "--csv",
        csv.to_str().unwrap(),
        "--summary-json",
        json.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let inputs = v["inputs"].as_array().unwrap();
    assert_eq!(inputs.len(), 1, "{v}");
    assert_eq!(inputs[0]["replicates"], 2, "{v}");
    // The CSV is an input: --summary-json may not overwrite it.
    let out = toolkit(&[
        "compare",
        "--summarize",
        "--csv",
        csv.to_str().unwrap(),
        "--summary-json",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(read_rows(&csv).unwrap().len() > 2, "the CSV was overwritten");
    let missing = dir.join("none.csv");
    let out = toolkit(&["compare", "--summarize", "--csv", missing.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("none.csv") && err.trim().lines().count() == 1, "{err}");
}
