//! Helpers shared by the fuzz targets in `fuzz_targets/`: the properties every loader must
//! keep on any input (an `Ok` meets the type's invariants; an `Err` is one line that names
//! the file), and a per-process scratch folder for the loaders that read from a path.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use sdfmesh::error::Error;
use sdfmesh::geometry::grid::SdfGrid;
use sdfmesh::mesh::{LoadReport, MeshFormat, TriangleMesh, is_degenerate, load_mesh_bytes};

/// A folder of this process's own (created once, empty at first, removed by nobody: the
/// fuzzer runs until it is killed), under `/dev/shm` when that exists so that writing an
/// input costs no disk I/O.
pub fn scratch_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let shm = Path::new("/dev/shm");
        let base = if shm.is_dir() { shm.to_path_buf() } else { std::env::temp_dir() };
        let dir = base.join(format!("sdfmesh-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("create the fuzz scratch folder");
        dir
    })
}

/// Writes `data` to the scratch file `input.<ext>` and returns its path.
pub fn scratch_file(ext: &str, data: &[u8]) -> PathBuf {
    let path = scratch_dir().join(format!("input.{ext}"));
    std::fs::write(&path, data).expect("write the fuzz input");
    path
}

/// An error must name the file and fit on one line (the crate's error contract).
pub fn check_error(path: &Path, e: &Error) {
    let msg = e.to_string();
    let name = path.display().to_string();
    let Some(rest) = msg.strip_prefix(&name) else {
        panic!("error does not start with the file name: {msg}");
    };
    // The file name itself may hold anything (a scene names its meshes).
    assert!(!rest.contains('\n'), "error is more than one line: {msg:?}");
    assert_eq!(e.exit_code(), 2, "{msg}");
}

/// Checks what a mesh loader returned: a mesh meeting the [`TriangleMesh`] invariants
/// (and at least one triangle, none degenerate, every vertex used) with a consistent
/// report, or a well-formed error.
pub fn check_mesh_result(path: &Path, result: &sdfmesh::error::Result<(TriangleMesh, LoadReport)>) {
    let (mesh, report) = match result {
        Ok(r) => r,
        Err(e) => return check_error(path, e),
    };
    if let Err(msg) = mesh.validate() {
        panic!("loaded mesh breaks an invariant: {msg}");
    }
    assert!(!mesh.triangles.is_empty(), "loaded mesh has no triangles");
    let mut used = vec![false; mesh.positions.len()];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        assert!(!is_degenerate(a, b, c), "degenerate triangle {t:?} kept");
        for &i in t {
            used[i as usize] = true;
        }
    }
    assert!(used.iter().all(|&u| u), "an unreferenced vertex was kept");
    assert_eq!(
        report.triangles_read,
        mesh.triangles.len() + report.degenerate_dropped,
        "report does not add up: {report}"
    );
}

/// Loads `data` as a mesh of `format` through [`load_mesh_bytes`] and checks the result.
/// The path lies in the (empty) scratch folder, so a glTF's relative buffer URIs find
/// nothing.
pub fn fuzz_mesh(data: &[u8], format: MeshFormat, ext: &str) {
    let path = scratch_dir().join(format!("input.{ext}"));
    let result = load_mesh_bytes(&path, data.to_vec(), format);
    check_mesh_result(&path, &result);
}

/// Checks what the grid reader returned: a grid with at least 2 samples per axis, as many
/// values as samples, no NaN, a finite origin and a finite voxel `> 0`; or a well-formed
/// error.
pub fn check_grid_result(path: &Path, result: &sdfmesh::error::Result<SdfGrid>) {
    let grid = match result {
        Ok(g) => g,
        Err(e) => return check_error(path, e),
    };
    let d = grid.dims;
    assert!(d.min_element() >= 2, "dims {d} below 2");
    let n = d.x as u128 * d.y as u128 * d.z as u128;
    assert_eq!(grid.values.len() as u128, n, "values do not match dims {d}");
    assert!(grid.values.iter().all(|v| !v.is_nan()), "NaN sample accepted");
    assert!(grid.origin.is_finite(), "origin {} not finite", grid.origin);
    assert!(grid.voxel.is_finite() && grid.voxel > 0.0, "voxel {} invalid", grid.voxel);
}

/// Writes `data` to a scratch file with extension `ext`, loads it with
/// [`sdfmesh::geometry::grid::io::load_grid`] and checks the result.
pub fn fuzz_grid(data: &[u8], ext: &str) {
    let path = scratch_file(ext, data);
    let result = sdfmesh::geometry::grid::io::load_grid(&path);
    check_grid_result(&path, &result);
}

/// Parses `data` (UTF-8 only) as a `.vm` implicit model with [`sdfmesh::implicit::parse_vm`]:
/// an error must be one line naming the file; a model must be in SSA order (every argument
/// names an earlier clause), and a small one is also prepared for ray casting (intervals,
/// shortening, Lipschitz bounds over 2^3 cells) and cast one ray through, which must not
/// panic and must report a hit inside the ray's range.
pub fn fuzz_vm(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let path = Path::new("fuzz.vm");
    let ssa = match sdfmesh::implicit::parse_vm(text, path) {
        Ok(s) => s,
        Err(e) => return check_error(path, &e),
    };
    assert!(!ssa.clauses.is_empty(), "a model without clauses was accepted");
    for (i, c) in ssa.clauses.iter().enumerate() {
        let k = c.op.arity();
        assert!(k < 1 || (c.a as usize) < i, "clause {i} reads a later clause");
        assert!(k < 2 || (c.b as usize) < i, "clause {i} reads a later clause");
    }
    let _ = ssa.eval_f64([0.25, -0.5, 0.75]);
    if ssa.clauses.len() <= 2000 {
        use sdfmesh::implicit::field3d::{Field3, RayWork, Scratch};
        let field = Field3::new(ssa, 2);
        let (mut s, mut w) = (Scratch::default(), RayWork::default());
        let o = glam::DVec3::new(0.3, 0.2, 4.0);
        let d = glam::DVec3::new(-0.1, 0.05, -1.0);
        if let Some(h) = field.first_root(o, d, 0.0, 10.0, 1e-3, 1e-3, &mut s, &mut w) {
            assert!((0.0..=10.0).contains(&h.t), "hit at {} outside the ray's range", h.t);
        }
    }
}
