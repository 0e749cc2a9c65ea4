//! The AVX2 backend's lane types: [`A8`] (eight f32 lanes in a `__m256`), its mask
//! [`AvxMask8`], [`A8x4`] (four of them run alike) and [`A4d`], each operation one
//! intrinsic, and the [`Simd`] implementation of the [`Avx2`] token.
//!
//! Soundness: an `A8` is made only through an [`Avx2`] token (its loads, [`Lane::splat`],
//! [`Simd::regs8`]), and a token exists only after the CPU check found AVX2, FMA, POPCNT
//! and BMI1; so wherever a method of these types runs, the CPU has the instructions its
//! intrinsic needs. Every method is `#[inline(always)]`, so inside a kernel run by
//! [`Avx2::run`] each intrinsic compiles to its one instruction.
//!
//! Bit identity with the portable twin ([`super::F8`]): `minps(a, b)` is `a < b ? a : b`,
//! `maxps(a, b)` is `a > b ? a : b` (the second operand with a NaN, as the twin's
//! comparisons), the select is a blend on the ordered `a < b`, `floor` rounds towards
//! minus infinity, `abs` and negation touch the sign bit only, and nothing is fused.

use core::arch::x86_64::*;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Sub};

use super::Avx2;
use super::Backend;
use super::backend::Simd;
use super::f4::Sse4;
use super::lane::{Lane, Lane8, Lane32, Lane64, Mask8};
use super::portable::{F8, F8x4};

/// Eight f32 lanes in a `__m256` (see the module documentation for why its safe methods
/// are sound).
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct A8(__m256);

/// A mask over eight [`A8`] lanes (all bits of a lane set, or none): the AVX2 backend's
/// [`Mask8`], made only by the comparisons of an [`A8`].
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct AvxMask8(__m256);

/// Four [`A8`]s run alike: four packets with one dispatch per operation. Each packet's
/// lanes get exactly the operations of an [`A8`] evaluation.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct A8x4([A8; 4]);

const _: () = assert!(size_of::<F8>() == size_of::<A8>() && align_of::<F8>() >= align_of::<A8>());
const _: () = assert!(size_of::<F8x4>() == size_of::<A8x4>() && align_of::<F8x4>() >= align_of::<A8x4>());

/// Reinterprets a slice of `T` as a slice of `U`, for the register files of [`Simd`].
///
/// # Safety
/// `T` and `U` must have the same size, `U`'s alignment must not exceed `T`'s, and every
/// bit pattern of `T` must be a valid `U` and the reverse.
#[inline(always)]
unsafe fn view<T, U>(v: &mut [T]) -> &mut [U] {
    // SAFETY: the caller's promise; the lifetime and length carry over unchanged, and the
    // borrow of `v` is held for the result's lifetime.
    unsafe { std::slice::from_raw_parts_mut(v.as_mut_ptr().cast(), v.len()) }
}

impl Simd for Avx2 {
    const BACKEND: Backend = Backend::Avx2;
    type F32x8 = A8;
    type F32x32 = A8x4;
    type F64x4 = A4d;
    type F32x4 = Sse4;

    #[inline(always)]
    fn splat4(self, x: f64) -> A4d {
        // SAFETY: the token proves AVX.
        A4d(unsafe { _mm256_set1_pd(x) })
    }
    #[inline(always)]
    fn load4_at(self, a: &[f64], i: usize) -> A4d {
        let a: &[f64; 4] = a[i..i + 4].try_into().unwrap();
        // SAFETY: the token proves AVX; an unaligned load of the 32 bytes of `a`.
        A4d(unsafe { _mm256_loadu_pd(a.as_ptr()) })
    }
    #[inline(always)]
    fn mask4(self, bits: u32) -> A4d {
        // SAFETY: the token proves AVX2; register operations only.
        A4d(unsafe {
            let b = _mm256_setr_epi64x(1, 2, 4, 8);
            _mm256_castsi256_pd(_mm256_cmpeq_epi64(
                _mm256_and_si256(_mm256_set1_epi64x(i64::from(bits)), b),
                b,
            ))
        })
    }
    #[inline(always)]
    fn u32_masks4(self, v: &[u32], i: usize, limit: i32) -> (A4d, A4d) {
        let v: &[u32; 4] = v[i..i + 4].try_into().unwrap();
        // SAFETY: the token proves AVX2; an unaligned load of the 16 bytes of `v`, then
        // register operations.
        unsafe {
            let x = _mm_loadu_si128(v.as_ptr().cast());
            let zero = _mm256_castsi256_pd(_mm256_cvtepi32_epi64(_mm_cmpeq_epi32(x, _mm_setzero_si128())));
            let below = _mm256_castsi256_pd(_mm256_cvtepi32_epi64(_mm_cmplt_epi32(x, _mm_set1_epi32(limit))));
            (A4d(zero), A4d(below))
        }
    }

