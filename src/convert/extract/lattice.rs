//! The sample lattice shared by the three extraction methods: the sampled grid
//! ([`SampleGrid`]), the blocks that the distance bound cannot rule out ([`Blocks`]), the
//! samples' signs packed 64 to a word ([`Signs`]) and the numbering of sign-changing grid
//! edges, which gives each crossing vertex its index without hashing ([`Crossings`]).

use super::*;

/// Samples of a function on the corners of a regular grid of cubic cells (from
/// [`sample_grid`]); point `(x, y, z)` is at `origin + cell * (x, y, z)` and its sample is
/// `values[x + n[0] * (y + n[1] * z)]`. Samples on the outermost layer are positive. For a
/// [`Field::DistanceBound`] function, points in blocks far from the surface hold a bound
/// `b` of their value instead (`f`'s sign, `0 < |b| <= |f|`; see [`Blocks`]).
pub struct SampleGrid {
    pub(super) origin: DVec3,
    /// Cell size.
    pub(super) h: f64,
    /// Points per axis (cells + 1).
    pub(super) n: [usize; 3],
    pub(super) values: Vec<f32>,
}

impl SampleGrid {
    /// Position of grid point (0, 0, 0).
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// Cell side.
    pub fn cell(&self) -> f64 {
        self.h
    }

    /// Grid points per axis (cells + 1).
    pub fn dims(&self) -> [usize; 3] {
        self.n
    }

    /// The samples, x fastest.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    pub(super) fn sample(
        f: &(impl Fn(DVec3) -> f64 + Sync),
        bounds: &Aabb,
        res: u32,
        field: Field,
    ) -> Option<SampleGrid> {
        let (lo, hi) = (bounds.min.as_dvec3(), bounds.max.as_dvec3());
        let ext = (hi - lo).max(DVec3::ZERO);
        let longest = ext.max_element();
        if !longest.is_finite() || longest <= 0.0 || !lo.is_finite() {
            return None;
        }
        let h = longest / res as f64;
        let mut n = [0usize; 3];
        let mut origin = DVec3::ZERO;
        for a in 0..3 {
            // Cells covering the extent (the longest axis gets exactly `res`), plus one on
            // each side; the grid is centred on the box.
            let cells = if ext[a] == longest { res as usize } else { (ext[a] / h).ceil() as usize } + 2;
            n[a] = cells + 1;
            origin[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * cells as f64 * h;
        }
        // Grid point indices are stored as u32 (res up to about 1600).
        assert!(n[0] * n[1] * n[2] < u32::MAX as usize, "extraction grid too large: {n:?} points");
        let mut grid = SampleGrid { origin, h, n, values: vec![0.0; n[0] * n[1] * n[2]] };
        let blocks = match field {
            Field::DistanceBound => Blocks::classify(f, &grid),
            Field::Arbitrary => Blocks::all_sampled(),
        };
        let slice = n[0] * n[1];
        let (origin, nn) = (grid.origin, grid.n);
        grid.values.par_chunks_mut(slice).enumerate().for_each_init(
            || vec![0.0f32; blocks.n[0]],
            |row_fill, (z, vals)| {
                for (y, row) in vals.chunks_exact_mut(nn[0]).enumerate() {
                    blocks.row_fill(y, z, row_fill);
                    for (x, v) in row.iter_mut().enumerate() {
                        let (b0, b1) = blocks.along_axis(0, x);
                        let (f0, f1) = (row_fill[b0], row_fill[b1]);
                        *v = if f0.is_nan() || f1.is_nan() {
                            f(origin + h * DVec3::new(x as f64, y as f64, z as f64)) as f32
                        } else {
                            f0
                        };
                    }
                }
                // The outermost layer positive: whole slices at the ends, else the rows at
                // y = 0 and the last y, and both ends of the others.
                let outside = |v: &mut f32| {
                    if !(*v > 0.0) {
                        *v = f32::MIN_POSITIVE;
                    }
                };
                let rows = vals.len() / nn[0];
                for (y, row) in vals.chunks_exact_mut(nn[0]).enumerate() {
                    if z == 0 || z + 1 == nn[2] || y == 0 || y + 1 == rows {
                        row.iter_mut().for_each(outside);
                    } else {
                        outside(&mut row[0]);
                        outside(&mut row[nn[0] - 1]);
                    }
                }
                crate::base::progress::advance(1);
            },
        );
        Some(grid)
    }

    /// Whether points within the grid that are at least `sep` apart stay distinct when
    /// rounded to f32 (each coordinate moves by at most half an ulp, `2^-24 |x|`).
    pub(super) fn separated_in_f32(&self, sep: f64) -> bool {
        let far =
            self.pos(self.n[0] - 1, self.n[1] - 1, self.n[2] - 1).abs().max(self.origin.abs()).max_element();
        sep > 8.0 * f32::EPSILON as f64 * far
    }

    #[inline]
    pub(super) fn idx(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.n[0] * (y + self.n[1] * z)
    }

    #[inline]
    pub(super) fn pos(&self, x: usize, y: usize, z: usize) -> DVec3 {
        self.origin + self.h * DVec3::new(x as f64, y as f64, z as f64)
    }

    /// Index offsets of a cell's eight corners from its lowest one (see [`corner`]).
    pub(super) fn corner_offsets(&self) -> [usize; 8] {
        std::array::from_fn(|c| {
            let o = corner(c);
            self.idx(o[0], o[1], o[2])
        })
    }

    #[inline]
    pub(super) fn inside(&self, i: usize) -> bool {
        self.values[i] < 0.0
    }
}

