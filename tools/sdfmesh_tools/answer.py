"""The first screen of REPORT.md: the verdict in three sentences, the table they come from
and the caveats (issue #37, item 8). Frame time comes from the paired duels (duel.py),
bytes from the selection pass (bytes do not vary between processes). Pure functions of the
rows; every number is computed here from the study's CSVs."""

from __future__ import annotations

import math
import re

import numpy as np

from . import analysis, data, duel
from .data import num

# The level the three sentences speak of (the table shows every level).
HEADLINE_LEVEL = 1.0


def _winner(c: dict) -> str | None:
    """sdf, mesh, tie, few (a ratio without an interval), only-sdf, only-mesh or None."""
    if c.get("ratio") is None:
        if c["only_sdf"] and not c["only_mesh"]:
            return "only-sdf"
        if c["only_mesh"] and not c["only_sdf"]:
            return "only-mesh"
        return None
    if c.get("too_few") or c.get("lo") is None:
        return "few"
    if c["within_noise"]:
        return "tie"
    return "sdf" if c["ratio"] < 1 else "mesh"


def _list(items: list[str]) -> str:
    if not items:
        return "no class"
    return ", ".join(items[:-1]) + (" and " if len(items) > 1 else "") + items[-1]


def sentences(time_v: list[dict], bytes_v: list[dict], n_inputs: int, n_classes: int, size: str,
              level: float = HEADLINE_LEVEL, raster_v: list[dict] | None = None) -> list[str]:
    """Three sentences: who is faster than ray-traced meshes, who is smaller, and against
    rasterized meshes and what the verdict does not cover."""
    def by(verdicts, key):
        out: dict[str, list[str]] = {}
        for v in verdicts:
            if v["level"] != level:
                continue
            c = v[key]
            w = _winner(c)
            if w is None:
                continue
            if w in ("sdf", "mesh"):
                r = c["ratio"]
                label = f"{v['class']} ({max(r, 1 / r):.2g}×)"
            else:
                label = v["class"]
            out.setdefault(w, []).append(label)
        return out

    t = by(time_v, "time")
    b = by(bytes_v, "bytes")
    parts = []
    if t.get("sdf"):
        parts.append(f"faster than ray tracing triangle meshes in {_list(t['sdf'])}")
    if t.get("mesh"):
        parts.append(f"slower in {_list(t['mesh'])}")
    if t.get("tie"):
        parts.append(f"tied within the noise of paired re-timing in {_list(t['tie'])}")
    if t.get("only-sdf"):
        parts.append(f"the only side to meet the level in {_list(t['only-sdf'])}")
    if t.get("only-mesh"):
        parts.append(f"unable to meet the level where meshes do in {_list(t['only-mesh'])}")
    few = (f"{_list(t['few'])} {'has' if len(t['few']) == 1 else 'have'} too few inputs for a verdict "
           "with an interval") if t.get("few") else ""
    if parts:
        s1 = f"At {level:g} px of error, ray marching SDFs is " + "; ".join(parts) + (f"; {few}" if few else "") + "."
    else:
        s1 = f"At {level:g} px of error no class has a frame-time verdict" + (f": {few}" if few else "") + "."
    bp = []
    if b.get("sdf"):
        bp.append(f"the SDF side is smaller in {_list(b['sdf'])}")
    if b.get("mesh"):
        bp.append(f"the mesh side in {_list(b['mesh'])}")
    if b.get("tie"):
        bp.append(f"neither clearly in {_list(b['tie'])}")
    bfew = f"{_list(b['few'])}: too few inputs for an interval" if b.get("few") else ""
    s2 = ("In bytes at the same level " + ("; ".join(bp) if bp else "no class has a verdict")
          + (f" ({bfew})" if bfew else "") + ".")
    r = by(raster_v or [], "time")
    raster = ""
    if raster_v:
        rp = []
        if r.get("sdf"):
            rp.append(f"SDFs are still faster in {_list(r['sdf'])}")
        if r.get("mesh"):
            rp.append(f"rasterized meshes are faster in {_list(r['mesh'])}")
        if r.get("tie"):
            rp.append(f"they tie in {_list(r['tie'])}")
        raster = ("Against meshes whose primary visibility is rasterized (z-buffer, same shading) "
                  + ("; ".join(rp) if rp else "no class has a verdict with an interval") + "; ")
    s3 = (raster + f"all of this holds for {n_inputs} inputs in {n_classes} classes, {size} images, frame "
          "time without build time, on one CPU machine without a GPU (the caveats below say what else it "
          "does not cover).")
    s3 = s3[0].upper() + s3[1:]
    return [s1, s2, s3]


