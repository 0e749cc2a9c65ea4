//! Triangle meshes in the tracer: a BVH per mesh (an obvhs PLOC BVH2 collapsed into the
//! 8-wide [`WideBvh`] with triangle corners pre-gathered into leaf packets; the triangle
//! list reordered into leaf order), the watertight ray/triangle test, flat or smooth
//! (vertex-normal) shading, instancing under a transform, and exact byte counts. Where the
//! CPU has AVX2 a closest hit runs whole (ray setup, walk, hit record) in one function
//! compiled for it, with no call in between.
//!
//! The triangles, normals and BVH of a mesh ([`MeshShape`]) are shared (an `Arc`) by every
//! [`MeshGeometry`] placed from it ([`MeshGeometry::placed`]): one mesh and one BVH,
//! one transform per instance, as a polygon renderer instances repeated geometry
//! ([`instance`]: the copies of a repetition).

pub mod compact;
pub mod instance;
pub mod packet;
pub mod triangle;
pub mod wide_bvh;

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{DVec3, Vec3};
use obvhs::BvhBuildParams;

use crate::geometry::bvh2;
use crate::geometry::mesh::compact::{CompactBvh, VertexGrid};
use crate::geometry::mesh::instance::compose;
use crate::geometry::mesh::triangle::{ShearedRay, closest_point_on_triangle};
use crate::geometry::mesh::wide_bvh::{LeafHit, WideBvh, WideLayout, any_hit_of, any_walk, closest_walk};
use crate::geometry::{
    Aabb, Census, Geometry, Hit, MaterialId, PACKET, Ray, RayStats, Shared, aabb, any_hits_one_by_one,
    closest_hits_one_by_one, f32_error, max_abs,
};
use crate::mesh::TriangleMesh;
pub use crate::scene::shape::{MeshLayout, Shading};
use crate::scene::transform::{Transform, TransformDesc};
use crate::simd::{Kernel, Portable, Simd, dispatch};

/// The extents (longest side of the box, scene units) of the meshes traced in the frame
/// they are given in: 2^-20 to 2^20 (about 1e-6 to 1e6). Beyond, a mesh is traced in a
/// frame scaled by a power of two ([`MeshShape::unit`]): the triangle test multiplies
/// three coordinates and the closest point four, and `f32` products of a mesh 2^32
/// across overflow (2^128), those of one 2^-32 across lose digits to subnormals. Every
/// mesh of the example scenes and `shared/meshes` lies within.
pub const ORDINARY_EXTENT: std::ops::RangeInclusive<f64> = 9.5367431640625e-7..=1048576.0;

/// A mesh's acceleration structure in one of the layouts.
enum Accel {
    /// [`MeshLayout::Full`].
    Full(WideBvh),
    /// [`MeshLayout::Compact`]: it holds the triangles and vertices too. Boxed, so that the
    /// full layout's shape keeps its size (and byte count).
    Compact(Box<CompactBvh>),
}

/// The part of a traced mesh that instances share: positions, triangles, normals and the
/// BVH, in the mesh's own frame.
pub struct MeshShape {
    /// Vertex positions (the full layout; empty in the compact one, whose BVH holds them).
    positions: Vec<Vec3>,
    /// Triangles in BVH leaf order: leaf primitive `i` is `triangles[i]` (the full layout;
    /// empty in the compact one, whose BVH holds them).
    triangles: Vec<[u32; 3]>,
    normals: Option<Vec<Vec3>>,
    bvh: Accel,
    /// The box of the triangles (padded as the BVH's leaves), `None` without triangles.
    local_bounds: Option<Aabb>,
    /// For a mesh whose extent lies outside [`ORDINARY_EXTENT`] (1e19 or 1e-30 across, say),
    /// the scale by a power of two from the shape's frame, in which `positions`
    /// are of ordinary size (see [`MeshGeometry::with_params`]), to the mesh's: the
    /// triangle test and the closest point multiply coordinates (squares and cubes of the
    /// extent overflow or underflow `f32` there). Exact both ways. `None` for every other
    /// mesh, stored as given.
    unit: Option<Box<Transform>>,
}

