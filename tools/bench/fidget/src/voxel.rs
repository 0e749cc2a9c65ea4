//! A `.vm` model's 3D view with Fidget's own voxel renderer (`fidget::raster::voxel`), JIT
//! or VM evaluator, the brute-force f64 reference it is compared with, and the comparison.
//!
//! The view: the cube [-1, 1]^3 seen from +z looking down -z, orthographic, N x N pixels
//! of N voxels depth. Pixel column j, row i (row 0 at the top) samples
//! x = -1 + (2j+1)/N, y = 1 - (2i+1)/N; voxel k (0 at the bottom) has centre
//! z = -1 + (2k+1)/N. Fidget's `VoxelSize::screen_to_world` maps voxel (j, i, k) to
//! x = -1 + 2j/N, y = 1 - 2(i+1)/N, z = -1 + 2k/N (a voxel corner; y flipped), so the
//! world-to-model matrix is a translation by (1/N, 1/N, 1/N). Fidget's gradients are taken
//! with respect to screen coordinates, whose y axis points down: the model-space normal is
//! (gx, -gy, gz); where Fidget's gradient is NaN (it is on most of bolt.vm) the normal
//! is written as (0, 0, 1) and counted in `nan_normal_px`. Fidget reports any pixel whose top filled voxel is N-2 or N-1 as
//! saturated (depth N, normal (0, 0, 1)).
//!
//! Images for a prefix P: `P.depth.png`, 16-bit grey, 0 = no surface, otherwise
//! round((z+1)/2 * 65535) clamped to [1, 65535] for the height z of the first surface seen
//! from above; `P.normal.png`, 8-bit RGB, the unit outward normal n as
//! round(n * 127.5 + 127.5), (0, 0, 0) where there is no surface.
//!
//! - `voxel MODEL.vm N THREADS RUNS jit|vm PREFIX`: builds the shape with Fidget's `.vm`
//!   reader, renders once cold, then RUNS timed renders (THREADS 1: Fidget's
//!   single-threaded path; more: a rayon pool). Prints one line of `key=value` fields and
//!   writes the last image: depth = centre of the topmost filled voxel (z = 1 where
//!   saturated), normal = Fidget's gradient normalised.
//! - `reference3d MODEL.vm N STRIDE PREFIX`: the pixels with i, j multiples of STRIDE,
//!   evaluated in f64 by the small evaluator of [`crate::prospero`] (neither Fidget's code
//!   nor sdfmesh's): top face if f(x, y, 1) < 0, else the first inside voxel centre from
//!   the top, the crossing bisected (50 steps) between it and the sample above (or z = 1),
//!   normal from central differences (h = 1e-6). Writes an (N/STRIDE)^2 image pair.
//! - `differ3d REF_PREFIX STRIDE IMAGE_PREFIX N`: compares the image's pixel (iS, jS) with
//!   the reference's (i, j): hits that differ, depths more than one voxel (2/N) apart, and
//!   the angles between normals (pixels on the top face z = 1 left out).

use std::time::Instant;

use fidget::context::Context;
use fidget::eval::{Function, MathFunction};
use fidget::raster::voxel::{self, EvalConfig, RenderConfig, RenderSize};
use fidget::render::RenderHints;
use fidget::shape::{Shape, ShapeVars};
use nalgebra::{Matrix4, Vector3};
use rayon::prelude::*;

use crate::median;
use crate::prospero::{eval_f64, read_clauses};

/// A depth and normal image in the shared convention (see the module header).
struct Geometry {
    width: usize,
    height: usize,
    depth: Vec<u16>,
    normal: Vec<[u8; 3]>,
}

/// The stored depth of height `z`.
fn depth_code(z: f64) -> u16 {
    ((z + 1.0) * 0.5 * 65535.0).round().clamp(1.0, 65535.0) as u16
}

/// The stored colour of unit normal `n`.
fn normal_code(n: [f64; 3]) -> [u8; 3] {
    n.map(|c| (c * 127.5 + 127.5).round().clamp(0.0, 255.0) as u8)
}

