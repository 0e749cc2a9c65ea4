//! Sound interval extension of every opcode, in f64: for every point of the input
//! intervals the f64 value of the opcode lies in the output interval, or the output says
//! it may be NaN. Each finite bound is widened outward by a few ulps, which covers the
//! rounding of the operation (libm's transcendentals are within an ulp or two).

use super::ops::Opcode;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// A closed interval `[lo, hi]` and whether some point of the region may give NaN.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// Lower bound (may be -inf).
    pub lo: f64,
    /// Upper bound (may be +inf).
    pub hi: f64,
    /// Whether NaN is possible.
    pub nan: bool,
}

/// Everything (and possibly NaN).
const ANY: Interval = Interval { lo: f64::NEG_INFINITY, hi: f64::INFINITY, nan: true };

#[inline(always)]
fn down(x: f64) -> f64 {
    if x.is_finite() { x - x.abs() * 8.0 * f64::EPSILON - f64::MIN_POSITIVE } else { x }
}

#[inline(always)]
fn up(x: f64) -> f64 {
    if x.is_finite() { x + x.abs() * 8.0 * f64::EPSILON + f64::MIN_POSITIVE } else { x }
}

impl Interval {
    /// `[lo, hi]`, no NaN.
    pub fn new(lo: f64, hi: f64) -> Interval {
        Interval { lo, hi, nan: false }
    }

    /// The single value `v` (NaN gives an interval that is only NaN).
    pub fn point(v: f64) -> Interval {
        if v.is_nan() {
            Interval { lo: f64::INFINITY, hi: f64::NEG_INFINITY, nan: true }
        } else {
            Interval::new(v, v)
        }
    }

    /// Whether `v` may be a value.
    pub fn contains(&self, v: f64) -> bool {
        self.lo <= v && v <= self.hi
    }

    /// Whether there is no value but NaN.
    fn is_empty(&self) -> bool {
        !(self.lo <= self.hi)
    }

    #[inline(always)]
    fn widened(lo: f64, hi: f64, nan: bool) -> Interval {
        let (lo, hi) =
            if lo.is_nan() || hi.is_nan() { (f64::NEG_INFINITY, f64::INFINITY) } else { (down(lo), up(hi)) };
        Interval { lo, hi, nan }
    }

    fn hull(self, o: Interval) -> Interval {
        Interval { lo: self.lo.min(o.lo), hi: self.hi.max(o.hi), nan: self.nan || o.nan }
    }

