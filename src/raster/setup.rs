//! Vertex projection, near-plane clipping, triangle setup and tile binning: the passes of
//! the rasterizer before the tiles ([`super::tile`]).
//!
//! Vertices go to homogeneous clip coordinates `(X, Y, w)`: `w` the view depth along the
//! camera's forward axis and `X / w + width / 2`, `Y / w + height / 2` the continuous pixel
//! coordinates, pixel (x, y)'s centre at (x + 0.5, y + 0.5), as the tracer's rays go
//! through pixel centres. The model and view transforms are composed in f64 and applied
//! once per vertex (an instance's vertices on their own), so every triangle sharing a
//! vertex sees the same coordinates.

use glam::{DAffine3, DMat3, Vec3};
use rayon::prelude::*;

use super::{Projection, RasterMesh, TILE};

/// Triangle setup chunk size floor: chunks are set up and binned in parallel.
const MIN_CHUNK: usize = 16_384;
/// Most chunks (a visibility id holds the chunk in its top 8 bits).
const MAX_CHUNKS: usize = 255;

/// One edge function of a triangle, in canonical vertex order: `sign * (dx (py - ay) -
/// dy (px - ax))`, positive inside the triangle.
#[derive(Clone, Copy, Debug, Default)]
pub struct Edge {
    /// The canonical first vertex (lexicographically smaller screen position).
    pub ax: f32,
    /// See `ax`.
    pub ay: f32,
    /// The edge vector from the first to the second canonical vertex.
    pub dx: f32,
    /// See `dx`.
    pub dy: f32,
    /// +1 or -1: the side of the edge the triangle lies on.
    pub sign: f32,
    /// Whether a pixel centre exactly on the edge belongs to this triangle (top-left rule).
    pub top_left: bool,
}

impl Edge {
    /// The edge function at (`px`, `py`): the scalar form of the tile kernel's lanes,
    /// the same operations in the same order.
    #[inline]
    pub fn at(&self, px: f32, py: f32) -> f32 {
        (self.dx * (py - self.ay) - self.dy * (px - self.ax)) * self.sign
    }
}

/// A triangle ready for the tiles.
#[derive(Clone, Copy, Debug)]
pub struct SetupTri {
    /// Edge `k` is the one opposite vertex `k`; its function over their sum is vertex
    /// `k`'s screen-space barycentric weight.
    pub edges: [Edge; 3],
    /// `1 / w` at the vertices.
    pub iw: [f32; 3],
    /// The largest `1 / w` (the nearest point): for early depth rejection.
    pub max_iw: f32,
    /// Pixels whose centres the triangle's box covers, inclusive: x0, y0, x1, y1.
    pub bbox: [u32; 4],
    /// Mesh index.
    pub mesh: u32,
    /// Triangle index in the mesh.
    pub tri: u32,
    /// For a piece of a clipped triangle, the index of its vertices' barycentric weights in
    /// the original triangle ([`Chunk::clip`]); `u32::MAX` otherwise.
    pub clip: u32,
}

/// A chunk of triangles set up and binned together.
#[derive(Debug, Default)]
pub struct Chunk {
    /// The set-up triangles, in input order.
    pub tris: Vec<SetupTri>,
    /// Per clipped piece, the barycentric weights (original triangle) of its vertices.
    pub clip: Vec<[[f32; 3]; 3]>,
    /// `bins[starts[t]..starts[t + 1]]`: the triangles (indices into `tris`) touching tile `t`.
    pub starts: Vec<u32>,
    /// See `starts`.
    pub bins: Vec<u32>,
}

impl Chunk {
    /// The triangles binned to tile `t`, in order.
    #[inline]
    pub fn bin(&self, t: usize) -> &[u32] {
        &self.bins[self.starts[t] as usize..self.starts[t + 1] as usize]
    }
}

/// The set-up frame: chunks in order.
#[derive(Debug, Default)]
pub struct Frame {
    /// The chunks, in input order.
    pub chunks: Vec<Chunk>,
    /// Triangles clipped at the near plane.
    pub clipped: u64,
}

/// The visibility id of triangle `i` of chunk `c`.
#[inline]
pub fn pack(c: usize, i: u32) -> u32 {
    ((c as u32) << 24) | i
}

/// Chunk and index of a visibility id.
#[inline]
pub fn unpack(id: u32) -> (usize, usize) {
    ((id >> 24) as usize, (id & 0x00ff_ffff) as usize)
}

/// A clip-space vertex with its barycentric weights in the original triangle.
#[derive(Clone, Copy, Debug)]
struct ClipVertex {
    p: Vec3,
    b: [f32; 3],
    /// Mesh vertex index (for the canonical order of clipping an edge); `u32::MAX` for a
    /// vertex made by clipping.
    id: u32,
}

