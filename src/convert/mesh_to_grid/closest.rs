//! The nearest-triangle query over a BVH, for sampling a mesh's distance field.
//!
//! The exact closest point on one triangle is [`closest_point_on_triangle`] (in
//! [`crate::geometry::mesh::triangle`], beside the ray/triangle test).
//!
//! [`TriangleBvh`] holds an obvhs [`Bvh2`] over a mesh's triangles with the corners stored
//! in leaf order, and the same hierarchy collapsed to 4-wide nodes whose children's bounds
//! are tested together with SIMD, its leaves gathered into packets of four triangles.
//! Every child has two bounds: its box and a bounding cylinder (a disc around the
//! cluster's mean normal times a slab along it). The box alone is loose by about its size
//! for a tilted patch, and from a point `d` away a patch at lateral offset `r` from the
//! nearest point is only about `r²/2d` farther, so with boxes alone the number of triangles
//! that must be tested grows with `d`; the cylinder follows the surface, and the count
//! stays about constant. A packet's four triangles get Ericson's test with SIMD, without
//! branches (every region evaluated, the scalar code's region selected per lane) and with
//! the same `f32` operations in the same order as [`closest_point_on_triangle`], so its
//! distances and points are bit for bit those of the scalar test.
//! [`TriangleBvh::nearest`] walks the wide nodes depth first, nearer children first,
//! pruning every node whose bound (squared distance) is farther than the best triangle so
//! far or than a caller-supplied upper bound. [`TriangleBvh::nearest_group`] answers up to
//! [`GROUP_MAX`] nearby points in one walk (a node is opened when any of them needs it,
//! each prunes by its own best), which shares the node loads and overlaps the points'
//! independent arithmetic; its node and leaf tests take two points per eight-lane
//! operation of the backend that [`crate::simd::dispatch`] picks (one instruction with
//! AVX2), with the same operations in the same order as the one-point tests (so the same
//! results on both backends). Neither allocates: the caller passes a
//! reusable [`NodeStack`] or [`GroupStack`]. The two walks over one tree are kept apart on
//! purpose: answering one point as a group walk of one point (same results, bit for bit)
//! made the one-point queries of [`super::MeshSampler`] about 25% slower on the bunny (1.1
//! against 0.9 CPU-seconds for 96^3 serpentine queries) and `band_from_mesh` 10 to 15%.
//! [`TriangleBvh::axis_segment_may_meet`] is a conservative segment test for signing by
//! regions.

use glam::{BVec4A, DVec3, Vec3, Vec3A, Vec4};
use obvhs::BvhBuildParams;
use obvhs::bvh2::Bvh2;

use crate::geometry::bvh2;
use crate::geometry::mesh::triangle::closest_point_on_triangle;
use crate::geometry::{Aabb, aabb};
use crate::mesh::TriangleMesh;
use crate::simd::{Kernel, Lane, Lane8, Mask8, Simd, dispatch};

/// A reusable traversal stack: per entry, the bits of the squared distance bound of a node
/// (high 32 bits) and its index (low). Keep one per thread; it grows to the BVH's depth
/// once and is then reused.
pub type NodeStack = Vec<u64>;

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

/// The most points [`TriangleBvh::nearest_group`] takes at once.
pub const GROUP_MAX: usize = 8;
const _: () = assert!(GROUP_MAX <= 8, "the transpose in `nearest_group` handles up to 8 points");

/// A reusable traversal stack for [`TriangleBvh::nearest_group`]; keep one per thread.
#[derive(Clone, Debug, Default)]
pub struct GroupStack(Vec<GroupEntry>);

/// A pending node of a group walk: the least bound of the points that need it, and which.
#[derive(Clone, Copy, Debug)]
struct GroupEntry {
    bound: f32,
    node: u32,
    mask: u32,
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
    /// The same hierarchy collapsed to four children per node, boxes and bounding
    /// cylinders in SIMD layout, for the nearest-triangle queries.
    wide: Vec<Node4>,
    /// The leaves' triangles in packets of four (in SIMD layout).
    packets: Vec<ClosestPacket>,
}

/// Bounding cylinders of four children, as structure of arrays: child `i` lies within
/// `t[i]` of the plane through `c[i]` orthogonal to the unit axis `n[i]`, and within `r[i]`
/// of the axis. For a flat cluster of triangles (a triangle, or a patch of a smooth
/// surface) this is much tighter than its box: a point far above such a patch sees the
/// patch's neighbours on the surface as barely farther than the patch itself, and only a
/// bound that follows the surface tells them apart. An unused or unfitted slot has
/// `r = t = inf` (no bound: distance 0).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Cyl4 {
    n: [Vec4; 3],
    c: [Vec4; 3],
    r: Vec4,
    t: Vec4,
}

impl Cyl4 {
    const NONE: Cyl4 = Cyl4 {
        n: [Vec4::ZERO; 3],
        c: [Vec4::ZERO; 3],
        r: Vec4::splat(f32::INFINITY),
        t: Vec4::splat(f32::INFINITY),
    };

    fn set(&mut self, lane: usize, cyl: &Cylinder) {
        for a in 0..3 {
            self.n[a][lane] = cyl.n[a];
            self.c[a][lane] = cyl.c[a];
        }
        self.r[lane] = cyl.r;
        self.t[lane] = cyl.t;
    }

