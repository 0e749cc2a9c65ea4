//! The scene's geometry as described, independent of how it is represented: the
//! closed-form primitives with their parameters in local space, and the object tree
//! (primitives, CSG nodes, domain repetition) with transforms and materials.

use std::path::PathBuf;
use std::sync::Arc;

use glam::{UVec3, Vec3};

use crate::base::transform::{Transform, TransformDesc};
use crate::base::{Aabb, MaterialId, aabb};
use crate::grid::SdfGrid;
use crate::implicit::field3d::Field3;
use crate::mesh::TriangleMesh;

/// A primitive in its local frame. All lengths are scene units, finite and > 0 unless
/// stated. Axis-symmetric shapes use the local y axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Primitive {
    /// Sphere of `radius` at the origin.
    Sphere {
        /// Radius.
        radius: f32,
    },
    /// The infinite plane `normal . p = offset`; `normal` is unit length. Solid below.
    Plane {
        /// Unit normal, pointing out of the solid.
        normal: Vec3,
        /// Signed distance of the plane from the origin along `normal`.
        offset: f32,
    },
    /// Axis-aligned box with half extents `half` (all > 0), centred at the origin.
    Box {
        /// Half extents per axis.
        half: Vec3,
    },
    /// Axis-aligned ellipsoid with semi-axes `radii` (all > 0), centred at the origin.
    Ellipsoid {
        /// Semi-axes per axis.
        radii: Vec3,
    },
    /// Capped cylinder around y from `-half_height` to `half_height`.
    Cylinder {
        /// Radius.
        radius: f32,
        /// Half the height along y.
        half_height: f32,
    },
    /// Capped cone (frustum) around y: radius `radius_bottom` at `y = -half_height`,
    /// `radius_top` at `y = half_height`; radii >= 0, not both 0. A radius of 0 is an apex.
    Cone {
        /// Radius at the bottom cap (`y = -half_height`), >= 0.
        radius_bottom: f32,
        /// Radius at the top cap (`y = half_height`), >= 0.
        radius_top: f32,
        /// Half the height along y.
        half_height: f32,
    },
    /// Torus in the xz plane: ring radius `major`, tube radius `minor` (`0 < minor`).
    Torus {
        /// Radius of the ring (from the origin to the tube's centre line).
        major: f32,
        /// Radius of the tube.
        minor: f32,
    },
    /// A single two-sided triangle (zero thickness); vertices are not collinear.
    Triangle {
        /// First vertex.
        a: Vec3,
        /// Second vertex.
        b: Vec3,
        /// Third vertex.
        c: Vec3,
    },
    /// Segment `a`..`b` swept by a sphere of `radius`.
    Capsule {
        /// One end of the segment.
        a: Vec3,
        /// The other end of the segment.
        b: Vec3,
        /// Radius of the swept sphere.
        radius: f32,
    },
}

impl Primitive {
    /// The scene-file name of the primitive kind.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Primitive::Sphere { .. } => "sphere",
            Primitive::Plane { .. } => "plane",
            Primitive::Box { .. } => "box",
            Primitive::Ellipsoid { .. } => "ellipsoid",
            Primitive::Cylinder { .. } => "cylinder",
            Primitive::Cone { .. } => "cone",
            Primitive::Torus { .. } => "torus",
            Primitive::Triangle { .. } => "triangle",
            Primitive::Capsule { .. } => "capsule",
        }
    }

    /// Local-space bounding box, `None` for the infinite plane.
    pub fn local_bounds(&self) -> Option<Aabb> {
        Some(match *self {
            Primitive::Sphere { radius } => aabb(Vec3::splat(-radius), Vec3::splat(radius)),
            Primitive::Plane { .. } => return None,
            Primitive::Box { half } => aabb(-half, half),
            Primitive::Ellipsoid { radii } => aabb(-radii, radii),
            Primitive::Cylinder { radius, half_height } => {
                let e = Vec3::new(radius, half_height, radius);
                aabb(-e, e)
            }
            Primitive::Cone { radius_bottom, radius_top, half_height } => {
                let r = radius_bottom.max(radius_top);
                let e = Vec3::new(r, half_height, r);
                aabb(-e, e)
            }
            Primitive::Torus { major, minor } => {
                let e = Vec3::new(major + minor, minor, major + minor);
                aabb(-e, e)
            }
            Primitive::Triangle { a, b, c } => aabb(a.min(b).min(c), a.max(b).max(c)),
            Primitive::Capsule { a, b, radius } => {
                aabb(a.min(b) - Vec3::splat(radius), a.max(b) + Vec3::splat(radius))
            }
        })
    }
}

