//! The first surfaces along a bundle of neighbouring rays ([`Field3::first_roots`]): a
//! pre-pass proves, for the whole bundle at once, the pieces of the rays that hold no
//! surface; what it cannot prove empty is sampled densely, many rays and points at once.
//!
//! The pre-pass walks the bundle front to back in pieces `[a, b]` of the ray parameter, a
//! cell long. A piece's box (the bounding box of every still-open ray's points at `a` and
//! `b`: the rays are straight, so it holds all their points in between) is proven empty when
//! it lies outside the cube, or when every cell it touches is outside ([`Field3`]'s census)
//! or has its shortened program's interval above 0 over the box's part in it; a box
//! touching more than 8 cells is evaluated on the whole model. A piece not proven empty is,
//! once its open rays need at most 32 points each and 256 in all at a spacing of the hit
//! tolerance, a leaf (`sample_leaf`): the program shortened over its box, every
//! open ray sampled a tolerance apart, 64 points at a time in f32, each ray's first sign
//! change bisected ten times the same way. Otherwise it is split: in `t` while it is long
//! next to the bundle's width, else the bundle into its two halves (the caller orders its
//! rays so that halves are neighbours: Morton order), down to single rays. A ray whose
//! first sample in a leaf is already not outside, or whose sign change gave NaN, is marched
//! on its own by [`Field3::first_root_hinted`] from there.
//!
//! The result is each ray's [`Field3::first_root`] up to the hit tolerance, not bit for bit:
//! every skipped piece is proven empty by an interval over a box that holds it, and a leaf
//! may pass over a sliver thinner than the tolerance between two samples, as the interval
//! isolation's leaves may. The f32 samples decide signs only near a surface, where a
//! rounding flip moves the root by far less than the tolerance. The work is counted in
//! [`RayWork`]. The scenes' tracer does not use bundles: with its hit tolerance of 1e-4
//! (a fiftieth of a pixel at 128 x 128) the dense leaves cost more than they save (primary
//! rays of the 128 x 128 previews: bear 342 to 414 ms, colonnade 21 to 53, geode 41 to 98;
//! only bolt gains, 452 to 204); the heightmap view, with half a pixel, is 5 to 8 times faster with them
//! (bear 13.0 s to 2.7 s, colonnade 0.78 to 0.17, bolt 9.2 to 1.2 at 512 x 512, 2 threads).

use glam::DVec3;

use super::field3d::{EXTENT, Field3, INSIDE, OUTSIDE, PAD, RayWork, RootHit, Scratch};
use super::interval::Interval;
use super::tape::{LANES, ShortenScratch, Ssa, TapeRunner};

/// Halvings of a leaf's sign change (from at most the hit tolerance to 1/1024 of it).
const BISECTIONS: usize = 10;

/// Cells a piece's box may touch and still be checked cell by cell.
const MAX_BOX_CELLS: usize = 8;

/// A piece not proven empty is sampled ([`Field3::sample_leaf`]) once its open rays need
/// at most this many points at a spacing of the hit tolerance.
const LEAF_POINTS: usize = 256;

/// ... and at most this many points per ray: one interval evaluation costs about as much
/// as 30 points, so a longer piece is halved (by intervals) rather than sampled.
const LEAF_RAY_POINTS: usize = 32;

/// Per-bundle storage (reused: no allocation per bundle once warm).
#[derive(Default)]
pub struct BundleScratch {
    /// Each ray's piece inside the cube and its `[t_min, t_max]` (empty: `lo > hi`).
    span: Vec<(f64, f64)>,
    /// Where each ray's own march starts (NaN: not yet known).
    start: Vec<f64>,
    /// The length of the first piece not proven empty, from `start`.
    hint: Vec<f64>,
    /// Whether the ray is known to be outside the solid at `start`.
    outside: Vec<bool>,
    /// A leaf's program, shortened over its box, and its tape.
    short: Ssa,
    shorten: ShortenScratch,
    tape: TapeRunner,
    /// A leaf's sample points: (ray, t) and the f32 value there.
    samples: Vec<(u32, f64)>,
    values: Vec<f32>,
    /// A leaf's sign changes being bisected: (ray, last t outside, first t not outside).
    brackets: Vec<(u32, f64, f64)>,
    /// Roots found by a leaf's bisection.
    found: Vec<Option<RootHit>>,
}

