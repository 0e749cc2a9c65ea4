//! The Prospero challenge's 2D image with Fidget's own 2D renderer (`fidget::raster::pixel`),
//! JIT or VM evaluator, and the brute-force f64 reference every side is compared with.
//!
//! The image is the square [-1, 1]^2 at SIZE x SIZE pixels, pixel centres
//! x = -1 + (2j+1)/W, y = 1 - (2i+1)/H (row i, column j), inside (white) where the value is
//! negative. Fidget maps pixel (j, i) to x = -1 + 2j/W, y = 1 - 2(i+1)/H (a pixel corner),
//! so the world-to-model matrix shifts by half a pixel (1/W, 1/H) to sample the centres.
//!
//! - `prospero MODEL.vm SIZE THREADS RUNS jit|vm OUT.pgm`: builds the shape from the file
//!   (Fidget's own `.vm` reader), renders once cold, then RUNS timed renders; prints one
//!   line of `key=value` fields; writes the last image as a PGM (255 inside, 0 outside).
//! - `reference MODEL.vm SIZE OUT.pgm`: every pixel evaluated in f64 on the whole program
//!   by the small evaluator below (its own reader; neither Fidget's nor sdfmesh's code).
//! - `differ REF.pgm IMAGE`: pixels of IMAGE (a PGM of this program or sdfmesh's PNG,
//!   inside where the pixel is bright) that differ from REF.

use std::time::Instant;

use fidget::context::Context;
use fidget::eval::{Function, MathFunction};
use fidget::raster::pixel::{self, EvalConfig, RenderConfig, RenderSize};
use fidget::render::RenderHints;
use fidget::shape::{Shape, ShapeVars};
use nalgebra::Matrix3;
use rayon::prelude::*;

use crate::median;

/// The opcodes of a `.vm` file the reference evaluator knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Op {
    X,
    Y,
    Z,
    Const,
    Copy,
    Neg,
    Abs,
    Recip,
    Sqrt,
    Square,
    Floor,
    Ceil,
    Round,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Exp,
    Ln,
    Not,
    Add,
    Sub,
    Mul,
    Div,
    Min,
    Max,
    Atan2,
    Mod,
    Compare,
    And,
    Or,
}

impl Op {
    fn parse(name: &str) -> Option<Op> {
        Some(match name {
            "var-x" => Op::X,
            "var-y" => Op::Y,
            "var-z" => Op::Z,
            "const" => Op::Const,
            "copy" => Op::Copy,
            "neg" => Op::Neg,
            "abs" => Op::Abs,
            "recip" => Op::Recip,
            "sqrt" => Op::Sqrt,
            "square" => Op::Square,
            "floor" => Op::Floor,
            "ceil" => Op::Ceil,
            "round" => Op::Round,
            "sin" => Op::Sin,
            "cos" => Op::Cos,
            "tan" => Op::Tan,
            "asin" => Op::Asin,
            "acos" => Op::Acos,
            "atan" => Op::Atan,
            "exp" => Op::Exp,
            "ln" => Op::Ln,
            "not" => Op::Not,
            "add" => Op::Add,
            "sub" => Op::Sub,
            "mul" => Op::Mul,
            "div" => Op::Div,
            "min" => Op::Min,
            "max" => Op::Max,
            "atan2" => Op::Atan2,
            "mod" => Op::Mod,
            "compare" => Op::Compare,
            "and" => Op::And,
            "or" => Op::Or,
            _ => return None,
        })
    }
}

/// One clause of the reference evaluator: opcode, argument indices (0 where absent),
/// constant.
pub(crate) struct Clause {
    op: Op,
    a: usize,
    b: usize,
    value: f64,
}