    /// Lower bounds on the squared distances from `q` to the four cylinders (shrunk by
    /// [`CYL_SHRINK`] for rounding): the squared distance to the disc times the slab.
    #[inline(always)]
    fn distances2(&self, q: &[Vec4; 3]) -> Vec4 {
        let v = [q[0] - self.c[0], q[1] - self.c[1], q[2] - self.c[2]];
        let h = self.n[0] * v[0] + self.n[1] * v[1] + self.n[2] * v[2];
        let w = [v[0] - h * self.n[0], v[1] - h * self.n[1], v[2] - h * self.n[2]];
        let rho = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        let dr = (rho - self.r).max(Vec4::ZERO);
        let dh = (h.abs() - self.t).max(Vec4::ZERO);
        (dr * dr + dh * dh) * CYL_SHRINK
    }
}

/// The cylinder bounds are multiplied by this: it covers the rounding of their `f32`
/// evaluation (relative errors of a few `1e-7`, including axes of length `1 ± 1e-7`).
const CYL_SHRINK: f32 = 1.0 - 1.0 / (1 << 18) as f32;

/// One bounding cylinder (see [`Cyl4`]).
#[derive(Clone, Copy, Debug)]
struct Cylinder {
    n: Vec3,
    c: Vec3,
    r: f32,
    t: f32,
}

impl Cylinder {
    const NONE: Cylinder = Cylinder { n: Vec3::ZERO, c: Vec3::ZERO, r: f32::INFINITY, t: f32::INFINITY };

    /// The cylinder around `points` with the axis `axis` (any non-zero direction) and,
    /// when given, the centre `centre` (else the middle of the points' extents in the
    /// axis' frame). Computed in `f64` from the rounded `f32` axis and centre that the
    /// queries use, radius and half height rounded up.
    fn fit(points: impl Iterator<Item = Vec3A> + Clone, axis: DVec3, centre: Option<DVec3>) -> Cylinder {
        let n = if axis.length_squared() > 0.0 { axis.normalize() } else { DVec3::Z };
        let nf = n.as_vec3();
        let n = nf.as_dvec3();
        let c = centre.unwrap_or_else(|| {
            let (u, w) = n.any_orthonormal_pair();
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for p in points.clone() {
                let p = p.as_dvec3();
                let x = DVec3::new(p.dot(u), p.dot(w), p.dot(n));
                lo = lo.min(x);
                hi = hi.max(x);
            }
            let m = (lo + hi) * 0.5;
            u * m.x + w * m.y + n * m.z
        });
        let cf = c.as_vec3();
        let c = cf.as_dvec3();
        let (mut r, mut t) = (0.0f64, 0.0f64);
        for p in points {
            let v = p.as_dvec3() - c;
            let h = v.dot(n);
            r = r.max((v - n * h).length());
            t = t.max(h.abs());
        }
        let up = |x: f64| {
            let x = x * (1.0 + 1e-6);
            let f = x as f32;
            if (f as f64) < x { f.next_up() } else { f }
        };
        Cylinder { n: nf, c: cf, r: up(r), t: up(t) }
    }
}

/// A node of the 4-wide hierarchy: its children's boxes and bounding cylinders as
/// structure of arrays (an unused slot has an empty box, infinitely far) and their
/// references (see [`Node4::LEAF`]).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Node4 {
    lo: [Vec4; 3],
    hi: [Vec4; 3],
    cyl: Cyl4,
    child: [u32; 4],
    /// Bit `i` set: child `i` is a leaf.
    leaves: u32,
}

/// A leaf packet: up to four triangles in SIMD layout (see [`PointTri4`]) and their slots in
/// [`TriangleBvh::corners`]. A leaf of more than four triangles continues in the next
/// packet while `more` is set.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct ClosestPacket {
    tri: PointTri4,
    slot: [u32; 4],
    more: bool,
}

impl ClosestPacket {
    /// The packet's triangles' exact closest points to `q` (splatted), taken in lane order
    /// as the scalar loop would: each at most `best2` away replaces the best so far. Lowers
    /// `best2` and returns the last replacement (slot and closest point), if any.
    #[inline(always)]
    fn improve(&self, q: &[Vec4; 3], best2: &mut f32) -> Option<(u32, Vec3A)> {
        let (d2, x) = self.tri.closest(q);
        let mut lanes = d2.cmple(Vec4::splat(*best2)).bitmask();
        if lanes == 0 {
            return None;
        }
        let d = d2.to_array();
        let mut found = 0;
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            if d[l] <= *best2 {
                *best2 = d[l];
                found = l;
            }
        }
        Some((self.slot[found], Vec3A::new(x[0][found], x[1][found], x[2][found])))
    }
}

/// Four triangles of a leaf packet for the SIMD closest-point test
/// ([`PointTri4::closest`]): corners `a`, `b`, `c`, the normal `n = (b - a) x (c - a)` and
/// `|n|^2`, as structure of arrays (the normal and its square computed by glam exactly as
/// [`closest_point_on_triangle`] computes them). An unused lane repeats lane 0 (triangle
/// and slot), so it can only tie with it.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct PointTri4 {
    a: [Vec4; 3],
    b: [Vec4; 3],
    c: [Vec4; 3],
    n: [Vec4; 3],
    nn: Vec4,
}

impl PointTri4 {
    /// The packet of `corners` (at least the first is `Some`).
    fn new(corners: [Option<[Vec3A; 3]>; 4]) -> PointTri4 {
        let first = corners[0].expect("a packet has a triangle");
        let mut t = PointTri4 {
            a: [Vec4::ZERO; 3],
            b: [Vec4::ZERO; 3],
            c: [Vec4::ZERO; 3],
            n: [Vec4::ZERO; 3],
            nn: Vec4::ZERO,
        };
        for (lane, tri) in corners.iter().enumerate() {
            let [a, b, c] = tri.unwrap_or(first);
            let n = (b - a).cross(c - a);
            for k in 0..3 {
                t.a[k][lane] = a[k];
                t.b[k][lane] = b[k];
                t.c[k][lane] = c[k];
                t.n[k][lane] = n[k];
            }
            t.nn[lane] = n.length_squared();
        }
        t
    }

