//! Discrete SDF grids in the tracer: sphere tracing of the trilinear interpolation of a
//! [`SdfGrid`] inside its box, with the same tolerance, step limit, refinement and
//! over-relaxation as analytic SDFs, and normals from the interpolated field's gradient.
//! The samples are stored densely ([`SdfGrid`]) or as a narrow band ([`BandGrid`]: bricks
//! near the surface, a conservative distance bound elsewhere). [`ClippedGrid`] grids only
//! the part of a huge object that the camera sees ([`view_region`]) and sphere traces the
//! rest analytically. A grid read from a file is placed in the scene by a rigid transform
//! with uniform scale ([`GridObject::placed`]), which keeps its distances exact. Grids
//! prefer packets: eight rays' points are interpolated by one 8-wide kernel
//! ([`GridStore::march_distance8`]), lane by lane equal to the scalar field.

use std::sync::Arc;

use glam::{DVec3, Vec3};

use crate::geometry::grid::SdfGrid;
use crate::geometry::grid::band::BandGrid;
use crate::geometry::march::MarchParams;
use crate::geometry::marched::{
    BlockKind, DistanceField, FieldFacts, FieldObject, Marched, PointBlock, Storage, SurfacePoint,
};
use crate::geometry::{
    Aabb, Census, Geometry, Hit, MaterialId, PACKET, Ray, RayStats, Shared, aabb, box_distance,
    distance_by_projection,
};
use crate::scene::Scene;
use crate::scene::shape::Object;
use crate::scene::transform::Transform;

/// Steps are scaled by this factor: the trilinear interpolation of exact distance samples
/// can be slightly steeper than 1 between samples, so a full step could overshoot.
pub const GRID_STEP_SCALE: f64 = 0.9;

/// How a [`GridObject`] stores its samples.
#[derive(Clone, Debug, PartialEq)]
pub enum GridStore {
    /// Every sample of the box.
    Dense(SdfGrid),
    /// Bricks near the surface only.
    Band(BandGrid),
}

impl GridStore {
    /// The interpolated field at `p` (see [`SdfGrid::trilinear`], [`BandGrid::trilinear`]).
    #[inline]
    pub fn trilinear(&self, p: Vec3) -> f32 {
        match self {
            GridStore::Dense(g) => g.trilinear(p),
            GridStore::Band(b) => b.trilinear(p),
        }
    }

    /// The distance sphere tracing steps by at `p`: [`SdfGrid::trilinear`] for a dense
    /// grid, [`BandGrid::march_distance`] (the trilinear field in stored bricks, empty-space
    /// skipping elsewhere) for a band.
    #[inline]
    pub fn march_distance(&self, p: Vec3) -> f32 {
        crate::simd::dispatch(MarchDistance { store: self, p })
    }

    /// [`GridStore::march_distance`] for the baseline target.
    #[inline(always)]
    fn march_distance_portable(&self, p: Vec3) -> f32 {
        match self {
            GridStore::Dense(g) => g.trilinear_inline(p),
            GridStore::Band(b) => b.march_distance(p),
        }
    }

    /// [`GridStore::march_distance`] at the eight points `(xs[l], ys[l], zs[l])`, equal lane
    /// by lane ([`SdfGrid::trilinear8`], [`BandGrid::march_distance8`]).
    #[inline]
    pub fn march_distance8(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        match self {
            GridStore::Dense(g) => g.trilinear8(xs, ys, zs),
            GridStore::Band(b) => b.march_distance8(xs, ys, zs),
        }
    }

    /// The sample spacing.
    pub fn voxel(&self) -> f32 {
        match self {
            GridStore::Dense(g) => g.voxel,
            GridStore::Band(b) => b.voxel,
        }
    }

    /// Samples per axis (of the dense lattice).
    pub fn dims(&self) -> glam::UVec3 {
        match self {
            GridStore::Dense(g) => g.dims,
            GridStore::Band(b) => b.dims,
        }
    }

