//! Signed distance functions: exact distances for every closed-form primitive where one
//! exists, CSG (sharp and smooth), domain repetition and transforms, compiled into a tree
//! that is evaluated without allocating. Each node knows whether it returns the exact
//! Euclidean distance or only a Lipschitz-1 lower bound (safe for sphere tracing).
//! [`tape`] compiles the tree into a flat f32 program evaluated one or eight points at a
//! time. [`SdfField`], the field the marcher traces, evaluates the tape wherever its f32
//! error bound is within the hit tolerance the march asks for at that step, and the f64
//! tree elsewhere (the radius-5000 ground sphere seen from nearby, a surface a secondary
//! ray starts on); materials and the error measurements always use the tree.

pub mod prune;
pub mod tape;

use crate::geometry::march::MarchParams;
use crate::geometry::marched::{
    BlockKind, DistanceField, FieldFacts, FieldObject, Lanes32, Marched, PointBlock, Rays32, Storage,
    SurfacePoint, WIDE,
};
use crate::geometry::scene::SceneGeometry;
use crate::geometry::{
    Census, Geometry, Hit, PACKET, Ray, RayStats, distance_by_projection, f32_error, max_abs,
};
use crate::scene::shape::grow;
use crate::simd::{Kernel, Lane64, Simd, dispatch};
use glam::{DVec2, DVec3, UVec3, Vec3};

use crate::geometry::MaterialId;
use crate::scene::shape::{CsgOp, Object, ObjectKind, Primitive};
use crate::scene::transform::{Transform, TransformDesc};

/// Signed distance from local point `p` to `prim`: negative inside. Exact except for the
/// ellipsoid (a Lipschitz-1 lower bound) and the triangle (unsigned, since it has no inside).
pub fn primitive_distance(prim: &Primitive, p: Vec3) -> f32 {
    primitive_distance_f64(prim, p.as_dvec3()) as f32
}

/// [`primitive_distance`] in f64. The tracer evaluates distances in f64: a radius-5000
/// sphere seen from near its surface has no precision left in f32 local coordinates.
pub fn primitive_distance_f64(prim: &Primitive, p: DVec3) -> f64 {
    match *prim {
        Primitive::Sphere { radius } => p.length() - radius as f64,
        Primitive::Plane { normal, offset } => normal.as_dvec3().dot(p) - offset as f64,
        Primitive::Box { half } => {
            let q = p.abs() - half.as_dvec3();
            q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
        }
        Primitive::Ellipsoid { radii } => {
            // |p/r| - 1 has gradient at most 1/min(r); scaling by min(r) makes it a bound.
            let r = radii.as_dvec3();
            ((p / r).length() - 1.0) * r.min_element()
        }
        Primitive::Cylinder { radius, half_height } => {
            let d = DVec2::new(DVec2::new(p.x, p.z).length() - radius as f64, p.y.abs() - half_height as f64);
            d.max_element().min(0.0) + d.max(DVec2::ZERO).length()
        }
        Primitive::Cone { radius_bottom, radius_top, half_height } => {
            capped_cone(p, half_height as f64, radius_bottom as f64, radius_top as f64)
        }
        Primitive::Torus { major, minor } => {
            let q = DVec2::new(DVec2::new(p.x, p.z).length() - major as f64, p.y);
            q.length() - minor as f64
        }
        Primitive::Triangle { a, b, c } => triangle_distance(p, a.as_dvec3(), b.as_dvec3(), c.as_dvec3()),
        Primitive::Capsule { a, b, radius } => {
            let (a, b) = (a.as_dvec3(), b.as_dvec3());
            let pa = p - a;
            let ba = b - a;
            // A capsule with a == b is a sphere (no 0/0).
            let bb = ba.dot(ba);
            let h = if bb > 0.0 { (pa.dot(ba) / bb).clamp(0.0, 1.0) } else { 0.0 };
            (pa - ba * h).length() - radius as f64
        }
    }
}

/// Whether [`primitive_distance`] is the exact Euclidean distance for `prim`.
pub fn primitive_is_exact(prim: &Primitive) -> bool {
    !matches!(prim, Primitive::Ellipsoid { radii } if radii.max_element() != radii.min_element())
}

/// Exact distance to a capped cone around y (Quilez): radius `r1` at `y = -h`, `r2` at `y = h`.
fn capped_cone(p: DVec3, h: f64, r1: f64, r2: f64) -> f64 {
    let q = DVec2::new(DVec2::new(p.x, p.z).length(), p.y);
    let k1 = DVec2::new(r2, h);
    let k2 = DVec2::new(r2 - r1, 2.0 * h);
    let ca = DVec2::new(q.x - q.x.min(if q.y < 0.0 { r1 } else { r2 }), q.y.abs() - h);
    let cb = q - k1 + k2 * ((k1 - q).dot(k2) / k2.dot(k2)).clamp(0.0, 1.0);
    let s = if cb.x < 0.0 && ca.y < 0.0 { -1.0 } else { 1.0 };
    s * ca.length_squared().min(cb.length_squared()).sqrt()
}

/// Exact unsigned distance from `p` to the triangle `abc`.
pub fn triangle_distance(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let ba = b - a;
    let pa = p - a;
    let cb = c - b;
    let pb = p - b;
    let ac = a - c;
    let pc = p - c;
    let nor = ba.cross(ac);
    let inside =
        ba.cross(nor).dot(pa).signum() + cb.cross(nor).dot(pb).signum() + ac.cross(nor).dot(pc).signum()
            >= 2.0;
    let d2 = if inside {
        nor.dot(pa) * nor.dot(pa) / nor.length_squared()
    } else {
        let e =
            |v: DVec3, w: DVec3| (v * (v.dot(w) / v.length_squared()).clamp(0.0, 1.0) - w).length_squared();
        e(ba, pa).min(e(cb, pb)).min(e(ac, pc))
    };
    d2.sqrt()
}

/// Polynomial smooth minimum (Quilez) of blend radius `k`; Lipschitz 1 when `a` and `b` are.
/// Returns the value and the blend weight of `a` (1 = all `a`).
#[inline]
fn smooth_min(a: f64, b: f64, k: f64) -> (f64, f64) {
    let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
    let d = b + (a - b) * h - k * h * (1.0 - h);
    (d, h)
}

/// A compiled SDF node. Distances are in the frame of the node's parent.
#[derive(Clone, Debug)]
pub enum SdfNode {
    /// A primitive under a transform.
    Primitive {
        /// The shape, in its local frame.
        prim: Primitive,
        /// Local frame to parent frame.
        transform: Transform,
        /// The material of its surface.
        material: MaterialId,
    },
    /// A CSG operation under a transform.
    Csg {
        /// How the children combine.
        op: CsgOp,
        /// The operands, in the operation's local frame.
        children: Vec<SdfNode>,
        /// Local frame to parent frame.
        transform: Transform,
    },
    /// Domain repetition under a transform (see [`ObjectKind::Repeat`]). `gaps[axis]`:
    /// where the child's bounds keep at least this distance (> 0, local units) from its
    /// cell's faces along that axis ([`cell_gaps`]), the neighbouring cells along it are
    /// bounded by the face instead of evaluated ([`eval_repeat`]).
    Repeat {
        /// Spacing of the copies per axis (local units); 0 for an axis not repeated.
        period: Vec3,
        /// Copies per repeated axis, centred on the origin; `None` for infinitely many.
        count: Option<UVec3>,
        /// What each cell holds.
        child: Box<SdfNode>,
        /// Local frame to parent frame.
        transform: Transform,
        /// Per axis, the child's clearance from its cell's faces, when positive.
        gaps: [Option<f64>; 3],
    },
}

