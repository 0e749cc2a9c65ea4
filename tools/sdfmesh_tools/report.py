"""REPORT.md from `toolkit compare` results: plots, tables, hypothesis test, the answer.

python -m sdfmesh_tools.report --csv compare.csv [--scaling scaling.csv]
    [--summary summary.json] [--artifacts DIR] --out reports/<date>/ [--commands "..."]

Everything in the report's results, tables and answer is computed from the CSVs; nothing
about the outcome is written by hand here.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import math
import os
import platform
import shlex
import sys
from collections import OrderedDict
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from . import data, plots, stats
from .data import num

THRESHOLDS = (1e-2, 3e-3, 1e-3)

FEW = "few smooth primitives"
CSG = "CSG and smooth blends"
REP = "repetition"
MANY = "many primitives"
ORGANIC = "scanned organic meshes"
CAD = "sharp CAD edges"
THIN = "thin features"
MIXED = "mixed (every feature)"
OTHER = "other (not in the mapping)"

# Input name (a glob pattern) -> kind of scene. First match wins.
KIND_MAP = (
    ("thesis_sdf_spheres", FEW),
    ("thesis_rt", FEW),
    ("coursework_primitives", FEW),
    ("coursework_reflect", FEW),
    ("thesis_sdf_tori", FEW),  # four tori, no repeat node
    ("thesis_sdf_csg", CSG),
    ("*csg*", CSG),
    ("*blend*", CSG),
    ("coursework_mirrors", REP),  # uses a `repeat` node
    ("*repeat*", REP),
    ("*repetition*", REP),
    ("scaling*", MANY),
    ("*bunny*", ORGANIC),
    ("armadillo*", ORGANIC),
    ("spot*", ORGANIC),
    ("fertility*", ORGANIC),
    ("dragon*", ORGANIC),
    ("lucy*", ORGANIC),
    ("happy*", ORGANIC),
    ("thesis_sdf_boxes", CAD),
    ("thesis_sdf_plane_cylinders", FEW),  # capped cylinders on an infinite plane
    ("showcase", MIXED),
)
KIND_ORDER = (FEW, CSG, REP, MANY, ORGANIC, CAD, THIN, MIXED, OTHER)

# Which hypothesis speaks about a kind, and the direction it predicts for
# time(SDF marching) / time(mesh): "<1" (SDF faster) or ">1" (mesh faster).
HYPOTHESIS_OF_KIND = {FEW: ("H1", "<1"), ORGANIC: ("H2", ">1")}

HYPOTHESIS = (
    "- **H1:** for scenes made of few smooth analytic primitives, sphere tracing the analytic "
    "SDF is faster and smaller than a triangle mesh of equal geometric error.\n"
    "- **H2:** for scanned organic meshes, the BVH-traced triangle mesh is faster than a "
    "sampled SDF grid of equal error, and smaller.\n"
    "- **H0 for the test:** the frame-time ratio (SDF marching / mesh) is 1.\n"
)


def kind_of(name: str) -> str:
    for pattern, kind in KIND_MAP:
        if fnmatch.fnmatch(name, pattern):
            return kind
    return OTHER


# ---------------------------------------------------------------------------------------
# Formatting


def fmt_bytes(b) -> str:
    if b is None:
        return "–"
    for unit, k in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if abs(b) >= k:
            return f"{b / k:.2f} {unit}"
    return f"{int(b)} B"


def fmt_ms(x) -> str:
    if x is None:
        return "–"
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


def fmt_g(x, digits: int = 3) -> str:
    return "–" if x is None else f"{x:.{digits}g}"


def fmt_p(p) -> str:
    if p is None:
        return "–"
    return f"{p:.2g}" if p >= 1e-4 else "< 1e-4"


def md_table(header, rows) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------------------------------
# Machine


def machine_info() -> dict:
    info = {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(), "ram": None}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["cpu"] = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                info["ram"] = int(line.split()[1]) * 1024
                break
    except OSError:
        pass
    info["os"] = f"{platform.system()} {platform.release()}"
    return info


# ---------------------------------------------------------------------------------------
# Selections


def meeting(rows, threshold: float, col: str = "chamfer_rel"):
    return [r for r in rows if num(r, col) is not None and num(r, col) <= threshold]


def fastest(rows):
    c = [r for r in rows if num(r, "frame_ms_median") is not None]
    return min(c, key=lambda r: num(r, "frame_ms_median")) if c else None


def smallest(rows):
    c = [r for r in rows if num(r, "total_bytes") is not None]
    return min(c, key=lambda r: (num(r, "total_bytes"), num(r, "frame_ms_median") or math.inf)) if c else None


def frame_samples(row) -> list[float]:
    s = data.samples(row)
    if not s and num(row, "frame_ms_median") is not None:
        s = [num(row, "frame_ms_median")]
    return s


def compare_rows(sdf_row, mesh_row) -> dict:
    """Time ratio sdf/mesh with bootstrap CI and Mann-Whitney p, and the memory ratio."""
    a, b = frame_samples(sdf_row), frame_samples(mesh_row)
    ratio, lo, hi = stats.ratio_of_medians_ci(a, b)
    p = stats.mann_whitney_p(a, b) if len(a) > 1 and len(b) > 1 else None
    sb, mb = num(sdf_row, "total_bytes"), num(mesh_row, "total_bytes")
    return {
        "sdf": sdf_row, "mesh": mesh_row, "ratio": ratio, "lo": lo, "hi": hi, "p": p,
        "n_sdf": len(a), "n_mesh": len(b),
        "bytes_ratio": (sb / mb) if sb is not None and mb else None,
    }


def verdict(c: dict) -> str:
    if c["lo"] is not None and c["hi"] < 1:
        return "SDF marching faster"
    if c["lo"] is not None and c["lo"] > 1:
        return "mesh faster"
    if c["lo"] is None:
        return "no per-frame samples: not tested"
    return "no significant difference"


def hypothesis_tests(rows) -> "OrderedDict[str, list[tuple[float, dict | None]]]":
    """Per input and threshold: the comparison of the best SDF and best mesh rows (or None)."""
    out: OrderedDict = OrderedDict()
    for name in data.inputs(rows):
        sub = [r for r in rows if r.get("input") == name]
        res = []
        for t in THRESHOLDS:
            ok = meeting(sub, t)
            s = fastest([r for r in ok if r.get("repr") in data.SDF_REPRS])
            m = fastest([r for r in ok if r.get("repr") in data.MESH_REPRS])
            res.append((t, compare_rows(s, m) if s is not None and m is not None else None))
        out[name] = res
    return out


def crossover(sub):
    """Per resolution, the fastest and the smallest of the rows at that resolution (mesh and
    grid representations; the resolution-free rows are listed apart).

    Returns (table rows, list of (resolution, previous winner, new winner)).
    """
    resolutions = sorted({num(r, "resolution") for r in sub if num(r, "resolution") is not None})
    table, changes, prev = [], [], None
    for res in resolutions:
        cands = [r for r in sub if num(r, "resolution") == res]
        f, s = fastest(cands), smallest(cands)
        if f is None:
            continue
        key = f"{f.get('repr')}/{f.get('method')}"
        table.append((int(res), data.label(f), fmt_ms(num(f, "frame_ms_median")),
                      data.label(s) if s else "–", fmt_bytes(num(s, "total_bytes")) if s else "–"))
        if prev is not None and key != prev:
            changes.append((int(res), prev, key))
        prev = key
    return table, changes


def scaling_summary(rows):
    """Per primitive: log-log slope of frame time vs count per (repr, method), and the
    SDF/mesh comparison at the largest count both have."""
    out = []
    for (prim,), grp in data.group(rows, "primitive").items():
        slopes = []
        for (rep, meth), g in data.group(grp, "repr", "method").items():
            pts = [(num(r, "count"), num(r, "frame_ms_median")) for r in g]
            pts = [(c, t) for c, t in pts if c and t and c > 0 and t > 0]
            slope = None
            if len({c for c, _ in pts}) >= 2:
                x, y = np.log([c for c, _ in pts]), np.log([t for _, t in pts])
                slope = float(np.polyfit(x, y, 1)[0])
            slopes.append((f"{rep}/{meth}", slope, len(pts)))
        counts_s = {num(r, "count") for r in grp if r.get("repr") in data.SDF_REPRS}
        counts_m = {num(r, "count") for r in grp if r.get("repr") in data.MESH_REPRS}
        common = sorted((counts_s & counts_m) - {None})
        comp = None
        if common:
            n = common[-1]
            s = fastest([r for r in grp if r.get("repr") in data.SDF_REPRS and num(r, "count") == n])
            m = fastest([r for r in grp if r.get("repr") in data.MESH_REPRS and num(r, "count") == n])
            if s is not None and m is not None:
                comp = (int(n), compare_rows(s, m))
        out.append((prim, slopes, comp))
    return out


# ---------------------------------------------------------------------------------------
# The report


def _window_name() -> str:
    from . import offscreen

    w = offscreen.window()
    return f"VTK `{w}` (off screen)" if w else "– (no 3D view drawn)"


def _img(path: Path, out: Path) -> str:
    rel = os.path.relpath(path, out)
    return f"![{Path(rel).stem}]({rel})"


def _comparison_sentence(c: dict, t: float) -> str:
    s, m = c["sdf"], c["mesh"]
    ci = f"95% CI [{c['lo']:.3g}, {c['hi']:.3g}]" if c["lo"] is not None else "no CI (no per-frame samples)"
    br = f"{c['bytes_ratio']:.3g}" if c["bytes_ratio"] is not None else "–"
    return (
        f"at chamfer_rel ≤ {t:g}, the fastest SDF-marching row `{data.label(s)}` "
        f"({fmt_ms(num(s, 'frame_ms_median'))} ms, {fmt_bytes(num(s, 'total_bytes'))}) against the fastest "
        f"mesh row `{data.label(m)}` ({fmt_ms(num(m, 'frame_ms_median'))} ms, "
        f"{fmt_bytes(num(m, 'total_bytes'))}): time ratio SDF/mesh {c['ratio']:.3g} ({ci}, "
        f"Mann-Whitney p = {fmt_p(c['p'])}), memory ratio SDF/mesh {br}: **{verdict(c)}**"
    )


def _hyp_outcome(kind: str, c: dict) -> str:
    if kind not in HYPOTHESIS_OF_KIND:
        return "No hypothesis was stated for this kind."
    h, direction = HYPOTHESIS_OF_KIND[kind]
    if c["lo"] is None:
        return f"{h} cannot be tested here (no per-frame samples)."
    faster_ok = c["hi"] < 1 if direction == "<1" else c["lo"] > 1
    faster_bad = c["lo"] > 1 if direction == "<1" else c["hi"] < 1
    br = c["bytes_ratio"]
    smaller_ok = None if br is None else (br < 1 if direction == "<1" else br > 1)
    if faster_ok and smaller_ok is not False:
        return f"This supports {h} (H0 rejected in the predicted direction" + (
            ", and the predicted representation is also smaller)." if smaller_ok else ").")
    if faster_ok:
        return f"The time part of {h} holds (H0 rejected as predicted) but the memory part does not."
    if faster_bad:
        return f"This contradicts {h}: H0 is rejected in the opposite direction."
    return f"H0 is not rejected, so this run does not decide {h}."


def answer_section(rows, scaling_rows, tests) -> str:
    by_kind: OrderedDict[str, list[str]] = OrderedDict((k, []) for k in KIND_ORDER)
    for name in data.inputs(rows):
        by_kind[kind_of(name)].append(name)
    paras = []
    for kind in KIND_ORDER:
        names = by_kind[kind]
        if kind == MANY:
            paras.append(_answer_many(scaling_rows, names))
            continue
        if not names:
            if kind not in (OTHER, MIXED):
                paras.append(f"**{kind}:** not measured in this run.")
            continue
        parts, n_sdf_fast, n_mesh_fast, n_sdf_small, n_tested = [], 0, 0, 0, 0
        for name in names:
            # the tightest threshold both an SDF-marching and a mesh row meet
            best = [(t, c) for t, c in tests.get(name, []) if c is not None]
            if not best:
                parts.append(f"On `{name}` no SDF-marching row and mesh row both reach "
                             f"chamfer_rel ≤ {max(THRESHOLDS):g}, so they cannot be compared at equal error.")
                continue
            t, c = min(best, key=lambda tc: tc[0])
            n_tested += 1
            v = verdict(c)
            n_sdf_fast += v.startswith("SDF")
            n_mesh_fast += v.startswith("mesh")
            n_sdf_small += bool(c["bytes_ratio"] is not None and c["bytes_ratio"] < 1)
            parts.append(f"On `{name}`, {_comparison_sentence(c, t)}. {_hyp_outcome(kind, c)}")
        head = f"**{kind}** ({', '.join(f'`{n}`' for n in names)}): "
        if n_tested:
            head += (f"SDF marching was significantly faster on {n_sdf_fast} and the mesh on "
                     f"{n_mesh_fast} of {n_tested} input(s) compared at equal error; the SDF "
                     f"representation was smaller on {n_sdf_small} of {n_tested}. ")
        paras.append(head + " ".join(parts))
    return "\n\n".join(paras) + "\n"


def _answer_many(scaling_rows, names) -> str:
    if not scaling_rows:
        extra = f" (inputs {', '.join(names)} are in the compare CSV)" if names else ""
        return f"**{MANY}:** not measured in this run{extra}."
    parts = []
    for prim, slopes, comp in scaling_summary(scaling_rows):
        sl = ", ".join(f"`{k}` {s:.2f}" for k, s, _ in slopes if s is not None) or "no slopes"
        txt = f"For `{prim}`, frame time grows as count^k with k = {sl}"
        if comp:
            n, c = comp
            ci = f"95% CI [{c['lo']:.3g}, {c['hi']:.3g}]" if c["lo"] is not None else "no CI"
            txt += (f"; at {n} primitives the time ratio SDF/mesh (`{data.label(c['sdf'])}` vs "
                    f"`{data.label(c['mesh'])}`) is {c['ratio']:.3g} ({ci}, p = {fmt_p(c['p'])}): "
                    f"**{verdict(c)}**. {_hyp_outcome(MANY, c)}")
        else:
            txt += "; no count has both an SDF-marching and a mesh row"
        parts.append(txt if txt.endswith(".") else txt + ".")
    return f"**{MANY}** (scaling CSV): " + " ".join(parts)


def _blank_lines_around_headings(text: str) -> str:
    lines = text.split("\n")
    out: list[str] = []
    fenced = False
    for i, line in enumerate(lines):
        if line.startswith("```"):
            fenced = not fenced
        heading = not fenced and line.startswith("#")
        if heading and out and out[-1] != "":
            out.append("")
        out.append(line)
        if heading and i + 1 < len(lines) and lines[i + 1] != "":
            out.append("")
    return "\n".join(out)


def write_report(csv_path, out, scaling=None, summary=None, artifacts=None, commands=None,
                 invocation=None, hard=None) -> Path:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = data.read_csv(csv_path)
    scaling_rows = data.read_csv(scaling)
    images = plots.all_plots(rows, scaling_rows, artifacts, out)
    tests = hypothesis_tests(rows)
    m = machine_info()

    def uniq(col, src=rows + scaling_rows):
        return sorted({r.get(col, "") for r in src} - {"", None})

    L = ["# sdfmesh: ray marching SDFs vs ray tracing meshes\n"]
    L.append(f"Report written {datetime.now(timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ')} by "
             "`python -m sdfmesh_tools.report`.\n")
    L.append("## Machine and run\n")
    L.append(md_table(["what", "value"], [
        ("CPU", m["cpu"]), ("logical cores", m["cores"]), ("RAM", fmt_bytes(m["ram"])), ("OS", m["os"]),
        ("commit", ", ".join(f"`{c}`" for c in uniq("commit")) or "–"),
        ("timestamps (UTC)", (lambda ts: f"{ts[0]} to {ts[-1]}" if len(ts) > 1 else (ts[0] if ts else "–"))(
            sorted(uniq("timestamp")))),
        ("render threads", ", ".join(uniq("threads")) or "–"),
        ("image size", ", ".join(f"{w}×{h}" for w, h in sorted({(r.get('width'), r.get('height')) for r in rows if r.get('width')})) or "–"),
        ("frames per row", ", ".join(uniq("frames")) or "–"),
        ("3D views rendered with", _window_name()),
        ("inputs", len(data.inputs(rows))), ("compare rows", len(rows)), ("scaling rows", len(scaling_rows)),
    ]))
    L.append("\n### Commands\n")
    cmd = commands or "(not given; pass --commands)"
    L.append("```sh\n" + cmd.strip() + "\n" + (invocation + "\n" if invocation else "") + "```\n")
    if summary:
        try:
            json.loads(Path(summary).read_text())
            L.append(f"\nThe toolkit's own summary (per input and error threshold: fastest, smallest, and the "
                     f"marched/mesh ratios) is `{Path(summary).name}`.\n")
        except (OSError, ValueError) as e:
            L.append(f"\n(summary {summary} could not be read: {e})\n")

    L.append("\n## Method\n")
    L.append(
        "Every input (a scene file or a mesh file) is rendered in each representation: `analytic` "
        "(closed-form ray–primitive intersection), `sdf` (sphere tracing the analytic SDF), `mesh` "
        "(BVH ray tracing of a tessellated or extracted triangle mesh at a resolution) and `grid` "
        "(sphere tracing a sampled SDF grid at a resolution). Each row is timed over several frames "
        "(`frame_ms_samples`); memory is `total_bytes` (geometry plus acceleration structure). "
        "Error is measured against the reference row of the input (`reference` column): "
        "`chamfer_rel` is the chamfer distance between the visible surfaces divided by the "
        "reference's bounding-box diagonal, `image_rmse` the RGB error of the image. "
        "A representation *meets* a threshold when `chamfer_rel ≤ threshold`. The hypothesis test "
        "compares, per input, the fastest SDF-marching row (`sdf` or `grid`) with the fastest `mesh` "
        "row meeting the threshold: the ratio of median frame times with a percentile bootstrap 95% "
        "confidence interval (4000 resamples of each row's per-frame samples) and a two-sided "
        "Mann–Whitney U test of the per-frame samples.\n")

    L.append("\n## Hypothesis (stated before the results)\n\n" + HYPOTHESIS)
    L.append("\nKinds of scene, by input name (first match wins; the hypotheses speak about the kinds "
             "marked):\n\n")
    L.append(md_table(["input name pattern", "kind", "hypothesis"],
                      [(f"`{p}`", k, HYPOTHESIS_OF_KIND.get(k, ("–",))[0]) for p, k in KIND_MAP]))

    L.append("\n## Results\n")
    if not rows:
        L.append("No compare rows were read.\n")
    for name in data.inputs(rows):
        sub = [r for r in rows if r.get("input") == name]
        L.append(f"\n### `{name}` ({kind_of(name)})\n\n")
        refs = sorted({r.get("reference", "") for r in sub} - {""})
        if refs:
            L.append(f"Reference: `{', '.join(refs)}`.\n\n")
        trows = []
        for t in THRESHOLDS:
            ok = meeting(sub, t)
            f, s = fastest(ok), smallest(ok)
            if f is None and s is None:
                trows.append((f"{t:g}", "none meets it", "–", "–", "–", "–", "–"))
                continue
            trows.append((f"{t:g}",
                           f"`{data.label(f)}`" if f else "–", fmt_ms(num(f, "frame_ms_median")) if f else "–",
                           fmt_bytes(num(f, "total_bytes")) if f else "–",
                           f"`{data.label(s)}`" if s else "–", fmt_ms(num(s, "frame_ms_median")) if s else "–",
                           fmt_bytes(num(s, "total_bytes")) if s else "–"))
        L.append(md_table(["chamfer_rel ≤", "fastest", "frame ms (median)", "bytes",
                           "smallest", "frame ms (median)", "bytes"], trows))
        table, changes = crossover(sub)
        if table:
            flat = [r for r in sub if num(r, "resolution") is None and num(r, "frame_ms_median") is not None]
            L.append("\nFastest and smallest per resolution, among the rows with a resolution"
                     + (" (resolution-free rows: " + ", ".join(
                         f"`{data.label(r)}` {fmt_ms(num(r, 'frame_ms_median'))} ms, "
                         f"{fmt_bytes(num(r, 'total_bytes'))}" for r in flat) + ")" if flat else "")
                     + ":\n\n")
            L.append(md_table(["resolution", "fastest", "frame ms", "smallest", "bytes"], table))
            if changes:
                L.append("\nCrossover: " + "; ".join(
                    f"at resolution {r} the fastest changes from `{a}` to `{b}`" for r, a, b in changes) + ".\n")
            else:
                L.append(f"\nCrossover: none; `{table[0][1].split('@')[0]}` is fastest at every resolution.\n")
        else:
            L.append("\nCrossover: no rows with a resolution.\n")
        L.append("\n<details><summary>All rows</summary>\n\n")
        L.append(md_table(
            ["repr/method@res", "triangles", "grid cells", "total bytes", "build ms", "frame ms", "steps/ray",
             "nodes/ray", "chamfer_rel", "hausdorff_rel", "image RMSE", "SSIM"],
            [(f"`{data.label(r)}`" + (" (ref)" if data.is_reference(r) else ""),
              fmt_g(num(r, "triangles"), 6), fmt_g(num(r, "grid_cells_stored"), 6),
              fmt_bytes(num(r, "total_bytes")), fmt_ms(num(r, "build_ms")),
              fmt_ms(num(r, "frame_ms_median")), fmt_g(num(r, "steps_per_ray")), fmt_g(num(r, "nodes_per_ray")),
              fmt_g(num(r, "chamfer_rel")), fmt_g(num(r, "hausdorff_rel")), fmt_g(num(r, "image_rmse")),
              fmt_g(num(r, "image_ssim"))) for r in sub]))
        L.append("\n</details>\n")

    L.append("\n## Hypothesis test\n\n")
    L.append("Time ratio = median frame time of the fastest SDF-marching row / that of the fastest "
             "mesh row, both meeting the threshold; < 1 means SDF marching is faster. H0: ratio = 1.\n\n")
    hrows = []
    for name, res in tests.items():
        for t, c in res:
            if c is None:
                hrows.append((f"`{name}`", f"{t:g}", "–", "–", "–", "–", "–", "–",
                              "no SDF-marching and mesh pair meets it"))
                continue
            ci = f"[{c['lo']:.3g}, {c['hi']:.3g}]" if c["lo"] is not None else "–"
            hrows.append((f"`{name}`", f"{t:g}", f"`{data.label(c['sdf'])}`", f"`{data.label(c['mesh'])}`",
                          f"{c['ratio']:.3g}", ci, fmt_p(c["p"]),
                          fmt_g(c["bytes_ratio"]), verdict(c)))
    if hrows:
        L.append(md_table(["input", "chamfer_rel ≤", "SDF row", "mesh row", "time ratio",
                           "95% CI", "Mann-Whitney p", "bytes ratio", "verdict"], hrows))
    else:
        L.append("No inputs.\n")
    for name, res in tests.items():
        for t, c in res:
            if c is not None and c["lo"] is not None:
                L.append(f"\n- `{name}` at {t:g}: ratio {c['ratio']:.3g}, 95% confidence interval "
                         f"[{c['lo']:.3g}, {c['hi']:.3g}] (n = {c['n_sdf']} and {c['n_mesh']} frames)")
    L.append("\n")

    L.append("\n## The answer\n\n")
    L.append("Generated from the numbers above, one paragraph per kind of scene.\n\n")
    L.append(answer_section(rows, scaling_rows, tests))

    if hard and Path(hard).is_file():
        L.append("\n## Hard cases\n\n")
        L.append("Which numerically hard cases each representation passes (`toolkit hard`, "
                 "data/hard/README.md explains each case and each known limit), measured in this "
                 "run at 96x96 against the analytic reference:\n\n")
        L.append(Path(hard).read_text().rstrip() + "\n")

    L.append("\n## Plots\n\n")
    if images:
        for p in images:
            L.append(f"{_img(p, out)}\n\n")
    else:
        L.append("No plots were written.\n")
    report = out / "REPORT.md"
    report.write_text(_blank_lines_around_headings("".join(L)))
    print(f"wrote {report} and {len(images)} PNG(s)")
    return report


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sdfmesh_tools.report", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--csv", required=True, help="compare CSV (toolkit compare --csv)")
    ap.add_argument("--scaling", help="scaling CSV (toolkit compare --scaling --csv)")
    ap.add_argument("--summary", help="summary JSON to include verbatim")
    ap.add_argument("--artifacts", help="artifacts folder (toolkit compare --artifacts)")
    ap.add_argument("--out", required=True, help="output folder, e.g. reports/2026-11-22/")
    ap.add_argument("--commands", help="the exact commands that produced the CSVs, quoted into the report")
    ap.add_argument("--hard", help="hard-case table (toolkit hard --table) to include")
    a = ap.parse_args(argv)
    argv = sys.argv[1:] if argv is None else list(argv)
    write_report(a.csv, a.out, a.scaling, a.summary, a.artifacts, a.commands,
                 invocation="python -m sdfmesh_tools.report " + shlex.join(argv), hard=a.hard)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
