//! Sphere tracing of distance functions: plain and over-relaxed ("enhanced", Keinert et
//! al. 2014), with a hit tolerance relative to the distance travelled, a step limit that is
//! counted rather than hidden, a refinement step, and normals from the distance gradient.
//! These are the loops; [`crate::geometry::marched::Marched`] is the one geometry that
//! runs them on every marched field (analytic SDFs, SDF grids).

use glam::DVec3;

use crate::geometry::{Ray, RayStats};

/// Sphere-tracing parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarchParams {
    /// Relative hit tolerance: a march stops when `|d| < e * max(s + t, 1e-4 * size)` with
    /// `e = min(epsilon, tolerance_px * pixel_footprint)` and `s` the ray's path length
    /// before its origin ([`Segment::spread`], 0 for camera rays), so the tolerance grows
    /// with distance like a pixel footprint and never exceeds `tolerance_px` pixels (which
    /// matters for a camera with a narrow field of view: a 1e-3 object seen from 1e3
    /// away); the floor only matters for rays that start next to a surface. Default 1e-4.
    pub epsilon: f64,
    /// The largest hit tolerance, in pixels (fractions of [`Self::pixel_footprint`] at the
    /// hit's distance): the SDF side's quality knob. Default 0.25.
    pub tolerance_px: f64,
    /// Maximum distance evaluations per march; a march that runs out is counted in
    /// [`RayStats::step_limit_hits`] and reported as a miss. Default 512.
    pub max_steps: u32,
    /// Over-relaxation factor in [1, 2): 1 is plain sphere tracing; larger values step
    /// `relaxation * d` and fall back to plain steps when the unbounding spheres stop
    /// overlapping. Default 1.
    pub relaxation: f64,
    /// Angular size of a pixel, radians (`2 tan(fov/2) / height`), set from the camera
    /// when the scene is built. A march that runs out of steps still reports a hit at its
    /// last point if that point is within this fraction of its distance from the surface,
    /// i.e. closer than the pixel it is seen through (the typical case: a ray grazing a
    /// plane near the horizon); such marches are counted in
    /// [`RayStats::step_limit_hits`] either way. Default 1e-3.
    pub pixel_footprint: f64,
}

impl Default for MarchParams {
    fn default() -> Self {
        MarchParams {
            epsilon: 1e-4,
            tolerance_px: 0.25,
            max_steps: 512,
            relaxation: 1.0,
            pixel_footprint: 1e-3,
        }
    }
}

impl MarchParams {
    /// The hit tolerance at parameter `t` for an object of characteristic `size`.
    #[inline]
    pub fn tolerance(&self, t: f64, size: f64) -> f64 {
        self.epsilon.min(self.tolerance_px * self.pixel_footprint) * t.max(1e-4 * size)
    }
}

/// A piece of a ray to march: `origin + t * dir` (`dir` unit length) for `t` in
/// `[t0, t1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Start of the ray (`t = 0`), scene units.
    pub origin: DVec3,
    /// Unit direction.
    pub dir: DVec3,
    /// First ray parameter marched, scene units.
    pub t0: f64,
    /// Last ray parameter marched (`>= t0` for a non-empty segment), scene units.
    pub t1: f64,
    /// The ray's path length before its origin ([`crate::geometry::Ray::spread`]): the
    /// hit tolerance at `t` is that of `spread + t`.
    pub spread: f64,
}

impl Segment {
    /// `ray` (origin, direction and [`Ray::spread`] in double precision) from `t0` to `t1`.
    #[inline]
    pub fn along(ray: &Ray, t0: f64, t1: f64) -> Self {
        Segment { origin: ray.origin.as_dvec3(), dir: ray.dir.as_dvec3(), t0, t1, spread: ray.spread as f64 }
    }
}

/// Sphere traces the ray segment `seg` through the distance function `f` (exact or a
/// Lipschitz-1 lower bound) with tolerances for an object of characteristic `size`.
/// `f(p, tol)` is the distance at `p`, evaluated precisely enough that its error is at
/// most a quarter of `tol`, the hit tolerance at that step (a field may answer in f32
/// where that is enough, [`crate::geometry::sdf::SdfField`]).
/// Returns the hit, or `None` for a miss. A march that exhausts its step budget reports its
/// last point if that is within the pixel footprint of the surface, else a miss. A ray that
/// starts inside the solid marches `|f|` and finds the exit. With `refine`, a converged
/// march takes one more step onto the surface (not for unsigned fields, whose gradient is
/// undefined there). [`crate::geometry::marched::Marched`] calls it for every marched
/// representation; its packets run the same steps through [`MarchLane`].
pub fn sphere_trace(
    f: &impl Fn(DVec3, f64) -> f64,
    seg: &Segment,
    size: f64,
    params: &MarchParams,
    refine: bool,
    stats: &mut RayStats,
) -> Option<MarchHit> {
    let mut lane = MarchLane::new(seg, stats);
    loop {
        let raw = f(seg.origin + seg.dir * lane.t(), lane.tolerance(params, size));
        if let Some(hit) = lane.feed(raw, seg, size, params, refine, stats) {
            return hit;
        }
    }
}

