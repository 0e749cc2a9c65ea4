//! Packets of up to eight rays through a mesh's 8-wide BVH ([`WideBvh`]): the batch
//! walks behind [`crate::geometry::Geometry::closest_hits`] and
//! [`crate::geometry::Geometry::any_hits`] of a mesh, after Embree's coherent packet
//! kernels (`rtcIntersect8`, `rtcOccluded8`), for the rays of a 4x2 pixel block and their
//! shadow rays.
//!
//! A coherent packet (directions of one sign per axis, origins close together: a
//! frustum) tests each node's eight child boxes once for all of its rays, with interval
//! arithmetic over the rays' origins and reciprocal directions, widened by a bound on the
//! rounding of both this test and the one-ray test, so that it enters every box some ray
//! enters alone. Children are visited nearest first by the frustum's entry distance and
//! skipped once it lies beyond every ray's closest hit. At a leaf each ray takes its own
//! box test of the leaf (the one-ray walk's test, bit for bit, in the lanes) and then, if
//! it enters, the one-ray triangle test ([`ShearedRay::intersect8`]). A packet that is not
//! coherent goes one ray at a time through the one-ray walk (the caller does that).
//!
//! A ray's closest hit is therefore the one-ray walk's: the nearest triangle it hits, and
//! among triangles hit at exactly the same distance, the last in leaf order, in both walks
//! (an order-independent rule). Work is counted per ray: a
//! node test for the packet counts once for each of its rays, a triangle test once per
//! ray tested.

use glam::Vec3;

use crate::geometry::RayStats;
use crate::geometry::mesh::triangle::ShearedRay;
use crate::geometry::mesh::wide_bvh::{
    LEAF, LEAF_MAX, LeafHit, WIDTH, WideBvh, WideNode, leaf_range, leaf_test, order_key, stack_needed,
    tie_wins,
};
use crate::simd::{Lane, Lane8, Mask8, Simd};

/// Rays per packet.
pub const RAYS: usize = 8;

/// Stack entries of a packet walk (12 bytes each). A BVH that could need more
/// ([`stack_needed`]) is walked one ray at a time.
const STACK: usize = 96;

/// Whether [`closest_coherent`] and [`any_coherent`] can walk `bvh` (its depth bounds the
/// stack they keep).
pub fn fits(bvh: &WideBvh) -> bool {
    !bvh.nodes.is_empty() && stack_needed(bvh) <= STACK
}

/// Eight rays (lane `l` is ray `l`) prepared for each ray's own test of a child box of a
/// [`WideNode`]: per lane, what [`super::wide_bvh`]'s one-ray box test keeps in all lanes.
struct Rays<S: Simd> {
    s: S,
    origin: [S::F32x8; 3],
    inv: [S::F32x8; 3],
    /// Per bound row, `origin * inv` rounded away from the box, as the one-ray test's.
    offset: [S::F32x8; 6],
}

impl<S: Simd> Rays<S> {
    /// The rays `origins[l] + t * dirs[l]` (every lane a ray; callers keep the lanes past
    /// a packet's end inactive), their reciprocal directions computed in the lanes with
    /// the one-ray test's scalar operations (so each lane's bits are that test's), and the
    /// lanes' origins and reciprocals as arrays (`[axis][lane]`).
    #[inline(always)]
    fn new(s: S, origins: &[Vec3; RAYS], dirs: &[Vec3; RAYS]) -> (Self, [[f32; RAYS]; 3], [[f32; RAYS]; 3]) {
        let mut o = [[0.0f32; RAYS]; 3];
        let mut d = [[0.0f32; RAYS]; 3];
        for l in 0..RAYS {
            for a in 0..3 {
                o[a][l] = origins[l][a];
                d[a][l] = dirs[l][a];
            }
        }
        let origin = [s.load8(&o[0]), s.load8(&o[1]), s.load8(&o[2])];
        let inv = [
            safe_inverse8(s, s.load8(&d[0])),
            safe_inverse8(s, s.load8(&d[1])),
            safe_inverse8(s, s.load8(&d[2])),
        ];
        // As `BoxRay::new`: `p + e` and `p - e` with `e >= 2 ulp(p)` bracket the exact
        // product; `e` takes the sign of the reciprocal.
        let sign = s.splat8(-0.0);
        let two_eps = s.splat8(2.0 * f32::EPSILON);
        let mut offset = [origin[0]; 6];
        for a in 0..3 {
            let p = origin[a] * inv[a];
            let e = (p.vabs() * two_eps).or(inv[a].and(sign));
            offset[a] = p + e;
            offset[a + 3] = p - e;
        }
        let inv_rows = [inv[0].store(), inv[1].store(), inv[2].store()];
        (Rays { s, origin, inv, offset }, o, inv_rows)
    }

