//! The per-mesh 4-wide BVH: an obvhs `Bvh2` collapsed into nodes of four children whose
//! boxes are stored as structure-of-arrays (so one ray tests all four at once, vectorised
//! by the compiler), with leaves of up to four triangles pre-gathered into a
//! [`Tri4`] packet for [`ShearedRay::intersect4`]. Owns the closest-hit, any-hit and
//! nearest-point walks over it and their work counting, and [`F4`], the four-lane f32
//! vector both tests use (SSE on x86_64, plain arrays elsewhere). The scene's top-level
//! BVH over objects stays in [`crate::bvh`].

use std::mem::MaybeUninit;
use std::ops::{Mul, Sub};

use glam::{DVec3, Vec3};
use obvhs::bvh2::Bvh2;

use crate::geometry::{Aabb, RayStats, box_distance};
use crate::triangle::{ShearedRay, Tri4};

/// Children per node.
const WIDTH: usize = 4;
/// Triangles per leaf packet.
pub const LEAF_MAX: usize = 4;
/// Marks a child reference as a leaf: `LEAF | packet << 2 | (count - 1)`.
const LEAF: u32 = 1 << 31;
/// Child reference of an unused slot (its box is empty, so it is never entered).
const NONE: u32 = u32::MAX;
/// Traversal stack entries kept on the stack; deeper walks spill to a heap vector.
const STACK: usize = 64;

/// An inner node: four child boxes and references (aligned to two 64-byte cache lines).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct Node {
    /// Child boxes, scene units: `bounds[0..3][lane]` are the minimum x, y, z and
    /// `bounds[3..6][lane]` the maximum; unused lanes are empty (min `+inf`, max `-inf`).
    pub bounds: [[f32; WIDTH]; 6],
    /// Per lane: an index into [`WideBvh::nodes`], or `LEAF | packet << 2 | (count - 1)`
    /// for a leaf of `count` triangles in [`WideBvh::packets`]`[packet]`, or `u32::MAX`.
    pub children: [u32; WIDTH],
}

/// A leaf: up to four triangles' corners and their indices.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub struct Packet {
    /// Corners, `tri[vertex][axis][lane]`, scene units (local frame); unused lanes NaN.
    pub tri: Tri4,
    /// Per lane, the triangle's index in the mesh's triangle list (`u32::MAX` if unused).
    pub ids: [u32; LEAF_MAX],
}

/// A 4-wide BVH over triangles. Node 0 is the root (absent for an empty mesh).
#[derive(Clone, Debug, Default)]
pub struct WideBvh {
    /// Inner nodes; node 0 is the root.
    pub nodes: Vec<Node>,
    /// Leaf packets.
    pub packets: Vec<Packet>,
    /// Deepest node level (root = 1), which bounds the traversal stack.
    pub depth: usize,
}

/// A ray prepared for the box tests: origin, safe reciprocal direction and, per axis,
/// which bounds row is the near plane (by the sign of the direction).
#[derive(Clone, Copy, Debug)]
struct BoxRay {
    origin: [F4; 3],
    inv: [F4; 3],
    near: [usize; 3],
    far: [usize; 3],
}

impl BoxRay {
    #[inline(always)]
    fn new(origin: Vec3, dir: Vec3) -> Self {
        let inv = [
            obvhs::ray::safe_inverse(dir.x),
            obvhs::ray::safe_inverse(dir.y),
            obvhs::ray::safe_inverse(dir.z),
        ];
        let side = |a: usize| if inv[a] < 0.0 { (a + 3, a) } else { (a, a + 3) };
        let (x, y, z) = (side(0), side(1), side(2));
        BoxRay {
            origin: [F4::splat(origin.x), F4::splat(origin.y), F4::splat(origin.z)],
            inv: [F4::splat(inv[0]), F4::splat(inv[1]), F4::splat(inv[2])],
            near: [x.0, y.0, z.0],
            far: [x.1, y.1, z.1],
        }
    }

    /// The lanes whose child box the ray enters within `[t_min, t_max]` (bit `l` for lane
    /// `l`) and the entry distances.
    #[inline(always)]
    fn hit4(&self, n: &Node, t_min: f32, t_max: f32) -> (u32, [f32; WIDTH]) {
        let b = &n.bounds;
        let slab = |row: usize, a: usize| F4::load(&b[row]).sub(self.origin[a]).mul(self.inv[a]);
        let near =
            slab(self.near[0], 0).max(slab(self.near[1], 1)).max(slab(self.near[2], 2).max(F4::splat(t_min)));
        let far =
            slab(self.far[0], 0).min(slab(self.far[1], 1)).min(slab(self.far[2], 2).min(F4::splat(t_max)));
        (near.le(far), near.to_array())
    }
}