/// One ray's sphere trace as a state machine: [`MarchLane::t`] is where the distance is
/// needed next, [`MarchLane::feed`] takes it and says whether the march is over. Scalar
/// marching ([`sphere_trace`]) feeds one lane; packets feed eight lanes from one 8-wide
/// evaluation. Every lane takes exactly the steps [`sphere_trace`] would.
///
/// # The surface is where the field changes sign
///
/// A signed field's surface is where it changes sign, not every place it comes within the
/// tolerance of zero: a subtraction whose cutter ends exactly on a face of the solid
/// (`max(box, -cross)` with the cross's end caps on the box's faces, the usual way a Menger
/// sponge is written) is zero on the cutter's end cap and positive on both sides of it, a
/// skin of zero thickness that is not the boundary of any solid. Marching cubes and grids
/// see no sign change there and leave a hole; so does this marcher (regularised CSG, the
/// same rule in every representation). A march that converges (`|d| < tolerance`) already
/// past the surface (`d < 0` in the march's sign) has crossed it; otherwise it probes the
/// field at `t + d + tolerance / 2` along the ray (twice as far after each touch, see
/// [`MAX_TOUCHES`]): a value of the other sign confirms the
/// crossing, and the hit is refined between the two points (secant) and kept where the
/// field is smaller there. Without a sign change the point only touches zero (a skin, or a
/// ray grazing a surface it does not enter), and the march goes on from the probe with
/// plain steps, up to [`MAX_TOUCHES`] times in a row. Unsigned fields (a triangle) have no inside: their hits are accepted on
/// convergence, unrefined.
#[derive(Clone, Copy, Debug)]
pub struct MarchLane {
    /// Ray parameter to evaluate next.
    t: f64,
    /// [`Segment::spread`].
    spread: f64,
    /// Sign of the field at the first point (1 outside, -1 inside).
    sign: f64,
    prev_t: f64,
    prev_r: f64,
    /// |distance| at the last point marched, `r_t`.
    r: f64,
    r_t: f64,
    omega: f64,
    /// March evaluations so far (the step budget, [`MarchParams::max_steps`]).
    iterations: u32,
    /// Probes in a row that found no sign change (see [`MAX_TOUCHES`]).
    touches: u32,
    /// The converged point where the current run of touches began.
    first_touch: MarchHit,
    phase: Phase,
}

/// Converged points in a row without a sign change after which a march accepts the first
/// of them as a hit: a ray that runs along a surface within the tolerance for that long (a
/// ray in the plane of a face) is seen as that surface. The probes after a touch reach
/// twice as far each time (half a tolerance, one, two, ...), so a skin is left after one or
/// two and a ray tangent to a curved surface leaves its zone of near-zero distance (of
/// length `2 sqrt(2 R tolerance)` for radius `R`) after a few; 16 probes cover `2^15`
/// tolerances.
pub const MAX_TOUCHES: u32 = 16;

/// What the value fed to a [`MarchLane`] is for.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    /// A sphere-tracing step.
    March,
    /// The probe past a converged point `t` (signed distance `d >= 0` in the march's sign,
    /// tolerance `eps`): does the field change sign?
    Probe { t: f64, d: f64, eps: f64 },
    /// The refinement between a converged point `t` (residual `r`) and the probe that
    /// confirmed the crossing.
    Refine { t: f64, r: f64, eps: f64 },
}

impl MarchLane {
    /// A lane at the start of `seg` (counts the ray in `stats.marched_rays`).
    pub fn new(seg: &Segment, stats: &mut RayStats) -> Self {
        stats.marched_rays += 1;
        MarchLane {
            t: seg.t0,
            spread: seg.spread,
            sign: 0.0,
            prev_t: seg.t0,
            prev_r: 0.0,
            r: f64::INFINITY,
            r_t: seg.t0,
            omega: 0.0,
            iterations: 0,
            touches: 0,
            first_touch: MarchHit { t: seg.t0, residual: 0.0 },
            phase: Phase::March,
        }
    }