impl BundleScratch {
    /// Ray `k`'s part of `[a, bnd]` within its span, while the ray is still open (its march
    /// has no start yet); `None` when it is not open or has no part there.
    fn open_piece(&self, k: usize, a: f64, bnd: f64) -> Option<(f64, f64)> {
        let (t0, t1) = self.span[k];
        let (ta, tb) = (a.max(t0), bnd.min(t1));
        (self.start[k].is_nan() && ta <= tb).then_some((ta, tb))
    }
}

/// Whether a box was proven to hold no surface.
#[derive(Clone, Copy, PartialEq, Eq)]
enum BoxState {
    Empty,
    Maybe,
}

impl Field3 {
    /// The first root of each ray `(o, d)` of `rays` (neighbours, in an order whose halves
    /// are neighbours) in `[t_min, t_max[k]]`, with hit tolerance `tol0 + tol1 t`
    /// ([`Field3::first_root`]'s contract per ray), into `out`.
    #[allow(clippy::too_many_arguments)]
    pub fn first_roots(
        &self,
        rays: &[(DVec3, DVec3)],
        t_min: f64,
        t_max: &[f64],
        tol0: f64,
        tol1: f64,
        out: &mut [Option<RootHit>],
        s: &mut Scratch,
        b: &mut BundleScratch,
        w: &mut RayWork,
    ) {
        let n = rays.len();
        b.span.clear();
        b.span.extend(rays.iter().zip(t_max).map(|(&(o, d), &t1)| cube_span(o, d, t_min, t1)));
        b.start.clear();
        b.start.resize(n, f64::NAN);
        b.hint.clear();
        b.hint.resize(n, f64::INFINITY);
        b.outside.clear();
        b.outside.resize(n, false);
        b.found.clear();
        b.found.resize(n, None);
        let (mut a, end) = b
            .span
            .iter()
            .filter(|s| s.0 <= s.1)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| (lo.min(s.0), hi.max(s.1)));
        let h = 2.0 * EXTENT / self.n as f64;
        let dn = rays.iter().map(|r| r.1.length()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
        while a < end {
            if self.width_at(rays, b, 0, n, a).is_none() {
                break;
            }
            let bnd = (a + h / dn).min(end);
            self.refine(rays, b, 0, n, a, bnd, tol0, tol1, s, w);
            a = bnd;
        }
        for (k, &(o, d)) in rays.iter().enumerate() {
            out[k] = if b.found[k].is_some() {
                b.found[k]
            } else if b.start[k].is_nan() {
                None
            } else {
                self.first_root_hinted(o, d, b.start[k], t_max[k], tol0, tol1, b.hint[k], b.outside[k], s, w)
            };
        }
    }

    /// The widest extent, across the open rays `lo..hi`, of their points at `t` (`None`
    /// when no ray is open there).
    fn width_at(
        &self,
        rays: &[(DVec3, DVec3)],
        b: &BundleScratch,
        lo: usize,
        hi: usize,
        t: f64,
    ) -> Option<f64> {
        let mut bmin = DVec3::splat(f64::INFINITY);
        let mut bmax = DVec3::splat(f64::NEG_INFINITY);
        let mut any = false;
        for (k, &(o, d)) in rays.iter().enumerate().take(hi).skip(lo) {
            let Some((ta, _)) = b.open_piece(k, t, f64::INFINITY) else { continue };
            let p = o + d * ta;
            bmin = bmin.min(p);
            bmax = bmax.max(p);
            any = true;
        }
        any.then(|| (bmax - bmin).max_element())
    }