/// Cells along each axis of the smallest blocks of [`Blocks`].
pub(super) const BLOCK_CELLS: usize = 4;

/// Which blocks of [`BLOCK_CELLS`]³ cells of a [`SampleGrid`] must be sampled, for a
/// [`Field::DistanceBound`] function.
///
/// Built top-down: starting from the whole grid, a box of blocks (all its cells' corners)
/// is evaluated at its centre `c` only; when `|f(c)|` exceeds the half-diagonal `r` of the
/// box's points, Lipschitz continuity puts every point `q` of the box on the sign of
/// `f(c)`, with `|f(q)| >= |f(c)| - r`, so the box holds no crossing and its points get that
/// bound as their value. Otherwise the box is split in two along each axis longer than one
/// block, down to single blocks, whose points are all sampled. Every grid cell lies in
/// exactly one block and every corner of a cell in a sampled block is sampled, so the cells
/// with a sign change, and the samples extraction reads around them (corners, ambiguous
/// faces), are those of sampling every point; the far points only keep their sign. Around
/// a surface this samples a shell about 2 √3 blocks thick: a sphere of radius 0.9 in a box
/// of side 2 at 128 cells takes 16% of the full grid's evaluations (`tests/integration/extract.rs`).
pub(super) struct Blocks {
    /// Blocks per axis (the last may be partial).
    pub(super) n: [usize; 3],
    /// Per block, x fastest: the value of all its points when it is not sampled (`|f|`
    /// bound with `f`'s sign, never zero), NaN when it is.
    pub(super) fill: Vec<f32>,
}

impl Blocks {
    /// Every block sampled.
    pub(super) fn all_sampled() -> Blocks {
        Blocks { n: [1; 3], fill: vec![f32::NAN] }
    }