impl MeshShape {
    /// Bytes of the shape: its struct and everything it owns (the BVH's struct counted once).
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.positions.capacity() * std::mem::size_of::<Vec3>()
            + self.triangles.capacity() * std::mem::size_of::<[u32; 3]>()
            + self.normals.as_ref().map_or(0, |n| n.capacity() * std::mem::size_of::<Vec3>())
            + self.accel_bytes()
    }

    /// Bytes of the BVH on the heap: the full layout's nodes and leaf packets (which hold
    /// the corners), the compact layout's boxed struct, nodes, triangle list (its leaves)
    /// and 16-bit vertices (it holds the mesh).
    pub fn accel_bytes(&self) -> usize {
        match &self.bvh {
            Accel::Full(b) => b.bytes_used() - std::mem::size_of::<WideBvh>(),
            Accel::Compact(b) => b.bytes_used(),
        }
    }

    /// Bytes of the BVH as the benchmarks count it per triangle: the full layout's nodes
    /// and leaf packets, the compact layout's nodes and triangle list.
    pub fn bvh_bytes(&self) -> usize {
        match &self.bvh {
            Accel::Full(b) => b.bytes_used() - std::mem::size_of::<WideBvh>(),
            Accel::Compact(b) => b.node_bytes() + b.triangles.capacity() * std::mem::size_of::<[u32; 3]>(),
        }
    }

    /// What the shape stores: its triangles and the BVH's nodes and packets.
    pub fn census(&self) -> Census {
        Census {
            triangles: self.triangle_count() as u64,
            grid_samples: 0,
            accel_bytes: self.bvh_bytes() as u64,
        }
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        match &self.bvh {
            Accel::Full(_) => self.triangles.len(),
            Accel::Compact(b) => b.triangles.len(),
        }
    }

    /// The layout of the BVH.
    pub fn layout(&self) -> MeshLayout {
        match &self.bvh {
            Accel::Full(_) => MeshLayout::Full,
            Accel::Compact(_) => MeshLayout::Compact,
        }
    }

    /// Triangle `i` (leaf order): its vertex indices.
    #[inline(always)]
    fn triangle(&self, i: u32) -> [u32; 3] {
        match &self.bvh {
            Accel::Full(_) => self.triangles[i as usize],
            Accel::Compact(b) => b.triangles[i as usize],
        }
    }

    /// The corners of triangle `i` (leaf order).
    #[inline]
    fn corners(&self, i: u32) -> [Vec3; 3] {
        match &self.bvh {
            Accel::Full(_) => self.triangle(i).map(|v| self.positions[v as usize]),
            Accel::Compact(b) => b.corners(i as usize),
        }
    }

    /// Vertex positions, the shape's frame.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// Triangles (indices into [`Self::positions`]), in BVH leaf order: the triangle
    /// indices a rasterizer reports are those of [`MeshGeometry::triangle_hit`].
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The box of the triangles in the shape's frame (the mesh's, unless
    /// [`MeshShape::unit`] scales it), `None` without triangles.
    pub fn local_bounds(&self) -> Option<Aabb> {
        self.local_bounds
    }

    /// The transform from the shape's frame to the world for a mesh placed by
    /// `placement` (mesh frame to world), and the placement where the two differ.
    fn frame(&self, placement: Transform) -> (Transform, Option<Box<Transform>>) {
        match &self.unit {
            None => (placement, None),
            Some(unit) => (compose(&placement, Vec3::ZERO, unit), Some(Box::new(placement))),
        }
    }
}

/// A triangle mesh ready for tracing: a shared [`MeshShape`] placed under a transform.
pub struct MeshGeometry {
    shape: Arc<MeshShape>,
    /// From the shape's frame to the world: the placement, composed with the shape's
    /// [`MeshShape::unit`] scale where it has one.
    transform: Transform,
    /// The placement (mesh frame to world) where it differs from `transform`.
    placement: Option<Box<Transform>>,
    /// Whether `transform` scales by less than 2^-8 or more than 2^8, so that local ray
    /// directions may be far from unit length (see [`rescale`]).
    far_scale: bool,
    material: MaterialId,
    world_bounds: Option<Aabb>,
    label: String,
    /// Wall-clock time of the BVH build (of the shared shape, for a placed instance).
    pub build_time: Duration,
}