    /// The box test of child `c` of `n` for every lane: each lane's entry distance and the
    /// lanes that enter the box within `[t_min, t_max]` (lane `l` against `t_max`'s lane
    /// `l`). `ROOT` for the root node, whose one-ray test is unfused.
    #[inline(always)]
    fn child<const ROOT: bool>(
        &self,
        n: &WideNode,
        c: usize,
        t_min: S::F32x8,
        t_max: S::F32x8,
    ) -> (S::F32x8, <S::F32x8 as Lane8>::Mask) {
        let b = &n.bounds;
        let (x0, x1) = (self.slab::<ROOT>(b[0][c], 0), self.slab::<ROOT>(b[3][c], 3));
        let (y0, y1) = (self.slab::<ROOT>(b[1][c], 1), self.slab::<ROOT>(b[4][c], 4));
        let (z0, z1) = (self.slab::<ROOT>(b[2][c], 2), self.slab::<ROOT>(b[5][c], 5));
        let near = x0.vmin(x1).vmax(y0.vmin(y1)).vmax(t_min.vmax(z0.vmin(z1)));
        let far = x0.vmax(x1).vmin(y0.vmax(y1)).vmin(t_max.vmin(z0.vmax(z1)));
        (near, near.mask_le(far))
    }

    /// Every lane's slab distance to the plane `bound` of bound row `row` (minimum x, y,
    /// z, then maximum x, y, z): unfused at the root, fused below, as the one-ray test.
    /// (A method rather than a closure, which the compiler could leave out of line, where
    /// it would not be compiled for the backend's instructions.)
    #[inline(always)]
    fn slab<const ROOT: bool>(&self, bound: f32, row: usize) -> S::F32x8 {
        let a = row % 3;
        let bound = self.s.splat8(bound);
        if ROOT {
            (bound - self.origin[a]) * self.inv[a]
        } else {
            bound.mul_sub(self.inv[a], self.offset[row])
        }
    }
}

/// `obvhs::ray::safe_inverse` of every lane: `1 / x`, or `±2^23` (the sign of `x`, of a
/// zero too) where `|x| <= f32::EPSILON`; bit for bit the scalar function's.
#[inline(always)]
fn safe_inverse8<S: Simd>(s: S, x: S::F32x8) -> S::F32x8 {
    let small = x.vabs().mask_le(s.splat8(f32::EPSILON));
    let clamped = s.splat8(1.0 / f32::EPSILON).or(x.and(s.splat8(-0.0)));
    small.select(clamped, s.splat8(1.0) / x)
}

/// The bounds of a coherent packet's rays, for one conservative eight-box test per node
/// for the whole packet (a frustum test, as Embree's coherent packet kernels): per axis the
/// range of the origins and of the reciprocal directions, which share one sign (else the
/// packet is not coherent and [`Frustum::new`] gives `None`).
struct Frustum<S: Simd> {
    s: S,
    /// Per axis: the bound row the rays enter through (the minimum for a positive
    /// direction) and the one they leave through.
    entry: [usize; 3],
    exit: [usize; 3],
    o_lo: [S::F32x8; 3],
    o_hi: [S::F32x8; 3],
    i_lo: [S::F32x8; 3],
    i_hi: [S::F32x8; 3],
    /// Per axis, a bound on the rounding error of any lane's slab distance in this test
    /// and in the one-ray test, so that the frustum contains every ray's box.
    slack: [S::F32x8; 3],
}

