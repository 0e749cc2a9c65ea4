//! Hybrid rendering (`--primary raster`), as hybrid real-time renderers do: the primary
//! visibility of the scene's triangle meshes from the z-buffer rasterizer
//! ([`crate::raster`]), then the same Whitted shading as a traced frame
//! ([`Tracer::shade_hits`]), whose shadow, reflection and refraction rays go through the
//! BVH.
//!
//! Per pixel, the rasterizer names the visible triangle; its hit record is that
//! triangle's watertight ray test ([`MeshGeometry::triangle_hit`]), the very hit the
//! traced mesh records when the same triangle is nearest. A pixel the rasterizer covers
//! but whose ray just misses that triangle (a centre on an edge, decided differently by
//! the 2D edge functions and the 3D ray test) is traced instead, as is every pixel of a
//! mesh placed under a scale far from 1. Objects that are not triangle meshes (closed-form
//! planes and spheres, marched fields) are not rasterized: every pixel's primary ray is
//! traced against each of them, out to the rasterized hit, and the nearer hit is kept.
//!
//! The frame runs in two passes. The first rasterizes the whole frame into the visibility
//! buffer. The second, tile by tile, makes each pixel's hit record from that buffer (and
//! traces the non-mesh objects' primary rays), then shades the tile's hits. The frame's time is
//! split into primary visibility (the first pass, plus the hit records' share of the second,
//! measured per tile: [`split_pass`]) and shading (the rest). The visibility buffer is
//! allocated once per thread and kept for the next frame.

use std::cell::RefCell;
use std::time::{Duration, Instant};

use glam::Vec3;
use image::RgbImage;
use rayon::prelude::*;

use crate::geometry::mesh::{MeshGeometry, MeshLayout};
use crate::geometry::scene::SceneGeometry;
use crate::geometry::{Geometry, Hit, Ray, RayStats};
use crate::raster::{RasterMesh, RasterStats, TILE, TILE_PIXELS, VisBuffer, rasterize_into};
use crate::render::tracer::Tracer;
use crate::render::{Frame, split_pass, to_rgb8};
use crate::scene::Scene;
use crate::scene::camera::RayGenerator;

/// What the primary-visibility pass leaves for the shading pass, and its counts.
pub struct Primary {
    /// The primary hit of every pixel, tile by tile (the rasterizer's tile order).
    pub hits: Vec<Option<Hit>>,
    /// The rasterizer's counters.
    pub raster: RasterStats,
    /// Covered pixels whose ray missed the rasterized triangle and were traced instead.
    pub traced: u64,
    /// Work counters of the primary pass (primary rays, the non-mesh objects' tests).
    pub stats: RayStats,
}

/// The meshes of `geometry` (each instance of an instanced mesh on its own) and the
/// objects that are not meshes. A mesh in the compact layout counts as not a mesh here:
/// the rasterizer reads full-precision positions, which it does not keep, so its primary
/// rays are traced like the other objects'.
pub fn split_meshes(geometry: &SceneGeometry) -> (Vec<&MeshGeometry>, Vec<&dyn Geometry>) {
    let (mut meshes, mut others) = (Vec::new(), Vec::new());
    let full = |m: &MeshGeometry| m.shape().layout() == MeshLayout::Full;
    for o in geometry.objects() {
        if !o.instances().is_empty() && o.instances().iter().all(full) {
            meshes.extend(o.instances().iter());
        } else if let Some(m) = o.as_mesh().filter(|m| full(m)) {
            meshes.push(m);
        } else {
            others.push(o.as_ref());
        }
    }
    (meshes, others)
}

/// Whether `geometry` has a triangle mesh the rasterizer can draw (else a hybrid frame
/// traces every primary ray).
pub fn rasterizable(geometry: &SceneGeometry) -> bool {
    !split_meshes(geometry).0.is_empty()
}