    pub(super) fn classify(f: &(impl Fn(DVec3) -> f64 + Sync), grid: &SampleGrid) -> Blocks {
        let cells = grid.n.map(|p| p - 1);
        let n = cells.map(|c| c.div_ceil(BLOCK_CELLS));
        let mut fill = vec![f32::NAN; n[0] * n[1] * n[2]];
        // Boxes of blocks, `[lo, hi)` in block indices.
        let mut level = vec![([0usize; 3], n)];
        let mut far = Vec::new();
        while !level.is_empty() {
            let bounds: Vec<Option<f32>> = level
                .par_iter()
                .map(|&(lo, hi)| {
                    let p0 = grid.origin + grid.h * DVec3::from(lo.map(|b| (b * BLOCK_CELLS) as f64));
                    let p1 = grid.origin
                        + grid.h
                            * DVec3::from(std::array::from_fn(|a| {
                                (hi[a] * BLOCK_CELLS).min(cells[a]) as f64
                            }));
                    let r = 0.5 * p0.distance(p1);
                    let v = f(0.5 * (p0 + p1));
                    // A relative margin for rounding in `f` and in the positions.
                    let margin = r * (1.0 + 1e-9) + 1e-12 * p0.abs().max(p1.abs()).max_element();
                    (v.abs() > margin).then(|| {
                        let b = (v.abs() - r) as f32;
                        if v > 0.0 { b.max(f32::MIN_POSITIVE) } else { -b.max(f32::MIN_POSITIVE) }
                    })
                })
                .collect();
            let mut next = Vec::new();
            for (&(lo, hi), bound) in level.iter().zip(bounds) {
                if let Some(b) = bound {
                    far.push((lo, hi, b));
                    continue;
                }
                // Split each axis longer than one block in two.
                let halves: [Vec<(usize, usize)>; 3] = std::array::from_fn(|a| {
                    let mid = lo[a] + (hi[a] - lo[a]) / 2;
                    if hi[a] - lo[a] > 1 { vec![(lo[a], mid), (mid, hi[a])] } else { vec![(lo[a], hi[a])] }
                });
                if halves.iter().all(|h| h.len() == 1) {
                    continue; // A single block near the surface: sampled.
                }
                for &(z0, z1) in &halves[2] {
                    for &(y0, y1) in &halves[1] {
                        for &(x0, x1) in &halves[0] {
                            next.push(([x0, y0, z0], [x1, y1, z1]));
                        }
                    }
                }
            }
            level = next;
        }
        for (lo, hi, b) in far {
            for z in lo[2]..hi[2] {
                for y in lo[1]..hi[1] {
                    let row = n[0] * (y + n[1] * z);
                    fill[row + lo[0]..row + hi[0]].fill(b);
                }
            }
        }
        Blocks { n, fill }
    }

    /// The blocks along one axis whose points include coordinate `i` (two where `i` is on
    /// a boundary between blocks, else the same one twice).
    #[inline]
    pub(super) fn along_axis(&self, a: usize, i: usize) -> (usize, usize) {
        if self.n[a] == 1 {
            return (0, 0);
        }
        let b = i / BLOCK_CELLS;
        let own = b.min(self.n[a] - 1);
        (own, if i.is_multiple_of(BLOCK_CELLS) && i > 0 { b - 1 } else { own })
    }

    /// Fills `out` (one entry per block along x) for grid row `(y, z)`: NaN where a block
    /// containing points of the row must be sampled, else a valid value for those points.
    pub(super) fn row_fill(&self, y: usize, z: usize, out: &mut [f32]) {
        let (y0, y1) = self.along_axis(1, y);
        let (z0, z1) = self.along_axis(2, z);
        let rows = [(y0, z0), (y1, z0), (y0, z1), (y1, z1)];
        for (bx, o) in out.iter_mut().enumerate().take(self.n[0]) {
            *o = self.fill[bx + self.n[0] * (y0 + self.n[1] * z0)];
            for &(by, bz) in &rows[1..] {
                if self.fill[bx + self.n[0] * (by + self.n[1] * bz)].is_nan() {
                    *o = f32::NAN;
                }
            }
        }
    }
}

/// The inside bits of a grid's samples (`< 0`), 64 points of an x-row per word.
pub(super) struct Signs {
    pub(super) n: [usize; 3],
    /// Words per row.
    pub(super) words: usize,
    /// Row `(y, z)` is `bits[(y + n[1] z) words ..][..words]`; bit `x % 64` of word `x / 64`
    /// is point `(x, y, z)`.
    pub(super) bits: Vec<u64>,
}

