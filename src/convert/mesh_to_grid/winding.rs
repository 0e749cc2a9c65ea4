//! Generalized winding numbers for the sign of a mesh's distance field (Barill, Dickson,
//! Schmidt, Levin and Jacobson 2018, "Fast Winding Numbers for Soups and Clouds").
//!
//! The winding number of a point `q` with respect to a triangle mesh is the sum of the
//! signed solid angles its triangles subtend at `q`, divided by `4π`: exactly 1 inside and
//! 0 outside a closed, consistently oriented (outward, counter-clockwise) mesh, and a
//! smooth, harmonic function away from the surface for open meshes and soups. A point is
//! inside when the winding number is `>= 0.5` ([`INSIDE`]).
//!
//! Each triangle's solid angle is exact (Van Oosterom and Strackee 1983, in `atan2` form).
//! [`FastWinding`] sums far clusters with Barill et al.'s far-field expansion: every BVH
//! node stores the area-weighted sum `N` of its triangles' normals at their area-weighted
//! centroid `p̃` (the dipole, first-order term; optionally also the moment
//! `M = Σ aₜ nₜ (cₜ - p̃)ᵀ` of the second-order term) and a radius `r` (the largest
//! distance from `p̃` to a corner of the node's box, at least the distance to any of its
//! triangles). A node whose `p̃` is farther than `beta * r` from the query is replaced by
//! its expansion; nearer nodes are opened, down to exact sums over leaf triangles.
//!
//! Accuracy: with `beta = 2` ([`BETA`]) the error is about `5e-3` on average but reaches a
//! few `1e-2` just off the surface of a dense mesh (the second-order term hardly helps at
//! `beta = 2`, the series being close to its radius of convergence); with `beta = 8`
//! ([`REFINE_BETA`]) it is about `1e-3`. [`FastWinding::is_inside`] therefore evaluates
//! with `beta = 2` and re-evaluates with `beta = 8` only when the result is within
//! [`REFINE_BAND`] of `0.5`, which happens only near an open mesh's `0.5` level set (a
//! closed mesh's winding number is 0 or 1 off the surface). The node data is
//! computed once, bottom up.

use std::f32::consts::PI;

use glam::{Mat3A, Vec3, Vec3A};

use super::closest::{TriangleBvh, axis_segment_box, axis_segment_may_meet_triangle, box_distance2};
use crate::mesh::TriangleMesh;

/// The winding number at and above which a point counts as inside.
pub const INSIDE: f32 = 0.5;

/// Barill et al.'s accuracy parameter: a node is approximated by its dipole when the query
/// is farther than `BETA` times the node's radius from its centre.
pub const BETA: f32 = 2.0;

/// The accuracy parameter of the second evaluation in [`FastWinding::is_inside`].
pub const REFINE_BETA: f32 = 8.0;

/// [`FastWinding::is_inside`] re-evaluates winding numbers within this of `0.5`.
pub const REFINE_BAND: f32 = 0.1;

/// The signed solid angle (steradians) that the triangle `a, b, c` subtends at `q`
/// (Van Oosterom and Strackee): positive when `q` sees the triangle's back (the side
/// `(b - a) × (c - a)` points away from), in `(-2π, 2π]`.
#[inline]
pub fn triangle_solid_angle(q: Vec3A, a: Vec3A, b: Vec3A, c: Vec3A) -> f32 {
    let (a, b, c) = (a - q, b - q, c - q);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let num = a.dot(b.cross(c));
    let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * num.atan2(den)
}

/// Per-node data of the expansion.
#[derive(Clone, Copy, Debug, Default)]
struct WindingNode {
    /// Area-weighted centroid `p̃` of the node's triangles.
    centre: Vec3A,
    /// `N = Σ aₜ nₜ`: the sum of the triangles' area-weighted unit normals (half the
    /// cross products).
    normal: Vec3A,
    /// `radius²`: the expansion is used beyond `(beta * radius)²` from `centre`.
    radius2: f32,
    /// Second-order moment `M = Σ aₜ nₜ (cₜ - p̃)ᵀ` (`cₜ` the triangle's centroid), as
    /// columns; zero for a first-order expansion.
    moment: Mat3A,
}

