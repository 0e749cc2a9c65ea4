//! The 2D image of a model without `var-z`, as the Prospero challenge defines it: the
//! square [-1, 1]^2 at `width` x `height` pixels, pixel centres x = -1 + (2j+1)/W,
//! y = 1 - (2i+1)/H (row i, column j), a pixel inside where the value is negative.
//!
//! As Fidget renders it: each 64-pixel tile is evaluated in interval arithmetic (filled
//! when the interval settles it), the program shortened for it, then each 8x8 block
//! likewise, and the blocks left are evaluated 64 pixels at a time on their shortened
//! tape; tiles run in parallel (rayon).

use rayon::prelude::*;

use super::interval::Interval;
use super::tape::{LANES, Ssa, Tape};

/// Edge of a first-level tile, pixels.
pub const TILE: usize = 64;
/// Edge of a second-level block, pixels (`BLOCK * BLOCK == LANES`).
pub const BLOCK: usize = 8;

/// A rendered mask: `inside[i * width + j]` for row i, column j.
#[derive(Clone, Debug, PartialEq)]
pub struct Mask {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// 1 where the value is negative, row-major.
    pub inside: Vec<u8>,
}

/// What the tile pruning did (for the report).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Census {
    /// Pixels filled from an interval (of a tile or a block).
    pub filled: u64,
    /// Pixels evaluated point by point.
    pub evaluated: u64,
    /// Sum over evaluated blocks of their tape length (clauses).
    pub clauses_evaluated: u64,
    /// Blocks evaluated.
    pub blocks: u64,
}

/// The x of column `j` of `w`.
pub fn pixel_x(j: usize, w: usize) -> f64 {
    -1.0 + (2 * j + 1) as f64 / w as f64
}

/// The y of row `i` of `h`.
pub fn pixel_y(i: usize, h: usize) -> f64 {
    1.0 - (2 * i + 1) as f64 / h as f64
}

#[derive(Default)]
struct Scratch {
    iv: Vec<Interval>,
    tile_ssa: Ssa,
    block_ssa: Ssa,
    alias: Vec<u32>,
    live: Vec<bool>,
    tape: Tape,
    last_use: Vec<u32>,
    reg_of: Vec<u32>,
    free: Vec<u32>,
    regs: Vec<f32>,
}

/// The mask of `ssa` at `width` x `height` (z = 0 if the model reads it).
pub fn render_2d(ssa: &Ssa, width: usize, height: usize) -> (Mask, Census) {
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    let tiles: Vec<(usize, usize)> =
        (0..tiles_y).flat_map(|ty| (0..tiles_x).map(move |tx| (ty, tx))).collect();
    let done: Vec<(usize, usize, Vec<u8>, Census)> = tiles
        .par_iter()
        .map_init(Scratch::default, |s, &(ty, tx)| {
            let mut px = vec![0u8; TILE * TILE];
            let mut census = Census::default();
            tile(ssa, width, height, ty * TILE, tx * TILE, &mut px, s, &mut census);
            (ty, tx, px, census)
        })
        .collect();
    let mut inside = vec![0u8; width * height];
    let mut census = Census::default();
    for (ty, tx, px, c) in done {
        census.filled += c.filled;
        census.evaluated += c.evaluated;
        census.clauses_evaluated += c.clauses_evaluated;
        census.blocks += c.blocks;
        for r in 0..TILE {
            let i = ty * TILE + r;
            if i >= height {
                break;
            }
            let j0 = tx * TILE;
            let n = TILE.min(width - j0);
            inside[i * width + j0..i * width + j0 + n].copy_from_slice(&px[r * TILE..r * TILE + n]);
        }
    }
    (Mask { width, height, inside }, census)
}

/// The interval box of the pixel centres of rows `i0..i1`, columns `j0..j1`.
fn region(w: usize, h: usize, i0: usize, i1: usize, j0: usize, j1: usize) -> (Interval, Interval) {
    (Interval::new(pixel_x(j0, w), pixel_x(j1 - 1, w)), Interval::new(pixel_y(i1 - 1, h), pixel_y(i0, h)))
}

/// Settled by the interval: Some(inside) or None.
fn settled(v: Interval) -> Option<bool> {
    if v.nan {
        None
    } else if v.hi < 0.0 {
        Some(true)
    } else if v.lo >= 0.0 {
        Some(false)
    } else {
        None
    }
}

