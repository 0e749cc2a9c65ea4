//! Interval bounds on a model's gradient over a box (forward-mode differentiation in
//! interval arithmetic), and from them a proven Lipschitz bound: for any two points `p`,
//! `q` of the box, `|f(p) - f(q)| <= L |p - q|`, so `f(p) / L` is a lower bound on the
//! distance from `p` to the surface within the box.
//!
//! Every opcode's derivative is bounded over the clause's value interval. Where the
//! function may be discontinuous in the box (`floor`, `ceil`, `round`, `mod` across a
//! period, `compare`, `and`, `or`, `not` and `atan2` across their jumps) or its derivative
//! unbounded (`sqrt` at 0, `ln` at 0, `div` by an interval holding 0), the bound is
//! infinite and there is no Lipschitz bound for the box: the caller must isolate roots by
//! interval subdivision instead. `min`, `max` and `abs` are continuous and piecewise
//! smooth: their gradient lies in the hull of their arguments' gradients.

use super::interval::Interval;
use super::ops::Opcode;
use super::tape::Ssa;

/// Value and gradient intervals of one clause.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual {
    /// The value over the box.
    pub v: Interval,
    /// The partial derivatives along x, y, z over the box.
    pub g: [Interval; 3],
}

const ZERO: Interval = Interval { lo: 0.0, hi: 0.0, nan: false };
const ONE: Interval = Interval { lo: 1.0, hi: 1.0, nan: false };
const UNBOUNDED: Interval = Interval { lo: f64::NEG_INFINITY, hi: f64::INFINITY, nan: true };

fn is_zero(i: Interval) -> bool {
    i.lo == 0.0 && i.hi == 0.0 && !i.nan
}

fn hull(a: Interval, b: Interval) -> Interval {
    Interval { lo: a.lo.min(b.lo), hi: a.hi.max(b.hi), nan: a.nan || b.nan }
}

fn mul(a: Interval, b: Interval) -> Interval {
    // A derivative that is exactly zero stays zero whatever it multiplies (an infinite
    // factor included): the clause does not depend on that variable.
    if is_zero(a) || is_zero(b) { ZERO } else { Interval::apply(Opcode::Mul, a, b) }
}

fn add(a: Interval, b: Interval) -> Interval {
    Interval::apply(Opcode::Add, a, b)
}

fn sub(a: Interval, b: Interval) -> Interval {
    Interval::apply(Opcode::Sub, a, b)
}

fn div(a: Interval, b: Interval) -> Interval {
    if is_zero(a) { ZERO } else { Interval::apply(Opcode::Div, a, b) }
}

fn neg(a: Interval) -> Interval {
    Interval { lo: -a.hi, hi: -a.lo, nan: a.nan }
}

fn scale(g: [Interval; 3], k: Interval) -> [Interval; 3] {
    g.map(|gi| mul(gi, k))
}

fn constant(g: [Interval; 3]) -> bool {
    g.iter().all(|&gi| is_zero(gi))
}

/// Gradient of a clause that is piecewise constant with jumps: zero where the jump is
/// decided away (`continuous`) or the argument does not vary, unbounded otherwise.
fn step(continuous: bool, args: &[[Interval; 3]]) -> [Interval; 3] {
    if continuous || args.iter().all(|&g| constant(g)) { [ZERO; 3] } else { [UNBOUNDED; 3] }
}

/// The value and gradient intervals of every clause of `ssa` over the box `x`, `y`, `z`,
/// into `out`; returns the output's.
pub fn eval_dual(ssa: &Ssa, x: Interval, y: Interval, z: Interval, out: &mut Vec<Dual>) -> Dual {
    use Opcode::*;
    out.clear();
    for c in &ssa.clauses {
        let d = match c.op {
            VarX => Dual { v: x, g: [ONE, ZERO, ZERO] },
            VarY => Dual { v: y, g: [ZERO, ONE, ZERO] },
            VarZ => Dual { v: z, g: [ZERO, ZERO, ONE] },
            Const => Dual { v: Interval::point(c.value), g: [ZERO; 3] },
            op => {
                let a = out[c.a as usize];
                let b = if op.arity() == 2 { out[c.b as usize] } else { a };
                let v = Interval::apply(op, a.v, b.v);
                let g = derivative(op, a, b, v);
                Dual { v, g }
            }
        };
        out.push(d);
    }
    out.last().copied().unwrap_or(Dual { v: Interval::point(f64::NAN), g: [UNBOUNDED; 3] })
}

