//! Pruning, the SDF counterpart of a BVH: per region of space, the [`Tape`] shortened to
//! the operations that can matter there ([`TapeRegions`]), as fidget and libfive do for
//! their tiles.
//!
//! # Interval bounds
//!
//! [`Bounds`] evaluates a tape over a box of points (relative to [`Tape::origin`]) in
//! interval arithmetic: point registers hold boxes, value registers intervals that contain
//! every value the register takes for a point in the box.
//! * Translations and affine maps are interval products, so the box a primitive sees
//!   contains every local point it can be asked about.
//! * A primitive's local distance is 1-Lipschitz in its local frame (exact distances, the
//!   ellipsoid's bound and the unsigned triangle all are), so over a local box of centre
//!   `c` and half diagonal `r` it lies within `f(c) +- r`, times the op's `scale`; the
//!   interval is widened by a relative `1e-5` for f32 rounding.
//! * A choice between two operands ([`Op::Min`], [`Op::Max`], [`Op::Subtract`] and the
//!   smooth blends) is decided where the intervals separate: a sharp minimum whose second
//!   operand is never below the first is the first; a polynomial smooth minimum is exactly
//!   the smaller operand where the two differ by at least its radius `k` (its blend weight
//!   `h` clamps to 0 or 1 there), and so on. Undecided, the result's interval is the
//!   operation's range over the two intervals (a smooth minimum lies at most `k / 4` below
//!   the smaller operand).
//! * Repetition cells ([`Op::Cells`], [`Op::CellFace`]) over an interval are a range of
//!   cells; a box that spans several makes the folded point's box wider, which is still
//!   sound.
//!
//! # Shortening
//!
//! A decided choice becomes [`Op::Copy`] (or [`Op::Neg`], a subtraction decided for its
//! second operand), and a backward liveness pass drops every operation whose result no
//! live register reads. The shortened tape computes, at any point of the box, the same
//! operations on the same values as the whole tape, minus blends whose weight is exactly 0
//! or 1 there: its value equals the whole tape's but for f32 rounding in those blends
//! (`b + (a - b) * 1` against `a`), well within [`Tape::error_bound`]. It is a tape of the
//! same registers and triangles, evaluated by [`Tape::eval_ops`] / [`Tape::eval8_ops`].
//!
//! # Regions
//!
//! [`TapeRegions`] covers the object's bounds with a uniform grid of cells (about
//! [`CELLS_PER_OP`] per tape operation, at most [`MAX_CELLS`]) and keeps each cell's
//! shortened tape, identical tapes stored once. A point looks its cell up by its relative coordinates, so a single
//! ray and a lane of a packet at the same point run the same operations and get the same
//! value bit for bit. Regions are kept only where they pay: when the shortened tapes are on
//! average at most [`KEEP_RATIO`] of the whole tape.

use std::collections::HashMap;

use glam::{UVec3, Vec3};

use crate::geometry::Aabb;
use crate::geometry::sdf::tape::{NO_REG, Op, Ops, Tape, TapeScratch, cell_index};

/// The most cells a [`TapeRegions`] grid has.
pub const MAX_CELLS: usize = 32_768;
/// Cells per tape operation a [`TapeRegions`] grid aims for.
pub const CELLS_PER_OP: usize = 32;
/// Regions are kept when their tapes average at most this fraction of the whole tape's
/// length (over the cells).
pub const KEEP_RATIO: f64 = 0.75;

/// A closed interval of f32 values, `lo <= hi` (or infinite ends).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// Lower end.
    pub lo: f32,
    /// Upper end.
    pub hi: f32,
}

impl Interval {
    const ZERO: Interval = Interval { lo: 0.0, hi: 0.0 };

    fn new(a: f32, b: f32) -> Self {
        Interval { lo: a.min(b), hi: a.max(b) }
    }

    fn add(self, c: f32) -> Self {
        Interval { lo: self.lo + c, hi: self.hi + c }
    }

    fn scale(self, c: f32) -> Self {
        Interval::new(self.lo * c, self.hi * c)
    }

    fn neg(self) -> Self {
        Interval { lo: -self.hi, hi: -self.lo }
    }

    fn sub(self, b: Interval) -> Self {
        Interval { lo: self.lo - b.hi, hi: self.hi - b.lo }
    }

