//! BVH traversal over obvhs's `Bvh2` with work counting: closest-hit and any-hit walks
//! that call back for each primitive in a visited leaf, visiting near children first, and
//! the nearest-first distance walk ([`nearest`]). Used for the scene's top-level BVH over
//! objects; meshes trace the 8-wide BVH of [`crate::geometry::mesh::wide_bvh`], collapsed
//! from a BVH2 built here (the traversal orders both wide-tree collapses share,
//! [`parents_first`] and [`subtree_primitives`], are here too).

use std::time::Duration;

use glam::{DVec3, Vec3};
use obvhs::BvhBuildParams;
use obvhs::bvh2::Bvh2;
use obvhs::bvh2::builder::build_bvh2;

use crate::geometry::{Aabb, Ray, RayStats};

/// Deepest traversal stack supported; deeper BVHs fall back to a heap stack.
const STACK: usize = 64;

/// Builds a BVH2 over boxes with obvhs's PLOC builder.
///
/// The builder works in `f32` on the boxes as given: their half areas (its merge costs)
/// overflow to infinity for boxes about 1e19 across and underflow to zero below about
/// 1e-19, and a NaN cost (an infinite box that is flat on an axis, or a NaN coordinate)
/// makes it index out of its node array. Equal costs pair nodes with one neighbour only,
/// a chain as deep as the box count and a build quadratic in it. So boxes that are not
/// all finite, or whose union's largest extent lies outside [`SAFE_EXTENT`], are handed
/// to it in a [`BuildFrame`] (centred on their union and scaled by a power of two to a
/// size of about 1) and the tree's boxes are then refitted from the caller's ([`refit`]).
/// Other boxes are handed over as they are, so the tree of every ordinary input is the one
/// obvhs builds for it.
pub fn build(boxes: &[Aabb], params: BvhBuildParams) -> Bvh2 {
    match BuildFrame::for_boxes(boxes) {
        None => build_bvh2(boxes, params, &mut Duration::default()),
        Some(frame) => {
            let unit: Vec<Aabb> = boxes.iter().map(|b| frame.apply(b)).collect();
            let mut bvh = build_bvh2(&unit, params, &mut Duration::default());
            drop(unit);
            refit(&mut bvh, boxes);
            bvh
        }
    }
}

/// The range of the largest extent of a set of boxes (the union's longest side) that
/// [`build`] hands to obvhs unchanged: squares of it, and of sides down to a millionth
/// of it (the padding meshes give their triangles' boxes), and sums of millions of such
/// areas stay normal `f32` numbers.
pub const SAFE_EXTENT: std::ops::RangeInclusive<f64> = 2.3283064365386963e-10..=4294967296.0; // 2^-32..=2^32

/// How [`build`] maps boxes for the builder: `x -> (x - centre) * scale` in `f64`, with
/// `scale` a power of two, so that the boxes' union is centred and about 1 across.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildFrame {
    centre: DVec3,
    scale: f64,
}

impl BuildFrame {
    /// Where a box's infinite (or NaN) coordinate lands: beyond every finite box (all
    /// within 1 of the centre), yet finite.
    const FAR: f64 = 4.0;

    /// `None` when the boxes can be built as they are: every coordinate finite and the
    /// union's largest extent within [`SAFE_EXTENT`] (or zero: one point, nothing to
    /// scale). Otherwise the frame of the union of their finite coordinates.
    pub fn for_boxes(boxes: &[Aabb]) -> Option<BuildFrame> {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        let mut all_finite = true;
        for b in boxes {
            for p in [b.min, b.max] {
                let p = Vec3::from(p);
                all_finite &= p.is_finite();
                for a in 0..3 {
                    if p[a].is_finite() {
                        lo[a] = lo[a].min(p[a] as f64);
                        hi[a] = hi[a].max(p[a] as f64);
                    }
                }
            }
        }
        let lo = DVec3::select(lo.cmple(hi), lo, DVec3::ZERO);
        let hi = DVec3::select(lo.cmple(hi), hi, DVec3::ZERO);
        let extent = (hi - lo).max_element();
        if all_finite && (extent == 0.0 || SAFE_EXTENT.contains(&extent)) {
            return None;
        }
        let scale = if extent > 0.0 { 2f64.powi(-extent.log2().floor() as i32) } else { 1.0 };
        Some(BuildFrame { centre: (lo + hi) * 0.5, scale })
    }