/// Fast winding numbers over a [`TriangleBvh`] (see the module documentation).
#[derive(Clone, Debug)]
pub struct FastWinding {
    nodes: Vec<WindingNode>,
    second_order: bool,
}

impl FastWinding {
    /// Precomputes the first-order (dipole) data of every node of `tree`.
    pub fn new(tree: &TriangleBvh) -> Self {
        Self::with_order(tree, false)
    }

    /// [`FastWinding::new`], choosing between the first-order (dipole only) and the
    /// second-order expansion.
    pub fn with_order(tree: &TriangleBvh, second_order: bool) -> Self {
        let mut nodes = vec![WindingNode::default(); tree.bvh.nodes.len()];
        if !nodes.is_empty() {
            let mut stack = vec![(0u32, false)];
            // Post-order without recursion: a node is finished after both children.
            // Per node: area, area-weighted centroid sum, raw moment Σ aₜ nₜ cₜᵀ.
            let mut sums = vec![(0.0f32, Vec3A::ZERO, Mat3A::ZERO); nodes.len()];
            while let Some((i, children_done)) = stack.pop() {
                let n = &tree.bvh.nodes[i as usize];
                let (area, weighted, normal, raw) = if n.is_leaf() {
                    let mut area = 0.0;
                    let mut weighted = Vec3A::ZERO;
                    let mut normal = Vec3A::ZERO;
                    let mut raw = Mat3A::ZERO;
                    for slot in n.first_index..n.first_index + n.prim_count {
                        let [a, b, c] = tree.corners[slot as usize];
                        let cross = (b - a).cross(c - a) * 0.5;
                        let ar = cross.length();
                        let centroid = (a + b + c) / 3.0;
                        area += ar;
                        weighted += centroid * ar;
                        normal += cross;
                        raw += outer(cross, centroid);
                    }
                    (area, weighted, normal, raw)
                } else if !children_done {
                    stack.push((i, true));
                    stack.push((n.first_index, false));
                    stack.push((n.first_index + 1, false));
                    continue;
                } else {
                    let (l, r) = (n.first_index as usize, n.first_index as usize + 1);
                    (
                        sums[l].0 + sums[r].0,
                        sums[l].1 + sums[r].1,
                        nodes[l].normal + nodes[r].normal,
                        sums[l].2 + sums[r].2,
                    )
                };
                sums[i as usize] = (area, weighted, raw);
                let (lo, hi) = (n.aabb().min, n.aabb().max);
                let centre = if area > 0.0 { weighted / area } else { (lo + hi) * 0.5 };
                let centre = centre.clamp(lo, hi);
                let radius2 = (centre - lo).max(hi - centre).length_squared();
                let moment = if second_order { raw - outer(normal, centre) } else { Mat3A::ZERO };
                nodes[i as usize] = WindingNode { centre, normal, radius2, moment };
            }
        }
        FastWinding { nodes, second_order }
    }

    /// Whether `q` is inside (winding number `>= 0.5`); see [`FastWinding::winding_for_sign`].
    #[inline]
    pub fn is_inside(&self, tree: &TriangleBvh, q: Vec3, stack: &mut Vec<u32>, visited: &mut u64) -> bool {
        self.winding_for_sign(tree, q, stack, visited) >= INSIDE
    }

    /// The winding number with [`BETA`], re-evaluated with [`REFINE_BETA`] when it lies
    /// within [`REFINE_BAND`] of `0.5` (only near an open mesh's `0.5` level set or the
    /// surface), so that its side of `0.5` is reliable. Adds the nodes visited to
    /// `visited`; `stack` is scratch.
    #[inline]
    pub fn winding_for_sign(
        &self,
        tree: &TriangleBvh,
        q: Vec3,
        stack: &mut Vec<u32>,
        visited: &mut u64,
    ) -> f32 {
        let w = self.winding_number(tree, q, BETA, stack, visited);
        if (w - INSIDE).abs() >= REFINE_BAND {
            return w;
        }
        self.winding_number(tree, q, REFINE_BETA, stack, visited)
    }

