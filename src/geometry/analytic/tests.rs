//! Tests of the closed-form intersections of [`super`]: every primitive against the crate's
//! signed distance functions (property tests over random rays, the SDF as the oracle),
//! occlusion against intersection, and the hard cases (grazing and tangent rays, rays from
//! inside, box faces and corners, the cone's apex, tori edge-on, degenerate inputs).

use super::*;
use crate::geometry::sdf::{primitive_distance, primitive_distance_f64};
use crate::geometry::{Ray, aabb};
use glam::Vec3Swizzles;
use proptest::prelude::*;

// ---------------------------------------------------------------- oracle helpers

fn size(prim: &Primitive) -> f32 {
    prim.local_bounds().map(|b| Vec3::from(b.max - b.min).length()).unwrap_or(1.0)
}

fn centre(prim: &Primitive) -> Vec3 {
    prim.local_bounds().map(|b| Vec3::from(b.min + b.max) * 0.5).unwrap_or(Vec3::ZERO)
}

fn is_solid(prim: &Primitive) -> bool {
    !matches!(prim, Primitive::Triangle { .. })
}

/// Normalised central-difference gradient of the crate's SDF (in f64, so that a small
/// step does not drown in rounding).
fn sdf_gradient(prim: &Primitive, p: Vec3, h: f32) -> DVec3 {
    let (p, h) = (p.as_dvec3(), h as f64);
    let mut g = DVec3::ZERO;
    for i in 0..3 {
        let mut e = DVec3::ZERO;
        e[i] = h;
        g[i] = primitive_distance_f64(prim, p + e) - primitive_distance_f64(prim, p - e);
    }
    g.normalize()
}

fn segment_distance(p: Vec3, a: Vec3, b: Vec3) -> f32 {
    let ba = b - a;
    let h = ((p - a).dot(ba) / ba.dot(ba)).clamp(0.0, 1.0);
    (p - a - ba * h).length()
}

/// Whether the SDF gradient at the surface point `p` is a well-defined normal (away from
/// edges, rims, apexes and the torus axis).
fn smooth_at(prim: &Primitive, p: Vec3, s: f32) -> bool {
    let eps = 1e-2 * s;
    let rho = (p.x * p.x + p.z * p.z).sqrt();
    match *prim {
        Primitive::Box { half } => {
            let near = (0..3).filter(|&i| p[i].abs() > half[i] - eps).count();
            near < 2
        }
        Primitive::Cylinder { radius, half_height } => !(rho > radius - eps && p.y.abs() > half_height - eps),
        Primitive::Cone { radius_bottom, radius_top, half_height } => {
            let r_end = if p.y > 0.0 { radius_top } else { radius_bottom };
            let near_rim = p.y.abs() > half_height - eps && rho > r_end - eps;
            let apex_dist = |r: f32, y: f32| {
                if r == 0.0 { (p - Vec3::new(0.0, y, 0.0)).length() } else { f32::INFINITY }
            };
            let near_apex =
                apex_dist(radius_top, half_height).min(apex_dist(radius_bottom, -half_height)) < 5e-2 * s;
            !near_rim && !near_apex
        }
        Primitive::Torus { .. } => rho > 5e-2 * s,
        Primitive::Triangle { a, b, c } => {
            segment_distance(p, a, b).min(segment_distance(p, b, c)).min(segment_distance(p, c, a))
                > 2.0 * eps
        }
        _ => true,
    }
}

/// Minimum SDF over a fine sampling of the ray on `[a, b]`.
fn sampled_min(prim: &Primitive, o: Vec3, d: Vec3, a: f32, b: f32, s: f32) -> f32 {
    sampled_range(prim, o, d, a, b, s).0
}

/// Minimum and maximum SDF over a fine sampling of the ray on `[a, b]`.
fn sampled_range(prim: &Primitive, o: Vec3, d: Vec3, a: f32, b: f32, s: f32) -> (f32, f32) {
    let len = (b - a) * d.length();
    let n = ((len / (5e-4 * s)).ceil() as usize).clamp(2, 200_000);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for i in 0..=n {
        let t = a + (b - a) * (i as f32 / n as f32);
        let v = primitive_distance(prim, o + d * t);
        lo = lo.min(v);
        hi = hi.max(v);
    }
    (lo, hi)
}

/// Plain sphere tracing of the crate's SDF from `a` to `b`: the first `t` within `eps`.
fn march(prim: &Primitive, o: Vec3, d: Vec3, a: f32, b: f32, eps: f32) -> Option<f32> {
    let dl = d.length();
    let mut t = a;
    for _ in 0..100_000 {
        if t > b {
            return None;
        }
        let s = primitive_distance(prim, o + d * t);
        if s < eps {
            return Some(t);
        }
        t += s / dl;
    }
    None
}

/// The part of `[t_min, t_max]` worth examining: inside the bounds grown by 5 %.
fn examined_span(prim: &Primitive, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
    match prim.local_bounds() {
        Some(b) => {
            let g = 0.05 * size(prim);
            let grown = aabb(Vec3::from(b.min) - g, Vec3::from(b.max) + g);
            Ray::new(o, d).clip_to_box(&grown, t_min, t_max)
        }
        None => Some((t_min, t_max.min(t_min + 20.0 / d.length()))),
    }
}

