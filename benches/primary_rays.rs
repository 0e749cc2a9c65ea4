//! Primary-ray and shadow-ray throughput: 1M closest-hit rays (1000x1000 through the
//! camera that `mesh_preview_scene` frames a mesh with), no shading, on the armadillo and
//! the Stanford bunny, and the shadow rays of their hits towards the preview scene's point
//! light (occlusion queries).
//!
//! * Our tracer on 1 and 2 rayon threads, rays in 16x16 tiles: one ray at a time
//!   (`Geometry::closest_hit` of the `MeshGeometry`, the tile's pixels row by row) and a
//!   tile's rays as one batch (`Geometry::closest_hits`, the rays in the renderer's order:
//!   packets of `geometry::PACKET` = 4x2 neighbours one after the other, see
//!   `render::render`); BVH build time (median of 3), bytes, Mrays/s (median, min and max
//!   of 5 frames after a warm-up), BVH nodes and triangle tests per ray, on the SIMD
//!   backend of the process (`SDFMESH_SIMD=portable cargo bench --bench primary_rays`
//!   times the portable one).
//! * Shadow rays: from each of our primary hits, moved off the surface as the renderer
//!   does (`render::tracer::spawn_offset` along the facing normal), towards the preview
//!   scene's point light, where the light is in front of the surface; a tile's shadow rays
//!   in the renderer's order (those of the primary rays' batch order, rays without one
//!   left out). Ours one at a time (`Geometry::any_hit`) and as one batch per tile
//!   (`Geometry::any_hits`).
//! * A sweep of obvhs build presets, leaf sizes and reinsertion ratios (1 thread; each
//!   Bvh2 is collapsed into the 8-wide BVH `MeshGeometry` traces) to choose
//!   `MeshGeometry::BUILD_PARAMS` by measurement. Nodes per ray count 8-wide nodes visited,
//!   tests per ray triangles. `--no-presets` skips it (it takes most of the run).
//! * With `--features embree` (Debian's `libembree-dev`, Embree 3;
//!   `primary_rays/embree.rs`), the same rays traced by Embree one ray at a time (`rtcIntersect1`), in packets of 4, 8 and (where the
//!   device has native 16-wide packets) 16 neighbouring rays of the renderer's order
//!   (`rtcIntersect4/8/16`), as a coherent stream of one tile (`rtcIntersect1M`) and one
//!   ray at a time in its robust mode (watertight, like ours); the shadow rays likewise
//!   (`rtcOccluded1/4/8/16/1M`); the ratio of our throughput to Embree's, and a per-ray
//!   check that both tracers agree on hit/miss and on `t` (shadow rays: on occluded or
//!   not).
//!
//! Frames of the tracers being compared are interleaved round by round (primary tracers
//! among themselves, then shadow tracers), so background load affects all of them alike;
//! besides wall-clock throughput, each frame's process CPU time is measured, and rays per
//! CPU-second is reported too (it is what a frame would reach per thread on an otherwise
//! idle machine, and it is far less noisy when other jobs share the cores). `cargo bench
//! --bench primary_rays [MESH-SUBSTRING] [--no-presets] [--frames=N]` runs it (`--frames`:
//! timed frames per tracer, 5 by default; more steady the medians on a loaded machine);
//! without `--bench` (as under `cargo test --all-targets`) it runs a quick smoke check on
//! a small image instead, and with `--quick` the full-size frames on one thread without
//! the preset sweep.
//! `tools/bench-embree` installs Embree and runs it with the feature.

use sdfmesh::metrics::median;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use obvhs::BvhBuildParams;
use rayon::ThreadPool;
use rayon::prelude::*;
use sdfmesh::geometry::mesh::{MeshGeometry, MeshLayout, Shading};
use sdfmesh::geometry::{Geometry, Hit, PACKET, Ray, RayStats};
use sdfmesh::mesh::{TriangleMesh, load_mesh};
use sdfmesh::render::tracer::spawn_offset;
use sdfmesh::scene::camera::RayGenerator;
use sdfmesh::scene::transform::Transform;
use sdfmesh::scene::{Light, mesh_preview_scene};

/// Side of a square tile of rays.
const TILE: u32 = 16;
/// Rays per tile (slots in the output buffer; edge tiles leave some unused).
const TILE_RAYS: usize = (TILE * TILE) as usize;
/// Output value of a pixel whose ray missed.
const MISS: f32 = f32::INFINITY;
/// Output value of a tile slot outside the image (never compared, never counted), or of
/// a pixel without a shadow ray.
const UNUSED: f32 = -1.0;
/// Output value of an occluded shadow ray (an unoccluded one gives `MISS`).
const OCCLUDED: f32 = 1.0;
/// Width and height of a packet of primary rays in the renderer (`render::render`): 4x2
/// pixels, `PACKET_W * PACKET_H = PACKET`.
const PACKET_W: u32 = 4;
/// See [`PACKET_W`].
const PACKET_H: u32 = 2;
const _: () = assert!((PACKET_W * PACKET_H) as usize == PACKET);

/// What one run measures.
#[derive(Clone, Copy, Debug)]
struct Plan {
    /// Image side in pixels.
    size: u32,
    /// Timed frames per tracer (after one warm-up frame).
    frames: usize,
    /// BVH builds timed per configuration.
    builds: usize,
    /// Thread counts to trace with.
    threads: &'static [usize],
    /// Whether to run the build-preset sweep (`--no-presets` turns it off).
    presets: bool,
}

const FULL: Plan = Plan { size: 1000, frames: 5, builds: 3, threads: &[1, 2], presets: true };

/// `--quick`: the full-size frames on one thread, without the preset sweep (for
/// profiling and quick comparisons while tuning).
const QUICK: Plan = Plan { size: 1000, frames: 5, builds: 1, threads: &[1], presets: false };