    /// The interval of `op` over `a` and `b` (`b` ignored for a unary opcode).
    pub fn apply(op: Opcode, a: Interval, b: Interval) -> Interval {
        use Opcode::*;
        let binary = op.arity() == 2;
        if a.is_empty() || (binary && b.is_empty()) {
            return Interval::point(f64::NAN);
        }
        let nan = a.nan || (binary && b.nan);
        let w = |lo: f64, hi: f64, extra: bool| Interval::widened(lo, hi, nan || extra);
        match op {
            VarX | VarY | VarZ | Const | Copy => a,
            Neg => neg(a, nan),
            Abs => abs(a, nan),
            Recip => {
                if a.lo > 0.0 || a.hi < 0.0 {
                    w(1.0 / a.hi, 1.0 / a.lo, false)
                } else {
                    ANY
                }
            }
            Sqrt => sqrt(a, nan),
            Square => square(a, nan),
            Floor => Interval { lo: a.lo.floor(), hi: a.hi.floor(), nan },
            Ceil => Interval { lo: a.lo.ceil(), hi: a.hi.ceil(), nan },
            Round => Interval { lo: a.lo.round(), hi: a.hi.round(), nan },
            Sin => periodic(a, 0.0, nan),
            Cos => periodic(a, FRAC_PI_2, nan),
            Tan => {
                // Asymptotes at pi/2 + k pi: monotonic between two of them.
                if !(a.hi - a.lo < PI) || !a.lo.is_finite() || !a.hi.is_finite() {
                    return ANY;
                }
                let k = ((a.lo - FRAC_PI_2) / PI).floor();
                let next = FRAC_PI_2 + (k + 1.0) * PI;
                // Keep a margin of rounding around the asymptote.
                if a.hi >= next - 1e-9 * next.abs().max(1.0) { ANY } else { w(a.lo.tan(), a.hi.tan(), false) }
            }
            Asin | Acos => {
                if a.hi < -1.0 || a.lo > 1.0 {
                    return Interval::point(f64::NAN);
                }
                let (l, h) = (a.lo.max(-1.0), a.hi.min(1.0));
                let extra = a.lo < -1.0 || a.hi > 1.0;
                if op == Asin { w(l.asin(), h.asin(), extra) } else { w(h.acos(), l.acos(), extra) }
            }
            Atan => w(a.lo.atan(), a.hi.atan(), false),
            Exp => w(a.lo.exp(), a.hi.exp(), false),
            Ln => {
                if a.hi < 0.0 {
                    Interval::point(f64::NAN)
                } else {
                    let l = if a.lo <= 0.0 { f64::NEG_INFINITY } else { a.lo.ln() };
                    w(l, a.hi.ln(), a.lo < 0.0)
                }
            }
            Not => {
                if !a.contains(0.0) {
                    Interval { lo: 0.0, hi: 0.0, nan }
                } else if a.lo == 0.0 && a.hi == 0.0 {
                    Interval { lo: 1.0, hi: 1.0, nan }
                } else {
                    Interval { lo: 0.0, hi: 1.0, nan }
                }
            }
            Add => add(a, b, nan),
            Sub => sub(a, b, nan),
            Mul => mul(a, b, nan),
            Div => {
                if b.lo > 0.0 || b.hi < 0.0 {
                    let r = Interval::apply(Recip, b, b);
                    Interval::apply(Mul, a, r)
                } else {
                    ANY
                }
            }
            Min => Interval { lo: a.lo.min(b.lo), hi: a.hi.min(b.hi), nan },
            Max => Interval { lo: a.lo.max(b.lo), hi: a.hi.max(b.hi), nan },
            Atan2 => {
                // atan2(y = a, x = b). Over a box that holds neither the origin nor a point
                // of the branch cut (x < 0, y = 0), the angle is extreme at a corner.
                if (b.lo <= 0.0 && a.contains(0.0)) || !a.lo.is_finite() || !a.hi.is_finite() {
                    return Interval { lo: -PI - 1e-12, hi: PI + 1e-12, nan };
                }
                let c = [a.lo.atan2(b.lo), a.lo.atan2(b.hi), a.hi.atan2(b.lo), a.hi.atan2(b.hi)];
                let lo = c.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                w(lo, hi, false)
            }
            Mod => {
                // Euclidean remainder: in [0, |b|) for b != 0; NaN for b = 0 or infinite a.
                let m = b.lo.abs().max(b.hi.abs());
                let bad = b.contains(0.0) || !a.lo.is_finite() || !a.hi.is_finite();
                if !bad && b.lo == b.hi {
                    let k_lo = (a.lo / m).floor();
                    let k_hi = (a.hi / m).floor();
                    // The same period all through, away from its ends: a shift.
                    let r_lo = a.lo - k_lo * m;
                    let r_hi = a.hi - k_lo * m;
                    if k_lo == k_hi && r_lo > 1e-9 * m && r_hi < m * (1.0 - 1e-9) {
                        return w(r_lo, r_hi, false);
                    }
                }
                w(0.0, m, bad)
            }
            Compare => {
                if a.hi < b.lo {
                    Interval { lo: -1.0, hi: -1.0, nan }
                } else if a.lo > b.hi {
                    Interval { lo: 1.0, hi: 1.0, nan }
                } else if a.lo == a.hi && b.lo == b.hi {
                    Interval { lo: 0.0, hi: 0.0, nan }
                } else {
                    Interval { lo: -1.0, hi: 1.0, nan }
                }
            }
            And => {
                if !a.contains(0.0) {
                    Interval { nan, ..b }
                } else if a.lo == 0.0 && a.hi == 0.0 {
                    Interval { lo: 0.0, hi: 0.0, nan: a.nan }
                } else {
                    b.hull(Interval::new(0.0, 0.0))
                }
            }
            Or => {
                if !a.contains(0.0) {
                    a
                } else if a.lo == 0.0 && a.hi == 0.0 {
                    Interval { nan, ..b }
                } else {
                    a.hull(b)
                }
            }
        }
    }
}