/// Per axis of a finite repetition with more than one copy along it, the distance between
/// `child`'s bounds and the faces of its cell (a box of `period` centred on the origin)
/// when it is positive (above a millionth of the period): then no copy reaches into the
/// next cell along that axis, with room to spare. `None` for the other axes, and for every
/// axis of an infinite repetition (whose rays graze across many cells, where the face
/// bound would cost more steps than the neighbours' evaluations save).
pub fn cell_gaps(period: Vec3, count: Option<UVec3>, child: &Object) -> [Option<f64>; 3] {
    let (Some(count), Some(b)) = (count, child.bounds()) else { return [None; 3] };
    let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
    std::array::from_fn(|axis| {
        let s = period[axis] as f64;
        // The bounds are f32, each end within a rounding of the child's true extent
        // (translation plus half size, rounded once): less that, so that the face bound
        // never exceeds the distance to a neighbouring copy.
        let rounding = 4.0 * f32::EPSILON as f64 * (0.5 * s + (hi[axis].abs()).max(lo[axis].abs()) as f64);
        let gap = (0.5 * s - hi[axis] as f64).min(lo[axis] as f64 + 0.5 * s) - rounding;
        (s > 0.0 && count[axis] > 1 && gap.is_finite() && gap > 1e-6 * s).then_some(gap)
    })
}

/// A compiled object tree with its distance bound kind.
#[derive(Clone, Debug)]
pub struct SdfTree {
    /// The root node.
    pub root: SdfNode,
    /// True when `distance` is the exact Euclidean distance everywhere; false when it is
    /// only a Lipschitz-1 lower bound (ellipsoids, smooth blends, non-uniform scale, repetition).
    pub exact: bool,
    /// False when the tree holds a triangle: its distance is unsigned (it has no inside),
    /// so the gradient is undefined on the surface itself.
    pub signed: bool,
    /// Number of nodes in the tree (for bytes used).
    pub node_count: usize,
}

impl SdfTree {
    /// Compiles an object tree; `None` when it holds a mesh. Repetitions evaluate the
    /// nearest cell and its neighbours on every repeated axis: the field that grids are
    /// sampled from and meshes extracted from, whose values away from the surface are the
    /// distance to the nearest copy.
    pub fn new(object: &Object) -> Option<Self> {
        Self::compiled(object, false)
    }

    /// [`SdfTree::new`] for sphere tracing: along an axis where a finite repetition's child
    /// stays inside its cell ([`cell_gaps`]), the neighbours are bounded by the cell's face
    /// instead of evaluated, except under a smooth blend. The bound is positive where the
    /// neighbours' value is and only lowers positive values, and sharp CSG depends only on
    /// its operands' signs, so the surface is the same; away from it the value is a bound
    /// a march may step by, but not what a grid or a mesh extraction should interpolate.
    /// For the same reason a repetition of a sharp union is distributed over the union's
    /// children where that evaluates fewer primitives ([`distributed`]).
    pub fn for_marching(object: &Object) -> Option<Self> {
        Self::compiled(object, true)
    }

    fn compiled(object: &Object, cell_faces: bool) -> Option<Self> {
        let mut exact = true;
        let mut node_count = 0;
        let root = compile(object, cell_faces, &mut exact, &mut node_count)?;
        let signed = !contains_triangle(object);
        Some(SdfTree { root, exact, signed, node_count })
    }

    /// Signed distance (or a Lipschitz-1 lower bound of it) at world point `p`.
    #[inline]
    pub fn distance(&self, p: DVec3) -> f64 {
        self.root.eval(p).0
    }

    /// Signed distance and the material of the surface nearest to `p`.
    #[inline]
    pub fn distance_material(&self, p: DVec3) -> (f64, MaterialId) {
        self.root.eval(p)
    }

    /// An upper bound on the primitives one [`SdfTree::distance`] evaluates
    /// ([`evaluations`]).
    pub fn evaluations(&self) -> f64 {
        evaluations(&self.root)
    }

    /// Approximate bytes held by the tree.
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.node_count * std::mem::size_of::<SdfNode>()
    }
}

/// An upper bound on the primitives one evaluation of `node` evaluates, in f64 so that it
/// cannot overflow: a CSG node evaluates all its children, a repetition its child once
/// per combination of cells ([`eval_repeat`]: two cells along each repeated axis with more
/// than one copy and no gap), so nested repetitions multiply (40 levels of 2 copies evaluate
/// 2^40 primitives per distance).
pub fn evaluations(node: &SdfNode) -> f64 {
    match node {
        SdfNode::Primitive { .. } => 1.0,
        SdfNode::Csg { children, .. } => children.iter().map(evaluations).sum(),
        SdfNode::Repeat { period, count, child, gaps, .. } => {
            let axes = (0..3)
                .filter(|&a| period[a] > 0.0 && gaps[a].is_none() && count.is_none_or(|c| c[a] > 1))
                .count();
            (1u32 << axes) as f64 * evaluations(child)
        }
    }
}

fn contains_triangle(object: &Object) -> bool {
    match &object.kind {
        ObjectKind::Primitive(p) => matches!(p, Primitive::Triangle { .. }),
        ObjectKind::Csg { children, .. } => children.iter().any(contains_triangle),
        ObjectKind::Repeat { child, .. } => contains_triangle(child),
        ObjectKind::Mesh { .. } => true,
        ObjectKind::Grid { .. } | ObjectKind::Implicit { .. } => false,
    }
}

/// Compiles `object` (`cell_faces`: see [`SdfTree::for_marching`]), or `None` when it holds
/// a mesh or a grid file (no analytic SDF).
fn compile(object: &Object, cell_faces: bool, exact: &mut bool, count: &mut usize) -> Option<SdfNode> {
    *count += 1;
    let transform = object.compiled_transform();
    if !transform.is_uniform() {
        *exact = false;
    }
    Some(match &object.kind {
        ObjectKind::Mesh { .. } | ObjectKind::Grid { .. } | ObjectKind::Implicit { .. } => return None,
        ObjectKind::Primitive(prim) => {
            if !primitive_is_exact(prim) {
                *exact = false;
            }
            SdfNode::Primitive { prim: *prim, transform, material: object.material }
        }
        ObjectKind::Csg { op, children } => {
            // Sharp union, intersection and subtraction of exact SDFs are exact outside and
            // bounds inside; treat all CSG as a bound except a plain union.
            if !matches!(op, CsgOp::Union) {
                *exact = false;
            }
            // A smooth blend's operands shape its surface wherever they are within the
            // blend radius of each other, also away from their own surfaces: below one,
            // repetitions keep their neighbours so that the surface stays the same.
            let sharp = matches!(op, CsgOp::Union | CsgOp::Intersection | CsgOp::Subtraction);
            let faces = cell_faces && sharp;
            let children = children.iter().map(|c| compile(c, faces, exact, count)).collect::<Option<_>>()?;
            SdfNode::Csg { op: *op, children, transform }
        }
        ObjectKind::Repeat { period, count: reps, child } => {
            *exact = false;
            if cell_faces && let Some(simpler) = distributed(object).or_else(|| merged_box(object)) {
                *count -= 1;
                return compile(&simpler, cell_faces, exact, count);
            }
            let gaps = if cell_faces { cell_gaps(*period, *reps, child) } else { [None; 3] };
            let child = Box::new(compile(child, cell_faces, exact, count)?);
            SdfNode::Repeat { period: *period, count: *reps, child, transform, gaps }
        }
    })
}

/// Tape cost of `object` as [`SdfTree::for_marching`] compiles it: primitive evaluations
/// per distance, a repetition counting its child once per evaluated cell combination
/// (`2^k` for `k` repeated axes without a [`cell_gaps`] gap).
fn march_cost(object: &Object) -> f64 {
    match &object.kind {
        ObjectKind::Primitive(_)
        | ObjectKind::Mesh { .. }
        | ObjectKind::Grid { .. }
        | ObjectKind::Implicit { .. } => 1.0,
        ObjectKind::Csg { children, .. } => children.iter().map(march_cost).sum(),
        ObjectKind::Repeat { period, count, child } => {
            let gaps = cell_gaps(*period, *count, child);
            let cells = (0..3).filter(|&a| period[a] > 0.0 && gaps[a].is_none()).count();
            (1u32 << cells) as f64 * march_cost(child)
        }
    }
}