/// The gradient of `op` over `a` (and `b`) whose value is `v`.
fn derivative(op: Opcode, a: Dual, b: Dual, v: Interval) -> [Interval; 3] {
    use Opcode::*;
    let two = Interval::point(2.0);
    let (av, bv) = (a.v, b.v);
    match op {
        VarX | VarY | VarZ | Const => [ZERO; 3],
        Copy => a.g,
        Neg => a.g.map(neg),
        Abs => {
            if av.lo >= 0.0 {
                a.g
            } else if av.hi <= 0.0 {
                a.g.map(neg)
            } else {
                a.g.map(|g| hull(g, neg(g)))
            }
        }
        // d(1/a) = -g / a^2.
        Recip => scale(a.g, neg(Interval::apply(Recip, Interval::apply(Square, av, av), av))),
        // d sqrt(a) = g / (2 sqrt a): unbounded where a reaches 0.
        Sqrt => {
            let k = Interval::apply(Recip, Interval::apply(Mul, two, v), v);
            if av.lo <= 0.0 && !constant(a.g) { [UNBOUNDED; 3] } else { scale(a.g, k) }
        }
        Square => scale(a.g, Interval::apply(Mul, two, av)),
        Floor => step(!v.nan && v.lo == v.hi && av.lo.floor() == av.hi.floor(), &[a.g]),
        Ceil => step(!v.nan && v.lo == v.hi && av.lo.ceil() == av.hi.ceil(), &[a.g]),
        Round => step(!v.nan && v.lo == v.hi && av.lo.round() == av.hi.round(), &[a.g]),
        Sin => scale(a.g, Interval::apply(Cos, av, av)),
        Cos => scale(a.g, neg(Interval::apply(Sin, av, av))),
        // d tan(a) = (1 + tan^2 a) g.
        Tan => scale(a.g, add(ONE, Interval::apply(Square, v, v))),
        // d asin(a) = g / sqrt(1 - a^2) (unbounded at +-1, where the interval says so).
        Asin | Acos => {
            let s = Interval::apply(Sqrt, sub(ONE, Interval::apply(Square, av, av)), av);
            let k = Interval::apply(Recip, s, s);
            let k = if op == Acos { neg(k) } else { k };
            if (av.lo <= -1.0 || av.hi >= 1.0) && !constant(a.g) { [UNBOUNDED; 3] } else { scale(a.g, k) }
        }
        Atan => {
            let den = add(ONE, Interval::apply(Square, av, av));
            scale(a.g, Interval::apply(Recip, den, den))
        }
        Exp => scale(a.g, v),
        Ln => {
            if av.lo <= 0.0 && !constant(a.g) {
                [UNBOUNDED; 3]
            } else {
                scale(a.g, Interval::apply(Recip, av, av))
            }
        }
        Not => step(!av.contains(0.0) || (av.lo == 0.0 && av.hi == 0.0), &[a.g]),
        Add => std::array::from_fn(|i| add(a.g[i], b.g[i])),
        Sub => std::array::from_fn(|i| sub(a.g[i], b.g[i])),
        Mul => std::array::from_fn(|i| add(mul(a.g[i], bv), mul(av, b.g[i]))),
        // (a / b)' = (a' - (a / b) b') / b.
        Div => {
            if bv.contains(0.0) {
                return [UNBOUNDED; 3];
            }
            std::array::from_fn(|i| div(sub(a.g[i], mul(v, b.g[i])), bv))
        }
        Min => {
            if av.hi < bv.lo {
                a.g
            } else if bv.hi < av.lo {
                b.g
            } else {
                std::array::from_fn(|i| hull(a.g[i], b.g[i]))
            }
        }
        Max => {
            if av.lo > bv.hi {
                a.g
            } else if bv.lo > av.hi {
                b.g
            } else {
                std::array::from_fn(|i| hull(a.g[i], b.g[i]))
            }
        }
        // atan2(y = a, x = b)' = (x y' - y x') / (x^2 + y^2); a jump across the branch cut
        // (x < 0, y = 0) and no bound at the origin.
        Atan2 => {
            if av.contains(0.0) && bv.lo <= 0.0 {
                return if constant(a.g) && constant(b.g) { [ZERO; 3] } else { [UNBOUNDED; 3] };
            }
            let r2 = add(Interval::apply(Square, av, av), Interval::apply(Square, bv, bv));
            std::array::from_fn(|i| div(sub(mul(bv, a.g[i]), mul(av, b.g[i])), r2))
        }
        // Euclidean remainder by a constant: a shift within one period (then a' itself),
        // a jump where a period boundary may fall inside.
        Mod => {
            let m = bv.lo.abs().max(bv.hi.abs());
            let within = constant(b.g)
                && bv.lo == bv.hi
                && m > 0.0
                && av.lo.is_finite()
                && av.hi.is_finite()
                && (av.lo / m).floor() == (av.hi / m).floor()
                && v.lo > 0.0
                && v.hi < m;
            if within {
                a.g
            } else if constant(a.g) && constant(b.g) {
                [ZERO; 3]
            } else {
                [UNBOUNDED; 3]
            }
        }
        Compare => step(v.lo == v.hi && !v.nan, &[a.g, b.g]),
        And => {
            if !av.contains(0.0) {
                b.g
            } else if av.lo == 0.0 && av.hi == 0.0 {
                [ZERO; 3]
            } else {
                step(false, &[a.g, b.g])
            }
        }
        Or => {
            if !av.contains(0.0) {
                a.g
            } else if av.lo == 0.0 && av.hi == 0.0 {
                b.g
            } else {
                step(false, &[a.g, b.g])
            }
        }
    }
}