    /// The squared distances from `q` (splatted) to the four triangles and the closest
    /// points (structure of arrays), bit for bit those of [`closest_point_on_triangle`]:
    /// the same operations on the same values in the same order (glam's `dot` on
    /// `Vec3A` sums `(x + y) + z`, as [`dot`] does; nothing is fused), Ericson's regions
    /// evaluated for all lanes and selected in the scalar code's order of precedence.
    #[inline(always)]
    fn closest(&self, q: &[Vec4; 3]) -> (Vec4, [Vec4; 3]) {
        let sub = |u: &[Vec4; 3], v: &[Vec4; 3]| [u[0] - v[0], u[1] - v[1], u[2] - v[2]];
        let ab = sub(&self.b, &self.a);
        let ac = sub(&self.c, &self.a);
        let ap = sub(q, &self.a);
        let bp = sub(q, &self.b);
        let cp = sub(q, &self.c);
        let d1 = dot(&ab, &ap);
        let d2 = dot(&ac, &ap);
        let d3 = dot(&ab, &bp);
        let d4 = dot(&ac, &bp);
        let d5 = dot(&ab, &cp);
        let d6 = dot(&ac, &cp);
        let vc = d1 * d4 - d3 * d2;
        let vb = d5 * d2 - d1 * d6;
        let va = d3 * d6 - d5 * d4;
        let zero = Vec4::ZERO;
        // The regions, each as the scalar code tests it (given that the earlier ones
        // failed: later selects are overridden by earlier ones below).
        let in_a = d1.cmple(zero) & d2.cmple(zero);
        let in_b = d3.cmpge(zero) & d4.cmple(d3);
        let in_ab = vc.cmple(zero) & d1.cmpge(zero) & d3.cmple(zero);
        let in_c = d6.cmpge(zero) & d5.cmple(d6);
        let in_ac = vb.cmple(zero) & d2.cmpge(zero) & d6.cmple(zero);
        let (e, f) = (d4 - d3, d5 - d6);
        let in_bc = va.cmple(zero) & e.cmpge(zero) & f.cmpge(zero);
        // Face: p - n (ap . n / |n|^2).
        let t = dot(&ap, &self.n) / self.nn;
        let x = [q[0] - self.n[0] * t, q[1] - self.n[1] * t, q[2] - self.n[2] * t];
        // Edge BC: b + (c - b) w.
        let w = e / (e + f);
        let bc = sub(&self.c, &self.b);
        let x = select3(in_bc, [self.b[0] + bc[0] * w, self.b[1] + bc[1] * w, self.b[2] + bc[2] * w], x);
        // Edge AC: a + ac w.
        let w = d2 / (d2 - d6);
        let x = select3(in_ac, [self.a[0] + ac[0] * w, self.a[1] + ac[1] * w, self.a[2] + ac[2] * w], x);
        let x = select3(in_c, self.c, x);
        // Edge AB: a + ab v.
        let v = d1 / (d1 - d3);
        let x = select3(in_ab, [self.a[0] + ab[0] * v, self.a[1] + ab[1] * v, self.a[2] + ab[2] * v], x);
        let x = select3(in_b, self.b, x);
        let x = select3(in_a, self.a, x);
        let off = sub(&x, q);
        (dot(&off, &off), x)
    }
}

/// Per lane, `u` where `m` is set, else `v` (3-vectors in structure-of-arrays layout).
#[inline(always)]
fn select3(m: BVec4A, u: [Vec4; 3], v: [Vec4; 3]) -> [Vec4; 3] {
    [Vec4::select(m, u[0], v[0]), Vec4::select(m, u[1], v[1]), Vec4::select(m, u[2], v[2])]
}

/// Four dot products of 3-vectors in structure-of-arrays layout.
#[inline(always)]
fn dot(u: &[Vec4; 3], v: &[Vec4; 3]) -> Vec4 {
    u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
}

/// Bit `s` set where `bound <= best2[s]` (the point may find something within `bound`).
#[inline(always)]
fn within_best(best2: &[f32; GROUP_MAX], bound: f32) -> u32 {
    let b = Vec4::splat(bound);
    let lo = Vec4::from_slice(&best2[..4]).cmpge(b).bitmask();
    let hi = Vec4::from_slice(&best2[4..]).cmpge(b).bitmask();
    lo | hi << 4
}

/// Bits 0, 4, 8 and 12 of `x` moved to bits 0 to 3: the product puts them at bits 12 to 15
/// (its other terms land on distinct bits elsewhere, so nothing carries).
#[inline(always)]
fn gather_nibble_bits(x: u32) -> u32 {
    (((x & 0x1111) * 0x1248) >> 12) & 0xf
}

/// `q`'s coordinates, each in all four lanes.
#[inline(always)]
fn splat3(q: Vec3A) -> [Vec4; 3] {
    [Vec4::splat(q.x), Vec4::splat(q.y), Vec4::splat(q.z)]
}

/// Squared distances from `q` (splatted) to four boxes in structure-of-arrays layout.
#[inline(always)]
fn box_distances2(lo: &[Vec4; 3], hi: &[Vec4; 3], q: &[Vec4; 3]) -> Vec4 {
    let mut d2 = Vec4::ZERO;
    for a in 0..3 {
        let d = (lo[a] - q[a]).max(q[a] - hi[a]).max(Vec4::ZERO);
        d2 += d * d;
    }
    d2
}

impl Node4 {
    /// Reference flag of a leaf: `LEAF | index of its first packet`; without the flag,
    /// the index of a 4-wide node. (An unused slot refers to packet 0, never reached: its
    /// box is empty.)
    const LEAF: u32 = 1 << 31;

