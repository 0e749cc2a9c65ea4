//! Analytic SDF evaluation throughput: the f64 object tree ([`SdfTree::distance`], what the
//! marcher evaluates today) against its compiled f32 tape ([`Tape::eval`], one point) and
//! the tape eight points at a time ([`Tape::eval8`], AVX2 where the CPU has it), on one
//! thread.
//!
//! Workloads: every analytic object of each bundled scene (`data/scenes/*.toml`) and of the
//! hard case `data/hard/ground_5000.toml`, a smooth union of 16 spheres, and a level-3
//! Menger sponge (a box minus three finitely repeated crosses). Points: uniform in each
//! object's bounds grown by 20% (a cube of side 20 around the camera for an unbounded
//! object), the same points for every evaluator; a scene's row covers all its objects.
//! Columns: `ops` tape length (summed over the objects), `Meval/s` million evaluations per
//! second (median of the timed rounds, evaluators interleaved round by round), the speed-ups
//! against the tree, `err` the largest `|tape - tree|` over the points in units of the
//! tape's own error estimate `Tape::error_bound(|p_rel|)` (must stay <= 1), and `f32 ok` how
//! many objects pass `Tape::f32_is_enough` at the hit tolerance of the default march seen
//! from the scene's camera (`MarchParams::tolerance(t, size)` with `t` the tree's distance
//! at the camera, the pixel footprint from the camera).
//!
//! `cargo bench --bench sdf_eval` runs it and writes its output to
//! `reports/bench/sdf_eval.txt`; without `--bench` (as under `cargo test --all-targets`) it
//! runs a quick smoke check with few points and short timings.

mod common;

use common::{Out, Rng, header};
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DVec3, UVec3, Vec3};
use sdfmesh::geometry::march::MarchParams;
use sdfmesh::geometry::sdf::SdfTree;
use sdfmesh::geometry::sdf::tape::{Tape, TapeScratch};
use sdfmesh::metrics::median;
use sdfmesh::scene::shape::{CsgOp, Object, ObjectKind, Primitive};
use sdfmesh::scene::transform::TransformDesc;
use sdfmesh::scene::{Camera, load_scene};

/// What one run measures.
#[derive(Clone, Copy, Debug)]
struct Plan {
    /// Points per object (a multiple of 8).
    points: usize,
    /// Timed rounds per evaluator.
    rounds: usize,
    /// Minimum seconds per timed round (passes over the points are repeated until then).
    secs: f64,
}

const FULL: Plan = Plan { points: 8192, rounds: 5, secs: 0.2 };
const SMOKE: Plan = Plan { points: 64, rounds: 1, secs: 0.0 };

/// One object prepared for every evaluator: the tree, the tape, and the same points as
/// world f64 points, tape-relative f32 points and eight-lane groups.
struct Prepared {
    tree: SdfTree,
    tape: Tape,
    world: Vec<DVec3>,
    rel: Vec<Vec3>,
    lanes: Vec<[[f32; 8]; 3]>,
    f32_ok: bool,
}

fn prepare(o: &Object, camera: &Camera, n: usize, rng: &mut Rng) -> Option<Prepared> {
    let tree = SdfTree::for_marching(o)?;
    let tape = Tape::from_object(o)?;
    let (lo, hi) = match o.bounds() {
        Some(b) => {
            let (lo, hi) = (Vec3::from(b.min).as_dvec3(), Vec3::from(b.max).as_dvec3());
            let grow = (hi - lo) * 0.1;
            (lo - grow, hi + grow)
        }
        None => {
            let c = camera.position.as_dvec3();
            (c - DVec3::splat(10.0), c + DVec3::splat(10.0))
        }
    };
    let world: Vec<DVec3> = (0..n)
        .map(|_| {
            let u = DVec3::new(rng.unit(), rng.unit(), rng.unit());
            lo + (hi - lo) * u
        })
        .collect();
    // The tree evaluated at exactly the points the tape sees.
    let rel: Vec<Vec3> = world.iter().map(|&p| tape.relative(p)).collect();
    let world: Vec<DVec3> = rel.iter().map(|&p| tape.origin + p.as_dvec3()).collect();
    let lanes = rel
        .chunks_exact(8)
        .map(|c| {
            [
                std::array::from_fn(|l| c[l].x),
                std::array::from_fn(|l| c[l].y),
                std::array::from_fn(|l| c[l].z),
            ]
        })
        .collect();
    let size = o.bounds().map_or(1.0, |b| b.diagonal().length() as f64);
    let footprint = 2.0 * (camera.fov_y_deg as f64 * 0.5).to_radians().tan() / camera.height as f64;
    let march = MarchParams { pixel_footprint: footprint, ..MarchParams::default() };
    let t = tree.distance(camera.position.as_dvec3()).abs();
    let f32_ok = tape.f32_is_enough(march.tolerance(t, size));
    Some(Prepared { tree, tape, world, rel, lanes, f32_ok })
}