impl Interval {
    /// [`Interval::apply`], the same result bit for bit, with the opcodes of distance-like
    /// models (arithmetic, `min`, `max`, `sqrt`, `square`, `neg`, `abs`) inlined into the
    /// caller's loop; the others call [`Interval::apply`].
    #[inline(always)]
    pub fn apply_inline(op: Opcode, a: Interval, b: Interval) -> Interval {
        use Opcode::*;
        // Empty arguments (NaN only) take the general path.
        let full_a = a.lo <= a.hi;
        let full_b = b.lo <= b.hi;
        match op {
            Add if full_a && full_b => add(a, b, a.nan || b.nan),
            Sub if full_a && full_b => sub(a, b, a.nan || b.nan),
            Mul if full_a && full_b => mul(a, b, a.nan || b.nan),
            Min if full_a && full_b => {
                Interval { lo: a.lo.min(b.lo), hi: a.hi.min(b.hi), nan: a.nan || b.nan }
            }
            Max if full_a && full_b => {
                Interval { lo: a.lo.max(b.lo), hi: a.hi.max(b.hi), nan: a.nan || b.nan }
            }
            Neg if full_a => neg(a, a.nan),
            Abs if full_a => abs(a, a.nan),
            Sqrt if full_a => sqrt(a, a.nan),
            Square if full_a => square(a, a.nan),
            _ => Interval::apply(op, a, b),
        }
    }
}

#[inline(always)]
fn neg(a: Interval, nan: bool) -> Interval {
    Interval { lo: -a.hi, hi: -a.lo, nan }
}

#[inline(always)]
fn abs(a: Interval, nan: bool) -> Interval {
    if a.lo >= 0.0 {
        a
    } else if a.hi <= 0.0 {
        Interval { lo: -a.hi, hi: -a.lo, nan }
    } else {
        Interval { lo: 0.0, hi: a.hi.max(-a.lo), nan }
    }
}

#[inline(always)]
fn sqrt(a: Interval, nan: bool) -> Interval {
    if a.hi < 0.0 {
        Interval::point(f64::NAN)
    } else {
        Interval::widened(a.lo.max(0.0).sqrt(), a.hi.sqrt(), nan || a.lo < 0.0)
    }
}

#[inline(always)]
fn square(a: Interval, nan: bool) -> Interval {
    let (l, h) = (a.lo * a.lo, a.hi * a.hi);
    if a.lo <= 0.0 && a.hi >= 0.0 {
        Interval::widened(0.0, l.max(h), nan)
    } else {
        Interval::widened(l.min(h), l.max(h), nan)
    }
}

#[inline(always)]
fn add(a: Interval, b: Interval, nan: bool) -> Interval {
    let extra = inf_minus_inf(a.lo, b.lo) || inf_minus_inf(a.hi, b.hi);
    Interval::widened(a.lo + b.lo, a.hi + b.hi, nan || extra)
}

#[inline(always)]
fn sub(a: Interval, b: Interval, nan: bool) -> Interval {
    let extra = inf_minus_inf(a.lo, -b.hi) || inf_minus_inf(a.hi, -b.lo);
    Interval::widened(a.lo - b.hi, a.hi - b.lo, nan || extra)
}

#[inline(always)]
fn mul(a: Interval, b: Interval, nan: bool) -> Interval {
    let p = [a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi];
    if p.iter().any(|v| v.is_nan()) {
        return ANY;
    }
    let lo = p[0].min(p[1]).min(p[2].min(p[3]));
    let hi = p[0].max(p[1]).max(p[2].max(p[3]));
    Interval::widened(lo, hi, nan)
}

#[inline(always)]
fn inf_minus_inf(x: f64, y: f64) -> bool {
    x.is_infinite() && y.is_infinite() && x.signum() != y.signum()
}

