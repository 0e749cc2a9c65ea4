//! Sphere tracing of distance functions: plain and over-relaxed ("enhanced", Keinert et
//! al. 2014), with a hit tolerance relative to the distance travelled, a step limit that is
//! counted rather than hidden, a refinement step, and normals from the distance gradient.
//! These are the loops; [`crate::geometry::marched::Marched`] is the one geometry that
//! runs them on every marched field (analytic SDFs, SDF grids).

use glam::DVec3;

use crate::geometry::RayStats;

/// Sphere-tracing parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarchParams {
    /// Relative hit tolerance: a march stops when `|d| < e * max(t, 1e-4 * size)` with
    /// `e = min(epsilon, tolerance_px * pixel_footprint)`, so the tolerance grows with
    /// distance like a pixel footprint and never exceeds `tolerance_px` pixels (which
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
            Phase::March => params.tolerance(self.t, size),
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
        let eps = params.tolerance(t, size);
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
        Some((t > 0.0 && r < params.pixel_footprint * t).then_some(MarchHit { t, residual: r }))
    }
}

/// Eight [`MarchLane`]s side by side, their state by field (one array per field, lane `i`
/// at index `i`), for packets of rays marched with one 8-wide field evaluation per step
/// ([`crate::geometry::marched::Marched`]). Every lane takes exactly the steps of its own
/// [`MarchLane`], bit for bit: [`MarchPacket::feed`] takes the common steps for all lanes
/// at once on the arrays (AVX2 where the CPU has it): a plain march step (the first one
/// included) that does not converge and either stays within the segment and the budget or
/// leaves the segment (a miss). Every other event (a convergence, its probe and
/// refinement, an over-relaxed step, the budget) is [`MarchLane::feed`] on that lane
/// alone. Holds no heap memory.
#[derive(Clone, Debug)]
pub struct MarchPacket {
    /// Ray parameter each lane evaluates next ([`MarchLane::t`]); lanes that are not
    /// marching keep their last value (or the first marching lane's start), a point the
    /// field can evaluate.
    t: [f64; 8],
    sign: [f64; 8],
    prev_t: [f64; 8],
    prev_r: [f64; 8],
    r: [f64; 8],
    r_t: [f64; 8],
    omega: [f64; 8],
    iterations: [u32; 8],
    touches: [u32; 8],
    /// The lanes' segments' ends (`Segment::t0`, `Segment::t1`).
    t0: [f64; 8],
    t1: [f64; 8],
    first_touch: [MarchHit; 8],
    phase: [Phase; 8],
    /// The tolerance of a lane's probe or refinement (`Phase::Probe`'s or `Phase::Refine`'s
    /// `eps`); not used in the march phase.
    phase_eps: [f64; 8],
    /// Bit `i`: lane `i` is marching.
    active: u8,
    /// Bit `i`: lane `i` is in the march phase (`Phase::March`).
    marching: u8,
    /// Bit `i`: lane `i` is in the march phase and its next step is plain: its first
    /// (whose `omega` is [`MarchParams::relaxation`]) or one with `omega` 1.
    plain: u8,
    /// Bit `i`: lane `i` has taken no step yet.
    fresh: u8,
    /// Calls of [`Self::feed`] so far: no lane has taken more march steps
    /// ([`MarchLane::step`] counts at most one per value fed).
    feeds: u32,
}

/// What [`MarchPacket`]'s common step did: lanes that stepped on, lanes that stepped past
/// their segment's end (misses).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Common {
    stay: u8,
    leave: u8,
}

impl MarchPacket {
    /// A packet with lane `i` marching from `t0` to `t1` where `segs[i]` is `Some((t0, t1))`
    /// (each counted in `stats.marched_rays`); `None` when no lane marches.
    pub fn new(segs: &[Option<(f64, f64)>; 8], stats: &mut RayStats) -> Option<Self> {
        let first = segs.iter().flatten().next()?.0;
        let mut p = MarchPacket {
            t: [first; 8],
            sign: [0.0; 8],
            prev_t: [first; 8],
            prev_r: [0.0; 8],
            r: [f64::INFINITY; 8],
            r_t: [first; 8],
            omega: [0.0; 8],
            iterations: [0; 8],
            touches: [0; 8],
            t0: [first; 8],
            t1: [first; 8],
            first_touch: [MarchHit { t: first, residual: 0.0 }; 8],
            phase: [Phase::March; 8],
            phase_eps: [0.0; 8],
            active: 0,
            marching: 0,
            plain: 0,
            fresh: 0,
            feeds: 0,
        };
        for (i, s) in segs.iter().enumerate() {
            if let Some((t0, t1)) = *s {
                let seg = Segment { origin: DVec3::ZERO, dir: DVec3::ZERO, t0, t1 };
                p.set(i, &MarchLane::new(&seg, stats));
                (p.t0[i], p.t1[i]) = (t0, t1);
                p.active |= 1 << i;
            }
        }
        Some(p)
    }

