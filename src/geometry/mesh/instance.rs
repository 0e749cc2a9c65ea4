//! Instanced meshes: the copies of a repetition as one shared mesh and BVH
//! ([`super::MeshShape`]) placed once per copy, as a polygon renderer instances repeated
//! geometry. [`InstancedMesh`] holds the placed copies; a scene
//! ([`crate::geometry::scene::SceneGeometry`]) puts each copy under its top-level BVH, so a
//! ray visits only the copies whose boxes it crosses, and counts the shared mesh once.
//!
//! Which copies exist: every copy of a finite repetition; for an infinite one, the copies
//! the camera can see ([`repeat_offsets`]): those whose bounding sphere lies within the
//! view frustum (widened by one period and the copy's radius, for the shadows and
//! reflections of near neighbours) and within a distance of the camera, the scene's
//! `max_distance` or less where that would exceed a cap on the number of copies.

use glam::{Affine3A, DAffine3, DVec3, Mat3A, Vec3};

use crate::geometry::mesh::MeshGeometry;
use crate::geometry::{Aabb, Census, Geometry, Hit, Ray, RayStats, Shared, box_distance};
use crate::mesh::TriangleMesh;
use crate::scene::Scene;
use crate::scene::shape::{Object, ObjectKind};
use crate::scene::transform::Transform;

/// Most copies a repetition is instanced with (about 400 bytes each with the top-level BVH's
/// share): a finite repetition with more is extracted whole, an infinite one is instanced
/// out to a shorter distance than `max_distance`.
pub const MAX_INSTANCES: u64 = 1 << 16;

/// The copies of one shared mesh, each under its own transform.
pub struct InstancedMesh {
    /// Every copy; all share one [`super::MeshShape`].
    instances: Vec<MeshGeometry>,
    bounds: Option<Aabb>,
    label: String,
}

impl InstancedMesh {
    /// `instances` (placed from one mesh: [`MeshGeometry::placed`]) described by `label`.
    ///
    /// # Panics
    /// When the instances do not all share one shape (a programming error).
    pub fn new(instances: Vec<MeshGeometry>, label: String) -> Self {
        if let Some(first) = instances.first() {
            assert!(
                instances.iter().all(|i| std::sync::Arc::ptr_eq(i.shape(), first.shape())),
                "instances of one shape"
            );
        }
        let bounds = instances.iter().filter_map(|i| i.bounds()).reduce(|a, b| a.union(&b));
        InstancedMesh { instances, bounds, label }
    }

    /// The copies' triangles in world space, one mesh (no normals).
    pub fn world_mesh(&self) -> TriangleMesh {
        let mut all = TriangleMesh::default();
        for i in &self.instances {
            let m = i.world_mesh();
            let base = all.positions.len() as u32;
            all.positions.extend(&m.positions);
            all.triangles.extend(m.triangles.iter().map(|t| t.map(|v| v + base)));
        }
        all
    }
}

impl Geometry for InstancedMesh {
    fn bounds(&self) -> Option<Aabb> {
        self.bounds
    }

    /// Tests every copy (traced alone; under a scene each copy is a leaf of its BVH).
    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        let mut best = None;
        let mut t_best = t_max;
        for i in &self.instances {
            if let Some(h) = i.closest_hit(ray, t_min, t_best, stats) {
                t_best = h.t;
                best = Some(h);
            }
        }
        best
    }

    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        self.instances.iter().any(|i| i.any_hit(ray, t_min, t_max, stats))
    }

    /// The struct, the label, every copy's record and the shared mesh once.
    fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.label.capacity()
            + (self.instances.capacity() - self.instances.len()) * std::mem::size_of::<MeshGeometry>()
            + self.instances.iter().map(MeshGeometry::instance_bytes).sum::<usize>()
            + self.instances.first().map_or(0, |i| i.shape().bytes_used())
    }

    fn describe(&self) -> String {
        match self.instances.first() {
            // The copies carry no label: the first one's description continues this one's.
            Some(first) => format!("{}{}", self.label, first.describe()),
            None => format!("{}: no copy in view", self.label),
        }
    }

    fn census(&self) -> Census {
        self.instances.first().map_or_else(Census::default, |i| i.shape().census())
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        let mut best = f64::INFINITY;
        for i in &self.instances {
            if i.bounds().is_none_or(|b| box_distance(&b, p) < best) {
                best = best.min(i.surface_distance(p));
            }
        }
        best
    }

    fn shared(&self) -> Option<Shared> {
        self.instances.first().and_then(|i| i.shared())
    }

    fn instances(&self) -> &[MeshGeometry] {
        &self.instances
    }
}

