//! `sdfmesh._sdfmesh`: the Python extension module over the sdfmesh library (PyO3 and
//! numpy). Thin: every array argument is checked once here (dtype, shape, finite values,
//! index ranges) and refused with a `ValueError` naming the argument and the element;
//! the work runs in the library with the GIL released, in parallel with rayon. Library
//! errors become `ValueError` (bad input, usage) or `OSError` (files) with the library's
//! one-line message.

use std::path::PathBuf;
use std::sync::OnceLock;

use clap::Parser;
use glam::{UVec3, Vec3};
use numpy::ndarray::{Array2, ArrayView2, ArrayView3, ShapeBuilder};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rayon::prelude::*;

use sdfmesh_lib::base::aabb;
use sdfmesh_lib::config::args::{Cli, Command};
use sdfmesh_lib::config::{EXTRACTION_RESOLUTION, SAMPLING_RESOLUTION, Task};
use sdfmesh_lib::convert::extract::{ExtractMethod, Field, extract_object};
use sdfmesh_lib::convert::mesh_to_grid::closest::{NodeStack, TriangleBvh};
use sdfmesh_lib::convert::mesh_to_grid::voxelize::voxelize_mesh;
use sdfmesh_lib::convert::mesh_to_grid::winding::{self, FastWinding};
use sdfmesh_lib::convert::mesh_to_grid::{MeshSampler, sample_mesh};
use sdfmesh_lib::error::Error;
use sdfmesh_lib::geometry::grid::SdfGrid;
use sdfmesh_lib::grid::io::save_grid;
use sdfmesh_lib::mesh::{TriangleMesh, is_degenerate, save_mesh};
use sdfmesh_lib::plan::budget::MemoryBudget;
use sdfmesh_lib::plan::{MeshMethod, grid_file_mesh};
use sdfmesh_lib::render::report::render_scene;
use sdfmesh_lib::scene::{load_input, load_scene};

/// Points per parallel task of the point queries: consecutive points (in Morton order)
/// share one sampler, whose previous answer bounds and starts the next query.
const CHUNK: usize = 2048;

/// The library's error as a Python exception with its one-line message.
fn py_err(e: Error) -> PyErr {
    match e {
        Error::Io { .. } => PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

fn value_error(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}

/// `"dtype float64, shape (3, 4)"` of any numpy array.
fn describe(a: &Bound<'_, PyUntypedArray>) -> String {
    let dtype = a.dtype().str().map(|s| s.to_string()).unwrap_or_else(|_| "?".into());
    let shape: Vec<String> = a.shape().iter().map(|d| d.to_string()).collect();
    let shape = if shape.len() == 1 { format!("({},)", shape[0]) } else { format!("({})", shape.join(", ")) };
    format!("dtype {dtype}, shape {shape}")
}

/// Rows of an `(N, 3)` float32 or float64 array (any strides) as points; every
/// coordinate must be finite. `name` names the argument in errors.
fn points_arg(obj: &Bound<'_, PyAny>, name: &str, allow_empty: bool) -> PyResult<Vec<Vec3>> {
    fn rows<T: Copy + Into<f64>>(v: ArrayView2<'_, T>, name: &str) -> PyResult<Vec<Vec3>> {
        let mut out = Vec::with_capacity(v.nrows());
        for (i, r) in v.outer_iter().enumerate() {
            let p = [r[0].into(), r[1].into(), r[2].into()];
            for (a, &c) in p.iter().enumerate() {
                if !c.is_finite() {
                    return Err(value_error(format!("{name}[{i}, {a}] is {c}: coordinates must be finite")));
                }
                if c.abs() > f32::MAX as f64 {
                    return Err(value_error(format!("{name}[{i}, {a}] = {c} does not fit in float32")));
                }
            }
            out.push(Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32));
        }
        Ok(out)
    }
    let Ok(any) = obj.cast::<PyUntypedArray>() else {
        return Err(value_error(format!(
            "{name} must be a numpy array of shape (N, 3), dtype float32 or float64, not {}",
            obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into())
        )));
    };
    let bad = || {
        value_error(format!(
            "{name} must be a numpy array of shape (N, 3), dtype float32 or float64; got {}",
            describe(any)
        ))
    };
    if any.ndim() != 2 || any.shape()[1] != 3 {
        return Err(bad());
    }
    if any.shape()[0] == 0 && !allow_empty {
        return Err(value_error(format!("{name} is empty: {}", describe(any))));
    }
    let borrow = |e: numpy::BorrowError| value_error(format!("{name}: {e}"));
    if let Ok(a) = obj.cast::<PyArray2<f32>>() {
        let r = a.try_readonly().map_err(borrow)?;
        rows(r.as_array(), name)
    } else if let Ok(a) = obj.cast::<PyArray2<f64>>() {
        let r = a.try_readonly().map_err(borrow)?;
        rows(r.as_array(), name)
    } else {
        Err(bad())
    }
}