const SMOKE: Plan = Plan { size: 64, frames: 1, builds: 1, threads: &[1], presets: false };

/// CPU time of the whole process (all threads), seconds, where the platform tells.
fn process_cpu_secs() -> Option<f64> {
    #[cfg(unix)]
    {
        let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: a valid clock id and a valid out-pointer.
        let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
        (rc == 0).then_some(t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9)
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// A frame of `size` x `size` pixels cut into 16x16 tiles; the output buffer holds
/// `TILE_RAYS` slots per tile, slot `ly * 16 + lx` for pixel (`x0 + lx`, `y0 + ly`).
#[derive(Clone, Copy, Debug)]
struct Frame {
    camera: RayGenerator,
    size: u32,
    tiles_x: u32,
}

impl Frame {
    fn new(camera: RayGenerator, size: u32) -> Self {
        Frame { camera, size, tiles_x: size.div_ceil(TILE) }
    }

    fn tiles(&self) -> usize {
        (self.tiles_x * self.tiles_x) as usize
    }

    fn rays(&self) -> u64 {
        u64::from(self.size) * u64::from(self.size)
    }

    /// Top-left pixel of tile `i`.
    fn origin(&self, i: usize) -> (u32, u32) {
        let i = i as u32;
        ((i % self.tiles_x) * TILE, (i / self.tiles_x) * TILE)
    }

    /// Pixel of slot `s` of the tile with top-left `(x0, y0)`, if inside the image.
    #[inline]
    fn pixel(&self, (x0, y0): (u32, u32), s: usize) -> Option<(u32, u32)> {
        let (x, y) = (x0 + s as u32 % TILE, y0 + s as u32 / TILE);
        (x < self.size && y < self.size).then_some((x, y))
    }

    /// The slots of tile `i`'s pixels inside the image in the order the renderer hands
    /// them to `Geometry::closest_hits` (`render::render`): packets of
    /// `PACKET_W x PACKET_H` pixels, clipped at the edge, one after the other, rows of
    /// packets top to bottom. Returns the slots and their count.
    fn packet_order(&self, i: usize) -> ([u16; TILE_RAYS], usize) {
        let (x0, y0) = self.origin(i);
        let (tw, th) = (TILE.min(self.size - x0), TILE.min(self.size - y0));
        let mut order = [0u16; TILE_RAYS];
        let mut n = 0;
        for py in (0..th).step_by(PACKET_H as usize) {
            for px in (0..tw).step_by(PACKET_W as usize) {
                for y in py..(py + PACKET_H).min(th) {
                    for x in px..(px + PACKET_W).min(tw) {
                        order[n] = (y * TILE + x) as u16;
                        n += 1;
                    }
                }
            }
        }
        (order, n)
    }

    /// Pixel of output buffer index `i`, if inside the image.
    fn pixel_of_index(&self, i: usize) -> Option<(u32, u32)> {
        self.pixel(self.origin(i / TILE_RAYS), i % TILE_RAYS)
    }
}

/// Something that traces one tile: fills its `TILE_RAYS` output slots with the hit
/// distance, `MISS` or `UNUSED`, and returns its work counters.
type TileFn<'a> = Box<dyn Fn(&Frame, usize, &mut [f32]) -> RayStats + Sync + 'a>;

/// One tracer under test, with the timings and output of its frames.
struct Contender<'a> {
    tracer: String,
    build_ms: Option<f64>,
    build_cpu_ms: Option<f64>,
    bytes: String,
    trace: TileFn<'a>,
    /// Wall-clock seconds of each timed frame.
    secs: Vec<f64>,
    /// Process CPU seconds of each timed frame (empty where unavailable).
    cpu_secs: Vec<f64>,
    stats: RayStats,
    out: Vec<f32>,
}

impl<'a> Contender<'a> {
    fn new(tracer: impl Into<String>, trace: TileFn<'a>) -> Self {
        Contender {
            tracer: tracer.into(),
            build_ms: None,
            build_cpu_ms: None,
            bytes: "-".into(),
            trace,
            secs: Vec::new(),
            cpu_secs: Vec::new(),
            stats: RayStats::default(),
            out: Vec::new(),
        }
    }

    /// Traces one frame on `pool`, keeping its output and counters; returns its wall
    /// and CPU seconds.
    fn frame(&mut self, pool: &ThreadPool, frame: &Frame) -> (f64, Option<f64>) {
        let mut out = std::mem::take(&mut self.out);
        out.clear();
        out.resize(frame.tiles() * TILE_RAYS, UNUSED);
        let trace = &self.trace;
        let cpu0 = process_cpu_secs();
        let start = Instant::now();
        let stats = pool.install(|| {
            out.par_chunks_mut(TILE_RAYS).enumerate().map(|(i, slots)| trace(frame, i, slots)).reduce(
                RayStats::default,
                |mut a, b| {
                    a.add(&b);
                    a
                },
            )
        });
        let wall = start.elapsed().as_secs_f64();
        let cpu = cpu0.zip(process_cpu_secs()).map(|(a, b)| b - a);
        self.out = out;
        self.stats = stats;
        (wall, cpu)
    }

    /// Rays one frame traces, as the tracer counts them (`RayStats::rays`: the image's
    /// pixels for primary rays, fewer for shadow rays).
    fn rays(&self) -> f64 {
        self.stats.rays as f64
    }

    /// Mrays per wall-clock second of each timed frame.
    fn mrays(&self, _frame: &Frame) -> Vec<f64> {
        self.secs.iter().map(|s| self.rays() / s / 1e6).collect()
    }

    /// Median Mrays per CPU-second over the timed frames, if measured.
    fn mrays_cpu(&self, _frame: &Frame) -> Option<f64> {
        (!self.cpu_secs.is_empty())
            .then(|| median(&self.cpu_secs.iter().map(|s| self.rays() / s / 1e6).collect::<Vec<_>>()))
    }
}

/// Runs `frames` timed frames of every contender after one warm-up frame each,
/// interleaved: round r traces frame r of each contender in turn.
fn race(contenders: &mut [Contender<'_>], pool: &ThreadPool, frame: &Frame, frames: usize) {
    for c in contenders.iter_mut() {
        c.frame(pool, frame);
    }
    for _ in 0..frames {
        for c in contenders.iter_mut() {
            let (wall, cpu) = c.frame(pool, frame);
            c.secs.push(wall);
            c.cpu_secs.extend(cpu);
        }
    }
}

fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| (lo.min(x), hi.max(x)))
}

