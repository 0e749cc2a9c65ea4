//! The lane traits the kernels are written against: [`Lane`] (any number of `f32` lanes
//! evaluated alike, `f32` itself included), [`Lane8`] (eight lanes, one packet) with its
//! [`Mask8`], [`Lane32`] (four packets of eight, the marcher's 32 lanes) and [`Lane64`]
//! (four f64 lanes); the mesh kernels' four-lane type is [`super::Lanes4`].
//!
//! A lane value of a vector backend can only be made through that backend's token
//! ([`Lane::splat`] and the loads of [`crate::simd::Simd`] take one), so a value of an AVX2
//! lane type proves that the CPU has AVX2: that is what makes the safe methods of the AVX2
//! lane types sound.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Sub};

/// A number of f32 lanes evaluated alike: `f32` (one), eight ([`Lane8`]) or 32
/// ([`Lane32`]). Every operation is the same IEEE single-precision operation on every lane,
/// so each lane of a wide computation equals the `f32` computation bit for bit: `min`/`max`/
/// select are the ordered comparisons `a < b` / `a > b` (the second operand where either
/// is NaN), `floor` rounds towards minus infinity, `abs` and negation touch the sign bit
/// only, and there is no fused multiply-add.
pub trait Lane:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    /// What it takes to make a value: the backend's token (`()` for `f32`).
    type Token: Copy;
    /// `x` in every lane.
    fn splat(t: Self::Token, x: f32) -> Self;
    /// Square root (correctly rounded).
    fn vsqrt(self) -> Self;
    /// Absolute value.
    fn vabs(self) -> Self;
    /// Round towards minus infinity.
    fn vfloor(self) -> Self;
    /// `if a < b { a } else { b }`.
    fn vmin(self, b: Self) -> Self;
    /// `if a > b { a } else { b }`.
    fn vmax(self, b: Self) -> Self;
    /// `if a < b { x } else { y }`, lane by lane.
    fn select_lt(a: Self, b: Self, x: Self, y: Self) -> Self;
}

/// Eight f32 lanes (one packet): the one eight-lane type of each backend, for the
/// marcher's packets and the mesh kernels alike. Besides [`Lane`]'s arithmetic, masks in
/// two forms: mask lanes of the type itself (`cmp_*`, `and`, `or`, `movemask`) and the
/// backend's [`Mask8`] (`mask_*`, for the mesh kernels' hit masks).
pub trait Lane8: Lane {
    /// The backend's mask over eight lanes.
    type Mask: Mask8<Lanes = Self>;
    /// The eight lanes.
    fn store(self) -> [f32; 8];
    /// Bit `l` set where lane `l` has `a < b` (false with a NaN).
    fn lt_mask(self, b: Self) -> u32;
    /// Mask lanes (every bit set where true, none where false): `a == b` (false with NaN).
    fn cmp_eq(self, b: Self) -> Self;
    /// Mask lanes: `a < b` (false with a NaN).
    fn cmp_lt(self, b: Self) -> Self;
    /// Mask lanes: `a > b` (false with a NaN).
    fn cmp_gt(self, b: Self) -> Self;
    /// Bitwise and.
    fn and(self, b: Self) -> Self;
    /// Bitwise or.
    fn or(self, b: Self) -> Self;
    /// Bitwise `!self & b`.
    fn andnot(self, b: Self) -> Self;
    /// Bit `l` set where lane `l`'s sign bit is.
    fn movemask(self) -> u32;
    /// Lane-wise `a * b - c`, rounded once: one FMA instruction on AVX2, exact `f64`
    /// arithmetic rounded to odd and then to `f32` on the portable backend (the same bits,
    /// slower). The one fused operation of the lanes.
    fn mul_sub(self, b: Self, c: Self) -> Self;
    /// The lanes where `a <= b` (false with a NaN).
    fn mask_le(self, b: Self) -> Self::Mask;
    /// The lanes where `a == b` (false with a NaN).
    fn mask_eq(self, b: Self) -> Self::Mask;
    /// Per lane, the bits of `x` mapped so that unsigned integer order is the order of the
    /// floats (negative floats have their bits flipped, others their sign bit set).
    fn order_keys(self) -> [u32; 8];
    /// Lane-wise `vmin` of the two halves (lanes 0..4 against 4..8).
    fn min_halves(self) -> [f32; 4];
}

/// A mask over eight lanes of a [`Lane8`] (the mesh kernels' hit masks): bit operations,
/// the lanes as bits, and a select.
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

/// Four f64 lanes. Comparisons give mask lanes (every bit set where true, none where
/// false; ordered, so false with a NaN) as AVX does; arithmetic is IEEE double precision
/// lane by lane, so each lane equals the scalar `f64` computation bit for bit.
pub trait Lane64:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    /// Square root (correctly rounded).
    fn vsqrt(self) -> Self;
    /// `if a > b { a } else { b }`.
    fn vmax(self, b: Self) -> Self;
    /// Mask lanes: `a < b`.
    fn cmp_lt(self, b: Self) -> Self;
    /// Mask lanes: `a <= b`.
    fn cmp_le(self, b: Self) -> Self;
    /// Mask lanes: `a > b`.
    fn cmp_gt(self, b: Self) -> Self;
    /// Mask lanes: `a >= b`.
    fn cmp_ge(self, b: Self) -> Self;
    /// Mask lanes: `a == b`.
    fn cmp_eq(self, b: Self) -> Self;
    /// Bitwise and.
    fn and(self, b: Self) -> Self;
    /// Bitwise `!self & b`.
    fn andnot(self, b: Self) -> Self;
    /// `x` where `mask`'s sign bit is set, else `y`, lane by lane.
    fn select(mask: Self, x: Self, y: Self) -> Self;
    /// Bit `l` set where lane `l`'s sign bit is.
    fn movemask(self) -> u32;
    /// The four lanes.
    fn store(self) -> [f64; 4];
    /// Stores the lanes into `a[i..i + 4]` (panics when out of range).
    fn store_at(self, a: &mut [f64], i: usize);
    /// The four lanes rounded to f32 (to nearest, as `as f32`).
    fn to_f32(self) -> [f32; 4];
}

/// Four packets of eight f32 lanes run alike: each packet's lanes get exactly the
/// operations of a [`Lane8`] evaluation.
pub trait Lane32: Lane {
    /// The four packets.
    fn store(self) -> [[f32; 8]; 4];
}

impl Lane for f32 {
    type Token = ();
    #[inline(always)]
    fn splat(_: (), x: f32) -> Self {
        x
    }
    #[inline(always)]
    fn vsqrt(self) -> Self {
        self.sqrt()
    }
    #[inline(always)]
    fn vabs(self) -> Self {
        self.abs()
    }
    #[inline(always)]
    fn vfloor(self) -> Self {
        self.floor()
    }
    #[inline(always)]
    fn vmin(self, b: Self) -> Self {
        if self < b { self } else { b }
    }
    #[inline(always)]
    fn vmax(self, b: Self) -> Self {
        if self > b { self } else { b }
    }
    #[inline(always)]
    fn select_lt(a: Self, b: Self, x: Self, y: Self) -> Self {
        if a < b { x } else { y }
    }
}