    #[inline(always)]
    fn load8(self, a: &[f32; 8]) -> A8 {
        // SAFETY: the token proves AVX; an unaligned load of the 32 bytes of `a`.
        A8(unsafe { _mm256_loadu_ps(a.as_ptr()) })
    }
    #[inline(always)]
    fn bytes8(self, a: &[u8; 8]) -> A8 {
        // SAFETY: the token proves AVX2; an unaligned load of the 8 bytes of `a`, widened
        // to eight 32-bit integers (exact in f32).
        A8(unsafe { _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(a.as_ptr().cast()))) })
    }
    #[inline(always)]
    fn halves8(self, lo: &[f32; 4], hi: &[f32; 4]) -> A8 {
        // SAFETY: the token proves AVX; unaligned loads of the 16 bytes of `lo` and `hi`.
        A8(unsafe { _mm256_set_m128(_mm_loadu_ps(hi.as_ptr()), _mm_loadu_ps(lo.as_ptr())) })
    }
    #[inline(always)]
    fn splat_halves8(self, lo: f32, hi: f32) -> A8 {
        // SAFETY: the token proves AVX.
        A8(unsafe { _mm256_set_m128(_mm_set1_ps(hi), _mm_set1_ps(lo)) })
    }
    #[inline(always)]
    fn both8(self, a: &[f32; 4]) -> A8 {
        // SAFETY: the token proves AVX; `[f32; 4]` has the size of `__m128`, and the
        // broadcast reads it unaligned.
        A8(unsafe { _mm256_broadcast_ps(&*(a as *const [f32; 4] as *const __m128)) })
    }
    #[inline(always)]
    fn splat4f(self, x: f32) -> Sse4 {
        Sse4::splat(x)
    }
    #[inline(always)]
    fn load4f(self, a: &[f32; 4]) -> Sse4 {
        Sse4::load(a)
    }
    #[inline(always)]
    fn load32(self, a: &[[f32; 8]; 4]) -> A8x4 {
        A8x4([self.load8(&a[0]), self.load8(&a[1]), self.load8(&a[2]), self.load8(&a[3])])
    }
    #[inline(always)]
    fn regs8(self, v: &mut [F8]) -> &mut [A8] {
        // SAFETY: `F8` is `repr(C, align(32))` over `[f32; 8]` and `A8` a transparent
        // `__m256`: the same 32 bytes (asserted above), every bit pattern valid for both;
        // the token proves AVX for the `A8`s made.
        unsafe { view(v) }
    }
    #[inline(always)]
    fn regs8x3(self, v: &mut [[F8; 3]]) -> &mut [[A8; 3]] {
        // SAFETY: as in `regs8`, three in a row.
        unsafe { view(v) }
    }
    #[inline(always)]
    fn regs32(self, v: &mut [F8x4]) -> &mut [A8x4] {
        // SAFETY: as in `regs8`, four in a row (`F8x4` and `A8x4` are transparent arrays).
        unsafe { view(v) }
    }
    #[inline(always)]
    fn regs32x3(self, v: &mut [[F8x4; 3]]) -> &mut [[A8x4; 3]] {
        // SAFETY: as in `regs8`, twelve in a row.
        unsafe { view(v) }
    }
}

// SAFETY (every `unsafe` block from here on, unless it says otherwise): an `A8` (and an
// `AvxMask8`, made only from `A8`s) exists only where the CPU has AVX2 and FMA (module
// documentation); the intrinsics only read and write registers.