/// Rows of an `(F, 3)` integer array as triangles, every index in `0..vertices`.
fn faces_arg(obj: &Bound<'_, PyAny>, vertices: usize) -> PyResult<Vec<[u32; 3]>> {
    fn rows<T: Copy + TryInto<i128>>(v: ArrayView2<'_, T>, vertices: usize) -> PyResult<Vec<[u32; 3]>> {
        let mut out = Vec::with_capacity(v.nrows());
        for (i, r) in v.outer_iter().enumerate() {
            let mut t = [0u32; 3];
            for (a, slot) in t.iter_mut().enumerate() {
                let x: i128 = r[a].try_into().unwrap_or(i128::MAX);
                if x < 0 || x >= vertices as i128 {
                    return Err(value_error(format!(
                        "faces[{i}, {a}] = {x} is out of range ({vertices} vertices)"
                    )));
                }
                *slot = x as u32;
            }
            out.push(t);
        }
        Ok(out)
    }
    let Ok(any) = obj.cast::<PyUntypedArray>() else {
        return Err(value_error("faces must be a numpy integer array of shape (F, 3)"));
    };
    if any.ndim() != 2 || any.shape()[1] != 3 {
        return Err(value_error(format!(
            "faces must be a numpy integer array of shape (F, 3); got {}",
            describe(any)
        )));
    }
    if any.shape()[0] == 0 {
        return Err(value_error(format!("faces is empty: {}", describe(any))));
    }
    let borrow = |e: numpy::BorrowError| value_error(format!("faces: {e}"));
    macro_rules! try_int {
        ($($t:ty),*) => {$(
            if let Ok(a) = obj.cast::<PyArray2<$t>>() {
                let r = a.try_readonly().map_err(borrow)?;
                return rows(r.as_array(), vertices);
            }
        )*};
    }
    try_int!(i64, i32, u32, u64, i16, u16, i8, u8);
    Err(value_error(format!("faces must have an integer dtype; got {}", describe(any))))
}

/// The search structures of a mesh, built on first use.
struct Prepared {
    tree: TriangleBvh,
    wind: FastWinding,
    closed: bool,
}

/// A triangle mesh (float32 vertices, uint32 faces). Immutable: `vertices` and `faces`
/// return copies; the search structures (BVH, winding-number data) are built on the first
/// query and reused by later ones.
#[pyclass(frozen, module = "sdfmesh")]
struct Mesh {
    mesh: TriangleMesh,
    /// For each triangle of `mesh`, its row in the faces given to `from_arrays` (which
    /// drops degenerate triangles); `None` when they are the same.
    face_map: Option<Vec<u32>>,
    prepared: OnceLock<Prepared>,
}

impl Mesh {
    fn new(mesh: TriangleMesh, face_map: Option<Vec<u32>>) -> Self {
        Mesh { mesh, face_map, prepared: OnceLock::new() }
    }

    /// The search structures (built without the GIL on first use).
    fn prepared(&self, py: Python<'_>) -> &Prepared {
        if let Some(p) = self.prepared.get() {
            return p;
        }
        let p = py.detach(|| {
            let tree = TriangleBvh::new(&self.mesh);
            let wind = FastWinding::new(&tree);
            Prepared { tree, wind, closed: winding::is_closed(&self.mesh) }
        });
        let _ = self.prepared.set(p);
        self.prepared.get().expect("set above")
    }

    fn original_face(&self, t: u32) -> i64 {
        match &self.face_map {
            Some(m) => m[t as usize] as i64,
            None => t as i64,
        }
    }
}

#[pymethods]
impl Mesh {
    /// A mesh from a float32/float64 array of vertices (V, 3) and an integer array of
    /// faces (F, 3) indexing them (counter-clockwise seen from outside). Degenerate faces
    /// (repeated or collinear corners) are dropped; `closest_points` reports face
    /// indices into the `faces` given here.
    #[staticmethod]
    fn from_arrays(vertices: &Bound<'_, PyAny>, faces: &Bound<'_, PyAny>) -> PyResult<Mesh> {
        let positions = points_arg(vertices, "vertices", false)?;
        if positions.len() > u32::MAX as usize {
            return Err(value_error("more vertices than uint32 indices can address"));
        }
        let all = faces_arg(faces, positions.len())?;
        let mut triangles = Vec::with_capacity(all.len());
        let mut map = Vec::with_capacity(all.len());
        for (i, t) in all.iter().enumerate() {
            let [a, b, c] = *t;
            let [pa, pb, pc] = t.map(|v| positions[v as usize]);
            if a != b && b != c && a != c && !is_degenerate(pa, pb, pc) {
                triangles.push(*t);
                map.push(i as u32);
            }
        }
        if triangles.is_empty() {
            return Err(value_error(format!("faces: all {} faces are degenerate", all.len())));
        }
        let face_map = (map.len() != all.len()).then_some(map);
        Ok(Mesh::new(TriangleMesh { positions, triangles, normals: None }, face_map))
    }