/// Four f32 lanes: SSE on x86_64 (part of its baseline, so the intrinsics are safe to
/// call), a plain array elsewhere. Arithmetic is IEEE single precision lane by lane, so
/// results equal the scalar ones bit for bit.
#[derive(Clone, Copy, Debug)]
pub struct F4(
    #[cfg(target_arch = "x86_64")] core::arch::x86_64::__m128,
    #[cfg(not(target_arch = "x86_64"))] [f32; 4],
);

#[cfg(target_arch = "x86_64")]
mod f4 {
    use super::F4;
    use core::arch::x86_64::*;

    // SAFETY (every block below): SSE and SSE2 are part of the x86_64 baseline, so the
    // intrinsics' target features are always present; loads and stores go through
    // references to `[f32; 4]`.

    impl F4 {
        /// Loads four lanes.
        #[inline(always)]
        pub fn load(a: &[f32; 4]) -> F4 {
            F4(unsafe { _mm_loadu_ps(a.as_ptr()) })
        }
        /// The same value in every lane.
        #[inline(always)]
        pub fn splat(x: f32) -> F4 {
            F4(unsafe { _mm_set1_ps(x) })
        }
        /// The four lanes.
        #[inline(always)]
        pub fn to_array(self) -> [f32; 4] {
            let mut a = [0.0f32; 4];
            unsafe { _mm_storeu_ps(a.as_mut_ptr(), self.0) };
            a
        }
        /// Lane-wise `if a < b { a } else { b }` (`b` where either is NaN).
        #[inline(always)]
        pub fn min(self, b: F4) -> F4 {
            F4(unsafe { _mm_min_ps(self.0, b.0) })
        }
        /// Lane-wise `if a > b { a } else { b }` (`b` where either is NaN).
        #[inline(always)]
        pub fn max(self, b: F4) -> F4 {
            F4(unsafe { _mm_max_ps(self.0, b.0) })
        }
        /// Bit `l` set where lane `l` has `a <= b`.
        #[inline(always)]
        pub fn le(self, b: F4) -> u32 {
            unsafe { _mm_movemask_ps(_mm_cmple_ps(self.0, b.0)) as u32 }
        }
        /// Bit `l` set where lane `l` has `a < b`.
        #[inline(always)]
        pub fn lt(self, b: F4) -> u32 {
            unsafe { _mm_movemask_ps(_mm_cmplt_ps(self.0, b.0)) as u32 }
        }
        /// Bit `l` set where lane `l` has `a == b`.
        #[inline(always)]
        pub fn eq(self, b: F4) -> u32 {
            unsafe { _mm_movemask_ps(_mm_cmpeq_ps(self.0, b.0)) as u32 }
        }
    }

    impl std::ops::Add for F4 {
        type Output = F4;
        /// Lane-wise `a + b`.
        #[inline(always)]
        fn add(self, b: F4) -> F4 {
            F4(unsafe { _mm_add_ps(self.0, b.0) })
        }
    }

    impl std::ops::Sub for F4 {
        type Output = F4;
        /// Lane-wise `a - b`.
        #[inline(always)]
        fn sub(self, b: F4) -> F4 {
            F4(unsafe { _mm_sub_ps(self.0, b.0) })
        }
    }

    impl std::ops::Mul for F4 {
        type Output = F4;
        /// Lane-wise `a * b`.
        #[inline(always)]
        fn mul(self, b: F4) -> F4 {
            F4(unsafe { _mm_mul_ps(self.0, b.0) })
        }
    }

