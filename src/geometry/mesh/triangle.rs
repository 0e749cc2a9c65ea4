//! Watertight ray/triangle intersection (Woop, Benthin and Wald 2013): the ray is sheared
//! so it runs along +z, and edge functions are evaluated in 2D with a fallback to f64 when
//! one is exactly zero. Rays through shared edges and vertices of a closed mesh never pass
//! between its triangles. [`ShearedRay::intersect4`] runs the same test on four triangles
//! at once, and [`ShearedRay::intersect8`] on eight (a leaf's two packets), in the lanes of
//! a [`Simd`] backend, with bit-identical results, returning a hit mask and skipping
//! the distances and their division when no lane's edge functions agree in sign. Also the exact closest point on a triangle
//! ([`closest_point_on_triangle`]), for distance queries.

use glam::{DVec3, Vec3, Vec3A};

use crate::simd::{Lane8, Lanes4, Mask8, Simd};

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
        let t = t_scaled / det;
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
    /// [`ShearedRay::intersect`] on the four triangles of `tri` at once, in the four-lane
    /// type of backend `s`: per lane, the hit's `t` (bit-identical to the one-triangle
    /// test), and a mask with bit `l` set where lane `l` hits (the `t` of other lanes is
    /// unspecified). Lanes with an edge function exactly zero in f32 are redone one at a
    /// time in f64, as there. Returns at once, before the distances and their division,
    /// when no lane's edge functions agree in sign (most packets a ray visits).
    #[inline(always)]
    pub fn intersect4<S: Simd>(&self, s: S, tri: &Tri4, t_min: f32, t_max: f32) -> ([f32; 4], u32) {
        let [kx, ky, kz] = self.k;
        let (sx, sy, sz) = (s.splat4f(self.shear.x), s.splat4f(self.shear.y), s.splat4f(self.shear.z));
        let (ox, oy, oz) =
            (s.splat4f(self.origin_k[0]), s.splat4f(self.origin_k[1]), s.splat4f(self.origin_k[2]));
        // Per vertex: sheared x, y and the z offset along the ray's main axis. (Functions
        // marked `#[inline(always)]` rather than closures, which the compiler may leave out
        // of line, where they would not be compiled for the backend's instructions.)
        #[inline(always)]
        fn vertex<L: Lanes4>(row: [L; 3], o: [L; 3], sx: L, sy: L) -> (L, L, L) {
            let z = row[2] - o[2];
            (row[0] - o[0] - sx * z, row[1] - o[1] - sy * z, z)
        }
        let o = [ox, oy, oz];
        let (ax, ay, az) =
            vertex([s.load4f(&tri[0][kx]), s.load4f(&tri[0][ky]), s.load4f(&tri[0][kz])], o, sx, sy);
        let (bx, by, bz) =
            vertex([s.load4f(&tri[1][kx]), s.load4f(&tri[1][ky]), s.load4f(&tri[1][kz])], o, sx, sy);
        let (cx, cy, cz) =
            vertex([s.load4f(&tri[2][kx]), s.load4f(&tri[2][ky]), s.load4f(&tri[2][kz])], o, sx, sy);
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        let zero = s.splat4f(0.0);
        if (u.eq(zero) | v.eq(zero) | w.eq(zero)) != 0 {
            let mut uvw = [u.to_array(), v.to_array(), w.to_array()];
            self.edges_f64(tri, &mut uvw);
            (u, v, w) = (s.load4f(&uvw[0]), s.load4f(&uvw[1]), s.load4f(&uvw[2]));
        }
        // Inside: no edge function of either sign against the others (for numbers, the
        // negation of "some negative and some positive"; NaN lanes, unused or degenerate,
        // are never inside, as their `t` would be NaN).
        let inside = (zero.le(u) & zero.le(v) & zero.le(w)) | (u.le(zero) & v.le(zero) & w.le(zero));
        let det = u + v + w;
        let candidates = inside & !det.eq(zero) & 0xf;
        if candidates == 0 {
            return ([0.0; 4], 0);
        }
        let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
        let t = t_scaled / det;
        let ok = candidates & s.splat4f(t_min).le(t) & t.le(s.splat4f(t_max));
        (t.to_array(), ok)
    }

    /// [`ShearedRay::intersect4`] on two packets at once, `a` in lanes 0..4 and `b` in
    /// lanes 4..8 of the eight-lane type of backend `s`: the same operations in the same
    /// order, so every lane's `t` and hit bit equal the four-lane test's.
    #[inline(always)]
    pub fn intersect8<S: Simd>(&self, s: S, a: &Tri4, b: &Tri4, t_min: f32, t_max: f32) -> ([f32; 8], u32) {
        let (sx, sy, sz) = (s.splat8(self.shear.x), s.splat8(self.shear.y), s.splat8(self.shear.z));
        let (ox, oy, oz) =
            (s.splat8(self.origin_k[0]), s.splat8(self.origin_k[1]), s.splat8(self.origin_k[2]));
        // Per vertex: sheared x, y and the z offset along the ray's main axis.
        #[inline(always)]
        fn vertex<L: Lane8>(row: [L; 3], o: [L; 3], sx: L, sy: L) -> (L, L, L) {
            let z = row[2] - o[2];
            (row[0] - o[0] - sx * z, row[1] - o[1] - sy * z, z)
        }
        let o = [ox, oy, oz];
        let (ax, ay, az) = vertex(rows8(s, a, b, 0, self.k), o, sx, sy);
        let (bx, by, bz) = vertex(rows8(s, a, b, 1, self.k), o, sx, sy);
        let (cx, cy, cz) = vertex(rows8(s, a, b, 2, self.k), o, sx, sy);
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        let zero = s.splat8(0.0);
        if (u.mask_eq(zero) | v.mask_eq(zero) | w.mask_eq(zero)).bits() != 0 {
            let mut uvw = [u.store(), v.store(), w.store()];
            self.edges_f64_8(a, b, &mut uvw);
            (u, v, w) = (s.load8(&uvw[0]), s.load8(&uvw[1]), s.load8(&uvw[2]));
        }
        let inside = (zero.mask_le(u) & zero.mask_le(v) & zero.mask_le(w))
            | (u.mask_le(zero) & v.mask_le(zero) & w.mask_le(zero));
        let det = u + v + w;
        let candidates = inside.and_not(det.mask_eq(zero)).bits();
        if candidates == 0 {
            return ([0.0; 8], 0);
        }
        let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
        let t = t_scaled / det;
        let ok = candidates & (s.splat8(t_min).mask_le(t) & t.mask_le(s.splat8(t_max))).bits();
        (t.store(), ok)
    }

    /// [`ShearedRay::edges_f64`] on the two packets of an eight-lane test (lanes 0..4 of
    /// `uvw` are `a`'s, 4..8 `b`'s).
    #[cold]
    #[inline(never)]
    fn edges_f64_8(&self, a: &Tri4, b: &Tri4, uvw: &mut [[f32; 8]; 3]) {
        for (h, tri) in [a, b].into_iter().enumerate() {
            let mut half = [[0.0f32; 4]; 3];
            for (dst, src) in half.iter_mut().zip(uvw.iter()) {
                dst.copy_from_slice(&src[4 * h..4 * h + 4]);
            }
            self.edges_f64(tri, &mut half);
            for (dst, src) in uvw.iter_mut().zip(half.iter()) {
                dst[4 * h..4 * h + 4].copy_from_slice(src);
            }
        }
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

/// Vertex `v`'s coordinates on the axes `k` (x', y', z' of the sheared frame) of the
/// packets `a` (lanes 0..4) and `b` (lanes 4..8).
#[inline(always)]
fn rows8<S: Simd>(s: S, a: &Tri4, b: &Tri4, v: usize, k: [usize; 3]) -> [S::F32x8; 3] {
    [
        s.halves8(&a[v][k[0]], &b[v][k[0]]),
        s.halves8(&a[v][k[1]], &b[v][k[1]]),
        s.halves8(&a[v][k[2]], &b[v][k[2]]),
    ]
}

/// Twice the area of a triangle, computed in f64.
pub fn double_area(v0: Vec3, v1: Vec3, v2: Vec3) -> f64 {
    let (a, b, c) = (DVec3::from(v0), DVec3::from(v1), DVec3::from(v2));
    (b - a).cross(c - a).length()
}

/// The closest point to `p` on the triangle `a, b, c`: Ericson's region-based method
/// (Real-Time Collision Detection, 5.1.5). The query point is classified against the
/// Voronoi regions of the triangle's corners and edges with dot products; in the face
/// region the point is projected onto the triangle's plane (more accurate in `f32` than
/// Ericson's barycentric form when the point is far from a small triangle).
///
/// The triangle must have non-zero area (the [`crate::mesh::TriangleMesh`] invariant).
#[inline]
pub fn closest_point_on_triangle(p: Vec3A, a: Vec3A, b: Vec3A, c: Vec3A) -> Vec3A {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a; // corner region A
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b; // corner region B
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return a + ab * v; // edge region AB
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c; // corner region C
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return a + ac * w; // edge region AC
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return b + (c - b) * w; // edge region BC
    }
    // Face region: project onto the plane.
    let n = ab.cross(ac);
    p - n * (ap.dot(n) / n.length_squared())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simd::Portable;
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

    /// Packs four triangles into a packet.
    fn packet(tris: &[[Vec3; 3]]) -> Tri4 {
        let mut p = [[[f32::NAN; 4]; 3]; 3];
        for (lane, t) in tris.iter().enumerate() {
            for (v, c) in t.iter().enumerate() {
                for a in 0..3 {
                    p[v][a][lane] = c[a];
                }
            }
        }
        p
    }

    proptest! {
        /// The eight-lane test of two packets gives, lane for lane, the hit bits and the
        /// bits of `t` of the four-lane test on each, on both backends (the AVX2 one where
        /// the CPU has it), also for rays aimed exactly at a corner or an edge (edge
        /// functions exactly zero, redone in f64) and for unused (NaN) lanes.
        #[test]
        fn eight_lane_test_equals_two_four_lane_tests(
            corners in prop::collection::vec(-2.0f32..2.0, 72),
            used in 1usize..=8,
            aim in 0usize..8,
            at in 0usize..4,
            o in prop::array::uniform3(-6.0f32..6.0),
        ) {
            let tris: Vec<[Vec3; 3]> = corners
                .chunks(9)
                .map(|c| [Vec3::new(c[0], c[1], c[2]), Vec3::new(c[3], c[4], c[5]), Vec3::new(c[6], c[7], c[8])])
                .take(used)
                .collect();
            let (a, b) = (packet(&tris[..used.min(4)]), packet(&tris[used.min(4)..]));
            // Aim at a corner (at < 3) or an edge midpoint of one used triangle.
            let t = tris[aim % used];
            let target = if at < 3 { t[at] } else { (t[0] + t[1]) * 0.5 };
            let origin = Vec3::from(o);
            prop_assume!((target - origin).length() > 1e-3);
            let r = ShearedRay::new(origin, (target - origin).normalize());
            let (ta, ma) = r.intersect4(Portable, &a, 0.0, 100.0);
            let (tb, mb) = r.intersect4(Portable, &b, 0.0, 100.0);
            let mut results = vec![r.intersect8(Portable, &a, &b, 0.0, 100.0)];
            if let Some(s) = crate::simd::avx2() {
                results.push(s.vectorize(|| r.intersect8(s, &a, &b, 0.0, 100.0)));
                let (a4, b4) = s.vectorize(|| (r.intersect4(s, &a, 0.0, 100.0), r.intersect4(s, &b, 0.0, 100.0)));
                prop_assert_eq!((a4.1, b4.1), (ma, mb));
                for l in 0..4 {
                    prop_assert!(ma & (1 << l) == 0 || a4.0[l].to_bits() == ta[l].to_bits());
                    prop_assert!(mb & (1 << l) == 0 || b4.0[l].to_bits() == tb[l].to_bits());
                }
            }
            for (t8, m8) in results {
                prop_assert_eq!(m8, ma | mb << 4);
                for l in 0..8 {
                    if m8 & (1 << l) != 0 {
                        let t4 = if l < 4 { ta[l] } else { tb[l - 4] };
                        prop_assert_eq!(t8[l].to_bits(), t4.to_bits());
                    }
                }
            }
        }

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