    const EMPTY: Node4 = Node4 {
        lo: [Vec4::splat(f32::INFINITY); 3],
        hi: [Vec4::splat(f32::NEG_INFINITY); 3],
        cyl: Cyl4::NONE,
        child: [Node4::LEAF; 4],
        leaves: 0,
    };

    /// Lower bounds on the squared distances from `q` to the four children.
    #[inline(always)]
    fn distances2(&self, q: &[Vec4; 3]) -> Vec4 {
        box_distances2(&self.lo, &self.hi, q).max(self.cyl.distances2(q))
    }
}

/// Subtrees of more triangles than this get no bounding cylinder (near the root a box is
/// as good, and fitting would cost a pass over the subtree per level).
const MAX_CYLINDER_TRIANGLES: u32 = 1 << 12;

/// The 4-wide hierarchy and leaf packets of `bvh` (a [`Bvh2`] with fewer than `2^31`
/// nodes and packets, whose `primitive_indices` are the identity into `corners`),
/// parents before children.
///
/// The mesh tracer collapses its BVH2 too
/// ([`crate::geometry::mesh::wide_bvh::WideBvh::from_bvh2`]); the two share the traversal
/// orders of [`bvh2`] ([`bvh2::parents_first`], [`bvh2::subtree_primitives`]), not the
/// grouping: that one chooses up to eight children per node and leaves of up to eight
/// triangles by a surface area heuristic tuned for ray tests, this one opens the largest
/// inner child until there are four (every BVH2 leaf a leaf of its own) and fits bounding
/// cylinders. A shared grouping would change one of the two trees, and with it the speed
/// each was measured at.
fn collapse(bvh: &Bvh2, corners: &[[Vec3A; 3]]) -> (Vec<Node4>, Vec<ClosestPacket>) {
    let nodes = &bvh.nodes;
    let mut out: Vec<Node4> = Vec::with_capacity(nodes.len() / 2 + 1);
    let mut packets: Vec<ClosestPacket> = Vec::with_capacity(corners.len() / 3 + 1);
    // Per BVH2 node: the area-weighted normal sum and the triangle count of its subtree,
    // children before parents (the reverse of a depth-first pre-order).
    let mut normal = vec![DVec3::ZERO; nodes.len()];
    let mut count = vec![0u32; nodes.len()];
    for &i in bvh2::parents_first(bvh).iter().rev() {
        let (i, n) = (i as usize, &nodes[i as usize]);
        if n.is_leaf() {
            for s in n.first_index..n.first_index + n.prim_count {
                let [a, b, c] = corners[s as usize].map(|x| x.as_dvec3());
                normal[i] += (b - a).cross(c - a);
            }
            count[i] = n.prim_count;
        } else {
            let (l, r) = (n.first_index as usize, n.first_index as usize + 1);
            normal[i] = normal[l] + normal[r];
            count[i] = count[l] + count[r];
        }
    }
    let mut slots: Vec<u32> = Vec::new();
    let mut cylinder = |i: u32| {
        if count[i as usize] > MAX_CYLINDER_TRIANGLES {
            return Cylinder::NONE;
        }
        // The subtree's slots (its primitive indices: the identity); the fit takes maxima
        // and extents, so their order does not matter.
        slots.clear();
        bvh2::subtree_primitives(bvh, i as usize, &mut slots);
        let points = slots.iter().flat_map(|&s| corners[s as usize]);
        Cylinder::fit(points, normal[i as usize], None)
    };
    let leaf = |i: u32, packets: &mut Vec<ClosestPacket>| {
        let n = &nodes[i as usize];
        let first = packets.len() as u32;
        let slots: Vec<u32> = (n.first_index..n.first_index + n.prim_count).collect();
        for (k, chunk) in slots.chunks(4).enumerate() {
            // Unused lanes repeat the first triangle (see `PointTri4`).
            let mut slot = [chunk[0]; 4];
            let mut tris = [None; 4];
            for (lane, &s) in chunk.iter().enumerate() {
                slot[lane] = s;
                tris[lane] = Some(corners[s as usize]);
            }
            let p = ClosestPacket { tri: PointTri4::new(tris), slot, more: (k + 1) * 4 < slots.len() };
            packets.push(p);
        }
        Node4::LEAF | first
    };
    // (BVH2 node whose children the new node holds, index of the new node)
    let mut todo: Vec<(u32, u32)> = Vec::new();
    out.push(Node4::EMPTY);
    if nodes[0].is_leaf() {
        let b = nodes[0].aabb();
        for a in 0..3 {
            out[0].lo[a].x = b.min[a];
            out[0].hi[a].x = b.max[a];
        }
        out[0].child[0] = leaf(0, &mut packets);
        out[0].leaves = 1;
        return (out, packets);
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
            out[slot as usize].cyl.set(c, &cylinder(k));
            out[slot as usize].child[c] = if nodes[k as usize].is_leaf() {
                out[slot as usize].leaves |= 1 << c;
                leaf(k, &mut packets)
            } else {
                let new = out.len() as u32;
                out.push(Node4::EMPTY);
                todo.push((k, new));
                new
            };
        }
    }
    (out, packets)
}

/// The group's points in pairs, in the lanes of backend `s`: entry `j` holds point `2 j`
/// in the low four lanes and point `2 j + 1` in the high four, per coordinate.
#[inline(always)]
fn pair_coordinates<S: Simd>(s: S, qa: &[Vec3A; GROUP_MAX]) -> [[S::F32x8; 3]; GROUP_MAX / 2] {
    let mut out = [[s.splat8(0.0); 3]; GROUP_MAX / 2];
    for (j, pair) in out.iter_mut().enumerate() {
        for (a, x) in pair.iter_mut().enumerate() {
            *x = s.splat_halves8(qa[2 * j][a], qa[2 * j + 1][a]);
        }
    }
    out
}