    impl std::ops::Div for F4 {
        type Output = F4;
        /// Lane-wise `a / b`.
        #[inline(always)]
        fn div(self, b: F4) -> F4 {
            F4(unsafe { _mm_div_ps(self.0, b.0) })
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
mod f4 {
    use super::F4;

    fn zip(a: F4, b: F4, f: impl Fn(f32, f32) -> f32) -> F4 {
        F4([f(a.0[0], b.0[0]), f(a.0[1], b.0[1]), f(a.0[2], b.0[2]), f(a.0[3], b.0[3])])
    }

    fn bits(a: F4, b: F4, f: impl Fn(f32, f32) -> bool) -> u32 {
        (0..4).fold(0, |m, l| m | (u32::from(f(a.0[l], b.0[l])) << l))
    }

    impl F4 {
        /// Loads four lanes.
        #[inline(always)]
        pub fn load(a: &[f32; 4]) -> F4 {
            F4(*a)
        }
        /// The same value in every lane.
        #[inline(always)]
        pub fn splat(x: f32) -> F4 {
            F4([x; 4])
        }
        /// The four lanes.
        #[inline(always)]
        pub fn to_array(self) -> [f32; 4] {
            self.0
        }
        /// Lane-wise `if a < b { a } else { b }` (`b` where either is NaN).
        #[inline(always)]
        pub fn min(self, b: F4) -> F4 {
            zip(self, b, |x, y| if x < y { x } else { y })
        }
        /// Lane-wise `if a > b { a } else { b }` (`b` where either is NaN).
        #[inline(always)]
        pub fn max(self, b: F4) -> F4 {
            zip(self, b, |x, y| if x > y { x } else { y })
        }
        /// Bit `l` set where lane `l` has `a <= b`.
        #[inline(always)]
        pub fn le(self, b: F4) -> u32 {
            bits(self, b, |x, y| x <= y)
        }
        /// Bit `l` set where lane `l` has `a < b`.
        #[inline(always)]
        pub fn lt(self, b: F4) -> u32 {
            bits(self, b, |x, y| x < y)
        }
        /// Bit `l` set where lane `l` has `a == b`.
        #[inline(always)]
        pub fn eq(self, b: F4) -> u32 {
            bits(self, b, |x, y| x == y)
        }
    }

    impl std::ops::Add for F4 {
        type Output = F4;
        /// Lane-wise `a + b`.
        #[inline(always)]
        fn add(self, b: F4) -> F4 {
            zip(self, b, |x, y| x + y)
        }
    }

    impl std::ops::Sub for F4 {
        type Output = F4;
        /// Lane-wise `a - b`.
        #[inline(always)]
        fn sub(self, b: F4) -> F4 {
            zip(self, b, |x, y| x - y)
        }
    }

    impl std::ops::Mul for F4 {
        type Output = F4;
        /// Lane-wise `a * b`.
        #[inline(always)]
        fn mul(self, b: F4) -> F4 {
            zip(self, b, |x, y| x * y)
        }
    }

    impl std::ops::Div for F4 {
        type Output = F4;
        /// Lane-wise `a / b`.
        #[inline(always)]
        fn div(self, b: F4) -> F4 {
            zip(self, b, |x, y| x / y)
        }
    }
}

/// A child being gathered during the collapse: its box and reference.
type Child = (Aabb, u32);

impl WideBvh {
    /// Collapses `bvh`, built over the boxes `boxes` of the triangles `corners(i)`, with
    /// its primitive indices already in leaf order (`primitive_indices[i] == i`). Leaves
    /// with more than [`LEAF_MAX`] triangles are split into several packets.
    pub fn from_bvh2(bvh: &Bvh2, boxes: &[Aabb], corners: impl Fn(u32) -> [Vec3; 3]) -> Self {
        let mut w = WideBvh::default();
        if bvh.nodes.is_empty() {
            return w;
        }
        let root = &bvh.nodes[0];
        w.nodes.push(empty_node());
        let children = if root.is_leaf() { vec![(*root.aabb(), 0)] } else { Self::gather(bvh, 0) };
        w.fill(bvh, boxes, &corners, 0, children, 1);
        w.nodes.shrink_to_fit();
        w.packets.shrink_to_fit();
        w
    }

    /// Up to four descendants of inner node `node` to become one wide node's children:
    /// starting from its two children, the inner child of largest surface area is opened
    /// while there is room. Returns Bvh2 node indices.
    fn gather(bvh: &Bvh2, node: usize) -> Vec<Child> {
        let n = &bvh.nodes[node];
        let mut kids: Vec<Child> = (0..2)
            .map(|i| {
                let c = n.first_index + i;
                (*bvh.nodes[c as usize].aabb(), c)
            })
            .collect();
        while kids.len() < WIDTH {
            let open = kids
                .iter()
                .enumerate()
                .filter(|(_, (_, c))| !bvh.nodes[*c as usize].is_leaf())
                .max_by(|a, b| a.1.0.half_area().total_cmp(&b.1.0.half_area()))
                .map(|(i, _)| i);
            let Some(i) = open else { break };
            let (_, c) = kids.swap_remove(i);
            let f = bvh.nodes[c as usize].first_index;
            kids.push((*bvh.nodes[f as usize].aabb(), f));
            kids.push((*bvh.nodes[f as usize + 1].aabb(), f + 1));
        }
        kids
    }

    /// Fills wide node `at` (already pushed) with `kids` (Bvh2 node indices), recursing.
    fn fill(
        &mut self,
        bvh: &Bvh2,
        boxes: &[Aabb],
        corners: &impl Fn(u32) -> [Vec3; 3],
        at: usize,
        kids: Vec<Child>,
        depth: usize,
    ) {
        self.depth = self.depth.max(depth);
        for (lane, (b, c)) in kids.into_iter().enumerate() {
            let n = &bvh.nodes[c as usize];
            let reference = if n.is_leaf() {
                let prims: Vec<u32> = (n.first_index..n.first_index + n.prim_count)
                    .map(|i| bvh.primitive_indices[i as usize])
                    .collect();
                self.leaf(boxes, corners, &prims, depth + 1)
            } else {
                let index = self.nodes.len();
                self.nodes.push(empty_node());
                let grand = Self::gather(bvh, c as usize);
                self.fill(bvh, boxes, corners, index, grand, depth + 1);
                index as u32
            };
            set_lane(&mut self.nodes[at], lane, &b, reference);
        }
    }

    /// A child reference for the triangles `prims`: one packet, or (more than
    /// [`LEAF_MAX`]) a node over up to four groups of them, recursively.
    fn leaf(
        &mut self,
        boxes: &[Aabb],
        corners: &impl Fn(u32) -> [Vec3; 3],
        prims: &[u32],
        depth: usize,
    ) -> u32 {
        if prims.len() <= LEAF_MAX {
            let mut p = Packet { tri: [[[f32::NAN; LEAF_MAX]; 3]; 3], ids: [u32::MAX; LEAF_MAX] };
            for (lane, &i) in prims.iter().enumerate() {
                for (v, c) in corners(i).into_iter().enumerate() {
                    for a in 0..3 {
                        p.tri[v][a][lane] = c[a];
                    }
                }
                p.ids[lane] = i;
            }
            self.packets.push(p);
            return LEAF | ((self.packets.len() as u32 - 1) << 2) | (prims.len() as u32 - 1);
        }
        self.depth = self.depth.max(depth);
        let index = self.nodes.len();
        self.nodes.push(empty_node());
        let group = prims.len().div_ceil(WIDTH).max(LEAF_MAX);
        for (lane, chunk) in prims.chunks(group).enumerate() {
            let b = chunk.iter().map(|&i| boxes[i as usize]).reduce(|a, b| a.union(&b)).expect("nonempty");
            let r = self.leaf(boxes, corners, chunk, depth + 1);
            set_lane(&mut self.nodes[index], lane, &b, r);
        }
        index as u32
    }

    /// Bytes held: the struct, nodes and packets.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.nodes.capacity() * std::mem::size_of::<Node>()
            + self.packets.capacity() * std::mem::size_of::<Packet>()
    }

    /// The closest triangle hit by the ray `origin + t * dir` with `t` in `[t_min, t_max]`: its index and `t`. Counts inner nodes
    /// visited (each a four-box test) in `stats.bvh_nodes` and triangles tested in
    /// `stats.prim_tests`.
    #[inline]
    pub fn closest_hit(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        mut t_max: f32,
        stats: &mut RayStats,
    ) -> Option<(u32, f32)> {
        if self.nodes.is_empty() {
            return None;
        }
        let br = BoxRay::new(origin, dir);
        // Prepared at the first leaf: most rays miss the mesh without reaching one.
        let mut sheared: Option<ShearedRay> = None;
        let mut best = None;
        // Entries below `len` are initialised; the rest are never read.
        let mut stack = [const { MaybeUninit::<(u32, f32)>::uninit() }; STACK];
        let mut overflow: Vec<(u32, f32)> = Vec::new();
        let mut len = 0usize;
        let mut cur = 0u32;
        let (mut nodes, mut tests) = (0u64, 0u64);
        'walk: loop {
            if cur & LEAF == 0 {
                let n = &self.nodes[cur as usize];
                nodes += 1;
                let (mut mask, d) = br.hit4(n, t_min, t_max);
                let mut ch = [0u32; WIDTH];
                let mut cd = [0.0f32; WIDTH];
                let mut k = 0;
                while mask != 0 {
                    let l = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    ch[k] = n.children[l];
                    cd[k] = d[l];
                    k += 1;
                }
                match k {
                    0 => {}
                    1 => {
                        cur = ch[0];
                        continue 'walk;
                    }
                    _ => {
                        // Sort by entry distance (insertion sort of at most four), push all
                        // but the nearest, farthest first.
                        for i in 1..k {
                            let (c, x) = (ch[i], cd[i]);
                            let mut j = i;
                            while j > 0 && cd[j - 1] > x {
                                ch[j] = ch[j - 1];
                                cd[j] = cd[j - 1];
                                j -= 1;
                            }
                            ch[j] = c;
                            cd[j] = x;
                        }
                        for i in (1..k).rev() {
                            if len < STACK {
                                stack[len].write((ch[i], cd[i]));
                                len += 1;
                            } else {
                                overflow.push((ch[i], cd[i]));
                            }
                        }
                        cur = ch[0];
                        continue 'walk;
                    }
                }
            } else {
                let p = &self.packets[((cur & !LEAF) >> 2) as usize];
                tests += u64::from((cur & 3) + 1);
                let sheared = sheared.get_or_insert_with(|| ShearedRay::new(origin, dir));
                let t = sheared.intersect4(&p.tri, t_min, t_max);
                for (&tl, &id) in t.iter().zip(&p.ids) {
                    // NaN (a miss) fails the comparison.
                    if tl <= t_max {
                        t_max = tl;
                        best = Some((id, tl));
                    }
                }
            }
            // Pop the nearest pending child still in front of the closest hit.
            loop {
                let (c, d) = if let Some(e) = overflow.pop() {
                    e
                } else if len > 0 {
                    len -= 1;
                    // SAFETY: entries below the old `len` were written by a push.
                    unsafe { stack[len].assume_init() }
                } else {
                    break 'walk;
                };
                if d <= t_max {
                    cur = c;
                    break;
                }
            }
        }
        stats.bvh_nodes += nodes;
        stats.prim_tests += tests;
        best
    }

