//! Grid files: `.sdf` round trips, the `.npy` and `.vti` layouts (checked with NumPy and
//! VTK when Python has them; set `PYTHON` to choose the interpreter, default `python3`),
//! and every load/save error.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use glam::{UVec3, Vec3};
use sdfmesh::error::Error;
use sdfmesh::geometry::grid::SdfGrid;
use sdfmesh::geometry::grid::io::{SDF_HEADER_LEN, load_grid, save_grid};

/// A small non-cubic grid with distinct values, including `-0.0` and infinities.
fn sample_grid() -> SdfGrid {
    let dims = UVec3::new(3, 4, 5);
    let n = (dims.x * dims.y * dims.z) as usize;
    let mut values: Vec<f32> = (0..n).map(|i| i as f32 * 0.25 - 7.125).collect();
    values[1] = -0.0;
    values[2] = f32::INFINITY;
    values[3] = f32::NEG_INFINITY;
    values[4] = 1e-30;
    SdfGrid { origin: Vec3::new(-1.5, 0.25, 3.0), voxel: 0.1, dims, values }
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Files in `dir` other than `keep`.
fn others(dir: &Path, keep: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !keep.contains(&n.as_str()))
        .collect();
    v.sort();
    v
}

fn python() -> String {
    std::env::var("PYTHON").unwrap_or_else(|_| "python3".into())
}