/// A repetition of a sharp union distributed over the union's children, when that is
/// cheaper to march: `repeat(a | b | c) = repeat(a) | repeat(b) | repeat(c)` (the same
/// set of copies), and each child's own repetition keeps to the cells it reaches. A
/// Menger cross (three bars, each reaching into the neighbouring cells along its length
/// only) costs 3 bars x 8 cell combinations as one repetition, 3 x 2 distributed. The
/// union's transform and material stay on a one-child union around each child; the
/// repetition's on the new union. `None` when `object` is not such a repetition or
/// distributing would not evaluate fewer primitives ([`march_cost`]).
fn distributed(object: &Object) -> Option<Object> {
    let ObjectKind::Repeat { period, count, child } = &object.kind else { return None };
    let ObjectKind::Csg { op: CsgOp::Union, children } = &child.kind else { return None };
    if children.len() < 2 {
        return None;
    }
    let repeat = |c: &Object| {
        let inner = if child.transform == TransformDesc::default() {
            c.clone()
        } else {
            Object {
                kind: ObjectKind::Csg { op: CsgOp::Union, children: vec![c.clone()] },
                transform: child.transform,
                material: child.material,
                label: child.label.clone(),
            }
        };
        Object {
            kind: ObjectKind::Repeat { period: *period, count: *count, child: Box::new(inner) },
            transform: TransformDesc::default(),
            material: object.material,
            label: object.label.clone(),
        }
    };
    let copies: Vec<Object> = children.iter().map(repeat).collect();
    let after: f64 = copies.iter().map(march_cost).sum();
    (after < march_cost(object)).then(|| Object {
        kind: ObjectKind::Csg { op: CsgOp::Union, children: copies },
        transform: object.transform,
        material: object.material,
        label: object.label.clone(),
    })
}

/// A finite repetition of an axis-aligned box (under a translation only) whose copies
/// overlap or touch along an axis, with that axis replaced by one box stretched over all
/// its copies: `n` boxes of half size `h` every `p <= 2 h` along an axis cover exactly the
/// box of half size `h + (n - 1) p / 2` there, whose distance is exact where the copies'
/// minimum is only a bound inside, and which costs one evaluation instead of the nearest
/// copy and its neighbour. A bar of a Menger cross after [`distributed`] is such a box.
/// The other axes stay repeated; with none left, the box under the repetition's transform.
/// `None` when `object` is not such a repetition.
fn merged_box(object: &Object) -> Option<Object> {
    let ObjectKind::Repeat { period, count: Some(count), child } = &object.kind else { return None };
    let ObjectKind::Primitive(Primitive::Box { half }) = child.kind else { return None };
    if child.transform.rotate_deg != Vec3::ZERO || child.transform.scale != Vec3::ONE {
        return None;
    }
    let (mut period, mut count, mut half) = (*period, *count, half);
    let mut merged = false;
    for a in 0..3 {
        if period[a] > 0.0 && count[a] >= 2 && period[a] <= 2.0 * half[a] {
            half[a] += (count[a] - 1) as f32 * 0.5 * period[a];
            (period[a], count[a], merged) = (0.0, 1, true);
        }
    }
    if !merged {
        return None;
    }
    let bar = Object { kind: ObjectKind::Primitive(Primitive::Box { half }), ..(**child).clone() };
    let kind = if (0..3).any(|a| period[a] > 0.0 && count[a] >= 2) {
        ObjectKind::Repeat { period, count: Some(count), child: Box::new(bar) }
    } else {
        ObjectKind::Csg { op: CsgOp::Union, children: vec![bar] }
    };
    Some(Object { kind, transform: object.transform, material: object.material, label: object.label.clone() })
}

impl SdfNode {
    fn transform(&self) -> &Transform {
        match self {
            SdfNode::Primitive { transform, .. }
            | SdfNode::Csg { transform, .. }
            | SdfNode::Repeat { transform, .. } => transform,
        }
    }

    /// Distance at `p` (parent frame) and the material of the nearest surface.
    pub fn eval(&self, p: DVec3) -> (f64, MaterialId) {
        let t = self.transform();
        let q = t.point_to_local_f64(p);
        let (d, m) = match self {
            SdfNode::Primitive { prim, material, .. } => (primitive_distance_f64(prim, q), *material),
            SdfNode::Csg { op, children, .. } => eval_csg(*op, children, q),
            SdfNode::Repeat { period, count, child, gaps, .. } => {
                eval_repeat(*period, *count, child, gaps, q)
            }
        };
        // Rotation and translation keep distances; scale multiplies them. The smallest scale
        // factor keeps the result a lower bound under non-uniform scale.
        (d * t.min_scale as f64, m)
    }
}

fn eval_csg(op: CsgOp, children: &[SdfNode], q: DVec3) -> (f64, MaterialId) {
    let (mut d, mut m) = children[0].eval(q);
    for c in &children[1..] {
        let (e, cm) = c.eval(q);
        match op {
            CsgOp::Union => {
                if e < d {
                    (d, m) = (e, cm);
                }
            }
            CsgOp::Intersection => {
                if e > d {
                    (d, m) = (e, cm);
                }
            }
            CsgOp::Subtraction => {
                if -e > d {
                    (d, m) = (-e, cm);
                }
            }
            CsgOp::SmoothUnion { k } => {
                let (v, h) = smooth_min(d, e, k as f64);
                d = v;
                if h < 0.5 {
                    m = cm;
                }
            }
            CsgOp::SmoothIntersection { k } => {
                let (v, h) = smooth_min(-d, -e, k as f64);
                d = -v;
                if h < 0.5 {
                    m = cm;
                }
            }
            CsgOp::SmoothSubtraction { k } => {
                let (v, h) = smooth_min(-d, e, k as f64);
                d = -v;
                if h < 0.5 {
                    m = cm;
                }
            }
        }
    }
    (d, m)
}

/// Repetition: the child is evaluated in the cell that holds `q` and in the neighbouring cell
/// on the nearer side along each repeated axis, so a child that reaches into its neighbours
/// is still seen. The result is a lower bound when the child stays within one period of its
/// cell centre.
///
/// Along an axis with a gap ([`cell_gaps`]: every copy stays at least `gap` inside its
/// cell along it), the neighbouring cell is not evaluated: the result is `min(d, face +
/// gap)` over those axes, `face` being the distance from `q` to the nearest cell's face on
/// that axis that has a neighbouring cell. Any copy in another cell along that axis lies
/// beyond that face by at least `gap`, so this is a Lipschitz-1 lower bound of the
/// distance to all copies, equal to `d` within `gap` of the surface (the zero set does not
/// change); a child that fits its cell on all three axes is evaluated once instead of 8
/// times.
fn eval_repeat(
    period: Vec3,
    count: Option<UVec3>,
    child: &SdfNode,
    gaps: &[Option<f64>; 3],
    q: DVec3,
) -> (f64, MaterialId) {
    let mut base = [0.0f64; 3];
    let mut other = [0.0f64; 3];
    let mut repeated = [false; 3];
    let mut face = f64::INFINITY;
    for axis in 0..3 {
        let s = period[axis] as f64;
        if s <= 0.0 {
            continue;
        }
        repeated[axis] = true;
        let x = q[axis] / s;
        let (lo, hi, shift) = match count {
            Some(c) => {
                let half = (c[axis] as f64 - 1.0) * 0.5;
                (-half, half, half.fract())
            }
            None => (f64::NEG_INFINITY, f64::INFINITY, 0.0),
        };
        // Cell centres sit at (k + shift) * s for integer k (shift 0.5 for even counts).
        let id = ((x - shift).round() + shift).clamp(lo, hi);
        let next = (id + if x > id { 1.0 } else { -1.0 }).clamp(lo, hi);
        base[axis] = id * s;
        other[axis] = next * s;
        if let Some(g) = gaps[axis] {
            // Bounded by the face: the corners below skip this axis (other == base).
            other[axis] = base[axis];
            let (local, half) = (q[axis] - base[axis], 0.5 * s + g);
            if id < hi {
                face = face.min(half - local);
            }
            if id > lo {
                face = face.min(half + local);
            }
        }
    }
    let mut best = (f64::INFINITY, 0);
    for corner in 0..8u32 {
        let mut offset = DVec3::ZERO;
        let mut skip = false;
        for axis in 0..3 {
            let use_other = corner & (1 << axis) != 0;
            if use_other && (!repeated[axis] || other[axis] == base[axis]) {
                skip = true;
                break;
            }
            offset[axis] = if use_other { other[axis] } else { base[axis] };
        }
        if skip {
            continue;
        }
        let r = child.eval(q - offset);
        if r.0 < best.0 {
            best = r;
        }
    }
    if face < best.0 { (face, best.1) } else { best }
}

