//! Four `f32` lanes for the mesh tracer's one-packet triangle test: [`F4`], a plain array
//! (the portable backend), and [`Sse4`], one SSE register (the AVX2 backend's, VEX-encoded
//! inside its kernels). Both implement [`Lanes4`] with IEEE single precision lane by lane,
//! so their results equal the scalar ones bit for bit. A kernel gets them from its backend
//! ([`super::Simd::splat4f`], [`super::Simd::load4f`]).

use std::ops::{Add, Div, Mul, Sub};

/// Four `f32` lanes: arithmetic lane by lane, comparisons to a bit mask (bit `l` for lane
/// `l`).
pub trait Lanes4:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    /// The four lanes.
    fn to_array(self) -> [f32; 4];
    /// Lane-wise `if a < b { a } else { b }` (`b` where either is NaN).
    fn min(self, b: Self) -> Self;
    /// Lane-wise `if a > b { a } else { b }` (`b` where either is NaN).
    fn max(self, b: Self) -> Self;
    /// Bit `l` set where lane `l` has `a <= b`.
    fn le(self, b: Self) -> u32;
    /// Bit `l` set where lane `l` has `a < b`.
    fn lt(self, b: Self) -> u32;
    /// Bit `l` set where lane `l` has `a == b`.
    fn eq(self, b: Self) -> u32;
}

/// Four `f32` lanes as a plain array: the portable backend's [`Lanes4`].
#[derive(Clone, Copy, Debug)]
pub struct F4(pub [f32; 4]);

impl F4 {
    #[inline(always)]
    fn zip(self, b: F4, f: impl Fn(f32, f32) -> f32) -> F4 {
        F4(std::array::from_fn(|l| f(self.0[l], b.0[l])))
    }

    #[inline(always)]
    fn bits(self, b: F4, f: impl Fn(f32, f32) -> bool) -> u32 {
        (0..4).fold(0, |m, l| m | (u32::from(f(self.0[l], b.0[l])) << l))
    }
}

impl Lanes4 for F4 {
    #[inline(always)]
    fn to_array(self) -> [f32; 4] {
        self.0
    }
    #[inline(always)]
    fn min(self, b: F4) -> F4 {
        self.zip(b, |x, y| if x < y { x } else { y })
    }
    #[inline(always)]
    fn max(self, b: F4) -> F4 {
        self.zip(b, |x, y| if x > y { x } else { y })
    }
    #[inline(always)]
    fn le(self, b: F4) -> u32 {
        self.bits(b, |x, y| x <= y)
    }
    #[inline(always)]
    fn lt(self, b: F4) -> u32 {
        self.bits(b, |x, y| x < y)
    }
    #[inline(always)]
    fn eq(self, b: F4) -> u32 {
        self.bits(b, |x, y| x == y)
    }
}

macro_rules! f4_op {
    ($t:ident, $f:ident, $op:tt) => {
        impl $t for F4 {
            type Output = F4;
            #[inline(always)]
            fn $f(self, b: F4) -> F4 {
                self.zip(b, |x, y| x $op y)
            }
        }
    };
}
f4_op!(Add, add, +);
f4_op!(Sub, sub, -);
f4_op!(Mul, mul, *);
f4_op!(Div, div, /);

#[cfg(target_arch = "x86_64")]
pub use sse::Sse4;

#[cfg(target_arch = "x86_64")]
mod sse {
    use super::Lanes4;
    use core::arch::x86_64::*;
    use std::ops::{Add, Div, Mul, Sub};

    /// Four `f32` lanes in one SSE register: the AVX2 backend's [`Lanes4`]. SSE and SSE2
    /// are part of the x86_64 baseline, so every operation is sound on any x86_64 CPU; the
    /// AVX2 backend's kernels compile them VEX-encoded.
    #[derive(Clone, Copy, Debug)]
    pub struct Sse4(pub(in crate::simd) __m128);