    /// The box, `(min, max)`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        match self {
            GridStore::Dense(g) => g.bounds(),
            GridStore::Band(b) => b.bounds(),
        }
    }

    /// Values actually stored (samples, plus one bound per empty brick of a band).
    pub fn stored_values(&self) -> u64 {
        match self {
            GridStore::Dense(g) => g.values.len() as u64,
            GridStore::Band(b) => b.stored_values(),
        }
    }

    /// Bytes held (struct included).
    pub fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>()
            + match self {
                GridStore::Dense(g) => g.bytes_used() - std::mem::size_of::<SdfGrid>(),
                GridStore::Band(b) => b.bytes_used() - std::mem::size_of::<BandGrid>(),
            }
    }
}

impl From<SdfGrid> for GridStore {
    fn from(g: SdfGrid) -> Self {
        GridStore::Dense(g)
    }
}

impl From<BandGrid> for GridStore {
    fn from(b: BandGrid) -> Self {
        GridStore::Band(b)
    }
}

/// A signed distance grid ready for tracing: the one marcher over a [`GridField`],
/// bounded by the grid's world-space box, with tolerances scaled by its diagonal.
pub type GridObject = Marched<GridField>;

/// The field of a [`GridObject`]: the trilinear interpolation of the samples, placed in
/// the world, with steps scaled by [`GRID_STEP_SCALE`] and one material.
pub struct GridField {
    /// The samples: the object's own, or shared by the objects that place one grid several
    /// times.
    grid: Samples,
    /// Where the grid's local frame sits in the world; `None` when the samples are in
    /// world space.
    placement: Option<Placement>,
    material: MaterialId,
}

/// A [`GridField`]'s samples. An object's own grid is held in place, not behind an `Arc`:
/// every evaluation reaches the samples through the field itself, one dependent load
/// fewer (measured: about 9% of a camera-ray frame of the dense bunny grid).
enum Samples {
    Own(GridStore),
    Shared(Arc<GridStore>),
}

impl std::ops::Deref for Samples {
    type Target = GridStore;

    #[inline(always)]
    fn deref(&self) -> &GridStore {
        match self {
            Samples::Own(g) => g,
            Samples::Shared(g) => g,
        }
    }
}

/// A rigid transform with uniform scale from a grid's frame to the world.
#[derive(Clone, Copy, Debug)]
struct Placement {
    /// World to grid frame.
    to_local: glam::DAffine3,
    /// Grid-frame distances times this are world distances (> 0).
    scale: f64,
}

impl GridObject {
    /// Wraps `grid` (world-space samples, a [`SdfGrid`] or a [`BandGrid`]) with a material.
    pub fn new(grid: impl Into<GridStore>, material: MaterialId, march: MarchParams, label: String) -> Self {
        let grid = Samples::Own(grid.into());
        let (lo, hi) = grid.bounds();
        let size = (hi - lo).length() as f64;
        let field = GridField { grid, placement: None, material };
        Marched::from_field(field, Some(aabb(lo, hi)), size, march, label)
    }

    /// Wraps `grid` whose samples are in a local frame placed in the world by `transform`,
    /// which must have a uniform scale ([`Transform::is_uniform`]; otherwise its smallest
    /// factor is used, which keeps the marched distance a lower bound).
    pub fn placed(
        grid: impl Into<GridStore>,
        transform: &Transform,
        material: MaterialId,
        march: MarchParams,
        label: String,
    ) -> Self {
        if transform.identity {
            return Self::new(grid, material, march, label);
        }
        Self::placed_samples(Samples::Own(grid.into()), transform, material, march, label)
    }

    /// [`GridObject::placed`] for a grid that other objects place too (each counts it in
    /// its bytes; a scene counts it once, [`Geometry::shared`]).
    pub fn placed_shared(
        grid: Arc<GridStore>,
        transform: &Transform,
        material: MaterialId,
        march: MarchParams,
        label: String,
    ) -> Self {
        Self::placed_samples(Samples::Shared(grid), transform, material, march, label)
    }

