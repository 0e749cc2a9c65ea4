"""Memory, declared against measured (issue #37, item 7): the report's section that puts each
run's declared bytes (`total_bytes`: the geometry and acceleration structure it keeps to
render) beside its measured peak heap (`peak_heap_bytes`: the toolkit's counting allocator,
reset before the run's build and read after its last frame), gives the bytes verdict again on
the measured column, and says where the two differ and why, from the rows themselves:

- the floor: what the closed-form reference runs, which keep almost nothing, still peak at
  (the frame's buffers and the render threads' scratch, paid by every run alike);
- measured above declared: build scratch freed before the frame, per representation;
- measured below declared: what a run shares with the input's other runs, allocated once
  before them (the prepared cells of an implicit model), is live at the reset and not counted.
"""

from __future__ import annotations

import numpy as np

from . import answer, data
from .data import num


def _family(r: dict) -> str:
    """`repr/method` with a decimation's percentage left out (one family per representation)."""
    method = (r.get("method") or "").strip()
    if method.startswith("decimated"):
        method = "decimated-raster" if method.endswith("-raster") else "decimated"
    return f"{(r.get('repr') or '').strip()}/{method}"


def _measured(rows) -> list[dict]:
    return [r for r in rows if num(r, "peak_heap_bytes") is not None and (num(r, "total_bytes") or 0) > 0]


def family_table(rows) -> list[tuple]:
    """Per representation family (most runs first): runs, median declared and measured bytes,
    and the median, 10th and 90th percentile of measured / declared."""
    by: dict[str, list[tuple[float, float]]] = {}
    for r in _measured(rows):
        by.setdefault(_family(r), []).append((num(r, "total_bytes"), num(r, "peak_heap_bytes")))
    out = []
    for fam, v in sorted(by.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        d = np.array([x[0] for x in v])
        m = np.array([x[1] for x in v])
        q = m / d
        out.append((fam, len(v), float(np.median(d)), float(np.median(m)), float(np.median(q)),
                    float(np.percentile(q, 10)), float(np.percentile(q, 90))))
    return out


def floor_bytes(rows) -> float | None:
    """The median measured peak heap of the closed-form reference runs (None without any)."""
    v = [num(r, "peak_heap_bytes") for r in _measured(rows) if (r.get("repr") or "").strip() == "analytic"]
    return float(np.median(v)) if v else None


def below_declared(rows) -> dict[str, set]:
    """{class: families} of the runs whose measured peak is below their declared bytes."""
    out: dict[str, set] = {}
    for r in _measured(rows):
        if num(r, "peak_heap_bytes") < num(r, "total_bytes"):
            out.setdefault(data.class_of(r), set()).add(_family(r))
    return out


def verdicts(rows, level: float) -> list[dict]:
    """Per class at `level`: answer.bytes_verdicts on declared bytes and on measured peak heap,
    each from the smallest run of each side by that column."""
    declared = answer.bytes_verdicts(rows, "total_bytes", (level,))
    measured = answer.bytes_verdicts(rows, "peak_heap_bytes", (level,))
    return [{"class": d["class"], "declared": d["bytes"], "measured": m["bytes"]}
            for d, m in zip(declared, measured)]


def _b(x: float) -> str:
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if x >= size:
            return f"{x / size:.3g} {unit}"
    return f"{x:.3g} B"


def family_markdown(table: list[tuple]) -> str:
    """A family_table as a markdown table (the memory appendix)."""
    from .report import md_table

    return md_table(["representation", "runs", "declared (median)", "measured (median)",
                     "measured / declared (median, p10–p90)"],
                    [(f"`{f}`", n, _b(d), _b(m), f"{q:.3g} ({lo:.3g}–{hi:.3g})")
                     for f, n, d, m, q, lo, hi in table])


def section(rows, level: float, appendix: str | None = None) -> str:
    """The report's "Memory: declared and measured" section (empty text when no run has a
    measured peak heap); `appendix` names the file with the per-representation table."""
    from .report import md_table

    if not _measured(rows):
        return ""
    sizes = sorted({f"{r.get('width')}×{r.get('height')}" for r in rows if r.get("width")})
    text = ("The bytes of the answer are declared: `total_bytes`, the geometry and acceleration structure "
            "a run keeps to render. Every run also has its measured peak heap (`peak_heap_bytes`: the "
            "toolkit's counting allocator, reset before the run's build and read after its last frame), "
            "which adds what the run held only while building or rendering and leaves out what was live "
            "before it began. The bytes verdict on each column, from the smallest run of each side by that "
            f"column meeting {level:g} px:\n\n")
    text += md_table(["class", "declared bytes (the answer)", "measured peak heap"],
                     [(v["class"], answer.bytes_cell(v["declared"]), answer.bytes_cell(v["measured"]))
                      for v in verdicts(rows, level)])
    fl = floor_bytes(rows)
    fams = family_table(rows)
    if appendix:
        text += f"\nPer representation, over every run: [{appendix}]({appendix}).\n"
    else:
        text += "\nPer representation, over every run:\n\n" + family_markdown(fams)
    why = []
    if fl is not None:
        why.append(f"**A floor every run pays.** The closed-form reference runs, which keep almost nothing, "
                   f"peak at a median {_b(fl)} ({', '.join(sizes)}): the frame's own buffers and the render "
                   "threads' scratch. A representation declared far below that measures mostly the floor, so "
                   "on the measured column small SDFs and small meshes draw closer than their declared bytes "
                   "say.")
    # Beyond the floor, more than twice what the run keeps: what its build held and freed.
    base = fl or 0.0
    above = sorted(((f[0], (f[3] - base) / f[2]) for f in fams
                    if not f[0].startswith("analytic") and f[3] - base > 2 * f[2]), key=lambda x: -x[1])
    if above:
        why.append("**Measured above declared: build scratch.** A run's peak includes what its build held and "
                   "freed before the frame (the sample grid an extraction or a re-extraction contours, the "
                   "tessellated or decimated mesh before the BVH reorders it, the BVH of an input mesh a "
                   "grid is sampled against, the builder's working arrays). Median measured peak above the "
                   "floor, in multiples of the declared bytes, where it is over 2: "
                   + ", ".join(f"`{f}` {q:.3g}×" for f, q in above[:8]) + ".")
    below = below_declared(rows)
    if below:
        why.append("**Measured below declared: what the runs share.** "
                   + "; ".join(f"{cls}: " + ", ".join(f"`{f}`" for f in sorted(v))
                               for cls, v in sorted(below.items()))
                   + ". What a run shares with the input's other runs is allocated once before them and is "
                   "live at the reset, so the meter does not count it again; the declared bytes do, since the "
                   "run needs it to render"
                   + (" (class implicit: the model's prepared cells, held by every run that marches it)"
                      if "implicit" in below else "") + ".")
    if why:
        text += "\n" + "\n\n".join(why) + "\n"
    return text
