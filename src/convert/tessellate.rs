//! Parametric tessellation of the closed-form primitives into triangle meshes.
//!
//! [`tessellate`] turns a [`Primitive`] (in its local frame) into a [`TriangleMesh`] whose
//! vertices all lie on the exact surface (the mesh is inscribed), at a `resolution` given
//! as the number of segments around the primitive's largest circle, so the distance from
//! the mesh to the surface shrinks as `O(1 / resolution^2)`. Every solid's mesh is closed
//! (each edge is shared by exactly two triangles using it in opposite directions),
//! oriented outwards (`(b - a) x (c - a)` points out of the solid), has no two vertices at
//! bit-identical positions and no degenerate triangle (see [`crate::mesh::is_degenerate`]).
//!
//! How each primitive is tessellated:
//! - **sphere, ellipsoid**: a geodesic icosphere: each face of the icosahedron is split
//!   into `f^2` triangles, with `f` the smallest frequency whose edge arcs are at most
//!   `2 pi / resolution`; points are placed by sine-weighted (slerp-like) barycentric
//!   coordinates, so edges along the icosahedron's edges are equal arcs. Measured max
//!   distance to the unit sphere times the triangle count is about 5.3 (the ideal for
//!   equilateral triangles is 4.8), against 7.4 for an equal-angle cube sphere and 9.8 for
//!   a UV sphere, whose rings crowd at the poles; it also has no poles (no fan of slivers).
//!   The ellipsoid is the same sphere scaled per axis.
//! - **box**: its 8 corners and 12 triangles (`resolution` is ignored).
//! - **cylinder, cone**: a surface of revolution of the profile (cap, side, cap); an apex
//!   (radius 0) is a single vertex. Caps are flat discs of concentric rings whose vertex
//!   counts fall in proportion to their radius (exact, since the cap is flat), ending in a
//!   small fan around a centre vertex; the side is split into rings along its rulings.
//! - **torus**: a grid of `resolution` segments around the y axis by `resolution *
//!   sqrt(minor / (major + minor))` around the tube, which balances the two directions'
//!   errors (their curvatures are `1 / (major + minor)` and `1 / minor` at the outer
//!   equator). A spindle torus (`minor >= major`) is its outer surface: the tube's arc
//!   between the two points where it meets the axis, closed by a vertex at each.
//! - **capsule**: two hemispheres of latitude rings (vertex counts falling towards the
//!   poles so that triangles keep their size) joined by a ruled cylinder.
//! - **triangle**: its single triangle (open, two-sided).
//! - **plane**: a quad (two triangles, open) covering the `clip` box's projection onto
//!   the plane, grown by a relative margin of `1e-4`.
//!
//! Flat and ruled regions (caps, cylinder and cone sides, the capsule's body) carry no
//! geometric error, so how they are split is a matter of triangle shape only, and long
//! slivers cost a BVH dearly: measured with [`crate::geometry::mesh::MeshGeometry`] on a
//! unit cylinder at resolution 1024 tilted by (30, 45, 0) degrees, fan caps and one side band (4096 triangles) cost
//! 160-340 triangle tests per ray, against 4-5 when no triangle there is longer than 4
//! ring segments (252k triangles) and 3.3 for the icosphere (655k). [`tessellate`]
//! therefore splits those regions so that their triangles are at most
//! [`DEFAULT_MAX_ASPECT`] ring segments long (and a side into at most `resolution` bands,
//! so that a needle does not become millions of rings); [`tessellate_with`] takes the
//! bound, and `f32::INFINITY` gives the minimal mesh (one side band, fan caps).
//!
//! Normals: smooth primitives (sphere, ellipsoid, torus, capsule) get per-vertex normals
//! from the exact surface normal. Primitives with sharp edges (box, cylinder, cone) get
//! `normals: None` (flat shading): a vertex on a sharp edge has no single normal, and the
//! mesh invariants allow neither partial normals nor, here, duplicated positions. A
//! spindle torus's axis vertices get `±y`. The triangle and the plane are flat and get
//! none either.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use glam::{DVec2, DVec3, Vec3};

use crate::geometry::{Aabb, max_abs};
use crate::mesh::TriangleMesh;
use crate::scene::shape::{Object, ObjectKind, Primitive};

/// The smallest resolution; smaller requests are raised to it.
pub const MIN_RESOLUTION: u32 = 3;

/// The aspect bound [`tessellate`] uses for flat and ruled regions: no triangle there is
/// longer than this many times the longest segment of its ring (see the module docs).
pub const DEFAULT_MAX_ASPECT: f32 = 4.0;

