//! Mesh loading and writing through the public API: round trips through every writable
//! format, small hand-written files in every readable format (including the awkward
//! cases: PLY polygons and big-endian binary, binary STL whose header starts with
//! "solid", OBJ groups, glTF node hierarchies and strips), every kind of bad input, the
//! real meshes in ../shared/meshes and the assimp test corpus when installed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use glam::{Affine3A, Vec3};
use sdfmesh::error::Error;
use sdfmesh::mesh::{LoadReport, TriangleMesh, load_mesh, save_mesh};

use crate::util::{icosphere, put};

// ---------------------------------------------------------------------------------------
// Helpers

fn tmp() -> tempfile::TempDir {
    tempfile::tempdir().expect("temp dir")
}

#[track_caller]
fn load(path: &Path) -> (TriangleMesh, LoadReport) {
    match load_mesh(path) {
        Ok(r) => r,
        Err(e) => panic!("{e}"),
    }
}

/// Loading `path` fails with exit code 2, one line naming the file and holding every
/// needle.
#[track_caller]
fn fails(path: &Path, needles: &[&str]) -> Error {
    let err = match load_mesh(path) {
        Ok((m, _)) => panic!("{} loaded ({} triangles)", path.display(), m.triangle_count()),
        Err(e) => e,
    };
    assert_eq!(err.exit_code(), 2, "{err}");
    let msg = err.to_string();
    assert!(msg.contains(&path.display().to_string()), "no file name in {msg:?}");
    assert!(!msg.contains('\n'), "not one line: {msg:?}");
    for n in needles {
        assert!(msg.contains(n), "expected {n:?} in {msg:?}");
    }
    err
}

/// Same triangles (positions within 1e-6, same connectivity and winding) and normals.
#[track_caller]
fn assert_same(a: &TriangleMesh, b: &TriangleMesh, what: &str) {
    assert_eq!(a.positions.len(), b.positions.len(), "{what}: vertex count");
    assert_eq!(a.triangles.len(), b.triangles.len(), "{what}: triangle count");
    let map: Vec<u32> = b
        .positions
        .iter()
        .map(|p| {
            a.positions
                .iter()
                .position(|q| (*p - *q).abs().max_element() <= 1e-6)
                .unwrap_or_else(|| panic!("{what}: vertex {p} not in the original")) as u32
        })
        .collect();
    let canon = |t: [u32; 3]| {
        let k = (0..3).min_by_key(|&k| t[k]).unwrap();
        [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
    };
    let mut ta: Vec<[u32; 3]> = a.triangles.iter().map(|&t| canon(t)).collect();
    let mut tb: Vec<[u32; 3]> = b.triangles.iter().map(|t| canon(t.map(|i| map[i as usize]))).collect();
    ta.sort();
    tb.sort();
    assert_eq!(ta, tb, "{what}: connectivity");
    match (&a.normals, &b.normals) {
        (Some(na), Some(nb)) => {
            for (i, n) in nb.iter().enumerate() {
                let d = (*n - na[map[i] as usize]).length();
                assert!(d <= 1e-6, "{what}: normal {i} differs by {d}");
            }
        }
        (None, None) => {}
        _ => panic!("{what}: normals present in one mesh only"),
    }
}

/// Loads `path` on another thread, catching panics and giving up after `limit`.
fn load_guarded(path: &Path, limit: Duration) -> Result<Result<(usize, LoadReport), Error>, &'static str> {
    let (tx, rx) = mpsc::channel();
    let owned = path.to_path_buf();
    std::thread::spawn(move || {
        let r = std::panic::catch_unwind(|| load_mesh(&owned));
        let _ = tx.send(r.map(|r| r.map(|(m, rep)| (m.triangle_count(), rep))));
    });
    match rx.recv_timeout(limit) {
        Ok(Ok(r)) => Ok(r),
        Ok(Err(_)) => Err("PANIC"),
        Err(_) => Err("HANG"),
    }
}

/// Checks an error from a guarded load: exit code 2, one line, names the file, and no
/// panic was turned into an error inside a loader.
#[track_caller]
fn check_error(e: &Error, path: &Path) {
    let msg = e.to_string();
    assert_eq!(e.exit_code(), 2, "{msg}");
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(!msg.contains('\n'), "{msg}");
    assert!(!msg.contains("internal panic"), "{msg}");
}

// ---------------------------------------------------------------------------------------
// TriangleMesh methods

#[test]
fn mesh_methods() {
    let mut m = icosphere(1, Vec3::new(1.0, 2.0, 3.0), 2.0);
    let before = m.triangle_count();
    assert!(before >= 80, "{before}");
    assert!(m.is_closed());
    assert_eq!(m.boundary_edge_count(), 0);
    assert!(m.validate().is_ok());
    let (lo, hi) = m.bounds().unwrap();
    let c = Vec3::new(1.0, 2.0, 3.0);
    assert!(lo.cmpge(c - 2.0001).all() && hi.cmple(c + 2.0001).all(), "{lo} {hi}");
    assert!((hi - lo).min_element() > 3.5, "{lo} {hi}");
    for p in &m.positions {
        assert!(p.cmpge(lo).all() && p.cmple(hi).all());
    }
    let expected_bytes = std::mem::size_of::<TriangleMesh>()
        + m.positions.capacity() * 12
        + m.triangles.capacity() * 12
        + m.normals.as_ref().unwrap().capacity() * 12;
    assert_eq!(m.bytes_used(), expected_bytes);

    // Area-weighted normals of a sphere point outwards, close to the analytic ones.
    let analytic = m.normals.clone().unwrap();
    m.compute_vertex_normals();
    for (n, a) in m.normals.as_ref().unwrap().iter().zip(&analytic) {
        assert!((n.length() - 1.0).abs() < 1e-5);
        assert!(n.dot(*a) > 0.98, "{n} vs {a}");
    }

    // A mirror keeps triangles facing out (winding flipped) and normals unit length.
    let mut mirrored = m.clone();
    mirrored.transform(&Affine3A::from_scale(Vec3::new(-1.0, 2.0, 1.0)));
    assert!(mirrored.is_closed());
    for (i, t) in mirrored.triangles.iter().enumerate() {
        let [a, b, c] = t.map(|i| mirrored.positions[i as usize]);
        let centre = Vec3::new(-1.0, 4.0, 3.0);
        let face = (b - a).cross(c - a);
        assert!(face.dot((a + b + c) / 3.0 - centre) > 0.0, "triangle {i} faces in");
        let n = mirrored.normals.as_ref().unwrap()[t[0] as usize];
        assert!((n.length() - 1.0).abs() < 1e-5);
        assert!(n.dot(face) > 0.0);
    }

    // Merge shifts indices; an open mesh has boundary edges.
    let mut two = m.clone();
    let other = icosphere(0, Vec3::new(10.0, 0.0, 0.0), 1.0);
    two.merge(&other);
    assert_eq!(two.triangle_count(), m.triangle_count() + other.triangle_count());
    assert_eq!(two.positions.len(), m.positions.len() + other.positions.len());
    assert!(two.validate().is_ok());
    assert!(two.is_closed());
    two.triangles.pop();
    assert_eq!(two.boundary_edge_count(), 3);
    assert!(!two.is_closed());
    let mut no_normals = icosphere(0, Vec3::ZERO, 1.0);
    no_normals.normals = None;
    two.merge(&no_normals);
    assert!(two.normals.is_none());
    assert_eq!(TriangleMesh::default().bounds(), None);
    assert!(!TriangleMesh::default().is_closed());
}

