"""Select, then measure (issue #37, item 1): the study's verdict on frame time comes from
paired, interleaved re-timing of each side's chosen configuration, not from the minimum of
the noisy timings it was chosen on.

1. **Selection** (`select`): for every input, quality level and side, the configuration of
   that side chosen on the compare CSV (the selection pass: every replicate of the sweep):
   among the configurations that meet the level in every replicate they ran in, the one with
   the lowest median over replicates of `frame_ms_median`. A configuration is named by its
   run label (`run_label`, the toolkit's `compare --duel` label).
2. **Duels** (the toolkit, `compare INPUT --duel A,B,...`): every chosen configuration of an
   input is re-timed in several separate processes, all of them in one process, one frame
   each per round, in an order that reverses each round.
3. **Verdict** (`duel_ratios`, `duel_verdicts`): per input, level and process, the median
   over rounds of log(SDF frame / mesh frame) taken within a round; the input's value is the
   mean over its processes; a class's ratio is the geometric mean over its inputs with a
   t-interval over inputs (stats.ratio_ci), printed only with at least MIN_INPUTS inputs.
   The selection's optimism per side is selected time / re-measured time: the selected
   configuration's own compare timing (the minimum over replicates, as a naive best-of
   would report it) against its duel median.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from collections import OrderedDict
from pathlib import Path

import numpy as np

from . import analysis, data, stats
from .data import num

LEVELS = data.QUALITY_LEVELS
# Below this many inputs a class's interval is not printed ("too few inputs").
MIN_INPUTS = 5
SELECTION_COLUMNS = ["input", "class", "level", "side", "run", "repr", "selected_ms_median",
                     "selected_ms_min", "replicates", "candidates", "total_bytes", "quality_px"]


def _fmt_num(v: str) -> str:
    """A CSV number as the toolkit's label writes it (`1.0` -> `1`, `0.25` -> `0.25`)."""
    x = float(v)
    return str(int(x)) if x == int(x) else repr(x)


def run_label(row: dict) -> str:
    """The toolkit's `--duel` label of a compare row: `asked_repr/method`, `/resolution`
    where there is one, `@tolerance_px:relaxation` for the sphere tracing sweep's runs."""
    def cell(k):
        v = row.get(k)
        return "" if v is None else str(v).strip()

    asked = cell("asked_repr") or cell("repr")
    s = f"{asked}/{cell('method')}"
    res = cell("resolution")
    if res:
        s += f"/{int(float(res))}"
    tol, relax = cell("tolerance_px"), cell("relaxation")
    if asked == "sdf" and tol and relax:
        s += f"@{_fmt_num(tol)}:{_fmt_num(relax)}"
    return s


# The sides of the selection: SDF (`sdf` and `grid` runs), meshes ray traced, and meshes whose
# primary visibility is rasterized (`raster` twins of mesh runs, issue #36), each chosen on its own.
SIDES = ("sdf", "mesh", "raster")


def is_raster(row: dict) -> bool:
    m = str(row.get("method") or "").strip()
    return m == "raster" or m.endswith("-raster")


def side_of(row: dict) -> str | None:
    """data.side, with the mesh runs whose primary visibility is rasterized apart (`raster`)."""
    s = data.side(row)
    return "raster" if s == "mesh" and is_raster(row) else s


def select(rows, levels=LEVELS) -> list[dict]:
    """The selection: one dict (SELECTION_COLUMNS) per (input, level, side) that has a
    configuration meeting the level in every replicate it ran in."""
    out = []
    for (inp,), grp in data.group(rows, "input").items():
        cls = data.class_of(grp[0])
        for side in SIDES:
            by_run: OrderedDict[str, list[dict]] = OrderedDict()
            for r in grp:
                if side_of(r) == side and num(r, "frame_ms_median") is not None:
                    by_run.setdefault(run_label(r), []).append(r)
            for level in levels:
                ok = {k: v for k, v in by_run.items() if all(data.meets(r, level) for r in v)}
                if not ok:
                    continue
                med = {k: float(np.median([num(r, "frame_ms_median") for r in v])) for k, v in ok.items()}
                best = min(med, key=lambda k: (med[k], k))
                v = ok[best]
                out.append({
                    "input": inp, "class": cls, "level": level, "side": side, "run": best,
                    "repr": v[0].get("repr", ""), "selected_ms_median": med[best],
                    "selected_ms_min": min(num(r, "frame_ms_median") for r in v),
                    "replicates": len(v), "candidates": len(by_run),
                    "total_bytes": num(v[0], "total_bytes"), "quality_px": num(v[0], "quality_px"),
                })
    return out