    /// The winding number of `q` with respect to `tree`'s triangles (`tree` must be the
    /// one this was built from) with accuracy parameter `beta` ([`BETA`]; larger is more
    /// accurate and slower; `f32::INFINITY` gives the exact sum). Adds the nodes visited
    /// to `visited`; `stack` is scratch.
    pub fn winding_number(
        &self,
        tree: &TriangleBvh,
        q: Vec3,
        beta: f32,
        stack: &mut Vec<u32>,
        visited: &mut u64,
    ) -> f32 {
        let beta2 = beta * beta;
        if self.nodes.is_empty() {
            return 0.0;
        }
        let q = Vec3A::from(q);
        let mut omega = 0.0f32;
        stack.clear();
        stack.push(0);
        while let Some(i) = stack.pop() {
            *visited += 1;
            let node = &self.nodes[i as usize];
            let d = node.centre - q;
            let d2 = d.length_squared();
            // (NaN for a zero radius and infinite beta: the node is opened.)
            if d2 > node.radius2 * beta2 {
                // r = p̃ - q; dipole N·r/|r|³, plus J : M with the Jacobian
                // J = I/|r|³ - 3 r rᵀ/|r|⁵ of r/|r|³.
                let inv = 1.0 / d2;
                let inv3 = inv * inv.sqrt();
                omega += node.normal.dot(d) * inv3;
                if self.second_order {
                    let m = &node.moment;
                    let trace = m.x_axis.x + m.y_axis.y + m.z_axis.z;
                    omega += (trace - 3.0 * d.dot(*m * d) * inv) * inv3;
                }
                continue;
            }
            let n = &tree.bvh.nodes[i as usize];
            if n.is_leaf() {
                for slot in n.first_index..n.first_index + n.prim_count {
                    let [a, b, c] = tree.corners[slot as usize];
                    omega += triangle_solid_angle(q, a, b, c);
                }
            } else {
                stack.push(n.first_index);
                stack.push(n.first_index + 1);
            }
        }
        omega / (4.0 * PI)
    }

    /// Bytes held by the node data.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.nodes.capacity() * std::mem::size_of::<WindingNode>()
    }
}

/// Whether every edge of `mesh` is shared by exactly two triangles that traverse it in
/// opposite directions (a closed, consistently oriented surface). The winding number of
/// such a mesh is constant off the surface in every connected region.
pub fn is_closed(mesh: &TriangleMesh) -> bool {
    let mut edges: Vec<u64> = mesh
        .triangles
        .iter()
        .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
        .map(|(a, b)| (a as u64) << 32 | b as u64)
        .collect();
    edges.sort_unstable();
    if edges.windows(2).any(|w| w[0] == w[1]) {
        return false;
    }
    edges.iter().all(|&e| edges.binary_search(&e.rotate_left(32)).is_ok())
}

/// Triangles that close a mesh's holes, for signing open meshes exactly (see
/// [`Caps::new`]).
///
/// Every directed edge `a → b` of the mesh that is not cancelled by an edge `b → a` (net,
/// counting multiplicities) gets the cap triangle `(c, b, a)`, where `c` is the centroid of
/// the vertices of the boundary loop (connected set of such edges) it belongs to. The mesh
/// with its caps is then closed as a chain (every directed edge is cancelled), so its
/// winding number `W` is an integer, constant off the mesh and the caps in every connected
/// region, however the caps lie (they may cut through the mesh), and the mesh's own
/// winding number is `W - w_caps`: the caps' winding number is exact and cheap (few
/// triangles), and small away from the holes.
#[derive(Clone, Debug, Default)]
pub struct Caps {
    /// Cap triangles, grouped by loop.
    pub triangles: Vec<[Vec3A; 3]>,
    /// Per loop: the range of its triangles, their box and total area.
    groups: Vec<CapGroup>,
    /// The box around every cap triangle (empty: inverted).
    lo: Vec3A,
    hi: Vec3A,
    /// Total area of the caps.
    area: f32,
}

