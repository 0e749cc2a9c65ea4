//! The lanes of the mesh kernels (the wide BVH's box test, the triangle tests, the
//! closest-point group walk): the [`MeshSimd`] backends, their eight-lane [`Lanes8`] and
//! [`Mask8`] and four-lane [`Lanes4`] types, and [`dispatch_mesh`], which runs a
//! [`MeshKernel`] on the backend selected once by [`super::backend`].
//!
//! A kernel is one `#[inline(always)]` body generic over `S: MeshSimd`; [`dispatch_mesh`]
//! runs it on [`Portable`] or, inlined into a function compiled for AVX2, on
//! [`super::Avx2`], so the whole kernel is compiled for AVX2 there. Lane values are made only through a backend token (its
//! `splat`/`load` methods), so an AVX value exists only after the CPU check that made the
//! token; that, and not inlining, is what makes the safe lane operations below sound.
//! Every operation is IEEE single precision lane by lane (no reassociation, nothing fused
//! but [`Lanes8::mul_sub`]), so both backends give the same bits.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};

use super::f4::{F4, Lanes4};
use super::{Portable, Simd, avx2};

/// A backend of the mesh kernels (an extension of [`Simd`] with the lanes they need): its
/// lane types and how values of them are made.
pub trait MeshSimd: Simd {
    /// Four `f32` lanes.
    type F4: Lanes4;
    /// Eight `f32` lanes.
    type F8: Lanes8<Mask = Self::M8>;
    /// A mask over eight lanes.
    type M8: Mask8<Lanes = Self::F8>;
    /// Four lanes of `x`.
    fn lanes4(self, x: f32) -> Self::F4;
    /// Four lanes loaded from `a`.
    fn load_lanes4(self, a: &[f32; 4]) -> Self::F4;
    /// Eight lanes of `x`.
    fn lanes8(self, x: f32) -> Self::F8;
    /// Eight lanes loaded from `a`.
    fn load_lanes8(self, a: &[f32; 8]) -> Self::F8;
    /// Lanes 0..4 from `lo`, lanes 4..8 from `hi`.
    fn halves8(self, lo: &[f32; 4], hi: &[f32; 4]) -> Self::F8;
    /// `lo` in lanes 0..4, `hi` in lanes 4..8.
    fn splat_halves8(self, lo: f32, hi: f32) -> Self::F8;
    /// `a` in both halves (lanes 0..4 and 4..8).
    fn both8(self, a: &[f32; 4]) -> Self::F8;
}

/// Eight `f32` lanes: arithmetic lane by lane, comparisons to a [`Mask8`].
pub trait Lanes8:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    /// The lane mask of comparisons.
    type Mask: Mask8<Lanes = Self>;
    /// The eight lanes.
    fn to_array(self) -> [f32; 8];
    /// Lane-wise `if a < b { a } else { b }` (`b` where either is NaN).
    fn min(self, b: Self) -> Self;
    /// Lane-wise `if a > b { a } else { b }` (`b` where either is NaN).
    fn max(self, b: Self) -> Self;
    /// Lane-wise square root.
    fn sqrt(self) -> Self;
    /// Lane-wise absolute value (the sign bit cleared).
    fn abs(self) -> Self;
    /// Lane-wise `a * b - c`, rounded once: one FMA instruction on AVX2, exact `f64`
    /// arithmetic rounded to odd and then to `f32` on the portable backend (the same bits,
    /// slower).
    fn mul_sub(self, b: Self, c: Self) -> Self;
    /// Lanes where `a <= b`.
    fn le(self, b: Self) -> Self::Mask;
    /// Lanes where `a == b`.
    fn eq(self, b: Self) -> Self::Mask;
    /// Per lane, the bits of `x` mapped so that unsigned integer order is the order of the
    /// floats (negative floats have their bits flipped, others their sign bit set).
    fn order_keys(self) -> [u32; 8];
    /// Lane-wise minimum of the two halves (lanes 0..4 against 4..8).
    fn min_halves(self) -> [f32; 4];
}