/// Checks one ray against the SDF oracle. Returns the hit for further checks.
fn check_ray(
    prim: &Primitive,
    o: Vec3,
    d: Vec3,
    t_min: f32,
    t_max: f32,
) -> Result<Option<(f32, Vec3)>, String> {
    let s = size(prim);
    let res = intersect(prim, o, d, t_min, t_max);
    let ctx = || format!("{prim:?} o={o:?} d={d:?} t in [{t_min}, {t_max}] -> {res:?}");
    if occluded(prim, o, d, t_min, t_max) != res.is_some() {
        return Err(format!("occluded disagrees: {}", ctx()));
    }
    let span = examined_span(prim, o, d, t_min, t_max);
    match res {
        Some((t, n)) => {
            if !(t.is_finite() && t >= t_min && t <= t_max && n.is_finite()) {
                return Err(format!("bad t or normal: {}", ctx()));
            }
            if (n.length() - 1.0).abs() > 1e-5 {
                return Err(format!("normal not unit: {}", ctx()));
            }
            let p = o + d * t;
            let dist = primitive_distance(prim, p);
            if dist.abs() > 1e-4 * s {
                return Err(format!("hit point off the surface by {dist}: {}", ctx()));
            }
            if smooth_at(prim, p, s) {
                let h = 1e-4 * s.max(p.length());
                let n64 = n.as_dvec3();
                let err = match prim {
                    Primitive::Triangle { .. } => {
                        // The unsigned distance has a kink on the plane: take the
                        // gradient just off it, and compare up to sign.
                        let g = sdf_gradient(prim, p + n * (1e-2 * s), h);
                        (n64 - g).length().min((n64 + g).length())
                    }
                    _ => (n64 - sdf_gradient(prim, p, h)).length(),
                };
                if err > 1e-3 {
                    return Err(format!("normal off the SDF gradient by {err}: {}", ctx()));
                }
            }
            // No earlier entry was skipped: before the hit the ray stays outside.
            if is_solid(prim)
                && let Some((a, _)) = span
            {
                let b = t - 2e-3 * s / d.length();
                if b > a && primitive_distance(prim, o + d * a) > 0.0 {
                    let m = sampled_min(prim, o, d, a, b, s);
                    if m < -1e-4 * s {
                        return Err(format!("skipped an earlier entry (min {m}): {}", ctx()));
                    }
                }
            }
        }
        None => {
            let Some((a, b)) = span else { return Ok(None) };
            let (m, top) = sampled_range(prim, o, d, a, b, s);
            // Missing is wrong when the ray crosses the surface: both clearly inside and
            // clearly outside somewhere along it.
            if is_solid(prim) && m < -1e-4 * s && top > 1e-4 * s {
                return Err(format!("missed a ray that crosses the surface (min {m}): {}", ctx()));
            }
            if let Primitive::Triangle { a: va, b: vb, c: vc } = *prim {
                // Zero thickness: sphere tracing cannot tell a graze from a crossing, so
                // check where the ray crosses the plane: not inside the triangle (up to
                // rounding at the edges).
                let nrm = (vb - va).cross(vc - va).as_dvec3();
                let tc = nrm.dot((va - o).as_dvec3()) / nrm.dot(d.as_dvec3());
                if tc >= t_min as f64 && tc <= t_max as f64 {
                    let x = (o.as_dvec3() + d.as_dvec3() * tc).as_vec3();
                    let inside = primitive_distance(prim, x) < 1e-6 * s;
                    let edge = segment_distance(x, va, vb)
                        .min(segment_distance(x, vb, vc))
                        .min(segment_distance(x, vc, va));
                    if inside && edge > 1e-4 * s {
                        return Err(format!("missed a ray through the interior at t={tc}: {}", ctx()));
                    }
                }
            } else {
                // From outside, the sphere tracer agrees, up to grazing contact.
                let start_outside = primitive_distance(prim, o + d * a) > 1e-4 * s;
                if let Some(tm) = march(prim, o, d, a, b, 1e-4 * s).filter(|_| start_outside)
                    && (m < -1e-4 * s || m > 1e-3 * s)
                {
                    return Err(format!("sphere tracing finds a surface at t={tm}: {}", ctx()));
                }
            }
        }
    }
    Ok(res)
}

/// A ray from outside the bounds (0.6..2.5 diagonals from the centre) towards a point
/// near the object, with a direction of arbitrary length.
#[derive(Clone, Copy, Debug)]
struct RaySpec {
    from: Vec3,
    dist: f32,
    target: Vec3,
    dscale: f32,
    range: u8,
    tval: f32,
}

fn ray_spec() -> impl Strategy<Value = RaySpec> {
    let v = || (fr(-1.0, 1.0), fr(-1.0, 1.0), fr(-1.0, 1.0)).prop_map(|(x, y, z)| Vec3::new(x, y, z));
    (v(), fr(0.6, 2.5), v(), fr(0.3, 3.0), 0u8..4, fr(0.0, 1.0)).prop_map(
        |(from, dist, target, dscale, range, tval)| RaySpec { from, dist, target, dscale, range, tval },
    )
}

/// The concrete ray for `prim`: origin, direction, t_min, t_max.
fn make_ray(prim: &Primitive, r: &RaySpec) -> (Vec3, Vec3, f32, f32) {
    let s = size(prim);
    let c = centre(prim);
    let ext = prim.local_bounds().map(|b| Vec3::from(b.max - b.min)).unwrap_or(Vec3::ONE);
    let o = c + r.from.try_normalize().unwrap_or(Vec3::X) * (r.dist * s);
    let target = c + r.target * 0.7 * ext;
    let d = (target - o).try_normalize().unwrap_or(-Vec3::X) * r.dscale;
    let reach = (target - o).length() / r.dscale;
    let (t_min, t_max) = match r.range {
        0 => (0.0, f32::INFINITY),
        1 => (0.0, 2.0 * reach * r.tval),
        2 => (reach * r.tval, f32::INFINITY),
        _ => (1e-4, 1e30),
    };
    (o, d, t_min, t_max)
}

