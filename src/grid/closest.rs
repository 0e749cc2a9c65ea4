//! Exact closest points on triangles and the nearest-triangle query over a BVH.
//!
//! [`closest_point_on_triangle`] is Ericson's region-based method (Real-Time Collision
//! Detection, 5.1.5): the query point is classified against the Voronoi regions of the
//! triangle's corners and edges with dot products; in the face region the point is
//! projected onto the triangle's plane (more accurate in `f32` than Ericson's barycentric
//! form when the point is far from a small triangle).
//!
//! [`TriangleBvh`] holds an obvhs [`Bvh2`] over a mesh's triangles with the corners stored
//! in leaf order; [`TriangleBvh::nearest`] walks it depth first, nearer child first,
//! pruning every node whose box is farther (squared distance) than the best triangle so
//! far or than a caller-supplied upper bound. It allocates nothing: the caller passes a
//! reusable [`NodeStack`].

use glam::{Vec3, Vec3A, Vec4};
use obvhs::BvhBuildParams;
use obvhs::bvh2::Bvh2;

use crate::bvh;
use crate::geometry::{Aabb, aabb};
use crate::mesh::TriangleMesh;

/// A reusable traversal stack of `(node index, squared distance to the node's box)`.
/// Keep one per thread; it grows to the BVH's depth once and is then reused.
pub type NodeStack = Vec<(u32, f32)>;

/// The closest point to `p` on the triangle `a, b, c` (Ericson's region-based method).
///
/// The triangle must have non-zero area (the [`TriangleMesh`] invariant).
#[inline]
pub fn closest_point_on_triangle(p: Vec3A, a: Vec3A, b: Vec3A, c: Vec3A) -> Vec3A {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a; // corner region A
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b; // corner region B
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return a + ab * v; // edge region AB
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c; // corner region C
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return a + ac * w; // edge region AC
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return b + (c - b) * w; // edge region BC
    }
    // Face region: project onto the plane.
    let n = ab.cross(ac);
    p - n * (ap.dot(n) / n.length_squared())
}

/// Squared distance from `p` to the box `[lo, hi]` (0 inside).
#[inline]
pub fn box_distance2(p: Vec3A, lo: Vec3A, hi: Vec3A) -> f32 {
    (lo - p).max(p - hi).max(Vec3A::ZERO).length_squared()
}

/// The result of a nearest-triangle query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nearest {
    /// Squared distance from the query point to [`Nearest::point`].
    pub dist2: f32,
    /// Index of the triangle in the mesh's `triangles`.
    pub triangle: u32,
    /// Index of the triangle in [`TriangleBvh::corners`] (leaf order), for
    /// [`TriangleBvh::nearest_with_hint`].
    pub slot: u32,
    /// The closest point on the mesh.
    pub point: Vec3,
}

/// A BVH over a mesh's triangles for closest-point (and winding-number) queries.
#[derive(Clone)]
pub struct TriangleBvh {
    /// The obvhs BVH; its `primitive_indices` are the identity (leaves index `corners`
    /// directly).
    pub bvh: Bvh2,
    /// Triangle corners in leaf order.
    pub corners: Vec<[Vec3A; 3]>,
    /// For each entry of `corners`, the index of the triangle in the mesh.
    pub original: Vec<u32>,
    /// For each entry of `corners`, its plane as unit normal (xyz) and offset (w):
    /// `|normal · p - offset|` is a lower bound on the distance from `p` to the triangle.
    pub planes: Vec<Vec4>,
}

impl TriangleBvh {
    /// BVH build parameters: PLOC, at most four triangles per leaf.
    pub const BUILD_PARAMS: BvhBuildParams =
        BvhBuildParams { max_prims_per_leaf: 4, ..BvhBuildParams::fast_build() };

    /// Builds the BVH over `mesh`'s triangles (which must satisfy the [`TriangleMesh`]
    /// invariants). An empty mesh gives an empty BVH, for which every query finds nothing.
    pub fn new(mesh: &TriangleMesh) -> Self {
        Self::with_params(mesh, Self::BUILD_PARAMS)
    }

