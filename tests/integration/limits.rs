//! Limits on what an input can make the toolkit do (issue 32): nested repetitions are
//! refused by the evaluation budget before anything is built (in every representation and
//! in `convert`), the tape compiler stops at its length limit instead of unrolling, a
//! sphere traced object's tape is counted in the memory estimate, `--max-memory` above the
//! machine's memory is refused, deep nesting is refused by the scene parser, two `compare`
//! processes on one new CSV keep every row whole and once, and one bad input of a batch
//! (`compare`, `gallery`, `hard`) fails only itself.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use sdfmesh::compare::{Row, read_rows};
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::geometry::sdf::tape::{Op, Tape};
use sdfmesh::geometry::sdf::{MAX_TAPE_OPS, SdfField, SdfTree};
use sdfmesh::plan::budget::{MAX_EVALUATIONS_PER_DISTANCE, MemoryBudget, object_evaluations, scene_bytes};
use sdfmesh::plan::{GridFill, GridStorage, MeshMethod, Representation, plan_object};
use sdfmesh::scene::load_scene;
use sdfmesh::scene::shape::Shading;

use crate::util::{put, temp_dir, toolkit};

const HEAD: &str = r#"
[camera]
position = [0, 2, -8]
look_at = [0, 0, 0]
fov = 45
width = 32
height = 24

[[lights]]
type = "ambient"
intensity = 0.5
"#;

/// A scene of `levels` nested finite repetitions of `count` copies each along x (period
/// 0.5) around a sphere of radius 1, which overlaps its neighbours (no cell gap): every
/// level doubles the primitives one distance evaluates, and the tape's length.
fn nested_repeats(levels: usize, count: &str) -> String {
    let mut s = format!("{HEAD}\n[[objects]]\n");
    let mut table = String::from("objects");
    for i in 0..levels {
        if i > 0 {
            s.push_str(&format!("[{table}]\n"));
        }
        s.push_str(&format!("type = \"repeat\"\nperiod = [0.5, 0, 0]\ncount = {count}\n\n"));
        table.push_str(".child");
    }
    s.push_str(&format!("[{table}]\ntype = \"sphere\"\nradius = 1.0\n"));
    s
}

fn reprs() -> [Representation; 4] {
    let march = MarchParams::default();
    [
        Representation::Analytic { march },
        Representation::Sdf { march },
        Representation::Mesh {
            resolution: 16,
            shading: Shading::Flat,
            method: MeshMethod::Parametric,
            plane: sdfmesh::plan::MeshPlane::ClosedForm,
            march,
        },
        Representation::Grid { resolution: 16, fill: GridFill::Sample, storage: GridStorage::Dense, march },
    ]
}

/// The 3 KB scene of 40 nested repetitions of 2 copies (2^40 primitives per distance,
/// which reached 8 GB in 18 s before) is refused at once in every representation and by
/// `convert --to mesh`, naming the evaluation budget, with no output written.
#[test]
fn nested_repeats_are_refused_at_once() {
    let dir = temp_dir("nested");
    let scene = put(&dir, "nested.toml", nested_repeats(40, "[2, 1, 1]"));
    let png = dir.join("out.png");
    let obj = dir.join("out.obj");
    let s = scene.to_str().unwrap();
    let mut runs: Vec<Vec<&str>> = ["analytic", "sdf", "mesh", "grid"]
        .iter()
        .map(|r| vec!["render", s, "--repr", r, "-o", png.to_str().unwrap()])
        .collect();
    runs.push(vec!["convert", s, "--to", "mesh", "--res", "16", "-o", obj.to_str().unwrap()]);
    for args in &runs {
        let start = Instant::now();
        let out = toolkit(args);
        let took = start.elapsed();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("evaluation budget") && err.contains("2^40"), "{args:?}: {err}");
        assert!(err.contains("nested.toml") && err.trim().lines().count() == 1, "{args:?}: {err}");
        assert!(took < Duration::from_secs(5), "{args:?}: took {took:?} to refuse");
    }
    assert!(!png.exists() && !obj.exists());
}

