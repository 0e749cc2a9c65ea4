//! The compiled form of an analytic SDF: a [`Tape`], one flat program of f32 operations
//! over a small register file, compiled once from an [`SdfTree`] and evaluated at one point
//! ([`Tape::eval`]) or at eight points at once ([`Tape::eval8`], on the selected SIMD
//! backend, both giving the same results), without allocating (the caller
//! owns a [`TapeScratch`] sized once from the tape).
//!
//! # What the compiler does
//!
//! * Transforms are folded: each primitive gets one [`Op::Translate`] (pure translation) or
//!   [`Op::Affine`] (3x4 matrix) that maps the current point register straight into its
//!   local frame, composed in f64 from every transform above it (and the tape origin) and
//!   rounded to f32 once (a sphere under a pure translation carries it in its own
//!   [`Op::Sphere`]: the same additions, one dispatch fewer); CSG nodes emit no point
//!   operations. The scale factor that keeps
//!   distances conservative (the smallest scale, as in [`SdfNode::eval`]) is a multiply:
//!   inside the primitive's op, and an [`Op::Scale`] after a CSG or repetition node whose own
//!   scale is not 1.
//! * CSG is [`Op::Min`] / [`Op::Max`] / [`Op::Subtract`] and the smooth blends over two
//!   value registers, folded left over the children like the tree.
//! * Domain repetition is point folding: [`Op::Cells`] finds, per repeated axis, the cell
//!   that holds the point and the neighbouring cell on the nearer side (clamped to the
//!   finite count), [`Op::Offset`] moves the point into one of the up to 8 cell
//!   combinations, and the child's code follows once per combination (unrolled, so the tape
//!   has no jumps and every lane runs the same instructions), combined with [`Op::Min`].
//!   Nested repetitions multiply: a child under repetition along `k` axes appears `2^k`
//!   times. Along an axis where the child stays inside its cell ([`super::cell_gaps`]),
//!   [`Op::CellFace`] takes the nearest cell only and bounds the others by the cell's face
//!   plus the gap, as the tree does; a child that fits on every axis appears once.
//! * Common subexpressions are computed once: a point map or a cell lookup whose input
//!   register never changes (the input point, or the result of another such operation)
//!   writes registers that nothing else writes, and an identical one later reads them
//!   instead of being emitted (a rotated Menger sponge maps its point once for its whole
//!   subtraction, and the three bars of a cross share their cell lookups).
//!
//! # Coordinates and precision
//!
//! The tape takes points relative to [`Tape::origin`] (an f64 point, the centre of the
//! object's bounds, or the world origin for an unbounded object): `p_rel = p - origin`,
//! rounded to f32 by the caller ([`Tape::relative`]). Near the object, `p_rel` is small, so
//! f32 keeps a relative precision of about 1e-7 of the object's size rather than of its
//! distance from the world origin. [`Tape::error_bound`] estimates the largest difference
//! from the f64 tree ([`SdfTree::distance`]) for points within a radius of the origin,
//! `C * f32::EPSILON * (radius + K)` with `K` the largest coordinate magnitude inside the
//! tape (primitive offsets from the origin and primitive sizes, in world units) and
//! `C = ERROR_FACTOR`, set from the measured worst case of the property tests with a
//! margin. Where that is above the hit tolerance the marcher needs, f32 is not enough
//! ([`Tape::f32_is_enough`]): the radius-5000 ground sphere of `data/hard/ground_5000.toml`,
//! seen from a few units away, needs distances to about 1e-4 while f32 coordinates of
//! magnitude 5000 resolve only 5e-4; the wiring keeps the f64 tree there.
//!
//! One place where the tape and the tree differ by more than rounding: at a repetition's
//! cell centre the tree takes the neighbouring cell on the point's side; within rounding of
//! the centre, f32 and f64 may take different sides. For a child that is an exact distance
//! within its cell both give the same minimum; for a child that is only a Lipschitz bound
//! the tree itself jumps there, and the tape equals the tree on the other side of the jump.
//!
//! # Scalar and 8-wide agree bit for bit
//!
//! One generic interpreter runs over a lane type: `f32` for [`Tape::eval`], eight `f32`
//! lanes for [`Tape::eval8`]. Every operation is IEEE single precision lane by lane (no
//! fused multiply-add: Rust does not contract, and `sqrt`, `floor` and division are
//! correctly rounded), minimum and maximum are the comparisons `a < b` and `a > b` on both
//! paths, and branches are selects computed the same way, so each lane of `eval8` equals
//! `eval` at that point exactly (tested). The AVX2 build of the 8-wide path runs the same
//! interpreter over a lane type whose operations are the AVX intrinsics of those same
//! IEEE operations (the SIMD layer's lanes, [`crate::simd::Simd`]), so it also equals
//! the portable build (tested).
//!
//! # Not on the tape
//!
//! Materials: the tape computes distances only. The material of a hit is looked up once
//! per hit with [`SdfTree::distance_material`] (the f64 tree), never per march step.