    impl Sse4 {
        /// Loads four lanes.
        #[inline(always)]
        pub(in crate::simd) fn load(a: &[f32; 4]) -> Sse4 {
            // SAFETY: SSE is part of the x86_64 baseline; the load reads the 16 bytes of `a`.
            Sse4(unsafe { _mm_loadu_ps(a.as_ptr()) })
        }
        /// The same value in every lane.
        #[inline(always)]
        pub(in crate::simd) fn splat(x: f32) -> Sse4 {
            // SAFETY: SSE is part of the x86_64 baseline.
            Sse4(unsafe { _mm_set1_ps(x) })
        }
    }

    impl Lanes4 for Sse4 {
        #[inline(always)]
        fn to_array(self) -> [f32; 4] {
            let mut a = [0.0f32; 4];
            // SAFETY: SSE is part of the x86_64 baseline; the store writes the 16 bytes of `a`.
            unsafe { _mm_storeu_ps(a.as_mut_ptr(), self.0) };
            a
        }
        #[inline(always)]
        fn min(self, b: Sse4) -> Sse4 {
            // SAFETY: SSE is part of the x86_64 baseline.
            Sse4(unsafe { _mm_min_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn max(self, b: Sse4) -> Sse4 {
            // SAFETY: SSE is part of the x86_64 baseline.
            Sse4(unsafe { _mm_max_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn le(self, b: Sse4) -> u32 {
            // SAFETY: SSE is part of the x86_64 baseline.
            unsafe { _mm_movemask_ps(_mm_cmple_ps(self.0, b.0)) as u32 }
        }
        #[inline(always)]
        fn lt(self, b: Sse4) -> u32 {
            // SAFETY: SSE is part of the x86_64 baseline.
            unsafe { _mm_movemask_ps(_mm_cmplt_ps(self.0, b.0)) as u32 }
        }
        #[inline(always)]
        fn eq(self, b: Sse4) -> u32 {
            // SAFETY: SSE is part of the x86_64 baseline.
            unsafe { _mm_movemask_ps(_mm_cmpeq_ps(self.0, b.0)) as u32 }
        }
    }

    macro_rules! sse_op {
        ($t:ident, $f:ident, $intr:ident) => {
            impl $t for Sse4 {
                type Output = Sse4;
                #[inline(always)]
                fn $f(self, b: Sse4) -> Sse4 {
                    // SAFETY: SSE is part of the x86_64 baseline.
                    Sse4(unsafe { $intr(self.0, b.0) })
                }
            }
        };
    }
    sse_op!(Add, add, _mm_add_ps);
    sse_op!(Sub, sub, _mm_sub_ps);
    sse_op!(Mul, mul, _mm_mul_ps);
    sse_op!(Div, div, _mm_div_ps);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both four-lane types give the scalar results, NaN lanes included (as NaN).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn sse_lanes_equal_portable_lanes() {
        let a = [1.5, -0.0, f32::NAN, 3.0];
        let b = [1.5, 0.0, 2.0, -7.25];
        let (pa, pb) = (F4(a), F4(b));
        let (sa, sb) = (Sse4::load(&a), Sse4::load(&b));
        // Bits, with every NaN alike (a NaN's payload is not part of the contract: the
        // compiler folds constants to another NaN than the CPU computes).
        let bits = |x: [f32; 4]| x.map(|v| if v.is_nan() { u32::MAX } else { v.to_bits() });
        assert_eq!(bits((pa + pb).to_array()), bits((sa + sb).to_array()));
        assert_eq!(bits((pa - pb).to_array()), bits((sa - sb).to_array()));
        assert_eq!(bits((pa * pb).to_array()), bits((sa * sb).to_array()));
        assert_eq!(bits((pa / pb).to_array()), bits((sa / sb).to_array()));
        assert_eq!(bits(pa.min(pb).to_array()), bits(sa.min(sb).to_array()));
        assert_eq!(bits(pa.max(pb).to_array()), bits(sa.max(sb).to_array()));
        assert_eq!((pa.le(pb), pa.lt(pb), pa.eq(pb)), (sa.le(sb), sa.lt(sb), sa.eq(sb)));
        assert_eq!((pa.le(pb), pa.lt(pb), pa.eq(pb)), (0b0011, 0b0000, 0b0011));
        assert_eq!(bits(Sse4::splat(2.0).to_array()), bits([2.0; 4]));
    }
}
