//! Side-by-side benchmark peer: renders the two SDF-favouring scenes of sdfmesh (a smooth
//! union of 16 spheres, `data/scenes/blend/metaballs_016.toml`, and a level-3 Menger
//! sponge, `data/scenes/fractal/menger_3.toml`) with Fidget's own 3D CPU renderer
//! (`fidget::raster::voxel`) through the same pinhole camera, and prints median wall times.
//!
//! What Fidget computes: a depth image (plus a gradient per hit pixel) of the voxel volume
//! `width x height x depth` in screen space, found by interval arithmetic over tiles of
//! 64, 16 and 8 voxels (JIT; VM: 128..8), with tape simplification per tile, and dense
//! evaluation of the last 8^3 tiles front to back. Depth is quantised to one voxel of
//! `depth` along each pixel's column; there is no per-pixel sphere tracing.
//!
//! Camera: the voxel volume is mapped to the camera frustum by a projective matrix
//! (`world_to_model`) so that voxel column `(x, y)` lies on our ray through the centre of
//! pixel `(x, y)`, and voxel `z` steps uniformly in 1/t between the near and far distances
//! that bracket the object's bounding sphere.
//!
//! Usage: `bench-fidget SCENE SIZE THREADS RUNS EVAL MASK.pgm`, with SCENE `metaballs` or
//! `menger`, EVAL `jit` or `vm`, THREADS 1 (Fidget's single-threaded path) or more (a
//! rayon pool of that many threads). Prints one line of `key=value` fields; writes the
//! depth image of the last run (0 = no hit, 1..255 = far..near) as a binary PGM. `bench-fidget compare MASK.pgm
//! OURS.png` counts the pixels where that mask and our render's hits differ.
//!
//! The Prospero challenge's 2D image (`prospero`, `reference`, `differ`): see [`prospero`].
//! A `.vm` model's orthographic 3D view (`voxel`, `reference3d`, `differ3d`): see [`voxel`].

mod prospero;
mod voxel;

use std::io::Write;
use std::time::Instant;

use fidget::context::Tree;
use fidget::eval::{Function, MathFunction};
use fidget::raster::voxel::{self as fidget_voxel, EvalConfig, RenderConfig, RenderSize};
use fidget::render::{RenderHints, ThreadPool};
use fidget::shape::{Shape, ShapeVars};
use nalgebra::{Matrix4, Vector3, Vector4};

/// A camera as in a sdfmesh scene file: position, look-at point, vertical field of view in
/// degrees, and a bounding sphere (centre, radius) of the object for the depth range.
struct View {
    position: [f32; 3],
    look_at: [f32; 3],
    fov_deg: f32,
    bound_centre: [f32; 3],
    bound_radius: f32,
}

/// `metaballs_016.toml`: 16 spheres (centre, radius) in a smooth union of blend 0.375.
const METABALLS: [([f32; 3], f32); 16] = [
    ([-0.3244, -0.2629, -0.3631], 0.4267),
    ([0.3437, 0.3691, -0.3635], 0.4155),
    ([-0.0755, 0.9794, -0.0544], 0.4181),
    ([0.2637, 0.1828, -0.7672], 0.4311),
    ([-0.4196, -0.3323, 0.9113], 0.3887),
    ([-0.4983, 0.2761, 0.7503], 0.4571),
    ([0.3471, -0.7597, -0.638], 0.4302),
    ([-0.3707, 0.6354, -0.8709], 0.3893),
    ([0.7479, -0.2965, 0.8734], 0.4235),
    ([0.826, 0.2017, 0.6279], 0.3664),
    ([1.0776, -0.2635, 0.0422], 0.406),
    ([-0.248, 1.1639, -0.0513], 0.4679),
    ([-0.1505, 0.4967, -0.7747], 0.3399),
    ([0.8274, -0.0592, 0.0141], 0.3688),
    ([-0.0235, 0.6046, -0.0815], 0.3557),
    ([0.029, 0.2423, 0.3703], 0.4692),
];
const METABALLS_BLEND: f32 = 0.375;

/// sdfmesh's polynomial smooth minimum (Quilez), `smooth_min` in `src/geometry/sdf/mod.rs`:
/// `h = clamp(0.5 + 0.5 (b - a) / k, 0, 1)`, `b + (a - b) h - k h (1 - h)`.
fn smin(a: Tree, b: Tree, k: f32) -> Tree {
    let h = ((b.clone() - a.clone()) * (0.5 / k) + 0.5).max(0.0).min(1.0);
    b.clone() + (a - b) * h.clone() - h.clone() * (1.0 - h) * k
}

