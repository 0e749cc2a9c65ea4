//! The tape compiler: [`Compiler`] turns an [`SdfTree`]'s nodes into the flat operations of
//! a [`Tape`] (transforms folded, repetition unrolled, common point maps shared).

#[allow(unused_imports)]
use super::*;

/// The first write-once register number of either file while compiling
/// ([`Compiler::once`]); [`Compiler::finish`] renumbers them above the others.
const ONCE: u32 = 1 << 30;

/// What makes two point maps or repetition cell lookups the same computation: the kind of
/// operation, its input register and the bits of its constants.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub(super) struct OnceKey {
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
pub(super) struct Compiler {
    pub(super) ops: Vec<Op>,
    pub(super) triangles: Vec<TriangleConsts>,
    /// Value registers used (below [`ONCE`]).
    pub(super) vals: u32,
    /// Point registers used (below [`ONCE`]).
    pub(super) points: u32,
    /// `K` of [`Tape::error_bound`] so far.
    pub(super) magnitude: f64,
    /// Common subexpressions: point maps and cell lookups whose input never changes (the
    /// input point, or a write-once register) write write-once registers (numbered from
    /// [`ONCE`]) that no other operation writes, and an identical one later reads those
    /// instead of being emitted again: a rotated Menger sponge maps its point once, not
    /// once per child of its subtraction, and its crosses' bars share their cell lookups.
    /// The results are the same bits, as the same f32 operations on the same inputs.
    pub(super) once: std::collections::HashMap<OnceKey, u32>,
    /// Write-once value registers used.
    pub(super) once_vals: u32,
    /// Write-once point registers used.
    pub(super) once_points: u32,
    /// Past this many operations the compiler stops emitting ([`Tape::compile_within`]).
    pub(super) max_ops: usize,
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
    pub(super) fn finish(&mut self) -> (usize, usize) {
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
    pub(super) fn node(
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