    fn min(self, b: Interval) -> Self {
        Interval { lo: self.lo.min(b.lo), hi: self.hi.min(b.hi) }
    }

    fn max(self, b: Interval) -> Self {
        Interval { lo: self.lo.max(b.lo), hi: self.hi.max(b.hi) }
    }

    fn centre(self) -> f32 {
        0.5 * (self.lo + self.hi)
    }

    fn radius(self) -> f32 {
        0.5 * (self.hi - self.lo)
    }
}

/// What a region's intervals decided for a two-operand operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
enum Choice {
    /// Both operands can matter: the operation is kept.
    Both = 0,
    /// The result is the first operand.
    First,
    /// The result is the second operand.
    Second,
    /// The result is the second operand negated (a subtraction).
    SecondNegated,
}

/// The interval evaluator's registers, sized once for a tape and reused for every box.
pub struct Bounds {
    vals: Vec<Interval>,
    pts: Vec<[Interval; 3]>,
    choices: Vec<Choice>,
    scratch: TapeScratch,
    live_v: Vec<bool>,
    live_p: Vec<bool>,
}

impl Bounds {
    /// Registers for `tape`.
    pub fn new(tape: &Tape) -> Self {
        let (vals, points) = tape.registers();
        Bounds {
            vals: vec![Interval::ZERO; vals],
            pts: vec![[Interval::ZERO; 3]; points],
            choices: vec![Choice::Both; tape.ops().len()],
            scratch: TapeScratch::new(tape),
            live_v: Vec::new(),
            live_p: Vec::new(),
        }
    }

