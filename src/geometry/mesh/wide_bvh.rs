//! The per-mesh 8-wide BVH: an obvhs `Bvh2` collapsed (grouped by a surface area heuristic
//! dynamic programme, [`WideBvh::from_bvh2`]) into nodes of eight children whose
//! boxes are stored as structure-of-arrays (so one ray tests all eight at once, [`BoxRay`],
//! in the eight lanes of a [`Simd`] backend: one AVX2 instruction per step where
//! [`crate::simd::dispatch`] picks AVX2), with leaves of up to eight triangles
//! pre-gathered into one or two [`Tri4`] packets (tested together in one eight-lane test,
//! [`ShearedRay::intersect8`]). Owns the closest-hit, any-hit and nearest-point walks over
//! it and their work counting. The scene's top-level BVH over objects stays in
//! [`crate::geometry::bvh2`].

use std::mem::MaybeUninit;

use glam::{DVec3, Vec3};
use obvhs::bvh2::Bvh2;

use crate::geometry::bvh2;
use crate::geometry::mesh::triangle::{ShearedRay, Tri4};
use crate::geometry::{Aabb, RayStats, box_distance};
use crate::simd::{Kernel, Lane, Lane8, Mask8, Simd, WalkStack, at_byte_offset, dispatch};

/// Children per node. Eight rather than four (benches/primary_rays.rs, armadillo) cuts the
/// nodes a primary ray visits from 3.4 to 2.5 and the depth from 11 to 7, and raised
/// throughput from 0.63 to 0.72 of Embree's together with the AVX2 test (which alone was
/// worth 8% over the portable one of two SSE halves).
pub const WIDTH: usize = 8;
/// Triangles per leaf packet.
pub const LEAF_MAX: usize = 4;
/// Packets per leaf at most: a leaf of up to `LEAF_MAX * LEAF_PACKETS` triangles is that
/// many consecutive packets. Two, because the AVX2 walks test two packets in one
/// eight-lane test for about the cost of one: with leaves of up to eight triangles the
/// armadillo's hit rays visit 7.7 nodes instead of 8.4 and its BVH shrinks from 6.19 to
/// 5.20 MB (benches/primary_rays.rs).
pub const LEAF_PACKETS: usize = 2;
/// Marks a child reference as a leaf: `LEAF | first_packet << LEAF_SHIFT | (triangles - 1)`.
pub(crate) const LEAF: u32 = 1 << 31;
/// Bits of a leaf reference that hold its triangle count less one.
pub(crate) const LEAF_SHIFT: u32 = 5;
const _: () = assert!(LEAF_MAX * LEAF_PACKETS <= 1 << LEAF_SHIFT);
// Node references are byte offsets, and `WideBvh::node` checks them as such.
const _: () = assert!(size_of::<WideNode>() == 256);
/// Cost of a leaf test (one or two packets, one eight-lane test) relative to a node test
/// in the surface area heuristic that groups the BVH2 into wide nodes
/// ([`WideBvh::from_bvh2`]). It decides which subtrees of at most eight triangles become
/// one leaf; 1, 1.5 and 2.5 built nearly the same tree for the armadillo (7.70 to 7.72
/// nodes per hit ray) and traced it equally fast.
const PACKET_COST: f32 = 1.5;
/// Child reference of an unused slot (its box is NaN, so it is never entered).
pub(crate) const NONE: u32 = u32::MAX;
/// Traversal stack entries kept on the call stack (enough for a BVH 36 levels deep); a
/// deeper BVH walks with a heap stack.
const STACK: usize = 255;

/// An inner node: eight child boxes and references (224 bytes, aligned to a 64-byte cache
/// line).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct WideNode {
    /// Child boxes, scene units: `bounds[0..3][lane]` are the minimum x, y, z and
    /// `bounds[3..6][lane]` the maximum; unused lanes are NaN (no ray enters them).
    pub bounds: [[f32; WIDTH]; 6],
    /// Per lane: a node's byte offset in [`WideBvh::nodes`] (its index times the 256
    /// bytes of a node, so that a walk reaches it with one add and no shift), or
    /// `LEAF | first << LEAF_SHIFT | (count - 1)` for a leaf of `count` triangles in the
    /// packets from [`WideBvh::packets`]`[first]` on, or `u32::MAX`.
    pub children: [u32; WIDTH],
}

/// Up to four triangles' corners and their indices; a leaf is one or two consecutive
/// packets.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub struct Packet {
    /// Corners, `tri[vertex][axis][lane]`, scene units (local frame); unused lanes NaN.
    pub tri: Tri4,
    /// Per lane, the triangle's index in the mesh's triangle list (`u32::MAX` if unused).
    pub ids: [u32; LEAF_MAX],
}

/// The closest hit of a walk: the triangle, `t`, and its corners (read from the leaf
/// packet, already in cache, rather than through the mesh's index and vertex lists).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafHit {
    /// Index of the triangle in the mesh's triangle list.
    pub triangle: u32,
    /// Ray parameter of the hit.
    pub t: f32,
    /// The triangle's corners, scene units (local frame).
    pub corners: [Vec3; 3],
}

/// An 8-wide BVH over triangles. Node 0 is the root (absent for an empty mesh).
#[derive(Clone, Debug, Default)]
pub struct WideBvh {
    /// Inner nodes; node 0 is the root.
    pub nodes: Vec<WideNode>,
    /// Leaf packets.
    pub packets: Vec<Packet>,
    /// Deepest node level (root = 1), which bounds the traversal stack.
    pub depth: usize,
}

/// The safe reciprocal of the direction, per axis (finite and nonzero, with the
/// direction's sign), so that no slab distance is NaN for a nonempty box.
#[inline(always)]
pub(crate) fn safe_inverse(dir: Vec3) -> [f32; 3] {
    [obvhs::ray::safe_inverse(dir.x), obvhs::ray::safe_inverse(dir.y), obvhs::ray::safe_inverse(dir.z)]
}