/// A mask over eight lanes of a [`Lanes8`].
pub trait Mask8: Copy + BitAnd<Output = Self> + BitOr<Output = Self> {
    /// The lanes it selects between.
    type Lanes: Copy;
    /// Lanes set in `self` and not in `b`.
    fn and_not(self, b: Self) -> Self;
    /// Bit `l` set where lane `l` is.
    fn bits(self) -> u32;
    /// Per lane, `a` where the mask is set, else `b`.
    fn select(self, a: Self::Lanes, b: Self::Lanes) -> Self::Lanes;
}

/// A kernel generic over the mesh backends, run by [`dispatch_mesh`].
pub trait MeshKernel {
    /// What the kernel returns.
    type Output;
    /// The kernel's body on backend `s` (mark it `#[inline(always)]` with everything it
    /// calls, so that it is compiled for the backend's instructions).
    fn run<S: MeshSimd>(self, s: S) -> Self::Output;
}

/// Runs `kernel` on the backend of this process: AVX2 where [`avx2`] hands out its token
/// (the kernel's body inlined into one function compiled for AVX2, FMA, POPCNT and BMI1),
/// else [`Portable`].
///
/// The body is called from that function directly, not through a closure as
/// [`super::Avx2::vectorize`] takes: a closure is compiled for the features of the function
/// that defines it, and a large one is left out of line, where none of the lane operations
/// it calls would be inlined (measured: a mesh frame seven times slower).
#[inline(always)]
pub fn dispatch_mesh<K: MeshKernel>(kernel: K) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    if let Some(t) = avx2() {
        #[target_feature(enable = "avx2,fma,popcnt,bmi1")]
        fn run<K: MeshKernel>(t: super::Avx2, kernel: K) -> K::Output {
            kernel.run(t)
        }
        // SAFETY: a token exists only after `cpu_has_avx2` found every feature `run` is
        // compiled for.
        return unsafe { run(t, kernel) };
    }
    kernel.run(Portable)
}

/// Eight `f32` lanes as a plain array: the portable backend's [`Lanes8`].
#[derive(Clone, Copy, Debug)]
pub struct Arr8(pub [f32; 8]);

/// A mask over eight portable lanes: bit `l` for lane `l`.
#[derive(Clone, Copy, Debug)]
pub struct Bits8(pub u32);

impl Arr8 {
    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> Arr8 {
        Arr8(self.0.map(f))
    }

    #[inline(always)]
    fn zip(self, b: Arr8, f: impl Fn(f32, f32) -> f32) -> Arr8 {
        Arr8(std::array::from_fn(|l| f(self.0[l], b.0[l])))
    }

    #[inline(always)]
    fn bits(self, b: Arr8, f: impl Fn(f32, f32) -> bool) -> Bits8 {
        Bits8((0..8).fold(0, |m, l| m | (u32::from(f(self.0[l], b.0[l])) << l)))
    }
}

impl MeshSimd for Portable {
    type F4 = F4;
    type F8 = Arr8;
    type M8 = Bits8;
    #[inline(always)]
    fn lanes4(self, x: f32) -> F4 {
        F4([x; 4])
    }
    #[inline(always)]
    fn load_lanes4(self, a: &[f32; 4]) -> F4 {
        F4(*a)
    }
    #[inline(always)]
    fn lanes8(self, x: f32) -> Arr8 {
        Arr8([x; 8])
    }
    #[inline(always)]
    fn load_lanes8(self, a: &[f32; 8]) -> Arr8 {
        Arr8(*a)
    }
    #[inline(always)]
    fn halves8(self, lo: &[f32; 4], hi: &[f32; 4]) -> Arr8 {
        Arr8(std::array::from_fn(|l| if l < 4 { lo[l] } else { hi[l - 4] }))
    }
    #[inline(always)]
    fn splat_halves8(self, lo: f32, hi: f32) -> Arr8 {
        Arr8(std::array::from_fn(|l| if l < 4 { lo } else { hi }))
    }
    #[inline(always)]
    fn both8(self, a: &[f32; 4]) -> Arr8 {
        self.halves8(a, a)
    }
}

