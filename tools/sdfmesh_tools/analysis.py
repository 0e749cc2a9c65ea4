"""The study's analysis of a schema-2 compare CSV: the verdict per class and quality level,
the families' crossovers and the cost model. Pure functions of the rows (no plotting).

- A *side* is `sdf` (rows of repr `sdf` or `grid`: ray marching) or `mesh` (repr `mesh`,
  the original of a scanned mesh included); the closed-form reference of scenes is neither,
  and so is a run traced (in whole or in part) by another side than the one asked
  (`asked_repr` `mesh`, `repr` `sdf` or `sdf+mesh`: data.side).
- The *best* run of a side at a quality level, per input and replicate, is the fastest (for
  frame time) or the smallest (for bytes) run of that side whose `quality_px` is at most
  the level.
- Per input, the log of best-SDF / best-mesh is taken in every replicate (a separate
  process); the class's ratio is the geometric mean over inputs of each input's geometric
  mean over replicates, with a t-interval over inputs (stats.ratio_ci).
"""

from __future__ import annotations

import math
import re
from collections import OrderedDict

import numpy as np

from . import data, stats
from .data import num

LEVELS = data.QUALITY_LEVELS
# The level the family plots compare at.
FAMILY_LEVEL = 1.0

# Classes in report order; any other class found in the CSV follows, sorted.
CLASS_ORDER = ("smooth", "csg", "blend", "cad", "thin", "repeat", "many", "fractal", "scenes", "scan")


def classes(rows) -> list[str]:
    found = {data.class_of(r) for r in rows}
    return [c for c in CLASS_ORDER if c in found] + sorted(found - set(CLASS_ORDER))


def _best(rows, key: str):
    c = [r for r in rows if num(r, key) is not None]
    return min(c, key=lambda r: num(r, key)) if c else None


def best_per_run(rows, level: float, key: str) -> "OrderedDict[tuple, dict]":
    """{(input, replicate): {"sdf": row or None, "mesh": row or None}} of the best run of each
    side meeting `level`, by `key` (frame_ms_median or total_bytes)."""
    out: OrderedDict = OrderedDict()
    for (inp, rep), grp in data.group(rows, "input", "replicate").items():
        ok = [r for r in grp if data.meets(r, level)]
        out[(inp, rep or "0")] = {
            s: _best([r for r in ok if data.side(r) == s], key) for s in ("sdf", "mesh")
        }
    return out


def compare_sides(rows, level: float, key: str) -> dict:
    """The ratio best-SDF / best-mesh over the inputs of `rows` (one class) at `level`.

    Returns stats.ratio_ci's dict plus: inputs (all inputs), only_sdf / only_mesh / neither
    (inputs where in no replicate both sides meet the level, by which side does)."""
    logs: OrderedDict[str, list[float]] = OrderedDict()
    seen: OrderedDict[str, set] = OrderedDict()
    for (inp, _rep), b in best_per_run(rows, level, key).items():
        seen.setdefault(inp, set())
        s, m = b["sdf"], b["mesh"]
        if s is not None:
            seen[inp].add("sdf")
        if m is not None:
            seen[inp].add("mesh")
        if s is not None and m is not None and num(s, key) > 0 and num(m, key) > 0:
            logs.setdefault(inp, []).append(math.log(num(s, key) / num(m, key)))
    out = stats.ratio_ci(logs)
    rest = [i for i in seen if i not in logs]
    out["inputs"] = list(seen)
    out["only_sdf"] = [i for i in rest if seen[i] == {"sdf"}]
    out["only_mesh"] = [i for i in rest if seen[i] == {"mesh"}]
    out["neither"] = [i for i in rest if not seen[i]]
    return out


def class_verdicts(rows) -> list[dict]:
    """One dict per (class, level): class, level, time, bytes (compare_sides dicts)."""
    out = []
    for cls in classes(rows):
        sub = [r for r in rows if data.class_of(r) == cls]
        for level in LEVELS:
            out.append({"class": cls, "level": level,
                        "time": compare_sides(sub, level, "frame_ms_median"),
                        "bytes": compare_sides(sub, level, "total_bytes")})
    return out


def _factor(x: float) -> str:
    return f"{x:.3g}×" if x < 100 else f"{x:.0f}×"


