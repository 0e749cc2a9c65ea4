//! A 3D model prepared for ray casting ([`Field3`]), and the first surface along a ray
//! found with a step that cannot cross a surface ([`Field3::first_root`]).
//!
//! The model is seen inside the cube [-1, 1]^3, as Fidget frames it: the solid is
//! `{f < 0}` within the cube (where it reaches the cube the cube's face closes it). The
//! cube is cut into `n^3` cells. Each cell is evaluated once in interval arithmetic: a
//! cell whose interval excludes 0 is all outside or all inside; every other cell keeps the
//! program shortened for it ([`Ssa::shorten`]) and, where one exists, a proven Lipschitz
//! bound `L` of that program over the cell ([`lipschitz_bound`]).
//!
//! A ray walks the cells it crosses (3D DDA). In a surface cell:
//! - with a bound `L`, it steps `f / L + tol`: the ball of radius `f / L` holds no surface
//!   (proven), so a step may pass over at most `tol` of the ray that was not proven empty
//!   (a sliver of the solid thinner than the hit tolerance). A point with `f <= 0` ends
//!   the walk; the root is bisected between it and the last point outside.
//! - without one (a jump or an unbounded derivative may lie in the cell), or after
//!   [`MAX_CELL_STEPS`] Lipschitz steps (a ray grazing the surface), the cell's piece of
//!   the ray is isolated by interval subdivision: a piece whose interval (of its bounding
//!   box) excludes 0 is skipped, any other is halved down to pieces of length `tol`, whose
//!   end values are evaluated; a sign change is bisected, and a leaf whose interval holds 0
//!   but whose ends are both outside is counted ([`RayWork::ambiguous_leaves`]): a surface
//!   there would be thinner than `tol` along the ray.
//!
//! No step is taken on the value alone: every skip is proven by an interval or a
//! Lipschitz bound, up to the stated `tol`.

use glam::DVec3;
use rayon::prelude::*;

use super::gradient::{Dual, lipschitz_bound};
use super::interval::Interval;
use super::tape::Ssa;

/// Default cells per axis of the cube.
pub const CELLS: usize = 32;

/// Lipschitz steps in one cell before its remaining piece is isolated by intervals.
pub const MAX_CELL_STEPS: u32 = 48;

/// A cell's Lipschitz bound `L` is used only where `L` times the cell's diagonal is at
/// most this many times the width of the cell's value interval (for a distance both are
/// about the same); a far weaker bound would only ever step by the tolerance.
pub const USEFUL_BOUND: f64 = 8.0;

/// Half the edge of the cube the model is seen in (`[-EXTENT, EXTENT]^3`).
pub const EXTENT: f64 = 1.0;

/// Cells are evaluated over their box grown by this much, so that a point computed just
/// outside its cell by rounding is still covered by the cell's shortened program.
pub(super) const PAD: f64 = 1e-9;

pub(super) const OUTSIDE: u32 = u32::MAX;
pub(super) const INSIDE: u32 = u32::MAX - 1;

/// A surface cell: the program shortened for it and its Lipschitz bound, if proven.
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    /// The model over the cell (equal to it at every point of the cell).
    pub ssa: Ssa,
    /// A proven Lipschitz bound over the cell; `None` where there is none.
    pub lipschitz: Option<f64>,
}

/// What the cells say about the model (for the report).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FieldSummary {
    /// Clauses of the model.
    pub clauses: usize,
    /// Cells per axis.
    pub cells: usize,
    /// Cells proven outside (interval above 0).
    pub outside: usize,
    /// Cells proven inside (interval below 0).
    pub inside: usize,
    /// Cells that may hold the surface.
    pub surface: usize,
    /// Surface cells with a proven Lipschitz bound that is used ([`USEFUL_BOUND`]).
    pub bounded: usize,
    /// Smallest, median and largest bound over the bounded cells (0 when none).
    pub lipschitz_min: f64,
    /// Median bound.
    pub lipschitz_median: f64,
    /// Largest bound.
    pub lipschitz_max: f64,
    /// Mean clauses of the surface cells' shortened programs.
    pub mean_region_clauses: f64,
}