/// Tessellates `prim` (local frame) at `resolution` (segments around the largest circle /
/// along the longest edge; values below [`MIN_RESOLUTION`] are raised to it).
///
/// Returns a closed (every edge shared by exactly two triangles with opposite
/// orientation), consistently outward-oriented (CCW seen from outside, so `(b-a)x(c-a)`
/// points out), watertight mesh without duplicate vertices and without degenerate
/// triangles, with per-vertex normals from the exact surface normal where the surface is
/// smooth (see the module docs for which primitives get normals).
///
/// The triangle primitive gives its single triangle (open; two-sided). The plane needs
/// `clip`: the finite quad of the plane covering `clip` (a box the camera sees, in the
/// primitive's frame), as two triangles (open); without `clip`, or with an empty or
/// non-finite one, the plane gives an empty mesh. Other primitives ignore `clip`.
///
/// # Panics
/// When the mesh would have more than `u32::MAX` vertices (resolutions far beyond what
/// fits in memory).
pub fn tessellate(prim: &Primitive, resolution: u32, clip: Option<&Aabb>) -> TriangleMesh {
    tessellate_with(prim, resolution, DEFAULT_MAX_ASPECT, clip)
}

/// [`tessellate`] with an explicit aspect bound for flat and ruled regions (raised to at
/// least 1; `f32::INFINITY` gives one band per cylinder or cone side and fan caps).
pub fn tessellate_with(
    prim: &Primitive,
    resolution: u32,
    max_aspect: f32,
    clip: Option<&Aabb>,
) -> TriangleMesh {
    let n = resolution.max(MIN_RESOLUTION);
    let aspect = if max_aspect >= 1.0 { max_aspect as f64 } else { 1.0 };
    match *prim {
        Primitive::Sphere { radius } => ellipsoid(DVec3::splat(radius as f64), n),
        Primitive::Ellipsoid { radii } => ellipsoid(radii.as_dvec3(), n),
        Primitive::Box { half } => box_mesh(half),
        Primitive::Cylinder { radius, half_height } => {
            cone(radius as f64, radius as f64, half_height as f64, n, aspect)
        }
        Primitive::Cone { radius_bottom, radius_top, half_height } => {
            cone(radius_bottom as f64, radius_top as f64, half_height as f64, n, aspect)
        }
        Primitive::Torus { major, minor } => torus(major as f64, minor as f64, n),
        Primitive::Capsule { a, b, radius } => capsule(a.as_dvec3(), b.as_dvec3(), radius as f64, n, aspect),
        Primitive::Triangle { a, b, c } => {
            TriangleMesh { positions: vec![a, b, c], triangles: vec![[0, 1, 2]], normals: None }
        }
        Primitive::Plane { normal, offset } => match clip {
            Some(clip) => plane_quad(normal, offset, clip),
            None => TriangleMesh::default(),
        },
    }
}

/// The tessellation of an [`ObjectKind::Primitive`] object (see [`tessellate`]) in its
/// parent's frame: positions through `object.compiled_transform().to_world`, normals
/// through its `normal_to_world` (winding reversed if the transform mirrors, which
/// positive scales never do). `clip` is in the parent's frame too.
///
/// `None` for CSG, repetition and mesh objects (they need SDF-to-mesh extraction), and for
/// a plane without a usable `clip`.
pub fn tessellate_object(object: &Object, resolution: u32, clip: Option<&Aabb>) -> Option<TriangleMesh> {
    tessellate_object_with(object, resolution, DEFAULT_MAX_ASPECT, clip)
}

/// [`tessellate_object`] with an explicit aspect bound (see [`tessellate_with`]).
pub fn tessellate_object_with(
    object: &Object,
    resolution: u32,
    max_aspect: f32,
    clip: Option<&Aabb>,
) -> Option<TriangleMesh> {
    let ObjectKind::Primitive(prim) = &object.kind else {
        return None;
    };
    let t = object.compiled_transform();
    if t.identity {
        return Some(tessellate_with(prim, resolution, max_aspect, clip)).filter(|m| !m.triangles.is_empty());
    }
    // The local box around the parent-frame box's corners.
    let local_clip = clip.map(|c| t.box_to_local(c));
    let mut mesh = tessellate_with(prim, resolution, max_aspect, local_clip.as_ref());
    if mesh.triangles.is_empty() {
        return None;
    }
    for p in &mut mesh.positions {
        *p = t.to_world.transform_point3(*p);
    }
    if let Some(normals) = &mut mesh.normals {
        for n in normals {
            *n = t.normal_to_world(*n);
        }
    }
    if t.to_world.matrix3.determinant() < 0.0 {
        for tri in &mut mesh.triangles {
            tri.swap(1, 2);
        }
    }
    Some(mesh)
}