    /// Vertex positions, float32 (V, 3) (a copy).
    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let flat: Vec<f32> = self.mesh.positions.iter().flat_map(|p| p.to_array()).collect();
        Array2::from_shape_vec((self.mesh.positions.len(), 3), flat).expect("3 per vertex").into_pyarray(py)
    }

    /// Triangles as vertex indices, uint32 (F, 3) (a copy; degenerate faces dropped).
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        let flat: Vec<u32> = self.mesh.triangles.iter().flatten().copied().collect();
        Array2::from_shape_vec((self.mesh.triangles.len(), 3), flat).expect("3 per face").into_pyarray(py)
    }

    /// `(min, max)` corners of the bounding box.
    #[getter]
    fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let (lo, hi) = self.mesh.bounds().unwrap_or_default();
        (lo.to_array(), hi.to_array())
    }

    /// Whether every edge is shared by exactly two consistently oriented faces.
    fn is_closed(&self) -> bool {
        winding::is_closed(&self.mesh)
    }

    /// Writes the mesh (.obj, .ply, .glb, .stl by the extension) atomically.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| save_mesh(&self.mesh, &path)).map_err(py_err)
    }

    fn __len__(&self) -> usize {
        self.mesh.triangles.len()
    }

    fn __repr__(&self) -> String {
        format!("<sdfmesh.Mesh: {} vertices, {} faces>", self.mesh.positions.len(), self.mesh.triangles.len())
    }
}

/// Loads a mesh file (OBJ, glTF/GLB, PLY, STL): vertices welded, degenerate faces dropped.
#[pyfunction]
fn load_mesh(py: Python<'_>, path: PathBuf) -> PyResult<Mesh> {
    let (mesh, _) = py.detach(|| sdfmesh_lib::mesh::load_mesh(&path)).map_err(py_err)?;
    Ok(Mesh::new(mesh, None))
}

