//! The one geometry interface the tracer sees: hits, work counters and the [`Geometry`]
//! trait that every representation (closed form, analytic SDF, SDF grid, triangle mesh)
//! implements, over the rays and boxes of [`crate::base`] (re-exported here). The tracer
//! never learns which representation it traces.

pub mod analytic;
pub mod bvh2;
pub mod grid;
pub mod implicit;
pub mod march;
pub mod marched;
pub mod mesh;
pub mod scene;
pub mod sdf;

use glam::{DVec3, Vec3};

pub use crate::base::{Aabb, MaterialId, Ray, aabb, box_distance, to_a};

/// Rays per packet: the width of an 8-wide f32 evaluation, the lanes a marched field runs
/// side by side in [`Geometry::closest_hits`].
pub const PACKET: usize = 8;

/// [`Geometry::closest_hits`] as a loop of [`Geometry::closest_hit`] over the batch's rays:
/// the trait's default, and what an aggregate falls back to.
pub fn closest_hits_one_by_one<G: Geometry + ?Sized>(
    g: &G,
    rays: &[Ray],
    t_min: f32,
    t_max: &mut [f32],
    hits: &mut [Option<Hit>],
    stats: &mut RayStats,
) {
    for ((ray, t_max), hit) in rays.iter().zip(t_max.iter_mut()).zip(hits.iter_mut()) {
        if let Some(h) = g.closest_hit(ray, t_min, *t_max, stats) {
            *t_max = h.t;
            *hit = Some(h);
        }
    }
}

/// [`Geometry::any_hits`] as a loop of [`Geometry::any_hit`] over the batch's rays not
/// yet occluded: the trait's default, and what an aggregate falls back to.
pub fn any_hits_one_by_one<G: Geometry + ?Sized>(
    g: &G,
    rays: &[Ray],
    t_min: f32,
    t_max: &[f32],
    occluded: &mut [bool],
    stats: &mut RayStats,
) {
    for ((ray, &t_max), occluded) in rays.iter().zip(t_max).zip(occluded.iter_mut()) {
        if !*occluded {
            *occluded = g.any_hit(ray, t_min, t_max, stats);
        }
    }
}

/// A ray/surface intersection in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit (distance along a unit world ray).
    pub t: f32,
    /// Hit point, world space.
    pub point: Vec3,
    /// Unit geometric surface normal pointing out of the solid (for open surfaces such as a
    /// triangle, an arbitrary but consistent side). Decides which side the ray is on and
    /// where spawned rays start; the tracer flips it to face the ray.
    pub normal: Vec3,
    /// Unit normal used for shading: equal to `normal` except for smoothly shaded meshes,
    /// whose interpolated vertex normals may lean away from the facet's.
    pub shading_normal: Vec3,
    /// Material of the surface at the hit.
    pub material: MaterialId,
    /// Absolute bound on the error of `point` (scene units). Spawned rays start at least
    /// this far off the surface so they do not hit it again.
    pub error: f32,
}

/// Work counters, one per thread, summed at the end of a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayStats {
    /// Rays cast of every kind (camera, shadow, reflection, refraction).
    pub rays: u64,
    /// Shadow rays among `rays`.
    pub shadow_rays: u64,
    /// Distance-function evaluations made while sphere tracing / ray marching.
    pub march_steps: u64,
    /// Rays that started a march (so `march_steps / marched_rays` is steps per marched ray).
    pub marched_rays: u64,
    /// Marches that ended because they ran out of steps (reported, never hidden).
    pub step_limit_hits: u64,
    /// BVH nodes visited (top-level and per-mesh).
    pub bvh_nodes: u64,
    /// Closed-form primitive intersection tests.
    pub prim_tests: u64,
    /// Interval evaluations of implicit models (a piece of a ray each), beside their point
    /// evaluations in `march_steps`.
    pub interval_evals: u64,
}

impl RayStats {
    /// Adds `other` into `self`.
    pub fn add(&mut self, other: &RayStats) {
        self.rays += other.rays;
        self.shadow_rays += other.shadow_rays;
        self.march_steps += other.march_steps;
        self.marched_rays += other.marched_rays;
        self.step_limit_hits += other.step_limit_hits;
        self.bvh_nodes += other.bvh_nodes;
        self.prim_tests += other.prim_tests;
        self.interval_evals += other.interval_evals;
    }
}

/// The interface every representation implements. All methods take world-space rays
/// with unit directions and report world-space results.
pub trait Geometry: Send + Sync {
    /// A conservative world-space bounding box, or `None` for unbounded geometry
    /// (infinite planes, unbounded repetition).
    fn bounds(&self) -> Option<Aabb>;

    /// The closest hit with `t` in `[t_min, t_max]`, if any.
    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit>;

    /// The closest hits of a batch of rays (any number; the tracer hands over a tile's
    /// primary rays, packets of [`PACKET`] neighbours one after the other): for each ray
    /// `i`, a hit with `t` in `[t_min, t_max[i]]` nearer than any found so far replaces
    /// `hits[i]` and lowers `t_max[i]` to its `t`, so calls over several geometries compose
    /// into the nearest hit. Every ray's result is the one [`Self::closest_hit`] gives for
    /// that ray alone (the contract suite checks it); the default is exactly that loop, and
    /// marched fields override it to evaluate their distance for eight points at once.
    /// `rays`, `t_max` and `hits` have the same length.
    fn closest_hits(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &mut [f32],
        hits: &mut [Option<Hit>],
        stats: &mut RayStats,
    ) {
        closest_hits_one_by_one(self, rays, t_min, t_max, hits, stats);
    }