// ---------------------------------------------------------------------------------------
// Round trips

#[test]
fn round_trip_every_writable_format() {
    let dir = tmp();
    let sphere = icosphere(2, Vec3::new(0.25, -1.5, 3.0), 1.75);
    let mut bare = sphere.clone();
    bare.normals = None;
    for (mesh, tag) in [(&sphere, "normals"), (&bare, "bare")] {
        for ext in ["obj", "ply", "glb"] {
            let path = dir.path().join(format!("sphere-{tag}.{ext}"));
            save_mesh(mesh, &path).unwrap_or_else(|e| panic!("{e}"));
            let (back, report) = load(&path);
            assert_eq!(report.degenerate_dropped, 0, "{ext}");
            assert_eq!(report.vertices_welded, 0, "{ext}");
            assert_same(mesh, &back, &format!("{tag}.{ext}"));
            assert!(back.is_closed(), "{ext}");
            if ext != "obj" {
                // PLY and GLB keep the vertex order exactly.
                assert_eq!(back.triangles, mesh.triangles, "{ext}");
            }
        }
    }
    // Nothing but the outputs is left in the directory (no temporary files).
    let mut names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names.len(), 6, "{names:?}");
    assert!(names.iter().all(|n| !n.starts_with('.')), "{names:?}");
}

#[test]
fn glb_writer_follows_the_container_layout() {
    let dir = tmp();
    let path = dir.path().join("s.glb");
    save_mesh(&icosphere(1, Vec3::ZERO, 1.0), &path).unwrap();
    let b = std::fs::read(&path).unwrap();
    let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap()) as usize;
    assert_eq!(&b[0..4], b"glTF");
    assert_eq!(u32_at(4), 2);
    assert_eq!(u32_at(8), b.len());
    let json_len = u32_at(12);
    assert_eq!(json_len % 4, 0);
    assert_eq!(&b[16..20], b"JSON");
    let json = std::str::from_utf8(&b[20..20 + json_len]).unwrap();
    assert!(json.contains("\"min\"") && json.contains("\"max\"") && json.contains("NORMAL"));
    let bin_at = 20 + json_len;
    assert_eq!(u32_at(bin_at) % 4, 0);
    assert_eq!(&b[bin_at + 4..bin_at + 8], b"BIN\0");
    assert_eq!(bin_at + 8 + u32_at(bin_at), b.len());
    // The gltf crate accepts it with full validation.
    let g = gltf::Gltf::from_slice(&b).expect("valid per the gltf crate");
    assert_eq!(g.meshes().count(), 1);
}

#[test]
fn save_errors() {
    let dir = tmp();
    let sphere = icosphere(0, Vec3::ZERO, 1.0);
    let missing = dir.path().join("no/such/dir/out.ply");
    let err = save_mesh(&sphere, &missing).unwrap_err();
    assert_eq!(err.exit_code(), 2);
    assert!(err.to_string().contains("does not exist"), "{err}");
    assert!(err.to_string().contains("out.ply"), "{err}");
    let err = save_mesh(&sphere, &dir.path().join("out.stl")).unwrap_err();
    assert!(err.to_string().contains("supported: .obj, .ply, .glb"), "{err}");
    let mut broken = sphere.clone();
    broken.triangles.push([0, 1, 99]);
    let err = save_mesh(&broken, &dir.path().join("b.obj")).unwrap_err();
    assert!(err.to_string().contains("index 99 out of range"), "{err}");
    assert!(!dir.path().join("b.obj").exists());
    // Writing over a directory fails and leaves no temporary file behind.
    std::fs::create_dir(dir.path().join("d.ply")).unwrap();
    assert!(save_mesh(&sphere, &dir.path().join("d.ply")).is_err());
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(left.len(), 1, "{left:?}");
}

// ---------------------------------------------------------------------------------------
// Hand-written files, one per awkward case

/// A pentagonal prism: two pentagons and five quads, 10 vertices, 16 triangles, closed.
fn prism_ascii_ply() -> String {
    let mut s = String::from(
        "ply\nformat ascii 1.0\ncomment a pentagonal prism\nelement vertex 10\n\
         property float x\nproperty float y\nproperty float z\nproperty uchar confidence\n\
         element face 7\nproperty list uchar int vertex_indices\nend_header\n",
    );
    for z in [0.0f32, 1.0] {
        for k in 0..5 {
            let a = k as f32 * std::f32::consts::TAU / 5.0;
            s += &format!("{} {} {z} 255\n", a.cos(), a.sin());
        }
    }
    s += "5 4 3 2 1 0\n5 5 6 7 8 9\n";
    for k in 0..5 {
        let k1 = (k + 1) % 5;
        s += &format!("4 {k} {k1} {} {}\n", k1 + 5, k + 5);
    }
    s
}

#[test]
fn ascii_ply_with_quads_and_pentagons() {
    let dir = tmp();
    let (m, report) = load(&put(dir.path(), "prism.ply", prism_ascii_ply()));
    assert_eq!(m.positions.len(), 10);
    assert_eq!(m.triangle_count(), 16);
    assert_eq!(report.triangles_read, 16);
    assert_eq!(report.degenerate_dropped, 0);
    assert!(m.is_closed());
    assert!(m.normals.is_none());
    let (lo, hi) = m.bounds().unwrap();
    assert!((hi.z - 1.0).abs() < 1e-6 && lo.z == 0.0 && (hi.x - 1.0).abs() < 1e-6);
}

const TETRA: [[f32; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
const TETRA_FACES: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];

fn assert_tetra(m: &TriangleMesh) {
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.triangle_count(), 4);
    assert!(m.is_closed(), "{m:?}");
    assert_eq!(m.bounds(), Some((Vec3::ZERO, Vec3::ONE)));
    // Outward: the signed volume is positive.
    let vol: f32 = m
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            a.dot(b.cross(c)) / 6.0
        })
        .sum();
    assert!((vol - 1.0 / 6.0).abs() < 1e-6, "{vol}");
}

#[test]
fn binary_big_endian_ply() {
    let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty double x\n\
        property double y\nproperty double z\nproperty uchar red\nelement face 4\n\
        property uchar flags\nproperty list uchar int vertex_indices\nelement edge 1\n\
        property int vertex1\nproperty int vertex2\nend_header\n"
        .to_vec();
    for p in TETRA {
        for c in p {
            b.extend_from_slice(&(c as f64).to_be_bytes());
        }
        b.push(200);
    }
    for f in TETRA_FACES {
        b.push(7);
        b.push(3);
        for i in f {
            b.extend_from_slice(&(i as i32).to_be_bytes());
        }
    }
    b.extend_from_slice(&0i32.to_be_bytes());
    b.extend_from_slice(&1i32.to_be_bytes());
    let dir = tmp();
    let (m, report) = load(&put(dir.path(), "tetra_be.ply", &b));
    assert_tetra(&m);
    assert_eq!(m.triangles, TETRA_FACES.to_vec());
    assert!(report.notes.iter().any(|n| n.contains("'edge'")), "{report:?}");

    // Truncating the binary data anywhere gives a "truncated" error, never a panic.
    let header_len = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    for cut in [header_len + 5, b.len() - 9, b.len() - 1] {
        let p = put(dir.path(), &format!("cut{cut}.ply"), &b[..cut]);
        fails(&p, &["truncated"]);
    }
}