impl FieldSummary {
    /// Whether the value itself is a distance bound in every surface cell (`L <= 1`):
    /// sphere tracing on the raw value would be safe.
    pub fn value_is_distance_bound(&self) -> bool {
        self.surface > 0 && self.bounded == self.surface && self.lipschitz_max <= 1.0 + 1e-9
    }

    /// Whether every surface cell has a proven Lipschitz bound (then `f / L` is a distance
    /// bound everywhere and no interval root isolation is needed, except for grazing rays).
    pub fn lipschitz_everywhere(&self) -> bool {
        self.bounded == self.surface
    }

    /// One line: the model's class and the cells' census.
    pub fn describe(&self) -> String {
        let class = if self.surface == 0 {
            "no surface in the cube".to_string()
        } else if self.value_is_distance_bound() {
            format!("its value is a distance bound (L <= {:.3} in every surface cell)", self.lipschitz_max)
        } else if self.lipschitz_everywhere() {
            format!(
                "not a distance (L from {:.3} to {:.3}, median {:.3}): marched by value / L",
                self.lipschitz_min, self.lipschitz_max, self.lipschitz_median
            )
        } else if self.bounded == 0 {
            format!(
                "not a distance: none of its {} surface cells has a useful Lipschitz bound (jumps, unbounded \
                 or huge derivatives): every one is isolated by interval subdivision along the ray",
                self.surface
            )
        } else {
            format!(
                "not a distance: {} of {} surface cells have no useful Lipschitz bound (jumps, unbounded \
                 or huge derivatives) and are isolated by interval subdivision; the others (L from {:.3} to {:.3}) \
                 are marched by value / L",
                self.surface - self.bounded,
                self.surface,
                self.lipschitz_min,
                self.lipschitz_max
            )
        };
        format!(
            "{} clauses; {}^3 cells: {} outside, {} inside, {} surface ({:.0} clauses each after \
             shortening); {class}",
            self.clauses, self.cells, self.outside, self.inside, self.surface, self.mean_region_clauses
        )
    }
}

/// A 3D model prepared for ray casting (see the module header).
#[derive(Clone, Debug, PartialEq)]
pub struct Field3 {
    /// The whole model.
    pub ssa: Ssa,
    /// Cells per axis.
    pub n: usize,
    /// Per cell (x fastest): [`OUTSIDE`], [`INSIDE`] or an index into `regions`.
    pub(super) cells: Vec<u32>,
    /// The surface cells' programs.
    pub(super) regions: Vec<Region>,
    /// The census.
    pub summary: FieldSummary,
    /// What its preparation took ([`super::load_field`]; `None` where it was not measured).
    pub preparation: Option<Preparation>,
}

/// What preparing a model took, measured when the model is loaded: the runs of an input
/// share the prepared model, so `compare` counts it in each run's build time and heap peak as
/// if the run had prepared the model itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Preparation {
    /// Wall time, milliseconds.
    pub ms: f64,
    /// The heap, where the counting allocator is installed.
    pub heap: Option<PreparedHeap>,
}

/// The heap of a [`Preparation`], in bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PreparedHeap {
    /// The most heap the preparation held at once (its scratch included).
    pub peak: u64,
    /// The heap the prepared model keeps (a copy of it, allocated and counted).
    pub live: u64,
}

/// Work of one ray, added to by [`Field3::first_root`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayWork {
    /// Interval evaluations (of a piece of the ray).
    pub interval_evals: u64,
    /// Point evaluations (Lipschitz steps, leaf ends, bisection, normals).
    pub point_evals: u64,
    /// Steps of `value / L`.
    pub lipschitz_steps: u64,
    /// Leaves of the interval subdivision whose interval held 0 with both ends outside.
    pub ambiguous_leaves: u64,
}

impl RayWork {
    /// Adds `o` into `self`.
    pub fn add(&mut self, o: &RayWork) {
        self.interval_evals += o.interval_evals;
        self.point_evals += o.point_evals;
        self.lipschitz_steps += o.lipschitz_steps;
        self.ambiguous_leaves += o.ambiguous_leaves;
    }
}

