//! Grids at eight points at once, for packets of marched rays: [`SdfGrid::trilinear8`]
//! (dense) and [`BandGrid::march_distance8`] (narrow band, with its empty-space skipping).
//! Where the CPU has AVX2 ([`crate::simd::avx2`]) the eight points go through one 8-wide
//! kernel that gathers the cells' corner samples; elsewhere (and for grids too large for
//! 32-bit gather offsets) each point goes through the scalar function. Each lane equals
//! the scalar function at that point bit for bit: the kernels perform the same IEEE single
//! precision operations in the same order (no fused multiply-add; `min`/`max` with the
//! operand order of glam's `Vec3::min`/`max`, which is that of `_mm256_min_ps`/`max_ps`),
//! and the tests below and in `tests/integration/grid_packets.rs` compare them.

use glam::Vec3;

use super::SdfGrid;
use super::band::BandGrid;

/// Largest sample count per axis the AVX2 kernels accept (cell coordinates are exact
/// `f32` integers and fit `i32`).
#[cfg(target_arch = "x86_64")]
const MAX_AVX2_DIM: u32 = 1 << 24;

impl SdfGrid {
    /// [`SdfGrid::trilinear`] at the eight points `(xs[l], ys[l], zs[l])`; lane `l` equals
    /// `trilinear` at point `l` bit for bit.
    #[inline]
    pub fn trilinear8(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2().is_some()
            && self.values.len() <= i32::MAX as usize
            && self.dims.max_element() <= MAX_AVX2_DIM
        {
            // SAFETY: the CPU has AVX2 and FMA (checked just above), and every sample index
            // fits the gathers' `i32` offsets.
            return unsafe { avx2::dense(self, xs, ys, zs) };
        }
        self.trilinear8_portable(xs, ys, zs)
    }

    /// [`SdfGrid::trilinear8`] at the points `origin + dir * t[l]` of the eight rays in
    /// lanes `at..at + 8` of `N` (`origin[a][l]` is component `a` of lane `l`; `at + 8 <= N`),
    /// each computed in double precision as `DVec3` does (`o + d * t` per component) and
    /// rounded to single precision; lane `l` of the result equals `trilinear` at the point
    /// of lane `at + l` bit for bit.
    #[inline]
    pub fn trilinear8_rays<const N: usize>(
        &self,
        origin: &[[f64; N]; 3],
        dir: &[[f64; N]; 3],
        t: &[f64; N],
        at: usize,
    ) -> [f32; 8] {
        assert!(at + 8 <= N, "lanes {at}..{} of {N}", at + 8);
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2().is_some()
            && self.values.len() <= i32::MAX as usize
            && self.dims.max_element() <= MAX_AVX2_DIM
        {
            // SAFETY: the CPU has AVX2 and FMA (checked just above), and every sample index
            // fits the gathers' `i32` offsets.
            return unsafe { avx2::dense_rays(self, origin, dir, t, at) };
        }
        let p = |a: usize| -> [f32; 8] {
            std::array::from_fn(|l| (origin[a][at + l] + dir[a][at + l] * t[at + l]) as f32)
        };
        self.trilinear8_portable(&p(0), &p(1), &p(2))
    }

    /// The portable build of [`SdfGrid::trilinear8`]: the scalar function lane by lane.
    pub fn trilinear8_portable(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        std::array::from_fn(|l| self.trilinear(Vec3::new(xs[l], ys[l], zs[l])))
    }
}

