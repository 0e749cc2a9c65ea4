//! One marcher for every ray-marched representation. A [`DistanceField`] says what is
//! marched, in four calls: the distance at a point (already scaled to be a safe step) to
//! within a tolerance, the same in bulk over a [`PointBlock`] of up to 32 lanes, the
//! field's facts (signed, exact, packets, lane refills), and the normal's gradient step and
//! material at a hit. How the object measures, describes and counts itself is a separate
//! [`FieldObject`], which the marcher never asks. [`Marched`] owns everything else, once:
//! the bounds the march is clipped to, the characteristic size that tolerances scale with,
//! the [`MarchParams`], sphere tracing ([`sphere_trace`]) with its refinement step, all
//! packing of rays into 8 and 32 lanes and of normal stencils into blocks, the normal by
//! [`gradient_normal`], the [`Hit`] record and its error bound, and the work counters.
//! Analytic SDFs ([`crate::geometry::sdf::SdfObject`], a [`Marched`] over an
//! [`SdfTree`](crate::geometry::sdf::SdfTree)) and SDF grids
//! ([`crate::geometry::grid::object::GridObject`], a [`Marched`] over a
//! [`GridField`](crate::geometry::grid::object::GridField)) are the fields plugged in
//! today; a new marched representation is a new field, not a new marcher. A field that
//! evaluates eight points at once ([`FieldFacts::packets`]) gets packets of primary rays
//! marched side by side ([`Geometry::closest_hits`]), each lane taking exactly the steps of
//! its own scalar march ([`sphere_trace`] and the batch share [`MarchLanes`], whose lanes
//! live in the block the field evaluates).

use crate::simd::{Kernel, Lane, Lane8, Simd, dispatch};
use glam::{DVec3, Vec3};

pub use crate::geometry::march::{BlockKind, Lanes32, PointBlock, Rays32, WIDE};
use crate::geometry::march::{
    MarchHit, MarchLanes, MarchParams, Segment, gradient_normal, gradient_normals, sphere_trace,
};
use crate::geometry::{
    Aabb, Census, Geometry, Hit, MaterialId, PACKET, Ray, RayStats, Shared, f32_error, max_abs,
};

thread_local! {
    /// Per-thread block of [`Marched::stencils`], built once.
    static STENCILS: std::cell::RefCell<PointBlock> = std::cell::RefCell::new(PointBlock::new(BlockKind::Stencils));
}

/// A distance field that [`Marched`] sphere traces, in world space.
pub trait DistanceField: Send + Sync {
    /// The distance marched at world point `p`, with an error of at most a quarter of
    /// `tolerance` (world units): signed (negative inside) or unsigned, and already scaled
    /// so that a step of this length never crosses the surface (an exact distance, a
    /// Lipschitz-1 lower bound, or a field times a safety factor). A field may answer from
    /// a faster, less precise evaluator where that is enough (the f32 tape of an analytic
    /// SDF).
    fn distance(&self, p: DVec3, tolerance: f64) -> f64;

    /// The bulk call: the distances of the active lanes of `block` into `block.out`
    /// (see [`BlockKind`] for what each lane's value must be). The marcher owns all
    /// packing into lanes; a field evaluates them in its own wide kernels or lane by lane
    /// ([`PointBlock::fill_each`]).
    fn distances<const W: usize>(&self, block: &mut PointBlock<W>);

    /// What the marcher needs to know of the field as a whole (cheap: asked per batch).
    fn facts(&self) -> FieldFacts;

    /// The gradient step for the normal and the material at hit point `p`, whose error
    /// bound is `eps` (the march tolerance at the hit, or its residual if larger).
    fn surface(&self, p: DVec3, eps: f64) -> SurfacePoint;
}

/// What [`Marched`] needs to know of a [`DistanceField`] as a whole
/// ([`DistanceField::facts`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FieldFacts {
    /// Whether [`DistanceField::distance`] is signed. An unsigned field (a triangle, which
    /// has no inside) has no gradient on the surface itself: its march takes no refinement
    /// step onto the surface, and its normal is sampled closer than the hit's own distance.
    pub signed: bool,
    /// Whether the field is the exact Euclidean distance everywhere (false: a bound).
    pub exact: bool,
    /// Whether the field evaluates eight points at once faster than one by one
    /// ([`DistanceField::distances`]), so that packets of rays should be marched together.
    pub packets: bool,
    /// Whether a packet lane whose march ends takes the next ray of the batch at once
    /// (true: no lane idles while rays wait), or only once every lane's march has ended
    /// (false: for a field whose 8-wide evaluation costs more when its lanes are far
    /// apart, such as a field pruned by region, whose packet is evaluated once per region
    /// its lanes fall in; refilled lanes march at different depths).
    pub refills_lanes: bool,
}