fn python_has(module: &str) -> bool {
    Command::new(python())
        .args(["-c", &format!("import {module}")])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

fn run_python(script: &str) -> String {
    let out = Command::new(python()).args(["-c", script]).output().expect("run python");
    assert!(
        out.status.success(),
        "python failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn sdf_bytes(grid: &SdfGrid) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("g.sdf");
    save_grid(grid, &p).unwrap();
    std::fs::read(&p).unwrap()
}

/// Writes `bytes` to `name` in `dir`, loads it, and checks the error: it names the file,
/// exits with code 2, is one line, and contains `needle`.
fn load_error(dir: &Path, name: &str, bytes: &[u8], needle: &str) -> Error {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    let e = load_grid(&p).expect_err("load should fail");
    check_error(&e, &p, needle);
    e
}

fn check_error(e: &Error, p: &Path, needle: &str) {
    let msg = e.to_string();
    eprintln!("{msg}");
    assert!(msg.contains(&p.display().to_string()), "message does not name the file: {msg}");
    assert!(msg.contains(needle), "message lacks {needle:?}: {msg}");
    assert!(!msg.contains('\n'), "message is not one line: {msg}");
    assert_eq!(e.exit_code(), 2, "{msg}");
}

// ---------------------------------------------------------------- .sdf

#[test]
fn sdf_round_trip_is_identical() {
    let dir = tempfile::tempdir().unwrap();
    let g = sample_grid();
    let p = dir.path().join("grid.sdf");
    save_grid(&g, &p).unwrap();
    let back = load_grid(&p).unwrap();
    assert_eq!(back.dims, g.dims);
    assert_eq!(back.origin.to_array().map(f32::to_bits), g.origin.to_array().map(f32::to_bits));
    assert_eq!(back.voxel.to_bits(), g.voxel.to_bits());
    assert_eq!(bits(&back.values), bits(&g.values));
    assert_eq!(std::fs::metadata(&p).unwrap().len(), SDF_HEADER_LEN as u64 + 4 * 60);
    assert_eq!(others(dir.path(), &["grid.sdf"]), Vec::<String>::new());

    // Saving again overwrites; upper-case extensions work too.
    let mut g2 = g.clone();
    g2.values[0] = 42.0;
    save_grid(&g2, &p).unwrap();
    assert_eq!(load_grid(&p).unwrap().values[0], 42.0);
    let upper = dir.path().join("GRID.SDF");
    save_grid(&g, &upper).unwrap();
    assert_eq!(bits(&load_grid(&upper).unwrap().values), bits(&g.values));
    assert_eq!(others(dir.path(), &["grid.sdf", "GRID.SDF"]), Vec::<String>::new());
}

#[test]
fn sdf_layout_matches_the_documented_header() {
    let g = sample_grid();
    let b = sdf_bytes(&g);
    let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let f32_at = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    assert_eq!(&b[..8], b"SDFGRID\0");
    assert_eq!(u32_at(8), 1);
    assert_eq!([u32_at(12), u32_at(16), u32_at(20)], [3, 4, 5]);
    assert_eq!([f32_at(24), f32_at(28), f32_at(32)], [-1.5, 0.25, 3.0]);
    assert_eq!(f32_at(36), 0.1);
    assert_eq!(f32_at(40), 0.0);
    // Sample (i, j, k) = (2, 1, 3) at index 2 + 3 * (1 + 4 * 3).
    let idx = 2 + 3 * (1 + 4 * 3);
    assert_eq!(f32_at(44 + 4 * idx).to_bits(), g.get(2, 1, 3).to_bits());
    assert_eq!(b.len(), 44 + 4 * 60);
}

#[test]
fn sdf_larger_than_one_chunk_round_trips() {
    let dims = UVec3::new(40, 33, 29);
    let n = (dims.x * dims.y * dims.z) as usize;
    let values: Vec<f32> = (0..n).map(|i| (i as f32).sin()).collect();
    let g = SdfGrid { origin: Vec3::ZERO, voxel: 0.5, dims, values };
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("big.sdf");
    save_grid(&g, &p).unwrap();
    assert_eq!(load_grid(&p).unwrap(), g);
}

// ---------------------------------------------------------------- .npy

#[test]
fn npy_header_and_layout() {
    let dir = tempfile::tempdir().unwrap();
    let g = sample_grid();
    let p = dir.path().join("grid.npy");
    save_grid(&g, &p).unwrap();
    let b = std::fs::read(&p).unwrap();
    assert_eq!(&b[..6], b"\x93NUMPY");
    assert_eq!(&b[6..8], &[1, 0]);
    let hlen = u16::from_le_bytes([b[8], b[9]]) as usize;
    let data_start = 10 + hlen;
    assert_eq!(data_start % 64, 0, "header not padded to 64 bytes");
    let header = std::str::from_utf8(&b[10..data_start]).unwrap();
    assert!(header.ends_with('\n'), "{header:?}");
    assert_eq!(
        header.trim_end(),
        "{'descr': '<f4', 'fortran_order': False, 'shape': (5, 4, 3), }",
        "{header:?}"
    );
    assert_eq!(b.len(), data_start + 4 * 60);
    // arr[k, j, i] = sample (i, j, k): C order of shape (nz, ny, nx).
    let at = |k: usize, j: usize, i: usize| {
        let o = data_start + 4 * ((k * 4 + j) * 3 + i);
        f32::from_le_bytes(b[o..o + 4].try_into().unwrap())
    };
    assert_eq!(at(3, 1, 2), g.get(2, 1, 3));
    assert_eq!(at(4, 3, 2), g.get(2, 3, 4));

    // Loads back with origin 0 and voxel 1.
    let back = load_grid(&p).unwrap();
    assert_eq!(back.dims, g.dims);
    assert_eq!(back.origin, Vec3::ZERO);
    assert_eq!(back.voxel, 1.0);
    assert_eq!(bits(&back.values), bits(&g.values));
    assert_eq!(others(dir.path(), &["grid.npy"]), Vec::<String>::new());
}

#[test]
fn npy_reads_back_with_numpy() {
    if !python_has("numpy") {
        eprintln!("SKIPPED npy_reads_back_with_numpy: `{} -c 'import numpy'` fails", python());
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let g = sample_grid();
    let p = dir.path().join("grid.npy");
    save_grid(&g, &p).unwrap();
    let out = run_python(&format!(
        "import numpy as np\n\
         a = np.load({:?})\n\
         print(a.dtype.str, a.shape, a.flags['C_CONTIGUOUS'])\n\
         print(repr(float(a[3, 1, 2])), repr(float(a[4, 3, 2])), repr(float(a[0, 0, 2])))",
        p.display().to_string()
    ));
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "<f4 (5, 4, 3) True", "{out}");
    assert_eq!(lines[1], format!("{:?} {:?} inf", g.get(2, 1, 3) as f64, g.get(2, 3, 4) as f64), "{out}");

    // And a file written by NumPy loads.
    let q = dir.path().join("from_numpy.npy");
    run_python(&format!(
        "import numpy as np\n\
         a = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)\n\
         np.save({:?}, a)",
        q.display().to_string()
    ));
    let h = load_grid(&q).unwrap();
    assert_eq!(h.dims, UVec3::new(4, 3, 2));
    // arr[1, 2, 3] = 1 * 12 + 2 * 4 + 3.
    assert_eq!(h.get(3, 2, 1), (12 + 2 * 4 + 3) as f32);
}

// ---------------------------------------------------------------- .vti

#[test]
fn vti_header_and_appended_data() {
    let dir = tempfile::tempdir().unwrap();
    let g = sample_grid();
    let p = dir.path().join("grid.vti");
    save_grid(&g, &p).unwrap();
    let b = std::fs::read(&p).unwrap();
    let tag = b"<AppendedData encoding=\"raw\">";
    let tag_at = b.windows(tag.len()).position(|w| w == tag).expect("AppendedData element");
    let us = tag_at + b[tag_at..].iter().position(|&c| c == b'_').expect("appended data marker");
    assert!(b[tag_at + tag.len()..us].iter().all(u8::is_ascii_whitespace));
    let xml = std::str::from_utf8(&b[..us]).unwrap();
    for needle in [
        "<?xml version=\"1.0\"?>",
        "<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">",
        "<ImageData WholeExtent=\"0 2 0 3 0 4\" Origin=\"-1.5 0.25 3\" Spacing=\"0.1 0.1 0.1\">",
        "<Piece Extent=\"0 2 0 3 0 4\">",
        "<PointData Scalars=\"sdf\">",
        "<DataArray type=\"Float32\" Name=\"sdf\" format=\"appended\" offset=\"0\"/>",
        "</PointData>",
        "</Piece>",
        "</ImageData>",
        "<AppendedData encoding=\"raw\">",
    ] {
        assert!(xml.contains(needle), "missing {needle:?} in\n{xml}");
    }
    let count = u64::from_le_bytes(b[us + 1..us + 9].try_into().unwrap());
    assert_eq!(count, 4 * 60);
    let data = &b[us + 9..us + 9 + count as usize];
    let values: Vec<f32> = data.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    assert_eq!(bits(&values), bits(&g.values));
    let tail = std::str::from_utf8(&b[us + 9 + count as usize..]).unwrap();
    assert_eq!(tail, "\n  </AppendedData>\n</VTKFile>\n");
    assert_eq!(others(dir.path(), &["grid.vti"]), Vec::<String>::new());
}

#[test]
fn vti_reads_back_with_vtk() {
    if !python_has("vtk") {
        eprintln!("SKIPPED vti_reads_back_with_vtk: `{} -c 'import vtk'` fails", python());
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let g = sample_grid();
    let p = dir.path().join("grid.vti");
    save_grid(&g, &p).unwrap();
    let out = run_python(&format!(
        "import vtk\n\
         r = vtk.vtkXMLImageDataReader()\n\
         r.SetFileName({:?})\n\
         r.Update()\n\
         assert r.GetErrorCode() == 0\n\
         im = r.GetOutput()\n\
         print(*im.GetDimensions())\n\
         print(*im.GetOrigin())\n\
         print(*im.GetSpacing())\n\
         a = im.GetPointData().GetScalars()\n\
         print(a.GetName(), a.GetNumberOfTuples(), a.GetDataTypeAsString())\n\
         print(repr(a.GetValue(2 + 3 * (1 + 4 * 3))), repr(im.GetScalarComponentAsDouble(2, 3, 4, 0)))",
        p.display().to_string()
    ));
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "3 4 5", "{out}");
    let nums = |l: &str| l.split(' ').map(|s| s.parse::<f64>().unwrap()).collect::<Vec<_>>();
    assert_eq!(nums(lines[1]), vec![-1.5, 0.25, 3.0], "{out}");
    let sp = nums(lines[2]);
    assert!(sp.iter().all(|&s| (s - 0.1).abs() < 1e-6), "{out}");
    assert_eq!(lines[3], "sdf 60 float", "{out}");
    assert_eq!(nums(lines[4]), vec![g.get(2, 1, 3) as f64, g.get(2, 3, 4) as f64], "{out}");
}

// ---------------------------------------------------------------- load errors

#[test]
fn load_wrong_magic() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = sdf_bytes(&sample_grid());
    b[0] = b'X';
    load_error(dir.path(), "magic.sdf", &b, "wrong magic");
    load_error(dir.path(), "text.sdf", b"hello", "wrong magic");
    load_error(dir.path(), "npy.npy", &b, "wrong magic");
    assert_eq!(others(dir.path(), &["magic.sdf", "text.sdf", "npy.npy"]), Vec::<String>::new());
}

#[test]
fn load_truncated() {
    let dir = tempfile::tempdir().unwrap();
    let b = sdf_bytes(&sample_grid());
    // Inside the values, inside the header, inside the magic, empty.
    load_error(dir.path(), "values.sdf", &b[..b.len() - 3], "truncated");
    load_error(dir.path(), "header.sdf", &b[..20], "truncated");
    load_error(dir.path(), "magic.sdf", &b[..5], "truncated");
    load_error(dir.path(), "empty.sdf", &[], "truncated");
    // One byte too many is reported too.
    let mut long = b.clone();
    long.push(0);
    load_error(dir.path(), "long.sdf", &long, "trailing data");

    let npy_dir = tempfile::tempdir().unwrap();
    let p = npy_dir.path().join("g.npy");
    save_grid(&sample_grid(), &p).unwrap();
    let n = std::fs::read(&p).unwrap();
    load_error(dir.path(), "values.npy", &n[..n.len() - 1], "truncated");
    load_error(dir.path(), "header.npy", &n[..40], "truncated");
    load_error(dir.path(), "pre.npy", &n[..7], "truncated");
}

#[test]
fn load_absurd_dims_fails_fast() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = sdf_bytes(&sample_grid());
    for a in 0..3 {
        b[12 + 4 * a..16 + 4 * a].copy_from_slice(&(1u32 << 20).to_le_bytes());
    }
    let t = Instant::now();
    load_error(dir.path(), "absurd.sdf", &b, "1048576x1048576x1048576");
    let mut m = b.clone();
    for a in 0..3 {
        m[12 + 4 * a..16 + 4 * a].copy_from_slice(&u32::MAX.to_le_bytes());
    }
    load_error(dir.path(), "max.sdf", &m, "truncated");
    assert!(t.elapsed().as_secs_f64() < 1.0, "took {:?}", t.elapsed());

    // The same for a .npy shape.
    let hdr = |shape: &str| {
        let mut dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
        while (10 + dict.len() + 1) % 64 != 0 {
            dict.push(' ');
        }
        dict.push('\n');
        let mut v = b"\x93NUMPY\x01\x00".to_vec();
        v.extend_from_slice(&(dict.len() as u16).to_le_bytes());
        v.extend_from_slice(dict.as_bytes());
        v.extend_from_slice(&[0u8; 64]);
        v
    };
    let t = Instant::now();
    load_error(dir.path(), "absurd.npy", &hdr("(1048576, 1048576, 1048576)"), "truncated");
    load_error(dir.path(), "huge.npy", &hdr("(99999999999, 2, 2)"), "too large");
    load_error(dir.path(), "flat.npy", &hdr("(4, 1, 4)"), "fewer than 2 samples");
    load_error(dir.path(), "twod.npy", &hdr("(4, 4)"), "3 axes");
    assert!(t.elapsed().as_secs_f64() < 1.0, "took {:?}", t.elapsed());
}