impl<S: Simd> Frustum<S> {
    /// The frustum of the lanes `l < n` of the rays with origins `o` and reciprocal
    /// directions `inv` (`[axis][lane]`), if the directions share a sign on every axis;
    /// `extent` bounds the absolute coordinates of the BVH's boxes.
    #[inline(always)]
    fn new(
        s: S,
        o: &[[f32; RAYS]; 3],
        inv: &[[f32; RAYS]; 3],
        n: usize,
        bounds: PacketBounds,
    ) -> Option<Self> {
        let extent = bounds.extent;
        let mut o_lo = [f32::INFINITY; 3];
        let mut o_hi = [f32::NEG_INFINITY; 3];
        let mut i_lo = [f32::INFINITY; 3];
        let mut i_hi = [f32::NEG_INFINITY; 3];
        let mut pos = [0usize; 3];
        for a in 0..3 {
            for l in 0..n {
                o_lo[a] = o_lo[a].min(o[a][l]);
                o_hi[a] = o_hi[a].max(o[a][l]);
                i_lo[a] = i_lo[a].min(inv[a][l]);
                i_hi[a] = i_hi[a].max(inv[a][l]);
                pos[a] += usize::from(inv[a][l] > 0.0);
            }
        }
        if pos.iter().any(|&p| p != 0 && p != n) || !extent.is_finite() {
            return None;
        }
        if (0..3).any(|a| !(o_hi[a] - o_lo[a] <= bounds.spread)) {
            return None;
        }
        let mut slack = [0.0f32; 3];
        for a in 0..3 {
            let o = o_lo[a].abs().max(o_hi[a].abs());
            let i = i_lo[a].abs().max(i_hi[a].abs());
            // Each slab distance here and in the one-ray test is a few roundings of terms
            // at most `(extent + o) * i` in size.
            slack[a] = 16.0 * f32::EPSILON * (extent + o) * i;
            if !(slack[a].is_finite() && o_lo[a].is_finite() && o_hi[a].is_finite()) {
                return None;
            }
        }
        let entry = std::array::from_fn(|a| if pos[a] == n { a } else { a + 3 });
        let exit = std::array::from_fn(|a| if pos[a] == n { a + 3 } else { a });
        Some(Frustum {
            s,
            entry,
            exit,
            o_lo: [s.splat8(o_lo[0]), s.splat8(o_lo[1]), s.splat8(o_lo[2])],
            o_hi: [s.splat8(o_hi[0]), s.splat8(o_hi[1]), s.splat8(o_hi[2])],
            i_lo: [s.splat8(i_lo[0]), s.splat8(i_lo[1]), s.splat8(i_lo[2])],
            i_hi: [s.splat8(i_hi[0]), s.splat8(i_hi[1]), s.splat8(i_hi[2])],
            slack: [s.splat8(slack[0]), s.splat8(slack[1]), s.splat8(slack[2])],
        })
    }

    /// The smallest and the largest of `(b - o) * i` over `o` in `[o_lo, o_hi]` and `i` in
    /// `[i_lo, i_hi]` (the products of the corners), per lane.
    #[inline(always)]
    fn range(&self, b: S::F32x8, a: usize) -> (S::F32x8, S::F32x8) {
        let (d0, d1) = (b - self.o_hi[a], b - self.o_lo[a]);
        let (p0, p1, p2, p3) = (d0 * self.i_lo[a], d0 * self.i_hi[a], d1 * self.i_lo[a], d1 * self.i_hi[a]);
        (p0.vmin(p1).vmin(p2.vmin(p3)), p0.vmax(p1).vmax(p2.vmax(p3)))
    }

    /// Whether some ray of the packet may enter a child of the root within `[t_min, t_max]`.
    #[inline(always)]
    fn enters_root(&self, bvh: &WideBvh, t_min: f32, t_max: f32) -> bool {
        let root = &bvh.nodes[0];
        let b0 = self.s.load8(&root.bounds[0]);
        self.node(root, t_min, t_max, b0.mask_eq(b0).bits()).0 != 0
    }

    /// The children of `n` that some ray of the packet may enter within `[t_min, t_max]`
    /// (a superset of those each ray's own test enters) and a lower bound of their entry
    /// distance per lane.
    #[inline(always)]
    fn node(&self, n: &WideNode, t_min: f32, t_max: f32, present: u32) -> (u32, [u32; WIDTH]) {
        let s = self.s;
        let b = &n.bounds;
        let mut near = s.splat8(t_min);
        let mut far = s.splat8(t_max);
        for a in 0..3 {
            let (lo, _) = self.range(s.load8(&b[self.entry[a]]), a);
            let (_, hi) = self.range(s.load8(&b[self.exit[a]]), a);
            near = near.vmax(lo - self.slack[a]);
            far = far.vmin(hi + self.slack[a]);
        }
        (near.mask_le(far).bits() & present, near.order_keys())
    }
}

