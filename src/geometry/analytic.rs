//! Closed-form ray intersection with every [`Primitive`] in its local frame: sphere, plane,
//! box, ellipsoid, cylinder, cone (frustum), capsule, torus and triangle.
//!
//! This module owns the exact reference the other representations are compared with, so
//! everything is computed in f64 with numerically stable formulas (quadratics in the
//! `q = -(b + sign(b) sqrt(disc))` form with the discriminant taken from the ray's closest
//! approach, slab tests without NaN, a torus quartic solved by root isolation on the shifted
//! and rescaled ray with Newton polishing). Nothing here allocates.
//!
//! Conventions: the ray is `o + t d` with `d` of any non-zero length (`t` keeps its meaning);
//! only `t` in `[t_min, t_max]` counts. Rays that start inside a solid report where they leave
//! it. Normals are unit length and point out of the solid (a triangle has a fixed side,
//! `(b - a) x (c - a)`); they are never flipped toward the ray.

use crate::geometry::{
    Aabb, Census, Geometry, Hit, MaterialId, Ray, RayStats, distance_by_projection, f32_error, max_abs,
};
use crate::scene::shape::Object;
use crate::scene::transform::Transform;
use glam::{DVec3, Vec3};

use crate::scene::shape::Primitive;

const INF: f64 = f64::INFINITY;

