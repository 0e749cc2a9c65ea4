//! Rays: a ray `origin + t * dir` with the length of the path that led to it, and its
//! clipping to a box.

use glam::Vec3;

use crate::base::Aabb;

/// A ray `origin + t * dir`. World-space rays have a unit `dir`, so `t` is a distance in
/// scene units; rays transformed into an object's local frame keep the same `t`
/// (their direction is not renormalised).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point, scene units.
    pub origin: Vec3,
    /// Direction; unit length for world-space rays.
    pub dir: Vec3,
    /// Length of the path from the camera to `origin` (scene units, >= 0): 0 for a camera
    /// ray, the parent's `spread` plus its hit distance for a shadow, reflection or
    /// refraction ray. A pixel's footprint at parameter `t` is that of `spread + t` from
    /// the camera (the ray cone of a flat mirror), so a marcher's hit tolerance, which
    /// scales with the footprint (geometry's `MarchParams::tolerance`), uses `spread + t`:
    /// a shadow ray need not resolve its occluder more finely than the pixel it shades.
    pub spread: f32,
}

impl Ray {
    /// A camera ray from `origin` along `dir` (not normalised here), `spread` 0.
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Ray { origin, dir, spread: 0.0 }
    }

    /// A ray spawned at the end of a path of length `spread` (see [`Ray::spread`]).
    #[inline]
    pub fn spawned(origin: Vec3, dir: Vec3, spread: f32) -> Self {
        Ray { origin, dir, spread }
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// The parametric interval `[t0, t1]` in which the ray is inside `b` (clipped to
    /// `[t_min, t_max]`), or `None`. Robust to zero direction components: a ray parallel
    /// to a slab is inside it for all `t` or for none, never NaN.
    #[inline]
    pub fn clip_to_box(&self, b: &Aabb, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
        let mut t0 = t_min;
        let mut t1 = t_max;
        for axis in 0..3 {
            let o = self.origin[axis];
            let d = self.dir[axis];
            let (lo, hi) = (b.min[axis], b.max[axis]);
            if d == 0.0 {
                if o < lo || o > hi {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / d;
            let (mut ta, mut tb) = ((lo - o) * inv, (hi - o) * inv);
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            // max/min written so that a NaN (inf * 0 cannot occur here, but be safe) never widens.
            if ta > t0 {
                t0 = ta;
            }
            if tb < t1 {
                t1 = tb;
            }
            if t0 > t1 {
                return None;
            }
        }
        Some((t0, t1))
    }
}