fn metaballs() -> Tree {
    let (x, y, z) = Tree::axes();
    let mut d: Option<Tree> = None;
    for (c, r) in METABALLS {
        let dx = x.clone() - c[0];
        let dy = y.clone() - c[1];
        let dz = z.clone() - c[2];
        let s = (dx.square() + dy.square() + dz.square()).sqrt() - r;
        // The n-ary smooth union folds left over the children, as ours does.
        d = Some(match d {
            None => s,
            Some(d) => smin(d, s, METABALLS_BLEND),
        });
    }
    d.expect("16 spheres")
}

/// Box of half sizes `h` centred at the origin (exact SDF, as ours).
fn sdf_box(x: &Tree, y: &Tree, z: &Tree, h: [f32; 3]) -> Tree {
    let qx = x.abs() - h[0];
    let qy = y.abs() - h[1];
    let qz = z.abs() - h[2];
    let outside = (qx.max(0.0).square() + qy.max(0.0).square() + qz.max(0.0).square()).sqrt();
    let inside = qx.max(qy).max(qz).min(0.0);
    outside + inside
}

/// Three orthogonal boxes: arms of half-length `arm` and half-width `w`.
fn cross(x: &Tree, y: &Tree, z: &Tree, arm: f32, w: f32) -> Tree {
    sdf_box(x, y, z, [arm, w, w]).min(sdf_box(x, y, z, [w, arm, w])).min(sdf_box(x, y, z, [w, w, arm]))
}

/// Finite repetition of odd `count` per axis with `period`: the nearest cell, clamped.
/// (Ours also evaluates the neighbouring cell per axis; for these crosses the surface is the
/// same, since neighbouring arms along one axis are collinear.)
fn repeat(v: &Tree, period: f32, count: u32) -> Tree {
    let half = (count as f32 - 1.0) * 0.5;
    let id = (v.clone() * (1.0 / period)).round().max(-half).min(half);
    v.clone() - id * period
}

/// `menger_3.toml`: rotate [0, 30, 0] of (box 1 minus a cross, minus 3x3x3 and 9x9x9
/// repeated crosses), with the scene's rounded constants.
fn menger() -> Tree {
    let (x, y, z) = Tree::axes();
    // local = R_y(30 deg)^T world (ours: world = R local, R = Rz Ry Rx).
    let (s, c) = 30f32.to_radians().sin_cos();
    let lx = x.clone() * c - z.clone() * s;
    let lz = x * s + z * c;
    let ly = y;
    let mut d = sdf_box(&lx, &ly, &lz, [1.0, 1.0, 1.0]);
    d = d.max(-cross(&lx, &ly, &lz, 1.5, 0.3333));
    let levels = [(0.6667, 3, 0.5, 0.1111), (0.2222, 9, 0.1667, 0.037)];
    for (period, count, arm, w) in levels {
        let (rx, ry, rz) =
            (repeat(&lx, period, count), repeat(&ly, period, count), repeat(&lz, period, count));
        d = d.max(-cross(&rx, &ry, &rz, arm, w));
    }
    d
}

fn view(scene: &str) -> Option<(Tree, View)> {
    match scene {
        "metaballs" => Some((
            metaballs(),
            View {
                position: [1.26, 1.764, -5.04],
                look_at: [0.0, 0.0, 0.0],
                fov_deg: 45.0,
                // Every sphere lies within 1.72 of the origin; blending only adds a little.
                bound_centre: [0.0, 0.0, 0.0],
                bound_radius: 1.9,
            },
        )),
        "menger" => Some((
            menger(),
            View {
                position: [1.6, 2.2, -3.4],
                look_at: [0.0, 0.0, 0.0],
                fov_deg: 45.0,
                bound_centre: [0.0, 0.0, 0.0],
                bound_radius: 3f32.sqrt() + 0.01,
            },
        )),
        _ => None,
    }
}

