//! The compiled form of an analytic SDF: a [`Tape`], one flat program of f32 operations
//! over a small register file, compiled once from an [`SdfTree`] and evaluated at one point
//! ([`Tape::eval`]) or at eight points at once ([`Tape::eval8`], AVX2 where the CPU has it,
//! a portable fallback with the same results elsewhere), without allocating (the caller
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
//! IEEE operations ([`avx::A8`]), so it also equals the portable build (tested).
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

/// [`Tape::eval8_ops`] as a SIMD kernel.
struct Eval8<'a> {
    tape: &'a Tape,
    ops: Ops<'a>,
    xs: &'a [f32; 8],
    ys: &'a [f32; 8],
    zs: &'a [f32; 8],
    scratch: &'a mut TapeScratch,
}

impl Kernel for Eval8<'_> {
    type Output = [f32; 8];
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> [f32; 8] {
        let Eval8 { tape, ops, xs, ys, zs, scratch } = self;
        let p = [s.load8(xs), s.load8(ys), s.load8(zs)];
        let (vals, pts) = (s.regs8(&mut scratch.vals8), s.regs8x3(&mut scratch.pts8));
        run_ops!(ops, &tape.triangles, vals, pts, p, s).store()
    }
}

/// [`Tape::eval32_ops`] as a SIMD kernel.
struct Eval32<'a> {
    tape: &'a Tape,
    ops: Ops<'a>,
    xs: &'a X32,
    ys: &'a X32,
    zs: &'a X32,
    scratch: &'a mut TapeScratch,
}

impl Kernel for Eval32<'_> {
    type Output = X32;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> X32 {
        let Eval32 { tape, ops, xs, ys, zs, scratch } = self;
        let p = [s.load32(xs), s.load32(ys), s.load32(zs)];
        let (vals, pts) = (s.regs32(&mut scratch.vals32), s.regs32x3(&mut scratch.pts32));
        run_ops!(ops, &tape.triangles, vals, pts, p, s).store()
    }
}

/// The first write-once register number of either file while compiling
/// ([`Compiler::once`]); [`Compiler::finish`] renumbers them above the others.
const ONCE: u32 = 1 << 30;

/// What makes two point maps or repetition cell lookups the same computation: the kind of
/// operation, its input register and the bits of its constants.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
struct OnceKey {
    kind: std::mem::Discriminant<Op>,
    input: u32,
    bits: [u32; 12],
}

/// An upper bound on the number of operations [`Tape::compile`] emits for `node` (no
/// sharing counted), in f64 so that it cannot overflow: a primitive maps its point, runs
/// and scales; a CSG node adds a combination per extra child; a repetition emits its cell
/// lookups and, per combination of cells (`2^k` for the `k` repeated axes without a gap),
/// an offset, its child and a minimum. Computed without building anything, so that a
/// memory estimate can count the tape before it exists.
pub fn ops_bound(node: &SdfNode) -> f64 {
    match node {
        SdfNode::Primitive { .. } => 3.0,
        SdfNode::Csg { children, .. } => {
            2.0 + children.iter().map(ops_bound).sum::<f64>() + children.len().saturating_sub(1) as f64
        }
        SdfNode::Repeat { period, child, gaps, .. } => {
            let axes = (0..3).filter(|&a| period[a] > 0.0 && gaps[a].is_none()).count();
            let corners = (1u32 << axes) as f64;
            8.0 + corners * (2.0 + ops_bound(child))
        }
    }
}

/// The tape compiler's state.
struct Compiler {
    ops: Vec<Op>,
    triangles: Vec<TriangleConsts>,
    /// Value registers used (below [`ONCE`]).
    vals: u32,
    /// Point registers used (below [`ONCE`]).
    points: u32,
    /// `K` of [`Tape::error_bound`] so far.
    magnitude: f64,
    /// Common subexpressions: point maps and cell lookups whose input never changes (the
    /// input point, or a write-once register) write write-once registers (numbered from
    /// [`ONCE`]) that no other operation writes, and an identical one later reads those
    /// instead of being emitted again: a rotated Menger sponge maps its point once, not
    /// once per child of its subtraction, and its crosses' bars share their cell lookups.
    /// The results are the same bits, as the same f32 operations on the same inputs.
    once: std::collections::HashMap<OnceKey, u32>,
    /// Write-once value registers used.
    once_vals: u32,
    /// Write-once point registers used.
    once_points: u32,
    /// Past this many operations the compiler stops emitting ([`Tape::compile_within`]).
    max_ops: usize,
}

impl Compiler {
    /// Whether point register `r` never changes once written: the input point, or a
    /// write-once register.
    fn fixed_point(r: u32) -> bool {
        r == 0 || r >= ONCE
    }

