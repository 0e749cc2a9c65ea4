//! A `.vm` program as SSA clauses ([`Ssa`]: clause `i` defines value `i`, arguments name
//! earlier clauses), its shortening over a region ([`Ssa::shorten`]: a `min`/`max` whose
//! intervals do not overlap becomes its winning argument, `and`/`or`/`compare` decided by
//! intervals likewise, then every clause the output no longer needs is dropped), and the
//! register form ([`Tape`]) evaluated [`LANES`] points at a time in f32 without allocating.

use super::interval::Interval;
use super::ops::{Opcode, apply_f32, apply_f64};

/// Points evaluated together by [`Tape::eval`].
pub const LANES: usize = 64;

/// One clause: `op` over the values of clauses `a` and `b` (unused ones 0), or the
/// constant `value`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clause {
    /// The opcode.
    pub op: Opcode,
    /// First argument (clause index).
    pub a: u32,
    /// Second argument (clause index).
    pub b: u32,
    /// The constant of a `const` clause.
    pub value: f64,
}

/// A program in SSA form; the last clause is the output.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Ssa {
    /// The clauses, each after its arguments.
    pub clauses: Vec<Clause>,
}

impl Ssa {
    /// Whether any live clause reads `var-z` (a 3D model).
    pub fn uses_z(&self) -> bool {
        self.clauses.iter().any(|c| c.op == Opcode::VarZ)
    }

    /// The f64 value at `(x, y, z)` (the reference; allocates one value per clause).
    pub fn eval_f64(&self, p: [f64; 3]) -> f64 {
        let mut v = Vec::with_capacity(self.clauses.len());
        self.eval_f64_into(p, &mut v)
    }

    /// [`Ssa::eval_f64`] reusing `v` as storage.
    pub fn eval_f64_into(&self, p: [f64; 3], v: &mut Vec<f64>) -> f64 {
        v.clear();
        for c in &self.clauses {
            let r = match c.op {
                Opcode::VarX => p[0],
                Opcode::VarY => p[1],
                Opcode::VarZ => p[2],
                Opcode::Const => c.value,
                op => apply_f64(op, v[c.a as usize], v[c.b as usize]),
            };
            v.push(r);
        }
        v.last().copied().unwrap_or(f64::NAN)
    }

    /// The interval of every clause over the box `x`, `y`, `z`, into `out`; returns the
    /// output's.
    pub fn eval_interval(&self, x: Interval, y: Interval, z: Interval, out: &mut Vec<Interval>) -> Interval {
        out.clear();
        for c in &self.clauses {
            let r = match c.op {
                Opcode::VarX => x,
                Opcode::VarY => y,
                Opcode::VarZ => z,
                Opcode::Const => Interval::point(c.value),
                op => Interval::apply(op, out[c.a as usize], out[c.b as usize]),
            };
            out.push(r);
        }
        out.last().copied().unwrap_or(Interval::point(f64::NAN))
    }

    /// This program over a region where the clauses have the intervals `iv` (from
    /// [`Ssa::eval_interval`]): equal to it at every point of the region, into `out`.
    /// `alias` and `live` are scratch.
    pub fn shorten(&self, iv: &[Interval], out: &mut Ssa, alias: &mut Vec<u32>, live: &mut Vec<bool>) {
        let mut index = Vec::new();
        self.shorten_with(|j| iv[j], out, alias, live, &mut index, false);
    }

    /// [`Ssa::eval_interval`], the same intervals, with the common opcodes inlined
    /// ([`Interval::apply_inline`]) and `out` written in place (no allocation once it has
    /// grown to the program's length).
    pub fn eval_interval_fast(
        &self,
        x: Interval,
        y: Interval,
        z: Interval,
        out: &mut Vec<Interval>,
    ) -> Interval {
        let n = self.clauses.len();
        if n == 0 {
            out.clear();
            return Interval::point(f64::NAN);
        }
        out.resize(n, Interval::new(0.0, 0.0));
        for (i, c) in self.clauses.iter().enumerate() {
            let r = match c.op {
                Opcode::VarX => x,
                Opcode::VarY => y,
                Opcode::VarZ => z,
                Opcode::Const => Interval::point(c.value),
                op => Interval::apply_inline(op, out[c.a as usize], out[c.b as usize]),
            };
            out[i] = r;
        }
        out[n - 1]
    }