/// A mesh under construction, in f64.
#[derive(Default)]
struct Builder {
    positions: Vec<DVec3>,
    normals: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
}

impl Builder {
    fn with_capacity(vertices: usize, triangles: usize) -> Self {
        assert!(
            vertices <= u32::MAX as usize,
            "tessellation would have {vertices} vertices, more than u32 indices can address"
        );
        Builder {
            positions: Vec::with_capacity(vertices),
            normals: Vec::with_capacity(vertices),
            triangles: Vec::with_capacity(triangles),
        }
    }

    fn push(&mut self, p: DVec3, n: DVec3) -> u32 {
        let i = self.positions.len();
        assert!(i < u32::MAX as usize, "tessellation has more vertices than u32 indices can address");
        self.positions.push(p);
        self.normals.push(n);
        i as u32
    }

    /// The f32 mesh, with the normals when `smooth`.
    fn finish(self, smooth: bool) -> TriangleMesh {
        TriangleMesh {
            positions: self.positions.iter().map(|p| p.as_vec3()).collect(),
            triangles: self.triangles,
            normals: smooth.then(|| self.normals.iter().map(|n| n.normalize().as_vec3()).collect()),
        }
    }
}

// ---------------------------------------------------------------------------------------
// Surfaces of revolution.

/// A point of a profile curve in the half-plane `rho >= 0` of a surface of revolution:
/// `rho` from the axis, `h` along it, `normal` the outward unit normal as (rho, h)
/// components, `count` the vertices of its ring (unused when `rho == 0`: a pole, one
/// vertex on the axis).
#[derive(Clone, Copy, Debug)]
struct ProfilePoint {
    rho: f64,
    h: f64,
    normal: DVec2,
    count: u32,
}

impl ProfilePoint {
    fn new(rho: f64, h: f64, normal: DVec2, count: u32) -> Self {
        ProfilePoint { rho, h, normal, count: count.max(3) }
    }

    fn is_pole(&self) -> bool {
        self.rho == 0.0
    }
}

/// An orthonormal frame for a surface of revolution, with `e1 x axis = e2` (as x, y, z).
struct Frame {
    origin: DVec3,
    axis: DVec3,
    e1: DVec3,
    e2: DVec3,
}

impl Frame {
    const Y: Frame = Frame { origin: DVec3::ZERO, axis: DVec3::Y, e1: DVec3::X, e2: DVec3::Z };

    /// A frame around unit `axis` through `origin`.
    fn along(origin: DVec3, axis: DVec3) -> Frame {
        let e1 = axis.any_orthonormal_vector();
        Frame { origin, axis, e1, e2: e1.cross(axis) }
    }
}

/// Revolves `profile` about `frame.axis`. The profile runs counter-clockwise around the
/// solid's cross-section in the (rho, h) half-plane (from the bottom pole outwards, up,
/// and back in), so the triangles face outwards. A `closed` profile also joins its last
/// point to its first. Ring vertex `j` of `count` lies at angle `2 pi j / count` from
/// `e1` towards `e2`. Consecutive points must differ; poles may only end an open profile,
/// and two end poles at the same place share one vertex.
fn revolve(b: &mut Builder, frame: &Frame, profile: &[ProfilePoint], closed: bool) {
    let last = profile.len() - 1;
    let shared_pole = !closed
        && last > 1
        && profile[0].is_pole()
        && profile[last].is_pole()
        && profile[0].h == profile[last].h;
    let mut first = Vec::with_capacity(profile.len());
    for (i, p) in profile.iter().enumerate() {
        if shared_pole && i == last {
            first.push(first[0]);
            continue;
        }
        let centre = frame.origin + frame.axis * p.h;
        if p.is_pole() {
            first.push(b.push(centre, frame.axis * p.normal.y));
            continue;
        }
        first.push(b.positions.len() as u32);
        for j in 0..p.count {
            let (s, c) = (TAU * j as f64 / p.count as f64).sin_cos();
            let radial = frame.e1 * c + frame.e2 * s;
            b.push(centre + radial * p.rho, radial * p.normal.x + frame.axis * p.normal.y);
        }
    }
    let bands = if closed { profile.len() } else { last };
    for i in 0..bands {
        let k = (i + 1) % profile.len();
        let (p, q) = (&profile[i], &profile[k]);
        match (p.is_pole(), q.is_pole()) {
            (true, true) => {}
            (true, false) => {
                let n = q.count;
                for j in 0..n {
                    b.triangles.push([first[i], first[k] + j, first[k] + (j + 1) % n]);
                }
            }
            (false, true) => {
                let n = p.count;
                for j in 0..n {
                    b.triangles.push([first[i] + j, first[k], first[i] + (j + 1) % n]);
                }
            }
            (false, false) => zip_rings(b, (first[i], p.count), (first[k], q.count)),
        }
    }
}

