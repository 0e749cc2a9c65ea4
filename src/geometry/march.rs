//! Sphere tracing of distance functions: plain and over-relaxed ("enhanced", Keinert et
//! al. 2014), with a hit tolerance relative to the distance travelled, a step limit that is
//! counted rather than hidden, a refinement step, and normals from the distance gradient.
//! One state machine ([`MarchLanes`]) runs one ray ([`sphere_trace`]) or 8 to 32 side by
//! side, the common step of four lanes at a time in AVX2;
//! [`crate::geometry::marched::Marched`] is the one geometry that runs it on every marched
//! field (analytic SDFs, SDF grids).

use glam::DVec3;

use crate::geometry::{PACKET, Ray, RayStats};
use crate::simd::{Kernel, Lane64, Simd};

/// Lanes a [`crate::geometry::marched::Marched`] batch marches side by side when its field
/// refills lanes, and the lanes of a stencil [`PointBlock`]: four packets.
pub const WIDE: usize = 4 * PACKET;

/// What the lanes of a [`PointBlock`] hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlockKind {
    /// Marching lanes: lane `l` is the point `origin + dir * t` of its ray, to within
    /// `tol[l]`, computed as `DVec3` arithmetic does (`o + d * t` per component, rounded
    /// after the product and the sum; [`PointBlock::point`]). Each lane's value must be
    /// what the field's scalar distance gives at that point alone.
    Rays,
    /// Normal stencils ([`gradient_normal`], a [`PointBlock`] of [`WIDE`] lanes): lanes
    /// `4 k .. 4 k + 4` are the four points of stencil `k` (in `origin`; `dir` and `t`
    /// unused), all to within `tol[4 k]`. The four points of a stencil are evaluated
    /// alike: a field may answer them from a faster evaluator only where it is precise
    /// enough for all four, else all four from its precise one (so that the gradient sees
    /// one smooth function).
    Stencils,
}

/// Points by component for the bulk call: `[a][l]` is component `a` of lane `l` (lane
/// `l % 8` of packet `l / 8`).
pub type Rays32 = [[f64; WIDE]; 3];

/// One number per lane of a [`WIDE`] block.
pub type Lanes32 = [f64; WIDE];

/// A structure-of-arrays block of `W` points (a multiple of [`PACKET`], at most [`WIDE`]; a
/// scalar march's one lane is never evaluated in bulk), the one bulk call of a field
/// (`DistanceField::distances`): a batch's lanes live in it ([`MarchLanes::pts`], so
/// nothing is copied to evaluate them), or the marcher packs its normal stencils into it;
/// the field writes each active lane's distance into `out`.
#[derive(Clone, Debug)]
pub struct PointBlock<const W: usize = WIDE> {
    /// What the lanes hold.
    pub kind: BlockKind,
    /// Ray origins by component ([`BlockKind::Rays`]), or the points themselves
    /// ([`BlockKind::Stencils`]).
    pub origin: [[f64; W]; 3],
    /// Ray directions by component ([`BlockKind::Rays`]).
    pub dir: [[f64; W]; 3],
    /// Ray parameters ([`BlockKind::Rays`]).
    pub t: [f64; W],
    /// The tolerance of each lane (world units): its value may be off by a quarter of it.
    pub tol: [f64; W],
    /// Bit `l` set: lane `l` is evaluated. A field evaluates lanes by packets of
    /// [`PACKET`] (those with an active lane); the values of other lanes are not used.
    /// [`BlockKind::Stencils`] are active in whole stencils, from lane 0 up.
    pub active: u32,
    /// The distances, written by the bulk call for the active lanes.
    pub out: [f64; W],
}

impl<const W: usize> PointBlock<W> {
    /// An empty block of `kind` (no active lane, every number 0, tolerances infinite).
    pub fn new(kind: BlockKind) -> Self {
        PointBlock {
            kind,
            origin: [[0.0; W]; 3],
            dir: [[0.0; W]; 3],
            t: [0.0; W],
            tol: [f64::INFINITY; W],
            active: 0,
            out: [0.0; W],
        }
    }

    /// Lane `l`'s point: the ray point ([`Self::ray_point`], [`BlockKind::Rays`]) or the
    /// stencil point.
    #[inline]
    pub fn point(&self, l: usize) -> DVec3 {
        match self.kind {
            BlockKind::Rays => self.ray_point(l),
            BlockKind::Stencils => DVec3::new(self.origin[0][l], self.origin[1][l], self.origin[2][l]),
        }
    }