/// A CSG operation. Smooth variants blend over `k` scene units (`k > 0`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CsgOp {
    /// Everything inside any child.
    Union,
    /// Inside the first child and outside every other child.
    Subtraction,
    /// Inside every child.
    Intersection,
    /// Union with a rounded blend of radius `k`.
    SmoothUnion {
        /// Blend radius, scene units, > 0.
        k: f32,
    },
    /// Subtraction with a rounded blend of radius `k`.
    SmoothSubtraction {
        /// Blend radius, scene units, > 0.
        k: f32,
    },
    /// Intersection with a rounded blend of radius `k`.
    SmoothIntersection {
        /// Blend radius, scene units, > 0.
        k: f32,
    },
}

impl CsgOp {
    /// The scene-file name of the operation.
    pub fn name(&self) -> &'static str {
        match self {
            CsgOp::Union => "union",
            CsgOp::Subtraction => "subtraction",
            CsgOp::Intersection => "intersection",
            CsgOp::SmoothUnion { .. } => "smooth_union",
            CsgOp::SmoothSubtraction { .. } => "smooth_subtraction",
            CsgOp::SmoothIntersection { .. } => "smooth_intersection",
        }
    }
}

/// What an object is.
#[derive(Clone, Debug, PartialEq)]
pub enum ObjectKind {
    /// A single primitive.
    Primitive(Primitive),
    /// A CSG node over at least one child (subtraction needs two or more).
    Csg {
        /// The operation.
        op: CsgOp,
        /// The operands, in file order (the first is what a subtraction subtracts from).
        children: Vec<Object>,
    },
    /// Domain repetition of `child`: copies every `period` along each axis whose period
    /// is > 0 (an axis with period 0 is not repeated). With `count`, only `count` copies per
    /// repeated axis (>= 1), centred on the origin; without, infinitely many.
    Repeat {
        /// Spacing of the copies per axis, scene units; 0 for an axis not repeated.
        period: Vec3,
        /// Copies per repeated axis (each >= 1); `None` for infinitely many.
        count: Option<UVec3>,
        /// The repeated object.
        child: Box<Object>,
    },
    /// A triangle mesh loaded from a file (top level only: meshes have no analytic SDF).
    Mesh {
        /// The loaded, validated mesh (shared, never copied per representation).
        mesh: Arc<TriangleMesh>,
        /// The file it came from.
        source: PathBuf,
        /// Flat or smooth shading.
        shading: Shading,
    },
    /// A signed distance grid loaded from a file (`.sdf` or `.npy`; top level only). Its
    /// samples are in the object's local frame; the object's scale is uniform (checked when
    /// the scene is read), so distances scale exactly.
    Grid {
        /// The loaded grid (shared, never copied per representation).
        grid: Arc<SdfGrid>,
        /// The file it came from.
        source: PathBuf,
    },
    /// An implicit model read from a `.vm` file (top level only), seen inside the cube
    /// [-1, 1]^3 of the object's frame: the solid is where its value is negative.
    Implicit {
        /// The model prepared for ray casting (shared, never copied per representation).
        field: Arc<Field3>,
        /// The file it came from.
        source: PathBuf,
    },
}

/// How a traced mesh stores its BVH and vertices; the command line's `--layout` values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum MeshLayout {
    /// `f32` positions, 256-byte nodes with `f32` child boxes, leaves of pre-gathered
    /// `f32` corners (`geometry::mesh::wide_bvh`): the fastest.
    #[default]
    Full,
    /// 16-bit positions on one grid per mesh, 96-byte quantised nodes, leaves that are
    /// ranges of the triangle list (`geometry::mesh::compact`): the smallest. Traces the quantised mesh.
    Compact,
}

