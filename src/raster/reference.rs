//! The rasterizer's oracle: every triangle against every pixel centre, one at a time, with
//! the scalar edge functions ([`Edge::at`]) and the same depth arithmetic as the tile
//! kernel, and no tiles, bins, lanes or early rejection. The tests hold the fast path to
//! it, pixel for pixel, and count with it how many triangles cover each pixel.

use super::setup::{Edge, SetupTri, setup};
use super::{Projection, RasterMesh};
use crate::scene::Camera;

/// Whether pixel centre (`px`, `py`) lies in `t` (top-left rule on its edges).
#[inline]
fn covers(t: &SetupTri, px: f32, py: f32) -> Option<[f32; 3]> {
    let f = t.edges.map(|e: Edge| e.at(px, py));
    let inside = |k: usize| f[k] > 0.0 || (f[k] == 0.0 && t.edges[k].top_left);
    (inside(0) && inside(1) && inside(2)).then_some(f)
}

/// Per pixel (row-major), how many set-up triangles of `meshes` cover its centre,
/// whatever their depth: 1 everywhere on a surface that tiles the view, 2 inside the
/// silhouette of a closed convex mesh (its front and back); never a gap or an overlap
/// along a shared edge.
pub fn coverage_counts(cam: &Camera, meshes: &[RasterMesh]) -> Vec<u32> {
    let proj = Projection::new(cam);
    let frame = setup(&proj, meshes);
    let mut counts = vec![0u32; (proj.width * proj.height) as usize];
    for t in frame.chunks.iter().flat_map(|c| c.tris.iter()) {
        let [x0, y0, x1, y1] = t.bbox;
        for y in y0..=y1 {
            for x in x0..=x1 {
                if covers(t, x as f32 + 0.5, y as f32 + 0.5).is_some() {
                    counts[(y * proj.width + x) as usize] += 1;
                }
            }
        }
    }
    counts
}

/// Per pixel (row-major), the (mesh, triangle) whose interpolated `1 / w` is largest (the
/// first in input order on a tie), by brute force: what [`super::rasterize`] must give.
pub fn nearest_triangles(cam: &Camera, meshes: &[RasterMesh]) -> Vec<Option<(u32, u32)>> {
    let proj = Projection::new(cam);
    let frame = setup(&proj, meshes);
    let n = (proj.width * proj.height) as usize;
    let mut best = vec![(0.0f32, None); n];
    for t in frame.chunks.iter().flat_map(|c| c.tris.iter()) {
        let [x0, y0, x1, y1] = t.bbox;
        for y in y0..=y1 {
            for x in x0..=x1 {
                if let Some(f) = covers(t, x as f32 + 0.5, y as f32 + 0.5) {
                    let depth = (f[0] * t.iw[0] + f[1] * t.iw[1] + f[2] * t.iw[2]) / (f[0] + f[1] + f[2]);
                    let b = &mut best[(y * proj.width + x) as usize];
                    if b.0 < depth {
                        *b = (depth, Some((t.mesh, t.tri)));
                    }
                }
            }
        }
    }
    best.into_iter().map(|b| b.1).collect()
}