use crate::simd::{F8, F8x4, Kernel, Lane, Lane8, Lane32, Portable, Simd, dispatch};

use glam::{DAffine3, DMat3, DVec3, Vec3};

use crate::geometry::Aabb;
use crate::geometry::sdf::{SdfNode, SdfTree};
use crate::scene::shape::{CsgOp, Object, Primitive};

/// `C` of [`Tape::error_bound`]: the worst `|tape - tree| / (f32::EPSILON * (|p_rel| + K))`
/// measured over 20000 random trees and 1.28M points (the ignored test `sdf_tape::calibrate`
/// in tests/integration/sdf_tape.rs) was 4.0 to 4.4 in the runs so far (its cases are random);
/// 16 keeps a margin of more than 3.
pub const ERROR_FACTOR: f64 = 16.0;

/// Marks an axis that [`Op::Offset`] leaves as it is.
pub const NO_REG: u32 = u32::MAX;

/// One tape operation. `p`, `src`, `dst` name point registers (three coordinates), `out`,
/// `a`, `b`, `base`, `other` value registers; register 0 of each file is the input point
/// and the result. Constants are f32 in the frame the op works in; `scale` multiplies a
/// primitive's local distance into its parent's units (the transform's smallest scale).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Op {
    /// `pts[dst] = pts[src] + t`.
    Translate {
        /// Source point register.
        src: u32,
        /// Destination point register.
        dst: u32,
        /// Translation added to every point.
        t: [f32; 3],
    },
    /// `pts[dst] = M * pts[src]`, row `i` being `m[i][0] x + m[i][1] y + m[i][2] z + m[i][3]`
    /// (summed in that order).
    Affine {
        /// Source point register.
        src: u32,
        /// Destination point register.
        dst: u32,
        /// The 3x4 matrix, by rows.
        m: [[f32; 4]; 3],
    },
    /// `vals[out] = (|p + t| - radius) * scale`: a sphere carries its own translation
    /// (the [`Op::Translate`] it would need, folded in: the same f32 additions, one
    /// operation fewer to dispatch).
    Sphere {
        /// Point register (the local frame once translated by `t`).
        p: u32,
        /// Translation added to the point first (zero when there is none), local units.
        t: [f32; 3],
        /// Value register written.
        out: u32,
        /// Radius, local units.
        radius: f32,
        /// Distance multiplier into the parent's units.
        scale: f32,
    },
    /// `vals[out] = (normal . p - offset) * scale`.
    Plane {
        /// Point register (local frame).
        p: u32,
        /// Value register written.
        out: u32,
        /// Unit normal.
        normal: [f32; 3],
        /// Offset along the normal, local units.
        offset: f32,
        /// Distance multiplier into the parent's units.
        scale: f32,
    },
    /// Exact box distance, half extents `half`.
    Box {
        /// Point register (local frame).
        p: u32,
        /// Value register written.
        out: u32,
        /// Half extents, local units.
        half: [f32; 3],
        /// Distance multiplier into the parent's units.
        scale: f32,
    },
    /// `(|p * inv_radii| - 1) * min_radius * scale` (a Lipschitz-1 bound).
    Ellipsoid {
        /// Point register (local frame).
        p: u32,
        /// Value register written.
        out: u32,
        /// Reciprocals of the semi-axes, 1 / local units.
        inv_radii: [f32; 3],
        /// Smallest semi-axis, local units.
        min_radius: f32,
        /// Distance multiplier into the parent's units.
        scale: f32,
    },
    /// Capped cylinder around y.
    Cylinder {
        /// Point register (local frame).
        p: u32,
        /// Value register written.
        out: u32,
        /// Radius, local units.
        radius: f32,
        /// Half height, local units.
        half_height: f32,
        /// Distance multiplier into the parent's units.
        scale: f32,
    },
    /// Capped cone around y (Quilez's exact form, its constants precomputed).
    Cone {
        /// Point register (local frame).
        p: u32,
        /// Value register written.
        out: u32,
        /// Half height, local units.
        h: f32,
        /// Radius at `y = -h`.
        r1: f32,
        /// Radius at `y = h`.
        r2: f32,
        /// `(r2 - r1, 2 h)`.
        k2: [f32; 2],
        /// `1 / (k2 . k2)`.
        inv_k2k2: f32,
        /// Distance multiplier into the parent's units.
        scale: f32,
    },
    /// Torus in the xz plane.
    Torus {
        /// Point register (local frame).
        p: u32,
        /// Value register written.
        out: u32,
        /// Ring radius, local units.
        major: f32,
        /// Tube radius, local units.
        minor: f32,
        /// Distance multiplier into the parent's units.
        scale: f32,
    },
    /// Unsigned triangle distance; the constants are `Tape::triangles[index]`.
    Triangle {
        /// Point register (local frame).
        p: u32,
        /// Value register written.
        out: u32,
        /// Index into the tape's triangle constants.
        index: u32,
        /// Distance multiplier into the parent's units.
        scale: f32,
    },
    /// Capsule: segment `a`..`a + ba` swept by `radius`.
    Capsule {
        /// Point register (local frame).
        p: u32,
        /// Value register written.
        out: u32,
        /// First end point.
        a: [f32; 3],
        /// `b - a`.
        ba: [f32; 3],
        /// `1 / |ba|^2`, or 0 when `a == b` (a sphere).
        inv_bb: f32,
        /// Radius, local units.
        radius: f32,
        /// Distance multiplier into the parent's units.
        scale: f32,
    },
    /// Union: `vals[out] = if vals[b] < vals[a] { vals[b] } else { vals[a] }`.
    Min {
        /// Value register written.
        out: u32,
        /// First operand (the children folded so far).
        a: u32,
        /// Second operand (the next child).
        b: u32,
    },
    /// Intersection: `vals[out] = if vals[b] > vals[a] { vals[b] } else { vals[a] }`.
    Max {
        /// Value register written.
        out: u32,
        /// First operand (the children folded so far).
        a: u32,
        /// Second operand (the next child).
        b: u32,
    },
    /// Subtraction: `vals[out] = if -vals[b] > vals[a] { -vals[b] } else { vals[a] }`.
    Subtract {
        /// Value register written.
        out: u32,
        /// First operand (the children folded so far).
        a: u32,
        /// Second operand (the next child).
        b: u32,
    },
    /// `vals[out] = smin(vals[a], vals[b])`, the polynomial smooth minimum of radius `k`.
    SmoothUnion {
        /// Value register written.
        out: u32,
        /// First operand (the children folded so far).
        a: u32,
        /// Second operand (the next child).
        b: u32,
        /// Blend radius, units of the CSG node's frame.
        k: f32,
        /// `1 / k`.
        inv_k: f32,
    },
    /// `vals[out] = -smin(-vals[a], -vals[b])`.
    SmoothIntersection {
        /// Value register written.
        out: u32,
        /// First operand (the children folded so far).
        a: u32,
        /// Second operand (the next child).
        b: u32,
        /// Blend radius.
        k: f32,
        /// `1 / k`.
        inv_k: f32,
    },
    /// `vals[out] = -smin(-vals[a], vals[b])`.
    SmoothSubtraction {
        /// Value register written.
        out: u32,
        /// First operand (the children folded so far).
        a: u32,
        /// Second operand (the next child).
        b: u32,
        /// Blend radius.
        k: f32,
        /// `1 / k`.
        inv_k: f32,
    },
    /// `vals[a] *= s`: a CSG or repetition node's smallest scale.
    Scale {
        /// Register scaled in place.
        a: u32,
        /// Factor (> 0).
        s: f32,
    },
    /// Repetition cells along `axis`: with `x = p[axis] * inv_period`, the cell index
    /// `id = clamp(floor(x - shift + 0.5) + shift, lo, hi)` and its neighbour on `x`'s side
    /// `next = clamp(id +- 1, lo, hi)`; writes `vals[base] = id * period`,
    /// `vals[other] = next * period`.
    Cells {
        /// Point register (the repetition's local frame).
        p: u32,
        /// Axis 0, 1 or 2.
        axis: u32,
        /// Value register for the nearest cell's offset.
        base: u32,
        /// Value register for the neighbouring cell's offset.
        other: u32,
        /// Period along the axis (> 0), local units.
        period: f32,
        /// `1 / period`.
        inv_period: f32,
        /// 0, or 0.5 for an even finite count (cell centres at half-integers).
        shift: f32,
        /// Lowest cell index (`-inf` for infinite repetition).
        lo: f32,
        /// Highest cell index (`inf` for infinite repetition).
        hi: f32,
    },
    /// The nearest repetition cell along `axis` as [`Op::Cells`] (`vals[base] = id *
    /// period`) and, for a child that stays inside its cell ([`super::cell_gap`]), the
    /// distance bound of every other copy along that axis: with `x = p[axis] - id *
    /// period`, `vals[face] = min(half_gap - x if id < hi, half_gap + x if id > lo)` (+inf
    /// where neither side has a neighbour), `half_gap` being half the period plus the gap.
    CellFace {
        /// Point register (the repetition's local frame).
        p: u32,
        /// Axis 0, 1 or 2.
        axis: u32,
        /// Value register for the nearest cell's offset.
        base: u32,
        /// Value register for the face distance plus the gap.
        face: u32,
        /// Period along the axis (> 0), local units.
        period: f32,
        /// `1 / period`.
        inv_period: f32,
        /// 0, or 0.5 for an even finite count.
        shift: f32,
        /// Lowest cell index (`-inf` for infinite repetition).
        lo: f32,
        /// Highest cell index (`inf` for infinite repetition).
        hi: f32,
        /// Half the period plus the gap, local units.
        half_gap: f32,
    },
    /// `pts[dst][i] = pts[src][i] - vals[offs[i]]`, or `pts[src][i]` where `offs[i]` is
    /// [`NO_REG`].
    Offset {
        /// Source point register.
        src: u32,
        /// Destination point register.
        dst: u32,
        /// Value register of each axis's offset, or [`NO_REG`].
        offs: [u32; 3],
    },
    /// `vals[out] = vals[a]`: a choice that a region's interval decided
    /// ([`super::prune`]); the compiler never emits it.
    Copy {
        /// Value register written.
        out: u32,
        /// Register copied.
        a: u32,
    },
    /// `vals[out] = -vals[a]`: a subtraction that a region's interval decided for its
    /// second operand ([`super::prune`]); the compiler never emits it.
    Neg {
        /// Value register written.
        out: u32,
        /// Register negated.
        a: u32,
    },
}