fn unit(n: [f64; 3]) -> Option<[f64; 3]> {
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    (l > 0.0 && l.is_finite()).then(|| n.map(|c| c / l))
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename.
fn write_atomic(path: &str, bytes: &[u8]) -> Result<(), String> {
    let tmp = format!("{path}.tmp{}", std::process::id());
    std::fs::write(&tmp, bytes).map_err(|e| format!("{tmp}: {e}"))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("{path}: {e}"))
}

fn encode_png(
    w: usize,
    h: usize,
    colour: png::ColorType,
    bits: png::BitDepth,
    data: &[u8],
) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w as u32, h as u32);
        enc.set_color(colour);
        enc.set_depth(bits);
        let mut writer = enc.write_header().map_err(|e| format!("PNG: {e}"))?;
        writer.write_image_data(data).map_err(|e| format!("PNG: {e}"))?;
    }
    Ok(out)
}

impl Geometry {
    fn write(&self, prefix: &str) -> Result<(), String> {
        let (w, h) = (self.width, self.height);
        let depth: Vec<u8> = self.depth.iter().flat_map(|d| d.to_be_bytes()).collect();
        let normal: Vec<u8> = self.normal.iter().flatten().copied().collect();
        let d = encode_png(w, h, png::ColorType::Grayscale, png::BitDepth::Sixteen, &depth)?;
        let n = encode_png(w, h, png::ColorType::Rgb, png::BitDepth::Eight, &normal)?;
        write_atomic(&format!("{prefix}.depth.png"), &d)?;
        write_atomic(&format!("{prefix}.normal.png"), &n)
    }

    fn read(prefix: &str) -> Result<Geometry, String> {
        let read = |path: String| -> Result<(usize, usize, png::ColorType, png::BitDepth, Vec<u8>), String> {
            let file = std::fs::File::open(&path).map_err(|e| format!("{path}: {e}"))?;
            let decoder = png::Decoder::new(std::io::BufReader::new(file));
            let mut reader = decoder.read_info().map_err(|e| format!("{path}: {e}"))?;
            let mut buf = vec![0; reader.output_buffer_size().ok_or_else(|| format!("{path}: too large"))?];
            let info = reader.next_frame(&mut buf).map_err(|e| format!("{path}: {e}"))?;
            buf.truncate(info.buffer_size());
            Ok((info.width as usize, info.height as usize, info.color_type, info.bit_depth, buf))
        };
        let dpath = format!("{prefix}.depth.png");
        let (w, h, c, b, dbuf) = read(dpath.clone())?;
        if c != png::ColorType::Grayscale || b != png::BitDepth::Sixteen {
            return Err(format!("{dpath}: not a 16-bit grey PNG ({c:?}, {b:?})"));
        }
        let npath = format!("{prefix}.normal.png");
        let (w2, h2, c2, b2, nbuf) = read(npath.clone())?;
        if c2 != png::ColorType::Rgb || b2 != png::BitDepth::Eight {
            return Err(format!("{npath}: not an 8-bit RGB PNG ({c2:?}, {b2:?})"));
        }
        if (w, h) != (w2, h2) {
            return Err(format!("{dpath} is {w}x{h}, {npath} is {w2}x{h2}"));
        }
        Ok(Geometry {
            width: w,
            height: h,
            depth: dbuf.chunks_exact(2).map(|p| u16::from_be_bytes([p[0], p[1]])).collect(),
            normal: nbuf.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(),
        })
    }
}

/// The render configuration of the view: Fidget samples the voxel corner
/// (-1 + 2j/n, 1 - 2(i+1)/n, -1 + 2k/n); a translation by 1/n moves it to the centre.
fn config(n: usize) -> RenderConfig {
    let shift = 1.0 / n as f32;
    RenderConfig {
        image_size: RenderSize::from(n as u32),
        world_to_model: Matrix4::new_translation(&Vector3::new(shift, shift, shift)),
    }
}