impl MeshGeometry {
    /// The BVH build parameters used by [`MeshGeometry::new`], chosen by measurement
    /// (benches/primary_rays.rs, reports/bench/primary_rays.txt): obvhs's fast PLOC preset
    /// with at most four triangles per leaf (one packet; the grouping into the 8-wide BVH
    /// merges sibling leaves into leaves of up to eight) and 25 times its reinsertion
    /// (obvhs tries to move half of the BVH2's nodes to where they cost less by the surface
    /// area heuristic, rather than 2%). The presets, as they are, and leaves of one to three
    /// triangles traced within 1% of the fast preset; reinsertion is what made a better
    /// tree: on the bunny, hit rays visit 6.1 nodes instead of 6.5, and primary rays trace
    /// 2% faster (15.9 against 15.6 Mrays/s on one thread; 1.7% on the armadillo), within
    /// 0.5% of a ratio of 1 in half its build time, for a build four times the fast
    /// preset's (72 against 17 ms for the bunny, 106 against 32 for the armadillo; see the
    /// report for the latest run).
    pub const BUILD_PARAMS: BvhBuildParams = BvhBuildParams {
        max_prims_per_leaf: 4,
        reinsertion_batch_ratio: 0.5,
        ..BvhBuildParams::fast_build()
    };

    /// Builds the BVH of `mesh` (which must satisfy the `TriangleMesh` invariants).
    pub fn new(
        mesh: TriangleMesh,
        shading: Shading,
        transform: Transform,
        material: MaterialId,
        label: String,
    ) -> Self {
        Self::with_params(mesh, shading, transform, material, label, Self::BUILD_PARAMS)
    }

    /// [`MeshGeometry::new`] with explicit BVH build parameters (for benchmarks).
    pub fn with_params(
        mesh: TriangleMesh,
        shading: Shading,
        transform: Transform,
        material: MaterialId,
        label: String,
        params: BvhBuildParams,
    ) -> Self {
        Self::with_options(mesh, shading, transform, material, label, params, MeshLayout::Full)
    }

    /// [`MeshGeometry::new`] in layout `layout`. The compact layout traces the mesh with its
    /// positions snapped to a 16-bit grid ([`VertexGrid`]); a mesh it cannot represent
    /// (boxes beyond `f32`, more than 2^26 triangles) keeps the full layout
    /// ([`MeshShape::layout`] says which was built).
    pub fn with_layout(
        mesh: TriangleMesh,
        shading: Shading,
        transform: Transform,
        material: MaterialId,
        label: String,
        layout: MeshLayout,
    ) -> Self {
        Self::with_options(mesh, shading, transform, material, label, Self::BUILD_PARAMS, layout)
    }