    /// [`Ssa::shorten`] when the intervals decide some clause: then the shortened program
    /// goes to `out` and the answer is true. When they decide none, `out` is left alone and
    /// the answer is false: a program without dead clauses (as every shortened one) is then
    /// already what shortening would give.
    pub fn shorten_decided(&self, iv: &[Interval], out: &mut Ssa, s: &mut ShortenScratch) -> bool {
        self.shorten_with(|j| iv[j], out, &mut s.alias, &mut s.live, &mut s.index, true)
    }

    /// The intervals of every clause over `L` boxes at once (box `k`: `x[k]`, `y[k]`,
    /// `z[k]`), into `out`: `out[i * L + k]` is clause `i` over box `k`, the interval
    /// [`Ssa::eval_interval`] gives for that box alone. One pass over the program for `L`
    /// boxes (the sub-tiles of a tile): each opcode is dispatched once for all of them.
    pub fn eval_interval_lanes<const L: usize>(
        &self,
        x: &[Interval; L],
        y: &[Interval; L],
        z: &[Interval; L],
        out: &mut Vec<Interval>,
    ) {
        self.eval_interval_lanes_inner::<L, false>(x, y, z, out, &mut Vec::new());
    }

    /// [`Ssa::eval_interval_lanes`] that also records, per clause and box, what shortening
    /// decides there (`choices[i * L + k]`: 0 nothing, 1 the clause is its first argument,
    /// 2 its second; written for `copy`, `min`, `max`, `and` and `or` clauses only), for
    /// [`Ssa::shorten_chosen`]. Returns, per box, how many clauses are decided there.
    pub fn eval_interval_choices<const L: usize>(
        &self,
        x: &[Interval; L],
        y: &[Interval; L],
        z: &[Interval; L],
        out: &mut Vec<Interval>,
        choices: &mut Vec<u8>,
    ) -> [u32; L] {
        self.eval_interval_lanes_inner::<L, true>(x, y, z, out, choices)
    }

    #[inline(always)]
    fn eval_interval_lanes_inner<const L: usize, const CHOICES: bool>(
        &self,
        x: &[Interval; L],
        y: &[Interval; L],
        z: &[Interval; L],
        out: &mut Vec<Interval>,
        choices: &mut Vec<u8>,
    ) -> [u32; L] {
        let n = self.clauses.len();
        out.resize(n * L, Interval::new(0.0, 0.0));
        if CHOICES {
            choices.resize(n * L, 0);
        }
        let mut counts = [0u32; L];
        for (i, c) in self.clauses.iter().enumerate() {
            let (done, rest) = out.split_at_mut(i * L);
            let dst: &mut [Interval; L] = (&mut rest[..L]).try_into().expect("L lanes");
            match c.op {
                Opcode::VarX => *dst = *x,
                Opcode::VarY => *dst = *y,
                Opcode::VarZ => *dst = *z,
                Opcode::Const => *dst = [Interval::point(c.value); L],
                op => {
                    let (a, b) = (c.a as usize * L, c.b as usize * L);
                    let a: &[Interval; L] = done[a..a + L].try_into().expect("L lanes");
                    // A unary clause's `b` is 0, a clause before it.
                    let b: &[Interval; L] = done[b..b + L].try_into().expect("L lanes");
                    interval_lanes(op, a, b, dst);
                    if CHOICES && is_choice(op) {
                        let ch: &mut [u8; L] = (&mut choices[i * L..i * L + L]).try_into().expect("L lanes");
                        for k in 0..L {
                            ch[k] = choose(op, a[k], b[k]);
                            counts[k] += (ch[k] != 0) as u32;
                        }
                    }
                }
            }
        }
        counts
    }