impl Lanes8 for Arr8 {
    type Mask = Bits8;
    #[inline(always)]
    fn to_array(self) -> [f32; 8] {
        self.0
    }
    #[inline(always)]
    fn min(self, b: Arr8) -> Arr8 {
        self.zip(b, |x, y| if x < y { x } else { y })
    }
    #[inline(always)]
    fn max(self, b: Arr8) -> Arr8 {
        self.zip(b, |x, y| if x > y { x } else { y })
    }
    #[inline(always)]
    fn sqrt(self) -> Arr8 {
        self.map(f32::sqrt)
    }
    #[inline(always)]
    fn abs(self) -> Arr8 {
        self.map(f32::abs)
    }
    #[inline(always)]
    fn mul_sub(self, b: Arr8, c: Arr8) -> Arr8 {
        // The exact product less `c`, rounded once to `f64`: rounding that to `f32` is the
        // fused result unless it fell exactly on a midpoint between two `f32`s (or below
        // or above their normal range), which the exact (slower) path decides.
        let s: [f64; 8] = std::array::from_fn(|l| self.0[l] as f64 * b.0[l] as f64 - c.0[l] as f64);
        let hard = s.iter().fold(false, |h, &x| {
            let m = x.abs();
            // (NaN, zero and normal `f32` results away from midpoints round alike.)
            h | (x.to_bits() & 0x1fff_ffff == 0x1000_0000) | (m > 0.0 && m < F32_NORMAL) | (m >= F32_TOP)
        });
        if hard {
            return Arr8(std::array::from_fn(|l| mul_sub_rounded_once(self.0[l], b.0[l], c.0[l])));
        }
        Arr8(s.map(|x| x as f32))
    }
    #[inline(always)]
    fn le(self, b: Arr8) -> Bits8 {
        self.bits(b, |x, y| x <= y)
    }
    #[inline(always)]
    fn eq(self, b: Arr8) -> Bits8 {
        self.bits(b, |x, y| x == y)
    }
    #[inline(always)]
    fn order_keys(self) -> [u32; 8] {
        self.0.map(|x| {
            let b = x.to_bits();
            b ^ ((((b as i32) >> 31) as u32) | 0x8000_0000)
        })
    }
    #[inline(always)]
    fn min_halves(self) -> [f32; 4] {
        let a = self.0;
        std::array::from_fn(|l| if a[l] < a[l + 4] { a[l] } else { a[l + 4] })
    }
}

/// The smallest normal `f32`, as `f64`.
const F32_NORMAL: f64 = f32::MIN_POSITIVE as f64;
/// `2^127`: above it an `f64` may round to `f32::MAX` or infinity.
const F32_TOP: f64 = 1.7014118346046923e38;

/// `a * b - c` rounded once to `f32`, as a fused multiply-subtract rounds it, without
/// one: the product is exact in `f64` (24 + 24 bits), the difference is taken in `f64`
/// with its rounding error (Knuth's two-sum) and rounded to odd (the last bit set where
/// the sum was inexact), and a number rounded to odd with 29 bits to spare rounds to the
/// nearest `f32` as the exact one does (Boldo and Melquiond 2008). Infinities and NaN
/// take the plain `f64` path.
#[inline(always)]
fn mul_sub_rounded_once(a: f32, b: f32, c: f32) -> f32 {
    let p = a as f64 * b as f64;
    let m = -(c as f64);
    let s = p + m;
    let v = s - p;
    let err = (p - (s - v)) + (m - v);
    let odd = if s.is_finite() && err != 0.0 && s.to_bits() & 1 == 0 {
        // Away from zero where the error has the sum's sign, else towards it (`s` is not
        // zero: a sum that rounds to zero is exact).
        let away = (err > 0.0) == (s > 0.0);
        f64::from_bits(if away { s.to_bits() + 1 } else { s.to_bits() - 1 })
    } else {
        s
    };
    odd as f32
}

macro_rules! f8_op {
    ($t:ident, $f:ident, $op:tt) => {
        impl $t for Arr8 {
            type Output = Arr8;
            #[inline(always)]
            fn $f(self, b: Arr8) -> Arr8 {
                self.zip(b, |x, y| x $op y)
            }
        }
    };
}
f8_op!(Add, add, +);
f8_op!(Sub, sub, -);
f8_op!(Mul, mul, *);
f8_op!(Div, div, /);

