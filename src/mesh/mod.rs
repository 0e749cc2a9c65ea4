//! Triangle meshes: the indexed triangle mesh type, its loaders and its writers.
//!
//! [`load_mesh`] reads Wavefront OBJ (through `tobj`), glTF 2.0 (`.gltf` and `.glb`,
//! through the `gltf` crate for the JSON document; buffers, accessors and the binary
//! container are read here with every offset checked), PLY (ASCII and binary, both byte
//! orders) and STL (ASCII and binary), chosen by the file's extension. Every loader
//! validates what it reads and fails with a one-line [`Error::Input`] naming the file, the
//! place (line and column for text formats) and the element at fault; no count read from
//! a file is trusted before it has been compared with the number of bytes that back it.
//!
//! Every loader then applies the same clean-up (see [`LoadReport`]): normals are kept only
//! when every vertex has a finite non-zero one; bit-identical vertices are welded (so
//! formats that repeat vertices per face or per group, such as STL, give a connected
//! mesh); triangles with a repeated vertex or zero area are dropped and counted;
//! vertices no triangle uses are removed.
//!
//! [`simplify::decimate`] decimates a mesh with meshoptimizer's quadric-error simplifier.
//!
//! [`save_mesh`] writes OBJ, binary little-endian PLY and GLB, through a temporary file in
//! the destination's directory that is renamed over the destination only once complete.

use std::collections::HashMap;
use std::fmt;
use std::path::Path;

use glam::{Affine3A, Mat3A, Vec3, Vec3A};

use crate::error::{Error, Result};

mod build;
mod gltf_io;
mod obj;
mod ply;
pub mod simplify;
mod stl;
mod text;
pub(crate) mod write;

/// An indexed triangle mesh.
///
/// Positions are in the file's (or the scene's) units; nothing is rescaled on loading.
/// Triangles list their corners counter-clockwise as seen from the side the surface faces
/// (the glTF, OBJ, PLY and STL convention), so `(b - a) × (c - a)` points outwards.
///
/// Invariants that every loader guarantees (and [`TriangleMesh::validate`] checks):
/// - every index is `< positions.len()`;
/// - every position is finite;
/// - no triangle repeats a vertex or has zero area (see [`is_degenerate`]);
/// - `normals`, when present, has one unit-length, finite normal per position.
///
/// Methods that edit the mesh ([`TriangleMesh::transform`], [`TriangleMesh::merge`])
/// keep the index and normal invariants; a singular transform may create zero-area
/// triangles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Triangles as indices into `positions`.
    pub triangles: Vec<[u32; 3]>,
    /// Optional per-vertex unit normals, `normals.len() == positions.len()`.
    pub normals: Option<Vec<Vec3>>,
}

/// What a loader did to the file's geometry on its way to a [`TriangleMesh`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoadReport {
    /// Triangles read from the file (after triangulating polygons, strips and fans),
    /// before any was dropped.
    pub triangles_read: usize,
    /// Triangles dropped because two of their corners are the same vertex (after
    /// welding) or because their area is zero (see [`is_degenerate`]).
    pub degenerate_dropped: usize,
    /// Vertices merged into an earlier vertex with bit-identical position (and normal).
    pub vertices_welded: usize,
    /// Vertices removed because no triangle used them.
    pub unreferenced_vertices_removed: usize,
    /// Non-triangle primitives skipped: glTF point and line primitives, OBJ points and
    /// lines, PLY triangle strips too short to hold a triangle. (An OBJ or PLY face or an
    /// STL facet with fewer than three corners is an error, as is an STL facet with more.)
    pub skipped_primitives: usize,
    /// One-line remarks about anything else ignored that the format allows (normals
    /// dropped, extensions or unused elements ignored ...).
    pub notes: Vec<String>,
    /// Departures from the format that real-world exporters write and that the loader
    /// therefore tolerates (free text in a PLY header, a few padding bytes after a binary
    /// STL's triangles, an OBJ statement that is no OBJ keyword ...): one-line messages
    /// naming the file, the place and the element. [`load_mesh`] prints each on stderr
    /// as `warning: ...`; everything the format forbids outright is an error instead.
    pub warnings: Vec<String>,
}