impl BandGrid {
    /// [`BandGrid::march_distance`] at the eight points `(xs[l], ys[l], zs[l])`; lane `l`
    /// equals `march_distance` at point `l` bit for bit.
    #[inline]
    pub fn march_distance8(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2().is_some() && self.fits_avx2() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above), and every slot, range
            // and sample index fits the gathers' `i32` offsets.
            return unsafe { avx2::band(self, xs, ys, zs) };
        }
        self.march_distance8_portable(xs, ys, zs)
    }

    /// The portable build of [`BandGrid::march_distance8`]: the scalar function lane by
    /// lane.
    pub fn march_distance8_portable(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        std::array::from_fn(|l| self.march_distance(Vec3::new(xs[l], ys[l], zs[l])))
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    //! The AVX2 kernels: the scalar functions' operations on eight lanes.

    use core::arch::x86_64::*;

    use glam::{UVec3, Vec3};

    use super::super::SdfGrid;
    use super::super::band::{BRICK_SAMPLES, BS, BandGrid, EMPTY};

    /// The lanes of the part both kernels share (see [`SdfGrid::trilinear`]): `d`, the
    /// distance from the point to the box; `f`, the clamped point in cell units; `t`, its
    /// offset in its cell; `cell`, the cell.
    struct Common {
        d: __m256,
        f: [__m256; 3],
        t: [__m256; 3],
        cell: [__m256i; 3],
    }

    #[inline(always)]
    fn splat(x: f32) -> __m256 {
        // SAFETY: AVX is implied by the callers' `avx2` target feature.
        unsafe { _mm256_set1_ps(x) }
    }

    /// `a + (b - a) * t`, rounded after each operation.
    #[inline(always)]
    unsafe fn lerp(a: __m256, b: __m256, t: __m256) -> __m256 {
        unsafe { _mm256_add_ps(a, _mm256_mul_ps(_mm256_sub_ps(b, a), t)) }
    }

    /// `if a < b { a } else { b }`: glam's `min` (operands in this order).
    #[inline(always)]
    unsafe fn min(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_min_ps(a, b) }
    }

    /// `if a > b { a } else { b }`: glam's `max`.
    #[inline(always)]
    unsafe fn max(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_max_ps(a, b) }
    }

    /// The lattice part of [`SdfGrid::trilinear`] for a grid at `origin`, `voxel`, `dims`
    /// whose box is `lo..hi`.
    #[inline(always)]
    unsafe fn common(
        (origin, voxel, dims): (Vec3, f32, UVec3),
        (lo, hi): (Vec3, Vec3),
        p: [__m256; 3],
    ) -> Common {
        unsafe {
            let max_cell = (dims - UVec3::splat(2)).as_vec3();
            let zero = _mm256_setzero_ps();
            let one = splat(1.0);
            // Plain loops, no closures: everything must inline into the AVX2 caller.
            let mut dv = [zero; 3];
            let mut f = [zero; 3];
            let mut t = [zero; 3];
            let mut cell = [_mm256_setzero_si256(); 3];
            for a in 0..3 {
                let q = min(max(p[a], splat(lo[a])), splat(hi[a]));
                dv[a] = _mm256_sub_ps(p[a], q);
                f[a] = _mm256_div_ps(_mm256_sub_ps(q, splat(origin[a])), splat(voxel));
                let c = min(max(_mm256_floor_ps(f[a]), zero), splat(max_cell[a]));
                t[a] = min(max(_mm256_sub_ps(f[a], c), zero), one);
                cell[a] = _mm256_cvttps_epi32(c);
            }
            let dd = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(dv[0], dv[0]), _mm256_mul_ps(dv[1], dv[1])),
                _mm256_mul_ps(dv[2], dv[2]),
            );
            let d = _mm256_sqrt_ps(dd);
            Common { d, f, t, cell }
        }
    }

    /// The sample pairs at `i + o` and `i + o + 1` (x and x + 1) lane by lane, as the two
    /// vectors of first and second samples, in 64-bit gathers of four pairs (half the
    /// element loads of two 32-bit gathers). `idx` holds the lanes' `i` in the order
    /// (0, 1, 4, 5) and (2, 3, 6, 7) ([`pair_order`]), which the two shuffles undo.
    #[inline(always)]
    unsafe fn gather_pairs(v: *const f32, idx: (__m128i, __m128i), o: i32) -> (__m256, __m256) {
        unsafe {
            let off = _mm_set1_epi32(o);
            let p = v as *const i64;
            // lo: the pairs of lanes 0, 1 | 4, 5; hi: of lanes 2, 3 | 6, 7.
            let lo = _mm256_castsi256_ps(_mm256_i32gather_epi64::<4>(p, _mm_add_epi32(idx.0, off)));
            let hi = _mm256_castsi256_ps(_mm256_i32gather_epi64::<4>(p, _mm_add_epi32(idx.1, off)));
            (_mm256_shuffle_ps::<0b10_00_10_00>(lo, hi), _mm256_shuffle_ps::<0b11_01_11_01>(lo, hi))
        }
    }

    /// The eight lanes of `i` as the index halves [`gather_pairs`] takes: lanes
    /// (0, 1, 4, 5) and (2, 3, 6, 7).
    #[inline(always)]
    unsafe fn pair_order(i: __m256i) -> (__m128i, __m128i) {
        unsafe {
            let p = _mm256_permute4x64_epi64::<0b11_01_10_00>(i);
            (_mm256_castsi256_si128(p), _mm256_extracti128_si256::<1>(p))
        }
    }

    /// The 16-bit samples at `base + o` and `base + o + 1` (x and x + 1, always in the same
    /// brick) of the lanes in `mask`, in one 32-bit gather at 2-byte granularity, as `f32`.
    #[inline(always)]
    unsafe fn pair(data: *const i32, base: __m256i, o: i32, mask: __m256i) -> (__m256, __m256) {
        unsafe {
            let w = _mm256_mask_i32gather_epi32::<2>(
                _mm256_setzero_si256(),
                data,
                _mm256_add_epi32(base, _mm256_set1_epi32(o)),
                mask,
            );
            (
                _mm256_cvtepi32_ps(_mm256_and_si256(w, _mm256_set1_epi32(0xffff))),
                _mm256_cvtepi32_ps(_mm256_srli_epi32::<16>(w)),
            )
        }
    }

    /// [`crate::geometry::grid::continue_outside`] lane by lane.
    #[inline(always)]
    unsafe fn continue_outside(v: __m256, d: __m256) -> __m256 {
        unsafe {
            let zero = _mm256_setzero_ps();
            let pos = _mm256_sqrt_ps(_mm256_add_ps(_mm256_mul_ps(d, d), _mm256_mul_ps(v, v)));
            let neg = _mm256_add_ps(v, d);
            let r = _mm256_blendv_ps(neg, pos, _mm256_cmp_ps::<_CMP_GE_OQ>(v, zero));
            _mm256_blendv_ps(r, v, _mm256_cmp_ps::<_CMP_EQ_OQ>(d, zero))
        }
    }

    #[inline(always)]
    fn store(v: __m256) -> [f32; 8] {
        let mut out = [0.0f32; 8];
        // SAFETY: `out` holds eight f32.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), v) };
        out
    }

    /// The eight points `(xs[l], ys[l], zs[l])` as three vectors.
    #[inline(always)]
    unsafe fn load(xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [__m256; 3] {
        unsafe { [_mm256_loadu_ps(xs.as_ptr()), _mm256_loadu_ps(ys.as_ptr()), _mm256_loadu_ps(zs.as_ptr())] }
    }

    /// [`SdfGrid::trilinear8`]'s kernel. The caller checks that the CPU has AVX2 and FMA
    /// and that `g.values.len() <= i32::MAX`.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn dense(g: &SdfGrid, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        unsafe { store(dense_at(g, load(xs, ys, zs))) }
    }

    /// [`SdfGrid::trilinear8_rays`]'s kernel: the points `origin + dir * t` in double
    /// precision (a product and a sum, rounded after each), rounded to single precision,
    /// then [`dense`]'s interpolation, for lanes `at..at + 8` of `N`. The caller checks as
    /// for [`dense`], and that `at + 8 <= N`.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn dense_rays<const N: usize>(
        g: &SdfGrid,
        origin: &[[f64; N]; 3],
        dir: &[[f64; N]; 3],
        t: &[f64; N],
        at: usize,
    ) -> [f32; 8] {
        unsafe {
            let t = t.as_ptr().add(at);
            let (t0, t1) = (_mm256_loadu_pd(t), _mm256_loadu_pd(t.add(4)));
            // A plain loop, no closure: everything must inline into this AVX2 function.
            let mut p = [_mm256_setzero_ps(); 3];
            for a in 0..3 {
                let (o, d) = (origin[a].as_ptr().add(at), dir[a].as_ptr().add(at));
                let lo = _mm256_add_pd(_mm256_loadu_pd(o), _mm256_mul_pd(_mm256_loadu_pd(d), t0));
                let hi =
                    _mm256_add_pd(_mm256_loadu_pd(o.add(4)), _mm256_mul_pd(_mm256_loadu_pd(d.add(4)), t1));
                p[a] = _mm256_set_m128(_mm256_cvtpd_ps(hi), _mm256_cvtpd_ps(lo));
            }
            store(dense_at(g, p))
        }
    }

    /// [`SdfGrid::trilinear`] at the eight points `p` (x, y and z lanes).
    #[inline(always)]
    unsafe fn dense_at(g: &SdfGrid, p: [__m256; 3]) -> __m256 {
        unsafe {
            let Common { d, t, cell, .. } = common((g.origin, g.voxel, g.dims), g.bounds(), p);
            let (sy, sz) = (g.dims.x as i32, (g.dims.x * g.dims.y) as i32);
            let base = _mm256_add_epi32(
                cell[0],
                _mm256_mullo_epi32(
                    _mm256_set1_epi32(sy),
                    _mm256_add_epi32(
                        cell[1],
                        _mm256_mullo_epi32(_mm256_set1_epi32(g.dims.y as i32), cell[2]),
                    ),
                ),
            );
            let v = g.values.as_ptr();
            // Each lane's x and x + 1 samples sit side by side: one 64-bit load per pair.
            let idx = pair_order(base);
            let (a0, a1) = gather_pairs(v, idx, 0);
            let (b0, b1) = gather_pairs(v, idx, sy);
            let (c0, c1) = gather_pairs(v, idx, sz);
            let (e0, e1) = gather_pairs(v, idx, sz + sy);
            let x00 = lerp(a0, a1, t[0]);
            let x10 = lerp(b0, b1, t[0]);
            let x01 = lerp(c0, c1, t[0]);
            let x11 = lerp(e0, e1, t[0]);
            let value = lerp(lerp(x00, x10, t[1]), lerp(x01, x11, t[1]), t[2]);
            // Every point in the box (the usual case of a march clipped to it): the
            // continuation outside leaves each value as it is, so skip its square root.
            if _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(d, _mm256_setzero_ps())) == 0xff {
                return value;
            }
            continue_outside(value, d)
        }
    }

    /// [`BandGrid::march_distance8`]'s kernel. The caller checks that the CPU has AVX2 and
    /// FMA and [`BandGrid::fits_avx2`].
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn band(g: &BandGrid, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        unsafe {
            let Common { d, f, t, cell } = common((g.origin, g.voxel, g.dims), g.bounds(), load(xs, ys, zs));
            let (slots, bounds, ranges, data) = (&g.slots, &g.bounds, &g.ranges, &g.data);
            let brick = [
                _mm256_srli_epi32::<3>(cell[0]),
                _mm256_srli_epi32::<3>(cell[1]),
                _mm256_srli_epi32::<3>(cell[2]),
            ];
            let bi = _mm256_add_epi32(
                brick[0],
                _mm256_mullo_epi32(
                    _mm256_set1_epi32(g.bricks.x as i32),
                    _mm256_add_epi32(
                        brick[1],
                        _mm256_mullo_epi32(_mm256_set1_epi32(g.bricks.y as i32), brick[2]),
                    ),
                ),
            );
            let slot = _mm256_i32gather_epi32::<4>(slots.as_ptr() as *const i32, bi);
            // `EMPTY` is the sign bit.
            let empty = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_setzero_si256(), slot));
            let stored_bits = !_mm256_movemask_ps(empty) & 0xff;
            let zero = _mm256_setzero_ps();
            let mut value = zero;
            if stored_bits != 0 {
                let stored =
                    _mm256_castps_si256(_mm256_xor_ps(empty, _mm256_castsi256_ps(_mm256_set1_epi32(-1))));
                let seven = _mm256_set1_epi32(7);
                let l = [
                    _mm256_and_si256(cell[0], seven),
                    _mm256_and_si256(cell[1], seven),
                    _mm256_and_si256(cell[2], seven),
                ];
                let bs = _mm256_set1_epi32(BS as i32);
                let base = _mm256_add_epi32(
                    _mm256_mullo_epi32(slot, _mm256_set1_epi32(BRICK_SAMPLES as i32)),
                    _mm256_add_epi32(
                        l[0],
                        _mm256_mullo_epi32(bs, _mm256_add_epi32(l[1], _mm256_mullo_epi32(bs, l[2]))),
                    ),
                );
                let rp = ranges.as_ptr() as *const f32;
                let two_slot = _mm256_add_epi32(slot, slot);
                let stored_ps = _mm256_castsi256_ps(stored);
                let offset = _mm256_mask_i32gather_ps::<4>(zero, rp, two_slot, stored_ps);
                let scale = _mm256_mask_i32gather_ps::<4>(
                    zero,
                    rp,
                    _mm256_add_epi32(two_slot, _mm256_set1_epi32(1)),
                    stored_ps,
                );
                let dp = data.as_ptr() as *const i32;
                let (sy, sz) = (BS as i32, (BS * BS) as i32);
                let (a0, a1) = pair(dp, base, 0, stored);
                let (b0, b1) = pair(dp, base, sy, stored);
                let (c0, c1) = pair(dp, base, sz, stored);
                let (e0, e1) = pair(dp, base, sz + sy, stored);
                let x00 = lerp(a0, a1, t[0]);
                let x10 = lerp(b0, b1, t[0]);
                let x01 = lerp(c0, c1, t[0]);
                let x11 = lerp(e0, e1, t[0]);
                let v = lerp(lerp(x00, x10, t[1]), lerp(x01, x11, t[1]), t[2]);
                value = _mm256_add_ps(offset, _mm256_mul_ps(scale, v));
            }
            if stored_bits != 0xff {
                let bound = _mm256_mask_i32gather_ps::<4>(zero, bounds.as_ptr(), bi, empty);
                // `BandGrid::skip_value`.
                let k = _mm256_and_si256(slot, _mm256_set1_epi32(!EMPTY as i32));
                let skips = _mm256_castsi256_ps(_mm256_cmpgt_epi32(k, _mm256_setzero_si256()));
                let km1 = _mm256_sub_epi32(k, _mm256_set1_epi32(1));
                let neg = _mm256_cmp_ps::<_CMP_LT_OQ>(bound, zero);
                let top = (g.dims - UVec3::ONE).as_vec3();
                let mut r = zero;
                for a in 0..3 {
                    let lo = _mm256_cvtepi32_ps(_mm256_slli_epi32::<3>(_mm256_sub_epi32(brick[a], km1)));
                    let hi = _mm256_cvtepi32_ps(_mm256_slli_epi32::<3>(_mm256_add_epi32(brick[a], k)));
                    let lo = _mm256_blendv_ps(lo, max(lo, zero), neg);
                    let hi = _mm256_blendv_ps(hi, min(hi, splat(top[a])), neg);
                    let m = min(_mm256_sub_ps(f[a], lo), _mm256_sub_ps(hi, f[a]));
                    r = if a == 0 { m } else { min(r, m) };
                }
                let s = _mm256_mul_ps(r, splat(g.voxel));
                let sign = splat(-0.0);
                let m = _mm256_andnot_ps(sign, bound);
                let v = max(m, s);
                let v = _mm256_blendv_ps(v, _mm256_xor_ps(v, sign), neg);
                let e = _mm256_blendv_ps(bound, v, skips);
                value = _mm256_blendv_ps(value, e, empty);
            }
            store(continue_outside(value, d))
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    /// A grid of a sphere's distance plus a wobble (so neighbouring lanes see different
    /// cells and values).
    fn grid() -> SdfGrid {
        let mut g = SdfGrid::for_bounds(Vec3::splat(-1.0), Vec3::splat(1.0), 48, 2).unwrap();
        for k in 0..g.dims.z {
            for j in 0..g.dims.y {
                for i in 0..g.dims.x {
                    let p = g.position(i, j, k);
                    let idx = g.index(i, j, k);
                    g.values[idx] = p.length() - 0.5 + 0.01 * (3.0 * p.x).sin();
                }
            }
        }
        g
    }

    /// Deterministic points in and around the box, with exact cell corners and box faces.
    fn points(n: usize) -> Vec<Vec3> {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut v: Vec<Vec3> = (0..n).map(|_| Vec3::new(next(), next(), next()) * 4.0 - 2.0).collect();
        v.extend([Vec3::ZERO, Vec3::splat(-1.2), Vec3::splat(1.2), Vec3::new(1.2, 0.0, -3.0), Vec3::NAN]);
        v
    }

    fn lanes(p: &[Vec3]) -> ([f32; 8], [f32; 8], [f32; 8]) {
        (
            std::array::from_fn(|l| p[l % p.len()].x),
            std::array::from_fn(|l| p[l % p.len()].y),
            std::array::from_fn(|l| p[l % p.len()].z),
        )
    }

    #[test]
    fn dense_lanes_equal_scalar() {
        let g = grid();
        for chunk in points(4000).chunks(8) {
            let (xs, ys, zs) = lanes(chunk);
            let wide = g.trilinear8(&xs, &ys, &zs);
            let portable = g.trilinear8_portable(&xs, &ys, &zs);
            for l in 0..8 {
                let p = Vec3::new(xs[l], ys[l], zs[l]);
                let s = g.trilinear(p);
                assert_eq!(wide[l].to_bits(), s.to_bits(), "{p}: {} vs {s}", wide[l]);
                assert_eq!(portable[l].to_bits(), s.to_bits(), "{p}");
            }
        }
    }

    #[test]
    fn marched_store_equals_the_baseline_build() {
        // `GridStore::march_distance` runs an AVX2 build of the scalar source where it can.
        use super::super::object::GridStore;
        let g = grid();
        let b = BandGrid::from_dense(&g, 2).unwrap();
        let (dense, band) = (GridStore::Dense(g.clone()), GridStore::Band(b.clone()));
        for p in points(2000) {
            assert_eq!(dense.march_distance(p).to_bits(), g.trilinear(p).to_bits(), "{p}");
            assert_eq!(band.march_distance(p).to_bits(), b.march_distance(p).to_bits(), "{p}");
        }
    }

    #[test]
    fn band_lanes_equal_scalar() {
        let g = grid();
        for cells in [1, 2] {
            let b = BandGrid::from_dense(&g, cells).unwrap();
            assert!(b.stored_bricks() > 0 && b.stored_bricks() < b.brick_count());
            let mut skipped = 0;
            for chunk in points(4000).chunks(8) {
                let (xs, ys, zs) = lanes(chunk);
                let wide = b.march_distance8(&xs, &ys, &zs);
                let portable = b.march_distance8_portable(&xs, &ys, &zs);
                for l in 0..8 {
                    let p = Vec3::new(xs[l], ys[l], zs[l]);
                    let s = b.march_distance(p);
                    assert_eq!(wide[l].to_bits(), s.to_bits(), "{p}: {} vs {s}", wide[l]);
                    assert_eq!(portable[l].to_bits(), s.to_bits(), "{p}");
                    skipped += usize::from(s != b.trilinear(p));
                }
            }
            assert!(skipped > 0, "some points skip farther than the bound");
        }
        // A band without stored bricks at all (every lane empty).
        let far =
            BandGrid::from_dense(&SdfGrid { values: vec![5.0; grid().values.len()], ..grid() }, 1).unwrap();
        assert_eq!(far.stored_bricks(), 0);
        let (xs, ys, zs) = lanes(&points(8));
        let wide = far.march_distance8(&xs, &ys, &zs);
        for l in 0..8 {
            let s = far.march_distance(Vec3::new(xs[l], ys[l], zs[l]));
            assert_eq!(wide[l].to_bits(), s.to_bits());
        }
    }
}