    /// [`MeshGeometry::with_params`] in layout `layout` ([`MeshGeometry::with_layout`]).
    pub fn with_options(
        mesh: TriangleMesh,
        shading: Shading,
        transform: Transform,
        material: MaterialId,
        label: String,
        params: BvhBuildParams,
        layout: MeshLayout,
    ) -> Self {
        let start = Instant::now();
        let TriangleMesh { mut positions, triangles, mut normals } = mesh;
        // Outside the ordinary range of extents, to the unit frame (see `MeshShape::unit`)
        // by a power of two (2^-120 to 2^120, normal f32 numbers): the one nearest the
        // geometric mean of the mesh's extent and its smallest triangle's, so that a mesh
        // whose triangles span many orders of magnitude (a plane disc 1e20 in radius,
        // whose rings grow from a fraction of the camera's height) keeps both its small
        // triangles and its large ones within the range of the triangle test.
        let unit = {
            let (lo, hi) = positions
                .iter()
                .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(l, h), &p| (l.min(p), h.max(p)));
            let size = (hi.as_dvec3() - lo.as_dvec3()).max(DVec3::ZERO).max_element();
            if triangles.is_empty() || size == 0.0 || ORDINARY_EXTENT.contains(&size) {
                None
            } else {
                let smallest = triangles
                    .iter()
                    .map(|t| {
                        let [a, b, c] = t.map(|i| positions[i as usize].as_dvec3());
                        (a.max(b).max(c) - a.min(b).min(c)).max_element()
                    })
                    .filter(|&e| e > 0.0)
                    .fold(size, f64::min);
                let k = ((0.5 * (smallest.log2() + size.log2())).floor() as i32).clamp(-120, 120);
                let down = 2f32.powi(-k);
                for p in &mut positions {
                    *p *= down;
                }
                let desc = TransformDesc { scale: Vec3::splat(2f32.powi(k)), ..TransformDesc::default() };
                Some(Box::new(Transform::new(&desc)))
            }
        };
        // The compact layout traces the mesh snapped to its grid: snapped before the BVH
        // is built, so that its boxes hold the triangles the walks test.
        let grid = if layout == MeshLayout::Compact && !triangles.is_empty() {
            VertexGrid::of(&positions)
        } else {
            None
        };
        if let Some(g) = &grid {
            for p in &mut positions {
                *p = g.snap(*p);
            }
        }
        // Triangles in axis-aligned planes have flat boxes, which the PLOC builder clusters
        // badly (measured: a cylinder's flat caps cost 326 leaf triangles per ray against 5
        // with padding); pad every box by a millionth of the mesh's size.
        let pad = {
            let (lo, hi) = positions
                .iter()
                .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(l, h), &p| (l.min(p), h.max(p)));
            Vec3::splat(1e-6 * (hi - lo).length().max(f32::MIN_POSITIVE))
        };
        // A mesh brought to the unit frame gets a box's pad of at most a thousandth of
        // the box's own longest side too: such a mesh may span many orders of magnitude
        // (the geometric rings of a plane disc 1e20 in radius), and the mesh's pad would
        // give all its small triangles the same padded box, which the builder pairs into
        // a chain.
        let boxes: Vec<Aabb> = triangles
            .iter()
            .map(|t| {
                let (a, b, c) =
                    (positions[t[0] as usize], positions[t[1] as usize], positions[t[2] as usize]);
                let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
                let pad =
                    if unit.is_none() { pad } else { pad.min(Vec3::splat(1e-3 * (hi - lo).max_element())) };
                aabb(lo - pad, hi + pad)
            })
            .collect();
        let mut bvh2 = bvh2::build(&boxes, params);
        // Reorder the triangles (and their boxes) into leaf order.
        let triangles: Vec<[u32; 3]> =
            bvh2.primitive_indices.iter().map(|&i| triangles[i as usize]).collect();
        let leaf_boxes: Vec<Aabb> = bvh2.primitive_indices.iter().map(|&i| boxes[i as usize]).collect();
        for (i, p) in bvh2.primitive_indices.iter_mut().enumerate() {
            *p = i as u32;
        }
        let bvh = WideBvh::from_bvh2(&bvh2, &leaf_boxes, |i| {
            let t = triangles[i as usize];
            t.map(|v| positions[v as usize])
        });
        drop(bvh2);
        match shading {
            Shading::Flat => normals = None,
            Shading::Smooth if normals.is_none() => {
                let mut m = TriangleMesh {
                    positions: positions.clone(),
                    triangles: triangles.clone(),
                    normals: None,
                };
                m.compute_vertex_normals();
                normals = m.normals;
            }
            Shading::Smooth => {}
        }
        let local_bounds = boxes.iter().copied().reduce(|a, b| a.union(&b));
        let compact = grid.and_then(|g| CompactBvh::from_wide(&bvh, triangles.clone(), &positions, g));
        let (positions, triangles, bvh) = match compact {
            Some(c) => (Vec::new(), Vec::new(), Accel::Compact(Box::new(c))),
            None => (positions, triangles, Accel::Full(bvh)),
        };
        let shape = Arc::new(MeshShape { positions, triangles, normals, bvh, local_bounds, unit });
        let build_time = start.elapsed();
        Self::on_shape(shape, transform, material, label, build_time)
    }

    /// Another instance of this geometry's mesh and BVH (shared, not copied) under
    /// `transform` (mesh frame to world) with `material`.
    pub fn placed(&self, transform: Transform, material: MaterialId, label: String) -> MeshGeometry {
        Self::on_shape(Arc::clone(&self.shape), transform, material, label, self.build_time)
    }

    /// The geometry of `shape` under `transform` (mesh frame to world): the one place an
    /// instance's frame, placement and world bounds are derived.
    fn on_shape(
        shape: Arc<MeshShape>,
        transform: Transform,
        material: MaterialId,
        label: String,
        build_time: std::time::Duration,
    ) -> MeshGeometry {
        let (transform, placement) = shape.frame(transform);
        let world_bounds = shape.local_bounds.map(|b| transform.box_to_world(&b));
        MeshGeometry {
            far_scale: far_scale(&transform),
            shape,
            transform,
            placement,
            material,
            world_bounds,
            label,
            build_time,
        }
    }

    /// The shared mesh and BVH.
    pub fn shape(&self) -> &Arc<MeshShape> {
        &self.shape
    }

    /// The transform from the mesh's frame to the world (as placed).
    pub fn transform(&self) -> &Transform {
        self.placement.as_deref().unwrap_or(&self.transform)
    }

    /// The transform from the shape's frame ([`MeshShape::positions`]) to the world: the
    /// placement, composed with the shape's unit scale where it has one.
    pub fn shape_to_world(&self) -> &Transform {
        &self.transform
    }

    /// The hit of `ray` with triangle `triangle` alone (an index into
    /// [`MeshShape::triangles`]), for `t` in `[0, t_max]`: the hit record
    /// [`Geometry::closest_hit`] gives when that triangle is the closest (the same
    /// watertight test and hit record), for a caller that already knows which triangle is
    /// visible (the rasterizer). `None` when the ray misses it, or for a mesh placed under a
    /// scale far from 1 (see [`far_scale`]; the caller then traces the ray).
    pub fn triangle_hit(&self, ray: &Ray, triangle: u32, t_max: f32) -> Option<Hit> {
        if self.far_scale || triangle as usize >= self.shape.triangles.len() {
            return None;
        }
        let local = if self.transform.identity { *ray } else { self.transform.ray_to_local(ray) };
        let corners = self.shape.corners(triangle);
        let [a, b, c] = corners;
        let h = ShearedRay::new(local.origin, local.dir).intersect(a, b, c, 0.0, t_max)?;
        Some(self.hit_record(ray, &local, LeafHit { triangle, t: h.t, corners }, h.t, &self.transform))
    }

    /// The triangles in world space (positions transformed; no normals).
    pub fn world_mesh(&self) -> TriangleMesh {
        let (positions, triangles) = match &self.shape.bvh {
            Accel::Full(_) => (self.shape.positions.clone(), self.shape.triangles.clone()),
            Accel::Compact(b) => {
                (b.vertices.iter().map(|&q| b.grid.position(q)).collect(), b.triangles.clone())
            }
        };
        TriangleMesh {
            positions: positions.into_iter().map(|p| self.transform.to_world.transform_point3(p)).collect(),
            triangles,
            normals: None,
        }
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.shape.triangle_count()
    }

    /// Bytes of this instance alone: its struct and label, without the shared shape.
    pub fn instance_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.label.capacity()
            + self.placement.as_ref().map_or(0, |_| std::mem::size_of::<Transform>())
    }

    /// Bytes of the BVH alone: its struct and what it holds ([`MeshShape::accel_bytes`]
    /// and the struct).
    pub fn accel_bytes(&self) -> usize {
        match &self.shape.bvh {
            Accel::Full(b) => b.bytes_used(),
            Accel::Compact(b) => b.bytes_used(),
        }
    }

    /// [`Geometry::closest_hit`] on backend `s`: ray setup, walk and hit record in one
    /// body (inlined into [`ClosestHit::run`], so that under AVX2 all of it is compiled
    /// with AVX2, in one function).
    #[inline(always)]
    fn closest_hit_on<S: Simd, L: WideLayout>(
        &self,
        s: S,
        bvh: &L,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stats: &mut RayStats,
    ) -> Option<Hit> {
        let local = if self.transform.identity { *ray } else { self.transform.ray_to_local(ray) };
        let leaf = closest_walk(s, bvh, local.origin, local.dir, t_min, t_max, stats)?;
        Some(self.hit_record(ray, &local, leaf, leaf.t, &self.transform))
    }

    /// For a mesh whose transform scales by less than 2^-8 or more than 2^8 (see
    /// [`far_scale`]) and a ray whose local direction is far from unit length
    /// ([`rescale`]): [`Geometry::closest_hit`] with the local direction divided by `f`,
    /// `t` times `f` along it, and normals through the placement (the shape's unit scale
    /// is uniform, so it leaves their directions alone, and the f32 inverse of a scale
    /// like 2^-100, whose determinant underflows, would make them NaN); on the portable
    /// backend, whose hits are the AVX2 backend's. `None` for other rays.
    #[inline(never)]
    #[cold]
    fn closest_hit_rescaled(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stats: &mut RayStats,
    ) -> Option<Option<Hit>> {
        let local = self.transform.ray_to_local(ray);
        let f = rescale(local.dir)?;
        let local = Ray::spawned(local.origin, local.dir / f, local.spread);
        let (o, d) = (local.origin, local.dir);
        let leaf = match &self.shape.bvh {
            Accel::Full(b) => closest_walk(Portable, b, o, d, t_min * f, t_max * f, stats),
            Accel::Compact(b) => closest_walk(Portable, &**b, o, d, t_min * f, t_max * f, stats),
        };
        Some(leaf.map(|leaf| self.hit_record(ray, &local, leaf, leaf.t / f, self.transform())))
    }

    /// The hit record of the closest hit `leaf` of `local` (`ray` in the shape's frame),
    /// at `t_world` along `ray`, with normals mapped to the world by `normals`.
    #[inline(always)]
    fn hit_record(&self, ray: &Ray, local: &Ray, leaf: LeafHit, t_world: f32, normals: &Transform) -> Hit {
        let LeafHit { triangle: i, t, corners: [a, b, c] } = leaf;
        let geometric = (b - a).cross(c - a);
        let normal = normals.normal_to_world(geometric);
        let mut shading_normal = normal;
        if let Some(vertex_normals) = &self.shape.normals {
            // The same test on the winner alone, for its barycentrics (bit-identical `t`).
            let bary = ShearedRay::new(local.origin, local.dir)
                .intersect(a, b, c, t, t)
                .map_or([1.0 / 3.0; 3], |h| h.bary);
            let t = self.shape.triangle(i);
            let s = vertex_normals[t[0] as usize] * bary[0]
                + vertex_normals[t[1] as usize] * bary[1]
                + vertex_normals[t[2] as usize] * bary[2];
            // Keep the side the geometric normal is on, so inside/outside stays consistent.
            if s.dot(geometric) > 0.0 {
                shading_normal = normals.normal_to_world(s);
            }
        }
        let point = ray.at(t_world);
        let local_point = local.at(t);
        let m = max_abs(point).max(max_abs(ray.origin)).max(max_abs(local_point) * self.transform.max_scale);
        Hit { t: t_world, point, normal, shading_normal, material: self.material, error: f32_error(m) }
    }
}

