//! The 2D image of a model without `var-z`, as the Prospero challenge defines it: the
//! square [-1, 1]^2 at `width` x `height` pixels, pixel centres x = -1 + (2j+1)/W,
//! y = 1 - (2i+1)/H (row i, column j), a pixel inside where the value is negative.
//!
//! As Fidget and MPR render it: the program is first shortened over the whole image, then
//! each tile of [`LEVELS`]`[0]` pixels is evaluated in interval arithmetic (filled when the
//! interval settles it) and the program shortened for it, then each of its sub-tiles of the
//! next level likewise on that shorter program, down to the last level, whose tiles are
//! evaluated pixel by pixel, [`LANES`] pixels (an 8x8 block) at a time, on their own shortened
//! tape. A level whose intervals decide no `min`/`max` reuses its parent's program
//! unchanged. Tiles of the first level run in parallel (rayon), each thread with its own
//! scratch (no allocation per tile once it has grown).

use std::sync::Mutex;

use rayon::prelude::*;

use super::interval::Interval;
use super::tape::{LANES, ShortenScratch, Ssa, TapeRunner};

/// Tile edges of the levels of interval pruning, pixels, each a multiple of the next; the
/// last level's tiles are evaluated pixel by pixel in [`BLOCK`] x [`BLOCK`] blocks.
pub const LEVELS: [usize; 4] = [128, 32, 16, 8];
/// Edge of a first-level tile, pixels.
pub const TILE: usize = LEVELS[0];
/// Edge of a block evaluated point by point, pixels (`BLOCK * BLOCK == LANES`).
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
    /// Clause intervals computed, all levels.
    pub interval_clauses: u64,
    /// Tiles (of every level) evaluated in interval arithmetic.
    pub interval_tiles: u64,
}

impl Census {
    fn add(&mut self, o: &Census) {
        self.filled += o.filled;
        self.evaluated += o.evaluated;
        self.clauses_evaluated += o.clauses_evaluated;
        self.blocks += o.blocks;
        self.interval_clauses += o.interval_clauses;
        self.interval_tiles += o.interval_tiles;
    }
}

/// The x of column `j` of `w`.
pub fn pixel_x(j: usize, w: usize) -> f64 {
    -1.0 + (2 * j + 1) as f64 / w as f64
}

/// The y of row `i` of `h`.
pub fn pixel_y(i: usize, h: usize) -> f64 {
    1.0 - (2 * i + 1) as f64 / h as f64
}

/// Per-thread scratch: the shortened program of each level, the intervals, the register
/// tape of the last level and its registers.
#[derive(Default)]
struct Scratch {
    iv: Vec<Interval>,
    ivs: Vec<Vec<Interval>>,
    choices: Vec<Vec<u8>>,
    tapes: Vec<Ssa>,
    shorten: ShortenScratch,
    tape: TapeRunner,
}

/// The image being rendered and its levels.
struct Frame<'a> {
    w: usize,
    h: usize,
    levels: &'a [usize],
}

/// The mask of `ssa` at `width` x `height` (z = 0 if the model reads it).
pub fn render_2d(ssa: &Ssa, width: usize, height: usize) -> (Mask, Census) {
    render_2d_levels(ssa, width, height, &LEVELS)
}

/// [`render_2d`] with the tile edges `levels` (each a multiple of the next and at most 8
/// times it, the last a multiple of [`BLOCK`]).
///
/// # Panics
/// When `levels` is not such a list.
pub fn render_2d_levels(ssa: &Ssa, width: usize, height: usize, levels: &[usize]) -> (Mask, Census) {
    assert!(
        !levels.is_empty()
            && levels.windows(2).all(|p| p[1] > 0 && p[0].is_multiple_of(p[1]) && p[0] <= 8 * p[1])
            && levels[levels.len() - 1].is_multiple_of(BLOCK),
        "tile levels {levels:?}: each a multiple of the next (at most 8 times it), the last of {BLOCK}"
    );
    let tile = levels[0];
    let mut inside = vec![0u8; width * height];
    let mut census = Census::default();
    if width == 0 || height == 0 {
        return (Mask { width, height, inside }, census);
    }
    // The whole image first: its settled answer, or the program without what it never needs.
    let zero = Interval::new(0.0, 0.0);
    let (x, y) = region(width, height, 0, height, 0, width);
    let mut iv = Vec::new();
    let v = ssa.eval_interval_fast(x, y, zero, &mut iv);
    if let Some(fill) = settled(v) {
        inside.fill(fill as u8);
        census.filled = (width * height) as u64;
        return (Mask { width, height, inside }, census);
    }
    let mut root = Ssa::default();
    ssa.shorten(&iv, &mut root, &mut Vec::new(), &mut Vec::new());
    let frame = Frame { w: width, h: height, levels };
    let tiles_x = width.div_ceil(tile);
    let tiles_y = height.div_ceil(tile);
    let tiles: Vec<(usize, usize)> =
        (0..tiles_y).flat_map(|ty| (0..tiles_x).map(move |tx| (ty, tx))).collect();
    // One scratch per worker thread for the whole image (rayon's `map_init` would make one
    // per split of the work, each growing its buffers again).
    let scratch: Vec<Mutex<Scratch>> = (0..rayon::current_num_threads().max(1))
        .map(|_| {
            Mutex::new(Scratch {
                tapes: vec![Ssa::default(); levels.len()],
                ivs: vec![Vec::new(); levels.len()],
                choices: vec![Vec::new(); levels.len()],
                ..Scratch::default()
            })
        })
        .collect();
    let done: Vec<(usize, usize, Vec<u8>, Census)> = tiles
        .par_iter()
        .map(|&(ty, tx)| {
            let slot = rayon::current_thread_index().unwrap_or(0) % scratch.len();
            // Only this thread locks its slot: never contended, never poisoned but by a panic.
            let mut guard = scratch[slot].lock().unwrap_or_else(|e| e.into_inner());
            let mut px = vec![0u8; tile * tile];
            let mut c = Census::default();
            let mut out = TileOut { px: &mut px, i0: ty * tile, j0: tx * tile, stride: tile };
            top(&frame, &mut guard, &root, ty * tile, tx * tile, &mut out, &mut c);
            (ty, tx, px, c)
        })
        .collect();
    for (ty, tx, px, c) in done {
        census.add(&c);
        for r in 0..tile {
            let i = ty * tile + r;
            if i >= height {
                break;
            }
            let j0 = tx * tile;
            let n = tile.min(width - j0);
            inside[i * width + j0..i * width + j0 + n].copy_from_slice(&px[r * tile..r * tile + n]);
        }
    }
    (Mask { width, height, inside }, census)
}