fn stl_ascii(name: &str) -> String {
    let mut s = format!("solid {name}\n");
    for f in TETRA_FACES {
        s += "  facet normal 0 0 0\n    outer loop\n";
        for i in f {
            let p = TETRA[i as usize];
            s += &format!("      vertex {:e} {} {}\n", p[0], p[1], p[2]);
        }
        s += "    endloop\n  endfacet\n";
    }
    s + &format!("endsolid {name}\n")
}

fn stl_binary(header: &[u8], faces: &[[u32; 3]]) -> Vec<u8> {
    let mut b = vec![b' '; 80];
    b[..header.len()].copy_from_slice(header);
    b.extend_from_slice(&(faces.len() as u32).to_le_bytes());
    for f in faces {
        b.extend_from_slice(&[0u8; 12]);
        for &i in f {
            for c in TETRA[i as usize] {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        b.extend_from_slice(&[0, 0]);
    }
    b
}

#[test]
fn stl_ascii_and_binary_with_solid_header() {
    let dir = tmp();
    let (m, report) = load(&put(dir.path(), "tetra.stl", stl_ascii("tetra")));
    assert_tetra(&m);
    assert_eq!(report.vertices_welded, 8);

    // Two solids in one file are merged.
    let two = stl_ascii("a") + &stl_ascii("b").replace("vertex 0e0", "vertex 5e0");
    let (m2, _) = load(&put(dir.path(), "two.STL", two));
    assert_eq!(m2.triangle_count(), 8);

    // A binary file whose header starts with "solid" is still binary (size 84 + 50n).
    let bin = stl_binary(b"solid exported by some CAD tool", &TETRA_FACES);
    assert_eq!(bin.len(), 84 + 50 * 4);
    let (m, _) = load(&put(dir.path(), "solid_header.stl", &bin));
    assert_tetra(&m);
}

#[test]
fn obj_with_quads_and_two_groups() {
    let obj = "# a unit cube in two groups, quads, a missing material library\n\
        mtllib does-not-exist.mtl\n\
        v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
        vt 0 0\nvt 1\n\
        g bottom_and_sides\nusemtl red\n\
        f 1/1 4/1 3/1 2/1\nf 1 2 6 5\nf 2 3 7 6\n\
        g top_and_rest\nusemtl\n\
        f -6 -5 -1 -2\nf 4 1 5 8\nf 5 6 7 8\n\
        l 1 2\np 3\n";
    let dir = tmp();
    let (m, report) = load(&put(dir.path(), "cube.obj", obj));
    assert_eq!(m.triangle_count(), 12);
    assert_eq!(m.positions.len(), 8, "groups welded back together");
    assert!(m.is_closed());
    assert_eq!(report.skipped_primitives, 2);
    assert_eq!(m.bounds(), Some((Vec3::ZERO, Vec3::ONE)));
}

/// Little-endian bytes of f32 values.
fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn base64(b: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in b.chunks(3) {
        let n = c.iter().enumerate().fold(0u32, |n, (i, &x)| n | (x as u32) << (16 - 8 * i));
        for k in 0..=c.len() {
            s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
        }
    }
    while !s.len().is_multiple_of(4) {
        s.push('=');
    }
    s
}

/// The binary data of the hierarchy test: a triangle (3 vertices), a strip (4 vertices),
/// u16 indices of the triangle.
fn hierarchy_bin() -> Vec<u8> {
    let mut b = f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
    b.extend(f32s(&[0., 0., 1., 1., 0., 1., 0., 1., 1., 1., 1., 1.]));
    for i in [0u16, 1, 2] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

/// A parent node translated by (10, 0, 0) whose child (translated by (0, 5, 0)) holds a
/// mesh with a triangle list, a triangle strip and a points primitive.
fn hierarchy_gltf(uri: &str) -> String {
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [
    {{"name": "parent", "translation": [10, 0, 0], "children": [1]}},
    {{"name": "child", "translation": [0, 5, 0], "mesh": 0}}
  ],
  "meshes": [{{"primitives": [
    {{"attributes": {{"POSITION": 0}}, "indices": 2, "mode": 4}},
    {{"attributes": {{"POSITION": 1}}, "mode": 5}},
    {{"attributes": {{"POSITION": 0}}, "mode": 0}}
  ]}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
      "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3",
      "min": [0, 0, 1], "max": [1, 1, 1]}},
    {{"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}}
  ],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 36}},
    {{"buffer": 0, "byteOffset": 36, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 84, "byteLength": 6}}
  ],
  "buffers": [{{"uri": "{uri}", "byteLength": 90}}]
}}"#
    )
}

#[test]
fn gltf_hierarchy_and_triangle_strip() {
    let dir = tmp();
    put(dir.path(), "geom data.bin", hierarchy_bin());
    let external = put(dir.path(), "scene.gltf", hierarchy_gltf("geom%20data.bin"));
    let embedded_uri = format!("data:application/octet-stream;base64,{}", base64(&hierarchy_bin()));
    let embedded = put(dir.path(), "embedded.gltf", hierarchy_gltf(&embedded_uri));
    for path in [external, embedded] {
        let (m, report) = load(&path);
        assert_eq!(m.triangle_count(), 3, "{}", path.display());
        assert_eq!(report.skipped_primitives, 1);
        assert_eq!(m.bounds(), Some((Vec3::new(10.0, 5.0, 0.0), Vec3::new(11.0, 6.0, 1.0))));
        // Every triangle faces +z (the strip's odd triangle has its winding swapped).
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            assert!((b - a).cross(c - a).z > 0.0, "{t:?}");
        }
    }
}

#[test]
fn glb_container_with_bin_chunk() {
    // The same hierarchy as a GLB: buffer 0 has no URI and lives in the BIN chunk.
    let json = hierarchy_gltf("").replace(r#""uri": "", "#, "");
    let mut json = json.into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut bin = hierarchy_bin();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut b = b"glTF".to_vec();
    for v in [2, total as u32, json.len() as u32] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.extend_from_slice(b"JSON");
    b.extend_from_slice(&json);
    b.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    b.extend_from_slice(b"BIN\0");
    b.extend_from_slice(&bin);
    let dir = tmp();
    let (m, _) = load(&put(dir.path(), "h.glb", &b));
    assert_eq!(m.triangle_count(), 3);
    // Cut anywhere: an error, never a panic.
    for cut in [0, 8, 13, 30, b.len() - 40, b.len() - 1] {
        let p = put(dir.path(), &format!("cut{cut}.glb"), &b[..cut]);
        let e = load_mesh(&p).unwrap_err();
        assert_eq!(e.exit_code(), 2);
    }
}

#[test]
fn degenerate_triangles_are_dropped_and_counted() {
    let ply = "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n\
        property float z\nelement face 5\nproperty list uchar uint vertex_indices\nend_header\n\
        0 0 0\n1 0 0\n0 1 0\n0.5 0 0\n1 0 0\n7 7 7\n\
        3 0 1 2\n3 0 0 1\n3 0 1 3\n3 0 1 4\n3 2 1 0\n";
    // Kept: two (0 1 2 and its reverse). Dropped: a repeated index, a collinear triangle,
    // and one whose corners 1 and 4 weld into the same vertex.
    let dir = tmp();
    let (m, report) = load(&put(dir.path(), "degenerate.ply", ply));
    assert_eq!(report.triangles_read, 5);
    assert_eq!(report.degenerate_dropped, 3);
    assert_eq!(report.vertices_welded, 1);
    assert_eq!(report.unreferenced_vertices_removed, 2);
    assert_eq!(m.triangle_count(), 2);
    assert_eq!(m.positions.len(), 3);

    let all_bad = "solid x\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex 1 1 1\n\
        vertex 2 2 2\nendloop\nendfacet\nendsolid x\n";
    fails(&put(dir.path(), "line.stl", all_bad), &["no triangles (all 1 triangles are degenerate)"]);
    assert!(sdfmesh::mesh::is_degenerate(Vec3::ZERO, Vec3::X, Vec3::X * 2.0));
    assert!(!sdfmesh::mesh::is_degenerate(Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1e-4, 0.0)));
}

