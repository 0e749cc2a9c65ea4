//! The portable backend: [`Portable`], its token, and its lane types [`F8`] and [`F8x4`],
//! plain Rust arrays whose every operation is a loop over the lanes (the compiler
//! vectorises them for the baseline target). The twin of every AVX2 lane type: the same
//! IEEE operation lane by lane, so both backends give the same bits.

use std::ops::{Add, Div, Mul, Neg, Sub};

use super::lane::{Lane, Lane8, Lane32, Lane64};
use super::mask::{Bits8, mul_sub8};

/// The portable backend's token: always available.
#[derive(Clone, Copy, Debug, Default)]
pub struct Portable;

/// Eight f32 lanes as a plain array (32-byte aligned, so a register file of them can be
/// viewed as any backend's eight-lane type: [`crate::simd::Simd::regs8`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub struct F8(pub [f32; 8]);

/// Four [`F8`] packets run alike (the portable 32 lanes).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(transparent)]
pub struct F8x4(pub [F8; 4]);

impl F8 {
    /// Zero in every lane (storage for register files; needs no token).
    pub const ZERO: F8 = F8([0.0; 8]);

    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> F8 {
        let mut r = [0.0f32; 8];
        for (l, r) in r.iter_mut().enumerate() {
            *r = f(self.0[l]);
        }
        F8(r)
    }
    #[inline(always)]
    fn zip(self, b: F8, f: impl Fn(f32, f32) -> f32) -> F8 {
        let mut r = [0.0f32; 8];
        for (l, r) in r.iter_mut().enumerate() {
            *r = f(self.0[l], b.0[l]);
        }
        F8(r)
    }
}

impl F8x4 {
    /// Zero in every lane (storage for register files; needs no token).
    pub const ZERO: F8x4 = F8x4([F8::ZERO; 4]);
}

macro_rules! binary {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for F8 {
            type Output = F8;
            #[inline(always)]
            fn $f(self, b: F8) -> F8 {
                self.zip(b, |x, y| x $op y)
            }
        }
        impl $tr for F8x4 {
            type Output = F8x4;
            #[inline(always)]
            fn $f(self, b: F8x4) -> F8x4 {
                F8x4([self.0[0] $op b.0[0], self.0[1] $op b.0[1], self.0[2] $op b.0[2], self.0[3] $op b.0[3]])
            }
        }
    };
}
binary!(Add, add, +);
binary!(Sub, sub, -);
binary!(Mul, mul, *);
binary!(Div, div, /);

impl Neg for F8 {
    type Output = F8;
    #[inline(always)]
    fn neg(self) -> F8 {
        self.map(|x| -x)
    }
}

impl Neg for F8x4 {
    type Output = F8x4;
    #[inline(always)]
    fn neg(self) -> F8x4 {
        F8x4(self.0.map(|a| -a))
    }
}

impl Lane for F8 {
    type Token = Portable;
    #[inline(always)]
    fn splat(_: Portable, x: f32) -> Self {
        F8([x; 8])
    }
    #[inline(always)]
    fn vsqrt(self) -> Self {
        self.map(f32::sqrt)
    }
    #[inline(always)]
    fn vabs(self) -> Self {
        self.map(f32::abs)
    }
    #[inline(always)]
    fn vfloor(self) -> Self {
        self.map(f32::floor)
    }
    #[inline(always)]
    fn vmin(self, b: Self) -> Self {
        self.zip(b, |x, y| if x < y { x } else { y })
    }
    #[inline(always)]
    fn vmax(self, b: Self) -> Self {
        self.zip(b, |x, y| if x > y { x } else { y })
    }
    #[inline(always)]
    fn select_lt(a: Self, b: Self, x: Self, y: Self) -> Self {
        let mut r = [0.0f32; 8];
        for (l, r) in r.iter_mut().enumerate() {
            *r = if a.0[l] < b.0[l] { x.0[l] } else { y.0[l] };
        }
        F8(r)
    }
}