/// Per-ray agreement of two frames' outputs.
#[derive(Clone, Debug, Default)]
struct Agreement {
    rays: u64,
    hits: u64,
    /// Hit in the first frame, miss in the second.
    only_first: u64,
    /// Miss in the first frame, hit in the second.
    only_second: u64,
    /// Both hit, `t` differing by more than 1e-4 relative.
    t_off: u64,
    /// Largest relative `t` difference where both hit.
    max_rel_dt: f64,
    /// The first few disagreeing rays: pixel, first `t`, second `t` (inf: miss).
    examples: Vec<(u32, u32, f32, f32)>,
}

impl Agreement {
    fn of(frame: &Frame, a: &[f32], b: &[f32]) -> Self {
        let mut g = Agreement::default();
        for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
            if x == UNUSED {
                continue;
            }
            g.rays += 1;
            let disagree = match (x != MISS, y != MISS) {
                (true, true) => {
                    g.hits += 1;
                    let rel = f64::from((x - y).abs()) / f64::from(x.abs().max(1e-30));
                    g.max_rel_dt = g.max_rel_dt.max(rel);
                    g.t_off += u64::from(rel > 1e-4);
                    rel > 1e-4
                }
                (true, false) => {
                    g.only_first += 1;
                    true
                }
                (false, true) => {
                    g.only_second += 1;
                    true
                }
                (false, false) => false,
            };
            if disagree
                && g.examples.len() < 3
                && let Some((px, py)) = frame.pixel_of_index(i)
            {
                g.examples.push((px, py, x, y));
            }
        }
        g
    }

    fn mismatches(&self) -> u64 {
        self.only_first + self.only_second + self.t_off
    }

    fn describe(&self, first: &str, second: &str) -> String {
        let mut s = format!(
            "{first} vs {second}: {} rays, {} both hit; hit only by {first} {}, only by {second} {}, \
             t differs > 1e-4 rel {}; max rel dt {:.2e}",
            self.rays, self.hits, self.only_first, self.only_second, self.t_off, self.max_rel_dt
        );
        for (x, y, a, b) in &self.examples {
            s += &format!("\n    pixel ({x}, {y}): t {a} vs {b}");
        }
        s
    }

    /// [`Self::describe`] for two frames of shadow rays (`OCCLUDED` or `MISS` per ray).
    fn describe_occlusion(&self, first: &str, second: &str) -> String {
        let word = |t: f32| if t == MISS { "unoccluded" } else { "occluded" };
        let mut s = format!(
            "{first} vs {second}: {} shadow rays, {} occluded by both; occluded only by {first} {}, \
             only by {second} {}",
            self.rays, self.hits, self.only_first, self.only_second
        );
        for (x, y, a, b) in &self.examples {
            s += &format!("\n    shadow ray of pixel ({x}, {y}): {} vs {}", word(*a), word(*b));
        }
        s
    }
}

fn pool(threads: usize) -> ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("rayon thread pool")
}

/// Our tracer on one tile.
fn ours_tile(geom: &MeshGeometry) -> TileFn<'_> {
    Box::new(move |frame: &Frame, tile: usize, slots: &mut [f32]| {
        let o = frame.origin(tile);
        let mut stats = RayStats::default();
        for (s, slot) in slots.iter_mut().enumerate() {
            if let Some((x, y)) = frame.pixel(o, s) {
                let ray = frame.camera.ray(x, y);
                stats.rays += 1;
                *slot = geom.closest_hit(&ray, 0.0, f32::INFINITY, &mut stats).map_or(MISS, |h| h.t);
            }
        }
        stats
    })
}

/// Tracer name of our one-by-one rows (primary rays): what they call.
const OURS_ONE: &str = "ours closest_hit";
/// Ours in the compact layout, one ray at a time (its batches go one by one too).
const OURS_COMPACT: &str = "ours compact closest_hit";
/// Tracer name of our batch rows (primary rays): what they call.
const OURS_BATCH: &str = "ours closest_hits batch";
/// Tracer name of our one-by-one shadow rows.
const OURS_SHADOW_ONE: &str = "ours any_hit";
/// Tracer name of our batch shadow rows: what they call.
const OURS_SHADOW_BATCH: &str = "ours any_hits batch";

/// Our tracer on one tile as the renderer calls it: the tile's rays in the renderer's
/// order ([`Frame::packet_order`]) as one `Geometry::closest_hits` batch.
fn ours_batch_tile(geom: &MeshGeometry) -> TileFn<'_> {
    Box::new(move |frame: &Frame, tile: usize, slots: &mut [f32]| {
        let o = frame.origin(tile);
        let (order, n) = frame.packet_order(tile);
        let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); TILE_RAYS];
        for (ray, &s) in rays.iter_mut().zip(&order[..n]) {
            let (x, y) = frame.pixel(o, s as usize).expect("packet_order keeps pixels inside the image");
            *ray = frame.camera.ray(x, y);
        }
        let mut t_max = [f32::INFINITY; TILE_RAYS];
        let mut hits: [Option<Hit>; TILE_RAYS] = [None; TILE_RAYS];
        let mut stats = RayStats { rays: n as u64, ..RayStats::default() };
        Geometry::closest_hits(geom, &rays[..n], 0.0, &mut t_max[..n], &mut hits[..n], &mut stats);
        for (hit, &s) in hits[..n].iter().zip(&order[..n]) {
            slots[s as usize] = hit.map_or(MISS, |h| h.t);
        }
        stats
    })
}

