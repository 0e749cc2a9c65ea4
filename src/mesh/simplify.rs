//! Quadric-error decimation of a [`TriangleMesh`] with meshoptimizer (crate `meshopt`),
//! as a polygon pipeline would ship a lighter version of a scan: [`decimate`].
//!
//! The mesh is first welded by position alone (meshopt's `generate_vertex_remap` over the
//! positions), so that a scan whose vertices are split by normals or texture seams is one
//! connected surface to the simplifier; a mesh that is then open (any edge not shared by
//! exactly two triangles) is simplified with its border vertices locked
//! (`SimplifyOptions::LockBorder`), so holes and open rims stay where they are. The
//! simplifier (`meshopt::simplify`, edge collapses ordered by quadric error) runs until the
//! triangle target of a [`DecimateTarget`] is met or no collapse is left within the error
//! limit; its reported error, the largest deviation of a kept vertex from the planes of the
//! triangles it replaced, is returned in mesh units and relative to the mesh's extent.
//! Folds the collapses leave (two triangles on the same three vertices) are removed, so a
//! closed mesh stays closed, and unused vertices are dropped (`optimize_vertex_fetch`). A mesh that came with
//! normals gets area-weighted normals of the decimated triangles
//! ([`TriangleMesh::compute_vertex_normals`]); one without stays without (the mesh
//! representation computes them when shading smoothly).

use std::fmt;
use std::str::FromStr;

use glam::Vec3;
use meshopt::SimplifyOptions;

use super::TriangleMesh;

/// How many triangles a decimation keeps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DecimateTarget {
    /// This fraction of the triangles, in `(0, 1]` (rounded, at least one triangle).
    Ratio(f64),
    /// This many triangles (at least 2; a mesh with fewer is kept as it is).
    Triangles(usize),
}

impl DecimateTarget {
    /// The triangle count this target asks of a mesh of `triangles` triangles: at least 1
    /// and at most `triangles`.
    pub fn triangles_of(&self, triangles: usize) -> usize {
        let n = match *self {
            DecimateTarget::Ratio(r) => (r * triangles as f64).round() as usize,
            DecimateTarget::Triangles(n) => n,
        };
        n.clamp(1, triangles.max(1))
    }

    /// The `method` name of a compare run decimated to this target: `decimated-25%` for a
    /// ratio of 0.25, `decimated-5000tris` for 5000 triangles.
    pub fn method_name(&self) -> String {
        format!("decimated-{self}")
    }
}

impl fmt::Display for DecimateTarget {
    /// `25%` for a ratio of 0.25 (to a hundredth of a percent), `5000tris` for a count.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            DecimateTarget::Ratio(r) => write!(f, "{}%", (r * 1e4).round() / 1e2),
            DecimateTarget::Triangles(n) => write!(f, "{n}tris"),
        }
    }
}

impl FromStr for DecimateTarget {
    type Err = String;

    /// A number in `(0, 1]` is a ratio, `N%` a percentage in `(0, 100]`, an integer of at
    /// least 2 (or `Ntris`, as [`fmt::Display`] writes it) a triangle count; anything else
    /// is refused with a one-line message.
    fn from_str(s: &str) -> Result<Self, String> {
        let t = s.trim();
        let bad =
            || format!("'{s}' is not a ratio in (0, 1], a percentage in (0, 100]% or a triangle count >= 2");
        if let Some(p) = t.strip_suffix('%') {
            let p: f64 = p.trim().parse().map_err(|_| bad())?;
            return if p > 0.0 && p <= 100.0 { Ok(DecimateTarget::Ratio(p / 100.0)) } else { Err(bad()) };
        }
        if let Some(n) = t.strip_suffix("tris") {
            return match n.trim().parse::<usize>() {
                Ok(n) if n >= 2 => Ok(DecimateTarget::Triangles(n)),
                _ => Err(bad()),
            };
        }
        if let Ok(n) = t.parse::<usize>() {
            return match n {
                0 => Err(bad()),
                1 => Ok(DecimateTarget::Ratio(1.0)),
                n => Ok(DecimateTarget::Triangles(n)),
            };
        }
        match t.parse::<f64>() {
            Ok(r) if r > 0.0 && r <= 1.0 => Ok(DecimateTarget::Ratio(r)),
            _ => Err(bad()),
        }
    }
}