/// Longest tape compiled for rendering; a longer one (nested repetition unrolls `2^k`
/// copies per level) is not built and the tree is evaluated instead.
pub const MAX_TAPE_OPS: usize = 1 << 16;

/// The analytic field the marcher traces: the f64 [`SdfTree`] and, for a compound object
/// (CSG, repetition) whose tape is not too long ([`MAX_TAPE_OPS`]), its compiled f32
/// [`Tape`](tape::Tape). Each distance asked for
/// with a tolerance ([`DistanceField::distance`]) comes from the tape when the
/// tape's error bound at that point ([`tape::Tape::error_bound`] of `|p - origin|`) is at
/// most a quarter of the tolerance, from the tree otherwise.
#[derive(Clone, Debug)]
pub struct SdfField {
    /// The f64 tree: the precise distance, materials, error measurements.
    pub tree: SdfTree,
    /// The compiled tape, `None` for a single primitive or when longer than
    /// [`MAX_TAPE_OPS`].
    pub tape: Option<tape::Tape>,
    /// The material of every primitive when they all have the same one (no lookup per
    /// hit), else `None` (the tree finds the nearest primitive's).
    pub uniform_material: Option<MaterialId>,
    /// The tape shortened per region of the object's bounds ([`prune::TapeRegions`]),
    /// where that pays; points outside the regions run the whole tape.
    pub regions: Option<prune::TapeRegions>,
}

/// The material every primitive under `node` has, if they all have the same one.
fn uniform_material(node: &SdfNode) -> Option<MaterialId> {
    match node {
        SdfNode::Primitive { material, .. } => Some(*material),
        SdfNode::Repeat { child, .. } => uniform_material(child),
        SdfNode::Csg { children, .. } => {
            let first = uniform_material(children.first()?)?;
            children.iter().skip(1).all(|c| uniform_material(c) == Some(first)).then_some(first)
        }
    }
}

thread_local! {
    /// Registers for evaluating tapes on this thread, grown to the largest tape seen
    /// (built once per thread, never per evaluation).
    static SCRATCH: std::cell::RefCell<tape::TapeScratch> = std::cell::RefCell::new(tape::TapeScratch::default());
}

impl SdfField {
    /// Compiles `object`'s tree and tape, the tape relative to the centre of `bounds`.
    pub fn new(object: &Object, bounds: Option<crate::geometry::Aabb>) -> Option<Self> {
        let tree = SdfTree::for_marching(object)?;
        // A single primitive is cheaper in the f64 tree (a few operations) than through the
        // tape's interpreter: the tape pays off for compound objects. A tape longer than
        // MAX_TAPE_OPS is abandoned as soon as it gets there, never unrolled whole.
        let tape =
            (tree.node_count > 1).then(|| tape::Tape::compile_within(&tree, bounds, MAX_TAPE_OPS)).flatten();
        let uniform_material = uniform_material(&tree.root);
        let regions = match (&tape, bounds) {
            (Some(t), Some(b)) => prune::TapeRegions::build(t, b),
            _ => None,
        };
        Some(SdfField { tree, tape, uniform_material, regions })
    }

    /// The shortened tape of the region of relative point `rel`
    /// ([`prune::TapeRegions::cell`], [`prune::TapeRegions::tape_of`]: cells with equal
    /// tapes give one number), `u32::MAX` where there is none (no regions, or outside them).
    #[inline]
    fn region(&self, rel: Vec3) -> u32 {
        self.regions.as_ref().and_then(|r| r.cell(rel).map(|c| r.tape_of(c))).unwrap_or(u32::MAX)
    }

    /// The operations to run for `region` (from [`SdfField::region`]): its shortened tape,
    /// or the whole tape.
    #[inline]
    fn ops_in<'a>(&'a self, tape: &'a tape::Tape, region: u32) -> tape::Ops<'a> {
        match &self.regions {
            Some(r) if region != u32::MAX => r.tape(region),
            _ => tape::Ops::All(tape.ops()),
        }
    }

    /// The distance at world point `p` with an error of at most a quarter of `tolerance`,
    /// or, where the tape cannot resolve that, a conservative bound that is as good for
    /// marching: the tape when its error bound `err` at `p` is within a quarter of
    /// `tolerance`; else, when the tape's value is farther than `4 err` from the surface,
    /// that value moved `err` towards zero (a lower bound of the true distance with the
    /// true sign, and no march converges there since the tolerance is below `4 err`);
    /// else the tree. `tape_value` gives the tape's value at `p` (evaluated, or taken from an
    /// 8-wide evaluation already made); it is computed first, and wasted only where the
    /// tree answers.
    #[inline]
    fn choose(&self, p: DVec3, tolerance: f64, tape_value: impl FnOnce(&tape::Tape) -> f64) -> f64 {
        let Some(tape) = self.tape.as_ref() else { return self.tree.distance(p) };
        let err = tape.error_bound((p - tape.origin).length());
        let d = tape_value(tape);
        if err <= 0.25 * tolerance {
            d
        } else if d.abs() > 4.0 * err {
            d - err.copysign(d)
        } else {
            self.tree.distance(p)
        }
    }

    /// Whether the tape's error bound over `points` (a normal's stencil) is within a
    /// quarter of `tolerance`, so that its values serve ([`SdfField::stencil`]);
    /// else the stencil takes the tree.
    #[inline]
    fn tape_resolves(&self, tape: &tape::Tape, points: &[DVec3; 4], tolerance: f64) -> bool {
        // One square root: a correctly rounded root is monotonic, so the root of the
        // largest square is the largest length, the same bits.
        let far2 = points.iter().map(|p| (*p - tape.origin).length_squared()).fold(0.0, f64::max);
        let far = far2.sqrt();
        tape.error_bound(far) <= 0.25 * tolerance
    }

