//! Exact closest points on triangles and the nearest-triangle query over a BVH.
//!
//! [`closest_point_on_triangle`] is Ericson's region-based method (Real-Time Collision
//! Detection, 5.1.5): the query point is classified against the Voronoi regions of the
//! triangle's corners and edges with dot products; in the face region the point is
//! projected onto the triangle's plane (more accurate in `f32` than Ericson's barycentric
//! form when the point is far from a small triangle).
//!
//! [`TriangleBvh`] holds an obvhs [`Bvh2`] over a mesh's triangles with the corners stored
//! in leaf order, and the same hierarchy collapsed to 4-wide nodes whose children's boxes
//! are tested together with SIMD; [`TriangleBvh::nearest`] walks the wide nodes depth
//! first, nearer children first, pruning every node whose box is farther (squared
//! distance) than the best triangle so far or than a caller-supplied upper bound, and
//! every triangle whose box or plane is. It allocates nothing: the caller passes a
//! reusable [`NodeStack`]. [`TriangleBvh::axis_segment_may_meet`] is a conservative
//! segment test for signing by regions.

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

/// The box of the axis-parallel segment from `p` to `end` along `axis`, grown by `eps`.
#[inline]
pub fn axis_segment_box(p: Vec3A, axis: usize, end: f32, eps: f32) -> (Vec3A, Vec3A) {
    let mut lo = p;
    let mut hi = p;
    lo[axis] = p[axis].min(end);
    hi[axis] = p[axis].max(end);
    (lo - Vec3A::splat(eps), hi + Vec3A::splat(eps))
}

/// Whether the axis-parallel segment from `p` to the point whose `axis` coordinate is `end`
/// (the others equal to `p`'s) may meet the triangle `a, b, c`. Conservative: `true`
/// whenever it does meet it (the test runs in `f64` from the exact `f32` inputs, with a
/// tolerance of `eps` along the segment and across the triangle's edges); also `true`
/// when it passes within about `eps` of it, and for triangles (nearly) parallel to the
/// segment whenever their boxes, grown by `eps`, overlap the segment.
pub fn axis_segment_may_meet_triangle(
    p: Vec3A,
    axis: usize,
    end: f32,
    eps: f32,
    a: Vec3A,
    b: Vec3A,
    c: Vec3A,
) -> bool {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let pd = p.as_dvec3();
    let (a, b, c) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    let n = (b - a).cross(c - a);
    let na = n[axis];
    let eps = eps as f64;
    if !(na.abs() > 1e-6 * n.length()) {
        // (Nearly) parallel: the boxes decide.
        let (lo, hi) = axis_segment_box(p, axis, end, 0.0);
        let (lo, hi) = (lo.as_dvec3() - eps, hi.as_dvec3() + eps);
        let (tlo, thi) = (a.min(b).min(c), a.max(b).max(c));
        return !(tlo.cmpgt(hi).any() || thi.cmplt(lo).any());
    }
    // Where the line meets the plane, along `axis`.
    let x = pd[axis] + n.dot(a - pd) / na;
    let (s0, s1) = (pd[axis].min(end as f64), pd[axis].max(end as f64));
    if x < s0 - eps || x > s1 + eps {
        return false;
    }
    // The crossing lies in the triangle iff the projection of p does (in the plane of the
    // other two axes), up to `eps` across each edge.
    let edge = |x: glam::DVec3, y: glam::DVec3| {
        let (eu, ev) = (y[u] - x[u], y[v] - x[v]);
        let f = eu * (pd[v] - x[v]) - ev * (pd[u] - x[u]);
        (f, eps * (eu * eu + ev * ev).sqrt())
    };
    let (e0, t0) = edge(a, b);
    let (e1, t1) = edge(b, c);
    let (e2, t2) = edge(c, a);
    (e0 >= -t0 && e1 >= -t1 && e2 >= -t2) || (e0 <= t0 && e1 <= t1 && e2 <= t2)
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
    /// The same hierarchy collapsed to four children per node, boxes in SIMD layout, for
    /// the nearest-triangle queries.
    wide: Vec<Node4>,
    /// For each entry of `corners`, its box (`min`, `max`): with the plane, a lower bound on
    /// the distance tested before the closest point.
    boxes: Vec<[Vec3A; 2]>,
}