#[allow(clippy::too_many_arguments)]
fn tile(
    ssa: &Ssa,
    w: usize,
    h: usize,
    i0: usize,
    j0: usize,
    px: &mut [u8],
    s: &mut Scratch,
    census: &mut Census,
) {
    let (i1, j1) = ((i0 + TILE).min(h), (j0 + TILE).min(w));
    let zero = Interval::new(0.0, 0.0);
    let (x, y) = region(w, h, i0, i1, j0, j1);
    let v = ssa.eval_interval(x, y, zero, &mut s.iv);
    if let Some(inside) = settled(v) {
        px.fill(inside as u8);
        census.filled += ((i1 - i0) * (j1 - j0)) as u64;
        return;
    }
    let mut tile_ssa = std::mem::take(&mut s.tile_ssa);
    ssa.shorten(&s.iv, &mut tile_ssa, &mut s.alias, &mut s.live);
    let mut block_ssa = std::mem::take(&mut s.block_ssa);
    let (mut xs, mut ys, zs) = ([0f32; LANES], [0f32; LANES], [0f32; LANES]);
    let mut out = [0f32; LANES];
    for bi in (i0..i1).step_by(BLOCK) {
        for bj in (j0..j1).step_by(BLOCK) {
            let (bi1, bj1) = ((bi + BLOCK).min(i1), (bj + BLOCK).min(j1));
            let (x, y) = region(w, h, bi, bi1, bj, bj1);
            let v = tile_ssa.eval_interval(x, y, zero, &mut s.iv);
            if let Some(inside) = settled(v) {
                for i in bi..bi1 {
                    px[(i - i0) * TILE + (bj - j0)..(i - i0) * TILE + (bj1 - j0)].fill(inside as u8);
                }
                census.filled += ((bi1 - bi) * (bj1 - bj)) as u64;
                continue;
            }
            tile_ssa.shorten(&s.iv, &mut block_ssa, &mut s.alias, &mut s.live);
            s.tape.allocate_into(&block_ssa, &mut s.last_use, &mut s.reg_of, &mut s.free);
            for k in 0..LANES {
                // Lanes past the image edge repeat its last pixel.
                let i = (bi + k / BLOCK).min(bi1 - 1);
                let j = (bj + k % BLOCK).min(bj1 - 1);
                xs[k] = pixel_x(j, w) as f32;
                ys[k] = pixel_y(i, h) as f32;
            }
            s.tape.eval(&xs, &ys, &zs, &mut s.regs, &mut out);
            for i in bi..bi1 {
                for j in bj..bj1 {
                    let k = (i - bi) * BLOCK + (j - bj);
                    px[(i - i0) * TILE + (j - j0)] = (out[k] < 0.0) as u8;
                }
            }
            census.evaluated += ((bi1 - bi) * (bj1 - bj)) as u64;
            census.clauses_evaluated += block_ssa.clauses.len() as u64;
            census.blocks += 1;
        }
    }
    s.tile_ssa = tile_ssa;
    s.block_ssa = block_ssa;
}

/// The mask by brute force: every pixel evaluated in f64 on the whole program.
pub fn render_2d_reference(ssa: &Ssa, width: usize, height: usize) -> Mask {
    let inside: Vec<u8> = (0..height)
        .into_par_iter()
        .flat_map_iter(|i| {
            let mut v = Vec::new();
            (0..width)
                .map(|j| {
                    (ssa.eval_f64_into([pixel_x(j, width), pixel_y(i, height), 0.0], &mut v) < 0.0) as u8
                })
                .collect::<Vec<u8>>()
        })
        .collect();
    Mask { width, height, inside }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::implicit::vm::parse_vm;

    #[test]
    fn a_disc_renders_like_the_reference_at_odd_sizes() {
        let ssa = parse_vm(
            "x var-x\ny var-y\na square x\nb square y\nc add a b\nd sqrt c\nr const 0.7\no sub d r\n",
            "d.vm".as_ref(),
        )
        .unwrap();
        for (w, h) in [(100, 70), (64, 64), (1, 3)] {
            let (m, c) = render_2d(&ssa, w, h);
            let r = render_2d_reference(&ssa, w, h);
            let differ = m.inside.iter().zip(&r.inside).filter(|(a, b)| a != b).count();
            assert!(differ <= 1, "{w}x{h}: {differ} differ");
            assert_eq!(c.filled + c.evaluated, (w * h) as u64);
        }
    }
}