    /// This program shortened for box `lane` of the choices recorded by
    /// [`Ssa::eval_interval_choices`] with `L` boxes, into `out`: what [`Ssa::shorten`] gives
    /// for that box's intervals, in two passes (needed clauses backward, then the kept ones
    /// renumbered forward). Call it only for a box where some clause is decided.
    pub fn shorten_chosen<const L: usize>(
        &self,
        choices: &[u8],
        lane: usize,
        out: &mut Ssa,
        s: &mut ShortenScratch,
    ) {
        let n = self.clauses.len();
        out.clauses.clear();
        if n == 0 {
            return;
        }
        // state: 0 not needed, 1 kept, 2 replaced by its first argument, 3 by its second.
        // Both passes are branch-free: whether a clause is needed is as good as random.
        let state = &mut s.index;
        state.clear();
        state.resize(n, 0);
        state[n - 1] = 1;
        for i in (0..n).rev() {
            let c = &self.clauses[i];
            let live = state[i] != 0;
            let ch = if is_choice(c.op) { choices[i * L + lane] } else { CHOSE_NONE };
            let k = c.op.arity();
            // A clause without arguments has a = b = 0 and marks nothing.
            let mark_a = live && ch != CHOSE_B && k >= 1;
            let mark_b = live && ch != CHOSE_A && k == 2;
            state[c.a as usize] |= mark_a as u32;
            state[c.b as usize] |= mark_b as u32;
            state[i] = live as u32 * (1 + ch as u32);
        }
        // Forward: `alias` holds each needed clause's new index (that of the clause it equals).
        let new_index = &mut s.alias;
        new_index.clear();
        new_index.resize(n, 0);
        out.clauses.resize(n, Clause { op: Opcode::Const, a: 0, b: 0, value: 0.0 });
        let mut len = 0usize;
        for i in 0..n {
            let c = self.clauses[i];
            let k = c.op.arity();
            let (na, nb) = (new_index[c.a as usize], new_index[c.b as usize]);
            let st = state[i];
            new_index[i] = match st {
                2 => na,
                3 => nb,
                _ => len as u32,
            };
            out.clauses[len] = Clause { a: if k >= 1 { na } else { 0 }, b: if k == 2 { nb } else { 0 }, ..c };
            len += (st == 1) as usize;
        }
        out.clauses.truncate(len);
    }

    #[inline(always)]
    fn shorten_with(
        &self,
        iv: impl Fn(usize) -> Interval,
        out: &mut Ssa,
        alias: &mut Vec<u32>,
        live: &mut Vec<bool>,
        new_index: &mut Vec<u32>,
        only_if_decided: bool,
    ) -> bool {
        let n = self.clauses.len();
        alias.clear();
        alias.extend(0..n as u32);
        // Forward: a decided clause becomes the clause it equals.
        let mut decided = false;
        for (i, c) in self.clauses.iter().enumerate() {
            let (a, b) = (alias[c.a as usize], alias[c.b as usize]);
            if !is_choice(c.op) {
                continue;
            }
            let pick = match choose(c.op, iv(c.a as usize), iv(c.b as usize)) {
                CHOSE_A => Some(a),
                CHOSE_B => Some(b),
                _ => None,
            };
            if let Some(p) = pick {
                alias[i] = p;
                decided = true;
            }
        }
        if only_if_decided && !decided {
            return false;
        }
        // Backward: which clauses the output needs.
        live.clear();
        live.resize(n, false);
        out.clauses.clear();
        if n == 0 {
            return true;
        }
        live[alias[n - 1] as usize] = true;
        for i in (0..n).rev() {
            if live[i] && alias[i] == i as u32 {
                let c = self.clauses[i];
                let k = c.op.arity();
                if k >= 1 {
                    live[alias[c.a as usize] as usize] = true;
                }
                if k == 2 {
                    live[alias[c.b as usize] as usize] = true;
                }
            }
        }
        // Emit the live clauses, renumbered through `new_index` (old to new indices).
        new_index.clear();
        new_index.resize(n, 0);
        for i in 0..n {
            if live[i] && alias[i] == i as u32 {
                let mut c = self.clauses[i];
                let k = c.op.arity();
                c.a = if k >= 1 { new_index[alias[c.a as usize] as usize] } else { 0 };
                c.b = if k == 2 { new_index[alias[c.b as usize] as usize] } else { 0 };
                new_index[i] = out.clauses.len() as u32;
                out.clauses.push(c);
            }
        }
        // The output is the last emitted clause: the alias of the old output is live and
        // emitted last among the live ones only if nothing after it is live, which holds
        // since every live clause is needed by it and so comes before it.
        true
    }
}

