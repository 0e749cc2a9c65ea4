//! A software z-buffer rasterizer for triangle meshes, as real-time engines draw polygons
//! (issue #36): the primary visibility of a mesh scene without tracing a ray.
//!
//! The pipeline, in passes over the whole frame:
//! 1. **Vertices** ([`setup`]): every vertex of every mesh (each instance of an instanced
//!    mesh on its own) to homogeneous clip coordinates of the tracer's pinhole camera, the
//!    same pixel centres and projection as [`crate::scene::camera::RayGenerator`], so that
//!    the triangle a pixel's ray hits first is the one rasterized there.
//! 2. **Triangles** ([`setup`]): clipped against the near plane in homogeneous
//!    coordinates (Sutherland-Hodgman; the guard band of `f32` screen coordinates takes
//!    the side planes: a triangle is only rejected against them, by its pixel box), set
//!    up as three edge functions, and binned into 16 x 16 pixel tiles. In chunks, in
//!    parallel (rayon); a tile reads the chunks' bins in order, so the frame is
//!    deterministic.
//! 3. **Tiles** ([`tile`]): in parallel, each tile's triangles in order, edge functions
//!    of eight pixels at once in the lanes of the [`crate::simd`] backend, the top-left
//!    fill rule, a z-buffer of interpolated `1/w` (perspective-correct depth) and early
//!    rejection of a triangle whose nearest point lies behind everything the tile holds.
//! 4. **Visibility buffer**: per pixel the id of the winner; its mesh, triangle,
//!    perspective-correct barycentrics and depth are computed from the id on demand.
//!
//! Shared edges: each edge function is evaluated in one canonical vertex order (the
//! lexicographically smaller screen vertex first) with the same single-precision
//! operations in every triangle, so two triangles sharing an edge get exactly opposite
//! values at every pixel centre, and the top-left rule gives a pixel on the edge to
//! exactly one of them: no cracks and no double hits on a closed mesh.

pub mod reference;
pub mod setup;
pub mod tile;

use glam::{Affine3A, Vec3};
use rayon::prelude::*;

use crate::scene::Camera;
use crate::scene::camera::RayGenerator;
use crate::simd::{Kernel, Portable, dispatch};

/// Tile edge, pixels: tiles are binned and rasterized as units.
pub const TILE: u32 = 16;
/// Pixels per tile.
pub const TILE_PIXELS: usize = (TILE * TILE) as usize;

/// No mesh at a pixel of the [`VisBuffer`].
pub const NONE: u32 = u32::MAX;

/// One mesh (or one instance of a shared mesh) to rasterize: its vertices and triangles
/// in its own frame and the transform to the world.
#[derive(Clone, Copy, Debug)]
pub struct RasterMesh<'a> {
    /// Vertex positions, the mesh's frame.
    pub positions: &'a [Vec3],
    /// Triangles (indices into `positions`).
    pub triangles: &'a [[u32; 3]],
    /// From the mesh's frame to the world.
    pub to_world: Affine3A,
}

/// The camera as the rasterizer projects with it: the tracer's own basis and image plane
/// ([`RayGenerator`]: its fields), so that both see the same pixel centres.
pub type Projection = RayGenerator;

/// What a pixel sees: the winner of the depth test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Visible {
    /// Index of the mesh in the list given to [`rasterize`].
    pub mesh: u32,
    /// Index of the triangle in that mesh.
    pub triangle: u32,
    /// Perspective-correct barycentric weights of the triangle's vertices 0, 1, 2.
    pub bary: [f32; 3],
    /// View depth (distance along the viewing direction, scene units).
    pub depth: f32,
}

/// The visibility buffer: per pixel, the id of the nearest triangle, as visibility-buffer
/// renderers keep it (one 32-bit id per pixel), with the frame's set-up triangles that the
/// ids name, from which [`Self::at`] computes the mesh, triangle, perspective-correct
/// barycentrics and depth of a pixel on demand (the same single-precision operations as
/// the tiles' depth test). Stored tile by tile ([`TILE`] x [`TILE`] pixels, row-major
/// within the tile; tiles row-major), the order the tiles are rasterized in.
#[derive(Debug, Default)]
pub struct VisBuffer {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    tiles_x: u32,
    /// Visibility id per pixel ([`setup::pack`]), [`NONE`] for background.
    id: Vec<u32>,
    /// The set-up triangles the ids name.
    frame: setup::Frame,
}

