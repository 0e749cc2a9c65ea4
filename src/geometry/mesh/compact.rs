//! The compact layout of a mesh's 8-wide BVH ([`CompactBvh`]), as a polygon renderer ships a
//! memory-optimised mesh: 96-byte quantised nodes (the parent box in `f32` and a power-of-two
//! step per axis, each child box as 8-bit offsets rounded outward, after compressed wide
//! BVHs: Ylitie, Karras and Laine 2017), 16-bit vertex positions on one grid per mesh
//! ([`VertexGrid`]), and leaves that are ranges of the triangle list (in leaf order) rather
//! than packets of pre-gathered corners.
//!
//! The mesh it traces is the quantised one: positions are snapped to the grid before the
//! BVH is built ([`VertexGrid::snap`]), and the leaf test dequantises them with the same
//! `f32` operations, so its corners are the snapped positions bit for bit and the node
//! boxes, built over them and then quantised outward (checked with the walk's own
//! dequantisation), hold every triangle. The walks are the full layout's
//! ([`super::wide_bvh::closest_walk`], [`super::wide_bvh::any_walk`]) through
//! [`WideLayout`]; only the node's box test and the leaf's triangle gather differ.

use glam::{DVec3, Vec3};

use crate::geometry::mesh::triangle::{ShearedRay, Tri4};
use crate::geometry::mesh::wide_bvh::{
    BoxRay, LEAF, LEAF_MAX, LEAF_SHIFT, LeafHit, NONE, WIDTH, WideBvh, WideLayout, WideNode, leaf_range,
};
use crate::geometry::{Aabb, box_distance};
use crate::simd::Simd;

/// Steps of a vertex coordinate on the mesh's grid: 16 bits.
const VERTEX_STEPS: f64 = 65535.0;
/// Steps of a child box's bound within its parent's box: 8 bits.
const BOX_STEPS: f64 = 255.0;

/// `2^e` as an `f32` (`e` in -126..=127: a normal number).
#[inline(always)]
fn pow2(e: i8) -> f32 {
    f32::from_bits(((i32::from(e) + 127) as u32) << 23)
}

/// The exponent of the smallest power of two `2^e` (within -126..=127) for which `steps`
/// steps from `lo` reach `hi` when dequantised as the walks do (`steps * 2^e + lo`,
/// rounded once in `f32`); `None` where none does (a non-finite or too large extent).
fn step_exponent(lo: f32, hi: f32, steps: f64) -> Option<i8> {
    if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
        return None;
    }
    let d = f64::from(hi) - f64::from(lo);
    let mut e = if d > 0.0 { ((d / steps).log2().ceil() as i32).clamp(-126, 127) } else { -126 };
    while e <= 127 {
        let top = steps as f32 * pow2(e as i8) + lo;
        if top >= hi && top.is_finite() {
            return Some(e as i8);
        }
        e += 1;
    }
    None
}

/// One grid for a mesh's vertex positions: per axis an origin and a power-of-two step, a
/// position `q * step + origin` for a 16-bit `q` (rounded once in `f32`; `q * step` is
/// exact).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexGrid {
    origin: [f32; 3],
    step: [f32; 3],
}

impl VertexGrid {
    /// The grid over the box of `positions`; `None` without positions or where a
    /// coordinate is not finite.
    pub fn of(positions: &[Vec3]) -> Option<Self> {
        let first = *positions.first()?;
        let (lo, hi) = positions.iter().fold((first, first), |(l, h), &p| (l.min(p), h.max(p)));
        let mut step = [0.0; 3];
        for a in 0..3 {
            step[a] = pow2(step_exponent(lo[a], hi[a], VERTEX_STEPS)?);
        }
        Some(VertexGrid { origin: lo.to_array(), step })
    }

    /// The grid point nearest `p` (clamped to the grid).
    pub fn quantise(&self, p: Vec3) -> [u16; 3] {
        std::array::from_fn(|a| {
            let q = ((f64::from(p[a]) - f64::from(self.origin[a])) / f64::from(self.step[a])).round();
            q.clamp(0.0, VERTEX_STEPS) as u16
        })
    }

    /// The position of grid point `q`, as the walks compute it.
    #[inline(always)]
    pub fn position(&self, q: [u16; 3]) -> Vec3 {
        Vec3::new(
            f32::from(q[0]) * self.step[0] + self.origin[0],
            f32::from(q[1]) * self.step[1] + self.origin[1],
            f32::from(q[2]) * self.step[2] + self.origin[2],
        )
    }