/// `best2[t]` where point `t` is in `mask`, else -1 (within which nothing is).
#[inline(always)]
fn masked_best(best2: &[f32; GROUP_MAX], mask: u32, t: usize) -> f32 {
    if mask >> t & 1 != 0 { best2[t] } else { -1.0 }
}

/// The lanes of `v` in both halves of eight.
#[inline(always)]
fn both<S: Simd>(s: S, v: &Vec4) -> S::F32x8 {
    s.both8(v.as_ref())
}

/// The node test of the group walks, two points per eight-lane operation: bit `4 s + k`
/// of the mask is set when child `k` of `n` is within `best2[s]` of point `s` (`qs8`, from
/// [`pair_coordinates`]), for the points in `mask`; and per child the least bound among
/// the points it is within (else infinity). The same operations in the same order as
/// [`Node4::distances2`] (box, then cylinder as [`Cyl4::distances2`]), so the same bits.
#[inline(always)]
fn node_within<S: Simd>(
    s: S,
    n: &Node4,
    qs8: &[[S::F32x8; 3]; GROUP_MAX / 2],
    best2: &[f32; GROUP_MAX],
    mask: u32,
) -> (u32, Vec4) {
    let inf = s.splat8(f32::INFINITY);
    let zero = s.splat8(0.0);
    let mut within_all = 0u32;
    let mut nearest = inf;
    let mut pairs = (mask | mask >> 1) & 0x55;
    while pairs != 0 {
        let p = pairs.trailing_zeros() as usize;
        pairs &= pairs - 1;
        let q = &qs8[p / 2];
        // Box.
        let mut box2 = zero;
        for (a, &qa) in q.iter().enumerate() {
            let d = (both(s, &n.lo[a]) - qa).vmax(qa - both(s, &n.hi[a])).vmax(zero);
            box2 = box2 + d * d;
        }
        // Cylinder (as `Cyl4::distances2`).
        let c = &n.cyl;
        let v = [q[0] - both(s, &c.c[0]), q[1] - both(s, &c.c[1]), q[2] - both(s, &c.c[2])];
        let nn = [both(s, &c.n[0]), both(s, &c.n[1]), both(s, &c.n[2])];
        let h = nn[0] * v[0] + nn[1] * v[1] + nn[2] * v[2];
        let w = [v[0] - h * nn[0], v[1] - h * nn[1], v[2] - h * nn[2]];
        let rho = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).vsqrt();
        let dr = (rho - both(s, &c.r)).vmax(zero);
        let dh = (h.vabs() - both(s, &c.t)).vmax(zero);
        let cyl2 = (dr * dr + dh * dh) * s.splat8(CYL_SHRINK);
        let d2 = box2.vmax(cyl2);
        // Points outside `mask` (the second of a pair may be) get a negative best: no
        // child is within it (the bounds are not NaN).
        let b = s.splat_halves8(masked_best(best2, mask, p), masked_best(best2, mask, p + 1));
        let within = d2.mask_le(b);
        within_all |= within.bits() << (4 * p);
        nearest = nearest.vmin(within.select(d2, inf));
    }
    (within_all, Vec4::from_array(nearest.min_halves()))
}

/// `u - v` per coordinate.
#[inline(always)]
fn sub3<L: Lane8>(u: [L; 3], v: [L; 3]) -> [L; 3] {
    [u[0] - v[0], u[1] - v[1], u[2] - v[2]]
}

/// `u . v` summed `(x + y) + z`, as glam's `dot` on `Vec3A` and [`dot`].
#[inline(always)]
fn dot3<L: Lane8>(u: [L; 3], v: [L; 3]) -> L {
    u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
}

/// `a + e s` per coordinate.
#[inline(always)]
fn along3<L: Lane8>(a: [L; 3], e: [L; 3], s: L) -> [L; 3] {
    [a[0] + e[0] * s, a[1] + e[1] * s, a[2] + e[2] * s]
}

/// Per lane, `u` where `m` is set, else `v`.
#[inline(always)]
fn select3_lanes<M: Mask8>(m: M, u: [M::Lanes; 3], v: [M::Lanes; 3]) -> [M::Lanes; 3] {
    [m.select(u[0], v[0]), m.select(u[1], v[1]), m.select(u[2], v[2])]
}

