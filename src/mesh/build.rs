//! The clean-up every loader ends with: normals checked, vertices welded, degenerate
//! triangles dropped, unreferenced vertices removed.

use std::path::Path;

use glam::Vec3;

use super::{LoadReport, TriangleMesh, is_degenerate};
use crate::error::{Error, Result};

/// What a format reader hands over: indices already checked to be in range and positions
/// already checked to be finite (each format names its own elements in those errors).
#[derive(Debug, Default)]
pub(crate) struct RawMesh {
    pub positions: Vec<Vec3>,
    /// One per position when present; checked here, not by the readers.
    pub normals: Option<Vec<Vec3>>,
    pub triangles: Vec<[u32; 3]>,
    pub report: LoadReport,
}

/// `Some("NaN")` or `Some("infinite")` when a coordinate of `p` is not finite.
pub(crate) fn non_finite(p: Vec3) -> Option<&'static str> {
    if p.is_nan() {
        Some("NaN")
    } else if !p.is_finite() {
        Some("infinite")
    } else {
        None
    }
}

/// Whether another vertex fits under `u32` indices.
pub(crate) fn check_vertex_count(path: &Path, n: usize) -> Result<()> {
    if n > u32::MAX as usize {
        return Err(Error::input(
            path,
            None,
            format!("more than {} vertices: too many for u32 indices", u32::MAX),
        ));
    }
    Ok(())
}

/// Turns a reader's output into a mesh that meets the [`TriangleMesh`] invariants.
pub(crate) fn finish(path: &Path, raw: RawMesh) -> Result<(TriangleMesh, LoadReport)> {
    let RawMesh { positions, normals, triangles, mut report } = raw;
    report.triangles_read = triangles.len();
    let n = positions.len();
    check_vertex_count(path, n)?;
    // The readers check these with better messages; this is the safety net.
    for (i, p) in positions.iter().enumerate() {
        if let Some(what) = non_finite(*p) {
            return Err(Error::input(path, None, format!("vertex {i}: coordinate is {what}")));
        }
    }
    for (i, t) in triangles.iter().enumerate() {
        for &v in t {
            if v as usize >= n {
                return Err(Error::input(
                    path,
                    None,
                    format!("triangle {i}: index {v} out of range ({n} vertices)"),
                ));
            }
        }
    }

    let normals = normals.and_then(|mut normals| {
        if normals.len() != n {
            report.notes.push(format!("normals ignored: {} normals for {n} vertices", normals.len()));
            return None;
        }
        for (i, v) in normals.iter_mut().enumerate() {
            let len = v.length();
            if !(len.is_finite() && len > 1e-20) {
                report.notes.push(format!(
                    "normals ignored: vertex {i} has a {} normal",
                    if len.is_finite() { "zero" } else { "non-finite" }
                ));
                return None;
            }
            *v /= len;
        }
        Some(normals)
    });

    let mut mesh = TriangleMesh { positions, triangles, normals };
    report.vertices_welded = mesh.weld();

    let before = mesh.triangles.len();
    let positions = &mesh.positions;
    mesh.triangles.retain(|&[a, b, c]| {
        a != b
            && b != c
            && a != c
            && !is_degenerate(positions[a as usize], positions[b as usize], positions[c as usize])
    });
    report.degenerate_dropped = before - mesh.triangles.len();

    if mesh.triangles.is_empty() {
        let msg = if report.triangles_read == 0 {
            if report.skipped_primitives > 0 {
                format!("no triangles ({} point or line primitives skipped)", report.skipped_primitives)
            } else {
                "no triangles".to_string()
            }
        } else {
            format!("no triangles (all {} triangles are degenerate)", report.triangles_read)
        };
        return Err(Error::input(path, None, msg));
    }

    // Remove vertices no triangle uses, keeping the order of the rest.
    let mut new_index = vec![u32::MAX; mesh.positions.len()];
    for t in &mesh.triangles {
        for &v in t {
            new_index[v as usize] = 0;
        }
    }
    let mut next = 0u32;
    for slot in new_index.iter_mut() {
        if *slot == 0 {
            *slot = next;
            next += 1;
        }
    }
    let kept = next as usize;
    report.unreferenced_vertices_removed = mesh.positions.len() - kept;
    if kept < mesh.positions.len() {
        let mut w = 0;
        for r in 0..mesh.positions.len() {
            if new_index[r] != u32::MAX {
                mesh.positions[w] = mesh.positions[r];
                if let Some(nrm) = &mut mesh.normals {
                    nrm[w] = nrm[r];
                }
                w += 1;
            }
        }
        mesh.positions.truncate(kept);
        if let Some(nrm) = &mut mesh.normals {
            nrm.truncate(kept);
        }
        for t in &mut mesh.triangles {
            *t = t.map(|i| new_index[i as usize]);
        }
    }
    mesh.positions.shrink_to_fit();
    mesh.triangles.shrink_to_fit();
    if let Some(nrm) = &mut mesh.normals {
        nrm.shrink_to_fit();
    }
    Ok((mesh, report))
}