/// The `world_to_model` matrix for a `size x size x size` voxel volume. Fidget maps voxel
/// `(i, j, k)` to screen `s = ((i - n/2), -(j + 1 - n/2), (k - n/2)) * 2/n` (z grows
/// towards the viewer); ours shoots pixel `(x, y)` through `u = (2 (x + 0.5)/n - 1) half`,
/// `v = (1 - 2 (y + 0.5)/n) half`, i.e. `u = (s.x + 1/n) half`, `v = (s.y + 1/n) half`.
/// A point at screen depth `s.z` lies at forward distance `t` with `1/t = a s.z + b`
/// (`s.z = 1`: near, `-1`: far), so the map is projective and linear in homogeneous form.
fn world_to_model(v: &View, n: u32) -> Matrix4<f32> {
    let p = Vector3::from(v.position);
    let forward = (Vector3::from(v.look_at) - p).normalize();
    let right = Vector3::y().cross(&forward).normalize();
    let up = forward.cross(&right);
    let half = (v.fov_deg.to_radians() * 0.5).tan();
    let centre_t = (Vector3::from(v.bound_centre) - p).dot(&forward);
    let near = (centre_t - v.bound_radius).max(1e-3);
    let far = centre_t + v.bound_radius;
    let (a, b) = ((1.0 / near - 1.0 / far) * 0.5, (1.0 / near + 1.0 / far) * 0.5);
    let shift = 1.0 / n as f32;
    let col_x = right * half;
    let col_y = up * half;
    let col_z = p * a;
    let col_1 = p * b + forward + (right + up) * (half * shift);
    Matrix4::from_columns(&[
        Vector4::new(col_x.x, col_x.y, col_x.z, 0.0),
        Vector4::new(col_y.x, col_y.y, col_y.z, 0.0),
        Vector4::new(col_z.x, col_z.y, col_z.z, a),
        Vector4::new(col_1.x, col_1.y, col_1.z, b),
    ])
}
/// Fidget's thread pool for `threads` threads: `None` (its single-threaded path) for 1.
pub(crate) fn pool(threads: usize) -> Result<Option<ThreadPool>, String> {
    if threads <= 1 {
        return Ok(None);
    }
    let p = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| format!("thread pool: {e}"))?;
    Ok(Some(ThreadPool::Custom(p)))
}

/// One cold call of `render`, then `runs` timed ones: the last result, the cold call's ms and
/// the timed calls' ms. `None` from `render` (a cancelled render) is an error.
pub(crate) fn time_renders<T>(
    runs: usize,
    mut render: impl FnMut() -> Option<T>,
) -> Result<(T, f64, Vec<f64>), String> {
    let mut times = Vec::with_capacity(runs);
    let mut cold_ms = 0.0;
    let mut last = None;
    for i in 0..=runs {
        let t = Instant::now();
        let out = render().ok_or("render cancelled")?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        if i == 0 {
            cold_ms = ms;
        } else {
            times.push(ms);
        }
        last = Some(out);
    }
    Ok((last.ok_or("no image")?, cold_ms, times))
}

pub(crate) fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

/// Renders `runs + 1` times (the first is reported separately as the cold run) and prints.
fn bench<F: Function + MathFunction + RenderHints + Clone>(
    eval: &str,
    tree: Tree,
    v: &View,
    n: u32,
    threads: usize,
    runs: usize,
    mask_path: &str,
) -> Result<(), String> {
    let t0 = Instant::now();
    let shape = Shape::<F>::from(tree);
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let vars = ShapeVars::<f32>::new();
    let bound = shape.bind(&vars).map_err(|e| format!("binding the shape: {e}"))?;
    let cfg = RenderConfig { image_size: RenderSize::from(n), world_to_model: world_to_model(v, n) };
    let pool = pool(threads)?;
    let eval_cfg = EvalConfig { threads: pool.as_ref(), ..Default::default() };
    let (image, cold_ms, mut times) =
        time_renders(runs, || fidget_voxel::render(bound.clone(), &cfg, &eval_cfg))?;
    let hits = image.iter().filter(|p| p.depth > 0).count();
    let saturated = image.iter().filter(|p| p.depth > n).count();
    let med = median(&mut times);
    let samples: Vec<String> = times.iter().map(|t| format!("{t:.2}")).collect();
    println!(
        "fidget eval={eval} size={n}x{n} depth={n} threads={threads} runs={runs} median_ms={med:.2} \
         cold_ms={cold_ms:.2} shape_build_ms={build_ms:.2} hit_px={hits} saturated_px={saturated} \
         mpx_per_s={:.3} samples_ms={}",
        (n as f64 * n as f64) / (med * 1e3),
        samples.join(",")
    );
    let mut f = std::fs::File::create(mask_path).map_err(|e| format!("{mask_path}: {e}"))?;
    let mut bytes = format!("P5\n{n} {n}\n255\n").into_bytes();
    // Grey levels show depth (brighter = nearer), 0 = no hit.
    bytes.extend(image.iter().map(|p| if p.depth > 0 { (1 + p.depth.min(n) * 254 / n) as u8 } else { 0 }));
    f.write_all(&bytes).map_err(|e| format!("{mask_path}: {e}"))?;
    Ok(())
}