    /// The tape at 1 to 8 world points in 8-wide evaluations (lanes past `points` repeat
    /// the first point and are ignored): one evaluation per distinct shortened tape among
    /// the points' regions, each running that region's shortened tape, so that every lane gets what
    /// [`SdfField::eval_tape`] gives at its point alone.
    #[inline]
    fn eval_tape8(&self, tape: &tape::Tape, points: &[DVec3]) -> [f32; 8] {
        let n = points.len().min(8);
        let (mut xs, mut ys, mut zs) = ([0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
        let mut cell = [u32::MAX; 8];
        for i in 0..8 {
            let r = tape.relative(points[if i < n { i } else { 0 }]);
            (xs[i], ys[i], zs[i]) = (r.x, r.y, r.z);
            cell[i] = self.region(r);
        }
        SCRATCH.with(|s| {
            let mut s = s.borrow_mut();
            s.fit(tape);
            let first = tape.eval8_ops(self.ops_in(tape, cell[0]), &xs, &ys, &zs, &mut s);
            if cell.iter().all(|&c| c == cell[0]) {
                return first;
            }
            let mut out = first;
            let mut done = cell.map(|c| c == cell[0]);
            while let Some(i) = done.iter().position(|d| !d) {
                let d = tape.eval8_ops(self.ops_in(tape, cell[i]), &xs, &ys, &zs, &mut s);
                for j in i..8 {
                    if cell[j] == cell[i] {
                        out[j] = d[j];
                        done[j] = true;
                    }
                }
            }
            out
        })
    }

    /// The tape at 32 points given relative to its origin ([`tape_inputs32`]): one 32-lane
    /// evaluation ([`tape::Tape::eval32_ops`]) where all of them fall in one region (or
    /// there are no regions), else each packet of the world points `points()` as
    /// [`SdfField::eval_tape8`] does it; every lane gets what [`SdfField::eval_tape`] gives
    /// at its point alone.
    #[inline]
    fn eval_tape32(
        &self,
        tape: &tape::Tape,
        rel: &[tape::X32; 3],
        points: impl FnOnce() -> [DVec3; WIDE],
    ) -> [f32; WIDE] {
        let at = |i: usize| {
            Vec3::new(
                rel[0][i / PACKET][i % PACKET],
                rel[1][i / PACKET][i % PACKET],
                rel[2][i / PACKET][i % PACKET],
            )
        };
        let cell = self.region(at(0));
        if self.regions.is_some() && (1..WIDE).any(|i| self.region(at(i)) != cell) {
            let points = points();
            let mut out = [0.0; WIDE];
            for (g, packet) in points.chunks_exact(PACKET).enumerate() {
                out[g * PACKET..(g + 1) * PACKET].copy_from_slice(&self.eval_tape8(tape, packet));
            }
            return out;
        }
        let d = SCRATCH.with(|s| {
            let mut s = s.borrow_mut();
            s.fit(tape);
            tape.eval32_ops(self.ops_in(tape, cell), &rel[0], &rel[1], &rel[2], &mut s)
        });
        std::array::from_fn(|i| d[i / PACKET][i % PACKET])
    }

    /// The tape's distance at world point `p` (f32, widened), running the shortened tape
    /// of its region. With AVX2 this is one lane of an 8-wide evaluation: the same value
    /// bit for bit (see [`tape`]), and faster than the scalar interpreter, whose chains of
    /// dependent operations (a smooth union's blends) wait on each other's latency.
    #[inline]
    fn eval_tape(&self, tape: &tape::Tape, p: DVec3) -> f64 {
        let rel = tape.relative(p);
        let ops = self.ops_in(tape, self.region(rel));
        SCRATCH.with(|s| {
            let mut s = s.borrow_mut();
            s.fit(tape);
            if crate::simd::backend() == crate::simd::Backend::Avx2 {
                tape.eval8_ops(ops, &[rel.x; 8], &[rel.y; 8], &[rel.z; 8], &mut s)[0] as f64
            } else {
                tape.eval_ops(ops, rel, &mut s) as f64
            }
        })
    }
}

/// An object tree rendered by sphere tracing its signed distance function: the one
/// marcher over an [`SdfField`], whose label says why the object is sphere traced.
pub type SdfObject = Marched<SdfField>;

impl SdfObject {
    /// Compiles `object` for sphere tracing; `why` says why it is sphere traced. `None`
    /// when the object holds a mesh. Tolerances scale with the diagonal of the object's
    /// bounds (1 when unbounded); the march runs a little beyond them.
    pub fn new(object: &Object, march: MarchParams, why: String) -> Option<Self> {
        let bounds = object.bounds();
        let field = SdfField::new(object, bounds)?;
        let size = bounds.map_or(1.0, |b| b.diagonal().length() as f64);
        // March a little beyond the bounds so a hit on the box face is not lost.
        let bounds = bounds.map(|b| {
            grow(
                &b,
                (march.tolerance(0.0, size) * 4.0) as f32
                    + f32_error(max_abs(b.max.into()).max(max_abs(b.min.into()))),
            )
        });
        Some(Marched::from_field(field, bounds, size, march, why))
    }
}

/// Fewest children of a sharp union that [`sdf_geometry`] splits into parts under a BVH.
pub const SPLIT_UNION_CHILDREN: usize = 8;

/// How an object's analytic SDF is traced: one [`SdfObject`], or, for a sharp union of at
/// least [`SPLIT_UNION_CHILDREN`] bounded children, an [`SdfUnion`] of one [`SdfObject`]
/// per child under a BVH. The surface of `min(a, b)` is the union of the children's
/// surfaces, so the nearest hit of the union is the nearest of the children's hits, with
/// the nearest child's material and normal, as the single field gives; but a ray now
/// evaluates only the children whose bounds it reaches, not every child at every step
/// (the SDF side's bounding volume hierarchy). `None` when the object holds a mesh.
pub fn sdf_geometry(object: &Object, march: MarchParams, why: String) -> Option<Box<dyn Geometry>> {
    if let ObjectKind::Csg { op: CsgOp::Union, children } = &object.kind
        && children.len() >= SPLIT_UNION_CHILDREN
    {
        // Each child keeps the union's transform above its own (a union of one child).
        let parts: Option<Vec<Object>> = children
            .iter()
            .map(|c| {
                let part = Object {
                    kind: ObjectKind::Csg { op: CsgOp::Union, children: vec![c.clone()] },
                    transform: object.transform,
                    material: object.material,
                    label: c.label.clone(),
                };
                part.bounds().is_some().then_some(part)
            })
            .collect();
        if let Some(parts) = parts {
            let geometries: Option<Vec<Box<dyn Geometry>>> = parts
                .iter()
                .map(|p| SdfObject::new(p, march, why.clone()).map(|g| Box::new(g) as Box<dyn Geometry>))
                .collect();
            return Some(Box::new(SdfUnion {
                parts: SceneGeometry::new(geometries?),
                label: format!(
                    "{why} (a union of {} children, each sphere traced in its bounds under a BVH)",
                    children.len()
                ),
            }));
        }
    }
    Some(Box::new(SdfObject::new(object, march, why)?))
}

/// A sharp union traced as its children under a BVH ([`sdf_geometry`]).
pub struct SdfUnion {
    /// One [`SdfObject`] per child.
    parts: SceneGeometry,
    /// What [`Geometry::describe`] says.
    label: String,
}

impl Geometry for SdfUnion {
    fn bounds(&self) -> Option<crate::geometry::Aabb> {
        self.parts.bounds()
    }

    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        self.parts.closest_hit(ray, t_min, t_max, stats)
    }

    fn prefers_packets(&self) -> bool {
        true
    }

    fn closest_hits(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &mut [f32],
        hits: &mut [Option<Hit>],
        stats: &mut RayStats,
    ) {
        self.parts.closest_hits(rays, t_min, t_max, hits, stats)
    }

    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        self.parts.any_hit(ray, t_min, t_max, stats)
    }

    fn any_hits(&self, rays: &[Ray], t_min: f32, t_max: &[f32], occluded: &mut [bool], stats: &mut RayStats) {
        self.parts.any_hits(rays, t_min, t_max, occluded, stats)
    }

    fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.parts.bytes_used() + self.label.capacity()
    }

    fn describe(&self) -> String {
        self.label.clone()
    }

    fn census(&self) -> Census {
        self.parts.census()
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        self.parts.surface_distance(p)
    }
}

/// The tape's inputs at the 32 ray points `o + d * t` (lane `8 g + l` in `[g][l]` of each
/// component): each point relative to the tape's origin, rounded to f32
/// ([`tape::Tape::relative`] of the point as `DVec3` arithmetic gives it), and the lanes
/// whose tape value [`SdfField::choose`] takes as it is (the tape's error bound at the
/// point at most a quarter of the lane's tolerance), as bits. Four lanes at a time with
/// AVX2 where the CPU has it; the same operations, so the same bits.
fn tape_inputs32(
    tape: &tape::Tape,
    o: &Rays32,
    d: &Rays32,
    t: &Lanes32,
    tol: &Lanes32,
) -> ([tape::X32; 3], u32) {
    dispatch(TapeInputs32 { tape, o, d, t, tol })
}