/// Triangulates the band between ring `lo` (earlier in the profile) and ring `hi`, each
/// `(first index, count)`, by merging their vertices in angle order; rings with equal
/// counts give quads split along the same diagonal.
fn zip_rings(b: &mut Builder, lo: (u32, u32), hi: (u32, u32)) {
    let (ma, mb) = (lo.1 as u64, hi.1 as u64);
    let a = |j: u64| lo.0 + (j % ma) as u32;
    let c = |k: u64| hi.0 + (k % mb) as u32;
    let (mut j, mut k) = (0u64, 0u64);
    while j < ma || k < mb {
        // Advance the ring whose next vertex comes first: angle (j+1)/ma vs (k+1)/mb.
        if k == mb || (j < ma && (j + 1) * mb <= (k + 1) * ma) {
            b.triangles.push([a(j), c(k), a(j + 1)]);
            j += 1;
        } else {
            b.triangles.push([a(j), c(k), c(k + 1)]);
            k += 1;
        }
    }
}

/// Number of equal bands of at most `spacing` across `length`, from 1 to `max`.
fn bands(length: f64, spacing: f64, max: u32) -> u32 {
    let k = (length / spacing).ceil();
    if k >= 1.0 { k.min(max.max(1) as f64) as u32 } else { 1 }
}

/// Pushes the rings of a flat disc of `radius` at height `h` whose rim ring has
/// `rim_count` vertices, from the centre outwards (`outward`, starting with the centre
/// pole and ending with the rim ring) or inwards (starting after the rim ring, which the
/// caller pushed, and ending with the centre pole). Rings are `aspect` rim segments
/// apart at most, with vertex counts proportional to their radius.
fn disc(profile: &mut Vec<ProfilePoint>, radius: f64, h: f64, rim_count: u32, aspect: f64, outward: bool) {
    let normal = DVec2::new(0.0, if outward { -1.0 } else { 1.0 });
    let k = bands(radius, aspect * TAU * radius / rim_count as f64, rim_count);
    let ring = |i: u32| {
        let count = (rim_count as u64 * i as u64).div_ceil(k as u64) as u32;
        let rho = if i == k { radius } else { radius * i as f64 / k as f64 };
        ProfilePoint::new(rho, h, normal, count)
    };
    if outward {
        profile.push(ProfilePoint::new(0.0, h, normal, 0));
        profile.extend((1..=k).map(ring));
    } else {
        profile.extend((1..k).rev().map(ring));
        profile.push(ProfilePoint::new(0.0, h, normal, 0));
    }
}

/// Pushes the rings strictly between `from` and `to` (as (rho, h)) on the straight
/// profile segment joining them, at most `spacing` apart but at most `count` bands (so a
/// needle-thin side is not split into millions of rings), all with `count` vertices.
fn ruled(profile: &mut Vec<ProfilePoint>, from: DVec2, to: DVec2, spacing: f64, count: u32) {
    let k = bands((to - from).length(), spacing, count);
    let d = to - from;
    let normal = DVec2::new(d.y, -d.x).normalize();
    for i in 1..k {
        let p = from + d * (i as f64 / k as f64);
        profile.push(ProfilePoint::new(p.x, p.y, normal, count));
    }
}