    /// The interval of `tape`'s value over the box `[lo, hi]` of relative points, deciding
    /// each choice on the way (kept for [`Bounds::shorten`]).
    pub fn eval(&mut self, tape: &Tape, lo: Vec3, hi: Vec3) -> Interval {
        self.pts[0] = [Interval::new(lo.x, hi.x), Interval::new(lo.y, hi.y), Interval::new(lo.z, hi.z)];
        for (i, op) in tape.ops().iter().enumerate() {
            self.choices[i] = Choice::Both;
            if let Some((p, out)) = op.primitive_registers() {
                let b = self.pts[p as usize];
                let centre = [b[0].centre(), b[1].centre(), b[2].centre()];
                let r = (b[0].radius().powi(2) + b[1].radius().powi(2) + b[2].radius().powi(2)).sqrt();
                let f = tape.primitive_at(op, centre, &mut self.scratch).unwrap_or(0.0);
                let scale = op.primitive_scale().unwrap_or(1.0).abs();
                let half = r * scale;
                let slack = 1e-5 * (f.abs() + half) + 1e-30;
                let iv = Interval { lo: f - half - slack, hi: f + half + slack };
                // A NaN (a degenerate primitive) bounds nothing: keep everything.
                self.vals[out as usize] = if iv.lo.is_nan() || iv.hi.is_nan() {
                    Interval { lo: f32::NEG_INFINITY, hi: f32::INFINITY }
                } else {
                    iv
                };
                continue;
            }
            match *op {
                Op::Translate { src, dst, t } => {
                    let q = self.pts[src as usize];
                    self.pts[dst as usize] = [q[0].add(t[0]), q[1].add(t[1]), q[2].add(t[2])];
                }
                Op::Affine { src, dst, m } => {
                    let q = self.pts[src as usize];
                    let row = |r: [f32; 4]| {
                        let mut acc = Interval { lo: r[3], hi: r[3] };
                        for j in 0..3 {
                            let s = q[j].scale(r[j]);
                            acc = Interval { lo: acc.lo + s.lo, hi: acc.hi + s.hi };
                        }
                        // Outward by the rounding of four f32 terms.
                        let slack = 4.0 * f32::EPSILON * (acc.lo.abs().max(acc.hi.abs()));
                        Interval { lo: acc.lo - slack, hi: acc.hi + slack }
                    };
                    self.pts[dst as usize] = [row(m[0]), row(m[1]), row(m[2])];
                }
                Op::Min { out, a, b } => {
                    let (x, y) = (self.vals[a as usize], self.vals[b as usize]);
                    // `if y < x { y } else { x }`
                    let (c, v) = if y.lo >= x.hi {
                        (Choice::First, x)
                    } else if y.hi < x.lo {
                        (Choice::Second, y)
                    } else {
                        (Choice::Both, x.min(y))
                    };
                    self.decide(i, out, c, v);
                }
                Op::Max { out, a, b } => {
                    let (x, y) = (self.vals[a as usize], self.vals[b as usize]);
                    // `if y > x { y } else { x }`
                    let (c, v) = if y.hi <= x.lo {
                        (Choice::First, x)
                    } else if y.lo > x.hi {
                        (Choice::Second, y)
                    } else {
                        (Choice::Both, x.max(y))
                    };
                    self.decide(i, out, c, v);
                }
                Op::Subtract { out, a, b } => {
                    let (x, ny) = (self.vals[a as usize], self.vals[b as usize].neg());
                    // `if -y > x { -y } else { x }`
                    let (c, v) = if ny.hi <= x.lo {
                        (Choice::First, x)
                    } else if ny.lo > x.hi {
                        (Choice::SecondNegated, ny)
                    } else {
                        (Choice::Both, x.max(ny))
                    };
                    self.decide(i, out, c, v);
                }
                Op::SmoothUnion { out, a, b, k, .. } => {
                    let (x, y) = (self.vals[a as usize], self.vals[b as usize]);
                    let (c, v) = smooth_min(x, y, k);
                    self.decide(i, out, c, v);
                }
                Op::SmoothIntersection { out, a, b, k, .. } => {
                    // -smin(-x, -y)
                    let (x, y) = (self.vals[a as usize], self.vals[b as usize]);
                    let (c, v) = smooth_min(x.neg(), y.neg(), k);
                    self.decide(i, out, c, v.neg());
                }
                Op::SmoothSubtraction { out, a, b, k, .. } => {
                    // -smin(-x, y)
                    let (x, y) = (self.vals[a as usize], self.vals[b as usize]);
                    let (c, v) = smooth_min(x.neg(), y, k);
                    let c = if c == Choice::Second { Choice::SecondNegated } else { c };
                    self.decide(i, out, c, v.neg());
                }
                Op::Scale { a, s } => {
                    self.vals[a as usize] = self.vals[a as usize].scale(s);
                }
                Op::Cells { p, axis, base, other, period, inv_period, shift, lo, hi } => {
                    let x = self.pts[p as usize][axis as usize].scale(inv_period);
                    let id = |x: f32| cell_index(x, shift, lo, hi);
                    let (id0, id1) = (id(x.lo), id(x.hi));
                    self.vals[base as usize] = Interval::new(id0 * period, id1 * period);
                    // The neighbour is on `x`'s side of the cell index (`id < x`: above): in
                    // one cell with `x` on one side, a single cell.
                    let (down, up) = if id0 != id1 {
                        (id0 - 1.0, id1 + 1.0)
                    } else if id0 < x.lo {
                        (id0 + 1.0, id0 + 1.0)
                    } else if x.hi <= id0 {
                        (id0 - 1.0, id0 - 1.0)
                    } else {
                        (id0 - 1.0, id0 + 1.0)
                    };
                    let (n0, n1) = (down.max(lo).min(hi), up.max(lo).min(hi));
                    self.vals[other as usize] = Interval::new(n0 * period, n1 * period);
                }
                Op::CellFace { p, axis, base, face, period, inv_period, shift, lo, hi, half_gap } => {
                    let v = self.pts[p as usize][axis as usize];
                    let x = v.scale(inv_period);
                    let id = |x: f32| cell_index(x, shift, lo, hi);
                    let (id0, id1) = (id(x.lo), id(x.hi));
                    self.vals[base as usize] = Interval::new(id0 * period, id1 * period);
                    // In one cell: the faces' distances over the box; across cells, a
                    // point is within its nearest cell, so the bound is at least the gap.
                    let none = Interval { lo: f32::INFINITY, hi: f32::INFINITY };
                    self.vals[face as usize] = if id0 == id1 {
                        let local = v.add(-(id0 * period));
                        let up = if id0 < hi { local.neg().add(half_gap) } else { none };
                        let down = if lo < id0 { local.add(half_gap) } else { none };
                        up.min(down)
                    } else {
                        Interval { lo: 0.0, hi: f32::INFINITY }
                    };
                }
                Op::Offset { src, dst, offs } => {
                    let q = self.pts[src as usize];
                    let mut r = q;
                    for j in 0..3 {
                        if offs[j] != NO_REG {
                            r[j] = q[j].sub(self.vals[offs[j] as usize]);
                        }
                    }
                    self.pts[dst as usize] = r;
                }
                Op::Copy { out, a } => self.vals[out as usize] = self.vals[a as usize],
                Op::Neg { out, a } => self.vals[out as usize] = self.vals[a as usize].neg(),
                _ => unreachable!("primitives are handled above"),
            }
        }
        self.vals[0]
    }

