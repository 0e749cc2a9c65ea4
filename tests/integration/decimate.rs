//! Decimation with meshoptimizer (`sdfmesh::mesh::simplify`): a decimated sphere stays
//! within a bound derived from the simplifier's reported error; `convert --decimate` writes
//! the decimated mesh and refuses bad values in one line; `compare` on a mesh input adds
//! one `mesh/decimated-T` run per target, traced as triangles and smaller than the original,
//! and raster twins (`raster`, `decimated-T-raster`) with the traced runs' errors.

use std::path::Path;

use glam::{DVec3, Vec3};
use sdfmesh::compare::read_rows;
use sdfmesh::geometry::mesh::{MeshGeometry, Shading};
use sdfmesh::mesh::simplify::{DecimateTarget, NO_ERROR_LIMIT, decimate};
use sdfmesh::mesh::{TriangleMesh, load_mesh, save_mesh};
use sdfmesh::metrics::surface_distance;
use sdfmesh::scene::transform::Transform;

use crate::util::{icosphere, temp_dir, toolkit};

/// Points on a mesh's surface: its vertices, edge midpoints and triangle centroids.
fn surface_points(m: &TriangleMesh) -> Vec<DVec3> {
    let mut points: Vec<DVec3> = m.positions.iter().map(|p| p.as_dvec3()).collect();
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize].as_dvec3());
        points.extend([(a + b + c) / 3.0, (a + b) / 2.0, (b + c) / 2.0, (c + a) / 2.0]);
    }
    points
}

fn geometry(m: &TriangleMesh) -> MeshGeometry {
    MeshGeometry::new(m.clone(), Shading::Flat, Transform::IDENTITY, 0, "test".into())
}

/// The simplifier's error is measured at the kept vertices (their distance to the planes
/// of the triangles they replace); between them a new triangle bends away from the old
/// surface by at most its sagitta. On a sphere of radius `r` a chord of length `l` has a
/// sagitta of `l^2 / 8r`, and the vertex error is the distance of a vertex from the plane
/// of a replaced triangle, itself about the sagitta of the chords it spans: so the
/// Hausdorff distance stays within a few times the reported error. Checked: at most 4 times
/// the error plus the original's own sagitta (its distance from the sphere it approximates).
#[test]
fn a_decimated_sphere_stays_within_the_reported_error() {
    let sphere = icosphere(3, Vec3::ZERO, 1.0);
    let n = sphere.triangles.len();
    let original = geometry(&sphere);
    let original_points = surface_points(&sphere);
    let original_sagitta = sphere
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| sphere.positions[i as usize].as_dvec3());
            1.0 - ((a + b + c) / 3.0).length()
        })
        .fold(0.0, f64::max);
    for ratio in [0.5, 0.25, 0.1] {
        let d = decimate(&sphere, DecimateTarget::Ratio(ratio), NO_ERROR_LIMIT).unwrap();
        let got = d.mesh.triangles.len();
        assert!(got <= d.target && got + 8 >= d.target, "ratio {ratio}: {got} of {} asked", d.target);
        assert!(d.mesh.is_closed(), "ratio {ratio}: the closed sphere stays closed");
        assert!(d.mesh.normals.is_some(), "the sphere had normals: recomputed");
        let decimated = geometry(&d.mesh);
        let dist =
            surface_distance(&decimated, &surface_points(&d.mesh), &original, &original_points).unwrap();
        let bound = 4.0 * d.error as f64 + original_sagitta;
        assert!(
            dist.hausdorff <= bound,
            "ratio {ratio} ({got} of {n} triangles): Hausdorff {} > bound {bound} (meshopt error {})",
            dist.hausdorff,
            d.error
        );
        assert!(dist.hausdorff > 0.0 && d.error > 0.0);
    }
}

fn write_sphere(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("ball.obj");
    save_mesh(&icosphere(2, Vec3::ZERO, 1.0), &path).unwrap();
    path
}