/// The clauses of a `.vm` file (its own small reader: `ID OPCODE ARGS...`, `#` comments).
pub(crate) fn read_clauses(path: &str) -> Result<Vec<Clause>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut ids = std::collections::HashMap::new();
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let body = line.split('#').next().unwrap_or("");
        let mut t = body.split_whitespace();
        let Some(id) = t.next() else { continue };
        let name = t.next().ok_or_else(|| format!("{path}:{}: no opcode", n + 1))?;
        let op = Op::parse(name).ok_or_else(|| format!("{path}:{}: unknown opcode {name:?}", n + 1))?;
        let rest: Vec<&str> = t.collect();
        let (args, value) = if op == Op::Const {
            let v = rest.first().and_then(|s| s.parse::<f64>().ok());
            (Vec::new(), v.ok_or_else(|| format!("{path}:{}: bad constant", n + 1))?)
        } else {
            let a = rest
                .iter()
                .map(|s| ids.get(*s).copied().ok_or_else(|| format!("{path}:{}: unknown id {s}", n + 1)))
                .collect::<Result<Vec<usize>, String>>()?;
            (a, 0.0)
        };
        ids.insert(id.to_string(), out.len());
        let a = args.first().copied().unwrap_or(0);
        let b = args.get(1).copied().unwrap_or(0);
        out.push(Clause { op, a, b, value });
    }
    if out.is_empty() {
        return Err(format!("{path}: no clauses"));
    }
    Ok(out)
}

/// The f64 value of the program at (x, y, z); `v` is scratch.
pub(crate) fn eval_f64(clauses: &[Clause], x: f64, y: f64, z: f64, v: &mut Vec<f64>) -> f64 {
    v.clear();
    for c in clauses {
        let a = v.get(c.a).copied().unwrap_or(0.0);
        let b = v.get(c.b).copied().unwrap_or(0.0);
        let nan2 = a.is_nan() || b.is_nan();
        let r = match c.op {
            Op::X => x,
            Op::Y => y,
            Op::Z => z,
            Op::Const => c.value,
            Op::Copy => a,
            Op::Neg => -a,
            Op::Abs => a.abs(),
            Op::Recip => 1.0 / a,
            Op::Sqrt => a.sqrt(),
            Op::Square => a * a,
            Op::Floor => a.floor(),
            Op::Ceil => a.ceil(),
            Op::Round => a.round(),
            Op::Sin => a.sin(),
            Op::Cos => a.cos(),
            Op::Tan => a.tan(),
            Op::Asin => a.asin(),
            Op::Acos => a.acos(),
            Op::Atan => a.atan(),
            Op::Exp => a.exp(),
            Op::Ln => a.ln(),
            Op::Not => (a == 0.0) as u8 as f64,
            Op::Add => a + b,
            Op::Sub => a - b,
            Op::Mul => a * b,
            Op::Div => a / b,
            Op::Min if nan2 => f64::NAN,
            Op::Min => a.min(b),
            Op::Max if nan2 => f64::NAN,
            Op::Max => a.max(b),
            Op::Atan2 => a.atan2(b),
            Op::Mod => a.rem_euclid(b),
            Op::Compare if nan2 => f64::NAN,
            Op::Compare => (a > b) as i32 as f64 - (a < b) as i32 as f64,
            Op::And => {
                if a == 0.0 {
                    a
                } else {
                    b
                }
            }
            Op::Or => {
                if a != 0.0 {
                    a
                } else {
                    b
                }
            }
        };
        v.push(r);
    }
    *v.last().unwrap_or(&f64::NAN)
}

fn write_pgm(path: &str, n: usize, inside: &[bool]) -> Result<(), String> {
    let mut bytes = format!("P5\n{n} {n}\n255\n").into_bytes();
    bytes.extend(inside.iter().map(|&b| if b { 255u8 } else { 0 }));
    std::fs::write(path, bytes).map_err(|e| format!("{path}: {e}"))
}