def time_verdicts(rows, sel, duel_rows, opponent: str = "mesh") -> tuple[list[dict], list[dict]]:
    """(per class and level duel verdicts against `opponent`, the per-input duel ratios)."""
    ratios = duel.duel_ratios(sel, duel_rows, opponent)
    return duel.duel_verdicts(sel, ratios, analysis.classes(rows), opponent), ratios


def bytes_verdicts(rows, key: str = "total_bytes", levels=analysis.LEVELS) -> list[dict]:
    """Per class and level: the bytes (`key`: declared `total_bytes`, or the measured
    `peak_heap_bytes`) of the smallest run of each side meeting the level, per input
    (stats.ratio_ci over inputs; fewer than duel.MIN_INPUTS inputs: no interval)."""
    out = []
    for cls in analysis.classes(rows):
        sub = [r for r in rows if data.class_of(r) == cls]
        for level in levels:
            c = duel.mark_too_few(analysis.compare_sides(sub, level, key))
            out.append({"class": cls, "level": level, "bytes": c})
    return out


def bytes_cell(c: dict) -> str:
    if c["ratio"] is None:
        return analysis.verdict_text(c, "bytes")
    r = c["ratio"]
    who = "SDF" if r < 1 else "mesh"
    fac = max(r, 1 / r)
    if c["too_few"]:
        return f"{who} {fac:.3g}× smaller, too few inputs ({c['n_inputs']})"
    return analysis.verdict_text(c, "bytes")


def table(time_v, bytes_v, raster_v=None) -> str:
    from .report import md_table

    bmap = {(v["class"], v["level"]): v["bytes"] for v in bytes_v}
    rmap = {(v["class"], v["level"]): v["time"] for v in raster_v or []}
    rows, last = [], None
    for v in time_v:
        t = v["time"]
        b = bmap.get((v["class"], v["level"]))
        cls = v["class"] if v["class"] != last else ""
        last = v["class"]
        rt = rmap.get((v["class"], v["level"]))
        rows.append((cls, f"≤ {v['level']:g} px", t["n_inputs"], duel.verdict_cell(t),
                     bytes_cell(b) if b else "–",
                     duel.verdict_cell(rt).replace("mesh", "raster") if rt else "–"))
    return md_table(["class", "quality", "inputs duelled", "frame time vs ray-traced meshes (paired duels)",
                     "bytes", "frame time vs rasterized meshes"], rows)


def optimism_text(ratios) -> str:
    o = duel.optimism(ratios)

    def one(side):
        d = o[side]
        if d["median"] is None:
            return f"{side}: no duel"
        return f"{side} {d['median']:.3g} (p10 {d['p10']:.3g}, p90 {d['p90']:.3g}, {d['n']} input-levels)"

    return ("Selection optimism, selected time / re-measured time (the selected configuration's best "
            "frame-time median over the sweep's replicates against its median in the duels; below 1: "
            "the sweep made that side look faster than it re-measures): " + one("sdf") + "; "
            + one("mesh") + "; of the SDF/mesh ratio itself (selected / duelled; a drift of the machine between "
            "the sweep and the duels moves each side's figure but cancels from this one): "
            + one("ratio").replace("ratio ", "", 1) + ".")


def candidates_text(sel) -> str:
    c = {"sdf": [], "mesh": [], "raster": []}
    for s in sel:
        c[s["side"]].append(int(s["candidates"]))
    parts = [f"{side} {int(np.median(v))} (median over inputs)" for side, v in c.items() if v]
    text = "Configurations each side chose from per input: " + ", ".join(parts) + "."
    per_class = class_candidates(sel)
    if per_class:
        text += (f" Per class (SDF/mesh, median over inputs at {HEADLINE_LEVEL:g} px): "
                 + ", ".join(f"{cls} {a:g}/{b:g}" for cls, (a, b) in per_class.items())
                 + ". A count is how many configurations the side's search ran on the input; each "
                 "family's search stops at the first knob that meets the finest level, so a side that "
                 "meets the levels early runs fewer. The duels re-time the chosen pair, so the counts "
                 "decide which configuration is chosen, not the ratio measured.")
    return text