/// The indices of `points` in Morton (Z-curve) order of their positions, so that
/// consecutive queries are close together.
fn morton_order(points: &[Vec3]) -> Vec<u32> {
    let (lo, hi) = points
        .par_iter()
        .fold(|| (Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| (lo.min(p), hi.max(p)))
        .reduce(|| (Vec3::INFINITY, Vec3::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    let scale = 1023.0 / (hi - lo).max_element().max(f32::MIN_POSITIVE);
    let spread = |v: u32| -> u64 {
        let mut x = v as u64 & 0x3ff;
        x = (x | (x << 16)) & 0x30000ff;
        x = (x | (x << 8)) & 0x300f00f;
        x = (x | (x << 4)) & 0x30c30c3;
        (x | (x << 2)) & 0x9249249
    };
    let mut keys: Vec<u64> = points
        .par_iter()
        .enumerate()
        .map(|(i, &p)| {
            let q = ((p - lo) * scale).clamp(Vec3::ZERO, Vec3::splat(1023.0)).as_uvec3();
            let code = spread(q.x) | (spread(q.y) << 1) | (spread(q.z) << 2);
            (code << 32) | i as u64
        })
        .collect();
    keys.par_sort_unstable();
    keys.into_iter().map(|k| k as u32).collect()
}

/// Runs `f` over `points` in Morton order in parallel chunks; `f` gets a chunk's points
/// (in that order) and writes one `T` per point.
fn in_order<T: Copy + Default + Send + Sync>(points: &[Vec3], f: impl Fn(&[u32], &mut [T]) + Sync) -> Vec<T> {
    let order = morton_order(points);
    let mut sorted = vec![T::default(); points.len()];
    sorted.par_chunks_mut(CHUNK).zip(order.par_chunks(CHUNK)).for_each(|(out, idx)| f(idx, out));
    let mut out = vec![T::default(); points.len()];
    for (k, &i) in order.iter().enumerate() {
        out[i as usize] = sorted[k];
    }
    out
}

/// Signed distances at `points` (no GIL); negative inside (winding number >= 1/2).
fn signed_distances(p: &Prepared, points: &[Vec3]) -> Vec<f32> {
    in_order(points, |idx, out| {
        let mut s = MeshSampler::new(&p.tree, &p.wind, p.closed);
        for (o, &i) in out.iter_mut().zip(idx) {
            *o = s.sample(points[i as usize]);
        }
    })
}

fn check_points(n: usize) -> PyResult<()> {
    if n > u32::MAX as usize {
        return Err(value_error("more than 2^32 - 1 points in one call"));
    }
    Ok(())
}

/// Signed distance from each of `points` (N, 3) to `mesh`, float32 (N,): exact distance
/// to the nearest triangle, negative where the generalized winding number is >= 1/2
/// (inside; open meshes and soups included).
#[pyfunction]
fn signed_distance<'py>(
    py: Python<'py>,
    mesh: &Mesh,
    points: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    let pts = points_arg(points, "points", true)?;
    check_points(pts.len())?;
    let p = mesh.prepared(py);
    let out = py.detach(|| signed_distances(p, &pts));
    Ok(out.into_pyarray(py))
}

type ClosestResult<'py> = (Bound<'py, PyArray2<f32>>, Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<i64>>);

/// The closest point on `mesh` to each of `points` (N, 3): `(closest (N, 3) float32,
/// distance (N,) float32, face (N,) int64)`, the face indexing the mesh's faces (the
/// faces given to `Mesh.from_arrays`).
#[pyfunction]
fn closest_points<'py>(
    py: Python<'py>,
    mesh: &Mesh,
    points: &Bound<'py, PyAny>,
) -> PyResult<ClosestResult<'py>> {
    let pts = points_arg(points, "points", true)?;
    check_points(pts.len())?;
    let p = mesh.prepared(py);
    let found: Vec<(Vec3, f32, u32)> = py.detach(|| {
        in_order(&pts, |idx, out| {
            let mut stack = NodeStack::with_capacity(128);
            let mut visited = 0u64;
            let mut prev: Option<(Vec3, f32, u32)> = None;
            for (o, &i) in out.iter_mut().zip(idx) {
                let q = pts[i as usize];
                let (hint, bound) = match prev {
                    Some((a, d, slot)) => (Some(slot), (d + (q - a).length()) * (1.0 + 1e-5) + 1e-30),
                    None => (None, f32::INFINITY),
                };
                let near = p
                    .tree
                    .nearest_with_hint(q, hint, bound, &mut stack, &mut visited)
                    .or_else(|| p.tree.nearest(q, f32::INFINITY, &mut stack, &mut visited));
                if let Some(n) = near {
                    let d = n.dist2.sqrt();
                    prev = Some((q, d, n.slot));
                    *o = (n.point, d, n.triangle);
                }
            }
        })
    });
    let n = found.len();
    let flat: Vec<f32> = found.iter().flat_map(|f| f.0.to_array()).collect();
    let closest = Array2::from_shape_vec((n, 3), flat).expect("3 per point").into_pyarray(py);
    let dist: Vec<f32> = found.iter().map(|f| f.1).collect();
    let face: Vec<i64> = found.iter().map(|f| mesh.original_face(f.2)).collect();
    Ok((closest, dist.into_pyarray(py), face.into_pyarray(py)))
}

/// The generalized winding number of `mesh` at each of `points`, float32 (N,): 1 inside
/// and 0 outside a closed mesh, fractional near the holes of open ones. `exact=False` uses
/// the fast (Barnes-Hut) approximation (error about 1e-3, refined near 1/2); `exact=True`
/// sums every triangle's solid angle.
#[pyfunction]
#[pyo3(signature = (mesh, points, exact = false))]
fn winding_number<'py>(
    py: Python<'py>,
    mesh: &Mesh,
    points: &Bound<'py, PyAny>,
    exact: bool,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    let pts = points_arg(points, "points", true)?;
    check_points(pts.len())?;
    let p = mesh.prepared(py);
    let out = py.detach(|| {
        in_order(&pts, |idx, out| {
            let mut stack = Vec::with_capacity(256);
            let mut visited = 0u64;
            for (o, &i) in out.iter_mut().zip(idx) {
                let q = pts[i as usize];
                *o = if exact {
                    p.wind.winding_number(&p.tree, q, f32::INFINITY, &mut stack, &mut visited)
                } else {
                    p.wind.winding_for_sign(&p.tree, q, &mut stack, &mut visited)
                };
            }
        })
    });
    Ok(out.into_pyarray(py))
}

/// A signed distance grid: `values[i, j, k]` (float32, shape (nx, ny, nz), Fortran
/// order, so that x varies fastest in memory as in the library's files) is the signed
/// distance at `origin + (i, j, k) * voxel_size`.
#[pyclass(module = "sdfmesh")]
struct Grid {
    values: Py<PyArray3<f32>>,
    origin: [f32; 3],
    voxel: f32,
}