impl MeshGeometry {
    /// Whether batches can go in packets ([`packet`]): the full layout, a BVH shallow
    /// enough for a packet's stack. The compact layout traces batches one ray at a time.
    fn packets_fit(&self) -> bool {
        match &self.shape.bvh {
            Accel::Full(b) => packet::fits(b),
            Accel::Compact(_) => false,
        }
    }
}

/// Whether `t` scales some direction by less than 2^-8 or more than 2^8.
fn far_scale(t: &Transform) -> bool {
    !t.identity && (t.min_scale < 1.0 / 256.0 || t.max_scale > 256.0)
}

/// For a local ray direction far from unit length (its largest component below 2^-8 or
/// above 2^8: under a placement's scale of 1e30, or the shape's [`MeshShape::unit`]
/// scale), the power of two `f` that `dir / f` brings back to about unit length (then a
/// `t` along the world ray is `t * f` along the local one, exactly); `None` otherwise. The
/// box tests' safe reciprocal treats direction components below `f32::EPSILON` as about
/// zero, which for a direction 2^-30 long would be all of them.
#[inline(always)]
fn rescale(dir: Vec3) -> Option<f32> {
    let m = max_abs(dir);
    if (1.0 / 256.0..=256.0).contains(&m) || !m.is_normal() {
        return None;
    }
    Some(2f32.powi(m.log2().floor() as i32))
}