/// A ray prepared for the eight-box test of a [`WideNode`] in the lanes of backend `S`.
///
/// Both rows of an axis sit at fixed offsets and are ordered by `min` and `max`, which
/// keep an empty lane's NaN, rather than rows chosen by the direction's signs: no row
/// index to keep per ray. Below the root a slab distance is one fused
/// `bound * inv - offset` ([`Lane8::mul_sub`]: one FMA on AVX2, the same bits computed
/// exactly on the portable backend), with `offset` the product `origin * inv` rounded
/// away from the box: its rounding error (up to half an ulp of the product, an absolute
/// error that grows with the origin's distance from the mesh's frame, unlike the relative
/// error of `(bound - origin) * inv`) is bounded by twice `f32::EPSILON` of it and added
/// to the entry offset and taken from the exit one, so the fused test shrinks no box
/// beyond the rounding of its own result (which the unfused test has too) and grows one
/// by about an ulp of the origin at most (without it, `tests/integration/mesh_tracing.rs`
/// finds rays through a mesh far from the origin that miss their nearest triangle; the
/// portable backend's unfused test missed them until it took the fused one too). A fused
/// product is one operation of latency instead of two on each node of a hit ray's
/// chain. The root, tested while `offset` is still being computed at the ray's start,
/// uses `(bound - origin) * inv` (a fused root made rays that miss slower; the root's box
/// holds every triangle well inside).
#[derive(Clone, Copy, Debug)]
pub(crate) struct BoxRay<S: Simd> {
    s: S,
    origin: [S::F32x8; 3],
    inv: [S::F32x8; 3],
    /// Per bound row (minimum x, y, z, then maximum x, y, z): `origin * inv` of its axis,
    /// raised where the row is the entry slab (the minimum for a nonnegative `inv`) and
    /// lowered where it is the exit slab.
    offset: [S::F32x8; 6],
}

impl<S: Simd> BoxRay<S> {
    /// Prepares the ray `origin + t * dir`.
    #[inline(always)]
    fn new(s: S, origin: Vec3, dir: Vec3) -> Self {
        let inv = safe_inverse(dir);
        let o = origin.to_array();
        // `p + e` and `p - e` with `e >= 2 ulp(p)` bracket the exact product (the rounded
        // `p` is within half an ulp of it); `copysign` picks the entry row without a branch.
        // (Loops rather than closures, which the compiler may leave out of line, where they
        // would not be compiled for the backend's instructions.)
        let mut offset = [s.splat8(0.0); 6];
        for (row, x) in offset.iter_mut().enumerate() {
            let a = row % 3;
            let p = o[a] * inv[a];
            let e = (p.abs() * (2.0 * f32::EPSILON)).copysign(inv[a]);
            *x = s.splat8(if row < 3 { p + e } else { p - e });
        }
        BoxRay {
            s,
            origin: [s.splat8(o[0]), s.splat8(o[1]), s.splat8(o[2])],
            inv: [s.splat8(inv[0]), s.splat8(inv[1]), s.splat8(inv[2])],
            offset,
        }
    }

    /// The lanes whose child box the ray enters within `[t_min, t_max]` (bit `l` for lane
    /// `l`) and the [`order_key`]s of the entry distances; `ROOT` for the root, the first
    /// node of every walk (see the type's documentation).
    #[inline(always)]
    fn hit<const ROOT: bool>(&self, n: &WideNode, t_min: f32, t_max: f32) -> (u32, [u32; WIDTH]) {
        let b = &n.bounds;
        let s = self.s;
        let rows =
            [s.load8(&b[0]), s.load8(&b[1]), s.load8(&b[2]), s.load8(&b[3]), s.load8(&b[4]), s.load8(&b[5])];
        self.hit_rows::<ROOT>(rows, t_min, t_max)
    }

    /// [`BoxRay::hit`] on the eight boxes whose bound rows (minimum x, y, z, then maximum
    /// x, y, z) are `rows`: the full layout's rows as stored, the compact layout's
    /// dequantised ([`super::compact`]).
    #[inline(always)]
    pub(crate) fn hit_rows<const ROOT: bool>(
        &self,
        rows: [S::F32x8; 6],
        t_min: f32,
        t_max: f32,
    ) -> (u32, [u32; WIDTH]) {
        let fused = !ROOT;
        let (x0, x1) = (self.slab(fused, rows[0], 0), self.slab(fused, rows[3], 3));
        let (y0, y1) = (self.slab(fused, rows[1], 1), self.slab(fused, rows[4], 4));
        let (z0, z1) = (self.slab(fused, rows[2], 2), self.slab(fused, rows[5], 5));
        // Per axis, the entry and exit distances of the slab. `min` and `max` return their
        // second operand where either is NaN, so the NaN of an empty lane carries through
        // every step below and fails the final comparison.
        let near = x0.vmin(x1).vmax(y0.vmin(y1)).vmax(self.s.splat8(t_min).vmax(z0.vmin(z1)));
        let far = x0.vmax(x1).vmin(y0.vmax(y1)).vmin(self.s.splat8(t_max).vmin(z0.vmax(z1)));
        (near.mask_le(far).bits(), near.order_keys())
    }

    /// The slab distances of bound row `row` (values `bound`): fused below the root, else
    /// `(bound - origin) * inv`.
    #[inline(always)]
    fn slab(&self, fused: bool, bound: S::F32x8, row: usize) -> S::F32x8 {
        let a = row % 3;
        if fused {
            bound.mul_sub(self.inv[a], self.offset[row])
        } else {
            (bound - self.origin[a]) * self.inv[a]
        }
    }

    /// The backend token.
    #[inline(always)]
    pub(crate) fn simd(&self) -> S {
        self.s
    }
}

/// Tests the triangles of one leaf (its one or two packets) with `sheared` on backend `s`:
/// per lane (`LEAF_MAX * k + l` for lane `l` of packet `k`) the hit's `t`, and the mask of
/// lanes hit within `[t_min, t_max]`. Two packets go through one eight-lane test. The leaf
/// test of the one-ray walks and of the packet walks ([`super::packet`]).
#[inline(always)]
pub(crate) fn leaf_test<S: Simd>(
    s: S,
    sheared: &ShearedRay,
    packets: &[Packet],
    t_min: f32,
    t_max: f32,
) -> ([f32; 8], u32) {
    const { assert!(LEAF_PACKETS == 2) };
    match packets {
        [a, b] => sheared.intersect8(s, &a.tri, &b.tri, t_min, t_max),
        _ => {
            let (t4, mask) = sheared.intersect4(s, &packets[0].tri, t_min, t_max);
            let mut t = [0.0; 8];
            t[..LEAF_MAX].copy_from_slice(&t4);
            (t, mask)
        }
    }
}

impl WideBvh {
    /// Collapses `bvh`, built over the boxes `boxes` of the triangles `corners(i)`, with
    /// its primitive indices already in leaf order (`primitive_indices[i] == i`). Which BVH2
    /// subtrees become the up to eight children of each wide node, and which (of at most
    /// `LEAF_MAX * LEAF_PACKETS` triangles) one leaf of one or two packets, is chosen by the
    /// surface area heuristic: a dynamic programme over the BVH2 (after Ylitie, Karras and
    /// Laine 2017, with the costs of our node and leaf tests, [`PACKET_COST`]). BVH2 leaves
    /// with more triangles become a node over several leaves.
    pub fn from_bvh2(bvh: &Bvh2, boxes: &[Aabb], corners: impl Fn(u32) -> [Vec3; 3]) -> Self {
        let mut w = WideBvh::default();
        if bvh.nodes.is_empty() {
            return w;
        }
        w.nodes.push(empty_node());
        w.depth = 1;
        let root = &bvh.nodes[0];
        if root.is_leaf() {
            let prims: Vec<u32> = bvh.primitive_indices.clone();
            let reference = w.leaf(boxes, &corners, &prims, 2);
            set_lane(&mut w.nodes[0], 0, root.aabb(), reference);
        } else {
            let plan = SahPlan::new(bvh, PACKET_COST);
            w.fill(bvh, &plan, boxes, &corners, 0, 0, 1);
        }
        w.nodes.shrink_to_fit();
        w.packets.shrink_to_fit();
        w
    }

