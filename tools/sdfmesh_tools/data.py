"""Reading the CSVs that `toolkit compare` writes (schema version 4; version 1 to 3 rows read
too, with the columns later versions added left empty, except `asked_repr`, which rows
without it take from `repr`: before version 3 `repr` was the asked representation).

Version 3 split what was asked from what traced the run: `asked_repr` is the asked
representation, `repr` what traced it (`sdf` for a mesh run whose extraction was empty and
sphere traced; several joined by `+`, e.g. `sdf+mesh`, when the objects went different ways).
A run counts for a side only when it was asked and traced on that side (`side`).

Rows are dicts of strings; `num` and `samples` turn cells into numbers and tolerate
missing columns and empty cells (both give None / an empty list).
"""

from __future__ import annotations

import csv
import math
from collections import OrderedDict
from pathlib import Path

COMPARE_COLUMNS = (
    "input class replicate repr asked_repr method resolution tolerance_px relaxation reference triangles "
    "grid_cells_stored geometry_bytes accel_bytes total_bytes build_ms frame_ms_median "
    "frame_ms_min frame_ms_max frames mrays_per_s steps_per_ray nodes_per_ray image_rmse "
    "image_psnr_db image_ssim flip_mean silhouette_mismatch_pct px_err_mean px_err_p95 "
    "px_err_max quality_px chamfer_rel hausdorff_rel peak_rss_bytes peak_heap_bytes threads width "
    "height depth commit timestamp frame_ms_samples schema_version note primary_ms shading_ms"
).split()

# Schema version 1, for the synthetic CSVs of older tests.
COMPARE_COLUMNS_V1 = (
    "input repr method resolution reference triangles grid_cells_stored geometry_bytes "
    "accel_bytes total_bytes build_ms frame_ms_median frame_ms_min frame_ms_max frames "
    "mrays_per_s steps_per_ray nodes_per_ray image_rmse image_psnr_db image_ssim "
    "hit_mismatch_pct chamfer_rel hausdorff_rel peak_rss_bytes threads width height depth "
    "commit timestamp frame_ms_samples schema_version"
).split()

# The quality levels of schema 2: `quality_px` is the smallest of these a run meets.
QUALITY_LEVELS = (0.5, 1.0, 2.0)

SCALING_COLUMNS = (
    "primitive repr method count triangles total_bytes build_ms frame_ms_median frame_ms_min "
    "frame_ms_max frames fps_median mrays_per_s steps_per_ray nodes_per_ray threads width "
    "height depth commit timestamp frame_ms_samples schema_version"
).split()

SDF_REPRS = ("sdf", "grid")
MESH_REPRS = ("mesh",)

# Mesh inputs' decimations (meshoptimizer) are `mesh` runs named `decimated-<target>`
# (`decimated-25%`, `decimated-5000tris`), without a resolution: mesh-side candidates like
# the original, outside the resolution sweep.
DECIMATED_PREFIX = "decimated-"


def is_decimated(row: dict) -> bool:
    """Whether a row is a decimation of a mesh input (`method` `decimated-<target>`)."""
    return (row.get("method") or "").startswith(DECIMATED_PREFIX)


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
    for r in rows:
        normalize(r)
    version = {r.get("schema_version", "") for r in rows} - {"", None}
    if version - {"1", "2", "3", "4", "5"}:
        print(f"note: {p} has schema_version {sorted(version)}; this reader knows versions 1 to 5")
    return rows


def normalize(row: dict) -> dict:
    """Fills `asked_repr` from `repr` where it is missing or empty (CSVs before schema 3)."""
    if not (row.get("asked_repr") or "").strip():
        row["asked_repr"] = row.get("repr", "")
    return row


def class_of(row: dict) -> str:
    """The `class` column (data/scenes/<class>/, `scenes`, `scan`); `unclassified` if empty."""
    return (row.get("class") or "").strip() or "unclassified"


def replicate_of(row: dict) -> str:
    """The `replicate` column as a string ("0" when missing or empty)."""
    return (row.get("replicate") or "").strip() or "0"


def _side_of(rep: str) -> str | None:
    if rep in SDF_REPRS:
        return "sdf"
    if rep in MESH_REPRS:
        return "mesh"
    return None


def side(row: dict) -> str | None:
    """`sdf` for ray-marched rows (analytic SDF, grids), `mesh` for triangle meshes (the
    original of a scanned mesh included), None for the closed-form reference of scenes.

    A row counts for the side of its asked representation (`asked_repr`, else `repr`) only
    when everything that traced it (`repr`, `+`-separated) is on that side too: a mesh run
    whose objects were sphere traced (`repr` `sdf` or `sdf+mesh`) is on no side."""
    rep = (row.get("repr") or "").strip()
    asked = _side_of((row.get("asked_repr") or "").strip() or rep)
    if asked is None or not rep:
        return None
    return asked if all(_side_of(k) == asked for k in rep.split("+")) else None


def meets(row: dict, level: float) -> bool:
    """Whether a run meets the quality level (`quality_px` <= level; empty: it meets none)."""
    q = num(row, "quality_px")
    return q is not None and q <= level + 1e-12


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
    """`repr/method`, `repr/method@res`, plus ` tol=T relax=R` for swept sphere tracing."""
    res = num(row, "resolution")
    base = f"{row.get('repr', '?')}/{row.get('method', '?')}"
    base = f"{base}@{int(res)}" if res is not None else base
    tol, rel = num(row, "tolerance_px"), num(row, "relaxation")
    if row.get("repr") == "sdf" and (tol is not None or rel is not None):
        base += f" tol={tol:g}" if tol is not None else ""
        base += f" relax={rel:g}" if rel is not None else ""
    return base


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
    asked = (row.get("asked_repr") or "").strip() or row.get("repr", "")
    return bool(ref) and ref == f"{asked}/{row.get('method', '')}"