    /// Whether any lane is still marching.
    #[inline]
    pub fn marching(&self) -> bool {
        self.active != 0
    }

    /// Where each lane needs the distance next ([`MarchLane::t`]).
    #[inline]
    pub fn t(&self) -> &[f64; 8] {
        &self.t
    }

    /// Lane `i` as a [`MarchLane`].
    #[inline]
    fn lane(&self, i: usize) -> MarchLane {
        MarchLane {
            t: self.t[i],
            sign: self.sign[i],
            prev_t: self.prev_t[i],
            prev_r: self.prev_r[i],
            r: self.r[i],
            r_t: self.r_t[i],
            omega: self.omega[i],
            iterations: self.iterations[i],
            touches: self.touches[i],
            first_touch: self.first_touch[i],
            phase: self.phase[i],
        }
    }

    /// Stores `lane` as lane `i`.
    #[inline]
    fn set(&mut self, i: usize, lane: &MarchLane) {
        self.t[i] = lane.t;
        self.sign[i] = lane.sign;
        self.prev_t[i] = lane.prev_t;
        self.prev_r[i] = lane.prev_r;
        self.r[i] = lane.r;
        self.r_t[i] = lane.r_t;
        self.omega[i] = lane.omega;
        self.iterations[i] = lane.iterations;
        self.touches[i] = lane.touches;
        self.first_touch[i] = lane.first_touch;
        self.phase[i] = lane.phase;
        let (marching, plain) = match lane.phase {
            Phase::March => (true, lane.iterations == 0 || lane.omega == 1.0),
            Phase::Probe { eps, .. } | Phase::Refine { eps, .. } => {
                self.phase_eps[i] = eps;
                (false, false)
            }
        };
        let bit = |b: bool| u8::from(b) << i;
        let keep = !(1u8 << i);
        self.marching = (self.marching & keep) | bit(marching);
        self.plain = (self.plain & keep) | bit(plain);
        self.fresh = (self.fresh & keep) | bit(lane.iterations == 0);
    }

    /// The tolerance each marching lane's evaluation must resolve
    /// ([`MarchLane::tolerance`]); infinite for the others.
    #[inline]
    pub fn tolerances(&self, params: &MarchParams, size: f64) -> [f64; 8] {
        let c = params.epsilon.min(params.tolerance_px * params.pixel_footprint);
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2() {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { self.tolerances_avx2(c, 1e-4 * size) };
        }
        self.tolerances_scalar(params, size)
    }

    /// [`Self::tolerances`] lane by lane (CPUs without AVX2).
    fn tolerances_scalar(&self, params: &MarchParams, size: f64) -> [f64; 8] {
        std::array::from_fn(|i| {
            if self.active & (1 << i) == 0 {
                f64::INFINITY
            } else if self.marching & (1 << i) != 0 {
                params.tolerance(self.t[i], size)
            } else {
                self.phase_eps[i]
            }
        })
    }