impl Op {
    /// `(point register, value register)` of a primitive operation; `None` for the rest.
    pub fn primitive_registers(&self) -> Option<(u32, u32)> {
        let mut op = *self;
        op.primitive_registers_mut().map(|(p, out)| (*p, *out))
    }

    /// [`Op::primitive_registers`], to rewrite.
    fn primitive_registers_mut(&mut self) -> Option<(&mut u32, &mut u32)> {
        match self {
            Op::Sphere { p, out, .. }
            | Op::Plane { p, out, .. }
            | Op::Box { p, out, .. }
            | Op::Ellipsoid { p, out, .. }
            | Op::Cylinder { p, out, .. }
            | Op::Cone { p, out, .. }
            | Op::Torus { p, out, .. }
            | Op::Triangle { p, out, .. }
            | Op::Capsule { p, out, .. } => Some((p, out)),
            _ => None,
        }
    }

    /// Calls `f` on every register the operation names, read or written, with whether it
    /// is a point register (else a value register); [`NO_REG`] included.
    pub fn for_each_register(&mut self, mut f: impl FnMut(&mut u32, bool)) {
        if let Some((p, out)) = self.primitive_registers_mut() {
            f(p, true);
            f(out, false);
            return;
        }
        match self {
            Op::Translate { src, dst, .. } | Op::Affine { src, dst, .. } => {
                f(src, true);
                f(dst, true);
            }
            Op::Min { out, a, b }
            | Op::Max { out, a, b }
            | Op::Subtract { out, a, b }
            | Op::SmoothUnion { out, a, b, .. }
            | Op::SmoothIntersection { out, a, b, .. }
            | Op::SmoothSubtraction { out, a, b, .. } => {
                for r in [out, a, b] {
                    f(r, false);
                }
            }
            Op::Scale { a, .. } => f(a, false),
            Op::Cells { p, base, other: second, .. } | Op::CellFace { p, base, face: second, .. } => {
                f(p, true);
                f(base, false);
                f(second, false);
            }
            Op::Offset { src, dst, offs } => {
                f(src, true);
                f(dst, true);
                for r in offs {
                    f(r, false);
                }
            }
            Op::Copy { out, a } | Op::Neg { out, a } => {
                f(out, false);
                f(a, false);
            }
            _ => unreachable!("primitives are handled above"),
        }
    }