/// The pixels of one first-level tile: `px[(i - i0) * stride + (j - j0)]` for image row i,
/// column j.
struct TileOut<'a> {
    px: &'a mut [u8],
    i0: usize,
    j0: usize,
    stride: usize,
}

impl TileOut<'_> {
    fn fill(&mut self, i0: usize, i1: usize, j0: usize, j1: usize, v: u8) {
        for i in i0..i1 {
            let o = (i - self.i0) * self.stride;
            self.px[o + j0 - self.j0..o + j1 - self.j0].fill(v);
        }
    }
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

/// The first-level tile at row `i0`, column `j0`, on the whole (pruned) program.
fn top(f: &Frame, s: &mut Scratch, root: &Ssa, i0: usize, j0: usize, out: &mut TileOut, census: &mut Census) {
    let size = f.levels[0];
    let (i1, j1) = ((i0 + size).min(f.h), (j0 + size).min(f.w));
    let (x, y) = region(f.w, f.h, i0, i1, j0, j1);
    let v = root.eval_interval_fast(x, y, Interval::new(0.0, 0.0), &mut s.iv);
    census.interval_clauses += root.clauses.len() as u64;
    census.interval_tiles += 1;
    if let Some(inside) = settled(v) {
        out.fill(i0, i1, j0, j1, inside as u8);
        census.filled += ((i1 - i0) * (j1 - j0)) as u64;
        return;
    }
    let mut mine = std::mem::take(&mut s.tapes[0]);
    let t = if root.shorten_decided(&s.iv, &mut mine, &mut s.shorten) { &mine } else { root };
    node(f, s, 0, t, (i0, i1, j0, j1), out, census);
    s.tapes[0] = mine;
}

/// The tile of level `level` covering rows `i0..i1`, columns `j0..j1`, not settled by its
/// interval, with its shortened program `tape`: its sub-tiles (the next level) evaluated
/// in interval arithmetic all at once, then each one not settled shortened and rendered;
/// at the last level, its pixels.
fn node(
    f: &Frame,
    s: &mut Scratch,
    level: usize,
    tape: &Ssa,
    (i0, i1, j0, j1): (usize, usize, usize, usize),
    out: &mut TileOut,
    census: &mut Census,
) {
    if level + 1 == f.levels.len() {
        leaf(f, s, tape, (i0, i1, j0, j1), out, census);
        return;
    }
    let sub = f.levels[level + 1];
    match (f.levels[level] / sub).pow(2) {
        4 => children::<4>(f, s, level, tape, (i0, i1, j0, j1), out, census),
        16 => children::<16>(f, s, level, tape, (i0, i1, j0, j1), out, census),
        64 => children::<64>(f, s, level, tape, (i0, i1, j0, j1), out, census),
        _ => children::<1>(f, s, level, tape, (i0, i1, j0, j1), out, census),
    }
}