/// A hit point's surface as a field sees it ([`DistanceField::surface`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// The step of the tetrahedron gradient ([`gradient_normal`]), scene units.
    pub normal_step: f64,
    /// The material of the surface there.
    pub material: MaterialId,
}

/// How a marched object measures, counts and describes itself: what [`Marched`]'s
/// [`Geometry`] reports beyond tracing (the marcher itself never asks).
pub trait FieldObject {
    /// What the field holds beyond its own struct (which [`Marched`] counts as part of
    /// itself), for [`Geometry::bytes_used`], [`Geometry::census`] and
    /// [`Geometry::shared`].
    fn storage(&self) -> Storage;

    /// Unsigned distance from `p` to the field's surface, for measuring error
    /// ([`Geometry::surface_distance`]); `size` is the object's characteristic size.
    fn surface_distance(&self, p: DVec3, size: f64) -> f64;

    /// How the object is traced ([`Geometry::describe`]), given its label.
    fn describe(&self, label: &str) -> String;
}

/// What a field stores ([`FieldObject::storage`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Storage {
    /// Bytes the field holds beyond its own struct.
    pub heap_bytes: usize,
    /// What the field stores, for measurement tables ([`Geometry::census`]).
    pub census: Census,
    /// Data the field shares with other fields ([`Geometry::shared`]).
    pub shared: Option<Shared>,
}

/// A distance field ray marched inside its bounds: the one marched [`Geometry`].
pub struct Marched<F> {
    field: F,
    /// World-space box the march is clipped to when `bounded` ([`Aabb::INFINITY`]
    /// otherwise). A box and a flag rather than an `Option<Aabb>`: the flag fits in the
    /// struct's padding, where an `Option`'s tag would add 16 bytes to every object's
    /// [`Geometry::bytes_used`].
    bounds: Aabb,
    /// False for an unbounded field, which is marched over the whole ray interval.
    bounded: bool,
    /// Characteristic size of the object (scene units, > 0) that the hit tolerance's floor
    /// scales with ([`MarchParams::tolerance`]).
    size: f64,
    march: MarchParams,
    /// Label or reason given to [`FieldObject::describe`].
    label: String,
}

impl<F: DistanceField> Marched<F> {
    /// Marches `field` inside `bounds` (`None`: unbounded) with tolerances for an object of
    /// characteristic `size` (scene units); `label` names the object in
    /// [`Geometry::describe`].
    pub fn from_field(field: F, bounds: Option<Aabb>, size: f64, march: MarchParams, label: String) -> Self {
        Marched {
            field,
            bounded: bounds.is_some(),
            bounds: bounds.unwrap_or(Aabb::INFINITY),
            size,
            march,
            label,
        }
    }

    /// The field marched.
    pub fn field(&self) -> &F {
        &self.field
    }

    /// Whether the distance is exact (false: a bound).
    pub fn is_exact(&self) -> bool {
        self.field.facts().exact
    }

