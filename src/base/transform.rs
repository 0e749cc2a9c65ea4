//! Object transforms: translation, rotation in degrees and uniform or per-axis scale,
//! compiled into the matrices the representations need (to world, to local, normals)
//! and the scale bounds sphere tracing needs to keep distances conservative.

use glam::{Affine3A, DAffine3, DMat3, DVec3, Mat3, Mat3A, Vec3, Vec3A};

use crate::base::{Aabb, Ray};

/// A transform as written in a scene file. Applied to an object as
/// `world = translate + rotate(scale * local)`, where the rotation turns first about x,
/// then y, then z (fixed axes), angles in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransformDesc {
    /// Translation, scene units.
    pub translate: Vec3,
    /// Rotation angles about x, y and z, degrees.
    pub rotate_deg: Vec3,
    /// Scale per axis; every component is finite and > 0.
    pub scale: Vec3,
}

impl Default for TransformDesc {
    fn default() -> Self {
        TransformDesc { translate: Vec3::ZERO, rotate_deg: Vec3::ZERO, scale: Vec3::ONE }
    }
}

/// A compiled affine transform (rotation, translation and positive per-axis scale).
#[derive(Clone, Copy, Debug)]
pub struct Transform {
    /// Local to world (or to parent).
    pub to_world: Affine3A,
    /// World (or parent) to local.
    pub to_local: Affine3A,
    /// World (or parent) to local in f64, for distance evaluation far from the origin
    /// (a radius-5000 sphere needs f64 local coordinates to resolve its surface).
    pub to_local_f64: DAffine3,
    /// Maps local normals to world normals (inverse transpose of the linear part).
    pub normal_to_world: Mat3A,
    /// Smallest scale factor: a local distance times this is a lower bound on the world distance.
    pub min_scale: f32,
    /// Largest scale factor.
    pub max_scale: f32,
    /// True when the transform is the identity (evaluation can skip it).
    pub identity: bool,
}

impl Transform {
    /// The identity transform.
    pub const IDENTITY: Transform = Transform {
        to_world: Affine3A::IDENTITY,
        to_local: Affine3A::IDENTITY,
        to_local_f64: DAffine3::IDENTITY,
        normal_to_world: Mat3A::IDENTITY,
        min_scale: 1.0,
        max_scale: 1.0,
        identity: true,
    };

    /// Compiles a scene-file transform.
    pub fn new(desc: &TransformDesc) -> Self {
        let r = desc.rotate_deg.as_dvec3() * (std::f64::consts::PI / 180.0);
        let rot = DMat3::from_rotation_z(r.z) * DMat3::from_rotation_y(r.y) * DMat3::from_rotation_x(r.x);
        let linear64 = rot * DMat3::from_diagonal(desc.scale.as_dvec3());
        let to_world64 = DAffine3::from_mat3_translation(linear64, desc.translate.as_dvec3());
        let to_local_f64 = to_world64.inverse();
        let linear: Mat3 = linear64.as_mat3();
        let to_world = Affine3A::from_mat3_translation(linear, desc.translate);
        let to_local = Affine3A::from_mat3_translation(
            to_local_f64.matrix3.as_mat3(),
            to_local_f64.translation.as_vec3(),
        );
        let normal_to_world = Mat3A::from(linear.inverse().transpose());
        let identity = *desc == TransformDesc::default();
        Transform {
            to_world,
            to_local,
            to_local_f64,
            normal_to_world,
            min_scale: desc.scale.min_element(),
            max_scale: desc.scale.max_element(),
            identity,
        }
    }

    /// Whether the scale is the same on every axis (then distances scale exactly).
    pub fn is_uniform(&self) -> bool {
        self.max_scale - self.min_scale <= 1e-6 * self.max_scale
    }

    /// Maps a world point into local space.
    #[inline]
    pub fn point_to_local(&self, p: Vec3) -> Vec3 {
        if self.identity { p } else { self.to_local.transform_point3(p) }
    }

    /// Maps a world point into local space in f64.
    #[inline]
    pub fn point_to_local_f64(&self, p: DVec3) -> DVec3 {
        if self.identity { p } else { self.to_local_f64.transform_point3(p) }
    }

    /// Maps a world ray into local space in f64 (origin and direction); `t` keeps its meaning.
    #[inline]
    pub fn ray_to_local_f64(&self, ray: &Ray) -> (DVec3, DVec3) {
        let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
        if self.identity {
            (o, d)
        } else {
            (self.to_local_f64.transform_point3(o), self.to_local_f64.transform_vector3(d))
        }
    }

    /// Maps a world ray into local space; `t` keeps its meaning.
    #[inline]
    pub fn ray_to_local(&self, ray: &Ray) -> Ray {
        if self.identity {
            *ray
        } else {
            let (origin, dir) =
                (self.to_local.transform_point3(ray.origin), self.to_local.transform_vector3(ray.dir));
            Ray::spawned(origin, dir, ray.spread)
        }
    }

    /// Maps a local normal to a unit world normal.
    #[inline]
    pub fn normal_to_world(&self, n: Vec3) -> Vec3 {
        if self.identity {
            n.normalize()
        } else {
            Vec3::from(self.normal_to_world * Vec3A::from(n)).normalize()
        }
    }

    /// The world box that encloses the local box `b` (all eight corners transformed).
    pub fn box_to_world(&self, b: &Aabb) -> Aabb {
        if self.identity { *b } else { transform_box(&self.to_world, b) }
    }

    /// The local box that encloses the world box `b` (all eight corners transformed).
    pub fn box_to_local(&self, b: &Aabb) -> Aabb {
        if self.identity { *b } else { transform_box(&self.to_local, b) }
    }
}

/// The box enclosing the eight corners of `b` mapped by `m`.
fn transform_box(m: &Affine3A, b: &Aabb) -> Aabb {
    let mut out = Aabb::empty();
    for i in 0..8 {
        let c = Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        );
        out.extend(Vec3A::from(m.transform_point3(c)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_normals() {
        let t = Transform::new(&TransformDesc {
            translate: Vec3::new(1.0, -2.0, 3.0),
            rotate_deg: Vec3::new(30.0, 45.0, 60.0),
            scale: Vec3::new(1.0, 2.0, 0.5),
        });
        let p = Vec3::new(0.3, -0.7, 2.0);
        let back = t.to_world.transform_point3(t.point_to_local(p));
        assert!((back - p).length() < 1e-5);
        // A normal stays perpendicular to a transformed tangent.
        let n_local = Vec3::new(0.0, 1.0, 0.0);
        let tangent_local = Vec3::new(1.0, 0.0, 0.3);
        let n = t.normal_to_world(n_local);
        let tangent = t.to_world.transform_vector3(tangent_local);
        assert!(n.dot(tangent).abs() < 1e-5);
        assert_eq!(t.min_scale, 0.5);
        assert!(!t.is_uniform());
    }

    #[test]
    fn rotation_order_is_x_then_y_then_z() {
        let t =
            Transform::new(&TransformDesc { rotate_deg: Vec3::new(90.0, 90.0, 0.0), ..Default::default() });
        // x rotation maps +y to +z, then y rotation maps +z to +x.
        let v = t.to_world.transform_vector3(Vec3::Y);
        assert!((v - Vec3::X).length() < 1e-5, "{v}");
    }
}