#[derive(Clone, Copy, Debug)]
struct CapGroup {
    first: u32,
    end: u32,
    lo: Vec3A,
    hi: Vec3A,
    area: f32,
}

impl Caps {
    /// The caps of `mesh` (none for a closed mesh).
    pub fn new(mesh: &TriangleMesh) -> Self {
        // Net multiplicity of every undirected edge: + for lo -> hi, - for hi -> lo.
        let mut edges: Vec<(u64, i32)> = mesh
            .triangles
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .map(
                |(a, b)| {
                    if a < b { ((a as u64) << 32 | b as u64, 1) } else { ((b as u64) << 32 | a as u64, -1) }
                },
            )
            .collect();
        edges.sort_unstable_by_key(|e| e.0);
        let mut open: Vec<(u32, u32)> = Vec::new();
        let mut i = 0;
        while i < edges.len() {
            let key = edges[i].0;
            let mut net = 0;
            while i < edges.len() && edges[i].0 == key {
                net += edges[i].1;
                i += 1;
            }
            let (lo, hi) = ((key >> 32) as u32, key as u32);
            for _ in 0..net.unsigned_abs() {
                open.push(if net > 0 { (lo, hi) } else { (hi, lo) });
            }
        }
        let mut caps = Caps { lo: Vec3A::INFINITY, hi: Vec3A::NEG_INFINITY, ..Caps::default() };
        if open.is_empty() {
            return caps;
        }
        // Loops: connected sets of open edges (union-find over their vertices).
        let mut verts: Vec<u32> = open.iter().flat_map(|&(a, b)| [a, b]).collect();
        verts.sort_unstable();
        verts.dedup();
        let id = |v: u32| verts.binary_search(&v).expect("vertex of an open edge") as u32;
        let mut parent: Vec<u32> = (0..verts.len() as u32).collect();
        fn find(parent: &mut [u32], mut x: u32) -> u32 {
            while parent[x as usize] != x {
                parent[x as usize] = parent[parent[x as usize] as usize];
                x = parent[x as usize];
            }
            x
        }
        for &(a, b) in &open {
            let (ra, rb) = (find(&mut parent, id(a)), find(&mut parent, id(b)));
            if ra != rb {
                parent[ra.max(rb) as usize] = ra.min(rb);
            }
        }
        let roots: Vec<u32> = (0..verts.len() as u32).map(|v| find(&mut parent, v)).collect();
        let mut sum = vec![(glam::DVec3::ZERO, 0u32); verts.len()];
        for (v, &r) in roots.iter().enumerate() {
            sum[r as usize].0 += mesh.positions[verts[v] as usize].as_dvec3();
            sum[r as usize].1 += 1;
        }
        let mut by_loop: Vec<(u32, u32, u32)> =
            open.iter().map(|&(a, b)| (roots[id(a) as usize], a, b)).collect();
        by_loop.sort_unstable();
        let mut k = 0;
        while k < by_loop.len() {
            let r = by_loop[k].0;
            let (s, count) = sum[r as usize];
            let c = Vec3A::from((s / count as f64).as_vec3());
            let first = caps.triangles.len() as u32;
            let (mut lo, mut hi, mut area) = (c, c, 0.0f32);
            while k < by_loop.len() && by_loop[k].0 == r {
                let (_, a, b) = by_loop[k];
                let (a, b) =
                    (Vec3A::from(mesh.positions[a as usize]), Vec3A::from(mesh.positions[b as usize]));
                caps.triangles.push([c, b, a]);
                lo = lo.min(a).min(b);
                hi = hi.max(a).max(b);
                area += 0.5 * (b - c).cross(a - c).length();
                k += 1;
            }
            caps.groups.push(CapGroup { first, end: caps.triangles.len() as u32, lo, hi, area });
            caps.lo = caps.lo.min(lo);
            caps.hi = caps.hi.max(hi);
            caps.area += area;
        }
        caps
    }