/// [`node`] with `L` sub-tiles evaluated together (1: one by one).
fn children<const L: usize>(
    f: &Frame,
    s: &mut Scratch,
    level: usize,
    tape: &Ssa,
    (i0, i1, j0, j1): (usize, usize, usize, usize),
    out: &mut TileOut,
    census: &mut Census,
) {
    let sub = f.levels[level + 1];
    // At most 64 sub-tiles (`L` of 1 takes them one at a time).
    let mut rects = [(0, 0, 0, 0); 64];
    let mut count = 0;
    for si in (i0..i1).step_by(sub) {
        for sj in (j0..j1).step_by(sub) {
            rects[count] = (si, (si + sub).min(i1), sj, (sj + sub).min(j1));
            count += 1;
        }
    }
    let rects = &rects[..count];
    let mut ivs = std::mem::take(&mut s.ivs[level]);
    let mut choices = std::mem::take(&mut s.choices[level]);
    for chunk in rects.chunks(L) {
        let zero = [Interval::new(0.0, 0.0); L];
        let (mut xs, mut ys) = (zero, zero);
        for k in 0..L {
            // Lanes past the tile's edge repeat its last sub-tile.
            let (a, b, c, d) = chunk[k.min(chunk.len() - 1)];
            (xs[k], ys[k]) = region(f.w, f.h, a, b, c, d);
        }
        let decided = tape.eval_interval_choices::<L>(&xs, &ys, &zero, &mut ivs, &mut choices);
        census.interval_clauses += (tape.clauses.len() * chunk.len()) as u64;
        census.interval_tiles += chunk.len() as u64;
        let n = tape.clauses.len();
        for (k, &(a, b, c, d)) in chunk.iter().enumerate() {
            if let Some(inside) = settled(ivs[(n - 1) * L + k]) {
                out.fill(a, b, c, d, inside as u8);
                census.filled += ((b - a) * (d - c)) as u64;
                continue;
            }
            if decided[k] == 0 {
                // Nothing decided: the sub-tile's program is this one.
                node(f, s, level + 1, tape, (a, b, c, d), out, census);
                continue;
            }
            let mut mine = std::mem::take(&mut s.tapes[level + 1]);
            tape.shorten_chosen::<L>(&choices, k, &mut mine, &mut s.shorten);
            node(f, s, level + 1, &mine, (a, b, c, d), out, census);
            s.tapes[level + 1] = mine;
        }
    }
    s.ivs[level] = ivs;
    s.choices[level] = choices;
}

/// The pixels of rows `i0..i1`, columns `j0..j1` evaluated one by one on `tape`, an 8x8
/// block at a time.
fn leaf(
    f: &Frame,
    s: &mut Scratch,
    tape: &Ssa,
    (i0, i1, j0, j1): (usize, usize, usize, usize),
    out: &mut TileOut,
    census: &mut Census,
) {
    s.tape.load(tape);
    let (mut xs, mut ys, zs) = ([0f32; LANES], [0f32; LANES], [0f32; LANES]);
    let mut values = [0f32; LANES];
    for bi in (i0..i1).step_by(BLOCK) {
        for bj in (j0..j1).step_by(BLOCK) {
            let (bi1, bj1) = ((bi + BLOCK).min(i1), (bj + BLOCK).min(j1));
            for k in 0..LANES {
                // Lanes past the image edge repeat its last pixel.
                let i = (bi + k / BLOCK).min(bi1 - 1);
                let j = (bj + k % BLOCK).min(bj1 - 1);
                xs[k] = pixel_x(j, f.w) as f32;
                ys[k] = pixel_y(i, f.h) as f32;
            }
            s.tape.eval(&xs, &ys, &zs, &mut values);
            for i in bi..bi1 {
                let o = (i - out.i0) * out.stride;
                for j in bj..bj1 {
                    out.px[o + j - out.j0] = (values[(i - bi) * BLOCK + (j - bj)] < 0.0) as u8;
                }
            }
            census.evaluated += ((bi1 - bi) * (bj1 - bj)) as u64;
            census.clauses_evaluated += tape.clauses.len() as u64;
            census.blocks += 1;
        }
    }
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
    fn every_level_list_renders_like_the_reference() {
        // Two discs joined by `min`, cut by `max` with a half-plane: choices to decide.
        let ssa = parse_vm(
            "x var-x\ny var-y\na square x\nb square y\nc add a b\nd sqrt c\nr const 0.5\no sub d r\n\
             k const 0.4\nxs sub x k\ne square xs\nf add e b\ng sqrt f\nh const 0.3\ni sub g h\n\
             m min o i\nq const 0.1234\nt sub y q\nu max m t\n",
            "d.vm".as_ref(),
        )
        .unwrap();
        for levels in [&[64, 16, 8][..], &[128, 32, 16, 8], &[8], &[64, 8], &[24, 8], &[16, 16, 8]] {
            for (w, h) in [(200, 130), (64, 64), (9, 1)] {
                let (m, c) = render_2d_levels(&ssa, w, h, levels);
                let r = render_2d_reference(&ssa, w, h);
                let differ = m.inside.iter().zip(&r.inside).filter(|(a, b)| a != b).count();
                let first: Vec<usize> = (0..w * h).filter(|&k| m.inside[k] != r.inside[k]).take(8).collect();
                let first: Vec<(usize, usize)> = first.iter().map(|k| (k / w, k % w)).collect();
                assert!(differ <= 1, "{levels:?} {w}x{h}: {differ} differ, first (row, col) {first:?}");
                assert_eq!(c.filled + c.evaluated, (w * h) as u64, "{levels:?} {w}x{h}");
            }
        }
        let (_, c) = render_2d_levels(&ssa, 256, 256, &LEVELS);
        assert!(c.filled > c.evaluated && c.interval_tiles > 16, "{c:?}");
    }

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
