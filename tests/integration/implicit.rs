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

/// `toolkit render MODEL.vm --heightmap`: the 16-bit height image holds the encoded height
/// of the first surface from above (a sphere of radius 0.5 at the origin: 1 at the centre
/// pixel's z = 0.5), the RGB image its normal; a 2D model, a scene file and a --repr are
/// refused with one line and no image.
#[test]
fn render_writes_a_heightmap_and_refuses_what_has_none() {
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_toolkit");
    let model = dir.path().join("ball.vm");
    std::fs::write(
        &model,
        "x var-x\ny var-y\nz var-z\na square x\nb square y\nc square z\nd add a b\ne add d c\nr const 0.25\no sub e r\n",
    )
    .unwrap();
    let (depth, normal) = (dir.path().join("h.png"), dir.path().join("n.png"));
    let run = |args: &[&str]| Command::new(exe).args(args).output().unwrap();
    let out = run(&[
        "render",
        model.to_str().unwrap(),
        "--heightmap",
        depth.to_str().unwrap(),
        "-o",
        normal.to_str().unwrap(),
        "--width",
        "33",
        "--height",
        "33",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let h = image::open(&depth).unwrap().to_luma16();
    // Pixel 16 of 33 is the centre: z = 0.5 there, encoded as round(0.75 * 65535), within the
    // bisection's bracket (a thousandth of the half-pixel tolerance: 2 codes).
    let centre = h.get_pixel(16, 16)[0] as i32;
    assert!((centre - (0.75f64 * 65535.0).round() as i32).abs() <= 2, "{centre}");
    assert_eq!(h.get_pixel(0, 0)[0], 0);
    let n = image::open(&normal).unwrap().to_rgb8();
    assert_eq!(n.get_pixel(16, 16).0, [128, 128, 255]);
    // A pixel right of the centre leans to +x.
    assert!(n.get_pixel(24, 16)[0] > 160, "{:?}", n.get_pixel(24, 16));

    let flat = dir.path().join("disc.vm");
    std::fs::write(&flat, "x var-x\ny var-y\na square x\nb square y\nc add a b\nr const 0.25\no sub c r\n")
        .unwrap();
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/thesis_sdf_csg.toml");
    let d2 = dir.path().join("h2.png");
    for args in [
        vec!["render", flat.to_str().unwrap(), "--heightmap", d2.to_str().unwrap(), "-o", "n2.png"],
        vec!["render", scene.to_str().unwrap(), "--heightmap", d2.to_str().unwrap(), "-o", "n2.png"],
        vec![
            "render",
            model.to_str().unwrap(),
            "--repr",
            "grid",
            "--heightmap",
            d2.to_str().unwrap(),
            "-o",
            "n2.png",
        ],
    ] {
        let out = run(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(!d2.exists());
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
    use sdfmesh::geometry::march::MarchParams;
    use sdfmesh::geometry::{Geometry, RayStats};
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
    let lines: Vec<([f64; 3], [f64; 3])> =
        rays.iter().map(|r| (r.origin.as_dvec3().to_array(), r.dir.as_dvec3().to_array())).collect();
    let reference: Vec<bool> = dense_first_hits(&ssa, &lines, 0.002).iter().map(Option::is_some).collect();
    let differ = ours.iter().zip(&reference).filter(|(a, b)| a != b).count();
    let only_ours = ours.iter().zip(&reference).filter(|(a, b)| **a && !**b).count();
    eprintln!("{name}: {only_ours} hits only in ours, {} only in the reference", differ - only_ours);
    let hits = reference.iter().filter(|&&h| h).count();
    let n = rays.len() as f64;
    Some((differ, hits, ms, stats.march_steps as f64 / n, stats.interval_evals as f64 / n))
}

/// The value of `ssa` at `p` in f64, by an evaluator written here (`v` is scratch).
fn eval_f64_here(ssa: &sdfmesh::implicit::Ssa, p: [f64; 3], v: &mut Vec<f64>) -> f64 {
    use sdfmesh::implicit::ops::{Opcode, apply_f64};
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
}

/// The independent reference of the 3D tests: each line `o + t d` clipped to the cube
/// [-1, 1]^3 by its own slab test and sampled every `step` (in `t`) in f64 by an evaluator
/// written here over the clauses (no code of the marcher); the first sample where the value
/// is negative (or the line's exit point, when negative there), as `t`, or `None`.
fn dense_first_hits(
    ssa: &sdfmesh::implicit::Ssa,
    lines: &[([f64; 3], [f64; 3])],
    step: f64,
) -> Vec<Option<f64>> {
    use rayon::prelude::*;
    let eval = |p: [f64; 3], v: &mut Vec<f64>| eval_f64_here(ssa, p, v);
    lines
        .par_iter()
        .map_init(Vec::new, |v, &(o, d)| {
            let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
            for a in 0..3 {
                if d[a] == 0.0 {
                    if o[a].abs() > 1.0 {
                        return None;
                    }
                    continue;
                }
                let (p, q): (f64, f64) = ((-1.0 - o[a]) / d[a], (1.0 - o[a]) / d[a]);
                t0 = t0.max(p.min(q));
                t1 = t1.min(p.max(q));
            }
            let at = |t: f64| [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
            let mut t = t0;
            while t <= t1 {
                if eval(at(t), v) < 0.0 {
                    return Some(t);
                }
                t += step;
            }
            (t0 <= t1 && eval(at(t1), v) < 0.0).then_some(t1)
        })
        .collect()
}

/// The heightmap view (`toolkit render MODEL.vm --heightmap`, rays cast as bundles) of every
/// 3D model against [`dense_first_hits`] down each pixel's column: at most 0.1% of pixels
/// differ in hit/miss, and where both hit, the heights agree within a sample step plus the
/// hit tolerance (half a pixel) on all but 0.1% of them. Not counted: a reference hit passed
/// over where the solid is thinner along the column than the tolerance (as the marcher
/// promises), and a hit of ours above the reference's where a sample of a twelfth of the
/// tolerance finds the solid (a thin feature the reference's step missed).
#[test]
fn heightmaps_step_over_no_surface() {
    use sdfmesh::implicit::field3d::{CELLS, Field3};
    use sdfmesh::implicit::heightmap::{pixel_centre, render_heightmap};
    let n = 96;
    for name in ["bear.vm", "colonnade.vm", "alien.vm", "bolt.vm", "geode.vm", "tanglecube.vm"] {
        let Some(path) = shared(name) else { continue };
        let ssa = load_vm(&path).unwrap();
        let map = render_heightmap(&Field3::new(ssa.clone(), CELLS), n, n);
        let lines: Vec<([f64; 3], [f64; 3])> = (0..n * n)
            .map(|k| {
                let (x, y) = pixel_centre(k % n, k / n, n, n);
                ([x, y, 1.0], [0.0, 0.0, -1.0])
            })
            .collect();
        let step = 0.002;
        let reference = dense_first_hits(&ssa, &lines, step);
        let (mut differ, mut far, mut hits, mut slivers, mut fine_hits) = (0, 0, 0, 0, 0);
        let mut v = Vec::new();
        let tol = 1.0 / n as f64;
        let fine = 1e-4;
        for (k, (p, r)) in map.pixels.iter().zip(&reference).enumerate() {
            let (o, d) = lines[k];
            let mut f =
                |t: f64| eval_f64_here(&ssa, [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]], &mut v);
            // A sliver passed over (allowed): the solid's run along the column through `t`
            // is no longer than the tolerance.
            let passed = |t: f64, f: &mut dyn FnMut(f64) -> f64| {
                let (mut a, mut b) = (t, t);
                while a - fine >= 0.0 && f(a - fine) < 0.0 {
                    a -= fine;
                }
                while b + fine <= 2.0 && f(b + fine) < 0.0 {
                    b += fine;
                }
                b - a <= tol + 2.0 * fine
            };
            // A root of ours that the reference's coarser samples stepped over: some fine
            // sample within the tolerance of it is inside.
            let real = |t: f64, f: &mut dyn FnMut(f64) -> f64| {
                (-12..=12).any(|i| f(t + i as f64 * tol / 12.0) < 0.0)
            };
            match (p.z, r) {
                (Some(z), Some(t)) => {
                    hits += 1;
                    let ours = 1.0 - z;
                    if (ours - t).abs() > step + tol + 1e-9 {
                        // Ours deeper: the reference's hit must be a sliver we may pass;
                        // ours higher: a thin feature the reference stepped over.
                        let ok = if ours > *t { passed(*t, &mut f) } else { real(ours, &mut f) };
                        if ok { fine_hits += 1 } else { far += 1 }
                    }
                }
                (None, None) => {}
                (Some(z), None) => {
                    if real(1.0 - z, &mut f) {
                        fine_hits += 1
                    } else {
                        differ += 1
                    }
                }
                (None, Some(t)) => {
                    if passed(*t, &mut f) {
                        slivers += 1
                    } else {
                        differ += 1
                    }
                }
            }
        }
        eprintln!(
            "{name}: {differ} of {} pixels differ in hit/miss, {far} of {hits} hits in height; besides, \
             {slivers} slivers thinner than the tolerance passed over, {fine_hits} thin features the \
             reference's samples stepped over",
            n * n
        );
        assert!(hits > n * n / 100, "{name}: only {hits} hits");
        assert!(differ * 1000 <= n * n, "{name}: {differ} pixels differ in hit/miss");
        assert!(far * 1000 <= hits, "{name}: {far} of {hits} heights differ");
    }
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

/// Malformed models through `toolkit render`: exit 2, one line naming the file and the line,
/// no image; a 10^6-clause chain is read (and its 3D render refused by nothing but its size
/// is not tried here: `convert`'s budget and the reader's limits cover that).
#[test]
fn malformed_models_get_one_line_with_the_line_number() {
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_toolkit");
    let cases = [
        ("unknown.vm", "x var-x\ny var-y\nz frob x\n", "unknown.vm:3:3: unknown opcode `frob`"),
        ("missing.vm", "x var-x\ny add x\n", "missing.vm:2:3: `add` takes 2 arguments, found 1"),
        ("undefined.vm", "x var-x\ny add x q\n", "undefined.vm:2:9: ID `q` is not defined"),
        ("cycle.vm", "a add b b\nb var-x\n", "cycle.vm:1:7: ID `b` is not defined"),
        ("nan.vm", "x var-x\nk const nan\no add x k\n", "nan.vm:2:9: constant `nan` is not finite"),
    ];
    for (name, text, want) in cases {
        let model = dir.path().join(name);
        std::fs::write(&model, text).unwrap();
        let png = dir.path().join(format!("{name}.png"));
        let out = Command::new(exe)
            .args(["render", model.to_str().unwrap(), "-o", png.to_str().unwrap()])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{name}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(want), "{name}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{name}: {err}");
        assert!(!png.exists(), "{name}");
    }
    // 10^6 clauses: read, and an error past the end names its line.
    let mut big = String::from("x var-x\n");
    for i in 0..1_000_000 {
        let prev = if i == 0 { "x".to_string() } else { format!("_{}", i - 1) };
        big.push_str(&format!("_{i} add {prev} x\n"));
    }
    big.push_str("bad frob x\n");
    let model = dir.path().join("big.vm");
    std::fs::write(&model, &big).unwrap();
    let out = Command::new(exe)
        .args(["render", model.to_str().unwrap(), "-o", dir.path().join("big.png").to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("big.vm:1000002:5: unknown opcode `frob`"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

/// Writes `ball.vm` into `dir`: |p|^2 - 0.36, not a distance (a sphere of radius 0.6).
fn write_ball(dir: &Path) -> PathBuf {
    let model = dir.join("ball.vm");
    std::fs::write(
        &model,
        "x var-x\ny var-y\nz var-z\na square x\nb square y\nc square z\nd add a b\ne add d c\nr const 0.36\n\
         o sub e r\n",
    )
    .unwrap();
    model
}

/// A 3D model end to end: `toolkit render` draws it in the preview scene, `convert` makes a
/// closed mesh and a grid of it (saying what the grid stores), and a scene file places it
/// with a transform and a material.
#[test]
fn three_d_models_render_convert_and_sit_in_scenes() {
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_toolkit");
    let model = write_ball(dir.path());
    let run = |args: &[&str]| {
        let out = Command::new(exe).args(args).output().unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let png = dir.path().join("ball.png");
    let text = run(&[
        "render",
        model.to_str().unwrap(),
        "--width",
        "48",
        "--height",
        "48",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(text.contains("not a distance"), "{text}");
    let img = image::open(&png).unwrap().to_rgb8();
    assert_ne!(img.get_pixel(24, 24).0, [0; 3], "the ball is in the middle of the view");
    assert_eq!(img.get_pixel(0, 0).0, [0; 3]);

    let obj = dir.path().join("ball.obj");
    let text = run(&[
        "convert",
        model.to_str().unwrap(),
        "-o",
        obj.to_str().unwrap(),
        "--to",
        "mesh",
        "--res",
        "32",
    ]);
    assert!(text.contains("closed: true"), "{text}");
    let grid = dir.path().join("ball.sdf");
    let text = run(&[
        "convert",
        model.to_str().unwrap(),
        "-o",
        grid.to_str().unwrap(),
        "--to",
        "grid",
        "--res",
        "24",
    ]);
    assert!(text.contains("exact signed distance to the model's surface"), "{text}");
    let g = sdfmesh::grid::io::load_grid(&grid).unwrap();
    // The grid's centre sample is about -0.6 (inside, 0.6 from the surface).
    let c = g.trilinear(glam::Vec3::ZERO);
    assert!((c + 0.6).abs() < 0.05, "{c}");

    let scene = dir.path().join("s.toml");
    std::fs::write(
        &scene,
        "[camera]\nposition = [0, 0, 6]\nlook_at = [0, 0, 0]\nwidth = 40\nheight = 40\n\
         [[lights]]\ntype = \"ambient\"\nintensity = 1.0\n\
         [materials.red]\ncolor = [1, 0, 0]\n\
         [[objects]]\ntype = \"implicit\"\npath = \"ball.vm\"\nmaterial = \"red\"\ntranslate = [0.5, 0, 0]\n",
    )
    .unwrap();
    let png = dir.path().join("s.png");
    run(&["render", scene.to_str().unwrap(), "-o", png.to_str().unwrap()]);
    let img = image::open(&png).unwrap().to_rgb8();
    let p = img.get_pixel(20, 20).0;
    assert!(p[0] > 100 && p[1] == 0 && p[2] == 0, "{p:?}");
}

/// `compare` of a 3D model: the model is prepared once when the input is loaded and shared
/// by the runs, and each run's measured heap peak counts it (as if the run had prepared it),
/// so a marched run's peak is not a few frame buffers below the model it holds. At 16 x 16
/// the frame's own buffers are a few kB and the model's 32^3 cells over 100 kB: without the
/// prepared model counted, the peak is a small fraction of the declared bytes.
#[test]
fn a_marched_models_heap_peak_counts_its_prepared_cells() {
    let dir = tempfile::tempdir().unwrap();
    let model = write_ball(dir.path());
    let csv = dir.path().join("rows.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_toolkit"))
        .args(["compare", "--csv"])
        .arg(&csv)
        .arg(&model)
        .args(["--res", "16", "--frames", "1", "--quiet", "--width", "16", "--height", "16"])
        .args(["--sdf-tolerance-px", "1", "--sdf-relax", "1"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = sdfmesh::compare::read_rows(&csv).unwrap();
    let marched: Vec<_> = rows.iter().filter(|r| r.repr == "sdf" && r.method == "sphere-trace").collect();
    assert!(!marched.is_empty());
    for r in marched {
        let heap = r.peak_heap_bytes.expect("a heap peak");
        // The declared bytes count the model's vectors by capacity, the measured copy by length.
        assert!(
            heap * 2 >= r.geometry_bytes,
            "{} at {:?}: heap peak {heap} against {} bytes declared",
            r.method,
            r.tolerance_px,
            r.geometry_bytes
        );
    }
}