    /// [`Self::tolerances`] with AVX2, `MarchParams::tolerance` as `c * max(t, floor)`:
    /// `maxpd(t, floor)` is Rust's `t.max(floor)` (a NaN `t` gives `floor`), so the same
    /// bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn tolerances_avx2(&self, c: f64, floor: f64) -> [f64; 8] {
        use std::arch::x86_64::*;
        let mut out = [0.0; 8];
        // SAFETY: loads and stores of four f64 at offsets 0 and 4 of `[f64; 8]`s.
        unsafe {
            let (c, floor, inf) = (_mm256_set1_pd(c), _mm256_set1_pd(floor), _mm256_set1_pd(f64::INFINITY));
            for h in [0usize, 4] {
                let march = _mm256_mul_pd(c, _mm256_max_pd(_mm256_loadu_pd(self.t.as_ptr().add(h)), floor));
                let v = _mm256_blendv_pd(
                    _mm256_loadu_pd(self.phase_eps.as_ptr().add(h)),
                    march,
                    lanes(self.marching >> h),
                );
                _mm256_storeu_pd(out.as_mut_ptr().add(h), _mm256_blendv_pd(inf, v, lanes(self.active >> h)));
            }
        }
        out
    }

    /// Takes the field's values `raw` at [`Self::t`] for every marching lane, as
    /// [`MarchLane::feed`] does lane by lane, and calls `done(i, outcome, stats)` for each
    /// lane whose march is over (`None`: a miss); that lane stops marching.
    #[inline]
    pub fn feed(
        &mut self,
        raw: &[f64; 8],
        size: f64,
        params: &MarchParams,
        refine: bool,
        stats: &mut RayStats,
        mut done: impl FnMut(usize, Option<MarchHit>, &mut RayStats),
    ) {
        // The common step for the plain lanes with steps left, all at once; the tolerance
        // as `MarchParams::tolerance` computes it.
        let c = params.epsilon.min(params.tolerance_px * params.pixel_footprint);
        let floor = 1e-4 * size;
        let mut candidates = self.active & self.plain;
        if params.relaxation != 1.0 {
            candidates &= !self.fresh;
        }
        if self.feeds + 1 >= params.max_steps {
            // Near the budget: only the lanes that have steps left after this one.
            for i in 0..8 {
                if self.iterations[i] + 1 >= params.max_steps {
                    candidates &= !(1 << i);
                }
            }
        }
        self.feeds += 1;
        let common =
            if candidates == 0 { Common::default() } else { self.common_steps(raw, c, floor, candidates) };
        let stepped = common.stay | common.leave;
        let mut bits = stepped;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            self.iterations[i] += 1;
            self.touches[i] = 0;
        }
        stats.march_steps += u64::from(stepped.count_ones());
        if stepped & self.fresh != 0 {
            // Their first step: `omega` from here on is the relaxation (1 for these).
            let mut bits = stepped & self.fresh;
            while bits != 0 {
                let i = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                self.omega[i] = params.relaxation;
            }
            self.fresh &= !stepped;
        }
        let mut other = self.active & !stepped;
        self.active &= !common.leave;
        let mut leave = common.leave;
        while leave != 0 {
            let i = leave.trailing_zeros() as usize;
            leave &= leave - 1;
            done(i, None, stats);
        }
        while other != 0 {
            let i = other.trailing_zeros() as usize;
            other &= other - 1;
            let mut lane = self.lane(i);
            let seg = Segment { origin: DVec3::ZERO, dir: DVec3::ZERO, t0: self.t0[i], t1: self.t1[i] };
            let outcome = lane.feed(raw[i], &seg, size, params, refine, stats);
            self.set(i, &lane);
            if let Some(outcome) = outcome {
                self.active &= !(1 << i);
                done(i, outcome, stats);
            }
        }
    }

    /// Takes the common step in every lane of `candidates` (plain lanes with steps left)
    /// where it is one, as [`MarchLane::step`] does: the lane's sign is set at its first
    /// step (`raw`'s, positive for zero); the distance `d = sign * raw` does not converge
    /// (`|d| >= eps`, `eps = c * max(t, floor)`); the lane moves to `t + d` (`omega` is 1)
    /// and stays (`t + d` within the segment) or leaves (past its end: a miss). Updates
    /// those lanes' `sign`, `t`, `r`, `r_t`, `prev_t` and `prev_r` (the caller the rest).
    #[inline]
    fn common_steps(&mut self, raw: &[f64; 8], c: f64, floor: f64, candidates: u8) -> Common {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2() {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { self.common_steps_avx2(raw, c, floor, candidates) };
        }
        self.common_steps_scalar(raw, c, floor, candidates)
    }

    /// [`Self::common_steps`] lane by lane (CPUs without AVX2).
    #[allow(clippy::needless_range_loop)] // lane `i` of eight arrays
    fn common_steps_scalar(&mut self, raw: &[f64; 8], c: f64, floor: f64, candidates: u8) -> Common {
        let mut common = Common::default();
        for i in 0..8 {
            let t = self.t[i];
            let sign = if self.sign[i] != 0.0 {
                self.sign[i]
            } else if raw[i] < 0.0 {
                -1.0
            } else {
                1.0
            };
            let d = sign * raw[i];
            let r = d.abs();
            let next = t + d;
            if candidates & (1 << i) != 0 && r >= c * t.max(floor) {
                (self.sign[i], self.r[i], self.r_t[i]) = (sign, r, t);
                (self.prev_t[i], self.prev_r[i], self.t[i]) = (t, r, next);
                if next > self.t1[i] {
                    common.leave |= 1 << i;
                } else {
                    common.stay |= 1 << i;
                }
            }
        }
        common
    }

    /// [`Self::common_steps`] four lanes at a time with AVX2: the same IEEE double
    /// operations (`max(t, floor)` as `maxpd`, see [`Self::tolerances_avx2`]), so the same
    /// bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn common_steps_avx2(&mut self, raw: &[f64; 8], c: f64, floor: f64, candidates: u8) -> Common {
        use std::arch::x86_64::*;
        let mut common = Common::default();
        // SAFETY: every load and store is of four f64 at offset 0 or 4 of an `[f64; 8]`.
        unsafe {
            let (c, floor, zero) = (_mm256_set1_pd(c), _mm256_set1_pd(floor), _mm256_setzero_pd());
            let abs = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX));
            for h in [0usize, 4] {
                if (candidates >> h) & 0xf == 0 {
                    continue;
                }
                let t = _mm256_loadu_pd(self.t.as_ptr().add(h));
                let raw = _mm256_loadu_pd(raw.as_ptr().add(h));
                let old_sign = _mm256_loadu_pd(self.sign.as_ptr().add(h));
                // `if raw < 0.0 { -1.0 } else { 1.0 }` where the sign is still 0.
                let own = _mm256_blendv_pd(
                    _mm256_set1_pd(1.0),
                    _mm256_set1_pd(-1.0),
                    _mm256_cmp_pd::<_CMP_LT_OQ>(raw, zero),
                );
                let sign = _mm256_blendv_pd(old_sign, own, _mm256_cmp_pd::<_CMP_EQ_OQ>(old_sign, zero));
                let d = _mm256_mul_pd(sign, raw);
                let r = _mm256_and_pd(d, abs);
                let next = _mm256_add_pd(t, d);
                let eps = _mm256_mul_pd(c, _mm256_max_pd(t, floor));
                let ok =
                    _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GE_OQ>(r, eps)) as u8 & (candidates >> h) & 0xf;
                if ok == 0 {
                    continue;
                }
                let past = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(
                    next,
                    _mm256_loadu_pd(self.t1.as_ptr().add(h)),
                )) as u8;
                common.leave |= (ok & past) << h;
                common.stay |= (ok & !past) << h;
                let m = lanes(ok);
                // A macro, not a closure: everything must inline into this AVX2 function.
                macro_rules! put {
                    ($field:ident, $v:expr) => {{
                        let dst = self.$field.as_mut_ptr().add(h);
                        _mm256_storeu_pd(dst, _mm256_blendv_pd(_mm256_loadu_pd(dst), $v, m));
                    }};
                }
                put!(sign, sign);
                put!(r, r);
                put!(r_t, t);
                put!(prev_t, t);
                put!(prev_r, r);
                put!(t, next);
            }
        }
        common
    }
}