/// Scratch storage of one thread (reused: no allocation per ray once warm).
#[derive(Default)]
pub struct Scratch {
    pub(super) iv: Vec<Interval>,
    v: Vec<f64>,
    stack: Vec<(f64, f64)>,
}

/// The first surface point along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RootHit {
    /// Ray parameter.
    pub t: f64,
    /// Bound on the error of `t` (the bracket the root was bisected to).
    pub error: f64,
    /// The outward normal where the hit is on a face of the cube (the solid cut by it);
    /// `None` on the model's own surface (its gradient is the normal).
    pub face: Option<DVec3>,
    /// The cell the hit lies in (`None` on a face of the cube of an inside cell).
    pub region: Option<u32>,
}

impl Field3 {
    /// `ssa` prepared with `n` cells per axis (cells evaluated in parallel).
    pub fn new(ssa: Ssa, n: usize) -> Field3 {
        let n = n.max(1);
        let h = 2.0 * EXTENT / n as f64;
        let built: Vec<(u32, Option<Region>)> = (0..n * n * n)
            .into_par_iter()
            .map_init(
                || (Vec::new(), Vec::new(), Vec::new(), Vec::new()),
                |(iv, alias, live, duals): &mut (Vec<Interval>, Vec<u32>, Vec<bool>, Vec<Dual>), c| {
                    let (i, j, k) = (c % n, (c / n) % n, c / (n * n));
                    let b = |a: usize| {
                        Interval::new(-EXTENT + a as f64 * h - PAD, -EXTENT + (a + 1) as f64 * h + PAD)
                    };
                    let (x, y, z) = (b(i), b(j), b(k));
                    let v = ssa.eval_interval(x, y, z, iv);
                    if !v.nan && v.lo > 0.0 {
                        return (OUTSIDE, None);
                    }
                    if !v.nan && v.hi < 0.0 {
                        return (INSIDE, None);
                    }
                    let mut short = Ssa::default();
                    ssa.shorten(iv, &mut short, alias, live);
                    // A bound far weaker than the cell's interval (exp and ln make huge
                    // ones) would step by tol for long: isolation does better there.
                    let diag = h * 3f64.sqrt();
                    let lipschitz = lipschitz_bound(&short, x, y, z, duals)
                        .filter(|l| !v.nan && l * diag <= USEFUL_BOUND * (v.hi - v.lo));
                    (0, Some(Region { ssa: short, lipschitz }))
                },
            )
            .collect();
        let mut cells = Vec::with_capacity(built.len());
        let mut regions = Vec::new();
        let mut summary = FieldSummary { clauses: ssa.clauses.len(), cells: n, ..FieldSummary::default() };
        let mut bounds = Vec::new();
        let mut region_clauses = 0usize;
        for (code, region) in built {
            match region {
                Some(r) => {
                    cells.push(regions.len() as u32);
                    summary.surface += 1;
                    region_clauses += r.ssa.clauses.len();
                    if let Some(l) = r.lipschitz {
                        bounds.push(l);
                    }
                    regions.push(r);
                }
                None => {
                    if code == OUTSIDE {
                        summary.outside += 1;
                    } else {
                        summary.inside += 1;
                    }
                    cells.push(code);
                }
            }
        }
        bounds.sort_by(f64::total_cmp);
        summary.bounded = bounds.len();
        if !bounds.is_empty() {
            summary.lipschitz_min = bounds[0];
            summary.lipschitz_median = bounds[bounds.len() / 2];
            summary.lipschitz_max = bounds[bounds.len() - 1];
        }
        summary.mean_region_clauses = region_clauses as f64 / summary.surface.max(1) as f64;
        Field3 { ssa, n, cells, regions, summary, preparation: None }
    }

