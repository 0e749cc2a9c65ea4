//! The hard-case suite of `data/hard` (see `sdfmesh::compare::hard` and `data/hard/README.md`):
//! every case in every representation meets its stated tolerance, or misses it where the
//! manifest records a known limit; an outcome that differs from the manifest fails here.
//! Cases whose input is a shared mesh that is not on this machine are skipped (and listed).

use std::path::Path;

use sdfmesh::compare::hard::{Expect, hard_command, load_cases};
use sdfmesh::plan::budget::MemoryBudget;

use crate::util::toolkit;

#[test]
fn every_hard_case_has_its_expected_outcome() {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/hard/cases.toml");
    let (table, as_expected) = hard_command(&manifest, None, &MemoryBudget::machine_default()).unwrap();
    println!("{table}");
    assert!(as_expected, "outcomes differ from data/hard/cases.toml:\n{table}");
    // Every case ran or was skipped for a missing shared mesh, and the table has a row per
    // (case, representation).
    let cases = load_cases(&manifest).unwrap();
    for c in &cases {
        let rows = table.lines().filter(|l| l.starts_with(&format!("| {} |", c.name))).count();
        assert!(
            rows == c.expect.len() || table.contains(&format!("| {} | all | - | - | skipped", c.name)),
            "{}",
            c.name
        );
    }
    // The suite states known limits, not only passes.
    assert!(cases.iter().flat_map(|c| c.expect.values()).any(|e| *e == Expect::Fail));
}

#[test]
fn a_bad_manifest_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let m = dir.path().join("cases.toml");
    let case = |extra: &str| {
        format!("[[case]]\nname = \"x\"\ninput = \"x.toml\"\nabout = \"\"\nmetric = \"pixels\"\n{extra}\n")
    };
    for (text, needle) in [
        (case("tolerance = 1.5\nexpect = { sdf = \"pass\" }"), "tolerance"),
        (case("tolerance = 0.9\nexpect = { raytrace = \"pass\" }"), "unknown representation 'raytrace'"),
        (case("tolerance = 0.9\nresolution = 0\nexpect = { sdf = \"pass\" }"), "resolution"),
        (case("tolerance = 0.9\nexpect = { sdf = \"maybe\" }"), "maybe"),
        (case("tolerance = 0.9\ncolour = 1\nexpect = { sdf = \"pass\" }"), "colour"),
    ] {
        std::fs::write(&m, text).unwrap();
        let e = load_cases(&m).unwrap_err().to_string();
        assert!(e.contains("cases.toml") && e.contains(needle), "{e}");
    }
}

/// The broken meshes of the suite (open, self-intersecting, a triangle soup) also go
/// through `convert` (both fills: voxelizing refuses open ones with a clear error) and
/// `compare` (rows for every run, a clean skip message for a refused one), never a panic.
#[test]
fn broken_meshes_convert_and_compare_cleanly() {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes");
    let dir = tempfile::tempdir().unwrap();
    let mut ran = 0;
    for name in ["suzanne.obj", "trimesh_bunny.ply", "trimesh_soup.obj"] {
        let mesh = shared.join(name);
        if !mesh.exists() {
            eprintln!("skipped {name}: {} not found", mesh.display());
            continue;
        }
        ran += 1;
        let mesh = mesh.to_str().unwrap();
        let sdf = dir.path().join(format!("{name}.sdf"));
        let o = toolkit(&["convert", mesh, "--to", "grid", "--res", "16", "-o", sdf.to_str().unwrap()]);
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(sdfmesh::geometry::grid::io::load_grid(&sdf).is_ok(), "{name}");
        let vox = dir.path().join(format!("{name}.vox.sdf"));
        let o = toolkit(&[
            "convert",
            mesh,
            "--to",
            "grid",
            "--fill",
            "voxelize",
            "--res",
            "16",
            "-o",
            vox.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success() || (o.status.code() == Some(2) && err.contains(name)), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
        let csv = dir.path().join(format!("{name}.csv"));
        let o = toolkit(&["compare", mesh, "--csv", csv.to_str().unwrap(), "--res", "8", "--frames", "1"]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
        let rows = std::fs::read_to_string(&csv).unwrap().lines().count();
        assert!(rows >= 4, "{name}: {rows} lines in the CSV");
    }
    eprintln!("{ran} broken meshes converted and compared");
}