/// A coherent packet walk's stack: entries of a child's reference, the order key of the
/// frustum's entry distance, and the byte offset of its parent node with the child's lane
/// in the low bits (node offsets are multiples of 256), for the per-ray test of a leaf's
/// box.
struct CoherentStack {
    child: [u32; STACK],
    key: [u32; STACK],
    from: [u32; STACK],
    len: usize,
}

impl CoherentStack {
    #[inline(always)]
    fn push(&mut self, child: u32, key: u32, from: u32) {
        self.child[self.len] = child;
        self.key[self.len] = key;
        self.from[self.len] = from;
        self.len += 1;
    }

    /// Pops the nearest entry whose key is at most `limit`.
    #[inline(always)]
    fn pop_within(&mut self, limit: u32) -> Option<(u32, u32)> {
        while self.len > 0 {
            self.len -= 1;
            if self.key[self.len] <= limit {
                return Some((self.child[self.len], self.from[self.len]));
            }
        }
        None
    }
}

/// Visits inner node `n` (byte offset `at`) with the frustum: pushes every child it may
/// enter but the nearest, farthest first, and returns the nearest (reference and
/// `at | lane`).
#[inline(always)]
fn coherent_visit<S: Simd>(
    f: &Frustum<S>,
    n: &WideNode,
    at: u32,
    t_min: f32,
    t_max: f32,
    stack: &mut CoherentStack,
) -> Option<(u32, u32)> {
    let b0 = f.s.load8(&n.bounds[0]);
    let present = b0.mask_eq(b0).bits();
    let (mut mask, keys) = f.node(n, t_min, t_max, present);
    if mask == 0 {
        return None;
    }
    // Up to eight (key, lane), sorted nearest first by insertion.
    let mut sorted = [(0u32, 0usize); WIDTH];
    let mut k = 0;
    while mask != 0 {
        let l = mask.trailing_zeros() as usize & (WIDTH - 1);
        mask &= mask - 1;
        let x = (keys[l], l);
        let mut j = k;
        while j > 0 && sorted[j - 1].0 > x.0 {
            sorted[j] = sorted[j - 1];
            j -= 1;
        }
        sorted[j] = x;
        k += 1;
    }
    for &(key, l) in sorted[1..k].iter().rev() {
        stack.push(n.children[l], key, at | l as u32);
    }
    let (_, l) = sorted[0];
    Some((n.children[l], at | l as u32))
}

/// The rays (lanes of `rays` within `t_max`) that enter the box of the child at
/// `from` (`parent offset | lane`), by each ray's own test (the one-ray walk's, unfused
/// below the root for `FUSED_ROOT` false).
#[inline(always)]
fn leaf_rays<S: Simd, const FUSED_ROOT: bool>(
    rays: &Rays<S>,
    bvh: &WideBvh,
    from: u32,
    tmin: S::F32x8,
    tmax: S::F32x8,
) -> u32 {
    let parent = from & !0xff;
    let lane = (from & 0xff) as usize & (WIDTH - 1);
    if parent == 0 && !FUSED_ROOT {
        rays.child::<true>(bvh.node(0), lane, tmin, tmax).1.bits()
    } else {
        rays.child::<false>(bvh.node(parent), lane, tmin, tmax).1.bits()
    }
}

/// The largest lane of `t` among the lanes `live`, or minus infinity.
#[inline(always)]
fn max_of(t: &[f32; RAYS], live: u32) -> f32 {
    let mut m = f32::NEG_INFINITY;
    for (l, &x) in t.iter().enumerate() {
        if live & (1 << l) != 0 && x > m {
            m = x;
        }
    }
    m
}