def class_candidates(sel) -> dict:
    """Per class, the median over its inputs of the SDF and the mesh side's candidate count at
    the headline level (classes where both sides chose at that level), in class order."""
    by: dict = {}
    for s in sel:
        if float(s["level"]) != HEADLINE_LEVEL or s["side"] not in ("sdf", "mesh"):
            continue
        by.setdefault(s["class"], {"sdf": [], "mesh": []})[s["side"]].append(int(s["candidates"]))
    return {cls: (float(np.median(by[cls]["sdf"])), float(np.median(by[cls]["mesh"])))
            for cls in [c for c in analysis.CLASS_ORDER if c in by] + sorted(set(by) - set(analysis.CLASS_ORDER))
            if by[cls]["sdf"] and by[cls]["mesh"]}


_SEARCH_NOTE = re.compile(r"search=(double|bisect) level=([0-9.]+)px(?: (unmet|last)=(budget|cap))?")


def _search_side(r: dict) -> str:
    """The side whose search ran a `--search` row: its asked representation's."""
    return "sdf" if (r.get("asked_repr") or r.get("repr") or "").strip() in ("sdf", "grid") else "mesh"


def _search_stops(rows) -> dict[tuple, set]:
    """{(input, side): {(level, stop)}} from the `--search` rows' notes: an `unmet=` row at the
    level it probed (which also holds for every finer level); a `last=` row, the last knob
    doubling could try, met its level and stopped every finer one (level inf)."""
    stops: dict[tuple, set] = {}
    for r in rows:
        m = _SEARCH_NOTE.search(r.get("note") or "")
        if m and m.group(3) in ("unmet", "last"):
            level = float(m.group(2)) if m.group(3) == "unmet" else math.inf
            stops.setdefault((r.get("input"), _search_side(r)), set()).add((level, m.group(4)))
    return stops


def _stopped(stops: set, level: float) -> set:
    """What stopped a side's search short of `level`: a stop at this level or a coarser one."""
    return {stop for lv, stop in stops if lv >= level - 1e-12}


def search_text(rows) -> str:
    """What `toolkit compare --search` evaluated (rows whose `note` says `search=double` or
    `search=bisect`; empty text when none does): each side's searched candidates per input
    (median over inputs; SDF: sphere tracing and grids, mesh: meshes ray traced, the raster
    twins of the chosen meshes apart), and per level and side, the inputs where no run of the
    side met the level, with what stopped the search there: the memory budget or the cap
    (the row's `unmet=`, written at the level it probed, also holds for every finer level; a
    `last=` row, the last knob doubling could try, met its level and stops every finer one)."""
    count: dict[tuple, int] = {}
    inputs = set()
    for r in rows:
        if not _SEARCH_NOTE.search(r.get("note") or ""):
            continue
        key = (r.get("input"), _search_side(r))
        inputs.add(key[0])
        count[key] = count.get(key, 0) + 1
    stops = _search_stops(rows)
    if not inputs:
        return ""
    parts = []
    for side in ("sdf", "mesh"):
        v = [count.get((i, side), 0) for i in sorted(inputs)]
        parts.append(f"{side} {float(np.median(v)):g}")
    text = ("Candidates each side's search evaluated per input (median over the "
            f"{len(inputs)} searched inputs): " + ", ".join(parts) + ".")
    unmet = []
    for level in duel.LEVELS:
        for side in ("sdf", "mesh"):
            missing = [i for i in sorted(inputs) if count.get((i, side))
                       and not any(data.meets(r, level) for r in rows if r.get("input") == i
                                   and duel.side_of(r) == side)]
            if not missing:
                continue
            why = {"budget": 0, "cap": 0, "unknown": 0}
            for i in missing:
                found = _stopped(stops.get((i, side), set()), level)
                why["budget" if "budget" in found else "cap" if "cap" in found else "unknown"] += 1
            said = [f"the memory budget stopped it on {why['budget']}" if why["budget"] else "",
                    f"the resolution cap on {why['cap']}" if why["cap"] else "",
                    f"neither on {why['unknown']}" if why["unknown"] else ""]
            unmet.append(f"at {level:g} px the {side} side met the level on no run for {len(missing)} "
                         f"input(s) ({', '.join(x for x in said if x)})")
    if unmet:
        text += " Where a side met a level nowhere: " + "; ".join(unmet) + "."
    return text


