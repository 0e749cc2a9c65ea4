"""REPORT.md from `toolkit compare` results: plots, tables, hypothesis test, the answer.

python -m sdfmesh_tools.report --csv compare.csv [--shards shards.csv] [--scaling scaling.csv]
    [--summary summary.json] [--artifacts DIR] --out reports/<date>/ [--commands "..."]

Everything in the report's results, tables and answer is computed from the CSVs; nothing
about the outcome is written by hand here.
"""

from __future__ import annotations

import argparse
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

from . import analysis, answer, data, memory, plots, shards as shard_info, stats
from . import duel as duel_mod
from .data import num

THRESHOLDS = (1e-2, 3e-3, 1e-3)
APPENDIX = "appendix-inputs.md"
DUEL_APPENDIX = "appendix-duels.md"
MEMORY_APPENDIX = "appendix-memory.md"

HYPOTHESIS = (
    "- **H1:** for scenes made of few smooth analytic primitives, sphere tracing the analytic "
    "SDF is faster and smaller than a triangle mesh of equal geometric error.\n"
    "- **H2:** for scanned organic meshes, the BVH-traced triangle mesh is faster than a "
    "sampled SDF grid of equal error, and smaller.\n"
    "- **H0 for the test:** the frame-time ratio (SDF marching / mesh) is 1.\n"
)


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
            s = fastest([r for r in ok if data.side(r) == "sdf"])
            m = fastest([r for r in ok if data.side(r) == "mesh"])
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
# The study's sections (schema 2): the answer per class, families, cost model


def answer_table(verdicts) -> str:
    """The verdict table: per class and quality level, who wins in time and in bytes."""
    if not verdicts:
        return "No class could be compared (no rows with `quality_px`).\n"
    trows, last = [], None
    for v in verdicts:
        t = v["time"]
        cls = f"**{v['class']}** ({len(t['inputs'])})" if v["class"] != last else ""
        n = f"{t['n_inputs']}"
        last = v["class"]
        spread = f"×/÷{t['run_spread']:.3g}" if t["run_spread"] else "–"
        trows.append((cls, n, f"≤ {v['level']:g} px", analysis.verdict_text(t, "time"), spread,
                      analysis.verdict_text(v["bytes"], "bytes")))
    return md_table(["class (inputs)", "compared", "quality", "frame time", "run-to-run", "bytes"], trows)


def machines_section(all_rows, shard_rows) -> str:
    """The machines the shards ran on (workflow/Snakefile: one shard per input and replicate)
    and, with more than one, the verdict per class and level on each machine's shards alone.
    Every ratio is taken within one shard (one input in one replicate: one process on one
    machine), so a machine's verdict never mixes timings of two machines."""
    if not shard_rows:
        return "No shard manifests (shards.csv) were given: the machine is the one above.\n"
    ms = shard_info.machines(shard_rows)
    L = [md_table(["host", "CPU", "cores", "threads per shard", "shards", "rows", "Slurm jobs"],
                  [(m["host"], m["cpu"], m["cores"], m["threads"], m["shards"], m["rows"], m["slurm"])
                   for m in ms])]
    if len(ms) < 2:
        L.append(f"\nAll {ms[0]['shards'] if ms else 0} shards ran on one machine, so the verdicts "
                 "cannot differ between machines.\n")
        return "".join(L)
    host = shard_info.host_of(shard_rows)
    per_host = {}
    for m in ms:
        sub = [r for r in all_rows if host.get((r.get("input", ""), data.replicate_of(r) or "0")) == m["host"]]
        per_host[m["host"]] = {(v["class"], v["level"]): analysis.winner(v["time"])
                               for v in analysis.class_verdicts(sub)}
    found = {k for w in per_host.values() for k in w}
    keys = [(c, lv) for c in analysis.classes(all_rows) for lv in analysis.LEVELS if (c, lv) in found]
    rows, differ = [], []
    for cls, level in keys:
        ws = [per_host[m["host"]].get((cls, level)) for m in ms]
        seen = {w for w in ws if w is not None}
        # "noise" (the interval contains 1) does not contradict a side's win
        split = len(seen - {"noise"}) > 1
        if split:
            differ.append(f"{cls} ≤ {level:g} px")
        rows.append((cls, f"≤ {level:g} px", *(w or "–" for w in ws), "**yes**" if split else "no"))
    L.append("\nFrame-time winner per class and level on each machine's shards alone "
             "(`sdf`, `mesh`, `noise`: within noise, –: not compared there):\n\n")
    L.append(md_table(["class", "quality", *(m["host"] for m in ms), "machines disagree"], rows))
    L.append("\n" + (f"The verdicts differ between machines at: {', '.join(differ)}.\n" if differ else
                     "The verdicts do not differ between the machines (where two machines both decide).\n"))
    return "".join(L)