impl VisBuffer {
    /// The index of pixel (`x`, `y`) in the tile-major arrays.
    #[inline]
    fn index(&self, x: u32, y: u32) -> usize {
        let tile = (y / TILE) * self.tiles_x + x / TILE;
        tile as usize * TILE_PIXELS + ((y % TILE) * TILE + x % TILE) as usize
    }

    /// The set-up triangle seen at pixel (`x`, `y`), and its chunk.
    #[inline]
    fn setup_at(&self, x: u32, y: u32) -> Option<(&setup::Chunk, &setup::SetupTri)> {
        let id = self.id[self.index(x, y)];
        (id != NONE).then(|| {
            let (c, i) = setup::unpack(id);
            let chunk = &self.frame.chunks[c];
            (chunk, &chunk.tris[i])
        })
    }

    /// The mesh and triangle pixel (`x`, `y`) sees, `None` for background.
    #[inline]
    pub fn triangle_at(&self, x: u32, y: u32) -> Option<(u32, u32)> {
        self.setup_at(x, y).map(|(_, t)| (t.mesh, t.tri))
    }

    /// What pixel (`x`, `y`) sees, `None` for background: the barycentrics (in the
    /// original triangle for a piece of a clipped one) and view depth computed from the
    /// set-up triangle at the pixel's centre.
    pub fn at(&self, x: u32, y: u32) -> Option<Visible> {
        let (chunk, t) = self.setup_at(x, y)?;
        let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
        let f: [f32; 3] = std::array::from_fn(|k| t.edges[k].at(px, py));
        let iw = (f[0] * t.iw[0] + f[1] * t.iw[1] + f[2] * t.iw[2]) / (f[0] + f[1] + f[2]);
        let w: [f32; 3] = std::array::from_fn(|k| f[k] * t.iw[k]);
        let sum = w[0] + w[1] + w[2];
        let mut b = w.map(|w| w / sum);
        if t.clip != u32::MAX {
            let v = &chunk.clip[t.clip as usize];
            b = std::array::from_fn(|j| b[0] * v[0][j] + b[1] * v[1][j] + b[2] * v[2][j]);
        }
        Some(Visible { mesh: t.mesh, triangle: t.tri, bary: b, depth: 1.0 / iw })
    }

    /// Pixels covered by some triangle.
    pub fn covered(&self) -> usize {
        (0..self.height)
            .flat_map(|y| (0..self.width).map(move |x| (x, y)))
            .filter(|&(x, y)| self.id[self.index(x, y)] != NONE)
            .count()
    }
}

/// Work counters of one rasterized frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RasterStats {
    /// Triangles given.
    pub triangles: u64,
    /// Triangles (after clipping, a clipped one may become two) that reached a tile.
    pub setup: u64,
    /// Triangles clipped at the near plane.
    pub clipped: u64,
    /// Triangle-tile pairs binned.
    pub binned: u64,
    /// Triangle-tile pairs skipped by early depth rejection.
    pub early_rejected: u64,
}

/// Rasterizes `meshes` seen by `cam` into a visibility buffer.
pub fn rasterize(cam: &Camera, meshes: &[RasterMesh]) -> (VisBuffer, RasterStats) {
    let mut vis = VisBuffer::default();
    let stats = rasterize_on(cam, meshes, &mut vis, false);
    (vis, stats)
}

/// [`rasterize`] into `vis`, whose arrays are reused (reallocated only when the image size
/// changes): every pixel of the image is written.
pub fn rasterize_into(cam: &Camera, meshes: &[RasterMesh], vis: &mut VisBuffer) -> RasterStats {
    rasterize_on(cam, meshes, vis, false)
}