fn check_rays(prim: &Primitive, rays: &[RaySpec]) -> Result<(), TestCaseError> {
    for r in rays {
        let (o, d, t_min, t_max) = make_ray(prim, r);
        check_ray(prim, o, d, t_min, t_max).map_err(TestCaseError::fail)?;
    }
    Ok(())
}

fn rays() -> impl Strategy<Value = Vec<RaySpec>> {
    proptest::collection::vec(ray_spec(), 6)
}

/// A float in `[lo, hi]` on a grid of 2^24 steps (proptest's own float ranges can trip a
/// debug assertion of its sampler), shrinking toward `lo`.
fn fr(lo: f32, hi: f32) -> impl Strategy<Value = f32> + Clone {
    (0u32..=1 << 24).prop_map(move |k| lo + (hi - lo) * (k as f32 / (1u32 << 24) as f32))
}

fn v3(lo: f32, hi: f32) -> impl Strategy<Value = Vec3> {
    (fr(lo, hi), fr(lo, hi), fr(lo, hi)).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn cfg() -> ProptestConfig {
    ProptestConfig { cases: 1000, failure_persistence: None, ..ProptestConfig::default() }
}

// ---------------------------------------------------------------- property tests

proptest! {
    #![proptest_config(cfg())]

    #[test]
    fn sphere_matches_sdf(radius in fr(0.2, 3.0), rays in rays()) {
        check_rays(&Primitive::Sphere { radius }, &rays)?;
    }

    #[test]
    fn ellipsoid_matches_sdf(radii in v3(0.2, 2.0), rays in rays()) {
        check_rays(&Primitive::Ellipsoid { radii }, &rays)?;
    }

    #[test]
    fn box_matches_sdf(half in v3(0.2, 2.0), rays in rays()) {
        check_rays(&Primitive::Box { half }, &rays)?;
    }

    #[test]
    fn cylinder_matches_sdf(radius in fr(0.2, 2.0), half_height in fr(0.2, 2.0), rays in rays()) {
        check_rays(&Primitive::Cylinder { radius, half_height }, &rays)?;
    }

    #[test]
    fn cone_matches_sdf(
        r1 in fr(0.2, 2.0),
        r2 in fr(0.0, 2.0),
        half_height in fr(0.2, 2.0),
        mode in 0u8..5,
        rays in rays(),
    ) {
        let (radius_bottom, radius_top) = match mode {
            0 => (r1, 0.0),
            1 => (0.0, r1),
            2 => (r1, r1),
            3 => (r1, r2),
            _ => (r2, r1),
        };
        check_rays(&Primitive::Cone { radius_bottom, radius_top, half_height }, &rays)?;
    }

    #[test]
    fn capsule_matches_sdf(a in v3(-1.0, 1.0), b in v3(-1.0, 1.0), radius in fr(0.1, 1.0), rays in rays()) {
        prop_assume!((b - a).length() > 1e-3);
        check_rays(&Primitive::Capsule { a, b, radius }, &rays)?;
    }

    #[test]
    fn torus_matches_sdf(major in fr(0.3, 2.0), ratio in fr(0.2, 1.3), rays in rays()) {
        check_rays(&Primitive::Torus { major, minor: major * ratio }, &rays)?;
    }

    #[test]
    fn triangle_matches_sdf(a in v3(-1.0, 1.0), b in v3(-1.0, 1.0), c in v3(-1.0, 1.0), rays in rays()) {
        let longest = (b - a).length().max((c - b).length()).max((a - c).length());
        prop_assume!((b - a).cross(c - a).length() > 0.1 * longest * longest);
        check_rays(&Primitive::Triangle { a, b, c }, &rays)?;
    }

    #[test]
    fn plane_matches_sdf(
        normal in v3(-1.0, 1.0),
        offset in fr(-2.0, 2.0),
        from in v3(-5.0, 5.0),
        target in v3(-3.0, 3.0),
        dir in v3(-1.0, 1.0),
        aim in any::<bool>(),
    ) {
        let normal = normal.try_normalize().unwrap_or(Vec3::Y);
        let prim = Primitive::Plane { normal, offset };
        // Aim at a point of the plane, or shoot anywhere.
        let on_plane = target - normal * (normal.dot(target) - offset);
        let d = if aim { on_plane - from } else { dir };
        prop_assume!(d.length() > 1e-3);
        // Hits within about 100 units (f32 hit points stay within 1e-5 of the plane).
        let t_max = 100.0 / d.length();
        let res = check_ray(&prim, from, d, 0.0, t_max).map_err(TestCaseError::fail)?;
        let side = normal.as_dvec3().dot(from.as_dvec3()) - offset as f64;
        let towards = normal.as_dvec3().dot(d.as_dvec3());
        let t_true = -side / towards;
        prop_assert_eq!(res.is_some(), towards != 0.0 && t_true >= 0.0 && t_true <= t_max as f64);
        if let Some((_, n)) = res {
            prop_assert!((n - normal).length() < 1e-6);
        }
    }

    #[test]
    fn occluded_agrees_with_intersect(
        kind in 0u8..9,
        p in v3(0.2, 2.0),
        o in v3(-4.0, 4.0),
        d in v3(-1.0, 1.0),
        t_min in fr(-1.0, 3.0),
        span in fr(0.0, 6.0),
    ) {
        let prim = match kind {
            0 => Primitive::Sphere { radius: p.x },
            1 => Primitive::Plane { normal: p.normalize(), offset: p.y - 1.0 },
            2 => Primitive::Box { half: p },
            3 => Primitive::Ellipsoid { radii: p },
            4 => Primitive::Cylinder { radius: p.x, half_height: p.y },
            5 => Primitive::Cone { radius_bottom: p.x, radius_top: p.z - 0.2, half_height: p.y },
            6 => Primitive::Torus { major: p.x, minor: p.y * 0.5 },
            7 => Primitive::Triangle { a: -p, b: p.zxy(), c: Vec3::new(p.y, -p.x, p.z) },
            _ => Primitive::Capsule { a: -p * 0.5, b: p.yzx() * 0.5, radius: p.z * 0.3 },
        };
        let t_max = t_min + span;
        let hit = intersect(&prim, o, d, t_min, t_max);
        prop_assert_eq!(occluded(&prim, o, d, t_min, t_max), hit.is_some());
        if let Some((t, n)) = hit {
            prop_assert!(t >= t_min && t <= t_max && n.is_finite());
        }
    }
}

// ---------------------------------------------------------------- hard cases

/// A tiny deterministic generator for loops over many rays.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next()
    }

    fn unit(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(self.range(-1.0, 1.0), self.range(-1.0, 1.0), self.range(-1.0, 1.0));
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }
}

