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
//! The frame's time is split: primary visibility (rasterizing, the hit records, the
//! non-mesh objects' primary rays) and shading (everything after).

use std::time::Instant;

use glam::Vec3;
use image::RgbImage;
use rayon::prelude::*;

use crate::geometry::mesh::{MeshGeometry, MeshLayout};
use crate::geometry::scene::SceneGeometry;
use crate::geometry::{Geometry, Hit, RayStats};
use crate::raster::{RasterMesh, RasterStats, TILE, TILE_PIXELS, rasterize};
use crate::render::tracer::Tracer;
use crate::render::{Frame, to_rgb8};
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

/// The primary hits of every pixel of `scene`'s camera: meshes rasterized, other objects
/// traced (see the module header).
pub fn primary_hits(scene: &Scene, geometry: &SceneGeometry) -> Primary {
    let cam = &scene.camera;
    let (meshes, others) = split_meshes(geometry);
    let list: Vec<RasterMesh> = meshes
        .iter()
        .map(|m| RasterMesh {
            positions: m.shape().positions(),
            triangles: m.shape().triangles(),
            to_world: m.shape_to_world().to_world,
        })
        .collect();
    let (vis, raster) = rasterize(cam, &list);
    let rays = RayGenerator::new(cam);
    let tiles_x = cam.width.div_ceil(TILE);
    let max_distance = scene.settings.max_distance;
    let mut hits = vec![None; (tiles_x * cam.height.div_ceil(TILE)) as usize * TILE_PIXELS];
    let (traced, stats) = hits
        .par_chunks_mut(TILE_PIXELS)
        .enumerate()
        .map(|(t, out)| {
            let (x0, y0) = ((t as u32 % tiles_x) * TILE, (t as u32 / tiles_x) * TILE);
            let mut stats = RayStats::default();
            let mut traced = 0u64;
            for y in y0..(y0 + TILE).min(cam.height) {
                for x in x0..(x0 + TILE).min(cam.width) {
                    let ray = rays.ray(x, y);
                    stats.rays += 1;
                    let mut hit = None;
                    if let Some(v) = vis.at(x, y) {
                        hit = meshes[v.mesh as usize].triangle_hit(&ray, v.triangle, max_distance);
                        if hit.is_none() {
                            traced += 1;
                            hit = geometry.closest_hit(&ray, 0.0, max_distance, &mut stats);
                        }
                    }
                    for o in &others {
                        let reach = hit.map_or(max_distance, |h: Hit| h.t);
                        if let Some(h) = o.closest_hit(&ray, 0.0, reach, &mut stats) {
                            hit = Some(h);
                        }
                    }
                    out[((y - y0) * TILE + x - x0) as usize] = hit;
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

/// Renders `scene` with primary visibility rasterized and everything else traced through
/// `geometry`: the hybrid frame, its time split into primary visibility and shading.
pub fn render_hybrid(scene: &Scene, geometry: &SceneGeometry) -> Frame {
    let cam = &scene.camera;
    let (w, h) = (cam.width, cam.height);
    let start = Instant::now();
    let primary = primary_hits(scene, geometry);
    let primary_time = start.elapsed();
    let rays = RayGenerator::new(cam);
    let tracer = Tracer::new(scene, geometry);
    let tiles_x = w.div_ceil(TILE);
    let tiles: Vec<(Vec<[u8; 3]>, RayStats)> = primary
        .hits
        .par_chunks(TILE_PIXELS)
        .enumerate()
        .map(|(t, hits)| {
            let (x0, y0) = ((t as u32 % tiles_x) * TILE, (t as u32 / tiles_x) * TILE);
            let (tw, th) = (TILE.min(w - x0), TILE.min(h - y0));
            let mut stats = RayStats::default();
            let mut batch = Vec::with_capacity(TILE_PIXELS);
            let mut batch_hits = Vec::with_capacity(TILE_PIXELS);
            for y in 0..th {
                for x in 0..tw {
                    batch.push(rays.ray(x0 + x, y0 + y));
                    batch_hits.push(hits[(y * TILE + x) as usize]);
                }
            }
            let mut colors = vec![Vec3::ZERO; batch.len()];
            tracer.shade_hits(&batch, &batch_hits, &mut colors, &mut stats);
            (colors.into_iter().map(to_rgb8).collect(), stats)
        })
        .collect();
    let time = start.elapsed();
    let mut image = RgbImage::new(w, h);
    let mut stats = primary.stats;
    for (t, (px, s)) in tiles.into_iter().enumerate() {
        stats.add(&s);
        let (x0, y0) = ((t as u32 % tiles_x) * TILE, (t as u32 / tiles_x) * TILE);
        let tw = TILE.min(w - x0);
        for (i, c) in px.into_iter().enumerate() {
            image.put_pixel(x0 + i as u32 % tw, y0 + i as u32 / tw, image::Rgb(c));
        }
    }
    Frame { image, time, stats, primary: Some(primary_time) }
}