    fn placed_samples(
        grid: Samples,
        transform: &Transform,
        material: MaterialId,
        march: MarchParams,
        label: String,
    ) -> Self {
        let (lo, hi) = grid.bounds();
        let bounds = transform.box_to_world(&aabb(lo, hi));
        let size = (bounds.max - bounds.min).length() as f64;
        let placement =
            Some(Placement { to_local: transform.to_local_f64, scale: transform.min_scale as f64 });
        Marched::from_field(GridField { grid, placement, material }, Some(bounds), size, march, label)
    }

    /// The grid.
    pub fn grid(&self) -> &GridStore {
        &self.field().grid
    }
}

impl GridField {
    /// The marched field at world point `p`, world units: the interpolated field (outside
    /// the grid's box continued as a distance bound, see [`SdfGrid::trilinear`]), in a
    /// band's empty bricks its skipping distance ([`GridStore::march_distance`]).
    #[inline]
    fn field(&self, p: DVec3) -> f64 {
        match &self.placement {
            None => self.grid.march_distance(p.as_vec3()) as f64,
            Some(m) => self.grid.march_distance(m.to_local.transform_point3(p).as_vec3()) as f64 * m.scale,
        }
    }

    /// [`GridField::field`] at eight points, equal lane by lane: the points are mapped to
    /// the grid's frame and rounded to `f32` one by one, exactly as `field` does, and
    /// interpolated together ([`GridStore::march_distance8`]).
    #[inline]
    fn field8(&self, points: &[DVec3; 8]) -> [f64; 8] {
        let local: [Vec3; 8] = match &self.placement {
            None => points.map(|p| p.as_vec3()),
            Some(m) => points.map(|p| m.to_local.transform_point3(p).as_vec3()),
        };
        let xs = local.map(|p| p.x);
        let ys = local.map(|p| p.y);
        let zs = local.map(|p| p.z);
        let v = self.grid.march_distance8(&xs, &ys, &zs);
        match &self.placement {
            None => v.map(|x| x as f64),
            Some(m) => v.map(|x| x as f64 * m.scale),
        }
    }
}

impl DistanceField for GridField {
    #[inline]
    fn distance(&self, p: DVec3, _tolerance: f64) -> f64 {
        self.field(p) * GRID_STEP_SCALE
    }

    /// Packet by packet: a dense grid in world space interpolates a packet of rays with
    /// the points computed in its kernel ([`SdfGrid::trilinear8_rays`]); other grids and
    /// stencils go through [`GridField::field8`]. Every lane is its scalar value.
    #[inline]
    fn distances<const W: usize>(&self, block: &mut PointBlock<W>) {
        let packets = block.packets();
        for g in 0..W / PACKET {
            if packets & 1 << g == 0 {
                continue;
            }
            let v = match (block.kind, &self.placement, &*self.grid) {
                (BlockKind::Rays, None, GridStore::Dense(grid)) => {
                    grid.trilinear8_rays(&block.origin, &block.dir, &block.t, PACKET * g).map(|v| v as f64)
                }
                _ => self.field8(&block.packet_points(g)),
            };
            for (x, v) in block.out[PACKET * g..PACKET * (g + 1)].iter_mut().zip(v) {
                *x = v * GRID_STEP_SCALE;
            }
        }
    }

    /// Signed, not exact (the interpolation of exact samples is not itself a distance),
    /// in packets ([`Self::distances`] interpolates eight points in one 8-wide kernel).
    fn facts(&self) -> FieldFacts {
        FieldFacts { signed: true, exact: false, packets: true, refills_lanes: true }
    }

    /// Half a voxel for the normal (the interpolant is piecewise, so smaller steps see
    /// cell seams); one material.
    fn surface(&self, _p: DVec3, _eps: f64) -> SurfacePoint {
        let voxel = self.grid.voxel() as f64 * self.placement.map_or(1.0, |m| m.scale);
        SurfacePoint { normal_step: 0.5 * voxel, material: self.material }
    }
}