#[test]
fn sphere_grazing_tangent_rays() {
    let r = 1.5f32;
    let prim = Primitive::Sphere { radius: r };
    for &(dir, off) in &[(Vec3::X, Vec3::Y), (Vec3::Z, Vec3::X), (Vec3::new(1.0, 1.0, 0.0), Vec3::Z)] {
        let dn = dir.normalize();
        for &(delta, hits) in &[(-1e-4f32, true), (-1e-5, true), (1e-5, false), (1e-4, false)] {
            let o = -dn * 10.0 + off * (r + delta);
            let res = check_ray(&prim, o, dn * 0.7, 0.0, f32::INFINITY).unwrap();
            assert_eq!(res.is_some(), hits, "delta {delta} dir {dir:?}");
            if let Some((t, n)) = res {
                let p = (o + dn * 0.7 * t).as_dvec3();
                assert!((p.length() - r as f64).abs() < 1e-6, "{p:?}");
                assert!(n.dot(dn) < 0.05 && n.dot(off) > 0.99);
            }
        }
    }
}

/// The ground of the classic test scene: radius 5000 centred at (0, -5001, 0), rays from
/// near the origin at grazing angles.
#[test]
fn ground_sphere_at_grazing_angles() {
    let radius = 5000.0f64;
    let prim = Primitive::Sphere { radius: radius as f32 };
    let centre = DVec3::new(0.0, -5001.0, 0.0);
    let mut rng = Rng(0x9e3779b97f4a7c15);
    let (mut hits, mut misses) = (0, 0);
    for i in 0..20_000 {
        // World origins on a 1/1024 grid, so that the f32 local origin is exact.
        let q = |v: f64| (v * 1024.0).round() / 1024.0;
        let ow = DVec3::new(q(rng.range(-3.0, 3.0)), q(rng.range(-0.9, 3.0)), q(rng.range(-3.0, 3.0)));
        let phi = rng.range(0.0, std::f64::consts::TAU);
        // Around the horizon dip (about sqrt(2 h / R) = 0.02 rad for h = 1).
        let theta = rng.range(-0.08, 0.01);
        let dw =
            DVec3::new(theta.cos() * phi.cos(), theta.sin(), theta.cos() * phi.sin()) * rng.range(0.5, 2.0);
        let (o, d) = ((ow - centre).as_vec3(), dw.as_vec3());
        let (o64, d64) = (o.as_dvec3(), d.as_dvec3());
        assert_eq!(o64, ow - centre);
        // Ground truth from the closest approach of the line to the centre.
        let along = -o64.dot(d64) / d64.length_squared();
        let closest = (o64 + d64 * along).length();
        // Alternate the f32 and the f64 entry points.
        let res = if i % 2 == 0 {
            intersect(&prim, o, d, 0.0, f32::INFINITY)
        } else {
            intersect_f64(&prim, o64, d64, 0.0, f32::INFINITY)
        };
        assert_eq!(res.is_some(), occluded(&prim, o, d, 0.0, f32::INFINITY));
        match res {
            Some((t, n)) => {
                hits += 1;
                let p = o64 + d64 * t as f64;
                let err = p.length() - radius;
                assert!(err.abs() < 1e-4, "hit {err} off the ground: o={ow:?} d={dw:?}");
                // The near root: entering, before the closest approach.
                assert!(n.as_dvec3().dot(d64) < 0.0 && (t as f64) <= along + 1e-3);
                assert!(closest <= radius + 1e-6);
                // The world hit point is as good.
                let pw = ow + dw * t as f64;
                assert!(((pw - centre).length() - radius).abs() < 1e-4);
            }
            None => {
                misses += 1;
                assert!(
                    !(closest < radius - 1e-3 && along > 0.0),
                    "missed a ray that enters: o={ow:?} d={dw:?} closest={closest}"
                );
            }
        }
    }
    assert!(hits > 1000 && misses > 1000, "{hits} hits, {misses} misses");
}

fn interior_point(prim: &Primitive, rng: &mut Rng) -> Vec3 {
    let b = prim.local_bounds().unwrap();
    let s = size(prim);
    loop {
        let p = Vec3::new(
            rng.range(b.min.x as f64, b.max.x as f64) as f32,
            rng.range(b.min.y as f64, b.max.y as f64) as f32,
            rng.range(b.min.z as f64, b.max.z as f64) as f32,
        );
        if primitive_distance(prim, p) < -0.02 * s {
            return p;
        }
    }
}