    /// Bytes held (the model and the cells' programs).
    pub fn bytes_used(&self) -> usize {
        let clause = std::mem::size_of::<super::tape::Clause>();
        std::mem::size_of::<Self>()
            + self.ssa.clauses.capacity() * clause
            + self.cells.capacity() * 4
            + self
                .regions
                .iter()
                .map(|r| std::mem::size_of::<Region>() + r.ssa.clauses.capacity() * clause)
                .sum::<usize>()
    }

    /// The surface cells' programs.
    pub fn regions(&self) -> &[Region] {
        &self.regions
    }

    /// The program valid at `p` (a surface cell's, or the whole model elsewhere).
    pub fn program_at(&self, p: DVec3) -> &Ssa {
        match self.cell_of(p).map(|c| self.cells[c]) {
            Some(r) if r < INSIDE => &self.regions[r as usize].ssa,
            _ => &self.ssa,
        }
    }

    pub(super) fn cell_of(&self, p: DVec3) -> Option<usize> {
        let h = 2.0 * EXTENT / self.n as f64;
        let mut idx = [0usize; 3];
        for a in 0..3 {
            // Outside the cube no cell's program holds: the whole model answers there.
            if !(p[a] >= -EXTENT && p[a] <= EXTENT) {
                return None;
            }
            let f = ((p[a] + EXTENT) / h).floor();
            idx[a] = (f.max(0.0) as usize).min(self.n - 1);
        }
        Some(idx[0] + self.n * (idx[1] + self.n * idx[2]))
    }

    /// The value at `p` (f64, the program of `p`'s cell).
    pub fn value(&self, p: DVec3, s: &mut Scratch) -> f64 {
        self.program_at(p).eval_f64_into(p.to_array(), &mut s.v)
    }

    /// The gradient at `p` by central differences of step `h` on the program of `p`'s cell
    /// (6 point evaluations).
    pub fn gradient(&self, p: DVec3, h: f64, s: &mut Scratch) -> DVec3 {
        let ssa = self.program_at(p);
        let mut g = [0.0; 3];
        for (a, ga) in g.iter_mut().enumerate() {
            let mut q = p;
            q[a] += h;
            let fp = ssa.eval_f64_into(q.to_array(), &mut s.v);
            q[a] = p[a] - h;
            let fm = ssa.eval_f64_into(q.to_array(), &mut s.v);
            *ga = (fp - fm) / (2.0 * h);
        }
        DVec3::from_array(g)
    }

    /// The first point of the ray `o + t d` (`d` any non-zero length) with `t` in
    /// `[t_min, t_max]` where it crosses the boundary of the solid (`{f < 0}` within the
    /// cube), with hit tolerance `tol(t) = tol0 + tol1 * t` along the ray. A ray that
    /// starts inside the solid finds where it leaves it. `None` when it crosses nothing.
    #[allow(clippy::too_many_arguments)]
    pub fn first_root(
        &self,
        o: DVec3,
        d: DVec3,
        t_min: f64,
        t_max: f64,
        tol0: f64,
        tol1: f64,
        s: &mut Scratch,
        w: &mut RayWork,
    ) -> Option<RootHit> {
        self.first_root_hinted(o, d, t_min, t_max, tol0, tol1, f64::INFINITY, false, s, w)
    }