#[test]
fn load_nan_value() {
    let dir = tempfile::tempdir().unwrap();
    let mut g = sample_grid();
    let idx = g.index(1, 2, 3);
    g.values[idx] = f32::NAN;
    // Saving writes NaN as is; loading rejects it.
    let p = dir.path().join("nan.sdf");
    save_grid(&g, &p).unwrap();
    let e = load_grid(&p).unwrap_err();
    check_error(&e, &p, &format!("value {idx} is NaN (sample 1, 2, 3)"));
    let q = dir.path().join("nan.npy");
    save_grid(&g, &q).unwrap();
    check_error(&load_grid(&q).unwrap_err(), &q, &format!("value {idx} is NaN"));
}

#[test]
fn load_unknown_version() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = sdf_bytes(&sample_grid());
    b[8..12].copy_from_slice(&2u32.to_le_bytes());
    load_error(dir.path(), "v2.sdf", &b, "unknown SDF grid format version 2");
    let mut n = b"\x93NUMPY\x09\x00".to_vec();
    n.extend_from_slice(&[0u8; 100]);
    load_error(dir.path(), "v9.npy", &n, "unknown .npy format version 9.0");
}

#[test]
fn load_invalid_header_fields() {
    let dir = tempfile::tempdir().unwrap();
    let b = sdf_bytes(&sample_grid());
    let with = |at: usize, v: [u8; 4]| {
        let mut c = b.clone();
        c[at..at + 4].copy_from_slice(&v);
        c
    };
    load_error(dir.path(), "flat.sdf", &with(16, 1u32.to_le_bytes()), "fewer than 2 samples");
    load_error(dir.path(), "origin.sdf", &with(28, f32::NAN.to_le_bytes()), "origin");
    load_error(dir.path(), "inf.sdf", &with(32, f32::INFINITY.to_le_bytes()), "origin");
    load_error(dir.path(), "voxel0.sdf", &with(36, 0f32.to_le_bytes()), "voxel size 0");
    load_error(dir.path(), "voxelneg.sdf", &with(36, (-1f32).to_le_bytes()), "voxel size -1");
    load_error(dir.path(), "band.sdf", &with(40, 0.5f32.to_le_bytes()), "narrow-band");
}

