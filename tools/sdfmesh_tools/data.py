"""Reading the CSVs that `toolkit compare` writes (schema version 1).

Rows are dicts of strings; `num` and `samples` turn cells into numbers and tolerate
missing columns and empty cells (both give None / an empty list).
"""

from __future__ import annotations

import csv
import math
from collections import OrderedDict
from pathlib import Path

COMPARE_COLUMNS = (
    "input repr method resolution reference triangles grid_cells_stored geometry_bytes "
    "accel_bytes total_bytes build_ms frame_ms_median frame_ms_min frame_ms_max frames "
    "mrays_per_s steps_per_ray nodes_per_ray image_rmse image_psnr_db image_ssim "
    "hit_mismatch_pct chamfer_rel hausdorff_rel peak_rss_bytes threads width height depth "
    "commit timestamp frame_ms_samples schema_version"
).split()

SCALING_COLUMNS = (
    "primitive repr method count triangles total_bytes build_ms frame_ms_median frame_ms_min "
    "frame_ms_max frames fps_median mrays_per_s steps_per_ray nodes_per_ray threads width "
    "height depth commit timestamp frame_ms_samples schema_version"
).split()

SDF_REPRS = ("sdf", "grid")
MESH_REPRS = ("mesh",)


def read_csv(path: str | Path | None) -> list[dict[str, str]]:
    """All rows of a CSV as dicts (empty list when the path is None or missing)."""
    if not path:
        return []
    p = Path(path)
    if not p.is_file():
        print(f"note: {p} not found; skipping it")
        return []
    with p.open(newline="") as f:
        rows = [dict(r) for r in csv.DictReader(f)]
    version = {r.get("schema_version", "") for r in rows} - {"", None}
    if version and version != {"1"}:
        print(f"note: {p} has schema_version {sorted(version)}; this reader knows version 1")
    return rows


def num(row: dict, col: str) -> float | None:
    """The cell as a float; None when missing, empty, not a number or NaN."""
    v = row.get(col)
    if v is None:
        return None
    v = str(v).strip()
    if not v:
        return None
    try:
        x = float(v)
    except ValueError:
        return None
    if math.isnan(x):
        return None
    return x


def samples(row: dict, col: str = "frame_ms_samples") -> list[float]:
    """Space-separated floats of a cell (per-frame times); bad tokens are dropped."""
    out = []
    for tok in str(row.get(col) or "").replace(",", " ").split():
        try:
            x = float(tok)
        except ValueError:
            continue
        if math.isfinite(x):
            out.append(x)
    return out


def label(row: dict) -> str:
    """`repr/method` or `repr/method@res`."""
    res = num(row, "resolution")
    base = f"{row.get('repr', '?')}/{row.get('method', '?')}"
    return f"{base}@{int(res)}" if res is not None else base


def group(rows, *cols) -> "OrderedDict[tuple, list[dict]]":
    """Rows grouped by the values of `cols`, in first-seen order."""
    out: OrderedDict[tuple, list[dict]] = OrderedDict()
    for r in rows:
        out.setdefault(tuple(r.get(c, "") for c in cols), []).append(r)
    return out


def inputs(rows) -> list[str]:
    return list(OrderedDict.fromkeys(r.get("input", "") for r in rows if r.get("input")))


def is_reference(row: dict) -> bool:
    ref = (row.get("reference") or "").strip()
    return bool(ref) and ref == f"{row.get('repr', '')}/{row.get('method', '')}"