    /// [`Self::first_root`] where a surface, if any, is expected within `hint` of `t_min`
    /// (a ray bundle's pre-pass proved the ray empty up to `t_min` and could not prove the
    /// next `hint` of it empty): the interval isolation of the first cell starts with that
    /// piece instead of halving the cell's whole piece down to it. The result is the
    /// same root up to the tolerance; only the work differs. With `outside` the caller
    /// knows the ray is outside the solid just before `t_min` (proven empty up to there, or
    /// sampled outside at `t_min`): a value `<= 0` at `t_min` is then a root there, not a
    /// start inside the solid.
    #[allow(clippy::too_many_arguments)]
    pub fn first_root_hinted(
        &self,
        o: DVec3,
        d: DVec3,
        t_min: f64,
        t_max: f64,
        tol0: f64,
        tol1: f64,
        hint: f64,
        outside: bool,
        s: &mut Scratch,
        w: &mut RayWork,
    ) -> Option<RootHit> {
        let hint_end = t_min + hint;
        // The ray's piece in the cube, and the faces it enters and leaves by.
        let (mut tin, mut tout) = (f64::NEG_INFINITY, f64::INFINITY);
        let (mut in_face, mut out_face) = (DVec3::ZERO, DVec3::ZERO);
        for a in 0..3 {
            if d[a] == 0.0 {
                if o[a].abs() > EXTENT {
                    return None;
                }
                continue;
            }
            let (t0, t1) = ((-EXTENT - o[a]) / d[a], (EXTENT - o[a]) / d[a]);
            let (near, far, sign) = if t0 < t1 { (t0, t1, -1.0) } else { (t1, t0, 1.0) };
            if near > tin {
                tin = near;
                in_face = DVec3::ZERO;
                in_face[a] = sign;
            }
            if far < tout {
                tout = far;
                out_face = DVec3::ZERO;
                out_face[a] = -sign;
            }
        }
        let t0 = tin.max(t_min);
        let t1 = tout.min(t_max);
        if !(t0 <= t1) {
            return None;
        }
        let dn = d.length();
        let tol = |t: f64| tol0 + tol1 * t.abs();
        // Which side the ray starts on: outside (look for f <= 0) or inside (f >= 0).
        let start = o + d * t0;
        w.point_evals += 1;
        let f_start = self.value(start, s);
        let entering = tin >= t_min;
        if f_start < 0.0 && entering {
            // The solid reaches the cube's face: the cut face is the surface here.
            return Some(RootHit { t: t0, error: 0.0, face: Some(in_face), region: None });
        }
        if outside && f_start <= 0.0 {
            let region = self.cell_of(start).map(|c| self.cells[c]).filter(|&r| r < INSIDE);
            return Some(RootHit { t: t0, error: 0.0, face: None, region });
        }
        let sign = if f_start < 0.0 { -1.0 } else { 1.0 };
        // 3D DDA over the cells.
        let n = self.n;
        let h = 2.0 * EXTENT / n as f64;
        let mut idx = [0i64; 3];
        let mut t_next = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        let mut step = [0i64; 3];
        let probe = o + d * (0.5 * (t0 + t1.min(t0 + 1e-9 * (1.0 + t0.abs()))));
        for a in 0..3 {
            let c = ((probe[a] + EXTENT) / h).floor().clamp(0.0, n as f64 - 1.0) as i64;
            idx[a] = c;
            if d[a] > 0.0 {
                step[a] = 1;
                t_next[a] = (-EXTENT + (c + 1) as f64 * h - o[a]) / d[a];
                t_delta[a] = h / d[a];
            } else if d[a] < 0.0 {
                step[a] = -1;
                t_next[a] = (-EXTENT + c as f64 * h - o[a]) / d[a];
                t_delta[a] = -h / d[a];
            }
        }
        let mut t = t0;
        loop {
            let cell = (idx[0] + n as i64 * (idx[1] + n as i64 * idx[2])) as usize;
            let seg_end = t_next[0].min(t_next[1]).min(t_next[2]).min(t1);
            let code = self.cells[cell];
            let solid_here = match code {
                OUTSIDE => sign < 0.0,
                INSIDE => sign > 0.0,
                _ => false,
            };
            if solid_here {
                return Some(RootHit { t, error: 0.0, face: None, region: None });
            }
            if code < INSIDE && seg_end > t {
                let region = &self.regions[code as usize];
                let found = match region.lipschitz {
                    Some(l) => self.lipschitz_walk(region, o, d, t, seg_end, sign, l * dn, &tol, s, w),
                    None => {
                        let first = if hint_end > t { hint_end - t } else { f64::INFINITY };
                        self.isolate(region, o, d, t, seg_end, sign, first, &tol, s, w)
                    }
                };
                if let Some((t, error)) = found {
                    return Some(RootHit { t, error, face: None, region: Some(code) });
                }
            }
            if seg_end >= t1 {
                break;
            }
            t = seg_end;
            let a = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                0
            } else if t_next[1] <= t_next[2] {
                1
            } else {
                2
            };
            idx[a] += step[a];
            if idx[a] < 0 || idx[a] >= n as i64 {
                break;
            }
            t_next[a] += t_delta[a];
        }
        // Inside the solid up to where the ray leaves the cube: the cut face.
        (sign < 0.0 && tout <= t_max).then_some(RootHit {
            t: tout,
            error: 0.0,
            face: Some(out_face),
            region: None,
        })
    }

    /// `sign * f` on the region's program at `o + t d`.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn eval(
        &self,
        r: &Region,
        o: DVec3,
        d: DVec3,
        t: f64,
        sign: f64,
        s: &mut Scratch,
        w: &mut RayWork,
    ) -> f64 {
        w.point_evals += 1;
        let p = o + d * t;
        sign * r.ssa.eval_f64_into(p.to_array(), &mut s.v)
    }

    /// Steps of `g / L + tol` through `[ta, tb]` (`g = sign f`, `ld` the bound per unit of
    /// `t`); the interval isolation takes over after [`MAX_CELL_STEPS`].
    #[allow(clippy::too_many_arguments)]
    fn lipschitz_walk(
        &self,
        r: &Region,
        o: DVec3,
        d: DVec3,
        ta: f64,
        tb: f64,
        sign: f64,
        ld: f64,
        tol: &impl Fn(f64) -> f64,
        s: &mut Scratch,
        w: &mut RayWork,
    ) -> Option<(f64, f64)> {
        let mut t = ta;
        let mut g = self.eval(r, o, d, t, sign, s, w);
        if g <= 0.0 {
            return Some((t, 0.0));
        }
        for _ in 0..MAX_CELL_STEPS {
            if g.is_nan() {
                break;
            }
            w.lipschitz_steps += 1;
            let next = t + g / ld + tol(t);
            if next >= tb {
                let gb = self.eval(r, o, d, tb, sign, s, w);
                return (gb <= 0.0).then(|| self.bisect(r, o, d, t, tb, sign, tol(t), s, w));
            }
            let gn = self.eval(r, o, d, next, sign, s, w);
            if gn <= 0.0 {
                return Some(self.bisect(r, o, d, t, next, sign, tol(t), s, w));
            }
            t = next;
            g = gn;
        }
        self.isolate(r, o, d, t, tb, sign, f64::INFINITY, tol, s, w)
    }

    /// The first root in `[ta, tb]` by interval subdivision (see the module header); its
    /// first piece is `[ta, ta + first]` when that is shorter than the whole.
    #[allow(clippy::too_many_arguments)]
    fn isolate(
        &self,
        r: &Region,
        o: DVec3,
        d: DVec3,
        ta: f64,
        tb: f64,
        sign: f64,
        first: f64,
        tol: &impl Fn(f64) -> f64,
        s: &mut Scratch,
        w: &mut RayWork,
    ) -> Option<(f64, f64)> {
        let mut stack = std::mem::take(&mut s.stack);
        stack.clear();
        if ta + first < tb {
            stack.push((ta + first, tb));
            stack.push((ta, ta + first));
        } else {
            stack.push((ta, tb));
        }
        // The last point value computed (pieces are visited in order along the ray).
        let mut last = (f64::NAN, f64::NAN);
        let mut found = None;
        while let Some((a, b)) = stack.pop() {
            let (pa, pb) = (o + d * a, o + d * b);
            let lo = pa.min(pb);
            let hi = pa.max(pb);
            let iv = |k: usize| Interval::new(lo[k] - PAD, hi[k] + PAD);
            w.interval_evals += 1;
            let v = r.ssa.eval_interval(iv(0), iv(1), iv(2), &mut s.iv);
            let (vlo, vhi) = if sign > 0.0 { (v.lo, v.hi) } else { (-v.hi, -v.lo) };
            if !v.nan && vlo > 0.0 {
                continue;
            }
            if !v.nan && vhi < 0.0 {
                // All of the piece is past the boundary: it lies at its start.
                found = Some((a, 0.0));
                break;
            }
            if b - a <= tol(a) {
                let ga = if last.0 == a { last.1 } else { self.eval(r, o, d, a, sign, s, w) };
                if ga <= 0.0 {
                    found = Some((a, 0.0));
                    break;
                }
                let gb = self.eval(r, o, d, b, sign, s, w);
                last = (b, gb);
                if gb <= 0.0 {
                    found = Some(self.bisect(r, o, d, a, b, sign, tol(a), s, w));
                    break;
                }
                w.ambiguous_leaves += 1;
                continue;
            }
            let mid = 0.5 * (a + b);
            stack.push((mid, b));
            stack.push((a, mid));
        }
        s.stack = stack;
        found
    }

    /// Bisects `[a, b]` (`g(a) > 0 >= g(b)`) down to `tol * 1e-3`; the root's `t` (the last
    /// point outside) and the bracket's width.
    #[allow(clippy::too_many_arguments)]
    fn bisect(
        &self,
        r: &Region,
        o: DVec3,
        d: DVec3,
        mut a: f64,
        mut b: f64,
        sign: f64,
        tol: f64,
        s: &mut Scratch,
        w: &mut RayWork,
    ) -> (f64, f64) {
        let goal = (tol * 1e-3).max(1e-12 * (1.0 + b.abs()));
        for _ in 0..48 {
            if b - a <= goal {
                break;
            }
            let m = 0.5 * (a + b);
            if self.eval(r, o, d, m, sign, s, w) > 0.0 {
                a = m;
            } else {
                b = m;
            }
        }
        (a, b - a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::implicit::vm::parse_vm;

    fn sphere(r: f64, square: bool) -> Ssa {
        // The exact distance, or r^2-scaled |p|^2 - r^2 (not a distance).
        let tail = if square { "o sub e k\n" } else { "s sqrt e\no sub s r\n" };
        parse_vm(
            &format!(
                "x var-x\ny var-y\nz var-z\na square x\nb square y\nc square z\nd add a b\ne add d c\n\
                 r const {r}\nk const {}\n{tail}",
                r * r
            ),
            "s.vm".as_ref(),
        )
        .unwrap()
    }

    #[test]
    fn rays_hit_a_sphere_where_it_is() {
        for square in [false, true] {
            let f = Field3::new(sphere(0.5, square), 8);
            if !square {
                assert!(f.summary.lipschitz_everywhere() || f.summary.bounded > 0);
            }
            let mut s = Scratch::default();
            let mut w = RayWork::default();
            for k in 0..50 {
                let y = -0.7 + 1.4 * k as f64 / 49.0;
                let o = DVec3::new(0.0, y, 3.0);
                let hit = f.first_root(o, DVec3::new(0.0, 0.0, -1.0), 0.0, 10.0, 1e-5, 1e-5, &mut s, &mut w);
                if y.abs() < 0.5 {
                    let want = 3.0 - (0.25 - y * y).sqrt();
                    let h = hit.unwrap_or_else(|| panic!("y {y}: missed"));
                    assert!((h.t - want).abs() < 1e-4, "y {y}: {} vs {want}", h.t);
                } else if y.abs() > 0.5 + 1e-3 {
                    assert!(hit.is_none(), "y {y}: {hit:?}");
                }
            }
            // From inside, the exit.
            let h = f.first_root(DVec3::ZERO, DVec3::X, 0.0, 10.0, 1e-6, 0.0, &mut s, &mut w).unwrap();
            assert!((h.t - 0.5).abs() < 1e-4, "{}", h.t);
        }
    }

    #[test]
    fn a_solid_filling_the_cube_shows_its_cut_face() {
        let f = Field3::new(parse_vm("x var-x\nk const -1\no add x k\n", "c.vm".as_ref()).unwrap(), 4);
        let mut s = Scratch::default();
        let mut w = RayWork::default();
        let h =
            f.first_root(DVec3::new(0.0, 0.0, 5.0), -DVec3::Z, 0.0, 10.0, 1e-6, 0.0, &mut s, &mut w).unwrap();
        assert_eq!(h.t, 4.0);
        assert_eq!(h.face, Some(DVec3::Z));
    }
}