/// [`tape_inputs32`] as a SIMD kernel: `DVec3` arithmetic on four lanes at once
/// (`o + d * t`, the difference to the origin, `x * x + y * y + z * z` and its square
/// root, rounded after each operation as the scalar code is), the rounding to f32 to
/// nearest (as `as f32` is) and the tolerance test as an ordered comparison.
struct TapeInputs32<'a> {
    tape: &'a tape::Tape,
    o: &'a Rays32,
    d: &'a Rays32,
    t: &'a Lanes32,
    tol: &'a Lanes32,
}

impl Kernel for TapeInputs32<'_> {
    type Output = ([tape::X32; 3], u32);
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> Self::Output {
        let TapeInputs32 { tape, o, d, t, tol } = self;
        let mut rel = [[[0.0f32; PACKET]; WIDE / PACKET]; 3];
        let mut resolved = 0u32;
        let (k, m) = tape.error_parts();
        let (k, m, quarter) = (s.splat4(k), s.splat4(m), s.splat4(0.25));
        for i in (0..WIDE).step_by(4) {
            let ti = s.load4_at(t, i);
            let mut sq = s.splat4(0.0);
            for a in 0..3 {
                let p = s.load4_at(&o[a], i) + s.load4_at(&d[a], i) * ti;
                let r = p - s.splat4(tape.origin[a]);
                rel[a][i / PACKET][i % PACKET..i % PACKET + 4].copy_from_slice(&r.to_f32());
                let rr = r * r;
                sq = if a == 0 { rr } else { sq + rr };
            }
            let err = k * (sq.vsqrt() + m);
            let within = err.cmp_le(quarter * s.load4_at(tol, i));
            resolved |= within.movemask() << i;
        }
        (rel, resolved)
    }
}

impl SdfField {
    /// [`DistanceField::distance`] at eight points at once, each with its own tolerance,
    /// each lane deciding as it does alone (the tape's lanes equal its scalar values bit
    /// for bit).
    fn distance8_within(&self, points: &[DVec3; 8], tolerances: &[f64; 8]) -> [f64; 8] {
        let Some(tape) = self.tape.as_ref() else {
            return points.map(|p| self.tree.distance(p));
        };
        let d = self.eval_tape8(tape, points);
        std::array::from_fn(|i| self.choose(points[i], tolerances[i], |_| d[i] as f64))
    }

    /// The [`BlockKind::Rays`] lanes of [`DistanceField::distances`]: a block of all four
    /// packets in one 32-lane tape evaluation ([`SdfField::eval_tape32`]), else packet by
    /// packet ([`SdfField::distance8_within`]: in a batch's last steps, evaluating idle
    /// packets along costs more).
    #[inline]
    fn ray_distances<const W: usize>(&self, block: &mut PointBlock<W>) {
        let packets = block.packets();
        let all = packets == (1 << (WIDE / PACKET)) - 1;
        if let (true, Some(tape)) = (all, self.tape.as_ref())
            && let Some(wide) = block.wide_mut()
        {
            return self.ray_distances32(tape, wide);
        }
        for g in 0..W / PACKET {
            if packets & 1 << g != 0 {
                let tol: [f64; PACKET] = std::array::from_fn(|l| block.tol[PACKET * g + l]);
                let v =
                    self.distance8_within(&std::array::from_fn(|l| block.ray_point(PACKET * g + l)), &tol);
                block.out[PACKET * g..PACKET * (g + 1)].copy_from_slice(&v);
            }
        }
    }

    /// The 32 lanes of a full block in one tape evaluation, each lane deciding as
    /// [`DistanceField::distance`] at its point alone.
    #[inline]
    fn ray_distances32(&self, tape: &tape::Tape, block: &mut PointBlock) {
        let PointBlock { origin: o, dir: d, t, tol, out, .. } = block;
        let (rel, resolved) = tape_inputs32(tape, o, d, t, tol);
        let point =
            |i: usize| DVec3::new(o[0][i], o[1][i], o[2][i]) + DVec3::new(d[0][i], d[1][i], d[2][i]) * t[i];
        let v = self.eval_tape32(tape, &rel, || std::array::from_fn(point));
        for i in 0..WIDE {
            out[i] = if resolved >> i & 1 != 0 {
                v[i] as f64
            } else {
                self.choose(point(i), tol[i], |_| v[i] as f64)
            };
        }
    }

    /// One normal stencil: all four points from the tape where it resolves them all, else
    /// all four from the tree.
    #[inline]
    fn stencil(&self, points: &[DVec3; 4], tolerance: f64) -> [f64; 4] {
        let Some(tape) = self.tape.as_ref().filter(|t| self.tape_resolves(t, points, tolerance)) else {
            return points.map(|p| self.tree.distance(p));
        };
        let d = self.eval_tape8(tape, points);
        [d[0] as f64, d[1] as f64, d[2] as f64, d[3] as f64]
    }

    /// Two stencils in one 8-wide tape evaluation where the tape resolves both (each lane's
    /// value is what it is alone); else one after the other ([`SdfField::stencil`]).
    #[inline]
    fn stencil_pair(&self, a: &[DVec3; 4], ta: f64, b: &[DVec3; 4], tb: f64) -> ([f64; 4], [f64; 4]) {
        let both = |t: &&tape::Tape| self.tape_resolves(t, a, ta) && self.tape_resolves(t, b, tb);
        let Some(tape) = self.tape.as_ref().filter(both) else {
            return (self.stencil(a, ta), self.stencil(b, tb));
        };
        let d = self.eval_tape8(tape, &[a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]]);
        (std::array::from_fn(|i| d[i] as f64), std::array::from_fn(|i| d[i + 4] as f64))
    }
}

/// The 32 world `points` relative to the tape's origin, rounded to f32
/// ([`tape::Tape::relative`]), by component (`[a][g][l]`: component `a` of lane `8 g + l`).
fn relative32(tape: &tape::Tape, points: &[DVec3; WIDE]) -> [tape::X32; 3] {
    let mut rel = [[[0.0f32; PACKET]; WIDE / PACKET]; 3];
    for (i, p) in points.iter().enumerate() {
        let r = tape.relative(*p);
        for a in 0..3 {
            rel[a][i / PACKET][i % PACKET] = r[a];
        }
    }
    rel
}

/// The analytic field: distances from the tape where f32 is precise enough for the
/// tolerance asked, else from the tree (exact or Lipschitz-1 bounds, marched as they
/// are); the material of the nearest surface at a hit from the tree.
impl DistanceField for SdfField {
    #[inline]
    fn distance(&self, p: DVec3, tolerance: f64) -> f64 {
        self.choose(p, tolerance, |tape| self.eval_tape(tape, p))
    }