    /// Fills wide node `at` (already pushed) with the children `plan` gives the inner BVH2
    /// node `node`, and their subtrees, depth first and in lane order (the order a
    /// recursion would take), with a stack on the heap: a BVH2 may be as deep as it has
    /// triangles.
    #[allow(clippy::too_many_arguments)]
    fn fill(
        &mut self,
        bvh: &Bvh2,
        plan: &SahPlan,
        boxes: &[Aabb],
        corners: &impl Fn(u32) -> [Vec3; 3],
        at: usize,
        node: usize,
        depth: usize,
    ) {
        /// A wide node being filled: its index, its children, the next lane, its level.
        struct Frame {
            at: usize,
            kids: Vec<(usize, bool)>,
            lane: usize,
            depth: usize,
        }
        let frame = |at: usize, node: usize, depth: usize| {
            let mut kids = Vec::with_capacity(WIDTH);
            plan.wide_children(bvh, node, &mut kids);
            Frame { at, kids, lane: 0, depth }
        };
        let mut stack = vec![frame(at, node, depth)];
        let mut prims = Vec::new();
        while let Some(f) = stack.last_mut() {
            let Some(&(c, packet)) = f.kids.get(f.lane) else {
                stack.pop();
                continue;
            };
            let (at, lane, depth) = (f.at, f.lane, f.depth);
            f.lane += 1;
            self.depth = self.depth.max(depth);
            let b = *bvh.nodes[c].aabb();
            if packet {
                prims.clear();
                bvh2::subtree_primitives(bvh, c, &mut prims);
                let reference = self.leaf(boxes, corners, &prims, depth + 1);
                set_lane(&mut self.nodes[at], lane, &b, reference);
            } else {
                let index = self.nodes.len();
                self.nodes.push(empty_node());
                set_lane(&mut self.nodes[at], lane, &b, node_ref(index));
                stack.push(frame(index, c, depth + 1));
            }
        }
    }

    /// A child reference for the triangles `prims`: a leaf of one or two packets, or (more
    /// than `LEAF_MAX * LEAF_PACKETS`) a node over up to eight groups of them, recursively.
    fn leaf(
        &mut self,
        boxes: &[Aabb],
        corners: &impl Fn(u32) -> [Vec3; 3],
        prims: &[u32],
        depth: usize,
    ) -> u32 {
        if prims.len() <= LEAF_MAX * LEAF_PACKETS {
            let first = self.packets.len() as u32;
            assert!(first < LEAF >> LEAF_SHIFT, "more than {} leaf packets", LEAF >> LEAF_SHIFT);
            for chunk in prims.chunks(LEAF_MAX) {
                let mut p = Packet { tri: [[[f32::NAN; LEAF_MAX]; 3]; 3], ids: [u32::MAX; LEAF_MAX] };
                for (lane, &i) in chunk.iter().enumerate() {
                    for (v, c) in corners(i).into_iter().enumerate() {
                        for a in 0..3 {
                            p.tri[v][a][lane] = c[a];
                        }
                    }
                    p.ids[lane] = i;
                }
                self.packets.push(p);
            }
            return LEAF | (first << LEAF_SHIFT) | (prims.len() as u32 - 1);
        }
        self.depth = self.depth.max(depth);
        let index = self.nodes.len();
        self.nodes.push(empty_node());
        let group = prims.len().div_ceil(WIDTH).max(LEAF_MAX * LEAF_PACKETS);
        for (lane, chunk) in prims.chunks(group).enumerate() {
            let b = chunk.iter().map(|&i| boxes[i as usize]).reduce(|a, b| a.union(&b)).expect("nonempty");
            let r = self.leaf(boxes, corners, chunk, depth + 1);
            set_lane(&mut self.nodes[index], lane, &b, r);
        }
        node_ref(index)
    }

    /// Bytes held: the struct, nodes and packets.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.nodes.capacity() * std::mem::size_of::<WideNode>()
            + self.packets.capacity() * std::mem::size_of::<Packet>()
    }

    /// The closest triangle hit by the ray `origin + t * dir` with `t` in `[t_min, t_max]`:
    /// its index and `t`. Counts inner nodes visited (each an eight-box test) in
    /// `stats.bvh_nodes` and triangles tested in `stats.prim_tests`. Runs on the backend of
    /// this process ([`dispatch`]); [`closest_walk`] runs on a given one.
    #[inline]
    pub fn closest_hit(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        t_max: f32,
        stats: &mut RayStats,
    ) -> Option<LeafHit> {
        closest_hit_of(self, origin, dir, t_min, t_max, stats)
    }

    /// Whether any triangle is hit with `t` in `[t_min, t_max]`; stops at the first
    /// (shadow rays). Counts work as [`WideBvh::closest_hit`] does.
    #[inline]
    pub fn any_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        any_hit_of(self, origin, dir, t_min, t_max, stats)
    }

    /// The node of inner-node reference `r` (its byte offset in [`WideBvh::nodes`]): one
    /// add where indexing would shift first, a step of latency less on each node of a
    /// walk (measured: 1.3% more primary rays per second on the bunny; indexing by
    /// `r >> 8` compiled to a shift, a mask and a shift back on the chain, 3% slower).
    #[inline(always)]
    pub(crate) fn node(&self, r: u32) -> &WideNode {
        at_byte_offset(&self.nodes, r)
    }

    /// The packets of the leaf whose first packet and triangle count are `range` (from
    /// [`leaf_range`]).
    #[inline(always)]
    pub(crate) fn leaf_packets(&self, (first, count): (usize, usize)) -> &[Packet] {
        &self.packets[first..first + count.div_ceil(LEAF_MAX)]
    }

    /// The hit at `t` on the triangle in lane `lane` of leaf packet `packet`: its index and
    /// its corners, read from the packet.
    #[inline(always)]
    pub(crate) fn leaf_hit(&self, (packet, lane): (usize, usize), t: f32) -> LeafHit {
        let p = &self.packets[packet];
        let corner = |v: usize| Vec3::new(p.tri[v][0][lane], p.tri[v][1][lane], p.tri[v][2][lane]);
        LeafHit { triangle: p.ids[lane], t, corners: [corner(0), corner(1), corner(2)] }
    }

    /// The smallest `dist(triangle)` over the triangles for a query at `p`, visiting
    /// nodes nearest first and skipping those whose boxes are farther than the best so far
    /// (`f64::INFINITY` if empty). For measurement, not for tracing: it allocates.
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
                for p in self.leaf_packets(leaf_range(cur)) {
                    for &i in p.ids.iter().filter(|&&i| i != u32::MAX) {
                        best = best.min(dist(i));
                    }
                }
                continue;
            }
            let n = self.node(cur);
            let mut kids: Vec<(u32, f64)> = (0..WIDTH)
                .filter(|&l| n.children[l] != NONE)
                .map(|l| {
                    let b = Aabb::new(
                        Vec3::new(n.bounds[0][l], n.bounds[1][l], n.bounds[2][l]).into(),
                        Vec3::new(n.bounds[3][l], n.bounds[4][l], n.bounds[5][l]).into(),
                    );
                    (n.children[l], box_distance(&b, p))
                })
                .collect();
            // Nearest popped first.
            kids.sort_by(|a, b| b.1.total_cmp(&a.1));
            stack.extend(kids);
        }
        best
    }
}