def caveats(rows) -> list[str]:
    sizes = sorted({(r.get("width"), r.get("height")) for r in rows if r.get("width")})
    threads = sorted({r.get("threads") for r in rows if r.get("threads")})
    per_class: dict[str, set] = {}
    for r in rows:
        per_class.setdefault(data.class_of(r), set()).add(r.get("input"))
    small = [f"{c} ({len(v)})" for c, v in per_class.items() if len(v) < duel.MIN_INPUTS]
    builds = [num(r, "build_ms") for r in rows if num(r, "build_ms") is not None]
    return [
        f"One CPU machine, {', '.join(threads) or '?'} render thread(s), no GPU: a GPU changes both sides.",
        "Image size: the verdict at " + ", ".join(f"{w}×{h}" for w, h in sizes) + "; pixel-relative "
        "error makes a mesh's needed resolution grow with the image (see Image size for the sizes "
        "covered, on one input per class).",
        "Rasterization is a software z-buffer on the CPU for primary visibility only (shadows, "
        "reflections and refractions are traced); a GPU rasterizer is another machine class.",
        f"Frame time excludes build time (build times here span {min(builds):.3g}–{max(builds):.3g} ms)."
        if builds else "Frame time excludes build time.",
        "Classes with fewer than 5 inputs get no interval: " + (", ".join(small) if small else "none") + ".",
        f"{len(data.inputs(rows))} inputs; intervals are 95% t-intervals over inputs, descriptive (not corrected for "
        "the number of classes and levels).",
    ] + _search_and_implicit_caveats(rows, per_class)


def _search_and_implicit_caveats(rows, per_class) -> list[str]:
    """The caveats of a searched study (the largest resolution any search tried bounds "only
    SDF meets it") and of the implicit class (its SDF side is the safe marcher of fields that
    are not distances, without the SDF tape's pruning and 8-wide evaluation)."""
    out = []
    searched = [int(num(r, "resolution")) for r in rows
                if _SEARCH_NOTE.search(r.get("note") or "") and num(r, "resolution")]
    if searched:
        out.append(f"Each side's knobs are searched up to resolution {max(searched)}: \"only SDF meets it\" "
                   "means no mesh met the level within that cap (the paragraph under the table counts the "
                   "stops), not that none can.")
    if "implicit" in per_class:
        out.append("Implicit models (class implicit) are fields, not distances: their SDF side is our safe "
                   "marcher (Lipschitz steps, else interval root isolation), one point at a time, without the "
                   "pruning and 8-wide evaluation of the SDF tape, so its frame times bound what marching "
                   "them can do from above. Fidget 0.5.1's CPU voxel renderer was raced against a different "
                   "path of ours, the orthographic heightmap view cast as ray bundles (tools/bench-implicit3d, "
                   "reports/bench/implicit3d.txt: on bear, colonnade and bolt Fidget is 2.6x to 11x faster), "
                   "not against this marcher.")
    return out


def bytes_points(rows, level: float = HEADLINE_LEVEL) -> dict:
    """{(class, input): geometric mean over replicates of smallest-SDF / smallest-mesh bytes}."""
    logs: dict[tuple, list[float]] = {}
    cls = {r.get("input"): data.class_of(r) for r in rows}
    for (inp, _rep), b in analysis.best_per_run(rows, level, "total_bytes").items():
        s, m = b["sdf"], b["mesh"]
        if s is not None and m is not None and num(s, "total_bytes") and num(m, "total_bytes"):
            logs.setdefault((cls[inp], inp), []).append(
                float(np.log(num(s, "total_bytes") / num(m, "total_bytes"))))
    return {k: float(np.exp(np.mean(v))) for k, v in logs.items()}


# Frame counts the amortised table reports the winner at.
FRAME_COUNTS = (1, 100, 10_000)