    /// `b` in the frame: finite, NaN and infinite coordinates moved to [`BuildFrame::FAR`]
    /// on their side (a NaN minimum to the low side, a NaN maximum to the high one).
    pub fn apply(&self, b: &Aabb) -> Aabb {
        let map = |x: f32, a: usize, side: f64| -> f32 {
            let x = x as f64;
            if x.is_finite() {
                (((x - self.centre[a]) * self.scale).clamp(-Self::FAR, Self::FAR)) as f32
            } else if x.is_nan() {
                (side * Self::FAR) as f32
            } else {
                (x.signum() * Self::FAR) as f32
            }
        };
        let (min, max) = (Vec3::from(b.min), Vec3::from(b.max));
        let min = Vec3::new(map(min.x, 0, -1.0), map(min.y, 1, -1.0), map(min.z, 2, -1.0));
        let max = Vec3::new(map(max.x, 0, 1.0), map(max.y, 1, 1.0), map(max.z, 2, 1.0));
        crate::geometry::aabb(min, max)
    }
}

/// Sets the boxes of `bvh`'s nodes to the unions of `boxes` (those it was built over, by
/// primitive index) below them, children before parents, NaN coordinates widened to
/// infinity (so that a box with one is always entered rather than never).
pub fn refit(bvh: &mut Bvh2, boxes: &[Aabb]) {
    let widen = |b: &Aabb| {
        let (min, max) = (Vec3::from(b.min), Vec3::from(b.max));
        let min = Vec3::select(min.cmpeq(min), min, Vec3::NEG_INFINITY);
        let max = Vec3::select(max.cmpeq(max), max, Vec3::INFINITY);
        crate::geometry::aabb(min, max)
    };
    for i in parents_first(bvh).into_iter().rev() {
        let n = &bvh.nodes[i as usize];
        let b = if n.is_leaf() {
            (n.first_index..n.first_index + n.prim_count)
                .map(|k| widen(&boxes[bvh.primitive_indices[k as usize] as usize]))
                .reduce(|a, b| a.union(&b))
                .unwrap_or_else(Aabb::empty)
        } else {
            let (l, r) = (n.first_index as usize, n.first_index as usize + 1);
            bvh.nodes[l].aabb().union(bvh.nodes[r].aabb())
        };
        bvh.nodes[i as usize].set_aabb(b);
    }
}

/// A ray prepared for box tests: origin and safe reciprocal direction (no infinities, so
/// `0 * inv` never makes NaN).
#[derive(Clone, Copy, Debug)]
pub struct BoxRay {
    origin: Vec3,
    inv_dir: Vec3,
}

impl BoxRay {
    /// Prepares `ray`.
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        let inv = |x: f32| obvhs::ray::safe_inverse(x);
        BoxRay { origin: ray.origin, inv_dir: Vec3::new(inv(ray.dir.x), inv(ray.dir.y), inv(ray.dir.z)) }
    }

    /// Entry distance into the box within `[t_min, t_max]`, or `None`.
    #[inline]
    pub fn hit(&self, min: Vec3, max: Vec3, t_min: f32, t_max: f32) -> Option<f32> {
        let t1 = (min - self.origin) * self.inv_dir;
        let t2 = (max - self.origin) * self.inv_dir;
        let near = t1.min(t2).max_element().max(t_min);
        let far = t1.max(t2).min_element().min(t_max);
        (near <= far).then_some(near)
    }
}