impl Signs {
    pub(super) fn new(grid: &SampleGrid) -> Signs {
        let n = grid.n;
        let words = n[0].div_ceil(64);
        let mut bits = vec![0u64; words * n[1] * n[2]];
        bits.par_chunks_mut(words * n[1]).zip(grid.values.par_chunks(n[0] * n[1])).for_each(|(b, v)| {
            for (brow, vrow) in b.chunks_exact_mut(words).zip(v.chunks_exact(n[0])) {
                for (word, vals) in brow.iter_mut().zip(vrow.chunks(64)) {
                    *word = vals.iter().enumerate().fold(0u64, |w, (k, &s)| w | ((s < 0.0) as u64) << k);
                }
            }
        });
        Signs { n, words, bits }
    }

    #[inline]
    pub(super) fn row(&self, y: usize, z: usize) -> &[u64] {
        let s = (y + self.n[1] * z) * self.words;
        &self.bits[s..s + self.words]
    }

    /// Calls `visit(x, y, config)` for every cell of the z-slab `z` (cells `(x, y, z)`)
    /// whose corners have both signs, with `config` bit `c` set when [`corner`] `c` is
    /// inside. Eight cells per byte of a row are skipped at once when all their corners
    /// share a sign.
    #[inline]
    pub(super) fn active_cells(&self, z: usize, mut visit: impl FnMut(usize, usize, u8)) {
        let (n, words) = (self.n, self.words);
        for y in 0..n[1] - 1 {
            let r = [self.row(y, z), self.row(y + 1, z), self.row(y, z + 1), self.row(y + 1, z + 1)];
            for w in 0..words {
                let word = |k: usize| -> (u64, u64) {
                    let any = r[0][k] | r[1][k] | r[2][k] | r[3][k];
                    let all = r[0][k] & r[1][k] & r[2][k] & r[3][k];
                    (any, all)
                };
                let (any, all) = word(w);
                // The same for each cell's upper x corner (bit x + 1).
                let (any_hi, all_hi) = if w + 1 < words {
                    let (a, b) = word(w + 1);
                    ((any >> 1) | (a << 63), (all >> 1) | (b << 63))
                } else {
                    (any >> 1, all >> 1)
                };
                // Cells x < n[0] - 1 only.
                let last = n[0] - 1 - 64 * w;
                let valid = if last >= 64 { u64::MAX } else { (1u64 << last) - 1 };
                let mut active = (any | any_hi) & !(all & all_hi) & valid;
                while active != 0 {
                    let b = active.trailing_zeros() as usize;
                    active &= active - 1;
                    let x = 64 * w + b;
                    let pair = |row: &[u64]| -> u8 {
                        let lo = (row[w] >> b) & 1;
                        let hi = if b < 63 { (row[w] >> (b + 1)) & 1 } else { row[w + 1] & 1 };
                        (lo | hi << 1) as u8
                    };
                    let config = pair(r[0]) | pair(r[1]) << 2 | pair(r[2]) << 4 | pair(r[3]) << 6;
                    visit(x, y, config);
                }
            }
        }
    }
}

/// The grid edges whose samples change sign, for the first `ndirs` of [`DIRS`], and the
/// index of the vertex on each: crossings are numbered by z-slice, then row, direction
/// and x of the edge's lower end, so an edge's vertex index is a prefix count of a row's
/// crossing bits (no hashing, no sort).
pub(super) struct Crossings {
    pub(super) n: [usize; 3],
    pub(super) ndirs: usize,
    pub(super) words: usize,
    /// Word `((y + n[1] z) ndirs + d) words + x / 64`, bit `x % 64`: the edge from point
    /// `(x, y, z)` in direction `d` changes sign.
    pub(super) bits: Vec<u64>,
    /// Per word of `bits`: the index of its first crossing.
    pub(super) base: Vec<u32>,
}