def amortised(rows, ratios, level: float = HEADLINE_LEVEL) -> list[dict]:
    """Per class at `level`: build + N frames of each side's chosen configuration (build time
    the median over the sweep's replicates, frame time the duel median), how many inputs each
    side wins at each of FRAME_COUNTS, and the median break-even frame count where the side
    that builds slower but renders faster catches up."""
    build: dict[tuple, list[float]] = {}
    for r in rows:
        b = num(r, "build_ms")
        if b is not None and data.side(r):
            build.setdefault((r.get("input"), duel.run_label(r)), []).append(b)
    per_class: dict[str, dict] = {}
    for r in ratios:
        if r["level"] != level:
            continue
        bs = build.get((r["input"], r["sdf_run"]))
        bm = build.get((r["input"], r["mesh_run"]))
        if not bs or not bm:
            continue
        bs, bm = float(np.median(bs)), float(np.median(bm))
        fs, fm = r["sdf_ms"], r["mesh_ms"]
        c = per_class.setdefault(r["class"], {"class": r["class"], "inputs": 0, "first_sdf": [],
                                              "first_mesh": [], "wins": {n: 0 for n in FRAME_COUNTS},
                                              "break_even": []})
        c["inputs"] += 1
        c["first_sdf"].append(bs + fs)
        c["first_mesh"].append(bm + fm)
        for n in FRAME_COUNTS:
            c["wins"][n] += bs + n * fs < bm + n * fm
        if (bs - bm) * (fs - fm) < 0 and fs != fm:
            c["break_even"].append(abs((bs - bm) / (fm - fs)))
    return list(per_class.values())


def amortised_table(rows, ratios, level: float = HEADLINE_LEVEL) -> str:
    from .report import md_table

    t = amortised(rows, ratios, level)
    if not t:
        return "No duelled input has build times for both sides.\n"
    out = []
    for c in t:
        be = (f"{np.median(c['break_even']):.3g} ({len(c['break_even'])} inputs)"
              if c["break_even"] else "– (one side is ahead at every N)")
        out.append((c["class"], c["inputs"], f"{np.median(c['first_sdf']):.3g}",
                    f"{np.median(c['first_mesh']):.3g}",
                    *(f"{c['wins'][n]}/{c['inputs']}" for n in FRAME_COUNTS), be))
    return md_table(["class", "inputs", "first frame SDF ms (median)", "first frame mesh ms (median)",
                     *(f"SDF cheaper, N = {n}" for n in FRAME_COUNTS), "break-even N (median)"], out)


# The gates of `quality_px` (src/metrics.rs QUALITY_LEVELS, GATE_SIZES, GATE_TABLE and
# quality_levels; tools/tests/test_duel.py checks that the two agree). GATES: the bounds at
# 256x256, level px -> (largest px_err_p95, largest silhouette %, largest FLIP); GATE_TABLE:
# per level, per side of GATE_SIZES, (largest silhouette %, largest FLIP), calibrated per image
# size by tools/calibrate-gates (reports/bench/gates.txt).
GATES = {0.5: (0.5, 0.5, 0.05), 1.0: (1.0, 1.5, 0.08), 2.0: (2.0, 4.0, 0.1)}
GATE_SIZES = (128, 256, 512, 1024)
GATE_TABLE = {
    0.5: ((0.895, 0.0821), (0.5, 0.05), (0.25, 0.0287), (0.129, 0.0162)),
    1.0: ((3.004, 0.1298), (1.5, 0.08), (0.773, 0.0469), (0.4, 0.0272)),
    2.0: ((7.964, 0.161), (4.0, 0.1), (2.026, 0.0583), (1.033, 0.0341)),
}
GATE_NAMES = ("p95 pixel error", "silhouette mismatch", "mean FLIP")


def gates_at(level: float, width: float = 256, height: float = 256) -> tuple[float, float, float] | None:
    """The gates of `level` for a width x height image, as src/metrics.rs quality_levels: the
    table interpolated linearly in log(bound) against log(side), side the geometric mean of
    width and height, clamped to the calibrated sides."""
    if level not in GATES:
        return None
    side = math.sqrt(max(float(width), 1.0) * max(float(height), 1.0))
    ls = [math.log(s) for s in GATE_SIZES]
    x = min(max(math.log(side), ls[0]), ls[-1])
    k = next((k for k in range(1, len(ls)) if x <= ls[k]), len(ls) - 1)
    f = (x - ls[k - 1]) / (ls[k] - ls[k - 1])
    (a0, a1), (b0, b1) = GATE_TABLE[level][k - 1], GATE_TABLE[level][k]

    def lerp(a, b):
        return a if f <= 0 else b if f >= 1 else math.exp(math.log(a) + f * (math.log(b) - math.log(a)))

    return level, lerp(a0, b0), lerp(a1, b1)


def binding_gate(row, level: float) -> str | None:
    """The gate a run meeting `level` is closest to failing: the largest of value / bound, the
    bounds those of the run's image size."""
    bounds = gates_at(level, num(row, "width") or 256, num(row, "height") or 256)
    vals = (num(row, "px_err_p95"), num(row, "silhouette_mismatch_pct"), num(row, "flip_mean"))
    if bounds is None or any(v is None for v in vals):
        return None
    return GATE_NAMES[max(range(3), key=lambda i: vals[i] / bounds[i])]