/// What [`Ssa::shorten`] decides for a clause: nothing.
const CHOSE_NONE: u8 = 0;
/// The clause equals its first argument over the region.
const CHOSE_A: u8 = 1;
/// The clause equals its second argument over the region.
const CHOSE_B: u8 = 2;

/// Whether shortening may replace a clause of `op` by one of its arguments.
#[inline(always)]
fn is_choice(op: Opcode) -> bool {
    matches!(op, Opcode::Copy | Opcode::Min | Opcode::Max | Opcode::And | Opcode::Or)
}

/// Which argument a clause of `op` (a choice, [`is_choice`]) equals over a region where its
/// arguments have the intervals `ia` and `ib`.
#[inline(always)]
fn choose(op: Opcode, ia: Interval, ib: Interval) -> u8 {
    match op {
        _ if ia.nan || (op.arity() == 2 && ib.nan) => CHOSE_NONE,
        Opcode::Copy => CHOSE_A,
        Opcode::Min if ia.hi < ib.lo => CHOSE_A,
        Opcode::Min if ib.hi < ia.lo => CHOSE_B,
        Opcode::Max if ia.lo > ib.hi => CHOSE_A,
        Opcode::Max if ib.lo > ia.hi => CHOSE_B,
        Opcode::And if !ia.contains(0.0) => CHOSE_B,
        Opcode::Or if !ia.contains(0.0) => CHOSE_A,
        Opcode::Or if ia.lo == 0.0 && ia.hi == 0.0 => CHOSE_B,
        _ => CHOSE_NONE,
    }
}

/// `op` over `L` lanes of intervals, each as [`Interval::apply`]; the opcode dispatched
/// once, the common ones inlined.
#[inline(always)]
fn interval_lanes<const L: usize>(op: Opcode, a: &[Interval; L], b: &[Interval; L], d: &mut [Interval; L]) {
    macro_rules! each {
        ($op:expr) => {
            for k in 0..L {
                d[k] = Interval::apply_inline($op, a[k], b[k]);
            }
        };
    }
    match op {
        Opcode::Add => each!(Opcode::Add),
        Opcode::Sub => each!(Opcode::Sub),
        Opcode::Mul => each!(Opcode::Mul),
        Opcode::Min => each!(Opcode::Min),
        Opcode::Max => each!(Opcode::Max),
        Opcode::Neg => each!(Opcode::Neg),
        Opcode::Square => each!(Opcode::Square),
        Opcode::Sqrt => each!(Opcode::Sqrt),
        Opcode::Abs => each!(Opcode::Abs),
        op => {
            for k in 0..L {
                d[k] = Interval::apply(op, a[k], b[k]);
            }
        }
    }
}

/// Scratch of [`Ssa::shorten_decided`], kept per thread so that shortening does not allocate.
#[derive(Clone, Debug, Default)]
pub struct ShortenScratch {
    alias: Vec<u32>,
    live: Vec<bool>,
    index: Vec<u32>,
}