impl Grid {
    fn from_sdf(py: Python<'_>, g: SdfGrid) -> PyResult<Grid> {
        let dims = (g.dims.x as usize, g.dims.y as usize, g.dims.z as usize);
        let a = numpy::ndarray::Array3::from_shape_vec(dims.f(), g.values)
            .map_err(|e| value_error(format!("grid: {e}")))?;
        Ok(Grid { values: a.into_pyarray(py).unbind(), origin: g.origin.to_array(), voxel: g.voxel })
    }

    /// The library's grid (a copy of `values`, which Python may have edited).
    fn to_sdf(&self, py: Python<'_>) -> PyResult<SdfGrid> {
        let a = self.values.bind(py);
        let r = a.try_readonly().map_err(|e| value_error(format!("grid values: {e}")))?;
        sdf_from_view(r.as_array(), self.origin, self.voxel)
    }
}

/// An [`SdfGrid`] from an (nx, ny, nz) view, checked.
fn sdf_from_view(v: ArrayView3<'_, f32>, origin: [f32; 3], voxel: f32) -> PyResult<SdfGrid> {
    let s = v.shape();
    if s.iter().any(|&d| d < 2 || d > u32::MAX as usize) {
        return Err(value_error(format!(
            "grid values must have at least 2 samples per axis; got shape ({}, {}, {})",
            s[0], s[1], s[2]
        )));
    }
    if !(voxel.is_finite() && voxel > 0.0) {
        return Err(value_error(format!("voxel_size must be finite and > 0; got {voxel}")));
    }
    if !origin.iter().all(|c| c.is_finite()) {
        return Err(value_error(format!("origin must be finite; got {origin:?}")));
    }
    // x fastest: the transposed view's logical order.
    let values: Vec<f32> = v.t().iter().copied().collect();
    if let Some(i) = values.iter().position(|x| x.is_nan()) {
        let (nx, ny) = (s[0], s[1]);
        return Err(value_error(format!(
            "grid values[{}, {}, {}] is NaN",
            i % nx,
            (i / nx) % ny,
            i / (nx * ny)
        )));
    }
    let dims = UVec3::new(s[0] as u32, s[1] as u32, s[2] as u32);
    Ok(SdfGrid { origin: Vec3::from_array(origin), voxel, dims, values })
}

#[pymethods]
impl Grid {
    /// A grid from a float32 array of shape (nx, ny, nz) (copied), the position of sample
    /// (0, 0, 0) and the sample spacing.
    #[new]
    fn py_new(
        py: Python<'_>,
        values: &Bound<'_, PyAny>,
        origin: [f32; 3],
        voxel_size: f32,
    ) -> PyResult<Grid> {
        let a = values.cast::<PyArray3<f32>>().map_err(|_| match values.cast::<PyUntypedArray>() {
            Ok(u) => value_error(format!(
                "values must be a float32 array of shape (nx, ny, nz); got {}",
                describe(u)
            )),
            Err(_) => value_error("values must be a numpy float32 array of shape (nx, ny, nz)"),
        })?;
        let r = a.try_readonly().map_err(|e| value_error(format!("values: {e}")))?;
        let g = sdf_from_view(r.as_array(), origin, voxel_size)?;
        Grid::from_sdf(py, g)
    }

    /// The samples, float32 (nx, ny, nz), Fortran order; the grid's own storage (no copy:
    /// edits show in `save` and `extract`).
    #[getter]
    fn values<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f32>> {
        self.values.bind(py).clone()
    }

    /// Position of sample (0, 0, 0).
    #[getter]
    fn origin(&self) -> [f32; 3] {
        self.origin
    }

    /// Spacing of the samples.
    #[getter]
    fn voxel_size(&self) -> f32 {
        self.voxel
    }

    /// Samples per axis, (nx, ny, nz).
    #[getter]
    fn shape(&self, py: Python<'_>) -> Vec<usize> {
        self.values.bind(py).shape().to_vec()
    }

    /// Writes the grid as `toolkit convert` does: `.sdf` (the toolkit's binary format),
    /// `.npy` or `.vti` by the extension, atomically.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let g = self.to_sdf(py)?;
        py.detach(|| save_grid(&g, &path)).map_err(py_err)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let s = self.values.bind(py).shape().to_vec();
        format!(
            "<sdfmesh.Grid: {}x{}x{} samples, voxel {}, origin {:?}>",
            s[0], s[1], s[2], self.voxel, self.origin
        )
    }
}