/// The transform `outer * translate(offset) * inner` (mesh frame to world), composed in
/// f64; its scale bounds are the products of the parts' (exact for uniform scales).
pub fn compose(outer: &Transform, offset: Vec3, inner: &Transform) -> Transform {
    let world = |t: &Transform| t.to_local_f64.inverse();
    let m = world(outer) * DAffine3::from_translation(offset.as_dvec3()) * world(inner);
    let to_local_f64 = m.inverse();
    let linear = m.matrix3.as_mat3();
    Transform {
        to_world: Affine3A::from_mat3_translation(linear, m.translation.as_vec3()),
        to_local: Affine3A::from_mat3_translation(
            to_local_f64.matrix3.as_mat3(),
            to_local_f64.translation.as_vec3(),
        ),
        to_local_f64,
        normal_to_world: Mat3A::from(linear.inverse().transpose()),
        min_scale: outer.min_scale * inner.min_scale,
        max_scale: outer.max_scale * inner.max_scale,
        identity: false,
    }
}

/// Which copies of a repetition [`repeat_offsets`] places, and how far out.
#[derive(Clone, Debug, PartialEq)]
pub struct RepeatCopies {
    /// Each copy's offset in the repetition node's frame (the child is placed at
    /// `offset` there).
    pub offsets: Vec<Vec3>,
    /// For an infinite repetition, the distance from the camera out to which copies are
    /// placed (scene units; the scene's `max_distance` unless the cap made it shorter);
    /// `None` for a finite one.
    pub reach: Option<f32>,
}

/// The copies of the repetition `o` (a top-level [`ObjectKind::Repeat`] of `scene`) that
/// are instanced: every copy of a finite repetition (`None` when there are more than
/// `cap`); for an infinite one, the copies whose bounding sphere lies within the view
/// frustum widened by one period and the copy's radius, and within `max_distance` of the
/// camera, or within the longest distance (shortened in steps of 20%) at which at most
/// `cap` copies are left. `None` as well when `o` is not a repetition or its child is
/// unbounded.
pub fn repeat_offsets(scene: &Scene, o: &Object, cap: u64) -> Option<RepeatCopies> {
    let ObjectKind::Repeat { period, count, child } = &o.kind else { return None };
    let child_box = child.bounds()?;
    let repeated = |a: usize| period[a] > 0.0;
    if let Some(c) = count {
        let n: u64 = (0..3).filter(|&a| repeated(a)).map(|a| c[a] as u64).product();
        if n > cap {
            return None;
        }
        let ids = |a: usize| -> Vec<f32> {
            if !repeated(a) {
                return vec![0.0];
            }
            let half = (c[a] as f32 - 1.0) * 0.5;
            (0..c[a]).map(|k| (k as f32 - half) * period[a]).collect()
        };
        let (xs, ys, zs) = (ids(0), ids(1), ids(2));
        let mut offsets = Vec::with_capacity(n as usize);
        for &z in &zs {
            for &y in &ys {
                for &x in &xs {
                    offsets.push(Vec3::new(x, y, z));
                }
            }
        }
        return Some(RepeatCopies { offsets, reach: None });
    }
    let view = View::new(scene, o, &child_box, *period);
    let mut reach = scene.settings.max_distance;
    for _ in 0..200 {
        if !(reach > 0.0) || !reach.is_finite() {
            return None;
        }
        if let Some(offsets) = view.copies_within(reach, cap) {
            return Some(RepeatCopies { offsets, reach: Some(reach) });
        }
        reach *= 0.8;
    }
    None
}

/// The camera and a repetition seen by it, for [`repeat_offsets`].
struct View {
    eye: Vec3,
    /// Outward normals of the frustum's side planes through the eye; empty when the camera
    /// has no frustum (degenerate up vector).
    planes: Vec<Vec3>,
    /// The repetition node's transform.
    transform: Transform,
    period: Vec3,
    /// The child's box centre, node frame.
    centre: Vec3,
    /// A copy's bounding radius, world.
    radius: f32,
    /// How far outside the frustum a copy may lie, world.
    margin: f32,
}