/// Capped cone (or cylinder) around y: radius `r0` at `-h`, `r1` at `h`.
fn cone(r0: f64, r1: f64, h: f64, n: u32, aspect: f64) -> TriangleMesh {
    if !(r0 > 0.0 || r1 > 0.0) {
        return TriangleMesh::default();
    }
    let spacing = aspect * TAU * r0.max(r1) / n as f64;
    let mut profile = Vec::new();
    if r0 > 0.0 {
        disc(&mut profile, r0, -h, n, aspect, true);
    } else {
        profile.push(ProfilePoint::new(0.0, -h, DVec2::NEG_Y, 0));
    }
    let side = DVec2::new(2.0 * h, r0 - r1).normalize();
    ruled(&mut profile, DVec2::new(r0, -h), DVec2::new(r1, h), spacing, n);
    if r1 > 0.0 {
        profile.push(ProfilePoint::new(r1, h, side, n));
        disc(&mut profile, r1, h, n, aspect, false);
    } else {
        profile.push(ProfilePoint::new(0.0, h, DVec2::Y, 0));
    }
    let rings: usize = profile.iter().map(|p| if p.is_pole() { 1 } else { p.count as usize }).sum();
    let mut b = Builder::with_capacity(rings, 2 * rings);
    revolve(&mut b, &Frame::Y, &profile, false);
    b.finish(false)
}

/// Torus around y; a spindle torus (`minor >= major`) as its outer surface.
fn torus(major: f64, minor: f64, n: u32) -> TriangleMesh {
    let tube = ((n as f64 * (minor / (major + minor)).sqrt()).ceil() as u32).max(3);
    let profile: Vec<ProfilePoint> = if minor < major {
        (0..tube)
            .map(|i| {
                let (s, c) = (TAU * i as f64 / tube as f64).sin_cos();
                ProfilePoint::new(major + minor * c, minor * s, DVec2::new(c, s), n)
            })
            .collect()
    } else {
        // The tube circle meets the axis at angles +-v0 (from the outer equator); its
        // arc between them, through the outer equator, is the surface.
        let v0 = (-major / minor).acos();
        let apex = (minor * minor - major * major).sqrt();
        let steps = ((tube as f64 * v0 / PI).ceil() as u32).max(2);
        (0..=steps)
            .map(|i| {
                if i == 0 || i == steps {
                    let sign = if i == 0 { -1.0 } else { 1.0 };
                    return ProfilePoint::new(0.0, sign * apex, DVec2::new(0.0, sign), 0);
                }
                let (s, c) = (-v0 + 2.0 * v0 * i as f64 / steps as f64).sin_cos();
                ProfilePoint::new(major + minor * c, minor * s, DVec2::new(c, s), n)
            })
            .collect()
    };
    let vertices = profile.len() * n as usize;
    let mut b = Builder::with_capacity(vertices, 2 * vertices);
    revolve(&mut b, &Frame::Y, &profile, minor < major);
    b.finish(true)
}

/// Pushes a hemisphere's latitude rings around height `h`, from the pole at `-radius`
/// up to (and including) the equator (`lower`), or from just above the equator to the
/// pole at `+radius`. `n` segments on the equator, `q` latitude bands per quarter circle;
/// ring vertex counts fall with the ring radius so that segments keep their length.
fn hemisphere(profile: &mut Vec<ProfilePoint>, radius: f64, h: f64, n: u32, lower: bool) {
    let q = n.div_ceil(4);
    let point = |i: u32| {
        // Latitude i * 90 / q degrees, from the equator (i = 0) to the pole (i = q).
        if i == q {
            let sign = if lower { -1.0 } else { 1.0 };
            return ProfilePoint::new(0.0, h + sign * radius, DVec2::new(0.0, sign), 0);
        }
        let (s, c) = (FRAC_PI_2 * i as f64 / q as f64).sin_cos();
        let s = if lower { -s } else { s };
        let count = (n as f64 * c).ceil().min(n as f64) as u32;
        ProfilePoint::new(radius * c, h + radius * s, DVec2::new(c, s), count)
    };
    if lower {
        profile.extend((0..=q).rev().map(point));
    } else {
        profile.extend((1..=q).map(point));
    }
}

/// Capsule around the segment `a`..`b`.
fn capsule(a: DVec3, b: DVec3, radius: f64, n: u32, aspect: f64) -> TriangleMesh {
    let d = b - a;
    let len = d.length();
    let frame = if len > 0.0 { Frame::along(a, d / len) } else { Frame::Y };
    let frame = Frame { origin: a, ..frame };
    let mut profile = Vec::new();
    hemisphere(&mut profile, radius, 0.0, n, true);
    if len > 0.0 {
        ruled(
            &mut profile,
            DVec2::new(radius, 0.0),
            DVec2::new(radius, len),
            aspect * TAU * radius / n as f64,
            n,
        );
        profile.push(ProfilePoint::new(radius, len, DVec2::X, n));
    }
    hemisphere(&mut profile, radius, len, n, false);
    let rings: usize = profile.iter().map(|p| p.count as usize).sum();
    let mut builder = Builder::with_capacity(rings, 2 * rings);
    revolve(&mut builder, &frame, &profile, false);
    builder.finish(true)
}

