//! An implicit `.vm` model in the tracer: its surface found along each ray by
//! [`Field3::first_root`] (steps of value / proven Lipschitz bound, interval root isolation
//! where no bound is proven; never a step on the value alone), the normal from the
//! model's gradient (central differences), placed by the object's transform. The model is
//! seen inside the cube [-1, 1]^3 of its own frame, as Fidget frames it.

use std::cell::RefCell;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use glam::{DVec3, Vec3};

use crate::geometry::march::MarchParams;
use crate::geometry::{Aabb, Census, Geometry, Hit, MaterialId, Ray, RayStats, aabb, f32_error, max_abs};
use crate::implicit::field3d::{EXTENT, Field3, RayWork, Scratch};
use crate::scene::transform::Transform;

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// A placed implicit model.
pub struct ImplicitObject {
    field: Arc<Field3>,
    transform: Transform,
    material: MaterialId,
    march: MarchParams,
    bounds: Aabb,
    label: String,
    work: [AtomicU64; 4],
}

impl ImplicitObject {
    /// `field` placed by `transform`, with `material`; hit tolerance from `march`
    /// ([`MarchParams::tolerance`]).
    pub fn new(
        field: Arc<Field3>,
        transform: Transform,
        material: MaterialId,
        march: MarchParams,
        label: String,
    ) -> Self {
        let cube = aabb(Vec3::splat(-EXTENT as f32), Vec3::splat(EXTENT as f32));
        let bounds = transform.box_to_world(&cube);
        ImplicitObject { field, transform, material, march, bounds, label, work: Default::default() }
    }

    /// The model.
    pub fn field(&self) -> &Field3 {
        &self.field
    }

    /// The work of every ray traced so far (interval and point evaluations, Lipschitz
    /// steps, ambiguous leaves).
    pub fn work(&self) -> RayWork {
        let [a, b, c, d] = &self.work;
        RayWork {
            interval_evals: a.load(Ordering::Relaxed),
            point_evals: b.load(Ordering::Relaxed),
            lipschitz_steps: c.load(Ordering::Relaxed),
            ambiguous_leaves: d.load(Ordering::Relaxed),
        }
    }

    fn record(&self, w: &RayWork, stats: &mut RayStats) {
        stats.marched_rays += 1;
        stats.march_steps += w.point_evals;
        stats.interval_evals += w.interval_evals;
        for (a, v) in
            self.work.iter().zip([w.interval_evals, w.point_evals, w.lipschitz_steps, w.ambiguous_leaves])
        {
            if v > 0 {
                a.fetch_add(v, Ordering::Relaxed);
            }
        }
    }

    /// The hit tolerance `tol0 + tol1 t` along `ray` ([`MarchParams::tolerance`] with the
    /// ray's spread, for an object of the cube's size).
    fn tolerance(&self, ray: &Ray) -> (f64, f64) {
        let e = self.march.epsilon.min(self.march.tolerance_px * self.march.pixel_footprint);
        let size = 2.0 * EXTENT * self.transform.max_scale as f64;
        (e * (ray.spread as f64 + 1e-4 * size), e)
    }
}

impl Geometry for ImplicitObject {
    fn bounds(&self) -> Option<Aabb> {
        Some(self.bounds)
    }

    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        let (o, d) = self.transform.ray_to_local_f64(ray);
        let (tol0, tol1) = self.tolerance(ray);
        let mut w = RayWork::default();
        let found = SCRATCH.with(|s| {
            let s = &mut *s.borrow_mut();
            let root = self.field.first_root(o, d, t_min as f64, t_max as f64, tol0, tol1, s, &mut w)?;
            let local = o + d * root.t;
            let n = match root.face {
                Some(face) => face,
                None => {
                    w.point_evals += 6;
                    let g = self.field.gradient(local, 1e-6, s);
                    if g.is_finite() && g.length_squared() > 0.0 { g } else { -d }
                }
            };
            Some((root, n))
        });
        self.record(&w, stats);
        let (root, n) = found?;
        let t = root.t as f32;
        let point = ray.origin + ray.dir * t;
        let normal = self.transform.normal_to_world(n.as_vec3());
        let normal = if normal.is_finite() { normal } else { -ray.dir };
        let error = f32_error(max_abs(point)) + (root.error as f32) * 2.0;
        Some(Hit { t, point, normal, shading_normal: normal, material: self.material, error })
    }

    fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.field.bytes_used() + self.label.capacity()
    }

    fn describe(&self) -> String {
        format!(
            "implicit '{}': {}; traced by value / proven Lipschitz bound where there is one, interval root \
             isolation along the ray elsewhere",
            self.label,
            self.field.summary.describe()
        )
    }

    fn census(&self) -> Census {
        Census::default()
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        let local = self.transform.point_to_local_f64(p);
        let f = |q: DVec3| SCRATCH.with(|s| self.field.value(q, &mut s.borrow_mut()));
        crate::geometry::distance_by_projection(&f, local, 1e-6, 1e-9) * self.transform.min_scale as f64
    }
}
