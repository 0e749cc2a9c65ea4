//! Grids at eight points at once, for packets of marched rays: [`SdfGrid::trilinear8`]
//! (dense) and [`BandGrid::march_distance8`] (narrow band, with its empty-space skipping).
//! Where the AVX2 backend is selected ([`crate::simd::avx2`]) the eight points go through
//! one 8-wide kernel of the SIMD layer that gathers the cells' corner samples; elsewhere
//! (and for grids too large for 32-bit gather offsets) each point goes through the scalar
//! function. Each lane equals
//! the scalar function at that point bit for bit: the kernels perform the same IEEE single
//! precision operations in the same order (no fused multiply-add; `min`/`max` with the
//! operand order of glam's `Vec3::min`/`max`, which is that of `_mm256_min_ps`/`max_ps`),
//! and the tests below and in `tests/integration/grid_packets.rs` compare them.

use glam::Vec3;

use super::SdfGrid;
use super::band::BandGrid;

impl SdfGrid {
    /// [`SdfGrid::trilinear`] at the eight points `(xs[l], ys[l], zs[l])`; lane `l` equals
    /// `trilinear` at point `l` bit for bit.
    #[inline]
    pub fn trilinear8(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        #[cfg(target_arch = "x86_64")]
        if let Some(a) = crate::simd::avx2() {
            let l = lattice(self.origin, self.voxel, self.dims, self.bounds());
            if let Some(d) = a.trilinear8(&l, &self.values, [xs, ys, zs]) {
                return d;
            }
        }
        self.trilinear8_portable(xs, ys, zs)
    }

    /// [`SdfGrid::trilinear8`] at the points `origin + dir * t[l]` of the eight rays in
    /// lanes `at..at + 8` of `N` (`origin[a][l]` is component `a` of lane `l`; `at + 8 <= N`),
    /// each computed in double precision as `DVec3` does (`o + d * t` per component) and
    /// rounded to single precision; lane `l` of the result equals `trilinear` at the point
    /// of lane `at + l` bit for bit.
    #[inline]
    pub fn trilinear8_rays<const N: usize>(
        &self,
        origin: &[[f64; N]; 3],
        dir: &[[f64; N]; 3],
        t: &[f64; N],
        at: usize,
    ) -> [f32; 8] {
        assert!(at + 8 <= N, "lanes {at}..{} of {N}", at + 8);
        #[cfg(target_arch = "x86_64")]
        if let Some(a) = crate::simd::avx2() {
            let l = lattice(self.origin, self.voxel, self.dims, self.bounds());
            if let Some(d) = a.trilinear8_rays(&l, &self.values, (origin, dir, t), at) {
                return d;
            }
        }
        let p = |a: usize| -> [f32; 8] {
            std::array::from_fn(|l| (origin[a][at + l] + dir[a][at + l] * t[at + l]) as f32)
        };
        self.trilinear8_portable(&p(0), &p(1), &p(2))
    }

    /// The portable build of [`SdfGrid::trilinear8`]: the scalar function lane by lane.
    pub fn trilinear8_portable(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        std::array::from_fn(|l| self.trilinear(Vec3::new(xs[l], ys[l], zs[l])))
    }
}

impl BandGrid {
    /// [`BandGrid::march_distance`] at the eight points `(xs[l], ys[l], zs[l])`; lane `l`
    /// equals `march_distance` at point `l` bit for bit.
    #[inline]
    pub fn march_distance8(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        #[cfg(target_arch = "x86_64")]
        if let Some(a) = crate::simd::avx2() {
            let layout = crate::simd::BandLayout {
                lattice: lattice(self.origin, self.voxel, self.dims, self.bounds()),
                bricks: self.bricks.into(),
                slots: &self.slots,
                bounds: &self.bounds,
                ranges: &self.ranges,
                data: &self.data,
            };
            if let Some(d) = a.band8(&layout, [xs, ys, zs]) {
                return d;
            }
        }
        self.march_distance8_portable(xs, ys, zs)
    }

    /// The portable build of [`BandGrid::march_distance8`]: the scalar function lane by
    /// lane.
    pub fn march_distance8_portable(&self, xs: &[f32; 8], ys: &[f32; 8], zs: &[f32; 8]) -> [f32; 8] {
        std::array::from_fn(|l| self.march_distance(Vec3::new(xs[l], ys[l], zs[l])))
    }
}

/// The grid's lattice as the AVX2 kernels take it.
#[cfg(target_arch = "x86_64")]
fn lattice(origin: Vec3, voxel: f32, dims: glam::UVec3, (lo, hi): (Vec3, Vec3)) -> crate::simd::Lattice {
    crate::simd::Lattice { origin: origin.into(), voxel, dims: dims.into(), lo: lo.into(), hi: hi.into() }
}