    fn decide(&mut self, i: usize, out: u32, c: Choice, v: Interval) {
        self.choices[i] = c;
        self.vals[out as usize] = v;
    }

    /// The operations of `tape` that matter over the box of the last [`Bounds::eval`], in
    /// order, written to `out` as `index * 4 + choice` (`choice` 0: the operation as it is,
    /// else the copy that replaces a decided choice, see [`replacement`]): decided choices
    /// replaced, dead operations dropped (see the module documentation).
    pub fn shorten(&mut self, tape: &Tape, out: &mut Vec<u32>) {
        let ops = tape.ops();
        self.live_v.clear();
        self.live_v.resize(tape.registers().0, false);
        self.live_p.clear();
        self.live_p.resize(tape.registers().1, false);
        self.live_v[0] = true;
        out.clear();
        for (i, op) in ops.iter().enumerate().rev() {
            let choice = self.choices[i];
            let op = match replacement(op, choice) {
                Some(None) => continue,
                Some(Some(copy)) => copy,
                None => *op,
            };
            if !kill_if_live(&op, &mut self.live_v, &mut self.live_p) {
                continue;
            }
            mark_inputs(&op, &mut self.live_v, &mut self.live_p);
            out.push(i as u32 * 4 + choice as u32);
        }
        out.reverse();
    }
}

/// What replaces choice operation `op` decided as `choice`: `None` when it is kept
/// ([`Choice::Both`]), `Some(None)` when it is a no-op (the result is already in place),
/// else the copy.
fn replacement(op: &Op, choice: Choice) -> Option<Option<Op>> {
    if choice == Choice::Both {
        return None;
    }
    let (o, a, b) = operands(op);
    Some(match choice {
        Choice::First if o == a => None,
        Choice::First => Some(Op::Copy { out: o, a }),
        Choice::Second => Some(Op::Copy { out: o, a: b }),
        _ => Some(Op::Neg { out: o, a: b }),
    })
}

/// The polynomial smooth minimum of radius `k` over two intervals: exactly `x` where
/// `y - x >= k` everywhere, `y` where `x - y >= k`, else within
/// `[min(x, y) - k / 4, min(x, y)]`.
fn smooth_min(x: Interval, y: Interval, k: f32) -> (Choice, Interval) {
    if y.lo - x.hi >= k {
        (Choice::First, x)
    } else if x.lo - y.hi >= k {
        (Choice::Second, y)
    } else {
        let m = x.min(y);
        (Choice::Both, Interval { lo: m.lo - 0.25 * k, hi: m.hi })
    }
}

/// `(out, a, b)` of a two-operand choice.
fn operands(op: &Op) -> (u32, u32, u32) {
    match *op {
        Op::Min { out, a, b }
        | Op::Max { out, a, b }
        | Op::Subtract { out, a, b }
        | Op::SmoothUnion { out, a, b, .. }
        | Op::SmoothIntersection { out, a, b, .. }
        | Op::SmoothSubtraction { out, a, b, .. } => (out, a, b),
        _ => unreachable!("only choices are decided"),
    }
}

/// Whether `op` writes a live register; if so, those registers are no longer live above it
/// (their earlier values are overwritten) — [`mark_inputs`] then makes what it reads live.
fn kill_if_live(op: &Op, live_v: &mut [bool], live_p: &mut [bool]) -> bool {
    match *op {
        Op::Translate { dst, .. } | Op::Affine { dst, .. } | Op::Offset { dst, .. } => {
            std::mem::replace(&mut live_p[dst as usize], false)
        }
        Op::Cells { base, other: second, .. } | Op::CellFace { base, face: second, .. } => {
            let l = live_v[base as usize] || live_v[second as usize];
            live_v[base as usize] = false;
            live_v[second as usize] = false;
            l
        }
        Op::Scale { a, .. } => live_v[a as usize],
        _ => {
            let out = match *op {
                Op::Copy { out, .. } | Op::Neg { out, .. } => out,
                ref o => o.primitive_registers().map_or_else(|| operands(o).0, |(_, out)| out),
            };
            std::mem::replace(&mut live_v[out as usize], false)
        }
    }
}

