//! The Whitted ray tracer, one implementation for every representation: ambient +
//! Lambert + Phong with light colours, one hard shadow ray per light, recursive mirror
//! reflection and Snell refraction with total internal reflection, a depth limit and a
//! cut-off for negligible contributions. It sees geometry only through [`Geometry`].

use glam::Vec3;

use crate::geometry::{Geometry, Hit, Ray, RayStats, max_abs};
use crate::scene::{Light, Material, Scene};

/// Contributions weighing less than this (a fraction of the pixel) are not traced.
pub const MIN_CONTRIBUTION: f32 = 1.0 / 512.0;

/// Lights whose shadow rays [`Tracer::trace_batch`] traces as batches; the shadow rays of
/// any further lights are traced one by one.
pub const PACKET_LIGHTS: usize = 8;

/// The most shadow rays [`Tracer::trace_batch`] hands to one [`Geometry::any_hits`] call:
/// the rays of two lights of a full batch.
const SHADOW_BATCH: usize = 2 * BATCH;

/// The most primary rays [`Tracer::trace_batch`] takes at once: a 16 x 16 pixel tile.
pub const BATCH: usize = 256;

/// Traces rays through one scene and geometry.
pub struct Tracer<'a> {
    scene: &'a Scene,
    geometry: &'a dyn Geometry,
    ambient: f32,
    /// Whether any of the first [`PACKET_LIGHTS`] lights casts shadow rays (any but the
    /// ambient light): else [`Tracer::trace_batch`] traces none.
    casts_shadows: bool,
}

/// How far to move a spawned ray's origin off the surface: the hit's own error bound,
/// but never less than what f32 rounding at the point's magnitude needs.
#[inline]
pub fn spawn_offset(hit: &Hit) -> f32 {
    2.0 * hit.error.max(64.0 * f32::EPSILON * max_abs(hit.point).max(1e-3))
}

impl<'a> Tracer<'a> {
    /// A tracer for `scene` rendered with `geometry`.
    pub fn new(scene: &'a Scene, geometry: &'a dyn Geometry) -> Self {
        let ambient = scene
            .lights
            .iter()
            .map(|l| if let Light::Ambient { intensity } = l { *intensity } else { 0.0 })
            .sum();
        let casts_shadows =
            scene.lights.iter().take(PACKET_LIGHTS).any(|l| !matches!(l, Light::Ambient { .. }));
        Tracer { scene, geometry, ambient, casts_shadows }
    }

    /// The colour seen along `ray` (unit direction), linear RGB, not clamped.
    pub fn trace(&self, ray: &Ray, stats: &mut RayStats) -> Vec3 {
        self.trace_rec(ray, self.scene.settings.max_depth, 1.0, stats)
    }

    /// The colours seen along a batch of up to [`BATCH`] primary rays (a tile's, packets
    /// of neighbours one after the other): their closest hits found together
    /// ([`Geometry::closest_hits`]), then the shadow rays of those hits towards each of the
    /// first [`PACKET_LIGHTS`] lights together ([`Geometry::any_hits`]), then each hit
    /// shaded as [`Self::trace`] does (further shadow rays and secondary rays one by one).
    /// `out[i]` is exactly `trace(&rays[i])`.
    pub fn trace_batch(&self, rays: &[Ray], out: &mut [Vec3], stats: &mut RayStats) {
        debug_assert!(rays.len() <= BATCH && out.len() == rays.len());
        let n = rays.len().min(BATCH);
        let mut t_max = [self.scene.settings.max_distance; BATCH];
        let mut hits: [Option<Hit>; BATCH] = [None; BATCH];
        stats.rays += n as u64;
        self.geometry.closest_hits(&rays[..n], 0.0, &mut t_max[..n], &mut hits[..n], stats);
        self.shade_hits(&rays[..n], &hits[..n], out, stats);
    }

    /// The colours of a batch of up to [`BATCH`] primary rays whose closest hits are known
    /// (`hits[i]` of `rays[i]`; found by [`Self::trace_batch`], or by a rasterizer): the
    /// shadow rays of the first [`PACKET_LIGHTS`] lights together, then each hit shaded as
    /// [`Self::trace`] does. Counts no primary ray (the caller does).
    pub fn shade_hits(&self, rays: &[Ray], hits: &[Option<Hit>], out: &mut [Vec3], stats: &mut RayStats) {
        debug_assert!(rays.len() <= BATCH && out.len() == rays.len() && hits.len() == rays.len());
        let n = rays.len().min(BATCH);
        // occluded[i][l]: whether hit i's shadow ray towards light l is blocked (only read
        // where that ray exists, i.e. where the light is in front of the surface).
        let mut occluded = [[false; PACKET_LIGHTS]; BATCH];
        // Shadow rays only towards lights that cast them, and only from hits.
        let shadows = self.casts_shadows && hits[..n].iter().any(Option::is_some);
        if shadows {
            self.batch_shadows(&rays[..n], &hits[..n], &mut occluded, stats);
        }
        let depth = self.scene.settings.max_depth;
        for i in 0..n {
            out[i] = match &hits[i] {
                Some(hit) => self.shade(&rays[i], hit, depth, 1.0, Some(&occluded[i]), stats),
                None => self.scene.settings.background,
            };
        }
    }