    /// [`TriangleBvh::new`] with explicit build parameters (`pre_split` must be off: every
    /// triangle must sit in exactly one leaf).
    pub fn with_params(mesh: &TriangleMesh, params: BvhBuildParams) -> Self {
        let params = BvhBuildParams { pre_split: false, ..params };
        let tri = |t: &[u32; 3]| t.map(|i| Vec3A::from(mesh.positions[i as usize]));
        let boxes: Vec<Aabb> = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = tri(t).map(Vec3::from);
                aabb(a.min(b).min(c), a.max(b).max(c))
            })
            .collect();
        if boxes.is_empty() {
            return TriangleBvh {
                bvh: Bvh2::default(),
                corners: Vec::new(),
                original: Vec::new(),
                planes: Vec::new(),
            };
        }
        let mut bvh = bvh::build(&boxes, params);
        let original = std::mem::take(&mut bvh.primitive_indices);
        let corners: Vec<[Vec3A; 3]> = original.iter().map(|&i| tri(&mesh.triangles[i as usize])).collect();
        let planes = corners
            .iter()
            .map(|&[a, b, c]| {
                let n = (b - a).cross(c - a).normalize_or_zero();
                // A zero normal (impossible for valid meshes) gives the bound 0: no pruning.
                n.extend(n.dot(a))
            })
            .collect();
        bvh.primitive_indices = (0..original.len() as u32).collect();
        TriangleBvh { bvh, corners, original, planes }
    }

    /// The nearest triangle to `p` among those closer than `max_dist` (pass
    /// `f32::INFINITY` for no bound), or `None` when there is none (or no triangle).
    ///
    /// A good `max_dist` (an upper bound on the answer, e.g. a neighbouring sample's
    /// distance plus the distance to that sample) lets the walk prune at once. Adds the
    /// number of BVH nodes whose boxes were tested to `visited`.
    pub fn nearest(
        &self,
        p: Vec3,
        max_dist: f32,
        stack: &mut NodeStack,
        visited: &mut u64,
    ) -> Option<Nearest> {
        self.nearest_with_hint(p, None, max_dist, stack, visited)
    }

    /// [`TriangleBvh::nearest`], starting from the triangle at `hint` (an index into
    /// [`TriangleBvh::corners`], e.g. [`Nearest::slot`] of a neighbouring query): its
    /// distance bounds the search from the start, so that nodes farther than it are never
    /// opened. The result is the same as without the hint (up to ties).
    pub fn nearest_with_hint(
        &self,
        p: Vec3,
        hint: Option<u32>,
        max_dist: f32,
        stack: &mut NodeStack,
        visited: &mut u64,
    ) -> Option<Nearest> {
        let nodes = &self.bvh.nodes;
        if nodes.is_empty() {
            return None;
        }
        let q = Vec3A::from(p);
        let mut best2 = if max_dist.is_finite() { max_dist * max_dist } else { f32::INFINITY };
        let mut best: Option<(u32, Vec3A)> = None;
        if let Some(slot) = hint.filter(|&s| (s as usize) < self.corners.len()) {
            let [a, b, c] = self.corners[slot as usize];
            let x = closest_point_on_triangle(q, a, b, c);
            let d2 = (x - q).length_squared();
            if d2 <= best2 {
                best2 = d2;
                best = Some((slot, x));
            }
        }
        stack.clear();
        let root = &nodes[0];
        *visited += 1;
        let d0 = box_distance2(q, root.aabb().min, root.aabb().max);
        if d0 > best2 {
            return None;
        }
        stack.push((0, d0));
        while let Some((mut node, d)) = stack.pop() {
            if d > best2 {
                continue;
            }
            loop {
                let n = &nodes[node as usize];
                if n.is_leaf() {
                    for slot in n.first_index..n.first_index + n.prim_count {
                        let plane = self.planes[slot as usize];
                        let s = Vec3A::from(plane.truncate()).dot(q) - plane.w;
                        if s * s > best2 {
                            continue;
                        }
                        let [a, b, c] = self.corners[slot as usize];
                        let x = closest_point_on_triangle(q, a, b, c);
                        let d2 = (x - q).length_squared();
                        if d2 <= best2 {
                            best2 = d2;
                            best = Some((slot, x));
                        }
                    }
                    break;
                }
                let (l, r) = (n.first_index, n.first_index + 1);
                let (nl, nr) = (&nodes[l as usize], &nodes[r as usize]);
                *visited += 2;
                let dl = box_distance2(q, nl.aabb().min, nl.aabb().max);
                let dr = box_distance2(q, nr.aabb().min, nr.aabb().max);
                let (near, dn, far, df) = if dl <= dr { (l, dl, r, dr) } else { (r, dr, l, dl) };
                if dn > best2 {
                    break;
                }
                if df <= best2 {
                    stack.push((far, df));
                }
                node = near;
            }
        }
        best.map(|(slot, x)| Nearest {
            dist2: best2,
            triangle: self.original[slot as usize],
            slot,
            point: Vec3::from(x),
        })
    }

    /// Bytes held: the BVH and the corner and index arrays.
    pub fn bytes_used(&self) -> usize {
        bvh::bytes_used(&self.bvh)
            + self.corners.capacity() * std::mem::size_of::<[Vec3A; 3]>()
            + self.original.capacity() * 4
            + self.planes.capacity() * std::mem::size_of::<Vec4>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corner_edge_and_face_regions() {
        let (a, b, c) = (Vec3A::ZERO, Vec3A::X, Vec3A::Y);
        let cp = |p: Vec3A| closest_point_on_triangle(p, a, b, c);
        assert_eq!(cp(Vec3A::new(-1.0, -1.0, 3.0)), a);
        assert_eq!(cp(Vec3A::new(2.0, -0.5, 0.0)), b);
        assert_eq!(cp(Vec3A::new(-0.1, 5.0, 1.0)), c);
        assert!((cp(Vec3A::new(0.5, -2.0, 1.0)) - Vec3A::new(0.5, 0.0, 0.0)).length() < 1e-6);
        assert!((cp(Vec3A::new(-3.0, 0.25, 0.0)) - Vec3A::new(0.0, 0.25, 0.0)).length() < 1e-6);
        assert!((cp(Vec3A::new(1.0, 1.0, 0.0)) - Vec3A::new(0.5, 0.5, 0.0)).length() < 1e-6);
        assert!((cp(Vec3A::new(0.2, 0.3, -4.0)) - Vec3A::new(0.2, 0.3, 0.0)).length() < 1e-6);
    }

    #[test]
    fn box_distance() {
        let (lo, hi) = (Vec3A::ZERO, Vec3A::ONE);
        assert_eq!(box_distance2(Vec3A::splat(0.5), lo, hi), 0.0);
        assert_eq!(box_distance2(Vec3A::new(3.0, 0.5, -2.0), lo, hi), 8.0);
    }

    #[test]
    fn empty_mesh_finds_nothing() {
        let t = TriangleBvh::new(&TriangleMesh::default());
        let mut s = NodeStack::new();
        assert!(t.nearest(Vec3::ZERO, f32::INFINITY, &mut s, &mut 0).is_none());
    }

    #[test]
    fn bound_below_answer_finds_nothing() {
        let mesh = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            triangles: vec![[0, 1, 2]],
            normals: None,
        };
        let t = TriangleBvh::new(&mesh);
        let mut s = NodeStack::new();
        let p = Vec3::new(0.2, 0.2, 2.0);
        assert!(t.nearest(p, 1.9, &mut s, &mut 0).is_none());
        let n = t.nearest(p, 2.1, &mut s, &mut 0).unwrap();
        assert!((n.dist2 - 4.0).abs() < 1e-5 && n.triangle == 0);
    }
}