/// `compare FIDGET.pgm OURS.png`: pixels hit in one image and not in the other. Ours is hit
/// where the pixel is not black (the benchmark scene has a black background and an ambient
/// light on a coloured material).
fn compare(pgm: &str, png_path: &str) -> Result<(), String> {
    let raw = std::fs::read(pgm).map_err(|e| format!("{pgm}: {e}"))?;
    let header: Vec<&[u8]> = raw.splitn(4, |b| *b == b'\n').collect();
    if header.len() != 4 || header[0] != b"P5" {
        return Err(format!("{pgm}: not a binary PGM written by this program"));
    }
    let dims = String::from_utf8_lossy(header[1]).to_string();
    let (w, h) = dims
        .split_once(' ')
        .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
        .ok_or_else(|| format!("{pgm}: bad size line {dims:?}"))?;
    let theirs = header[3];
    let file = std::fs::File::open(png_path).map_err(|e| format!("{png_path}: {e}"))?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().map_err(|e| format!("{png_path}: {e}"))?;
    let mut buf = vec![0; reader.output_buffer_size().ok_or("PNG too large")?];
    let info = reader.next_frame(&mut buf).map_err(|e| format!("{png_path}: {e}"))?;
    let channels = info.color_type.samples();
    if info.width as usize != w || info.height as usize != h || theirs.len() != w * h {
        return Err(format!("sizes differ: {pgm} {w}x{h}, {png_path} {}x{}", info.width, info.height));
    }
    let (mut ours_hits, mut their_hits, mut differ) = (0usize, 0usize, 0usize);
    for i in 0..w * h {
        let px = &buf[i * channels..i * channels + channels.min(3)];
        let ours = px.iter().any(|c| *c > 0);
        let them = theirs[i] > 0;
        ours_hits += ours as usize;
        their_hits += them as usize;
        differ += (ours != them) as usize;
    }
    println!(
        "silhouettes {w}x{h}: ours {ours_hits} px, fidget {their_hits} px, differ {differ} px = {:.3}%",
        100.0 * differ as f64 / (w * h) as f64
    );
    Ok(())
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() == 4 && args[1] == "compare" {
        return compare(&args[2], &args[3]);
    }
    if args.len() == 4 && args[1] == "differ" {
        return prospero::differ(&args[2], &args[3]);
    }
    let positive = |s: &str, what: &str| match s.parse::<usize>() {
        Ok(v) if v > 0 => Ok(v),
        _ => Err(format!("{what} must be a positive integer, not {s:?}")),
    };
    if args.len() == 6 && args[1] == "reference3d" {
        let (n, s) = (positive(&args[3], "N")?, positive(&args[4], "STRIDE")?);
        return voxel::reference(&args[2], n, s, &args[5]);
    }
    if args.len() == 6 && args[1] == "differ3d" {
        let (s, n) = (positive(&args[3], "STRIDE")?, positive(&args[5], "N")?);
        return voxel::differ(&args[2], s, &args[4], n);
    }
    if args.len() == 8 && args[1] == "voxel" {
        let (n, t, r) =
            (positive(&args[3], "N")?, positive(&args[4], "THREADS")?, positive(&args[5], "RUNS")?);
        return match args[6].as_str() {
            "jit" => voxel::bench::<fidget::jit::JitFunction>("jit", &args[2], n, t, r, &args[7]),
            "vm" => voxel::bench::<fidget::vm::VmFunction>("vm", &args[2], n, t, r, &args[7]),
            other => Err(format!("unknown evaluator {other:?} (jit or vm)")),
        };
    }
    if args.len() == 5 && args[1] == "reference" {
        return prospero::reference(&args[2], positive(&args[3], "SIZE")?, &args[4]);
    }
    if args.len() == 8 && args[1] == "prospero" {
        let (n, t, r) =
            (positive(&args[3], "SIZE")?, positive(&args[4], "THREADS")?, positive(&args[5], "RUNS")?);
        return match args[6].as_str() {
            "jit" => prospero::bench::<fidget::jit::JitFunction>("jit", &args[2], n, t, r, &args[7]),
            "vm" => prospero::bench::<fidget::vm::VmFunction>("vm", &args[2], n, t, r, &args[7]),
            other => Err(format!("unknown evaluator {other:?} (jit or vm)")),
        };
    }
    if args.len() != 7 {
        return Err("usage: bench-fidget metaballs|menger SIZE THREADS RUNS jit|vm MASK.pgm | \
                    prospero MODEL.vm SIZE THREADS RUNS jit|vm OUT.pgm | reference MODEL.vm SIZE OUT.pgm | \
                    differ REF.pgm IMAGE | compare MASK.pgm OURS.png | \
                    voxel MODEL.vm N THREADS RUNS jit|vm PREFIX | reference3d MODEL.vm N STRIDE PREFIX | \
                    differ3d REF_PREFIX STRIDE IMAGE_PREFIX N"
            .into());
    }
    let (tree, v) = view(&args[1]).ok_or_else(|| format!("unknown scene {:?}", args[1]))?;
    let n: u32 = args[2].parse().map_err(|_| "SIZE must be a positive integer")?;
    let threads: usize = args[3].parse().map_err(|_| "THREADS must be a positive integer")?;
    let runs: usize = args[4].parse().map_err(|_| "RUNS must be a positive integer")?;
    if n == 0 || threads == 0 || runs == 0 {
        return Err("SIZE, THREADS and RUNS must be positive".into());
    }
    match args[5].as_str() {
        "jit" => bench::<fidget::jit::JitFunction>("jit", tree, &v, n, threads, runs, &args[6]),
        "vm" => bench::<fidget::vm::VmFunction>("vm", tree, &v, n, threads, runs, &args[6]),
        other => Err(format!("unknown evaluator {other:?} (jit or vm)")),
    }
}