/// Walks `bvh` front to back, calling `leaf(primitive, t_max, stats)` for each primitive (an index
/// into the boxes the BVH was built from) in every leaf the ray enters before `t_max`.
/// `leaf` returns a new, smaller `t_max` when it finds a closer hit, and `Err(())` to stop
/// the walk (any-hit). Counts visited nodes in `stats.bvh_nodes`.
#[inline]
pub fn traverse(
    bvh: &Bvh2,
    ray: &Ray,
    t_min: f32,
    mut t_max: f32,
    stats: &mut RayStats,
    mut leaf: impl FnMut(u32, f32, &mut RayStats) -> Result<Option<f32>, ()>,
) {
    if bvh.nodes.is_empty() {
        return;
    }
    let br = BoxRay::new(ray);
    let mut stack = [0u32; STACK];
    let mut overflow: Vec<u32> = Vec::new();
    let mut len = 0usize;
    let root = &bvh.nodes[0];
    stats.bvh_nodes += 1;
    if br.hit(root.aabb().min.into(), root.aabb().max.into(), t_min, t_max).is_none() {
        return;
    }
    let mut node = 0u32;
    loop {
        let n = &bvh.nodes[node as usize];
        if n.is_leaf() {
            for i in n.first_index..n.first_index + n.prim_count {
                match leaf(bvh.primitive_indices[i as usize], t_max, stats) {
                    Ok(Some(t)) => t_max = t_max.min(t),
                    Ok(None) => {}
                    Err(()) => return,
                }
            }
        } else {
            let (a, b) = (n.first_index, n.first_index + 1);
            stats.bvh_nodes += 2;
            let na = &bvh.nodes[a as usize];
            let nb = &bvh.nodes[b as usize];
            let ta = br.hit(na.aabb().min.into(), na.aabb().max.into(), t_min, t_max);
            let tb = br.hit(nb.aabb().min.into(), nb.aabb().max.into(), t_min, t_max);
            match (ta, tb) {
                (Some(x), Some(y)) => {
                    let (near, far) = if x <= y { (a, b) } else { (b, a) };
                    if len < STACK {
                        stack[len] = far;
                        len += 1;
                    } else {
                        overflow.push(far);
                    }
                    node = near;
                    continue;
                }
                (Some(_), None) => {
                    node = a;
                    continue;
                }
                (None, Some(_)) => {
                    node = b;
                    continue;
                }
                (None, None) => {}
            }
        }
        // Pop the next node (boxes pushed earlier may now lie beyond t_max; they are
        // re-tested when their children are).
        if let Some(next) = overflow.pop() {
            node = next;
        } else if len > 0 {
            len -= 1;
            node = stack[len];
        } else {
            return;
        }
    }
}

/// Whether `hit(primitive, t_max, stats)` is true for any primitive in a leaf the ray
/// enters before `t_max`; stops at the first (shadow rays).
#[inline]
pub fn traverse_any(
    bvh: &Bvh2,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    stats: &mut RayStats,
    mut hit: impl FnMut(u32, f32, &mut RayStats) -> bool,
) -> bool {
    let mut found = false;
    traverse(bvh, ray, t_min, t_max, stats, |prim, t_max, stats| {
        if hit(prim, t_max, stats) {
            found = true;
            Err(())
        } else {
            Ok(None)
        }
    });
    found
}

/// The smallest `dist(primitive)` over the BVH's primitives for a query at `p`, visiting
/// nodes nearest first and skipping those whose boxes are farther than the best so far
/// (`f64::INFINITY` for an empty BVH). For measurement, not for tracing: it allocates.
pub fn nearest(bvh: &Bvh2, p: glam::DVec3, mut dist: impl FnMut(u32) -> f64) -> f64 {
    use crate::geometry::box_distance;
    let mut best = f64::INFINITY;
    if bvh.nodes.is_empty() {
        return best;
    }
    let mut stack = vec![(0u32, box_distance(bvh.nodes[0].aabb(), p))];
    while let Some((node, d)) = stack.pop() {
        if d >= best {
            continue;
        }
        let n = &bvh.nodes[node as usize];
        if n.is_leaf() {
            for i in n.first_index..n.first_index + n.prim_count {
                best = best.min(dist(bvh.primitive_indices[i as usize]));
            }
            continue;
        }
        let (l, r) = (n.first_index, n.first_index + 1);
        let dl = box_distance(bvh.nodes[l as usize].aabb(), p);
        let dr = box_distance(bvh.nodes[r as usize].aabb(), p);
        // Push the farther first so the nearer is popped first.
        let (near, dn, far, df) = if dl <= dr { (l, dl, r, dr) } else { (r, dr, l, dl) };
        stack.push((far, df));
        stack.push((near, dn));
    }
    best
}