    /// Emits `map(pts[src])` into point register `dst` and returns it, or returns `src` when
    /// `map` is the identity. Where `src` never changes, the result goes to a write-once
    /// register instead, shared with every identical map ([`Compiler::once`]).
    fn point(&mut self, src: u32, map: &DAffine3, dst: u32) -> u32 {
        if *map == DAffine3::IDENTITY {
            return src;
        }
        let t = map.translation.as_vec3().to_array();
        let m = map.matrix3.as_mat3();
        let row = |i: usize| [m.x_axis[i], m.y_axis[i], m.z_axis[i], t[i]];
        let m = [row(0), row(1), row(2)];
        let translate = map.matrix3 == DMat3::IDENTITY;
        let op =
            |dst: u32| if translate { Op::Translate { src, dst, t } } else { Op::Affine { src, dst, m } };
        if !Self::fixed_point(src) {
            self.points = self.points.max(dst + 1);
            self.ops.push(op(dst));
            return dst;
        }
        let consts = if translate { &t[..] } else { m.as_flattened() };
        self.share(&op(0), src, consts, op)
    }

    /// Emits `lookup(base)`, an [`Op::Cells`] or [`Op::CellFace`] writing value registers
    /// `base` and `base + 1`, and returns `base`: `reg`, or, where its point register never
    /// changes, the first of a pair of write-once registers shared with every identical
    /// lookup ([`Compiler::once`]).
    fn cells(&mut self, reg: u32, lookup: impl Fn(u32) -> Op) -> u32 {
        let op = lookup(reg);
        let (p, consts) = match op {
            Op::Cells { p, axis, period, inv_period, shift, lo, hi, .. } => {
                (p, [axis as f32, period, inv_period, shift, lo, hi, 0.0])
            }
            Op::CellFace { p, axis, period, inv_period, shift, lo, hi, half_gap, .. } => {
                (p, [axis as f32, period, inv_period, shift, lo, hi, half_gap])
            }
            _ => unreachable!("a cell lookup"),
        };
        if !Self::fixed_point(p) {
            self.vals = self.vals.max(reg + 2);
            self.ops.push(op);
            return reg;
        }
        self.share(&op, p, &consts, lookup)
    }

    /// The write-once register that holds `like`'s result (a point map, or a cell lookup's
    /// pair of value registers) for input register `input` (which never changes) and
    /// constants `consts`: the one an identical operation wrote, else new ones, written by
    /// `emit(register)`.
    fn share(&mut self, like: &Op, input: u32, consts: &[f32], emit: impl Fn(u32) -> Op) -> u32 {
        let mut bits = [0u32; 12];
        for (b, x) in bits.iter_mut().zip(consts) {
            *b = x.to_bits();
        }
        let key = OnceKey { kind: std::mem::discriminant(like), input, bits };
        if let Some(&r) = self.once.get(&key) {
            return r;
        }
        let r = if matches!(like, Op::Translate { .. } | Op::Affine { .. }) {
            self.once_points += 1;
            ONCE + self.once_points - 1
        } else {
            self.once_vals += 2;
            ONCE + self.once_vals - 2
        };
        self.once.insert(key, r);
        self.ops.push(emit(r));
        r
    }

    /// Renumbers the write-once registers above the others, so that each file is one
    /// contiguous range from 0; returns the value and point register counts.
    fn finish(&mut self) -> (usize, usize) {
        let (vals, points) = (self.vals, self.points);
        for op in &mut self.ops {
            op.for_each_register(|r, point| {
                if *r != NO_REG && *r >= ONCE {
                    *r = *r - ONCE + if point { points } else { vals };
                }
            });
        }
        ((vals + self.once_vals) as usize, (points + self.once_points) as usize)
    }