/// [`Geometry::closest_hit`] of a [`MeshGeometry`] whose BVH is `bvh` as a [`Kernel`]
/// (one per layout, so that each is compiled apart).
struct ClosestHit<'a, L> {
    mesh: &'a MeshGeometry,
    bvh: &'a L,
    ray: &'a Ray,
    t_min: f32,
    t_max: f32,
    stats: &'a mut RayStats,
}

impl<L: WideLayout> Kernel for ClosestHit<'_, L> {
    type Output = Option<Hit>;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> Option<Hit> {
        let ray = Ray::new(self.ray.origin, self.ray.dir);
        self.mesh.closest_hit_on(s, self.bvh, &ray, self.t_min, self.t_max, self.stats)
    }
}

/// The rays of one packet of a batch in the shape's frame (lanes past `rays.len()` repeat
/// the last ray, so every lane holds a valid ray; the walks keep them inactive).
#[inline(always)]
fn local_packet(transform: &Transform, rays: &[Ray]) -> ([Ray; PACKET], [Vec3; PACKET], [Vec3; PACKET]) {
    let mut local = [rays[0]; PACKET];
    for (l, slot) in local.iter_mut().enumerate() {
        let ray = &rays[l.min(rays.len() - 1)];
        *slot = if transform.identity { *ray } else { transform.ray_to_local(ray) };
    }
    let mut origins = [Vec3::ZERO; PACKET];
    let mut dirs = [Vec3::ZERO; PACKET];
    for l in 0..PACKET {
        (origins[l], dirs[l]) = (local[l].origin, local[l].dir);
    }
    (local, origins, dirs)
}

