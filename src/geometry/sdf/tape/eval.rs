//! The tape interpreter: [`run`], generic over the SIMD layer's lane types (`f32`, eight
//! and 32 lanes), and the kernels [`Eval8`] and [`Eval32`] that run it on the selected
//! backend.

#[allow(unused_imports)]
use super::*;

/// [`Tape::eval8_ops`] as a SIMD kernel.
pub(super) struct Eval8<'a> {
    pub(super) tape: &'a Tape,
    pub(super) ops: Ops<'a>,
    pub(super) xs: &'a [f32; 8],
    pub(super) ys: &'a [f32; 8],
    pub(super) zs: &'a [f32; 8],
    pub(super) scratch: &'a mut TapeScratch,
}

impl Kernel for Eval8<'_> {
    type Output = [f32; 8];
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> [f32; 8] {
        let Eval8 { tape, ops, xs, ys, zs, scratch } = self;
        let p = [s.load8(xs), s.load8(ys), s.load8(zs)];
        let (vals, pts) = (s.regs8(&mut scratch.vals8), s.regs8x3(&mut scratch.pts8));
        run_ops!(ops, &tape.triangles, vals, pts, p, s).store()
    }
}

/// [`Tape::eval32_ops`] as a SIMD kernel.
pub(super) struct Eval32<'a> {
    pub(super) tape: &'a Tape,
    pub(super) ops: Ops<'a>,
    pub(super) xs: &'a X32,
    pub(super) ys: &'a X32,
    pub(super) zs: &'a X32,
    pub(super) scratch: &'a mut TapeScratch,
}

impl Kernel for Eval32<'_> {
    type Output = X32;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> X32 {
        let Eval32 { tape, ops, xs, ys, zs, scratch } = self;
        let p = [s.load32(xs), s.load32(ys), s.load32(zs)];
        let (vals, pts) = (s.regs32(&mut scratch.vals32), s.regs32x3(&mut scratch.pts32));
        run_ops!(ops, &tape.triangles, vals, pts, p, s).store()
    }
}

type P<L> = [L; 3];

#[inline(always)]
fn dot<L: Lane>(a: P<L>, b: P<L>) -> L {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline(always)]
fn sub3<L: Lane>(a: P<L>, b: P<L>) -> P<L> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
fn splat3<L: Lane>(tk: L::Token, v: [f32; 3]) -> P<L> {
    [L::splat(tk, v[0]), L::splat(tk, v[1]), L::splat(tk, v[2])]
}

#[inline(always)]
fn clamp01<L: Lane>(tk: L::Token, x: L) -> L {
    x.vmax(L::splat(tk, 0.0)).vmin(L::splat(tk, 1.0))
}

/// The repetition cell holding `x` (the coordinate in periods) of [`Op::Cells`] and
/// [`Op::CellFace`]: `clamp(floor(x - shift + 0.5) + shift, lo, hi)`.
#[inline(always)]
fn cell_id<L: Lane>(tk: L::Token, x: L, shift: L, lo: L, hi: L) -> L {
    ((x - shift + L::splat(tk, 0.5)).vfloor() + shift).vmax(lo).vmin(hi)
}

/// [`cell_id`] for one value, as the interval bounds of [`super::prune`] need it.
pub(crate) fn cell_index(x: f32, shift: f32, lo: f32, hi: f32) -> f32 {
    cell_id((), x, shift, lo, hi)
}

/// The polynomial smooth minimum of [`crate::geometry::sdf`] (`k` and `1 / k` given).
#[inline(always)]
fn smooth_min<L: Lane>(tk: L::Token, a: L, b: L, k: f32, inv_k: f32) -> L {
    let h = clamp01(tk, L::splat(tk, 0.5) + L::splat(tk, 0.5) * (b - a) * L::splat(tk, inv_k));
    b + (a - b) * h - L::splat(tk, k) * h * (L::splat(tk, 1.0) - h)
}

/// `|v * clamp(v . w / |v|^2, 0, 1) - w|^2`: squared distance from `w` to the segment `v`.
#[inline(always)]
fn segment2<L: Lane>(tk: L::Token, v: [f32; 3], w: P<L>, inv_vv: f32) -> L {
    let v = splat3::<L>(tk, v);
    let h = clamp01(tk, dot(v, w) * L::splat(tk, inv_vv));
    let d = [v[0] * h - w[0], v[1] * h - w[1], v[2] * h - w[2]];
    dot(d, d)
}

/// Row `r` of an affine map applied to `q`. A function rather than a closure in [`run`]:
/// a closure is compiled on its own, without the AVX2 of the function it is inlined into.
#[inline(always)]
fn affine_row<L: Lane>(tk: L::Token, r: [f32; 4], q: P<L>) -> L {
    L::splat(tk, r[0]) * q[0] + L::splat(tk, r[1]) * q[1] + L::splat(tk, r[2]) * q[2] + L::splat(tk, r[3])
}