impl fmt::Display for LoadReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} triangles read, {} degenerate dropped, {} vertices welded, {} unreferenced \
             vertices removed, {} non-triangle primitives skipped",
            self.triangles_read,
            self.degenerate_dropped,
            self.vertices_welded,
            self.unreferenced_vertices_removed,
            self.skipped_primitives
        )?;
        for n in &self.notes {
            write!(f, "; {n}")?;
        }
        for w in &self.warnings {
            write!(f, "; warning: {w}")?;
        }
        Ok(())
    }
}

/// The mesh file formats, chosen by file extension (case-insensitive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// Stanford PLY (`.ply`), ASCII or binary.
    Ply,
    /// STL (`.stl`), ASCII or binary.
    Stl,
    /// glTF 2.0 JSON (`.gltf`), with external or embedded (`data:`) buffers.
    Gltf,
    /// glTF 2.0 binary container (`.glb`).
    Glb,
}

/// Extensions [`load_mesh`] reads.
pub const LOADABLE_EXTENSIONS: &[&str] = &["obj", "ply", "stl", "gltf", "glb"];
/// Extensions [`save_mesh`] writes.
pub const WRITABLE_EXTENSIONS: &[&str] = &["obj", "ply", "glb"];

impl MeshFormat {
    /// The format that `path`'s extension names, or `None`.
    pub fn from_path(path: &Path) -> Option<MeshFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "obj" => MeshFormat::Obj,
            "ply" => MeshFormat::Ply,
            "stl" => MeshFormat::Stl,
            "gltf" => MeshFormat::Gltf,
            "glb" => MeshFormat::Glb,
            _ => return None,
        })
    }
}

fn list_extensions(exts: &[&str]) -> String {
    exts.iter().map(|e| format!(".{e}")).collect::<Vec<_>>().join(", ")
}

fn format_for(path: &Path, supported: &[&str], verb: &str) -> Result<MeshFormat> {
    let fmt = MeshFormat::from_path(path);
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    match (fmt, ext) {
        (Some(f), Some(e)) if supported.contains(&e.as_str()) => Ok(f),
        (_, Some(e)) => Err(Error::input(
            path,
            None,
            format!("cannot {verb} mesh format '.{e}' (supported: {})", list_extensions(supported)),
        )),
        (_, None) => Err(Error::input(
            path,
            None,
            format!("no file extension to tell the mesh format (supported: {})", list_extensions(supported)),
        )),
    }
}

/// Loads a triangle mesh, choosing the format by `path`'s extension (see
/// [`LOADABLE_EXTENSIONS`]).
///
/// All objects, groups, nodes and primitives are merged into one mesh (glTF node
/// transforms applied). Returns the mesh and what was dropped or ignored on the way;
/// each of the report's [`LoadReport::warnings`] is also printed on stderr.
///
/// # Errors
/// [`Error::Io`] when the file cannot be read; [`Error::Input`] for an unknown extension,
/// malformed or truncated data, a non-finite vertex, an index out of range, a recursive
/// glTF node graph, a missing glTF buffer, or when no triangle remains.
pub fn load_mesh(path: &Path) -> Result<(TriangleMesh, LoadReport)> {
    let format = format_for(path, LOADABLE_EXTENSIONS, "read")?;
    let data = crate::files::read_input(path, crate::files::MAX_INPUT_BYTES)?;
    let loaded = load_mesh_bytes(path, data, format)?;
    for w in &loaded.1.warnings {
        eprintln!("warning: {w}");
    }
    Ok(loaded)
}