def gates_section(rows, sel) -> str:
    from .report import md_table

    sizes = sorted({int(w) for r in rows if (w := num(r, "width"))} | {256})
    head = ["level", "p95 pixel error ≤"]
    for side in sizes:
        head += [f"silhouette ≤ at {side}² (% of pixels)", f"mean FLIP ≤ at {side}²"]
    defs_rows = []
    for lv in GATES:
        cells = [f"{lv:g} px", f"{lv:g} px"]
        for side in sizes:
            g = gates_at(lv, side, side)
            cells += [f"{g[1]:.3g}%", f"{g[2]:.3g}"]
        defs_rows.append(cells)
    defs = md_table(head, defs_rows)
    by_key = {}
    for r in rows:
        if data.side(r):
            by_key.setdefault((r.get("input"), duel.run_label(r)), r)
    counts: dict[tuple, dict[str, int]] = {}
    for s in sel:
        r = by_key.get((s["input"], s["run"]))
        g = binding_gate(r, s["level"]) if r else None
        if g:
            c = counts.setdefault((s["side"], s["level"]), {n: 0 for n in GATE_NAMES})
            c[g] += 1
    table = md_table(["side", "level", *GATE_NAMES],
                     [(side, f"{lv:g} px", *(c[n] for n in GATE_NAMES)) for (side, lv), c in sorted(counts.items())])
    return ("`quality_px` is the finest level whose three gates a run passes, all measured against the "
            "input's reference image and hit points: the 95th percentile of the geometric error in "
            "pixels of the surface both hit, the share of pixels where exactly one of the two hits a "
            "surface, and the mean FLIP of the shaded images. The silhouette and FLIP bounds were chosen "
            "at 256×256 on the bundled scenes and are scaled per image size by tools/calibrate-gates "
            "(src/metrics.rs GATE_TABLE; measured on seeded scenes outside the study: how the same "
            "sphere-traced runs' silhouette mismatch and FLIP change with the image size; "
            "reports/bench/gates.txt). The bounds at 256² and at this study's sizes:\n\n" + defs
            + "\nWhich gate bound the chosen runs (the gate closest to failing: the largest value / bound), "
            "counted over inputs:\n\n" + table)


def size_table(size_rows, size_duel_rows, level: float = HEADLINE_LEVEL) -> str:
    """The image-size experiment: per input (the first of each class) and square image size,
    the SDF/mesh frame-time ratio of that size's own selection, re-timed in one duel process,
    and the bytes ratio, at `level`; where the frame-time winner changes along the sizes."""
    from .report import md_table

    def width(r):
        return str(r.get("width", "")).strip()

    out, notes = [], []
    by_size: dict[int, list[float]] = {}
    caps: dict[int, list[int]] = {}
    for inp in data.inputs(size_rows):
        sub = [r for r in size_rows if r.get("input") == inp]
        sizes = sorted({int(width(r)) for r in sub if width(r)})
        winners = []
        for px in sizes:
            rows = [r for r in sub if width(r) == str(px)]
            sel = [s for s in duel.select(rows) if s["level"] == level]
            d = [r for r in size_duel_rows if r.get("input") == inp and width(r) == str(px)]
            ratios = duel.duel_ratios(sel, d)
            b = bytes_points(rows, level).get((data.class_of(rows[0]), inp))
            if ratios:
                t = float(np.exp(np.mean(ratios[0]["logs"])))
                winners.append("SDF" if t < 1 else "mesh")
                cell = f"{t:.3g} (`{ratios[0]['sdf_run']}` vs `{ratios[0]['mesh_run']}`)"
            else:
                sides = {s["side"] for s in sel}
                winners.append(None)
                cell = "only SDF meets it" if sides == {"sdf"} else "only mesh meets it" if sides == {
                    "mesh"} else "neither meets it"
                why = _size_stops(rows, level)
                if why:
                    cell += f" ({why})"
            if ratios:
                by_size.setdefault(px, []).append(float(np.mean(ratios[0]["logs"])))
            caps.setdefault(px, []).append(_largest_knob(rows))
            out.append((f"`{inp}`" if px == sizes[0] else "", data.class_of(rows[0]) if px == sizes[0] else "",
                        f"{px}×{px}", cell, f"{b:.3g}" if b else "–"))
        seen = [(px, w) for px, w in zip(sizes, winners) if w]
        changes = [f"{a[1]} → {b[1]} between {a[0]} and {b[0]}" for a, b in zip(seen, seen[1:]) if a[1] != b[1]]
        if changes:
            notes.append(f"`{inp}`: " + "; ".join(changes))
    if not out:
        return "No image-size runs.\n"
    means = "; ".join(f"{px}×{px}: {math.exp(np.mean(v)):.3g} ({len(v)} inputs, largest resolution tried "
                      f"{max(caps[px])})" for px, v in sorted(by_size.items()))
    return (md_table(["input", "class", "image", f"SDF/mesh frame time at {level:g} px (duel)",
                      "SDF/mesh bytes"], out)
            + "\n" + ("Frame-time winner changes with image size: " + "; ".join(notes) + ".\n" if notes else
                      "The frame-time winner does not change with image size on these inputs.\n")
            + (f"\nGeometric mean of the duelled SDF/mesh frame-time ratio over the inputs both sides met "
               f"at each size (one input per class: descriptive, no interval): {means}.\n" if means else ""))