/// Fidget's image in the shared convention: depth d > 0 is voxel d - 1 (z = 1 where
/// saturated, d = n); the normal is the gradient with screen y flipped back, normalised.
/// Also returns the number of hit pixels whose gradient is zero or not finite (Fidget's
/// automatic differentiation gives NaN where, e.g., a `sqrt` argument is 0): their normal is
/// written as (0, 0, 1).
fn geometry(image: &voxel::Image, n: usize) -> (Geometry, usize) {
    let mut bad = 0;
    let mut out = Geometry { width: n, height: n, depth: vec![0; n * n], normal: vec![[0; 3]; n * n] };
    for (o, p) in image.iter().enumerate() {
        let d = p.depth as usize;
        if d == 0 {
            continue;
        }
        let (z, nrm) = if d >= n {
            (1.0, [0.0, 0.0, 1.0])
        } else {
            let [gx, gy, gz] = p.normal.map(f64::from);
            let nrm = unit([gx, -gy, gz]);
            bad += nrm.is_none() as usize;
            (-1.0 + (2 * d - 1) as f64 / n as f64, nrm.unwrap_or([0.0, 0.0, 1.0]))
        };
        out.depth[o] = depth_code(z);
        out.normal[o] = normal_code(nrm);
    }
    (out, bad)
}

/// `voxel MODEL.vm N THREADS RUNS EVAL PREFIX` with evaluator `F`.
pub fn bench<F: Function + MathFunction + RenderHints + Clone>(
    eval: &str,
    model: &str,
    n: usize,
    threads: usize,
    runs: usize,
    prefix: &str,
) -> Result<(), String> {
    let file = std::fs::File::open(model).map_err(|e| format!("{model}: {e}"))?;
    let t0 = Instant::now();
    let (ctx, root) = Context::from_text(file).map_err(|e| format!("{model}: {e}"))?;
    let shape = Shape::<F>::new(&ctx, root).map_err(|e| format!("{model}: {e}"))?;
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let vars = ShapeVars::<f32>::new();
    let bound = shape.bind(&vars).map_err(|e| format!("binding the shape: {e}"))?;
    let cfg = config(n);
    let pool = crate::pool(threads)?;
    let eval_cfg = EvalConfig { threads: pool.as_ref(), ..Default::default() };
    let (image, cold_ms, mut times) =
        crate::time_renders(runs, || voxel::render(bound.clone(), &cfg, &eval_cfg))?;
    let (out, bad_normals) = geometry(&image, n);
    out.write(prefix)?;
    let med = median(&mut times);
    println!(
        "tool=fidget-{eval} size={n} threads={threads} median_ms={med:.2} cold_ms={cold_ms:.2} \
         shape_build_ms={build_ms:.2} hit_px={} nan_normal_px={bad_normals}",
        out.depth.iter().filter(|&&d| d > 0).count()
    );
    Ok(())
}