    /// `p` snapped to the grid: the position of its grid point.
    pub fn snap(&self, p: Vec3) -> Vec3 {
        self.position(self.quantise(p))
    }
}

/// A quantised inner node (96 bytes): the box of its children in `f32` (its minimum) and a
/// power-of-two step per axis, each child's box as 8-bit step counts from that minimum,
/// rounded outward, and the child references.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct CompactNode {
    /// The minimum corner of the node's box: the children's bounds are
    /// `q * 2^exp + origin` per axis.
    origin: [f32; 3],
    /// Per axis, the exponent of the step.
    exp: [i8; 3],
    /// Bit `l` set where lane `l` holds a child.
    used: u8,
    /// Child box minima, `lo[axis][lane]`, in steps from `origin` (rounded down).
    lo: [[u8; WIDTH]; 3],
    /// Child box maxima, `hi[axis][lane]`, in steps from `origin` (rounded up).
    hi: [[u8; WIDTH]; 3],
    /// Per lane: a node's index in [`CompactBvh::nodes`], or
    /// `LEAF | first << LEAF_SHIFT | (count - 1)` for a leaf of the `count` triangles of
    /// [`CompactBvh::triangles`] from `first` on, or [`NONE`].
    children: [u32; WIDTH],
}

const _: () = assert!(size_of::<CompactNode>() == 96);

impl CompactNode {
    /// The dequantised box of lane `l` (its minimum and maximum), as the walks compute it.
    pub fn child_box(&self, l: usize) -> (Vec3, Vec3) {
        let b = |q: [u8; 3]| {
            Vec3::from_array(std::array::from_fn(|a| f32::from(q[a]) * pow2(self.exp[a]) + self.origin[a]))
        };
        (b([self.lo[0][l], self.lo[1][l], self.lo[2][l]]), b([self.hi[0][l], self.hi[1][l], self.hi[2][l]]))
    }

    /// The lanes in use, as bits.
    pub fn used(&self) -> u32 {
        u32::from(self.used)
    }

    /// The quantised node over the child boxes `boxes` (minimum, maximum; `None` for an
    /// unused lane) with references `children`; `None` where a box is not finite.
    pub fn quantise(boxes: &[Option<(Vec3, Vec3)>; WIDTH], children: [u32; WIDTH]) -> Option<Self> {
        let (lo, hi) = boxes
            .iter()
            .flatten()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), &(a, b)| (l.min(a), h.max(b)));
        if boxes.iter().flatten().any(|(a, b)| !(a.is_finite() && b.is_finite())) {
            return None;
        }
        let mut n = CompactNode {
            origin: [0.0; 3],
            exp: [0; 3],
            used: 0,
            lo: [[0; WIDTH]; 3],
            hi: [[0; WIDTH]; 3],
            children,
        };
        if boxes.iter().all(Option::is_none) {
            n.children = [NONE; WIDTH];
            return Some(n);
        }
        for a in 0..3 {
            n.exp[a] = step_exponent(lo[a], hi[a], BOX_STEPS)?;
            n.origin[a] = lo[a];
        }
        for (l, b) in boxes.iter().enumerate() {
            let Some((bmin, bmax)) = b else {
                n.children[l] = NONE;
                continue;
            };
            n.used |= 1 << l;
            for a in 0..3 {
                let (step, origin) = (pow2(n.exp[a]), n.origin[a]);
                let deq = |q: u8| f32::from(q) * step + origin;
                let exact = |x: f32| (f64::from(x) - f64::from(origin)) / f64::from(step);
                // Outward: the largest step count not above the minimum, the smallest not
                // below the maximum, checked in the walks' arithmetic (0 dequantises to
                // `origin`, 255 to at least the node's maximum: `step_exponent`).
                let mut q = exact(bmin[a]).floor().clamp(0.0, BOX_STEPS) as u8;
                while q > 0 && deq(q) > bmin[a] {
                    q -= 1;
                }
                n.lo[a][l] = q;
                let mut q = exact(bmax[a]).ceil().clamp(0.0, BOX_STEPS) as u8;
                while q < u8::MAX && deq(q) < bmax[a] {
                    q += 1;
                }
                n.hi[a][l] = q;
            }
        }
        Some(n)
    }
}