// ---------------------------------------------------------------------------------------
// Sphere and ellipsoid.

/// The icosahedron's 12 unit corners and 20 faces (counter-clockwise from outside).
fn icosahedron() -> ([DVec3; 12], [[usize; 3]; 20]) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let corners = [
        DVec3::new(-1.0, t, 0.0),
        DVec3::new(1.0, t, 0.0),
        DVec3::new(-1.0, -t, 0.0),
        DVec3::new(1.0, -t, 0.0),
        DVec3::new(0.0, -1.0, t),
        DVec3::new(0.0, 1.0, t),
        DVec3::new(0.0, -1.0, -t),
        DVec3::new(0.0, 1.0, -t),
        DVec3::new(t, 0.0, -1.0),
        DVec3::new(t, 0.0, 1.0),
        DVec3::new(-t, 0.0, -1.0),
        DVec3::new(-t, 0.0, 1.0),
    ]
    .map(DVec3::normalize);
    let faces = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    (corners, faces)
}

/// A geodesic icosphere of unit directions (positions and normals both the direction)
/// with each icosahedron edge split into equal arcs of at most `2 pi / n`.
fn icosphere(n: u32) -> Builder {
    let (corners, faces) = icosahedron();
    let edge_arc = corners[0].angle_between(corners[11]);
    let f = ((n as f64 * edge_arc / TAU).ceil() as usize).max(1);
    let vertices = 10 * f * f + 2;
    let mut b = Builder::with_capacity(vertices, 20 * f * f);
    // The unit direction at barycentric (f - i - j, i, j) / f of triangle (p, q, r):
    // sine weights make the points on each edge a slerp (equal arcs).
    let point = |p: DVec3, q: DVec3, r: DVec3, i: usize, j: usize| {
        let w = |k: usize| (edge_arc * k as f64 / f as f64).sin();
        (p * w(f - i - j) + q * w(i) + r * w(j)).normalize()
    };
    for c in corners {
        b.push(c, c);
    }
    // Edge interiors: edge_start[u][v] (u < v) is the index of the point next to u.
    let mut edge_start = [[u32::MAX; 12]; 12];
    for face in &faces {
        for e in 0..3 {
            let (u, v) = (face[e].min(face[(e + 1) % 3]), face[e].max(face[(e + 1) % 3]));
            if edge_start[u][v] == u32::MAX {
                edge_start[u][v] = b.positions.len() as u32;
                for k in 1..f {
                    let d = point(corners[u], corners[v], corners[v], k, 0);
                    b.push(d, d);
                }
            }
        }
    }
    let on_edge = |u: usize, v: usize, k: usize| -> u32 {
        if u < v { edge_start[u][v] + (k - 1) as u32 } else { edge_start[v][u] + (f - k - 1) as u32 }
    };
    for face in &faces {
        let [p, q, r] = face.map(|i| corners[i]);
        // Interior points (i, j), i, j >= 1, i + j < f, row by row in j.
        let interior = b.positions.len();
        for j in 1..f {
            for i in 1..f - j {
                let d = point(p, q, r, i, j);
                b.push(d, d);
            }
        }
        let index = |i: usize, j: usize| -> u32 {
            match (i, j) {
                (0, 0) => face[0] as u32,
                _ if i == f => face[1] as u32,
                _ if j == f => face[2] as u32,
                (_, 0) => on_edge(face[0], face[1], i),
                (0, _) => on_edge(face[0], face[2], j),
                _ if i + j == f => on_edge(face[1], face[2], j),
                _ => {
                    let row = (j - 1) * (f - 1) - (j - 1) * j / 2;
                    (interior + row + i - 1) as u32
                }
            }
        };
        for j in 0..f {
            for i in 0..f - j {
                b.triangles.push([index(i, j), index(i + 1, j), index(i, j + 1)]);
                if i + j + 1 < f {
                    b.triangles.push([index(i + 1, j), index(i + 1, j + 1), index(i, j + 1)]);
                }
            }
        }
    }
    b
}