/// A proven Lipschitz bound of `ssa` over the box `x`, `y`, `z` (Euclidean norm of the
/// largest gradient magnitudes per axis, rounded up), or `None` where the model may be
/// discontinuous, its gradient unbounded, or NaN in the box. `scratch` is reused.
pub fn lipschitz_bound(
    ssa: &Ssa,
    x: Interval,
    y: Interval,
    z: Interval,
    scratch: &mut Vec<Dual>,
) -> Option<f64> {
    let d = eval_dual(ssa, x, y, z, scratch);
    if d.v.nan {
        return None;
    }
    let mut s = 0.0f64;
    for g in d.g {
        if g.nan || !g.lo.is_finite() || !g.hi.is_finite() {
            return None;
        }
        let m = g.lo.abs().max(g.hi.abs());
        s += m * m;
    }
    let l = s.sqrt() * (1.0 + 4.0 * f64::EPSILON);
    l.is_finite().then_some(l)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::implicit::vm::parse_vm;

    fn ssa(text: &str) -> Ssa {
        parse_vm(text, "t.vm".as_ref()).unwrap()
    }

    /// The bound holds between sampled pairs of points of random boxes, for a model mixing
    /// smooth, min/max and transcendental clauses.
    #[test]
    fn the_bound_holds_between_sampled_points() {
        let m =
            ssa("x var-x\ny var-y\nz var-z\na square x\nb mul y z\nc sin b\nd add a c\ne exp y\nf min d e\n\
             g abs z\nh max f g\nk const 0.3\nl sub h k\nq atan2 y x\nr mul q k\no add l r\n");
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut scratch = Vec::new();
        let mut checked = 0;
        for _ in 0..300 {
            let c = [rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0];
            let r = 0.05 + 0.3 * rnd();
            let iv: [Interval; 3] = std::array::from_fn(|i| Interval::new(c[i] - r, c[i] + r));
            let Some(l) = lipschitz_bound(&m, iv[0], iv[1], iv[2], &mut scratch) else { continue };
            checked += 1;
            for _ in 0..20 {
                let p: [f64; 3] = std::array::from_fn(|i| c[i] + r * (2.0 * rnd() - 1.0));
                let q: [f64; 3] = std::array::from_fn(|i| c[i] + r * (2.0 * rnd() - 1.0));
                let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                let df = (m.eval_f64(p) - m.eval_f64(q)).abs();
                assert!(df <= l * d + 1e-12, "{df} > {l} * {d}");
            }
        }
        assert!(checked > 100, "{checked}");
    }

    #[test]
    fn a_sphere_is_one_lipschitz_and_jumps_have_no_bound() {
        let sphere = ssa(
            "x var-x\ny var-y\nz var-z\na square x\nb square y\nc square z\nd add a b\ne add d c\nf sqrt e\n",
        );
        let iv = Interval::new(0.5, 0.6);
        let l = lipschitz_bound(&sphere, iv, iv, iv, &mut Vec::new()).unwrap();
        // Per-axis maxima: within sqrt(3) of the true largest gradient (1 here).
        assert!((1.0..1.25).contains(&l), "{l}");
        // Across the origin sqrt's derivative is unbounded: no bound.
        let around = Interval::new(-0.1, 0.1);
        assert_eq!(lipschitz_bound(&sphere, around, around, around, &mut Vec::new()), None);
        let floor = ssa("x var-x\nf floor x\n");
        assert_eq!(lipschitz_bound(&floor, Interval::new(0.5, 1.5), ZERO, ZERO, &mut Vec::new()), None);
        assert_eq!(lipschitz_bound(&floor, Interval::new(0.2, 0.8), ZERO, ZERO, &mut Vec::new()), Some(0.0));
    }
}