/// The camera-from-mesh transform in f64: rows scaled so that `(X, Y, w)` come out.
fn view_of(proj: &Projection, m: &RasterMesh) -> DAffine3 {
    let kx = proj.width as f64 / (2.0 * proj.half_w as f64);
    let ky = proj.height as f64 / (2.0 * proj.half_h as f64);
    let (r, u, f) = (proj.right.as_dvec3() * kx, -proj.up.as_dvec3() * ky, proj.forward.as_dvec3());
    let view = DMat3::from_cols(r, u, f).transpose();
    let a = m.to_world;
    let lin = DMat3::from_cols(
        Vec3::from(a.matrix3.x_axis).as_dvec3(),
        Vec3::from(a.matrix3.y_axis).as_dvec3(),
        Vec3::from(a.matrix3.z_axis).as_dvec3(),
    );
    let t = Vec3::from(a.translation).as_dvec3() - proj.origin.as_dvec3();
    DAffine3::from_mat3_translation(view * lin, view * t)
}

/// Sets up every triangle of `meshes` and bins it into the tiles.
pub fn setup(proj: &Projection, meshes: &[RasterMesh]) -> Frame {
    // Vertices to clip space, per mesh.
    let clip: Vec<Vec<Vec3>> = meshes
        .iter()
        .map(|m| {
            let v = view_of(proj, m);
            let f = |p: &Vec3| v.transform_point3(p.as_dvec3()).as_vec3();
            if m.positions.len() > 65_536 {
                m.positions.par_iter().map(f).collect()
            } else {
                m.positions.iter().map(f).collect()
            }
        })
        .collect();
    let far = clip.iter().flat_map(|c| c.iter()).fold(0.0f32, |a, p| a.max(p.z));
    if !(far > 0.0) {
        return Frame::default();
    }
    // The near plane: close enough to the eye to cut nothing a tracer would see in front
    // of the scene, far enough for `1 / w` to stay finite.
    let near = (far * 1e-6).max(f32::MIN_POSITIVE * 16.0);
    let mut starts = Vec::with_capacity(meshes.len() + 1);
    let mut total = 0usize;
    for m in meshes {
        starts.push(total);
        total += m.triangles.len();
    }
    starts.push(total);
    let size = MIN_CHUNK.max(total.div_ceil(MAX_CHUNKS));
    assert!(size < 1 << 23, "too many triangles to rasterize in one frame");
    let tiles_x = proj.width.div_ceil(TILE);
    let tiles = (tiles_x * proj.height.div_ceil(TILE)) as usize;
    let chunks: Vec<Chunk> = (0..total.div_ceil(size))
        .into_par_iter()
        .map(|c| {
            let (lo, hi) = (c * size, ((c + 1) * size).min(total));
            let mut chunk = Chunk::default();
            let mut mesh = starts.partition_point(|&s| s <= lo) - 1;
            for g in lo..hi {
                while g >= starts[mesh + 1] {
                    mesh += 1;
                }
                let tri = (g - starts[mesh]) as u32;
                let idx = meshes[mesh].triangles[tri as usize];
                let v = idx.map(|i| clip[mesh][i as usize]);
                setup_triangle(proj, near, mesh as u32, tri, idx, v, &mut chunk);
            }
            bin(&mut chunk, tiles, tiles_x);
            chunk
        })
        .collect();
    let clipped = chunks.iter().map(|c| c.clip.len() as u64).sum();
    Frame { chunks, clipped }
}

/// Sets up triangle `tri` of mesh `mesh` (vertex indices `idx`, clip-space vertices `v`)
/// into `chunk`: as it is when in front of the near plane, else clipped into one or two
/// pieces.
fn setup_triangle(
    proj: &Projection,
    near: f32,
    mesh: u32,
    tri: u32,
    idx: [u32; 3],
    v: [Vec3; 3],
    chunk: &mut Chunk,
) {
    let inside = v.map(|p| p.z >= near);
    if inside.iter().all(|&i| i) {
        if let Some(t) = triangle(proj, v, mesh, tri, u32::MAX) {
            chunk.tris.push(t);
        }
        return;
    }
    if !inside.iter().any(|&i| i) {
        return;
    }
    // Sutherland-Hodgman against w >= near, in homogeneous coordinates; an edge is cut in
    // the order of its vertices' indices, so the neighbour sharing it gets the same point.
    let unit = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let cv: [ClipVertex; 3] = std::array::from_fn(|k| ClipVertex { p: v[k], b: unit[k], id: idx[k] });
    let mut poly = [cv[0]; 4];
    let mut n = 0;
    for k in 0..3 {
        let (a, b) = (cv[k], cv[(k + 1) % 3]);
        if inside[k] {
            poly[n] = a;
            n += 1;
        }
        if inside[k] != inside[(k + 1) % 3] {
            let (p, q) = if a.id < b.id { (a, b) } else { (b, a) };
            let s = (p.p.z - near) / (p.p.z - q.p.z);
            let mut x = p.p + (q.p - p.p) * s;
            x.z = near;
            let bw = std::array::from_fn(|i| p.b[i] + (q.b[i] - p.b[i]) * s);
            poly[n] = ClipVertex { p: x, b: bw, id: u32::MAX };
            n += 1;
        }
    }
    for k in 1..n - 1 {
        let piece = [poly[0], poly[k], poly[k + 1]];
        let index = chunk.clip.len() as u32;
        if let Some(t) = triangle(proj, piece.map(|c| c.p), mesh, tri, index) {
            chunk.tris.push(t);
            chunk.clip.push(piece.map(|c| c.b));
        }
    }
}

