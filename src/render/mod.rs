//! Frame rendering: image tiles traced in parallel with rayon, deterministic output,
//! frame statistics (time, rays per second, steps and nodes per ray), and PNG writing
//! through a temporary file so a failed write never leaves a partial image.
//! A tile's primary rays go to the tracer as one batch, in packets of eight (4x2 pixels)
//! one after the other, which marched geometry marches side by side (a lane taking the
//! next ray as its march ends); everything else traces them one by one.

pub mod hybrid;
pub mod report;
pub mod tracer;

use std::path::Path;
use std::time::{Duration, Instant};

use glam::Vec3;
use image::RgbImage;
use rayon::prelude::*;

use crate::error::Result;
use crate::geometry::scene::SceneGeometry;
use crate::geometry::{Geometry, Hit, PACKET, Ray, RayStats};
use crate::render::tracer::{BATCH, Tracer};
use crate::scene::Scene;
use crate::scene::camera::RayGenerator;

/// Tile edge, pixels: a tile's primary rays are one batch of the tracer.
const TILE: u32 = 16;
const _: () = assert!((TILE * TILE) as usize <= BATCH);

/// Width and height of a packet of primary rays, pixels (`PACKET_W * PACKET_H = PACKET`):
/// a 4x2 block keeps the eight rays closer together than a row of eight.
const PACKET_W: u32 = 4;
/// See [`PACKET_W`].
const PACKET_H: u32 = 2;

/// A rendered frame and what it cost.
pub struct Frame {
    /// The image, 8-bit RGB (linear colour clamped to [0, 1]).
    pub image: RgbImage,
    /// Wall-clock time of the frame.
    pub time: Duration,
    /// Work counters summed over all threads.
    pub stats: RayStats,
    /// Of `time`, the primary visibility: finding every pixel's primary hit record. In a
    /// traced frame, the closest hits of the primary rays; in a hybrid frame
    /// ([`hybrid::render_hybrid`]), rasterizing (`raster`) and the hit records made from
    /// the visibility buffer. Where it shares a parallel pass with shading, its part of
    /// the pass's wall-clock time is its share of the time the tiles spent ([`split_pass`]).
    /// The rest of `time` is shading. `None` where a frame has no primary rays (a 2D image).
    pub primary: Option<Duration>,
    /// Of `primary`, the rasterizer's pass (the visibility buffer) of a hybrid frame;
    /// `None` for a traced frame.
    pub raster: Option<Duration>,
}

/// The part of a parallel pass's wall-clock time `wall` spent on the first of two steps
/// every tile runs one after the other, given the summed time of each step over the tiles
/// (`parts`): `wall` split in proportion (the tiles' threads run the two steps alike).
pub fn split_pass(wall: Duration, parts: [Duration; 2]) -> Duration {
    let total = parts[0] + parts[1];
    if total.is_zero() { Duration::ZERO } else { wall.mul_f64(parts[0].as_secs_f64() / total.as_secs_f64()) }
}

/// How a frame finds what each pixel sees first.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PrimaryVisibility {
    /// Primary rays traced, as every other ray (the default).
    #[default]
    Trace,
    /// The triangle meshes rasterized ([`crate::raster`]), the rest traced
    /// ([`hybrid::render_hybrid`]).
    Raster,
}

impl PrimaryVisibility {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            PrimaryVisibility::Trace => "trace",
            PrimaryVisibility::Raster => "raster",
        }
    }
}

impl Frame {
    /// Rays (all kinds) per second, millions.
    pub fn mrays_per_s(&self) -> f64 {
        self.stats.rays as f64 / self.time.as_secs_f64() / 1e6
    }

    /// Mean distance evaluations per ray (all kinds of rays).
    pub fn steps_per_ray(&self) -> f64 {
        self.stats.march_steps as f64 / self.stats.rays.max(1) as f64
    }

    /// Mean BVH nodes visited per ray.
    pub fn nodes_per_ray(&self) -> f64 {
        self.stats.bvh_nodes as f64 / self.stats.rays.max(1) as f64
    }
}

/// Converts a linear colour to 8 bits (clamped, rounded).
#[inline]
#[allow(clippy::manual_clamp)] // `clamp` keeps NaN, which `as u8` would then have to check
pub fn to_rgb8(c: Vec3) -> [u8; 3] {
    // `max` and `min` take the number where one side is NaN: NaN gives 0, as `clamp` then
    // a saturating `as u8` would (the value below lies in [0.5, 255.5] either way, so the
    // saturating cast truncates it as an unchecked one would).
    let q = |x: f32| (x.max(0.0).min(1.0) * 255.0 + 0.5) as u8;
    [q(c.x), q(c.y), q(c.z)]
}

/// A rendered tile: its index, pixels, work counters and the time its two steps took
/// (primary visibility, shading).
type TileResult = (u32, Vec<[u8; 3]>, RayStats, [Duration; 2]);

/// Renders `scene` through `geometry`, primary visibility traced or rasterized
/// ([`hybrid::render_hybrid`]).
pub fn render_with(scene: &Scene, geometry: &SceneGeometry, primary: PrimaryVisibility) -> Frame {
    match primary {
        PrimaryVisibility::Trace => render(scene, geometry),
        PrimaryVisibility::Raster => hybrid::render_hybrid(scene, geometry),
    }
}