/// Samples `mesh`'s signed distance on a grid of `resolution` cells along the longest
/// axis of its bounding box, padded by `margin` cells. `fill="sample"` (exact distances,
/// winding-number signs) or `"voxelize"` (closed meshes only, about a voxel of error).
/// `band=K` truncates the values to +-K voxels (a TSDF); `None` keeps them exact.
#[pyfunction]
#[pyo3(signature = (mesh, resolution, band = None, fill = "sample", margin = 2))]
fn mesh_to_grid(
    py: Python<'_>,
    mesh: &Mesh,
    resolution: u32,
    band: Option<u32>,
    fill: &str,
    margin: u32,
) -> PyResult<Grid> {
    let res = SAMPLING_RESOLUTION.check("resolution", resolution).map_err(py_err)?;
    let voxelize = match fill {
        "sample" => false,
        "voxelize" => true,
        other => return Err(value_error(format!("fill must be \"sample\" or \"voxelize\", not {other:?}"))),
    };
    if band == Some(0) {
        return Err(value_error("band must be at least 1 voxel (or None)"));
    }
    let mut g = py
        .detach(|| {
            if voxelize {
                voxelize_mesh(&mesh.mesh, res, margin)
            } else {
                sample_mesh(&mesh.mesh, res, margin)
            }
        })
        .map_err(py_err)?;
    if let Some(k) = band {
        let t = k as f32 * g.voxel;
        g.values.par_iter_mut().for_each(|v| *v = v.clamp(-t, t));
    }
    Grid::from_sdf(py, g)
}

/// A small, fast generator (SplitMix64) for the sampling recipes: seeded, reproducible.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Standard normal (Box-Muller).
    fn normal(&mut self) -> f64 {
        let u = 1.0 - self.unit();
        let v = self.unit();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

type PointsAndDistances<'py> = (Bound<'py, PyArray2<f32>>, Bound<'py, PyArray1<f32>>);

/// The DeepSDF recipe: `n` points near the surface of `mesh` and their signed distances.
/// Points are drawn uniformly on the surface (area-weighted) and moved by Gaussian noise:
/// half with standard deviation `sigma`, half with `sigma / sqrt(10)` (DeepSDF's variances
/// 0.0025 and 0.00025 for `sigma = 0.05`); a fraction `uniform` of the points is instead
/// uniform in the bounding box grown by 5% per side. Returns `(points (n, 3) float32,
/// sdf (n,) float32)`; `seed` makes the draw reproducible.
#[pyfunction]
#[pyo3(signature = (mesh, n, sigma, uniform = 0.0, seed = 0))]
fn sample_near_surface<'py>(
    py: Python<'py>,
    mesh: &Mesh,
    n: usize,
    sigma: f64,
    uniform: f64,
    seed: u64,
) -> PyResult<PointsAndDistances<'py>> {
    if !(sigma.is_finite() && sigma >= 0.0) {
        return Err(value_error(format!("sigma must be finite and >= 0; got {sigma}")));
    }
    if !(0.0..=1.0).contains(&uniform) {
        return Err(value_error(format!("uniform must be in [0, 1]; got {uniform}")));
    }
    check_points(n)?;
    let m = &mesh.mesh;
    let points: Vec<Vec3> = py.detach(|| {
        // Cumulative areas for area-weighted triangle choice.
        let mut cum = Vec::with_capacity(m.triangles.len());
        let mut total = 0.0f64;
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize].as_dvec3());
            total += 0.5 * (b - a).cross(c - a).length();
            cum.push(total);
        }
        let (lo, hi) = m.bounds().unwrap_or_default();
        let pad = (hi - lo) * 0.05;
        let (lo, ext) = ((lo - pad).as_dvec3(), (hi - lo + 2.0 * pad).as_dvec3());
        let n_uniform = (n as f64 * uniform).round() as usize;
        (0..n)
            .into_par_iter()
            .map(|i| {
                let mut r = SplitMix(seed ^ (i as u64).wrapping_mul(0xd1b5_4a32_d192_ed03));
                r.next();
                if i < n_uniform {
                    let u = glam::DVec3::new(r.unit(), r.unit(), r.unit());
                    return (lo + u * ext).as_vec3();
                }
                let x = r.unit() * total;
                let t = cum.partition_point(|&c| c <= x).min(cum.len() - 1);
                let [a, b, c] = m.triangles[t].map(|v| m.positions[v as usize].as_dvec3());
                let (mut u, mut v) = (r.unit(), r.unit());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                let s = if (i - n_uniform).is_multiple_of(2) { sigma } else { sigma / 10f64.sqrt() };
                let noise = glam::DVec3::new(r.normal(), r.normal(), r.normal()) * s;
                (a + (b - a) * u + (c - a) * v + noise).as_vec3()
            })
            .collect()
    });
    let p = mesh.prepared(py);
    let d = py.detach(|| signed_distances(p, &points));
    let flat: Vec<f32> = points.iter().flat_map(|q| q.to_array()).collect();
    let pts = Array2::from_shape_vec((points.len(), 3), flat).expect("3 per point").into_pyarray(py);
    Ok((pts, d.into_pyarray(py)))
}

