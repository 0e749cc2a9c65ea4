//! Axis-aligned boxes: obvhs's [`Aabb`] (the box the BVHs store) and the few helpers the
//! crate builds and measures boxes with.

use glam::{DVec3, Vec3, Vec3A};
pub use obvhs::aabb::Aabb;

/// Distance from `p` to the box `b` (0 inside).
#[inline]
pub fn box_distance(b: &Aabb, p: DVec3) -> f64 {
    let lo = DVec3::new(b.min.x as f64, b.min.y as f64, b.min.z as f64);
    let hi = DVec3::new(b.max.x as f64, b.max.y as f64, b.max.z as f64);
    (lo - p).max(p - hi).max(DVec3::ZERO).length()
}

/// Converts a glam `Vec3` into obvhs's `Vec3A`.
#[inline]
pub fn to_a(v: Vec3) -> Vec3A {
    Vec3A::from(v)
}

/// An empty-or-not box from two corners.
#[inline]
pub fn aabb(min: Vec3, max: Vec3) -> Aabb {
    Aabb::new(to_a(min), to_a(max))
}