/// One workload: a name and its prepared objects.
struct Workload {
    name: String,
    objects: Vec<Prepared>,
}

/// Seconds of one pass of `f` repeated until `min_secs`, per point; and the passes' sum.
fn time(min_secs: f64, points: usize, mut f: impl FnMut() -> f32) -> f64 {
    let start = Instant::now();
    let mut passes = 0usize;
    let mut sink = 0.0f32;
    loop {
        sink += f();
        passes += 1;
        if start.elapsed().as_secs_f64() >= min_secs {
            break;
        }
    }
    black_box(sink);
    (passes * points) as f64 / start.elapsed().as_secs_f64() / 1e6
}

/// Throughput of the three evaluators (Meval/s medians) and the worst error ratio.
fn measure(w: &Workload, plan: &Plan) -> ([f64; 3], f64) {
    let points: usize = w.objects.iter().map(|o| o.world.len()).sum();
    let mut scratch: Vec<TapeScratch> = w.objects.iter().map(|o| TapeScratch::new(&o.tape)).collect();
    let mut rates = [Vec::new(), Vec::new(), Vec::new()];
    for _ in 0..plan.rounds {
        rates[0].push(time(plan.secs, points, || {
            let mut s = 0.0;
            for o in &w.objects {
                for &p in &o.world {
                    s += o.tree.distance(black_box(p)) as f32;
                }
            }
            s
        }));
        rates[1].push(time(plan.secs, points, || {
            let mut s = 0.0;
            for (o, sc) in w.objects.iter().zip(scratch.iter_mut()) {
                for &p in &o.rel {
                    s += o.tape.eval(black_box(p), sc);
                }
            }
            s
        }));
        rates[2].push(time(plan.secs, points, || {
            let mut s = 0.0;
            for (o, sc) in w.objects.iter().zip(scratch.iter_mut()) {
                for [xs, ys, zs] in &o.lanes {
                    let d = o.tape.eval8(black_box(xs), ys, zs, sc);
                    s += d[0] + d[7];
                }
            }
            s
        }));
    }
    let mut worst = 0.0f64;
    for (o, sc) in w.objects.iter().zip(scratch.iter_mut()) {
        for (&p, &world) in o.rel.iter().zip(&o.world) {
            let err = (o.tape.eval(p, sc) as f64 - o.tree.distance(world)).abs();
            worst = worst.max(err / o.tape.error_bound(p.length() as f64));
        }
    }
    (rates.map(|r| median(&r)), worst)
}

fn sphere(radius: f32, translate: Vec3) -> Object {
    Object {
        kind: ObjectKind::Primitive(Primitive::Sphere { radius }),
        transform: TransformDesc { translate, ..Default::default() },
        material: 0,
        label: "sphere".into(),
    }
}

/// 16 spheres of radius 0.3 to 0.6 on a wobbly ring, smooth union with k = 0.3.
fn sixteen_spheres() -> Object {
    let children = (0..16)
        .map(|i| {
            let a = i as f32 * std::f32::consts::TAU / 16.0;
            let r = 0.3 + 0.3 * ((i * 7) % 5) as f32 / 4.0;
            sphere(r, Vec3::new(2.0 * a.cos(), 0.5 * (3.0 * a).sin(), 2.0 * a.sin()))
        })
        .collect();
    Object {
        kind: ObjectKind::Csg { op: CsgOp::SmoothUnion { k: 0.3 }, children },
        transform: TransformDesc { translate: Vec3::new(0.0, 0.0, 8.0), ..Default::default() },
        material: 0,
        label: "16 spheres".into(),
    }
}

