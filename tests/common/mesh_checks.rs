//! Shared checks on extracted and tessellated meshes: edge manifoldness, enclosed volume,
//! and the cube meshes are extracted in.
#![allow(dead_code)]

use std::collections::HashMap;

use glam::Vec3A;
use sdfmesh::geometry::Aabb;
use sdfmesh::mesh::TriangleMesh;

/// The axis-aligned cube of half-side `r` around the origin.
pub fn cube(r: f32) -> Aabb {
    Aabb::new(Vec3A::splat(-r), Vec3A::splat(r))
}

/// Undirected edges not used by exactly two triangles, once in each direction.
pub fn non_manifold_edges(m: &TriangleMesh) -> usize {
    let mut uses: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let e = uses.entry((a.min(b), a.max(b))).or_default();
            if a < b {
                e.0 += 1;
            } else {
                e.1 += 1;
            }
        }
    }
    uses.values().filter(|&&u| u != (1, 1)).count()
}

/// Signed enclosed volume (positive for an outward-oriented closed mesh).
pub fn signed_volume(m: &TriangleMesh) -> f64 {
    m.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize].as_dvec3());
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}