    /// The factor a primitive's local distance is multiplied by ([`Op::Sphere`]'s `scale`
    /// and the like); `None` for the rest.
    pub fn primitive_scale(&self) -> Option<f32> {
        match *self {
            Op::Sphere { scale, .. }
            | Op::Plane { scale, .. }
            | Op::Box { scale, .. }
            | Op::Ellipsoid { scale, .. }
            | Op::Cylinder { scale, .. }
            | Op::Cone { scale, .. }
            | Op::Torus { scale, .. }
            | Op::Triangle { scale, .. }
            | Op::Capsule { scale, .. } => Some(scale),
            _ => None,
        }
    }
}

/// The operations one evaluation runs: a whole tape's, or a shortened tape's picked from a
/// list ([`super::prune::TapeRegions`]: the tape's operations followed by the copies that
/// replace decided choices) by index.
#[derive(Clone, Copy, Debug)]
pub enum Ops<'a> {
    /// Every operation, in order.
    All(&'a [Op]),
    /// `ops[order[0]], ops[order[1]], ...`.
    Picked {
        /// The operations picked from.
        ops: &'a [Op],
        /// Indices into `ops`, in evaluation order.
        order: &'a [u16],
    },
}

/// One coordinate (or value) of four packets of eight points, for [`Tape::eval32_ops`]:
/// `[g][l]` is lane `l` of packet `g`.
pub type X32 = [[f32; 8]; 4];