/// The closest hits of the rays `origins[l] + t * dirs[l]`, `l < n` (`n <= 8`), with `t`
/// in `[t_min, t_max[l]]`, for a coherent packet (directions of one sign per axis, origins
/// close together): per lane the hit (and `t_max[l]` lowered to its
/// `t`), or `None`; exactly the one-ray walk's hit of each ray (see the module's
/// documentation). One frustum test per node for the whole packet, each ray's own box
/// test only at leaves. `None` for a packet that is not coherent (the caller then traces
/// its rays one by one). `bvh` must [`fits`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn closest_coherent<S: Simd>(
    s: S,
    bvh: &WideBvh,
    bounds: PacketBounds,
    origins: &[Vec3; RAYS],
    dirs: &[Vec3; RAYS],
    n: usize,
    t_min: f32,
    t_max: &mut [f32; RAYS],
    stats: &mut RayStats,
) -> Option<[Option<LeafHit>; RAYS]> {
    let (rays, o, inv) = Rays::new(s, origins, dirs);
    let f = Frustum::new(s, &o, &inv, n, bounds)?;
    let all = (1u32 << n) - 1;
    let mut reach = max_of(t_max, all);
    if !f.enters_root(bvh, t_min, reach) {
        // The commonest packet: every ray misses the mesh.
        stats.bvh_nodes += n as u64;
        return Some([None; RAYS]);
    }
    for t in &mut t_max[n..] {
        *t = f32::NEG_INFINITY;
    }
    let mut best: [Option<(usize, usize)>; RAYS] = [None; RAYS];
    let mut nodes = 1u64;
    let mut stack = CoherentStack { child: [0; STACK], key: [0; STACK], from: [0; STACK], len: 0 };
    let mut cur = coherent_visit(&f, &bvh.nodes[0], 0, t_min, reach, &mut stack);
    let tmin = s.splat8(t_min);
    let mut tmax = s.load8(t_max);
    let mut tests = 0u64;
    let mut sheared: [Option<ShearedRay>; RAYS] = [None; RAYS];
    loop {
        let (node, from) = match cur {
            Some(x) => x,
            None => match stack.pop_within(order_key(reach)) {
                Some(x) => x,
                None => break,
            },
        };
        if node & LEAF == 0 {
            nodes += 1;
            cur = coherent_visit(&f, bvh.node(node), node, t_min, reach, &mut stack);
            continue;
        }
        cur = None;
        let lanes = leaf_rays::<S, false>(&rays, bvh, from, tmin, tmax) & all;
        if lanes == 0 {
            continue;
        }
        let (first, count) = leaf_range(node);
        let packets = bvh.leaf_packets((first, count));
        let mut todo = lanes;
        let mut lowered = false;
        while todo != 0 {
            let r = todo.trailing_zeros() as usize & (RAYS - 1);
            todo &= todo - 1;
            tests += count as u64;
            let sheared = sheared[r].get_or_insert_with(|| ShearedRay::new(origins[r], dirs[r]));
            let (t, mut hits) = leaf_test(s, sheared, packets, t_min, t_max[r]);
            while hits != 0 {
                let lane = hits.trailing_zeros() as usize & 7;
                hits &= hits - 1;
                let at = (first + lane / LEAF_MAX, lane % LEAF_MAX);
                if tie_wins(t[lane], t_max[r], at, best[r]) {
                    t_max[r] = t[lane];
                    best[r] = Some(at);
                    lowered = true;
                }
            }
        }
        if lowered {
            tmax = s.load8(t_max);
            reach = max_of(t_max, all);
        }
    }
    // Work per ray as the one-ray walk counts it would be the nodes each ray enters; the
    // packet tests each node once for all of its rays, counted once per ray of the packet.
    stats.bvh_nodes += nodes * n as u64;
    stats.prim_tests += tests;
    Some(std::array::from_fn(|r| best[r].map(|at| bvh.leaf_hit(at, t_max[r]))))
}