/// The rasterizer's view of the meshes.
fn raster_list<'a>(meshes: &[&'a MeshGeometry]) -> Vec<RasterMesh<'a>> {
    meshes
        .iter()
        .map(|m| RasterMesh {
            positions: m.shape().positions(),
            triangles: m.shape().triangles(),
            to_world: m.shape_to_world().to_world,
        })
        .collect()
}

/// Makes the hit records of one tile's pixels from the visibility buffer.
struct TileHits<'a> {
    vis: &'a VisBuffer,
    meshes: &'a [&'a MeshGeometry],
    others: &'a [&'a dyn Geometry],
    geometry: &'a SceneGeometry,
    rays: RayGenerator,
    max_distance: f32,
}

impl TileHits<'_> {
    /// The rays of the tile at (`x0`, `y0`), `tw` x `th` pixels, row-major into `rays`
    /// (eight at a time, as the traced frame makes them).
    fn rays(&self, (x0, y0, tw, th): (u32, u32, u32, u32), rays: &mut [Ray]) {
        for y in 0..th {
            let v = [self.rays.v(y0 + y); 8];
            for x in (0..tw).step_by(8) {
                let u: [f32; 8] = std::array::from_fn(|k| self.rays.u(x0 + (x + k as u32).min(tw - 1)));
                let k = (tw - x).min(8) as usize;
                let at = (y * tw + x) as usize;
                rays[at..at + k].copy_from_slice(&self.rays.rays_uv8(&u, &v)[..k]);
            }
        }
    }

    /// The hits of the tile's `rays` (made by [`Self::rays`]) into `hits`; returns the
    /// covered pixels traced instead (see the module header).
    fn hits(
        &self,
        (x0, y0, tw, th): (u32, u32, u32, u32),
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        stats: &mut RayStats,
    ) -> u64 {
        let mut traced = 0;
        stats.rays += (tw * th) as u64;
        for y in 0..th {
            for x in 0..tw {
                let i = (y * tw + x) as usize;
                let ray = &rays[i];
                let mut hit = None;
                if let Some((mesh, triangle)) = self.vis.triangle_at(x0 + x, y0 + y) {
                    hit = self.meshes[mesh as usize].triangle_hit(ray, triangle, self.max_distance);
                    if hit.is_none() {
                        traced += 1;
                        hit = self.geometry.closest_hit(ray, 0.0, self.max_distance, stats);
                    }
                }
                for o in self.others {
                    let reach = hit.map_or(self.max_distance, |h: Hit| h.t);
                    if let Some(h) = o.closest_hit(ray, 0.0, reach, stats) {
                        hit = Some(h);
                    }
                }
                hits[i] = hit;
            }
        }
        traced
    }
}

/// The primary hits of every pixel of `scene`'s camera: meshes rasterized, other objects
/// traced (see the module header). The whole frame's hits at once, for tests and tools;
/// [`render_hybrid`] makes them tile by tile.
pub fn primary_hits(scene: &Scene, geometry: &SceneGeometry) -> Primary {
    let cam = &scene.camera;
    let (meshes, others) = split_meshes(geometry);
    let mut vis = VisBuffer::default();
    let raster = rasterize_into(cam, &raster_list(&meshes), &mut vis);
    let maker = TileHits {
        vis: &vis,
        meshes: &meshes,
        others: &others,
        geometry,
        rays: RayGenerator::new(cam),
        max_distance: scene.settings.max_distance,
    };
    let tiles_x = cam.width.div_ceil(TILE);
    let mut hits = vec![None; (tiles_x * cam.height.div_ceil(TILE)) as usize * TILE_PIXELS];
    let (traced, stats) = hits
        .par_chunks_mut(TILE_PIXELS)
        .enumerate()
        .map(|(t, out)| {
            let (x0, y0) = ((t as u32 % tiles_x) * TILE, (t as u32 / tiles_x) * TILE);
            let (tw, th) = (TILE.min(cam.width - x0), TILE.min(cam.height - y0));
            let mut stats = RayStats::default();
            let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); TILE_PIXELS];
            let mut tile = [None; TILE_PIXELS];
            let n = (tw * th) as usize;
            maker.rays((x0, y0, tw, th), &mut rays[..n]);
            let traced = maker.hits((x0, y0, tw, th), &rays[..n], &mut tile[..n], &mut stats);
            for y in 0..th {
                for x in 0..tw {
                    out[(y * TILE + x) as usize] = tile[(y * tw + x) as usize];
                }
            }
            (traced, stats)
        })
        .reduce(
            || (0, RayStats::default()),
            |(a, mut s), (b, t)| {
                s.add(&t);
                (a + b, s)
            },
        );
    Primary { hits, raster, traced, stats }
}