/// Runs `$ops` ([`Ops`]) through [`run`] with the rest of the arguments.
macro_rules! run_ops {
    ($ops:expr, $($rest:expr),*) => {
        match $ops {
            Ops::All(ops) => run(ops.iter(), $($rest),*),
            Ops::Picked { ops, order } => run(order.iter().map(|&i| &ops[i as usize]), $($rest),*),
        }
    };
}

/// The constants of an [`Op::Triangle`] (vertices, edges, normal and their reciprocal
/// squared lengths), as the exact triangle distance of [`crate::geometry::sdf::triangle_distance`]
/// uses them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleConsts {
    /// Vertices.
    pub a: [f32; 3],
    /// Second vertex.
    pub b: [f32; 3],
    /// Third vertex.
    pub c: [f32; 3],
    /// `b - a`.
    pub ba: [f32; 3],
    /// `c - b`.
    pub cb: [f32; 3],
    /// `a - c`.
    pub ac: [f32; 3],
    /// `ba x ac`.
    pub nor: [f32; 3],
    /// `ba x nor`, `cb x nor`, `ac x nor` (edge planes).
    pub edge_n: [[f32; 3]; 3],
    /// `1 / |nor|^2`.
    pub inv_nn: f32,
    /// `1 / |ba|^2`, `1 / |cb|^2`, `1 / |ac|^2`.
    pub inv_edge2: [f32; 3],
}

