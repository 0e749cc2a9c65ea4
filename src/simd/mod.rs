//! The crate's one SIMD layer: the CPU check, the backend switch, and the lane types.
//!
//! Every intrinsic and every `unsafe` block of the crate lives in this module, each with a
//! SAFETY note. Kernels elsewhere are written against the lane types and reach the AVX2
//! instructions only through an [`Avx2`] token, which [`avx2`] hands out after the one CPU
//! check, and only when the backend switch allows it:
//!
//! - `SDFMESH_SIMD=portable` forces the portable backend (plain Rust, the twin of every
//!   AVX2 kernel), so tests can run both backends on an AVX2 machine;
//! - `SDFMESH_SIMD=avx2` or `auto` (or unset) uses AVX2 where the CPU has it.
//!
//! The value is read once per process ([`backend`]); the `toolkit` binary refuses an unknown
//! value with a one-line error ([`check_env`]).

#[cfg(target_arch = "x86_64")]
mod avx2;
mod backend;
mod f4;
#[cfg(target_arch = "x86_64")]
mod grid;
mod lane;
mod mask;
mod portable;
mod stack;

#[cfg(target_arch = "x86_64")]
pub use avx2::{A4d, A8, A8x4, AvxMask8};
pub use backend::{Kernel, Simd, dispatch};
#[cfg(target_arch = "x86_64")]
pub use f4::Sse4;
pub use f4::{F4, Lanes4};
#[cfg(target_arch = "x86_64")]
pub use grid::{BAND_BRICK, BAND_BRICK_SAMPLES, BAND_BS, BAND_EMPTY, BandLayout, Lattice};
pub use lane::{Lane, Lane8, Lane32, Lane64, Mask8};
pub use mask::Bits8;
pub use portable::{D4, F8, F8x4, Portable};
pub use stack::{WalkStack, at_byte_offset};

use std::sync::OnceLock;

/// The environment variable that selects the backend.
pub const ENV: &str = "SDFMESH_SIMD";

/// Which implementation of the lane types the kernels run on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// Plain Rust: every target, and what `SDFMESH_SIMD=portable` forces.
    Portable,
    /// AVX2, FMA, POPCNT and BMI1 on x86_64.
    Avx2,
}

impl Backend {
    /// The name used in `SDFMESH_SIMD` and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Portable => "portable",
            Backend::Avx2 => "avx2",
        }
    }
}

/// What `SDFMESH_SIMD` asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Request {
    Auto,
    Portable,
}

/// Parses a value of `SDFMESH_SIMD` (`None`: unset).
fn parse_request(value: Option<&str>) -> Result<Request, String> {
    match value.map(str::trim) {
        None | Some("") | Some("auto") | Some("avx2") => Ok(Request::Auto),
        Some("portable") => Ok(Request::Portable),
        Some(other) => Err(format!("{ENV}={other:?} is not a backend: expected portable, avx2 or auto")),
    }
}

/// Whether the CPU has AVX2, FMA, POPCNT and BMI1, the one feature level of the crate's
/// AVX2 kernels. Detected once and cached.
pub fn cpu_has_avx2() -> bool {
    static CPU: OnceLock<bool> = OnceLock::new();
    *CPU.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
                && std::arch::is_x86_feature_detected!("popcnt")
                && std::arch::is_x86_feature_detected!("bmi1")
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    })
}

/// The backend this process runs: AVX2 where the CPU has it, unless `SDFMESH_SIMD=portable`
/// (an unknown value counts as `auto` here; [`check_env`] reports it). Decided once.
pub fn backend() -> Backend {
    static BACKEND: OnceLock<Backend> = OnceLock::new();
    *BACKEND.get_or_init(|| {
        let value = std::env::var(ENV).ok();
        let request = parse_request(value.as_deref()).unwrap_or(Request::Auto);
        if request == Request::Auto && cpu_has_avx2() { Backend::Avx2 } else { Backend::Portable }
    })
}

/// Checks `SDFMESH_SIMD`: an error message naming the variable and the value when it is set
/// to something other than `portable`, `avx2` or `auto`.
pub fn check_env() -> Result<Backend, String> {
    let value = std::env::var(ENV).ok();
    parse_request(value.as_deref())?;
    Ok(backend())
}

/// Proof that the AVX2 backend is selected: the CPU has AVX2, FMA, POPCNT and BMI1 and
/// `SDFMESH_SIMD` does not force the portable backend. Only [`avx2`] makes one, so a
/// function that takes an `Avx2` can only run where those instructions exist.
#[derive(Clone, Copy, Debug)]
pub struct Avx2 {
    _private: (),
}

/// The AVX2 token, when the AVX2 backend is selected ([`backend`]).
#[inline]
pub fn avx2() -> Option<Avx2> {
    (backend() == Backend::Avx2).then_some(Avx2 { _private: () })
}

impl Avx2 {
    /// Runs `f` compiled for AVX2, FMA, POPCNT and BMI1: `f` and everything inlined into it
    /// may use those instructions (closures inherit the caller's target features). Kernels
    /// mark their generic bodies `#[inline(always)]` so they are compiled here.
    #[inline(always)]
    pub fn vectorize<R>(self, f: impl FnOnce() -> R) -> R {
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2,fma,popcnt,bmi1")]
            fn run<R>(f: impl FnOnce() -> R) -> R {
                f()
            }
            // SAFETY: an `Avx2` exists only after `cpu_has_avx2` found every feature `run`
            // is compiled for.
            unsafe { run(f) }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            f()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_parse() {
        assert_eq!(parse_request(None), Ok(Request::Auto));
        assert_eq!(parse_request(Some("auto")), Ok(Request::Auto));
        assert_eq!(parse_request(Some("avx2")), Ok(Request::Auto));
        assert_eq!(parse_request(Some(" portable ")), Ok(Request::Portable));
        let e = parse_request(Some("sse9")).unwrap_err();
        assert!(e.contains("SDFMESH_SIMD") && e.contains("sse9"), "{e}");
    }

    #[test]
    fn token_only_with_the_avx2_backend() {
        assert_eq!(avx2().is_some(), backend() == Backend::Avx2);
        if backend() == Backend::Avx2 {
            assert!(cpu_has_avx2());
        }
    }
}

#[cfg(test)]
mod lane_tests;