fn extract_method(method: &str) -> PyResult<ExtractMethod> {
    match method {
        "mc" => Ok(ExtractMethod::MarchingCubes),
        "mt" => Ok(ExtractMethod::MarchingTetrahedra),
        "dc" => Ok(ExtractMethod::DualContouring),
        other => Err(value_error(format!("method must be \"mc\", \"mt\" or \"dc\", not {other:?}"))),
    }
}

/// A triangle mesh of the zero level set of `source`: a `Grid` (its trilinear
/// interpolation, resampled at `resolution` cells along the longest axis; default the
/// grid's own) or a scene file path (its bounded SDF objects, as `toolkit convert --to
/// mesh`; default 128). `method`: "mc" (marching cubes), "mt" (marching tetrahedra) or
/// "dc" (dual contouring, sharp edges).
#[pyfunction]
#[pyo3(signature = (source, method = "mc", resolution = None))]
fn extract(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    method: &str,
    resolution: Option<u32>,
) -> PyResult<Mesh> {
    let method = extract_method(method)?;
    let mesh = if let Ok(grid) = source.cast::<Grid>() {
        let g = grid.borrow().to_sdf(py)?;
        let own = g.dims.max_element() - 1;
        let res = EXTRACTION_RESOLUTION.check("resolution", resolution.unwrap_or(own)).map_err(py_err)?;
        py.detach(|| {
            let (lo, hi) = g.bounds();
            let f = |p: glam::DVec3| g.trilinear(p.as_vec3()) as f64;
            sdfmesh_lib::convert::extract::extract(&f, Field::Arbitrary, &aabb(lo, hi), res, method)
        })
    } else {
        let path: PathBuf = source.extract().map_err(|_| {
            value_error("source must be a sdfmesh.Grid or a scene file path (str or os.PathLike)")
        })?;
        let res = EXTRACTION_RESOLUTION.check("resolution", resolution.unwrap_or(128)).map_err(py_err)?;
        py.detach(|| -> Result<TriangleMesh, Error> {
            let scene = load_scene(&path)?;
            let mut out = TriangleMesh::default();
            for o in &scene.objects {
                if let Some(m) = extract_object(o, res, method)
                    .or_else(|| grid_file_mesh(o, res, MeshMethod::Extracted(method)))
                {
                    out.merge(&m);
                }
            }
            if out.triangles.is_empty() {
                return Err(Error::input(&path, None, "no bounded SDF object to extract a mesh from"));
            }
            Ok(out)
        })
        .map_err(py_err)?
    };
    if mesh.triangles.is_empty() {
        return Err(value_error("the grid has no zero crossing: nothing to extract"));
    }
    Ok(Mesh::new(mesh, None))
}

/// Parses `args` (after the program name) as the toolkit's command line and validates it
/// as the toolkit does.
fn task(args: Vec<String>) -> PyResult<Task> {
    let cli = Cli::try_parse_from(std::iter::once("toolkit".to_string()).chain(args)).map_err(|e| {
        let text = e.to_string();
        value_error(text.lines().next().unwrap_or("invalid arguments").trim_end().to_string())
    })?;
    let budget = cli.max_memory.unwrap_or_else(MemoryBudget::machine_default);
    if let Command::Compare { inputs, .. } = &cli.command
        && inputs.is_empty()
    {
        return Err(value_error("compare needs at least one input"));
    }
    Task::new(cli.command, budget).map_err(py_err)
}

fn extra_args(args: Option<Vec<String>>) -> Vec<String> {
    args.unwrap_or_default()
}

