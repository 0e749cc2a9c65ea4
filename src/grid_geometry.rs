//! Discrete SDF grids in the tracer: sphere tracing of the trilinear interpolation of a
//! [`SdfGrid`] inside its box, with the same tolerance, step limit, refinement and
//! over-relaxation as analytic SDFs, and normals from the interpolated field's gradient.

use glam::{DVec3, Vec3};

use crate::geometry::{
    Aabb, Census, Geometry, Hit, MaterialId, Ray, RayStats, aabb, box_distance, distance_by_projection,
    f32_error, max_abs,
};
use crate::grid::SdfGrid;
use crate::march::{MarchHit, MarchParams, gradient_normal, march_ray};

/// Steps are scaled by this factor: the trilinear interpolation of exact distance samples
/// can be slightly steeper than 1 between samples, so a full step could overshoot.
pub const GRID_STEP_SCALE: f64 = 0.9;

/// A signed distance grid ready for tracing (world space).
pub struct GridObject {
    grid: SdfGrid,
    bounds: Aabb,
    size: f64,
    material: MaterialId,
    march: MarchParams,
    label: String,
}

impl GridObject {
    /// Wraps `grid` (world-space samples) with a material.
    pub fn new(grid: SdfGrid, material: MaterialId, march: MarchParams, label: String) -> Self {
        let (lo, hi) = grid.bounds();
        let size = (hi - lo).length() as f64;
        GridObject { bounds: aabb(lo, hi), grid, size, material, march, label }
    }

    /// The grid.
    pub fn grid(&self) -> &SdfGrid {
        &self.grid
    }

    fn distance(&self, p: DVec3) -> f64 {
        self.grid.trilinear(p.as_vec3()) as f64 * GRID_STEP_SCALE
    }

    fn march(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<MarchHit> {
        let f = |p: DVec3| self.distance(p);
        march_ray(&f, ray, Some(&self.bounds), t_min, t_max, self.size, &self.march, true, stats)
    }
}

impl Geometry for GridObject {
    fn bounds(&self) -> Option<Aabb> {
        Some(self.bounds)
    }

    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        let MarchHit { t, residual } = self.march(ray, t_min, t_max, stats)?;
        let p = ray.origin.as_dvec3() + ray.dir.as_dvec3() * t;
        let eps = self.march.tolerance(t, self.size).max(residual);
        // Half a voxel: the interpolant is piecewise, so smaller steps see cell seams.
        let f = |q: DVec3| self.distance(q);
        let normal = gradient_normal(&f, p, 0.5 * self.grid.voxel as f64, stats).as_vec3();
        let point: Vec3 = p.as_vec3();
        Some(Hit {
            t: t as f32,
            point,
            normal,
            shading_normal: normal,
            material: self.material,
            error: 4.0 * eps as f32 + f32_error(max_abs(point)),
        })
    }

    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        self.march(ray, t_min, t_max, stats).is_some()
    }

    fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.grid.bytes_used() - std::mem::size_of::<SdfGrid>()
            + self.label.capacity()
    }

    fn census(&self) -> Census {
        Census { triangles: 0, grid_samples: self.grid.values.len() as u64, accel_bytes: 0 }
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        // Outside the box the field is undefined: measure from the nearest box point.
        let outside = box_distance(&self.bounds, p);
        let (lo, hi) = (self.bounds.min.as_dvec3(), self.bounds.max.as_dvec3());
        let q = p.clamp(lo, hi);
        let f = |x: DVec3| self.grid.trilinear(x.as_vec3()) as f64;
        let h = 0.25 * self.grid.voxel as f64;
        outside + distance_by_projection(&f, q, h, 1e-6 * self.size)
    }

    fn describe(&self) -> String {
        let d = self.grid.dims;
        format!(
            "{}: grid {}x{}x{} samples, voxel {:.5}, ray marched",
            self.label, d.x, d.y, d.z, self.grid.voxel
        )
    }
}