/// One instruction of a [`Tape`]: registers instead of clause indices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instr {
    /// The opcode.
    pub op: Opcode,
    /// Output register.
    pub out: u32,
    /// First argument register.
    pub a: u32,
    /// Second argument register.
    pub b: u32,
    /// The constant of a `const` instruction, rounded to f32.
    pub value: f32,
}

/// A program with registers allocated (a register is reused once its value is dead).
#[derive(Clone, Debug, Default)]
pub struct Tape {
    /// The instructions.
    pub instrs: Vec<Instr>,
    /// Registers used.
    pub registers: usize,
    /// Register of the output.
    pub output: u32,
}

impl Tape {
    /// `ssa` with registers allocated; `last_use` and `free` are scratch.
    pub fn allocate_into(
        &mut self,
        ssa: &Ssa,
        last_use: &mut Vec<u32>,
        reg_of: &mut Vec<u32>,
        free: &mut Vec<u32>,
    ) {
        let n = ssa.clauses.len();
        last_use.clear();
        last_use.resize(n, 0);
        for (i, c) in ssa.clauses.iter().enumerate() {
            let k = c.op.arity();
            last_use[i] = i as u32;
            if k >= 1 {
                last_use[c.a as usize] = i as u32;
            }
            if k == 2 {
                last_use[c.b as usize] = i as u32;
            }
        }
        if n > 0 {
            last_use[n - 1] = u32::MAX;
        }
        reg_of.clear();
        reg_of.resize(n, 0);
        free.clear();
        self.instrs.clear();
        self.registers = 0;
        for (i, c) in ssa.clauses.iter().enumerate() {
            let k = c.op.arity();
            let a = if k >= 1 { reg_of[c.a as usize] } else { 0 };
            let b = if k == 2 { reg_of[c.b as usize] } else { 0 };
            // Arguments that die here free their registers before the output takes one
            // (the evaluator reads its arguments before it writes).
            if k >= 1 && last_use[c.a as usize] == i as u32 {
                free.push(a);
            }
            if k == 2 && last_use[c.b as usize] == i as u32 && c.b != c.a {
                free.push(b);
            }
            let out = free.pop().unwrap_or_else(|| {
                self.registers += 1;
                self.registers as u32 - 1
            });
            reg_of[i] = out;
            if last_use[i] == i as u32 {
                free.push(out);
            }
            self.instrs.push(Instr { op: c.op, out, a, b, value: c.value as f32 });
        }
        self.output = if n > 0 { reg_of[n - 1] } else { 0 };
    }

    /// `ssa` with registers allocated.
    pub fn allocate(ssa: &Ssa) -> Tape {
        let mut t = Tape::default();
        t.allocate_into(ssa, &mut Vec::new(), &mut Vec::new(), &mut Vec::new());
        t
    }

    /// The f32 values at [`LANES`] points, into `out`; `regs` is resized to fit (no
    /// allocation once it has).
    pub fn eval(
        &self,
        xs: &[f32; LANES],
        ys: &[f32; LANES],
        zs: &[f32; LANES],
        regs: &mut Vec<f32>,
        out: &mut [f32; LANES],
    ) {
        if regs.len() < self.registers * LANES {
            regs.resize(self.registers * LANES, 0.0);
        }
        if self.instrs.is_empty() {
            *out = [f32::NAN; LANES];
            return;
        }
        let mut a = [0f32; LANES];
        let mut b = [0f32; LANES];
        for ins in &self.instrs {
            let o = ins.out as usize * LANES;
            let dst: &mut [f32; LANES] = (&mut regs[o..o + LANES]).try_into().expect("LANES");
            match ins.op {
                Opcode::VarX => *dst = *xs,
                Opcode::VarY => *dst = *ys,
                Opcode::VarZ => *dst = *zs,
                Opcode::Const => *dst = [ins.value; LANES],
                op => {
                    let ra = ins.a as usize * LANES;
                    a.copy_from_slice(&regs[ra..ra + LANES]);
                    if op.arity() == 2 {
                        let rb = ins.b as usize * LANES;
                        b.copy_from_slice(&regs[rb..rb + LANES]);
                    }
                    let dst: &mut [f32; LANES] = (&mut regs[o..o + LANES]).try_into().expect("LANES");
                    lanes(op, &a, &b, dst);
                }
            }
        }
        let o = self.output as usize * LANES;
        out.copy_from_slice(&regs[o..o + LANES]);
    }
}