/// A layout of the 8-wide BVH: what the one-ray walks ([`closest_walk`], [`any_walk`])
/// need of it, so that the same walk code runs on the full layout ([`WideBvh`]) and the
/// compact one ([`super::compact::CompactBvh`]). The walks are generic over it and
/// monomorphised (every method `#[inline(always)]`, no `dyn`): the full layout's walks
/// compile to what they were before the compact one existed.
///
/// Child references are shared: `LEAF | first << LEAF_SHIFT | (count - 1)` for a leaf of
/// `count` triangles ([`leaf_range`]; `first` is a packet index in the full layout, a
/// triangle index in the compact one), an opaque node reference otherwise, [`NONE`] for an
/// unused lane.
pub(crate) trait WideLayout {
    /// An inner node.
    type Node;
    /// Whether there is no node (an empty mesh).
    fn is_empty(&self) -> bool;
    /// Deepest node level (root = 1), which bounds the traversal stack.
    fn depth(&self) -> usize;
    /// The root node.
    fn root(&self) -> &Self::Node;
    /// The node of inner-node reference `r`.
    fn node(&self, r: u32) -> &Self::Node;
    /// The child references of `n`, lane by lane.
    fn children(n: &Self::Node) -> &[u32; WIDTH];
    /// The lanes of `n` whose child box the ray `br` enters within `[t_min, t_max]` and
    /// the [`order_key`]s of the entry distances, as [`BoxRay::hit`].
    fn test_node<S: Simd, const ROOT: bool>(
        br: &BoxRay<S>,
        n: &Self::Node,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [u32; WIDTH]);
    /// The triangle test of the leaf `leaf` (from [`leaf_range`]) with `sheared`: per lane
    /// the hit's `t`, and the mask of lanes hit within `[t_min, t_max]`.
    fn leaf_test<S: Simd>(
        &self,
        s: S,
        sheared: &ShearedRay,
        leaf: (usize, usize),
        t_min: f32,
        t_max: f32,
    ) -> ([f32; 8], u32);
    /// Where lane `lane` of leaf `leaf`'s test lies, as a pair ordered as the leaf order
    /// (the tie rule [`tie_wins`] compares them).
    fn leaf_at(leaf: (usize, usize), lane: usize) -> (usize, usize);
    /// The hit at `t` on the triangle at `at` (from [`WideLayout::leaf_at`]).
    fn leaf_hit(&self, at: (usize, usize), t: f32) -> LeafHit;
}

impl WideLayout for WideBvh {
    type Node = WideNode;
    #[inline(always)]
    fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
    #[inline(always)]
    fn depth(&self) -> usize {
        self.depth
    }
    #[inline(always)]
    fn root(&self) -> &WideNode {
        &self.nodes[0]
    }
    #[inline(always)]
    fn node(&self, r: u32) -> &WideNode {
        WideBvh::node(self, r)
    }
    #[inline(always)]
    fn children(n: &WideNode) -> &[u32; WIDTH] {
        &n.children
    }
    #[inline(always)]
    fn test_node<S: Simd, const ROOT: bool>(
        br: &BoxRay<S>,
        n: &WideNode,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [u32; WIDTH]) {
        br.hit::<ROOT>(n, t_min, t_max)
    }
    #[inline(always)]
    fn leaf_test<S: Simd>(
        &self,
        s: S,
        sheared: &ShearedRay,
        leaf: (usize, usize),
        t_min: f32,
        t_max: f32,
    ) -> ([f32; 8], u32) {
        leaf_test(s, sheared, self.leaf_packets(leaf), t_min, t_max)
    }
    #[inline(always)]
    fn leaf_at((first, _): (usize, usize), lane: usize) -> (usize, usize) {
        (first + lane / LEAF_MAX, lane % LEAF_MAX)
    }
    #[inline(always)]
    fn leaf_hit(&self, at: (usize, usize), t: f32) -> LeafHit {
        WideBvh::leaf_hit(self, at, t)
    }
}

/// A traversal stack entry: the order key ([`order_key`]) of the distance at which the ray
/// enters the child in the high 32 bits, its child reference in the low ones. Comparing
/// entries as integers compares their distances, so sorting children is a few
/// branch-free compare-exchanges of one register each.
type Entry = u64;

/// The bits of `x` mapped so that unsigned integer order is the order of the floats
/// (negative floats have their bits flipped, others their sign bit set).
#[inline(always)]
pub(crate) fn order_key(x: f32) -> u32 {
    let b = x.to_bits();
    b ^ ((((b as i32) >> 31) as u32) | 0x8000_0000)
}

/// The first packet of the leaf reference `cur` and its number of triangles (its packets
/// are the next `count.div_ceil(LEAF_MAX)`).
#[inline(always)]
pub(crate) fn leaf_range(cur: u32) -> (usize, usize) {
    (((cur & !LEAF) >> LEAF_SHIFT) as usize, ((cur & ((1 << LEAF_SHIFT) - 1)) + 1) as usize)
}

/// A stack entry for child reference `child` entered at distance key `key`.
#[inline(always)]
fn entry(key: u32, child: u32) -> Entry {
    (u64::from(key) << 32) | u64::from(child)
}

/// The lowest lane set in `mask` (nonzero), cleared from it. The lane is masked below
/// [`WIDTH`], which it is, so that indexing with it needs no bounds check.
#[inline(always)]
fn next_lane(mask: &mut u32) -> usize {
    let l = mask.trailing_zeros() as usize & (WIDTH - 1);
    *mask &= *mask - 1;
    l
}