/// Marks the registers `op` reads as live.
fn mark_inputs(op: &Op, live_v: &mut [bool], live_p: &mut [bool]) {
    match *op {
        Op::Translate { src, .. } | Op::Affine { src, .. } => live_p[src as usize] = true,
        Op::Offset { src, offs, .. } => {
            live_p[src as usize] = true;
            for o in offs {
                if o != NO_REG {
                    live_v[o as usize] = true;
                }
            }
        }
        Op::Cells { p, .. } | Op::CellFace { p, .. } => live_p[p as usize] = true,
        Op::Scale { a, .. } | Op::Copy { a, .. } | Op::Neg { a, .. } => live_v[a as usize] = true,
        ref o => match o.primitive_registers() {
            Some((p, _)) => live_p[p as usize] = true,
            None => {
                let (_, a, b) = operands(o);
                live_v[a as usize] = true;
                live_v[b as usize] = true;
            }
        },
    }
}

/// Shortened tapes per cell of a uniform grid over an object's bounds (see the module
/// documentation). A shortened tape is a list of 16-bit indices into `ops`: the whole
/// tape's operations followed by the copies that replace decided choices.
#[derive(Clone, Debug)]
pub struct TapeRegions {
    /// Lower corner of the grid, relative to [`Tape::origin`], world units.
    lo: Vec3,
    /// Cells per world unit along each axis.
    inv_cell: Vec3,
    /// Cells per axis, each `>= 1`.
    n: UVec3,
    /// Index into `orders` of each cell, `x` fastest.
    cell_tape: Vec<u32>,
    /// The tape's operations, then the replacement copies.
    ops: Vec<Op>,
    /// The distinct shortened tapes, as indices into `ops`.
    orders: Vec<Box<[u16]>>,
    /// The mean shortened length as a fraction of the whole tape's, over the cells.
    mean_ratio: f64,
}

impl TapeRegions {
    /// Regions over `bounds` (world) for `tape`, or `None` when they would not pay
    /// ([`KEEP_RATIO`]), the bounds are not finite, or the tape is too long for 16-bit
    /// indices.
    pub fn build(tape: &Tape, bounds: Aabb) -> Option<Self> {
        // Cells per unit of work: a sphere that carries its translation counts as the two
        // operations it stands for.
        let work = tape
            .ops()
            .iter()
            .map(|op| 1 + matches!(op, Op::Sphere { t, .. } if *t != [0.0; 3]) as usize)
            .sum::<usize>();
        let target = (work * CELLS_PER_OP).clamp(64, MAX_CELLS);
        Self::with_cells(tape, bounds, target).filter(|r| r.mean_ratio <= KEEP_RATIO)
    }

