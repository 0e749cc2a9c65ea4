//! Primary-ray throughput: 1M closest-hit rays (1000x1000 through the camera that
//! `mesh_preview_scene` frames a mesh with), no shading, on the armadillo and the
//! Stanford bunny.
//!
//! * Our tracer (`MeshGeometry::closest_hit`) on 1 and 2 rayon threads, rays in 16x16
//!   tiles: BVH build time (median of 3), bytes, Mrays/s (median, min and max of 5 frames
//!   after a warm-up), BVH nodes and triangle tests per ray, on the SIMD backend of the
//!   process (`SDFMESH_SIMD=portable cargo bench --bench primary_rays` times the portable
//!   one).
//! * A sweep of obvhs build presets, leaf sizes and reinsertion ratios (1 thread; each
//!   Bvh2 is collapsed into the 8-wide BVH `MeshGeometry` traces) to choose
//!   `MeshGeometry::BUILD_PARAMS` by measurement. Nodes per ray count 8-wide nodes visited, tests per ray triangles.
//! * With `--features embree` (Debian's `libembree-dev`, Embree 3), the same frames
//!   traced by Embree one ray at a time (`rtcIntersect1`), in packets of 8
//!   (`rtcIntersect8`), as a coherent stream of one tile (`rtcIntersect1M`) and one ray
//!   at a time in its robust mode (watertight, like ours), the ratio of our throughput to
//!   Embree's, and a per-ray check that both tracers agree on hit/miss and on `t`.
//!
//! Frames of the tracers being compared are interleaved round by round, so background
//! load affects all of them alike; besides wall-clock throughput, each frame's process
//! CPU time is measured, and rays per CPU-second is reported too (it is what a frame
//! would reach per thread on an otherwise idle machine, and it is far less noisy when
//! other jobs share the cores). `cargo bench --bench primary_rays [MESH-SUBSTRING]` runs
//! it; without `--bench` (as under `cargo test --all-targets`) it runs a quick smoke
//! check on a small image instead, and with `--quick` the full-size frames on one thread
//! without the preset sweep. `tools/bench-embree` installs Embree and runs it with
//! the feature.

use sdfmesh::metrics::median;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use obvhs::BvhBuildParams;
use rayon::ThreadPool;
use rayon::prelude::*;
use sdfmesh::geometry::mesh::{MeshGeometry, Shading};
use sdfmesh::geometry::{Geometry, RayStats};
use sdfmesh::mesh::{TriangleMesh, load_mesh};
use sdfmesh::scene::camera::RayGenerator;
use sdfmesh::scene::mesh_preview_scene;
use sdfmesh::scene::transform::Transform;