/// The set-up triangle of clip-space vertices `v` (all in front of the near plane), or
/// `None` when it covers no pixel centre of the image or is degenerate.
fn triangle(proj: &Projection, v: [Vec3; 3], mesh: u32, tri: u32, clip: u32) -> Option<SetupTri> {
    let (hw, hh) = (proj.width as f32 * 0.5, proj.height as f32 * 0.5);
    let iw = v.map(|p| 1.0 / p.z);
    let s = std::array::from_fn::<[f32; 2], 3, _>(|k| [v[k].x * iw[k] + hw, v[k].y * iw[k] + hh]);
    let (min_x, max_x) = (s[0][0].min(s[1][0]).min(s[2][0]), s[0][0].max(s[1][0]).max(s[2][0]));
    let (min_y, max_y) = (s[0][1].min(s[1][1]).min(s[2][1]), s[0][1].max(s[1][1]).max(s[2][1]));
    // Pixel centres x + 0.5 within [min, max]; the image bounds the box (the side planes).
    let x0 = (min_x - 0.5).ceil().max(0.0);
    let x1 = (max_x - 0.5).floor().min(proj.width as f32 - 1.0);
    let y0 = (min_y - 0.5).ceil().max(0.0);
    let y1 = (max_y - 0.5).floor().min(proj.height as f32 - 1.0);
    if !(x0 <= x1 && y0 <= y1) {
        return None;
    }
    let mut edges = [Edge::default(); 3];
    for (k, e) in edges.iter_mut().enumerate() {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        let (a, b) = if (s[i][0], s[i][1]) <= (s[j][0], s[j][1]) { (s[i], s[j]) } else { (s[j], s[i]) };
        *e = Edge { ax: a[0], ay: a[1], dx: b[0] - a[0], dy: b[1] - a[1], sign: 1.0, top_left: false };
        let side = e.at(s[k][0], s[k][1]);
        if !(side != 0.0) {
            return None;
        }
        e.sign = if side > 0.0 { 1.0 } else { -1.0 };
        // The inward normal (the function's gradient): a left edge has the inside to its
        // right (+x), a top edge (horizontal) has it below (+y, image y grows downwards).
        let (nx, ny) = (-e.dy * e.sign, e.dx * e.sign);
        e.top_left = nx > 0.0 || (nx == 0.0 && ny > 0.0);
    }
    Some(SetupTri {
        edges,
        iw,
        max_iw: iw[0].max(iw[1]).max(iw[2]),
        bbox: [x0 as u32, y0 as u32, x1 as u32, y1 as u32],
        mesh,
        tri,
        clip,
    })
}

/// Bins the chunk's triangles into the tiles their pixel boxes touch (counting sort: the
/// bins keep the triangles' order).
fn bin(chunk: &mut Chunk, tiles: usize, tiles_x: u32) {
    let mut starts = vec![0u32; tiles + 1];
    let range = |t: &SetupTri| {
        let [x0, y0, x1, y1] = t.bbox;
        (x0 / TILE, y0 / TILE, x1 / TILE, y1 / TILE)
    };
    for t in &chunk.tris {
        let (tx0, ty0, tx1, ty1) = range(t);
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                starts[(ty * tiles_x + tx) as usize + 1] += 1;
            }
        }
    }
    for i in 0..tiles {
        starts[i + 1] += starts[i];
    }
    let mut fill = starts.clone();
    let mut bins = vec![0u32; starts[tiles] as usize];
    for (i, t) in chunk.tris.iter().enumerate() {
        let (tx0, ty0, tx1, ty1) = range(t);
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                let at = &mut fill[(ty * tiles_x + tx) as usize];
                bins[*at as usize] = i as u32;
                *at += 1;
            }
        }
    }
    chunk.starts = starts;
    chunk.bins = bins;
}