/// Loads a triangle mesh of `format` from bytes already in memory, exactly as
/// [`load_mesh`] would from a file holding them (used by the fuzz targets in `fuzz/`).
///
/// `path` is not read: it names the data in error messages and, for glTF, is the file
/// whose folder relative buffer URIs are resolved against. [`MeshFormat::Gltf`] and
/// [`MeshFormat::Glb`] behave alike (the GLB magic decides). Warnings are returned in
/// the report, not printed.
///
/// # Errors
/// As [`load_mesh`], except that the extension of `path` is not checked.
pub fn load_mesh_bytes(path: &Path, data: Vec<u8>, format: MeshFormat) -> Result<(TriangleMesh, LoadReport)> {
    let raw = match format {
        MeshFormat::Obj => obj::read(path, data)?,
        MeshFormat::Ply => ply::read(path, &data)?,
        MeshFormat::Stl => stl::read(path, &data)?,
        MeshFormat::Gltf | MeshFormat::Glb => gltf_io::read(path, &data)?,
    };
    build::finish(path, raw)
}

/// Writes `mesh` in the format `path`'s extension names (see [`WRITABLE_EXTENSIONS`]):
/// OBJ (with `vn` lines when the mesh has normals), binary little-endian PLY, or GLB
/// (one mesh, one primitive: `POSITION` with min/max, `NORMAL` when present, `u32`
/// indices).
///
/// The data goes to a temporary file in the same directory which is renamed over `path`
/// only when complete; on failure no file is left behind.
///
/// # Errors
/// [`Error::Input`] for an unsupported extension or a mesh that breaks the
/// [`TriangleMesh`] invariants (or has no triangles); [`Error::Io`] when the directory
/// does not exist or writing fails.
pub fn save_mesh(mesh: &TriangleMesh, path: &Path) -> Result<()> {
    let format = format_for(path, WRITABLE_EXTENSIONS, "write")?;
    if let Err(msg) = mesh.validate() {
        return Err(Error::input(path, None, format!("cannot write mesh: {msg}")));
    }
    if mesh.triangles.is_empty() {
        return Err(Error::input(path, None, "cannot write mesh: no triangles"));
    }
    let bytes = match format {
        MeshFormat::Obj => write::obj_bytes(mesh),
        MeshFormat::Ply => write::ply_bytes(mesh),
        MeshFormat::Glb => gltf_io::glb_bytes(mesh)
            .map_err(|msg| Error::input(path, None, format!("cannot write mesh: {msg}")))?,
        MeshFormat::Stl | MeshFormat::Gltf => unreachable!("not in WRITABLE_EXTENSIONS"),
    };
    crate::files::write_atomic_bytes(path, &bytes)
}

/// Whether the triangle `a, b, c` has zero area to `f32` precision: the cross product of
/// two edges, computed in `f64` from the `f32` corners (exactly, up to one rounding), is
/// at most `1e-10` times the longest edge squared, i.e. the triangle's smallest angle is
/// below about `1e-10` radians. Also true when two corners coincide. Scale-invariant.
pub fn is_degenerate(a: Vec3, b: Vec3, c: Vec3) -> bool {
    let a = a.as_dvec3();
    let (e1, e2, e3) = (b.as_dvec3() - a, c.as_dvec3() - a, c.as_dvec3() - b.as_dvec3());
    let longest2 = e1.length_squared().max(e2.length_squared()).max(e3.length_squared());
    let cross = e1.cross(e2).length();
    // Finite f32 inputs cannot overflow f64 here, so `cross` is never NaN.
    cross <= 1e-10 * longest2
}

