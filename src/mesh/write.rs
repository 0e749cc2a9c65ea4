//! Writers for OBJ and PLY: the bytes of a file (written by [`crate::files::write_atomic_bytes`]).

use std::fmt::Write as _;

use super::TriangleMesh;

/// OBJ text: `v` lines, `vn` lines when there are normals, then `f` lines (1-based, with
/// `v//vn` references when there are normals). `f32` values are printed in the shortest
/// form that reads back to the same value.
pub(crate) fn obj_bytes(mesh: &TriangleMesh) -> Vec<u8> {
    let mut s = String::with_capacity(mesh.positions.len() * 40 + mesh.triangles.len() * 30);
    let _ = writeln!(
        s,
        "# written by sdfmesh: {} vertices, {} triangles",
        mesh.positions.len(),
        mesh.triangles.len()
    );
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
    }
    if let Some(normals) = &mesh.normals {
        for n in normals {
            let _ = writeln!(s, "vn {} {} {}", n.x, n.y, n.z);
        }
    }
    let with_normals = mesh.normals.is_some();
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i + 1);
        if with_normals {
            let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
        } else {
            let _ = writeln!(s, "f {a} {b} {c}");
        }
    }
    s.into_bytes()
}

/// Binary little-endian PLY: float x, y, z (and nx, ny, nz), faces as `uchar`-counted
/// lists of `uint` indices.
pub(crate) fn ply_bytes(mesh: &TriangleMesh) -> Vec<u8> {
    let mut header = String::new();
    header.push_str("ply\nformat binary_little_endian 1.0\ncomment written by sdfmesh\n");
    let _ = writeln!(header, "element vertex {}", mesh.positions.len());
    header.push_str("property float x\nproperty float y\nproperty float z\n");
    if mesh.normals.is_some() {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    let _ = writeln!(header, "element face {}", mesh.triangles.len());
    header.push_str("property list uchar uint vertex_indices\nend_header\n");
    let per_vertex = if mesh.normals.is_some() { 24 } else { 12 };
    let mut out =
        Vec::with_capacity(header.len() + mesh.positions.len() * per_vertex + mesh.triangles.len() * 13);
    out.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        for c in p.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
        if let Some(normals) = &mesh.normals {
            for c in normals[i].to_array() {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    for t in &mesh.triangles {
        out.push(3);
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    out
}