#[test]
fn convert_decimates_a_mesh_file_and_refuses_bad_values_in_one_line() {
    let dir = temp_dir("convert");
    let input = write_sphere(&dir);
    let (original, _) = load_mesh(&input).unwrap();
    let out = dir.join("quarter.ply");
    let (i, o) = (input.to_str().unwrap(), out.to_str().unwrap());
    let run = toolkit(&["convert", i, "--to", "mesh", "--decimate", "25%", "-o", o]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(text.contains("decimated to 25%") && text.contains("closed: true"), "{text}");
    let (quarter, _) = load_mesh(&out).unwrap();
    let n = original.triangles.len();
    assert!(
        quarter.triangles.len() <= n / 4 && quarter.triangles.len() >= n / 4 - 8,
        "{n} -> {}",
        quarter.triangles.len()
    );
    assert!(quarter.is_closed());
    // A count as the target.
    let run = toolkit(&["convert", i, "--to", "mesh", "--decimate", "100", "-o", o]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    assert!(load_mesh(&out).unwrap().0.triangles.len() <= 100);
    let before = std::fs::read(&out).unwrap();
    for bad in ["0", "1.5", "-0.5", "150%", "half", "NaN"] {
        let run = toolkit(&["convert", i, "--to", "mesh", "--decimate", bad, "-o", o]);
        assert_eq!(run.status.code(), Some(2), "--decimate {bad}");
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(err.contains("--decimate") && err.contains(&format!("'{bad}'")), "{err}");
    }
    let grid = dir.join("g.sdf");
    let run = toolkit(&["convert", i, "--to", "grid", "--decimate", "0.5", "-o", grid.to_str().unwrap()]);
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("--decimate 50% needs --to mesh") && err.trim_end().lines().count() == 1, "{err}");
    assert!(!grid.exists());
    assert_eq!(std::fs::read(&out).unwrap(), before, "failed runs leave the output alone");
}

#[test]
fn compare_runs_each_decimation_as_a_smaller_mesh() {
    let dir = temp_dir("compare");
    let input = write_sphere(&dir);
    let csv = dir.join("out.csv");
    let args = |extra: &[&str]| {
        let mut a = vec![
            "compare",
            input.to_str().unwrap(),
            "--csv",
            csv.to_str().unwrap(),
            "--res",
            "8",
            "--frames",
            "1",
            "--surface-samples",
            "500",
            "--width",
            "40",
            "--height",
            "32",
            "--quiet",
            "--overwrite",
        ];
        a.extend_from_slice(extra);
        a.iter().map(|s| s.to_string()).collect::<Vec<_>>()
    };
    let run = |extra: &[&str]| {
        let a = args(extra);
        toolkit(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let out = run(&["--decimate", "0.5,25%,0.5,300"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = read_rows(&csv).unwrap();
    let original = rows.iter().find(|r| r.method == "original").expect("the reference");
    let decimated: Vec<_> =
        rows.iter().filter(|r| r.method.starts_with("decimated") && !r.method.ends_with("-raster")).collect();
    let methods: Vec<&str> = decimated.iter().map(|r| r.method.as_str()).collect();
    assert_eq!(methods, ["decimated-50%", "decimated-25%", "decimated-300tris"], "duplicates dropped");
    for r in &decimated {
        assert_eq!((r.repr.as_str(), r.asked_repr.as_str()), ("mesh", "mesh"), "{}", r.method);
        assert!(r.note.is_empty(), "{}: {}", r.method, r.note);
        assert!(
            r.triangles > 0 && r.triangles < original.triangles,
            "{}: {} triangles",
            r.method,
            r.triangles
        );
        assert!(r.total_bytes < original.total_bytes, "{}: {} bytes", r.method, r.total_bytes);
        assert!(r.resolution.is_none() && r.tolerance_px.is_none());
        assert!(r.build_ms > 0.0 && r.chamfer_rel.is_some_and(|c| c > 0.0));
        assert_eq!(r.reference, "mesh/original");
    }
    // The raster twins (primary visibility rasterized): the original's (`raster`) and each
    // decimation's, the same triangles and about the same errors as their traced runs, the
    // frame split into primary visibility and shading.
    for (traced, twin) in std::iter::once((original, "raster".to_string()))
        .chain(decimated.iter().map(|r| (*r, format!("{}-raster", r.method))))
    {
        let r = rows.iter().find(|r| r.method == twin).unwrap_or_else(|| panic!("no {twin} row"));
        assert_eq!((r.repr.as_str(), r.triangles), ("mesh", traced.triangles), "{twin}");
        let (p, s) = (r.primary_ms.unwrap(), r.shading_ms.unwrap());
        assert!(p > 0.0 && s >= 0.0 && p + s <= r.frame_ms_median * (1.0 + 1e-9), "{twin}: {p} + {s}");
        assert!(
            (r.image_rmse - traced.image_rmse).abs() < 0.01,
            "{twin}: {} vs {}",
            r.image_rmse,
            traced.image_rmse
        );
        let (a, b) = (r.px_err_p95.unwrap(), traced.px_err_p95.unwrap());
        assert!((a - b).abs() < 0.1, "{twin}: p95 {a} vs {b}");
        let (a, b) = (r.silhouette_mismatch_pct, traced.silhouette_mismatch_pct);
        assert!((a - b).abs() < 0.5, "{twin}: silhouette {a} vs {b}");
    }
    let by = |m: &str| decimated.iter().find(|r| r.method == m).unwrap().triangles;
    assert!(by("decimated-25%") < by("decimated-50%"));
    assert!(by("decimated-300tris") <= 300);
    // --no-decimate: none; a bad value: one line naming the flag.
    let out = run(&["--no-decimate"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(read_rows(&csv).unwrap().iter().all(|r| !r.method.starts_with("decimated")));
    let out = run(&["--decimate", "0.5,2.5"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--decimate") && err.contains("'2.5'") && err.trim_end().lines().count() == 1,
        "{err}"
    );
}