/// A node of the 4-wide hierarchy: its children's boxes as structure of arrays (an unused
/// slot has an empty box, infinitely far) and their references (see [`Node4::LEAF`]).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Node4 {
    lo: [Vec4; 3],
    hi: [Vec4; 3],
    child: [u32; 4],
}

impl Node4 {
    /// Reference flag of a leaf: `LEAF | index of the leaf in the BVH2`; without the flag,
    /// the index of a 4-wide node. (An unused slot refers to the BVH2's root, never
    /// reached: its box is empty.)
    const LEAF: u32 = 1 << 31;
    /// With [`Node4::LEAF`]: the leaf's slots are packed into the reference instead, as
    /// `LEAF | PACKED | first << 3 | count` (`count <= 7`, `first < 2^27`).
    const PACKED: u32 = 1 << 30;

    /// Squared distances from `q` to the four children's boxes.
    #[inline(always)]
    fn distances2(&self, q: Vec3A) -> Vec4 {
        let mut d2 = Vec4::ZERO;
        for a in 0..3 {
            let x = Vec4::splat(q[a]);
            let d = (self.lo[a] - x).max(x - self.hi[a]).max(Vec4::ZERO);
            d2 += d * d;
        }
        d2
    }
}

/// Collapses `bvh` (a [`Bvh2`] with fewer than `2^31` nodes) into 4-wide nodes,
/// parents before children.
fn collapse(bvh: &Bvh2) -> Vec<Node4> {
    let nodes = &bvh.nodes;
    let mut out: Vec<Node4> = Vec::with_capacity(nodes.len() / 2 + 1);
    let empty = Node4 {
        lo: [Vec4::splat(f32::INFINITY); 3],
        hi: [Vec4::splat(f32::NEG_INFINITY); 3],
        child: [Node4::LEAF; 4],
    };
    let reference = |i: u32| {
        let n = &nodes[i as usize];
        n.is_leaf().then_some(if n.prim_count <= 7 && n.first_index < 1 << 27 {
            Node4::LEAF | Node4::PACKED | n.first_index << 3 | n.prim_count
        } else {
            Node4::LEAF | i
        })
    };
    // (BVH2 node whose children the new node holds, index of the new node)
    let mut todo: Vec<(u32, u32)> = Vec::new();
    out.push(empty);
    if nodes[0].is_leaf() {
        let b = nodes[0].aabb();
        for a in 0..3 {
            out[0].lo[a].x = b.min[a];
            out[0].hi[a].x = b.max[a];
        }
        out[0].child[0] = Node4::LEAF;
        return out;
    }
    todo.push((0, 0));
    while let Some((i, slot)) = todo.pop() {
        let n = &nodes[i as usize];
        let mut kids: Vec<u32> = vec![n.first_index, n.first_index + 1];
        // Open the largest inner child until there are four.
        while kids.len() < 4 {
            let area = |k: u32| {
                let b = nodes[k as usize].aabb();
                let e = b.max - b.min;
                e.x * e.y + e.y * e.z + e.z * e.x
            };
            let Some(pos) = (0..kids.len())
                .filter(|&p| !nodes[kids[p] as usize].is_leaf())
                .max_by(|&a, &b| area(kids[a]).total_cmp(&area(kids[b])))
            else {
                break;
            };
            let k = kids.swap_remove(pos);
            let f = nodes[k as usize].first_index;
            kids.extend([f, f + 1]);
        }
        for (c, &k) in kids.iter().enumerate() {
            let b = nodes[k as usize].aabb();
            for a in 0..3 {
                out[slot as usize].lo[a][c] = b.min[a];
                out[slot as usize].hi[a][c] = b.max[a];
            }
            out[slot as usize].child[c] = match reference(k) {
                Some(leaf) => leaf,
                None => {
                    let new = out.len() as u32;
                    out.push(empty);
                    todo.push((k, new));
                    new
                }
            };
        }
    }
    out
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
                wide: Vec::new(),
                boxes: Vec::new(),
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
        let wide = collapse(&bvh);
        let boxes = corners.iter().map(|&[a, b, c]| [a.min(b).min(c), a.max(b).max(c)]).collect();
        TriangleBvh { bvh, corners, original, planes, wide, boxes }
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
        let test_leaf = |r: u32, best2: &mut f32, best: &mut Option<(u32, Vec3A)>| {
            let (first, count) = if r & Node4::PACKED != 0 {
                ((r & !(Node4::LEAF | Node4::PACKED)) >> 3, r & 7)
            } else {
                let leaf = &nodes[(r & !Node4::LEAF) as usize];
                (leaf.first_index, leaf.prim_count)
            };
            for slot in first..first + count {
                let [lo, hi] = self.boxes[slot as usize];
                if box_distance2(q, lo, hi) > *best2 {
                    continue;
                }
                let plane = self.planes[slot as usize];
                let s = Vec3A::from(plane.truncate()).dot(q) - plane.w;
                if s * s > *best2 {
                    continue;
                }
                let [a, b, c] = self.corners[slot as usize];
                let x = closest_point_on_triangle(q, a, b, c);
                let d2 = (x - q).length_squared();
                if d2 <= *best2 {
                    *best2 = d2;
                    *best = Some((slot, x));
                }
            }
        };
        let wide = &self.wide;
        stack.clear();
        stack.push((0, 0.0));
        while let Some((node, d)) = stack.pop() {
            if d > best2 {
                continue;
            }
            let n = &wide[node as usize];
            *visited += 4;
            let d2 = n.distances2(q).to_array();
            // The children within the bound, nearest first.
            let mut order = [(0.0f32, 0u32); 4];
            let mut count = 0;
            for (&dc, &child) in d2.iter().zip(&n.child) {
                if dc <= best2 {
                    let mut at = count;
                    while at > 0 && order[at - 1].0 > dc {
                        order[at] = order[at - 1];
                        at -= 1;
                    }
                    order[at] = (dc, child);
                    count += 1;
                }
            }
            // Leaves at once (tightening the bound), inner nodes onto the stack farthest first.
            for &(dc, r) in &order[..count] {
                if r & Node4::LEAF != 0 && dc <= best2 {
                    test_leaf(r, &mut best2, &mut best);
                }
            }
            for &(dc, r) in order[..count].iter().rev() {
                if r & Node4::LEAF == 0 && dc <= best2 {
                    stack.push((r, dc));
                }
            }
        }
        best.map(|(slot, x)| Nearest {
            dist2: best2,
            triangle: self.original[slot as usize],
            slot,
            point: Vec3::from(x),
        })
    }

    /// Whether the axis-parallel segment from `p` to the point whose `axis` coordinate is
    /// `end` (the others equal to `p`'s) may meet a triangle: always `true` when it does,
    /// sometimes also when it passes within about `eps` of one (see
    /// [`axis_segment_may_meet_triangle`]). `stack` is scratch.
    pub fn axis_segment_may_meet(
        &self,
        p: Vec3A,
        axis: usize,
        end: f32,
        eps: f32,
        stack: &mut Vec<u32>,
    ) -> bool {
        let nodes = &self.bvh.nodes;
        if nodes.is_empty() {
            return false;
        }
        let (lo, hi) = axis_segment_box(p, axis, end, eps);
        stack.clear();
        stack.push(0);
        while let Some(i) = stack.pop() {
            let n = &nodes[i as usize];
            let b = n.aabb();
            if b.min.cmpgt(hi).any() || b.max.cmplt(lo).any() {
                continue;
            }
            if n.is_leaf() {
                for slot in n.first_index..n.first_index + n.prim_count {
                    let [a, b, c] = self.corners[slot as usize];
                    if axis_segment_may_meet_triangle(p, axis, end, eps, a, b, c) {
                        return true;
                    }
                }
            } else {
                stack.push(n.first_index);
                stack.push(n.first_index + 1);
            }
        }
        false
    }

    /// Bytes held: the BVH and the corner and index arrays.
    pub fn bytes_used(&self) -> usize {
        bvh::bytes_used(&self.bvh)
            + self.corners.capacity() * std::mem::size_of::<[Vec3A; 3]>()
            + self.original.capacity() * 4
            + self.planes.capacity() * std::mem::size_of::<Vec4>()
            + self.wide.capacity() * std::mem::size_of::<Node4>()
            + self.boxes.capacity() * std::mem::size_of::<[Vec3A; 2]>()
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