/// [`Geometry::closest_hits`] of a [`MeshGeometry`] as a [`Kernel`]: the batch in packets of
/// [`PACKET`] rays through [`packet::closest_coherent`] (incoherent packets one ray at a
/// time), in one function compiled for the
/// backend.
struct ClosestHits<'a> {
    mesh: &'a MeshGeometry,
    rays: &'a [Ray],
    t_min: f32,
    t_max: &'a mut [f32],
    hits: &'a mut [Option<Hit>],
    stats: &'a mut RayStats,
}

impl Kernel for ClosestHits<'_> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        let mesh = self.mesh;
        let Accel::Full(bvh) = &mesh.shape.bvh else { unreachable!("packets of the full layout only") };
        let bounds = packet::PacketBounds::of(bvh);
        let packets =
            self.rays.chunks(PACKET).zip(self.t_max.chunks_mut(PACKET)).zip(self.hits.chunks_mut(PACKET));
        for ((rays, t_max), hits) in packets {
            let (local, origins, dirs) = local_packet(&mesh.transform, rays);
            let mut reach = [f32::NEG_INFINITY; PACKET];
            reach[..rays.len()].copy_from_slice(t_max);
            let (n, t_min) = (rays.len(), self.t_min);
            let coherent =
                packet::closest_coherent(s, bvh, bounds, &origins, &dirs, n, t_min, &mut reach, self.stats);
            // An incoherent packet goes one ray at a time (loops rather than closures, which
            // the compiler could leave out of line, where they would not be compiled for the
            // backend's instructions).
            let found = match coherent {
                Some(found) => found,
                None => {
                    let mut found = [None; PACKET];
                    for l in 0..n {
                        found[l] = closest_walk(s, bvh, origins[l], dirs[l], t_min, reach[l], self.stats);
                    }
                    found
                }
            };
            for (l, leaf) in found.into_iter().enumerate() {
                if let Some(leaf) = leaf {
                    let ray = Ray::new(rays[l].origin, rays[l].dir);
                    hits[l] = Some(mesh.hit_record(&ray, &local[l], leaf, leaf.t, &mesh.transform));
                    t_max[l] = leaf.t;
                }
            }
        }
    }
}

/// [`Geometry::any_hits`] of a [`MeshGeometry`] as a [`Kernel`]: the batch in packets of
/// [`PACKET`] rays through [`packet::any_coherent`] (incoherent packets one ray at a time).
struct AnyHits<'a> {
    mesh: &'a MeshGeometry,
    rays: &'a [Ray],
    t_min: f32,
    t_max: &'a [f32],
    occluded: &'a mut [bool],
    stats: &'a mut RayStats,
}

impl Kernel for AnyHits<'_> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        let mesh = self.mesh;
        let Accel::Full(bvh) = &mesh.shape.bvh else { unreachable!("packets of the full layout only") };
        let bounds = packet::PacketBounds::of(bvh);
        let packets =
            self.rays.chunks(PACKET).zip(self.t_max.chunks(PACKET)).zip(self.occluded.chunks_mut(PACKET));
        for ((rays, t_max), occluded) in packets {
            let given = occluded.iter().enumerate().fold(0u32, |m, (l, &o)| m | u32::from(o) << l);
            if given.count_ones() as usize == rays.len() {
                continue;
            }
            let (_, origins, dirs) = local_packet(&mesh.transform, rays);
            let mut reach = [f32::NEG_INFINITY; PACKET];
            reach[..rays.len()].copy_from_slice(t_max);
            let (n, t_min) = (rays.len(), self.t_min);
            let found = match packet::any_coherent(
                s, bvh, bounds, &origins, &dirs, n, t_min, &reach, given, self.stats,
            ) {
                Some(found) => found,
                None => {
                    let mut found = given;
                    for l in 0..n {
                        if given & (1 << l) == 0
                            && any_walk(s, bvh, origins[l], dirs[l], t_min, reach[l], self.stats)
                        {
                            found |= 1 << l;
                        }
                    }
                    found
                }
            };
            for (l, o) in occluded.iter_mut().enumerate() {
                *o = found & (1 << l) != 0;
            }
        }
    }
}