// ---------------------------------------------------------------------------------------
// Errors

#[test]
fn non_finite_vertex() {
    let dir = tmp();
    let ply = prism_ascii_ply();
    let mut lines: Vec<String> = ply.lines().map(String::from).collect();
    let first_vertex = lines.iter().position(|l| l == "end_header").unwrap() + 1;
    lines[first_vertex + 1] = "NaN 0 0 255".into();
    let p = put(dir.path(), "nan.ply", lines.join("\n"));
    fails(&p, &["vertex 1: coordinate is NaN", ":13:1:"]);

    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 nan\nf 1 2 3\n";
    fails(&put(dir.path(), "nan.obj", obj), &["vertex 2: coordinate is NaN", ":3:"]);
    let stl = stl_ascii("t").replace("vertex 1e0 0 0", "vertex 1e0 inf 0");
    fails(&put(dir.path(), "inf.stl", stl), &["coordinate is infinite"]);
    let mut bin = stl_binary(b"x", &TETRA_FACES);
    bin[84 + 12 + 4..84 + 12 + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    fails(&put(dir.path(), "nan.stl", bin), &["triangle 0 vertex 0: coordinate is NaN"]);
}

#[test]
fn index_out_of_range() {
    let dir = tmp();
    let ply = prism_ascii_ply().replace("5 4 3 2 1 0", "5 4 3 999 1 0");
    fails(&put(dir.path(), "range.ply", ply), &["face 0: index 999 out of range (10 vertices)", ":22:7:"]);
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 3\nf 1 2 3\nf 1 999 3\n";
    fails(&put(dir.path(), "range.obj", obj), &["face 3: index 999 out of range (3 vertices)", ":7:"]);
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n";
    fails(&put(dir.path(), "neg.obj", obj), &["face 0: index -4 out of range"]);
    let gltf = hierarchy_gltf("b.bin");
    let mut bin = hierarchy_bin();
    bin[88..90].copy_from_slice(&7u16.to_le_bytes());
    put(dir.path(), "b.bin", bin);
    fails(
        &put(dir.path(), "range.gltf", gltf),
        &["mesh 0 primitive 0: index 7", "out of range (3 vertices)"],
    );
}

#[test]
fn absurd_ply_count_fails_fast() {
    let dir = tmp();
    let ply = "ply\nformat binary_little_endian 1.0\nelement vertex 1099511627776\n\
        property float x\nproperty float y\nproperty float z\nelement face 1\n\
        property list uchar int vertex_indices\nend_header\n0123456789";
    let start = Instant::now();
    fails(&put(dir.path(), "absurd.ply", ply), &["1099511627776", ":3:"]);
    let ascii = ply.replace("binary_little_endian", "ascii");
    fails(&put(dir.path(), "absurd_ascii.ply", ascii), &["1099511627776"]);
    let faces = "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\n\
        property float y\nproperty float z\nelement face 4000000000\n\
        property list uchar int vertex_indices\nend_header\n"
        .as_bytes()
        .iter()
        .chain(&[0u8; 36])
        .copied()
        .collect::<Vec<u8>>();
    fails(&put(dir.path(), "absurd_faces.ply", faces), &["element 'face' declares 4000000000"]);
    assert!(start.elapsed() < Duration::from_secs(1), "{:?}", start.elapsed());
}

#[test]
fn truncated_and_empty_stl() {
    let dir = tmp();
    let bin = stl_binary(b"binary", &TETRA_FACES);
    fails(&put(dir.path(), "cut.stl", &bin[..bin.len() - 30]), &["truncated binary STL", "4 triangles"]);
    let solid_header = stl_binary(b"solid but binary", &TETRA_FACES);
    fails(&put(dir.path(), "cut_solid.stl", &solid_header[..150]), &["truncated"]);
    fails(&put(dir.path(), "short.stl", [1u8, 2, 3]), &["truncated"]);
    fails(&put(dir.path(), "empty_solid.stl", "solid empty\nendsolid empty\n"), &["no triangles"]);
    fails(&put(dir.path(), "zero.stl", stl_binary(b"none", &[])), &["no triangles"]);
    let ascii = stl_ascii("t");
    let cut = ascii.match_indices("endloop").nth(1).unwrap().0;
    fails(&put(dir.path(), "cut_ascii.stl", &ascii[..cut]), &["truncated"]);
    fails(&put(dir.path(), "nothing.stl", ""), &["empty file"]);
}

#[test]
fn gltf_errors() {
    let dir = tmp();
    fails(
        &put(dir.path(), "nobuf.gltf", hierarchy_gltf("missing-buffer.bin")),
        &["buffer 0", "missing-buffer.bin"],
    );
    put(dir.path(), "short.bin", &hierarchy_bin()[..50]);
    fails(
        &put(dir.path(), "shortbuf.gltf", hierarchy_gltf("short.bin")),
        &["buffer 0", "'short.bin' holds 50 bytes", "byteLength 90"],
    );
    let recursive = r#"{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"children": [1]}, {"children": [2]}, {"children": [1]}]}"#;
    fails(&put(dir.path(), "recursive.gltf", recursive), &["node 1 is its own ancestor"]);
    let self_child = r#"{"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}],
        "nodes": [{"children": [0]}]}"#;
    fails(&put(dir.path(), "self.gltf", self_child), &["node 0"]);
    fails(
        &put(dir.path(), "bad.gltf", "{\"asset\": {\"version\": \"2.0\"},\n  \"nodes\": [1,]}"),
        &["invalid glTF JSON", ":2:"],
    );
    fails(
        &put(dir.path(), "v1.gltf", r#"{"asset": {"version": "1.0"}, "meshes": {"a": {}}}"#),
        &["glTF version 1.0 is not supported"],
    );
    let lines_only = hierarchy_gltf("data:;base64,").replace(r#""mode": 4"#, r#""mode": 1"#);
    let lines_only = lines_only.replace(r#""mode": 5"#, r#""mode": 3"#);
    fails(&put(dir.path(), "lines.gltf", lines_only), &["no triangles (3 point or line primitives skipped)"]);
    let bad_index = hierarchy_gltf("x.bin").replace(r#""indices": 2"#, r#""indices": 9"#);
    fails(&put(dir.path(), "badindex.gltf", bad_index), &["invalid glTF", "indices"]);
    let draco = hierarchy_gltf("x.bin")
        .replace(r#""asset""#, r#""extensionsRequired": ["KHR_draco_mesh_compression"], "asset""#);
    fails(&put(dir.path(), "draco.gltf", draco), &["KHR_draco_mesh_compression"]);
}

#[test]
fn other_errors() {
    let dir = tmp();
    let p = put(dir.path(), "mesh.xyz", "whatever");
    fails(&p, &["'.xyz'", "supported: .obj, .ply, .stl, .gltf, .glb"]);
    fails(&put(dir.path(), "noext", "x"), &["no file extension"]);
    let missing = dir.path().join("missing.obj");
    let err = fails(&missing, &["cannot read"]);
    assert!(matches!(err, Error::Io { .. }));
    fails(&put(dir.path(), "empty.obj", ""), &["no triangles"]);
    fails(&put(dir.path(), "points.obj", "v 0 0 0\nv 1 1 1\np 1 2\n"), &["no triangles"]);
    fails(&put(dir.path(), "utf16.obj", [0xFF, 0xFE, b'v', 0]), &["UTF-16"]);
    fails(&put(dir.path(), "notply.ply", "solid x\n"), &["not a PLY file"]);
    fails(&put(dir.path(), "empty.ply", ""), &["empty file"]);
    let cloud = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
        property float z\nend_header\n1 2 3\n";
    fails(&put(dir.path(), "cloud.ply", cloud), &["no triangles", "'face'"]);
    let extra = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
        property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
        0 0 0\n1 0 0 9\n0 1 0\n3 0 1 2\n";
    fails(&put(dir.path(), "extra.ply", extra), &["vertex 1: unexpected value '9'", ":11:7:"]);
    let badnum = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
        property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
        0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n";
    fails(&put(dir.path(), "badnum.ply", badnum), &["vertex 1: property 'y': 'zero'", ":11:3:"]);
}

// ---------------------------------------------------------------------------------------
// Nonsense no loader accepts silently (issue 32, class 10): counts that disagree with the
// data, elements of the wrong size, garbage statements, unknown versions, header entries
// declared twice. Each is an error naming the file and the element, or, where real
// exporters write it, a warning naming both (in the report, and on stderr from the CLI).

/// `report` holds exactly one warning with every needle, and it names `path` first.
#[track_caller]
fn warns(report: &LoadReport, path: &Path, needles: &[&str]) {
    let hits: Vec<&String> =
        report.warnings.iter().filter(|w| needles.iter().all(|n| w.contains(n))).collect();
    assert_eq!(hits.len(), 1, "expected one warning with {needles:?}: {report:?}");
    assert!(hits[0].starts_with(&path.display().to_string()), "{hits:?}");
    assert!(!hits[0].contains('\n'), "{hits:?}");
}

/// A binary little-endian PLY of the tetrahedron, with `extra` after the last face.
fn tetra_binary_ply(extra: &[u8]) -> Vec<u8> {
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n\
        property float y\nproperty float z\nelement face 4\nproperty list uchar int vertex_indices\n\
        end_header\n"
        .to_vec();
    b.extend(TETRA.iter().flatten().flat_map(|c| c.to_le_bytes()));
    for f in TETRA_FACES {
        b.push(3);
        b.extend(f.iter().flat_map(|&i| (i as i32).to_le_bytes()));
    }
    b.extend_from_slice(extra);
    b
}

#[test]
fn stl_binary_triangle_count_must_match_the_data() {
    let dir = tmp();
    // The header says 3, the data holds 4: the fourth used to be dropped without a word.
    let mut more = stl_binary(b"binary", &TETRA_FACES);
    more[80..84].copy_from_slice(&3u32.to_le_bytes());
    fails(
        &put(dir.path(), "more.stl", &more),
        &["declares 3 triangles", "50 bytes, 1 more triangle records"],
    );
    let mut zero = stl_binary(b"solid but binary", &TETRA_FACES);
    zero[80..84].copy_from_slice(&0u32.to_le_bytes());
    fails(&put(dir.path(), "zero_count.stl", &zero), &["declares 0 triangles", "4 more triangle records"]);
    // The opposite, a count larger than the data, is a truncated file.
    let mut fewer = stl_binary(b"binary", &TETRA_FACES);
    fewer[80..84].copy_from_slice(&5u32.to_le_bytes());
    fails(&put(dir.path(), "fewer.stl", &fewer), &["truncated binary STL", "declares 5 triangles"]);
    // Less than one record after the data is padding: loaded, with a warning.
    let mut pad = stl_binary(b"binary", &TETRA_FACES);
    pad.extend_from_slice(&[0, 0, b'\n']);
    let p = put(dir.path(), "padded.stl", &pad);
    let (m, report) = load(&p);
    assert_tetra(&m);
    warns(&report, &p, &["3 bytes after the last of the 4 triangles ignored"]);
}

#[test]
fn stl_ascii_facet_must_be_a_triangle() {
    let dir = tmp();
    let ascii = stl_ascii("t");
    // Line 7 is the fourth vertex of facet 0.
    let quad = ascii.replacen("    endloop", "      vertex 1 1 1\n    endloop", 1);
    fails(
        &put(dir.path(), "quad.stl", quad),
        &[":7:7:", "facet 0: a 4th vertex; an STL facet is a triangle"],
    );
    let second = ascii.match_indices("    endloop").nth(1).unwrap().0;
    let mut quad2 = ascii.clone();
    quad2.insert_str(second, "      vertex 1 1 1\n");
    fails(&put(dir.path(), "quad2.stl", quad2), &[":14:7:", "facet 1: a 4th vertex"]);
    let two = ascii.replacen("      vertex 0e0 1 0\n", "", 1);
    fails(&put(dir.path(), "two.stl", two), &[":2:3:", "facet 0: 2 vertices; an STL facet is a triangle"]);
    let none = "solid x\nfacet normal 0 0 1\nouter loop\nendloop\nendfacet\nendsolid x\n";
    fails(&put(dir.path(), "none.stl", none), &[":2:1:", "facet 0: 0 vertices"]);
}

const TETRA_OBJ_3: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\n";

#[test]
fn obj_garbage_statements_are_refused_or_reported() {
    let dir = tmp();
    let base = TETRA_OBJ_3;
    // A face behind NUL bytes: tobj skipped the line without a word.
    let p = put(dir.path(), "nul.obj", format!("{base}\0\0f 2 3 4\n"));
    fails(&p, &[":8:1:", r"'\u{0}\u{0}f' is not an OBJ statement", "binary data"]);
    // Other control bytes, a file padded with NULs, a keyword that is not ASCII.
    fails(
        &put(dir.path(), "ctrl.obj", format!("{base}\x01\x02junk 1 2\n")),
        &[":8:1:", "not an OBJ statement"],
    );
    fails(
        &put(dir.path(), "padded.obj", format!("{base}f 2 3 4\n\0\0\0\0")),
        &[":9:1:", "not an OBJ statement"],
    );
    fails(
        &put(dir.path(), "latin.obj", format!("{base}f\u{e9} 2 3 4\n")),
        &[":8:1:", "'f\u{e9}' is not an OBJ statement"],
    );
    // A printable word that is no OBJ keyword: ignored, with one warning naming the first.
    let p = put(dir.path(), "unknown.obj", format!("{base}f 2 3 4\nfo 2 3 4\nfoo\n"));
    let (m, report) = load(&p);
    assert_eq!(m.triangle_count(), 4);
    warns(&report, &p, &[":9:1:", "'fo' is not an OBJ statement: 2 such line(s) ignored"]);
    // Valid statements that carry no triangles give no warning: free-form geometry (a
    // note), groups, smoothing, comments, the DOS end-of-file mark.
    let valid = format!("{base}g a\ns 1\nmg 1\n# c\nf 2 3 4\nvp 0.5\ncurv 0 1 1 2\nparm u 0 1\nend\n\x1a\n");
    let p = put(dir.path(), "valid.obj", valid);
    let (m, report) = load(&p);
    assert_eq!(m.triangle_count(), 4);
    assert!(report.warnings.is_empty(), "{report:?}");
    assert!(
        report
            .notes
            .iter()
            .any(|n| n.contains("free-form geometry")
                && n.contains("4 statement(s), the first 'vp' on line 13")),
        "{report:?}"
    );
    // A normal with more than three numbers.
    fails(
        &put(dir.path(), "vn4.obj", format!("{base}vn 0 0 1 1\n")),
        &[":8:1:", "normal 0: expected 'vn x y z'"],
    );
}

#[test]
fn faces_need_three_vertices() {
    let dir = tmp();
    for (name, face, count) in [("two.obj", "f 1 2", 2), ("one.obj", "f 3", 1), ("none.obj", "f", 0)] {
        let p = put(dir.path(), name, format!("{TETRA_OBJ_3}{face}\nf 2 3 4\n"));
        fails(&p, &[":8:1:", &format!("face 3: {count} vertices; a face needs at least 3")]);
    }
    // Lines and points are valid OBJ: skipped and counted.
    let p = put(dir.path(), "lines.obj", format!("{TETRA_OBJ_3}f 2 3 4\nl 1 2\np 3\n"));
    assert_eq!(load(&p).1.skipped_primitives, 2);
    // PLY: face 0 (line 22) with two corners, ASCII and binary.
    let ply = prism_ascii_ply().replace("5 4 3 2 1 0", "2 4 3");
    fails(&put(dir.path(), "two.ply", ply), &[":22:1:", "face 0: 2 vertices; a face needs at least 3"]);
    let mut bin = tetra_binary_ply(&[]);
    let faces = bin.len() - 4 * 13;
    bin.splice(faces + 3 * 13.., [1u8, 0, 0, 0, 0]);
    fails(&put(dir.path(), "one.ply", bin), &["face 3: 1 vertices"]);
}

#[test]
fn ply_header_is_read_strictly() {
    let dir = tmp();
    let prism = prism_ascii_ply();
    let case = |name: &str, from: &str, to: &str, needles: &[&str]| {
        assert!(prism.contains(from), "{from}");
        fails(&put(dir.path(), name, prism.replacen(from, to, 1)), needles);
    };
    case(
        "v2.ply",
        "format ascii 1.0",
        "format ascii 2.0",
        &[":2:1:", "unknown PLY version '2.0' (the only version is 1.0)"],
    );
    case("v11.ply", "format ascii 1.0", "format ascii 1.1", &[":2:1:", "unknown PLY version '1.1'"]);
    case("noversion.ply", "format ascii 1.0", "format ascii", &[":2:1:", "expected 'format ascii 1.0'"]);
    case("extra.ply", "format ascii 1.0", "format ascii 1.0 1.0", &[":2:1:", "expected 'format ascii 1.0'"]);
    case(
        "twoformats.ply",
        "comment a pentagonal prism",
        "format ascii 1.0",
        &[":3:1:", "a second 'format' line (the first is line 2)"],
    );
    case(
        "twice.ply",
        "property float z\n",
        "property float z\nproperty float y\n",
        &[":8:1:", "element 'vertex': property 'y' declared twice"],
    );
    case("endjunk.ply", "end_header", "end_header 5 4", &[":11:1:", "unexpected '5' after 'end_header'"]);
    case(
        "binaryline.ply",
        "comment a pentagonal prism",
        "\x01\x02 junk",
        &[":3:1:", r"'\u{1}\u{2}' is not a PLY header keyword"],
    );
    // Free text in the header (Blender 2.4 wrote "Created by ..."): a warning.
    let p =
        put(dir.path(), "created.ply", prism.replacen("comment a pentagonal prism", "Created by hand", 1));
    let (m, report) = load(&p);
    assert_eq!(m.triangle_count(), 16);
    warns(&report, &p, &[":3:1:", "header line ignored: 'Created' is not a PLY header keyword"]);
}

#[test]
fn ply_data_must_end_with_the_last_element() {
    let dir = tmp();
    // ASCII: a face more than the header declares (line 29).
    let more = prism_ascii_ply() + "3 0 1 2\n";
    fails(&put(dir.path(), "more.ply", more), &[":29:1:", "unexpected '3' after the last 'face' entry"]);
    let blank = prism_ascii_ply() + "\n  \n\t\n";
    assert_eq!(load(&put(dir.path(), "blank.ply", blank)).0.triangle_count(), 16);
    // Binary: data after the last face is an error; padding is a warning.
    let data = tetra_binary_ply(&[3, 0, 0, 0, 0]);
    fails(&put(dir.path(), "more_bin.ply", data), &["5 bytes of data after the last 'face' entry"]);
    let p = put(dir.path(), "padded.ply", tetra_binary_ply(b"\n\0"));
    let (m, report) = load(&p);
    assert_tetra(&m);
    warns(&report, &p, &["2 bytes of padding (white space or NUL) after the last 'face' entry ignored"]);
    assert_tetra(&load(&put(dir.path(), "exact.ply", tetra_binary_ply(&[]))).0);
}

/// The CLI prints a loader's warnings on stderr, one line each, and still succeeds.
#[test]
fn warnings_reach_stderr() {
    let dir = tmp();
    let p = put(
        dir.path(),
        "created.ply",
        prism_ascii_ply().replacen("comment a pentagonal prism", "Created by hand", 1),
    );
    let out = dir.path().join("out.png");
    let o = crate::util::toolkit(&["render", p.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let want =
        format!("warning: {}:3:1: header line ignored: 'Created' is not a PLY header keyword\n", p.display());
    assert!(err.contains(&want), "{err}");
    assert!(out.is_file());
}

// ---------------------------------------------------------------------------------------
// Real data

fn shared_meshes() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes");
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("note: {} is absent; real-mesh checks skipped", dir.display());
        None
    }
}

#[test]
fn real_meshes() {
    let Some(dir) = shared_meshes() else { return };
    for (name, triangles) in [("stanford-bunny.obj", 69_451), ("trimesh_Duck.glb", 4_212)] {
        let path = dir.join(name);
        if !path.exists() {
            println!("note: {} is absent; skipped", path.display());
            continue;
        }
        let (m, report) = load(&path);
        println!("{name}: {} triangles; {report}", m.triangle_count());
        assert_eq!(report.triangles_read, triangles, "{name}");
        assert_eq!(m.triangle_count() + report.degenerate_dropped, triangles, "{name}");
        assert!(m.validate().is_ok());
    }
    // Every mesh in the folder loads; print what the loaders made of it.
    let mut names: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| sdfmesh::mesh::MeshFormat::from_path(p).is_some())
        .collect();
    names.sort();
    for path in names {
        let start = Instant::now();
        let (m, report) = load(&path);
        println!(
            "{}: {} triangles, {} vertices, normals: {}, {} boundary edges, loaded in {:?}; {report}",
            path.file_name().unwrap().to_string_lossy(),
            m.triangle_count(),
            m.positions.len(),
            m.normals.is_some(),
            m.boundary_edge_count(),
            start.elapsed()
        );
    }
    let bunny = dir.join("trimesh_bunny.ply");
    if bunny.exists() {
        let r = std::panic::catch_unwind(|| load_mesh(&bunny));
        match r {
            Ok(Ok((m, report))) => {
                println!("trimesh_bunny.ply: {} triangles; {report}", m.triangle_count())
            }
            Ok(Err(e)) => println!("trimesh_bunny.ply: error: {e}"),
            Err(_) => panic!("trimesh_bunny.ply: panicked"),
        }
    }
}

// ---------------------------------------------------------------------------------------
// The assimp test corpus (Debian package assimp-testmodels)

/// The message of an error with the path and numbers taken out, to group similar errors.
fn error_kind(msg: &str, path: &Path) -> String {
    let msg = msg.replace(&path.display().to_string(), "");
    let msg = msg.trim_start_matches(|c: char| c == ':' || c.is_ascii_digit() || c == ' ');
    let mut out = String::new();
    let mut in_quote = false;
    for c in msg.chars() {
        if c == '\'' {
            in_quote = !in_quote;
            if in_quote {
                out.push_str("'…");
            }
        }
        if in_quote {
            continue;
        }
        if c.is_ascii_digit() {
            if !out.ends_with('N') {
                out.push('N');
            }
        } else {
            out.push(c);
        }
    }
    out
}

#[test]
fn assimp_corpus_never_panics_or_hangs() {
    let root = Path::new("/usr/share/assimp/models");
    if !root.is_dir() {
        println!(
            "note: {} is absent (apt-get install assimp-testmodels); corpus check skipped",
            root.display()
        );
        return;
    }
    let mut files = Vec::new();
    let mut dirs = vec![root.to_path_buf()];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if let Some(ext) = p.extension().and_then(|e| e.to_str())
                && ["obj", "ply", "stl", "gltf", "glb"].contains(&ext.to_ascii_lowercase().as_str())
            {
                files.push(p);
            }
        }
    }
    files.sort();
    let start = Instant::now();
    let mut loaded = 0;
    let mut kinds: BTreeMap<String, Vec<String>> = BTreeMap::new();
    let mut bad = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(root).unwrap().display().to_string();
        match load_guarded(f, Duration::from_secs(10)) {
            Ok(Ok((n, report))) => {
                loaded += 1;
                println!("ok    {rel}: {n} triangles; {report}");
            }
            Ok(Err(e)) => {
                println!("error {rel}: {e}");
                check_error(&e, f);
                kinds.entry(error_kind(&e.to_string(), f)).or_default().push(rel);
            }
            Err(what) => bad.push(format!("{what} {rel}")),
        }
    }
    println!(
        "\nassimp corpus: {} files, {loaded} loaded, {} failed with an error, in {:?}",
        files.len(),
        files.len() - loaded - bad.len(),
        start.elapsed()
    );
    for (kind, files) in &kinds {
        println!("  {:3} x {kind}   e.g. {}", files.len(), files[0]);
    }
    assert!(bad.is_empty(), "{bad:#?}");
    assert!(start.elapsed() < Duration::from_secs(60));
}

// ---------------------------------------------------------------------------------------
// Mutated files

/// xorshift64*: a small deterministic generator for the mutations.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 { 0 } else { (self.next() % n as u64) as usize }
    }
}