/// Whether a hit at `t` on the triangle at `at` (packet, lane) replaces the closest so
/// far, `best` at `t_max` (or none, within `t_max`): when it is nearer, or as near and
/// later in leaf order (or the first). The rule does not depend on the order in which a
/// walk reaches leaves, so the one-ray walk and the packet walk
/// ([`super::packet`]), which reach them in different orders, report the same triangle
/// where several are hit at exactly the same distance (a ray through a shared edge).
#[inline(always)]
pub(crate) fn tie_wins(t: f32, t_max: f32, at: (usize, usize), best: Option<(usize, usize)>) -> bool {
    t < t_max || (t == t_max && best.is_none_or(|b| at > b))
}

/// The two entries in order.
#[inline(always)]
fn ordered(a: Entry, b: Entry) -> (Entry, Entry) {
    (a.min(b), a.max(b))
}

/// Stack entries a walk over `bvh` needs at most: each level of the current path holds at
/// most `WIDTH - 1` pending children, and [`visit_node`] may write two slots past the
/// entries it keeps.
pub(crate) fn stack_needed(bvh: &impl WideLayout) -> usize {
    bvh.depth() * (WIDTH - 1) + 1 + 2
}

/// Evaluates `$walk` with `$stack` bound to a traversal stack ([`WalkStack`], not zeroed)
/// for `$bvh`: on the call stack where [`STACK`] entries suffice, else (a pathological
/// BVH) on the heap. A macro rather than a function taking a closure, which the compiler
/// could leave out of line, where it would not be compiled for the walk's backend.
macro_rules! with_stack {
    ($bvh:expr, $stack:ident => $walk:expr) => {
        if stack_needed($bvh) <= STACK {
            let mut slots = [const { MaybeUninit::<Entry>::uninit() }; STACK];
            let $stack = &mut WalkStack::new(&mut slots);
            $walk
        } else {
            let mut slots = vec![MaybeUninit::<Entry>::uninit(); stack_needed($bvh)];
            let $stack = &mut WalkStack::new(&mut slots);
            $walk
        }
    };
}

/// [`WideBvh::closest_hit`] on any layout.
#[inline(always)]
pub(crate) fn closest_hit_of<L: WideLayout>(
    bvh: &L,
    origin: Vec3,
    dir: Vec3,
    t_min: f32,
    t_max: f32,
    stats: &mut RayStats,
) -> Option<LeafHit> {
    dispatch(Walk::<L, false> { bvh, origin, dir, t_min, t_max, stats })
}

/// [`WideBvh::any_hit`] on any layout.
#[inline(always)]
pub(crate) fn any_hit_of<L: WideLayout>(
    bvh: &L,
    origin: Vec3,
    dir: Vec3,
    t_min: f32,
    t_max: f32,
    stats: &mut RayStats,
) -> bool {
    dispatch(Walk::<L, true> { bvh, origin, dir, t_min, t_max, stats })
}

/// A walk of [`WideBvh::closest_hit`] (`ANY` false) or [`WideBvh::any_hit`] (`ANY` true)
/// on layout `L` as a [`Kernel`]: the ray and the work counters.
struct Walk<'a, L, const ANY: bool> {
    bvh: &'a L,
    origin: Vec3,
    dir: Vec3,
    t_min: f32,
    t_max: f32,
    stats: &'a mut RayStats,
}

impl<L: WideLayout> Kernel for Walk<'_, L, false> {
    type Output = Option<LeafHit>;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> Option<LeafHit> {
        closest_walk(s, self.bvh, self.origin, self.dir, self.t_min, self.t_max, self.stats)
    }
}

impl<L: WideLayout> Kernel for Walk<'_, L, true> {
    type Output = bool;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> bool {
        any_walk(s, self.bvh, self.origin, self.dir, self.t_min, self.t_max, self.stats)
    }
}

/// [`WideBvh::closest_hit`] on backend `s`: the root's test, then (for a ray that enters
/// it) the walk on a stack from [`with_stack`], set up only then. Inlined into its
/// callers, so that inside a kernel run by [`dispatch`] all of it is compiled for the
/// backend.
#[inline(always)]
pub(crate) fn closest_walk<S: Simd, L: WideLayout>(
    s: S,
    bvh: &L,
    origin: Vec3,
    dir: Vec3,
    t_min: f32,
    t_max: f32,
    stats: &mut RayStats,
) -> Option<LeafHit> {
    if bvh.is_empty() {
        return None;
    }
    let br = BoxRay::new(s, origin, dir);
    // The root, before the stack: most rays that miss end here.
    let (mask, d) = L::test_node::<S, true>(&br, bvh.root(), t_min, t_max);
    if mask == 0 {
        stats.bvh_nodes += 1;
        return None;
    }
    with_stack!(bvh, stack => closest_walk_in(&br, bvh, stack, (mask, d), origin, dir, t_min, t_max, stats))
}

/// Tests the children of node `n` and pushes every hit one but the nearest onto `stack`
/// farthest deepest, with its entry distance; returns the nearest, or
/// [`NONE`] where the ray enters none. Two children are ordered by one compare-exchange of
/// their entries, three or four by a network of four, more by insertion.
#[inline(always)]
fn visit_node<S: Simd, L: WideLayout>(
    br: &BoxRay<S>,
    n: &L::Node,
    t_min: f32,
    t_max: f32,
    stack: &mut WalkStack,
) -> u32 {
    let (mask, d) = L::test_node::<S, false>(br, n, t_min, t_max);
    push_children(L::children(n), mask, d, stack)
}

/// [`visit_node`] after the box test: the children `children` in `mask`, entered at the
/// distances whose keys are `d`.
#[inline(always)]
fn push_children(children: &[u32; WIDTH], mut mask: u32, d: [u32; WIDTH], stack: &mut WalkStack) -> u32 {
    if mask == 0 {
        return NONE;
    }
    let l0 = next_lane(&mut mask);
    if mask == 0 {
        return children[l0];
    }
    let key = |l: usize| entry(d[l], children[l]);
    let (a, b) = ordered(key(l0), key(next_lane(&mut mask)));
    if mask == 0 {
        // Two children, the commonest case after one: no network.
        stack.push(b);
        return a as u32;
    }
    // Three or four children without a branch on which (it varies from node to node and
    // would be mispredicted): an absent fourth gets the largest key, which sorts last,
    // four compare-exchanges finish sorting all four (`a` and `b` are in order), and the
    // pushes write three slots whatever the number, of which the stack keeps the present
    // ones.
    let k2 = key(next_lane(&mut mask));
    let present3 = mask != 0;
    let k3 = if present3 { key(next_lane(&mut mask)) } else { Entry::MAX };
    let (c, d4) = ordered(k2, k3);
    let (a, c) = ordered(a, c);
    let (b, d4) = ordered(b, d4);
    let (b, c) = ordered(b, c);
    if mask == 0 {
        // Two or three entries, farthest deepest: [c, b] or [d4, c, b].
        let (first, second) = if present3 { (d4, c) } else { (c, b) };
        stack.push_2_or_3([first, second, b], present3);
        return a as u32;
    }
    let mut push = |e: Entry| {
        stack.push(e);
    };
    // Five to eight (rare): insertion sort of all, then push all but the nearest.
    let mut sorted = [a, b, c, d4, 0, 0, 0, 0];
    let mut k = 4;
    while mask != 0 {
        let x = key(next_lane(&mut mask));
        let mut j = k;
        while j > 0 && sorted[j - 1] > x {
            sorted[j] = sorted[j - 1];
            j -= 1;
        }
        sorted[j] = x;
        k += 1;
    }
    for &e in sorted[1..k].iter().rev() {
        push(e);
    }
    sorted[0] as u32
}