impl View {
    fn new(scene: &Scene, o: &Object, child_box: &Aabb, period: Vec3) -> View {
        let cam = &scene.camera;
        let transform = o.compiled_transform();
        let f = cam.forward.normalize();
        let mut planes = Vec::new();
        if let Some(r) = f.cross(cam.up).try_normalize() {
            let u = r.cross(f);
            let half_h = (0.5 * cam.fov_y_deg.to_radians()).tan();
            let half_w = half_h * cam.width as f32 / cam.height.max(1) as f32;
            for (edge, along) in
                [(f + r * half_w, u), (f - r * half_w, u), (f + u * half_h, r), (f - u * half_h, r)]
            {
                let n = edge.cross(along).normalize();
                planes.push(if n.dot(f) > 0.0 { -n } else { n });
            }
        }
        let (lo, hi) = (Vec3::from(child_box.min), Vec3::from(child_box.max));
        let radius = 0.5 * (hi - lo).length() * transform.max_scale;
        let margin = radius + period.max_element() * transform.max_scale;
        View { eye: cam.position, planes, transform, period, centre: 0.5 * (lo + hi), radius, margin }
    }

    /// The offsets of the copies within `reach` of the eye and the widened frustum, or
    /// `None` when there are more than `cap` (or the cells to look at are more than 16
    /// times `cap`).
    fn copies_within(&self, reach: f32, cap: u64) -> Option<Vec<Vec3>> {
        // The cells whose centre lies within `reach + radius` (world) of the eye.
        let eye = self.transform.point_to_local(self.eye);
        let local = (reach + self.radius) / self.transform.min_scale;
        let mut range = [(0i64, 0i64); 3];
        let mut cells: f64 = 1.0;
        for (a, r) in range.iter_mut().enumerate() {
            let s = self.period[a];
            if s > 0.0 {
                let lo = ((eye[a] - self.centre[a] - local) / s).ceil() as f64;
                let hi = ((eye[a] - self.centre[a] + local) / s).floor() as f64;
                if hi < lo {
                    return Some(Vec::new());
                }
                cells *= hi - lo + 1.0;
                *r = (lo as i64, hi as i64);
            }
        }
        if cells > 16.0 * cap as f64 {
            return None;
        }
        let mut out = Vec::new();
        for z in range[2].0..=range[2].1 {
            for y in range[1].0..=range[1].1 {
                for x in range[0].0..=range[0].1 {
                    let offset = Vec3::new(x as f32, y as f32, z as f32) * self.period;
                    let c = self.transform.to_world.transform_point3(self.centre + offset) - self.eye;
                    if c.length() > reach + self.radius || self.planes.iter().any(|n| n.dot(c) > self.margin)
                    {
                        continue;
                    }
                    if out.len() as u64 == cap {
                        return None;
                    }
                    out.push(offset);
                }
            }
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::transform::TransformDesc;

    #[test]
    fn composition_matches_applying_the_parts_in_turn() {
        let outer = Transform::new(&TransformDesc {
            translate: Vec3::new(1.0, 2.0, 3.0),
            rotate_deg: Vec3::new(10.0, 20.0, 30.0),
            scale: Vec3::splat(2.0),
        });
        let inner = Transform::new(&TransformDesc {
            translate: Vec3::new(-0.5, 0.0, 0.25),
            rotate_deg: Vec3::new(0.0, 45.0, 0.0),
            scale: Vec3::new(1.0, 0.5, 1.5),
        });
        let offset = Vec3::new(0.8, 0.0, -1.6);
        let t = compose(&outer, offset, &inner);
        let p = Vec3::new(0.3, -0.7, 0.2);
        let expect = outer.to_world.transform_point3(inner.to_world.transform_point3(p) + offset);
        assert!((t.to_world.transform_point3(p) - expect).length() < 1e-5);
        assert!((t.to_local.transform_point3(expect) - p).length() < 1e-5);
        assert_eq!((t.min_scale, t.max_scale), (1.0, 3.0));
    }
}