def answer_legend(rows, verdicts) -> str:
    reps = sorted({data.replicate_of(r) for r in rows})
    spreads = [v["time"]["run_spread"] for v in verdicts if v["time"]["run_spread"]]
    spread = (f" The run-to-run factor (pooled over inputs, between the separate processes) is "
              f"×/÷{float(np.median(spreads)):.3g} at the median class and level.") if spreads else ""
    return (
        f"Best run of a side at a level: the fastest (or smallest) run whose `quality_px` is at most "
        f"the level; SDF = `sdf` and `grid` runs, mesh = `mesh` runs (the scanned mesh itself "
        f"included). Factor: geometric mean over the class's inputs of best-SDF / best-mesh, each "
        f"input's ratio first averaged (geometrically) over {len(reps)} replicate(s) run as separate "
        f"processes in different orders. 95% CI: t-interval over inputs (inputs are the unit of "
        f"replication; each input's mean carries its run-to-run noise); a class with one input gets "
        f"a t-interval over its replicates (run-to-run noise only). **within noise**: the interval "
        f"contains 1. Class (inputs); \"compared\": inputs where both sides meet the level in "
        f"frame time; \"run-to-run\": exp of the pooled standard deviation of an input's log time "
        f"ratio between replicates (the noise of one process's ratio; inputs fixed).{spread}\n")


def families_section(fams, images_by_class, out) -> str:
    if not fams:
        return "No family (inputs of one class whose names differ only in a trailing number) in this run.\n"
    L = []
    for f in fams:
        parts = []
        for key, what in (("frame_ms_median", "frame time"), ("total_bytes", "bytes")):
            d = f[key]
            wins = ", ".join(f"{x:g}: {w or '–'}" for x, w in zip(f["xs"], d["winner"]))
            if not any(d["winner"]):
                parts.append(f"{what}: no run of either side meets the level")
            elif d["crossovers"]:
                ch = "; ".join(f"between {a:g} and {b:g} from {o} to {n}" for a, b, o, n in d["crossovers"])
                parts.append(f"{what}: the winner changes {ch} (winners {wins})")
            else:
                parts.append(f"{what}: no change of winner (winners {wins})")
        lvl = f"at ≤ {f['level']:g} px" if f["level"] is not None else "best run per resolution, any quality"
        L.append(f"- `{f['class']}/{f['family']}` ({f['axis']}, {lvl}): " + "; ".join(parts) + ".\n")
    L.append("\nA winner needs its whole replicate range (min to max) below the other's; where the "
             "ranges overlap the lower median wins. Plots: frame time (top) and bytes (bottom) per "
             "class.\n\n")
    for cls, paths in images_by_class.items():
        for p in paths:
            L.append(f"{_img(p, out)}\n\n")
    return "".join(L)


def cost_section(model, image, out) -> str:
    if not model:
        return "Not fitted: fewer than 5 runs with `mrays_per_s` on one of the halves.\n"
    a, b, d, c = model["coef"]
    L = [
        "frame_ms ≈ a·(rays·steps_per_ray) + b·(rays·nodes_per_ray) + d·rays + c, non-negative least "
        "squares of the relative error over "
        f"every run of half the inputs ({len(model['inputs_fit'])} inputs, {model['n_fit']} runs; "
        "alternate inputs of each class by name), checked on the other half "
        f"({len(model['inputs_check'])} inputs, {model['n_check']} runs). rays = mrays_per_s × frame "
        "time (every ray of the frame).\n\n",
        md_table(["term", "value"], [
            ("a: per distance evaluation", f"{a * 1e6:.3g} ns"),
            ("b: per BVH node visited", f"{b * 1e6:.3g} ns"),
            ("d: per ray (shading, setup)", f"{d * 1e6:.3g} ns"),
            ("c: per frame", f"{c:.3g} ms"),
        ]),
        f"\nError |predicted − measured| / measured on the check half: median "
        f"{100 * model['median_err']:.3g}%, 90th percentile {100 * model['p90_err']:.3g}% "
        f"(fit half: median {100 * model['median_err_fit']:.3g}%)"
        + (f"; worst input `{model['worst'][0]}` (median {100 * model['worst'][1]:.3g}%)" if model["worst"] else "")
        + ". The model has one cost per distance evaluation, whatever the SDF tree's size, and one "
        "per BVH node, whatever the leaves hold; the error above is what that simplification "
        "costs on inputs it was not fitted on.\n\n",
    ]
    if image:
        L.append(f"{_img(image, out)}\n")
    return "".join(L)