impl MeshLayout {
    /// Both layouts.
    pub const ALL: [MeshLayout; 2] = [MeshLayout::Full, MeshLayout::Compact];

    /// The name on the command line and in `compare`'s method names: `full`, `compact`.
    pub fn name(self) -> &'static str {
        match self {
            MeshLayout::Full => "full",
            MeshLayout::Compact => "compact",
        }
    }
}

/// How mesh normals are shaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Shading {
    /// The triangle's own normal.
    #[default]
    Flat,
    /// Vertex normals interpolated by barycentric weights (computed if the mesh has none).
    Smooth,
}

/// A node of the object tree: what it is, where it is and what it is made of.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    /// What the object is.
    pub kind: ObjectKind,
    /// The transform as written (relative to the parent node, or the world at the top).
    pub transform: TransformDesc,
    /// Material; a child of a CSG node without its own material inherits its parent's.
    pub material: MaterialId,
    /// Where the object came from, for messages (e.g. `objects[3]` or a user name).
    pub label: String,
}

impl Object {
    /// The compiled transform.
    pub fn compiled_transform(&self) -> Transform {
        Transform::new(&self.transform)
    }

    /// The operation's name or the primitive's kind, for messages.
    pub fn kind_name(&self) -> &'static str {
        match &self.kind {
            ObjectKind::Primitive(p) => p.kind_name(),
            ObjectKind::Csg { op, .. } => op.name(),
            ObjectKind::Repeat { .. } => "repeat",
            ObjectKind::Mesh { .. } => "mesh",
            ObjectKind::Grid { .. } => "grid",
            ObjectKind::Implicit { .. } => "implicit",
        }
    }

    /// Bounding box in the parent's frame, `None` when unbounded.
    pub fn bounds(&self) -> Option<Aabb> {
        let local = match &self.kind {
            ObjectKind::Primitive(p) => p.local_bounds()?,
            ObjectKind::Mesh { mesh, .. } => {
                let (lo, hi) = mesh.bounds()?;
                aabb(lo, hi)
            }
            ObjectKind::Grid { grid, .. } => {
                let (lo, hi) = grid.bounds();
                aabb(lo, hi)
            }
            ObjectKind::Implicit { .. } => {
                let e = crate::implicit::field3d::EXTENT as f32;
                aabb(Vec3::splat(-e), Vec3::splat(e))
            }
            ObjectKind::Csg { op: CsgOp::Intersection | CsgOp::SmoothIntersection { .. }, children } => {
                // Unbounded children do not constrain an intersection.
                let mut bounded = children.iter().filter_map(Object::bounds);
                let first = bounded.next()?;
                bounded.fold(first, |b, c| b.intersection(&c))
            }
            ObjectKind::Csg { op, children } => {
                let mut it = children.iter().map(Object::bounds);
                let first = it.next()??;
                match op {
                    CsgOp::Union => {
                        let mut b = first;
                        for c in it {
                            b = b.union(&c?);
                        }
                        b
                    }
                    CsgOp::SmoothUnion { k } => {
                        let mut b = first;
                        for c in it {
                            b = b.union(&c?);
                        }
                        grow(&b, *k)
                    }
                    CsgOp::Subtraction | CsgOp::SmoothSubtraction { .. } => first,
                    CsgOp::Intersection | CsgOp::SmoothIntersection { .. } => unreachable!(),
                }
            }
            ObjectKind::Repeat { period, count, child } => {
                let cb = child.bounds()?;
                let count = (*count)?;
                let mut b = cb;
                for axis in 0..3 {
                    if period[axis] > 0.0 {
                        let span = 0.5 * (count[axis] as f32 - 1.0) * period[axis];
                        b.min[axis] -= span;
                        b.max[axis] += span;
                    }
                }
                b
            }
        };
        Some(self.compiled_transform().box_to_world(&local))
    }
}

/// `b` grown by `r` on every side.
pub fn grow(b: &Aabb, r: f32) -> Aabb {
    let e = glam::Vec3A::splat(r);
    Aabb::new(b.min - e, b.max + e)
}