impl BitAnd for Bits8 {
    type Output = Bits8;
    #[inline(always)]
    fn bitand(self, b: Bits8) -> Bits8 {
        Bits8(self.0 & b.0)
    }
}

impl BitOr for Bits8 {
    type Output = Bits8;
    #[inline(always)]
    fn bitor(self, b: Bits8) -> Bits8 {
        Bits8(self.0 | b.0)
    }
}

impl Mask8 for Bits8 {
    type Lanes = Arr8;
    #[inline(always)]
    fn and_not(self, b: Bits8) -> Bits8 {
        Bits8(self.0 & !b.0)
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        self.0
    }
    #[inline(always)]
    fn select(self, a: Arr8, b: Arr8) -> Arr8 {
        Arr8(std::array::from_fn(|l| if self.0 >> l & 1 != 0 { a.0[l] } else { b.0[l] }))
    }
}

#[cfg(target_arch = "x86_64")]
pub use avx::{Avx8, AvxMask8};

#[cfg(target_arch = "x86_64")]
mod avx {
    use super::{Lanes8, Mask8, MeshSimd};
    use crate::simd::Avx2;
    use crate::simd::f4::Sse4;
    use core::arch::x86_64::*;
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};

    // SAFETY (every `unsafe` block of this module, unless it says more): the intrinsics
    // need AVX, AVX2 or FMA. An `Avx8` or `AvxMask8` is only made by a method of an
    // `Avx2` token (its fields are private to `crate::simd`), and a token exists only
    // after `cpu_has_avx2` found AVX2, FMA, POPCNT and BMI1; so wherever one of these
    // values exists, the CPU has every feature used here. The operations are sound
    // wherever they are compiled; `dispatch_mesh` compiles them inline, for speed.

    /// Eight `f32` lanes in one AVX register: the AVX2 backend's [`Lanes8`].
    #[derive(Clone, Copy, Debug)]
    pub struct Avx8(__m256);

    /// A mask over eight AVX lanes (all bits of a lane set, or none).
    #[derive(Clone, Copy, Debug)]
    pub struct AvxMask8(__m256);

    impl MeshSimd for Avx2 {
        type F4 = Sse4;
        type F8 = Avx8;
        type M8 = AvxMask8;
        #[inline(always)]
        fn lanes4(self, x: f32) -> Sse4 {
            Sse4::splat(x)
        }
        #[inline(always)]
        fn load_lanes4(self, a: &[f32; 4]) -> Sse4 {
            Sse4::load(a)
        }
        #[inline(always)]
        fn lanes8(self, x: f32) -> Avx8 {
            // SAFETY: see the module's note (`self` is the token).
            Avx8(unsafe { _mm256_set1_ps(x) })
        }
        #[inline(always)]
        fn load_lanes8(self, a: &[f32; 8]) -> Avx8 {
            // SAFETY: see the module's note; the load reads the 32 bytes of `a`.
            Avx8(unsafe { _mm256_loadu_ps(a.as_ptr()) })
        }
        #[inline(always)]
        fn halves8(self, lo: &[f32; 4], hi: &[f32; 4]) -> Avx8 {
            // SAFETY: see the module's note; the loads read the 16 bytes of `lo` and `hi`.
            Avx8(unsafe { _mm256_set_m128(_mm_loadu_ps(hi.as_ptr()), _mm_loadu_ps(lo.as_ptr())) })
        }
        #[inline(always)]
        fn splat_halves8(self, lo: f32, hi: f32) -> Avx8 {
            // SAFETY: see the module's note.
            Avx8(unsafe { _mm256_set_m128(_mm_set1_ps(hi), _mm_set1_ps(lo)) })
        }
        #[inline(always)]
        fn both8(self, a: &[f32; 4]) -> Avx8 {
            // SAFETY: see the module's note; `[f32; 4]` has the size of `__m128`, and the
            // broadcast reads it unaligned.
            Avx8(unsafe { _mm256_broadcast_ps(&*(a as *const [f32; 4] as *const __m128)) })
        }
    }

    impl Lanes8 for Avx8 {
        type Mask = AvxMask8;
        #[inline(always)]
        fn to_array(self) -> [f32; 8] {
            let mut a = [0.0f32; 8];
            // SAFETY: see the module's note; the store writes the 32 bytes of `a`.
            unsafe { _mm256_storeu_ps(a.as_mut_ptr(), self.0) };
            a
        }
        #[inline(always)]
        fn min(self, b: Avx8) -> Avx8 {
            // SAFETY: see the module's note.
            Avx8(unsafe { _mm256_min_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn max(self, b: Avx8) -> Avx8 {
            // SAFETY: see the module's note.
            Avx8(unsafe { _mm256_max_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn sqrt(self) -> Avx8 {
            // SAFETY: see the module's note.
            Avx8(unsafe { _mm256_sqrt_ps(self.0) })
        }
        #[inline(always)]
        fn abs(self) -> Avx8 {
            // SAFETY: see the module's note.
            Avx8(unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0) })
        }
        #[inline(always)]
        fn mul_sub(self, b: Avx8, c: Avx8) -> Avx8 {
            // SAFETY: see the module's note (FMA).
            Avx8(unsafe { _mm256_fmsub_ps(self.0, b.0, c.0) })
        }
        #[inline(always)]
        fn le(self, b: Avx8) -> AvxMask8 {
            // SAFETY: see the module's note.
            AvxMask8(unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(self.0, b.0) })
        }
        #[inline(always)]
        fn eq(self, b: Avx8) -> AvxMask8 {
            // SAFETY: see the module's note.
            AvxMask8(unsafe { _mm256_cmp_ps::<_CMP_EQ_OQ>(self.0, b.0) })
        }
        #[inline(always)]
        fn order_keys(self) -> [u32; 8] {
            let mut d = [0u32; 8];
            // SAFETY: see the module's note (AVX2); the store writes the 32 bytes of `d`.
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
            // SAFETY: see the module's note; the store writes the 16 bytes of `a`.
            unsafe {
                let m = _mm_min_ps(_mm256_castps256_ps128(self.0), _mm256_extractf128_ps::<1>(self.0));
                _mm_storeu_ps(a.as_mut_ptr(), m);
            }
            a
        }
    }

    macro_rules! avx_op {
        ($t:ident, $f:ident, $intr:ident) => {
            impl $t for Avx8 {
                type Output = Avx8;
                #[inline(always)]
                fn $f(self, b: Avx8) -> Avx8 {
                    // SAFETY: see the module's note.
                    Avx8(unsafe { $intr(self.0, b.0) })
                }
            }
        };
    }
    avx_op!(Add, add, _mm256_add_ps);
    avx_op!(Sub, sub, _mm256_sub_ps);
    avx_op!(Mul, mul, _mm256_mul_ps);
    avx_op!(Div, div, _mm256_div_ps);

    impl BitAnd for AvxMask8 {
        type Output = AvxMask8;
        #[inline(always)]
        fn bitand(self, b: AvxMask8) -> AvxMask8 {
            // SAFETY: see the module's note.
            AvxMask8(unsafe { _mm256_and_ps(self.0, b.0) })
        }
    }

    impl BitOr for AvxMask8 {
        type Output = AvxMask8;
        #[inline(always)]
        fn bitor(self, b: AvxMask8) -> AvxMask8 {
            // SAFETY: see the module's note.
            AvxMask8(unsafe { _mm256_or_ps(self.0, b.0) })
        }
    }

    impl Mask8 for AvxMask8 {
        type Lanes = Avx8;
        #[inline(always)]
        fn and_not(self, b: AvxMask8) -> AvxMask8 {
            // SAFETY: see the module's note.
            AvxMask8(unsafe { _mm256_andnot_ps(b.0, self.0) })
        }
        #[inline(always)]
        fn bits(self) -> u32 {
            // SAFETY: see the module's note.
            unsafe { _mm256_movemask_ps(self.0) as u32 }
        }
        #[inline(always)]
        fn select(self, a: Avx8, b: Avx8) -> Avx8 {
            // SAFETY: see the module's note.
            Avx8(unsafe { _mm256_blendv_ps(b.0, a.0, self.0) })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A kernel that exercises every eight-lane operation and returns the bits.
    struct Every([f32; 8], [f32; 8]);

    impl MeshKernel for Every {
        type Output = Vec<u32>;
        fn run<S: MeshSimd>(self, s: S) -> Vec<u32> {
            let (a, b) = (s.load_lanes8(&self.0), s.load_lanes8(&self.1));
            let c = s.halves8(&[1.0, 2.0, 3.0, 4.0], &[5.0, 6.0, 7.0, 8.0]);
            let mut out = Vec::new();
            for x in [
                a + b,
                a - b,
                a * b,
                a / b,
                a.min(b),
                a.max(b),
                a.sqrt(),
                b.abs(),
                a.mul_sub(b, c),
                a.le(b).select(a, c),
                (a.le(b) | a.eq(c)).select(c, b),
                (a.le(b) & b.le(a)).select(s.lanes8(9.0), b),
                a.le(b).and_not(a.eq(b)).select(a, s.both8(&[0.5, 1.5, 2.5, 3.5])),
                s.splat_halves8(-1.0, 1.0),
            ] {
                // Every NaN alike: its payload is not part of the contract.
                out.extend(x.to_array().map(|v| if v.is_nan() { u32::MAX } else { v.to_bits() }));
            }
            out.extend(a.order_keys());
            out.extend(a.min_halves().map(|v| if v.is_nan() { u32::MAX } else { v.to_bits() }));
            out.push(a.le(b).bits());
            out.push(a.eq(b).bits());
            out
        }
    }

    /// The portable fused multiply-subtract equals `f32::mul_add` (a correctly rounded
    /// fused operation) bit for bit, on products whose exact difference lies near halfway
    /// between two floats and on random ones.
    #[test]
    fn portable_mul_sub_is_rounded_once() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for i in 0..200_000 {
            let r = next();
            let a = f32::from_bits(0x3f80_0000 | (r as u32 & 0x7f_ffff)) * if i % 3 == 0 { 1e4 } else { 1.0 };
            let b = f32::from_bits(0x3f80_0000 | ((r >> 23) as u32 & 0x7f_ffff))
                * if i % 5 == 0 { -1.0 } else { 1.0 };
            // Near the product (cancellation) or a random offset, and the product's own
            // rounding (exact halfway cases after the subtraction).
            let c = match i % 4 {
                0 => a * b,
                1 => (a * b).next_up(),
                2 => f32::from_bits((r >> 40) as u32 & 0x7fff_ffff) % 1e6,
                _ => (a as f64 * b as f64 - 2f64.powi(-30)) as f32,
            };
            let c = if c.is_finite() { c } else { 1.5 };
            let want = a.mul_add(b, -c);
            assert_eq!(mul_sub_rounded_once(a, b, c).to_bits(), want.to_bits(), "{a} * {b} - {c}");
        }
        assert!(mul_sub_rounded_once(f32::INFINITY, 2.0, 1.0).is_infinite());
        assert!(mul_sub_rounded_once(f32::NAN, 2.0, 1.0).is_nan());
    }

    /// The AVX2 lanes give the portable lanes' bits, NaN, zeros and infinities included.
    #[test]
    fn avx2_lanes_equal_portable_lanes() {
        let a = [1.5, -0.0, f32::NAN, 3.0, -2.0, f32::INFINITY, 1e-40, 7.0];
        let b = [1.5, 0.0, 2.0, -7.25, -3.0, 1.0, -1e-40, f32::NAN];
        let portable = Every(a, b).run(Portable);
        assert_eq!(portable[portable.len() - 2], 0b11);
        #[cfg(target_arch = "x86_64")]
        if let Some(t) = crate::simd::avx2() {
            assert_eq!(t.vectorize(|| Every(a, b).run(t)), portable);
        }
        assert_eq!(dispatch_mesh(Every(a, b)), portable);
    }
}