def hypotheses_outcome(verdicts) -> str:
    """H1 (smooth: SDF faster and smaller) and H2 (scan: mesh faster) from the verdicts."""
    L = []
    for h, cls, want in (("H1", "smooth", "sdf"), ("H2", "scan", "mesh")):
        vs = [v for v in verdicts if v["class"] == cls]
        if not vs:
            L.append(f"- {h}: class `{cls}` not measured in this run.")
            continue
        cells = []
        for v in vs:
            w = analysis.winner(v["time"])
            res = ("supports" if w == want else "undecided (within noise)" if w == "noise"
                   else "not compared" if w is None else "contradicts")
            cells.append(f"≤ {v['level']:g} px: {res}")
        L.append(f"- {h} (class `{cls}`, time): " + "; ".join(cells) + ".")
    return "\n".join(L) + "\n"


# ---------------------------------------------------------------------------------------
# The report


def _window_name() -> str:
    from . import offscreen

    w = offscreen.window()
    return f"VTK `{w}` (off screen)" if w else "– (no 3D view drawn)"


def _img(path: Path, out: Path) -> str:
    rel = os.path.relpath(path, out)
    return f"![{Path(rel).stem}]({rel})"


def _answer_many(scaling_rows, names) -> str:
    if not scaling_rows:
        extra = f" (inputs {', '.join(names)} are in the compare CSV)" if names else ""
        return f"**many primitives:** not measured in this run{extra}."
    parts = []
    for prim, slopes, comp in scaling_summary(scaling_rows):
        sl = ", ".join(f"`{k}` {s:.2f}" for k, s, _ in slopes if s is not None) or "no slopes"
        txt = f"For `{prim}`, frame time grows as count^k with k = {sl}"
        if comp:
            n, c = comp
            ci = f"95% CI [{c['lo']:.3g}, {c['hi']:.3g}]" if c["lo"] is not None else "no CI"
            txt += (f"; at {n} primitives the time ratio SDF/mesh (`{data.label(c['sdf'])}` vs "
                    f"`{data.label(c['mesh'])}`) is {c['ratio']:.3g} ({ci}, p = {fmt_p(c['p'])}): "
                    f"**{verdict(c)}**.")
        else:
            txt += "; no count has both an SDF-marching and a mesh row"
        parts.append(txt if txt.endswith(".") else txt + ".")
    return "**many primitives** (scaling CSV): " + " ".join(parts)


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


def write_duel_appendix(path: Path, ratios) -> None:
    """Every duelled (input, level): the two runs, their duel medians and the ratio per process."""
    rows = [(f"`{r['input']}`", r["class"], f"≤ {r['level']:g} px", f"`{r['sdf_run']}`", f"`{r['mesh_run']}`",
             fmt_ms(r["sdf_ms"]), fmt_ms(r["mesh_ms"]), f"{math.exp(float(np.mean(r['logs']))):.3g}",
             " ".join(f"{math.exp(x):.3g}" for x in r["logs"]), r["rounds"]) for r in ratios]
    path.write_text("# Appendix: the duels\n\n[Back to the report](REPORT.md).\n\n"
                    "SDF/mesh frame-time ratio of each input's chosen pair, per separate process (the median "
                    "of the within-round ratios) and their geometric mean.\n\n"
                    + md_table(["input", "class", "quality", "SDF run", "mesh run", "SDF ms", "mesh ms",
                                "SDF/mesh", "per process", "rounds"], rows))


