//! `toolkit compare INPUT --check-reference`: an independent check of an input's reference
//! (issue #37, item 4).
//!
//! The reference every run of a scene is measured against is closed form where the scene has
//! one, and otherwise sphere traced by the same tape marcher the `sdf` runs use (at a finer
//! tolerance). This check finds every primary ray's first root a second way that shares no
//! code with the marcher, its tapes, its SIMD lanes or its pruning: the object trees
//! ([`SdfTree`]) evaluated in f64, one scalar point at a time, stepped by their distance bound
//! (never past a surface: the bound is Lipschitz 1) but at least [`MIN_STEP_PX`] pixels, and
//! the sign change then bisected to [`BISECTIONS`] halvings. Its own error: the root to
//! within 2^-60 of the last step, and a feature thinner than the minimum step may be stepped
//! over (a miss where the reference hits). The result compares hit/miss per pixel and the hit
//! distance in pixels where both hit.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{build, catch_panic, load_single, plan, write_csv_whole};
use crate::config::CompareOptions;
use crate::error::Result;
use crate::geometry::sdf::SdfTree;
use crate::metrics;
use crate::scene::camera::RayGenerator;

/// The smallest step near a surface, pixels at the distance travelled.
pub const MIN_STEP_PX: f64 = 1e-3;
/// Halvings of the last step once the sign has changed.
pub const BISECTIONS: u32 = 60;
/// Steps per ray before the ray is called undecided (a graze along a surface).
pub const MAX_STEPS: u32 = 200_000;

/// One input's check: a row of the reference check CSV.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RefCheck {
    /// Input name.
    pub input: String,
    /// Class of the input.
    pub class: String,
    /// `repr/method` of the reference checked.
    pub reference: String,
    /// Pixels (primary rays).
    pub pixels: u64,
    /// Pixels the reference hits.
    pub reference_hits: u64,
    /// Pixels the independent root finder hits.
    pub independent_hits: u64,
    /// Pixels where exactly one of the two hits, percent.
    pub mismatch_pct: f64,
    /// 95th percentile of |t_reference - t_independent| in pixels at the hit's distance, over
    /// the pixels both hit; empty when none is.
    pub p95_px: Option<f64>,
    /// The largest of the same.
    pub max_px: Option<f64>,
    /// Rays that ran out of steps (counted as misses).
    pub undecided: u64,
    /// Mean tree evaluations per ray of the independent finder.
    pub steps_per_ray: f64,
    /// Time of the independent finder, ms.
    pub ms: f64,
    /// Why the input was not checked (empty when it was).
    pub skipped: String,
}