fn main() {
    if let Err(e) = run() {
        eprintln!("bench-fidget: {e}");
        std::process::exit(2);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fidget::shape::EzShape;

    fn at(t: &Tree, p: [f32; 3]) -> f32 {
        let shape = fidget::vm::VmShape::from(t.clone());
        let tape = shape.ez_point_tape();
        let mut eval = fidget::vm::VmShape::new_point_eval();
        eval.eval(&tape, p[0], p[1], p[2]).unwrap().0
    }

    #[test]
    fn menger_has_holes_and_solid() {
        let m = menger();
        // The y axis is unchanged by the rotation about y: inside the level-0 cross.
        assert!(at(&m, [0.0, 0.0, 0.0]) > 0.3);
        assert!(at(&m, [0.0, 0.95, 0.0]) > 0.0);
        // Local (0.95, 0.95, 0.95) is solid (no cross of any level reaches it); world = R local.
        let (s, c) = 30f32.to_radians().sin_cos();
        let (lx, lz) = (0.95f32, 0.95f32);
        assert!(at(&m, [lx * c + lz * s, 0.95, -lx * s + lz * c]) < 0.0);
        assert!(at(&m, [0.0, 2.0, 0.0]) > 0.9);
    }

    #[test]
    fn metaballs_match_a_direct_fold() {
        let t = metaballs();
        for p in [[0.0f32, 0.0, 0.0], [0.5, -0.3, 0.2], [1.5, 0.2, -0.4], [0.0, 3.0, 0.0]] {
            let mut d: Option<f32> = None;
            for (ctr, r) in METABALLS {
                let e =
                    ((p[0] - ctr[0]).powi(2) + (p[1] - ctr[1]).powi(2) + (p[2] - ctr[2]).powi(2)).sqrt() - r;
                d = Some(match d {
                    None => e,
                    Some(a) => {
                        let k = METABALLS_BLEND;
                        let h = (0.5 + 0.5 * (e - a) / k).clamp(0.0, 1.0);
                        e + (a - e) * h - k * h * (1.0 - h)
                    }
                });
            }
            let want = d.unwrap();
            let got = at(&t, p);
            assert!((got - want).abs() < 1e-5, "{p:?}: fidget {got}, direct {want}");
        }
    }
}