/// The axis-aligned ellipsoid with semi-axes `radii` (a sphere when they are equal).
fn ellipsoid(radii: DVec3, n: u32) -> TriangleMesh {
    let mut b = icosphere(n);
    for (p, normal) in b.positions.iter_mut().zip(&mut b.normals) {
        let d = *p;
        *p = d * radii;
        *normal = (d / radii).normalize();
    }
    b.finish(true)
}

// ---------------------------------------------------------------------------------------
// Box and plane.

/// The box's 8 corners and 12 triangles.
fn box_mesh(half: Vec3) -> TriangleMesh {
    // Corner i has +half on axis k when bit k of i is set.
    let positions = (0..8u32)
        .map(|i| Vec3::select(glam::BVec3::new(i & 1 != 0, i & 2 != 0, i & 4 != 0), half, -half))
        .collect();
    let mut triangles = Vec::with_capacity(12);
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [0u32, 1] {
            let corner = |du: u32, dv: u32| (side << axis) | (du << u) | (dv << v);
            // Counter-clockwise seen from +axis (u, v, axis are right-handed).
            let mut q = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
            if side == 0 {
                q.reverse();
            }
            triangles.push([q[0], q[1], q[2]]);
            triangles.push([q[0], q[2], q[3]]);
        }
    }
    TriangleMesh { positions, triangles, normals: None }
}