def write_report(csv_path, out, scaling=None, summary=None, artifacts=None, commands=None,
                 invocation=None, hard=None, shards=None, selection=None, duels=None, sizes=None,
                 sizes_duels=None, refcheck=None) -> Path:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    all_rows = data.read_csv(csv_path)
    scaling_rows = data.read_csv(scaling)
    # the per-input tables and plots of the appendix use one replicate (the first)
    reps = sorted({data.replicate_of(r) for r in all_rows}, key=lambda x: (len(x), x))
    rows = [r for r in all_rows if data.replicate_of(r) == reps[0]] if reps else []
    verdicts = analysis.class_verdicts(all_rows) if any(
        num(r, "quality_px") is not None for r in all_rows) else []
    fams = analysis.families(all_rows)
    model = analysis.cost_model(all_rows)
    fam_images: dict = {}
    for p in plots.family_plots(fams, out):
        fam_images.setdefault(p.stem.removeprefix("family_"), []).append(p)
    cost_images = plots.cost_model_plot(model, out)
    # the per-input plots of the appendix: the first input of each class (48 panels per
    # figure would take minutes to draw and be unreadable)
    first: dict[str, str] = {}
    for r in rows:
        first.setdefault(data.class_of(r), r.get("input", ""))
    plot_rows = [r for r in rows if r.get("input") in set(first.values())]
    images = plots.all_plots(plot_rows, scaling_rows, artifacts, out)
    tests = hypothesis_tests(rows)
    m = machine_info()

    def uniq(col, src=all_rows + scaling_rows):
        return sorted({r.get(col, "") for r in src} - {"", None})

    n_classes = len(analysis.classes(all_rows))
    L = ["# sdfmesh: ray marching SDFs vs polygon meshes, ray traced and rasterized\n"]
    L.append(f"{len(data.inputs(all_rows))} inputs in {n_classes} class(es), {len(reps)} replicate(s) "
             f"(separate processes), {len(all_rows)} runs; commit "
             f"{', '.join(f'`{c}`' for c in uniq('commit')) or '–'}. Report written "
             f"{datetime.now(timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ')} by "
             "`python -m sdfmesh_tools.report`; every number below comes from the CSVs of this run.\n")
    sel = duel_mod.read_selection(Path(selection)) if selection and Path(selection).is_file() else None
    duel_rows = duel_mod.read_duels(Path(duels)) if duels and Path(duels).is_file() else []
    size_text = ", ".join(sorted({f"{r.get('width')}×{r.get('height')}" for r in all_rows if r.get("width")}))
    L.append("\n## The answer\n\n")
    bytes_v = answer.bytes_verdicts(all_rows)
    if sel is not None and duel_rows:
        time_v, ratios = answer.time_verdicts(all_rows, sel, duel_rows)
        raster_v, raster_ratios = answer.time_verdicts(all_rows, sel, duel_rows, "raster")
        if not raster_ratios and not any(s["side"] == "raster" for s in sel):
            raster_v = None
        for sentence in answer.sentences(time_v, bytes_v, len(data.inputs(all_rows)), n_classes, size_text,
                                         raster_v=raster_v):
            L.append(sentence + " ")
        L.append("\n\n")
        L.append(answer.table(time_v, bytes_v, raster_v))
        procs = sorted({r.get("process") for r in duel_rows})
        rounds = sorted({int(r.get("round", 0)) for r in duel_rows})
        L.append(f"\nFrame time: each input's configuration of each side is chosen on the sweep (the fastest "
                 f"median over its replicates among the configurations meeting the level in every replicate), "
                 f"then the chosen pair is re-timed in {len(procs)} separate process(es) of {len(rounds)} "
                 "rounds, one frame of each per round in alternating order; an input's ratio is the mean over "
                 "processes of the median within-round log ratio, a class's the geometric mean over inputs "
                 "with a 95% t-interval over inputs. Bytes: the smallest run of each side meeting the level. "
                 + answer.candidates_text(sel) + " " + answer.search_text(all_rows) + " "
                 + answer.optimism_text(ratios) + "\n")
    else:
        time_v, ratios = [], []
        L.append("No duels were given (--selection, --duels): the answer below is the selection pass's "
                 "best-of, which is biased towards the side with more configurations.\n")
    forest = plots.forest_plot(time_v, ratios, bytes_v, answer.bytes_points(all_rows), out) if time_v else []
    for p in forest:
        L.append(f"\n{_img(p, out)}\n")
    L.append("\n> **Caveats.**\n")
    for c in answer.caveats(all_rows):
        L.append(f"> - {c}\n")
    if ratios:
        L.append(f"\n## Build time: one-shot, edited and static scenes\n\n")
        L.append(f"Build plus N frames of each side's chosen configuration at {answer.HEADLINE_LEVEL:g} px (build "
                 "time: the median over the sweep's replicates; frame time: the duel median). A one-shot "
                 "render is N = 1, an edited scene rebuilds every few frames, a static one renders "
                 "thousands of frames per build.\n\n")
        L.append(answer.amortised_table(all_rows, ratios))
    mem = memory.section(all_rows, answer.HEADLINE_LEVEL, MEMORY_APPENDIX)
    if mem:
        L.append("\n## Memory: declared and measured\n\n" + mem)
        (out / MEMORY_APPENDIX).write_text(
            "# Appendix: memory per representation\n\n[Back to the report](REPORT.md).\n\n"
            "Declared bytes (`total_bytes`) and measured heap peak (`peak_heap_bytes`) of every run, per "
            "representation (`repr/method`, decimations as one):\n\n"
            + memory.family_markdown(memory.family_table(all_rows)))
    size_rows = data.read_csv(sizes) if sizes else []
    if size_rows:
        L.append("\n## Image size\n\nPixel-relative error makes a mesh's needed resolution grow with the image. "
                 "On the first input of each class, the sweep at each image size (the workflow scales the "
                 "search cap with the image side: the largest resolution each size's sweeps ran is under "
                 "the table), its own selection and one duel process (SDF/mesh below 1: SDF faster):\n\n")
        L.append(answer.size_table(size_rows, duel_mod.read_duels(Path(sizes_duels)) if sizes_duels and
                                   Path(sizes_duels).is_file() else []))
    pareto = plots.pareto_plot(all_rows, out)
    if pareto:
        L.append("\n## Frontiers\n\nEach side's Pareto frontier of frame time against p95 pixel error "
                 "(median over replicates) on the first input of each class; the verdict above compares the "
                 "frontiers at three points (0.5, 1, 2 px).\n\n")
        L.append(f"{_img(pareto[0], out)}\n")
    ref_rows = data.read_csv(refcheck) if refcheck else []
    if ref_rows:
        L.append("\n## The references, checked independently\n\n")
        L.append(answer.refcheck_section(ref_rows))
    if sel:
        L.append("\n## What the quality levels are, and which gate binds\n\n")
        L.append(answer.gates_section(all_rows, sel))
    L.append("\n## The selection pass, for comparison\n\n")
    L.append("Best-of over each side's configurations in every replicate, the measurement the "
             "configurations were chosen on (not the verdict: the minimum of noisy timings favours the "
             "side with more candidates):\n\n")
    L.append(answer_table(verdicts))
    L.append("\n" + answer_legend(all_rows, verdicts))
    L.append("\n## Crossovers along the families\n\n")
    L.append(families_section(fams, fam_images, out))
    L.append("\n## Cost model\n\n")
    L.append(cost_section(model, cost_images[0] if cost_images else None, out))
    L.append("\n## Machine and run\n")
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
    L.append("\n### Machines of the shards\n\n")
    L.append(machines_section(all_rows, shard_info.read_shards(shards)))
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
        "Every input (a scene file or a mesh file; its `class` is its folder under data/scenes, "
        "`scan` for scanned meshes) is rendered in each representation: `analytic` "
        "(closed-form ray–primitive intersection, the reference of scenes), `sdf` (sphere tracing "
        "the analytic SDF, swept over the hit tolerance `tolerance_px` and the over-relaxation "
        "`relaxation`), `mesh` (BVH ray tracing of a tessellated or extracted triangle mesh at a "
        "resolution; for scanned meshes the original mesh is the reference, and its decimations by "
        "meshoptimizer's quadric-error simplifier, `decimated-<target>`, are mesh runs too) and `grid` (sphere "
        "tracing a sampled SDF grid at a resolution). The whole sweep runs in separate processes "
        "(`replicate` 0, 1, 2, ...), each in its own shuffled order (`--order-seed`), so that "
        "run-to-run noise (frequency scaling, cache state, other load) shows between replicates. "
        "Each run is timed over several frames (`frame_ms_samples`); memory is `total_bytes` "
        "(geometry plus acceleration structure). Error is measured against the input's reference: "
        "`px_err_*` is the geometric error of the visible surface in pixels at its distance and "
        "`quality_px` the smallest of 0.5, 1 and 2 px the run meets (empty: none); `chamfer_rel` "
        "is the chamfer distance divided by the reference's bounding-box diagonal. The answer "
        "chooses each side's configuration per input and level on this sweep (the selection pass) and "
        "decides frame time on paired, interleaved re-timing of the chosen pair in separate processes "
        "(the duels); bytes come from the sweep. The "
        "per-input appendix keeps the earlier per-frame test: per input, the fastest SDF-marching "
        "row against the fastest mesh row meeting a `chamfer_rel` threshold, ratio of median frame "
        "times with a percentile bootstrap 95% confidence interval (4000 resamples of each row's "
        "per-frame samples) and a two-sided Mann–Whitney U test of the per-frame samples.\n")

    L.append("\n## Hypothesis (stated before the results)\n\n" + HYPOTHESIS)
    L.append("\nOutcome, from the answer table (H1 speaks about class `smooth`, H2 about class "
             "`scan`):\n\n" + hypotheses_outcome(verdicts))

    if hard and Path(hard).is_file():
        L.append("\n## Hard cases\n\n")
        L.append("Which numerically hard cases each representation passes (`toolkit hard`, "
                 "data/hard/README.md explains each case and each known limit), measured in this "
                 "run at 96x96 against the analytic reference:\n\n")
        L.append(Path(hard).read_text().rstrip() + "\n")

    L.append("\n## Many primitives: the scaling experiment\n\n")
    L.append(_answer_many(scaling_rows, []) + "\n")

    L.append(f"\n## Appendices\n\n- [{APPENDIX}]({APPENDIX}): the results of every input (replicate "
             f"{reps[0] if reps else '–'}), the per-input frame-time test and the per-input plots.\n")
    if mem:
        L.append(f"- [{MEMORY_APPENDIX}]({MEMORY_APPENDIX}): declared and measured memory per representation.\n")
    if duel_rows:
        L.append(f"- [{DUEL_APPENDIX}]({DUEL_APPENDIX}): every input's duelled pair and ratio.\n")
        write_duel_appendix(out / DUEL_APPENDIX, ratios)
    front, L = L, ["# Appendix: every input\n\n[Back to the report](REPORT.md).\n"]
    L.append(f"\n## Results per input (replicate {reps[0] if reps else '–'})\n")
    if not rows:
        L.append("No compare rows were read.\n")
    for name in data.inputs(rows):
        sub = [r for r in rows if r.get("input") == name]
        L.append(f"\n### `{name}` ({data.class_of(sub[0])})\n\n")
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

    L.append("\n## Per-input test at chamfer thresholds\n\n")
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


    L.append("\n## Plots\n\n")
    L.append("Per-input plots of replicate " + (reps[0] if reps else "–") + " for the first input of "
             "each class: " + ", ".join(f"`{v}`" for v in first.values()) + ".\n\n")
    if images:
        for p in images:
            L.append(f"{_img(p, out)}\n\n")
    else:
        L.append("No plots were written.\n")
    (out / APPENDIX).write_text(_blank_lines_around_headings("".join(L)))
    report = out / "REPORT.md"
    report.write_text(_blank_lines_around_headings("".join(front)))
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
    ap.add_argument("--shards", help="shards.csv of the workflow (host and CPU of every input and replicate)")
    ap.add_argument("--selection", help="selection.csv of the workflow (sdfmesh_tools.duel select)")
    ap.add_argument("--duels", help="duels.csv of the workflow (toolkit compare --duel, every process)")
    ap.add_argument("--sizes", help="sizes.csv of the workflow (the image-size experiment's sweeps)")
    ap.add_argument("--refcheck", help="refcheck.csv of the workflow (toolkit compare --check-reference)")
    ap.add_argument("--sizes-duels", help="sizes_duels.csv of the workflow (its duels)")
    a = ap.parse_args(argv)
    argv = sys.argv[1:] if argv is None else list(argv)
    write_report(a.csv, a.out, a.scaling, a.summary, a.artifacts, a.commands,
                 invocation="python -m sdfmesh_tools.report " + shlex.join(argv), hard=a.hard,
                 shards=a.shards, selection=a.selection, duels=a.duels, sizes=a.sizes,
                 sizes_duels=a.sizes_duels, refcheck=a.refcheck)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