/// The BVH2's nodes (indices), every parent before its children: a depth-first pre-order,
/// right subtree first. Reversed, children come before their parents: the order of the
/// bottom-up passes of the two collapses of a BVH2 into a wide tree (the mesh tracer's
/// [`crate::geometry::mesh::wide_bvh::WideBvh::from_bvh2`] and the nearest-triangle BVH
/// of `convert::mesh_to_grid::closest`). Empty for an empty BVH.
pub fn parents_first(bvh: &Bvh2) -> Vec<u32> {
    let mut order = Vec::with_capacity(bvh.nodes.len());
    if bvh.nodes.is_empty() {
        return order;
    }
    let mut stack = vec![0u32];
    while let Some(i) = stack.pop() {
        order.push(i);
        let n = &bvh.nodes[i as usize];
        if !n.is_leaf() {
            stack.extend([n.first_index, n.first_index + 1]);
        }
    }
    order
}

/// Appends the primitives (entries of `primitive_indices`) of the subtree at `node` to
/// `out`, left subtree first. Iterative: a subtree may be as deep as it has primitives.
pub fn subtree_primitives(bvh: &Bvh2, node: usize, out: &mut Vec<u32>) {
    let leaf = |n: &obvhs::bvh2::node::Bvh2Node, out: &mut Vec<u32>| {
        out.extend((n.first_index..n.first_index + n.prim_count).map(|i| bvh.primitive_indices[i as usize]));
    };
    if bvh.nodes[node].is_leaf() {
        leaf(&bvh.nodes[node], out);
        return;
    }
    let mut stack = vec![node as u32];
    while let Some(i) = stack.pop() {
        let n = &bvh.nodes[i as usize];
        if n.is_leaf() {
            leaf(n, out);
        } else {
            stack.extend([n.first_index + 1, n.first_index]);
        }
    }
}