    /// Whether there are no caps (the mesh is closed as a chain).
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Number of loops (holes).
    pub fn loops(&self) -> usize {
        self.groups.len()
    }

    /// A lower bound on the distance from `q` to the caps, or `f32::INFINITY` when it is
    /// more than `far`.
    #[inline]
    pub fn lower_distance(&self, q: Vec3A, far: f32) -> f32 {
        if self.is_empty() || box_distance2(q, self.lo, self.hi) > far * far {
            return f32::INFINITY;
        }
        let d2 = self.groups.iter().map(|g| box_distance2(q, g.lo, g.hi)).fold(f32::INFINITY, f32::min);
        d2.sqrt()
    }

    /// An upper bound on `|w_caps(q)|` (each loop's area over `4π` times its box's
    /// distance squared: a surface subtends at most its area over the squared distance).
    #[inline]
    pub fn winding_bound(&self, q: Vec3A) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let all = self.area / (4.0 * PI * box_distance2(q, self.lo, self.hi));
        if all < 0.25 {
            return all;
        }
        self.groups.iter().map(|g| g.area / (4.0 * PI * box_distance2(q, g.lo, g.hi))).sum()
    }

    /// The caps' exact winding number at `q`.
    pub fn winding_number(&self, q: Vec3A) -> f32 {
        let omega: f32 = self.triangles.iter().map(|&[a, b, c]| triangle_solid_angle(q, a, b, c)).sum();
        omega / (4.0 * PI)
    }

    /// [`TriangleBvh::axis_segment_may_meet`] for the caps.
    pub fn axis_segment_may_meet(&self, p: Vec3A, axis: usize, end: f32, eps: f32) -> bool {
        if self.is_empty() {
            return false;
        }
        let (lo, hi) = axis_segment_box(p, axis, end, eps);
        self.groups.iter().filter(|g| !(g.lo.cmpgt(hi).any() || g.hi.cmplt(lo).any())).any(|g| {
            self.triangles[g.first as usize..g.end as usize]
                .iter()
                .any(|&[a, b, c]| axis_segment_may_meet_triangle(p, axis, end, eps, a, b, c))
        })
    }
}

/// The matrix `u vᵀ`.
#[inline]
fn outer(u: Vec3A, v: Vec3A) -> Mat3A {
    Mat3A::from_cols(u * v.x, u * v.y, u * v.z)
}

/// The exact winding number of `q` with respect to `tree`'s triangles: the plain sum of
/// every triangle's solid angle (for checks; linear in the triangle count).
pub fn exact_winding_number(tree: &TriangleBvh, q: Vec3) -> f32 {
    let q = Vec3A::from(q);
    let omega: f64 = tree.corners.iter().map(|&[a, b, c]| triangle_solid_angle(q, a, b, c) as f64).sum();
    (omega / (4.0 * std::f64::consts::PI)) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solid_angle_of_a_face_seen_from_a_cube_centre() {
        // The face z = 1 of the cube [-1, 1]^3, outward (+z) counter-clockwise, seen from
        // the centre: one sixth of the sphere, in two triangles.
        let v = |x, y| Vec3A::new(x, y, 1.0);
        let q = Vec3A::ZERO;
        let s = triangle_solid_angle(q, v(-1.0, -1.0), v(1.0, -1.0), v(1.0, 1.0))
            + triangle_solid_angle(q, v(-1.0, -1.0), v(1.0, 1.0), v(-1.0, 1.0));
        assert!((s - 4.0 * PI / 6.0).abs() < 1e-5, "{s}");
        // Seen from outside, the sign flips.
        let s2 = triangle_solid_angle(Vec3A::new(0.0, 0.0, 3.0), v(-1.0, -1.0), v(1.0, -1.0), v(1.0, 1.0));
        assert!(s2 < 0.0);
    }
}