#[test]
fn rays_from_inside_exit_with_outward_normals() {
    let solids = [
        Primitive::Sphere { radius: 1.3 },
        Primitive::Ellipsoid { radii: Vec3::new(0.5, 1.5, 1.0) },
        Primitive::Box { half: Vec3::new(0.5, 1.0, 1.5) },
        Primitive::Cylinder { radius: 0.7, half_height: 1.2 },
        Primitive::Cone { radius_bottom: 1.0, radius_top: 0.0, half_height: 1.0 },
        Primitive::Cone { radius_bottom: 0.0, radius_top: 0.8, half_height: 0.6 },
        Primitive::Cone { radius_bottom: 0.4, radius_top: 1.1, half_height: 0.9 },
        Primitive::Cone { radius_bottom: 0.6, radius_top: 0.6, half_height: 0.9 },
        Primitive::Capsule { a: Vec3::new(-0.5, 0.2, 0.1), b: Vec3::new(0.7, -0.4, 0.3), radius: 0.4 },
        Primitive::Torus { major: 2.0, minor: 0.5 },
        Primitive::Torus { major: 0.6, minor: 0.8 },
    ];
    let mut rng = Rng(12345);
    for prim in &solids {
        let s = size(prim);
        for _ in 0..300 {
            let o = interior_point(prim, &mut rng);
            let d = (rng.unit() * rng.range(0.3, 3.0)).as_vec3();
            let (t, n) = check_ray(prim, o, d, 0.0, f32::INFINITY)
                .unwrap()
                .unwrap_or_else(|| panic!("no exit from inside {prim:?} o={o:?} d={d:?}"));
            assert!(t > 0.0);
            assert!(n.dot(d) > 0.0, "normal not outward at the exit: {prim:?} o={o:?} d={d:?}");
            let p = o + d * t;
            if smooth_at(prim, p, s) {
                let g = sdf_gradient(prim, p, 1e-4 * s);
                assert!((n.as_dvec3() - g).length() < 1e-3);
            }
        }
    }
    // The plane: solid below.
    let normal = Vec3::new(0.3, 0.9, -0.2).normalize();
    let plane = Primitive::Plane { normal, offset: 0.5 };
    let o = normal * -1.0;
    let up = intersect(&plane, o, normal + Vec3::X * 0.3, 0.0, f32::INFINITY).unwrap();
    assert!((up.1 - normal).length() < 1e-6);
    assert!(primitive_distance(&plane, o + (normal + Vec3::X * 0.3) * up.0).abs() < 1e-6);
    assert!(intersect(&plane, o, -normal, 0.0, f32::INFINITY).is_none());
}