    /// Ray parameter where the distance is needed next.
    #[inline]
    pub fn t(&self) -> f64 {
        self.t
    }

    /// The hit tolerance at [`Self::t`] (what the field's evaluation must resolve).
    #[inline]
    pub fn tolerance(&self, params: &MarchParams, size: f64) -> f64 {
        match self.phase {
            Phase::Probe { eps, .. } | Phase::Refine { eps, .. } => eps,
            Phase::March => params.tolerance(self.spread + self.t, size),
        }
    }

    /// Takes the field's value `raw` at [`Self::t`]; returns `Some(outcome)` when the
    /// march is over (`Some(None)`: a miss), `None` when it needs the next point.
    #[inline]
    pub fn feed(
        &mut self,
        raw: f64,
        seg: &Segment,
        size: f64,
        params: &MarchParams,
        refine: bool,
        stats: &mut RayStats,
    ) -> Option<Option<MarchHit>> {
        match self.phase {
            Phase::March => {}
            Phase::Refine { t, r, eps } => {
                // Kept where the field is smaller than at the converged point and not
                // before the segment.
                let r2 = raw.abs();
                return Some(Some(if r2 <= r && self.t >= seg.t0 - eps {
                    MarchHit { t: self.t, residual: r2 }
                } else {
                    MarchHit { t, residual: r }
                }));
            }
            Phase::Probe { t, d, eps } => {
                let dp = self.sign * raw;
                if dp < 0.0 {
                    // The field changes sign between t and the probe: a surface. Refine at
                    // the secant's zero (two evaluations: the probe and the refinement).
                    stats.march_steps += 2;
                    self.phase = Phase::Refine { t, r: d, eps };
                    self.t = t + (self.t - t) * d / (d - dp);
                    return None;
                }
                // Only touching zero: march on from the probe, with plain steps.
                self.phase = Phase::March;
                if self.touches == 0 {
                    self.first_touch = MarchHit { t, residual: d };
                }
                self.touches += 1;
                self.omega = 1.0;
                self.prev_t = t;
                self.prev_r = d;
                if self.t > seg.t1 {
                    return Some(None);
                }
                return self.step(raw, seg, size, params, refine, stats);
            }
        }
        self.step(raw, seg, size, params, refine, stats)
    }

    /// One sphere-tracing step with the field's value `raw` at [`Self::t`].
    #[inline]
    fn step(
        &mut self,
        raw: f64,
        seg: &Segment,
        size: f64,
        params: &MarchParams,
        refine: bool,
        stats: &mut RayStats,
    ) -> Option<Option<MarchHit>> {
        if self.iterations == 0 {
            self.omega = params.relaxation;
        }
        self.iterations += 1;
        stats.march_steps += 1;
        let t = self.t;
        let eps = params.tolerance(self.spread + t, size);
        if self.sign == 0.0 {
            self.sign = if raw < 0.0 { -1.0 } else { 1.0 };
        }
        let d = self.sign * raw;
        self.r = d.abs();
        self.r_t = t;
        // With over-relaxation the step may jump over a surface; detect it by the two
        // unbounding spheres (radii prev_r and r) failing to cover the step, and go back
        // to the plain step from the previous point.
        if self.omega > 1.0 && self.prev_r + self.r < t - self.prev_t {
            self.omega = 1.0;
            self.t = self.prev_t + self.prev_r;
            return self.budget(params, stats);
        }
        if self.r >= eps {
            self.touches = 0;
        }
        if self.r < eps {
            if !refine {
                return Some(Some(MarchHit { t, residual: self.r }));
            }
            if self.touches >= MAX_TOUCHES {
                return Some(Some(self.first_touch));
            }
            if d < 0.0 {
                // Already past the surface: crossed. One refinement step back onto it.
                stats.march_steps += 1;
                self.phase = Phase::Refine { t, r: self.r, eps };
                self.t = t + d;
                return None;
            }
            if self.iterations >= params.max_steps {
                return self.budget(params, stats);
            }
            // The probe is counted as a step when it is marched on from (`step`), or with
            // the refinement when it confirms the crossing.
            self.phase = Phase::Probe { t, d, eps };
            self.t = t + d + 0.5 * eps * f64::from(1u32 << self.touches.min(15));
            return None;
        }
        self.prev_t = t;
        self.prev_r = self.r;
        self.t = t + d * self.omega;
        if self.t > seg.t1 {
            // A relaxed step past the end may have jumped a surface near the end: retry it
            // as a plain step, which is safe.
            if self.omega > 1.0 && self.prev_t + self.prev_r <= seg.t1 {
                self.omega = 1.0;
                self.t = self.prev_t + self.prev_r;
                return self.budget(params, stats);
            }
            return Some(None);
        }
        self.budget(params, stats)
    }