    /// The shadow rays of a batch's hits towards each of the first [`PACKET_LIGHTS`] lights
    /// that cast shadows, traced together ([`Geometry::any_hits`]; the rays of two lights
    /// in one call where they fit in [`SHADOW_BATCH`], so that fewer calls end with lanes
    /// idle): sets `occluded[i][l]` where hit `i`'s ray towards light `l` is blocked.
    fn batch_shadows(
        &self,
        rays: &[Ray],
        hits: &[Option<Hit>],
        occluded: &mut [[bool; PACKET_LIGHTS]; BATCH],
        stats: &mut RayStats,
    ) {
        let n = rays.len().min(BATCH);
        let frames: [Option<SurfaceFrame>; BATCH] =
            std::array::from_fn(|i| hits.get(i).and_then(|h| h.as_ref()).map(|h| surface_frame(&rays[i], h)));
        let mut shadow = [Ray::new(Vec3::ZERO, Vec3::Z); SHADOW_BATCH];
        let mut reach = [0.0f32; SHADOW_BATCH];
        // Ray j is hit `of[j].0`'s towards light `of[j].1`.
        let mut of = [(0usize, 0usize); SHADOW_BATCH];
        let mut m = 0;
        let mut flush = |shadow: &[Ray], reach: &[f32], of: &[(usize, usize)], stats: &mut RayStats| {
            let blocked = &mut [false; SHADOW_BATCH][..shadow.len()];
            if !shadow.is_empty() {
                self.geometry.any_hits(shadow, 0.0, reach, blocked, stats);
            }
            for (&(i, l), &b) in of.iter().zip(blocked.iter()) {
                occluded[i][l] = b;
            }
        };
        for (l, light) in self.scene.lights.iter().take(PACKET_LIGHTS).enumerate() {
            if matches!(light, Light::Ambient { .. }) {
                continue;
            }
            if m + n > SHADOW_BATCH {
                flush(&shadow[..m], &reach[..m], &of[..m], stats);
                m = 0;
            }
            for (i, frame) in frames.iter().enumerate().take(n) {
                let Some(f) = frame else { continue };
                let Some((to_light, dist, ..)) = self.light_towards(light, f.above) else { continue };
                if f.n.dot(to_light) > 0.0 {
                    (shadow[m], reach[m], of[m]) = (Ray::spawned(f.above, to_light, f.spread), dist, (i, l));
                    m += 1;
                }
            }
        }
        flush(&shadow[..m], &reach[..m], &of[..m], stats);
    }

    fn trace_rec(&self, ray: &Ray, depth: u32, weight: f32, stats: &mut RayStats) -> Vec3 {
        stats.rays += 1;
        match self.geometry.closest_hit(ray, 0.0, self.scene.settings.max_distance, stats) {
            Some(hit) => self.shade(ray, &hit, depth, weight, None, stats),
            None => self.scene.settings.background,
        }
    }

    /// The direction towards `light` from `from`, the distance a shadow ray goes, and the
    /// light's intensity and colour; `None` for the ambient light and a point light at
    /// `from` itself.
    fn light_towards(&self, light: &Light, from: Vec3) -> Option<(Vec3, f32, f32, Vec3)> {
        match *light {
            Light::Ambient { .. } => None,
            Light::Point { position, intensity, color } => {
                let v = position - from;
                let d = v.length();
                (d > 0.0).then(|| (v / d, d, intensity, color))
            }
            Light::Directional { direction, intensity, color } => {
                Some((-direction, self.scene.settings.max_distance, intensity, color))
            }
        }
    }