    /// Lane `l`'s ray point `origin + dir * t`, as `DVec3` arithmetic computes it (for a
    /// block known to hold [`BlockKind::Rays`]).
    #[inline]
    pub fn ray_point(&self, l: usize) -> DVec3 {
        DVec3::new(self.origin[0][l], self.origin[1][l], self.origin[2][l])
            + DVec3::new(self.dir[0][l], self.dir[1][l], self.dir[2][l]) * self.t[l]
    }

    /// The points of packet `g` (lanes `8 g ..`), [`Self::point`] lane by lane.
    #[inline]
    pub fn packet_points(&self, g: usize) -> [DVec3; PACKET] {
        std::array::from_fn(|l| self.point(PACKET * g + l))
    }

    /// Bit `g` set: packet `g` has an active lane.
    #[inline]
    pub fn packets(&self) -> u32 {
        (0..W / PACKET).filter(|g| self.active >> (PACKET * g) & 0xff != 0).fold(0, |p, g| p | 1 << g)
    }

    /// This block as a [`WIDE`] one, where `W` is [`WIDE`] (for a field's 32-lane kernels).
    #[inline]
    pub fn wide_mut(&mut self) -> Option<&mut PointBlock<WIDE>> {
        (self as &mut dyn std::any::Any).downcast_mut()
    }

    /// Writes `f(point, tolerance)` into `out` for each lane of the packets with an active
    /// lane: the lane-by-lane evaluation of a field without a faster one.
    #[inline]
    pub fn fill_each(&mut self, f: impl Fn(DVec3, f64) -> f64) {
        let packets = self.packets();
        for g in 0..W / PACKET {
            if packets & 1 << g != 0 {
                for l in PACKET * g..PACKET * (g + 1) {
                    self.out[l] = f(self.point(l), self.tol[l]);
                }
            }
        }
    }
}

impl PointBlock<WIDE> {
    /// A block of the `N` normal stencils `stencils` (stencil `k` to within
    /// `tolerances[k]`), `N` at most 8.
    pub fn stencils<const N: usize>(stencils: &[[DVec3; 4]; N], tolerances: &[f64; N]) -> Self {
        let mut b = PointBlock::new(BlockKind::Stencils);
        b.set_stencils(stencils, tolerances);
        b
    }

    /// Makes this block hold the `N` normal stencils `stencils` (stencil `k` to within
    /// `tolerances[k]`), `N` at most 8, as [`Self::stencils`] builds them; lanes past
    /// them are left as they were and inactive.
    #[inline]
    pub fn set_stencils<const N: usize>(&mut self, stencils: &[[DVec3; 4]; N], tolerances: &[f64; N]) {
        const { assert!(N <= 8) };
        let b = self;
        b.kind = BlockKind::Stencils;
        for (k, s) in stencils.iter().enumerate() {
            for (j, p) in s.iter().enumerate() {
                let l = 4 * k + j;
                (b.origin[0][l], b.origin[1][l], b.origin[2][l]) = (p.x, p.y, p.z);
                b.tol[l] = tolerances[k];
            }
        }
        b.active = (1u64 << (4 * N)).wrapping_sub(1) as u32;
    }

    /// The number of stencils of a [`BlockKind::Stencils`] block.
    #[inline]
    pub fn stencil_count(&self) -> usize {
        self.active.count_ones() as usize / 4
    }
}

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
/// representation; its batches run the same steps in more lanes of [`MarchLanes`].
pub fn sphere_trace(
    f: &impl Fn(DVec3, f64) -> f64,
    seg: &Segment,
    size: f64,
    params: &MarchParams,
    refine: bool,
    stats: &mut RayStats,
) -> Option<MarchHit> {
    let mut lane = MarchLanes::<1>::new(params, size, refine);
    lane.start(0, seg, stats);
    loop {
        let raw = f(seg.origin + seg.dir * lane.pts.t[0], lane.pts.tol[0]);
        // [`MarchLanes::feed`] for the one lane, its common step taken directly.
        if lane.special == 0 && lane.plain_step(0, raw) {
            stats.march_steps += 1;
        } else if lane.feed_lanes(&[raw], 1, stats) != 0 {
            return lane.outcome(0);
        }
    }
}