/// A decimated mesh and what the simplifier reported.
#[derive(Clone, Debug)]
pub struct Decimated {
    /// The decimated mesh (meets the [`TriangleMesh`] invariants but for zero-area
    /// triangles, which the simplifier avoids but does not rule out).
    pub mesh: TriangleMesh,
    /// The triangle count asked for ([`DecimateTarget::triangles_of`]).
    pub target: usize,
    /// meshopt's result error in mesh units: the largest distance of a kept vertex from
    /// the planes of the original triangles it stands for (0 when nothing was collapsed).
    pub error: f32,
    /// The same relative to the mesh's extent (meshopt's `simplify_scale`, its largest
    /// side).
    pub relative_error: f32,
    /// Vertices merged by the position-only weld before simplifying.
    pub vertices_welded: usize,
    /// Whether the welded mesh was open, so its border vertices were locked.
    pub border_locked: bool,
    /// Triangles removed after simplifying because another triangle has the same three
    /// vertices ([`remove_folds`]).
    pub folds_removed: usize,
}

/// Memory a decimation may take, as a multiple of the input's [`TriangleMesh::bytes_used`]:
/// the position copy, the welded copy, meshopt's quadrics, adjacency and collapse tables
/// (about 150 bytes a vertex and 100 a triangle against the input's 12 and 12) and the
/// output, rounded up.
pub const SCRATCH_FACTOR: u64 = 16;

/// No limit on the simplifier's error: the triangle target alone decides where it stops.
pub const NO_ERROR_LIMIT: f32 = f32::MAX;

/// Decimates `mesh` to `target` triangles with meshopt's quadric-error simplifier (see
/// the module docs), stopping early where the next collapse would exceed `max_error`
/// (relative to the mesh's extent; [`NO_ERROR_LIMIT`] for none).
///
/// A target at or above the mesh's triangle count returns the mesh unchanged (error 0).
///
/// # Errors
/// A one-line message when the mesh has no triangles, breaks the [`TriangleMesh`]
/// invariants, or when nothing is left after simplifying (every triangle degenerate).
pub fn decimate(mesh: &TriangleMesh, target: DecimateTarget, max_error: f32) -> Result<Decimated, String> {
    mesh.validate()?;
    let n = mesh.triangles.len();
    if n == 0 {
        return Err("no triangles to decimate".into());
    }
    let wanted = target.triangles_of(n);
    if wanted >= n {
        return Ok(Decimated {
            mesh: mesh.clone(),
            target: wanted,
            error: 0.0,
            relative_error: 0.0,
            vertices_welded: 0,
            border_locked: false,
            folds_removed: 0,
        });
    }
    // Weld by position alone (bit-identical coordinates).
    let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.to_array()).collect();
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let (unique, remap) = meshopt::generate_vertex_remap(&positions, Some(&indices));
    let welded_positions = meshopt::remap_vertex_buffer(&positions, unique, &remap);
    let mut welded = meshopt::remap_index_buffer(Some(&indices), unique, &remap);
    // A weld can only collapse triangles whose corners share a position: drop those.
    let mut kept = Vec::with_capacity(welded.len());
    for t in welded.chunks_exact(3) {
        if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
            kept.extend_from_slice(t);
        }
    }
    welded = kept;
    if welded.is_empty() {
        return Err(format!("no triangles left after welding the {n} triangles' vertices by position"));
    }
    let welded_mesh = TriangleMesh {
        positions: Vec::new(),
        triangles: welded.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        normals: None,
    };
    let border_locked = welded_mesh.boundary_edge_count() > 0;
    drop(welded_mesh);
    let options = if border_locked { SimplifyOptions::LockBorder } else { SimplifyOptions::None };
    let mut relative_error = 0.0f32;
    let target_indices = (wanted * 3).min(welded.len());
    let mut simplified = meshopt::simplify_decoder(
        &welded,
        &welded_positions,
        target_indices,
        max_error,
        options,
        Some(&mut relative_error),
    );
    let folds_removed = remove_folds(&mut simplified);
    if simplified.is_empty() {
        return Err(format!("simplifying {n} triangles to {wanted} left none"));
    }
    let scale = meshopt::simplify_scale_decoder(&welded_positions);
    let mut vertices = meshopt::optimize_vertex_fetch(&mut simplified, &welded_positions);
    vertices.shrink_to_fit();
    let mut out = TriangleMesh {
        positions: vertices.into_iter().map(Vec3::from_array).collect(),
        triangles: simplified.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        normals: None,
    };
    if mesh.normals.is_some() {
        out.compute_vertex_normals();
    }
    Ok(Decimated {
        mesh: out,
        target: wanted,
        error: relative_error * scale,
        relative_error,
        vertices_welded: positions.len() - unique,
        border_locked,
        folds_removed,
    })
}