    /// Emits `node`: its distance in its parent's units into value register `out`, for the
    /// point in register `pin`, which `frame` maps into the node's parent frame. Uses value
    /// registers from `out` up and point registers from `next_pt` up. `mult` is the product
    /// of the smallest scales above the node (local units to world units), `inherited` the
    /// magnitude (world units) of coordinates folded by repetitions above it.
    #[allow(clippy::too_many_arguments)]
    fn node(
        &mut self,
        node: &SdfNode,
        pin: u32,
        frame: DAffine3,
        mult: f64,
        inherited: f64,
        out: u32,
        next_pt: u32,
    ) {
        // Over the limit: the tape is dropped, so the rest of the tree is not unrolled
        // (every call below emits at least one operation, so this ends the walk quickly).
        if self.ops.len() > self.max_ops {
            return;
        }
        let t = node.transform();
        let map = if t.identity { frame } else { t.to_local_f64 * frame };
        let mult = mult * t.min_scale as f64;
        self.vals = self.vals.max(out + 1);
        match node {
            SdfNode::Primitive { prim: Primitive::Sphere { radius }, .. }
                if map.matrix3 == DMat3::IDENTITY =>
            {
                // The translation folded into the sphere's op (as `point` would round it).
                let shift = map.translation.as_vec3().to_array();
                self.ops.push(Op::Sphere { p: pin, t: shift, out, radius: *radius, scale: t.min_scale });
                self.magnitude =
                    self.magnitude.max(inherited + mult * (map.translation.length() + *radius as f64));
                return;
            }
            SdfNode::Primitive { prim, .. } => {
                let p = self.point(pin, &map, next_pt);
                let size = self.primitive(prim, p, out, t.min_scale);
                self.magnitude = self.magnitude.max(inherited + mult * (map.translation.length() + size));
                return;
            }
            SdfNode::Csg { op, children, .. } => {
                // The children that would each map the point by this node's `map` as it is
                // (primitives and repetitions without a transform of their own, but a
                // sphere, which carries a pure translation for free) share one mapped
                // point when there are two or more of them: the same f32 operation, done
                // once (a rotated Menger sponge maps its point once per CSG node, not once
                // per bar). The others map from `pin` as before, above that register.
                let shares = |c: &SdfNode| {
                    c.transform().identity
                        && match c {
                            SdfNode::Primitive { prim: Primitive::Sphere { .. }, .. } => {
                                map.matrix3 != DMat3::IDENTITY
                            }
                            SdfNode::Primitive { .. } | SdfNode::Repeat { .. } => true,
                            SdfNode::Csg { .. } => false,
                        }
                };
                let hoist = map != DAffine3::IDENTITY && children.iter().filter(|c| shares(c)).count() >= 2;
                let (shared, next_pt) =
                    if hoist { (self.point(pin, &map, next_pt), next_pt + 1) } else { (pin, next_pt) };
                let shared_inherited = inherited + mult * map.translation.length();
                let child = |this: &mut Self, c: &SdfNode, out: u32| {
                    if hoist && shares(c) {
                        this.node(c, shared, DAffine3::IDENTITY, mult, shared_inherited, out, next_pt);
                    } else {
                        this.node(c, pin, map, mult, inherited, out, next_pt);
                    }
                };
                child(self, &children[0], out);
                for c in &children[1..] {
                    child(self, c, out + 1);
                    let (a, b) = (out, out + 1);
                    let out = a;
                    let inv = |k: f32| 1.0 / k;
                    self.ops.push(match *op {
                        CsgOp::Union => Op::Min { out, a, b },
                        CsgOp::Intersection => Op::Max { out, a, b },
                        CsgOp::Subtraction => Op::Subtract { out, a, b },
                        CsgOp::SmoothUnion { k } => Op::SmoothUnion { out, a, b, k, inv_k: inv(k) },
                        CsgOp::SmoothIntersection { k } => {
                            Op::SmoothIntersection { out, a, b, k, inv_k: inv(k) }
                        }
                        CsgOp::SmoothSubtraction { k } => {
                            Op::SmoothSubtraction { out, a, b, k, inv_k: inv(k) }
                        }
                    });
                }
            }
            SdfNode::Repeat { period, count, child, gaps, .. } => {
                let q = self.point(pin, &map, next_pt);
                let mut axes = [(0u32, 0u32); 3];
                let mut n = 0;
                let mut reg = out + 1;
                let mut extent = 0.0f64;
                // Axes along which the child fits its cell: the nearest cell only, and the
                // face bound (`eval_repeat`) in `faces`; their offsets in `fixed`.
                let mut faces = [NO_REG; 3];
                let mut fixed = [NO_REG; 3];
                for axis in 0..3 {
                    let s = period[axis];
                    if s <= 0.0 {
                        continue;
                    }
                    let (lo, hi, shift) = match count {
                        Some(c) => {
                            let half = (c[axis] as f64 - 1.0) * 0.5;
                            extent = extent.max(half * s as f64);
                            (-half as f32, half as f32, half.fract() as f32)
                        }
                        None => (f32::NEG_INFINITY, f32::INFINITY, 0.0),
                    };
                    if let Some(gap) = gaps[axis] {
                        let half_gap = (0.5 * s as f64 + gap) as f32;
                        let base = self.cells(reg, |base| Op::CellFace {
                            p: q,
                            axis: axis as u32,
                            base,
                            face: base + 1,
                            period: s,
                            inv_period: 1.0 / s,
                            shift,
                            lo,
                            hi,
                            half_gap,
                        });
                        fixed[axis] = base;
                        faces[axis] = base + 1;
                        reg += if base == reg { 2 } else { 0 };
                        continue;
                    }
                    let base = self.cells(reg, |base| Op::Cells {
                        p: q,
                        axis: axis as u32,
                        base,
                        other: base + 1,
                        period: s,
                        inv_period: 1.0 / s,
                        shift,
                        lo,
                        hi,
                    });
                    axes[n] = (axis as u32, base);
                    n += 1;
                    reg += if base == reg { 2 } else { 0 };
                }
                // Every copy of the child is evaluated above the cell registers (the child
                // uses the registers above its result), the last combination writes `out`.
                let acc = reg;
                self.vals = self.vals.max(acc + 2);
                // The folded point goes above the mapped one where that took `next_pt`.
                let folded = if q == next_pt { next_pt + 1 } else { next_pt };
                self.points = self.points.max(folded + 1);
                let inherited = inherited + mult * (map.translation.length() + extent);
                let corners = 1u32 << n;
                // With face bounds, the copies' minimum goes to `acc` (the child's registers
                // lie above it, clear of the face registers), and `out` takes the faces'.
                let faces: Vec<u32> = faces.into_iter().filter(|&f| f != NO_REG).collect();
                let result = if faces.is_empty() { out } else { acc };
                for corner in 0..corners {
                    let mut offs = fixed;
                    for (j, &(axis, r)) in axes[..n].iter().enumerate() {
                        offs[axis as usize] = if corner & (1 << j) != 0 { r + 1 } else { r };
                    }
                    self.ops.push(Op::Offset { src: q, dst: folded, offs });
                    let dst = if corners == 1 {
                        result
                    } else if corner == 0 {
                        acc
                    } else {
                        acc + 1
                    };
                    self.node(child, folded, DAffine3::IDENTITY, mult, inherited, dst, folded + 1);
                    if corner > 0 {
                        let dst = if corner + 1 == corners { result } else { acc };
                        self.ops.push(Op::Min { out: dst, a: acc, b: acc + 1 });
                    }
                }
                for (j, &f) in faces.iter().enumerate() {
                    self.ops.push(Op::Min { out, a: if j == 0 { result } else { out }, b: f });
                }
            }
        }
        if t.min_scale != 1.0 {
            self.ops.push(Op::Scale { a: out, s: t.min_scale });
        }
    }

