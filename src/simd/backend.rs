//! [`Simd`], the trait of the backend tokens ([`Portable`] and [`Avx2`]) that names each
//! backend's lane types and makes their values, and [`dispatch`], the crate's one
//! dispatcher, which runs a [`Kernel`] (the marcher's, the distance fields', the mesh
//! tracer's) on the backend [`super::backend`] selected, compiled for it.

use super::f4::{F4, Lanes4};
use super::lane::{Lane, Lane8, Lane32, Lane64};
use super::portable::D4;
use super::portable::{F8, F8x4, Portable};
use super::{Avx2, Backend};

/// A backend token: proof that its lane types may be used on this CPU. Kernels are generic
/// over it (`fn run<S: Simd>(self, s: S)`); lane values are made only through a token
/// (the loads here, [`Lane::splat`]), so a lane value of a backend exists only where that
/// backend's instructions do.
pub trait Simd: Copy + Send + Sync + 'static {
    /// Which backend this is.
    const BACKEND: Backend;
    /// Eight f32 lanes (one packet).
    type F32x8: Lane8<Token = Self>;
    /// Four packets of eight f32 lanes (the marcher's 32 lanes).
    type F32x32: Lane32<Token = Self>;
    /// Four f64 lanes.
    type F64x4: Lane64;
    /// Four f32 lanes (the mesh tracer's one-packet triangle test).
    type F32x4: Lanes4;

    /// `x` in every lane of a packet.
    #[inline(always)]
    fn splat8(self, x: f32) -> Self::F32x8 {
        Lane::splat(self, x)
    }
    /// `x` in every lane of four f64 lanes.
    fn splat4(self, x: f64) -> Self::F64x4;
    /// Loads `a[i..i + 4]` (panics when out of range).
    fn load4_at(self, a: &[f64], i: usize) -> Self::F64x4;
    /// Mask lanes (every bit set, or none) from the low four bits of `bits`.
    fn mask4(self, bits: u32) -> Self::F64x4;
    /// For `v[i..i + 4]` (panics when out of range), as mask lanes: where the lane is 0,
    /// and where it is below `limit` as a signed 32-bit integer.
    fn u32_masks4(self, v: &[u32], i: usize, limit: i32) -> (Self::F64x4, Self::F64x4);
    /// Loads a packet.
    fn load8(self, a: &[f32; 8]) -> Self::F32x8;
    /// Eight bytes as a packet, lane `l` the value of `a[l]` (0 to 255, exact): the
    /// quantised child boxes of the compact BVH's nodes.
    fn bytes8(self, a: &[u8; 8]) -> Self::F32x8;
    /// A packet of lanes 0..4 from `lo` and lanes 4..8 from `hi`.
    fn halves8(self, lo: &[f32; 4], hi: &[f32; 4]) -> Self::F32x8;
    /// A packet of `lo` in lanes 0..4 and `hi` in lanes 4..8.
    fn splat_halves8(self, lo: f32, hi: f32) -> Self::F32x8;
    /// A packet of `a` in both halves (lanes 0..4 and 4..8).
    #[inline(always)]
    fn both8(self, a: &[f32; 4]) -> Self::F32x8 {
        self.halves8(a, a)
    }
    /// `x` in four f32 lanes.
    fn splat4f(self, x: f32) -> Self::F32x4;
    /// Loads four f32 lanes.
    fn load4f(self, a: &[f32; 4]) -> Self::F32x4;
    /// Loads four packets.
    fn load32(self, a: &[[f32; 8]; 4]) -> Self::F32x32;
    /// A register file of portable packets viewed as this backend's packets (same size and
    /// alignment): scratch built once serves every backend.
    fn regs8(self, v: &mut [F8]) -> &mut [Self::F32x8];
    /// [`Simd::regs8`] for point registers (three packets each).
    fn regs8x3(self, v: &mut [[F8; 3]]) -> &mut [[Self::F32x8; 3]];
    /// [`Simd::regs8`] for four-packet registers.
    fn regs32(self, v: &mut [F8x4]) -> &mut [Self::F32x32];
    /// [`Simd::regs8`] for four-packet point registers.
    fn regs32x3(self, v: &mut [[F8x4; 3]]) -> &mut [[Self::F32x32; 3]];
}

/// A computation written once for every backend: [`dispatch`] calls `run` with the token
/// of the selected backend. Mark `run` `#[inline(always)]`: it is then compiled inside the
/// backend's target-feature function, with its instructions.
pub trait Kernel {
    /// What the kernel returns.
    type Output;
    /// Runs the kernel with backend `S`.
    fn run<S: Simd>(self, s: S) -> Self::Output;
}