/// Removes triangles that share all three vertices with another: a pair facing opposite
/// ways (a fold, which meshopt's collapses leave now and then: measured, one or two pairs
/// in armadillo's decimations to 25%-5%) is a zero-thickness sheet that covers nothing and
/// makes its edges non-manifold, so both go; of a pair facing the same way one stays.
/// `indices` is a triangle list; returns how many triangles were removed.
fn remove_folds(indices: &mut Vec<u32>) -> usize {
    // (sorted corners, orientation: whether the corners are an even rotation of sorted).
    let mut keys: Vec<([u32; 3], bool, usize)> = indices
        .chunks_exact(3)
        .enumerate()
        .map(|(i, t)| {
            let mut s = [t[0], t[1], t[2]];
            s.sort_unstable();
            let even = [[t[0], t[1], t[2]], [t[1], t[2], t[0]], [t[2], t[0], t[1]]].contains(&s);
            (s, even, i)
        })
        .collect();
    keys.sort_unstable();
    let mut drop = vec![false; keys.len()];
    for run in keys.chunk_by(|a, b| a.0 == b.0).filter(|run| run.len() > 1) {
        let plus = run.iter().filter(|k| k.1).count();
        let minus = run.len() - plus;
        // Opposite pairs cancel; of what is left, one triangle stays.
        let keep = if plus == minus { None } else { Some(plus > minus) };
        let mut kept = false;
        for k in run {
            if !kept && keep == Some(k.1) {
                kept = true;
            } else {
                drop[k.2] = true;
            }
        }
    }
    let removed = drop.iter().filter(|&&d| d).count();
    if removed > 0 {
        let mut i = 0;
        indices.retain(|_| {
            let keep = !drop[i / 3];
            i += 1;
            keep
        });
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An icosphere of radius 1: the icosahedron with each triangle split into four
    /// `levels` times, every vertex pushed onto the sphere (20 * 4^levels triangles,
    /// closed, welded, outward-facing).
    fn icosphere(levels: u32) -> TriangleMesh {
        let t = (1.0 + 5f32.sqrt()) / 2.0;
        let mut positions: Vec<Vec3> = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ]
        .map(|p| Vec3::from_array(p).normalize())
        .to_vec();
        let mut triangles: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..levels {
            let mut mid = std::collections::HashMap::new();
            let mut middle = |a: u32, b: u32, positions: &mut Vec<Vec3>| -> u32 {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    positions.push((positions[a as usize] + positions[b as usize]).normalize());
                    positions.len() as u32 - 1
                })
            };
            let mut next = Vec::with_capacity(triangles.len() * 4);
            for [a, b, c] in triangles {
                let (ab, bc, ca) = (
                    middle(a, b, &mut positions),
                    middle(b, c, &mut positions),
                    middle(c, a, &mut positions),
                );
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            triangles = next;
        }
        TriangleMesh { positions, triangles, normals: None }
    }

    #[test]
    fn targets_parse_and_print() {
        assert_eq!("0.25".parse::<DecimateTarget>(), Ok(DecimateTarget::Ratio(0.25)));
        assert_eq!("25%".parse::<DecimateTarget>(), Ok(DecimateTarget::Ratio(0.25)));
        assert_eq!("1".parse::<DecimateTarget>(), Ok(DecimateTarget::Ratio(1.0)));
        assert_eq!("5000".parse::<DecimateTarget>(), Ok(DecimateTarget::Triangles(5000)));
        for t in [DecimateTarget::Ratio(0.02), DecimateTarget::Ratio(0.5), DecimateTarget::Triangles(7)] {
            assert_eq!(t.to_string().parse::<DecimateTarget>(), Ok(t), "{t} round trip");
        }
        for bad in ["0", "0.0", "-0.5", "1.5", "150%", "0%", "NaN", "inf", "", "half", "2.5e3", "1tris"] {
            let e = bad.parse::<DecimateTarget>().unwrap_err();
            assert!(e.contains(&format!("'{bad}'")) && !e.contains('\n'), "{bad}: {e}");
        }
        assert_eq!(DecimateTarget::Ratio(0.1).method_name(), "decimated-10%");
        assert_eq!(DecimateTarget::Ratio(0.025).method_name(), "decimated-2.5%");
        assert_eq!(DecimateTarget::Triangles(5000).method_name(), "decimated-5000tris");
        assert_eq!(DecimateTarget::Ratio(0.25).triangles_of(1000), 250);
        assert_eq!(DecimateTarget::Ratio(1e-9).triangles_of(1000), 1);
        assert_eq!(DecimateTarget::Triangles(5000).triangles_of(1000), 1000);
    }

    #[test]
    fn a_closed_sphere_decimates_to_about_the_target_and_stays_closed() {
        let sphere = icosphere(4); // 5120 triangles
        assert!(sphere.is_closed());
        let d = decimate(&sphere, DecimateTarget::Ratio(0.25), NO_ERROR_LIMIT).unwrap();
        assert_eq!(d.target, 1280);
        let got = d.mesh.triangles.len();
        // meshopt stops at or just below the target (a collapse removes two triangles).
        assert!((1240..=1280).contains(&got), "{got} triangles");
        assert!(d.mesh.is_closed(), "a closed sphere stays closed");
        assert!(!d.border_locked);
        assert!(d.mesh.validate().is_ok());
        assert!(d.mesh.normals.is_none());
        assert_eq!(d.vertices_welded, 0);
        // Edge collapses keep vertices on the sphere; the reported error is small but not 0.
        assert!(d.error > 0.0 && d.error < 0.05, "error {}", d.error);
        for p in &d.mesh.positions {
            assert!((p.length() - 1.0).abs() < 1e-5);
        }
        // Every vertex is used (no left-overs of the original vertex buffer).
        let mut used = vec![false; d.mesh.positions.len()];
        d.mesh.triangles.iter().flatten().for_each(|&i| used[i as usize] = true);
        assert!(used.iter().all(|&u| u));
    }

    #[test]
    fn ratio_one_keeps_the_mesh_and_normals_are_recomputed() {
        let mut sphere = icosphere(2);
        let same = decimate(&sphere, DecimateTarget::Ratio(1.0), NO_ERROR_LIMIT).unwrap();
        assert_eq!(same.mesh, sphere);
        assert_eq!(same.error, 0.0);
        sphere.compute_vertex_normals();
        let d = decimate(&sphere, DecimateTarget::Triangles(100), NO_ERROR_LIMIT).unwrap();
        assert!(d.mesh.triangles.len() <= 100);
        let normals = d.mesh.normals.as_ref().expect("normals recomputed");
        assert_eq!(normals.len(), d.mesh.positions.len());
        assert!(d.mesh.validate().is_ok());
    }

    #[test]
    fn split_vertices_are_welded_and_open_meshes_keep_their_border() {
        // The sphere with every triangle's corners split (a soup), then its top cap cut off.
        let sphere = icosphere(3);
        let mut soup = TriangleMesh::default();
        for t in &sphere.triangles {
            let base = soup.positions.len() as u32;
            soup.positions.extend(t.map(|i| sphere.positions[i as usize]));
            soup.triangles.push([base, base + 1, base + 2]);
        }
        let positions = soup.positions.clone();
        soup.triangles.retain(|t| positions[t[0] as usize].y < 0.8);
        let border: Vec<Vec3> = {
            let welded = decimate(&soup, DecimateTarget::Ratio(1.0), NO_ERROR_LIMIT).unwrap();
            assert_eq!(welded.vertices_welded, 0, "ratio 1 touches nothing");
            let mut w = soup.clone();
            w.weld();
            w.odd_edges()
                .iter()
                .flat_map(|&(a, b)| [w.positions[a as usize], w.positions[b as usize]])
                .collect()
        };
        assert!(!border.is_empty());
        let d = decimate(&soup, DecimateTarget::Ratio(0.2), NO_ERROR_LIMIT).unwrap();
        assert!(d.vertices_welded > 2 * soup.triangles.len(), "{} welded", d.vertices_welded);
        assert!(d.border_locked);
        assert!(d.mesh.triangles.len() < soup.triangles.len() / 3);
        // The rim is locked: every border vertex is still there.
        for p in &border {
            assert!(d.mesh.positions.contains(p), "border vertex {p} moved");
        }
        assert_eq!(d.mesh.odd_edges().len(), {
            let mut w = soup.clone();
            w.weld();
            w.odd_edges().len()
        });
    }

    #[test]
    fn folds_cancel_and_duplicates_keep_one() {
        // A fold (one triangle and its mirror), a triangle repeated in one orientation, a
        // rotation of a triangle that is the same triangle, and one triangle alone.
        let mut indices = vec![0, 1, 2, 2, 1, 0, 3, 4, 5, 4, 5, 3, 5, 3, 4, 6, 7, 8];
        assert_eq!(remove_folds(&mut indices), 4);
        assert_eq!(indices, vec![3, 4, 5, 6, 7, 8]);
        // Two against one: one of the two stays.
        let mut indices = vec![0, 1, 2, 0, 2, 1, 1, 2, 0];
        assert_eq!(remove_folds(&mut indices), 2);
        assert_eq!(indices, vec![0, 1, 2]);
        let mut clean = vec![0, 1, 2, 0, 2, 3];
        assert_eq!(remove_folds(&mut clean), 0);
    }

    #[test]
    fn empty_and_degenerate_meshes_fail_cleanly() {
        let empty = TriangleMesh::default();
        assert_eq!(
            decimate(&empty, DecimateTarget::Ratio(0.5), NO_ERROR_LIMIT).unwrap_err(),
            "no triangles to decimate"
        );
        // Every triangle repeats a position (a weld leaves nothing).
        let flat = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::ZERO, Vec3::X],
            triangles: vec![[0, 1, 2], [1, 2, 3]],
            normals: None,
        };
        let e = decimate(&flat, DecimateTarget::Ratio(0.5), NO_ERROR_LIMIT).unwrap_err();
        assert!(e.contains("no triangles left"), "{e}");
        // Out-of-range indices are refused before meshopt sees them.
        let bad = TriangleMesh {
            positions: vec![Vec3::ZERO],
            triangles: vec![[0, 1, 2], [0, 1, 2]],
            normals: None,
        };
        assert!(
            decimate(&bad, DecimateTarget::Ratio(0.5), NO_ERROR_LIMIT).unwrap_err().contains("out of range")
        );
        // Collinear but distinct corners: meshopt keeps or drops them, never panics.
        let line = TriangleMesh {
            positions: (0..6).map(|i| Vec3::X * i as f32).collect(),
            triangles: vec![[0, 1, 2], [2, 3, 4], [3, 4, 5], [0, 2, 4]],
            normals: None,
        };
        let _ = decimate(&line, DecimateTarget::Ratio(0.5), NO_ERROR_LIMIT);
    }
}
