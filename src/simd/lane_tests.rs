//! Bit identity of the lane types: every operation of each backend's lanes equals the
//! scalar `f32` operation lane by lane, on values that include NaN, infinities, signed
//! zeros and subnormals.

use super::*;

/// Interesting values, then a pseudo-random spread.
fn values() -> Vec<f32> {
    let mut v = vec![
        0.0,
        -0.0,
        1.0,
        -1.0,
        0.5,
        -2.5,
        f32::NAN,
        -f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::MIN_POSITIVE / 4.0,
        f32::MAX,
        3.0e-8,
        -7.75,
    ];
    let mut s = 0x2545_f491_4f6c_dd1du64;
    while v.len() < 64 {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        v.push(((s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * 100.0);
    }
    v
}

/// A lane result beside the scalar operation it must equal.
type Unary<V> = (V, fn(f32) -> f32);
/// A lane result beside the scalar binary operation it must equal.
type Binary<V> = (V, fn(f32, f32) -> f32);

fn same(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// Runs every lane operation of backend `S` on packets of `values()` against `f32`.
fn check_backend<S: Simd>(s: S) {
    // Bytes to lanes: every byte value, exactly.
    for k in 0..32u8 {
        let b: [u8; 8] = std::array::from_fn(|l| k.wrapping_mul(8).wrapping_add(l as u8).wrapping_mul(37));
        assert_eq!(s.bytes8(&b).store(), b.map(f32::from));
    }
    let v = values();
    for i in 0..v.len() {
        let a: [f32; 8] = std::array::from_fn(|l| v[(i + l) % v.len()]);
        let b: [f32; 8] = std::array::from_fn(|l| v[(i * 7 + 3 * l + 1) % v.len()]);
        let (x, y) = (s.load8(&a), s.load8(&b));
        let unary: [Unary<S::F32x8>; 5] = [
            (-x, |a| -a),
            (x.vsqrt(), f32::vsqrt),
            (x.vabs(), f32::vabs),
            (x.vfloor(), f32::vfloor),
            (x + s.splat8(0.25), |a| a + 0.25),
        ];
        for (k, (got, f)) in unary.into_iter().enumerate() {
            let got = got.store();
            for l in 0..8 {
                assert!(same(got[l], f(a[l])), "unary {k} lane {l}: {} vs {}", got[l], f(a[l]));
            }
        }
        let binary: [Binary<S::F32x8>; 7] = [
            (x + y, |a, b| a + b),
            (x - y, |a, b| a - b),
            (x * y, |a, b| a * b),
            (x / y, |a, b| a / b),
            (x.vmin(y), f32::vmin),
            (x.vmax(y), f32::vmax),
            (S::F32x8::select_lt(x, y, y, x), |a, b| f32::select_lt(a, b, b, a)),
        ];
        for (k, (got, f)) in binary.into_iter().enumerate() {
            let got = got.store();
            for l in 0..8 {
                let want = f(a[l], b[l]);
                // NaN payloads: division and arithmetic may pick either input's; only
                // min/max/select must give the exact operand.
                let exact = k >= 4;
                let ok = if exact { got[l].to_bits() == want.to_bits() } else { same(got[l], want) };
                assert!(ok, "binary {k} lane {l}: {} vs {want} ({} and {})", got[l], a[l], b[l]);
            }
        }
        let mask = x.lt_mask(y);
        for l in 0..8 {
            assert_eq!(mask >> l & 1 == 1, a[l] < b[l], "lt lane {l}");
        }
        // The four-packet type: each packet as the eight-lane one.
        let four = [a, b, a, b];
        let (x4, y4) = (s.load32(&four), s.load32(&[b, a, b, a]));
        let got = S::F32x32::select_lt(x4, y4, (x4 * y4).vsqrt(), x4.vmin(y4) - y4).store();
        let want8 =
            |p: S::F32x8, q: S::F32x8| S::F32x8::select_lt(p, q, (p * q).vsqrt(), p.vmin(q) - q).store();
        let (ab, ba) = (want8(x, y), want8(y, x));
        for (g, packet) in got.iter().enumerate() {
            let want = if g % 2 == 0 { ab } else { ba };
            for l in 0..8 {
                assert!(same(packet[l], want[l]), "packet {g} lane {l}");
            }
        }
    }
}

#[test]
fn portable_lanes_equal_scalar() {
    check_backend(Portable);
}

#[test]
fn avx2_lanes_equal_scalar() {
    // The token only where the CPU has AVX2 (whatever SDFMESH_SIMD says: this test calls
    // the AVX2 lanes directly).
    if cpu_has_avx2() {
        Avx2 { _private: () }.run(CheckBackend);
    }
}

struct CheckBackend;

impl Kernel for CheckBackend {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        check_backend(s)
    }
}

#[test]
fn dispatch_runs_the_selected_backend() {
    struct Which;
    impl Kernel for Which {
        type Output = Backend;
        fn run<S: Simd>(self, _: S) -> Backend {
            S::BACKEND
        }
    }
    assert_eq!(dispatch(Which), backend());
}