/// Renders a scene file (or a mesh or grid file, framed by a default camera) with one
/// representation, as `toolkit render` does, and returns the image as uint8 (height,
/// width, 3). `repr`: "analytic", "mesh", "sdf", "grid" (see `toolkit render --help`);
/// `res`: the mesh and grid representations' resolution; `width`, `height`, `depth`
/// override the scene's; `args`: further `toolkit render` flags.
#[pyfunction]
#[pyo3(signature = (scene, repr = "analytic", res = 64, width = None, height = None, depth = None, args = None))]
#[allow(clippy::too_many_arguments)]
fn render<'py>(
    py: Python<'py>,
    scene: PathBuf,
    repr: &str,
    res: u32,
    width: Option<u32>,
    height: Option<u32>,
    depth: Option<u32>,
    args: Option<Vec<String>>,
) -> PyResult<Bound<'py, PyArray3<u8>>> {
    let mut a: Vec<String> = vec!["render".into(), scene.to_string_lossy().into_owned()];
    a.extend([
        "-o".into(),
        "unused.png".into(),
        "--repr".into(),
        repr.into(),
        "--res".into(),
        res.to_string(),
    ]);
    for (flag, v) in [("--width", width), ("--height", height), ("--depth", depth)] {
        if let Some(v) = v {
            a.extend([flag.to_string(), v.to_string()]);
        }
    }
    a.extend(extra_args(args));
    let Task::Render(opts) = task(a)? else { unreachable!("a render command line") };
    let image = py
        .detach(|| -> Result<_, Error> {
            let mut scene = load_input(&opts.scene, opts.shading)?;
            opts.overrides.apply(&mut scene);
            let what = format!("the {} representation of {}", opts.repr.name(), opts.scene.display());
            opts.budget.check_scene(&what, &scene, opts.repr)?;
            Ok(render_scene(&scene, opts.repr).frame.image)
        })
        .map_err(py_err)?;
    let (w, h) = (image.width() as usize, image.height() as usize);
    let a = numpy::ndarray::Array3::from_shape_vec((h, w, 3), image.into_raw())
        .map_err(|e| value_error(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => match (n.as_i64(), n.as_u64()) {
            (Some(i), _) => i.into_pyobject(py)?.into_any(),
            (None, Some(u)) => u.into_pyobject(py)?.into_any(),
            _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(a) => {
            let l = PyList::empty(py);
            for x in a {
                l.append(json_to_py(py, x)?)?;
            }
            l.into_any()
        }
        Value::Object(m) => {
            let d = PyDict::new(py);
            for (k, x) in m {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// Runs `toolkit compare` on `inputs` (scene and mesh files) and returns its rows, one
/// dict per run (the CSV's columns; None for empty cells). `csv`: where the CSV goes
/// (default: a temporary file, removed afterwards; an existing one is replaced); `res`:
/// the resolution sweep; `frames`: timed frames per run; `args`: further `toolkit
/// compare` flags.
#[pyfunction]
#[pyo3(signature = (inputs, csv = None, res = None, frames = None, args = None))]
fn compare<'py>(
    py: Python<'py>,
    inputs: Vec<PathBuf>,
    csv: Option<PathBuf>,
    res: Option<Vec<u32>>,
    frames: Option<u32>,
    args: Option<Vec<String>>,
) -> PyResult<Bound<'py, PyList>> {
    if inputs.is_empty() {
        return Err(value_error("compare needs at least one input"));
    }
    let temp = csv.is_none();
    let csv = csv.unwrap_or_else(|| {
        static N: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let k = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        std::env::temp_dir().join(format!("sdfmesh-compare-{}-{k}.csv", std::process::id()))
    });
    let mut a: Vec<String> = vec!["compare".into()];
    a.extend(inputs.iter().map(|p| p.to_string_lossy().into_owned()));
    a.extend(["--csv".into(), csv.to_string_lossy().into_owned(), "--overwrite".into()]);
    if let Some(r) = res {
        a.extend(["--res".into(), r.iter().map(u32::to_string).collect::<Vec<_>>().join(",")]);
    }
    if let Some(f) = frames {
        a.extend(["--frames".into(), f.to_string()]);
    }
    a.extend(extra_args(args));
    let Task::Compare(opts) = task(a)? else {
        return Err(value_error("compare: --scaling is not supported here"));
    };
    let rows = py.detach(|| -> Result<_, Error> {
        let run = sdfmesh_lib::compare::compare_command(&opts);
        let rows = sdfmesh_lib::compare::read_rows(&csv);
        if temp {
            let _ = std::fs::remove_file(&csv);
        }
        run?;
        rows
    });
    let rows = rows.map_err(py_err)?;
    let out = PyList::empty(py);
    for r in &rows {
        let v = serde_json::to_value(r).map_err(|e| value_error(e.to_string()))?;
        out.append(json_to_py(py, &v)?)?;
    }
    Ok(out)
}

/// The extension module.
#[pymodule]
fn _sdfmesh(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // The SIMD backend switch (SDFMESH_SIMD) is read once; an unknown value is refused.
    sdfmesh_lib::simd::check_env().map_err(value_error)?;
    m.add_class::<Mesh>()?;
    m.add_class::<Grid>()?;
    m.add_function(wrap_pyfunction!(load_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(signed_distance, m)?)?;
    m.add_function(wrap_pyfunction!(closest_points, m)?)?;
    m.add_function(wrap_pyfunction!(winding_number, m)?)?;
    m.add_function(wrap_pyfunction!(mesh_to_grid, m)?)?;
    m.add_function(wrap_pyfunction!(sample_near_surface, m)?)?;
    m.add_function(wrap_pyfunction!(extract, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    Ok(())
}