/// The shadow rays of a frame: from each of our primary hits towards one point light,
/// grouped by tile, each tile's in the renderer's order.
struct Shadows {
    /// Rays of tile `i`: `start[i]..start[i + 1]`.
    start: Vec<usize>,
    rays: Vec<Ray>,
    /// How far each ray goes: the distance to the light.
    reach: Vec<f32>,
    /// The tile slot (primary pixel) each ray belongs to.
    slot: Vec<u16>,
}

impl Shadows {
    /// The shadow rays of `geom`'s primary hits in `frame` towards a point light at
    /// `light`, spawned as the renderer spawns them (`render::tracer`): off the hit
    /// along the normal facing the viewer by `spawn_offset`, only where the light is in
    /// front of the (facing) shading normal.
    fn new(geom: &MeshGeometry, frame: &Frame, light: Vec3) -> Self {
        let mut sh = Shadows { start: vec![0], rays: Vec::new(), reach: Vec::new(), slot: Vec::new() };
        let mut stats = RayStats::default();
        for tile in 0..frame.tiles() {
            let o = frame.origin(tile);
            let (order, n) = frame.packet_order(tile);
            for &s in &order[..n] {
                let (x, y) = frame.pixel(o, s as usize).expect("packet_order keeps pixels inside the image");
                let ray = frame.camera.ray(x, y);
                let Some(hit) = geom.closest_hit(&ray, 0.0, f32::INFINITY, &mut stats) else { continue };
                // render::tracer's surface_frame and batch_shadows, for one point light.
                let leaving = hit.normal.dot(ray.dir) > 0.0;
                let face = if leaving { -hit.normal } else { hit.normal };
                let n = if leaving { -hit.shading_normal } else { hit.shading_normal };
                let n = if n.dot(face) > 0.0 { n } else { face };
                let above = hit.point + face * spawn_offset(&hit);
                let v = light - above;
                let d = v.length();
                if d > 0.0 && n.dot(v / d) > 0.0 {
                    sh.rays.push(Ray::spawned(above, v / d, ray.spread + hit.t));
                    sh.reach.push(d);
                    sh.slot.push(s);
                }
            }
            sh.start.push(sh.rays.len());
        }
        sh
    }

    /// The index range of tile `i`'s rays.
    fn of_tile(&self, i: usize) -> std::ops::Range<usize> {
        self.start[i]..self.start[i + 1]
    }
}

/// Our tracer on one tile's shadow rays, one at a time (`Geometry::any_hit`).
fn ours_shadow_tile<'a>(geom: &'a MeshGeometry, sh: &'a Shadows) -> TileFn<'a> {
    Box::new(move |_frame: &Frame, tile: usize, slots: &mut [f32]| {
        let r = sh.of_tile(tile);
        let mut stats = RayStats { rays: r.len() as u64, ..RayStats::default() };
        for j in r {
            let blocked = Geometry::any_hit(geom, &sh.rays[j], 0.0, sh.reach[j], &mut stats);
            slots[sh.slot[j] as usize] = if blocked { OCCLUDED } else { MISS };
        }
        stats
    })
}

/// Our tracer on one tile's shadow rays as the renderer calls it: one
/// `Geometry::any_hits` batch.
fn ours_shadow_batch_tile<'a>(geom: &'a MeshGeometry, sh: &'a Shadows) -> TileFn<'a> {
    Box::new(move |_frame: &Frame, tile: usize, slots: &mut [f32]| {
        let r = sh.of_tile(tile);
        let m = r.len();
        let mut blocked = [false; TILE_RAYS];
        let mut stats = RayStats { rays: m as u64, ..RayStats::default() };
        Geometry::any_hits(
            geom,
            &sh.rays[r.clone()],
            0.0,
            &sh.reach[r.clone()],
            &mut blocked[..m],
            &mut stats,
        );
        for (&b, &s) in blocked[..m].iter().zip(&sh.slot[r]) {
            slots[s as usize] = if b { OCCLUDED } else { MISS };
        }
        stats
    })
}

/// Builds `mesh` with `params` `builds` times; returns the last geometry and the
/// median build time in ms (`MeshGeometry::build_time`: boxes, BVH, reordering) by the
/// wall clock and in process CPU time.
fn build_ours(
    mesh: &TriangleMesh,
    params: BvhBuildParams,
    builds: usize,
) -> (MeshGeometry, f64, Option<f64>) {
    let mut times = Vec::new();
    let mut cpu_times = Vec::new();
    let mut geom = None;
    for _ in 0..builds.max(1) {
        let copy = mesh.clone();
        let cpu0 = process_cpu_secs();
        let g =
            MeshGeometry::with_params(copy, Shading::Flat, Transform::IDENTITY, 0, "bench".into(), params);
        cpu_times.extend(cpu0.zip(process_cpu_secs()).map(|(a, b)| (b - a) * 1e3));
        times.push(g.build_time.as_secs_f64() * 1e3);
        geom = Some(g);
    }
    let cpu = (!cpu_times.is_empty()).then(|| median(&cpu_times));
    (geom.expect("at least one build"), median(&times), cpu)
}

