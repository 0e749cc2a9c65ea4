//! The AVX2 kernels of the sampled grids: trilinear interpolation of a dense grid and the
//! marching distance of a narrow band grid at eight points, gathering the cells' corner
//! samples. Their portable twin is the scalar function lane by lane (in the grid's
//! module): these kernels perform the same IEEE single precision operations in the same
//! order (no fused multiply-add; `min`/`max` with the operand order of glam's `Vec3::min`/
//! `max`, which is that of `_mm256_min_ps`/`max_ps`).
//!
//! Soundness of the gathers: the entry points check the layout once per call (sizes of the
//! arrays against the lattice, and each stored brick's slot against the stored arrays)
//! and answer `None` where it does not hold; given that, every gathered index is inside
//! its array because every cell is clamped into the lattice before its index is formed.

use core::arch::x86_64::*;

use super::Avx2;

/// A lattice of samples: position of sample `(0, 0, 0)`, spacing, samples per axis (each
/// at least 2) and the box `lo..hi` (`origin + voxel * (dims - 1)`), as the grids hold them.
#[derive(Clone, Copy, Debug)]
pub struct Lattice {
    /// Position of sample `(0, 0, 0)`.
    pub origin: [f32; 3],
    /// Sample spacing.
    pub voxel: f32,
    /// Samples per axis.
    pub dims: [u32; 3],
    /// Box minimum.
    pub lo: [f32; 3],
    /// Box maximum.
    pub hi: [f32; 3],
}

/// Cells per brick edge of a band grid's layout.
pub const BAND_BRICK: u32 = 8;
/// Samples per brick edge.
pub const BAND_BS: usize = BAND_BRICK as usize + 1;
/// Samples per stored brick.
pub const BAND_BRICK_SAMPLES: usize = BAND_BS * BAND_BS * BAND_BS;
/// The slot bit of an empty brick (the rest is its skip distance).
pub const BAND_EMPTY: u32 = 1 << 31;

/// A narrow band grid's arrays: per brick (x fastest) its slot (or [`BAND_EMPTY`] with a
/// skip distance) and bound; per stored brick its `(offset, scale)` and quantized samples.
#[derive(Clone, Copy, Debug)]
pub struct BandLayout<'a> {
    /// The lattice.
    pub lattice: Lattice,
    /// Bricks per axis.
    pub bricks: [u32; 3],
    /// Per brick: slot or `BAND_EMPTY | skip`.
    pub slots: &'a [u32],
    /// Per brick: the bound of an empty brick.
    pub bounds: &'a [f32],
    /// Per stored brick: `(offset, scale)`.
    pub ranges: &'a [[f32; 2]],
    /// Per stored brick: [`BAND_BRICK_SAMPLES`] samples.
    pub data: &'a [u16],
}

impl Lattice {
    /// Whether the lattice suits the kernels: at least 2 and at most 2^24 samples per axis
    /// and `count` samples, at least as many as the lattice has and at most `i32::MAX`.
    fn fits(&self, count: usize) -> bool {
        let [x, y, z] = self.dims.map(|n| n as usize);
        self.dims.iter().all(|&n| (2..=1 << 24).contains(&n))
            && count <= i32::MAX as usize
            && x.checked_mul(y).and_then(|xy| xy.checked_mul(z)).is_some_and(|n| n <= count)
    }
}

impl BandLayout<'_> {
    /// Whether the arrays suit the band kernel (see the module documentation); the stored
    /// slots are checked per call.
    fn fits(&self) -> bool {
        let [bx, by, bz] = self.bricks.map(|n| n as usize);
        let bricks = bx.checked_mul(by).and_then(|xy| xy.checked_mul(bz));
        let max = i32::MAX as usize;
        self.lattice.dims.iter().all(|&n| (2..=1 << 24).contains(&n))
            && (0..3).all(|a| (self.lattice.dims[a] - 2) / BAND_BRICK < self.bricks[a])
            && bricks.is_some_and(|n| n <= self.slots.len() && n <= self.bounds.len())
            && self.slots.len() <= max
            && self.ranges.len() <= max / 2
            && self.data.len() <= max
    }

    /// How many stored bricks the arrays hold.
    fn stored(&self) -> usize {
        self.ranges.len().min(self.data.len() / BAND_BRICK_SAMPLES)
    }
}

/// The lanes of the part both kernels share (see the scalar trilinear interpolation): `d`, the
/// distance from the point to the box; `f`, the clamped point in cell units; `t`, its
/// offset in its cell; `cell`, the cell.
struct Common {
    d: __m256,
    f: [__m256; 3],
    t: [__m256; 3],
    cell: [__m256i; 3],
}

// SAFETY (the helpers below): each is an `unsafe fn` whose only requirement is that AVX2
// be enabled where it runs; they are called only from the target-feature functions of
// this module, and take and return registers (no memory) unless their note says so.