/// The grid's samples, shared or its own; its error measured on the interpolated surface.
impl FieldObject for GridField {
    fn storage(&self) -> Storage {
        let census = Census { triangles: 0, grid_samples: self.grid.stored_values(), accel_bytes: 0 };
        match &self.grid {
            // The store's own struct is part of the field's.
            Samples::Own(g) => Storage {
                heap_bytes: g.bytes_used() - std::mem::size_of::<GridStore>(),
                census,
                shared: None,
            },
            Samples::Shared(g) => Storage {
                heap_bytes: g.bytes_used(),
                census,
                shared: Some(Shared::of(g, g.bytes_used(), census)),
            },
        }
    }

    fn surface_distance(&self, p: DVec3, _size: f64) -> f64 {
        // Outside the box the field is undefined: measure from the nearest box point. In a
        // narrow band's empty bricks the field is a constant bound (no gradient): there the
        // projection gives up and this returns that bound, a lower bound, not an upper
        // one; hit points (where errors are measured) always lie in stored bricks.
        // A placed grid is measured in its own frame and scaled.
        let (p, scale) = match &self.placement {
            None => (p, 1.0),
            Some(m) => (m.to_local.transform_point3(p), m.scale),
        };
        let (lo, hi) = self.grid.bounds();
        let local_box = aabb(lo, hi);
        let outside = box_distance(&local_box, p);
        let q = p.clamp(lo.as_dvec3(), hi.as_dvec3());
        let f = |x: DVec3| self.grid.trilinear(x.as_vec3()) as f64;
        let h = 0.25 * self.grid.voxel() as f64;
        let size = (hi - lo).length() as f64;
        scale * (outside + distance_by_projection(&f, q, h, 1e-6 * size))
    }

    fn describe(&self, label: &str) -> String {
        let d = self.grid.dims();
        let storage = match &*self.grid {
            GridStore::Dense(_) => String::new(),
            GridStore::Band(b) => format!(
                ", narrow band of {} cells ({} of {} bricks stored)",
                b.band_cells,
                b.stored_bricks(),
                b.brick_count()
            ),
        };
        format!(
            "{}: grid {}x{}x{} samples{storage}, voxel {:.5}, ray marched",
            label,
            d.x,
            d.y,
            d.z,
            self.grid.voxel()
        )
    }
}

/// A grid clipping box is used only when its longest extent is below this fraction of
/// the object's (otherwise the object is gridded whole).
pub const VIEW_CLIP_FRACTION: f32 = 0.5;

/// The region of the scene the camera can see well enough to need a fine grid: the
/// bounding box of the camera's view frustum out to a far distance of twice the distance
/// from the eye to the farthest bounding-box corner of the other bounded objects (all
/// objects but `exclude` whose longest extent is below [`VIEW_CLIP_FRACTION`] times
/// `exclude`'s, so that two huge objects do not stretch each other's region), never
/// beyond the scene's `max_distance` (which is also used when there is no such object).
/// `None` when that distance is not positive and finite.
pub fn view_region(scene: &Scene, exclude: &Object) -> Option<Aabb> {
    let cam = &scene.camera;
    let extent = |b: &Aabb| (Vec3::from(b.max) - Vec3::from(b.min)).max_element();
    let own = exclude.bounds().map_or(f32::INFINITY, |b| extent(&b));
    let mut far = 0.0f32;
    let mut any = false;
    for o in scene.objects.iter().filter(|o| !std::ptr::eq(*o, exclude)) {
        if let Some(b) = o.bounds().filter(|b| extent(b) < VIEW_CLIP_FRACTION * own) {
            let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
            for c in 0..8 {
                let corner = Vec3::new(
                    if c & 1 == 0 { lo.x } else { hi.x },
                    if c & 2 == 0 { lo.y } else { hi.y },
                    if c & 4 == 0 { lo.z } else { hi.z },
                );
                far = far.max((corner - cam.position).length());
            }
            any = true;
        }
    }
    let max = scene.settings.max_distance;
    let far = if any { (2.0 * far).min(max) } else { max };
    if !(far > 0.0) || !far.is_finite() {
        return None;
    }
    let f = cam.forward.normalize();
    let r = f.cross(cam.up).try_normalize()?;
    let u = r.cross(f);
    let half_h = (0.5 * cam.fov_y_deg.to_radians()).tan();
    let half_w = half_h * cam.width as f32 / cam.height.max(1) as f32;
    let (mut lo, mut hi) = (cam.position, cam.position);
    for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        // Depth `far` along the axis; the corner rays reach a little farther.
        let p = cam.position + (f + r * (sx * half_w) + u * (sy * half_h)) * far;
        lo = lo.min(p);
        hi = hi.max(p);
    }
    Some(aabb(lo, hi))
}