// The band layout the AVX2 kernel assumes is this module's.
#[cfg(target_arch = "x86_64")]
const _: () = assert!(
    crate::simd::BAND_BRICK == super::band::BRICK
        && crate::simd::BAND_BS == super::band::BS
        && crate::simd::BAND_BRICK_SAMPLES == super::band::BRICK_SAMPLES
        && crate::simd::BAND_EMPTY == super::band::EMPTY
);

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    /// A grid of a sphere's distance plus a wobble (so neighbouring lanes see different
    /// cells and values).
    fn grid() -> SdfGrid {
        let mut g = SdfGrid::for_bounds(Vec3::splat(-1.0), Vec3::splat(1.0), 48, 2).unwrap();
        for k in 0..g.dims.z {
            for j in 0..g.dims.y {
                for i in 0..g.dims.x {
                    let p = g.position(i, j, k);
                    let idx = g.index(i, j, k);
                    g.values[idx] = p.length() - 0.5 + 0.01 * (3.0 * p.x).sin();
                }
            }
        }
        g
    }

    /// Deterministic points in and around the box, with exact cell corners and box faces.
    fn points(n: usize) -> Vec<Vec3> {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut v: Vec<Vec3> = (0..n).map(|_| Vec3::new(next(), next(), next()) * 4.0 - 2.0).collect();
        v.extend([Vec3::ZERO, Vec3::splat(-1.2), Vec3::splat(1.2), Vec3::new(1.2, 0.0, -3.0), Vec3::NAN]);
        v
    }

    fn lanes(p: &[Vec3]) -> ([f32; 8], [f32; 8], [f32; 8]) {
        (
            std::array::from_fn(|l| p[l % p.len()].x),
            std::array::from_fn(|l| p[l % p.len()].y),
            std::array::from_fn(|l| p[l % p.len()].z),
        )
    }

    #[test]
    fn dense_lanes_equal_scalar() {
        let g = grid();
        for chunk in points(4000).chunks(8) {
            let (xs, ys, zs) = lanes(chunk);
            let wide = g.trilinear8(&xs, &ys, &zs);
            let portable = g.trilinear8_portable(&xs, &ys, &zs);
            for l in 0..8 {
                let p = Vec3::new(xs[l], ys[l], zs[l]);
                let s = g.trilinear(p);
                assert_eq!(wide[l].to_bits(), s.to_bits(), "{p}: {} vs {s}", wide[l]);
                assert_eq!(portable[l].to_bits(), s.to_bits(), "{p}");
            }
        }
    }

    #[test]
    fn marched_store_equals_the_baseline_build() {
        // `GridStore::march_distance` runs an AVX2 build of the scalar source where it can.
        use super::super::object::GridStore;
        let g = grid();
        let b = BandGrid::from_dense(&g, 2).unwrap();
        let (dense, band) = (GridStore::Dense(g.clone()), GridStore::Band(b.clone()));
        for p in points(2000) {
            assert_eq!(dense.march_distance(p).to_bits(), g.trilinear(p).to_bits(), "{p}");
            assert_eq!(band.march_distance(p).to_bits(), b.march_distance(p).to_bits(), "{p}");
        }
    }

    #[test]
    fn band_lanes_equal_scalar() {
        let g = grid();
        for cells in [1, 2] {
            let b = BandGrid::from_dense(&g, cells).unwrap();
            assert!(b.stored_bricks() > 0 && b.stored_bricks() < b.brick_count());
            let mut skipped = 0;
            for chunk in points(4000).chunks(8) {
                let (xs, ys, zs) = lanes(chunk);
                let wide = b.march_distance8(&xs, &ys, &zs);
                let portable = b.march_distance8_portable(&xs, &ys, &zs);
                for l in 0..8 {
                    let p = Vec3::new(xs[l], ys[l], zs[l]);
                    let s = b.march_distance(p);
                    assert_eq!(wide[l].to_bits(), s.to_bits(), "{p}: {} vs {s}", wide[l]);
                    assert_eq!(portable[l].to_bits(), s.to_bits(), "{p}");
                    skipped += usize::from(s != b.trilinear(p));
                }
            }
            assert!(skipped > 0, "some points skip farther than the bound");
        }
        // A band without stored bricks at all (every lane empty).
        let far =
            BandGrid::from_dense(&SdfGrid { values: vec![5.0; grid().values.len()], ..grid() }, 1).unwrap();
        assert_eq!(far.stored_bricks(), 0);
        let (xs, ys, zs) = lanes(&points(8));
        let wide = far.march_distance8(&xs, &ys, &zs);
        for l in 0..8 {
            let s = far.march_distance(Vec3::new(xs[l], ys[l], zs[l]));
            assert_eq!(wide[l].to_bits(), s.to_bits());
        }
    }
}