    /// Emits the op of `prim` at point register `p` into `out`; returns the primitive's
    /// size (largest local coordinate magnitude of its shape), local units.
    fn primitive(&mut self, prim: &Primitive, p: u32, out: u32, scale: f32) -> f64 {
        let (op, size) = match *prim {
            Primitive::Sphere { radius } => (Op::Sphere { p, t: [0.0; 3], out, radius, scale }, radius),
            Primitive::Plane { normal, offset } => {
                (Op::Plane { p, out, normal: normal.to_array(), offset, scale }, offset.abs())
            }
            Primitive::Box { half } => (Op::Box { p, out, half: half.to_array(), scale }, half.length()),
            Primitive::Ellipsoid { radii } => (
                Op::Ellipsoid {
                    p,
                    out,
                    inv_radii: radii.recip().to_array(),
                    min_radius: radii.min_element(),
                    scale,
                },
                radii.max_element(),
            ),
            Primitive::Cylinder { radius, half_height } => {
                (Op::Cylinder { p, out, radius, half_height, scale }, radius.hypot(half_height))
            }
            Primitive::Cone { radius_bottom: r1, radius_top: r2, half_height: h } => {
                let k2 = [r2 - r1, 2.0 * h];
                let inv_k2k2 = 1.0 / (k2[0] * k2[0] + k2[1] * k2[1]);
                (Op::Cone { p, out, h, r1, r2, k2, inv_k2k2, scale }, r1.max(r2) + h)
            }
            Primitive::Torus { major, minor } => (Op::Torus { p, out, major, minor, scale }, major + minor),
            Primitive::Triangle { a, b, c } => {
                let index = self.triangles.len() as u32;
                self.triangles.push(triangle_consts(a, b, c));
                (Op::Triangle { p, out, index, scale }, a.length().max(b.length()).max(c.length()))
            }
            Primitive::Capsule { a, b, radius } => {
                let ba = b - a;
                let bb = ba.dot(ba);
                let inv_bb = if bb > 0.0 { 1.0 / bb } else { 0.0 };
                (
                    Op::Capsule { p, out, a: a.to_array(), ba: ba.to_array(), inv_bb, radius, scale },
                    a.length().max(b.length()) + radius,
                )
            }
        };
        self.ops.push(op);
        size as f64
    }
}

/// The constants of the triangle `abc`, computed in f64 and rounded once.
fn triangle_consts(a: Vec3, b: Vec3, c: Vec3) -> TriangleConsts {
    let (a64, b64, c64) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    let (ba, cb, ac) = (b64 - a64, c64 - b64, a64 - c64);
    let nor = ba.cross(ac);
    let f = |v: DVec3| v.as_vec3().to_array();
    TriangleConsts {
        a: a.to_array(),
        b: b.to_array(),
        c: c.to_array(),
        ba: f(ba),
        cb: f(cb),
        ac: f(ac),
        nor: f(nor),
        edge_n: [f(ba.cross(nor)), f(cb.cross(nor)), f(ac.cross(nor))],
        inv_nn: (1.0 / nor.length_squared()) as f32,
        inv_edge2: [
            (1.0 / ba.length_squared()) as f32,
            (1.0 / cb.length_squared()) as f32,
            (1.0 / ac.length_squared()) as f32,
        ],
    }
}

type P<L> = [L; 3];

#[inline(always)]
fn dot<L: Lane>(a: P<L>, b: P<L>) -> L {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline(always)]
fn sub3<L: Lane>(a: P<L>, b: P<L>) -> P<L> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
fn splat3<L: Lane>(tk: L::Token, v: [f32; 3]) -> P<L> {
    [L::splat(tk, v[0]), L::splat(tk, v[1]), L::splat(tk, v[2])]
}

#[inline(always)]
fn clamp01<L: Lane>(tk: L::Token, x: L) -> L {
    x.vmax(L::splat(tk, 0.0)).vmin(L::splat(tk, 1.0))
}