/// An object gridded only inside a clipping box (the part of it the camera sees, see
/// [`view_region`]) and sphere traced through its analytic SDF everywhere else, so that a
/// huge object (a ground sphere, a large box) does not spend its samples where the
/// camera never looks, and the image stays right where it does (reflections, shadows).
pub struct ClippedGrid {
    grid: GridObject,
    inner: Aabb,
    outside: Box<dyn Geometry>,
}

impl ClippedGrid {
    /// `grid` covers part of the object whose whole analytic geometry is `outside` (its
    /// `bounds()` are the object's).
    pub fn new(grid: GridObject, outside: Box<dyn Geometry>) -> Self {
        let inner = grid.bounds().expect("a grid object is bounded");
        ClippedGrid { grid, inner, outside }
    }

    /// The gridded part.
    pub fn grid(&self) -> &GridObject {
        &self.grid
    }
}

impl Geometry for ClippedGrid {
    fn bounds(&self) -> Option<Aabb> {
        self.outside.bounds()
    }

    fn closest_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> Option<Hit> {
        let Some((t0, t1)) = ray.clip_to_box(&self.inner, t_min, t_max) else {
            return self.outside.closest_hit(ray, t_min, t_max, stats);
        };
        if t0 > t_min
            && let Some(h) = self.outside.closest_hit(ray, t_min, t0, stats)
        {
            return Some(h);
        }
        if let Some(h) = self.grid.closest_hit(ray, t0, t1, stats) {
            return Some(h);
        }
        if t1 < t_max { self.outside.closest_hit(ray, t1, t_max, stats) } else { None }
    }

    fn any_hit(&self, ray: &Ray, t_min: f32, t_max: f32, stats: &mut RayStats) -> bool {
        let Some((t0, t1)) = ray.clip_to_box(&self.inner, t_min, t_max) else {
            return self.outside.any_hit(ray, t_min, t_max, stats);
        };
        (t0 > t_min && self.outside.any_hit(ray, t_min, t0, stats))
            || self.grid.any_hit(ray, t0, t1, stats)
            || (t1 < t_max && self.outside.any_hit(ray, t1, t_max, stats))
    }

    fn bytes_used(&self) -> usize {
        std::mem::size_of::<Self>() + self.grid.bytes_used() + self.outside.bytes_used()
    }

    fn describe(&self) -> String {
        let (lo, hi) = (Vec3::from(self.inner.min), Vec3::from(self.inner.max));
        format!(
            "{}, clipped to the view region {lo:.3} .. {hi:.3}; sphere traced on its analytic SDF \
             outside it",
            self.grid.describe()
        )
    }

    fn census(&self) -> Census {
        self.grid.census() + self.outside.census()
    }

    fn surface_distance(&self, p: DVec3) -> f64 {
        if box_distance(&self.inner, p) == 0.0 {
            self.grid.surface_distance(p)
        } else {
            self.outside.surface_distance(p)
        }
    }
}

/// [`GridStore::march_distance`] as a kernel: the scalar source compiled for the selected
/// backend (the same source, so the same bits; with AVX2 `floor` becomes one instruction
/// instead of a call to the C library).
struct MarchDistance<'a> {
    store: &'a GridStore,
    p: Vec3,
}

impl crate::simd::Kernel for MarchDistance<'_> {
    type Output = f32;
    #[inline(always)]
    fn run<S: crate::simd::Simd>(self, _: S) -> f32 {
        self.store.march_distance_portable(self.p)
    }
}
