//! The hard-case suite (`data/hard`, `toolkit hard`): numerically hard scenes and broken
//! meshes rendered in every representation and measured against a reference render, with
//! a stated tolerance per case and the expected outcome per representation.
//!
//! The manifest (`data/hard/cases.toml`) lists the cases:
//!
//! ```toml
//! [[case]]
//! name = "grazing"
//! input = "grazing.toml"      # a scene file, or a mesh file framed by the preview camera
//! about = "what is hard here"
//! metric = "silhouette"       # or "pixels"
//! tolerance = 0.99            # the smallest fraction of agreeing pixels that passes
//! resolution = 64             # of the mesh and grid representations
//! expect = { sdf = "pass", mesh = "pass", grid = "fail" }
//! ```
//!
//! The reference is the `analytic` representation (closed form where there is one; a mesh
//! file is traced as its own triangles there). Metrics, over all pixels of the two images:
//! `silhouette`, the fraction whose hit/miss status (background colour or not) agrees;
//! `pixels`, the fraction whose every channel is within [`PIXEL_TOLERANCE`] of the
//! reference. A representation passes when the fraction is at least `tolerance`. An
//! `expect` of `"fail"` records a known limit (documented in `data/hard/README.md`); the
//! suite checks that every outcome is what the manifest expects, so a limit that goes away
//! or a case that starts failing is noticed. Each outcome also reports the sphere-tracing
//! step-limit misses of the frame: they are counted, never hidden.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use image::RgbImage;
use serde::Deserialize;

use crate::config::CASE_RESOLUTION;
use crate::error::{Error, Result, catch_panic};
use crate::geometry::march::MarchParams;
use crate::plan::budget::MemoryBudget;
use crate::plan::{GridFill, GridStorage, MeshMethod, MeshPlane, ReprKind, Representation};
use crate::render::report::render_scene;
use crate::scene::load_input;
use crate::scene::shape::Shading;

/// Largest difference per channel (0..255) for a pixel to agree under the `pixels` metric.
pub const PIXEL_TOLERANCE: u8 = 16;

/// The representations every case is run in (besides the reference).
pub const REPRS: [ReprKind; 3] = [ReprKind::Sdf, ReprKind::Mesh, ReprKind::Grid];

/// How a case compares a render with the reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Metric {
    /// Fraction of pixels whose hit/miss status agrees.
    Silhouette,
    /// Fraction of pixels within [`PIXEL_TOLERANCE`] in every channel.
    Pixels,
}

/// The outcome a case expects of a representation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Expect {
    /// Meets the tolerance.
    Pass,
    /// A known limit: misses the tolerance.
    Fail,
}

/// One case of the manifest.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Case {
    /// Short name.
    pub name: String,
    /// Scene or mesh file, relative to the manifest's folder.
    pub input: PathBuf,
    /// What makes the case hard, and what each representation does.
    pub about: String,
    /// How renders are compared.
    pub metric: Metric,
    /// Smallest agreeing fraction that passes, in (0, 1].
    pub tolerance: f64,
    /// Resolution of the mesh and grid representations (default 64).
    #[serde(default = "default_resolution")]
    pub resolution: u32,
    /// Expected outcome per representation name ([`REPRS`]).
    pub expect: BTreeMap<String, Expect>,
}

fn default_resolution() -> u32 {
    64
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    case: Vec<Case>,
}

/// What one representation did on one case.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// The case's name.
    pub case: String,
    /// Representation name.
    pub repr: &'static str,
    /// Agreeing fraction of pixels, in [0, 1].
    pub value: f64,
    /// The case's tolerance.
    pub tolerance: f64,
    /// Whether `value >= tolerance`.
    pub passed: bool,
    /// What the manifest expects.
    pub expected: Expect,
    /// Sphere-tracing marches that hit the step limit in the frame.
    pub step_limit_hits: u64,
    /// How the objects were traced (the geometry's description).
    pub how: String,
}

impl Outcome {
    /// Whether the outcome is what the manifest expects.
    pub fn as_expected(&self) -> bool {
        self.passed == (self.expected == Expect::Pass)
    }
}

/// A case whose input file is missing (e.g. a shared mesh not present on this machine).
#[derive(Clone, Debug)]
pub struct Skipped {
    /// The case's name.
    pub case: String,
    /// Why.
    pub why: String,
}

/// Reads and checks a manifest. Inputs are resolved relative to its folder.
///
/// # Errors
/// When the file cannot be read, is not valid TOML of the documented shape, or a case has
/// a tolerance outside (0, 1], a resolution outside [`CASE_RESOLUTION`] (3..=512), or an
/// `expect` naming an unknown representation or missing one.
pub fn load_cases(manifest: &Path) -> Result<Vec<Case>> {
    let text = crate::files::read_input_text(manifest, crate::files::MAX_TEXT_BYTES)?;
    let m: Manifest = toml::from_str(&text).map_err(|e| Error::input(manifest, None, e.message()))?;
    let dir = manifest.parent().unwrap_or(Path::new(""));
    let mut cases = m.case;
    for c in &mut cases {
        let bad = |msg: String| Error::input(manifest, None, format!("case '{}': {msg}", c.name));
        if !(c.tolerance > 0.0 && c.tolerance <= 1.0) {
            return Err(bad(format!("tolerance must be in (0, 1], got {}", c.tolerance)));
        }
        CASE_RESOLUTION.check("resolution", c.resolution).map_err(|e| bad(e.to_string()))?;
        for k in c.expect.keys() {
            if !REPRS.iter().any(|r| r.name() == k) {
                return Err(bad(format!(
                    "expect: unknown representation '{k}'; valid: {}",
                    REPRS.map(ReprKind::name).join(", ")
                )));
            }
        }
        c.input = dir.join(&c.input);
    }
    Ok(cases)
}