/// Runs the tape over lanes `L`: the input point in point register 0, the result in value
/// register 0.
#[inline(always)]
pub(super) fn run<'a, L: Lane>(
    ops: impl Iterator<Item = &'a Op>,
    tris: &[TriangleConsts],
    vals: &mut [L],
    pts: &mut [P<L>],
    p: P<L>,
    tk: L::Token,
) -> L {
    pts[0] = p;
    for op in ops {
        match *op {
            Op::Translate { src, dst, t } => {
                let q = pts[src as usize];
                pts[dst as usize] =
                    [q[0] + L::splat(tk, t[0]), q[1] + L::splat(tk, t[1]), q[2] + L::splat(tk, t[2])];
            }
            Op::Affine { src, dst, m } => {
                let q = pts[src as usize];
                pts[dst as usize] =
                    [affine_row(tk, m[0], q), affine_row(tk, m[1], q), affine_row(tk, m[2], q)];
            }
            Op::Sphere { p, t, out, radius, scale } => {
                let q = pts[p as usize];
                let q = [q[0] + L::splat(tk, t[0]), q[1] + L::splat(tk, t[1]), q[2] + L::splat(tk, t[2])];
                vals[out as usize] = (dot(q, q).vsqrt() - L::splat(tk, radius)) * L::splat(tk, scale);
            }
            Op::Plane { p, out, normal, offset, scale } => {
                let q = pts[p as usize];
                vals[out as usize] =
                    (dot(splat3(tk, normal), q) - L::splat(tk, offset)) * L::splat(tk, scale);
            }
            Op::Box { p, out, half, scale } => {
                let q = pts[p as usize];
                let z = L::splat(tk, 0.0);
                let d = [
                    q[0].vabs() - L::splat(tk, half[0]),
                    q[1].vabs() - L::splat(tk, half[1]),
                    q[2].vabs() - L::splat(tk, half[2]),
                ];
                let o = [d[0].vmax(z), d[1].vmax(z), d[2].vmax(z)];
                let inside = d[0].vmax(d[1]).vmax(d[2]).vmin(z);
                vals[out as usize] = (dot(o, o).vsqrt() + inside) * L::splat(tk, scale);
            }
            Op::Ellipsoid { p, out, inv_radii, min_radius, scale } => {
                let q = pts[p as usize];
                let s = [
                    q[0] * L::splat(tk, inv_radii[0]),
                    q[1] * L::splat(tk, inv_radii[1]),
                    q[2] * L::splat(tk, inv_radii[2]),
                ];
                vals[out as usize] =
                    (dot(s, s).vsqrt() - L::splat(tk, 1.0)) * L::splat(tk, min_radius) * L::splat(tk, scale);
            }
            Op::Cylinder { p, out, radius, half_height, scale } => {
                let q = pts[p as usize];
                let z = L::splat(tk, 0.0);
                let dx = (q[0] * q[0] + q[2] * q[2]).vsqrt() - L::splat(tk, radius);
                let dy = q[1].vabs() - L::splat(tk, half_height);
                let (ox, oy) = (dx.vmax(z), dy.vmax(z));
                vals[out as usize] =
                    (dx.vmax(dy).vmin(z) + (ox * ox + oy * oy).vsqrt()) * L::splat(tk, scale);
            }
            Op::Cone { p, out, h, r1, r2, k2, inv_k2k2, scale } => {
                let q = pts[p as usize];
                let z = L::splat(tk, 0.0);
                let (qx, qy) = ((q[0] * q[0] + q[2] * q[2]).vsqrt(), q[1]);
                let (k1x, k1y) = (L::splat(tk, r2), L::splat(tk, h));
                let (k2x, k2y) = (L::splat(tk, k2[0]), L::splat(tk, k2[1]));
                let r = L::select_lt(qy, z, L::splat(tk, r1), L::splat(tk, r2));
                let (cax, cay) = (qx - qx.vmin(r), qy.vabs() - k1y);
                let t = clamp01(tk, ((k1x - qx) * k2x + (k1y - qy) * k2y) * L::splat(tk, inv_k2k2));
                let (cbx, cby) = (qx - k1x + k2x * t, qy - k1y + k2y * t);
                let s = L::select_lt(cbx.vmax(cay), z, L::splat(tk, -1.0), L::splat(tk, 1.0));
                vals[out as usize] =
                    s * (cax * cax + cay * cay).vmin(cbx * cbx + cby * cby).vsqrt() * L::splat(tk, scale);
            }
            Op::Torus { p, out, major, minor, scale } => {
                let q = pts[p as usize];
                let qx = (q[0] * q[0] + q[2] * q[2]).vsqrt() - L::splat(tk, major);
                vals[out as usize] =
                    ((qx * qx + q[1] * q[1]).vsqrt() - L::splat(tk, minor)) * L::splat(tk, scale);
            }
            Op::Triangle { p, out, index, scale } => {
                let t = &tris[index as usize];
                let q = pts[p as usize];
                let pa = sub3(q, splat3(tk, t.a));
                let pb = sub3(q, splat3(tk, t.b));
                let pc = sub3(q, splat3(tk, t.c));
                // Inside the prism over the triangle when the point is on the inner side of
                // all three edge planes (the tree's sum of signs >= 2).
                let s = dot(splat3(tk, t.edge_n[0]), pa)
                    .vmin(dot(splat3(tk, t.edge_n[1]), pb))
                    .vmin(dot(splat3(tk, t.edge_n[2]), pc));
                let np = dot(splat3(tk, t.nor), pa);
                let plane2 = np * np * L::splat(tk, t.inv_nn);
                let edge2 = segment2(tk, t.ba, pa, t.inv_edge2[0])
                    .vmin(segment2(tk, t.cb, pb, t.inv_edge2[1]))
                    .vmin(segment2(tk, t.ac, pc, t.inv_edge2[2]));
                vals[out as usize] =
                    L::select_lt(s, L::splat(tk, 0.0), edge2, plane2).vsqrt() * L::splat(tk, scale);
            }
            Op::Capsule { p, out, a, ba, inv_bb, radius, scale } => {
                let q = pts[p as usize];
                let pa = sub3(q, splat3(tk, a));
                let ba = splat3::<L>(tk, ba);
                let h = clamp01(tk, dot(pa, ba) * L::splat(tk, inv_bb));
                let d = [pa[0] - ba[0] * h, pa[1] - ba[1] * h, pa[2] - ba[2] * h];
                vals[out as usize] = (dot(d, d).vsqrt() - L::splat(tk, radius)) * L::splat(tk, scale);
            }
            Op::Min { out, a, b } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = y.vmin(x);
            }
            Op::Max { out, a, b } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = y.vmax(x);
            }
            Op::Subtract { out, a, b } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = (-y).vmax(x);
            }
            Op::SmoothUnion { out, a, b, k, inv_k } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = smooth_min(tk, x, y, k, inv_k);
            }
            Op::SmoothIntersection { out, a, b, k, inv_k } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = -smooth_min(tk, -x, -y, k, inv_k);
            }
            Op::SmoothSubtraction { out, a, b, k, inv_k } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = -smooth_min(tk, -x, y, k, inv_k);
            }
            Op::Scale { a, s } => {
                vals[a as usize] = vals[a as usize] * L::splat(tk, s);
            }
            Op::Cells { p, axis, base, other, period, inv_period, shift, lo, hi } => {
                let x = pts[p as usize][axis as usize] * L::splat(tk, inv_period);
                let (lo, hi) = (L::splat(tk, lo), L::splat(tk, hi));
                let id = cell_id(tk, x, L::splat(tk, shift), lo, hi);
                let step = L::select_lt(id, x, L::splat(tk, 1.0), L::splat(tk, -1.0));
                let next = (id + step).vmax(lo).vmin(hi);
                vals[base as usize] = id * L::splat(tk, period);
                vals[other as usize] = next * L::splat(tk, period);
            }
            Op::CellFace { p, axis, base, face, period, inv_period, shift, lo, hi, half_gap } => {
                let v = pts[p as usize][axis as usize];
                let x = v * L::splat(tk, inv_period);
                let (lo, hi) = (L::splat(tk, lo), L::splat(tk, hi));
                let id = cell_id(tk, x, L::splat(tk, shift), lo, hi);
                let offset = id * L::splat(tk, period);
                let local = v - offset;
                let inf = L::splat(tk, f32::INFINITY);
                let up = L::select_lt(id, hi, L::splat(tk, half_gap) - local, inf);
                let down = L::select_lt(lo, id, L::splat(tk, half_gap) + local, inf);
                vals[base as usize] = offset;
                vals[face as usize] = down.vmin(up);
            }
            Op::Offset { src, dst, offs } => {
                let q = pts[src as usize];
                let mut r = q;
                for i in 0..3 {
                    if offs[i] != NO_REG {
                        r[i] = q[i] - vals[offs[i] as usize];
                    }
                }
                pts[dst as usize] = r;
            }
            Op::Copy { out, a } => vals[out as usize] = vals[a as usize],
            Op::Neg { out, a } => vals[out as usize] = -vals[a as usize],
        }
    }
    vals[0]
}
