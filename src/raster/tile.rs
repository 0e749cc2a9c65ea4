//! One tile of the rasterizer: its binned triangles in order, eight pixels of a row at a
//! time in the lanes of the [`crate::simd`] backend (the same single-precision operations
//! lane by lane as the scalar [`super::setup::Edge::at`], so the backends agree bit for
//! bit), the top-left fill rule, a z-buffer of interpolated `1 / w` (linear in screen
//! space, so the depth test is perspective-correct) with early rejection of triangles
//! behind everything the tile holds, and at the end the winners' visibility ids.

use super::setup::{Frame, pack};
use super::{NONE, Projection, TILE, TILE_PIXELS};
use crate::simd::{Kernel, Lane, Lane8, Simd};

/// Rasterizes one tile; returns how many binned triangles early depth rejection skipped.
pub struct TileKernel<'a> {
    /// The set-up triangles and bins.
    pub frame: &'a Frame,
    /// The tile's index.
    pub tile: usize,
    /// The tile's first pixel column.
    pub x0: u32,
    /// The tile's first pixel row.
    pub y0: u32,
    /// The camera.
    pub proj: &'a Projection,
    /// The tile's visibility ids, [`TILE_PIXELS`] of them.
    pub out: &'a mut [u32],
}

/// Lanes per pixel group: eight pixels of a row.
const GROUP: u32 = 8;

impl Kernel for TileKernel<'_> {
    type Output = u64;

    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> u64 {
        let TileKernel { frame, tile, x0, y0, proj, out } = self;
        let x_end = (x0 + TILE).min(proj.width);
        let y_end = (y0 + TILE).min(proj.height);
        // 1/w per pixel (0: nothing yet); pixels outside the image hold infinity, which
        // no triangle beats and the tile's farthest depth ignores.
        let mut z = [f32::INFINITY; TILE_PIXELS];
        for y in y0..y_end {
            for x in x0..x_end {
                z[((y - y0) * TILE + x - x0) as usize] = 0.0;
            }
        }
        // Image pixels no triangle covers yet: while any is left, the farthest depth is 0
        // and nothing is rejected, so it is only computed once the tile is full.
        let mut empty = (x_end - x0) * (y_end - y0);
        let mut id = [NONE; TILE_PIXELS];
        let mut far = 0.0f32;
        let mut rejected = 0u64;
        let lane = s.load8(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        let zero = s.splat8(0.0);
        let none = zero;
        for (c, chunk) in frame.chunks.iter().enumerate() {
            for &i in chunk.bin(tile) {
                let t = &chunk.tris[i as usize];
                // Conservative by a few ulps: the interpolated depth may round above the
                // vertices' largest.
                if t.max_iw * (1.0 + 4.0 * f32::EPSILON) < far {
                    rejected += 1;
                    continue;
                }
                let (bx0, by0) = (t.bbox[0].max(x0), t.bbox[1].max(y0));
                let (bx1, by1) = (t.bbox[2].min(x_end - 1), t.bbox[3].min(y_end - 1));
                let (g0, g1) = ((bx0 - x0) / GROUP, (bx1 - x0) / GROUP);
                let e = &t.edges;
                let ax = e.map(|e| s.splat8(e.ax));
                let dy = e.map(|e| s.splat8(e.dy));
                let sign = e.map(|e| s.splat8(e.sign));
                // All-ones lanes where a zero counts as inside (top-left), else zeros.
                let tl = e.map(|e| if e.top_left { zero.cmp_eq(zero) } else { none });
                let iw = t.iw.map(|w| s.splat8(w));
                // Lanes within the box's columns (the pixels the oracle tests).
                let (left, right) = (s.splat8(bx0 as f32), s.splat8(bx1 as f32 + 1.0));
                let mut wrote = false;
                for y in by0..=by1 {
                    let py = y as f32 + 0.5;
                    let row = e.map(|e| s.splat8(e.dx * (py - e.ay)));
                    for g in g0..=g1 {
                        let px = s.splat8((x0 + g * GROUP) as f32 + 0.5) + lane;
                        let f: [S::F32x8; 3] =
                            std::array::from_fn(|k| (row[k] - dy[k] * (px - ax[k])) * sign[k]);
                        let inside = |k: usize| f[k].cmp_gt(zero).or(f[k].cmp_eq(zero).and(tl[k]));
                        let cover = inside(0)
                            .and(inside(1))
                            .and(inside(2))
                            .and(px.cmp_gt(left))
                            .and(px.cmp_lt(right));
                        if cover.movemask() == 0 {
                            continue;
                        }
                        let depth = (f[0] * iw[0] + f[1] * iw[1] + f[2] * iw[2]) / (f[0] + f[1] + f[2]);
                        let cand = cover.and(depth);
                        let base = ((y - y0) * TILE + g * GROUP) as usize;
                        let zs: &mut [f32; 8] = (&mut z[base..base + 8]).try_into().unwrap();
                        let old = s.load8(zs);
                        let mut won = old.lt_mask(cand);
                        if won != 0 {
                            empty -= (old.cmp_eq(zero).movemask() & won).count_ones();
                            *zs = old.vmax(cand).store();
                            wrote = true;
                            while won != 0 {
                                id[base + won.trailing_zeros() as usize] = pack(c, i);
                                won &= won - 1;
                            }
                        }
                    }
                }
                if wrote && empty == 0 {
                    far = z.iter().fold(f32::INFINITY, |a, &b| a.min(b));
                }
            }
        }
        // Every pixel's id (the buffer is reused from frame to frame).
        out.copy_from_slice(&id);
        rejected
    }
}