macro_rules! binary {
    ($tr:ident, $f:ident, $op:ident) => {
        impl $tr for A8 {
            type Output = A8;
            #[inline(always)]
            fn $f(self, b: A8) -> A8 {
                A8(unsafe { $op(self.0, b.0) })
            }
        }
        impl $tr for A8x4 {
            type Output = A8x4;
            #[inline(always)]
            fn $f(self, b: A8x4) -> A8x4 {
                let (a, b) = (self.0, b.0);
                A8x4([$tr::$f(a[0], b[0]), $tr::$f(a[1], b[1]), $tr::$f(a[2], b[2]), $tr::$f(a[3], b[3])])
            }
        }
    };
}
binary!(Add, add, _mm256_add_ps);
binary!(Sub, sub, _mm256_sub_ps);
binary!(Mul, mul, _mm256_mul_ps);
binary!(Div, div, _mm256_div_ps);

impl Neg for A8 {
    type Output = A8;
    #[inline(always)]
    fn neg(self) -> A8 {
        A8(unsafe { _mm256_xor_ps(self.0, _mm256_set1_ps(-0.0)) })
    }
}

impl Lane for A8 {
    type Token = Avx2;
    #[inline(always)]
    fn splat(_: Avx2, x: f32) -> Self {
        // SAFETY: the token proves AVX.
        A8(unsafe { _mm256_set1_ps(x) })
    }
    #[inline(always)]
    fn vsqrt(self) -> Self {
        A8(unsafe { _mm256_sqrt_ps(self.0) })
    }
    #[inline(always)]
    fn vabs(self) -> Self {
        A8(unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0) })
    }
    #[inline(always)]
    fn vfloor(self) -> Self {
        A8(unsafe { _mm256_round_ps::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(self.0) })
    }
    #[inline(always)]
    fn vmin(self, b: Self) -> Self {
        A8(unsafe { _mm256_min_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn vmax(self, b: Self) -> Self {
        A8(unsafe { _mm256_max_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn select_lt(a: Self, b: Self, x: Self, y: Self) -> Self {
        A8(unsafe { _mm256_blendv_ps(y.0, x.0, _mm256_cmp_ps::<_CMP_LT_OQ>(a.0, b.0)) })
    }
}

impl Lane8 for A8 {
    type Mask = AvxMask8;
    #[inline(always)]
    fn mul_sub(self, b: A8, c: A8) -> A8 {
        // (FMA.)
        A8(unsafe { _mm256_fmsub_ps(self.0, b.0, c.0) })
    }
    #[inline(always)]
    fn mask_le(self, b: A8) -> AvxMask8 {
        AvxMask8(unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(self.0, b.0) })
    }
    #[inline(always)]
    fn mask_eq(self, b: A8) -> AvxMask8 {
        AvxMask8(unsafe { _mm256_cmp_ps::<_CMP_EQ_OQ>(self.0, b.0) })
    }
    #[inline(always)]
    fn order_keys(self) -> [u32; 8] {
        let mut d = [0u32; 8];
        // SAFETY: as above (AVX2); an unaligned store into the 32 bytes of `d`.
        unsafe {
            let bits = _mm256_castps_si256(self.0);
            let flip = _mm256_or_si256(_mm256_srai_epi32::<31>(bits), _mm256_set1_epi32(i32::MIN));
            _mm256_storeu_si256(d.as_mut_ptr() as *mut __m256i, _mm256_xor_si256(bits, flip));
        }
        d
    }
    #[inline(always)]
    fn min_halves(self) -> [f32; 4] {
        let mut a = [0.0f32; 4];
        // SAFETY: as above; an unaligned store into the 16 bytes of `a`.
        unsafe {
            let m = _mm_min_ps(_mm256_castps256_ps128(self.0), _mm256_extractf128_ps::<1>(self.0));
            _mm_storeu_ps(a.as_mut_ptr(), m);
        }
        a
    }
    #[inline(always)]
    fn store(self) -> [f32; 8] {
        let mut r = [0.0f32; 8];
        // SAFETY: as above; an unaligned store into the 32 bytes of `r`.
        unsafe { _mm256_storeu_ps(r.as_mut_ptr(), self.0) };
        r
    }
    #[inline(always)]
    fn lt_mask(self, b: Self) -> u32 {
        (unsafe { _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(self.0, b.0)) }) as u32
    }
    #[inline(always)]
    fn cmp_eq(self, b: Self) -> Self {
        A8(unsafe { _mm256_cmp_ps::<_CMP_EQ_OQ>(self.0, b.0) })
    }
    #[inline(always)]
    fn cmp_lt(self, b: Self) -> Self {
        A8(unsafe { _mm256_cmp_ps::<_CMP_LT_OS>(self.0, b.0) })
    }
    #[inline(always)]
    fn cmp_gt(self, b: Self) -> Self {
        A8(unsafe { _mm256_cmp_ps::<_CMP_GT_OS>(self.0, b.0) })
    }
    #[inline(always)]
    fn and(self, b: Self) -> Self {
        A8(unsafe { _mm256_and_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn or(self, b: Self) -> Self {
        A8(unsafe { _mm256_or_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn andnot(self, b: Self) -> Self {
        A8(unsafe { _mm256_andnot_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn movemask(self) -> u32 {
        (unsafe { _mm256_movemask_ps(self.0) }) as u32
    }
}

impl BitAnd for AvxMask8 {
    type Output = AvxMask8;
    #[inline(always)]
    fn bitand(self, b: AvxMask8) -> AvxMask8 {
        AvxMask8(unsafe { _mm256_and_ps(self.0, b.0) })
    }
}

impl BitOr for AvxMask8 {
    type Output = AvxMask8;
    #[inline(always)]
    fn bitor(self, b: AvxMask8) -> AvxMask8 {
        AvxMask8(unsafe { _mm256_or_ps(self.0, b.0) })
    }
}

impl Mask8 for AvxMask8 {
    type Lanes = A8;
    #[inline(always)]
    fn and_not(self, b: AvxMask8) -> AvxMask8 {
        AvxMask8(unsafe { _mm256_andnot_ps(b.0, self.0) })
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        (unsafe { _mm256_movemask_ps(self.0) }) as u32
    }
    #[inline(always)]
    fn select(self, a: A8, b: A8) -> A8 {
        A8(unsafe { _mm256_blendv_ps(b.0, a.0, self.0) })
    }
}

/// Four f64 lanes in a `__m256d` (made only through an [`Avx2`] token, as [`A8`]).
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct A4d(__m256d);

macro_rules! binary_pd {
    ($tr:ident, $f:ident, $op:ident) => {
        impl $tr for A4d {
            type Output = A4d;
            #[inline(always)]
            fn $f(self, b: A4d) -> A4d {
                A4d(unsafe { $op(self.0, b.0) })
            }
        }
    };
}
binary_pd!(Add, add, _mm256_add_pd);
binary_pd!(Sub, sub, _mm256_sub_pd);
binary_pd!(Mul, mul, _mm256_mul_pd);
binary_pd!(Div, div, _mm256_div_pd);

impl Lane64 for A4d {
    #[inline(always)]
    fn vsqrt(self) -> Self {
        A4d(unsafe { _mm256_sqrt_pd(self.0) })
    }
    #[inline(always)]
    fn vmax(self, b: Self) -> Self {
        A4d(unsafe { _mm256_max_pd(self.0, b.0) })
    }
    #[inline(always)]
    fn cmp_lt(self, b: Self) -> Self {
        A4d(unsafe { _mm256_cmp_pd::<_CMP_LT_OQ>(self.0, b.0) })
    }
    #[inline(always)]
    fn cmp_le(self, b: Self) -> Self {
        A4d(unsafe { _mm256_cmp_pd::<_CMP_LE_OQ>(self.0, b.0) })
    }
    #[inline(always)]
    fn cmp_gt(self, b: Self) -> Self {
        A4d(unsafe { _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, b.0) })
    }
    #[inline(always)]
    fn cmp_ge(self, b: Self) -> Self {
        A4d(unsafe { _mm256_cmp_pd::<_CMP_GE_OQ>(self.0, b.0) })
    }
    #[inline(always)]
    fn cmp_eq(self, b: Self) -> Self {
        A4d(unsafe { _mm256_cmp_pd::<_CMP_EQ_OQ>(self.0, b.0) })
    }
    #[inline(always)]
    fn and(self, b: Self) -> Self {
        A4d(unsafe { _mm256_and_pd(self.0, b.0) })
    }
    #[inline(always)]
    fn andnot(self, b: Self) -> Self {
        A4d(unsafe { _mm256_andnot_pd(self.0, b.0) })
    }
    #[inline(always)]
    fn select(mask: Self, x: Self, y: Self) -> Self {
        A4d(unsafe { _mm256_blendv_pd(y.0, x.0, mask.0) })
    }
    #[inline(always)]
    fn movemask(self) -> u32 {
        (unsafe { _mm256_movemask_pd(self.0) }) as u32
    }
    #[inline(always)]
    fn store(self) -> [f64; 4] {
        let mut r = [0.0f64; 4];
        // SAFETY: as above; an unaligned store into the 32 bytes of `r`.
        unsafe { _mm256_storeu_pd(r.as_mut_ptr(), self.0) };
        r
    }
    #[inline(always)]
    fn store_at(self, a: &mut [f64], i: usize) {
        let a: &mut [f64; 4] = (&mut a[i..i + 4]).try_into().unwrap();
        // SAFETY: as above; an unaligned store into the 32 bytes of `a`.
        unsafe { _mm256_storeu_pd(a.as_mut_ptr(), self.0) };
    }
    #[inline(always)]
    fn to_f32(self) -> [f32; 4] {
        let mut r = [0.0f32; 4];
        // SAFETY: as above; `cvtpd_ps` rounds to nearest (the MXCSR default, as `as f32`);
        // an unaligned store into the 16 bytes of `r`.
        unsafe { _mm_storeu_ps(r.as_mut_ptr(), _mm256_cvtpd_ps(self.0)) };
        r
    }
}

/// `$f` of [`A8`] on each packet, written out (a closure would be compiled without AVX,
/// and its intrinsics called rather than inlined).
macro_rules! each {
    ($f:expr, $a:expr) => {
        A8x4([$f($a.0[0]), $f($a.0[1]), $f($a.0[2]), $f($a.0[3])])
    };
    ($f:expr, $a:expr, $b:expr) => {
        A8x4([$f($a.0[0], $b.0[0]), $f($a.0[1], $b.0[1]), $f($a.0[2], $b.0[2]), $f($a.0[3], $b.0[3])])
    };
}

impl Neg for A8x4 {
    type Output = A8x4;
    #[inline(always)]
    fn neg(self) -> A8x4 {
        each!(<A8 as Neg>::neg, self)
    }
}

impl Lane for A8x4 {
    type Token = Avx2;
    #[inline(always)]
    fn splat(s: Avx2, x: f32) -> Self {
        A8x4([A8::splat(s, x); 4])
    }
    #[inline(always)]
    fn vsqrt(self) -> Self {
        each!(A8::vsqrt, self)
    }
    #[inline(always)]
    fn vabs(self) -> Self {
        each!(A8::vabs, self)
    }
    #[inline(always)]
    fn vfloor(self) -> Self {
        each!(A8::vfloor, self)
    }
    #[inline(always)]
    fn vmin(self, b: Self) -> Self {
        each!(A8::vmin, self, b)
    }
    #[inline(always)]
    fn vmax(self, b: Self) -> Self {
        each!(A8::vmax, self, b)
    }
    #[inline(always)]
    fn select_lt(a: Self, b: Self, x: Self, y: Self) -> Self {
        A8x4([
            A8::select_lt(a.0[0], b.0[0], x.0[0], y.0[0]),
            A8::select_lt(a.0[1], b.0[1], x.0[1], y.0[1]),
            A8::select_lt(a.0[2], b.0[2], x.0[2], y.0[2]),
            A8::select_lt(a.0[3], b.0[3], x.0[3], y.0[3]),
        ])
    }
}

impl Lane32 for A8x4 {
    #[inline(always)]
    fn store(self) -> [[f32; 8]; 4] {
        [self.0[0].store(), self.0[1].store(), self.0[2].store(), self.0[3].store()]
    }
}
