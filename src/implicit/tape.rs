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
        let n = self.clauses.len();
        alias.clear();
        alias.extend(0..n as u32);
        // Forward: a decided clause becomes the clause it equals.
        for (i, c) in self.clauses.iter().enumerate() {
            let (a, b) = (alias[c.a as usize], alias[c.b as usize]);
            let (ia, ib) = (iv[c.a as usize], iv[c.b as usize]);
            let pick = match c.op {
                _ if ia.nan || (c.op.arity() == 2 && ib.nan) => None,
                Opcode::Copy => Some(a),
                Opcode::Min if ia.hi < ib.lo => Some(a),
                Opcode::Min if ib.hi < ia.lo => Some(b),
                Opcode::Max if ia.lo > ib.hi => Some(a),
                Opcode::Max if ib.lo > ia.hi => Some(b),
                Opcode::And if !ia.contains(0.0) => Some(b),
                Opcode::Or if !ia.contains(0.0) => Some(a),
                Opcode::Or if ia.lo == 0.0 && ia.hi == 0.0 => Some(b),
                _ => None,
            };
            if let Some(p) = pick {
                alias[i] = p;
            }
        }
        // Backward: which clauses the output needs.
        live.clear();
        live.resize(n, false);
        if n == 0 {
            out.clauses.clear();
            return;
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
        // Emit the live clauses, renumbered; `alias` now maps old to new indices.
        out.clauses.clear();
        let mut new_index = std::mem::take(alias);
        let old_alias = new_index.clone();
        for i in 0..n {
            if live[i] && old_alias[i] == i as u32 {
                let mut c = self.clauses[i];
                let k = c.op.arity();
                c.a = if k >= 1 { new_index[old_alias[c.a as usize] as usize] } else { 0 };
                c.b = if k == 2 { new_index[old_alias[c.b as usize] as usize] } else { 0 };
                new_index[i] = out.clauses.len() as u32;
                out.clauses.push(c);
            }
        }
        // The output is the last emitted clause: the alias of the old output is live and
        // emitted last among the live ones only if nothing after it is live, which holds
        // since every live clause is needed by it and so comes before it.
        *alias = new_index;
    }
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