/// The compact layout of a mesh's BVH: quantised nodes, the triangle list in leaf order
/// (leaves are ranges of it) and the vertices on one 16-bit grid.
#[derive(Clone, Debug)]
pub struct CompactBvh {
    /// Inner nodes; node 0 is the root.
    pub nodes: Vec<CompactNode>,
    /// Triangles (vertex indices) in leaf order.
    pub triangles: Vec<[u32; 3]>,
    /// Vertex positions on `grid`.
    pub vertices: Vec<[u16; 3]>,
    /// The grid of the vertex positions.
    pub grid: VertexGrid,
    /// Deepest node level (root = 1).
    pub depth: usize,
}

impl CompactBvh {
    /// The compact layout of `full`, built over the triangles `triangles` (indexed by the
    /// full layout's packet ids) of the vertices `positions`, already snapped to `grid`
    /// ([`VertexGrid::snap`]); its own triangle list is in the full layout's packet order,
    /// so that each leaf is a run of it (triangle indices of its hits index that list:
    /// [`CompactBvh::triangles`]). `None` where a box is not finite, or the list is too long
    /// for a leaf reference.
    pub fn from_wide(
        full: &WideBvh,
        triangles: Vec<[u32; 3]>,
        positions: &[Vec3],
        grid: VertexGrid,
    ) -> Option<Self> {
        if triangles.len() >= (LEAF >> LEAF_SHIFT) as usize {
            return None;
        }
        // The triangles in the full layout's packet order (a leaf's packets are consecutive,
        // so each leaf becomes a run of the list, its lanes in the same order), and where
        // each packet's triangles start in it.
        let mut start = Vec::with_capacity(full.packets.len());
        let mut order = Vec::with_capacity(triangles.len());
        for p in &full.packets {
            start.push(order.len() as u32);
            order.extend(p.ids.iter().copied().filter(|&i| i != u32::MAX));
        }
        if order.len() != triangles.len() {
            return None;
        }
        let mut nodes = Vec::with_capacity(full.nodes.len());
        for n in &full.nodes {
            let boxes: [Option<(Vec3, Vec3)>; WIDTH] = std::array::from_fn(|l| {
                (n.children[l] != NONE).then(|| {
                    (
                        Vec3::new(n.bounds[0][l], n.bounds[1][l], n.bounds[2][l]),
                        Vec3::new(n.bounds[3][l], n.bounds[4][l], n.bounds[5][l]),
                    )
                })
            });
            let mut children = [NONE; WIDTH];
            for (l, &c) in n.children.iter().enumerate() {
                children[l] = if c == NONE {
                    NONE
                } else if c & LEAF == 0 {
                    c / size_of::<WideNode>() as u32
                } else {
                    let (first, count) = leaf_range(c);
                    LEAF | (start[first] << LEAF_SHIFT) | (count as u32 - 1)
                };
            }
            nodes.push(CompactNode::quantise(&boxes, children)?);
        }
        let mut triangles =
            order.iter().map(|&i| triangles.get(i as usize).copied()).collect::<Option<Vec<_>>>()?;
        // Collecting through `Option` does not know the length in advance: the vector grew
        // by doubling (131,072 slots for the bunny's 69,451 triangles); the layout holds
        // only what it needs.
        triangles.shrink_to_fit();
        let vertices = positions.iter().map(|&p| grid.quantise(p)).collect();
        Some(CompactBvh { nodes, triangles, vertices, grid, depth: full.depth })
    }

    /// Bytes of the nodes alone.
    pub fn node_bytes(&self) -> usize {
        self.nodes.capacity() * size_of::<CompactNode>()
    }

    /// Bytes held: the struct, nodes, triangle list and vertices.
    pub fn bytes_used(&self) -> usize {
        size_of::<Self>()
            + self.node_bytes()
            + self.triangles.capacity() * size_of::<[u32; 3]>()
            + self.vertices.capacity() * size_of::<[u16; 3]>()
    }

    /// Vertex `v`'s position.
    #[inline(always)]
    pub fn position(&self, v: u32) -> Vec3 {
        self.grid.position(self.vertices[v as usize])
    }

    /// The corners of triangle `i` (leaf order).
    #[inline(always)]
    pub fn corners(&self, i: usize) -> [Vec3; 3] {
        self.triangles[i].map(|v| self.position(v))
    }