/// [`PointTri4::closest`] for two points at once (`q`: point `2 j` in the low four lanes,
/// `2 j + 1` in the high four, as [`pair_coordinates`] gives them): the same operations in
/// the same order, so the same bits.
#[inline(always)]
fn tri_closest<S: Simd>(s: S, t: &PointTri4, q: &[S::F32x8; 3]) -> (S::F32x8, [S::F32x8; 3]) {
    let q = *q;
    let a = [both(s, &t.a[0]), both(s, &t.a[1]), both(s, &t.a[2])];
    let b = [both(s, &t.b[0]), both(s, &t.b[1]), both(s, &t.b[2])];
    let c = [both(s, &t.c[0]), both(s, &t.c[1]), both(s, &t.c[2])];
    let n = [both(s, &t.n[0]), both(s, &t.n[1]), both(s, &t.n[2])];
    let ab = sub3(b, a);
    let ac = sub3(c, a);
    let ap = sub3(q, a);
    let bp = sub3(q, b);
    let cp = sub3(q, c);
    let d1 = dot3(ab, ap);
    let d2 = dot3(ac, ap);
    let d3 = dot3(ab, bp);
    let d4 = dot3(ac, bp);
    let d5 = dot3(ab, cp);
    let d6 = dot3(ac, cp);
    let vc = d1 * d4 - d3 * d2;
    let vb = d5 * d2 - d1 * d6;
    let va = d3 * d6 - d5 * d4;
    let zero = s.splat8(0.0);
    // The regions, each as the scalar code tests it (see `PointTri4::closest`).
    let in_a = d1.mask_le(zero) & d2.mask_le(zero);
    let in_b = zero.mask_le(d3) & d4.mask_le(d3);
    let in_ab = vc.mask_le(zero) & zero.mask_le(d1) & d3.mask_le(zero);
    let in_c = zero.mask_le(d6) & d5.mask_le(d6);
    let in_ac = vb.mask_le(zero) & zero.mask_le(d2) & d6.mask_le(zero);
    let (e, f) = (d4 - d3, d5 - d6);
    let in_bc = va.mask_le(zero) & zero.mask_le(e) & zero.mask_le(f);
    let tt = dot3(ap, n) / both(s, &t.nn);
    let x = [q[0] - n[0] * tt, q[1] - n[1] * tt, q[2] - n[2] * tt];
    let x = select3_lanes(in_bc, along3(b, sub3(c, b), e / (e + f)), x);
    let x = select3_lanes(in_ac, along3(a, ac, d2 / (d2 - d6)), x);
    let x = select3_lanes(in_c, c, x);
    let x = select3_lanes(in_ab, along3(a, ab, d1 / (d1 - d3)), x);
    let x = select3_lanes(in_b, b, x);
    let x = select3_lanes(in_a, a, x);
    let off = sub3(x, q);
    (dot3(off, off), x)
}

/// [`ClosestPacket::improve`] for points `p` and `p + 1` (`p` even; those in `mask`) of a
/// group walk at once, in the lanes of backend `s`.
#[inline(always)]
fn improve_pair<S: Simd>(
    s: S,
    packet: &ClosestPacket,
    q: &[S::F32x8; 3],
    p: usize,
    mask: u32,
    best2: &mut [f32; GROUP_MAX],
    best: &mut [(u32, Vec3A); GROUP_MAX],
) {
    let (d2, x) = tri_closest(s, &packet.tri, q);
    // Points outside `mask` get a negative best: no lane is within it.
    let b = s.splat_halves8(masked_best(best2, mask, p), masked_best(best2, mask, p + 1));
    let bits = d2.mask_le(b).bits();
    if bits == 0 {
        return;
    }
    let d = d2.store();
    for h in 0..2 {
        let mut lanes = bits >> (4 * h) & 0xf;
        if lanes == 0 {
            continue;
        }
        let t = p + h;
        let mut found = 0;
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            if d[4 * h + l] <= best2[t] {
                best2[t] = d[4 * h + l];
                found = l;
            }
        }
        let xs = [x[0].store(), x[1].store(), x[2].store()];
        let i = 4 * h + found;
        best[t] = (packet.slot[found], Vec3A::new(xs[0][i], xs[1][i], xs[2][i]));
    }
}

/// [`TriangleBvh::nearest_group`] as a [`Kernel`].
struct GroupWalk<'a> {
    tree: &'a TriangleBvh,
    points: &'a [Vec3],
    hints: &'a [Option<u32>],
    out: &'a mut [Option<Nearest>],
    stack: &'a mut GroupStack,
    visited: &'a mut u64,
}