fn mutate(rng: &mut Rng, data: &[u8]) -> Vec<u8> {
    let mut d = data.to_vec();
    for _ in 0..1 + rng.below(3) {
        let at = rng.below(d.len());
        match rng.below(6) {
            0 if !d.is_empty() => d[at] = rng.next() as u8,
            1 if !d.is_empty() => d[at] ^= 1 << rng.below(8),
            2 => d.truncate(rng.below(d.len() + 1)),
            3 => d.insert(at.min(d.len()), b"0123456789 \n-.eE/\xff\0"[rng.below(18)]),
            4 => {
                let text = ["4294967295", "-1", "1e39", "nan", "99999999999", "0", "-0"];
                let t = text[rng.below(text.len())].as_bytes();
                let at = at.min(d.len());
                d.splice(at..at, t.iter().copied());
            }
            _ if d.len() >= 4 => {
                let at = rng.below(d.len() - 3);
                let v: [u32; 4] = [u32::MAX, 0x7FFF_FFFF, 0, 0x8000_0000];
                d[at..at + 4].copy_from_slice(&v[rng.below(4)].to_le_bytes());
            }
            _ => {}
        }
    }
    d
}

#[test]
fn mutated_files_never_panic_or_hang() {
    let dir = tmp();
    let embedded =
        hierarchy_gltf(&format!("data:application/octet-stream;base64,{}", base64(&hierarchy_bin())));
    let sphere = icosphere(1, Vec3::new(0.5, 0.25, -1.0), 2.0);
    let mut seeds: Vec<(&str, Vec<u8>)> = vec![
        ("ply", prism_ascii_ply().into_bytes()),
        ("stl", stl_ascii("t").into_bytes()),
        ("stl", stl_binary(b"solid binary", &TETRA_FACES)),
        ("gltf", embedded.into_bytes()),
        (
            "obj",
            b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\ng a\nf 1//1 2//1 3//1 4//1\nf -4 -2 -1\n"
                .to_vec(),
        ),
    ];
    for ext in ["glb", "ply", "obj"] {
        let p = dir.path().join(format!("seed.{ext}"));
        save_mesh(&sphere, &p).unwrap();
        seeds.push((ext, std::fs::read(&p).unwrap()));
    }
    let mut rng =
        Rng(std::env::var("SDFMESH_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(0x9E37_79B9_7F4A_7C15));
    let (mut ok, mut err) = (0, 0);
    let start = Instant::now();
    // SDFMESH_MUTATIONS raises the count for a longer hunt.
    let per_seed: usize = std::env::var("SDFMESH_MUTATIONS").ok().and_then(|v| v.parse().ok()).unwrap_or(250);
    for (k, (ext, seed)) in seeds.iter().enumerate() {
        for i in 0..per_seed {
            let data = mutate(&mut rng, seed);
            let path = put(dir.path(), &format!("m{k}-{i}.{ext}"), &data);
            match load_guarded(&path, Duration::from_secs(10)) {
                Ok(Ok(_)) => ok += 1,
                Ok(Err(e)) => {
                    err += 1;
                    check_error(&e, &path);
                }
                Err(what) => {
                    let keep = std::env::temp_dir().join(format!("sdfmesh-mutant-{k}-{i}.{ext}"));
                    let _ = std::fs::write(&keep, &data);
                    panic!("{what} on a mutant of seed {k} (saved to {})", keep.display());
                }
            }
            let _ = std::fs::remove_file(&path);
        }
    }
    println!("mutated files: {ok} loaded, {err} errors, in {:?}", start.elapsed());
}

// ---------------------------------------------------------------------------------------
// glTF accessors: sparse, quantized, and every way an accessor can point past its data

/// A one-node, one-mesh glTF whose buffer 0 is the hierarchy test's data (90 bytes: two
/// VEC3 float blocks of 3 and 4 vertices at 0 and 36, three u16 indices at 84).
fn mini_gltf(prim: &str, accessors: &str, views: &str, extra_buffers: &str) -> String {
    let uri = format!("data:application/octet-stream;base64,{}", base64(&hierarchy_bin()));
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0}}], "meshes": [{{"primitives": [{prim}]}}],
  "accessors": [{accessors}], "bufferViews": [{views}],
  "buffers": [{{"uri": "{uri}", "byteLength": 90}}{extra_buffers}]}}"#
    )
}