/// `x` in every lane.
#[inline(always)]
unsafe fn splat(x: f32) -> __m256 {
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

/// The lattice part of the scalar trilinear interpolation for a grid at `origin`, `voxel`, `dims`
/// whose box is `lo..hi`.
#[inline(always)]
unsafe fn common(l: &Lattice, p: [__m256; 3]) -> Common {
    unsafe {
        let (origin, voxel, lo, hi) = (l.origin, l.voxel, l.lo, l.hi);
        let max_cell = l.dims.map(|n| (n - 2) as f32);
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

/// The grid's continuation outside its box lane by lane.
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

/// The eight lanes.
#[inline(always)]
unsafe fn store(v: __m256) -> [f32; 8] {
    let mut out = [0.0f32; 8];
    // SAFETY: AVX is enabled (the caller's promise); `out` holds eight f32.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), v) };
    out
}

impl Avx2 {
    /// Trilinear interpolation of `values` (x fastest) on lattice `l` at the eight points
    /// `p` (x, y and z lanes), continued outside the box as the dense grid does; `None`
    /// when the lattice does not suit the kernel ([`Lattice`]'s sizes).
    #[inline]
    pub fn trilinear8(self, l: &Lattice, values: &[f32], p: [&[f32; 8]; 3]) -> Option<[f32; 8]> {
        if !l.fits(values.len()) {
            return None;
        }
        // SAFETY: the token proves AVX2 and FMA; the lattice fits `values` (checked).
        Some(unsafe { dense(l, values, p) })
    }

    /// [`Avx2::trilinear8`] at the points `origin + dir * t` of lanes `at..at + 8` of `N`,
    /// computed in double precision as `DVec3` does (`o + d * t` per component) and rounded
    /// to single precision. Panics unless `at + 8 <= N`.
    #[inline]
    pub fn trilinear8_rays<const N: usize>(
        self,
        l: &Lattice,
        values: &[f32],
        (origin, dir, t): (&[[f64; N]; 3], &[[f64; N]; 3], &[f64; N]),
        at: usize,
    ) -> Option<[f32; 8]> {
        assert!(at + 8 <= N, "lanes {at}..{} of {N}", at + 8);
        if !l.fits(values.len()) {
            return None;
        }
        // SAFETY: the token proves AVX2 and FMA; the lattice fits `values` (checked);
        // `at + 8 <= N` (asserted).
        Some(unsafe { dense_rays(l, values, origin, dir, t, at) })
    }

    /// The marching distance of band grid `b` at the eight points `p`: the band's samples
    /// in stored bricks, its empty-space skipping value elsewhere, continued outside the
    /// box; `None` when the arrays do not suit the kernel.
    #[inline]
    pub fn band8(self, b: &BandLayout, p: [&[f32; 8]; 3]) -> Option<[f32; 8]> {
        if !b.fits() {
            return None;
        }
        // SAFETY: the token proves AVX2 and FMA; the arrays fit the lattice (checked).
        unsafe { band(b, p) }
    }
}

/// The eight points as three vectors.
///
/// # Safety
/// AVX must be enabled.
#[inline(always)]
unsafe fn load(p: [&[f32; 8]; 3]) -> [__m256; 3] {
    // SAFETY: unaligned loads of 32 bytes each.
    unsafe {
        [_mm256_loadu_ps(p[0].as_ptr()), _mm256_loadu_ps(p[1].as_ptr()), _mm256_loadu_ps(p[2].as_ptr())]
    }
}

/// [`Avx2::trilinear8`]'s kernel.
///
/// # Safety
/// The CPU must have AVX2 and FMA, and `l.fits(values.len())`.
#[target_feature(enable = "avx2,fma")]
unsafe fn dense(l: &Lattice, values: &[f32], p: [&[f32; 8]; 3]) -> [f32; 8] {
    // SAFETY: the caller's promise.
    unsafe { store(dense_at(l, values, load(p))) }
}

/// [`Avx2::trilinear8_rays`]'s kernel.
///
/// # Safety
/// As [`dense`], and `at + 8 <= N`.
#[target_feature(enable = "avx2,fma")]
unsafe fn dense_rays<const N: usize>(
    l: &Lattice,
    values: &[f32],
    origin: &[[f64; N]; 3],
    dir: &[[f64; N]; 3],
    t: &[f64; N],
    at: usize,
) -> [f32; 8] {
    // SAFETY: AVX is enabled; every load is of lanes `at..at + 8` of an `N`-lane array.
    unsafe {
        let t = t.as_ptr().add(at);
        let (t0, t1) = (_mm256_loadu_pd(t), _mm256_loadu_pd(t.add(4)));
        // A plain loop, no closure: everything must inline into this AVX2 function.
        let mut p = [_mm256_setzero_ps(); 3];
        for a in 0..3 {
            let (o, d) = (origin[a].as_ptr().add(at), dir[a].as_ptr().add(at));
            let lo = _mm256_add_pd(_mm256_loadu_pd(o), _mm256_mul_pd(_mm256_loadu_pd(d), t0));
            let hi = _mm256_add_pd(_mm256_loadu_pd(o.add(4)), _mm256_mul_pd(_mm256_loadu_pd(d.add(4)), t1));
            p[a] = _mm256_set_m128(_mm256_cvtpd_ps(hi), _mm256_cvtpd_ps(lo));
        }
        store(dense_at(l, values, p))
    }
}
/// The trilinear interpolation at the eight points `p` (x, y and z lanes).
///
/// # Safety
/// AVX2 must be enabled, and `l.fits(values.len())`: every cell is clamped into the
/// lattice, so every gathered pair lies in `values`.
#[inline(always)]
unsafe fn dense_at(l: &Lattice, values: &[f32], p: [__m256; 3]) -> __m256 {
    unsafe {
        let Common { d, t, cell, .. } = common(l, p);
        let (sy, sz) = (l.dims[0] as i32, (l.dims[0] * l.dims[1]) as i32);
        let base = _mm256_add_epi32(
            cell[0],
            _mm256_mullo_epi32(
                _mm256_set1_epi32(sy),
                _mm256_add_epi32(cell[1], _mm256_mullo_epi32(_mm256_set1_epi32(l.dims[1] as i32), cell[2])),
            ),
        );
        let v = values.as_ptr();
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

/// [`Avx2::band8`]'s kernel; `None` when a stored brick's slot is past the stored arrays.
///
/// # Safety
/// The CPU must have AVX2 and FMA, and `g.fits()`: every cell is clamped into the
/// lattice, so every brick index lies in `slots` and `bounds`; the slots of the lanes
/// that gather samples are checked against [`BandLayout::stored`] first.
#[target_feature(enable = "avx2,fma")]
unsafe fn band(g: &BandLayout, p: [&[f32; 8]; 3]) -> Option<[f32; 8]> {
    unsafe {
        let Common { d, f, t, cell } = common(&g.lattice, load(p));
        let (slots, bounds, ranges, data) = (g.slots, g.bounds, g.ranges, g.data);
        let brick = [
            _mm256_srli_epi32::<3>(cell[0]),
            _mm256_srli_epi32::<3>(cell[1]),
            _mm256_srli_epi32::<3>(cell[2]),
        ];
        let bi = _mm256_add_epi32(
            brick[0],
            _mm256_mullo_epi32(
                _mm256_set1_epi32(g.bricks[0] as i32),
                _mm256_add_epi32(
                    brick[1],
                    _mm256_mullo_epi32(_mm256_set1_epi32(g.bricks[1] as i32), brick[2]),
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
            // Every gathering lane's slot inside the stored arrays (slots of stored bricks
            // are below `BAND_EMPTY`, so positive as `i32`).
            let past =
                _mm256_and_si256(stored, _mm256_cmpgt_epi32(slot, _mm256_set1_epi32(g.stored() as i32 - 1)));
            if _mm256_testz_si256(past, past) == 0 {
                return None;
            }
            let seven = _mm256_set1_epi32(7);
            let l = [
                _mm256_and_si256(cell[0], seven),
                _mm256_and_si256(cell[1], seven),
                _mm256_and_si256(cell[2], seven),
            ];
            let bs = _mm256_set1_epi32(BAND_BS as i32);
            let base = _mm256_add_epi32(
                _mm256_mullo_epi32(slot, _mm256_set1_epi32(BAND_BRICK_SAMPLES as i32)),
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
            let (sy, sz) = (BAND_BS as i32, (BAND_BS * BAND_BS) as i32);
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
            let k = _mm256_and_si256(slot, _mm256_set1_epi32(!BAND_EMPTY as i32));
            let skips = _mm256_castsi256_ps(_mm256_cmpgt_epi32(k, _mm256_setzero_si256()));
            let km1 = _mm256_sub_epi32(k, _mm256_set1_epi32(1));
            let neg = _mm256_cmp_ps::<_CMP_LT_OQ>(bound, zero);
            let top = g.lattice.dims.map(|n| (n - 1) as f32);
            let mut r = zero;
            for a in 0..3 {
                let lo = _mm256_cvtepi32_ps(_mm256_slli_epi32::<3>(_mm256_sub_epi32(brick[a], km1)));
                let hi = _mm256_cvtepi32_ps(_mm256_slli_epi32::<3>(_mm256_add_epi32(brick[a], k)));
                let lo = _mm256_blendv_ps(lo, max(lo, zero), neg);
                let hi = _mm256_blendv_ps(hi, min(hi, splat(top[a])), neg);
                let m = min(_mm256_sub_ps(f[a], lo), _mm256_sub_ps(hi, f[a]));
                r = if a == 0 { m } else { min(r, m) };
            }
            let s = _mm256_mul_ps(r, splat(g.lattice.voxel));
            let sign = splat(-0.0);
            let m = _mm256_andnot_ps(sign, bound);
            let v = max(m, s);
            let v = _mm256_blendv_ps(v, _mm256_xor_ps(v, sign), neg);
            let e = _mm256_blendv_ps(bound, v, skips);
            value = _mm256_blendv_ps(value, e, empty);
        }
        Some(store(continue_outside(value, d)))
    }
}