    /// The piece of `ray` to march: clipped to the bounds when there are any, `None` when
    /// it misses them.
    #[inline]
    fn segment(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Segment> {
        let (t0, t1) =
            if self.bounded { ray.clip_to_box(&self.bounds, t_min, t_max)? } else { (t_min, t_max) };
        Some(Segment::along(ray, t0 as f64, t1 as f64))
    }

    /// The intervals of [`Self::segment`] for up to [`PACKET`] rays (ray `k` up to
    /// `t_max[k]`), bit for bit: where the CPU has AVX2 the box clip
    /// ([`Ray::clip_to_box`]) runs for the eight rays at once ([`clip8`]).
    #[inline]
    fn segments8(&self, rays: &[Ray], t_min: f32, t_max: &[f32; PACKET]) -> Segments8 {
        let n = rays.len().min(PACKET);
        let first_n = (1u32 << n) - 1;
        if !self.bounded {
            return Segments8 { t0: [t_min; PACKET], t1: *t_max, some: first_n };
        }
        if crate::simd::backend() == crate::simd::Backend::Avx2 {
            // Lanes past the packet's end clip a copy of its first ray (not used).
            let rays = std::array::from_fn(|k| rays.get(k).unwrap_or(&rays[0]));
            let mut clipped = dispatch(Clip8 { rays, b: &self.bounds, t_min, t_max: *t_max });
            clipped.some &= first_n;
            return clipped;
        }
        let mut out = Segments8 { t0: [0.0; PACKET], t1: [0.0; PACKET], some: 0 };
        for (k, ray) in rays.iter().enumerate().take(n) {
            if let Some((t0, t1)) = ray.clip_to_box(&self.bounds, t_min, t_max[k]) {
                (out.t0[k], out.t1[k], out.some) = (t0, t1, out.some | 1 << k);
            }
        }
        out
    }

    /// Sphere traces the world ray `ray` (unit direction) through the field, only inside
    /// the bounds when there are any, and keeps hits with `t` in `[t_min, t_max]`.
    fn march(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<MarchHit> {
        let segment = self.segment(ray, t_min, t_max)?;
        let f = |p: DVec3, tolerance: f64| self.field.distance(p, tolerance);
        let hit = sphere_trace(&f, &segment, self.size, &self.march, self.field.facts().signed, stats)?;
        (hit.t >= t_min as f64 && hit.t <= t_max as f64).then_some(hit)
    }

    /// Marches the rays `rays[i]` over `[t_min, reach(i)]` (not at all where `reach(i)` is
    /// `None`) side by side, one field evaluation per step for all lanes. A field that
    /// refills lanes ([`FieldFacts::refills_lanes`]) marches [`WIDE`] lanes, four
    /// packets evaluated together ([`DistanceField::distances`]), and a lane whose
    /// march ends takes the next ray of the batch, so lanes idle only once the batch runs
    /// out (a packet would wait for its slowest ray). Otherwise a packet of [`PACKET`]
    /// lanes marches until its last lane is done before it takes the next rays. Each lane
    /// takes the steps of its own scalar march (one state machine, [`MarchLanes`]), so it
    /// converges where [`Marched::march`] does for that ray alone, and `on_hit(i, hit,
    /// stats)` is called for each ray whose march converges within `[t_min, reach(i)]`, in
    /// the order the marches end. `reach(i)` is read before ray `i`'s march starts.
    fn march_batch(
        &self,
        rays: &[Ray],
        t_min: f32,
        reach: impl Fn(usize) -> Option<f32>,
        stats: &mut RayStats,
        on_hit: impl FnMut(usize, MarchHit, &mut RayStats),
    ) {
        // A batch of one packet has no rays to refill lanes with, and marches in eight
        // lanes rather than setting up 32 (the objects of a large union take packets).
        if self.field.facts().refills_lanes && rays.len() > PACKET {
            self.march_lanes::<WIDE>(rays, t_min, reach, stats, on_hit, true);
        } else {
            self.march_lanes::<PACKET>(rays, t_min, reach, stats, on_hit, false);
        }
    }

    /// [`Marched::march_batch`] in `W` lanes (a multiple of [`PACKET`], at most [`WIDE`]),
    /// refilled as marches end or not, the field evaluated at the lanes' points in one
    /// [`PointBlock`] per step ([`DistanceField::distances`]).
    #[inline]
    fn march_lanes<const W: usize>(
        &self,
        rays: &[Ray],
        t_min: f32,
        reach: impl Fn(usize) -> Option<f32>,
        stats: &mut RayStats,
        mut on_hit: impl FnMut(usize, MarchHit, &mut RayStats),
        refill: bool,
    ) {
        // Each lane's state, its ray by component and its ray's index and end included
        // (`MarchLanes::ray`, `MarchLanes::reach`), lives in `lanes`; the field evaluates
        // their points where they stand ([`MarchLanes::pts`]).
        let mut lanes = MarchLanes::<W>::new(&self.march, self.size, self.field.facts().signed);
        // The rays are clipped to the bounds eight at a time ([`Marched::segments8`]) as the
        // lanes reach them: `ready` has bit `k` set where ray `chunk + k` is asked for, has a
        // segment and waits for a lane; `next` is the first ray not clipped yet. `idle`
        // has bit `l` set where lane `l` (of the `all` in use) marches nothing.
        const ONE_PACKET: u32 = (1 << PACKET) - 1;
        let all: u32 = if refill { u32::MAX >> (32 - W) } else { ONE_PACKET };
        let mut clipped = Segments8 { t0: [0.0; PACKET], t1: [0.0; PACKET], some: 0 };
        let mut ends = [0.0f32; PACKET];
        let (mut chunk, mut next, mut ready, mut idle) = (0, 0, 0u32, all);
        loop {
            if idle != 0 && (refill || idle == all) {
                while idle != 0 {
                    if ready == 0 {
                        if next >= rays.len() {
                            break;
                        }
                        let end = (next + PACKET).min(rays.len());
                        // Bit `k` set: ray `next + k` is asked for, up to `ends[k]`.
                        let mut asked = 0u32;
                        for (k, e) in ends.iter_mut().enumerate() {
                            *e = match (next + k < end).then(|| reach(next + k)).flatten() {
                                Some(reach) => {
                                    asked |= 1 << k;
                                    reach
                                }
                                None => 0.0,
                            };
                        }
                        clipped = self.segments8(&rays[next..end], t_min, &ends);
                        ready = clipped.some & asked;
                        (chunk, next) = (next, end);
                        continue;
                    }
                    let (k, l) = (ready.trailing_zeros() as usize, idle.trailing_zeros() as usize);
                    (ready, idle) = (ready & (ready - 1), idle & (idle - 1));
                    let i = chunk + k;
                    let seg = Segment::along(&rays[i], clipped.t0[k] as f64, clipped.t1[k] as f64);
                    lanes.start(l, &seg, stats);
                    lanes.assign(l, i, ends[k]);
                }
            }
            let mut marching = !idle & all;
            if marching == 0 {
                break;
            }
            // Once no ray waits, the marches left move to the lowest lanes, so that the
            // batch's last steps evaluate as few packets as their lanes fill.
            if refill && ready == 0 && next >= rays.len() {
                loop {
                    // The lowest idle lane (32: none) and the highest marching one.
                    let (to, from) =
                        ((idle & all).trailing_zeros() as usize, 31 - marching.leading_zeros() as usize);
                    if to >= from {
                        break;
                    }
                    lanes.move_lane(from, to);
                    (idle, marching) = ((idle & !(1 << to)) | 1 << from, (marching & !(1 << from)) | 1 << to);
                }
            }
            // The packets with a marching lane are evaluated. Their idle lanes evaluate the
            // first marching lane's point, with no tolerance to meet, and their values are
            // not used. (Their own last points would split the packet across more regions
            // of a pruned field: a smooth union of 64 spheres took 15% more instructions
            // per frame.)
            let active = (0..W / PACKET)
                .filter(|g| marching >> (PACKET * g) & ONE_PACKET != 0)
                .fold(0, |m, g| m | ONE_PACKET << (PACKET * g));
            let first = marching.trailing_zeros() as usize;
            let mut rest = idle & active;
            while rest != 0 {
                let l = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                lanes.copy_point(first, l);
            }
            lanes.pts.active = active;
            self.field.distances(&mut lanes.pts);
            let d = lanes.pts.out;
            let mut ended = lanes.feed(&d, marching, stats);
            idle |= ended;
            while ended != 0 {
                let l = ended.trailing_zeros() as usize;
                ended &= ended - 1;
                lanes.stop(l);
                if let Some(mh) =
                    lanes.outcome(l).filter(|h| h.t >= t_min as f64 && h.t <= lanes.reach[l] as f64)
                {
                    on_hit(lanes.ray[l], mh, stats);
                }
            }
        }
    }

    /// Where the normal of a converged march of `ray` is taken: the hit point, its error
    /// bound `eps`, and the field's gradient step and material there.
    #[inline]
    fn hit_point(&self, ray: &Ray, hit: MarchHit) -> (DVec3, f64, SurfacePoint) {
        let MarchHit { t, residual } = hit;
        let p = ray.origin.as_dvec3() + ray.dir.as_dvec3() * t;
        let eps = self.march.tolerance(ray.spread as f64 + t, self.size).max(residual);
        (p, eps, self.field.surface(p, eps))
    }

    /// The hit record at `p` (error bound `eps`, `material`) of a march converged at `t`,
    /// with `normal`.
    #[inline]
    fn record(&self, t: f64, p: DVec3, eps: f64, material: MaterialId, normal: DVec3) -> Hit {
        let normal = normal.as_vec3();
        let point: Vec3 = p.as_vec3();
        Hit {
            t: t as f32,
            point,
            normal,
            shading_normal: normal,
            material,
            error: 4.0 * eps as f32 + f32_error(max_abs(point)),
        }
    }

    /// The hit record of a converged march of `ray`: point, normal from the gradient,
    /// material and error bound.
    fn hit(&self, ray: &Ray, hit: MarchHit, stats: &mut RayStats) -> Hit {
        let (p, eps, at) = self.hit_point(ray, hit);
        let h = at.normal_step;
        // The gradient's error is about the distance error over h: a field evaluates the
        // stencil with an error of at most h / 20 (a quarter of the tolerance asked), so
        // the normal's direction is off by at most a few percent where the evaluator's
        // error bound is reached, far less in practice.
        let f4 = |q: &[DVec3; 4]| self.stencils(&[*q], &[0.2 * h])[0];
        let normal = gradient_normal(&f4, p, h, stats);
        self.record(hit.t, p, eps, at.material, normal)
    }

    /// [`Marched::hit`] for `N` converged marches at once, their normals' stencils evaluated
    /// together in one [`PointBlock`] ([`Marched::stencils`]); each record is bit for bit
    /// the one [`Marched::hit`] gives alone.
    fn hits<const N: usize>(&self, found: [(&Ray, MarchHit); N], stats: &mut RayStats) -> [Hit; N] {
        let at = found.map(|(ray, mh)| self.hit_point(ray, mh));
        let tolerances = at.map(|(_, _, s)| 0.2 * s.normal_step);
        let normals = gradient_normals(
            |s| self.stencils(s, &tolerances),
            at.map(|(p, _, s)| (p, s.normal_step)),
            stats,
        );
        std::array::from_fn(|k| self.record(found[k].1.t, at[k].0, at[k].1, at[k].2.material, normals[k]))
    }

    /// The field at `N` (at most 8) normal stencils, stencil `k` to within
    /// `tolerances[k]`, in one bulk call ([`BlockKind::Stencils`]).
    #[inline]
    fn stencils<const N: usize>(&self, stencils: &[[DVec3; 4]; N], tolerances: &[f64; N]) -> [[f64; 4]; N] {
        STENCILS.with(|b| {
            let mut block = b.borrow_mut();
            block.set_stencils(stencils, tolerances);
            self.field.distances(&mut block);
            std::array::from_fn(|k| std::array::from_fn(|j| block.out[4 * k + j]))
        })
    }
}

impl<F: DistanceField + FieldObject> Geometry for Marched<F> {
    fn bounds(&self) -> Option<Aabb> {
        self.bounded.then_some(self.bounds)
    }

    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        let hit = self.march(ray, t_min, t_max, stats)?;
        Some(self.hit(ray, hit, stats))
    }

    fn prefers_packets(&self) -> bool {
        self.field.facts().packets
    }

    /// Marches the batch's rays side by side ([`Marched::march_batch`]); each lane takes
    /// the steps of its own scalar march, so the hits are those of
    /// [`Geometry::closest_hit`].
    fn closest_hits(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &mut [f32],
        hits: &mut [Option<Hit>],
        stats: &mut RayStats,
    ) {
        debug_assert!(t_max.len() == rays.len() && hits.len() == rays.len());
        // The hit records eight at a time, as the marches end: their normals' stencils in
        // one evaluation ([`Marched::stencils`]); the last ones two at a
        // time, then alone.
        const EIGHT: usize = 8;
        let mut pending = [(0usize, MarchHit { t: 0.0, residual: 0.0 }); EIGHT];
        let mut n = 0;
        let mut record = |i: usize, mh: MarchHit, stats: &mut RayStats| {
            pending[n] = (i, mh);
            n += 1;
            if n == EIGHT {
                n = 0;
                let found = pending.map(|(j, mh)| (&rays[j], mh));
                let done = self.hits(found, stats);
                for ((j, _), h) in pending.iter().zip(done) {
                    hits[*j] = Some(h);
                }
            }
        };
        self.march_batch(rays, t_min, |i| Some(t_max[i]), stats, &mut record);
        for pair in pending[..n].chunks(2) {
            if let [(i, a), (j, b)] = *pair {
                let [ha, hb] = self.hits([(&rays[i], a), (&rays[j], b)], stats);
                (hits[i], hits[j]) = (Some(ha), Some(hb));
            } else if let [(i, a)] = *pair {
                hits[i] = Some(self.hit(&rays[i], a, stats));
            }
        }
        // A new hit is nearer than its ray's `t_max`; one found before sets it already.
        for (t, h) in t_max.iter_mut().zip(hits.iter()) {
            if let Some(h) = h {
                *t = t.min(h.t);
            }
        }
    }

    /// The batch march of [`Geometry::closest_hits`] for the rays not yet occluded; a
    /// ray is occluded where its march converges within its interval, as
    /// [`Geometry::any_hit`] says for that ray alone.
    fn any_hits(&self, rays: &[Ray], t_min: f32, t_max: &[f32], occluded: &mut [bool], stats: &mut RayStats) {
        debug_assert!(t_max.len() == rays.len() && occluded.len() == rays.len());
        // Read when a lane takes a ray, set when its march converges: cells, so that both
        // closures can hold them.
        let occluded = std::cell::Cell::from_mut(occluded).as_slice_of_cells();
        let reach = |i: usize| (!occluded[i].get()).then_some(t_max[i]);
        self.march_batch(rays, t_min, reach, stats, |i, _, _| occluded[i].set(true));
    }

    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        self.march(ray, t_min, t_max, stats).is_some()
    }

    fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.field.storage().heap_bytes + self.label.capacity()
    }

    fn describe(&self) -> String {
        self.field.describe(&self.label)
    }

    fn census(&self) -> Census {
        self.field.storage().census
    }

    fn shared(&self) -> Option<Shared> {
        self.field.storage().shared
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        self.field.surface_distance(p, self.size)
    }
}

/// The march intervals of up to [`PACKET`] rays ([`Marched::segments8`]): ray `k`'s is
/// `[t0[k], t1[k]]` where bit `k` of `some` is set; it misses the bounds where it is not.
#[derive(Clone, Copy)]
struct Segments8 {
    /// Interval starts, world units along each ray.
    t0: [f32; PACKET],
    /// Interval ends, world units along each ray.
    t1: [f32; PACKET],
    /// Bit `k` set: ray `k` has an interval.
    some: u32,
}

/// [`Ray::clip_to_box`] for eight rays at once (ray `k` over `[t_min, t_max[k]]`), bit for
/// bit: the same single precision operations, with the scalar code's comparisons as AVX
/// `min`/`max` in its operand order (`a > t0 ? a : t0` is `max(a, t0)`, NaN keeping
/// `t0`) and its early exits as masks (the interval only narrows from one axis to the
/// next, so an interval found empty at one axis is empty at the end).
///
#[derive(Clone, Copy)]
struct Clip8<'a> {
    rays: [&'a Ray; 8],
    b: &'a Aabb,
    t_min: f32,
    t_max: [f32; 8],
}