/// `W` sphere traces side by side, each a state machine in its lane: `MarchLanes::pts.t` is
/// where a lane's distance is needed next, to within `MarchLanes::pts.tol`, and
/// [`MarchLanes::feed`] takes the distances of the lanes marching and says whose marches
/// are over. Scalar marching ([`sphere_trace`]) uses one lane; a batch
/// ([`crate::geometry::marched::Marched`]) feeds 8 or 32 lanes from one wide evaluation.
/// Every lane takes exactly the steps [`sphere_trace`] would for its ray alone.
///
/// The state is kept by field, one array per field (structure of arrays): the common step
/// (a plain sphere-tracing step that neither converges, leaves the segment nor runs out of
/// budget) runs for all lanes at once, without branches
/// ([`MarchLanes::feed`]); the rest (first contact, probes, refinement, the end of a march)
/// goes lane by lane.
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
/// [`MAX_TOUCHES`]): a value of the other sign confirms the crossing, and the hit is
/// refined between the two points (secant) and kept where the field is smaller there.
/// Without a sign change the point only touches zero (a skin, or a ray grazing a surface it
/// does not enter), and the march goes on from the probe with plain steps, up to
/// [`MAX_TOUCHES`] times in a row. Unsigned fields (a triangle) have no inside: their hits
/// are accepted on convergence, unrefined.
#[derive(Clone, Debug)]
pub struct MarchLanes<const W: usize> {
    /// Each lane's ray by component, the ray parameter where its distance is needed next
    /// (`t`) and the tolerance it must be resolved to there (`tol`, world units; infinite
    /// for a lane that marches nothing): the field is evaluated at `origin + dir * t`,
    /// this block as it stands (the bulk call of a batch, with `active` set by the caller).
    pub pts: PointBlock<W>,
    /// The caller's index of each lane's ray ([`Self::assign`]), moved with the lane.
    pub ray: [usize; W],
    /// The caller's end of each lane's ray ([`Self::assign`]), moved with the lane.
    pub reach: [f32; W],
    /// [`Segment::spread`].
    spread: [f64; W],
    /// [`Segment::t0`] and [`Segment::t1`].
    t0: [f64; W],
    t1: [f64; W],
    /// Sign of the field at the first point (1 outside, -1 inside; 0 before it).
    sign: [f64; W],
    prev_t: [f64; W],
    prev_r: [f64; W],
    /// |distance| at the last point marched, `r_t`.
    r: [f64; W],
    r_t: [f64; W],
    omega: [f64; W],
    /// March evaluations so far (the step budget, [`MarchParams::max_steps`]).
    iterations: [u32; W],
    /// Probes in a row that found no sign change (see [`MAX_TOUCHES`]).
    touches: [u32; W],
    /// The converged point where the current run of touches began.
    first_touch: [MarchHit; W],
    phase: [Phase; W],
    /// Bit `l` set where lane `l`'s phase is not [`Phase::March`] (kept with `phase` by
    /// [`Self::set_phase`]).
    special: u32,
    /// How each lane's march ended, for the lanes [`Self::feed`] last reported.
    outcome: [Option<MarchHit>; W],
    params: MarchParams,
    /// `min(epsilon, tolerance_px * pixel_footprint)` and `1e-4 * size`: the factor and
    /// floor of [`MarchParams::tolerance`], computed once.
    tol_scale: f64,
    tol_floor: f64,
    refine: bool,
}

/// Converged points in a row without a sign change after which a march accepts the first
/// of them as a hit: a ray that runs along a surface within the tolerance for that long (a
/// ray in the plane of a face) is seen as that surface. The probes after a touch reach
/// twice as far each time (half a tolerance, one, two, ...), so a skin is left after one or
/// two and a ray tangent to a curved surface leaves its zone of near-zero distance (of
/// length `2 sqrt(2 R tolerance)` for radius `R`) after a few; 16 probes cover `2^15`
/// tolerances.
pub const MAX_TOUCHES: u32 = 16;

/// What the value fed to a lane of [`MarchLanes`] is for.
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

/// What a lane's step says: the march goes on (`None`), or it is over with a hit or a
/// miss.
type Step = Option<Option<MarchHit>>;

impl<const W: usize> MarchLanes<W> {
    /// `W` idle lanes (`W <= 32`) marching with `params`, tolerances for an object of
    /// characteristic `size`, and refinement onto the surface where `refine` (a signed
    /// field).
    pub fn new(params: &MarchParams, size: f64, refine: bool) -> Self {
        const { assert!(W >= 1 && W <= 32) };
        MarchLanes {
            pts: PointBlock::new(BlockKind::Rays),
            ray: [0; W],
            reach: [0.0; W],
            spread: [0.0; W],
            t0: [0.0; W],
            t1: [0.0; W],
            sign: [0.0; W],
            prev_t: [0.0; W],
            prev_r: [0.0; W],
            r: [f64::INFINITY; W],
            r_t: [0.0; W],
            omega: [0.0; W],
            iterations: [0; W],
            touches: [0; W],
            first_touch: [MarchHit { t: 0.0, residual: 0.0 }; W],
            phase: [Phase::March; W],
            special: 0,
            outcome: [None; W],
            params: *params,
            tol_scale: params.epsilon.min(params.tolerance_px * params.pixel_footprint),
            tol_floor: 1e-4 * size,
            refine,
        }
    }