/// A compiled analytic SDF (see the module documentation).
#[derive(Clone, Debug)]
pub struct Tape {
    /// The point the tape's coordinates are relative to, world units: [`Tape::eval`] takes
    /// `p - origin`. The centre of the object's bounds, or zero when it is unbounded.
    pub origin: DVec3,
    /// Half the diagonal of the object's bounds, world units (0 when unbounded): the radius
    /// around [`Tape::origin`] that [`Tape::f32_is_enough`] checks.
    pub reach: f64,
    /// As [`SdfTree::exact`]: the distance is exact, not only a Lipschitz-1 bound.
    pub exact: bool,
    /// As [`SdfTree::signed`]: false when the object holds a triangle.
    pub signed: bool,
    ops: Vec<Op>,
    triangles: Vec<TriangleConsts>,
    vals: usize,
    points: usize,
    /// `K` of [`Tape::error_bound`], world units.
    magnitude: f64,
}

/// Registers for evaluating one [`Tape`] (scalar, 8-wide and 32-wide), allocated once;
/// evaluation never allocates. A scratch sized for one tape serves any tape with as many
/// registers or fewer ([`TapeScratch::fits`]).
#[derive(Clone, Debug, Default)]
pub struct TapeScratch {
    vals: Vec<f32>,
    pts: Vec<[f32; 3]>,
    vals8: Vec<F8>,
    pts8: Vec<[F8; 3]>,
    /// Four packets' registers for [`Tape::eval32_ops`].
    vals32: Vec<F8x4>,
    pts32: Vec<[F8x4; 3]>,
}

impl TapeScratch {
    /// Registers for `tape`.
    pub fn new(tape: &Tape) -> Self {
        TapeScratch {
            vals: vec![0.0; tape.vals],
            pts: vec![[0.0; 3]; tape.points],
            vals8: vec![F8::ZERO; tape.vals],
            pts8: vec![[F8::ZERO; 3]; tape.points],
            vals32: vec![F8x4::ZERO; tape.vals],
            pts32: vec![[F8x4::ZERO; 3]; tape.points],
        }
    }

    /// Grows this scratch to fit `tape` (allocates only when it does not fit yet).
    #[inline]
    pub fn fit(&mut self, tape: &Tape) {
        if !self.fits(tape) {
            let (vals, points) = (self.vals.len().max(tape.vals), self.pts.len().max(tape.points));
            *self = TapeScratch {
                vals: vec![0.0; vals],
                pts: vec![[0.0; 3]; points],
                vals8: vec![F8::ZERO; vals],
                pts8: vec![[F8::ZERO; 3]; points],
                vals32: vec![F8x4::ZERO; vals],
                pts32: vec![[F8x4::ZERO; 3]; points],
            };
        }
    }

    /// Whether this scratch has enough registers for `tape`.
    pub fn fits(&self, tape: &Tape) -> bool {
        self.vals.len() >= tape.vals && self.pts.len() >= tape.points
    }
}

impl Tape {
    /// Compiles `tree`, with coordinates relative to the centre of `bounds` (the object's
    /// world bounds; `None` for an unbounded object, whose tape is relative to the world
    /// origin).
    pub fn compile(tree: &SdfTree, bounds: Option<Aabb>) -> Tape {
        Self::compile_within(tree, bounds, usize::MAX).expect("no limit on the tape's length")
    }