/// Runs `k` on the backend [`super::backend`] selected: with the [`Avx2`] token inside a
/// function compiled for AVX2, FMA, POPCNT and BMI1 where that backend is selected, else
/// with [`Portable`], out of line.
///
/// The kernel's body is called from the target-feature function directly, not through a
/// closure as [`super::Avx2::vectorize`] takes: a closure is compiled for the features of
/// the function that defines it, and a large one is left out of line, where none of the
/// lane operations it calls would be inlined (measured: a mesh frame seven times slower).
/// The portable body is out of line too: inlined, it would make every caller as large as
/// the kernel (a frame of kilobytes set up on each call, for either backend) and keep the
/// dispatch from being inlined into it (measured: 2% of the mesh tracer's primary rays).
#[inline(always)]
pub fn dispatch<K: Kernel>(k: K) -> K::Output {
    match super::avx2() {
        Some(a) => a.run(k),
        None => run_portable(k),
    }
}

/// [`Kernel::run`] on [`Portable`], out of line (see [`dispatch`]).
#[inline(never)]
fn run_portable<K: Kernel>(k: K) -> K::Output {
    k.run(Portable)
}

impl Simd for Portable {
    const BACKEND: Backend = Backend::Portable;
    type F32x8 = F8;
    type F32x32 = F8x4;
    type F64x4 = D4;
    type F32x4 = F4;

    #[inline(always)]
    fn splat4(self, x: f64) -> D4 {
        D4([x; 4])
    }
    #[inline(always)]
    fn load4_at(self, a: &[f64], i: usize) -> D4 {
        D4(a[i..i + 4].try_into().unwrap())
    }
    #[inline(always)]
    fn mask4(self, bits: u32) -> D4 {
        D4(std::array::from_fn(|l| D4::mask(bits >> l & 1 == 1)))
    }
    #[inline(always)]
    fn u32_masks4(self, v: &[u32], i: usize, limit: i32) -> (D4, D4) {
        let v: &[u32; 4] = v[i..i + 4].try_into().unwrap();
        (D4(v.map(|x| D4::mask(x == 0))), D4(v.map(|x| D4::mask((x as i32) < limit))))
    }

    #[inline(always)]
    fn load8(self, a: &[f32; 8]) -> F8 {
        F8(*a)
    }
    #[inline(always)]
    fn bytes8(self, a: &[u8; 8]) -> F8 {
        F8(a.map(f32::from))
    }
    #[inline(always)]
    fn halves8(self, lo: &[f32; 4], hi: &[f32; 4]) -> F8 {
        F8([lo[0], lo[1], lo[2], lo[3], hi[0], hi[1], hi[2], hi[3]])
    }
    #[inline(always)]
    fn splat_halves8(self, lo: f32, hi: f32) -> F8 {
        F8([lo, lo, lo, lo, hi, hi, hi, hi])
    }
    #[inline(always)]
    fn splat4f(self, x: f32) -> F4 {
        F4([x; 4])
    }
    #[inline(always)]
    fn load4f(self, a: &[f32; 4]) -> F4 {
        F4(*a)
    }
    #[inline(always)]
    fn load32(self, a: &[[f32; 8]; 4]) -> F8x4 {
        F8x4(a.map(F8))
    }
    #[inline(always)]
    fn regs8(self, v: &mut [F8]) -> &mut [F8] {
        v
    }
    #[inline(always)]
    fn regs8x3(self, v: &mut [[F8; 3]]) -> &mut [[F8; 3]] {
        v
    }
    #[inline(always)]
    fn regs32(self, v: &mut [F8x4]) -> &mut [F8x4] {
        v
    }
    #[inline(always)]
    fn regs32x3(self, v: &mut [[F8x4; 3]]) -> &mut [[F8x4; 3]] {
        v
    }
}

impl Avx2 {
    /// Runs `k` with this token inside a function compiled for AVX2, FMA, POPCNT and BMI1.
    #[inline(always)]
    pub fn run<K: Kernel>(self, k: K) -> K::Output {
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2,fma,popcnt,bmi1")]
            fn run_avx2<K: Kernel>(k: K, s: Avx2) -> K::Output {
                k.run(s)
            }
            // SAFETY: an `Avx2` exists only after `cpu_has_avx2` found every feature
            // `run_avx2` is compiled for.
            unsafe { run_avx2(k, self) }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            k.run(Portable)
        }
    }
}