    /// Lane `l` starts marching `seg` (counts the ray in `stats.marched_rays`).
    #[inline]
    pub fn start(&mut self, l: usize, seg: &Segment, stats: &mut RayStats) {
        stats.marched_rays += 1;
        self.pts.t[l] = seg.t0;
        for a in 0..3 {
            (self.pts.origin[a][l], self.pts.dir[a][l]) = (seg.origin[a], seg.dir[a]);
        }
        self.spread[l] = seg.spread;
        (self.t0[l], self.t1[l]) = (seg.t0, seg.t1);
        self.sign[l] = 0.0;
        (self.prev_t[l], self.prev_r[l]) = (seg.t0, 0.0);
        (self.r[l], self.r_t[l]) = (f64::INFINITY, seg.t0);
        self.omega[l] = 0.0;
        (self.iterations[l], self.touches[l]) = (0, 0);
        self.first_touch[l] = MarchHit { t: seg.t0, residual: 0.0 };
        self.set_phase(l, Phase::March);
        self.pts.tol[l] = self.march_tolerance(l);
    }

    /// Records the caller's index `ray` and end `reach` of lane `l`'s ray
    /// ([`Self::ray`], [`Self::reach`]).
    #[inline]
    pub fn assign(&mut self, l: usize, ray: usize, reach: f32) {
        (self.ray[l], self.reach[l]) = (ray, reach);
    }

    /// Idle lane `l` evaluates lane `from`'s point (its value is not used): the same
    /// parameter, origin and direction.
    #[inline]
    pub fn copy_point(&mut self, from: usize, l: usize) {
        self.pts.t[l] = self.pts.t[from];
        for a in 0..3 {
            (self.pts.origin[a][l], self.pts.dir[a][l]) = (self.pts.origin[a][from], self.pts.dir[a][from]);
        }
    }

    /// Lane `l` marches nothing (its tolerance is infinite, `Self::pts.tol`).
    #[inline]
    pub fn stop(&mut self, l: usize) {
        self.pts.tol[l] = f64::INFINITY;
    }

    /// Lane `to` (idle) takes over lane `from`'s march where it stands, and `from` marches
    /// nothing: the march goes on in `to` with the same steps.
    #[inline]
    pub fn move_lane(&mut self, from: usize, to: usize) {
        self.copy_point(from, to);
        (self.ray[to], self.reach[to]) = (self.ray[from], self.reach[from]);
        self.pts.tol[to] = self.pts.tol[from];
        self.spread[to] = self.spread[from];
        (self.t0[to], self.t1[to]) = (self.t0[from], self.t1[from]);
        self.sign[to] = self.sign[from];
        (self.prev_t[to], self.prev_r[to]) = (self.prev_t[from], self.prev_r[from]);
        (self.r[to], self.r_t[to]) = (self.r[from], self.r_t[from]);
        self.omega[to] = self.omega[from];
        (self.iterations[to], self.touches[to]) = (self.iterations[from], self.touches[from]);
        self.first_touch[to] = self.first_touch[from];
        self.set_phase(to, self.phase[from]);
        self.set_phase(from, Phase::March);
        self.stop(from);
    }

    /// How lane `l`'s march ended, once [`Self::feed`] reported it: the hit, or `None` for
    /// a miss.
    #[inline]
    pub fn outcome(&self, l: usize) -> Option<MarchHit> {
        self.outcome[l]
    }

    /// [`MarchParams::tolerance`] at lane `l`'s `Self::pts.t`.
    #[inline]
    fn march_tolerance(&self, l: usize) -> f64 {
        self.tol_scale * (self.spread[l] + self.pts.t[l]).max(self.tol_floor)
    }

    #[inline]
    fn set_phase(&mut self, l: usize, phase: Phase) {
        self.phase[l] = phase;
        let bit = 1u32 << l;
        self.special = if phase == Phase::March { self.special & !bit } else { self.special | bit };
    }

