//! Watertight ray/triangle intersection (Woop, Benthin and Wald 2013): the ray is sheared
//! so it runs along +z, and edge functions are evaluated in 2D with a fallback to f64 when
//! one is exactly zero. Rays through shared edges and vertices of a closed mesh never pass
//! between its triangles. [`ShearedRay::intersect4`] runs the same test on four triangles
//! at once (structure-of-arrays, vectorised by the compiler) with bit-identical results,
//! returning a hit mask and skipping the distances and their division when no lane's edge
//! functions agree in sign.

use std::ops::{Add, Div, Mul, Sub};

use glam::{DVec3, Vec3};

use crate::wide_bvh::F4;

/// Per-ray precomputation of the shear that maps the ray to the +z axis.
#[derive(Clone, Copy, Debug)]
pub struct ShearedRay {
    origin: Vec3,
    /// The origin's coordinates on the axes `k` (x', y', z' of the sheared frame), kept
    /// so that the packet test does not index a `Vec3` (a branch per axis) per call.
    origin_k: [f32; 3],
    /// The axes that become x', y' and z' (each in `0..3`).
    k: [usize; 3],
    shear: Vec3,
}

/// A triangle hit: distance and barycentric weights of vertices 0, 1, 2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriHit {
    /// Ray parameter.
    pub t: f32,
    /// Barycentric weights (sum 1) of the three vertices.
    pub bary: [f32; 3],
}

impl ShearedRay {
    /// Prepares the ray `origin + t * dir` (`dir` nonzero).
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        let a = dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if dir.to_array()[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let (d, o) = (dir.to_array(), origin.to_array());
        let shear = Vec3::new(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]);
        ShearedRay { origin, origin_k: [o[kx], o[ky], o[kz]], k: [kx, ky, kz], shear }
    }

    /// Intersects the triangle (`v0`, `v1`, `v2`), both sides, for `t` in `[t_min, t_max]`.
    #[inline]
    pub fn intersect(&self, v0: Vec3, v1: Vec3, v2: Vec3, t_min: f32, t_max: f32) -> Option<TriHit> {
        let [kx, ky, kz] = self.k;
        let (sx, sy, sz) = (self.shear.x, self.shear.y, self.shear.z);
        let a = v0 - self.origin;
        let b = v1 - self.origin;
        let c = v2 - self.origin;
        let ax = a[kx] - sx * a[kz];
        let ay = a[ky] - sy * a[kz];
        let bx = b[kx] - sx * b[kz];
        let by = b[ky] - sy * b[kz];
        let cx = c[kx] - sx * c[kz];
        let cy = c[ky] - sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            // Exactly on an edge in f32: decide in f64 so neighbours agree.
            let (cx, cy, bx, by, ax, ay) = (cx as f64, cy as f64, bx as f64, by as f64, ax as f64, ay as f64);
            u = (cx * by - cy * bx) as f32;
            v = (ax * cy - ay * cx) as f32;
            w = (bx * ay - by * ax) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let az = sz * a[kz];
        let bz = sz * b[kz];
        let cz = sz * c[kz];
        let t_scaled = u * az + v * bz + w * cz;
        let inv = 1.0 / det;
        let t = t_scaled * inv;
        if !(t >= t_min && t <= t_max) {
            return None;
        }
        Some(TriHit { t, bary: [u * inv, v * inv, w * inv] })
    }
}

/// Four triangles in structure-of-arrays layout: `v[vertex][axis][lane]` (scene units,
/// the mesh's local frame). Unused lanes hold NaN vertices, which never hit.
pub type Tri4 = [[[f32; 4]; 3]; 3];

impl ShearedRay {
    /// [`ShearedRay::intersect`] on the four triangles of `tri` at once: per lane, the hit's
    /// `t` (bit-identical to the one-triangle test), and a mask with bit `l` set where lane
    /// `l` hits (the `t` of other lanes is unspecified). Lanes with an edge function exactly
    /// zero in f32 are redone one at a time in f64, as there. Returns at once, before the
    /// distances and their division, when no lane's edge functions agree in sign (most
    /// packets a ray visits).
    #[inline(always)]
    pub fn intersect4(&self, tri: &Tri4, t_min: f32, t_max: f32) -> ([f32; 4], u32) {
        let [kx, ky, kz] = self.k;
        let (sx, sy, sz) = (F4::splat(self.shear.x), F4::splat(self.shear.y), F4::splat(self.shear.z));
        let (ox, oy, oz) =
            (F4::splat(self.origin_k[0]), F4::splat(self.origin_k[1]), F4::splat(self.origin_k[2]));
        // Per vertex: sheared x, y and the z offset along the ray's main axis.
        let vertex = |v: &[[f32; 4]; 3]| {
            let z = F4::load(&v[kz]).sub(oz);
            (F4::load(&v[kx]).sub(ox).sub(sx.mul(z)), F4::load(&v[ky]).sub(oy).sub(sy.mul(z)), z)
        };
        let (ax, ay, az) = vertex(&tri[0]);
        let (bx, by, bz) = vertex(&tri[1]);
        let (cx, cy, cz) = vertex(&tri[2]);
        let mut u = cx.mul(by).sub(cy.mul(bx));
        let mut v = ax.mul(cy).sub(ay.mul(cx));
        let mut w = bx.mul(ay).sub(by.mul(ax));
        let zero = F4::splat(0.0);
        if (u.eq(zero) | v.eq(zero) | w.eq(zero)) != 0 {
            let mut uvw = [u.to_array(), v.to_array(), w.to_array()];
            self.edges_f64(tri, &mut uvw);
            (u, v, w) = (F4::load(&uvw[0]), F4::load(&uvw[1]), F4::load(&uvw[2]));
        }
        // Inside: no edge function of either sign against the others (for numbers, the
        // negation of "some negative and some positive"; NaN lanes, unused or degenerate,
        // are never inside, as their `t` would be NaN).
        let inside = (zero.le(u) & zero.le(v) & zero.le(w)) | (u.le(zero) & v.le(zero) & w.le(zero));
        let det = u.add(v).add(w);
        let candidates = inside & !det.eq(zero) & 0xf;
        if candidates == 0 {
            return ([0.0; 4], 0);
        }
        let t_scaled = u.mul(sz.mul(az)).add(v.mul(sz.mul(bz))).add(w.mul(sz.mul(cz)));
        let t = t_scaled.mul(F4::splat(1.0).div(det));
        let ok = candidates & F4::splat(t_min).le(t) & t.le(F4::splat(t_max));
        (t.to_array(), ok)
    }