def write_selection(sel: list[dict], path: Path) -> None:
    tmp = Path(str(path) + ".part")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=SELECTION_COLUMNS)
        w.writeheader()
        for s in sel:
            w.writerow({k: s[k] for k in SELECTION_COLUMNS})
    tmp.replace(path)


def read_selection(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        out = []
        for r in csv.DictReader(f):
            r["level"] = float(r["level"])
            for k in ("selected_ms_median", "selected_ms_min"):
                r[k] = float(r[k])
            out.append(r)
        return out


def runs_of(sel: list[dict], inp: str) -> list[str]:
    """The distinct runs chosen for `inp`, SDF side first (the duel's --duel list)."""
    seen: list[str] = []
    for side in SIDES:
        for s in sel:
            if s["input"] == inp and s["side"] == side and s["run"] not in seen:
                seen.append(s["run"])
    return seen


def read_duels(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def duel_ratios(sel: list[dict], duel_rows: list[dict], opponent: str = "mesh") -> list[dict]:
    """Per (input, level) with the SDF side and `opponent` (`mesh`: ray traced, `raster`)
    chosen and duelled: the two runs (`sdf_run`, `mesh_run`: the opponent's), the
    per-process log ratios (median over rounds of the within-round log(sdf/opponent)) and
    each run's duel median, ms."""
    frames: dict = {}
    for r in duel_rows:
        t = num(r, "frame_ms")
        if t is None or t <= 0:
            continue
        frames.setdefault((r["input"], r["process"], r["round"]), {})[r["run"]] = t
    out = []
    chosen: OrderedDict = OrderedDict()
    for s in sel:
        chosen.setdefault((s["input"], s["level"]), {})[s["side"]] = s
    for (inp, level), sides in chosen.items():
        if "sdf" not in sides or opponent not in sides:
            continue
        a, b = sides["sdf"]["run"], sides[opponent]["run"]
        per_proc: dict[str, list[float]] = {}
        ta, tb = [], []
        for (i, proc, _rnd), runs in frames.items():
            if i != inp or a not in runs or b not in runs:
                continue
            per_proc.setdefault(proc, []).append(math.log(runs[a] / runs[b]))
            ta.append(runs[a])
            tb.append(runs[b])
        if not per_proc:
            continue
        out.append({
            "input": inp, "class": sides["sdf"]["class"], "level": level, "sdf_run": a, "mesh_run": b,
            "logs": [float(np.median(v)) for _, v in sorted(per_proc.items())],
            "rounds": sum(len(v) for v in per_proc.values()),
            "sdf_ms": float(np.median(ta)), "mesh_ms": float(np.median(tb)),
            "sdf_selected_ms": sides["sdf"]["selected_ms_min"],
            "mesh_selected_ms": sides[opponent]["selected_ms_min"],
        })
    return out


def mark_too_few(c: dict) -> dict:
    """A stats.ratio_ci dict with `too_few` set (fewer than MIN_INPUTS inputs) and, then, no
    interval: "too few inputs" is said, not dressed as an interval."""
    c["too_few"] = 0 < c["n_inputs"] < MIN_INPUTS
    if c["too_few"]:
        c["lo"] = c["hi"] = c["within_noise"] = None
    return c


def duel_verdicts(sel: list[dict], ratios: list[dict], classes: list[str], opponent: str = "mesh") -> list[dict]:
    """One dict per (class, level): stats.ratio_ci over the class's duelled inputs (None
    interval below MIN_INPUTS: `too_few`), and the inputs only one side meets the level on."""
    out = []
    for cls in classes:
        for level in LEVELS:
            logs = OrderedDict((r["input"], r["logs"]) for r in ratios
                               if r["class"] == cls and r["level"] == level)
            c = mark_too_few(stats.ratio_ci(logs))
            sides: dict[str, set] = {}
            for s in sel:
                if s["class"] == cls and s["level"] == level and s["side"] in ("sdf", opponent):
                    sides.setdefault(s["input"], set()).add(s["side"].replace(opponent, "mesh"))
            ins = {s["input"] for s in sel if s["class"] == cls}
            c["only_sdf"] = sorted(i for i, v in sides.items() if v == {"sdf"})
            c["only_mesh"] = sorted(i for i, v in sides.items() if v == {"mesh"})
            c["neither"] = sorted(ins - set(sides))
            c["inputs"] = sorted(logs)
            out.append({"class": cls, "level": level, "time": c})
    return out


def optimism(ratios: list[dict]) -> dict:
    """Per side, the median over (input, level) of selected time / duel time (> 1: the
    selection pass made that side look slower; < 1: faster than it re-measures); and under
    `ratio`, the same of the SDF/mesh ratio (selected ratio / duelled ratio: what the selection
    did to the answer itself; a drift of the machine between the sweep and the duels that
    slows both sides alike cancels from it, while it moves each side's own optimism)."""
    def stats_of(v):
        return {"median": float(np.median(v)) if v else None,
                "p10": float(np.quantile(v, 0.1)) if v else None,
                "p90": float(np.quantile(v, 0.9)) if v else None, "n": len(v)}

    out = {}
    for side in ("sdf", "mesh"):
        out[side] = stats_of([r[f"{side}_selected_ms"] / r[f"{side}_ms"] for r in ratios if r[f"{side}_ms"] > 0])
    out["ratio"] = stats_of([(r["sdf_selected_ms"] / r["sdf_ms"]) / (r["mesh_selected_ms"] / r["mesh_ms"])
                             for r in ratios if r["sdf_ms"] > 0 and r["mesh_ms"] > 0 and r["mesh_selected_ms"] > 0])
    return out


def verdict_cell(c: dict) -> str:
    """The text of one verdict cell."""
    extra = "".join(f"; +{len(c[k])} only {w}" for k, w in (("only_sdf", "SDF"), ("only_mesh", "mesh"))
                    if c[k])
    if c["ratio"] is None:
        return analysis.verdict_text(c, "time")  # who alone meets the level, or neither
    r = c["ratio"]
    fac = max(r, 1 / r)
    who = "SDF" if r < 1 else "mesh"
    if c["too_few"]:
        return f"{who} {fac:.3g}× faster, too few inputs ({c['n_inputs']}) for an interval{extra}"
    if c["within_noise"]:
        return f"**tie** (SDF/mesh {r:.3g}, CI {c['lo']:.3g}–{c['hi']:.3g}){extra}"
    lo, hi = (1 / c["hi"], 1 / c["lo"]) if r < 1 else (c["lo"], c["hi"])
    return f"**{who} {fac:.3g}× faster** (CI {lo:.3g}–{hi:.3g}×, {c['n_inputs']} inputs){extra}"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="sdfmesh_tools.duel", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("select", help="write the selection CSV from a compare CSV")
    s.add_argument("--csv", required=True, type=Path)
    s.add_argument("--out", required=True, type=Path)
    r = sub.add_parser("runs", help="print the comma-separated runs chosen for one input")
    r.add_argument("--selection", required=True, type=Path)
    r.add_argument("--input", required=True)
    m = sub.add_parser("merge", help="concatenate duel CSVs (whole files only)")
    m.add_argument("--out", required=True, type=Path)
    m.add_argument("parts", nargs="*", type=Path)
    a = p.parse_args(argv)
    if a.cmd == "select":
        write_selection(select(data.read_csv(a.csv)), a.out)
    elif a.cmd == "runs":
        print(",".join(runs_of(read_selection(a.selection), a.input)))
    else:
        header, body = None, []
        for part in a.parts:
            with open(part, newline="") as f:
                rows = list(csv.reader(f))
            if not rows:
                continue
            if header is None:
                header = rows[0]
            elif rows[0] != header:
                print(f"error: {part}: line 1: the header differs from {a.parts[0]}'s", file=sys.stderr)
                return 2
            for i, row in enumerate(rows[1:], start=2):
                if len(row) != len(header):
                    print(f"error: {part}: line {i}: {len(row)} fields, the header has {len(header)}",
                          file=sys.stderr)
                    return 2
                body.append(row)
        tmp = Path(str(a.out) + ".part")
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            if header:
                w.writerow(header)
            w.writerows(body)
        tmp.replace(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