/// Renders `scene` through `geometry` at the camera's resolution.
pub fn render(scene: &Scene, geometry: &dyn Geometry) -> Frame {
    let cam = &scene.camera;
    let (w, h) = (cam.width, cam.height);
    let rays = RayGenerator::new(cam);
    let tracer = Tracer::new(scene, geometry);
    let tiles_x = w.div_ceil(TILE);
    let tiles_y = h.div_ceil(TILE);
    let start = Instant::now();
    let max_distance = scene.settings.max_distance;
    let tiles: Vec<TileResult> = (0..tiles_x * tiles_y)
        .into_par_iter()
        .map(|tile| {
            let (tx, ty) = (tile % tiles_x, tile / tiles_x);
            let mut stats = RayStats::default();
            let (x0, y0) = (tx * TILE, ty * TILE);
            let (tw, th) = (TILE.min(w - x0), TILE.min(h - y0));
            let mut px = vec![[0u8; 3]; (tw * th) as usize];
            // The image-plane coordinates of the tile's columns and rows, once per tile.
            let us: [f32; TILE as usize] = std::array::from_fn(|x| rays.u(x0 + (x as u32).min(tw - 1)));
            let vs: [f32; TILE as usize] = std::array::from_fn(|y| rays.v(y0 + (y as u32).min(th - 1)));
            // The tile's primary rays in packets of PACKET_W x PACKET_H pixels (clipped at
            // the tile's edge), one packet after the other, traced as one batch.
            let mut batch = [Ray::new(Vec3::ZERO, Vec3::Z); BATCH];
            let mut pixel = [0u32; BATCH];
            let mut n = 0;
            for py in (0..th).step_by(PACKET_H as usize) {
                for pxx in (0..tw).step_by(PACKET_W as usize) {
                    let (mut u, mut v) = ([us[pxx as usize]; PACKET], [vs[py as usize]; PACKET]);
                    let mut k = 0;
                    for y in py..(py + PACKET_H).min(th) {
                        for x in pxx..(pxx + PACKET_W).min(tw) {
                            (u[k], v[k], pixel[n + k]) = (us[x as usize], vs[y as usize], y * tw + x);
                            k += 1;
                        }
                    }
                    batch[n..n + k].copy_from_slice(&rays.rays_uv8(&u, &v)[..k]);
                    n += k;
                }
            }
            // What `Tracer::trace_batch` does, in its two steps, each timed: the primary
            // rays' closest hits, then their shading.
            let t0 = Instant::now();
            let mut t_max = [max_distance; BATCH];
            let mut hits: [Option<Hit>; BATCH] = [None; BATCH];
            stats.rays += n as u64;
            geometry.closest_hits(&batch[..n], 0.0, &mut t_max[..n], &mut hits[..n], &mut stats);
            let t1 = Instant::now();
            let mut colors = [Vec3::ZERO; BATCH];
            tracer.shade_hits(&batch[..n], &hits[..n], &mut colors[..n], &mut stats);
            let t2 = Instant::now();
            for (&p, &c) in pixel[..n].iter().zip(&colors[..n]) {
                px[p as usize] = to_rgb8(c);
            }
            (tile, px, stats, [t1 - t0, t2 - t1])
        })
        .collect();
    let time = start.elapsed();
    let mut image = RgbImage::new(w, h);
    let mut stats = RayStats::default();
    let mut parts = [Duration::ZERO; 2];
    for (tile, px, s, d) in tiles {
        stats.add(&s);
        parts[0] += d[0];
        parts[1] += d[1];
        let (tx, ty) = (tile % tiles_x, tile / tiles_x);
        let mut i = 0;
        for y in ty * TILE..((ty + 1) * TILE).min(h) {
            for x in tx * TILE..((tx + 1) * TILE).min(w) {
                image.put_pixel(x, y, image::Rgb(px[i]));
                i += 1;
            }
        }
    }
    Frame { image, time, stats, primary: Some(split_pass(time, parts)), raster: None }
}

/// Writes `image` as PNG to `path` through [`crate::files::write_atomic`]: a temporary
/// file in the same directory, renamed into place only when complete, so a failure leaves
/// any existing file untouched.
pub fn write_png(image: &RgbImage, path: &Path) -> Result<()> {
    use image::ImageEncoder;
    crate::files::write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(image.as_raw(), image.width(), image.height(), image::ExtendedColorType::Rgb8)
            .map_err(std::io::Error::other)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`to_rgb8`] against the plain reference (`clamp`, then a saturating cast) on special
    /// values and a sweep over [-1, 2] in steps finer than a level.
    #[test]
    fn to_rgb8_matches_clamp_and_cast() {
        let reference = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
        let special =
            [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0, 0.0, 1.0, f32::MIN_POSITIVE];
        let sweep = (0..=30_000).map(|i| -1.0 + i as f32 * 1e-4);
        for x in special.into_iter().chain(sweep) {
            let [r, g, b] = to_rgb8(Vec3::new(x, 0.5, 1.0 - x));
            assert_eq!([r, g, b], [reference(x), reference(0.5), reference(1.0 - x)], "x = {x}");
        }
    }
}