#[test]
fn load_unsupported_npy_contents() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("g.npy");
    save_grid(&sample_grid(), &p).unwrap();
    let n = std::fs::read(&p).unwrap();
    let text = String::from_utf8_lossy(&n[10..64]).into_owned();
    let swap = |from: &str, to: &str| {
        assert_eq!(from.len(), to.len());
        let mut c = n.clone();
        let t = text.replace(from, to);
        c[10..64].copy_from_slice(t.as_bytes());
        c
    };
    load_error(dir.path(), "f8.npy", &swap("'<f4'", "'<f8'"), "dtype '<f8'");
    load_error(dir.path(), "be.npy", &swap("'<f4'", "'>f4'"), "dtype '>f4'");
    load_error(dir.path(), "fortran.npy", &swap("False", "True "), "Fortran-order");
}

#[test]
fn load_missing_file_and_unknown_extension() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("absent.sdf");
    check_error(&load_grid(&p).unwrap_err(), &p, "cannot read");
    let e = load_error(dir.path(), "grid.xyz", b"SDFGRID\0", "unknown grid file extension `.xyz`");
    assert!(e.to_string().contains(".sdf, .npy"), "{e}");
    load_error(dir.path(), "noext", b"SDFGRID\0", "no extension");
    load_error(dir.path(), "grid.vti", b"<?xml", "write only");
}