/// The limit is far above every scene the project ships: none comes within 2^6 of it in
/// any representation, so it refuses only runaway nesting.
#[test]
fn every_shipped_scene_is_far_within_the_evaluation_budget() {
    fn collect(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                collect(&p, out);
            } else if p.extension().is_some_and(|x| x == "toml")
                // Hard-case manifests (cases.toml, tiny_cases.toml) are not scenes.
                && !p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.ends_with("cases.toml"))
            {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    collect(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/data")), &mut files);
    assert!(files.len() > 20, "{} scenes", files.len());
    let mut most = (0.0f64, String::new());
    for f in &files {
        let scene = load_scene(f).unwrap_or_else(|e| panic!("{e}"));
        for repr in reprs() {
            for o in &scene.objects {
                let n = object_evaluations(o, &plan_object(&scene, o, repr));
                if n > most.0 {
                    most = (n, format!("{} {} '{}'", f.display(), repr.name(), o.label));
                }
            }
        }
    }
    eprintln!("most primitives per distance: {} ({})", most.0, most.1);
    assert!(most.0 >= 8.0, "the count sees repetitions and CSG: {most:?}");
    assert!(most.0 * 64.0 <= MAX_EVALUATIONS_PER_DISTANCE, "{most:?}");
}

/// The tape compiler stops at the limit instead of unrolling every copy: 30 nested
/// repetitions of one copy still unroll 2 cells per level (2^30 copies) and are abandoned
/// at once; below the limit `compile_within` is `compile`. The evaluation count sees that
/// a single copy along an axis evaluates one cell.
#[test]
fn tape_compilation_stops_at_its_limit() {
    let dir = temp_dir("tape");
    let scene = load_scene(&put(&dir, "deep.toml", nested_repeats(30, "[1, 1, 1]"))).unwrap();
    let o = &scene.objects[0];
    let tree = SdfTree::for_marching(o).unwrap();
    assert_eq!(tree.evaluations(), 1.0);
    let start = Instant::now();
    assert!(Tape::compile_within(&tree, o.bounds(), MAX_TAPE_OPS).is_none());
    let field = SdfField::new(o, o.bounds()).unwrap();
    assert!(field.tape.is_none());
    assert!(start.elapsed() < Duration::from_secs(2), "{:?}", start.elapsed());
    // Shallow enough: the same tape either way.
    let scene = load_scene(&put(&dir, "shallow.toml", nested_repeats(4, "[2, 1, 1]"))).unwrap();
    let o = &scene.objects[0];
    let tree = SdfTree::for_marching(o).unwrap();
    assert_eq!(tree.evaluations(), 16.0);
    let whole = Tape::compile(&tree, o.bounds());
    let within = Tape::compile_within(&tree, o.bounds(), MAX_TAPE_OPS).unwrap();
    assert_eq!(whole.ops(), within.ops());
    assert!(Tape::compile_within(&tree, o.bounds(), whole.ops().len() - 1).is_none());
    // Counted in the memory estimate of a sphere traced object, bounded by the limit.
    let bytes = scene_bytes(&scene, reprs()[1]);
    assert!(bytes >= std::mem::size_of_val(whole.ops()) as u64, "{bytes}");
    let deep = load_scene(&put(&dir, "deep2.toml", nested_repeats(60, "[1, 1, 1]"))).unwrap();
    assert!(scene_bytes(&deep, reprs()[1]) <= (MAX_TAPE_OPS * size_of::<Op>()) as u64);
}

/// `--max-memory` above the machine's physical memory is refused (exit 2, a clear message),
/// not accepted and then failed in the middle.
#[test]
fn max_memory_above_physical_memory_is_refused() {
    let dir = temp_dir("max_memory");
    let scene = put(&dir, "s.toml", nested_repeats(1, "[2, 1, 1]"));
    let png = dir.join("out.png");
    let out =
        toolkit(&["--max-memory", "1EB", "render", scene.to_str().unwrap(), "-o", png.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("1EB") && err.contains("physical memory"), "{err}");
    assert!(!png.exists());
    if let Some(total) = sdfmesh::plan::budget::machine_total() {
        assert!(format!("{}", total + 1).parse::<MemoryBudget>().is_err());
        let out = toolkit(&[
            "--max-memory",
            &format!("{}", total / 2),
            "render",
            scene.to_str().unwrap(),
            "-o",
            png.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
}

/// Nesting deeper than the scene parser allows (10,000 nested unions, 200 nested
/// repetitions) is a one-line error, not a stack overflow.
#[test]
fn deep_nesting_is_refused_by_the_parser() {
    let dir = temp_dir("deep");
    let mut u = String::from("{ type = \"sphere\", radius = 1.0 }");
    for _ in 0..10_000 {
        u = format!("{{ type = \"union\", children = [{u}, {{ type = \"sphere\", radius = 0.5 }}] }}");
    }
    let unions =
        put(&dir, "unions.toml", format!("{HEAD}\n[[objects]]\ntype = \"union\"\nchildren = [{u}]\n"));
    let repeats = put(&dir, "repeats.toml", nested_repeats(200, "[1, 1, 1]"));
    let png = dir.join("out.png");
    for scene in [&unions, &repeats] {
        let out = toolkit(&["render", scene.to_str().unwrap(), "-o", png.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("recursion"), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
}

const SMALL: &str = r#"
[camera]
position = [0, 1, -5]
look_at = [0, 0, 0]
width = 32
height = 24

[[lights]]
type = "ambient"
intensity = 0.3

[[objects]]
type = "sphere"
radius = 1

[[objects]]
type = "box"
half_size = [0.5, 0.5, 0.5]
translate = [1.5, 0, 0.5]
"#;

fn compare_args<'a>(inputs: &[&'a str], csv: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["compare"];
    args.extend_from_slice(inputs);
    args.extend_from_slice(&["--csv", csv, "--res", "8,12", "--frames", "1", "--surface-samples", "500"]);
    args.extend_from_slice(&["--quiet"]);
    args.extend_from_slice(extra);
    args
}

/// Every line of `csv` is a whole row of the schema, and no key is there twice.
fn whole_rows(csv: &Path) -> Vec<Row> {
    let rows = read_rows(csv).unwrap_or_else(|e| panic!("{e}"));
    let text = std::fs::read_to_string(csv).unwrap();
    assert!(text.ends_with('\n'));
    assert_eq!(text.lines().count(), rows.len() + 1, "every line a row");
    let mut keys: Vec<_> = rows.iter().map(Row::key).collect();
    keys.sort();
    keys.dedup();
    assert_eq!(keys.len(), rows.len(), "a row twice");
    rows
}

/// Two `compare --resume` processes with different replicates creating one new CSV at the
/// same time: both succeed, and every row of both is there once and whole (the second
/// waits for the first's lock, then appends). Without `--resume` a second writer is refused
/// at once (exit 2), and `--overwrite` does not truncate a CSV another process holds.
#[test]
fn concurrent_compares_keep_every_row() {
    let dir = temp_dir("concurrent");
    let scene = put(&dir, "small.toml", SMALL);
    let csv = dir.join("out.csv");
    let (s, c) = (scene.to_str().unwrap(), csv.to_str().unwrap());
    let spawn = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_toolkit"))
            .args(compare_args(&[s], c, extra))
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let a = spawn(&["--resume", "--replicate", "1"]);
    let b = spawn(&["--resume", "--replicate", "2"]);
    for child in [a, b] {
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let rows = whole_rows(&csv);
    let per = |r: u32| rows.iter().filter(|row| row.replicate == r).count();
    assert!(per(1) > 5 && per(1) == per(2), "{} and {} rows", per(1), per(2));
    let before = std::fs::read(&csv).unwrap();

    // A writer that holds the CSV (a bigger image, so that it runs a while).
    let big = put(
        &dir,
        "big.toml",
        SMALL.replace("width = 32", "width = 640").replace("height = 24", "height = 480"),
    );
    let holder = Command::new(env!("CARGO_BIN_EXE_toolkit"))
        .args(["compare", big.to_str().unwrap(), "--csv", c, "--res", "8,12,16", "--frames", "5", "--quiet"])
        .args(["--resume", "--replicate", "3"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Wait until it has the lock: its first row is written under it.
    let start = Instant::now();
    while std::fs::read(&csv).unwrap().len() == before.len() {
        assert!(start.elapsed() < Duration::from_secs(120), "the holder wrote no row");
        std::thread::sleep(Duration::from_millis(10));
    }
    for extra in [&["--replicate", "4"][..], &["--overwrite"][..]] {
        let out = toolkit(&compare_args(&[s], c, extra));
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains("another process"), "{extra:?}: {err}");
    }
    let out = holder.wait_with_output().unwrap();
    assert!(out.status.success(), "the holder failed");
    let rows = whole_rows(&csv);
    assert!(std::fs::read(&csv).unwrap().starts_with(&before), "the earlier rows were kept");
    assert!(rows.iter().any(|r| r.replicate == 3) && !rows.iter().any(|r| r.replicate == 4));
}

/// A batch with a bad input in the middle (a file that does not parse, and a scene over
/// the evaluation budget): the inputs after it still run, the failures are named on
/// stderr, and the exit code says that something failed.
#[test]
fn one_bad_input_fails_only_itself() {
    let dir = temp_dir("batch");
    let scenes = dir.join("scenes");
    std::fs::create_dir_all(&scenes).unwrap();
    let a = put(&scenes, "a.toml", SMALL);
    let b = put(&scenes, "b.toml", "[camera\n");
    let n = put(&scenes, "n.toml", nested_repeats(40, "[2, 1, 1]"));
    let z = put(&scenes, "z.toml", SMALL);
    let csv = dir.join("out.csv");
    let inputs: Vec<&str> = [&a, &b, &n, &z].iter().map(|p| p.to_str().unwrap()).collect();
    let out = toolkit(&compare_args(&inputs, csv.to_str().unwrap(), &[]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("b.toml:1") && err.contains("evaluation budget"), "{err}");
    assert!(err.contains("2 of 4 inputs failed"), "{err}");
    let rows = whole_rows(&csv);
    let of = |name: &str| rows.iter().filter(|r| r.input == name).count();
    assert!(of("a") > 5 && of("z") == of("a") && of("b") == 0 && of("n") == 0, "{}", rows.len());
    assert!(String::from_utf8_lossy(&out.stdout).contains("z (reference"), "the summary is printed");

    // gallery: the pictures of the scene after the bad ones are written.
    let gallery = dir.join("gallery");
    let out = toolkit(&["gallery", scenes.to_str().unwrap(), "-o", gallery.to_str().unwrap(), "--res", "8"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("2 of 4 scenes failed"), "{err}");
    for r in ["analytic", "sdf", "mesh", "grid"] {
        assert!(gallery.join(format!("z.{r}.png")).exists(), "{r}");
        assert!(!gallery.join(format!("n.{r}.png")).exists(), "{r}");
    }

    // hard: a case that cannot run is in the table, the case after it still runs.
    let case = |name: &str, input: &str| {
        format!(
            "[[case]]\nname = \"{name}\"\ninput = \"{input}\"\nabout = \"x\"\nmetric = \"silhouette\"\n\
             tolerance = 0.5\nresolution = 16\nexpect = {{ sdf = \"pass\" }}\n\n"
        )
    };
    let manifest = put(
        &scenes,
        "cases.toml",
        format!("{}{}{}", case("bad", "b.toml"), case("nested", "n.toml"), case("good", "z.toml")),
    );
    let out = toolkit(&["hard", manifest.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{text} {}", String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("| good | sdf |"), "{text}");
    assert!(text.contains("| bad | all |") && text.contains("| nested | all |"), "{text}");
}