#[test]
fn box_rays_parallel_to_faces() {
    let half = Vec3::new(1.0, 2.0, 0.5);
    let prim = Primitive::Box { half };
    let inf = f32::INFINITY;
    // In the top face plane, coming from outside: enters through the edge at x = -1.
    let (t, n) = intersect(&prim, Vec3::new(-3.0, 2.0, 0.2), Vec3::X, 0.0, inf).unwrap();
    assert_eq!((t, n), (2.0, -Vec3::X));
    // In the top face plane, starting inside the face: leaves at x = 1.
    let (t, n) = intersect(&prim, Vec3::new(0.0, 2.0, 0.0), Vec3::X * 2.0, 0.0, inf).unwrap();
    assert_eq!((t, n), (0.5, Vec3::X));
    // Just above the face plane: misses.
    assert!(intersect(&prim, Vec3::new(-3.0, 2.000001, 0.2), Vec3::X, 0.0, inf).is_none());
    // Two zero components, origin on two planes (an edge line of the box).
    let (t, n) = intersect(&prim, Vec3::new(1.0, 5.0, 0.5), -Vec3::Y, 0.0, inf).unwrap();
    assert_eq!((t, n), (3.0, Vec3::Y));
    // Straight through the middle of a face.
    let (t, n) = intersect(&prim, Vec3::new(0.2, 0.3, -4.0), Vec3::Z * 0.5, 0.0, inf).unwrap();
    assert_eq!((t, n), (7.0, -Vec3::Z));
    // Every combination of zero and non-zero components from origins on, inside and
    // outside the face planes: never NaN, and consistent with the SDF.
    let coords = |h: f32| [-3.0 * h, -h, -0.5 * h, 0.0, 0.5 * h, h, 3.0 * h];
    let comps = [-1.0f32, 0.0, 0.7];
    for &x in &coords(half.x) {
        for &y in &coords(half.y) {
            for &z in &coords(half.z) {
                let o = Vec3::new(x, y, z);
                for &dx in &comps {
                    for &dy in &comps {
                        for &dz in &comps {
                            let d = Vec3::new(dx, dy, dz);
                            let res = intersect(&prim, o, d, 0.0, inf);
                            assert_eq!(res.is_some(), occluded(&prim, o, d, 0.0, inf));
                            if d == Vec3::ZERO {
                                assert!(res.is_none());
                            }
                            if let Some((t, n)) = res {
                                assert!(t.is_finite() && n.is_finite() && t >= 0.0);
                                assert_eq!(n.abs().max_element(), 1.0);
                                assert!(primitive_distance(&prim, o + d * t).abs() < 1e-6);
                                // The face normal is the one of the face the point is on.
                                let p = o + d * t;
                                let axis = n.abs().max_position();
                                assert!((p[axis] - n[axis] * half[axis]).abs() < 1e-6);
                            }
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn box_corners_and_edges_pick_one_face_deterministically() {
    let prim = Primitive::Box { half: Vec3::ONE };
    let o = Vec3::splat(-3.0);
    let d = Vec3::ONE;
    let (t, n) = intersect(&prim, o, d, 0.0, f32::INFINITY).unwrap();
    assert_eq!(t, 2.0);
    assert_eq!(n, -Vec3::X);
    assert_eq!(intersect(&prim, o, d, 0.0, f32::INFINITY), Some((t, n)));
    // From inside through the opposite corner.
    let (t, n) = intersect(&prim, Vec3::ZERO, d, 0.0, f32::INFINITY).unwrap();
    assert_eq!((t, n), (1.0, Vec3::X));
    // An edge (x and y tie).
    let (t, n) =
        intersect(&prim, Vec3::new(-3.0, -3.0, 0.2), Vec3::new(1.0, 1.0, 0.0), 0.0, f32::INFINITY).unwrap();
    assert_eq!((t, n), (2.0, -Vec3::X));
}

#[test]
fn cone_apex_hit_exactly() {
    let inf = f32::INFINITY;
    let up = Primitive::Cone { radius_bottom: 1.0, radius_top: 0.0, half_height: 1.0 };
    // Down the axis onto the apex.
    let (t, n) = intersect(&up, Vec3::new(0.0, 3.0, 0.0), -Vec3::Y, 0.0, inf).unwrap();
    assert!((t - 2.0).abs() < 1e-6, "{t}");
    assert_eq!(n, Vec3::Y);
    // Steeper than the surface, through the apex: enters there.
    let apex = Vec3::Y;
    for &o in &[Vec3::new(0.5, 3.0, 0.0), Vec3::new(-0.2, 2.0, 0.3), Vec3::new(0.01, 4.0, -0.02)] {
        let d = (apex - o) * 0.37;
        let (t, _) = intersect(&up, o, d, 0.0, inf).unwrap_or_else(|| panic!("missed the apex from {o:?}"));
        assert!((o + d * t - apex).length() < 1e-5, "{t}");
    }
    // Exactly along a generator line through the apex (the ray slides on the surface):
    // a miss or a point of the surface, nothing else.
    let o = Vec3::new(-0.3, 2.0, 0.4);
    if let Some((t, n)) = intersect(&up, o, (apex - o) * 0.37, 0.0, inf) {
        assert!(primitive_distance(&up, o + (apex - o) * 0.37 * t).abs() < 1e-5);
        assert!(n.is_finite());
    }
    // Along the axis from inside: leaves through the apex, normal along the axis.
    let (t, n) = intersect(&up, Vec3::ZERO, Vec3::Y, 0.0, inf).unwrap();
    assert!((t - 1.0).abs() < 1e-6 && n == Vec3::Y);
    // Apex at the bottom.
    let down = Primitive::Cone { radius_bottom: 0.0, radius_top: 0.5, half_height: 2.0 };
    let (t, n) = intersect(&down, Vec3::new(0.0, -5.0, 0.0), Vec3::Y * 2.0, 0.0, inf).unwrap();
    assert!((t - 1.5).abs() < 1e-6 && n == -Vec3::Y);
    let o = Vec3::new(0.05, -4.0, 0.0);
    let d = Vec3::new(0.0, -2.0, 0.0) - o;
    let (t, _) = intersect(&down, o, d, 0.0, inf).unwrap();
    assert!((o + d * t - Vec3::new(0.0, -2.0, 0.0)).length() < 1e-5);
    // Just beside the apex, parallel to the axis: misses.
    assert!(
        intersect(&up, Vec3::new(1e-3, 3.0, 0.0), -Vec3::Y, 0.0, inf).map(|(t, _)| t > 2.0).unwrap_or(true)
    );
}

#[test]
fn cone_with_equal_radii_is_a_cylinder() {
    let cone = Primitive::Cone { radius_bottom: 0.8, radius_top: 0.8, half_height: 1.1 };
    let cyl = Primitive::Cylinder { radius: 0.8, half_height: 1.1 };
    let mut rng = Rng(777);
    for i in 0..5000 {
        let o = (rng.unit() * 4.0).as_vec3();
        let mut d = (DVec3::new(rng.range(-1.2, 1.2), rng.range(-1.2, 1.2), rng.range(-1.2, 1.2))
            - o.as_dvec3())
        .as_vec3();
        if i % 5 == 0 {
            // Parallel to the axis.
            d = Vec3::new(0.0, -o.y.signum(), 0.0);
        }
        let a = intersect(&cone, o, d, 0.0, f32::INFINITY);
        let b = intersect(&cyl, o, d, 0.0, f32::INFINITY);
        match (a, b) {
            (Some((ta, na)), Some((tb, nb))) => {
                assert!((ta - tb).abs() <= 1e-5 * tb.max(1.0), "{o:?} {d:?}");
                if smooth_at(&cyl, o + d * tb, size(&cyl)) {
                    assert!((na - nb).length() < 1e-5);
                }
            }
            (None, None) => {}
            _ => panic!("cone and cylinder disagree: {o:?} {d:?} {a:?} {b:?}"),
        }
    }
}

#[test]
fn torus_edge_on() {
    let (major, minor) = (2.0f32, 0.5f32);
    let prim = Primitive::Torus { major, minor };
    let outer = (major + minor) as f64;
    // Through the centre in the torus plane: t = dist - (R + r).
    let (t, n) = intersect(&prim, Vec3::new(-10.0, 0.0, 0.0), Vec3::X, 0.0, f32::INFINITY).unwrap();
    assert!((t - 7.5).abs() < 1e-6, "{t}");
    assert!((n + Vec3::X).length() < 1e-6);
    let (t, _) = intersect(&prim, Vec3::new(-10.0, 0.0, 0.0), Vec3::X * 3.0, 0.0, f32::INFINITY).unwrap();
    assert!((t - 2.5).abs() < 1e-6, "{t}");
    // Many rays in the plane y = 0 against the two circles of radii R + r and R - r.
    let mut rng = Rng(99);
    for _ in 0..5000 {
        let phi = rng.range(0.0, std::f64::consts::TAU);
        let dist = rng.range(3.0, 20.0);
        let o = DVec3::new(phi.cos() * dist, 0.0, phi.sin() * dist);
        let aim = DVec3::new(rng.range(-3.0, 3.0), 0.0, rng.range(-3.0, 3.0));
        let d = ((aim - o) * rng.range(0.2, 2.0)).as_vec3();
        let o = o.as_vec3();
        let (o64, d64) = (o.as_dvec3(), d.as_dvec3());
        // First crossing of |x| = outer, then of |x| = inner.
        let circle = |r: f64| {
            let a = d64.length_squared();
            let b = o64.dot(d64);
            let c = o64.length_squared() - r * r;
            let disc = b * b - a * c;
            (disc >= 0.0).then(|| ((-b - disc.sqrt()) / a, (-b + disc.sqrt()) / a))
        };
        let expect = circle(outer).and_then(|(t0, _)| (t0 >= 0.0).then_some(t0));
        let res = intersect(&prim, o, d, 0.0, f32::INFINITY);
        match (expect, res) {
            (Some(te), Some((t, n))) => {
                assert!(((t as f64) - te).abs() < 1e-5 * te.max(1.0), "{t} vs {te}: o={o:?} d={d:?}");
                assert!(n.y.abs() < 1e-6);
            }
            (None, None) => {}
            (Some(te), None) => {
                // Only a numerically tangent ray may miss.
                let along = -o64.dot(d64) / d64.length_squared();
                let closest = (o64 + d64 * along).length();
                assert!((closest - outer).abs() < 1e-6, "missed: o={o:?} d={d:?} expected {te}");
            }
            (None, Some(h)) => panic!("spurious hit {h:?}: o={o:?} d={d:?}"),
        }
    }
}

#[test]
fn torus_rays_in_the_plane_starting_inside_the_tube() {
    let (major, minor) = (2.0f32, 0.5f32);
    let prim = Primitive::Torus { major, minor };
    let mut rng = Rng(4242);
    for _ in 0..2000 {
        let phi = rng.range(0.0, std::f64::consts::TAU);
        let rho = rng.range(1.55, 2.45);
        let o = DVec3::new(phi.cos() * rho, 0.0, phi.sin() * rho).as_vec3();
        let psi = rng.range(0.0, std::f64::consts::TAU);
        let d = DVec3::new(psi.cos(), 0.0, psi.sin()).as_vec3();
        let (t, n) = check_ray(&prim, o, d, 0.0, f32::INFINITY).unwrap().unwrap();
        let p = (o + d * t).as_dvec3();
        let r = p.length();
        assert!((r - 2.5).abs() < 1e-5 || (r - 1.5).abs() < 1e-5, "{r}");
        assert!(n.dot(d) > 0.0);
    }
}

#[test]
fn torus_grazing_the_outer_equator() {
    let prim = Primitive::Torus { major: 2.0, minor: 0.5 };
    let inf = f32::INFINITY;
    // Exactly tangent: either a touch at the tangent point or a miss, never anything else.
    if let Some((t, _)) = intersect(&prim, Vec3::new(-10.0, 0.0, 2.5), Vec3::X, 0.0, inf) {
        assert!((t - 10.0).abs() < 1e-2, "{t}");
    }
    // Just inside: a hit near the tangent point, on the surface.
    for &delta in &[1e-4f32, 1e-3, 1e-2] {
        let o = Vec3::new(-10.0, 0.0, 2.5 - delta);
        let (t, n) = check_ray(&prim, o, Vec3::X, 0.0, inf).unwrap().unwrap();
        let z = 2.5 - delta as f64;
        let expect = 10.0 - (2.5f64 * 2.5 - z * z).sqrt();
        assert!((t as f64 - expect).abs() < 1e-4, "{t} vs {expect}");
        assert!(n.z > 0.9);
        // Slightly above or below the plane too.
        let o2 = o + Vec3::Y * 1e-6;
        assert!(check_ray(&prim, o2, Vec3::X, 0.0, inf).unwrap().is_some());
    }
    // Just outside: a miss.
    for &delta in &[1e-4f32, 1e-3] {
        let o = Vec3::new(-10.0, 0.0, 2.5 + delta);
        assert!(check_ray(&prim, o, Vec3::X, 0.0, inf).unwrap().is_none());
    }
    // Grazing the top circle (y = r, rho = R) along a tangent.
    let o = Vec3::new(-10.0, 0.5 - 1e-4, 2.0);
    assert!(check_ray(&prim, o, Vec3::X, 0.0, inf).unwrap().is_some());
    let o = Vec3::new(-10.0, 0.5 + 1e-4, 2.0);
    assert!(check_ray(&prim, o, Vec3::X, 0.0, inf).unwrap().is_none());
}

#[test]
fn torus_hole_is_empty() {
    let prim = Primitive::Torus { major: 2.0, minor: 0.5 };
    let inf = f32::INFINITY;
    assert!(intersect(&prim, Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, 0.0, inf).is_none());
    assert!(intersect(&prim, Vec3::new(0.5, 5.0, 0.0), Vec3::new(-0.1, -1.0, 0.0), 0.0, inf).is_none());
    assert!(intersect(&prim, Vec3::new(1.0, 4.0, -1.0), Vec3::new(-0.3, -1.0, 0.25), 0.0, inf).is_none());
    // Parallel to the axis just inside and just outside the inner equator (rho = 1.5).
    for &(x, hits) in &[(-1.45f32, false), (-1.499, false), (-1.501, true), (-1.55, true)] {
        let res = check_ray(&prim, Vec3::new(x, 3.0, 0.0), -Vec3::Y, 0.0, inf).unwrap();
        assert_eq!(res.is_some(), hits, "{x}");
    }
    // Thin ring, long way through the hole along the axis from below.
    let ring = Primitive::Torus { major: 100.0, minor: 0.1 };
    assert!(intersect(&ring, Vec3::new(3.0, -50.0, -2.0), Vec3::Y, 0.0, inf).is_none());
    let (t, _) = check_ray(&ring, Vec3::new(100.0, -50.0, 0.0), Vec3::Y, 0.0, inf).unwrap().unwrap();
    assert!((t - 49.9).abs() < 1e-4);
}

#[test]
fn triangle_normal_is_fixed_and_edges_are_closed() {
    let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
    let tri = Primitive::Triangle { a, b, c };
    let inf = f32::INFINITY;
    let (t1, n1) = intersect(&tri, Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 0.0, inf).unwrap();
    let (t2, n2) = intersect(&tri, Vec3::new(0.2, 0.2, -2.0), Vec3::Z * 2.0, 0.0, inf).unwrap();
    assert_eq!((t1, t2), (1.0, 1.0));
    assert_eq!(n1, Vec3::Z);
    assert_eq!(n2, Vec3::Z);
    // Parallel to the plane, even in it: no hit and no NaN.
    assert!(intersect(&tri, Vec3::new(-1.0, 0.2, 0.0), Vec3::X, 0.0, inf).is_none());
    assert!(intersect(&tri, Vec3::new(-1.0, 0.2, 0.5), Vec3::X, 0.0, inf).is_none());
    // Two coplanar triangles sharing an edge: a ray through a point of the edge hits one.
    let d_ = Vec3::new(1.0, 1.0, 0.0);
    let t2 = Primitive::Triangle { a: b, b: d_, c };
    let mut rng = Rng(5);
    for _ in 0..5000 {
        let u = rng.next() as f32;
        let p = b + (c - b) * u;
        let o = p + (rng.unit() * 2.0).as_vec3();
        let d = p - o;
        let h1 = intersect(&tri, o, d, 0.0, inf);
        let h2 = intersect(&t2, o, d, 0.0, inf);
        assert!(h1.is_some() || h2.is_some(), "crack at {p:?} from {o:?}");
    }
}

#[test]
fn degenerate_inputs_never_nan() {
    let prims = [
        Primitive::Sphere { radius: 1.0 },
        Primitive::Plane { normal: Vec3::Y, offset: 0.0 },
        Primitive::Box { half: Vec3::ONE },
        Primitive::Ellipsoid { radii: Vec3::new(1.0, 2.0, 3.0) },
        Primitive::Cylinder { radius: 1.0, half_height: 1.0 },
        Primitive::Cone { radius_bottom: 1.0, radius_top: 0.0, half_height: 1.0 },
        Primitive::Torus { major: 1.0, minor: 0.3 },
        Primitive::Triangle { a: Vec3::ZERO, b: Vec3::X, c: Vec3::Z },
        Primitive::Capsule { a: Vec3::ZERO, b: Vec3::Y, radius: 0.5 },
    ];
    let origins = [Vec3::ZERO, Vec3::new(0.0, 5.0, 0.0), Vec3::new(1.0, 1.0, 1.0), Vec3::new(0.0, 1.0, 0.0)];
    let dirs =
        [Vec3::ZERO, Vec3::Y, -Vec3::Y, Vec3::X, Vec3::new(0.0, 1e-30, 0.0), Vec3::new(1e-38, -1.0, 0.0)];
    for prim in &prims {
        for &o in &origins {
            for &d in &dirs {
                for &(t0, t1) in
                    &[(0.0, f32::INFINITY), (1.0, 0.5), (f32::NEG_INFINITY, f32::INFINITY), (f32::NAN, 1.0)]
                {
                    let r = intersect(prim, o, d, t0, t1);
                    assert_eq!(r.is_some(), occluded(prim, o, d, t0, t1));
                    if let Some((t, n)) = r {
                        assert!(t.is_finite() && n.is_finite() && t >= t0 && t <= t1, "{prim:?} {o:?} {d:?}");
                    }
                    if d == Vec3::ZERO || t0 > t1 || t0.is_nan() {
                        assert!(r.is_none());
                    }
                }
            }
        }
        assert!(intersect(prim, Vec3::NAN, Vec3::X, 0.0, 1.0).is_none());
        assert!(intersect(prim, Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 1.0), 0.0, 1.0).is_none());
    }
    // Plane: parallel rays miss, even in the plane.
    let plane = Primitive::Plane { normal: Vec3::Y, offset: 1.0 };
    assert!(intersect(&plane, Vec3::new(0.0, 1.0, 0.0), Vec3::X, 0.0, f32::INFINITY).is_none());
    assert!(intersect(&plane, Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY).is_none());
    // A capsule with a == b is a sphere.
    let cap = Primitive::Capsule { a: Vec3::ONE, b: Vec3::ONE, radius: 0.5 };
    let (t, n) = intersect(&cap, Vec3::new(1.0, 1.0, -3.0), Vec3::Z, 0.0, f32::INFINITY).unwrap();
    assert!((t - 3.5).abs() < 1e-6 && (n + Vec3::Z).length() < 1e-6);
    // Cylinder: rays along the axis, inside and outside.
    let cyl = prims[4];
    let (t, n) = intersect(&cyl, Vec3::new(0.3, -4.0, 0.2), Vec3::Y, 0.0, f32::INFINITY).unwrap();
    assert!((t - 3.0).abs() < 1e-6 && n == -Vec3::Y);
    assert!(intersect(&cyl, Vec3::new(1.3, -4.0, 0.2), Vec3::Y, 0.0, f32::INFINITY).is_none());
    let (t, n) = intersect(&cyl, Vec3::new(0.3, 0.0, 0.2), -Vec3::Y * 2.0, 0.0, f32::INFINITY).unwrap();
    assert!((t - 0.5).abs() < 1e-6 && n == -Vec3::Y);
}
