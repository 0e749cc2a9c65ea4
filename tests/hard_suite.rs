//! The hard-case suite of `data/hard` (see `sdfmesh::hard` and `data/hard/README.md`):
//! every case in every representation meets its stated tolerance, or misses it where the
//! manifest records a known limit; an outcome that differs from the manifest fails here.
//! Cases whose input is a shared mesh that is not on this machine are skipped (and listed).

use std::path::Path;

use sdfmesh::hard::{Expect, hard_command, load_cases};

#[test]
fn every_hard_case_has_its_expected_outcome() {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/hard/cases.toml");
    let (table, as_expected) = hard_command(&manifest, None).unwrap();
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