    /// The pre-pass over rays `lo..hi` and the piece `[a, bnd]` (see the module header).
    #[allow(clippy::too_many_arguments)]
    fn refine(
        &self,
        rays: &[(DVec3, DVec3)],
        b: &mut BundleScratch,
        lo: usize,
        hi: usize,
        a: f64,
        bnd: f64,
        tol0: f64,
        tol1: f64,
        s: &mut Scratch,
        w: &mut RayWork,
    ) {
        let mut bmin = DVec3::splat(f64::INFINITY);
        let mut bmax = DVec3::splat(f64::NEG_INFINITY);
        let mut open = 0usize;
        for (k, &(o, d)) in rays.iter().enumerate().take(hi).skip(lo) {
            let Some((ta, tb)) = b.open_piece(k, a, bnd) else { continue };
            for p in [o + d * ta, o + d * tb] {
                bmin = bmin.min(p);
                bmax = bmax.max(p);
            }
            open += 1;
        }
        if open == 0 || self.box_state(bmin, bmax, s, w) == BoxState::Empty {
            return;
        }
        let tol = tol0 + tol1 * a.abs();
        let dn = (lo..hi).map(|k| rays[k].1.length()).fold(0.0, f64::max);
        let per_ray = ((bnd - a) * dn / tol).ceil() as usize + 1;
        if per_ray <= LEAF_RAY_POINTS && open * per_ray <= LEAF_POINTS {
            self.sample_leaf(rays, b, lo, hi, a, bnd, (bmin, bmax), tol0, tol1, s, w);
            return;
        }
        let width = self.width_at(rays, b, lo, hi, a).unwrap_or(0.0);
        if (bnd - a) * dn > 2.0 * width.max(tol) && bnd - a > 4.0 * tol / dn.max(f64::MIN_POSITIVE) {
            let m = 0.5 * (a + bnd);
            self.refine(rays, b, lo, hi, a, m, tol0, tol1, s, w);
            self.refine(rays, b, lo, hi, m, bnd, tol0, tol1, s, w);
        } else if open > 1 && hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            self.refine(rays, b, lo, mid, a, bnd, tol0, tol1, s, w);
            self.refine(rays, b, mid, hi, a, bnd, tol0, tol1, s, w);
        } else {
            for k in lo..hi {
                if let Some((ta, _)) = b.open_piece(k, a, bnd) {
                    b.start[k] = ta;
                    b.hint[k] = bnd - ta;
                }
            }
        }
    }

    /// Samples the open rays of `lo..hi` over `[a, bnd]` (their points in the box `bx`) at
    /// a spacing of at most the hit tolerance, [`LANES`] at a time in f32 on the program
    /// shortened over the box. A ray whose first sample is not outside starts its own
    /// march there (inside the solid only where that is the ray's first point); a ray with an outside sample followed by one that
    /// is not starts its march at the outside one, known outside, with the bracket as its
    /// hint; a ray sampled outside throughout stays open (a sliver thinner than the
    /// tolerance may pass between samples, as between the leaves of the interval
    /// isolation).
    #[allow(clippy::too_many_arguments)]
    fn sample_leaf(
        &self,
        rays: &[(DVec3, DVec3)],
        b: &mut BundleScratch,
        lo: usize,
        hi: usize,
        a: f64,
        bnd: f64,
        bx: (DVec3, DVec3),
        tol0: f64,
        tol1: f64,
        s: &mut Scratch,
        w: &mut RayWork,
    ) {
        // The program over the box: a cell's where the box lies in one, else the model's.
        let (blo, bhi) = (bx.0 - DVec3::splat(PAD), bx.1 + DVec3::splat(PAD));
        let prog = match (self.cell_of(bx.0), self.cell_of(bx.1)) {
            (Some(c0), Some(c1)) if c0 == c1 && self.cells[c0] < INSIDE => {
                &self.regions[self.cells[c0] as usize].ssa
            }
            _ => &self.ssa,
        };
        let iv = |k: usize| Interval::new(blo[k], bhi[k]);
        w.interval_evals += 1;
        prog.eval_interval_fast(iv(0), iv(1), iv(2), &mut s.iv);
        // Where the box decides no clause the program stays as it is (no copy).
        let src = if prog.shorten_decided(&s.iv, &mut b.short, &mut b.shorten) { &b.short } else { prog };
        b.tape.load(src);
        b.samples.clear();
        for (k, &(_, d)) in rays.iter().enumerate().take(hi).skip(lo) {
            let Some((ta, tb)) = b.open_piece(k, a, bnd) else { continue };
            let tol = tol0 + tol1 * ta.abs();
            let m = (((tb - ta) * d.length() / tol).ceil() as usize).max(1);
            for i in 0..=m {
                b.samples.push((k as u32, ta + (tb - ta) * i as f64 / m as f64));
            }
        }
        b.values.clear();
        let (mut xs, mut ys, mut zs) = ([0f32; LANES], [0f32; LANES], [0f32; LANES]);
        let mut out = [0f32; LANES];
        for chunk in b.samples.chunks(LANES) {
            for (i, &(k, t)) in chunk.iter().enumerate() {
                let p = rays[k as usize].0 + rays[k as usize].1 * t;
                (xs[i], ys[i], zs[i]) = (p.x as f32, p.y as f32, p.z as f32);
            }
            b.tape.eval(&xs, &ys, &zs, &mut out);
            b.values.extend_from_slice(&out[..chunk.len()]);
        }
        w.point_evals += b.samples.len() as u64;
        // Each ray's samples are consecutive, in order along it.
        b.brackets.clear();
        let mut i = 0;
        while i < b.samples.len() {
            let k = b.samples[i].0 as usize;
            let mut j = i;
            while j < b.samples.len() && b.samples[j].0 as usize == k {
                j += 1;
            }
            // The first sample that is not outside (NaN counts as not outside).
            match (i..j).find(|&q| !(b.values[q] > 0.0)) {
                Some(q) if q == i => {
                    // Past the ray's first point every earlier piece was proven (or
                    // sampled) outside, up to and including this one.
                    b.start[k] = b.samples[i].1;
                    b.hint[k] = bnd - b.start[k];
                    b.outside[k] = b.start[k] > b.span[k].0;
                }
                Some(q) => {
                    b.start[k] = b.samples[q - 1].1;
                    b.hint[k] = b.samples[q].1 - b.start[k];
                    b.outside[k] = true;
                    if !b.values[q].is_nan() {
                        b.brackets.push((k as u32, b.samples[q - 1].1, b.samples[q].1));
                    }
                }
                None => w.ambiguous_leaves += 1,
            }
            i = j;
        }
        self.bisect_brackets(rays, b, &mut xs, &mut ys, &mut zs, w);
    }

    /// Bisects the leaf's sign changes ([`BISECTIONS`] halvings, [`LANES`] rays at a time
    /// on the leaf's program, whose box holds every bracket). A ray whose midpoint gives
    /// NaN is left to its own march from its last point outside.
    fn bisect_brackets(
        &self,
        rays: &[(DVec3, DVec3)],
        b: &mut BundleScratch,
        xs: &mut [f32; LANES],
        ys: &mut [f32; LANES],
        zs: &mut [f32; LANES],
        w: &mut RayWork,
    ) {
        let mut out = [0f32; LANES];
        for chunk in b.brackets.chunks_mut(LANES) {
            for _ in 0..BISECTIONS {
                for (i, &(k, lo, hi)) in chunk.iter().enumerate() {
                    let p = rays[k as usize].0 + rays[k as usize].1 * (0.5 * (lo + hi));
                    (xs[i], ys[i], zs[i]) = (p.x as f32, p.y as f32, p.z as f32);
                }
                b.tape.eval(xs, ys, zs, &mut out);
                w.point_evals += chunk.len() as u64;
                for (br, &v) in chunk.iter_mut().zip(&out) {
                    let m = 0.5 * (br.1 + br.2);
                    if v.is_nan() {
                        br.2 = f64::NAN;
                    } else if v > 0.0 {
                        br.1 = m;
                    } else {
                        br.2 = m;
                    }
                }
            }
            for &(k, lo, hi) in chunk.iter() {
                if hi.is_nan() {
                    continue;
                }
                let p = rays[k as usize].0 + rays[k as usize].1 * lo;
                let region = self.cell_of(p).map(|c| self.cells[c]).filter(|&r| r < INSIDE);
                b.found[k as usize] = Some(RootHit { t: lo, error: hi - lo, face: None, region });
            }
        }
    }

    /// Whether the box `[lo, hi]` holds no part of the solid (see the module header).
    fn box_state(&self, lo: DVec3, hi: DVec3, s: &mut Scratch, w: &mut RayWork) -> BoxState {
        let lo = (lo - DVec3::splat(PAD)).max(DVec3::splat(-EXTENT));
        let hi = (hi + DVec3::splat(PAD)).min(DVec3::splat(EXTENT));
        if lo.cmpgt(hi).any() {
            return BoxState::Empty;
        }
        let n = self.n;
        let h = 2.0 * EXTENT / n as f64;
        let index = |v: f64| (((v + EXTENT) / h).floor().max(0.0) as usize).min(n - 1);
        let (i0, i1) = (index(lo.x), index(hi.x));
        let (j0, j1) = (index(lo.y), index(hi.y));
        let (k0, k1) = (index(lo.z), index(hi.z));
        let count = (i1 - i0 + 1) * (j1 - j0 + 1) * (k1 - k0 + 1);
        let iv = |a: f64, b: f64| Interval::new(a, b);
        if count > MAX_BOX_CELLS {
            w.interval_evals += 1;
            let v = self.ssa.eval_interval_fast(iv(lo.x, hi.x), iv(lo.y, hi.y), iv(lo.z, hi.z), &mut s.iv);
            return if !v.nan && v.lo > 0.0 { BoxState::Empty } else { BoxState::Maybe };
        }
        for k in k0..=k1 {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let code = self.cells[i + n * (j + n * k)];
                    if code == OUTSIDE {
                        continue;
                    }
                    if code == INSIDE {
                        return BoxState::Maybe;
                    }
                    // The box's part in the cell (the cell's program holds there).
                    let c = |a: usize| -EXTENT + a as f64 * h;
                    let clip = |l: f64, u: f64, a: usize| iv(l.max(c(a) - PAD), u.min(c(a + 1) + PAD));
                    w.interval_evals += 1;
                    let v = self.regions[code as usize].ssa.eval_interval_fast(
                        clip(lo.x, hi.x, i),
                        clip(lo.y, hi.y, j),
                        clip(lo.z, hi.z, k),
                        &mut s.iv,
                    );
                    if v.nan || v.lo <= 0.0 {
                        return BoxState::Maybe;
                    }
                }
            }
        }
        BoxState::Empty
    }
}