/// Side of a square tile of rays.
const TILE: u32 = 16;
/// Rays per tile (slots in the output buffer; edge tiles leave some unused).
const TILE_RAYS: usize = (TILE * TILE) as usize;
/// Output value of a pixel whose ray missed.
const MISS: f32 = f32::INFINITY;
/// Output value of a tile slot outside the image (never compared, never counted).
const UNUSED: f32 = -1.0;

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
    /// Whether to run the build-preset sweep.
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

    /// Mrays per wall-clock second of each timed frame.
    fn mrays(&self, frame: &Frame) -> Vec<f64> {
        self.secs.iter().map(|s| frame.rays() as f64 / s / 1e6).collect()
    }

    /// Median Mrays per CPU-second over the timed frames, if measured.
    fn mrays_cpu(&self, frame: &Frame) -> Option<f64> {
        (!self.cpu_secs.is_empty())
            .then(|| median(&self.cpu_secs.iter().map(|s| frame.rays() as f64 / s / 1e6).collect::<Vec<_>>()))
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
    ratio: Option<f64>,
    ratio_cpu: Option<f64>,
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
        "{:<16} {:<23} {:>3} {:>8} {:>7} {:>6} {:>6} {:>6} {:>7} {:>6} {:>7} {:>7} {:>21} {:>5}",
        "mesh",
        "tracer",
        "thr",
        "build ms",
        "Mray/s",
        "min",
        "max",
        "ratio",
        "cpu M/s",
        "ratio",
        "nodes/r",
        "tests/r",
        "bytes (total/accel)",
        "mism."
    );
    for r in rows {
        let (lo, hi) = min_max(&r.mrays);
        println!(
            "{:<16} {:<23} {:>3} {:>8} {:>7.2} {:>6.2} {:>6.2} {:>6} {:>7} {:>6} {:>7} {:>7} {:>21} {:>5}",
            r.mesh,
            r.tracer,
            r.threads,
            opt(r.build_ms, 1),
            median(&r.mrays),
            lo,
            hi,
            opt(r.ratio, 2),
            opt(r.mrays_cpu, 2),
            opt(r.ratio_cpu, 2),
            opt(r.nodes_per_ray, 1),
            opt(r.tests_per_ray, 2),
            r.bytes,
            r.mismatches
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

    let mut rows = Vec::new();
    let mut ours_out: Vec<f32> = Vec::new();
    for &threads in plan.threads {
        let pool = pool(threads);
        let mut cs = vec![Contender::new("ours", ours_tile(&ours))];
        cs[0].build_ms = Some(ours_ms);
        cs[0].bytes = format!("{}/{}", ours.bytes_used(), ours.accel_bytes());
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

        let ours_median = median(&cs[0].mrays(&frame));
        let ours_cpu = cs[0].mrays_cpu(&frame);
        let e1 = cs.iter().find(|c| c.tracer == embree::ONE_RAY);
        let (e1_median, e1_cpu) =
            (e1.map(|c| median(&c.mrays(&frame))), e1.and_then(|c| c.mrays_cpu(&frame)));
        for (i, c) in cs.iter().enumerate() {
            let m = c.mrays(&frame);
            let cpu = c.mrays_cpu(&frame);
            let agreement = (i > 0).then(|| Agreement::of(&frame, &cs[0].out, &c.out));
            let (ratio, ratio_cpu) = if i == 0 {
                (e1_median.map(|e| ours_median / e), ours_cpu.zip(e1_cpu).map(|(a, b)| a / b))
            } else {
                (Some(ours_median / median(&m)), ours_cpu.zip(cpu).map(|(a, b)| a / b))
            };
            rows.push(Row {
                mesh: label.clone(),
                tracer: c.tracer.clone(),
                threads,
                build_ms: c.build_ms,
                mrays: m,
                mrays_cpu: cpu,
                ratio,
                ratio_cpu,
                nodes_per_ray: (i == 0).then(|| per_ray(c.stats.bvh_nodes, c.stats.rays)).flatten(),
                tests_per_ray: (i == 0).then(|| per_ray(c.stats.prim_tests, c.stats.rays)).flatten(),
                bytes: c.bytes.clone(),
                mismatches: agreement.as_ref().map_or("-".into(), |g| g.mismatches().to_string()),
            });
            if let Some(g) = agreement
                && threads == plan.threads[0]
            {
                println!("agreement {}", g.describe("ours", &c.tracer));
            }
        }
    }
    #[cfg(feature = "embree")]
    println!("agreement {}", emb.robust_agreement(&frame, &ours_out).describe("ours", "embree robust"));
    if plan.presets {
        preset_sweep(&label, &mesh, &frame, plan);
    }
    rows
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let plan = if args.iter().any(|a| a == "--quick") {
        QUICK
    } else if args.iter().any(|a| a == "--bench") {
        FULL
    } else {
        println!("smoke mode (run with `cargo bench --bench primary_rays` for the benchmark)");
        SMOKE
    };
    let filters: Vec<&String> = args.iter().filter(|a| !a.starts_with('-')).collect();
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes");
    let meshes: &[&str] = if plan.size == FULL.size {
        &["armadillo.obj", "stanford-bunny.obj"]
    } else {
        &["stanford-bunny.obj"]
    };
    println!(
        "primary rays: {0}x{0}, 16x16 tiles, closest hit only, t in [0, inf); threads {1:?}; \
         {2} timed frames after 1 warm-up, interleaved across tracers; {3} CPUs available",
        plan.size,
        plan.threads,
        plan.frames,
        std::thread::available_parallelism().map_or(0, |n| n.get())
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
    println!(
        "\nMray/s: million rays per wall-clock second, median of the timed frames (min, max beside it). \
         cpu M/s: million rays per process CPU second (median): per-thread throughput, robust to other \
         load on the machine. ratio: on our rows, ours / embree rtcIntersect1 at the same thread \
         count; on embree rows, ours / that row (first by wall clock, then by CPU time). \
         bytes: ours Geometry::bytes_used / MeshGeometry::accel_bytes; embree: net bytes its \
         memory monitor saw allocated for the scene / the same less the vertex and index \
         buffers. mism.: rays whose hit/miss differs, or whose t differs by more than 1e-4 \
         relative, from ours."
    );
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
}

/// Embree 3 (Debian's libembree-dev) through a minimal hand-written FFI, checked against
/// the C headers' layouts in /usr/include/embree3.
#[cfg(feature = "embree")]
mod embree {
    use std::ffi::{c_char, c_void};
    use std::mem::{align_of, offset_of, size_of};
    use std::sync::atomic::{AtomicIsize, Ordering};
    use std::time::Instant;

    use sdfmesh::geometry::RayStats;
    use sdfmesh::mesh::TriangleMesh;

    use super::{Agreement, Contender, Frame, MISS, TILE, TILE_RAYS, TileFn, median, process_cpu_secs};

    #[allow(non_camel_case_types, non_snake_case, dead_code)]
    mod ffi {
        use std::ffi::{c_char, c_int, c_uint, c_void};

        pub type RTCDevice = *mut c_void;
        pub type RTCScene = *mut c_void;
        pub type RTCGeometry = *mut c_void;
        /// C enums are passed as `unsigned int`-sized values.
        pub type RTCEnum = c_uint;

        pub const RTC_INVALID_GEOMETRY_ID: c_uint = c_uint::MAX;
        pub const RTC_FORMAT_UINT3: RTCEnum = 0x5003;
        pub const RTC_FORMAT_FLOAT3: RTCEnum = 0x9003;
        pub const RTC_GEOMETRY_TYPE_TRIANGLE: RTCEnum = 0;
        pub const RTC_BUFFER_TYPE_INDEX: RTCEnum = 0;
        pub const RTC_BUFFER_TYPE_VERTEX: RTCEnum = 1;
        pub const RTC_BUILD_QUALITY_MEDIUM: RTCEnum = 1;
        pub const RTC_SCENE_FLAG_NONE: RTCEnum = 0;
        pub const RTC_SCENE_FLAG_ROBUST: RTCEnum = 1 << 2;
        pub const RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT: RTCEnum = 0;
        pub const RTC_INTERSECT_CONTEXT_FLAG_COHERENT: RTCEnum = 1;
        pub const RTC_DEVICE_PROPERTY_VERSION: RTCEnum = 0;
        pub const RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED: RTCEnum = 33;
        pub const RTC_DEVICE_PROPERTY_RAY_STREAM_SUPPORTED: RTCEnum = 35;
        pub const RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED: RTCEnum = 65;
        pub const RTC_DEVICE_PROPERTY_TASKING_SYSTEM: RTCEnum = 128;
        /// RTC_MAX_INSTANCE_LEVEL_COUNT in rtcore_config.h (Debian's build: 1).
        pub const MAX_INSTANCE_LEVEL_COUNT: usize = 1;

        /// `struct RTCRay` (rtcore_ray.h).
        #[repr(C, align(16))]
        #[derive(Clone, Copy, Debug, Default)]
        pub struct RTCRay {
            pub org_x: f32,
            pub org_y: f32,
            pub org_z: f32,
            pub tnear: f32,
            pub dir_x: f32,
            pub dir_y: f32,
            pub dir_z: f32,
            pub time: f32,
            pub tfar: f32,
            pub mask: c_uint,
            pub id: c_uint,
            pub flags: c_uint,
        }

        /// `struct RTCHit` (rtcore_ray.h).
        #[repr(C, align(16))]
        #[derive(Clone, Copy, Debug, Default)]
        pub struct RTCHit {
            pub Ng_x: f32,
            pub Ng_y: f32,
            pub Ng_z: f32,
            pub u: f32,
            pub v: f32,
            pub primID: c_uint,
            pub geomID: c_uint,
            pub instID: [c_uint; MAX_INSTANCE_LEVEL_COUNT],
        }

        /// `struct RTCRayHit` (rtcore_ray.h).
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default)]
        pub struct RTCRayHit {
            pub ray: RTCRay,
            pub hit: RTCHit,
        }

        /// `struct RTCRay8` (rtcore_ray.h).
        #[repr(C, align(32))]
        #[derive(Clone, Copy, Debug, Default)]
        pub struct RTCRay8 {
            pub org_x: [f32; 8],
            pub org_y: [f32; 8],
            pub org_z: [f32; 8],
            pub tnear: [f32; 8],
            pub dir_x: [f32; 8],
            pub dir_y: [f32; 8],
            pub dir_z: [f32; 8],
            pub time: [f32; 8],
            pub tfar: [f32; 8],
            pub mask: [c_uint; 8],
            pub id: [c_uint; 8],
            pub flags: [c_uint; 8],
        }

        /// `struct RTCHit8` (rtcore_ray.h).
        #[repr(C, align(32))]
        #[derive(Clone, Copy, Debug, Default)]
        pub struct RTCHit8 {
            pub Ng_x: [f32; 8],
            pub Ng_y: [f32; 8],
            pub Ng_z: [f32; 8],
            pub u: [f32; 8],
            pub v: [f32; 8],
            pub primID: [c_uint; 8],
            pub geomID: [c_uint; 8],
            pub instID: [[c_uint; 8]; MAX_INSTANCE_LEVEL_COUNT],
        }

        /// `struct RTCRayHit8` (rtcore_ray.h).
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default)]
        pub struct RTCRayHit8 {
            pub ray: RTCRay8,
            pub hit: RTCHit8,
        }

        /// The `valid` mask of `rtcIntersect8`: -1 active, 0 inactive, 32-byte aligned.
        #[repr(C, align(32))]
        #[derive(Clone, Copy, Debug, Default)]
        pub struct Valid8(pub [c_int; 8]);

        pub type RTCFilterFunctionN = Option<unsafe extern "C" fn(args: *const c_void)>;

        /// `struct RTCIntersectContext` (rtcore_common.h) with RTC_MAX_INSTANCE_LEVEL_COUNT
        /// 1 (no `instStackSize`) and RTC_MIN_WIDTH 0 (no `minWidthDistanceFactor`).
        #[repr(C)]
        #[derive(Clone, Copy, Debug)]
        pub struct RTCIntersectContext {
            pub flags: RTCEnum,
            pub filter: RTCFilterFunctionN,
            pub instID: [c_uint; MAX_INSTANCE_LEVEL_COUNT],
        }

        /// `rtcInitIntersectContext`, an inline function in rtcore_common.h.
        pub fn rtcInitIntersectContext() -> RTCIntersectContext {
            RTCIntersectContext {
                flags: RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT,
                filter: None,
                instID: [RTC_INVALID_GEOMETRY_ID; MAX_INSTANCE_LEVEL_COUNT],
            }
        }

        /// `struct RTCBounds` (rtcore_common.h).
        #[repr(C, align(16))]
        #[derive(Clone, Copy, Debug, Default)]
        pub struct RTCBounds {
            pub lower_x: f32,
            pub lower_y: f32,
            pub lower_z: f32,
            pub align0: f32,
            pub upper_x: f32,
            pub upper_y: f32,
            pub upper_z: f32,
            pub align1: f32,
        }

        pub type RTCMemoryMonitorFunction =
            Option<unsafe extern "C" fn(ptr: *mut c_void, bytes: isize, post: bool) -> bool>;

        #[link(name = "embree3")]
        unsafe extern "C" {
            pub fn rtcNewDevice(config: *const c_char) -> RTCDevice;
            pub fn rtcReleaseDevice(device: RTCDevice);
            pub fn rtcGetDeviceError(device: RTCDevice) -> RTCEnum;
            pub fn rtcGetDeviceProperty(device: RTCDevice, prop: RTCEnum) -> isize;
            pub fn rtcSetDeviceMemoryMonitorFunction(
                device: RTCDevice,
                monitor: RTCMemoryMonitorFunction,
                user: *mut c_void,
            );
            pub fn rtcNewScene(device: RTCDevice) -> RTCScene;
            pub fn rtcSetSceneBuildQuality(scene: RTCScene, quality: RTCEnum);
            pub fn rtcSetSceneFlags(scene: RTCScene, flags: RTCEnum);
            pub fn rtcNewGeometry(device: RTCDevice, kind: RTCEnum) -> RTCGeometry;
            pub fn rtcSetNewGeometryBuffer(
                geometry: RTCGeometry,
                kind: RTCEnum,
                slot: c_uint,
                format: RTCEnum,
                byte_stride: usize,
                item_count: usize,
            ) -> *mut c_void;
            pub fn rtcCommitGeometry(geometry: RTCGeometry);
            pub fn rtcAttachGeometry(scene: RTCScene, geometry: RTCGeometry) -> c_uint;
            pub fn rtcReleaseGeometry(geometry: RTCGeometry);
            pub fn rtcCommitScene(scene: RTCScene);
            pub fn rtcGetSceneBounds(scene: RTCScene, bounds: *mut RTCBounds);
            pub fn rtcIntersect1(scene: RTCScene, context: *mut RTCIntersectContext, rayhit: *mut RTCRayHit);
            pub fn rtcIntersect8(
                valid: *const Valid8,
                scene: RTCScene,
                context: *mut RTCIntersectContext,
                rayhit: *mut RTCRayHit8,
            );
            pub fn rtcIntersect1M(
                scene: RTCScene,
                context: *mut RTCIntersectContext,
                rayhit: *mut RTCRayHit,
                m: c_uint,
                byte_stride: usize,
            );
            pub fn rtcReleaseScene(scene: RTCScene);
        }
    }

    use ffi::*;

    // Layouts as compiled C reports them for Debian's embree 3.13.5 (x86-64):
    // RTCRayHit 80/16 (hit at 48, tfar at 32, geomID at 72), RTCRayHit8 640/32 (hit at
    // 384), RTCIntersectContext 24/8 (filter at 8, instID at 16), RTCBounds 32/16.
    const _: () = {
        assert!(size_of::<RTCRay>() == 48 && align_of::<RTCRay>() == 16);
        assert!(size_of::<RTCHit>() == 32 && align_of::<RTCHit>() == 16);
        assert!(size_of::<RTCRayHit>() == 80 && align_of::<RTCRayHit>() == 16);
        assert!(offset_of!(RTCRayHit, hit) == 48);
        assert!(offset_of!(RTCRay, tfar) == 32);
        assert!(offset_of!(RTCHit, primID) == 20 && offset_of!(RTCHit, geomID) == 24);
        assert!(size_of::<RTCRayHit8>() == 640 && align_of::<RTCRayHit8>() == 32);
        assert!(offset_of!(RTCRayHit8, hit) == 384);
        assert!(size_of::<RTCIntersectContext>() == 24);
        assert!(offset_of!(RTCIntersectContext, filter) == 8);
        assert!(offset_of!(RTCIntersectContext, instID) == 16);
        assert!(size_of::<RTCBounds>() == 32 && align_of::<RTCBounds>() == 16);
    };

    /// Tracer name of the one-ray-at-a-time Embree rows.
    pub const ONE_RAY: &str = "embree rtcIntersect1";

    /// Net bytes the device's memory monitor has seen allocated.
    static DEVICE_BYTES: AtomicIsize = AtomicIsize::new(0);

    unsafe extern "C" fn monitor(_user: *mut c_void, bytes: isize, _post: bool) -> bool {
        DEVICE_BYTES.fetch_add(bytes, Ordering::Relaxed);
        true
    }

    /// An Embree device (released on drop).
    struct Device(RTCDevice);

    impl Device {
        fn new(config: &std::ffi::CStr) -> Self {
            // SAFETY: a NUL-terminated config string; the handle is checked below.
            let d = unsafe { rtcNewDevice(config.as_ptr() as *const c_char) };
            assert!(!d.is_null(), "rtcNewDevice failed");
            Device(d)
        }

        fn check(&self, what: &str) {
            // SAFETY: a live device.
            let e = unsafe { rtcGetDeviceError(self.0) };
            assert_eq!(e, 0, "embree error {e} after {what}");
        }

        fn property(&self, p: RTCEnum) -> isize {
            // SAFETY: a live device.
            unsafe { rtcGetDeviceProperty(self.0, p) }
        }
    }

    impl Drop for Device {
        fn drop(&mut self) {
            // SAFETY: released once; scenes hold their own reference to the device.
            unsafe { rtcReleaseDevice(self.0) }
        }
    }

    /// A committed Embree scene holding one triangle geometry.
    struct Scene(RTCScene);

    // SAFETY: a committed scene is immutable and Embree allows concurrent intersect calls.
    unsafe impl Send for Scene {}
    // SAFETY: as above.
    unsafe impl Sync for Scene {}

    impl Drop for Scene {
        fn drop(&mut self) {
            // SAFETY: released once.
            unsafe { rtcReleaseScene(self.0) }
        }
    }

    /// Builds a scene of `mesh` on `device`, timing scene creation, buffer copies and
    /// the commit.
    fn build(device: &Device, mesh: &TriangleMesh, flags: RTCEnum) -> Built {
        let cpu0 = process_cpu_secs();
        let start = Instant::now();
        // SAFETY: valid device; the buffers Embree returns have the requested sizes
        // (item_count * stride bytes), written in full before the commit.
        let scene = unsafe {
            let scene = rtcNewScene(device.0);
            rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM);
            rtcSetSceneFlags(scene, flags);
            let geom = rtcNewGeometry(device.0, RTC_GEOMETRY_TYPE_TRIANGLE);
            let n = mesh.positions.len();
            let vb = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, n)
                as *mut f32;
            assert!(!vb.is_null(), "vertex buffer");
            let vb = std::slice::from_raw_parts_mut(vb, 3 * n);
            for (dst, p) in vb.chunks_exact_mut(3).zip(&mesh.positions) {
                dst.copy_from_slice(&p.to_array());
            }
            let m = mesh.triangles.len();
            let ib =
                rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, m) as *mut u32;
            assert!(!ib.is_null(), "index buffer");
            let ib = std::slice::from_raw_parts_mut(ib, 3 * m);
            for (dst, t) in ib.chunks_exact_mut(3).zip(&mesh.triangles) {
                dst.copy_from_slice(t);
            }
            rtcCommitGeometry(geom);
            rtcAttachGeometry(scene, geom);
            rtcReleaseGeometry(geom);
            rtcCommitScene(scene);
            Scene(scene)
        };
        let ms = start.elapsed().as_secs_f64() * 1e3;
        device.check("scene build");
        Built {
            scene,
            ms,
            cpu_ms: cpu0.zip(process_cpu_secs()).map(|(a, b)| (b - a) * 1e3),
            buffer_bytes: 12 * (mesh.positions.len() + mesh.triangles.len()),
        }
    }

    /// A scene just built, with its build's wall and process CPU time.
    struct Built {
        scene: Scene,
        ms: f64,
        cpu_ms: Option<f64>,
        buffer_bytes: usize,
    }

    #[inline]
    fn ray_hit(frame: &Frame, x: u32, y: u32) -> RTCRayHit {
        let r = frame.camera.ray(x, y);
        RTCRayHit {
            ray: RTCRay {
                org_x: r.origin.x,
                org_y: r.origin.y,
                org_z: r.origin.z,
                tnear: 0.0,
                dir_x: r.dir.x,
                dir_y: r.dir.y,
                dir_z: r.dir.z,
                time: 0.0,
                tfar: f32::INFINITY,
                mask: u32::MAX,
                id: 0,
                flags: 0,
            },
            hit: RTCHit {
                geomID: RTC_INVALID_GEOMETRY_ID,
                instID: [RTC_INVALID_GEOMETRY_ID; MAX_INSTANCE_LEVEL_COUNT],
                ..RTCHit::default()
            },
        }
    }

    #[inline]
    fn result(rh: &RTCRayHit) -> f32 {
        if rh.hit.geomID != RTC_INVALID_GEOMETRY_ID { rh.ray.tfar } else { MISS }
    }

    /// Embree one ray at a time.
    fn tile_1(scene: &Scene) -> TileFn<'_> {
        Box::new(move |frame: &Frame, tile: usize, slots: &mut [f32]| {
            let o = frame.origin(tile);
            let mut ctx = rtcInitIntersectContext();
            let mut stats = RayStats::default();
            for (s, slot) in slots.iter_mut().enumerate() {
                if let Some((x, y)) = frame.pixel(o, s) {
                    let mut rh = ray_hit(frame, x, y);
                    // SAFETY: committed scene, initialised context and ray.
                    unsafe { rtcIntersect1(scene.0, &mut ctx, &mut rh) };
                    stats.rays += 1;
                    *slot = result(&rh);
                }
            }
            stats
        })
    }

    /// Embree packets of 8 rays (4 x 2 pixels), coherent context.
    fn tile_8(scene: &Scene) -> TileFn<'_> {
        Box::new(move |frame: &Frame, tile: usize, slots: &mut [f32]| {
            let o = frame.origin(tile);
            let mut ctx = rtcInitIntersectContext();
            ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
            let mut stats = RayStats::default();
            for py in 0..TILE / 2 {
                for px in 0..TILE / 4 {
                    let mut valid = Valid8([0; 8]);
                    let mut p = RTCRayHit8::default();
                    let mut slot_of = [usize::MAX; 8];
                    for k in 0..8u32 {
                        let s = ((py * 2 + k / 4) * TILE + px * 4 + k % 4) as usize;
                        let Some((x, y)) = frame.pixel(o, s) else {
                            continue;
                        };
                        let k = k as usize;
                        let r = frame.camera.ray(x, y);
                        slot_of[k] = s;
                        valid.0[k] = -1;
                        p.ray.org_x[k] = r.origin.x;
                        p.ray.org_y[k] = r.origin.y;
                        p.ray.org_z[k] = r.origin.z;
                        p.ray.dir_x[k] = r.dir.x;
                        p.ray.dir_y[k] = r.dir.y;
                        p.ray.dir_z[k] = r.dir.z;
                        p.ray.tfar[k] = f32::INFINITY;
                        p.ray.mask[k] = u32::MAX;
                        p.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
                        p.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
                    }
                    if valid.0.iter().all(|&v| v == 0) {
                        continue;
                    }
                    // SAFETY: 32-byte aligned mask and packet, committed scene.
                    unsafe { rtcIntersect8(&valid, scene.0, &mut ctx, &mut p) };
                    for (k, &s) in slot_of.iter().enumerate() {
                        if s != usize::MAX {
                            stats.rays += 1;
                            slots[s] =
                                if p.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID { p.ray.tfar[k] } else { MISS };
                        }
                    }
                }
            }
            stats
        })
    }

    /// Embree ray stream: one tile's rays in one `rtcIntersect1M` call, coherent context.
    fn tile_1m(scene: &Scene) -> TileFn<'_> {
        Box::new(move |frame: &Frame, tile: usize, slots: &mut [f32]| {
            let o = frame.origin(tile);
            let mut ctx = rtcInitIntersectContext();
            ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
            let mut rays = [RTCRayHit::default(); TILE_RAYS];
            let mut slot_of = [0usize; TILE_RAYS];
            let mut m = 0;
            for s in 0..TILE_RAYS {
                if let Some((x, y)) = frame.pixel(o, s) {
                    rays[m] = ray_hit(frame, x, y);
                    slot_of[m] = s;
                    m += 1;
                }
            }
            // SAFETY: `m` contiguous initialised rays with their natural stride.
            unsafe { rtcIntersect1M(scene.0, &mut ctx, rays.as_mut_ptr(), m as u32, size_of::<RTCRayHit>()) };
            for (rh, &s) in rays[..m].iter().zip(&slot_of[..m]) {
                slots[s] = result(rh);
            }
            RayStats { rays: m as u64, ..RayStats::default() }
        })
    }

    /// Embree's side of one mesh's benchmark.
    pub struct Bench {
        // Field order: scenes drop before the device.
        scene: Scene,
        robust: Scene,
        build_ms: f64,
        bytes: String,
        _device: Device,
    }

    impl Bench {
        pub fn new(mesh: &TriangleMesh, builds: usize) -> Self {
            let device = Device::new(c"verbose=0");
            // SAFETY: a plain function and no user data.
            unsafe { rtcSetDeviceMemoryMonitorFunction(device.0, Some(monitor), std::ptr::null_mut()) };
            println!(
                "embree {} (tasking system {}, native ray8 {}, ray streams {}, backface culling {})",
                device.property(RTC_DEVICE_PROPERTY_VERSION),
                match device.property(RTC_DEVICE_PROPERTY_TASKING_SYSTEM) {
                    0 => "internal",
                    1 => "TBB",
                    2 => "PPL",
                    _ => "?",
                },
                device.property(RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED),
                device.property(RTC_DEVICE_PROPERTY_RAY_STREAM_SUPPORTED),
                device.property(RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED),
            );
            let mut times = Vec::new();
            let mut cpu_times = Vec::new();
            let mut kept = None;
            let mut bytes = (0, 0);
            for _ in 0..builds.max(1) {
                drop(kept.take());
                let before = DEVICE_BYTES.load(Ordering::Relaxed);
                let b = build(&device, mesh, RTC_SCENE_FLAG_NONE);
                bytes = (DEVICE_BYTES.load(Ordering::Relaxed) - before, b.buffer_bytes);
                times.push(b.ms);
                cpu_times.extend(b.cpu_ms);
                kept = Some(b.scene);
            }
            let scene = kept.expect("built");
            // Build time with Embree's builder limited to one thread, for reference.
            let device1 = Device::new(c"verbose=0,threads=1");
            let (mut times1, mut cpu_times1) = (Vec::new(), Vec::new());
            for _ in 0..builds.max(1) {
                let b = build(&device1, mesh, RTC_SCENE_FLAG_NONE);
                times1.push(b.ms);
                cpu_times1.extend(b.cpu_ms);
            }
            drop(device1);
            let robust = build(&device, mesh, RTC_SCENE_FLAG_ROBUST).scene;
            let mut b = RTCBounds::default();
            // SAFETY: committed scene, aligned output.
            unsafe { rtcGetSceneBounds(scene.0, &mut b) };
            let (lo, hi) = mesh.bounds().expect("nonempty mesh");
            let bounds_ok = (lo.x, lo.y, lo.z, hi.x, hi.y, hi.z)
                == (b.lower_x, b.lower_y, b.lower_z, b.upper_x, b.upper_y, b.upper_z);
            let build_ms = median(&times);
            let cpu = |v: &[f64]| if v.is_empty() { "-".to_string() } else { format!("{:.1}", median(v)) };
            println!(
                "embree build (quality medium): {build_ms:.1} ms median of {} ({} ms CPU) on the default \
                 device (TBB, all hardware threads), {:.1} ms ({} ms CPU) with threads=1; \
                 rtcGetSceneBounds [{:.4} {:.4} {:.4}]..[{:.4} {:.4} {:.4}] {}",
                times.len(),
                cpu(&cpu_times),
                median(&times1),
                cpu(&cpu_times1),
                b.lower_x,
                b.lower_y,
                b.lower_z,
                b.upper_x,
                b.upper_y,
                b.upper_z,
                if bounds_ok { "equals the mesh's bounds" } else { "DIFFERS from the mesh's bounds" }
            );
            let (total, buffers) = bytes;
            Bench {
                scene,
                robust,
                build_ms,
                bytes: format!("~{}/~{}", total, total - buffers as isize),
                _device: device,
            }
        }

        /// The Embree tracers to race at `threads`.
        pub fn contenders(&self) -> Vec<Contender<'_>> {
            let mut v = vec![
                Contender::new(ONE_RAY, tile_1(&self.scene)),
                Contender::new("embree rtcIntersect8", tile_8(&self.scene)),
                Contender::new("embree rtcIntersect1M", tile_1m(&self.scene)),
                // Watertight like ours (RTC_SCENE_FLAG_ROBUST), one ray at a time.
                Contender::new("embree robust Isect1", tile_1(&self.robust)),
            ];
            for c in &mut v[..3] {
                c.build_ms = Some(self.build_ms);
                c.bytes = self.bytes.clone();
            }
            v
        }

        /// Agreement of `ours` (a frame's output) with Embree's robust (watertight) mode.
        pub fn robust_agreement(&self, frame: &Frame, ours: &[f32]) -> Agreement {
            let mut c = Contender::new("embree robust", tile_1(&self.robust));
            c.frame(&super::pool(1), frame);
            Agreement::of(frame, ours, &c.out)
        }
    }
}