impl Kernel for Clip8<'_> {
    type Output = Segments8;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> Segments8 {
        let Clip8 { rays, b, t_min, t_max } = self;
        let mut t0 = s.splat8(t_min);
        let mut t1 = s.load8(&t_max);
        let zero = s.splat8(0.0);
        let (mut dead, mut moving) = (zero, zero);
        let all = s.splat8(f32::from_bits(!0));
        for axis in 0..3 {
            // Plain arrays, no closures: everything must inline into the kernel.
            let mut o = [0.0f32; 8];
            let mut d = [0.0f32; 8];
            for k in 0..8 {
                (o[k], d[k]) = (rays[k].origin[axis], rays[k].dir[axis]);
            }
            let (o, d) = (s.load8(&o), s.load8(&d));
            let (lo, hi) = (s.splat8(b.min[axis]), s.splat8(b.max[axis]));
            let flat = d.cmp_eq(zero);
            let outside = o.cmp_lt(lo).or(o.cmp_gt(hi));
            dead = dead.or(flat.and(outside));
            moving = moving.or(flat.andnot(all));
            let inv = s.splat8(1.0) / d;
            let ta = (lo - o) * inv;
            let tb = (hi - o) * inv;
            let (near, far) = (tb.vmin(ta), ta.vmax(tb));
            t0 = flat.and(t0).or(flat.andnot(near.vmax(t0)));
            t1 = flat.and(t1).or(flat.andnot(far.vmin(t1)));
        }
        dead = dead.or(moving.and(t0.cmp_gt(t1)));
        Segments8 { t0: t0.store(), t1: t1.store(), some: !dead.movemask() & 0xff }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::geometry::aabb;
    use crate::simd::Portable;

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn eight_box_clips_at_once_equal_one_by_one() {
        let b = aabb(Vec3::new(-1.0, -0.5, 0.25), Vec3::new(2.0, 1.5, 3.0));
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 * 8.0 - 4.0
        };
        let mut rays = Vec::new();
        for i in 0..4000 {
            let mut o = Vec3::new(next(), next(), next());
            let mut d = Vec3::new(next(), next(), next());
            // Zero components (inside and outside the slab), slab-face origins, -0.0.
            match i % 7 {
                0 => d.x = 0.0,
                1 => (d.y, d.z) = (-0.0, 0.0),
                2 => o.x = b.min.x,
                3 => (d, o.y) = (Vec3::ZERO, 0.5),
                _ => {}
            }
            rays.push(Ray::new(o, d));
        }
        let avx2 = |k: Clip8| crate::simd::avx2().map(|a| a.run(k));
        for (q, chunk) in rays.chunks(8).enumerate() {
            let t_min = if q % 5 == 0 { 1.0 } else { 0.0 };
            let t_max: [f32; 8] = std::array::from_fn(|k| [100.0, 2.0, 0.5, f32::INFINITY, 3.0][(q + k) % 5]);
            let eight: [&Ray; 8] = std::array::from_fn(|k| &chunk[k]);
            let kernel = Clip8 { rays: eight, b: &b, t_min, t_max };
            let bits = |c: Option<(f32, f32)>| c.map(|(a, b)| (a.to_bits(), b.to_bits()));
            for wide in [Some(kernel.run(Portable)), avx2(kernel)].into_iter().flatten() {
                for k in 0..8 {
                    let one = chunk[k].clip_to_box(&b, t_min, t_max[k]);
                    let eight = (wide.some & 1 << k != 0).then_some((wide.t0[k], wide.t1[k]));
                    assert_eq!(bits(eight), bits(one), "{:?} over [{t_min}, {}]", chunk[k], t_max[k]);
                }
            }
        }
    }

    /// The bulk call of a field equals its scalar distance lane by lane, bit for bit, for
    /// 32 lanes, for one packet, and for the normal stencils (1, 2 and 8 of them, each all
    /// from the field's fast evaluator or all from its precise one).
    fn bulk_equals_scalar<F: DistanceField>(field: &F, o: [f64; 3], dirs: &[[f64; 3]], ts: &[f64], tol: f64) {
        let lane = |l: usize| l % dirs.len();
        let mut block = PointBlock::new(BlockKind::Rays);
        block.origin = [[o[0]; WIDE], [o[1]; WIDE], [o[2]; WIDE]];
        block.dir = std::array::from_fn(|a| std::array::from_fn(|l| dirs[lane(l)][a]));
        block.t = std::array::from_fn(|l| ts[l % ts.len()]);
        block.tol = std::array::from_fn(|l| tol * (1.0 + (l % 3) as f64));
        block.active = u32::MAX;
        field.distances(&mut block);
        let wide = block.out;
        for (l, w) in wide.iter().enumerate() {
            let p = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
                block.origin[a][l] + block.dir[a][l] * block.t[l]
            }));
            assert_eq!(block.point(l), p);
            let one = field.distance(p, block.tol[l]);
            assert_eq!(w.to_bits(), one.to_bits(), "lane {l} at {p}: {w} vs {one}");
        }
        // One packet of the 32, and a block of one packet (a batch of eight lanes).
        block.active = 0xff;
        block.out = [f64::NAN; WIDE];
        field.distances(&mut block);
        let mut eight = PointBlock::<PACKET>::new(BlockKind::Rays);
        eight.origin = std::array::from_fn(|a| std::array::from_fn(|l| block.origin[a][l]));
        eight.dir = std::array::from_fn(|a| std::array::from_fn(|l| block.dir[a][l]));
        eight.t = std::array::from_fn(|l| block.t[l]);
        eight.tol = std::array::from_fn(|l| block.tol[l]);
        eight.active = 0xff;
        field.distances(&mut eight);
        for (l, w) in wide.iter().enumerate().take(PACKET) {
            assert_eq!(block.out[l].to_bits(), w.to_bits(), "packet lane {l}");
            assert_eq!(eight.out[l].to_bits(), w.to_bits(), "eight-lane block, lane {l}");
        }
        // Stencils: eight and two at a time, each as it is alone.
        let stencils: [[DVec3; 4]; 8] =
            std::array::from_fn(|k| std::array::from_fn(|j| block.point(4 * k + j)));
        let tols: [f64; 8] = std::array::from_fn(|k| block.tol[4 * k]);
        let one = |k: usize| {
            let mut b = PointBlock::stencils(&[stencils[k]], &[tols[k]]);
            field.distances(&mut b);
            [b.out[0], b.out[1], b.out[2], b.out[3]]
        };
        let mut eight = PointBlock::stencils(&stencils, &tols);
        field.distances(&mut eight);
        let mut two = PointBlock::stencils(&[stencils[2], stencils[3]], &[tols[2], tols[3]]);
        field.distances(&mut two);
        for k in 0..8 {
            let alone = one(k);
            for (j, a) in alone.iter().enumerate() {
                assert_eq!(eight.out[4 * k + j].to_bits(), a.to_bits(), "stencil {k} point {j}");
                if (2..4).contains(&k) {
                    assert_eq!(two.out[4 * (k - 2) + j].to_bits(), a.to_bits(), "pair {k} point {j}");
                }
            }
        }
    }

    fn sphere_union() -> crate::scene::shape::Object {
        use crate::scene::shape::{CsgOp, Object, ObjectKind, Primitive};
        use crate::scene::transform::TransformDesc;
        let ball = |x: f32, r: f32| Object {
            kind: ObjectKind::Primitive(Primitive::Sphere { radius: r }),
            transform: TransformDesc { translate: Vec3::new(x, 0.1, 0.0), ..TransformDesc::default() },
            material: 0,
            label: "s".into(),
        };
        Object {
            kind: ObjectKind::Csg {
                op: CsgOp::SmoothUnion { k: 0.2 },
                children: vec![ball(-0.4, 0.5), ball(0.5, 0.4)],
            },
            transform: TransformDesc::default(),
            material: 0,
            label: "u".into(),
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]
        #[test]
        fn bulk_distance_equals_scalar_per_lane(
            o in proptest::array::uniform3(-3.0f64..3.0),
            dirs in proptest::collection::vec(proptest::array::uniform3(-1.0f64..1.0), 1..9),
            ts in proptest::collection::vec(0.0f64..6.0, 1..33),
            tol in 1e-6f64..1e-1,
        ) {
            let object = sphere_union();
            let sdf = crate::geometry::sdf::SdfField::new(&object, object.bounds()).unwrap();
            bulk_equals_scalar(&sdf, o, &dirs, &ts, tol);
            let mut g = crate::geometry::grid::SdfGrid::for_bounds(Vec3::splat(-1.0), Vec3::splat(1.0), 24, 2).unwrap();
            for k in 0..g.dims.z {
                for j in 0..g.dims.y {
                    for i in 0..g.dims.x {
                        let idx = g.index(i, j, k);
                        g.values[idx] = g.position(i, j, k).length() - 0.6;
                    }
                }
            }
            let band = crate::geometry::grid::band::BandGrid::from_dense(&g, 2).unwrap();
            let dense = crate::geometry::grid::object::GridObject::new(g, 0, Default::default(), "g".into());
            bulk_equals_scalar(&dense.field, o, &dirs, &ts, tol);
            let band = crate::geometry::grid::object::GridObject::new(band, 0, Default::default(), "b".into());
            bulk_equals_scalar(&band.field, o, &dirs, &ts, tol);
        }
    }
}
