//! Honest fallbacks in `toolkit compare` (issue 34, item 3): a run in which an object is
//! traced in another representation than the one asked records what traced it (`repr`)
//! beside what was asked (`asked_repr`), its note names the true cause, and the summary
//! never counts it for the asked side; CSVs of schema 2 (no `asked_repr`, no
//! `peak_heap_bytes`) still read.

use std::path::Path;

use sdfmesh::compare::{COLUMNS, Row, read_rows};

use crate::util::{temp_dir, toolkit};

/// `thin/thin_shell` (a sphere shell 1.5% of its radius thick) compared at resolution 16:
/// the shell is thinner than a cell, so its extraction (the mesh representation's only way
/// to make CSG into triangles) gives no triangles and it is sphere traced.
fn thin_shell_at_16(dir: &Path) -> (Vec<Row>, serde_json::Value) {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/thin/thin_shell.toml");
    let (csv, json) = (dir.join("out.csv"), dir.join("summary.json"));
    let out = toolkit(&[
        "compare",
        scene.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
        "--summary-json",
        json.to_str().unwrap(),
        "--res",
        "16",
        "--width",
        "64",
        "--height",
        "48",
        "--frames",
        "1",
        "--surface-samples",
        "500",
        "--sdf-tolerance-px",
        "0.25",
        "--sdf-relax",
        "1",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    (read_rows(&csv).unwrap(), summary)
}

#[test]
fn an_empty_extraction_is_recorded_as_sphere_traced_and_never_counts_as_a_mesh() {
    let dir = temp_dir("thin_shell");
    let (rows, summary) = thin_shell_at_16(&dir);
    let find = |method: &str| {
        rows.iter().find(|r| r.method == method).unwrap_or_else(|| panic!("no {method} row in {rows:#?}"))
    };
    for method in ["parametric", "extracted"] {
        let r = find(method);
        assert_eq!((r.asked_repr.as_str(), r.repr.as_str()), ("mesh", "sdf"), "{r:#?}");
        assert_eq!(r.triangles, 0, "{r:#?}");
        // The true cause, not "unbounded".
        assert!(
            r.note.starts_with("1 of 1 objects not as asked: subtraction 'shell with window': extraction at 16 cells gave no triangles")
                && r.note.contains("thinner than a cell")
                && r.note.ends_with("sphere traced")
                && !r.note.contains("unbounded"),
            "{}",
            r.note
        );
    }
    // The target: no row with repr = mesh was traced by anything but triangles.
    for r in rows.iter().filter(|r| r.repr == "mesh") {
        assert!(r.triangles > 0 && r.note.is_empty(), "{r:#?}");
    }
    // Every other run is as asked.
    for r in rows.iter().filter(|r| r.asked_repr != "mesh") {
        assert_eq!(r.repr, r.asked_repr, "{r:#?}");
    }
    // The summary's best mesh run at every level is none (both mesh runs fell back), its
    // best marched run a run asked and traced by marching.
    for level in summary["inputs"][0]["levels"].as_array().unwrap() {
        assert!(level["best_mesh"].is_null(), "{level}");
        assert!(level["marched_over_mesh_time"].is_null(), "{level}");
        if let Some(run) = level["best_marched"]["run"].as_str() {
            assert!(run.starts_with("sdf/sphere-trace") || run.starts_with("grid/"), "{run}");
            assert!(!run.contains("asked"), "{run}");
        }
    }
    // The fallback runs keep their asked representation in the summary's names.
    let fastest: Vec<&str> = summary["inputs"][0]["winners"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|w| w["fastest"]["run"].as_str())
        .collect();
    assert!(
        fastest.iter().all(|r| !r.starts_with("sdf/parametric") || r.ends_with("(asked mesh)")),
        "{fastest:?}"
    );

    // The same CSV written as schema 2 (no asked_repr, no peak_heap_bytes): read with
    // asked_repr = repr and no heap peak.
    let dropped: Vec<usize> = COLUMNS
        .iter()
        .enumerate()
        .filter(|(_, c)| ["asked_repr", "peak_heap_bytes"].contains(c))
        .map(|(i, _)| i)
        .collect();
    let text = std::fs::read_to_string(dir.join("out.csv")).unwrap();
    let mut reader = csv::Reader::from_reader(text.as_bytes());
    let mut w = csv::Writer::from_writer(Vec::new());
    let drop_asked = |r: &csv::StringRecord| -> Vec<String> {
        r.iter().enumerate().filter(|(i, _)| !dropped.contains(i)).map(|(_, f)| f.to_string()).collect()
    };
    w.write_record(drop_asked(reader.headers().unwrap())).unwrap();
    for r in reader.records() {
        w.write_record(drop_asked(&r.unwrap())).unwrap();
    }
    let old = dir.join("v2.csv");
    std::fs::write(&old, w.into_inner().unwrap()).unwrap();
    let read = read_rows(&old).unwrap();
    assert_eq!(read.len(), rows.len());
    for (a, b) in read.iter().zip(&rows) {
        assert_eq!((&a.repr, &a.asked_repr), (&b.repr, &b.repr));
        assert_eq!(a.peak_heap_bytes, None);
        let filled =
            Row { asked_repr: b.asked_repr.clone(), peak_heap_bytes: b.peak_heap_bytes, ..a.clone() };
        assert_eq!(filled, *b);
    }
    // ... but never appended to: its rows would not match its header.
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/thin/thin_shell.toml");
    let out =
        toolkit(&["compare", scene.to_str().unwrap(), "--csv", old.to_str().unwrap(), "--resume", "--quiet"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("v2.csv:1:1") && err.contains("schema version 5"), "{err}");
}