/// The first surface seen from above in column (x, y): height and unit normal.
fn column(
    clauses: &[crate::prospero::Clause],
    n: usize,
    x: f64,
    y: f64,
    v: &mut Vec<f64>,
) -> Option<(f64, [f64; 3])> {
    let mut f = |z: f64| eval_f64(clauses, x, y, z, v);
    if f(1.0) < 0.0 {
        return Some((1.0, [0.0, 0.0, 1.0]));
    }
    let mut above = 1.0;
    for k in (0..n).rev() {
        let z = -1.0 + (2 * k + 1) as f64 / n as f64;
        if f(z) < 0.0 {
            // f(above) >= 0 (or NaN), f(z) < 0.
            let (mut lo, mut hi) = (z, above);
            for _ in 0..50 {
                let mid = 0.5 * (lo + hi);
                if f(mid) < 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let zs = 0.5 * (lo + hi);
            let h = 1e-6;
            let g = [
                eval_f64(clauses, x + h, y, zs, v) - eval_f64(clauses, x - h, y, zs, v),
                eval_f64(clauses, x, y + h, zs, v) - eval_f64(clauses, x, y - h, zs, v),
                eval_f64(clauses, x, y, zs + h, v) - eval_f64(clauses, x, y, zs - h, v),
            ];
            return Some((zs, unit(g).unwrap_or([0.0, 0.0, 1.0])));
        }
        above = z;
    }
    None
}

/// `reference3d MODEL.vm N STRIDE PREFIX`.
pub fn reference(model: &str, n: usize, stride: usize, prefix: &str) -> Result<(), String> {
    let clauses = read_clauses(model)?;
    let m = n.div_ceil(stride);
    let t = Instant::now();
    let cols: Vec<Option<(f64, [f64; 3])>> = (0..m * m)
        .into_par_iter()
        .map_init(Vec::new, |v, o| {
            let (i, j) = ((o / m) * stride, (o % m) * stride);
            let x = -1.0 + (2 * j + 1) as f64 / n as f64;
            let y = 1.0 - (2 * i + 1) as f64 / n as f64;
            column(&clauses, n, x, y, v)
        })
        .collect();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let out = Geometry {
        width: m,
        height: m,
        depth: cols.iter().map(|c| c.map_or(0, |(z, _)| depth_code(z))).collect(),
        normal: cols.iter().map(|c| c.map_or([0; 3], |(_, nrm)| normal_code(nrm))).collect(),
    };
    out.write(prefix)?;
    println!(
        "reference3d size={n} stride={stride} clauses={} hit_px={} ms={ms:.0}",
        clauses.len(),
        cols.iter().filter(|c| c.is_some()).count()
    );
    Ok(())
}

fn decode_normal(c: [u8; 3]) -> Option<[f64; 3]> {
    unit(c.map(|v| (v as f64 - 127.5) / 127.5))
}

/// `differ3d REF_PREFIX STRIDE IMAGE_PREFIX N`.
pub fn differ(reference: &str, stride: usize, image: &str, n: usize) -> Result<(), String> {
    let r = Geometry::read(reference)?;
    let g = Geometry::read(image)?;
    if (g.width, g.height) != (n, n) {
        return Err(format!("{image}: {}x{} pixels, expected {n}x{n}", g.width, g.height));
    }
    let m = n.div_ceil(stride);
    if (r.width, r.height) != (m, m) {
        return Err(format!(
            "{reference}: {}x{} pixels, expected {m}x{m} (N {n}, stride {stride})",
            r.width, r.height
        ));
    }
    let (mut hit_differ, mut depth_differ, mut both) = (0usize, 0usize, 0usize);
    let mut angles = Vec::new();
    for i in 0..m {
        for j in 0..m {
            let (dr, nr) = (r.depth[i * m + j], r.normal[i * m + j]);
            let o = i * stride * n + j * stride;
            let (dg, ng) = (g.depth[o], g.normal[o]);
            if (dr > 0) != (dg > 0) {
                hit_differ += 1;
                continue;
            }
            if dr == 0 {
                continue;
            }
            both += 1;
            let z = |d: u16| d as f64 / 65535.0 * 2.0 - 1.0;
            // One voxel, plus the depth code's own rounding.
            if (z(dr) - z(dg)).abs() > 2.0 / n as f64 + 2.0 / 65535.0 {
                depth_differ += 1;
            }
            if dr == 65535 || dg == 65535 {
                continue;
            }
            if let (Some(a), Some(b)) = (decode_normal(nr), decode_normal(ng)) {
                let dot = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0);
                angles.push(dot.acos().to_degrees());
            }
        }
    }
    let compared = m * m;
    angles.sort_by(|a, b| a.total_cmp(b));
    let p95 = if angles.is_empty() {
        f64::NAN
    } else {
        angles[((angles.len() - 1) as f64 * 0.95).round() as usize]
    };
    let med = if angles.is_empty() { f64::NAN } else { median(&mut angles) };
    println!(
        "compared={compared} hit_differ={hit_differ} hit_differ_pct={:.4} depth_differ={depth_differ} \
         depth_differ_pct={:.4} normal_deg_median={med:.3} normal_deg_p95={p95:.3}",
        100.0 * hit_differ as f64 / compared as f64,
        if both > 0 { 100.0 * depth_differ as f64 / both as f64 } else { 0.0 },
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sphere of radius 0.3 at (0.4, -0.2, 0.1).
    const SPHERE: &str = "_x var-x\n_y var-y\n_z var-z\n_a const 0.4\n_b const -0.2\n_c const 0.1\n\
        _dx sub _x _a\n_dy sub _y _b\n_dz sub _z _c\n_xx square _dx\n_yy square _dy\n_zz square _dz\n\
        _s add _xx _yy\n_t add _s _zz\n_r sqrt _t\n_k const 0.3\n_f sub _r _k\n";

    fn z_of(d: u16) -> f64 {
        d as f64 / 65535.0 * 2.0 - 1.0
    }

    #[test]
    fn fidget_and_reference_agree_on_an_off_centre_sphere() {
        let path = std::env::temp_dir().join(format!("bench-fidget-sphere-{}.vm", std::process::id()));
        std::fs::write(&path, SPHERE).unwrap();
        let clauses = read_clauses(path.to_str().unwrap()).unwrap();
        std::fs::remove_file(&path).unwrap();
        let n = 64;
        let (ctx, root) = Context::from_text(SPHERE.as_bytes()).unwrap();
        let shape = fidget::vm::VmShape::new(&ctx, root).unwrap();
        let vars = ShapeVars::<f32>::new();
        let eval_cfg = EvalConfig { threads: None, ..Default::default() };
        let image = voxel::render(shape.bind(&vars).unwrap(), &config(n), &eval_cfg).unwrap();
        let (g, bad) = geometry(&image, n);
        assert_eq!(bad, 0);
        let mut v = Vec::new();
        let mut hits = 0;
        for i in 0..n {
            for j in 0..n {
                let x = -1.0 + (2 * j + 1) as f64 / n as f64;
                let y = 1.0 - (2 * i + 1) as f64 / n as f64;
                let r = column(&clauses, n, x, y, &mut v);
                let o = i * n + j;
                assert_eq!(r.is_some(), g.depth[o] > 0, "pixel ({i}, {j})");
                let Some((z, nrm)) = r else { continue };
                hits += 1;
                // The exact sphere height, and Fidget within one voxel of it.
                let want = 0.1 + (0.09 - (x - 0.4).powi(2) - (y + 0.2).powi(2)).sqrt();
                assert!((z - want).abs() < 1e-9, "pixel ({i}, {j}): {z} vs {want}");
                assert!((z_of(g.depth[o]) - z).abs() <= 2.0 / n as f64, "pixel ({i}, {j})");
                // Normals point the same way (not mirrored in y).
                let f = decode_normal(g.normal[o]).unwrap();
                let dot = f[0] * nrm[0] + f[1] * nrm[1] + f[2] * nrm[2];
                assert!(dot > 0.95, "pixel ({i}, {j}): {f:?} vs {nrm:?}");
            }
        }
        assert!(hits > 200, "{hits} pixels hit");
        // The disc's centroid: right of centre (x = 0.4: column 44.3) and below it
        // (y = -0.2: row 37.9), so the image is not mirrored.
        let hit: Vec<usize> = (0..n * n).filter(|&o| g.depth[o] > 0).collect();
        let mean =
            |f: &dyn Fn(usize) -> usize| hit.iter().map(|&o| f(o) as f64).sum::<f64>() / hit.len() as f64;
        let (row, col) = (mean(&|o| o / n), mean(&|o| o % n));
        assert!((row - 37.9).abs() < 0.3 && (col - 44.3).abs() < 0.3, "centroid ({row}, {col})");
    }

    #[test]
    fn top_face_and_codes() {
        assert_eq!(depth_code(1.0), 65535);
        assert_eq!(depth_code(-1.0), 1);
        assert_eq!(normal_code([0.0, 0.0, 1.0]), [128, 128, 255]);
        // The half space z < 0.5: its surface is z = 0.5, normal +z.
        let clauses_path = std::env::temp_dir().join(format!("bench-fidget-half-{}.vm", std::process::id()));
        std::fs::write(&clauses_path, "z var-z\nh const 0.5\nf sub z h\n").unwrap();
        let c = read_clauses(clauses_path.to_str().unwrap()).unwrap();
        std::fs::remove_file(&clauses_path).unwrap();
        let (z, nrm) = column(&c, 32, 0.1, 0.2, &mut Vec::new()).unwrap();
        assert!((z - 0.5).abs() < 1e-12 && (nrm[2] - 1.0).abs() < 1e-9, "{z} {nrm:?}");
    }
}