/// One table row.
struct Row {
    mesh: String,
    tracer: String,
    threads: usize,
    build_ms: Option<f64>,
    mrays: Vec<f64>,
    mrays_cpu: Option<f64>,
    /// Our one-by-one tracer / this row (on that row itself: / Embree's one-ray row), by
    /// wall clock and by CPU time.
    ratio: Option<f64>,
    ratio_cpu: Option<f64>,
    /// Our batch tracer / this row (on that row itself: / Embree's 8-ray packets), by
    /// wall clock and by CPU time.
    ratio_batch: Option<f64>,
    ratio_batch_cpu: Option<f64>,
    nodes_per_ray: Option<f64>,
    tests_per_ray: Option<f64>,
    bytes: String,
    mismatches: String,
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("-".to_string(), |x| format!("{x:.prec$}"))
}

fn print_table(rows: &[Row]) {
    println!(
        "{:<16} {:<23} {:>3} {:>8} {:>7} {:>6} {:>6} {:>7} {:>6} {:>6} {:>6} {:>6} {:>7} {:>7} {:>21} {:>5}",
        "mesh",
        "tracer",
        "thr",
        "build ms",
        "Mray/s",
        "min",
        "max",
        "cpu M/s",
        "ratio",
        "cpu r",
        "batch",
        "cpu b",
        "nodes/r",
        "tests/r",
        "bytes (total/accel)",
        "mism."
    );
    for r in rows {
        let (lo, hi) = min_max(&r.mrays);
        println!(
            "{:<16} {:<23} {:>3} {:>8} {:>7.2} {:>6.2} {:>6.2} {:>7} {:>6} {:>6} {:>6} {:>6} {:>7} {:>7} {:>21} {:>5}",
            r.mesh,
            r.tracer,
            r.threads,
            opt(r.build_ms, 1),
            median(&r.mrays),
            lo,
            hi,
            opt(r.mrays_cpu, 2),
            opt(r.ratio, 2),
            opt(r.ratio_cpu, 2),
            opt(r.ratio_batch, 2),
            opt(r.ratio_batch_cpu, 2),
            opt(r.nodes_per_ray, 1),
            opt(r.tests_per_ray, 2),
            r.bytes,
            r.mismatches
        );
    }
}

/// The issue's targets read off the table: our batch rows against Embree's 8-ray
/// packets (`rtcIntersect8`, `rtcOccluded8`), >= 1.0 wanted.
fn print_targets(rows: &[Row]) {
    if !rows.iter().any(|r| r.tracer == embree::PACKET8) {
        return;
    }
    println!("\ntargets: ours batch / embree packets of 8, by wall clock (by CPU time); >= 1.0 wanted");
    for r in rows.iter().filter(|r| r.tracer == OURS_BATCH || r.tracer == OURS_SHADOW_BATCH) {
        let peer = if r.tracer == OURS_BATCH { embree::PACKET8 } else { embree::OCCLUDED8 };
        println!(
            "  {:<16} {} thr  {:<23} / {:<21} {} ({})",
            r.mesh,
            r.threads,
            r.tracer,
            peer,
            opt(r.ratio_batch, 2),
            opt(r.ratio_batch_cpu, 2)
        );
    }
}

fn per_ray(total: u64, rays: u64) -> Option<f64> {
    (rays > 0).then(|| total as f64 / rays as f64)
}

/// The obvhs presets compared, by name: the five presets as they are (leaves of up to 8
/// triangles, which the 8-wide BVH splits into packets of at most 4), the fast preset with
/// 1 to 4 triangles per leaf (one packet per leaf), and the fast preset with 4 per leaf
/// and more of obvhs's reinsertion optimisation (the ratio of nodes it tries to move;
/// the fast preset's is 0.02).
fn presets() -> Vec<(String, BvhBuildParams)> {
    let mut v: Vec<(String, BvhBuildParams)> = vec![
        ("fastest_build".into(), BvhBuildParams::fastest_build()),
        ("very_fast_build".into(), BvhBuildParams::very_fast_build()),
        ("fast_build".into(), BvhBuildParams::fast_build()),
        ("medium_build".into(), BvhBuildParams::medium_build()),
        ("slow_build".into(), BvhBuildParams::slow_build()),
    ];
    let fast = BvhBuildParams::fast_build();
    for leaf in 1..=4 {
        v.push((format!("fast leaf={leaf}"), BvhBuildParams { max_prims_per_leaf: leaf, ..fast }));
    }
    for ratio in [0.1, 0.2, 0.5, 1.0] {
        v.push((
            format!("fast leaf=4 reinsert={ratio}"),
            BvhBuildParams { max_prims_per_leaf: 4, reinsertion_batch_ratio: ratio, ..fast },
        ));
    }
    // Mark the rows that build what `MeshGeometry::BUILD_PARAMS` builds.
    let current = MeshGeometry::BUILD_PARAMS;
    for (name, p) in &mut v {
        if format!("{p:?}") == format!("{current:?}") {
            name.push_str(" (current)");
        }
    }
    v
}

