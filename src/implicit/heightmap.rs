//! The view Fidget's voxel renderer makes of a 3D model ([`render_heightmap`]): the cube
//! [-1, 1]^3 seen from +z, orthographic, a W x H image whose pixel (column j, row i, row 0
//! at the top) looks down the line x = -1 + (2j+1)/W, y = 1 - (2i+1)/H. Each pixel holds the
//! first surface from above (its height z and outward normal), or none.
//!
//! Every ray is cast by [`Field3::first_roots`] (tiles of neighbouring rays as bundles;
//! per ray the marcher the scenes use), with a hit tolerance of half a pixel: a sliver of solid thinner than that along the ray may be
//! passed over, as a voxel renderer sampling at voxel centres (one pixel apart) can miss
//! one. A solid reaching the top face shows the cut face (z = 1, normal +z), as Fidget
//! shows a saturated pixel. The normal is the gradient by central differences of the
//! program of the hit's cell.
//!
//! [`Heightmap::depth_png`] and [`Heightmap::normal_png`] write the images the side-by-side
//! benchmark compares (`tools/bench-implicit3d`): a 16-bit height (0: no surface, else
//! round((z + 1) / 2 * 65535), at least 1) and an RGB normal (round(n * 127.5 + 127.5)).

use glam::DVec3;
use rayon::prelude::*;

use super::bundle::BundleScratch;
use super::field3d::{EXTENT, Field3, RayWork, Scratch};

/// One pixel of a [`Heightmap`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HeightPixel {
    /// Height of the first surface from above; `None` where the ray meets none.
    pub z: Option<f64>,
    /// Unit outward normal there (zero where there is no surface).
    pub normal: DVec3,
}

/// A model's view from +z (see the module header).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Heightmap {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Row by row from the top.
    pub pixels: Vec<HeightPixel>,
    /// The marcher's work over all rays.
    pub work: RayWork,
}

/// The x (column `j` of `width`) or y (row `i` of `height`, top down) of a pixel centre.
pub fn pixel_centre(j: usize, i: usize, width: usize, height: usize) -> (f64, f64) {
    (
        -EXTENT + (2 * j + 1) as f64 * EXTENT / width as f64,
        EXTENT - (2 * i + 1) as f64 * EXTENT / height as f64,
    )
}

/// A tile's pixels (index in the image, pixel) and its work.
type TilePixels = (Vec<(usize, HeightPixel)>, RayWork);

/// Pixels per side of the tiles whose rays are cast as one bundle.
const TILE: usize = 16;

/// The view of `field` at `width` x `height`: tiles of [`TILE`]^2 pixels in parallel on
/// the rayon pool, each cast as one bundle ([`Field3::first_roots`]) in Morton order, one
/// scratch per thread.
pub fn render_heightmap(field: &Field3, width: usize, height: usize) -> Heightmap {
    let tol = EXTENT / width.max(height).max(1) as f64;
    let (tx, ty) = (width.div_ceil(TILE), height.div_ceil(TILE));
    // The Morton order of a tile's pixels: halves of any aligned range are neighbours.
    let order: Vec<(usize, usize)> = {
        let mut v: Vec<(usize, usize)> = (0..TILE * TILE).map(|k| (k % TILE, k / TILE)).collect();
        v.sort_by_key(|&(x, y)| morton(x, y));
        v
    };
    let tiles: Vec<TilePixels> = (0..tx * ty)
        .into_par_iter()
        .map_init(
            || (Scratch::default(), BundleScratch::default(), Vec::new(), Vec::new(), Vec::new(), Vec::new()),
            |(s, b, rays, t_max, out, index), tile| {
                let (x0, y0) = ((tile % tx) * TILE, (tile / tx) * TILE);
                rays.clear();
                index.clear();
                for &(x, y) in &order {
                    let (j, i) = (x0 + x, y0 + y);
                    if j < width && i < height {
                        let (px, py) = pixel_centre(j, i, width, height);
                        rays.push((DVec3::new(px, py, EXTENT), DVec3::NEG_Z));
                        index.push(i * width + j);
                    }
                }
                t_max.clear();
                t_max.resize(rays.len(), 2.0 * EXTENT);
                out.clear();
                out.resize(rays.len(), None);
                let mut w = RayWork::default();
                field.first_roots(rays, 0.0, t_max, tol, 0.0, out, s, b, &mut w);
                let pixels = rays
                    .iter()
                    .zip(out.iter())
                    .zip(index.iter())
                    .map(|((&(o, d), root), &at)| {
                        let Some(root) = root else { return (at, HeightPixel::default()) };
                        let p = o + d * root.t;
                        let normal = match root.face {
                            Some(face) => face,
                            None => {
                                w.point_evals += 6;
                                let g = field.gradient(p, 1e-6, s);
                                if g.is_finite() && g.length_squared() > 0.0 {
                                    g.normalize()
                                } else {
                                    DVec3::Z
                                }
                            }
                        };
                        (at, HeightPixel { z: Some(p.z), normal })
                    })
                    .collect();
                (pixels, w)
            },
        )
        .collect();
    let mut map = Heightmap {
        width,
        height,
        pixels: vec![HeightPixel::default(); width * height],
        work: RayWork::default(),
    };
    for (pixels, w) in tiles {
        for (at, p) in pixels {
            map.pixels[at] = p;
        }
        map.work.add(&w);
    }
    map
}