/// The representation `kind` at `resolution`.
fn representation(kind: ReprKind, resolution: u32) -> Representation {
    let march = MarchParams::default();
    match kind {
        ReprKind::Sdf => Representation::Sdf { march },
        ReprKind::Mesh => Representation::Mesh {
            resolution,
            shading: Shading::Smooth,
            method: MeshMethod::Parametric,
            plane: MeshPlane::ClosedForm,
            march,
        },
        ReprKind::Grid => {
            Representation::Grid { resolution, fill: GridFill::Sample, storage: GridStorage::Dense, march }
        }
        ReprKind::Analytic => Representation::Analytic { march },
    }
}

/// Fraction of pixels that agree under `metric`, given the background colour.
pub fn agreement(metric: Metric, a: &RgbImage, b: &RgbImage, background: [u8; 3]) -> f64 {
    let n = (a.width() * a.height()).max(1) as f64;
    let ok = a
        .pixels()
        .zip(b.pixels())
        .filter(|(p, q)| match metric {
            Metric::Silhouette => (p.0 == background) == (q.0 == background),
            Metric::Pixels => p.0.iter().zip(q.0.iter()).all(|(x, y)| x.abs_diff(*y) <= PIXEL_TOLERANCE),
        })
        .count();
    ok as f64 / n
}

/// Runs one case in the reference and every representation its `expect` names; `Err`
/// when its input cannot be loaded, `Ok(Err(skipped))` when the input file is missing.
pub fn run_case(case: &Case, budget: &MemoryBudget) -> Result<std::result::Result<Vec<Outcome>, Skipped>> {
    if !case.input.exists() {
        let why = format!("{} not found", case.input.display());
        return Ok(Err(Skipped { case: case.name.clone(), why }));
    }
    let scene = load_input(&case.input, Shading::Smooth)?;
    // The evaluation and memory budgets, as `render` checks them, before anything is built.
    for kind in std::iter::once(ReprKind::Analytic)
        .chain(REPRS.into_iter().filter(|k| case.expect.contains_key(k.name())))
    {
        let what = format!("the {kind} representation of {}", case.input.display());
        budget.check_scene(&what, &scene, representation(kind, case.resolution))?;
    }
    let bg = scene.settings.background.to_array().map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8);
    let reference = render_scene(&scene, representation(ReprKind::Analytic, case.resolution));
    let mut out = Vec::new();
    for kind in REPRS {
        let Some(&expected) = case.expect.get(kind.name()) else { continue };
        let r = render_scene(&scene, representation(kind, case.resolution));
        let value = agreement(case.metric, &reference.frame.image, &r.frame.image, bg);
        let how =
            r.text.lines().filter(|l| l.starts_with("  ")).map(str::trim).collect::<Vec<_>>().join("; ");
        out.push(Outcome {
            case: case.name.clone(),
            repr: kind.name(),
            value,
            tolerance: case.tolerance,
            passed: value >= case.tolerance,
            expected,
            step_limit_hits: r.frame.stats.step_limit_hits,
            how,
        });
    }
    Ok(Ok(out))
}

/// A Markdown table of outcomes: case, representation, result, tolerance, step-limit
/// misses, and whether the outcome is the expected one.
pub fn table(outcomes: &[Outcome], skipped: &[Skipped]) -> String {
    let mut t = String::from(
        "| case | representation | agreement | tolerance | result | expected | step-limit misses |\n\
         |---|---|---:|---:|---|---|---:|\n",
    );
    for o in outcomes {
        let result = if o.passed { "pass" } else { "fail" };
        let expected = match (o.expected, o.as_expected()) {
            (Expect::Pass, _) => "pass",
            (Expect::Fail, true) => "fail (known limit)",
            (Expect::Fail, false) => "fail",
        };
        let mark = if o.as_expected() { "" } else { " **UNEXPECTED**" };
        let _ = writeln!(
            t,
            "| {} | {} | {:.4} | {:.3} | {result}{mark} | {expected} | {} |",
            o.case, o.repr, o.value, o.tolerance, o.step_limit_hits
        );
    }
    for s in skipped {
        let _ = writeln!(t, "| {} | all | - | - | skipped: {} | - | - |", s.case, s.why);
    }
    t
}

/// `toolkit hard`: runs every case of `manifest` within `budget` and returns the table (also
/// written to `table_out` when given), and whether every outcome was the expected one.
///
/// # Errors
/// When the manifest or a present input cannot be read, or the table cannot be written.
pub fn hard_command(
    manifest: &Path,
    table_out: Option<&Path>,
    budget: &MemoryBudget,
) -> Result<(String, bool)> {
    let cases = load_cases(manifest)?;
    let mut outcomes = Vec::new();
    let mut skipped = Vec::new();
    let mut failed = 0;
    for c in &cases {
        // A case that cannot be loaded or fails (a panic included) is reported in the table
        // and on stderr, the others still run, and the suite is not as expected.
        match catch_panic(|| run_case(c, budget)).and_then(|r| r) {
            Ok(Ok(o)) => outcomes.extend(o),
            Ok(Err(s)) => skipped.push(s),
            Err(e) => {
                eprintln!("error: case {}: {e}", c.name);
                skipped.push(Skipped { case: c.name.clone(), why: format!("error: {e}") });
                failed += 1;
            }
        }
    }
    let ok = failed == 0 && outcomes.iter().all(Outcome::as_expected);
    let text = table(&outcomes, &skipped);
    if let Some(path) = table_out {
        crate::files::write_atomic_bytes(path, text.as_bytes())?;
    }
    Ok((text, ok))
}