/// The quad of the plane `normal . p = offset` that covers `clip`'s projection onto it.
fn plane_quad(normal: Vec3, offset: f32, clip: &Aabb) -> TriangleMesh {
    let n = normal.as_dvec3().normalize();
    let (lo, hi) = (Vec3::from(clip.min).as_dvec3(), Vec3::from(clip.max).as_dvec3());
    if !(n.is_finite() && lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()) {
        return TriangleMesh::default();
    }
    // t1 x t2 = n, so (t1, t2) counter-clockwise is seen from above the plane.
    let t1 = n.any_orthonormal_vector();
    let t2 = n.cross(t1);
    let (mut u0, mut u1, mut v0, mut v1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for i in 0..8 {
        let c = DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        let (u, v) = (t1.dot(c), t2.dot(c));
        (u0, u1, v0, v1) = (u0.min(u), u1.max(u), v0.min(v), v1.max(v));
    }
    let margin = 1e-4 * (u1 - u0).max(v1 - v0);
    if !(margin > 0.0) {
        return TriangleMesh::default();
    }
    let (u0, u1, v0, v1) = (u0 - margin, u1 + margin, v0 - margin, v1 + margin);
    let origin = n * offset as f64;
    let corner = |u: f64, v: f64| (origin + t1 * u + t2 * v).as_vec3();
    TriangleMesh {
        positions: vec![corner(u0, v0), corner(u1, v0), corner(u1, v1), corner(u0, v1)],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        normals: None,
    }
}

/// The part of the plane `normal . p = offset` within `radius` of `eye`, as a disc of
/// rings around the eye's foot point whose radii grow geometrically (by 1.25), so the
/// triangles near the camera are small (precise hits in f32) and far ones large (few
/// triangles). Flat, so the rings lose nothing: the disc is exactly the plane out to its
/// polygonal rim, which circumscribes the circle of `radius`. Oriented with `normal` out.
pub fn plane_view_mesh(normal: Vec3, offset: f32, eye: Vec3, radius: f32) -> TriangleMesh {
    const SEGMENTS: u32 = 16;
    let n = normal.normalize();
    let height = n.dot(eye) - offset;
    let foot = eye - n * height;
    if !foot.is_finite() {
        // The plane lies beyond the f32 range seen from the eye: nothing to draw.
        return TriangleMesh::default();
    }
    // The rim stays within the f32 range (a `max_distance` near f32::MAX would put it at
    // infinity): no ray reaches farther from the eye than that anyway.
    let radius = radius.min(0.9 * (f32::MAX - max_abs(foot)));
    let (u, v) = n.any_orthonormal_pair();
    // u x v = n keeps the winding counter-clockwise seen from +n.
    let (u, v) = if u.cross(v).dot(n) > 0.0 { (u, v) } else { (v, u) };
    let mut positions = vec![foot];
    let mut triangles = Vec::new();
    let mut r = 0.25 * height.abs().max(1e-3);
    let mut ring = 0u32;
    loop {
        let last = r >= radius;
        let r_ring = r.min(radius) / (std::f32::consts::PI / SEGMENTS as f32).cos();
        for i in 0..SEGMENTS {
            let a = i as f32 * std::f32::consts::TAU / SEGMENTS as f32;
            positions.push(foot + (u * a.cos() + v * a.sin()) * r_ring);
        }
        let base = 1 + ring * SEGMENTS;
        for i in 0..SEGMENTS {
            let j = (i + 1) % SEGMENTS;
            if ring == 0 {
                triangles.push([0, base + i, base + j]);
            } else {
                let inner = base - SEGMENTS;
                triangles.push([inner + i, base + i, base + j]);
                triangles.push([inner + i, base + j, inner + j]);
            }
        }
        if last {
            break;
        }
        ring += 1;
        r *= 1.25;
    }
    TriangleMesh { positions, triangles, normals: None }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosahedron_faces_point_outwards_and_close() {
        let (corners, faces) = icosahedron();
        for f in faces {
            let [a, b, c] = f.map(|i| corners[i]);
            assert!((b - a).cross(c - a).dot(a + b + c) > 0.0, "face {f:?}");
        }
        for f in 1..6 {
            let m = icosphere(f * 6).finish(true);
            assert!(m.is_closed(), "frequency for resolution {}", f * 6);
            assert_eq!(m.positions.len() as u32 * 2 - 4, m.triangles.len() as u32);
        }
    }

    #[test]
    fn zipped_rings_and_poles_close() {
        // A pole, rings of 3, 7, 7, 5 and 12 vertices, a pole: every band kind.
        let mut profile = vec![ProfilePoint::new(0.0, -1.0, DVec2::NEG_Y, 0)];
        for (i, count) in [3, 7, 7, 5, 12].into_iter().enumerate() {
            profile.push(ProfilePoint::new(1.0, i as f64 * 0.5 - 0.9, DVec2::X, count));
        }
        profile.push(ProfilePoint::new(0.0, 2.0, DVec2::Y, 0));
        let mut b = Builder::default();
        revolve(&mut b, &Frame::Y, &profile, false);
        let m = b.finish(true);
        assert_eq!(m.positions.len(), 2 + 3 + 7 + 7 + 5 + 12);
        // Each band has as many triangles as its two rings have vertices together.
        assert_eq!(m.triangles.len(), 3 + 10 + 14 + 12 + 17 + 12);
        assert!(m.is_closed());
        let volume: f32 = m
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.positions[i as usize]);
                a.dot(b.cross(c))
            })
            .sum();
        assert!(volume > 0.0, "outward orientation");
    }

    #[test]
    fn band_counts() {
        assert_eq!(bands(1.0, f64::INFINITY, 9), 1);
        assert_eq!(bands(1.0, 0.3, 9), 4);
        assert_eq!(bands(1.0, 0.3, 3), 3);
        assert_eq!(bands(1.0, 1.0, 9), 1);
        assert_eq!(bands(0.0, 1.0, 9), 1);
        assert_eq!(bands(1.0, f64::NAN, 9), 1);
        assert_eq!(bands(1.0, 0.0, 0), 1);
        let mut p = Vec::new();
        disc(&mut p, 2.0, 0.5, 40, 2.0, true);
        assert!(p[0].is_pole());
        assert_eq!(p.last().unwrap().rho, 2.0);
        assert_eq!(p.last().unwrap().count, 40);
        assert!(p.windows(2).all(|w| w[0].rho < w[1].rho && w[0].count <= w[1].count));
        let mut q = vec![ProfilePoint::new(2.0, 0.5, DVec2::Y, 40)];
        disc(&mut q, 2.0, 0.5, 40, 2.0, false);
        assert_eq!(q.len(), p.len());
        assert!(q.last().unwrap().is_pole());
    }

    #[test]
    fn box_faces_point_outwards() {
        let m = box_mesh(Vec3::new(1.0, 2.0, 3.0));
        assert!(m.is_closed());
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let n = (b - a).cross(c - a);
            // The face normal points the way its centroid lies from the centre.
            assert!(n.dot(a + b + c) > 0.0);
            assert_eq!(n.normalize().abs().max_element(), 1.0);
        }
    }

    #[test]
    fn resolution_and_aspect_are_clamped() {
        let cyl = Primitive::Cylinder { radius: 1.0, half_height: 1.0 };
        let m = tessellate_with(&cyl, 0, f32::INFINITY, None);
        // 3 side segments, 2 fan caps of 3 with centre vertices.
        assert_eq!((m.positions.len(), m.triangles.len()), (8, 12));
        let m = tessellate_with(&cyl, 3, 0.0, None);
        assert_eq!(m, tessellate_with(&cyl, 3, 1.0, None));
        assert!(m.is_closed());
    }
}
