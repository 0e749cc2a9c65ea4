//! `.vm` implicit models: the 2D image against a brute-force f64 evaluation of every pixel
//! on the models of `../shared/implicit` (skipped with a message where that folder is
//! missing), and `toolkit render MODEL.vm` end to end, bad files included.

use std::path::{Path, PathBuf};
use std::process::Command;

use sdfmesh::implicit::image2d::{render_2d, render_2d_reference};
use sdfmesh::implicit::load_vm;

fn shared(name: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/implicit").join(name);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipped: {} is missing", p.display());
        None
    }
}

fn differing(name: &str, w: usize, h: usize) -> Option<(usize, usize)> {
    let path = shared(name)?;
    let ssa = load_vm(&path).unwrap();
    let (fast, census) = render_2d(&ssa, w, h);
    assert_eq!(census.filled + census.evaluated, (w * h) as u64);
    let slow = render_2d_reference(&ssa, w, h);
    let d = fast.inside.iter().zip(&slow.inside).filter(|(a, b)| a != b).count();
    let inside = slow.inside.iter().filter(|&&v| v == 1).count();
    Some((d, inside))
}

#[test]
fn two_d_images_agree_with_brute_force_f64() {
    for (name, w, h) in [("hi.vm", 512, 512), ("quarter.vm", 512, 384), ("prospero.vm", 256, 256)] {
        let Some((d, inside)) = differing(name, w, h) else { continue };
        // Not a blank image, and at most 0.01% of pixels differ.
        assert!(inside > 100 && inside < w * h - 100, "{name}: {inside} inside");
        assert!(d * 10_000 <= w * h, "{name}: {d} of {} pixels differ", w * h);
    }
}

#[test]
fn render_writes_the_prospero_image_and_refuses_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_toolkit");
    let model = dir.path().join("disc.vm");
    std::fs::write(&model, "x var-x\ny var-y\na square x\nb square y\nc add a b\nr const 0.25\no sub c r\n")
        .unwrap();
    let png = dir.path().join("d.png");
    let out = Command::new(exe)
        .args([
            "render",
            model.to_str().unwrap(),
            "--width",
            "40",
            "--height",
            "20",
            "-o",
            png.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (40, 20));
    assert_eq!(img.get_pixel(20, 10).0, [255; 3]);
    assert_eq!(img.get_pixel(0, 0).0, [0; 3]);

    let bad = dir.path().join("bad.vm");
    std::fs::write(&bad, "x var-x\ny frob x\n").unwrap();
    let png2 = dir.path().join("bad.png");
    let out = Command::new(exe)
        .args(["render", bad.to_str().unwrap(), "-o", png2.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.vm:2:3: unknown opcode `frob`"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!png2.exists());
}

/// The hit/miss image of a 3D model's preview scene (`toolkit render MODEL.vm`'s camera at
/// `size` x `size`) traced by the safe marcher, against an independent reference: each
/// primary ray clipped to the cube [-1, 1]^3 by its own slab test and sampled densely in
/// f64 (a step of 0.002, a twentieth of a pixel at the model) with an evaluator written
/// here over the clauses; a ray hits where a sample is negative. Returns (pixels that
/// differ, reference hits, marcher's ms, point and interval evaluations per ray).
fn three_d_disagreement(name: &str, size: u32) -> Option<(usize, usize, f64, f64, f64)> {
    use rayon::prelude::*;
    use sdfmesh::geometry::march::MarchParams;
    use sdfmesh::geometry::{Geometry, RayStats};
    use sdfmesh::implicit::ops::{Opcode, apply_f64};
    use sdfmesh::plan::{Representation, build_scene};
    use sdfmesh::scene::camera::RayGenerator;
    use sdfmesh::scene::shape::Shading;

    let path = shared(name)?;
    let mut scene = sdfmesh::scene::load_input(&path, Shading::Flat).unwrap();
    scene.camera.width = size;
    scene.camera.height = size;
    let rg = RayGenerator::new(&scene.camera);
    let rays: Vec<_> = (0..size * size).map(|i| rg.ray(i % size, i / size)).collect();

    let start = std::time::Instant::now();
    let geometry = build_scene(&scene, Representation::Sdf { march: MarchParams::default() });
    let mut stats = RayStats::default();
    let ours: Vec<bool> =
        rays.iter().map(|r| geometry.closest_hit(r, 0.0, f32::INFINITY, &mut stats).is_some()).collect();
    let ms = start.elapsed().as_secs_f64() * 1e3;

    let ssa = load_vm(&path).unwrap();
    let eval = |p: [f64; 3], v: &mut Vec<f64>| {
        v.clear();
        for c in &ssa.clauses {
            let r = match c.op {
                Opcode::VarX => p[0],
                Opcode::VarY => p[1],
                Opcode::VarZ => p[2],
                Opcode::Const => c.value,
                op => apply_f64(op, v[c.a as usize], v[c.b as usize]),
            };
            v.push(r);
        }
        *v.last().unwrap()
    };
    let step = 0.002;
    let reference: Vec<bool> = rays
        .par_iter()
        .map_init(Vec::new, |v, r| {
            let o: [f64; 3] = r.origin.as_dvec3().to_array();
            let d: [f64; 3] = r.dir.as_dvec3().to_array();
            let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
            for a in 0..3 {
                if d[a] == 0.0 {
                    if o[a].abs() > 1.0 {
                        return false;
                    }
                    continue;
                }
                let (p, q): (f64, f64) = ((-1.0 - o[a]) / d[a], (1.0 - o[a]) / d[a]);
                t0 = t0.max(p.min(q));
                t1 = t1.min(p.max(q));
            }
            let mut t = t0;
            while t <= t1 {
                if eval([o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]], v) < 0.0 {
                    return true;
                }
                t += step;
            }
            let end = eval([o[0] + t1 * d[0], o[1] + t1 * d[1], o[2] + t1 * d[2]], v);
            t0 <= t1 && end < 0.0
        })
        .collect();
    let differ = ours.iter().zip(&reference).filter(|(a, b)| a != b).count();
    let only_ours = ours.iter().zip(&reference).filter(|(a, b)| **a && !**b).count();
    eprintln!("{name}: {only_ours} hits only in ours, {} only in the reference", differ - only_ours);
    let hits = reference.iter().filter(|&&h| h).count();
    let n = rays.len() as f64;
    Some((differ, hits, ms, stats.march_steps as f64 / n, stats.interval_evals as f64 / n))
}

#[test]
fn three_d_models_step_over_no_surface() {
    let size = 80;
    for name in ["bear.vm", "colonnade.vm", "alien.vm", "bolt.vm", "geode.vm", "tanglecube.vm"] {
        let Some((differ, hits, ms, points, intervals)) = three_d_disagreement(name, size) else { continue };
        eprintln!(
            "{name}: {differ} of {} pixels differ in hit/miss ({hits} hits); {ms:.0} ms, {points:.1} point \
             and {intervals:.1} interval evaluations per ray",
            size * size
        );
        let pixels = (size * size) as usize;
        assert!(hits > pixels / 100, "{name}: only {hits} hits: the model is not in view");
        assert!(differ * 1000 <= pixels, "{name}: {differ} of {pixels} pixels differ in hit/miss");
    }
}
