//! BVH traversal over obvhs's `Bvh2` with work counting: closest-hit and any-hit walks
//! that call back for each primitive in a visited leaf, visiting near children first, and
//! the nearest-first distance walk ([`nearest`]). Used for the scene's top-level BVH over
//! objects; meshes trace the 8-wide BVH of [`crate::geometry::mesh::wide_bvh`], collapsed
//! from a BVH2 built here (the traversal orders both wide-tree collapses share,
//! [`parents_first`] and [`subtree_primitives`], are here too).

use std::time::Duration;

use glam::Vec3;
use obvhs::BvhBuildParams;
use obvhs::bvh2::Bvh2;
use obvhs::bvh2::builder::build_bvh2;

use crate::geometry::{Aabb, Ray, RayStats};

/// Deepest traversal stack supported; deeper BVHs fall back to a heap stack.
const STACK: usize = 64;

/// Builds a BVH2 over boxes with obvhs's PLOC builder.
pub fn build(boxes: &[Aabb], params: BvhBuildParams) -> Bvh2 {
    build_bvh2(boxes, params, &mut Duration::default())
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
/// `out`, left subtree first.
pub fn subtree_primitives(bvh: &Bvh2, node: usize, out: &mut Vec<u32>) {
    let n = &bvh.nodes[node];
    if n.is_leaf() {
        out.extend((n.first_index..n.first_index + n.prim_count).map(|i| bvh.primitive_indices[i as usize]));
    } else {
        subtree_primitives(bvh, n.first_index as usize, out);
        subtree_primitives(bvh, n.first_index as usize + 1, out);
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
}