    /// The edge functions of the lanes of `tri` where one is exactly zero in f32, redone
    /// in f64 (the rare path of [`ShearedRay::intersect4`]).
    #[cold]
    #[inline(never)]
    fn edges_f64(&self, tri: &Tri4, uvw: &mut [[f32; 4]; 3]) {
        let [kx, ky, kz] = self.k;
        for l in 0..4 {
            if uvw[0][l] != 0.0 && uvw[1][l] != 0.0 && uvw[2][l] != 0.0 {
                continue;
            }
            let (sx, sy) = (self.shear.x, self.shear.y);
            let o = self.origin;
            let p = |i: usize| Vec3::new(tri[i][0][l], tri[i][1][l], tri[i][2][l]) - o;
            let (a, b, c) = (p(0), p(1), p(2));
            let ax = (a[kx] - sx * a[kz]) as f64;
            let ay = (a[ky] - sy * a[kz]) as f64;
            let bx = (b[kx] - sx * b[kz]) as f64;
            let by = (b[ky] - sy * b[kz]) as f64;
            let cx = (c[kx] - sx * c[kz]) as f64;
            let cy = (c[ky] - sy * c[kz]) as f64;
            uvw[0][l] = (cx * by - cy * bx) as f32;
            uvw[1][l] = (ax * cy - ay * cx) as f32;
            uvw[2][l] = (bx * ay - by * ax) as f32;
        }
    }
}

/// Twice the area of a triangle, computed in f64.
pub fn double_area(v0: Vec3, v1: Vec3, v2: Vec3) -> f64 {
    let (a, b, c) = (DVec3::from(v0), DVec3::from(v1), DVec3::from(v2));
    (b - a).cross(c - a).length()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn hits_centre_and_reports_barycentrics() {
        let r = ShearedRay::new(Vec3::new(0.25, 0.25, -1.0), Vec3::Z);
        let h = r.intersect(Vec3::ZERO, Vec3::X, Vec3::Y, 0.0, 10.0).unwrap();
        assert!((h.t - 1.0).abs() < 1e-6);
        assert!((h.bary[0] - 0.5).abs() < 1e-6 && (h.bary[1] - 0.25).abs() < 1e-6);
        // Both sides.
        let r = ShearedRay::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z);
        assert!(r.intersect(Vec3::ZERO, Vec3::X, Vec3::Y, 0.0, 10.0).is_some());
        // Ray parallel to the triangle's plane.
        let r = ShearedRay::new(Vec3::new(-1.0, 0.25, 0.0), Vec3::X);
        assert!(r.intersect(Vec3::ZERO, Vec3::X, Vec3::Y, 0.0, 10.0).is_none());
    }

    proptest! {
        /// Rays aimed exactly at the shared diagonal or the shared vertices of a quad split
        /// into two triangles (in a random plane, seen from either side) hit at least one.
        #[test]
        fn shared_edges_and_vertices_are_watertight(
            ox in -5.0f32..5.0, oy in -5.0f32..5.0, oz in 1.0f32..5.0, s in 0.0f32..=1.0,
            tilt in -1.0f32..1.0, spin in 0.0f32..std::f32::consts::TAU, side in prop::bool::ANY,
        ) {
            let rot = glam::Quat::from_rotation_y(spin) * glam::Quat::from_rotation_x(tilt);
            let corner = |x: f32, y: f32| rot * Vec3::new(x, y, 0.0) + Vec3::new(0.1, -0.2, 0.3);
            let (p, q) = (corner(-1.3, -0.9), corner(1.1, 1.2));
            let (a, b) = (corner(1.2, -1.0), corner(-1.0, 1.4));
            let target = p + (q - p) * s;
            let origin = Vec3::new(ox, oy, if side { oz } else { -oz });
            let r = ShearedRay::new(origin, (target - origin).normalize());
            let h1 = r.intersect(p, a, q, 0.0, 100.0).is_some();
            let h2 = r.intersect(q, b, p, 0.0, 100.0).is_some();
            prop_assert!(h1 || h2);
        }
    }
}