impl TriangleMesh {
    /// The axis-aligned box of all positions, as `(min, max)`; `None` when there are none.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let first = *self.positions.first()?;
        Some(self.positions.iter().fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))))
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Bytes of memory this mesh holds: the struct itself plus the allocated capacity of
    /// each vector.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.positions.capacity() * std::mem::size_of::<Vec3>()
            + self.triangles.capacity() * std::mem::size_of::<[u32; 3]>()
            + self.normals.as_ref().map_or(0, |n| n.capacity() * std::mem::size_of::<Vec3>())
    }

    /// Checks the [`TriangleMesh`] invariants, describing the first one broken.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let n = self.positions.len();
        if n > u32::MAX as usize {
            return Err(format!("{n} vertices is more than u32 indices can address"));
        }
        for (i, p) in self.positions.iter().enumerate() {
            if let Some(what) = build::non_finite(*p) {
                return Err(format!("vertex {i}: coordinate is {what}"));
            }
        }
        for (i, t) in self.triangles.iter().enumerate() {
            for &v in t {
                if v as usize >= n {
                    return Err(format!("triangle {i}: index {v} out of range ({n} vertices)"));
                }
            }
        }
        if let Some(normals) = &self.normals {
            if normals.len() != n {
                return Err(format!("{} normals for {n} vertices", normals.len()));
            }
            for (i, v) in normals.iter().enumerate() {
                if !v.is_finite() || (v.length() - 1.0).abs() > 1e-3 {
                    return Err(format!("vertex {i}: normal {v} is not unit length"));
                }
            }
        }
        Ok(())
    }

    /// Replaces `normals` with area-weighted vertex normals: each vertex gets the
    /// normalised sum of the (unnormalised, so area-weighted) face normals of the
    /// triangles around it. A vertex whose sum vanishes (no triangle, or faces that
    /// cancel) gets the unit normal of its first triangle, or `+Z` when it has none.
    pub fn compute_vertex_normals(&mut self) {
        let n = self.positions.len();
        let mut sum = vec![Vec3A::ZERO; n];
        let mut first = vec![Vec3A::ZERO; n];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| Vec3A::from(self.positions[i as usize]));
            let face = (b - a).cross(c - a);
            let unit = face.normalize_or_zero();
            for &i in t {
                sum[i as usize] += face;
                if first[i as usize] == Vec3A::ZERO {
                    first[i as usize] = unit;
                }
            }
        }
        let normals = sum
            .iter()
            .zip(&first)
            .map(|(s, f)| {
                let v = s.normalize_or_zero();
                let v = if v == Vec3A::ZERO { *f } else { v };
                if v == Vec3A::ZERO { Vec3::Z } else { Vec3::from(v) }
            })
            .collect();
        self.normals = Some(normals);
    }

    /// Appends `other`'s vertices and triangles (its indices shifted). Normals are kept
    /// when both meshes have them (or when `self` is empty and `other` has them);
    /// otherwise the result has none.
    ///
    /// # Panics
    /// When the merged mesh would have more than `u32::MAX` vertices.
    pub fn merge(&mut self, other: &TriangleMesh) {
        let offset = self.positions.len();
        assert!(
            offset + other.positions.len() <= u32::MAX as usize,
            "merged mesh would exceed u32::MAX vertices"
        );
        let offset = offset as u32;
        self.normals = match (self.normals.take(), &other.normals) {
            (Some(mut a), Some(b)) => {
                a.extend_from_slice(b);
                Some(a)
            }
            (None, Some(_)) if self.positions.is_empty() && self.triangles.is_empty() => {
                other.normals.clone()
            }
            _ => None,
        };
        self.positions.extend_from_slice(&other.positions);
        self.triangles.extend(other.triangles.iter().map(|t| t.map(|i| i + offset)));
    }

    /// Applies `m` to the positions; normals are transformed by the inverse transpose of
    /// the linear part and renormalised. A mirroring transform (negative determinant)
    /// also reverses every triangle's winding so that the triangles keep facing out. A
    /// singular or non-finite transform drops the normals (they are undefined).
    pub fn transform(&mut self, m: &Affine3A) {
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        let det = m.matrix3.determinant();
        if det < 0.0 {
            for t in &mut self.triangles {
                t.swap(1, 2);
            }
        }
        if let Some(normals) = &mut self.normals {
            let nm: Mat3A = m.matrix3.inverse().transpose();
            let ok = det != 0.0 && det.is_finite() && nm.is_finite();
            let mut all_ok = ok;
            if ok {
                for n in normals.iter_mut() {
                    let v = (nm * Vec3A::from(*n)).normalize_or_zero();
                    if v == Vec3A::ZERO || !v.is_finite() {
                        all_ok = false;
                        break;
                    }
                    *n = v.into();
                }
            }
            if !all_ok {
                self.normals = None;
            }
        }
    }

    /// Number of undirected edges that are not shared by exactly two triangles using
    /// them in opposite directions: boundary edges, non-manifold edges (three or more
    /// triangles) and edges where neighbouring triangles disagree on orientation. Works
    /// on indices, so it is meaningful for welded meshes (which the loaders produce).
    pub fn boundary_edge_count(&self) -> usize {
        // Each directed edge a->b becomes (min, max, forward?) packed in a u64 + flag.
        let mut edges: Vec<(u64, bool)> = Vec::with_capacity(self.triangles.len() * 3);
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let (lo, hi, fwd) = if a < b { (a, b, true) } else { (b, a, false) };
                edges.push(((lo as u64) << 32 | hi as u64, fwd));
            }
        }
        edges.sort_unstable();
        let mut bad = 0;
        let mut i = 0;
        while i < edges.len() {
            let mut j = i;
            while j < edges.len() && edges[j].0 == edges[i].0 {
                j += 1;
            }
            // Sorted: false sorts before true, so a good pair is exactly [false, true].
            let good = j - i == 2 && !edges[i].1 && edges[i + 1].1;
            if !good {
                bad += 1;
            }
            i = j;
        }
        bad
    }

    /// The undirected edges (vertex index pairs, smaller first, sorted) shared by an odd
    /// number of triangles: the borders of holes. Empty when the mesh separates space
    /// (every edge shared by an even number of triangles, whatever their orientation).
    pub fn odd_edges(&self) -> Vec<(u32, u32)> {
        let mut edges: Vec<(u32, u32)> = self
            .triangles
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        edges.sort_unstable();
        edges.chunk_by(|a, b| a == b).filter(|run| run.len() % 2 == 1).map(|run| run[0]).collect()
    }

    /// Whether the mesh is a closed, consistently oriented 2-manifold in terms of edges:
    /// it has triangles and every undirected edge is used by exactly two triangles in
    /// opposite directions (see [`TriangleMesh::boundary_edge_count`]).
    pub fn is_closed(&self) -> bool {
        !self.triangles.is_empty() && self.boundary_edge_count() == 0
    }

    /// Merges vertices with bit-identical positions (and normals, when present), keeping
    /// the first occurrence; returns how many were merged. Triangles keep their order.
    pub fn weld(&mut self) -> usize {
        let key = |i: usize| -> [u32; 6] {
            // `+ 0.0` turns -0.0 into +0.0 so that the two zeros weld.
            let p = self.positions[i] + Vec3::ZERO;
            let n = self.normals.as_ref().map_or(Vec3::ZERO, |n| n[i] + Vec3::ZERO);
            [p.x.to_bits(), p.y.to_bits(), p.z.to_bits(), n.x.to_bits(), n.y.to_bits(), n.z.to_bits()]
        };
        let n = self.positions.len();
        let mut map: HashMap<[u32; 6], u32> = HashMap::with_capacity(n);
        let mut remap = Vec::with_capacity(n);
        let mut keep = Vec::with_capacity(n);
        for i in 0..n {
            let next = keep.len() as u32;
            let id = *map.entry(key(i)).or_insert(next);
            if id == next {
                keep.push(i);
            }
            remap.push(id);
        }
        let merged = n - keep.len();
        if merged > 0 {
            self.positions = keep.iter().map(|&i| self.positions[i]).collect();
            if let Some(normals) = &self.normals {
                self.normals = Some(keep.iter().map(|&i| normals[i]).collect());
            }
            for t in &mut self.triangles {
                *t = t.map(|i| remap[i as usize]);
            }
        }
        merged
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> TriangleMesh {
        TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            normals: None,
        }
    }

    #[test]
    fn degenerate_test_is_scale_invariant() {
        for s in [1e-20f32, 1e-3, 1.0, 1e3, 1e18] {
            let (a, b) = (Vec3::ZERO, Vec3::X * s);
            assert!(is_degenerate(a, b, Vec3::X * 0.5 * s), "collinear at scale {s}");
            assert!(is_degenerate(a, b, b), "repeated corner at scale {s}");
            assert!(!is_degenerate(a, b, Vec3::new(0.5, 1e-6, 0.0) * s), "thin at scale {s}");
        }
        assert!(is_degenerate(Vec3::ONE, Vec3::ONE, Vec3::ONE));
    }

    #[test]
    fn edges_boundary_non_manifold_and_orientation() {
        let q = quad();
        assert_eq!(q.boundary_edge_count(), 4);
        assert!(!q.is_closed());
        // A fin on the diagonal: that edge is used three times.
        let mut fin = q.clone();
        fin.positions.push(Vec3::Z);
        fin.triangles.push([0, 2, 4]);
        assert_eq!(fin.boundary_edge_count(), 4 + 1 + 2);
        // Two triangles using their shared edge in the same direction.
        let mut flipped = q.clone();
        flipped.triangles[1] = [0, 3, 2];
        assert_eq!(flipped.boundary_edge_count(), 5);
        // Odd edges: the quad's border; the fin's three uses of the diagonal and its two
        // new edges are odd too; orientation does not matter.
        let border = q.odd_edges();
        assert_eq!(border.len(), 4);
        assert!(!border.contains(&(0, 2)));
        assert_eq!(fin.odd_edges().len(), 4 + 1 + 2);
        assert_eq!(flipped.odd_edges(), border);
        // Doubling every triangle makes every edge even.
        let mut doubled = q.clone();
        doubled.triangles.extend(q.triangles.iter().map(|&[a, b, c]| [a, c, b]));
        assert!(doubled.odd_edges().is_empty());
    }

    #[test]
    fn weld_merges_identical_vertices_and_both_zeros() {
        let mut m = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(-0.0, 0.0, 0.0), Vec3::Y],
            triangles: vec![[0, 1, 2], [3, 1, 4]],
            normals: None,
        };
        assert_eq!(m.weld(), 2);
        assert_eq!(m.positions, vec![Vec3::ZERO, Vec3::X, Vec3::Y]);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 1, 2]]);
        // Different normals keep vertices apart.
        let mut n = quad();
        n.positions.push(Vec3::ZERO);
        n.normals = Some(vec![Vec3::Z, Vec3::Z, Vec3::Z, Vec3::Z, -Vec3::Z]);
        assert_eq!(n.weld(), 0);
    }

    #[test]
    fn normals_transform_and_validate() {
        let mut q = quad();
        q.positions.push(Vec3::splat(9.0)); // unreferenced: gets +Z
        q.compute_vertex_normals();
        assert_eq!(q.normals.as_ref().unwrap(), &vec![Vec3::Z; 5]);
        assert!(q.validate().is_ok());
        q.transform(&Affine3A::from_scale(Vec3::new(1.0, 1.0, 0.0)));
        assert!(q.normals.is_none(), "a singular transform drops normals");
        q.triangles.push([0, 1, 7]);
        assert!(q.validate().unwrap_err().contains("index 7 out of range"));
        q.triangles.pop();
        q.positions[0].x = f32::NAN;
        assert!(q.validate().unwrap_err().contains("vertex 0: coordinate is NaN"));
    }

    #[test]
    fn bytes_used_counts_capacity() {
        let mut m = quad();
        m.positions.reserve_exact(100);
        let expected =
            std::mem::size_of::<TriangleMesh>() + m.positions.capacity() * 12 + m.triangles.capacity() * 12;
        assert_eq!(m.bytes_used(), expected);
        assert!(m.positions.capacity() >= 104);
    }

    #[test]
    fn formats_by_extension() {
        assert_eq!(MeshFormat::from_path(Path::new("a/b.GLB")), Some(MeshFormat::Glb));
        assert_eq!(MeshFormat::from_path(Path::new("a.Stl")), Some(MeshFormat::Stl));
        assert_eq!(MeshFormat::from_path(Path::new("a.off")), None);
        assert_eq!(MeshFormat::from_path(Path::new("obj")), None);
    }
}