/// Closest intersection of the local-space ray `o + t d` (`d` need not be unit length; `t`
/// keeps its meaning) with `prim`, for `t` in `[t_min, t_max]`. Returns `t` and the outward
/// local-space normal (unit length). Rays starting inside a solid return the exit point.
/// Never returns NaN; returns `None` on a miss.
pub fn intersect(prim: &Primitive, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> Option<(f32, Vec3)> {
    intersect_f64(prim, o.as_dvec3(), d.as_dvec3(), t_min, t_max)
}

/// Whether any intersection exists in `[t_min, t_max]`; agrees exactly with [`intersect`]
/// (it runs the same solver and only skips the normal).
pub fn occluded(prim: &Primitive, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> bool {
    occluded_f64(prim, o.as_dvec3(), d.as_dvec3(), t_min, t_max)
}

/// [`intersect`] for a ray given in f64. A local ray computed in f32 carries the rounding of
/// its origin (about 2.4e-4 for coordinates near 5000, the centre distance of the classic
/// ground sphere); callers that can map the origin into local space in f64 keep the hit
/// point on the surface to about 1e-9 instead.
pub fn intersect_f64(prim: &Primitive, o: DVec3, d: DVec3, t_min: f32, t_max: f32) -> Option<(f32, Vec3)> {
    hit::<true>(prim, o, d, t_min, t_max).map(|(t, n)| (t, n.as_vec3()))
}

/// [`occluded`] for a ray given in f64; agrees exactly with [`intersect_f64`].
pub fn occluded_f64(prim: &Primitive, o: DVec3, d: DVec3, t_min: f32, t_max: f32) -> bool {
    hit::<false>(prim, o, d, t_min, t_max).is_some()
}

/// The shared solver. With `NORMAL` false the normal is left zero (shadow rays).
#[inline]
fn hit<const NORMAL: bool>(
    prim: &Primitive,
    o: DVec3,
    d: DVec3,
    t_min: f32,
    t_max: f32,
) -> Option<(f32, DVec3)> {
    if !(o.is_finite() && d.is_finite() && t_min <= t_max) || d == DVec3::ZERO {
        return None;
    }
    let (lo, hi) = (t_min as f64, t_max as f64);
    let (t, n) = match *prim {
        Primitive::Sphere { radius } => sphere::<NORMAL>(o, d, radius as f64, lo, hi),
        Primitive::Plane { normal, offset } => plane(o, d, normal.as_dvec3(), offset as f64, lo, hi),
        Primitive::Box { half } => box_hit::<NORMAL>(o, d, half.as_dvec3(), lo, hi),
        Primitive::Ellipsoid { radii } => ellipsoid::<NORMAL>(o, d, radii.as_dvec3(), lo, hi),
        Primitive::Cylinder { radius, half_height } => {
            cylinder::<NORMAL>(o, d, radius as f64, half_height as f64, lo, hi)
        }
        Primitive::Cone { radius_bottom, radius_top, half_height } => {
            cone::<NORMAL>(o, d, radius_bottom as f64, radius_top as f64, half_height as f64, lo, hi)
        }
        Primitive::Torus { major, minor } => torus::<NORMAL>(o, d, major as f64, minor as f64, lo, hi),
        Primitive::Triangle { a, b, c } => triangle(o, d, a.as_dvec3(), b.as_dvec3(), c.as_dvec3(), lo, hi),
        Primitive::Capsule { a, b, radius } => {
            capsule::<NORMAL>(o, d, a.as_dvec3(), b.as_dvec3(), radius as f64, lo, hi)
        }
    }?;
    // Rounding to f32 is monotone, so a t inside [lo, hi] stays inside [t_min, t_max]; the
    // check also rejects anything non-finite.
    let tf = t as f32;
    (tf.is_finite() && tf >= t_min && tf <= t_max).then_some((tf, n))
}

// ---------------------------------------------------------------------------------------
// Shared helpers
// ---------------------------------------------------------------------------------------

/// `v` normalised, or `fallback` when `v` has no direction.
#[inline]
fn unit_or(v: DVec3, fallback: DVec3) -> DVec3 {
    let l2 = v.length_squared();
    if l2 > 0.0 && l2.is_finite() { v / l2.sqrt() } else { fallback }
}

/// Both roots, ascending, of `a t^2 + 2 b t + c` (half-`b` form) given its quarter
/// discriminant `disc = b^2 - a c >= 0` and `a != 0`, without cancellation.
#[inline]
fn stable_roots(a: f64, b: f64, c: f64, disc: f64) -> (f64, f64) {
    let q = -(b + disc.max(0.0).sqrt().copysign(b));
    if q == 0.0 {
        // b == 0 and disc == 0: a double root at -b / a.
        let t = -b / a;
        return (t, t);
    }
    let (r0, r1) = (q / a, c / q);
    if r0 <= r1 { (r0, r1) } else { (r1, r0) }
}

/// The span `[t0, t1]` in which the ray is inside the ball of radius `r` at the origin.
/// The discriminant comes from the ray's closest approach to the centre (Hearn & Baker),
/// which stays accurate for huge spheres seen at grazing angles.
#[inline]
fn sphere_span(o: DVec3, d: DVec3, r: f64) -> Option<(f64, f64)> {
    let a = d.length_squared();
    let b = o.dot(d);
    let c = o.length_squared() - r * r;
    let l = o - d * (b / a);
    let disc = a * ((r - l.length()) * (r + l.length()));
    if !(disc >= 0.0) {
        return None;
    }
    Some(stable_roots(a, b, c, disc))
}

/// The span in which the 1D ray `o + t d` lies in `[-h, h]` (`None`: never; a ray parallel
/// to the slab is inside for all `t` or for none).
#[inline]
fn slab(o: f64, d: f64, h: f64) -> Option<(f64, f64)> {
    if d == 0.0 {
        if o < -h || o > h { None } else { Some((-INF, INF)) }
    } else {
        let ta = (-h - o) / d;
        let tb = (h - o) / d;
        Some(if d > 0.0 { (ta, tb) } else { (tb, ta) })
    }
}

/// The first boundary crossing in `[lo, hi]` of a convex solid the ray is inside during
/// `[t0, t1]`: the entry, or the exit when the ray starts inside. `true` means entry.
#[inline]
fn first_crossing(t0: f64, t1: f64, lo: f64, hi: f64) -> Option<(f64, bool)> {
    if t0 >= lo {
        (t0 <= hi).then_some((t0, true))
    } else if t1 >= lo && t1 <= hi {
        Some((t1, false))
    } else {
        None
    }
}

/// Span of the ray inside the infinite cylinder of radius `r` around the axis through the
/// origin along the unit vector `axis`.
#[inline]
fn infinite_cylinder_span(o: DVec3, d: DVec3, axis: DVec3, r: f64) -> Option<(f64, f64)> {
    let op = o - axis * o.dot(axis);
    let dp = d - axis * d.dot(axis);
    let a = dp.length_squared();
    if a == 0.0 {
        // Parallel to the axis: inside everywhere or nowhere.
        return (op.length_squared() <= r * r).then_some((-INF, INF));
    }
    let b = op.dot(dp);
    let c = op.length_squared() - r * r;
    let l = (op - dp * (b / a)).length();
    let disc = a * ((r - l) * (r + l));
    if !(disc >= 0.0) {
        return None;
    }
    Some(stable_roots(a, b, c, disc))
}

// ---------------------------------------------------------------------------------------
// Quadric and planar primitives
// ---------------------------------------------------------------------------------------

fn sphere<const N: bool>(o: DVec3, d: DVec3, r: f64, lo: f64, hi: f64) -> Option<(f64, DVec3)> {
    let (t0, t1) = sphere_span(o, d, r)?;
    let (t, _) = first_crossing(t0, t1, lo, hi)?;
    let n = if N { unit_or(o + d * t, DVec3::Y) } else { DVec3::ZERO };
    Some((t, n))
}

fn ellipsoid<const N: bool>(o: DVec3, d: DVec3, radii: DVec3, lo: f64, hi: f64) -> Option<(f64, DVec3)> {
    // Dividing by the radii maps the ellipsoid to the unit sphere and keeps t.
    let inv = radii.recip();
    let (t0, t1) = sphere_span(o * inv, d * inv, 1.0)?;
    let (t, _) = first_crossing(t0, t1, lo, hi)?;
    let n = if N { unit_or((o + d * t) * inv * inv, DVec3::Y) } else { DVec3::ZERO };
    Some((t, n))
}

fn plane(o: DVec3, d: DVec3, normal: DVec3, offset: f64, lo: f64, hi: f64) -> Option<(f64, DVec3)> {
    let denom = normal.dot(d);
    if denom == 0.0 {
        return None;
    }
    let t = (offset - normal.dot(o)) / denom;
    (t >= lo && t <= hi).then(|| (t, unit_or(normal, DVec3::Y)))
}

fn box_hit<const N: bool>(o: DVec3, d: DVec3, half: DVec3, lo: f64, hi: f64) -> Option<(f64, DVec3)> {
    let mut t0 = -INF;
    let mut t1 = INF;
    // Axis of the entered and exited face; ties go to the lowest axis.
    let mut enter_axis = 0;
    let mut exit_axis = 0;
    for axis in 0..3 {
        let (oa, da, h) = (o[axis], d[axis], half[axis]);
        if da == 0.0 {
            // Parallel to this slab (the closed box: a ray in a face plane is inside it).
            if oa < -h || oa > h {
                return None;
            }
            continue;
        }
        // Division (not multiplication by 1/d): no 0 * inf.
        let ta = (-h - oa) / da;
        let tb = (h - oa) / da;
        let (near, far) = if da > 0.0 { (ta, tb) } else { (tb, ta) };
        if near > t0 {
            t0 = near;
            enter_axis = axis;
        }
        if far < t1 {
            t1 = far;
            exit_axis = axis;
        }
    }
    if !(t0 <= t1) {
        return None;
    }
    let (t, entering) = first_crossing(t0, t1, lo, hi)?;
    let n = if N {
        let axis = if entering { enter_axis } else { exit_axis };
        let sign = if d[axis] > 0.0 { 1.0 } else { -1.0 };
        let mut n = DVec3::ZERO;
        n[axis] = if entering { -sign } else { sign };
        n
    } else {
        DVec3::ZERO
    };
    Some((t, n))
}

fn cylinder<const N: bool>(o: DVec3, d: DVec3, r: f64, h: f64, lo: f64, hi: f64) -> Option<(f64, DVec3)> {
    let (c0, c1) = infinite_cylinder_span(o, d, DVec3::Y, r)?;
    let (s0, s1) = slab(o.y, d.y, h)?;
    // The side wins ties at the rim (deterministic).
    let (t0, side0) = if c0 >= s0 { (c0, true) } else { (s0, false) };
    let (t1, side1) = if c1 <= s1 { (c1, true) } else { (s1, false) };
    if !(t0 <= t1) {
        return None;
    }
    let (t, entering) = first_crossing(t0, t1, lo, hi)?;
    if !N {
        return Some((t, DVec3::ZERO));
    }
    let side = if entering { side0 } else { side1 };
    let n = if side {
        let p = o + d * t;
        unit_or(DVec3::new(p.x, 0.0, p.z), DVec3::X)
    } else {
        // A cap: entered against d.y, exited along it.
        let up = (d.y > 0.0) != entering;
        DVec3::new(0.0, if up { 1.0 } else { -1.0 }, 0.0)
    };
    Some((t, n))
}

/// Capped cone around y: radius `rb` at `y = -h`, `rt` at `y = h`.
///
/// The radius along y is `g(y) = k0 + k1 y`. Inside the slab `|y| <= h` the solid is
/// `x^2 + z^2 <= g(y)^2` (the other nappe of the double cone lies beyond an apex, outside the
/// slab), so the ray's span in the solid is the slab span intersected with the set where the
/// quadratic `A t^2 + 2 B t + C` is <= 0, taken on the correct nappe.
fn cone<const N: bool>(
    o: DVec3,
    d: DVec3,
    rb: f64,
    rt: f64,
    h: f64,
    lo: f64,
    hi: f64,
) -> Option<(f64, DVec3)> {
    let k1 = (rt - rb) / (2.0 * h);
    let k0 = 0.5 * (rb + rt);
    let g0 = k0 + k1 * o.y;
    let gd = k1 * d.y;
    let a = d.x * d.x + d.z * d.z - gd * gd;
    let b = o.x * d.x + o.z * d.z - g0 * gd;
    let c = o.x * o.x + o.z * o.z - g0 * g0;
    let (l0, l1) = if a == 0.0 {
        // Parallel to a generator (or to the axis of an equal-radii cone): linear.
        if b == 0.0 {
            if c <= 0.0 { (-INF, INF) } else { return None }
        } else {
            let t = -c / (2.0 * b);
            if b > 0.0 { (-INF, t) } else { (t, INF) }
        }
    } else {
        let disc = b * b - a * c;
        if a > 0.0 {
            // Shallower than the cone: one bounded span (or none).
            if !(disc >= 0.0) {
                return None;
            }
            stable_roots(a, b, c, disc)
        } else {
            // Steeper than the cone: the line crosses both nappes, so the roots are real
            // (a negative disc is rounding at the apex). Keep the piece on the nappe where
            // g >= 0: later along the ray when g grows with t.
            let (r0, r1) = stable_roots(a, b, c, disc.max(0.0));
            if gd > 0.0 { (r1, INF) } else { (-INF, r0) }
        }
    };
    let (s0, s1) = slab(o.y, d.y, h)?;
    let (t0, side0) = if l0 >= s0 { (l0, true) } else { (s0, false) };
    let (t1, side1) = if l1 <= s1 { (l1, true) } else { (s1, false) };
    if !(t0 <= t1) {
        return None;
    }
    let (t, entering) = first_crossing(t0, t1, lo, hi)?;
    if !N {
        return Some((t, DVec3::ZERO));
    }
    let side = if entering { side0 } else { side1 };
    // At an apex the normal points out along the axis, like the (zero-radius) cap there.
    let apex_normal = DVec3::new(0.0, if k1 < 0.0 { 1.0 } else { -1.0 }, 0.0);
    let n = if side {
        let p = o + d * t;
        let rho = (p.x * p.x + p.z * p.z).sqrt();
        if rho > 0.0 {
            // Gradient of rho - (k0 + k1 y).
            unit_or(DVec3::new(p.x / rho, -k1, p.z / rho), apex_normal)
        } else {
            apex_normal
        }
    } else {
        let up = (d.y > 0.0) != entering;
        DVec3::new(0.0, if up { 1.0 } else { -1.0 }, 0.0)
    };
    Some((t, n))
}

/// Capsule: the union of the cylinder around the segment (between its end planes) and the
/// two end balls. It is convex, so the ray's span in it is the hull of the three spans.
fn capsule<const N: bool>(
    o: DVec3,
    d: DVec3,
    a: DVec3,
    b: DVec3,
    r: f64,
    lo: f64,
    hi: f64,
) -> Option<(f64, DVec3)> {
    let mut t0 = INF;
    let mut t1 = -INF;
    for centre in [a, b] {
        if let Some((s0, s1)) = sphere_span(o - centre, d, r) {
            t0 = t0.min(s0);
            t1 = t1.max(s1);
        }
    }
    let ba = b - a;
    let len2 = ba.length_squared();
    if len2 > 0.0 {
        let len = len2.sqrt();
        let axis = ba / len;
        let oa = o - a;
        if let Some((c0, c1)) = infinite_cylinder_span(oa, d, axis, r) {
            // Along the axis: 0 <= (p - a) . axis <= len, i.e. a slab of half width len/2.
            if let Some((s0, s1)) = slab(oa.dot(axis) - 0.5 * len, d.dot(axis), 0.5 * len) {
                let (u0, u1) = (c0.max(s0), c1.min(s1));
                if u0 <= u1 {
                    t0 = t0.min(u0);
                    t1 = t1.max(u1);
                }
            }
        }
    }
    if !(t0 <= t1) {
        return None;
    }
    let (t, _) = first_crossing(t0, t1, lo, hi)?;
    let n = if N {
        let pa = o + d * t - a;
        let h = if len2 > 0.0 { (pa.dot(ba) / len2).clamp(0.0, 1.0) } else { 0.0 };
        unit_or(pa - ba * h, DVec3::Y)
    } else {
        DVec3::ZERO
    };
    Some((t, n))
}

/// Two-sided Möller–Trumbore in f64. The normal has the triangle's fixed orientation.
fn triangle(o: DVec3, d: DVec3, a: DVec3, b: DVec3, c: DVec3, lo: f64, hi: f64) -> Option<(f64, DVec3)> {
    let e1 = b - a;
    let e2 = c - a;
    let pv = d.cross(e2);
    let det = e1.dot(pv);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - a;
    let u = s.dot(pv) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qv = s.cross(e1);
    let v = d.dot(qv) * inv;
    if !(v >= 0.0 && u + v <= 1.0) {
        return None;
    }
    let t = e2.dot(qv) * inv;
    if !(t >= lo && t <= hi) {
        return None;
    }
    Some((t, unit_or(e1.cross(e2), DVec3::Y)))
}

// ---------------------------------------------------------------------------------------
// Torus
// ---------------------------------------------------------------------------------------

/// Torus in the xz plane, ring radius `major`, tube radius `minor`.
///
/// The ray is first clipped to a slightly enlarged bounding sphere and slab (so the moved
/// origin is clearly outside the torus, which touches its tight bounds), its origin moved to
/// the clip entry, its direction normalised and all lengths divided by `major + minor`. On
/// that interval of length <= ~2 the quartic's real roots are isolated exactly: the roots of
/// f'' (a quadratic) split the interval into pieces where f' is monotone, the sign changes of
/// f' there are its roots, and those split it into pieces where f is monotone, each holding
/// at most one root, found by bracketed Newton iteration (bisection when Newton leaves the
/// bracket). The first root that lies on the tube (not on the inner "lemon" sheet a spindle
/// torus's quartic also has) is the hit.
fn torus<const N: bool>(
    o: DVec3,
    d: DVec3,
    major: f64,
    minor: f64,
    lo: f64,
    hi: f64,
) -> Option<(f64, DVec3)> {
    let outer = major + minor;
    let pad = 0.01 * outer;
    let (b0, b1) = sphere_span(o, d, outer + pad)?;
    let (s0, s1) = slab(o.y, d.y, minor + pad)?;
    let start = b0.max(s0).max(lo);
    let end = b1.min(s1).min(hi);
    if !(start <= end) {
        return None;
    }
    let len = d.length();
    let scale = 1.0 / outer;
    let quartic = TorusQuartic::new((o + d * start) * scale, d / len, major * scale, minor * scale);
    let s = quartic.first_root((end - start) * len * scale)?;
    let t = (start + s * outer / len).min(end);
    let n = if N { quartic.normal(s) } else { DVec3::ZERO };
    Some((t, n))
}

/// `f(s) = (|x|^2 + R^2 - r^2)^2 - 4 R^2 (x_x^2 + x_z^2)` along `x = p + s e`, `|e| = 1`.
/// Values and derivatives are evaluated from the factored form (no coefficient cancellation).
struct TorusQuartic {
    p: DVec3,
    e: DVec3,
    big: f64,
    small: f64,
    /// `R^2 - r^2`.
    k: f64,
    /// `4 R^2`.
    four_r2: f64,
}

impl TorusQuartic {
    fn new(p: DVec3, e: DVec3, big: f64, small: f64) -> Self {
        TorusQuartic { p, e, big, small, k: (big - small) * (big + small), four_r2: 4.0 * big * big }
    }

    #[inline]
    fn point(&self, s: f64) -> DVec3 {
        self.p + self.e * s
    }

    /// f and f'.
    #[inline]
    fn value(&self, s: f64) -> (f64, f64) {
        let x = self.point(s);
        let q = x.length_squared() + self.k;
        let f = q * q - self.four_r2 * (x.x * x.x + x.z * x.z);
        let df = 4.0 * q * x.dot(self.e) - 2.0 * self.four_r2 * (x.x * self.e.x + x.z * self.e.z);
        (f, df)
    }

    /// f' and f''.
    #[inline]
    fn slope(&self, s: f64) -> (f64, f64) {
        let x = self.point(s);
        let q = x.length_squared() + self.k;
        let xe = x.dot(self.e);
        let e = self.e;
        let df = 4.0 * q * xe - 2.0 * self.four_r2 * (x.x * e.x + x.z * e.z);
        let ddf = 8.0 * xe * xe + 4.0 * q * e.length_squared() - 2.0 * self.four_r2 * (e.x * e.x + e.z * e.z);
        (df, ddf)
    }

    /// The first root in `[0, s_end]` on the tube.
    fn first_root(&self, s_end: f64) -> Option<f64> {
        // f''(s) / 2 = 6 s^2 + 12 a s + (4 a^2 + 2 b - 4 R^2 (e_x^2 + e_z^2)), with
        // a = p.e and b = |p|^2 + R^2 - r^2 (|e| = 1).
        let alpha = self.p.dot(self.e);
        let beta = self.p.length_squared() + self.k;
        let c2 =
            4.0 * alpha * alpha + 2.0 * beta - self.four_r2 * (self.e.x * self.e.x + self.e.z * self.e.z);
        let mut knots = [0.0; 4];
        let mut nk = 1;
        let disc = 36.0 * alpha * alpha - 6.0 * c2;
        if disc > 0.0 {
            let (r0, r1) = stable_roots(6.0, 6.0 * alpha, c2, disc);
            for r in [r0, r1] {
                if r > 0.0 && r < s_end {
                    knots[nk] = r;
                    nk += 1;
                }
            }
        }
        knots[nk] = s_end;
        nk += 1;

        // Where f' changes sign: f is monotone between consecutive breaks.
        let mut breaks = [0.0; 5];
        let mut nb = 1;
        for w in knots[..nk].windows(2) {
            let (u, v) = (w[0], w[1]);
            let (fu, _) = self.slope(u);
            let (fv, _) = self.slope(v);
            if (fu < 0.0) != (fv < 0.0) && fu != 0.0 && fv != 0.0 {
                breaks[nb] = bracketed_root(|s| self.slope(s), u, v, fu);
                nb += 1;
            }
        }
        breaks[nb] = s_end;
        nb += 1;

        for w in breaks[..nb].windows(2) {
            let (u, v) = (w[0], w[1]);
            let (fu, _) = self.value(u);
            let (fv, _) = self.value(v);
            let root = if fu == 0.0 {
                Some(u)
            } else if (fu < 0.0) != (fv < 0.0) {
                Some(if fv == 0.0 { v } else { bracketed_root(|s| self.value(s), u, v, fu) })
            } else if fv == 0.0 {
                Some(v)
            } else {
                None
            };
            if let Some(s) = root
                && self.on_tube(s)
            {
                return Some(s);
            }
        }
        None
    }

    /// Whether the root at `s` lies on the tube `(rho - R)^2 + y^2 = r^2` rather than on the
    /// sheet `(rho + R)^2 + y^2 = r^2` (only present when r > R, inside the solid).
    #[inline]
    fn on_tube(&self, s: f64) -> bool {
        let x = self.point(s);
        let rho = (x.x * x.x + x.z * x.z).sqrt();
        let tube = ((rho - self.big).hypot(x.y) - self.small).abs();
        let lemon = ((rho + self.big).hypot(x.y) - self.small).abs();
        tube <= lemon
    }

    /// Outward normal at `s`: from the nearest point of the ring circle to the hit point.
    #[inline]
    fn normal(&self, s: f64) -> DVec3 {
        let x = self.point(s);
        let rho = (x.x * x.x + x.z * x.z).sqrt();
        let fallback = DVec3::new(0.0, if x.y < 0.0 { -1.0 } else { 1.0 }, 0.0);
        if rho > 0.0 {
            let ring = DVec3::new(x.x, 0.0, x.z) * (self.big / rho);
            unit_or(x - ring, fallback)
        } else {
            fallback
        }
    }
}

/// A root of `f` in `[a, b]`, where `f(a)` (= `fa`, non-zero) and `f(b)` differ in sign;
/// `f` returns the value and the derivative. Newton steps that stay inside the shrinking
/// bracket, bisection otherwise; converges to full f64 precision.
#[inline]
fn bracketed_root(f: impl Fn(f64) -> (f64, f64), mut a: f64, mut b: f64, fa: f64) -> f64 {
    let a_negative = fa < 0.0;
    let mut x = 0.5 * (a + b);
    for _ in 0..100 {
        let (fx, dfx) = f(x);
        if fx == 0.0 {
            return x;
        }
        if (fx < 0.0) == a_negative {
            a = x;
        } else {
            b = x;
        }
        let newton = x - fx / dfx;
        let next = if newton > a && newton < b { newton } else { 0.5 * (a + b) };
        if (next - x).abs() <= 1e-15 * (1.0 + x.abs()) {
            return next;
        }
        x = next;
    }
    x
}

/// A closed-form primitive under a transform.
pub struct AnalyticObject {
    prim: Primitive,
    transform: Transform,
    material: MaterialId,
    bounds: Option<Aabb>,
    label: String,
}

impl AnalyticObject {
    /// A closed-form object for `prim` with the object's transform and material.
    pub fn new(prim: Primitive, object: &Object) -> Self {
        AnalyticObject {
            prim,
            transform: object.compiled_transform(),
            material: object.material,
            bounds: object.bounds(),
            label: object.label.clone(),
        }
    }
}

impl Geometry for AnalyticObject {
    fn bounds(&self) -> Option<Aabb> {
        self.bounds
    }

    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        stats.prim_tests += 1;
        // f64 local rays: a radius-5000 sphere centred 5001 away has no f32 precision left
        // for the small offsets that keep shadow rays off its surface.
        let (o, d) = self.transform.ray_to_local_f64(ray);
        let (t, n) = intersect_f64(&self.prim, o, d, t_min, t_max)?;
        let point = ray.at(t);
        Some(Hit {
            t,
            point,
            normal: self.transform.normal_to_world(n),
            shading_normal: self.transform.normal_to_world(n),
            material: self.material,
            error: f32_error(max_abs(point).max(max_abs(ray.origin))),
        })
    }

    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        stats.prim_tests += 1;
        let (o, d) = self.transform.ray_to_local_f64(ray);
        occluded_f64(&self.prim, o, d, t_min, t_max)
    }

    fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.label.capacity()
    }

    fn describe(&self) -> String {
        format!("{} '{}': closed form", self.prim.kind_name(), self.label)
    }

    fn census(&self) -> Census {
        Census::default()
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        let f = |q: DVec3| {
            crate::geometry::sdf::primitive_distance_f64(&self.prim, self.transform.point_to_local_f64(q))
        };
        let scale = self.bounds.map_or(1.0, |b| b.diagonal().length() as f64).max(1e-30);
        distance_by_projection(&f, p, 1e-7 * scale.max(p.abs().max_element()), 1e-9 * scale)
    }
}

#[cfg(test)]
mod tests;