    /// The end of a march that goes on: over when the step budget is spent (reported as a
    /// hit at the last point marched, only within the pixel footprint of the surface).
    #[inline]
    fn budget(&self, params: &MarchParams, stats: &mut RayStats) -> Option<Option<MarchHit>> {
        if self.iterations < params.max_steps {
            return None;
        }
        stats.step_limit_hits += 1;
        let (t, r) = (self.r_t, self.r);
        Some(
            (t > 0.0 && r < params.pixel_footprint * (self.spread + t))
                .then_some(MarchHit { t, residual: r }),
        )
    }
}

/// Where a march stopped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarchHit {
    /// Ray parameter of the hit.
    pub t: f64,
    /// |distance| at the hit point: how far from the surface it may be.
    pub residual: f64,
}

/// The four offsets of the tetrahedron technique: [`gradient_normal`] evaluates the field at
/// `p + h * k` for each.
pub const TETRAHEDRON: [DVec3; 4] = [
    DVec3::new(1.0, -1.0, -1.0),
    DVec3::new(-1.0, -1.0, 1.0),
    DVec3::new(-1.0, 1.0, -1.0),
    DVec3::new(1.0, 1.0, 1.0),
];

/// The unit gradient at `p` by the tetrahedron technique with step `h`: `f4` evaluates the
/// field at the four points `p + h * k` ([`TETRAHEDRON`]) at once (a field may do that with
/// one 8-wide evaluation); falls back to +y where the gradient vanishes.
pub fn gradient_normal(
    f4: &impl Fn(&[DVec3; 4]) -> [f64; 4],
    p: DVec3,
    h: f64,
    stats: &mut RayStats,
) -> DVec3 {
    stats.march_steps += 4;
    tetrahedron_normal(f4(&tetrahedron_points(p, h)))
}

/// [`gradient_normal`] at two points at once (`a` with step `ha`, `b` with step `hb`):
/// `f8` evaluates both stencils together (a field does that with one 8-wide evaluation),
/// each lane as [`gradient_normal`]'s `f4` would, so each normal is bit for bit the one
/// [`gradient_normal`] gives at that point alone.
pub fn gradient_normal2(
    f8: &impl Fn(&[DVec3; 4], &[DVec3; 4]) -> ([f64; 4], [f64; 4]),
    (a, ha): (DVec3, f64),
    (b, hb): (DVec3, f64),
    stats: &mut RayStats,
) -> (DVec3, DVec3) {
    stats.march_steps += 8;
    let (da, db) = f8(&tetrahedron_points(a, ha), &tetrahedron_points(b, hb));
    (tetrahedron_normal(da), tetrahedron_normal(db))
}

/// The stencil of [`gradient_normal`]: `p + h * k` for each of [`TETRAHEDRON`]'s `k`.
#[inline]
fn tetrahedron_points(p: DVec3, h: f64) -> [DVec3; 4] {
    TETRAHEDRON.map(|k| p + k * h)
}