impl F8 {
    #[inline(always)]
    fn mask(t: bool) -> f32 {
        f32::from_bits(if t { !0 } else { 0 })
    }
    #[inline(always)]
    fn cmp(self, b: F8, f: impl Fn(f32, f32) -> bool) -> F8 {
        F8(std::array::from_fn(|l| F8::mask(f(self.0[l], b.0[l]))))
    }
    #[inline(always)]
    fn bits(self, b: F8, f: impl Fn(u32, u32) -> u32) -> F8 {
        F8(std::array::from_fn(|l| f32::from_bits(f(self.0[l].to_bits(), b.0[l].to_bits()))))
    }
}

impl Lane8 for F8 {
    type Mask = Bits8;
    #[inline(always)]
    fn store(self) -> [f32; 8] {
        self.0
    }
    #[inline(always)]
    fn mul_sub(self, b: Self, c: Self) -> Self {
        F8(mul_sub8(&self.0, &b.0, &c.0))
    }
    #[inline(always)]
    fn mask_le(self, b: Self) -> Bits8 {
        Bits8((0..8).fold(0, |m, l| m | u32::from(self.0[l] <= b.0[l]) << l))
    }
    #[inline(always)]
    fn mask_eq(self, b: Self) -> Bits8 {
        Bits8((0..8).fold(0, |m, l| m | u32::from(self.0[l] == b.0[l]) << l))
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
    #[inline(always)]
    fn lt_mask(self, b: Self) -> u32 {
        (0..8).fold(0, |m, l| m | ((self.0[l] < b.0[l]) as u32) << l)
    }
    #[inline(always)]
    fn cmp_eq(self, b: Self) -> Self {
        self.cmp(b, |x, y| x == y)
    }
    #[inline(always)]
    fn cmp_lt(self, b: Self) -> Self {
        self.cmp(b, |x, y| x < y)
    }
    #[inline(always)]
    fn cmp_gt(self, b: Self) -> Self {
        self.cmp(b, |x, y| x > y)
    }
    #[inline(always)]
    fn and(self, b: Self) -> Self {
        self.bits(b, |x, y| x & y)
    }
    #[inline(always)]
    fn or(self, b: Self) -> Self {
        self.bits(b, |x, y| x | y)
    }
    #[inline(always)]
    fn andnot(self, b: Self) -> Self {
        self.bits(b, |x, y| !x & y)
    }
    #[inline(always)]
    fn movemask(self) -> u32 {
        (0..8).fold(0, |m, l| m | (self.0[l].to_bits() >> 31) << l)
    }
}

/// Four f64 lanes as a plain array (the portable [`crate::simd::Simd::F64x4`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct D4(pub [f64; 4]);

impl D4 {
    /// Every bit set where `t`, none where not.
    #[inline(always)]
    pub(super) fn mask(t: bool) -> f64 {
        f64::from_bits(if t { !0 } else { 0 })
    }
    #[inline(always)]
    fn zip(self, b: D4, f: impl Fn(f64, f64) -> f64) -> D4 {
        D4(std::array::from_fn(|l| f(self.0[l], b.0[l])))
    }
    #[inline(always)]
    fn cmp(self, b: D4, f: impl Fn(f64, f64) -> bool) -> D4 {
        D4(std::array::from_fn(|l| D4::mask(f(self.0[l], b.0[l]))))
    }
    #[inline(always)]
    fn bits(self, b: D4, f: impl Fn(u64, u64) -> u64) -> D4 {
        D4(std::array::from_fn(|l| f64::from_bits(f(self.0[l].to_bits(), b.0[l].to_bits()))))
    }
}

impl Add for D4 {
    type Output = D4;
    #[inline(always)]
    fn add(self, b: D4) -> D4 {
        self.zip(b, |x, y| x + y)
    }
}
impl Sub for D4 {
    type Output = D4;
    #[inline(always)]
    fn sub(self, b: D4) -> D4 {
        self.zip(b, |x, y| x - y)
    }
}
impl Mul for D4 {
    type Output = D4;
    #[inline(always)]
    fn mul(self, b: D4) -> D4 {
        self.zip(b, |x, y| x * y)
    }
}
impl Div for D4 {
    type Output = D4;
    #[inline(always)]
    fn div(self, b: D4) -> D4 {
        self.zip(b, |x, y| x / y)
    }
}

impl Lane64 for D4 {
    #[inline(always)]
    fn vsqrt(self) -> Self {
        D4(self.0.map(f64::sqrt))
    }
    #[inline(always)]
    fn vmax(self, b: Self) -> Self {
        self.zip(b, |x, y| if x > y { x } else { y })
    }
    #[inline(always)]
    fn cmp_lt(self, b: Self) -> Self {
        self.cmp(b, |x, y| x < y)
    }
    #[inline(always)]
    fn cmp_le(self, b: Self) -> Self {
        self.cmp(b, |x, y| x <= y)
    }
    #[inline(always)]
    fn cmp_gt(self, b: Self) -> Self {
        self.cmp(b, |x, y| x > y)
    }
    #[inline(always)]
    fn cmp_ge(self, b: Self) -> Self {
        self.cmp(b, |x, y| x >= y)
    }
    #[inline(always)]
    fn cmp_eq(self, b: Self) -> Self {
        self.cmp(b, |x, y| x == y)
    }
    #[inline(always)]
    fn and(self, b: Self) -> Self {
        self.bits(b, |x, y| x & y)
    }
    #[inline(always)]
    fn andnot(self, b: Self) -> Self {
        self.bits(b, |x, y| !x & y)
    }
    #[inline(always)]
    fn select(mask: Self, x: Self, y: Self) -> Self {
        D4(std::array::from_fn(|l| if mask.0[l].to_bits() >> 63 == 1 { x.0[l] } else { y.0[l] }))
    }
    #[inline(always)]
    fn movemask(self) -> u32 {
        (0..4).fold(0, |m, l| m | ((self.0[l].to_bits() >> 63) as u32) << l)
    }
    #[inline(always)]
    fn store(self) -> [f64; 4] {
        self.0
    }
    #[inline(always)]
    fn store_at(self, a: &mut [f64], i: usize) {
        a[i..i + 4].copy_from_slice(&self.0);
    }
    #[inline(always)]
    fn to_f32(self) -> [f32; 4] {
        self.0.map(|x| x as f32)
    }
}

impl Lane for F8x4 {
    type Token = Portable;
    #[inline(always)]
    fn splat(s: Portable, x: f32) -> Self {
        F8x4([F8::splat(s, x); 4])
    }
    #[inline(always)]
    fn vsqrt(self) -> Self {
        F8x4(self.0.map(F8::vsqrt))
    }
    #[inline(always)]
    fn vabs(self) -> Self {
        F8x4(self.0.map(F8::vabs))
    }
    #[inline(always)]
    fn vfloor(self) -> Self {
        F8x4(self.0.map(F8::vfloor))
    }
    #[inline(always)]
    fn vmin(self, b: Self) -> Self {
        F8x4(std::array::from_fn(|g| self.0[g].vmin(b.0[g])))
    }
    #[inline(always)]
    fn vmax(self, b: Self) -> Self {
        F8x4(std::array::from_fn(|g| self.0[g].vmax(b.0[g])))
    }
    #[inline(always)]
    fn select_lt(a: Self, b: Self, x: Self, y: Self) -> Self {
        F8x4(std::array::from_fn(|g| F8::select_lt(a.0[g], b.0[g], x.0[g], y.0[g])))
    }
}

impl Lane32 for F8x4 {
    #[inline(always)]
    fn store(self) -> [[f32; 8]; 4] {
        self.0.map(|p| p.0)
    }
}