/// The four-lane mask (all ones in lane `k` where bit `k` of `bits` is set).
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn lanes(bits: u8) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    let lane_bits = _mm256_setr_epi64x(1, 2, 4, 8);
    _mm256_castsi256_pd(_mm256_cmpeq_epi64(
        _mm256_and_si256(_mm256_set1_epi64x(i64::from(bits & 0xf)), lane_bits),
        lane_bits,
    ))
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
        Segment { origin, dir, t0, t1 }
    }

    fn sphere(p: DVec3, _tol: f64) -> f64 {
        (p - DVec3::new(0.0, 0.0, 5.0)).length() - 1.0
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

    /// A field with the events a march meets: a sphere (hits, grazing rays), a plane
    /// (long slanted marches), a thin sheet (probes past a skin of near-zero distance) and
    /// a skin of zero thickness (a box face whose cutter ends on it: touches, no crossing).
    fn events(p: DVec3, _tol: f64) -> f64 {
        let sphere = (p - DVec3::new(0.0, 0.0, 5.0)).length() - 1.0;
        let plane = p.y + 2.0;
        let sheet = (p.x - 3.0).abs() - 0.002;
        let skin = (p.z - 8.0).abs().max(p.x.abs() - 1.0);
        sphere.min(plane).min(sheet).min(skin)
    }

    fn xorshift(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn packets_take_each_lane_s_own_steps() {
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        let settings = [
            MarchParams::default(),
            MarchParams { relaxation: 1.6, ..Default::default() },
            MarchParams { max_steps: 7, pixel_footprint: 0.05, ..Default::default() },
            MarchParams { max_steps: 40, relaxation: 1.9, tolerance_px: 2.0, ..Default::default() },
        ];
        for params in &settings {
            for batch in 0..200 {
                let segs: [Segment; 8] = std::array::from_fn(|_| {
                    let origin = DVec3::new(next() * 4.0 - 2.0, next() * 4.0 - 1.0, next() * 2.0 - 1.0);
                    let aim = DVec3::new(next() * 8.0 - 3.0, next() * 4.0 - 2.5, 5.0 + next() * 4.0);
                    let (t0, t1) = if batch % 3 == 0 { (0.0, 100.0) } else { (next(), 2.0 + next() * 10.0) };
                    Segment { origin, dir: (aim - origin).normalize(), t0, t1 }
                });
                let live: [bool; 8] = std::array::from_fn(|i| batch % 5 != 0 || i % 3 != 0);
                let mut alone = RayStats::default();
                let expected: [Option<Option<MarchHit>>; 8] = std::array::from_fn(|i| {
                    live[i].then(|| sphere_trace(&events, &segs[i], 2.0, params, true, &mut alone))
                });
                let mut together = RayStats::default();
                let mut got = [None; 8];
                let bounds = std::array::from_fn(|i| live[i].then_some((segs[i].t0, segs[i].t1)));
                if let Some(mut packet) = MarchPacket::new(&bounds, &mut together) {
                    while packet.marching() {
                        let tol = packet.tolerances(params, 2.0);
                        let raw = std::array::from_fn(|i| {
                            events(segs[i].origin + segs[i].dir * packet.t()[i], tol[i])
                        });
                        packet.feed(&raw, 2.0, params, true, &mut together, |i, outcome, _| {
                            got[i] = Some(outcome)
                        });
                    }
                }
                assert_eq!(got, expected, "{params:?}");
                assert_eq!(together, alone, "{params:?}");
            }
        }
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn wide_common_steps_equal_lane_by_lane() {
        if !crate::simd::avx2() {
            return;
        }
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        let special = [0.0, -0.0, f64::NAN, f64::INFINITY, -f64::INFINITY, 1e-300, -1e-9];
        let mut pick = |scale: f64| {
            let u = next();
            if u < 0.1 { special[(u * 70.0) as usize % special.len()] } else { (next() - 0.3) * scale }
        };
        for round in 0..5000 {
            let segs = std::array::from_fn(|i| (i != round % 9).then_some((0.0, 10.0)));
            let Some(mut a) = MarchPacket::new(&segs, &mut RayStats::default()) else { continue };
            for i in 0..8 {
                (a.t[i], a.t1[i], a.phase_eps[i]) = (pick(10.0), pick(12.0), pick(0.01));
                a.sign[i] = [0.0, 1.0, -1.0][round % 3];
            }
            a.marching = (round * 37) as u8;
            let raw = std::array::from_fn(|_| pick(2.0));
            // The tolerance's factors are finite and positive (a scene's camera and size).
            let (c, floor, candidates) =
                (1e-2 / (1 + round % 7) as f64, 1e-3 * (1 + round % 3) as f64, (round * 101) as u8);
            let mut b = a.clone();
            let wide = unsafe { a.common_steps_avx2(&raw, c, floor, candidates) };
            let one = b.common_steps_scalar(&raw, c, floor, candidates);
            assert_eq!(wide, one);
            let bits = |x: &[f64; 8]| x.map(f64::to_bits);
            for (x, y) in [(&a.t, &b.t), (&a.sign, &b.sign), (&a.r, &b.r), (&a.r_t, &b.r_t)] {
                assert_eq!(bits(x), bits(y));
            }
            assert_eq!(bits(&a.prev_t), bits(&b.prev_t));
            assert_eq!(bits(&a.prev_r), bits(&b.prev_r));
            let params = MarchParams { epsilon: c, tolerance_px: 1e9, ..Default::default() };
            let size = floor / 1e-4;
            assert_eq!(
                bits(&unsafe { a.tolerances_avx2(c, 1e-4 * size) }),
                bits(&a.tolerances_scalar(&params, size))
            );
        }
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