/// The repetition cell holding `x` (the coordinate in periods) of [`Op::Cells`] and
/// [`Op::CellFace`]: `clamp(floor(x - shift + 0.5) + shift, lo, hi)`.
#[inline(always)]
fn cell_id<L: Lane>(tk: L::Token, x: L, shift: L, lo: L, hi: L) -> L {
    ((x - shift + L::splat(tk, 0.5)).vfloor() + shift).vmax(lo).vmin(hi)
}

/// [`cell_id`] for one value, as the interval bounds of [`super::prune`] need it.
pub(crate) fn cell_index(x: f32, shift: f32, lo: f32, hi: f32) -> f32 {
    cell_id((), x, shift, lo, hi)
}

/// The polynomial smooth minimum of [`crate::geometry::sdf`] (`k` and `1 / k` given).
#[inline(always)]
fn smooth_min<L: Lane>(tk: L::Token, a: L, b: L, k: f32, inv_k: f32) -> L {
    let h = clamp01(tk, L::splat(tk, 0.5) + L::splat(tk, 0.5) * (b - a) * L::splat(tk, inv_k));
    b + (a - b) * h - L::splat(tk, k) * h * (L::splat(tk, 1.0) - h)
}

/// `|v * clamp(v . w / |v|^2, 0, 1) - w|^2`: squared distance from `w` to the segment `v`.
#[inline(always)]
fn segment2<L: Lane>(tk: L::Token, v: [f32; 3], w: P<L>, inv_vv: f32) -> L {
    let v = splat3::<L>(tk, v);
    let h = clamp01(tk, dot(v, w) * L::splat(tk, inv_vv));
    let d = [v[0] * h - w[0], v[1] * h - w[1], v[2] * h - w[2]];
    dot(d, d)
}

/// Row `r` of an affine map applied to `q`. A function rather than a closure in [`run`]:
/// a closure is compiled on its own, without the AVX2 of the function it is inlined into.
#[inline(always)]
fn affine_row<L: Lane>(tk: L::Token, r: [f32; 4], q: P<L>) -> L {
    L::splat(tk, r[0]) * q[0] + L::splat(tk, r[1]) * q[1] + L::splat(tk, r[2]) * q[2] + L::splat(tk, r[3])
}