    /// Regions over `bounds` (world) for `tape` in a grid of about `target` cells (at most
    /// 64 per axis), whatever they save; `None` when the bounds are not finite or the tape
    /// is too short (under 4 operations) or too long for 16-bit indices.
    pub fn with_cells(tape: &Tape, bounds: Aabb, target: usize) -> Option<Self> {
        let whole = tape.ops().len();
        if !bounds.valid() || whole < 4 || 4 * whole > u16::MAX as usize {
            return None;
        }
        let origin = tape.origin;
        let lo = (Vec3::from(bounds.min).as_dvec3() - origin).as_vec3();
        let hi = (Vec3::from(bounds.max).as_dvec3() - origin).as_vec3();
        let ext = (hi - lo).max(Vec3::splat(1e-6 * (hi - lo).max_element().max(1e-30)));
        if !ext.is_finite() {
            return None;
        }
        let cell = (ext.x * ext.y * ext.z / target.max(1) as f32).cbrt();
        let n = (ext / cell).ceil().max(Vec3::ONE).as_uvec3().min(UVec3::splat(64));
        let size = ext / n.as_vec3();
        let mut bounds_eval = Bounds::new(tape);
        let mut ops: Vec<Op> = tape.ops().to_vec();
        let mut copies: HashMap<u32, u16> = HashMap::new();
        let mut index: HashMap<Box<[u16]>, u32> = HashMap::new();
        let mut orders: Vec<Box<[u16]>> = Vec::new();
        let mut cell_tape = Vec::with_capacity((n.x * n.y * n.z) as usize);
        let (mut picked, mut order) = (Vec::new(), Vec::new());
        let mut total_ops = 0usize;
        // Each cell's box is widened by a little more than the rounding of the lookup, so
        // that every point that looks the cell up lies in the box its tape was made for.
        let pad = size * 1e-4 + Vec3::splat(1e-6 * (lo.abs().max(hi.abs())).max_element());
        for z in 0..n.z {
            for y in 0..n.y {
                for x in 0..n.x {
                    let c0 = lo + size * UVec3::new(x, y, z).as_vec3();
                    bounds_eval.eval(tape, c0 - pad, c0 + size + pad);
                    bounds_eval.shorten(tape, &mut picked);
                    total_ops += picked.len();
                    order.clear();
                    for &code in &picked {
                        let (i, choice) = ((code / 4) as usize, code % 4);
                        if choice == 0 {
                            order.push(i as u16);
                            continue;
                        }
                        let at = *copies.entry(code).or_insert_with(|| {
                            let c = [Choice::Both, Choice::First, Choice::Second, Choice::SecondNegated]
                                [choice as usize];
                            let copy = replacement(&tape.ops()[i], c).flatten().expect("a kept copy");
                            ops.push(copy);
                            (ops.len() - 1) as u16
                        });
                        order.push(at);
                    }
                    let id = match index.get(order.as_slice()) {
                        Some(&id) => id,
                        None => {
                            let id = orders.len() as u32;
                            orders.push(order.clone().into_boxed_slice());
                            index.insert(order.clone().into_boxed_slice(), id);
                            id
                        }
                    };
                    cell_tape.push(id);
                }
            }
        }
        let mean_ratio = total_ops as f64 / (cell_tape.len() * whole) as f64;
        Some(TapeRegions { lo, inv_cell: size.recip(), n, cell_tape, ops, orders, mean_ratio })
    }

    /// The cell holding relative point `p_rel`, `None` outside the grid (or for NaN).
    #[inline]
    pub fn cell(&self, p_rel: Vec3) -> Option<u32> {
        let q = (p_rel - self.lo) * self.inv_cell;
        let n = self.n.as_vec3();
        if !(q.x >= 0.0 && q.y >= 0.0 && q.z >= 0.0 && q.x < n.x && q.y < n.y && q.z < n.z) {
            return None;
        }
        let c = q.as_uvec3().min(self.n - UVec3::ONE);
        Some(c.x + self.n.x * (c.y + self.n.y * c.z))
    }

    /// The shortened tape of cell `cell` (from [`TapeRegions::cell`]).
    #[inline]
    pub fn ops(&self, cell: u32) -> Ops<'_> {
        self.tape(self.tape_of(cell))
    }

    /// Which distinct shortened tape cell `cell` runs (cells with equal tapes share one).
    #[inline]
    pub fn tape_of(&self, cell: u32) -> u32 {
        self.cell_tape[cell as usize]
    }

    /// Distinct shortened tape `tape` (from [`TapeRegions::tape_of`]).
    #[inline]
    pub fn tape(&self, tape: u32) -> Ops<'_> {
        Ops::Picked { ops: &self.ops, order: &self.orders[tape as usize] }
    }

    /// Cells per axis.
    pub fn cells(&self) -> UVec3 {
        self.n
    }

    /// Distinct shortened tapes.
    pub fn distinct(&self) -> usize {
        self.orders.len()
    }

    /// The mean shortened tape's length as a fraction of the whole tape's, over the cells.
    pub fn mean_ratio(&self) -> f64 {
        self.mean_ratio
    }

    /// Bytes held.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.cell_tape.len() * 4
            + self.ops.len() * std::mem::size_of::<Op>()
            + self.orders.iter().map(|t| t.len() * 2 + 16).sum::<usize>()
    }
}