    /// The colour of `hit` seen along `ray`. `occluded`, where the shadow rays of the
    /// first [`PACKET_LIGHTS`] lights were traced already ([`Self::trace_batch`]), says
    /// which were blocked; other shadow rays are traced here.
    fn shade(
        &self,
        ray: &Ray,
        hit: &Hit,
        depth: u32,
        weight: f32,
        occluded: Option<&[bool; PACKET_LIGHTS]>,
        stats: &mut RayStats,
    ) -> Vec3 {
        let m: &Material = &self.scene.materials[hit.material as usize];
        let SurfaceFrame { leaving, face, n, offset, above, spread } = surface_frame(ray, hit);
        let view = -ray.dir;

        let mut local = m.ka * self.ambient * m.color;
        for (l, light) in self.scene.lights.iter().enumerate() {
            let Some((to_light, dist, intensity, color)) = self.light_towards(light, above) else { continue };
            let n_dot_l = n.dot(to_light);
            if n_dot_l <= 0.0 {
                continue;
            }
            stats.rays += 1;
            stats.shadow_rays += 1;
            let blocked = match occluded {
                Some(o) if l < PACKET_LIGHTS => o[l],
                _ => self.geometry.any_hit(&Ray::spawned(above, to_light, spread), 0.0, dist, stats),
            };
            if blocked {
                continue;
            }
            local += m.kd * intensity * n_dot_l * m.color * color;
            if let Some(exp) = m.shininess {
                let r = 2.0 * n_dot_l * n - to_light;
                let r_dot_v = r.dot(view);
                if r_dot_v > 0.0 {
                    local += m.ks * intensity * r_dot_v.powf(exp) * color;
                }
            }
        }

        if depth == 0 || (m.reflectivity <= 0.0 && m.transparency <= 0.0) {
            return local;
        }
        let mut refl_dir = ray.dir - 2.0 * ray.dir.dot(n) * n;
        if refl_dir.dot(face) <= 0.0 {
            // A shading normal leaning far from the facet would send the mirror ray into the
            // surface; mirror about the facet instead.
            refl_dir = ray.dir - 2.0 * ray.dir.dot(face) * face;
        }
        let reflected = |w: f32, stats: &mut RayStats| {
            if w < MIN_CONTRIBUTION {
                Vec3::ZERO
            } else {
                self.trace_rec(&Ray::spawned(above, refl_dir.normalize(), spread), depth - 1, w, stats)
            }
        };
        let (r, tr) = (m.reflectivity, m.transparency);
        let opaque = (1.0 - r) * local
            + if r > 0.0 { r * reflected(weight * (1.0 - tr) * r, stats) } else { Vec3::ZERO };
        if tr <= 0.0 {
            return opaque;
        }
        let w = weight * tr;
        let transmitted = if w < MIN_CONTRIBUTION {
            Vec3::ZERO
        } else {
            let eta = if leaving { m.ior } else { 1.0 / m.ior };
            match refract(ray.dir, n, eta) {
                Some(dir) => {
                    let below = hit.point - face * offset;
                    self.trace_rec(&Ray::spawned(below, dir, spread), depth - 1, w, stats)
                }
                // Total internal reflection: all of it is reflected.
                None => reflected(w, stats),
            }
        };
        (1.0 - tr) * opaque + tr * transmitted
    }
}

/// Where a hit is shaded from: which side of the surface the ray is on, and the normals
/// and spawn point that follow.
#[derive(Clone, Copy, Debug)]
struct SurfaceFrame {
    /// Whether the ray leaves the solid (it meets the geometric normal's back).
    leaving: bool,
    /// The geometric normal turned towards the viewer.
    face: Vec3,
    /// The shading normal turned to the same side (the facing normal where it leans past
    /// the facet).
    n: Vec3,
    /// How far spawned rays start off the surface ([`spawn_offset`]).
    offset: f32,
    /// The hit point moved `offset` along `face`: where shadow and reflection rays start.
    above: Vec3,
    /// The path length from the camera to the hit: the spawned rays' [`Ray::spread`].
    spread: f32,
}

/// The [`SurfaceFrame`] of `hit` seen along `ray`.
#[inline]
fn surface_frame(ray: &Ray, hit: &Hit) -> SurfaceFrame {
    let leaving = hit.normal.dot(ray.dir) > 0.0;
    let face = if leaving { -hit.normal } else { hit.normal };
    let n = if leaving { -hit.shading_normal } else { hit.shading_normal };
    let n = if n.dot(face) > 0.0 { n } else { face };
    let offset = spawn_offset(hit);
    SurfaceFrame { leaving, face, n, offset, above: hit.point + face * offset, spread: ray.spread + hit.t }
}

/// Refracts unit `d` through a surface with unit normal `n` facing against `d`, with
/// `eta` = n_incident / n_transmitted. `None` on total internal reflection.
pub fn refract(d: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = -d.dot(n);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t > 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((eta * d + (eta * cos_i - cos_t) * n).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snell_and_total_internal_reflection() {
        let n = Vec3::Y;
        let d = Vec3::new(1.0, -1.0, 0.0).normalize();
        let t = refract(d, n, 1.0 / 1.5).unwrap();
        let sin_i = d.x;
        let sin_t = t.x;
        assert!((sin_i / sin_t - 1.5).abs() < 1e-5);
        assert!(t.y < 0.0);
        // From glass at 45 degrees: beyond the critical angle (41.8 degrees).
        assert!(refract(d, n, 1.5).is_none());
        // Straight through when eta = 1.
        assert!((refract(d, n, 1.0).unwrap() - d).length() < 1e-6);
    }
}