def verdict_text(c: dict, what: str = "time") -> str:
    """A plain sentence fragment for one cell of the verdict table."""
    better = "faster" if what == "time" else "smaller"
    if c["ratio"] is None:
        if c["only_sdf"] and not c["only_mesh"]:
            return f"only SDF meets it ({len(c['only_sdf'])} inputs)"
        if c["only_mesh"] and not c["only_sdf"]:
            return f"only mesh meets it ({len(c['only_mesh'])} inputs)"
        if c["only_sdf"] or c["only_mesh"]:
            return f"only SDF on {len(c['only_sdf'])}, only mesh on {len(c['only_mesh'])} inputs"
        return "neither meets it"
    r, lo, hi = c["ratio"], c["lo"], c["hi"]
    extra = "".join(f"; +{len(c[k])} only {w}" for k, w in (("only_sdf", "SDF"), ("only_mesh", "mesh"))
                    if c[k])
    if lo is None:
        win = "SDF" if r < 1 else "mesh"
        return f"{win} {_factor(max(r, 1 / r))} {better}? (no interval: one run){extra}"
    if c["within_noise"]:
        return f"**within noise** (SDF/mesh {r:.3g}, CI {lo:.3g}–{hi:.3g}){extra}"
    if r < 1:
        return f"**SDF {_factor(1 / r)} {better}** (CI {_factor(1 / hi)}–{_factor(1 / lo)}){extra}"
    return f"**mesh {_factor(r)} {better}** (CI {_factor(lo)}–{_factor(hi)}){extra}"


def winner(c: dict) -> str | None:
    """`sdf`, `mesh`, `noise` or None (not compared), from a compare_sides dict."""
    if c["ratio"] is None:
        if c["only_sdf"] and not c["only_mesh"]:
            return "sdf"
        if c["only_mesh"] and not c["only_sdf"]:
            return "mesh"
        return None
    if c["within_noise"]:
        return "noise"
    return "sdf" if c["ratio"] < 1 else "mesh"


# ---------------------------------------------------------------------------------------
# Families

_PARAM = re.compile(r"^(?P<family>.*?)_?(?P<param>\d+)$")

FAMILY_AXIS = {"metaballs": "spheres in the smooth union", "copies": "copies (one repeat node)",
               "menger": "Menger level", "separate": "primitives (separate objects)",
               "union": "primitives in one union", "resolution": "resolution (cells; grids vs re-extracted meshes)"}


def family_of(stem: str):
    """(family, parameter) from a file stem ending in a number (`copies_01000` -> ("copies",
    1000)); None when the stem has no trailing number."""
    m = _PARAM.match(stem)
    if not m or not m.group("family"):
        return None
    return m.group("family"), int(m.group("param"))


def _side_point(rows, side: str, key: str, level: float | None):
    """Median, min and max over replicates of the best value of a side (None if no run)."""
    vals = []
    for _rep, grp in data.group(rows, "replicate").items():
        c = [r for r in grp if data.side(r) == side and (level is None or data.meets(r, level))]
        b = _best(c, key)
        if b is not None:
            vals.append(num(b, key))
    if not vals:
        return None
    return float(np.median(vals)), min(vals), max(vals)


def _win(ps, pm):
    if ps is None and pm is None:
        return None
    if pm is None:
        return "sdf"
    if ps is None:
        return "mesh"
    # a change of winner within the replicates' spread is not a winner
    if ps[2] < pm[1]:
        return "sdf"
    if pm[2] < ps[1]:
        return "mesh"
    return "sdf" if ps[0] < pm[0] else "mesh"


def families(rows, level: float = FAMILY_LEVEL) -> list[dict]:
    """The families of inputs (same class, same stem up to a trailing number, at least 2
    members) and, for scanned meshes, the resolution sweep of each mesh.

    Each: class, family, axis (label), xs, and per key (`frame_ms_median`, `total_bytes`):
    {"sdf": [point or None], "mesh": [...], "winner": [...], "crossovers": [...]}, where a
    point is (median, min, max) over replicates of the best run of the side meeting `level`
    (for the resolution sweep: grids against meshes re-extracted at that resolution, any
    quality; the original mesh, the reference, has no resolution).
    """
    out = []
    fam: OrderedDict[tuple, dict] = OrderedDict()
    for inp in data.inputs(rows):
        sub = [r for r in rows if r.get("input") == inp]
        cls = data.class_of(sub[0])
        f = family_of(inp)
        if f is not None and cls != "scan":
            fam.setdefault((cls, f[0]), {})[f[1]] = sub
    for (cls, name), members in fam.items():
        if len(members) < 2:
            continue
        xs = sorted(members)
        out.append(_family(cls, name, FAMILY_AXIS.get(name, name), xs, [members[x] for x in xs], level))
    for inp in data.inputs(rows):
        sub = [r for r in rows if r.get("input") == inp]
        if data.class_of(sub[0]) != "scan":
            continue
        res = sorted({int(num(r, "resolution")) for r in sub if num(r, "resolution") is not None})
        if len(res) < 2:
            continue
        groups = [[r for r in sub if num(r, "resolution") == x] for x in res]
        out.append(_family("scan", inp, FAMILY_AXIS["resolution"], res, groups, None))
    return out