    /// Takes the field's values `raw[l]` at `Self::pts.t` for the lanes `l` whose bits are
    /// set in `marching`; returns the lanes whose marches are over ([`Self::outcome`]).
    /// Every other marching lane has its next `Self::pts.t` and `Self::pts.tol`.
    ///
    /// The common step runs for all lanes at once: a lane in [`Phase::March`] whose step
    /// neither converges, nor falls back from over-relaxation, nor leaves the segment, nor
    /// spends the budget just moves on (the test and the move are the operations of
    /// [`Self::step`], so the results are the same bits). The other lanes take
    /// [`Self::feed_lane`].
    #[inline]
    pub fn feed(&mut self, raw: &[f64; W], marching: u32, stats: &mut RayStats) -> u32 {
        let plain = self.plain_steps(raw, marching & !self.special);
        stats.march_steps += u64::from(plain.count_ones());
        self.feed_lanes(raw, marching & !plain, stats)
    }

    /// [`Self::feed_lane`] for each lane set in `lanes` (those whose step is not plain);
    /// returns the lanes whose marches are over, and sets the others' `Self::pts.tol`.
    #[inline(always)]
    fn feed_lanes(&mut self, raw: &[f64; W], lanes: u32, stats: &mut RayStats) -> u32 {
        let mut ended = 0;
        let mut rest = lanes;
        while rest != 0 {
            let l = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            if let Some(outcome) = self.feed_lane(l, raw[l], stats) {
                self.outcome[l] = outcome;
                ended |= 1 << l;
            } else {
                self.pts.tol[l] = match self.phase[l] {
                    Phase::Probe { eps, .. } | Phase::Refine { eps, .. } => eps,
                    Phase::March => self.march_tolerance(l),
                };
            }
        }
        ended
    }

    /// The common steps of [`Self::feed`] for the lanes in `lanes` (all in
    /// [`Phase::March`]): each lane whose step is plain ([`Self::plain_step`]) takes it;
    /// returns those lanes. Four lanes at a time with AVX2 where the CPU has it.
    #[inline]
    fn plain_steps(&mut self, raw: &[f64; W], lanes: u32) -> u32 {
        if W.is_multiple_of(4) && crate::simd::backend() == crate::simd::Backend::Avx2 {
            return crate::simd::dispatch(PlainSteps { m: self, raw, lanes });
        }
        let mut plain = 0;
        let mut m = lanes;
        while m != 0 {
            let l = m.trailing_zeros() as usize;
            m &= m - 1;
            if self.plain_step(l, raw[l]) {
                plain |= 1 << l;
            }
        }
        plain
    }

    /// Lane `l`'s step with the field's value `raw` at `Self::pts.t` if it is plain: the
    /// lane is in [`Phase::March`], and [`Self::step`] would neither fall back from
    /// over-relaxation, nor converge, nor leave the segment, nor spend the step budget, but
    /// only move on by `d * omega`. Then takes it, as [`Self::step`] does (same
    /// operations, same bits), and returns true; else changes nothing and returns false.
    #[inline(always)]
    fn plain_step(&mut self, l: usize, raw: f64) -> bool {
        let sign = if self.sign[l] != 0.0 {
            self.sign[l]
        } else if raw < 0.0 {
            -1.0
        } else {
            1.0
        };
        let omega = if self.iterations[l] == 0 { self.params.relaxation } else { self.omega[l] };
        let (t, d) = (self.pts.t[l], sign * raw);
        let (r, next) = (d.abs(), t + d * omega);
        let fallback = omega > 1.0 && self.prev_r[l] + r < t - self.prev_t[l];
        if fallback
            || !(r >= self.pts.tol[l])
            || !(next <= self.t1[l])
            || self.iterations[l] >= self.params.max_steps.saturating_sub(1)
        {
            return false;
        }
        (self.sign[l], self.omega[l]) = (sign, omega);
        (self.prev_t[l], self.prev_r[l], self.r[l], self.r_t[l]) = (t, r, r, t);
        self.pts.t[l] = next;
        self.iterations[l] += 1;
        self.touches[l] = 0;
        self.pts.tol[l] = self.march_tolerance(l);
        true
    }