    /// Whether any triangle is hit with `t` in `[t_min, t_max]`; stops at the first
    /// (shadow rays). Counts work as [`WideBvh::closest_hit`] does.
    #[inline]
    pub fn any_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let br = BoxRay::new(origin, dir);
        let mut stack = [0u32; STACK];
        let mut overflow: Vec<u32> = Vec::new();
        let mut len = 1usize;
        let mut found = false;
        let mut sheared: Option<ShearedRay> = None;
        while let Some(cur) = overflow.pop().or_else(|| {
            len = len.checked_sub(1)?;
            Some(stack[len])
        }) {
            if cur & LEAF == 0 {
                let n = &self.nodes[cur as usize];
                stats.bvh_nodes += 1;
                let (mut mask, _) = br.hit4(n, t_min, t_max);
                while mask != 0 {
                    let l = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    {
                        if len < STACK {
                            stack[len] = n.children[l];
                            len += 1;
                        } else {
                            overflow.push(n.children[l]);
                        }
                    }
                }
            } else {
                let p = &self.packets[((cur & !LEAF) >> 2) as usize];
                stats.prim_tests += u64::from((cur & 3) + 1);
                let sheared = sheared.get_or_insert_with(|| ShearedRay::new(origin, dir));
                if sheared.intersect4(&p.tri, t_min, t_max).iter().any(|t| !t.is_nan()) {
                    found = true;
                    break;
                }
            }
        }
        found
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
                let packet = &self.packets[((cur & !LEAF) >> 2) as usize];
                for &i in &packet.ids[..=(cur & 3) as usize] {
                    best = best.min(dist(i));
                }
                continue;
            }
            let n = &self.nodes[cur as usize];
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

fn empty_node() -> Node {
    let e = [f32::INFINITY; WIDTH];
    Node { bounds: [e, e, e, e.map(|x| -x), e.map(|x| -x), e.map(|x| -x)], children: [NONE; WIDTH] }
}

fn set_lane(n: &mut Node, lane: usize, b: &Aabb, reference: u32) {
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
            let mut bvh2 = crate::bvh::build(
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
                assert_eq!(ours.map(|h| h.1), brute);
                if let Some((i, t)) = ours {
                    let [a, b, c] = leaf_tris[i as usize];
                    assert_eq!(s.intersect(a, b, c, t, t).map(|h| h.t), Some(t));
                }
                assert_eq!(w.any_hit(origin, dir, 0.0, t_max, &mut stats), brute.is_some());
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
        }
    }
}
