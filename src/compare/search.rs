//! `compare --search`: the search of one knob family to the quality levels (issue #37,
//! "search each side's knobs to the level"), instead of a fixed list of resolutions.
//!
//! A family is one way of making a run with one integer knob where a larger knob is finer
//! (a grid or mesh resolution, a decimation's fraction of triangles in basis points, the
//! inverse of a hit tolerance). For each quality level, coarsest first, [`search`]:
//! 1. **doubles** the knob from [`Spec::start`] (or from the largest knob tried so far)
//!    until a run meets the level, the next knob would exceed the memory budget (`fits`
//!    says no: the level is [`Stop::Budget`] unmet) or the cap was tried and failed
//!    ([`Stop::Cap`]); a level left unmet leaves every finer level unmet for the same reason;
//! 2. **bisects** (where [`Spec::bisect`]) between the largest knob that failed below the
//!    smallest that met, until they are within [`Spec::min_gap`] or a tenth of the met knob;
//! 3. answers the smallest knob *tried* that met the level, and goes on to the next finer
//!    level from everything tried so far.
//!
//! Every knob is evaluated at most once (a cache by knob value); a run meeting a finer
//! level meets the coarser ones too (the levels are nested), so one run can settle several.
//!
//! Quality is not strictly monotone in the knob (a coarse grid can hit the reference's
//! silhouette by luck, a finer one miss it). Bisection assumes monotonicity, so with a
//! non-monotone family the answer may not be the smallest knob meeting the level, but it is
//! always a knob whose run met the level (the answer is taken from the runs, never
//! inferred); and a lucky coarse run that met the level is the answer when it is the
//! smallest tried. The unit tests below pin both.

use std::collections::BTreeMap;
use std::fmt;

/// How one family's knob is searched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Spec {
    /// The first knob tried.
    pub start: u32,
    /// The largest knob tried.
    pub cap: u32,
    /// Bisect after doubling (otherwise the search only doubles: the hit tolerance).
    pub bisect: bool,
    /// Bisection stops when the failed and met knobs are this close (or within a tenth of
    /// the met knob).
    pub min_gap: u32,
}

/// Which step of the search ran a candidate (the CSV's `note`: `search=double`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// Doubling towards the level.
    Double,
    /// Bisection between a failed and a met knob.
    Bisect,
}

impl fmt::Display for Step {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Step::Double => "double",
            Step::Bisect => "bisect",
        })
    }
}

/// Why a level was not met.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// The next knob's run would exceed the memory budget.
    Budget,
    /// The cap was tried and failed.
    Cap,
}

impl fmt::Display for Stop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Stop::Budget => "budget",
            Stop::Cap => "cap",
        })
    }
}

/// One candidate the search asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Probe {
    /// The knob.
    pub knob: u32,
    /// The step that asks for it.
    pub step: Step,
    /// The level (pixels) it probes.
    pub level: f64,
    /// Where this is the last knob that doubling can try, why: when this run fails the
    /// level, the level is unmet for that reason.
    pub last: Option<Stop>,
}

impl Probe {
    /// The text the candidate's CSV row carries in its `note` given the quality it met
    /// (`quality_px`): `search=double level=2px`, with ` unmet=cap` or ` unmet=budget` when
    /// the level is left unmet with this run, and ` last=cap` or ` last=budget` when this is
    /// the last knob doubling can try but its run met the level: a finer level this run does
    /// not meet is then unmet for that reason, though the search asks for no run there (the
    /// knob is cached).
    pub fn note(&self, quality: Option<f64>) -> String {
        let mut s = format!("search={} level={}px", self.step, self.level);
        if let Some(stop) = self.last {
            let why = if meets(quality, self.level) { "last" } else { "unmet" };
            s += &format!(" {why}={stop}");
        }
        s
    }
}

/// What the search found for one level.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Found {
    /// The smallest knob tried that met the level.
    Met(u32),
    /// Not met: why, and the largest knob tried (`None`: not even the start fits).
    Unmet {
        /// Budget or cap.
        stop: Stop,
        /// The largest knob tried.
        largest: Option<u32>,
    },
}

/// The result of one family's search.
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    /// Every candidate run, in order: the probe and the quality it met.
    pub tried: Vec<(Probe, Option<f64>)>,
    /// Per level (as given, coarsest first), what was found.
    pub levels: Vec<(f64, Found)>,
}

/// Whether a run of quality `quality` (its finest level met, pixels) meets `level`.
pub fn meets(quality: Option<f64>, level: f64) -> bool {
    quality.is_some_and(|q| q <= level + 1e-12)
}