/// Compares the build presets at 1 thread, frames interleaved across presets.
fn preset_sweep(label: &str, mesh: &TriangleMesh, frame: &Frame, plan: &Plan) {
    let pool1 = pool(1);
    let built: Vec<(String, MeshGeometry, f64, Option<f64>)> = presets()
        .into_iter()
        .map(|(name, params)| {
            let (g, ms, cpu) = build_ours(mesh, params, plan.builds);
            (name, g, ms, cpu)
        })
        .collect();
    let mut cs: Vec<Contender<'_>> = built
        .iter()
        .map(|(name, g, ms, cpu)| {
            let mut c = Contender::new(name.clone(), ours_tile(g));
            c.build_ms = Some(*ms);
            c.build_cpu_ms = *cpu;
            c.bytes = format!("{}/{}", g.bytes_used(), g.accel_bytes());
            c
        })
        .collect();
    race(&mut cs, &pool1, frame, plan.frames);
    println!(
        "\nBVH build presets on {label}, 1 thread (obvhs builds from boxes, so slow_build's \
         pre_split has no effect; the Bvh2 is collapsed into the 8-wide BVH either way)"
    );
    println!(
        "{:<26} {:>8} {:>7} {:>7} {:>6} {:>6} {:>7} {:>7} {:>7} {:>21}",
        "preset",
        "build ms",
        "cpu ms",
        "Mray/s",
        "min",
        "max",
        "cpu M/s",
        "nodes/r",
        "tests/r",
        "bytes (total/accel)"
    );
    for c in &cs {
        let m = c.mrays(frame);
        let (lo, hi) = min_max(&m);
        println!(
            "{:<26} {:>8.1} {:>7} {:>7.2} {:>6.2} {:>6.2} {:>7} {:>7.1} {:>7.2} {:>21}",
            c.tracer,
            c.build_ms.unwrap_or(f64::NAN),
            opt(c.build_cpu_ms, 1),
            median(&m),
            lo,
            hi,
            opt(c.mrays_cpu(frame), 2),
            per_ray(c.stats.bvh_nodes, c.stats.rays).unwrap_or(f64::NAN),
            per_ray(c.stats.prim_tests, c.stats.rays).unwrap_or(f64::NAN),
            c.bytes
        );
    }
}