/// sin(x + shift) over `a`: endpoints, and +-1 where a maximum or minimum falls inside.
fn periodic(a: Interval, shift: f64, nan: bool) -> Interval {
    if !a.lo.is_finite() || !a.hi.is_finite() {
        return Interval { lo: -1.0, hi: 1.0, nan: nan || a.lo.is_infinite() || a.hi.is_infinite() };
    }
    if a.hi - a.lo >= TAU {
        return Interval { lo: -1.0, hi: 1.0, nan };
    }
    let f = |x: f64| if shift == 0.0 { x.sin() } else { x.cos() };
    let (fl, fh) = (f(a.lo), f(a.hi));
    let (mut lo, mut hi) = (down(fl.min(fh)), up(fl.max(fh)));
    // Maxima of sin(x + shift) at pi/2 - shift + 2k pi, minima at -pi/2 - shift + 2k pi;
    // a small margin stands for the rounding of the phase.
    let eps = 1e-12 * a.lo.abs().max(a.hi.abs()).max(1.0);
    let has = |phase: f64| {
        let k = ((a.lo - eps - phase) / TAU).ceil();
        phase + k * TAU <= a.hi + eps
    };
    if has(FRAC_PI_2 - shift) {
        hi = 1.0;
    }
    if has(-FRAC_PI_2 - shift) {
        lo = -1.0;
    }
    Interval { lo: lo.max(-1.0), hi: hi.min(1.0), nan }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::implicit::ops::apply_f64;

    /// The inlined path gives `apply`'s result bit for bit, NaN flags and empty
    /// (NaN-only) arguments included.
    #[test]
    fn inline_path_equals_apply() {
        use Opcode::*;
        let mut s = 0x0bad_cafe_1234_5678u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut pick = || -> Interval {
            let k = rnd();
            if k < 0.05 {
                return Interval::point(f64::NAN);
            }
            if k < 0.1 {
                return Interval::new(f64::NEG_INFINITY, (rnd() - 0.5) * 4.0);
            }
            if k < 0.15 {
                return Interval::new((rnd() - 0.5) * 4.0, f64::INFINITY);
            }
            let c = (rnd() - 0.5) * 10.0;
            let r = if rnd() < 0.2 { 0.0 } else { rnd() * 3.0 };
            Interval { lo: c - r, hi: c + r, nan: rnd() < 0.1 }
        };
        for op in [Add, Sub, Mul, Min, Max, Neg, Abs, Sqrt, Square, Div, Sin] {
            for _ in 0..2000 {
                let (a, b) = (pick(), pick());
                let (f, g) = (Interval::apply_inline(op, a, b), Interval::apply(op, a, b));
                let same = |x: f64, y: f64| x.to_bits() == y.to_bits() || (x == 0.0 && y == 0.0);
                assert!(
                    same(f.lo, g.lo) && same(f.hi, g.hi) && f.nan == g.nan,
                    "{op:?} {a:?} {b:?}: {f:?} vs {g:?}"
                );
            }
        }
    }

    /// Every opcode, over many random intervals: values at sample points lie inside.
    #[test]
    fn every_opcode_contains_its_sampled_values() {
        use Opcode::*;
        let ops = [
            Neg, Abs, Recip, Sqrt, Square, Floor, Ceil, Round, Sin, Cos, Tan, Asin, Acos, Atan, Exp, Ln, Not,
            Add, Sub, Mul, Div, Min, Max, Atan2, Mod, Compare, And, Or,
        ];
        let mut s = 0x1234_5678_9abc_def0u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for &op in &ops {
            for _ in 0..400 {
                let mut iv = || {
                    let scale = [0.0, 0.5, 3.0, 20.0][(rnd() * 4.0) as usize];
                    let c = (rnd() - 0.5) * 2.0 * scale;
                    let r = rnd() * scale * if rnd() < 0.2 { 0.0 } else { 1.0 };
                    let c = if rnd() < 0.1 { c.round() } else { c };
                    (c - r, c + r)
                };
                let (a, b) = (iv(), iv());
                let out = Interval::apply(op, Interval::new(a.0, a.1), Interval::new(b.0, b.1));
                for i in 0..=8 {
                    for j in 0..=8 {
                        // Clamped: the rounded sample may fall just past the interval.
                        let x = (a.0 + (a.1 - a.0) * i as f64 / 8.0).clamp(a.0, a.1);
                        let y = (b.0 + (b.1 - b.0) * j as f64 / 8.0).clamp(b.0, b.1);
                        let v = apply_f64(op, x, y);
                        if v.is_nan() {
                            assert!(out.nan, "{op:?} {a:?} {b:?} at ({x}, {y}): NaN not flagged in {out:?}");
                        } else {
                            assert!(
                                out.contains(v),
                                "{op:?} {a:?} {b:?} at ({x}, {y}) = {v} outside {out:?}"
                            );
                        }
                    }
                }
            }
        }
    }
}