/// A level-3 Menger sponge of side 2: a box minus, at each level, a cross of three bars
/// repeated 3^level times per axis.
fn menger() -> Object {
    let plain = |kind: ObjectKind| Object {
        kind,
        transform: TransformDesc::default(),
        material: 0,
        label: "m".into(),
    };
    let bar = |half: Vec3| plain(ObjectKind::Primitive(Primitive::Box { half }));
    let mut children = vec![bar(Vec3::ONE)];
    for level in 0..3 {
        let cell = 2.0 / 3f32.powi(level);
        let (w, long) = (cell / 6.0, cell / 2.0);
        let cross = plain(ObjectKind::Csg {
            op: CsgOp::Union,
            children: vec![
                bar(Vec3::new(long, w, w)),
                bar(Vec3::new(w, long, w)),
                bar(Vec3::new(w, w, long)),
            ],
        });
        let n = 3u32.pow(level as u32);
        children.push(plain(ObjectKind::Repeat {
            period: Vec3::splat(cell),
            count: Some(UVec3::splat(n)),
            child: Box::new(cross),
        }));
    }
    Object {
        kind: ObjectKind::Csg { op: CsgOp::Subtraction, children },
        transform: TransformDesc { translate: Vec3::new(0.0, 0.0, 6.0), ..Default::default() },
        material: 0,
        label: "menger".into(),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let full = args.iter().any(|a| a == "--bench");
    let plan = if full { FULL } else { SMOKE };
    let mut out = Out::default();
    if full {
        out.line(header());
    } else {
        out.line("smoke mode (run with `cargo bench --bench sdf_eval` for the benchmark)");
    }
    out.line(format!(
        "analytic SDF evaluation, 1 thread: f64 tree vs f32 tape, scalar and 8-wide ({}); {} points per \
         object, {} timed rounds of >= {} s per evaluator, interleaved",
        if sdfmesh::simd::avx2().is_some() { "AVX2" } else { "portable, no AVX2" },
        plan.points,
        plan.rounds,
        plan.secs
    ));
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut files: Vec<PathBuf> = std::fs::read_dir(root.join("data/scenes"))
        .expect("data/scenes")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files.push(root.join("data/hard/ground_5000.toml"));
    let mut rng = Rng(0x5eed);
    let mut workloads = Vec::new();
    let name = |p: &Path| p.file_stem().map_or("?".into(), |s| s.to_string_lossy().into_owned());
    for path in &files {
        let scene = load_scene(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let objects: Vec<Prepared> =
            scene.objects.iter().filter_map(|o| prepare(o, &scene.camera, plan.points, &mut rng)).collect();
        if !objects.is_empty() {
            workloads.push(Workload { name: name(path), objects });
        }
    }
    let camera = Camera::default();
    for o in [sixteen_spheres(), menger()] {
        let objects = vec![prepare(&o, &camera, plan.points, &mut rng).expect("analytic")];
        workloads.push(Workload { name: o.label.clone(), objects });
    }
    out.line("");
    out.line(format!(
        "{:<28} {:>4} {:>6} {:>9} {:>9} {:>9} {:>7} {:>7} {:>6} {:>6}",
        "workload", "objs", "ops", "tree", "tape", "tape8", "tape/", "tape8/", "err", "f32"
    ));
    out.line(format!(
        "{:<28} {:>4} {:>6} {:>9} {:>9} {:>9} {:>7} {:>7} {:>6} {:>6}",
        "", "", "", "Meval/s", "Meval/s", "Meval/s", "tree", "tree", "/bound", "ok"
    ));
    let mut worst_all = 0.0f64;
    for w in &workloads {
        let ([tree, tape, tape8], worst) = measure(w, &plan);
        worst_all = worst_all.max(worst);
        let ops: usize = w.objects.iter().map(|o| o.tape.ops().len()).sum();
        let ok = w.objects.iter().filter(|o| o.f32_ok).count();
        out.line(format!(
            "{:<28} {:>4} {:>6} {:>9.2} {:>9.2} {:>9.2} {:>7.2} {:>7.2} {:>6.3} {:>3}/{:<2}",
            w.name,
            w.objects.len(),
            ops,
            tree,
            tape,
            tape8,
            tape / tree,
            tape8 / tree,
            worst,
            ok,
            w.objects.len()
        ));
    }
    out.line(
        "\nMeval/s: million distance evaluations per second on one thread (tree: SdfTree::distance \
         in f64; tape: Tape::eval; tape8: Tape::eval8, counted per point). err/bound: the worst \
         |tape - tree| over the workload's points divided by Tape::error_bound(|p_rel|). f32 ok: \
         objects for which Tape::f32_is_enough at the tolerance they are marched with from the \
         scene's camera (the rest would keep the f64 tree). A smooth union is one chain of \
         dependent blends, so one point at a time waits on its latency while eight lanes fill it.",
    );
    assert!(worst_all <= 1.0, "the tape left its error bound: {worst_all}");
    if full {
        let path = root.join("reports/bench/sdf_eval.txt");
        match std::fs::write(&path, &out.text) {
            Ok(()) => println!("written to {}", path.display()),
            Err(e) => println!("could not write {}: {e}", path.display()),
        }
    }
}