/// `reference MODEL.vm SIZE OUT.pgm`.
pub fn reference(model: &str, n: usize, out: &str) -> Result<(), String> {
    let clauses = read_clauses(model)?;
    let t = Instant::now();
    let inside: Vec<bool> = (0..n * n)
        .into_par_iter()
        .map_init(Vec::new, |v, k| {
            let (i, j) = (k / n, k % n);
            let x = -1.0 + (2 * j + 1) as f64 / n as f64;
            let y = 1.0 - (2 * i + 1) as f64 / n as f64;
            eval_f64(&clauses, x, y, 0.0, v) < 0.0
        })
        .collect();
    write_pgm(out, n, &inside)?;
    println!(
        "reference size={n}x{n} clauses={} inside_px={} ms={:.0}",
        clauses.len(),
        inside.iter().filter(|&&b| b).count(),
        t.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}

/// Reads a PGM written here or a PNG: (width, height, inside per pixel: value >= 128).
fn read_mask(path: &str) -> Result<(usize, usize, Vec<bool>), String> {
    if path.ends_with(".pgm") {
        let raw = std::fs::read(path).map_err(|e| format!("{path}: {e}"))?;
        let header: Vec<&[u8]> = raw.splitn(4, |b| *b == b'\n').collect();
        if header.len() != 4 || header[0] != b"P5" {
            return Err(format!("{path}: not a binary PGM written by this program"));
        }
        let dims = String::from_utf8_lossy(header[1]).to_string();
        let (w, h) = dims
            .split_once(' ')
            .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
            .ok_or_else(|| format!("{path}: bad size line {dims:?}"))?;
        if header[3].len() != w * h {
            return Err(format!("{path}: {} bytes of pixels, expected {}", header[3].len(), w * h));
        }
        return Ok((w, h, header[3].iter().map(|&b| b >= 128).collect()));
    }
    let file = std::fs::File::open(path).map_err(|e| format!("{path}: {e}"))?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().map_err(|e| format!("{path}: {e}"))?;
    let mut buf = vec![0; reader.output_buffer_size().ok_or("PNG too large")?];
    let info = reader.next_frame(&mut buf).map_err(|e| format!("{path}: {e}"))?;
    let c = info.color_type.samples();
    let (w, h) = (info.width as usize, info.height as usize);
    Ok((w, h, (0..w * h).map(|i| buf[i * c] >= 128).collect()))
}

/// `differ REF.pgm IMAGE`: prints `differ=N inside_ref=N inside=N`.
pub fn differ(reference: &str, image: &str) -> Result<(), String> {
    let (w, h, r) = read_mask(reference)?;
    let (w2, h2, m) = read_mask(image)?;
    if (w, h) != (w2, h2) {
        return Err(format!("sizes differ: {reference} {w}x{h}, {image} {w2}x{h2}"));
    }
    let d = r.iter().zip(&m).filter(|(a, b)| a != b).count();
    println!(
        "differ={d} inside_ref={} inside={} percent={:.4}",
        r.iter().filter(|&&b| b).count(),
        m.iter().filter(|&&b| b).count(),
        100.0 * d as f64 / (w * h) as f64
    );
    Ok(())
}

/// `prospero MODEL.vm SIZE THREADS RUNS EVAL OUT.pgm` with evaluator `F`.
pub fn bench<F: Function + MathFunction + RenderHints + Clone>(
    eval: &str,
    model: &str,
    n: usize,
    threads: usize,
    runs: usize,
    out: &str,
) -> Result<(), String> {
    let file = std::fs::File::open(model).map_err(|e| format!("{model}: {e}"))?;
    let t0 = Instant::now();
    let (ctx, root) = Context::from_text(file).map_err(|e| format!("{model}: {e}"))?;
    let shape = Shape::<F>::new(&ctx, root).map_err(|e| format!("{model}: {e}"))?;
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let vars = ShapeVars::<f32>::new();
    let bound = shape.bind(&vars).map_err(|e| format!("binding the shape: {e}"))?;
    // Pixel centres: Fidget samples x = -1 + 2j/n, y = 1 - 2(i+1)/n.
    let shift = 1.0 / n as f32;
    let cfg = RenderConfig {
        world_to_model: Matrix3::new_translation(&nalgebra::Vector2::new(shift, shift)),
        ..RenderConfig::from_size(RenderSize::from(n as u32))
    };
    let pool = crate::pool(threads)?;
    let eval_cfg = EvalConfig { threads: pool.as_ref(), ..Default::default() };
    let (image, cold_ms, mut times) =
        crate::time_renders(runs, || pixel::render(bound.clone(), &cfg, &eval_cfg))?;
    let inside: Vec<bool> = image.iter().map(|p| p.inside()).collect();
    write_pgm(out, n, &inside)?;
    let med = median(&mut times);
    let samples: Vec<String> = times.iter().map(|t| format!("{t:.2}")).collect();
    println!(
        "fidget2d eval={eval} size={n}x{n} threads={threads} runs={runs} median_ms={med:.2} cold_ms={cold_ms:.2} \
         shape_build_ms={build_ms:.2} inside_px={} samples_ms={}",
        inside.iter().filter(|&&b| b).count(),
        samples.join(",")
    );
    Ok(())
}