// ---------------------------------------------------------------- save errors

#[test]
fn save_unknown_extension() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("grid.obj");
    let e = save_grid(&sample_grid(), &p).unwrap_err();
    check_error(&e, &p, "unknown grid file extension `.obj`");
    assert!(e.to_string().contains(".sdf, .npy, .vti"), "{e}");
    let q = dir.path().join("grid");
    check_error(&save_grid(&sample_grid(), &q).unwrap_err(), &q, "no extension");
    assert_eq!(others(dir.path(), &[]), Vec::<String>::new());
}

#[test]
fn save_missing_directory() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["g.sdf", "g.npy", "g.vti"] {
        let p: PathBuf = dir.path().join("no_such_dir").join(name);
        let e = save_grid(&sample_grid(), &p).unwrap_err();
        check_error(&e, &p, "directory does not exist");
        assert!(!p.exists());
    }
    assert_eq!(others(dir.path(), &[]), Vec::<String>::new());
}

#[test]
fn failed_save_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    // The target is a directory: the rename fails after the temporary file was written.
    for name in ["d.sdf", "d.npy", "d.vti"] {
        let p = dir.path().join(name);
        std::fs::create_dir(&p).unwrap();
        let e = save_grid(&sample_grid(), &p).unwrap_err();
        check_error(&e, &p, "cannot write");
        assert!(p.is_dir());
    }
    assert_eq!(others(dir.path(), &["d.sdf", "d.npy", "d.vti"]), Vec::<String>::new());
}