/// [`closest_walk`] on `stack` (at least [`stack_needed`] entries) from the root, whose
/// box test gave `root`. Two loops: the first descends to the first leaf the ray reaches,
/// with no triangle test yet, so that the most rays, which miss the mesh's triangles
/// without reaching a leaf, leave before the sheared ray is set up (one level below the
/// root); the second goes on from that leaf with it.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn closest_walk_in<S: Simd, L: WideLayout>(
    br: &BoxRay<S>,
    bvh: &L,
    stack: &mut WalkStack,
    root: (u32, [u32; WIDTH]),
    origin: Vec3,
    dir: Vec3,
    t_min: f32,
    mut t_max: f32,
    stats: &mut RayStats,
) -> Option<LeafHit> {
    let mut nodes = 1u64;
    let mut cur = push_children(L::children(bvh.root()), root.0, root.1, stack);
    // One step down (a macro: a closure would not inherit the walk's target feature):
    // the nearest child the ray enters, else the nearest pending one; where there is none
    // the ray misses.
    macro_rules! descend {
        () => {{
            nodes += 1;
            cur = visit_node::<S, L>(br, bvh.node(cur), t_min, t_max, stack);
            if cur == NONE {
                let Some(e) = stack.pop() else {
                    stats.bvh_nodes += nodes;
                    return None;
                };
                cur = e as u32;
            }
        }};
    }
    // Down to the first leaf. No hit yet, so every pushed child (entered within `t_max`)
    // is still in front. The sheared ray is set up one level below the root, where most
    // rays that miss have left, and pinned there with `black_box`: left to the compiler,
    // its setup (a division and a chain of selects) sinks to the first leaf, right onto
    // the critical path of every ray that hits (measured on the bunny: hit rays 157 ns
    // there, 151 ns pinned here; rays that miss 16.1 ns against 16.4).
    if cur & LEAF == 0 {
        descend!();
    }
    let sheared = std::hint::black_box(ShearedRay::new(origin, dir));
    while cur & LEAF == 0 {
        descend!();
    }
    let mut best = None;
    let mut tests = 0u64;
    // `order_key(t_max)`, to compare with the distance keys of stack entries.
    let mut t_max_key = order_key(t_max);
    'walk: loop {
        if cur & LEAF == 0 {
            nodes += 1;
            cur = visit_node::<S, L>(br, bvh.node(cur), t_min, t_max, stack);
            if cur != NONE {
                continue 'walk;
            }
        } else {
            let leaf = leaf_range(cur);
            tests += leaf.1 as u64;
            let (t, mut hits) = bvh.leaf_test(br.simd(), &sheared, leaf, t_min, t_max);
            if hits != 0 {
                // The nearest hit lane; among hits at the same distance, the last in leaf
                // order, in this leaf or any other ([`tie_wins`]).
                while hits != 0 {
                    let lane = hits.trailing_zeros() as usize & 7;
                    hits &= hits - 1;
                    let at = L::leaf_at(leaf, lane);
                    if tie_wins(t[lane], t_max, at, best) {
                        t_max = t[lane];
                        best = Some(at);
                    }
                }
                t_max_key = order_key(t_max);
            }
        }
        // Pop the nearest pending child still in front of the closest hit.
        loop {
            let Some(e) = stack.pop() else {
                break 'walk;
            };
            if (e >> 32) as u32 <= t_max_key {
                cur = e as u32;
                break;
            }
        }
    }
    stats.bvh_nodes += nodes;
    stats.prim_tests += tests;
    best.map(|at| bvh.leaf_hit(at, t_max))
}

/// [`WideBvh::any_hit`] on backend `s` with a stack from [`with_stack`].
#[inline(always)]
pub(crate) fn any_walk<S: Simd, L: WideLayout>(
    s: S,
    bvh: &L,
    origin: Vec3,
    dir: Vec3,
    t_min: f32,
    t_max: f32,
    stats: &mut RayStats,
) -> bool {
    with_stack!(bvh, stack => any_walk_in(s, bvh, stack, origin, dir, t_min, t_max, stats))
}

/// [`any_walk`] on `stack` (at least [`stack_needed`] entries).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn any_walk_in<S: Simd, L: WideLayout>(
    s: S,
    bvh: &L,
    stack: &mut WalkStack,
    origin: Vec3,
    dir: Vec3,
    t_min: f32,
    t_max: f32,
    stats: &mut RayStats,
) -> bool {
    if bvh.is_empty() {
        return false;
    }
    let br = BoxRay::new(s, origin, dir);
    // Set up at the start and pinned there, as in the closest walk (shadow rays start on
    // a surface inside the mesh's box, so nearly all of them reach a leaf): left to the
    // compiler, or built lazily at the first leaf, its latency lands on the walk's chain
    // (measured, shadow rays from the primary hits toward a light: bunny 122-124 ns
    // against 118-121 pinned, armadillo 183-187 against 179-186).
    let sheared = std::hint::black_box(ShearedRay::new(origin, dir));
    let mut found = false;
    stack.push(0);
    while let Some(e) = stack.pop() {
        let cur = e as u32;
        if cur & LEAF == 0 {
            let n = bvh.node(cur);
            stats.bvh_nodes += 1;
            // Every node, the root too, with the test below the root (as measured).
            let (mut mask, _) = L::test_node::<S, false>(&br, n, t_min, t_max);
            let children = L::children(n);
            while mask != 0 {
                let l = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                stack.push(u64::from(children[l]));
            }
        } else {
            let leaf = leaf_range(cur);
            stats.prim_tests += leaf.1 as u64;
            if bvh.leaf_test(s, &sheared, leaf, t_min, t_max).1 != 0 {
                found = true;
                break;
            }
        }
    }
    found
}