    /// [`Self::feed`] for lane `l` alone, whatever its phase.
    #[inline(always)]
    fn feed_lane(&mut self, l: usize, raw: f64, stats: &mut RayStats) -> Step {
        match self.phase[l] {
            Phase::March => {}
            Phase::Refine { t, r, eps } => {
                // Kept where the field is smaller than at the converged point and not
                // before the segment.
                let r2 = raw.abs();
                return Some(Some(if r2 <= r && self.pts.t[l] >= self.t0[l] - eps {
                    MarchHit { t: self.pts.t[l], residual: r2 }
                } else {
                    MarchHit { t, residual: r }
                }));
            }
            Phase::Probe { t, d, eps } => {
                let dp = self.sign[l] * raw;
                if dp < 0.0 {
                    // The field changes sign between t and the probe: a surface. Refine at
                    // the secant's zero (two evaluations: the probe and the refinement).
                    stats.march_steps += 2;
                    self.set_phase(l, Phase::Refine { t, r: d, eps });
                    self.pts.t[l] = t + (self.pts.t[l] - t) * d / (d - dp);
                    return None;
                }
                // Only touching zero: march on from the probe, with plain steps.
                self.set_phase(l, Phase::March);
                if self.touches[l] == 0 {
                    self.first_touch[l] = MarchHit { t, residual: d };
                }
                self.touches[l] += 1;
                self.omega[l] = 1.0;
                self.prev_t[l] = t;
                self.prev_r[l] = d;
                if self.pts.t[l] > self.t1[l] {
                    return Some(None);
                }
            }
        }
        self.step(l, raw, stats)
    }

    /// One sphere-tracing step of lane `l` with the field's value `raw` at `Self::pts.t`.
    #[inline(always)]
    fn step(&mut self, l: usize, raw: f64, stats: &mut RayStats) -> Step {
        if self.iterations[l] == 0 {
            self.omega[l] = self.params.relaxation;
        }
        self.iterations[l] += 1;
        stats.march_steps += 1;
        let t = self.pts.t[l];
        let eps = self.march_tolerance(l);
        if self.sign[l] == 0.0 {
            self.sign[l] = if raw < 0.0 { -1.0 } else { 1.0 };
        }
        let d = self.sign[l] * raw;
        let r = d.abs();
        (self.r[l], self.r_t[l]) = (r, t);
        // With over-relaxation the step may jump over a surface; detect it by the two
        // unbounding spheres (radii prev_r and r) failing to cover the step, and go back
        // to the plain step from the previous point.
        if self.omega[l] > 1.0 && self.prev_r[l] + r < t - self.prev_t[l] {
            self.omega[l] = 1.0;
            self.pts.t[l] = self.prev_t[l] + self.prev_r[l];
            return self.budget(l, stats);
        }
        if r >= eps {
            self.touches[l] = 0;
        }
        if r < eps {
            if !self.refine {
                return Some(Some(MarchHit { t, residual: r }));
            }
            if self.touches[l] >= MAX_TOUCHES {
                return Some(Some(self.first_touch[l]));
            }
            if d < 0.0 {
                // Already past the surface: crossed. One refinement step back onto it.
                stats.march_steps += 1;
                self.set_phase(l, Phase::Refine { t, r, eps });
                self.pts.t[l] = t + d;
                return None;
            }
            if self.iterations[l] >= self.params.max_steps {
                return self.budget(l, stats);
            }
            // The probe is counted as a step when it is marched on from (`step`), or with
            // the refinement when it confirms the crossing.
            self.set_phase(l, Phase::Probe { t, d, eps });
            self.pts.t[l] = t + d + 0.5 * eps * f64::from(1u32 << self.touches[l].min(15));
            return None;
        }
        (self.prev_t[l], self.prev_r[l]) = (t, r);
        self.pts.t[l] = t + d * self.omega[l];
        if self.pts.t[l] > self.t1[l] {
            // A relaxed step past the end may have jumped a surface near the end: retry it
            // as a plain step, which is safe.
            if self.omega[l] > 1.0 && self.prev_t[l] + self.prev_r[l] <= self.t1[l] {
                self.omega[l] = 1.0;
                self.pts.t[l] = self.prev_t[l] + self.prev_r[l];
                return self.budget(l, stats);
            }
            return Some(None);
        }
        self.budget(l, stats)
    }

    /// The end of lane `l`'s march that goes on: over when the step budget is spent
    /// (reported as a hit at the last point marched, only within the pixel footprint of
    /// the surface).
    #[inline(always)]
    fn budget(&self, l: usize, stats: &mut RayStats) -> Step {
        if self.iterations[l] < self.params.max_steps {
            return None;
        }
        stats.step_limit_hits += 1;
        let (t, r) = (self.r_t[l], self.r[l]);
        Some(
            (t > 0.0 && r < self.params.pixel_footprint * (self.spread[l] + t))
                .then_some(MarchHit { t, residual: r }),
        )
    }
}

/// [`MarchLanes::plain_steps`] four lanes at a time, for `W` a multiple of 4:
/// [`MarchLanes::plain_step`]'s operations on four lanes at once, with its comparisons as
/// ordered ones (false with a NaN, as Rust's are), its selections as blends and its
/// updates kept only in the lanes that take the step, so each lane's results are the
/// scalar ones bit for bit.
struct PlainSteps<'a, const W: usize> {
    m: &'a mut MarchLanes<W>,
    raw: &'a [f64; W],
    lanes: u32,
}