    /// Rays: all four packets in one 32-lane tape evaluation ([`SdfField::eval_tape32`])
    /// when all four are active (else packet by packet, [`SdfField::distance8_within`]: in
    /// a batch's last steps, evaluating idle packets along costs more); each lane decides as
    /// [`DistanceField::distance`] at its point alone. Stencils: the eight in one 32-lane
    /// tape evaluation where the tape resolves each, else two at a time
    /// ([`SdfField::stencil_pair`]).
    fn distances<const W: usize>(&self, block: &mut PointBlock<W>) {
        match (block.kind, block.wide_mut()) {
            (BlockKind::Rays, _) => self.ray_distances(block),
            // Stencils are only packed into WIDE blocks (`PointBlock::set_stencils`).
            (BlockKind::Stencils, None) => block.fill_each(|p, tol| self.distance(p, tol)),
            (BlockKind::Stencils, Some(block)) => {
                let n = block.stencil_count();
                let o = &block.origin;
                let stencil = |k: usize| -> [DVec3; 4] {
                    std::array::from_fn(|j| DVec3::new(o[0][4 * k + j], o[1][4 * k + j], o[2][4 * k + j]))
                };
                // One stencil (a single ray's hit): no more unpacked than it.
                if n == 1 {
                    let d = self.stencil(&stencil(0), block.tol[0]);
                    block.out[..4].copy_from_slice(&d);
                    return;
                }
                let stencils: [[DVec3; 4]; 8] = std::array::from_fn(stencil);
                let tol: [f64; 8] = std::array::from_fn(|k| block.tol[4 * k]);
                if n == 8
                    && let Some(tape) = self.tape.as_ref()
                    && (0..8).all(|k| self.tape_resolves(tape, &stencils[k], tol[k]))
                {
                    let points: [DVec3; WIDE] = std::array::from_fn(|i| stencils[i / 4][i % 4]);
                    let v = self.eval_tape32(tape, &relative32(tape, &points), || points);
                    for (x, v) in block.out.iter_mut().zip(v) {
                        *x = v as f64;
                    }
                    return;
                }
                for k in (0..n).step_by(2) {
                    let (a, ta) = (stencils[k], tol[k]);
                    let v = if k + 1 < n {
                        let (da, db) = self.stencil_pair(&a, ta, &stencils[k + 1], tol[k + 1]);
                        [da[0], da[1], da[2], da[3], db[0], db[1], db[2], db[3]]
                    } else {
                        let d = self.stencil(&a, ta);
                        [d[0], d[1], d[2], d[3], 0.0, 0.0, 0.0, 0.0]
                    };
                    block.out[4 * k..4 * k + 8].copy_from_slice(&v);
                }
            }
        }
    }

    /// Signed and exact as the tree is; in packets where there is a tape; lanes refilled
    /// as marches end except where the tape is pruned by region (lanes refilled as marches
    /// end march at different depths, so a packet falls in more regions, each evaluated
    /// on its own; measured: a smooth union of 64 spheres took 13% more instructions per
    /// frame).
    fn facts(&self) -> FieldFacts {
        FieldFacts {
            signed: self.tree.signed,
            exact: self.tree.exact,
            packets: self.tape.is_some(),
            refills_lanes: self.regions.is_none(),
        }
    }

    /// Half the hit's error bound for the normal; an unsigned field (a triangle) has no
    /// gradient on the surface, so it samples closer than the point's own distance, so
    /// that every sample lies on the ray's side. The material of the nearest surface.
    fn surface(&self, p: DVec3, eps: f64) -> SurfacePoint {
        let floor = 1e-9 * (1.0 + p.abs().max_element());
        let step =
            if self.tree.signed { 0.5 * eps } else { (0.25 * self.tree.distance(p).abs()).min(0.5 * eps) };
        SurfacePoint {
            normal_step: step.max(floor),
            material: self.uniform_material.unwrap_or_else(|| self.tree.distance_material(p).1),
        }
    }
}

/// The tree, tape and regions the field holds; its error measured on the tree's surface.
impl FieldObject for SdfField {
    fn storage(&self) -> Storage {
        let heap_bytes = self.tree.bytes_used() - std::mem::size_of::<SdfTree>()
            + self.tape.as_ref().map_or(0, |t| t.bytes_used())
            + self.regions.as_ref().map_or(0, |r| r.bytes_used());
        Storage { heap_bytes, census: Census::default(), shared: None }
    }

    fn surface_distance(&self, p: DVec3, size: f64) -> f64 {
        let f = |q: DVec3| self.tree.distance(q);
        distance_by_projection(&f, p, 1e-7 * size.max(p.abs().max_element()), 1e-9 * size)
    }