/// The SAH-optimal grouping of a BVH2 into wide nodes and packets
/// ([`WideBvh::from_bvh2`]). Per BVH2 node and slot budget `j` (1 to [`WIDTH`]), how its
/// subtree is best covered by at most `j` child slots of a wide node.
struct SahPlan {
    /// `choice[node][j - 1]`: [`SahPlan::PACKET`] (one slot, a leaf of one or two packets),
    /// [`SahPlan::NODE`] (one slot, a wide node of its own) or `SPLIT | kl << 3 | kr`
    /// (its two children covered with `kl` and `kr` slots).
    choice: Vec<[u8; WIDTH]>,
    /// Per inner node, `kl << 3 | kr`: its children's slots as a wide node of its own.
    wide: Vec<u8>,
}

impl SahPlan {
    const PACKET: u8 = 0;
    const NODE: u8 = 1;
    const SPLIT: u8 = 64;

    fn new(bvh: &Bvh2, packet_cost: f32) -> Self {
        let count = bvh.nodes.len();
        let mut cost = vec![[0.0f32; WIDTH]; count];
        let mut choice = vec![[Self::PACKET; WIDTH]; count];
        let mut wide = vec![0u8; count];
        let mut prims = vec![0u32; count];
        // Children before parents.
        let area = SahArea::for_root(bvh.nodes[0].aabb());
        for &i in bvh2::parents_first(bvh).iter().rev() {
            let i = i as usize;
            let n = &bvh.nodes[i];
            let area = area.of(n.aabb());
            if n.is_leaf() {
                prims[i] = n.prim_count;
                // A leaf over LEAF_MAX * LEAF_PACKETS becomes a node of leaves (see
                // `WideBvh::leaf`).
                let leaves = (n.prim_count as usize).div_ceil(LEAF_MAX * LEAF_PACKETS);
                let c =
                    if leaves <= 1 { packet_cost * area } else { area * (1.0 + packet_cost * leaves as f32) };
                cost[i] = [c; WIDTH];
                continue;
            }
            let (l, r) = (n.first_index as usize, n.first_index as usize + 1);
            prims[i] = prims[l] + prims[r];
            // Best split of `j` slots between the two children, j = 2..=WIDTH.
            let mut split = [(f32::INFINITY, 0u8); WIDTH];
            for (j, best) in split.iter_mut().enumerate().skip(1) {
                for kl in 1..=j {
                    let c = cost[l][kl - 1] + cost[r][j - kl];
                    // The first candidate is taken whatever its cost (an infinite or NaN
                    // cost must not leave the split without slots).
                    if c < best.0 || kl == 1 {
                        *best = (c, ((kl as u8) << 3) | (j + 1 - kl) as u8);
                    }
                }
            }
            wide[i] = split[WIDTH - 1].1;
            let as_node = area + split[WIDTH - 1].0;
            let as_packet =
                if prims[i] as usize <= LEAF_MAX * LEAF_PACKETS { packet_cost * area } else { f32::INFINITY };
            (cost[i][0], choice[i][0]) =
                if as_packet <= as_node { (as_packet, Self::PACKET) } else { (as_node, Self::NODE) };
            for j in 1..WIDTH {
                (cost[i][j], choice[i][j]) = if split[j].0 < cost[i][j - 1] {
                    (split[j].0, Self::SPLIT | split[j].1)
                } else {
                    (cost[i][j - 1], choice[i][j - 1])
                };
            }
        }
        SahPlan { choice, wide }
    }

    /// The children of the wide node made from inner BVH2 node `node`: BVH2 nodes, each
    /// with whether it becomes a packet (else a wide node).
    fn wide_children(&self, bvh: &Bvh2, node: usize, out: &mut Vec<(usize, bool)>) {
        let n = &bvh.nodes[node];
        let w = self.wide[node];
        self.cover(bvh, n.first_index as usize, (w >> 3) as usize, out);
        self.cover(bvh, n.first_index as usize + 1, (w & 7) as usize, out);
    }

    /// Appends the slots covering `node` with at most `slots` slots.
    fn cover(&self, bvh: &Bvh2, node: usize, slots: usize, out: &mut Vec<(usize, bool)>) {
        match self.choice[node][slots - 1] {
            Self::PACKET => out.push((node, true)),
            Self::NODE => out.push((node, false)),
            c => {
                let first = bvh.nodes[node].first_index as usize;
                self.cover(bvh, first, ((c >> 3) & 7) as usize, out);
                self.cover(bvh, first + 1, (c & 7) as usize, out);
            }
        }
    }
}

/// The half areas the SAH plan of [`SahPlan::new`] compares: `f32` half areas of the
/// BVH2's boxes as they are where the root's largest extent lies within
/// [`bvh2::SAFE_EXTENT`] (every ordinary mesh), else of the boxes scaled by the power of
/// two that makes the root about 1 across, computed in `f64` (where `f32` areas of a
/// mesh 1e19 across overflow to infinity, and those of one 1e-30 across are zero).
#[derive(Clone, Copy, Debug)]
struct SahArea {
    scale: Option<f64>,
}

impl SahArea {
    fn for_root(root: &Aabb) -> Self {
        let d = (Vec3::from(root.max).as_dvec3() - Vec3::from(root.min).as_dvec3()).max_element();
        let scale = if d.is_finite() && bvh2::SAFE_EXTENT.contains(&d) {
            None
        } else if d.is_finite() && d > 0.0 {
            Some(2f64.powi(-d.log2().floor() as i32))
        } else {
            // Infinite or empty: no scale to take; areas are capped below.
            Some(1.0)
        };
        SahArea { scale }
    }

    #[inline]
    fn of(&self, b: &Aabb) -> f32 {
        match self.scale {
            None => b.half_area(),
            Some(s) => {
                let d = (Vec3::from(b.max).as_dvec3() - Vec3::from(b.min).as_dvec3()) * s;
                // Sides capped at 2^20 roots (an infinite one too); a NaN side counts as 0.
                let d = d.max(DVec3::ZERO).min(DVec3::splat(1048576.0));
                ((d.x + d.y) * d.z + d.x * d.y) as f32
            }
        }
    }
}

/// The reference of node `index`: its byte offset in [`WideBvh::nodes`]. Panics past
/// 2^23 nodes (some 200 million triangles), where it would reach the [`LEAF`] bit.
fn node_ref(index: usize) -> u32 {
    let r = index * size_of::<WideNode>();
    assert!(r < LEAF as usize, "more than {} BVH nodes", LEAF as usize / size_of::<WideNode>());
    r as u32
}

/// A node with every lane unused: NaN boxes (never entered) and [`NONE`] references.
fn empty_node() -> WideNode {
    WideNode { bounds: [[f32::NAN; WIDTH]; 6], children: [NONE; WIDTH] }
}