/// [`rasterize_into`], on the portable backend where `portable` (the tests compare both).
fn rasterize_on(cam: &Camera, meshes: &[RasterMesh], vis: &mut VisBuffer, portable: bool) -> RasterStats {
    let proj = Projection::new(cam);
    let frame = setup::setup(&proj, meshes);
    let tiles_x = proj.width.div_ceil(TILE);
    let tiles_y = proj.height.div_ceil(TILE);
    let n = (tiles_x * tiles_y) as usize * TILE_PIXELS;
    if (vis.width, vis.height, vis.id.len()) != (proj.width, proj.height, n) {
        (vis.width, vis.height, vis.tiles_x) = (proj.width, proj.height, tiles_x);
        vis.id = vec![NONE; n];
    }
    vis.frame = frame;
    let frame = &vis.frame;
    let rejected: u64 = vis
        .id
        .par_chunks_mut(TILE_PIXELS)
        .enumerate()
        .map(|(t, out)| {
            let (tx, ty) = (t as u32 % tiles_x, t as u32 / tiles_x);
            let k = tile::TileKernel { frame, tile: t, x0: tx * TILE, y0: ty * TILE, proj: &proj, out };
            if portable { k.run(Portable) } else { dispatch(k) }
        })
        .sum();
    RasterStats {
        triangles: meshes.iter().map(|m| m.triangles.len() as u64).sum(),
        setup: frame.chunks.iter().map(|c| c.tris.len() as u64).sum(),
        clipped: frame.clipped,
        binned: frame.chunks.iter().map(|c| c.bins.len() as u64).sum(),
        early_rejected: rejected,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small xorshift generator (deterministic).
    struct Rng(u64);
    impl Rng {
        fn unit(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    fn soup(seed: u64, n: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut r = Rng(seed);
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for i in 0..n {
            let c = Vec3::new(r.unit() * 4.0 - 2.0, r.unit() * 4.0 - 2.0, r.unit() * 6.0 - 1.0);
            for _ in 0..3 {
                positions.push(c + Vec3::new(r.unit() - 0.5, r.unit() - 0.5, r.unit() - 0.5) * 1.5);
            }
            let k = 3 * i as u32;
            triangles.push([k, k + 1, k + 2]);
        }
        (positions, triangles)
    }

    /// Random triangle soups (some crossing the near plane, some behind the camera) on
    /// both backends against the brute-force oracle, pixel for pixel.
    #[test]
    fn tiles_match_the_brute_force_oracle_on_both_backends() {
        for seed in 1..6u64 {
            let (positions, triangles) = soup(seed * 7919, 300);
            let meshes =
                [RasterMesh { positions: &positions, triangles: &triangles, to_world: Affine3A::IDENTITY }];
            let cam = Camera {
                position: Vec3::new(0.0, 0.0, 0.5),
                width: 61 + seed as u32 * 13,
                height: 47 + seed as u32 * 5,
                ..Camera::default()
            };
            let want = reference::nearest_triangles(&cam, &meshes);
            // One buffer for every run: a reused buffer must hold no pixel of the last frame.
            let mut vis = VisBuffer::default();
            for portable in [false, true, false] {
                let stats = rasterize_on(&cam, &meshes, &mut vis, portable);
                assert!(stats.clipped > 0, "some triangles cross the near plane");
                let mut covered = 0;
                for y in 0..cam.height {
                    for x in 0..cam.width {
                        let got = vis.at(x, y).map(|v| (v.mesh, v.triangle));
                        assert_eq!(got, want[(y * cam.width + x) as usize], "seed {seed} pixel ({x}, {y})");
                        covered += got.is_some() as usize;
                    }
                }
                assert!(covered > 100, "{covered}");
            }
        }
    }

    /// The visibility buffer's depth and barycentrics give back the point on the triangle
    /// seen through the pixel's centre.
    #[test]
    fn depth_and_barycentrics_are_perspective_correct() {
        let positions = [Vec3::new(-3.0, -2.0, 2.0), Vec3::new(3.0, -1.0, 9.0), Vec3::new(0.0, 3.0, 4.0)];
        let triangles = [[0, 1, 2]];
        let meshes =
            [RasterMesh { positions: &positions, triangles: &triangles, to_world: Affine3A::IDENTITY }];
        let cam = Camera { width: 64, height: 48, ..Camera::default() };
        let (vis, _) = rasterize(&cam, &meshes);
        let rays = crate::scene::camera::RayGenerator::new(&cam);
        let proj = Projection::new(&cam);
        let mut n = 0;
        for y in 0..48 {
            for x in 0..64 {
                let Some(v) = vis.at(x, y) else { continue };
                let p = positions[0] * v.bary[0] + positions[1] * v.bary[1] + positions[2] * v.bary[2];
                let ray = rays.ray(x, y);
                let t = v.depth * proj.depth_to_distance(x, y);
                assert!((ray.at(t) - p).length() < 1e-4 * t, "({x}, {y}): {} vs {p}", ray.at(t));
                n += 1;
            }
        }
        assert!(n > 300, "{n}");
    }
}