    /// Whether [`Self::closest_hits`] is faster than its rays one by one (true for marched
    /// fields); an aggregate marches packets only through geometries that say so.
    fn prefers_packets(&self) -> bool {
        false
    }

    /// Whether any surface is hit with `t` in `[t_min, t_max]` (shadow rays). May stop at
    /// the first hit found.
    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        self.closest_hit(ray, t_min, t_max, stats).is_some()
    }

    /// [`Self::any_hit`] for a batch of rays (any number: the shadow rays of a tile's
    /// primary hits towards one light): each ray not yet `occluded` becomes occluded when
    /// [`Self::any_hit`] would say so for that ray alone, so calls over several geometries
    /// compose. The default is that loop; marched fields override it to evaluate their
    /// distance for eight points at once. `rays`, `t_max` and `occluded` have the same
    /// length.
    fn any_hits(&self, rays: &[Ray], t_min: f32, t_max: &[f32], occluded: &mut [bool], stats: &mut RayStats) {
        any_hits_one_by_one(self, rays, t_min, t_max, occluded, stats);
    }

    /// Bytes of memory this geometry holds (its own struct and everything it owns).
    fn bytes_used(&self) -> usize;

    /// A short human-readable description of how this geometry is traced, e.g.
    /// `"closed form"` or `"sphere traced (no closed form for union)"`.
    fn describe(&self) -> String;

    /// What the geometry stores, for measurement tables.
    fn census(&self) -> Census;

    /// Unsigned distance from `p` to this geometry's surface, scene units: exact or an
    /// upper bound (the distance to a point on the surface). For measuring geometric error,
    /// not for tracing: it may be slow and is not counted in any work counter.
    fn surface_distance(&self, p: DVec3) -> f64;

    /// Data this geometry may share with other geometries (a mesh and its BVH placed
    /// several times), counted in its own `bytes_used` and `census`; a scene counts each
    /// `id` once. `None`: nothing shared.
    fn shared(&self) -> Option<Shared> {
        None
    }

    /// The separately placed instances this geometry consists of (the copies of a
    /// repetition), which a scene puts one by one under its top-level BVH; empty when the
    /// geometry is one piece.
    fn instances(&self) -> &[mesh::MeshGeometry] {
        &[]
    }

    /// This geometry as one placed triangle mesh, where it is one (the rasterizer draws
    /// it); `None` for every other geometry.
    fn as_mesh(&self) -> Option<&mesh::MeshGeometry> {
        None
    }
}

/// Data shared between geometries (see [`Geometry::shared`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shared {
    /// Identifies the shared data (its address while it lives).
    pub id: usize,
    /// Its bytes, part of each sharer's `bytes_used`.
    pub bytes: usize,
    /// What it stores, part of each sharer's `census`.
    pub census: Census,
}

impl Shared {
    /// The data behind `arc`, identified by its address, with its `bytes` and `census`.
    pub fn of<T>(arc: &std::sync::Arc<T>, bytes: usize, census: Census) -> Shared {
        Shared { id: std::sync::Arc::as_ptr(arc) as usize, bytes, census }
    }
}

/// What a geometry stores. `bytes_used() - accel_bytes` is the geometry itself.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Census {
    /// Triangles stored.
    pub triangles: u64,
    /// Distance samples stored in grids.
    pub grid_samples: u64,
    /// Bytes of acceleration structures (BVH nodes and index arrays), part of `bytes_used`.
    pub accel_bytes: u64,
}

impl std::ops::Sub for Census {
    type Output = Census;

    fn sub(self, o: Census) -> Census {
        Census {
            triangles: self.triangles - o.triangles,
            grid_samples: self.grid_samples - o.grid_samples,
            accel_bytes: self.accel_bytes - o.accel_bytes,
        }
    }
}

impl std::ops::Add for Census {
    type Output = Census;

    fn add(self, o: Census) -> Census {
        Census {
            triangles: self.triangles + o.triangles,
            grid_samples: self.grid_samples + o.grid_samples,
            accel_bytes: self.accel_bytes + o.accel_bytes,
        }
    }
}

/// Distance from `p` to the zero set of the field `f` by projection: Newton steps
/// `q -= f(q) grad f(q) / |grad f(q)|^2` (central differences of step `h`) until `|f(q)|`
/// is below `tol`; returns `|p - q|`, an upper bound on the true distance when `q`
/// converged onto the surface (exact in one step for exact distance fields), or `|f(p)|`
/// when it did not converge or the gradient vanished.
pub fn distance_by_projection(f: &dyn Fn(DVec3) -> f64, p: DVec3, h: f64, tol: f64) -> f64 {
    let mut q = p;
    for _ in 0..16 {
        let d = f(q);
        if d.abs() <= tol {
            return (p - q).length();
        }
        let g = DVec3::new(
            f(q + DVec3::X * h) - f(q - DVec3::X * h),
            f(q + DVec3::Y * h) - f(q - DVec3::Y * h),
            f(q + DVec3::Z * h) - f(q - DVec3::Z * h),
        ) / (2.0 * h);
        let g2 = g.length_squared();
        if !(g2 > 1e-12) || !g2.is_finite() {
            break;
        }
        q -= g * (d / g2);
    }
    f(p).abs()
}

/// The largest absolute coordinate of `p`: the magnitude that f32 rounding error scales with.
#[inline]
pub fn max_abs(p: Vec3) -> f32 {
    p.abs().max_element()
}

/// A bound on the rounding error of an f32 point of magnitude `m` after the few operations
/// that compute a hit point (floored at magnitude 1e-3, so points at the origin still get
/// a usable offset).
#[inline]
pub fn f32_error(m: f32) -> f32 {
    32.0 * f32::EPSILON * m.max(1e-3)
}