fn set_lane(n: &mut WideNode, lane: usize, b: &Aabb, reference: u32) {
    for a in 0..3 {
        n.bounds[a][lane] = b.min[a];
        n.bounds[a + 3][lane] = b.max[a];
    }
    n.children[lane] = reference;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::aabb;
    use crate::simd::Portable;
    use obvhs::BvhBuildParams;

    /// Closest hit, any hit and nearest distance over the wide BVH equal brute-force loops,
    /// for leaves that fit a packet and for larger ones split into several.
    #[test]
    fn walks_equal_brute_force() {
        let mut seed = 12345u32;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f32 / u32::MAX as f32
        };
        let tris: Vec<[Vec3; 3]> = (0..500)
            .map(|_| {
                let c = Vec3::new(rnd(), rnd(), rnd()) * 4.0;
                let mut v = || c + Vec3::new(rnd(), rnd(), rnd()) * 0.3;
                [v(), v(), v()]
            })
            .collect();
        let boxes: Vec<Aabb> =
            tris.iter().map(|[a, b, c]| aabb(a.min(*b).min(*c), a.max(*b).max(*c))).collect();
        for leaf in [1, 4, 8, 40] {
            let mut bvh2 = crate::geometry::bvh2::build(
                &boxes,
                BvhBuildParams { max_prims_per_leaf: leaf, ..BvhBuildParams::fast_build() },
            );
            let order = bvh2.primitive_indices.clone();
            for (i, p) in bvh2.primitive_indices.iter_mut().enumerate() {
                *p = i as u32;
            }
            let leaf_tris: Vec<[Vec3; 3]> = order.iter().map(|&i| tris[i as usize]).collect();
            let leaf_boxes: Vec<Aabb> = order.iter().map(|&i| boxes[i as usize]).collect();
            let w = WideBvh::from_bvh2(&bvh2, &leaf_boxes, |i| leaf_tris[i as usize]);
            // As deep as no call stack holds: the walks take a heap stack, same results.
            let mut deep = w.clone();
            deep.depth = 40;
            // Deeper than the small call stack holds: the larger one.
            let mut medium = w.clone();
            medium.depth = 20;
            let mut portable_stats = RayStats::default();
            let ids: Vec<u32> = w.packets.iter().flat_map(|p| p.ids).filter(|&i| i != u32::MAX).collect();
            assert_eq!(ids.len(), tris.len(), "every triangle in one packet lane");
            let mut stats = RayStats::default();
            for _ in 0..300 {
                let origin = Vec3::new(rnd(), rnd(), rnd()) * 8.0 - 2.0;
                let dir = (Vec3::splat(2.0) + Vec3::new(rnd(), rnd(), rnd()) - origin).normalize();
                let t_max = 3.0 + 5.0 * rnd();
                let s = ShearedRay::new(origin, dir);
                let brute = leaf_tris
                    .iter()
                    .filter_map(|[a, b, c]| s.intersect(*a, *b, *c, 0.0, t_max).map(|h| h.t))
                    .min_by(f32::total_cmp);
                let ours = w.closest_hit(origin, dir, 0.0, t_max, &mut stats);
                assert_eq!(ours.map(|h| h.t), brute);
                // The AVX2 and the portable box tests walk alike: same hits, same work.
                let portable = closest_walk(Portable, &w, origin, dir, 0.0, t_max, &mut portable_stats);
                assert_eq!(portable, ours);
                assert_eq!(deep.closest_hit(origin, dir, 0.0, t_max, &mut RayStats::default()), ours);
                assert_eq!(deep.any_hit(origin, dir, 0.0, t_max, &mut RayStats::default()), brute.is_some());
                assert_eq!(medium.closest_hit(origin, dir, 0.0, t_max, &mut RayStats::default()), ours);
                assert_eq!(
                    medium.any_hit(origin, dir, 0.0, t_max, &mut RayStats::default()),
                    brute.is_some()
                );
                if let Some(h) = ours {
                    let [a, b, c] = leaf_tris[h.triangle as usize];
                    assert_eq!(h.corners, [a, b, c]);
                    assert_eq!(s.intersect(a, b, c, h.t, h.t).map(|h| h.t), Some(h.t));
                }
                assert_eq!(w.any_hit(origin, dir, 0.0, t_max, &mut stats), brute.is_some());
                let portable = any_walk(Portable, &w, origin, dir, 0.0, t_max, &mut portable_stats);
                assert_eq!(portable, brute.is_some());
                let p = origin.as_dvec3();
                let near = w.nearest(p, |i| {
                    leaf_tris[i as usize].iter().map(|v| (v.as_dvec3() - p).length()).fold(f64::MAX, f64::min)
                });
                let brute_near = leaf_tris
                    .iter()
                    .flat_map(|t| t.iter().map(|v| (v.as_dvec3() - p).length()))
                    .fold(f64::MAX, f64::min);
                assert_eq!(near, brute_near);
            }
            assert!(stats.bvh_nodes > 0 && stats.prim_tests > 0);
            assert_eq!(
                (portable_stats.bvh_nodes, portable_stats.prim_tests),
                (stats.bvh_nodes, stats.prim_tests)
            );
        }
    }
    /// Boxes whose half areas are infinite in f32 (a BVH2 refitted to boxes 1e38 across
    /// and infinite ones): the grouping never leaves a split without slots, and every
    /// triangle ends up in one packet lane.
    #[test]
    fn grouping_survives_infinite_areas() {
        let tris: Vec<[Vec3; 3]> = (0..300)
            .map(|i| {
                let c = Vec3::new((i % 7) as f32, (i / 7 % 7) as f32, (i / 49) as f32) * 3e37 - 1e38;
                [c, c + Vec3::X * 1e37, c + Vec3::Y * 1e37]
            })
            .collect();
        let mut boxes: Vec<Aabb> =
            tris.iter().map(|[a, b, c]| aabb(a.min(*b).min(*c), a.max(*b).max(*c))).collect();
        boxes[7] = aabb(Vec3::splat(f32::NEG_INFINITY), Vec3::splat(f32::INFINITY));
        let bvh2 = crate::geometry::bvh2::build(&boxes, BvhBuildParams::fast_build());
        let order = bvh2.primitive_indices.clone();
        let mut bvh2 = bvh2;
        for (i, p) in bvh2.primitive_indices.iter_mut().enumerate() {
            *p = i as u32;
        }
        let leaf_boxes: Vec<Aabb> = order.iter().map(|&i| boxes[i as usize]).collect();
        crate::geometry::bvh2::refit(&mut bvh2, &leaf_boxes);
        assert!(bvh2.nodes[0].aabb().half_area().is_infinite());
        let w = WideBvh::from_bvh2(&bvh2, &leaf_boxes, |i| tris[order[i as usize] as usize]);
        let mut ids: Vec<u32> = w.packets.iter().flat_map(|p| p.ids).filter(|&i| i != u32::MAX).collect();
        ids.sort_unstable();
        assert_eq!(ids, (0..tris.len() as u32).collect::<Vec<_>>());
    }
}