impl<const W: usize> Kernel for PlainSteps<'_, W> {
    type Output = u32;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> u32 {
        let PlainSteps { m, raw, lanes } = self;
        let (zero, one) = (s.splat4(0.0), s.splat4(1.0));
        let relaxation = s.splat4(m.params.relaxation);
        let (scale, floor) = (s.splat4(m.tol_scale), s.splat4(m.tol_floor));
        let magnitude = s.splat4(f64::from_bits(i64::MAX as u64));
        // `iterations < max_steps - 1` as a signed comparison: a lane past i32::MAX
        // iterations takes the scalar step.
        let limit = m.params.max_steps.saturating_sub(1).min(i32::MAX as u32) as i32;
        let mut plain = 0u32;
        for i in (0..W).step_by(4) {
            let want = lanes >> i & 0xf;
            if want == 0 {
                continue;
            }
            let (t, x, sign0) = (s.load4_at(&m.pts.t, i), s.load4_at(raw, i), s.load4_at(&m.sign, i));
            let (fresh, budget) = s.u32_masks4(&m.iterations, i, limit);
            let negative = x.cmp_lt(zero);
            let first_sign = S::F64x4::select(negative, s.splat4(-1.0), one);
            let sign = S::F64x4::select(sign0.cmp_eq(zero), first_sign, sign0);
            let omega = S::F64x4::select(fresh, relaxation, s.load4_at(&m.omega, i));
            let d = sign * x;
            let r = d.and(magnitude);
            let next = t + d * omega;
            let covered = s.load4_at(&m.prev_r, i) + r;
            let fallback = omega.cmp_gt(one).and(covered.cmp_lt(t - s.load4_at(&m.prev_t, i)));
            let moves = r.cmp_ge(s.load4_at(&m.pts.tol, i)).and(next.cmp_le(s.load4_at(&m.t1, i)));
            let go = fallback.andnot(moves).and(budget);
            let k = go.movemask() & want;
            if k == 0 {
                continue;
            }
            plain |= k << i;
            let keep = s.mask4(k);
            // Lanes `i..i + 4` of `a` become `v` where the step is taken. A macro, not a
            // closure: a closure is compiled without the AVX2 of the kernel's function.
            macro_rules! store {
                ($a:expr, $v:expr) => {
                    S::F64x4::select(keep, $v, s.load4_at($a, i)).store_at($a, i)
                };
            }
            store!(&mut m.sign, sign);
            store!(&mut m.omega, omega);
            store!(&mut m.prev_t, t);
            store!(&mut m.prev_r, r);
            store!(&mut m.r, r);
            store!(&mut m.r_t, t);
            store!(&mut m.pts.t, next);
            let spread = s.load4_at(&m.spread, i);
            store!(&mut m.pts.tol, scale * (spread + next).vmax(floor));
            let mut taken = k;
            while taken != 0 {
                let l = i + taken.trailing_zeros() as usize;
                taken &= taken - 1;
                m.iterations[l] += 1;
                m.touches[l] = 0;
            }
        }
        plain
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

/// [`gradient_normal`] at `N` points at once (`at[k]`: point `k` and its step): `f`
/// evaluates all the stencils together (a field does that in one wide evaluation), each
/// lane as [`gradient_normal`]'s `f4` would, so each normal is bit for bit the one
/// [`gradient_normal`] gives at that point alone.
pub fn gradient_normals<const N: usize>(
    f: impl FnOnce(&[[DVec3; 4]; N]) -> [[f64; 4]; N],
    at: [(DVec3, f64); N],
    stats: &mut RayStats,
) -> [DVec3; N] {
    stats.march_steps += 4 * N as u64;
    f(&at.map(|(p, h)| tetrahedron_points(p, h))).map(tetrahedron_normal)
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
        let tolerance_at_start = |s: &Segment| {
            let mut lane = MarchLanes::<1>::new(&params, size, false);
            lane.start(0, s, &mut RayStats::default());
            lane.pts.tol[0]
        };
        assert_eq!(tolerance_at_start(&s), params.tolerance(0.0, size));
        let mut stats = RayStats::default();
        // Hits accepted on convergence (as for an unsigned field): the test is the tolerance.
        assert!(sphere_trace(&sphere, &s, size, &params, false, &mut stats).is_none());
        s.spread = spread;
        assert_eq!(tolerance_at_start(&s), params.tolerance(spread, size));
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

    /// A field with what a march must survive: a rippled sphere (not a true distance, so
    /// relaxed steps overshoot), a sheet thinner than most tolerances, a skin where the
    /// field touches zero without changing sign, and a slab where it is NaN.
    fn rough(p: DVec3, _tol: f64) -> f64 {
        if (p.x - 0.3).abs() < 2e-3 && p.z > 6.0 {
            return f64::NAN;
        }
        let ripple = 0.08 * (7.0 * p.x).sin() * (5.0 * p.y).cos();
        let ball = (p - DVec3::new(0.0, 0.0, 5.0)).length() - 1.0 + ripple;
        let sheet = (p.z - 8.0).abs() - 1e-5;
        let skin = (p.y - 0.5).abs().max(p.z - 3.0);
        ball.min(sheet).min(skin)
    }

    /// `W` rays marched side by side through [`rough`], one lane each, refilled from
    /// `segs` as lanes end; the outcomes and counters.
    fn march_wide<const W: usize>(
        segs: &[Segment],
        params: &MarchParams,
        refine: bool,
    ) -> (Vec<Option<MarchHit>>, RayStats) {
        let (mut stats, mut out) = (RayStats::default(), vec![None; segs.len()]);
        let mut lanes = MarchLanes::<W>::new(params, 2.0, refine);
        let (mut ray_of, mut next, mut marching) = ([0usize; W], 0, 0u32);
        loop {
            for (l, ray) in ray_of.iter_mut().enumerate() {
                if marching & 1 << l == 0 && next < segs.len() {
                    lanes.start(l, &segs[next], &mut stats);
                    (*ray, next, marching) = (next, next + 1, marching | 1 << l);
                }
            }
            if marching == 0 {
                return (out, stats);
            }
            let raw = std::array::from_fn(|l| {
                let s = &segs[ray_of[l]];
                if marching & 1 << l != 0 {
                    rough(s.origin + s.dir * lanes.pts.t[l], lanes.pts.tol[l])
                } else {
                    f64::NAN
                }
            });
            let mut ended = lanes.feed(&raw, marching, &mut stats);
            marching &= !ended;
            while ended != 0 {
                let l = ended.trailing_zeros() as usize;
                ended &= ended - 1;
                lanes.stop(l);
                out[ray_of[l]] = lanes.outcome(l);
            }
        }
    }

    proptest::proptest! {
        /// Lanes marched side by side (4 at a time with AVX2 in 8 and 32 lanes) take the
        /// steps of [`sphere_trace`] alone, bit for bit, and count the same work.
        #[test]
        fn lanes_march_as_one_ray_alone(
            rays in proptest::collection::vec(
                ((-1.5f64..1.5, -1.5f64..1.5), (-0.3f64..0.3, -0.3f64..0.3), 0.0f64..0.5, 0.0f64..50.0),
                1..40,
            ),
            relaxation in proptest::sample::select(vec![1.0, 1.6, 1.95]),
            max_steps in proptest::sample::select(vec![1u32, 2, 7, 40, 512]),
            tolerance_px in proptest::sample::select(vec![0.25, 4.0]),
            refine in proptest::bool::ANY,
        ) {
            let params = MarchParams { relaxation, max_steps, tolerance_px, ..Default::default() };
            let segs: Vec<Segment> = rays
                .iter()
                .map(|&((x, y), (dx, dy), t0, spread)| Segment {
                    origin: DVec3::new(x, y, 0.0),
                    dir: DVec3::new(dx, dy, 1.0).normalize(),
                    t0,
                    t1: 12.0,
                    spread,
                })
                .collect();
            let mut one_stats = RayStats::default();
            let one: Vec<_> =
                segs.iter().map(|s| sphere_trace(&rough, s, 2.0, &params, refine, &mut one_stats)).collect();
            let bits = |h: &Option<MarchHit>| h.map(|h| (h.t.to_bits(), h.residual.to_bits()));
            for (wide, stats) in [march_wide::<8>(&segs, &params, refine), march_wide::<32>(&segs, &params, refine)] {
                for (i, (a, b)) in one.iter().zip(&wide).enumerate() {
                    proptest::prop_assert_eq!(bits(a), bits(b), "ray {}: {:?} alone, {:?} in lanes", i, a, b);
                }
                proptest::prop_assert_eq!(
                    (stats.march_steps, stats.marched_rays, stats.step_limit_hits),
                    (one_stats.march_steps, one_stats.marched_rays, one_stats.step_limit_hits)
                );
            }
        }
    }
}