/// A [`Tape`] with the storage its allocation and evaluation reuse (per thread: loading a
/// program and evaluating it allocate nothing once the vectors have grown).
#[derive(Clone, Debug, Default)]
pub struct TapeRunner {
    tape: Tape,
    last_use: Vec<u32>,
    reg_of: Vec<u32>,
    free: Vec<u32>,
    regs: Vec<f32>,
}

impl TapeRunner {
    /// Allocates `ssa`'s registers; [`Self::eval`] evaluates it from now on.
    pub fn load(&mut self, ssa: &Ssa) {
        self.tape.allocate_into(ssa, &mut self.last_use, &mut self.reg_of, &mut self.free);
    }

    /// [`Tape::eval`] of the loaded program.
    pub fn eval(&mut self, xs: &[f32; LANES], ys: &[f32; LANES], zs: &[f32; LANES], out: &mut [f32; LANES]) {
        self.tape.eval(xs, ys, zs, &mut self.regs, out);
    }
}

/// `op` lane by lane; the common arithmetic written out so that it vectorizes.
#[inline(always)]
fn lanes(op: Opcode, a: &[f32; LANES], b: &[f32; LANES], d: &mut [f32; LANES]) {
    macro_rules! each {
        (|$x:ident, $y:ident| $e:expr) => {
            for i in 0..LANES {
                let ($x, $y) = (a[i], b[i]);
                d[i] = $e;
            }
        };
    }
    match op {
        Opcode::Add => each!(|x, y| x + y),
        Opcode::Sub => each!(|x, y| x - y),
        Opcode::Mul => each!(|x, y| x * y),
        Opcode::Div => each!(|x, y| x / y),
        Opcode::Neg => each!(|x, _y| -x),
        Opcode::Square => each!(|x, _y| x * x),
        Opcode::Sqrt => each!(|x, _y| x.sqrt()),
        Opcode::Abs => each!(|x, _y| x.abs()),
        // NaN-propagating min and max, branch-free.
        Opcode::Min => each!(|x, y| if x < y || x.is_nan() { x } else { y }),
        Opcode::Max => each!(|x, y| if x > y || x.is_nan() { x } else { y }),
        op => each!(|x, y| apply_f32(op, x, y)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::implicit::vm::parse_vm;

    const MODEL: &str = "x var-x\ny var-y\nz var-z\nr const 0.5\nxx square x\nyy square y\nd add xx yy\n\
        s sqrt d\nc sub s r\nk const 0.2\nzz sub z k\nm max c zz\nw sin x\nv mul w y\nq min m v\no copy q\n";

    /// Boxes of the plane, some deciding `min`/`max` clauses of [`MODEL`] and some not.
    fn boxes() -> [(Interval, Interval, Interval); 4] {
        [
            (Interval::new(0.6, 0.8), Interval::new(0.6, 0.8), Interval::new(-0.1, 0.1)),
            (Interval::new(-2.0, 2.0), Interval::new(-2.0, 2.0), Interval::new(-2.0, 2.0)),
            (Interval::new(-0.1, 0.05), Interval::new(0.3, 0.31), Interval::new(0.5, 0.6)),
            (Interval::new(1.5, 1.6), Interval::new(-1.0, -0.9), Interval::new(0.0, 0.0)),
        ]
    }

    #[test]
    fn lanes_give_each_box_its_own_intervals_and_shortening() {
        let ssa = parse_vm(MODEL, "t.vm".as_ref()).unwrap();
        let b = boxes();
        let (x, y, z) = (b.map(|v| v.0), b.map(|v| v.1), b.map(|v| v.2));
        let (mut lanes, mut choices) = (Vec::new(), Vec::new());
        let counts = ssa.eval_interval_choices::<4>(&x, &y, &z, &mut lanes, &mut choices);
        let mut plain = Vec::new();
        ssa.eval_interval_lanes::<4>(&x, &y, &z, &mut plain);
        assert_eq!(lanes, plain);
        let mut scratch = ShortenScratch::default();
        let mut decided_somewhere = false;
        for k in 0..4 {
            let mut one = Vec::new();
            let v = ssa.eval_interval(x[k], y[k], z[k], &mut one);
            assert_eq!(v, lanes[(ssa.clauses.len() - 1) * 4 + k]);
            for (i, iv) in one.iter().enumerate() {
                assert_eq!(*iv, lanes[i * 4 + k], "clause {i}, box {k}");
            }
            let mut want = Ssa::default();
            ssa.shorten(&one, &mut want, &mut Vec::new(), &mut Vec::new());
            let mut got = Ssa::default();
            ssa.shorten_chosen::<4>(&choices, k, &mut got, &mut scratch);
            assert_eq!(got, want, "box {k}");
            let mut fast = Vec::new();
            assert_eq!(ssa.eval_interval_fast(x[k], y[k], z[k], &mut fast), v);
            assert_eq!(fast, one);
            let mut again = Ssa::default();
            // The whole program has no dead clause: when nothing is decided it is `want`.
            if ssa.shorten_decided(&one, &mut again, &mut scratch) {
                assert_eq!(again, want);
            } else {
                assert_eq!(ssa, want);
            }
            // The shortened program decides nothing more over its own box.
            let mut iv2 = Vec::new();
            want.eval_interval_fast(x[k], y[k], z[k], &mut iv2);
            assert!(!want.shorten_decided(&iv2, &mut again, &mut scratch), "box {k}");
            decided_somewhere |= counts[k] > 1;
        }
        assert!(decided_somewhere);
    }

    #[test]
    fn shortened_tape_agrees_inside_its_region_and_is_shorter() {
        let ssa = parse_vm(MODEL, "t.vm".as_ref()).unwrap();
        let mut iv = Vec::new();
        let (x, y, z) = (Interval::new(0.6, 0.8), Interval::new(0.6, 0.8), Interval::new(-0.1, 0.1));
        ssa.eval_interval(x, y, z, &mut iv);
        let mut short = Ssa::default();
        ssa.shorten(&iv, &mut short, &mut Vec::new(), &mut Vec::new());
        assert!(short.clauses.len() < ssa.clauses.len(), "{} clauses", short.clauses.len());
        let tape = Tape::allocate(&short);
        let full = Tape::allocate(&ssa);
        let mut xs = [0f32; LANES];
        let mut ys = [0f32; LANES];
        let mut zs = [0f32; LANES];
        for i in 0..LANES {
            xs[i] = 0.6 + 0.2 * (i % 8) as f32 / 7.0;
            ys[i] = 0.6 + 0.2 * (i / 8) as f32 / 7.0;
            zs[i] = -0.1 + 0.2 * i as f32 / 63.0;
        }
        let (mut o1, mut o2) = ([0f32; LANES], [0f32; LANES]);
        let mut regs = Vec::new();
        tape.eval(&xs, &ys, &zs, &mut regs, &mut o1);
        full.eval(&xs, &ys, &zs, &mut regs, &mut o2);
        for i in 0..LANES {
            let r = ssa.eval_f64([xs[i] as f64, ys[i] as f64, zs[i] as f64]);
            assert_eq!(o1[i], o2[i]);
            assert!((o1[i] as f64 - r).abs() < 1e-5, "{} vs {r}", o1[i]);
        }
        assert!(tape.registers < short.clauses.len());
    }
}