const VIEWS: &str = r#"{"buffer": 0, "byteOffset": 0, "byteLength": 36},
    {"buffer": 0, "byteOffset": 36, "byteLength": 48},
    {"buffer": 0, "byteOffset": 84, "byteLength": 6}"#;

#[test]
fn gltf_sparse_and_quantized_accessors() {
    let dir = tmp();
    // POSITION with no buffer view: zeros replaced by three sparse values.
    let sparse = mini_gltf(
        r#"{"attributes": {"POSITION": 0}}"#,
        r#"{"componentType": 5126, "count": 3, "type": "VEC3",
            "sparse": {"count": 3, "indices": {"bufferView": 2, "componentType": 5123},
                       "values": {"bufferView": 0}}}"#,
        VIEWS,
        "",
    );
    let (m, _) = load(&put(dir.path(), "sparse.gltf", sparse));
    assert_eq!(m.triangle_count(), 1);
    assert_eq!(m.bounds(), Some((Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0))));

    // KHR_mesh_quantization: u8 positions, 4-byte stride, and normalized i8 normals.
    let q = [0u8, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 127, 0, 0, 0, 127, 0, 0, 0, 127, 0];
    let quant = mini_gltf(
        r#"{"attributes": {"POSITION": 0, "NORMAL": 1}}"#,
        r#"{"bufferView": 3, "componentType": 5121, "count": 3, "type": "VEC3"},
           {"bufferView": 4, "componentType": 5120, "normalized": true, "count": 3, "type": "VEC3"}"#,
        &format!(
            r#"{VIEWS}, {{"buffer": 1, "byteOffset": 0, "byteLength": 12, "byteStride": 4}},
            {{"buffer": 1, "byteOffset": 12, "byteLength": 12, "byteStride": 4}}"#
        ),
        &format!(r#", {{"uri": "data:application/octet-stream;base64,{}", "byteLength": 24}}"#, base64(&q)),
    )
    .replace(r#""asset""#, r#""extensionsRequired": ["KHR_mesh_quantization"], "asset""#);
    let (m, report) = load(&put(dir.path(), "quant.gltf", quant));
    assert_eq!(m.bounds(), Some((Vec3::ZERO, Vec3::new(2.0, 2.0, 0.0))), "{report:?}");
    assert_eq!(m.normals.as_ref().unwrap(), &vec![Vec3::Z; 3]);
}

#[test]
fn gltf_accessors_out_of_bounds() {
    let dir = tmp();
    let tri = r#"{"attributes": {"POSITION": 0}}"#;
    let cases: Vec<(&str, String, &[&str])> = vec![
        (
            "count.gltf",
            mini_gltf(
                tri,
                r#"{"bufferView": 0, "componentType": 5126, "count": 4000000000, "type": "VEC3"}"#,
                VIEWS,
                "",
            ),
            &["accessor 0 (4000000000 elements) needs", "buffer view 0, which has 36"],
        ),
        (
            "stride.gltf",
            mini_gltf(
                tri,
                r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}"#,
                &VIEWS.replacen(r#""byteLength": 36"#, r#""byteLength": 36, "byteStride": 4"#, 1),
                "",
            ),
            &["byteStride 4", "smaller than one element (12 bytes)"],
        ),
        (
            "view.gltf",
            mini_gltf(
                tri,
                r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}"#,
                &VIEWS.replacen(r#""byteOffset": 0"#, r#""byteOffset": 80"#, 1),
                "",
            ),
            &["buffer view 0: bytes 80..116 lie outside buffer 0 (90 bytes)"],
        ),
        (
            "buflen.gltf",
            mini_gltf(
                tri,
                r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}"#,
                VIEWS,
                "",
            )
            .replace(r#""byteLength": 90"#, r#""byteLength": 1000"#),
            &["buffer 0: its data URI holds 90 bytes, fewer than its byteLength 1000"],
        ),
        (
            "zeros.gltf",
            mini_gltf(
                tri,
                r#"{"componentType": 5126, "count": 100000000, "type": "VEC3",
                    "sparse": {"count": 1, "indices": {"bufferView": 2, "componentType": 5123},
                               "values": {"bufferView": 0}}}"#,
                VIEWS,
                "",
            ),
            &["100000000 elements but no buffer view"],
        ),
        (
            "sparse.gltf",
            mini_gltf(
                tri,
                r#"{"componentType": 5126, "count": 2, "type": "VEC3",
                    "sparse": {"count": 3, "indices": {"bufferView": 2, "componentType": 5123},
                               "values": {"bufferView": 0}}}"#,
                VIEWS,
                "",
            ),
            &["sparse index 2 out of range (2 elements)"],
        ),
        (
            "vec2.gltf",
            mini_gltf(
                tri,
                r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC2"}"#,
                VIEWS,
                "",
            ),
            &["POSITION: accessor 0 has type Vec2, expected VEC3"],
        ),
        (
            "twice.gltf",
            mini_gltf(
                tri,
                r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}"#,
                VIEWS,
                "",
            )
            .replace(r#""nodes": [0]"#, r#""nodes": [1, 0]"#)
            .replace(r#""nodes": [{"mesh": 0}]"#, r#""nodes": [{"mesh": 0}, {"children": [0]}]"#),
            &["node 0 is reached twice"],
        ),
        (
            "nesting.gltf",
            format!(
                r#"{{"asset": {{"version": "2.0"}}, "extras": {}{}}}"#,
                "[".repeat(100_000),
                "]".repeat(100_000)
            ),
            &["invalid glTF JSON"],
        ),
    ];
    for (name, json, needles) in cases {
        let start = Instant::now();
        fails(&put(dir.path(), name, json), needles);
        assert!(start.elapsed() < Duration::from_secs(2), "{name}");
    }

    // A deep (non-recursive) chain of 20,000 nodes is walked without recursion.
    let mut nodes: Vec<String> = (0..20_000).map(|i| format!(r#"{{"children": [{}]}}"#, i + 1)).collect();
    nodes.push(r#"{"mesh": 0, "translation": [1, 2, 3]}"#.into());
    let deep =
        mini_gltf(tri, r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}"#, VIEWS, "")
            .replace(r#""nodes": [{"mesh": 0}]"#, &format!(r#""nodes": [{}]"#, nodes.join(",")));
    let (m, _) = load(&put(dir.path(), "deep.gltf", deep));
    assert_eq!(m.bounds().unwrap().0, Vec3::new(1.0, 2.0, 3.0));
}