/// The part of `[t_min, t_max]` where the ray `o + t d` is inside the cube (empty:
/// `lo > hi`).
fn cube_span(o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (t_min, t_max);
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a].abs() > EXTENT {
                return (1.0, 0.0);
            }
            continue;
        }
        let (t0, t1) = ((-EXTENT - o[a]) / d[a], (EXTENT - o[a]) / d[a]);
        lo = lo.max(t0.min(t1));
        hi = hi.min(t0.max(t1));
    }
    if lo.is_nan() || hi.is_nan() { (1.0, 0.0) } else { (lo, hi) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::implicit::vm::parse_vm;

    /// The bundle finds every ray's root where the ray alone finds it.
    #[test]
    fn bundles_agree_with_single_rays_on_a_non_distance_field() {
        // A wavy blob: |p|^2 - 0.3 + 0.05 sin(9x) cos(7y) + 0 floor(x) (not a distance; the
        // floor's jumps leave it no Lipschitz bound, so single rays isolate by intervals).
        let text = "x var-x\ny var-y\nz var-z\na square x\nb square y\nc square z\nd add a b\ne add d c\n\
                    k const 0.3\nf sub e k\nn9 const 9\nn7 const 7\nu mul x n9\nv mul y n7\nsu sin u\ncv cos v\n\
                    m mul su cv\nq const 0.05\nr mul m q\ng add f r\nfl floor x\nz0 const 0\nfz mul fl z0\no add g fz\n";
        let field = Field3::new(parse_vm(text, "w.vm".as_ref()).unwrap(), 16);
        let (mut s, mut b) = (Scratch::default(), BundleScratch::default());
        let (mut w1, mut wb) = (RayWork::default(), RayWork::default());
        let side = 16;
        let mut differ = 0;
        for tile in 0..4 {
            // Perspective rays from one origin through a 16 x 16 patch, in row order.
            let rays: Vec<(DVec3, DVec3)> = (0..side * side)
                .map(|k| {
                    let (u, v) = ((k % side) as f64, (k / side) as f64);
                    let (u, v) = (
                        -0.8 + (u + 16.0 * (tile % 2) as f64) * 0.05,
                        -0.8 + (v + 16.0 * (tile / 2) as f64) * 0.05,
                    );
                    (DVec3::new(0.1, 0.05, 3.0), DVec3::new(u, v, -2.5))
                })
                .collect();
            let t_max = vec![10.0; rays.len()];
            let mut out = vec![None; rays.len()];
            field.first_roots(&rays, 0.0, &t_max, 1e-4, 0.0, &mut out, &mut s, &mut b, &mut wb);
            for (k, &(o, d)) in rays.iter().enumerate() {
                let one = field.first_root(o, d, 0.0, 10.0, 1e-4, 0.0, &mut s, &mut w1);
                match (one, out[k]) {
                    (None, None) => {}
                    (Some(x), Some(y)) => assert!((x.t - y.t).abs() < 1e-3, "ray {k}: {} vs {}", x.t, y.t),
                    _ => differ += 1,
                }
            }
        }
        assert_eq!(differ, 0);
        assert!(wb.point_evals > 0 && w1.point_evals > 0);
    }
}