    /// As [`WideBvh::nearest`]: the smallest `dist(triangle)` for a query at `p`, nearest
    /// boxes first, pruned by the best so far. Allocates (for measurement, not tracing).
    pub fn nearest(&self, p: DVec3, mut dist: impl FnMut(u32) -> f64) -> f64 {
        let mut best = f64::INFINITY;
        if self.nodes.is_empty() {
            return best;
        }
        let mut stack = vec![(0u32, 0.0f64)];
        while let Some((cur, d)) = stack.pop() {
            if d >= best {
                continue;
            }
            if cur & LEAF != 0 {
                let (first, count) = leaf_range(cur);
                for i in first..first + count {
                    best = best.min(dist(i as u32));
                }
                continue;
            }
            let n = &self.nodes[cur as usize];
            let mut kids: Vec<(u32, f64)> = (0..WIDTH)
                .filter(|&l| n.used() & (1 << l) != 0)
                .map(|l| {
                    let (lo, hi) = n.child_box(l);
                    (n.children[l], box_distance(&Aabb::new(lo.into(), hi.into()), p))
                })
                .collect();
            kids.sort_by(|a, b| b.1.total_cmp(&a.1));
            stack.extend(kids);
        }
        best
    }
}

impl WideLayout for CompactBvh {
    type Node = CompactNode;
    #[inline(always)]
    fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
    #[inline(always)]
    fn depth(&self) -> usize {
        self.depth
    }
    #[inline(always)]
    fn root(&self) -> &CompactNode {
        &self.nodes[0]
    }
    #[inline(always)]
    fn node(&self, r: u32) -> &CompactNode {
        &self.nodes[r as usize]
    }
    #[inline(always)]
    fn children(n: &CompactNode) -> &[u32; WIDTH] {
        &n.children
    }
    /// The dequantised rows (`q * step + origin`: the product exact, one rounding, the
    /// arithmetic [`CompactNode::quantise`] checked its rounding outward in) through the full
    /// layout's test; unused lanes are masked off (their rows are not NaN).
    #[inline(always)]
    fn test_node<S: Simd, const ROOT: bool>(
        br: &BoxRay<S>,
        n: &CompactNode,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [u32; WIDTH]) {
        let s = br.simd();
        let step = [s.splat8(pow2(n.exp[0])), s.splat8(pow2(n.exp[1])), s.splat8(pow2(n.exp[2]))];
        let origin = [s.splat8(n.origin[0]), s.splat8(n.origin[1]), s.splat8(n.origin[2])];
        let rows = [
            s.bytes8(&n.lo[0]) * step[0] + origin[0],
            s.bytes8(&n.lo[1]) * step[1] + origin[1],
            s.bytes8(&n.lo[2]) * step[2] + origin[2],
            s.bytes8(&n.hi[0]) * step[0] + origin[0],
            s.bytes8(&n.hi[1]) * step[1] + origin[1],
            s.bytes8(&n.hi[2]) * step[2] + origin[2],
        ];
        let (mask, d) = br.hit_rows::<ROOT>(rows, t_min, t_max);
        (mask & u32::from(n.used), d)
    }
    /// Gathers the leaf's triangles (dequantised corners) into one or two packets and tests
    /// them as the full layout tests its packets.
    #[inline(always)]
    fn leaf_test<S: Simd>(
        &self,
        s: S,
        sheared: &ShearedRay,
        (first, count): (usize, usize),
        t_min: f32,
        t_max: f32,
    ) -> ([f32; 8], u32) {
        let mut tri: [Tri4; 2] = [[[[f32::NAN; LEAF_MAX]; 3]; 3]; 2];
        for (j, t) in self.triangles[first..first + count].iter().enumerate() {
            let (k, lane) = (j / LEAF_MAX, j % LEAF_MAX);
            for v in 0..3 {
                let p = self.position(t[v]);
                for a in 0..3 {
                    tri[k & 1][v][a][lane] = p[a];
                }
            }
        }
        if count > LEAF_MAX {
            sheared.intersect8(s, &tri[0], &tri[1], t_min, t_max)
        } else {
            let (t4, mask) = sheared.intersect4(s, &tri[0], t_min, t_max);
            let mut t = [0.0; 8];
            t[..LEAF_MAX].copy_from_slice(&t4);
            (t, mask)
        }
    }
    #[inline(always)]
    fn leaf_at((first, _): (usize, usize), lane: usize) -> (usize, usize) {
        (first + lane, 0)
    }
    #[inline(always)]
    fn leaf_hit(&self, (i, _): (usize, usize), t: f32) -> LeafHit {
        LeafHit { triangle: i as u32, t, corners: self.corners(i) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn vec3() -> impl Strategy<Value = Vec3> {
        (-1e3f32..1e3, -1e3f32..1e3, -1e3f32..1e3).prop_map(|(x, y, z)| Vec3::new(x, y, z))
    }

    proptest! {
        /// The dequantised child boxes contain the true ones, and stay within the node's box
        /// grown by one step per side.
        #[test]
        fn quantised_boxes_contain_the_true_ones(
            corners in proptest::collection::vec((vec3(), vec3(), 0f32..1.0), 1..=WIDTH),
            scale in -20i32..20,
        ) {
            let f = 2f32.powi(scale);
            let boxes: [Option<(Vec3, Vec3)>; WIDTH] = std::array::from_fn(|l| {
                corners.get(l).map(|&(a, b, w)| {
                    // Some boxes thin (w small), some flat (w == 0 after rounding).
                    let b = a + (b - a) * w;
                    (a.min(b) * f, a.max(b) * f)
                })
            });
            let n = CompactNode::quantise(&boxes, [7; WIDTH]).expect("finite boxes");
            for (l, b) in boxes.iter().enumerate() {
                match b {
                    None => prop_assert!(n.used() & (1 << l) == 0 && n.children[l] == NONE),
                    Some((lo, hi)) => {
                        prop_assert!(n.used() & (1 << l) != 0);
                        let (qlo, qhi) = n.child_box(l);
                        prop_assert!(qlo.cmple(*lo).all() && qhi.cmpge(*hi).all(), "{qlo} {qhi} vs {lo} {hi}");
                        let step = Vec3::from_array(n.exp.map(pow2));
                        prop_assert!((*lo - qlo).cmple(step * 1.0001 + lo.abs() * 1e-6).all());
                        prop_assert!((qhi - *hi).cmple(step * 1.0001 + hi.abs() * 1e-6).all());
                    }
                }
            }
        }

        /// Snapped positions are grid positions: quantising them again gives the same
        /// point, and they lie within half a step (and a rounding) of the input.
        #[test]
        fn vertices_snap_to_the_grid(points in proptest::collection::vec(vec3(), 1..50)) {
            let g = VertexGrid::of(&points).expect("finite");
            for &p in &points {
                let s = g.snap(p);
                prop_assert_eq!(g.snap(s), s);
                let step = Vec3::from_array(g.step);
                prop_assert!((s - p).abs().cmple(step * 0.5 + p.abs() * 1e-6 + 1e-6).all());
            }
        }
    }

    /// The walks over the compact layout find what the full layout's find over the same
    /// (snapped) triangles, which is what brute force finds: same triangle, same `t`, same
    /// any-hit answers and nearest distances, on both backends; every triangle is in one
    /// leaf.
    #[test]
    fn compact_walks_equal_full_ones() {
        use crate::geometry::RayStats;
        use crate::geometry::mesh::wide_bvh::{any_walk, closest_walk};
        use crate::simd::Portable;
        use obvhs::BvhBuildParams;
        let mut seed = 777u32;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f32 / u32::MAX as f32
        };
        // A shared vertex list (as meshes have), triangles over random vertices near each other.
        let raw: Vec<Vec3> = (0..600).map(|_| Vec3::new(rnd(), rnd(), rnd()) * 4.0).collect();
        let grid = VertexGrid::of(&raw).unwrap();
        let positions: Vec<Vec3> = raw.iter().map(|&p| grid.snap(p)).collect();
        let tris: Vec<[u32; 3]> = (0..500u32)
            .map(|i| {
                let a = (i * 7) % 600;
                let near = |k: u32| {
                    let pa = positions[a as usize];
                    (0..600u32)
                        .filter(|&j| j != a && (positions[j as usize] - pa).length() < 0.6)
                        .nth(k as usize)
                        .unwrap_or((a + k + 1) % 600)
                };
                [a, near(i % 3), near(3 + i % 4)]
            })
            .collect();
        let corners = |t: [u32; 3]| t.map(|v| positions[v as usize]);
        let boxes: Vec<Aabb> = tris
            .iter()
            .map(|&t| {
                let [a, b, c] = corners(t);
                crate::geometry::aabb(a.min(b).min(c), a.max(b).max(c))
            })
            .collect();
        for leaf in [1, 4, 8] {
            let mut bvh2 = crate::geometry::bvh2::build(
                &boxes,
                BvhBuildParams { max_prims_per_leaf: leaf, ..BvhBuildParams::fast_build() },
            );
            let order = bvh2.primitive_indices.clone();
            for (i, p) in bvh2.primitive_indices.iter_mut().enumerate() {
                *p = i as u32;
            }
            let leaf_tris: Vec<[u32; 3]> = order.iter().map(|&i| tris[i as usize]).collect();
            let leaf_boxes: Vec<Aabb> = order.iter().map(|&i| boxes[i as usize]).collect();
            let full = WideBvh::from_bvh2(&bvh2, &leaf_boxes, |i| corners(leaf_tris[i as usize]));
            let compact =
                CompactBvh::from_wide(&full, leaf_tris.clone(), &positions, grid).expect("representable");
            assert_eq!(compact.nodes.len(), full.nodes.len());
            assert!(compact.node_bytes() * 8 <= full.nodes.len() * size_of::<WideNode>() * 3);
            let mut stats = (RayStats::default(), RayStats::default());
            for _ in 0..400 {
                let origin = Vec3::new(rnd(), rnd(), rnd()) * 8.0 - 2.0;
                let dir = (Vec3::splat(2.0) + Vec3::new(rnd(), rnd(), rnd()) - origin).normalize();
                let t_max = 3.0 + 5.0 * rnd();
                let s = ShearedRay::new(origin, dir);
                let brute = leaf_tris
                    .iter()
                    .filter_map(|&t| {
                        let [a, b, c] = corners(t);
                        s.intersect(a, b, c, 0.0, t_max).map(|h| h.t)
                    })
                    .min_by(f32::total_cmp);
                let f = closest_walk(Portable, &full, origin, dir, 0.0, t_max, &mut stats.0);
                let c = closest_walk(Portable, &compact, origin, dir, 0.0, t_max, &mut stats.1);
                assert_eq!(c.map(|h| h.t), brute);
                assert_eq!(c.map(|h| (h.t, h.corners)), f.map(|h| (h.t, h.corners)));
                if let Some(h) = c {
                    assert_eq!(
                        compact.triangles[h.triangle as usize],
                        leaf_tris[f.unwrap().triangle as usize]
                    );
                }
                let auto = crate::geometry::mesh::wide_bvh::closest_hit_of(
                    &compact,
                    origin,
                    dir,
                    0.0,
                    t_max,
                    &mut RayStats::default(),
                );
                assert_eq!(auto, c);
                assert_eq!(
                    any_walk(Portable, &compact, origin, dir, 0.0, t_max, &mut stats.1),
                    brute.is_some()
                );
                assert_eq!(
                    crate::geometry::mesh::wide_bvh::any_hit_of(
                        &compact,
                        origin,
                        dir,
                        0.0,
                        t_max,
                        &mut RayStats::default()
                    ),
                    brute.is_some()
                );
                let p = origin.as_dvec3();
                let d = |i: u32| {
                    corners(leaf_tris[i as usize])
                        .iter()
                        .map(|v| (v.as_dvec3() - p).length())
                        .fold(f64::MAX, f64::min)
                };
                let dc = |i: u32| {
                    compact
                        .corners(i as usize)
                        .iter()
                        .map(|v| (v.as_dvec3() - p).length())
                        .fold(f64::MAX, f64::min)
                };
                assert_eq!(compact.nearest(p, dc), full.nearest(p, d));
            }
            // The compact boxes are at least as large: as many nodes or more per ray.
            assert!(stats.1.bvh_nodes >= stats.0.bvh_nodes && stats.0.bvh_nodes > 0);
        }
    }

    /// Infinite and NaN boxes cannot be quantised.
    #[test]
    fn non_finite_boxes_are_refused() {
        let mut boxes = [None; WIDTH];
        boxes[0] = Some((Vec3::ZERO, Vec3::INFINITY));
        assert!(CompactNode::quantise(&boxes, [0; WIDTH]).is_none());
        boxes[0] = Some((Vec3::splat(f32::NAN), Vec3::ONE));
        assert!(CompactNode::quantise(&boxes, [0; WIDTH]).is_none());
        assert!(VertexGrid::of(&[Vec3::ZERO, Vec3::splat(f32::INFINITY)]).is_none());
    }
}