/// The unit gradient from the field's values `d` at [`tetrahedron_points`] (+y where it
/// vanishes).
#[inline]
fn tetrahedron_normal(d: [f64; 4]) -> DVec3 {
    let g = TETRAHEDRON.iter().zip(d).fold(DVec3::ZERO, |acc, (k, d)| acc + *k * d);
    g.try_normalize().unwrap_or(DVec3::Y)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(origin: DVec3, dir: DVec3, t0: f64, t1: f64) -> Segment {
        Segment { origin, dir, t0, t1, spread: 0.0 }
    }

    fn sphere(p: DVec3, _tol: f64) -> f64 {
        (p - DVec3::new(0.0, 0.0, 5.0)).length() - 1.0
    }

    /// A ray passing the sphere at a clearance between the tolerance of its own `t` and
    /// that of `spread + t`: a camera ray passes, the same ray spawned at the end of a
    /// long path (a shadow ray, whose pixel's footprint is that wide) touches it.
    #[test]
    fn spread_widens_the_tolerance() {
        let params =
            MarchParams { pixel_footprint: 1e-3, tolerance_px: 1.0, epsilon: 1.0, ..Default::default() };
        let (size, spread) = (2.0, 100.0);
        // At the closest approach, t = 5: tolerance 5e-3 without spread, 0.105 with.
        let clearance = 0.05;
        let origin = DVec3::new(1.0 + clearance, 0.0, 0.0);
        let mut s = seg(origin, DVec3::Z, 0.0, 10.0);
        assert_eq!(
            MarchLane::new(&s, &mut RayStats::default()).tolerance(&params, size),
            params.tolerance(0.0, size)
        );
        let mut stats = RayStats::default();
        // Hits accepted on convergence (as for an unsigned field): the test is the tolerance.
        assert!(sphere_trace(&sphere, &s, size, &params, false, &mut stats).is_none());
        s.spread = spread;
        let lane = MarchLane::new(&s, &mut stats);
        assert_eq!(lane.tolerance(&params, size), params.tolerance(spread, size));
        let hit = sphere_trace(&sphere, &s, size, &params, false, &mut stats)
            .expect("a touch within the footprint");
        assert!((hit.t - 5.0).abs() < 0.5, "{hit:?}");
    }

    #[test]
    fn hits_sphere_front_and_exits_from_inside() {
        let mut stats = RayStats::default();
        let p = MarchParams::default();
        let t = sphere_trace(&sphere, &seg(DVec3::ZERO, DVec3::Z, 0.0, 100.0), 2.0, &p, true, &mut stats)
            .unwrap()
            .t;
        assert!((t - 4.0).abs() < 1e-3, "{t}");
        let t = sphere_trace(
            &sphere,
            &seg(DVec3::new(0.0, 0.0, 5.0), DVec3::Z, 0.0, 100.0),
            2.0,
            &p,
            true,
            &mut stats,
        )
        .unwrap()
        .t;
        assert!((t - 1.0).abs() < 1e-3, "{t}");
        assert!(stats.march_steps > 0);
    }

    #[test]
    fn misses_and_step_limit_are_reported() {
        let mut stats = RayStats::default();
        let p = MarchParams { max_steps: 4, pixel_footprint: 1e-6, ..Default::default() };
        let miss = sphere_trace(&sphere, &seg(DVec3::ZERO, DVec3::Y, 0.0, 10.0), 2.0, &p, true, &mut stats);
        assert_eq!(miss, None);
        // Grazing: the ray passes at distance 1.0001 from the centre; 4 steps are not enough.
        let dir = DVec3::new(1.0001 / 5.0, 0.0, 1.0).normalize();
        let r = sphere_trace(&sphere, &seg(DVec3::ZERO, dir, 0.0, 100.0), 2.0, &p, true, &mut stats);
        assert_eq!(r, None);
        assert_eq!(stats.step_limit_hits, 1);
    }

    #[test]
    fn over_relaxation_takes_fewer_steps_and_finds_the_same_hit() {
        // A thin slab seen at a slant: plain sphere tracing crawls along it.
        let plane = |p: DVec3, _: f64| p.y + 1.0;
        let dir = DVec3::new(0.0, -0.05, 1.0).normalize();
        let (mut a, mut b) = (RayStats::default(), RayStats::default());
        let plain = MarchParams::default();
        let relaxed = MarchParams { relaxation: 1.6, ..plain };
        let t_plain =
            sphere_trace(&plane, &seg(DVec3::ZERO, dir, 0.0, 1e3), 1.0, &plain, true, &mut a).unwrap().t;
        let t_relax =
            sphere_trace(&plane, &seg(DVec3::ZERO, dir, 0.0, 1e3), 1.0, &relaxed, true, &mut b).unwrap().t;
        assert!((t_plain - t_relax).abs() < 1e-4 * t_plain);
        assert!(b.march_steps < a.march_steps, "{} vs {}", b.march_steps, a.march_steps);
    }

    #[test]
    fn over_relaxation_does_not_skip_a_thin_sheet() {
        // A sheet of thickness 0.02 behind a sphere that pulls relaxed steps long.
        let f = |p: DVec3, _: f64| (p.z - 3.0).abs() - 0.01;
        let relaxed = MarchParams { relaxation: 1.9, ..Default::default() };
        let mut s = RayStats::default();
        let t =
            sphere_trace(&f, &seg(DVec3::ZERO, DVec3::Z, 0.0, 10.0), 1.0, &relaxed, true, &mut s).unwrap().t;
        assert!((t - 2.99).abs() < 1e-3, "{t}");
    }
}