thread_local! {
    /// The visibility buffer of the last hybrid frame rendered on this thread, reused.
    static VIS: RefCell<VisBuffer> = RefCell::new(VisBuffer::default());
}

/// Renders `scene` with primary visibility rasterized and everything else traced through
/// `geometry`: the hybrid frame, its time split into primary visibility and shading.
pub fn render_hybrid(scene: &Scene, geometry: &SceneGeometry) -> Frame {
    VIS.with(|vis| render_hybrid_with(scene, geometry, &mut vis.borrow_mut()))
}

fn render_hybrid_with(scene: &Scene, geometry: &SceneGeometry, vis: &mut VisBuffer) -> Frame {
    let cam = &scene.camera;
    let (w, h) = (cam.width, cam.height);
    let (meshes, others) = split_meshes(geometry);
    let list = raster_list(&meshes);
    let start = Instant::now();
    rasterize_into(cam, &list, vis);
    let raster_time = start.elapsed();
    let maker = TileHits {
        vis,
        meshes: &meshes,
        others: &others,
        geometry,
        rays: RayGenerator::new(cam),
        max_distance: scene.settings.max_distance,
    };
    let tracer = Tracer::new(scene, geometry);
    let tiles_x = w.div_ceil(TILE);
    let second = Instant::now();
    let tiles: Vec<(Vec<[u8; 3]>, RayStats, [Duration; 2])> = (0..tiles_x * h.div_ceil(TILE))
        .into_par_iter()
        .map(|t| {
            let (x0, y0) = ((t % tiles_x) * TILE, (t / tiles_x) * TILE);
            let (tw, th) = (TILE.min(w - x0), TILE.min(h - y0));
            let n = (tw * th) as usize;
            let mut stats = RayStats::default();
            let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); TILE_PIXELS];
            let mut hits = [None; TILE_PIXELS];
            // The rays are made outside the timed steps, as in the traced frame.
            maker.rays((x0, y0, tw, th), &mut rays[..n]);
            let t0 = Instant::now();
            maker.hits((x0, y0, tw, th), &rays[..n], &mut hits[..n], &mut stats);
            let t1 = Instant::now();
            let mut colors = [Vec3::ZERO; TILE_PIXELS];
            tracer.shade_hits(&rays[..n], &hits[..n], &mut colors[..n], &mut stats);
            let t2 = Instant::now();
            (colors[..n].iter().map(|&c| to_rgb8(c)).collect(), stats, [t1 - t0, t2 - t1])
        })
        .collect();
    let end = Instant::now();
    let mut image = RgbImage::new(w, h);
    let mut stats = RayStats::default();
    let mut parts = [Duration::ZERO; 2];
    for (t, (px, s, d)) in tiles.into_iter().enumerate() {
        stats.add(&s);
        parts[0] += d[0];
        parts[1] += d[1];
        let (x0, y0) = ((t as u32 % tiles_x) * TILE, (t as u32 / tiles_x) * TILE);
        let tw = TILE.min(w - x0);
        for (i, c) in px.into_iter().enumerate() {
            image.put_pixel(x0 + i as u32 % tw, y0 + i as u32 / tw, image::Rgb(c));
        }
    }
    let records = split_pass(end - second, parts);
    Frame { image, time: end - start, stats, primary: Some(raster_time + records), raster: Some(raster_time) }
}