impl Geometry for MeshGeometry {
    fn bounds(&self) -> Option<Aabb> {
        self.world_bounds
    }

    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        if self.far_scale
            && let Some(hit) = self.closest_hit_rescaled(ray, t_min, t_max, stats)
        {
            return hit;
        }
        match &self.shape.bvh {
            Accel::Full(bvh) => dispatch(ClosestHit { mesh: self, bvh, ray, t_min, t_max, stats }),
            Accel::Compact(bvh) => dispatch(ClosestHit { mesh: self, bvh: &**bvh, ray, t_min, t_max, stats }),
        }
    }

    /// Packets of [`PACKET`] rays through the BVH together ([`packet`]), each ray's hit
    /// the one [`Geometry::closest_hit`] gives it; one by one for a mesh placed at a far
    /// scale (whose rays may need rescaling) or with a BVH too deep for a packet's stack.
    fn closest_hits(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &mut [f32],
        hits: &mut [Option<Hit>],
        stats: &mut RayStats,
    ) {
        if self.far_scale || !self.packets_fit() {
            return closest_hits_one_by_one(self, rays, t_min, t_max, hits, stats);
        }
        dispatch(ClosestHits { mesh: self, rays, t_min, t_max, hits, stats });
    }

    /// False, although batches go in packets: a scene of several objects traces rays
    /// front to back through its top-level BVH faster, one by one (measured: ten
    /// tessellated objects 12.7 ms a frame one by one, 19.6 ms in packets), and a scene of
    /// one bounded object hands its batches to it whatever this says
    /// ([`crate::geometry::scene::SceneGeometry`]).
    fn prefers_packets(&self) -> bool {
        false
    }

    /// As [`Self::closest_hits`], for the rays not yet occluded.
    fn any_hits(&self, rays: &[Ray], t_min: f32, t_max: &[f32], occluded: &mut [bool], stats: &mut RayStats) {
        if self.far_scale || !self.packets_fit() {
            return any_hits_one_by_one(self, rays, t_min, t_max, occluded, stats);
        }
        dispatch(AnyHits { mesh: self, rays, t_min, t_max, occluded, stats });
    }

    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        let local = self.transform.ray_to_local(ray);
        let (mut dir, mut t_min, mut t_max) = (local.dir, t_min, t_max);
        if self.far_scale
            && let Some(f) = rescale(local.dir)
        {
            // As in `closest_hit_rescaled`.
            (dir, t_min, t_max) = (local.dir / f, t_min * f, t_max * f);
        }
        match &self.shape.bvh {
            Accel::Full(b) => b.any_hit(local.origin, dir, t_min, t_max, stats),
            Accel::Compact(b) => any_hit_of(&**b, local.origin, dir, t_min, t_max, stats),
        }
    }

    fn bytes_used(&self) -> usize {
        self.instance_bytes() + self.shape.bytes_used()
    }

    fn census(&self) -> Census {
        self.shape.census()
    }

    fn shared(&self) -> Option<Shared> {
        Some(Shared::of(&self.shape, self.shape.bytes_used(), self.shape.census()))
    }

    fn as_mesh(&self) -> Option<&MeshGeometry> {
        Some(self)
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        // Nearest point in the local frame, measured in the world (exact for rigid and
        // uniformly scaled transforms, an upper bound otherwise).
        let local = self.transform.point_to_local_f64(p);
        let to_world = |x: DVec3| self.transform.to_world.transform_point3(x.as_vec3()).as_dvec3();
        let mut best = f64::INFINITY;
        let dist = |i| {
            let [a, b, c] = self.shape.corners(i);
            let x = closest_point_on_triangle(local.as_vec3().into(), a.into(), b.into(), c.into());
            let d = (to_world(Vec3::from(x).as_dvec3()) - p).length();
            best = best.min(d);
            // The BVH prunes by local distance: convert the world distance back.
            d / self.transform.max_scale.max(f32::MIN_POSITIVE) as f64
        };
        match &self.shape.bvh {
            Accel::Full(b) => b.nearest(local, dist),
            Accel::Compact(b) => b.nearest(local, dist),
        };
        best
    }

    fn describe(&self) -> String {
        let bvh = match &self.shape.bvh {
            Accel::Full(b) => {
                format!(
                    "8-wide BVH of {} nodes and {} leaf packets (depth {})",
                    b.nodes.len(),
                    b.packets.len(),
                    b.depth
                )
            }
            Accel::Compact(b) => format!(
                "compact 8-wide BVH of {} quantised nodes over 16-bit vertices (depth {})",
                b.nodes.len(),
                b.depth
            ),
        };
        format!(
            "{}: {} triangles, {bvh} built in {:.1} ms, {}, {} lanes",
            self.label,
            self.shape.triangle_count(),
            self.build_time.as_secs_f64() * 1e3,
            if self.shape.normals.is_some() { "smooth shading" } else { "flat shading" },
            crate::simd::backend().name()
        )
    }
}