/// Bytes held by a BVH2: nodes and primitive indices.
pub fn bytes_used(bvh: &Bvh2) -> usize {
    std::mem::size_of::<Bvh2>()
        + bvh.nodes.len() * std::mem::size_of::<obvhs::bvh2::node::Bvh2Node>()
        + bvh.primitive_indices.len() * std::mem::size_of::<u32>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::aabb;

    #[test]
    fn traversal_finds_every_box_a_ray_crosses() {
        // 100 unit boxes along x; a ray along x crosses all, a ray above crosses none.
        let boxes: Vec<Aabb> = (0..100)
            .map(|i| aabb(Vec3::new(i as f32 * 2.0, 0.0, 0.0), Vec3::new(i as f32 * 2.0 + 1.0, 1.0, 1.0)))
            .collect();
        let bvh = build(&boxes, BvhBuildParams::medium_build());
        let mut seen = [false; 100];
        let mut stats = RayStats::default();
        let ray = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X);
        traverse(&bvh, &ray, 0.0, f32::INFINITY, &mut stats, |p, _, _| {
            seen[p as usize] = true;
            Ok(None)
        });
        assert!(seen.iter().all(|&s| s));
        let mut any = false;
        let ray = Ray::new(Vec3::new(-1.0, 2.5, 0.5), Vec3::X);
        traverse(&bvh, &ray, 0.0, f32::INFINITY, &mut stats, |_, _, _| {
            any = true;
            Ok(None)
        });
        assert!(!any);
        // Closest-first: shrinking t_max to the first box prunes the rest.
        let mut calls = 0;
        let ray = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X);
        traverse(&bvh, &ray, 0.0, f32::INFINITY, &mut stats, |p, _, _| {
            calls += 1;
            Ok(Some(1.0 + 2.0 * p as f32))
        });
        assert!(calls < 10, "{calls}");
        assert!(stats.bvh_nodes > 0);
    }
    /// Depth of a BVH2 (root = 1), iteratively.
    fn depth(bvh: &Bvh2) -> usize {
        let mut deepest = 0;
        let mut stack = vec![(0usize, 1usize)];
        while let Some((i, d)) = stack.pop() {
            deepest = deepest.max(d);
            let n = &bvh.nodes[i];
            if !n.is_leaf() {
                stack.extend([(n.first_index as usize, d + 1), (n.first_index as usize + 1, d + 1)]);
            }
        }
        deepest
    }

    #[test]
    fn build_frame_only_for_extreme_or_non_finite_boxes() {
        let unit = |c: f32, s: f32| aabb(Vec3::splat(c), Vec3::splat(c + s));
        assert_eq!(BuildFrame::for_boxes(&[unit(0.0, 1.0), unit(5.0, 1.0)]), None);
        assert_eq!(BuildFrame::for_boxes(&[unit(1e30, 1.0)]), None, "far but small: as it is");
        assert!(BuildFrame::for_boxes(&[unit(0.0, 1e-30), unit(1e-30, 1e-30)]).is_some());
        assert!(BuildFrame::for_boxes(&[unit(-1e20, 1.0), unit(1e20, 1.0)]).is_some());
        assert!(
            BuildFrame::for_boxes(&[unit(0.0, 1.0), aabb(Vec3::ZERO, Vec3::splat(f32::INFINITY))]).is_some()
        );
        let f = BuildFrame::for_boxes(&[unit(0.0, 1e-30), unit(3e-30, 1e-30)]).unwrap();
        let b = f.apply(&unit(3e-30, 1e-30));
        assert!(Vec3::from(b.max - b.min).min_element() > 0.1, "{b:?}");
    }

    /// Boxes whose f32 areas overflow or underflow, infinite and NaN boxes, and boxes
    /// flat on one axis and infinite on another (a NaN area): the build does not panic,
    /// stays shallow, and its boxes contain every primitive's (NaN widened to infinity).
    #[test]
    fn builds_over_extreme_and_non_finite_boxes() {
        for scale in [1e-30f32, 1e-19, 1e19, 1e30] {
            let boxes: Vec<Aabb> = (0..4000)
                .map(|i| {
                    let c = Vec3::new((i % 20) as f32, (i / 20 % 20) as f32, (i / 400) as f32) * scale;
                    aabb(c, c + Vec3::splat(0.5 * scale))
                })
                .collect();
            let bvh = build(&boxes, BvhBuildParams::medium_build());
            assert!(depth(&bvh) < 40, "scale {scale:e}: depth {}", depth(&bvh));
            // A ray along the first row crosses its 20 boxes.
            let mut seen = 0;
            let ray = Ray::new(Vec3::new(-1.0, 0.25, 0.25) * scale, Vec3::X);
            traverse(&bvh, &ray, 0.0, f32::INFINITY, &mut RayStats::default(), |p, _, _| {
                seen += usize::from(p < 20);
                Ok(None)
            });
            assert_eq!(seen, 20, "scale {scale:e}");
        }
        let inf = f32::INFINITY;
        let mut boxes = vec![
            aabb(Vec3::new(-inf, 0.0, 0.0), Vec3::new(inf, 0.0, 1.0)),
            aabb(Vec3::splat(-inf), Vec3::splat(inf)),
            aabb(Vec3::splat(f32::NAN), Vec3::splat(f32::NAN)),
            aabb(Vec3::splat(inf), Vec3::splat(inf)),
        ];
        boxes.extend((0..100).map(|i| aabb(Vec3::splat(i as f32), Vec3::splat(i as f32 + 0.5))));
        let bvh = build(&boxes, BvhBuildParams::medium_build());
        let mut prims = Vec::new();
        subtree_primitives(&bvh, 0, &mut prims);
        prims.sort_unstable();
        assert_eq!(prims, (0..boxes.len() as u32).collect::<Vec<_>>());
        // The NaN box is widened to everything: every ray visits it.
        let mut found = false;
        let ray = Ray::new(Vec3::splat(-5.0), Vec3::Y);
        traverse(&bvh, &ray, 0.0, f32::INFINITY, &mut RayStats::default(), |p, _, _| {
            found |= p == 2;
            Ok(None)
        });
        assert!(found);
    }
}