    fn describe(&self, why: &str) -> String {
        let bound = if self.tree.exact { "exact distance" } else { "Lipschitz bound" };
        match &self.tape {
            Some(t) => match &self.regions {
                Some(r) => {
                    let n = r.cells();
                    format!(
                        "{why} ({bound}, f32 tape of {} ops, pruned over {}x{}x{} regions to {:.0}% on average, {} distinct)",
                        t.ops().len(),
                        n.x,
                        n.y,
                        n.z,
                        100.0 * r.mean_ratio(),
                        r.distinct()
                    )
                }
                None => format!("{why} ({bound}, f32 tape of {} ops)", t.ops().len()),
            },
            None if self.tree.node_count <= 1 => format!("{why} ({bound}, f64 tree: a single primitive)"),
            None => format!("{why} ({bound}, f64 tree: tape over {MAX_TAPE_OPS} ops)"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::transform::TransformDesc;

    fn obj(kind: ObjectKind) -> Object {
        Object { kind, transform: TransformDesc::default(), material: 0, label: "t".into() }
    }

    #[test]
    fn primitive_distances_at_known_points() {
        let s = Primitive::Sphere { radius: 2.0 };
        assert!((primitive_distance(&s, Vec3::new(3.0, 0.0, 0.0)) - 1.0).abs() < 1e-6);
        let b = Primitive::Box { half: Vec3::new(1.0, 2.0, 3.0) };
        assert!((primitive_distance(&b, Vec3::new(2.0, 3.0, 0.0)) - 2f32.sqrt()).abs() < 1e-6);
        assert!((primitive_distance(&b, Vec3::ZERO) + 1.0).abs() < 1e-6);
        let c = Primitive::Cylinder { radius: 1.0, half_height: 1.0 };
        assert!((primitive_distance(&c, Vec3::new(0.0, 3.0, 0.0)) - 2.0).abs() < 1e-6);
        let t = Primitive::Torus { major: 2.0, minor: 0.5 };
        assert!((primitive_distance(&t, Vec3::new(2.0, 1.0, 0.0)) - 0.5).abs() < 1e-6);
        let cone = Primitive::Cone { radius_bottom: 1.0, radius_top: 0.0, half_height: 1.0 };
        assert!((primitive_distance(&cone, Vec3::new(0.0, 2.0, 0.0)) - 1.0).abs() < 1e-6);
        assert!(primitive_distance(&cone, Vec3::new(0.0, -0.5, 0.0)) < 0.0);
        let tri = Primitive::Triangle { a: Vec3::ZERO, b: Vec3::X, c: Vec3::Y };
        assert!((primitive_distance(&tri, Vec3::new(0.2, 0.2, -0.5)) - 0.5).abs() < 1e-6);
        assert!((primitive_distance(&tri, Vec3::new(2.0, 0.0, 0.0)) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn huge_sphere_is_precise_near_its_surface() {
        // World point just above the top of a radius-5000 sphere centred at (0, -5001, 0).
        let mut o = obj(ObjectKind::Primitive(Primitive::Sphere { radius: 5000.0 }));
        o.transform.translate = Vec3::new(0.0, -5001.0, 0.0);
        let tree = SdfTree::new(&o).unwrap();
        for h in [1e-3, 1e-4, 1e-5] {
            let d = tree.distance(DVec3::new(0.0, -1.0 + h, 0.0));
            assert!((d - h).abs() < 1e-8, "{d} vs {h}");
        }
    }

    #[test]
    fn csg_and_materials() {
        let a = Object { material: 1, ..obj(ObjectKind::Primitive(Primitive::Sphere { radius: 1.0 })) };
        let mut b = Object { material: 2, ..obj(ObjectKind::Primitive(Primitive::Sphere { radius: 1.0 })) };
        b.transform.translate = Vec3::new(1.5, 0.0, 0.0);
        let u =
            SdfTree::new(&obj(ObjectKind::Csg { op: CsgOp::Union, children: vec![a.clone(), b.clone()] }))
                .unwrap();
        assert_eq!(u.distance_material(DVec3::new(-2.0, 0.0, 0.0)), (1.0, 1));
        assert_eq!(u.distance_material(DVec3::new(3.5, 0.0, 0.0)).1, 2);
        assert!(u.exact);
        let s = SdfTree::new(&obj(ObjectKind::Csg {
            op: CsgOp::Subtraction,
            children: vec![a.clone(), b.clone()],
        }))
        .unwrap();
        assert!(s.distance(DVec3::new(0.75, 0.0, 0.0)) > 0.0);
        assert!(s.distance(DVec3::new(-0.5, 0.0, 0.0)) < 0.0);
        assert!(!s.exact);
        let i = SdfTree::new(&obj(ObjectKind::Csg {
            op: CsgOp::Intersection,
            children: vec![a.clone(), b.clone()],
        }))
        .unwrap();
        assert!(i.distance(DVec3::new(0.75, 0.0, 0.0)) < 0.0);
        assert!(i.distance(DVec3::new(-0.5, 0.0, 0.0)) > 0.0);
        let su =
            SdfTree::new(&obj(ObjectKind::Csg { op: CsgOp::SmoothUnion { k: 0.5 }, children: vec![a, b] }))
                .unwrap();
        // The smooth union fills the waist between the spheres.
        assert!(su.distance(DVec3::new(0.75, 0.75, 0.0)) < u.distance(DVec3::new(0.75, 0.75, 0.0)));
    }

    /// At the points of a 24^3 lattice over `[-r, r]^3`: the point, the sampling tree's
    /// value and the marching tree's.
    fn sampling_and_marching(o: &Object, r: f64) -> Vec<(DVec3, f64, f64)> {
        let (sampling, marching) = (SdfTree::new(o).unwrap(), SdfTree::for_marching(o).unwrap());
        let n = 24;
        let c = |k: usize| -r + 2.0 * r * (k % n) as f64 / (n - 1) as f64;
        (0..n * n * n)
            .map(|i| {
                let p = DVec3::new(c(i), c(i / n), c(i / (n * n)));
                (p, sampling.distance(p), marching.distance(p))
            })
            .collect()
    }

    /// A Menger level: three bars that reach past their cell along their length only.
    fn crosses(transform: TransformDesc) -> Object {
        let bar = |h: Vec3| obj(ObjectKind::Primitive(Primitive::Box { half: h }));
        let (l, w) = (0.5, 0.1111);
        let mut cross = obj(ObjectKind::Csg {
            op: CsgOp::Union,
            children: vec![bar(Vec3::new(l, w, w)), bar(Vec3::new(w, l, w)), bar(Vec3::new(w, w, l))],
        });
        cross.transform = transform;
        obj(ObjectKind::Repeat {
            period: Vec3::splat(0.6667),
            count: Some(UVec3::splat(3)),
            child: Box::new(cross),
        })
    }

    #[test]
    fn repeated_union_is_distributed_for_marching() {
        let turned = TransformDesc { rotate_deg: Vec3::new(0.0, 0.0, 90.0), ..Default::default() };
        for o in [crosses(TransformDesc::default()), crosses(turned)] {
            // 3 bars x 8 cell combinations as one repetition; 3 x 2 distributed.
            assert_eq!(march_cost(&o), 24.0);
            let d = distributed(&o).expect("distributed");
            assert_eq!(march_cost(&d), 6.0);
            for (p, a, m) in sampling_and_marching(&o, 1.3) {
                // The same surface: the same sign, and the marching value a bound of the
                // distance to the copies (equal to it near the surface).
                assert!(a * m > 0.0 || a.abs() < 1e-12, "{a} vs {m} at {p}");
                assert!(m.abs() <= a.abs() + 1e-12, "{a} vs {m} at {p}");
            }
        }
        // A union of spheres that fit their cells is cheaper as it is: not distributed.
        let s = |x: f32| {
            let mut o = obj(ObjectKind::Primitive(Primitive::Sphere { radius: 0.1 }));
            o.transform.translate = Vec3::new(x, 0.0, 0.0);
            o
        };
        let fits = obj(ObjectKind::Repeat {
            period: Vec3::ONE,
            count: Some(UVec3::splat(4)),
            child: Box::new(obj(ObjectKind::Csg { op: CsgOp::Union, children: vec![s(-0.2), s(0.2)] })),
        });
        assert!(distributed(&fits).is_none());
    }

    #[test]
    fn overlapping_repeated_boxes_merge_into_one() {
        let bar = |half: Vec3, t: Vec3| {
            let mut b = obj(ObjectKind::Primitive(Primitive::Box { half }));
            b.transform.translate = t;
            b
        };
        let rep = |child: Object, period: Vec3, n: UVec3| {
            obj(ObjectKind::Repeat { period, count: Some(n), child: Box::new(child) })
        };
        // 3 bars along x overlap (period 0.6 <= 2 x 0.5); along y they are apart.
        let o = rep(
            bar(Vec3::new(0.5, 0.1, 0.1), Vec3::new(0.0, 0.05, 0.0)),
            Vec3::new(0.6, 0.5, 0.0),
            UVec3::new(3, 2, 1),
        );
        let m = merged_box(&o).expect("merged along x");
        let ObjectKind::Repeat { period, count, child } = &m.kind else { panic!("{m:?}") };
        assert_eq!((*period, *count), (Vec3::new(0.0, 0.5, 0.0), Some(UVec3::new(1, 2, 1))));
        assert!(
            matches!(child.kind, ObjectKind::Primitive(Primitive::Box { half }) if (half.x - 1.1).abs() < 1e-6)
        );
        for (p, a, m) in sampling_and_marching(&o, 1.5) {
            assert!(a * m > 0.0 || a.abs() < 1e-6, "{a} vs {m} at {p}");
            // Outside, the sampling tree is the exact distance to the copies; the marching
            // one a bound of it (the face bound along y, gap 0.1), equal near the surface.
            if a > 0.0 {
                assert!(m <= a + 1e-6, "{a} vs {m} at {p}");
                assert!(a > 0.05 || (a - m).abs() < 1e-6, "{a} vs {m} at {p}");
            }
        }
        // Along every axis: the box itself, under the repetition's transform.
        let all = rep(bar(Vec3::splat(0.5), Vec3::ZERO), Vec3::splat(1.0), UVec3::splat(2));
        let m = merged_box(&all).expect("merged");
        assert!(matches!(&m.kind, ObjectKind::Csg { op: CsgOp::Union, children } if children.len() == 1));
        // Apart (gap 0.1), rotated, or not a box: left alone.
        assert!(
            merged_box(&rep(bar(Vec3::splat(0.45), Vec3::ZERO), Vec3::splat(1.0), UVec3::splat(2))).is_none()
        );
        let mut turned = bar(Vec3::splat(0.5), Vec3::ZERO);
        turned.transform.rotate_deg = Vec3::new(0.0, 10.0, 0.0);
        assert!(merged_box(&rep(turned, Vec3::splat(1.0), UVec3::splat(2))).is_none());
    }

    #[test]
    fn repetition_finite_and_infinite() {
        let s = obj(ObjectKind::Primitive(Primitive::Sphere { radius: 0.5 }));
        let inf = SdfTree::new(&obj(ObjectKind::Repeat {
            period: Vec3::new(2.0, 0.0, 0.0),
            count: None,
            child: Box::new(s.clone()),
        }))
        .unwrap();
        assert!((inf.distance(DVec3::new(100.0, 0.0, 0.0)) + 0.5).abs() < 1e-4);
        assert!((inf.distance(DVec3::new(101.0, 0.0, 0.0)) - 0.5).abs() < 1e-4);
        let fin = SdfTree::new(&obj(ObjectKind::Repeat {
            period: Vec3::new(2.0, 0.0, 0.0),
            count: Some(UVec3::new(2, 1, 1)),
            child: Box::new(s),
        }))
        .unwrap();
        // Two copies at x = -1 and x = 1.
        assert!((fin.distance(DVec3::new(1.0, 0.0, 0.0)) + 0.5).abs() < 1e-5);
        assert!((fin.distance(DVec3::new(-1.0, 0.0, 0.0)) + 0.5).abs() < 1e-5);
        assert!((fin.distance(DVec3::new(5.0, 0.0, 0.0)) - 3.5).abs() < 1e-5);
        assert!((fin.distance(DVec3::ZERO) - 0.5).abs() < 1e-5);
    }
}