    /// [`Tape::compile`], or `None` as soon as the tape grows past `max_ops` operations:
    /// nested repetitions unroll `2^k` copies of their child per level, so a small tree can
    /// have an enormous tape, and this stops after at most about `max_ops` operations of
    /// work and memory instead of unrolling it all first. A tape of at most `max_ops`
    /// operations is the same as [`Tape::compile`]'s.
    pub fn compile_within(tree: &SdfTree, bounds: Option<Aabb>, max_ops: usize) -> Option<Tape> {
        let (origin, reach) = match bounds {
            Some(b) if b.valid() => {
                let (lo, hi) = (Vec3::from(b.min).as_dvec3(), Vec3::from(b.max).as_dvec3());
                ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
            }
            _ => (DVec3::ZERO, 0.0),
        };
        let mut c = Compiler {
            ops: Vec::new(),
            triangles: Vec::new(),
            vals: 1,
            points: 1,
            magnitude: 0.0,
            once: std::collections::HashMap::new(),
            once_vals: 0,
            once_points: 0,
            max_ops,
        };
        c.node(&tree.root, 0, DAffine3::from_translation(origin), 1.0, 0.0, 0, 1);
        if c.ops.len() > max_ops {
            return None;
        }
        let (vals, points) = c.finish();
        Some(Tape {
            origin,
            reach,
            exact: tree.exact,
            signed: tree.signed,
            ops: c.ops,
            triangles: c.triangles,
            vals,
            points,
            magnitude: c.magnitude,
        })
    }

    /// Compiles an object's tree for marching ([`SdfTree::for_marching`]) relative to the
    /// centre of its bounds; `None` when it holds a mesh or a grid (no analytic SDF).
    pub fn from_object(object: &Object) -> Option<Tape> {
        Some(Tape::compile(&SdfTree::for_marching(object)?, object.bounds()))
    }

    /// The operations, in evaluation order.
    pub fn ops(&self) -> &[Op] {
        &self.ops
    }

    /// The triangle constants [`Op::Triangle`] refers to.
    pub fn triangles(&self) -> &[TriangleConsts] {
        &self.triangles
    }

    /// Number of value registers and of point registers.
    pub fn registers(&self) -> (usize, usize) {
        (self.vals, self.points)
    }