/// The table rows of one race whose contenders 0 and 1 are ours one by one and ours as
/// batches: ratios of those two to every row (on their own rows, to the Embree rows named
/// by `peers`, one-ray and 8-ray packets), work counts of ours, and the agreement of every
/// row with contender 0, printed where `print` (`occlusion`: the outputs are shadow rays).
fn race_rows(
    label: &str,
    threads: usize,
    cs: &[Contender<'_>],
    frame: &Frame,
    peers: [&str; 2],
    occlusion: bool,
    print: bool,
) -> Vec<Row> {
    let speed = |c: &Contender<'_>| (median(&c.mrays(frame)), c.mrays_cpu(frame));
    let ours = [speed(&cs[0]), speed(&cs[1])];
    // Ours `k` / contender `c`, wall clock and CPU time; on our own row `k`, / peer `k`.
    let ratio_of = |k: usize, i: usize| {
        let other = if i == k { cs.iter().find(|c| c.tracer == peers[k]) } else { Some(&cs[i]) };
        let (wall, cpu) = match other {
            Some(c) => speed(c),
            None => return (None, None),
        };
        (Some(ours[k].0 / wall), ours[k].1.zip(cpu).map(|(a, b)| a / b))
    };
    let mut rows = Vec::new();
    for (i, c) in cs.iter().enumerate() {
        let agreement = (i > 0).then(|| Agreement::of(frame, &cs[0].out, &c.out));
        let (ratio, ratio_cpu) = ratio_of(0, i);
        let (ratio_batch, ratio_batch_cpu) = ratio_of(1, i);
        // Only our tracers count BVH nodes and triangle tests.
        let counted = c.stats.bvh_nodes > 0;
        rows.push(Row {
            mesh: label.to_string(),
            tracer: c.tracer.clone(),
            threads,
            build_ms: c.build_ms,
            mrays: c.mrays(frame),
            mrays_cpu: c.mrays_cpu(frame),
            ratio,
            ratio_cpu,
            ratio_batch,
            ratio_batch_cpu,
            nodes_per_ray: counted.then(|| per_ray(c.stats.bvh_nodes, c.stats.rays)).flatten(),
            tests_per_ray: counted.then(|| per_ray(c.stats.prim_tests, c.stats.rays)).flatten(),
            bytes: c.bytes.clone(),
            mismatches: agreement.as_ref().map_or("-".into(), |g| g.mismatches().to_string()),
        });
        if let Some(g) = agreement
            && print
        {
            let text = if occlusion {
                g.describe_occlusion(&cs[0].tracer, &c.tracer)
            } else {
                g.describe(&cs[0].tracer, &c.tracer)
            };
            println!("agreement {text}");
        }
    }
    rows
}

/// Benchmarks one mesh; returns its table rows.
fn bench_mesh(path: &Path, plan: &Plan) -> Vec<Row> {
    let label = path.file_stem().map_or_else(|| "mesh".into(), |s| s.to_string_lossy().into_owned());
    let (mesh, report) = match load_mesh(path) {
        Ok(m) => m,
        Err(e) => {
            println!("note: skipping {}: cannot load: {e}", path.display());
            return Vec::new();
        }
    };
    let mesh = Arc::new(mesh);
    let scene = mesh_preview_scene(Arc::clone(&mesh), path.to_path_buf(), Shading::Flat);
    let mut cam = scene.camera;
    cam.width = plan.size;
    cam.height = plan.size;
    let frame = Frame::new(RayGenerator::new(&cam), plan.size);
    println!(
        "\n{label}: {} triangles, {} vertices ({} triangles read, {} degenerate dropped); {}x{} rays",
        mesh.triangle_count(),
        mesh.positions.len(),
        report.triangles_read,
        report.degenerate_dropped,
        plan.size,
        plan.size
    );

    let (ours, ours_ms, ours_cpu_ms) = build_ours(&mesh, MeshGeometry::BUILD_PARAMS, plan.builds);
    println!(
        "ours: {}; build {ours_ms:.1} ms median of {} ({} ms CPU), single-threaded",
        ours.describe(),
        plan.builds,
        opt(ours_cpu_ms, 1)
    );
    #[cfg(feature = "embree")]
    let emb = embree::Bench::new(&mesh, plan.builds);

    // The shadow rays of our primary hits towards the preview scene's point light.
    let light = scene
        .lights
        .iter()
        .find_map(|l| if let Light::Point { position, .. } = l { Some(*position) } else { None })
        .expect("the preview scene has a point light");
    let shadows = Shadows::new(&ours, &frame, light);
    println!(
        "shadow rays: {} (from our hits, where the point light at [{:.4} {:.4} {:.4}] is in front of \
         the surface), t in [0, distance to the light]",
        shadows.rays.len(),
        light.x,
        light.y,
        light.z
    );
    println!(
        "ours batch rows: {OURS_BATCH} = MeshGeometry's Geometry::closest_hits, {OURS_SHADOW_BATCH} = \
         its Geometry::any_hits, one call per tile (up to {TILE_RAYS} rays in the renderer's order, \
         packets of {PACKET}); MeshGeometry::prefers_packets() = {}",
        ours.prefers_packets()
    );

    let mut rows = Vec::new();
    let mut ours_out: Vec<f32> = Vec::new();
    for &threads in plan.threads {
        let pool = pool(threads);
        let bytes = format!("{}/{}", ours.bytes_used(), ours.accel_bytes());
        // Primary rays: ours one by one (index 0) and as batches (index 1), then Embree's.
        let mut cs = vec![
            Contender::new(OURS_ONE, ours_tile(&ours)),
            Contender::new(OURS_BATCH, ours_batch_tile(&ours)),
        ];
        for c in &mut cs {
            c.build_ms = Some(ours_ms);
            c.bytes = bytes.clone();
        }
        #[cfg(feature = "embree")]
        cs.extend(emb.contenders());
        race(&mut cs, &pool, &frame, plan.frames);
        if ours_out.is_empty() {
            ours_out = cs[0].out.clone();
            let hits = ours_out.iter().filter(|&&t| t != UNUSED && t != MISS).count();
            println!(
                "ours: {hits} of {} rays hit ({:.1}%)",
                frame.rays(),
                100.0 * hits as f64 / frame.rays() as f64
            );
        }
        let first = threads == plan.threads[0];
        rows.extend(race_rows(
            &label,
            threads,
            &cs,
            &frame,
            [embree::ONE_RAY, embree::PACKET8],
            false,
            first,
        ));
        drop(cs);

        // Shadow rays: ours one by one (index 0) and as batches (index 1), then Embree's.
        let mut cs = vec![
            Contender::new(OURS_SHADOW_ONE, ours_shadow_tile(&ours, &shadows)),
            Contender::new(OURS_SHADOW_BATCH, ours_shadow_batch_tile(&ours, &shadows)),
        ];
        for c in &mut cs {
            c.build_ms = Some(ours_ms);
            c.bytes = bytes.clone();
        }
        #[cfg(feature = "embree")]
        cs.extend(emb.shadow_contenders(&shadows));
        race(&mut cs, &pool, &frame, plan.frames);
        rows.extend(race_rows(
            &label,
            threads,
            &cs,
            &frame,
            [embree::OCCLUDED1, embree::OCCLUDED8],
            true,
            first,
        ));
    }
    compact_race(&mesh, &ours, &frame, plan);
    #[cfg(feature = "embree")]
    println!("agreement {}", emb.robust_agreement(&frame, &ours_out).describe("ours", "embree robust"));
    if plan.presets {
        preset_sweep(&label, &mesh, &frame, plan);
    }
    rows
}

/// The compact layout ([`MeshLayout::Compact`]) against the full one (`full`), one ray at
/// a time, frames interleaved: bytes per triangle (total and BVH, as
/// `MeshShape::bvh_bytes` counts it) and throughput by the wall clock and by CPU time.
fn compact_race(mesh: &TriangleMesh, full: &MeshGeometry, frame: &Frame, plan: &Plan) {
    let params = MeshGeometry::BUILD_PARAMS;
    let compact = MeshGeometry::with_options(
        mesh.clone(),
        Shading::Flat,
        Transform::IDENTITY,
        0,
        "bench".into(),
        params,
        MeshLayout::Compact,
    );
    let tris = mesh.triangle_count() as f64;
    let per_tri = |g: &MeshGeometry| (g.bytes_used() as f64 / tris, g.shape().bvh_bytes() as f64 / tris);
    let ((ft, fb), (ct, cb)) = (per_tri(full), per_tri(&compact));
    println!(
        "compact layout: {}; bytes per triangle total {ct:.1} (full {ft:.1}), BVH {cb:.1} (full {fb:.1})",
        compact.describe()
    );
    for &threads in plan.threads {
        let pool = pool(threads);
        let mut cs = vec![
            Contender::new(OURS_ONE, ours_tile(full)),
            Contender::new(OURS_COMPACT, ours_tile(&compact)),
        ];
        race(&mut cs, &pool, frame, plan.frames);
        let m = |c: &Contender<'_>| median(&c.mrays(frame));
        let cpu = |c: &Contender<'_>| c.mrays_cpu(frame);
        let (f, c) = (m(&cs[0]), m(&cs[1]));
        println!(
            "compact layout, {threads} thread(s): {c:.2} Mrays/s against full {f:.2} ({:.1}% of full); by CPU time {} \
             against {} ({}% of full)",
            100.0 * c / f,
            opt(cpu(&cs[1]), 2),
            opt(cpu(&cs[0]), 2),
            opt(cpu(&cs[1]).zip(cpu(&cs[0])).map(|(c, f)| 100.0 * c / f), 1)
        );
    }
}

/// Checks of the smoke run (`cargo test --all-targets`): [`Frame::packet_order`] is the
/// renderer's order on frames whose edge tiles are cut at odd places, and our batch rows
/// agree ray for ray with our one-by-one rows (the `Geometry::closest_hits` /
/// `Geometry::any_hits` contract).
fn smoke_checks(rows: &[Row]) {
    let cam = sdfmesh::scene::Camera { width: 37, height: 37, ..Default::default() };
    for size in [37, 64] {
        let frame = Frame::new(RayGenerator::new(&cam), size);
        for tile in 0..frame.tiles() {
            let o = frame.origin(tile);
            let (order, n) = frame.packet_order(tile);
            let mut inside: Vec<u16> =
                (0..TILE_RAYS as u16).filter(|&s| frame.pixel(o, s as usize).is_some()).collect();
            let mut got = order[..n].to_vec();
            got.sort_unstable();
            inside.sort_unstable();
            assert_eq!(got, inside, "packet_order of tile {tile} at size {size}: every pixel once");
            // A packet is a 4x2 block, clipped at the edge: the rays of a packet lie within
            // one block of 4 columns and 2 rows, and blocks come in the renderer's order.
            let block = |s: u16| (u32::from(s) / TILE / PACKET_H, u32::from(s) % TILE / PACKET_W);
            assert!(order[..n].windows(2).all(|w| block(w[0]) <= block(w[1])), "packets in order");
            if frame.pixel(o, TILE_RAYS - 1).is_some() {
                assert_eq!(order[..PACKET], [0, 1, 2, 3, 16, 17, 18, 19], "first packet of a full tile");
            }
        }
    }
    // No rows where the meshes are missing (the run says which it skipped).
    let ours = rows.iter().filter(|r| r.tracer == OURS_BATCH || r.tracer == OURS_SHADOW_BATCH);
    assert!(rows.is_empty() || ours.clone().count() == 2, "both batch rows ran");
    for r in ours {
        assert_eq!(r.mismatches, "0", "{} disagrees with our one-by-one tracer", r.tracer);
    }
    println!("smoke checks passed: packet order, our batches agree with our one-by-one rays");
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut plan = if args.iter().any(|a| a == "--quick") {
        QUICK
    } else if args.iter().any(|a| a == "--bench") {
        FULL
    } else {
        println!("smoke mode (run with `cargo bench --bench primary_rays` for the benchmark)");
        SMOKE
    };
    if args.iter().any(|a| a == "--no-presets") {
        plan.presets = false;
    }
    for a in args.iter().filter_map(|a| a.strip_prefix("--frames=")) {
        match a.parse::<usize>() {
            Ok(n) if n > 0 => plan.frames = n,
            _ => {
                eprintln!("error: --frames={a}: expected a positive number of frames");
                std::process::exit(2);
            }
        }
    }
    let filters: Vec<&String> = args.iter().filter(|a| !a.starts_with('-')).collect();
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes");
    let meshes: &[&str] = if plan.size == FULL.size {
        &["armadillo.obj", "stanford-bunny.obj"]
    } else {
        &["stanford-bunny.obj"]
    };
    println!(
        "primary rays: {0}x{0}, 16x16 tiles, closest hit only, t in [0, inf); shadow rays of their \
         hits towards a point light, occlusion only; threads {1:?}; {2} timed frames after 1 warm-up, \
         interleaved across tracers; {3} CPUs available; BVH-preset sweep {4}",
        plan.size,
        plan.threads,
        plan.frames,
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        if plan.presets { "on" } else { "off" }
    );
    let mut rows = Vec::new();
    for name in meshes {
        if !filters.is_empty() && !filters.iter().any(|f| name.contains(f.as_str())) {
            continue;
        }
        let path = dir.join(name);
        if !path.exists() {
            println!("note: skipping {name}: {} not found", path.display());
            continue;
        }
        rows.extend(bench_mesh(&path, &plan));
    }
    println!();
    print_table(&rows);
    if plan.size == SMOKE.size {
        smoke_checks(&rows);
    }
    println!(
        "\nMray/s: million rays per wall-clock second, median of the timed frames (min, max beside it). \
         cpu M/s: million rays per process CPU second (median): per-thread throughput, robust to other \
         load on the machine. ratio, cpu r: ours one by one ({OURS_ONE}; shadow rays {OURS_SHADOW_ONE}) / \
         that row at the same thread count, by wall clock and by CPU time; on that row itself, / {} \
         ({}). batch, cpu b: likewise for ours as batches ({OURS_BATCH}; {OURS_SHADOW_BATCH}); on that \
         row itself, / {} ({}). nodes/r, tests/r: our 8-wide BVH nodes visited and triangles tested \
         per ray. bytes: ours Geometry::bytes_used / MeshGeometry::accel_bytes; embree: net bytes its \
         memory monitor saw allocated for the scene / the same less the vertex and index \
         buffers. mism.: rays whose hit/miss (shadow rays: occluded or not) differs, or whose t \
         differs by more than 1e-4 relative, from ours one by one.",
        embree::ONE_RAY,
        embree::OCCLUDED1,
        embree::PACKET8,
        embree::OCCLUDED8
    );
    print_targets(&rows);
    #[cfg(not(feature = "embree"))]
    println!(
        "Embree rows disabled: run tools/bench-embree, or install libembree-dev and run \
         `cargo bench --bench primary_rays --features embree`."
    );
}

/// Stand-ins for the names the Embree rows use, so the code above compiles without it.
#[cfg(not(feature = "embree"))]
mod embree {
    /// Tracer name of the one-ray-at-a-time Embree rows.
    pub const ONE_RAY: &str = "embree rtcIntersect1";
    /// Tracer name of the Embree rows of 8-ray packets.
    pub const PACKET8: &str = "embree rtcIntersect8";
    /// Tracer name of the one-ray-at-a-time Embree shadow rows.
    pub const OCCLUDED1: &str = "embree rtcOccluded1";
    /// Tracer name of the Embree shadow rows of 8-ray packets.
    pub const OCCLUDED8: &str = "embree rtcOccluded8";
}

/// Embree 3 (Debian's libembree-dev) through a minimal hand-written FFI (a directory
/// without `main.rs`, so cargo does not take it for a benchmark of its own).
#[cfg(feature = "embree")]
#[path = "primary_rays/embree.rs"]
mod embree;