impl Kernel for GroupWalk<'_> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        self.tree.group_walk(s, self.points, self.hints, self.out, self.stack, self.visited)
    }
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
                wide: Vec::new(),
                packets: Vec::new(),
            };
        }
        let mut bvh = bvh2::build(&boxes, params);
        let original = std::mem::take(&mut bvh.primitive_indices);
        let corners: Vec<[Vec3A; 3]> = original.iter().map(|&i| tri(&mesh.triangles[i as usize])).collect();
        bvh.primitive_indices = (0..original.len() as u32).collect();
        let (wide, packets) = collapse(&bvh, &corners);
        TriangleBvh { bvh, corners, original, wide, packets }
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
    /// opened. The result is the same as without the hint (up to ties). A walk of its own
    /// rather than [`TriangleBvh::nearest_group`] of one point, which is slower for one
    /// point (see the module documentation).
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
        let qs = splat3(q);
        // At most `f32::MAX`, so that empty (infinitely far) slots are never entered.
        let mut best2 = (max_dist * max_dist).min(f32::MAX);
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
            let mut at = (r & !Node4::LEAF) as usize;
            loop {
                let packet = &self.packets[at];
                if let Some(found) = packet.improve(&qs, best2) {
                    *best = Some(found);
                }
                if !packet.more {
                    break;
                }
                at += 1;
            }
        };
        let wide = &self.wide;
        stack.clear();
        stack.push(0); // the root, bound 0
        while let Some(key) = stack.pop() {
            if f32::from_bits((key >> 32) as u32) > best2 {
                continue;
            }
            let n = &wide[key as u32 as usize];
            *visited += 4;
            let d2 = n.distances2(&qs);
            let within = d2.cmple(Vec4::splat(best2)).bitmask();
            // Leaves at once (tightening the bound).
            let mut leaves = within & n.leaves;
            while leaves != 0 {
                let k = leaves.trailing_zeros() as usize;
                leaves &= leaves - 1;
                test_leaf(n.child[k], &mut best2, &mut best);
            }
            // Inner nodes onto the stack, farthest first: keys (bound bits, reference) sorted
            // without branches (non-negative floats order as their bits).
            let inner = within & !n.leaves;
            if inner != 0 {
                let d = d2.to_array();
                let key = |k: usize| {
                    if inner >> k & 1 != 0 {
                        (d[k].to_bits() as u64) << 32 | n.child[k] as u64
                    } else {
                        u64::MAX
                    }
                };
                let mut keys = [key(0), key(1), key(2), key(3)];
                for (x, y) in [(0, 1), (2, 3), (0, 2), (1, 3), (1, 2)] {
                    let (lo, hi) = (keys[x].min(keys[y]), keys[x].max(keys[y]));
                    keys[x] = lo;
                    keys[y] = hi;
                }
                for &k in keys[..inner.count_ones() as usize].iter().rev() {
                    stack.push(k);
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

    /// [`TriangleBvh::nearest_with_hint`] for up to [`GROUP_MAX`] nearby points at once
    /// (e.g. a 2x4 block of grid samples): one walk whose nodes are opened when any of the
    /// points needs them, each point pruning by its own best distance, so that the nodes'
    /// bounds are loaded once for all and the points' independent arithmetic overlaps.
    /// `hints[i]` (a slot, see [`Nearest::slot`]) bounds point `i`'s search from the start.
    /// Writes point `i`'s answer to `out[i]` (`None` only for an empty BVH). Adds the child
    /// bounds evaluated (four per node and point) to `visited`.
    ///
    /// # Panics
    /// When `points`, `hints` and `out` differ in length or are longer than [`GROUP_MAX`].
    pub fn nearest_group(
        &self,
        points: &[Vec3],
        hints: &[Option<u32>],
        out: &mut [Option<Nearest>],
        stack: &mut GroupStack,
        visited: &mut u64,
    ) {
        dispatch(GroupWalk { tree: self, points, hints, out, stack, visited })
    }

    /// [`TriangleBvh::nearest_group`] on backend `s` (for comparing backends: the results
    /// and the work are the same, bit for bit). Call it for [`crate::simd::Avx2`] inside
    /// [`crate::simd::Avx2::vectorize`], which compiles it for AVX2.
    #[inline(always)]
    pub fn nearest_group_on<S: Simd>(
        &self,
        s: S,
        points: &[Vec3],
        hints: &[Option<u32>],
        out: &mut [Option<Nearest>],
        stack: &mut GroupStack,
        visited: &mut u64,
    ) {
        self.group_walk(s, points, hints, out, stack, visited)
    }

    /// The leaf `r` (a reference with [`Node4::LEAF`]) for the points in `mask` of a group
    /// walk: each point's best improved by the leaf's triangles, as [`ClosestPacket::improve`]
    /// does (two points per eight-lane operation, the same bits).
    #[inline(always)]
    fn group_leaf<S: Simd>(
        &self,
        s: S,
        r: u32,
        mask: u32,
        qs8: &[[S::F32x8; 3]; GROUP_MAX / 2],
        best2: &mut [f32; GROUP_MAX],
        best: &mut [(u32, Vec3A); GROUP_MAX],
    ) {
        let mut at = (r & !Node4::LEAF) as usize;
        loop {
            let packet = &self.packets[at];
            let mut pairs = (mask | mask >> 1) & 0x55;
            while pairs != 0 {
                let p = pairs.trailing_zeros() as usize;
                pairs &= pairs - 1;
                improve_pair(s, packet, &qs8[p / 2], p, mask, best2, best);
            }
            if !packet.more {
                break;
            }
            at += 1;
        }
    }

    #[inline(always)]
    fn group_walk<S: Simd>(
        &self,
        s: S,
        points: &[Vec3],
        hints: &[Option<u32>],
        out: &mut [Option<Nearest>],
        stack: &mut GroupStack,
        visited: &mut u64,
    ) {
        let g = points.len();
        assert!(g <= GROUP_MAX && hints.len() == g && out.len() == g, "a group of up to {GROUP_MAX} points");
        if self.wide.is_empty() {
            out.fill(None);
            return;
        }
        let mut qa = [Vec3A::ZERO; GROUP_MAX];
        let mut best2 = [f32::MAX; GROUP_MAX];
        let mut best: [(u32, Vec3A); GROUP_MAX] = [(u32::MAX, Vec3A::ZERO); GROUP_MAX];
        for s in 0..g {
            qa[s] = Vec3A::from(points[s]);
            if let Some(slot) = hints[s].filter(|&h| (h as usize) < self.corners.len()) {
                let [a, b, c] = self.corners[slot as usize];
                let x = closest_point_on_triangle(qa[s], a, b, c);
                best2[s] = (x - qa[s]).length_squared().min(f32::MAX);
                best[s] = (slot, x);
            }
        }
        let qs8 = pair_coordinates(s, &qa);
        let wide = &self.wide;
        stack.0.clear();
        stack.0.push(GroupEntry { bound: 0.0, node: 0, mask: (1 << g) - 1 });
        while let Some(e) = stack.0.pop() {
            // The points that may still find something below (`bound` is the least of
            // theirs, so a point whose best is nearer is done with this node).
            let mask = within_best(&best2, e.bound) & e.mask;
            if mask == 0 {
                continue;
            }
            let n = &wide[e.node as usize];
            // Bit `4 s + k`: child `k` is within point `s`'s best; `nearest`: per child, the
            // least bound among the points it is within.
            *visited += 4 * mask.count_ones() as u64;
            let (within_all, nearest) = node_within(s, n, &qs8, &best2, mask);
            // Transposed: bit `s` of `children[k]`, four points at a time (`GROUP_MAX` is 8).
            let mut children = [0u32; 4];
            for (k, c) in children.iter_mut().enumerate() {
                *c = gather_nibble_bits(within_all >> k) | gather_nibble_bits(within_all >> (16 + k)) << 4;
            }
            // Bit `k`: some point needs child `k`.
            let needed = within_all | within_all >> 16;
            let needed = needed | needed >> 8;
            let needed = (needed | needed >> 4) & 0xf;
            let mut leaves = needed & n.leaves;
            while leaves != 0 {
                let k = leaves.trailing_zeros() as usize;
                leaves &= leaves - 1;
                self.group_leaf(s, n.child[k], children[k], &qs8, &mut best2, &mut best);
            }
            // Inner nodes onto the stack, farthest first (keys: bound bits, child number).
            let d = nearest.to_array();
            let mut keys = [u64::MAX; 4];
            let mut count = 0;
            let mut inner = needed & !n.leaves;
            while inner != 0 {
                let k = inner.trailing_zeros() as usize;
                inner &= inner - 1;
                keys[count] = (d[k].to_bits() as u64) << 32 | k as u64;
                count += 1;
            }
            for (x, y) in [(0, 1), (2, 3), (0, 2), (1, 3), (1, 2)] {
                let (lo, hi) = (keys[x].min(keys[y]), keys[x].max(keys[y]));
                keys[x] = lo;
                keys[y] = hi;
            }
            for &key in keys[..count].iter().rev() {
                let k = key as u32 as usize;
                stack.0.push(GroupEntry { bound: d[k], node: n.child[k], mask: children[k] });
            }
        }
        for s in 0..g {
            let (slot, x) = best[s];
            out[s] = (slot != u32::MAX).then(|| Nearest {
                dist2: best2[s],
                triangle: self.original[slot as usize],
                slot,
                point: Vec3::from(x),
            });
        }
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
        bvh2::bytes_used(&self.bvh)
            + self.corners.capacity() * std::mem::size_of::<[Vec3A; 3]>()
            + self.original.capacity() * 4
            + self.wide.capacity() * std::mem::size_of::<Node4>()
            + self.packets.capacity() * std::mem::size_of::<ClosestPacket>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simd::Portable;

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

    /// [`PointTri4::closest`] gives the bits of [`closest_point_on_triangle`] (distance and
    /// point) in every lane: random triangles (some slivers, some far from the origin, some
    /// with corners on a coarse lattice so that ties and region borders are hit exactly),
    /// query points in every region, on corners and edges, with unused lanes.
    #[test]
    fn simd_closest_points_match_the_scalar_bits() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut unit = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let (mut corners, mut others) = (0, 0);
        for round in 0..20000 {
            let offset = if round % 4 == 3 { Vec3A::new(1e3, -2e3, 5e2) } else { Vec3A::ZERO };
            let lattice = round % 5 == 4;
            let mut v = || {
                let p = Vec3A::new(unit(), unit(), unit());
                if lattice { (p * 4.0).round() * 0.25 } else { p }
            };
            let mut tris = [None; 4];
            let used = 1 + round % 4;
            for (lane, t) in tris.iter_mut().enumerate().take(used) {
                let (a, b) = (v(), v());
                // Lane 1 of every other round: a sliver.
                let c = if lane == 1 && round % 2 == 0 { a + (b - a) * 0.37 + v() * 1e-3 } else { v() };
                if (b - a).cross(c - a).length_squared() > 1e-12 {
                    *t = Some([a + offset, b + offset, c + offset]);
                }
            }
            if tris[0].is_none() {
                continue;
            }
            let t4 = PointTri4::new(tris);
            let q = match round % 3 {
                0 => offset + v() * 3.0,
                1 => tris[0].unwrap()[round / 3 % 3],
                _ => {
                    let [a, b, _] = tris[0].unwrap();
                    a + (b - a) * 0.5 + v() * 1e-3
                }
            };
            let (d2, x) = t4.closest(&splat3(q));
            // Two points at once (the group walks' test), on both backends: each half has
            // the bits of the one-point test.
            let q2 = q * 0.5 + Vec3A::new(0.25, -0.5, 0.125);
            let (d2b, _) = t4.closest(&splat3(q2));
            let mut pair = vec![pair_test(Portable, &t4, q, q2)];
            if let Some(s) = crate::simd::avx2() {
                pair.push(s.vectorize(|| pair_test(s, &t4, q, q2)));
            }
            for (pd, px) in pair {
                for lane in 0..4 {
                    assert_eq!(pd[lane].to_bits(), d2[lane].to_bits(), "round {round} lane {lane}");
                    assert_eq!(pd[lane + 4].to_bits(), d2b[lane].to_bits(), "round {round} lane {lane}");
                    for a in 0..3 {
                        assert_eq!(px[a][lane].to_bits(), x[a][lane].to_bits(), "round {round} lane {lane}");
                    }
                }
            }
            for lane in 0..4 {
                let [a, b, c] = tris[lane].or(tris[0]).unwrap();
                let want = closest_point_on_triangle(q, a, b, c);
                let got = Vec3A::new(x[0][lane], x[1][lane], x[2][lane]);
                assert_eq!(
                    got.to_array().map(f32::to_bits),
                    want.to_array().map(f32::to_bits),
                    "round {round} lane {lane}"
                );
                assert_eq!(
                    d2[lane].to_bits(),
                    (want - q).length_squared().to_bits(),
                    "round {round} lane {lane}"
                );
                if [a, b, c].contains(&want) {
                    corners += 1;
                } else {
                    others += 1;
                }
            }
        }
        assert!(corners > 10000 && others > 10000, "{corners} {others}");
    }

    /// [`tri_closest`] on backend `s` for `q` (lanes 0..4) and `q2` (lanes 4..8).
    fn pair_test<S: Simd>(s: S, t: &PointTri4, q: Vec3A, q2: Vec3A) -> ([f32; 8], [[f32; 8]; 3]) {
        let qs = [s.splat_halves8(q.x, q2.x), s.splat_halves8(q.y, q2.y), s.splat_halves8(q.z, q2.z)];
        let (d2, x) = tri_closest(s, t, &qs);
        (d2.store(), [x[0].store(), x[1].store(), x[2].store()])
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