/// The Morton (Z-order) index of `(x, y)`.
fn morton(x: usize, y: usize) -> usize {
    let spread = |mut v: usize| {
        let mut r = 0;
        for bit in 0..16 {
            r |= (v & 1) << (2 * bit);
            v >>= 1;
        }
        r
    };
    spread(x) | (spread(y) << 1)
}

impl Heightmap {
    /// Pixels with a surface.
    pub fn hits(&self) -> usize {
        self.pixels.iter().filter(|p| p.z.is_some()).count()
    }

    /// The heights as a 16-bit grayscale image (see the module header).
    pub fn depth_png(&self) -> image::ImageBuffer<image::Luma<u16>, Vec<u16>> {
        image::ImageBuffer::from_fn(self.width as u32, self.height as u32, |j, i| {
            let p = &self.pixels[i as usize * self.width + j as usize];
            image::Luma([p
                .z
                .map_or(0, |z| ((z + EXTENT) / (2.0 * EXTENT) * 65535.0).round().clamp(1.0, 65535.0) as u16)])
        })
    }

    /// The normals as an RGB image (see the module header).
    pub fn normal_png(&self) -> image::RgbImage {
        image::RgbImage::from_fn(self.width as u32, self.height as u32, |j, i| {
            let p = &self.pixels[i as usize * self.width + j as usize];
            if p.z.is_none() {
                return image::Rgb([0; 3]);
            }
            let c = |v: f64| (v * 127.5 + 127.5).round().clamp(0.0, 255.0) as u8;
            image::Rgb([c(p.normal.x), c(p.normal.y), c(p.normal.z)])
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::implicit::vm::parse_vm;

    #[test]
    fn an_off_centre_sphere_is_seen_where_it_is() {
        // (x - 0.4)^2 + (y + 0.2)^2 + (z - 0.1)^2 - 0.09: not a distance.
        let text = "x var-x\ny var-y\nz var-z\ncx const 0.4\ncy const -0.2\ncz const 0.1\n\
                    a sub x cx\nb sub y cy\nc sub z cz\naa square a\nbb square b\ncc square c\n\
                    s add aa bb\nt add s cc\nr const 0.09\no sub t r\n";
        let field = Field3::new(parse_vm(text, "s.vm".as_ref()).unwrap(), 8);
        let n = 40;
        let map = render_heightmap(&field, n, n);
        let mut hits = 0;
        for i in 0..n {
            for j in 0..n {
                let (x, y) = pixel_centre(j, i, n, n);
                let r2 = (x - 0.4).powi(2) + (y + 0.2).powi(2);
                let p = map.pixels[i * n + j];
                if r2 < 0.09 - 1e-3 {
                    let want = 0.1 + (0.09 - r2).sqrt();
                    let z = p.z.unwrap_or_else(|| panic!("pixel ({j}, {i}) missed"));
                    assert!((z - want).abs() < 1e-3, "({j}, {i}): {z} vs {want}");
                    let n_want = DVec3::new(x - 0.4, y + 0.2, z - 0.1).normalize();
                    assert!(p.normal.dot(n_want) > 0.999, "({j}, {i}): {:?} vs {n_want:?}", p.normal);
                    hits += 1;
                } else if r2 > 0.09 + 1e-3 {
                    assert_eq!(p.z, None, "({j}, {i})");
                }
            }
        }
        assert!(hits > 100, "{hits}");
        // x grows to the right and y upwards: the sphere is right of and below the centre.
        let depth = map.depth_png();
        assert!(depth.get_pixel(28, 24)[0] > 0 && depth.get_pixel(11, 15)[0] == 0);
        let normal = map.normal_png();
        assert_eq!(normal.get_pixel(0, 0).0, [0, 0, 0]);
    }

    #[test]
    fn a_solid_reaching_the_top_shows_the_cut_face() {
        let field = Field3::new(parse_vm("x var-x\nk const 2\no sub x k\n", "c.vm".as_ref()).unwrap(), 4);
        let map = render_heightmap(&field, 4, 4);
        for p in &map.pixels {
            assert_eq!(p.z, Some(1.0));
            assert_eq!(p.normal, DVec3::Z);
        }
        assert_eq!(map.depth_png().get_pixel(0, 0)[0], 65535);
    }
}
