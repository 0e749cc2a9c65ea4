//! [`F4`], four `f32` lanes: SSE on x86_64 (part of its baseline), a plain array elsewhere.
//! Used by the mesh tracer's box and triangle tests.

/// Four f32 lanes: SSE on x86_64 (part of its baseline, so the intrinsics are safe to
/// call), a plain array elsewhere. Arithmetic is IEEE single precision lane by lane, so
/// results equal the scalar ones bit for bit.
#[derive(Clone, Copy, Debug)]
pub struct F4(
    #[cfg(target_arch = "x86_64")] core::arch::x86_64::__m128,
    #[cfg(not(target_arch = "x86_64"))] [f32; 4],
);

#[cfg(target_arch = "x86_64")]
mod imp {
    use super::F4;
    use core::arch::x86_64::*;

    // SAFETY (every block below): SSE and SSE2 are part of the x86_64 baseline, so the
    // intrinsics' target features are always present; loads and stores go through
    // references to `[f32; 4]`.

    impl F4 {
        /// Loads four lanes.
        #[inline(always)]
        pub fn load(a: &[f32; 4]) -> F4 {
            F4(unsafe { _mm_loadu_ps(a.as_ptr()) })
        }
        /// The same value in every lane.
        #[inline(always)]
        pub fn splat(x: f32) -> F4 {
            F4(unsafe { _mm_set1_ps(x) })
        }
        /// The four lanes.
        #[inline(always)]
        pub fn to_array(self) -> [f32; 4] {
            let mut a = [0.0f32; 4];
            unsafe { _mm_storeu_ps(a.as_mut_ptr(), self.0) };
            a
        }
        /// Lane-wise `if a < b { a } else { b }` (`b` where either is NaN).
        #[inline(always)]
        pub fn min(self, b: F4) -> F4 {
            F4(unsafe { _mm_min_ps(self.0, b.0) })
        }
        /// Lane-wise `if a > b { a } else { b }` (`b` where either is NaN).
        #[inline(always)]
        pub fn max(self, b: F4) -> F4 {
            F4(unsafe { _mm_max_ps(self.0, b.0) })
        }
        /// Bit `l` set where lane `l` has `a <= b`.
        #[inline(always)]
        pub fn le(self, b: F4) -> u32 {
            unsafe { _mm_movemask_ps(_mm_cmple_ps(self.0, b.0)) as u32 }
        }
        /// Bit `l` set where lane `l` has `a < b`.
        #[inline(always)]
        pub fn lt(self, b: F4) -> u32 {
            unsafe { _mm_movemask_ps(_mm_cmplt_ps(self.0, b.0)) as u32 }
        }
        /// Bit `l` set where lane `l` has `a == b`.
        #[inline(always)]
        pub fn eq(self, b: F4) -> u32 {
            unsafe { _mm_movemask_ps(_mm_cmpeq_ps(self.0, b.0)) as u32 }
        }
    }

    impl std::ops::Add for F4 {
        type Output = F4;
        /// Lane-wise `a + b`.
        #[inline(always)]
        fn add(self, b: F4) -> F4 {
            F4(unsafe { _mm_add_ps(self.0, b.0) })
        }
    }

    impl std::ops::Sub for F4 {
        type Output = F4;
        /// Lane-wise `a - b`.
        #[inline(always)]
        fn sub(self, b: F4) -> F4 {
            F4(unsafe { _mm_sub_ps(self.0, b.0) })
        }
    }

    impl std::ops::Mul for F4 {
        type Output = F4;
        /// Lane-wise `a * b`.
        #[inline(always)]
        fn mul(self, b: F4) -> F4 {
            F4(unsafe { _mm_mul_ps(self.0, b.0) })
        }
    }

    impl std::ops::Div for F4 {
        type Output = F4;
        /// Lane-wise `a / b`.
        #[inline(always)]
        fn div(self, b: F4) -> F4 {
            F4(unsafe { _mm_div_ps(self.0, b.0) })
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
mod imp {
    use super::F4;

    fn zip(a: F4, b: F4, f: impl Fn(f32, f32) -> f32) -> F4 {
        F4([f(a.0[0], b.0[0]), f(a.0[1], b.0[1]), f(a.0[2], b.0[2]), f(a.0[3], b.0[3])])
    }

    fn bits(a: F4, b: F4, f: impl Fn(f32, f32) -> bool) -> u32 {
        (0..4).fold(0, |m, l| m | (u32::from(f(a.0[l], b.0[l])) << l))
    }

    impl F4 {
        /// Loads four lanes.
        #[inline(always)]
        pub fn load(a: &[f32; 4]) -> F4 {
            F4(*a)
        }
        /// The same value in every lane.
        #[inline(always)]
        pub fn splat(x: f32) -> F4 {
            F4([x; 4])
        }
        /// The four lanes.
        #[inline(always)]
        pub fn to_array(self) -> [f32; 4] {
            self.0
        }
        /// Lane-wise `if a < b { a } else { b }` (`b` where either is NaN).
        #[inline(always)]
        pub fn min(self, b: F4) -> F4 {
            zip(self, b, |x, y| if x < y { x } else { y })
        }
        /// Lane-wise `if a > b { a } else { b }` (`b` where either is NaN).
        #[inline(always)]
        pub fn max(self, b: F4) -> F4 {
            zip(self, b, |x, y| if x > y { x } else { y })
        }
        /// Bit `l` set where lane `l` has `a <= b`.
        #[inline(always)]
        pub fn le(self, b: F4) -> u32 {
            bits(self, b, |x, y| x <= y)
        }
        /// Bit `l` set where lane `l` has `a < b`.
        #[inline(always)]
        pub fn lt(self, b: F4) -> u32 {
            bits(self, b, |x, y| x < y)
        }
        /// Bit `l` set where lane `l` has `a == b`.
        #[inline(always)]
        pub fn eq(self, b: F4) -> u32 {
            bits(self, b, |x, y| x == y)
        }
    }

    impl std::ops::Add for F4 {
        type Output = F4;
        /// Lane-wise `a + b`.
        #[inline(always)]
        fn add(self, b: F4) -> F4 {
            zip(self, b, |x, y| x + y)
        }
    }

    impl std::ops::Sub for F4 {
        type Output = F4;
        /// Lane-wise `a - b`.
        #[inline(always)]
        fn sub(self, b: F4) -> F4 {
            zip(self, b, |x, y| x - y)
        }
    }

    impl std::ops::Mul for F4 {
        type Output = F4;
        /// Lane-wise `a * b`.
        #[inline(always)]
        fn mul(self, b: F4) -> F4 {
            zip(self, b, |x, y| x * y)
        }
    }

    impl std::ops::Div for F4 {
        type Output = F4;
        /// Lane-wise `a / b`.
        #[inline(always)]
        fn div(self, b: F4) -> F4 {
            zip(self, b, |x, y| x / y)
        }
    }
}