/// The first root along `o + t d`, `t` in `(0, t_max]`, of the union of `trees` (the minimum
/// of their values), with `angle` the pixel angle; `Err(steps)` when the ray is undecided.
fn first_root(
    trees: &[SdfTree],
    o: DVec3,
    d: DVec3,
    t_max: f64,
    angle: f64,
    steps: &mut u64,
) -> Result<Option<f64>, ()> {
    let f = |t: f64| trees.iter().map(|tree| tree.distance(o + d * t)).fold(f64::INFINITY, f64::min);
    let mut t = 0.0;
    let mut v = f(t);
    *steps += 1;
    if v <= 0.0 {
        return Ok(Some(0.0));
    }
    for _ in 0..MAX_STEPS {
        let step = v.max(MIN_STEP_PX * angle * t.max(1e-9));
        let next = t + step;
        if next > t_max {
            return Ok(None);
        }
        let w = f(next);
        *steps += 1;
        if w <= 0.0 {
            // A sign change in (t, next]: bisect it.
            let (mut lo, mut hi) = (t, next);
            for _ in 0..BISECTIONS {
                let mid = 0.5 * (lo + hi);
                *steps += 1;
                if f(mid) > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            return Ok(Some(hi));
        }
        t = next;
        v = w;
    }
    Err(())
}

/// Runs the check on `opts`' single input and writes its row to `opts.csv` (atomically).
///
/// # Errors
/// The input does not load, the reference cannot be built, the CSV cannot be written.
pub fn check_reference_command(opts: &CompareOptions) -> Result<String> {
    let (_, name, class, scene) = load_single(opts, "--check-reference")?;
    let runs = plan(&scene, opts);
    let reference = &runs[0];
    let label = format!("{}/{}", reference.repr, reference.method());
    let mut row = RefCheck {
        input: name.clone(),
        class,
        reference: label.clone(),
        pixels: u64::from(scene.camera.width) * u64::from(scene.camera.height),
        reference_hits: 0,
        independent_hits: 0,
        mismatch_pct: 0.0,
        p95_px: None,
        max_px: None,
        undecided: 0,
        steps_per_ray: 0.0,
        ms: 0.0,
        skipped: String::new(),
    };
    let trees: Vec<Option<SdfTree>> = scene.objects.iter().map(SdfTree::for_marching).collect();
    if let Some(i) = trees.iter().position(Option::is_none) {
        let o = &scene.objects[i];
        row.skipped = if o.kind_name() == "implicit" {
            format!(
                "object {} is an implicit model: no distance tree (its safe marcher is checked against a dense f64 reference by the test suite)",
                o.label
            )
        } else {
            format!(
                "object {} is a {}: no distance tree (the reference is that object itself)",
                o.label,
                o.kind_name()
            )
        };
    } else {
        let trees: Vec<SdfTree> = trees.into_iter().flatten().collect();
        let built = catch_panic(|| build(&scene, reference.build, &opts.budget)).and_then(|r| r)?;
        let max_distance = scene.settings.max_distance;
        let probe = metrics::probe(&scene.camera, &built.geometry, max_distance);
        let rays = RayGenerator::new(&scene.camera);
        let angle = metrics::pixel_angle(&scene.camera);
        let (w, h) = (scene.camera.width, scene.camera.height);
        let start = Instant::now();
        let found: Vec<(Option<f64>, bool, u64)> = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let ray = rays.ray(i % w, i / w);
                let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3().normalize());
                let mut steps = 0;
                match first_root(&trees, o, d, f64::from(max_distance), angle, &mut steps) {
                    Ok(t) => (t, false, steps),
                    Err(()) => (None, true, steps),
                }
            })
            .collect();
        row.ms = start.elapsed().as_secs_f64() * 1e3;
        let origin = scene.camera.position.as_dvec3();
        let mut points = probe.points.iter();
        let mut errors = Vec::new();
        let mut mismatched = 0u64;
        for (hit, (t, undecided, _)) in probe.hits.iter().zip(&found) {
            let reference_t = if *hit { points.next().map(|p| (*p - origin).length()) } else { None };
            row.reference_hits += u64::from(*hit);
            row.independent_hits += u64::from(t.is_some());
            row.undecided += u64::from(*undecided);
            match (reference_t, t) {
                (Some(a), Some(b)) => errors.push((a - b).abs() / (angle * a.max(*b)).max(f64::MIN_POSITIVE)),
                (None, None) => {}
                _ => mismatched += 1,
            }
        }
        row.mismatch_pct = 100.0 * mismatched as f64 / row.pixels.max(1) as f64;
        row.steps_per_ray = found.iter().map(|f| f.2 as f64).sum::<f64>() / found.len().max(1) as f64;
        if !errors.is_empty() {
            errors.sort_by(f64::total_cmp);
            row.p95_px = Some(errors[((errors.len() - 1) as f64 * 0.95).round() as usize]);
            row.max_px = errors.last().copied();
        }
    }
    write_csv_whole(&opts.csv, std::slice::from_ref(&row))?;
    Ok(if row.skipped.is_empty() {
        format!(
            "{name}: reference {label} against f64 root finding on the object trees: {:.3}% of pixels differ in hit/miss, p95 {} px, max {} px ({} undecided rays, {:.0} evaluations per ray, {:.0} ms)\n",
            row.mismatch_pct,
            row.p95_px.map_or("-".into(), |p| format!("{p:.3}")),
            row.max_px.map_or("-".into(), |p| format!("{p:.3}")),
            row.undecided,
            row.steps_per_ray,
            row.ms
        )
    } else {
        format!("{name}: not checked: {}\n", row.skipped)
    })
}