/// For the rays `origins[l] + t * dirs[l]`, `l < n`, not yet occluded (bit `l` clear in
/// `occluded`): whether a triangle is hit with `t` in `[t_min, t_max[l]]`, for a coherent
/// packet as [`closest_coherent`]. Returns the occluded lanes (those given and those
/// found); a ray stops at its first hit, the packet when every ray has. `None` for a
/// packet that is not coherent.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn any_coherent<S: Simd>(
    s: S,
    bvh: &WideBvh,
    bounds: PacketBounds,
    origins: &[Vec3; RAYS],
    dirs: &[Vec3; RAYS],
    n: usize,
    t_min: f32,
    t_max: &[f32; RAYS],
    occluded: u32,
    stats: &mut RayStats,
) -> Option<u32> {
    let all = (1u32 << n) - 1;
    let mut done = occluded & all;
    if done == all {
        return Some(occluded);
    }
    let (rays, o, inv) = Rays::new(s, origins, dirs);
    let f = Frustum::new(s, &o, &inv, n, bounds)?;
    let mut limit = *t_max;
    for (l, t) in limit.iter_mut().enumerate() {
        if done & (1 << l) != 0 || l >= n {
            *t = f32::NEG_INFINITY;
        }
    }
    let reach = max_of(&limit, all);
    let live = u64::from((all & !done).count_ones());
    if !f.enters_root(bvh, t_min, reach) {
        stats.bvh_nodes += live;
        return Some(done | occluded);
    }
    let mut nodes = 1u64;
    let mut stack = CoherentStack { child: [0; STACK], key: [0; STACK], from: [0; STACK], len: 0 };
    let mut cur = coherent_visit(&f, &bvh.nodes[0], 0, t_min, reach, &mut stack);
    let tmin = s.splat8(t_min);
    let mut tmax = s.load8(&limit);
    let mut tests = 0u64;
    let mut sheared: [Option<ShearedRay>; RAYS] = [None; RAYS];
    let limit_key = order_key(reach);
    loop {
        let (node, from) = match cur {
            Some(x) => x,
            None => match stack.pop_within(limit_key) {
                Some(x) => x,
                None => break,
            },
        };
        if node & LEAF == 0 {
            nodes += 1;
            cur = coherent_visit(&f, bvh.node(node), node, t_min, reach, &mut stack);
            continue;
        }
        cur = None;
        let lanes = leaf_rays::<S, true>(&rays, bvh, from, tmin, tmax) & all & !done;
        if lanes == 0 {
            continue;
        }
        let (first, count) = leaf_range(node);
        let packets = bvh.leaf_packets((first, count));
        let mut todo = lanes;
        while todo != 0 {
            let r = todo.trailing_zeros() as usize & (RAYS - 1);
            todo &= todo - 1;
            tests += count as u64;
            let sheared = sheared[r].get_or_insert_with(|| ShearedRay::new(origins[r], dirs[r]));
            if leaf_test(s, sheared, packets, t_min, limit[r]).1 != 0 {
                done |= 1 << r;
                limit[r] = f32::NEG_INFINITY;
            }
        }
        if done == all {
            break;
        }
        tmax = s.load8(&limit);
    }
    stats.bvh_nodes += nodes * live;
    stats.prim_tests += tests;
    Some(done | occluded)
}

/// What a packet walk needs to know of a BVH's root box ([`PacketBounds::of`]).
#[derive(Clone, Copy, Debug)]
pub struct PacketBounds {
    /// The largest absolute coordinate of its boxes (their rounding scales with it).
    pub extent: f32,
    /// The largest spread of a coherent packet's origins on any axis: a sixteenth of the
    /// root box's longest side. Packets whose origins spread wider (shadow rays from hits
    /// scattered over the mesh) go one ray at a time: their frustum culls too little.
    pub spread: f32,
}

impl PacketBounds {
    /// The bounds of `bvh`'s root box (an empty BVH gets an infinite extent, which no
    /// packet walk takes).
    pub fn of(bvh: &WideBvh) -> Self {
        let Some(root) = bvh.nodes.first() else {
            return PacketBounds { extent: f32::INFINITY, spread: 0.0 };
        };
        let (mut extent, mut lo, mut hi) = (0.0f32, [f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for (row, bounds) in root.bounds.iter().enumerate() {
            for (&x, &c) in bounds.iter().zip(&root.children) {
                if c != u32::MAX {
                    extent = extent.max(x.abs());
                    lo[row % 3] = lo[row % 3].min(x);
                    hi[row % 3] = hi[row % 3].max(x);
                }
            }
        }
        let side = (0..3).map(|a| hi[a] - lo[a]).fold(0.0f32, f32::max);
        PacketBounds { extent, spread: side / 16.0 }
    }
}