/// Runs the tape over lanes `L`: the input point in point register 0, the result in value
/// register 0.
#[inline(always)]
fn run<'a, L: Lane>(
    ops: impl Iterator<Item = &'a Op>,
    tris: &[TriangleConsts],
    vals: &mut [L],
    pts: &mut [P<L>],
    p: P<L>,
    tk: L::Token,
) -> L {
    pts[0] = p;
    for op in ops {
        match *op {
            Op::Translate { src, dst, t } => {
                let q = pts[src as usize];
                pts[dst as usize] =
                    [q[0] + L::splat(tk, t[0]), q[1] + L::splat(tk, t[1]), q[2] + L::splat(tk, t[2])];
            }
            Op::Affine { src, dst, m } => {
                let q = pts[src as usize];
                pts[dst as usize] =
                    [affine_row(tk, m[0], q), affine_row(tk, m[1], q), affine_row(tk, m[2], q)];
            }
            Op::Sphere { p, t, out, radius, scale } => {
                let q = pts[p as usize];
                let q = [q[0] + L::splat(tk, t[0]), q[1] + L::splat(tk, t[1]), q[2] + L::splat(tk, t[2])];
                vals[out as usize] = (dot(q, q).vsqrt() - L::splat(tk, radius)) * L::splat(tk, scale);
            }
            Op::Plane { p, out, normal, offset, scale } => {
                let q = pts[p as usize];
                vals[out as usize] =
                    (dot(splat3(tk, normal), q) - L::splat(tk, offset)) * L::splat(tk, scale);
            }
            Op::Box { p, out, half, scale } => {
                let q = pts[p as usize];
                let z = L::splat(tk, 0.0);
                let d = [
                    q[0].vabs() - L::splat(tk, half[0]),
                    q[1].vabs() - L::splat(tk, half[1]),
                    q[2].vabs() - L::splat(tk, half[2]),
                ];
                let o = [d[0].vmax(z), d[1].vmax(z), d[2].vmax(z)];
                let inside = d[0].vmax(d[1]).vmax(d[2]).vmin(z);
                vals[out as usize] = (dot(o, o).vsqrt() + inside) * L::splat(tk, scale);
            }
            Op::Ellipsoid { p, out, inv_radii, min_radius, scale } => {
                let q = pts[p as usize];
                let s = [
                    q[0] * L::splat(tk, inv_radii[0]),
                    q[1] * L::splat(tk, inv_radii[1]),
                    q[2] * L::splat(tk, inv_radii[2]),
                ];
                vals[out as usize] =
                    (dot(s, s).vsqrt() - L::splat(tk, 1.0)) * L::splat(tk, min_radius) * L::splat(tk, scale);
            }
            Op::Cylinder { p, out, radius, half_height, scale } => {
                let q = pts[p as usize];
                let z = L::splat(tk, 0.0);
                let dx = (q[0] * q[0] + q[2] * q[2]).vsqrt() - L::splat(tk, radius);
                let dy = q[1].vabs() - L::splat(tk, half_height);
                let (ox, oy) = (dx.vmax(z), dy.vmax(z));
                vals[out as usize] =
                    (dx.vmax(dy).vmin(z) + (ox * ox + oy * oy).vsqrt()) * L::splat(tk, scale);
            }
            Op::Cone { p, out, h, r1, r2, k2, inv_k2k2, scale } => {
                let q = pts[p as usize];
                let z = L::splat(tk, 0.0);
                let (qx, qy) = ((q[0] * q[0] + q[2] * q[2]).vsqrt(), q[1]);
                let (k1x, k1y) = (L::splat(tk, r2), L::splat(tk, h));
                let (k2x, k2y) = (L::splat(tk, k2[0]), L::splat(tk, k2[1]));
                let r = L::select_lt(qy, z, L::splat(tk, r1), L::splat(tk, r2));
                let (cax, cay) = (qx - qx.vmin(r), qy.vabs() - k1y);
                let t = clamp01(tk, ((k1x - qx) * k2x + (k1y - qy) * k2y) * L::splat(tk, inv_k2k2));
                let (cbx, cby) = (qx - k1x + k2x * t, qy - k1y + k2y * t);
                let s = L::select_lt(cbx.vmax(cay), z, L::splat(tk, -1.0), L::splat(tk, 1.0));
                vals[out as usize] =
                    s * (cax * cax + cay * cay).vmin(cbx * cbx + cby * cby).vsqrt() * L::splat(tk, scale);
            }
            Op::Torus { p, out, major, minor, scale } => {
                let q = pts[p as usize];
                let qx = (q[0] * q[0] + q[2] * q[2]).vsqrt() - L::splat(tk, major);
                vals[out as usize] =
                    ((qx * qx + q[1] * q[1]).vsqrt() - L::splat(tk, minor)) * L::splat(tk, scale);
            }
            Op::Triangle { p, out, index, scale } => {
                let t = &tris[index as usize];
                let q = pts[p as usize];
                let pa = sub3(q, splat3(tk, t.a));
                let pb = sub3(q, splat3(tk, t.b));
                let pc = sub3(q, splat3(tk, t.c));
                // Inside the prism over the triangle when the point is on the inner side of
                // all three edge planes (the tree's sum of signs >= 2).
                let s = dot(splat3(tk, t.edge_n[0]), pa)
                    .vmin(dot(splat3(tk, t.edge_n[1]), pb))
                    .vmin(dot(splat3(tk, t.edge_n[2]), pc));
                let np = dot(splat3(tk, t.nor), pa);
                let plane2 = np * np * L::splat(tk, t.inv_nn);
                let edge2 = segment2(tk, t.ba, pa, t.inv_edge2[0])
                    .vmin(segment2(tk, t.cb, pb, t.inv_edge2[1]))
                    .vmin(segment2(tk, t.ac, pc, t.inv_edge2[2]));
                vals[out as usize] =
                    L::select_lt(s, L::splat(tk, 0.0), edge2, plane2).vsqrt() * L::splat(tk, scale);
            }
            Op::Capsule { p, out, a, ba, inv_bb, radius, scale } => {
                let q = pts[p as usize];
                let pa = sub3(q, splat3(tk, a));
                let ba = splat3::<L>(tk, ba);
                let h = clamp01(tk, dot(pa, ba) * L::splat(tk, inv_bb));
                let d = [pa[0] - ba[0] * h, pa[1] - ba[1] * h, pa[2] - ba[2] * h];
                vals[out as usize] = (dot(d, d).vsqrt() - L::splat(tk, radius)) * L::splat(tk, scale);
            }
            Op::Min { out, a, b } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = y.vmin(x);
            }
            Op::Max { out, a, b } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = y.vmax(x);
            }
            Op::Subtract { out, a, b } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = (-y).vmax(x);
            }
            Op::SmoothUnion { out, a, b, k, inv_k } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = smooth_min(tk, x, y, k, inv_k);
            }
            Op::SmoothIntersection { out, a, b, k, inv_k } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = -smooth_min(tk, -x, -y, k, inv_k);
            }
            Op::SmoothSubtraction { out, a, b, k, inv_k } => {
                let (x, y) = (vals[a as usize], vals[b as usize]);
                vals[out as usize] = -smooth_min(tk, -x, y, k, inv_k);
            }
            Op::Scale { a, s } => {
                vals[a as usize] = vals[a as usize] * L::splat(tk, s);
            }
            Op::Cells { p, axis, base, other, period, inv_period, shift, lo, hi } => {
                let x = pts[p as usize][axis as usize] * L::splat(tk, inv_period);
                let (lo, hi) = (L::splat(tk, lo), L::splat(tk, hi));
                let id = cell_id(tk, x, L::splat(tk, shift), lo, hi);
                let step = L::select_lt(id, x, L::splat(tk, 1.0), L::splat(tk, -1.0));
                let next = (id + step).vmax(lo).vmin(hi);
                vals[base as usize] = id * L::splat(tk, period);
                vals[other as usize] = next * L::splat(tk, period);
            }
            Op::CellFace { p, axis, base, face, period, inv_period, shift, lo, hi, half_gap } => {
                let v = pts[p as usize][axis as usize];
                let x = v * L::splat(tk, inv_period);
                let (lo, hi) = (L::splat(tk, lo), L::splat(tk, hi));
                let id = cell_id(tk, x, L::splat(tk, shift), lo, hi);
                let offset = id * L::splat(tk, period);
                let local = v - offset;
                let inf = L::splat(tk, f32::INFINITY);
                let up = L::select_lt(id, hi, L::splat(tk, half_gap) - local, inf);
                let down = L::select_lt(lo, id, L::splat(tk, half_gap) + local, inf);
                vals[base as usize] = offset;
                vals[face as usize] = down.vmin(up);
            }
            Op::Offset { src, dst, offs } => {
                let q = pts[src as usize];
                let mut r = q;
                for i in 0..3 {
                    if offs[i] != NO_REG {
                        r[i] = q[i] - vals[offs[i] as usize];
                    }
                }
                pts[dst as usize] = r;
            }
            Op::Copy { out, a } => vals[out as usize] = vals[a as usize],
            Op::Neg { out, a } => vals[out as usize] = -vals[a as usize],
        }
    }
    vals[0]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::shape::ObjectKind;
    use crate::scene::transform::TransformDesc;
    use glam::UVec3;

    fn obj(kind: ObjectKind) -> Object {
        Object { kind, transform: TransformDesc::default(), material: 0, label: "t".into() }
    }

    fn prim(p: Primitive, translate: Vec3, rotate: Vec3, scale: Vec3) -> Object {
        Object {
            transform: TransformDesc { translate, rotate_deg: rotate, scale },
            ..obj(ObjectKind::Primitive(p))
        }
    }

    /// Every primitive kind, transformed, in a smooth union (with a subtraction and a
    /// repetition inside) placed away from the world origin.
    fn zoo() -> Object {
        let tr = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let kids = vec![
            prim(Primitive::Sphere { radius: 0.7 }, tr(0.0, 0.0, 0.0), Vec3::ZERO, Vec3::ONE),
            prim(
                Primitive::Box { half: tr(0.3, 0.5, 0.2) },
                tr(1.0, 0.2, 0.0),
                tr(10.0, 20.0, 30.0),
                Vec3::ONE,
            ),
            prim(
                Primitive::Ellipsoid { radii: tr(0.5, 0.2, 0.3) },
                tr(-1.0, 0.0, 0.3),
                Vec3::ZERO,
                Vec3::ONE,
            ),
            prim(
                Primitive::Cylinder { radius: 0.3, half_height: 0.6 },
                tr(0.0, 1.0, 0.0),
                tr(0.0, 0.0, 40.0),
                tr(1.0, 2.0, 0.5),
            ),
            prim(
                Primitive::Cone { radius_bottom: 0.4, radius_top: 0.1, half_height: 0.5 },
                tr(0.0, -1.0, 0.5),
                Vec3::ZERO,
                Vec3::ONE,
            ),
            prim(
                Primitive::Torus { major: 0.6, minor: 0.1 },
                tr(0.5, 0.5, -0.5),
                tr(60.0, 0.0, 0.0),
                Vec3::ONE,
            ),
            prim(
                Primitive::Triangle { a: Vec3::ZERO, b: Vec3::X, c: tr(0.2, 0.9, 0.1) },
                tr(-1.0, 1.0, 0.0),
                Vec3::ZERO,
                Vec3::splat(0.5),
            ),
            prim(
                Primitive::Capsule { a: tr(-0.3, 0.0, 0.0), b: tr(0.3, 0.2, 0.0), radius: 0.15 },
                tr(1.0, -1.0, 0.0),
                Vec3::ZERO,
                Vec3::ONE,
            ),
            obj(ObjectKind::Csg {
                op: CsgOp::Subtraction,
                children: vec![
                    prim(Primitive::Box { half: Vec3::splat(0.4) }, tr(0.0, 0.0, 1.2), Vec3::ZERO, Vec3::ONE),
                    prim(Primitive::Sphere { radius: 0.5 }, tr(0.2, 0.2, 1.0), Vec3::ZERO, Vec3::ONE),
                ],
            }),
            Object {
                transform: TransformDesc { translate: tr(0.0, 0.0, -1.5), ..Default::default() },
                ..obj(ObjectKind::Repeat {
                    period: tr(0.5, 0.0, 0.5),
                    count: Some(UVec3::new(3, 1, 2)),
                    child: Box::new(prim(
                        Primitive::Sphere { radius: 0.2 },
                        Vec3::ZERO,
                        Vec3::ZERO,
                        Vec3::ONE,
                    )),
                })
            },
        ];
        Object {
            transform: TransformDesc {
                translate: tr(30.0, -20.0, 100.0),
                rotate_deg: tr(5.0, 10.0, 15.0),
                scale: Vec3::splat(1.5),
            },
            ..obj(ObjectKind::Csg { op: CsgOp::SmoothUnion { k: 0.2 }, children: kids })
        }
    }

    /// Deterministic points around the tape origin within `r`.
    fn points(n: usize, r: f32) -> Vec<Vec3> {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut u = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        (0..n).map(|_| Vec3::new(u(), u(), u()) * r).collect()
    }

    #[test]
    fn tape_matches_tree_and_lanes_match_scalar() {
        let o = zoo();
        let tree = SdfTree::new(&o).unwrap();
        let tape = Tape::from_object(&o).unwrap();
        let mut scratch = TapeScratch::new(&tape);
        let pts = points(4096, 1.2 * tape.reach as f32);
        for chunk in pts.chunks_exact(8) {
            let xs = std::array::from_fn(|l| chunk[l].x);
            let ys = std::array::from_fn(|l| chunk[l].y);
            let zs = std::array::from_fn(|l| chunk[l].z);
            let wide = tape.eval8(&xs, &ys, &zs, &mut scratch);
            let portable = tape.eval8_portable(&xs, &ys, &zs, &mut scratch);
            // The same packet as each of four in a 32-lane evaluation, beside other points.
            let shift = |a: &[f32; 8], g: usize| a.map(|x| x * (1.0 - 0.1 * g as f32));
            let four = |a: &[f32; 8]| std::array::from_fn(|g| if g == 2 { *a } else { shift(a, g) });
            let wider =
                tape.eval32_ops(Ops::All(tape.ops()), &four(&xs), &four(&ys), &four(&zs), &mut scratch);
            let bits = |a: [f32; 8]| a.map(f32::to_bits);
            assert_eq!(bits(wider[2]), bits(wide), "packet 2 of 4");
            for (l, &p) in chunk.iter().enumerate() {
                let d = tape.eval(p, &mut scratch);
                assert_eq!(d.to_bits(), wide[l].to_bits(), "lane {l} at {p}");
                assert_eq!(d.to_bits(), portable[l].to_bits(), "portable lane {l} at {p}");
                let reference = tree.distance(tape.origin + p.as_dvec3());
                let err = (d as f64 - reference).abs();
                assert!(err <= tape.error_bound(p.length() as f64), "{d} vs {reference} at {p}");
            }
        }
    }

    #[test]
    fn transforms_are_folded_into_one_op_per_primitive() {
        let tape = Tape::from_object(&zoo()).unwrap();
        let moves =
            tape.ops().iter().filter(|o| matches!(o, Op::Translate { .. } | Op::Affine { .. })).count();
        // Ten children: eight primitives, a subtraction of two and a repetition (one point
        // op for the repetition node, none for the four unrolled copies of its identity child).
        assert_eq!(moves, 8 + 2 + 1);
        assert!(tape.bytes_used() > 0);
        let scratch = TapeScratch::new(&tape);
        assert!(scratch.fits(&tape));
    }

    #[test]
    fn infinite_repetition_far_from_the_origin() {
        let s = obj(ObjectKind::Primitive(Primitive::Sphere { radius: 0.5 }));
        let o = obj(ObjectKind::Repeat { period: Vec3::new(2.0, 0.0, 3.0), count: None, child: Box::new(s) });
        let tree = SdfTree::new(&o).unwrap();
        let tape = Tape::from_object(&o).unwrap();
        assert_eq!(tape.origin, DVec3::ZERO);
        let mut scratch = TapeScratch::new(&tape);
        for p in points(2000, 300.0) {
            let d = tape.eval(p, &mut scratch) as f64;
            let reference = tree.distance(p.as_dvec3());
            assert!(
                (d - reference).abs() <= tape.error_bound(p.length() as f64),
                "{d} vs {reference} at {p}"
            );
        }
    }

    #[test]
    fn f32_is_not_enough_for_the_ground_sphere() {
        // data/hard/ground_5000.toml: seen from about 6 units away, with the default
        // relative tolerance of 1e-4 (a quarter of the default pixel footprint is larger).
        let tolerance = 1e-4 * 6.0;
        let mut ground = obj(ObjectKind::Primitive(Primitive::Sphere { radius: 5000.0 }));
        ground.transform.translate = Vec3::new(0.0, -5001.0, 0.0);
        assert!(!Tape::from_object(&ground).unwrap().f32_is_enough(tolerance));
        let unit = obj(ObjectKind::Primitive(Primitive::Sphere { radius: 1.0 }));
        assert!(Tape::from_object(&unit).unwrap().f32_is_enough(tolerance));
        // The zoo far from the world origin is fine: its tape is relative to its centre.
        assert!(Tape::from_object(&zoo()).unwrap().f32_is_enough(tolerance));
    }

    #[test]
    fn meshes_have_no_tape() {
        let mesh = crate::mesh::TriangleMesh::default();
        let o = obj(ObjectKind::Mesh {
            mesh: std::sync::Arc::new(mesh),
            source: "m.obj".into(),
            shading: Default::default(),
        });
        assert!(Tape::from_object(&o).is_none());
    }
}