    /// Approximate bytes held by the tape.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.ops.len() * std::mem::size_of::<Op>()
            + self.triangles.len() * std::mem::size_of::<TriangleConsts>()
    }

    /// World point `p` relative to [`Tape::origin`], rounded to f32: the tape's input.
    #[inline]
    pub fn relative(&self, p: DVec3) -> Vec3 {
        (p - self.origin).as_vec3()
    }

    /// An estimate of the largest `|eval(p_rel) - tree.distance(origin + p_rel)|` for
    /// `|p_rel| <= radius`, world units: `ERROR_FACTOR * f32::EPSILON * (radius + K)`,
    /// where `K` is the largest coordinate magnitude the tape computes with (see the module
    /// documentation).
    pub fn error_bound(&self, radius: f64) -> f64 {
        let (k, m) = self.error_parts();
        k * (radius + m)
    }

    /// [`Tape::error_bound`] is `k * (radius + m)` with `(k, m)` these two: for kernels that
    /// compute it themselves, with the same operations.
    #[inline]
    pub fn error_parts(&self) -> (f64, f64) {
        (ERROR_FACTOR * f32::EPSILON as f64, self.magnitude)
    }

    /// Whether f32 evaluation is precise enough for a march whose smallest hit tolerance
    /// is `tolerance` (world units; e.g. `MarchParams::tolerance(t, size)` at the nearest
    /// distance `t` the object is seen from): true when [`Tape::error_bound`] over the
    /// object's bounds ([`Tape::reach`]) is at most a quarter of it. For an unbounded object
    /// only the constants count: far from the origin the error grows with `|p_rel|` like
    /// the march's tolerance grows with the distance travelled. False for the radius-5000
    /// ground sphere seen from a few units away, where the f64 tree must be kept.
    pub fn f32_is_enough(&self, tolerance: f64) -> bool {
        self.error_bound(self.reach) <= 0.25 * tolerance
    }

    /// Distance (or Lipschitz-1 bound) at `p_rel`, a point relative to [`Tape::origin`].
    /// `scratch` must fit the tape (panics otherwise).
    #[inline]
    pub fn eval(&self, p_rel: Vec3, scratch: &mut TapeScratch) -> f32 {
        self.eval_ops(Ops::All(&self.ops), p_rel, scratch)
    }

    /// [`Tape::eval`] running `ops` instead of the whole tape: a shortened tape of this
    /// one ([`super::prune::TapeRegions`]), which uses its registers and triangles.
    #[inline]
    pub fn eval_ops(&self, ops: Ops, p_rel: Vec3, scratch: &mut TapeScratch) -> f32 {
        run_ops!(ops, &self.triangles, &mut scratch.vals, &mut scratch.pts, p_rel.to_array(), ())
    }

    /// The value of primitive operation `op` (one of this tape's) at point `local` of its
    /// point register, for interval bounds ([`super::prune`]); `None` when `op` is not a
    /// primitive. `scratch` must fit the tape.
    #[inline]
    pub(crate) fn primitive_at(&self, op: &Op, local: [f32; 3], scratch: &mut TapeScratch) -> Option<f32> {
        let (p, out) = op.primitive_registers()?;
        scratch.pts[p as usize] = local;
        let input = scratch.pts[0];
        run::<f32>(std::iter::once(op), &self.triangles, &mut scratch.vals, &mut scratch.pts, input, ());
        Some(scratch.vals[out as usize])
    }

    /// [`Tape::eval`] at the eight points `(xs[l], ys[l], zs[l])` (relative to
    /// [`Tape::origin`]); lane `l` of the result equals `eval` at point `l` bit for bit.
    /// Runs on the selected SIMD backend ([`crate::simd::dispatch`]).
    #[inline]
    pub fn eval8(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8], scratch: &mut TapeScratch) -> [f32; 8] {
        self.eval8_ops(Ops::All(&self.ops), xs, ys, zs, scratch)
    }

    /// [`Tape::eval8`] running `ops`, a shortened tape of this one (as [`Tape::eval_ops`]).
    #[inline]
    pub fn eval8_ops(
        &self,
        ops: Ops,
        xs: &[f32; 8],
        ys: &[f32; 8],
        zs: &[f32; 8],
        scratch: &mut TapeScratch,
    ) -> [f32; 8] {
        dispatch(Eval8 { tape: self, ops, xs, ys, zs, scratch })
    }

    /// [`Tape::eval8_ops`] for four packets of eight points at once (`xs[g][l]` is lane `l`
    /// of packet `g`): each operation is dispatched once for all 32 lanes, which with AVX2
    /// run as four independent 8-wide chains. Packet `g` of the result equals
    /// `eval8_ops` on packet `g` bit for bit (the same operations lane by lane).
    #[inline]
    pub fn eval32_ops(&self, ops: Ops, xs: &X32, ys: &X32, zs: &X32, scratch: &mut TapeScratch) -> X32 {
        dispatch(Eval32 { tape: self, ops, xs, ys, zs, scratch })
    }

    /// The portable build of [`Tape::eval8`] (eight-lane arrays the compiler vectorises for
    /// the baseline target); same results.
    pub fn eval8_portable(
        &self,
        xs: &[f32; 8],
        ys: &[f32; 8],
        zs: &[f32; 8],
        scratch: &mut TapeScratch,
    ) -> [f32; 8] {
        Eval8 { tape: self, ops: Ops::All(&self.ops), xs, ys, zs, scratch }.run(Portable)
    }
}

mod compile;
mod eval;

use compile::Compiler;
pub use compile::ops_bound;
pub(crate) use eval::cell_index;
use eval::{Eval8, Eval32, run};

#[cfg(test)]
mod tests;