def _size_stops(rows, level: float) -> str:
    """Why a side met `level` on no run of an image size's sweep, from the search notes
    (`unmet=cap` or `unmet=budget` at that level or a coarser one): "mesh: cap", or ""."""
    out = []
    per_side: dict[str, set] = {}
    for (_inp, side), s in _search_stops(rows).items():
        per_side.setdefault(side, set()).update(s)
    for side in ("sdf", "mesh"):
        if any(data.side(r) == side and data.meets(r, level) for r in rows):
            continue
        stops = _stopped(per_side.get(side, set()), level)
        if stops:
            out.append(f"{'SDF' if side == 'sdf' else side}: {' and '.join(sorted(stops))}")
    return "; ".join(out)


def _largest_knob(rows) -> int:
    """The largest grid or mesh resolution an image size's sweep ran (0: none)."""
    return max((int(v) for r in rows if (v := num(r, "resolution")) is not None), default=0)


def refcheck_section(ref_rows) -> str:
    """The reference check (toolkit compare --check-reference) summarised, worst inputs named."""
    from .report import md_table

    checked = [r for r in ref_rows if not (r.get("skipped") or "").strip()]
    skipped = [r for r in ref_rows if (r.get("skipped") or "").strip()]
    head = ("Each scene input's reference (closed form where the scene has one, else the tape marcher at "
            "the finest tolerance: the same code the `sdf` runs use) is checked against a method that "
            "shares none of that code: every primary ray's first root found on the object trees in f64, "
            "one point at a time, stepped by the distance bound (at least 0.001 px) and bisected 60 times. "
            f"{len(checked)} inputs checked")
    if not checked:
        return head + ".\n"
    mism = [num(r, "mismatch_pct") or 0.0 for r in checked]
    p95 = [num(r, "p95_px") for r in checked if num(r, "p95_px") is not None]
    head += (f": hit/miss differs on a median {np.median(mism):.3g}% of pixels (largest "
             f"{max(mism):.3g}%), and where both hit the distance differs by a median p95 of "
             f"{np.median(p95):.3g} px (largest p95 {max(p95):.3g} px)" if p95 else "") + ". "
    implicit = [r for r in skipped if "implicit model" in (r.get("skipped") or "")]
    own = len(skipped) - len(implicit)
    head += (f"{own} mesh or grid inputs are their own reference and are not checked. " if own else "")
    head += (f"{len(implicit)} implicit models are not checked here: their safe marcher is checked against a "
             "dense f64 reference by the test suite. " if implicit else "")
    worst = sorted(checked, key=lambda r: -(num(r, "mismatch_pct") or 0.0))[:5]
    return head + "The inputs that differ most:\n\n" + md_table(
        ["input", "class", "reference", "hit/miss differs", "p95 px", "max px", "evaluations per ray"],
        [(f"`{r['input']}`", r.get("class", ""), f"`{r.get('reference', '')}`",
          f"{num(r, 'mismatch_pct') or 0:.3g}%",
          f"{num(r, 'p95_px'):.3g}" if num(r, "p95_px") is not None else "–",
          f"{num(r, 'max_px'):.3g}" if num(r, "max_px") is not None else "–",
          f"{num(r, 'steps_per_ray') or 0:.0f}") for r in worst])