def _family(cls, name, axis, xs, groups, level) -> dict:
    d = {"class": cls, "family": name, "axis": axis, "xs": xs, "level": level}
    for key in ("frame_ms_median", "total_bytes"):
        ps = [_side_point(g, "sdf", key, level) for g in groups]
        pm = [_side_point(g, "mesh", key, level) for g in groups]
        w = [_win(a, b) for a, b in zip(ps, pm)]
        d[key] = {"sdf": ps, "mesh": pm, "winner": w, "crossovers": stats.crossovers(xs, w)}
    return d


# ---------------------------------------------------------------------------------------
# Cost model: frame_ms = a * steps + b * nodes + d * rays + c, per frame, where steps and
# nodes are totals over the frame's rays (rays * steps_per_ray, rays * nodes_per_ray).
# Fitted by non-negative least squares on relative errors (every run weighs alike, whatever
# its frame time; a negative cost per step or node would mean nothing).

COST_TERMS = ("a (ms per distance evaluation)", "b (ms per BVH node)", "d (ms per ray)", "c (ms)")


def cost_features(row):
    """(steps, nodes, rays) of one frame, or None without the columns. rays =
    mrays_per_s * 1e6 * frame_ms_median / 1000 (every ray of the frame)."""
    t, mr = num(row, "frame_ms_median"), num(row, "mrays_per_s")
    if t is None or mr is None or t <= 0:
        return None
    rays = mr * 1e3 * t
    steps = num(row, "steps_per_ray") or 0.0
    nodes = num(row, "nodes_per_ray") or 0.0
    return rays * steps, rays * nodes, rays


def split_inputs(rows) -> tuple[set, set]:
    """Inputs split in two halves, alternating within each class (sorted by name), so both
    halves hold every class with two or more inputs."""
    fit, check = set(), set()
    for cls in classes(rows):
        names = sorted({r.get("input", "") for r in rows if data.class_of(r) == cls})
        for i, n in enumerate(names):
            (fit if i % 2 == 0 else check).add(n)
    return fit, check


def cost_model(rows) -> dict | None:
    """Fit the model on half of the inputs and check it on the others.

    Returns coef (a, b, d, c), n_fit, n_check, and on the check half: median and 90th
    percentile of |predicted - measured| / measured, the worst input, and the points
    (measured, predicted, half) for a plot; None with fewer than 5 usable rows per half."""
    fit_in, check_in = split_inputs(rows)
    pts = []
    for r in rows:
        f = cost_features(r)
        if f is not None:
            pts.append((r, f, num(r, "frame_ms_median")))
    pts = [p for p in pts if p[2] > 0]
    fit = [p for p in pts if p[0].get("input") in fit_in]
    check = [p for p in pts if p[0].get("input") in check_in]
    if len(fit) < 5 or len(check) < 5:
        return None
    X = np.array([[*f, 1.0] for _, f, _ in fit])
    y = np.array([t for *_, t in fit])
    coef = stats.fit_linear(X, y, relative=True, nonneg=True)
    Xc = np.array([[*f, 1.0] for _, f, _ in check])
    yc = np.array([t for *_, t in check])
    pred_c = Xc @ coef
    err = stats.relative_errors(pred_c, yc)
    err_fit = stats.relative_errors(X @ coef, y)
    by_input: dict[str, list[float]] = {}
    for (r, _, t), p in zip(check, pred_c):
        if t > 0:
            by_input.setdefault(r.get("input", ""), []).append(abs(p - t) / t)
    worst = max(by_input.items(), key=lambda kv: float(np.median(kv[1]))) if by_input else None
    return {
        "coef": [float(x) for x in coef], "n_fit": len(fit), "n_check": len(check),
        "inputs_fit": sorted(fit_in), "inputs_check": sorted(check_in),
        "median_err": float(np.median(err)) if err.size else None,
        "p90_err": float(np.quantile(err, 0.9)) if err.size else None,
        "median_err_fit": float(np.median(err_fit)) if err_fit.size else None,
        "worst": (worst[0], float(np.median(worst[1]))) if worst else None,
        "points": [(float(t), float(p), "check") for (_, _, t), p in zip(check, pred_c)]
        + [(float(t), float(p), "fit") for t, p in zip(y, X @ coef)],
    }