#[test]
fn save_rejects_inconsistent_grids() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.sdf");
    let mut g = sample_grid();
    g.values.pop();
    check_error(&save_grid(&g, &p).unwrap_err(), &p, "59 values");
    let mut g = sample_grid();
    g.voxel = 0.0;
    check_error(&save_grid(&g, &p).unwrap_err(), &p, "voxel size");
    let mut g = sample_grid();
    g.origin.y = f32::NAN;
    check_error(&save_grid(&g, &p).unwrap_err(), &p, "origin");
    let g = SdfGrid { origin: Vec3::ZERO, voxel: 1.0, dims: UVec3::new(1, 2, 2), values: vec![0.0; 4] };
    check_error(&save_grid(&g, &p).unwrap_err(), &p, "at least 2 samples");
    assert_eq!(others(dir.path(), &[]), Vec::<String>::new());
}

// ---------------------------------------------------------------- nonsense refused (issue 32)

/// A version 1.0 `.npy` file of a 2x2x2 grid of zeros with header dictionary `dict`.
fn npy_with(dict: &str) -> Vec<u8> {
    let mut header = dict.to_owned();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut v = b"\x93NUMPY\x01\x00".to_vec();
    v.extend_from_slice(&(header.len() as u16).to_le_bytes());
    v.extend_from_slice(header.as_bytes());
    v.extend_from_slice(&[0u8; 32]);
    v
}

#[test]
fn npy_header_holds_numpys_three_keys_exactly() {
    let dir = tempfile::tempdir().unwrap();
    // What NumPy writes, with and without the trailing commas, loads.
    for (name, dict) in [
        ("numpy.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2), }"),
        ("plain.npy", "{\"shape\": (2,2,2,), \"descr\": \"<f4\", \"fortran_order\": False}"),
    ] {
        let p = dir.path().join(name);
        std::fs::write(&p, npy_with(dict)).unwrap();
        assert_eq!(load_grid(&p).unwrap().dims, UVec3::splat(2), "{dict}");
    }
    let cases = [
        (
            "unknown.npy",
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2), 'origin': (0, 0, 0), }",
            "unknown key 'origin' in the .npy header (the keys are 'descr', 'fortran_order' and 'shape')",
        ),
        (
            "twice.npy",
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2), 'shape': (9, 9, 9), }",
            "the .npy header has the key 'shape' twice",
        ),
        (
            "missing.npy",
            "{'descr': '<f4', 'shape': (2, 2, 2), }",
            "the .npy header has no 'fortran_order' entry",
        ),
        (
            "after.npy",
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2), } x",
            "unexpected text after the closing '}' at character 64",
        ),
        (
            "nodict.npy",
            "'descr': '<f4'",
            "not a Python dictionary literal: expected '{' at character 1, found '\\''",
        ),
        ("colon.npy", "{'descr' '<f4'}", "expected ':' at character 10, found '\\''"),
        ("comma.npy", "{'descr': '<f4' 'shape': (2, 2, 2)}", "expected ',' or '}' at character 17"),
        (
            "open.npy",
            "{'descr': '<f4', 'shape': (2, 2, 2}",
            "expected ')' at character 36, found the end of the header",
        ),
        (
            "hole.npy",
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2,,2,2), }",
            "invalid .npy shape (2,,2,2)",
        ),
    ];
    for (name, dict, needle) in cases {
        load_error(dir.path(), name, &npy_with(dict), needle);
    }
    // Only the minor version 0 exists.
    let mut v = npy_with("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2), }");
    v[7] = 1;
    load_error(dir.path(), "v11.npy", &v, "unknown .npy format version 1.1");
}

/// `toolkit render` of a `.vti` file (which the toolkit writes but cannot read) said
/// "stream did not contain valid UTF-8": the scene parser read its bytes. It now says
/// which file and what is wrong, in one line, and writes nothing.
#[test]
fn render_of_a_vti_names_the_file_and_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let mut grid = Vec::new();
    save_grid(&sample_grid(), &dir.path().join("g.vti")).unwrap();
    grid.extend(std::fs::read(dir.path().join("g.vti")).unwrap());
    let garbage = dir.path().join("t.vti");
    std::fs::write(&garbage, [0xffu8, 0xfe, 0, 1, 2, 3]).unwrap();
    for p in [dir.path().join("g.vti"), garbage] {
        let o = crate::util::toolkit(&["render", p.to_str().unwrap(), "-o", out.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(&format!("{}: cannot load .vti grids (write only)", p.display())), "{err}");
        assert!(!out.exists());
    }
}