/// Searches one family (see the module header): `levels` in pixels, coarsest first;
/// `fits(knob)` whether a run at `knob` stays within the memory budget; `eval` runs a
/// candidate and returns the finest level it met (`None`: none, or the run failed).
pub fn search(
    spec: Spec,
    levels: &[f64],
    fits: impl Fn(u32) -> bool,
    mut eval: impl FnMut(&Probe) -> Option<f64>,
) -> Outcome {
    let cap = spec.cap.max(1);
    let start = spec.start.clamp(1, cap);
    let mut cache: BTreeMap<u32, Option<f64>> = BTreeMap::new();
    let mut tried = Vec::new();
    let mut found = Vec::new();
    let mut run = |probe: Probe, cache: &mut BTreeMap<u32, Option<f64>>| {
        debug_assert!(!cache.contains_key(&probe.knob));
        let q = eval(&probe);
        cache.insert(probe.knob, q);
        tried.push((probe, q));
    };
    let smallest_met = |cache: &BTreeMap<u32, Option<f64>>, level| {
        cache.iter().find(|(_, q)| meets(**q, level)).map(|(k, _)| *k)
    };
    let mut unmet: Option<Found> = None;
    for &level in levels {
        if let Some(u) = unmet {
            found.push((level, u));
            continue;
        }
        // Doubling.
        let hi = loop {
            if let Some(k) = smallest_met(&cache, level) {
                break Some(k);
            }
            let largest = cache.keys().next_back().copied();
            let next = match largest {
                None => start,
                Some(k) if k >= cap => {
                    unmet = Some(Found::Unmet { stop: Stop::Cap, largest });
                    break None;
                }
                Some(k) => k.saturating_mul(2).min(cap),
            };
            if !fits(next) {
                unmet = Some(Found::Unmet { stop: Stop::Budget, largest });
                break None;
            }
            let last = if next >= cap {
                Some(Stop::Cap)
            } else if !fits(next.saturating_mul(2).min(cap)) {
                Some(Stop::Budget)
            } else {
                None
            };
            run(Probe { knob: next, step: Step::Double, level, last }, &mut cache);
        };
        let Some(mut hi) = hi else {
            found.push((level, unmet.expect("set when doubling stops")));
            continue;
        };
        // Bisection between the largest knob below the smallest met one (it failed) and it.
        while let Some(lo) = cache.range(..hi).next_back().map(|(k, _)| *k).filter(|_| spec.bisect) {
            if hi - lo <= spec.min_gap.max(hi / 10).max(1) {
                break;
            }
            let mid = lo + (hi - lo) / 2;
            run(Probe { knob: mid, step: Step::Bisect, level, last: None }, &mut cache);
            hi = smallest_met(&cache, level).expect("hi met the level");
        }
        found.push((level, Found::Met(hi)));
    }
    Outcome { tried, levels: found }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LEVELS: [f64; 3] = [2.0, 1.0, 0.5];
    const RES: Spec = Spec { start: 8, cap: 1024, bisect: true, min_gap: 4 };

    /// A monotone family: the finest level met at `k` from thresholds per level.
    fn monotone(k: u32, t2: u32, t1: u32, t05: u32) -> Option<f64> {
        if k >= t05 {
            Some(0.5)
        } else if k >= t1 {
            Some(1.0)
        } else if k >= t2 {
            Some(2.0)
        } else {
            None
        }
    }

    fn run(spec: Spec, fits: impl Fn(u32) -> bool, q: impl Fn(u32) -> Option<f64>) -> Outcome {
        let out = search(spec, &LEVELS, fits, |p| q(p.knob));
        // Never the same knob twice.
        let mut knobs: Vec<u32> = out.tried.iter().map(|(p, _)| p.knob).collect();
        let n = knobs.len();
        knobs.sort_unstable();
        knobs.dedup();
        assert_eq!(knobs.len(), n, "a knob was run twice: {:?}", out.tried);
        out
    }

    #[test]
    fn monotone_finds_the_smallest_within_the_gap() {
        let out = run(RES, |_| true, |k| monotone(k, 37, 100, 300));
        let met: Vec<u32> = out
            .levels
            .iter()
            .map(|(_, f)| match f {
                Found::Met(k) => *k,
                f => panic!("unmet: {f:?}"),
            })
            .collect();
        for (&k, t) in met.iter().zip([37, 100, 300]) {
            assert!(k >= t && k - t <= (k / 10).max(4), "{k} for threshold {t}");
        }
        // Doubling then bisection, both recorded; far fewer runs than every resolution.
        assert!(out.tried.iter().any(|(p, _)| p.step == Step::Bisect));
        assert_eq!(out.tried[0].0, Probe { knob: 8, step: Step::Double, level: 2.0, last: None });
        assert!(out.tried.len() < 25, "{} runs", out.tried.len());
    }

    #[test]
    fn one_run_can_settle_several_levels() {
        // 8 fails, 16 meets 0.5 px: every level at 16, bisection between 8 and 16 for the
        // first level only (then nothing lies between).
        let out = run(RES, |_| true, |k| monotone(k, 16, 16, 16));
        assert!(out.levels.iter().all(|(_, f)| *f == Found::Met(16)), "{:?}", out.levels);
        let knobs: Vec<u32> = out.tried.iter().map(|(p, _)| p.knob).collect();
        assert_eq!(knobs, [8, 16, 12]);
    }

    #[test]
    fn non_monotone_answers_a_knob_that_met() {
        // Meets 2 px at 8 (luck), fails 16..64, meets again from 100; 1 px from 200 except
        // a hole at 230..260.
        let q = |k: u32| match k {
            8 => Some(2.0),
            k if (230..260).contains(&k) => None,
            k if k >= 200 => Some(1.0),
            k if k >= 100 => Some(2.0),
            _ => None,
        };
        let out = run(RES, |_| true, q);
        for (level, f) in &out.levels {
            if let Found::Met(k) = f {
                assert!(meets(q(*k), *level), "answered {k} for {level} px, which does not meet it");
            }
        }
        // The lucky start is the 2 px answer (the smallest tried that met).
        assert_eq!(out.levels[0], (2.0, Found::Met(8)));
        // 0.5 px is never met: the cap stopped it after 1024 was tried.
        assert_eq!(out.levels[2], (0.5, Found::Unmet { stop: Stop::Cap, largest: Some(1024) }));
    }

    #[test]
    fn budget_stops_doubling_and_says_so() {
        // Only up to 100 fits; 1 px needs 300.
        let out = run(RES, |k| k <= 100, |k| monotone(k, 20, 300, 600));
        assert!(matches!(out.levels[0], (2.0, Found::Met(k)) if (20..=24).contains(&k)));
        let budget = Found::Unmet { stop: Stop::Budget, largest: Some(64) };
        assert_eq!(out.levels[1], (1.0, budget));
        assert_eq!(out.levels[2], (0.5, budget), "a finer level inherits the stop");
        assert!(out.tried.iter().all(|(p, _)| p.knob <= 100));
        // The last run doubling could try carries the reason (its note says unmet=budget).
        let last = out.tried.iter().rfind(|(p, _)| p.step == Step::Double).expect("a doubling run");
        assert_eq!(last.0.knob, 64);
        assert_eq!(last.0.last, Some(Stop::Budget));
        assert_eq!(last.0.note(last.1), "search=double level=1px unmet=budget");
    }

    #[test]
    fn nothing_fits() {
        let out = run(RES, |_| false, |_| Some(0.5));
        assert!(out.tried.is_empty());
        assert!(out.levels.iter().all(|(_, f)| *f == Found::Unmet { stop: Stop::Budget, largest: None }));
    }

    #[test]
    fn cap_stops_doubling_and_says_so() {
        let spec = Spec { cap: 48, ..RES };
        let out = run(spec, |_| true, |k| monotone(k, 40, 1000, 1000));
        assert!(matches!(out.levels[0], (2.0, Found::Met(k)) if (40..=44).contains(&k)));
        assert_eq!(out.levels[1], (1.0, Found::Unmet { stop: Stop::Cap, largest: Some(48) }));
        let capped = out.tried.iter().find(|(p, _)| p.knob == 48).expect("the cap is tried");
        assert_eq!(capped.0.last, Some(Stop::Cap));
        // 48 met 2 px, the level it probed, and is the last knob doubling can try: its note
        // says so, since the 1 px probe that the cap stops asks for no new run.
        assert_eq!(capped.0.note(capped.1), "search=double level=2px last=cap");
        assert!(!out.tried.iter().any(|(p, _)| p.level == 1.0 && p.knob == 48));
    }

    #[test]
    fn doubling_only_halves_a_tolerance() {
        // The hit tolerance: knob k is 2/k px; met at 0.5 px tolerance (k = 4) for every level.
        let spec = Spec { start: 1, cap: 32, bisect: false, min_gap: 1 };
        let out = run(spec, |_| true, |k| monotone(k, 2, 4, 4));
        let knobs: Vec<u32> = out.tried.iter().map(|(p, _)| p.knob).collect();
        assert_eq!(knobs, [1, 2, 4]);
        assert_eq!(out.levels, vec![(2.0, Found::Met(2)), (1.0, Found::Met(4)), (0.5, Found::Met(4))]);
    }
}