impl Crossings {
    /// Finds the crossing edges and numbers them; `make(p0, v0, p1, v1)` turns each (its
    /// end points and their samples, inside end or not) into an output vertex. Returns
    /// the vertices in index order.
    pub(super) fn new<T: Copy + Default + Send>(
        grid: &SampleGrid,
        signs: &Signs,
        ndirs: usize,
        make: impl Fn(DVec3, f64, DVec3, f64) -> T + Sync,
    ) -> (Crossings, Vec<T>) {
        let (n, words) = (grid.n, signs.words);
        let per_slice = n[1] * ndirs * words;
        let mut bits = vec![0u64; per_slice * n[2]];
        bits.par_chunks_mut(per_slice).enumerate().for_each(|(z, b)| {
            for y in 0..n[1] {
                let a = signs.row(y, z);
                for (d, o) in DIRS.iter().enumerate().take(ndirs) {
                    if y + o[1] >= n[1] || z + o[2] >= n[2] {
                        continue;
                    }
                    let other = signs.row(y + o[1], z + o[2]);
                    let out = &mut b[(y * ndirs + d) * words..][..words];
                    for w in 0..words {
                        let mut v = other[w];
                        if o[0] == 1 {
                            v = (v >> 1) | other.get(w + 1).map_or(0, |&u| u << 63);
                        }
                        out[w] = a[w] ^ v;
                    }
                    // Edges from points x < n[0] - o[0] only.
                    let limit = n[0] - o[0];
                    let lw = limit / 64;
                    if lw < words {
                        out[lw] &= (1u64 << (limit % 64)) - 1;
                        out[lw + 1..].iter_mut().for_each(|v| *v = 0);
                    }
                }
            }
        });
        let mut base = vec![0u32; bits.len()];
        let mut total = 0u64;
        let mut slice_start = Vec::with_capacity(n[2] + 1);
        for (k, (b, c)) in base.iter_mut().zip(&bits).enumerate() {
            if k % per_slice == 0 {
                slice_start.push(total as usize);
            }
            *b = total as u32;
            total += c.count_ones() as u64;
        }
        slice_start.push(total as usize);
        assert!(total < u32::MAX as u64, "too many vertices for u32 indices");
        let cross = Crossings { n, ndirs, words, bits, base };
        let mut out = vec![T::default(); total as usize];
        // Disjoint output ranges per z-slice.
        let mut parts = Vec::with_capacity(n[2]);
        let mut rest = out.as_mut_slice();
        for z in 0..n[2] {
            let (head, tail) = rest.split_at_mut(slice_start[z + 1] - slice_start[z]);
            parts.push(head);
            rest = tail;
        }
        let offsets: [usize; 7] = std::array::from_fn(|d| grid.idx(DIRS[d][0], DIRS[d][1], DIRS[d][2]));
        parts.into_par_iter().enumerate().for_each(|(z, part)| {
            let mut k = 0;
            for y in 0..n[1] {
                for d in 0..ndirs {
                    let row = &cross.bits[((y + n[1] * z) * ndirs + d) * words..][..words];
                    for (w, &word) in row.iter().enumerate() {
                        let mut m = word;
                        while m != 0 {
                            let x = 64 * w + m.trailing_zeros() as usize;
                            m &= m - 1;
                            let i = grid.idx(x, y, z);
                            let o = DIRS[d];
                            let p0 = grid.pos(x, y, z);
                            let p1 = grid.pos(x + o[0], y + o[1], z + o[2]);
                            part[k] = make(p0, grid.values[i] as f64, p1, grid.values[i + offsets[d]] as f64);
                            k += 1;
                        }
                    }
                }
            }
            debug_assert_eq!(k, part.len());
        });
        (cross, out)
    }

    /// The vertex on the sign-changing edge from point `(x, y, z)` in direction `d`.
    #[inline]
    pub(super) fn vertex(&self, x: usize, y: usize, z: usize, d: usize) -> u32 {
        let k = ((y + self.n[1] * z) * self.ndirs + d) * self.words + x / 64;
        debug_assert!((self.bits[k] >> (x % 64)) & 1 != 0);
        self.base[k] + (self.bits[k] & ((1u64 << (x % 64)) - 1)).count_ones()
    }

    /// Number of crossings on edges from points of z-slice `z`.
    pub(super) fn in_slice(&self, z: usize) -> usize {
        let per_slice = self.n[1] * self.ndirs * self.words;
        let next = if z + 1 < self.n[2] {
            self.base[(z + 1) * per_slice] as usize
        } else {
            let last = self.bits.len() - 1;
            self.base[last] as usize + self.bits[last].count_ones() as usize
        };
        next - self.base[z * per_slice] as usize
    }
}
