//! The portable backend's mask over eight lanes of the mesh kernels' hit tests
//! ([`Bits8`], a [`super::Mask8`]; the AVX2 backend's is [`super::AvxMask8`]) and its fused
//! multiply-subtract ([`super::Lane8::mul_sub`]), rounded once as an FMA rounds it.

use std::ops::{BitAnd, BitOr};

use super::lane::Mask8;
use super::portable::F8;

/// A mask over eight portable lanes: bit `l` for lane `l`.
#[derive(Clone, Copy, Debug)]
pub struct Bits8(pub u32);

/// Lane-wise `a * b - c` rounded once (the portable [`super::Lane8::mul_sub`]).
#[inline(always)]
pub(super) fn mul_sub8(a: &[f32; 8], b: &[f32; 8], c: &[f32; 8]) -> [f32; 8] {
    // The exact product less `c`, rounded once to `f64`: rounding that to `f32` is the
    // fused result unless it fell exactly on a midpoint between two `f32`s (or below
    // or above their normal range), which the exact (slower) path decides.
    let s: [f64; 8] = std::array::from_fn(|l| a[l] as f64 * b[l] as f64 - c[l] as f64);
    let hard = s.iter().fold(false, |h, &x| {
        let m = x.abs();
        // (NaN, zero and normal `f32` results away from midpoints round alike.)
        h | (x.to_bits() & 0x1fff_ffff == 0x1000_0000) | (m > 0.0 && m < F32_NORMAL) | (m >= F32_TOP)
    });
    if hard {
        return std::array::from_fn(|l| mul_sub_rounded_once(a[l], b[l], c[l]));
    }
    s.map(|x| x as f32)
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
    type Lanes = F8;
    #[inline(always)]
    fn and_not(self, b: Bits8) -> Bits8 {
        Bits8(self.0 & !b.0)
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        self.0
    }
    #[inline(always)]
    fn select(self, a: F8, b: F8) -> F8 {
        F8(std::array::from_fn(|l| if self.0 >> l & 1 != 0 { a.0[l] } else { b.0[l] }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::simd::{Kernel, Lane, Lane8, Portable, Simd, dispatch};

    /// A kernel that exercises every mask and mesh operation of the eight-lane type and
    /// returns the bits.
    struct Every([f32; 8], [f32; 8]);

    impl Kernel for Every {
        type Output = Vec<u32>;
        #[inline(always)]
        fn run<S: Simd>(self, s: S) -> Vec<u32> {
            let (a, b) = (s.load8(&self.0), s.load8(&self.1));
            let c = s.halves8(&[1.0, 2.0, 3.0, 4.0], &[5.0, 6.0, 7.0, 8.0]);
            let mut out = Vec::new();
            for x in [
                a.vmin(b),
                a.vmax(b),
                a.mul_sub(b, c),
                a.mask_le(b).select(a, c),
                (a.mask_le(b) | a.mask_eq(c)).select(c, b),
                (a.mask_le(b) & b.mask_le(a)).select(s.splat8(9.0), b),
                a.mask_le(b).and_not(a.mask_eq(b)).select(a, s.both8(&[0.5, 1.5, 2.5, 3.5])),
                s.splat_halves8(-1.0, 1.0),
            ] {
                // Every NaN alike: its payload is not part of the contract.
                out.extend(x.store().map(|v| if v.is_nan() { u32::MAX } else { v.to_bits() }));
            }
            out.extend(a.order_keys());
            out.extend(a.min_halves().map(|v| if v.is_nan() { u32::MAX } else { v.to_bits() }));
            out.push(a.mask_le(b).bits());
            out.push(a.mask_eq(b).bits());
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

    /// The AVX2 lanes and masks give the portable ones' bits, NaN, zeros and infinities
    /// included.
    #[test]
    fn avx2_masks_equal_portable_masks() {
        let a = [1.5, -0.0, f32::NAN, 3.0, -2.0, f32::INFINITY, 1e-40, 7.0];
        let b = [1.5, 0.0, 2.0, -7.25, -3.0, 1.0, -1e-40, f32::NAN];
        let portable = Every(a, b).run(Portable);
        assert_eq!(portable[portable.len() - 2], 0b11);
        assert_eq!(dispatch(Every(a, b)), portable);
    }
}
