"""Plots of `toolkit compare` results.

2D plots use matplotlib (Agg); 3D views use pyvista off screen (see offscreen.py).
Every function returns the list of PNG paths it wrote and prints a note instead of
failing when the columns or rows it needs are missing.

CLI: python -m sdfmesh_tools.plots --csv compare.csv [--scaling scaling.csv]
         [--artifacts DIR] --out DIR
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from . import data  # noqa: E402
from .data import num  # noqa: E402

MARKERS = "o s ^ D v P X * < >".split()


def note(msg: str) -> None:
    print(f"note: {msg}")


def _style(key: tuple, keys: list) -> dict:
    i = keys.index(key) if key in keys else 0
    cmap = plt.get_cmap("tab10")
    return {"color": cmap(i % 10), "marker": MARKERS[i % len(MARKERS)]}


def _panels(n: int, width: float = 5.0, height: float = 4.0):
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(width * cols, height * rows), squeeze=False)
    flat = list(axes.ravel())
    for ax in flat[n:]:
        ax.axis("off")
    return fig, flat[:n]


def _save(fig, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _log_axis(axis, decades: float | None = None) -> None:
    """Log scale labelled with plain numbers (no 2x10^0 pile-ups): 1, 2, 5 per decade, or,
    over `decades` decades, 1 and 3 per decade above 2.5 and only the powers of ten above 4
    (at most about 8 labels, so they do not overlap on a panel a few inches wide)."""
    from matplotlib import ticker

    subs = (1.0, 2.0, 5.0) if decades is None or decades <= 2.5 else (1.0, 3.0) if decades <= 4 else (1.0,)
    axis.set_major_locator(ticker.LogLocator(base=10, subs=subs, numticks=9))
    axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(ticker.NullFormatter())


def _has(rows, *cols) -> bool:
    return any(all(num(r, c) is not None for c in cols) for r in rows)


def per_input_xy(rows, x: str, y: str, path: Path, title: str, xlabel: str, ylabel: str,
                 logx: bool = True, logy: bool = True, flat_rows_as_lines: bool = False):
    """One panel per input, one line per (repr, method), points sorted by x.

    Points whose x or y is missing (or not positive on a log axis) are left out. A group
    with no x at all (rows without a resolution) is drawn as a horizontal line at its y
    when `flat_rows_as_lines` is set.
    """
    names = data.inputs(rows)
    if not names or not _has(rows, y):
        note(f"{path.name}: no rows with '{y}'; skipped")
        return []
    keys = list(data.group(rows, "repr", "method").keys())
    fig, axes = _panels(len(names))
    drawn = 0
    for ax, name in zip(axes, names):
        sub = [r for r in rows if r.get("input") == name]
        ref_y = None
        for key, grp in data.group(sub, "repr", "method").items():
            pts = []
            for r in grp:
                xv, yv = num(r, x), num(r, y)
                if yv is None or (logy and yv <= 0):
                    continue
                if data.is_reference(r) and x in ("chamfer_rel", "hausdorff_rel", "image_rmse"):
                    ref_y = (yv, data.label(r))
                    continue
                if xv is None or (logx and xv <= 0):
                    if flat_rows_as_lines and xv is None:
                        ax.axhline(yv, ls="--", lw=1.2, label=f"{key[0]}/{key[1]}", **{"color": _style(key, keys)["color"]})
                        drawn += 1
                    continue
                pts.append((xv, yv))
            if not pts:
                continue
            pts.sort()
            xs, ys = zip(*pts)
            ax.plot(xs, ys, label=f"{key[0]}/{key[1]}", lw=1.4, ms=5, **_style(key, keys))
            drawn += 1
        if ref_y is not None:
            ax.axhline(ref_y[0], color="k", ls=":", lw=1, label=f"reference {ref_y[1]}")
            drawn += 1
        ax.set_title(name)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        if logx:
            ax.set_xscale("log")
            _log_axis(ax.xaxis)
        if logy:
            ax.set_yscale("log")
            _log_axis(ax.yaxis)
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
    if drawn == 0:
        plt.close(fig)
        note(f"{path.name}: nothing to draw; skipped")
        return []
    fig.suptitle(title)
    return [_save(fig, path)]


def frame_time_vs_error(rows, out: Path):
    out = Path(out)
    written = per_input_xy(rows, "chamfer_rel", "frame_ms_median", out / "frame_time_vs_chamfer.png",
                           "Frame time vs geometric error (dotted: reference)",
                           "chamfer distance / bbox diagonal", "frame time, median (ms)")
    written += per_input_xy(rows, "image_rmse", "frame_ms_median", out / "frame_time_vs_image_rmse.png",
                            "Frame time vs image error (dotted: reference)",
                            "image RMSE (0..1 RGB)", "frame time, median (ms)")
    return written


def bytes_vs_error(rows, out: Path):
    out = Path(out)
    written = per_input_xy(rows, "chamfer_rel", "total_bytes", out / "bytes_vs_chamfer.png",
                           "Memory vs geometric error (dotted: reference)",
                           "chamfer distance / bbox diagonal", "total bytes")
    written += per_input_xy(rows, "image_rmse", "total_bytes", out / "bytes_vs_image_rmse.png",
                            "Memory vs image error (dotted: reference)",
                            "image RMSE (0..1 RGB)", "total bytes")
    return written


def build_time_vs_resolution(rows, out: Path):
    return per_input_xy(rows, "resolution", "build_ms", Path(out) / "build_time_vs_resolution.png",
                        "Build time vs resolution", "resolution (cells / segments)", "build time (ms)",
                        logy=True)


def per_ray_vs_resolution(rows, out: Path):
    out = Path(out)
    written = per_input_xy(rows, "resolution", "steps_per_ray", out / "steps_per_ray_vs_resolution.png",
                           "Marching steps per ray vs resolution (dashed: no resolution)",
                           "resolution (cells / segments)", "steps per ray",
                           logy=False, flat_rows_as_lines=True)
    written += per_input_xy(rows, "resolution", "nodes_per_ray", out / "nodes_per_ray_vs_resolution.png",
                            "BVH nodes visited per ray vs resolution (dashed: no resolution)",
                            "resolution (cells / segments)", "nodes per ray",
                            logy=False, flat_rows_as_lines=True)
    return written


def scaling_plot(rows, out: Path):
    """Frame time vs primitive count, one line per (primitive, repr, method)."""
    path = Path(out) / "scaling_frame_time_vs_count.png"
    if not rows or not _has(rows, "count", "frame_ms_median"):
        note(f"{path.name}: no scaling rows with count and frame_ms_median; skipped")
        return []
    fig, ax = plt.subplots(figsize=(7, 5))
    groups = data.group(rows, "primitive", "repr", "method")
    keys = list(groups.keys())
    drawn = 0
    for key, grp in groups.items():
        pts = sorted((num(r, "count"), num(r, "frame_ms_median")) for r in grp
                     if (num(r, "count") or 0) > 0 and (num(r, "frame_ms_median") or 0) > 0)
        if not pts:
            continue
        xs, ys = zip(*pts)
        ax.plot(xs, ys, label="/".join(k for k in key if k), lw=1.4, ms=5, **_style(key, keys))
        drawn += 1
    if not drawn:
        plt.close(fig)
        note(f"{path.name}: nothing to draw; skipped")
        return []
    ax.set_xscale("log")
    ax.set_yscale("log")
    _log_axis(ax.xaxis)
    _log_axis(ax.yaxis)
    ax.set_xlabel("primitive count")
    ax.set_ylabel("frame time, median (ms)")
    ax.set_title("Frame time vs number of primitives")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return [_save(fig, path)]


# ---------------------------------------------------------------------------------------
# Artifacts: images side by side (matplotlib) and 3D views (pyvista)


def _read_png(path: Path) -> np.ndarray:
    import matplotlib.image as mpimg

    img = mpimg.imread(str(path)).astype(np.float64)
    if img.ndim == 2:
        img = np.stack([img] * 3, axis=-1)
    if img.max() > 1.0:
        img = img / 255.0
    return img[..., :3]


def _reference_stem(rows, name: str, folder: Path) -> str | None:
    for r in rows:
        if r.get("input") == name and r.get("reference"):
            return r["reference"].replace("/", "-")
    for guess in ("analytic-closed-form", "analytic-interval-march", "mesh-original"):
        if (folder / f"{guess}.png").is_file():
            return guess
    return None


def _res_of(stem: str) -> int | None:
    tail = stem.rsplit("-", 1)[-1]
    return int(tail) if tail.isdigit() else None


def image_comparisons(rows, artifacts: Path, out: Path, max_rows: int = 6):
    """Per input: reference PNG, candidate PNG and |difference| heat map, one row per candidate."""
    artifacts, out = Path(artifacts), Path(out)
    written = []
    if not artifacts.is_dir():
        note(f"artifacts folder {artifacts} not found; image comparisons skipped")
        return written
    for folder in sorted(p for p in artifacts.iterdir() if p.is_dir()):
        name = folder.name
        ref_stem = _reference_stem(rows, name, folder)
        ref_path = folder / f"{ref_stem}.png" if ref_stem else None
        if ref_path is None or not ref_path.is_file():
            note(f"{name}: no reference PNG in {folder}; image comparison skipped")
            continue
        cands = sorted((p for p in folder.glob("*.png") if p != ref_path),
                       key=lambda p: (p.stem.rsplit("-", 1)[0] if _res_of(p.stem) else p.stem,
                                      _res_of(p.stem) or 0))
        if not cands:
            note(f"{name}: no candidate PNGs; image comparison skipped")
            continue
        if len(cands) > max_rows:  # spread the choice over the list
            idx = np.linspace(0, len(cands) - 1, max_rows).round().astype(int)
            cands = [cands[i] for i in sorted(set(idx))]
        ref = _read_png(ref_path)
        fig, axes = plt.subplots(len(cands), 3, figsize=(10, 3.2 * len(cands)), squeeze=False)
        for (a0, a1, a2), cand in zip(axes, cands):
            img = _read_png(cand)
            a0.imshow(ref)
            a0.set_title(f"reference {ref_stem}", fontsize=8)
            a1.imshow(img)
            a1.set_title(cand.stem, fontsize=8)
            if img.shape == ref.shape:
                diff = np.abs(img - ref).mean(axis=-1)
                rmse = float(np.sqrt(((img - ref) ** 2).mean()))
                im = a2.imshow(diff, cmap="inferno", vmin=0, vmax=max(float(diff.max()), 1e-6))
                fig.colorbar(im, ax=a2, fraction=0.046, pad=0.04)
                a2.set_title(f"|difference|, RMSE {rmse:.4f}", fontsize=8)
            else:
                a2.text(0.5, 0.5, f"size differs\n{img.shape} vs {ref.shape}", ha="center", va="center")
            for a in (a0, a1, a2):
                a.set_xticks([])
                a.set_yticks([])
        written.append(_save(fig, out / f"images_{name}.png"))
    return written


def _screenshot(pv, plotter, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(path))
    plotter.close()
    return path


def _triangles(pv, mesh):
    mesh = mesh.extract_surface() if not isinstance(mesh, pv.PolyData) else mesh
    return mesh.triangulate()


def mesh_distance_views(artifacts: Path, out: Path, max_per_input: int = 3):
    """Each extracted/tessellated mesh coloured by its distance to the reference surface.

    The reference is DIR/<input>/reference.ply, else the largest (finest) mesh PLY of the input.
    Distances are unsigned and divided by the reference's bounding-box diagonal.
    """
    artifacts, out = Path(artifacts), Path(out)
    written = []
    if not artifacts.is_dir():
        note(f"artifacts folder {artifacts} not found; mesh distance views skipped")
        return written
    try:
        from .offscreen import pyvista
        pv = pyvista()
    except Exception as e:  # noqa: BLE001
        note(f"3D views skipped: {e}")
        return written
    for folder in sorted(p for p in artifacts.iterdir() if p.is_dir()):
        meshes = sorted((p for p in folder.glob("*.ply") if p.name != "reference.ply"),
                        key=lambda p: (_res_of(p.stem) or 0, p.stem))
        ref_path = folder / "reference.ply"
        if not ref_path.is_file():
            if len(meshes) < 2:
                note(f"{folder.name}: no reference.ply and fewer than two meshes; distance view skipped")
                continue
            ref_path = max(meshes, key=lambda p: p.stat().st_size)  # the finest (most triangles)
            meshes.remove(ref_path)
        if not meshes:
            note(f"{folder.name}: no mesh PLY besides the reference; distance view skipped")
            continue
        try:
            ref = _triangles(pv, pv.read(str(ref_path)))
        except Exception as e:  # noqa: BLE001
            note(f"{folder.name}: cannot read {ref_path.name}: {e}")
            continue
        if ref.n_cells == 0:
            note(f"{folder.name}: {ref_path.name} is empty; distance view skipped")
            continue
        diag = float(np.linalg.norm(np.subtract(ref.bounds[1::2], ref.bounds[0::2]))) or 1.0
        if len(meshes) > max_per_input:
            idx = np.linspace(0, len(meshes) - 1, max_per_input).round().astype(int)
            meshes = [meshes[i] for i in sorted(set(idx))]
        for mpath in meshes:
            try:
                mesh = _triangles(pv, pv.read(str(mpath)))
                if mesh.n_points == 0:
                    note(f"{folder.name}: {mpath.name} is empty; skipped")
                    continue
                # distances at the triangle centres (vertices often lie on the surface)
                centres = mesh.cell_centers().compute_implicit_distance(ref)
                d = np.abs(np.asarray(centres["implicit_distance"])) / diag
                mesh.cell_data["distance / diag"] = d
                p = pv.Plotter(off_screen=True, window_size=(900, 700))
                p.add_mesh(mesh, scalars="distance / diag", preference="cell", cmap="viridis",
                           clim=(0.0, max(float(d.max()), 1e-9)), show_edges=False,
                           scalar_bar_args={"title": "|distance| / bbox diagonal"})
                p.add_text(f"{folder.name}: {mpath.stem}\nvs {ref_path.name}; max {d.max():.2e}, "
                           f"mean {d.mean():.2e}", font_size=10)
                p.view_isometric()
                written.append(_screenshot(pv, p, out / f"distance_{folder.name}_{mpath.stem}.png"))
            except Exception as e:  # noqa: BLE001
                note(f"{folder.name}: distance view of {mpath.name} failed: {e}")
    return written


def sdf_grid_views(artifacts: Path, out: Path, max_per_input: int = 2):
    """Each SDF grid (.vti): the mid slice coloured by distance plus the zero isosurface."""
    artifacts, out = Path(artifacts), Path(out)
    written = []
    if not artifacts.is_dir():
        note(f"artifacts folder {artifacts} not found; SDF grid views skipped")
        return written
    grids = sorted(artifacts.glob("*/*.vti"))
    if not grids:
        note("no .vti grids in the artifacts; SDF grid views skipped")
        return written
    try:
        from .offscreen import pyvista
        pv = pyvista()
    except Exception as e:  # noqa: BLE001
        note(f"3D views skipped: {e}")
        return written
    per_input: dict[str, int] = {}
    for gpath in grids:
        name = gpath.parent.name
        if per_input.get(name, 0) >= max_per_input:
            continue
        try:
            grid = pv.read(str(gpath))
            arrays = list(grid.point_data.keys())
            if not arrays:
                note(f"{gpath}: no point data; skipped")
                continue
            array = "sdf" if "sdf" in arrays else arrays[0]
            grid.set_active_scalars(array)
            values = np.asarray(grid[array], dtype=np.float64)
            lim = float(np.nanmax(np.abs(values))) or 1.0
            p = pv.Plotter(off_screen=True, window_size=(900, 700))
            sl = grid.slice(normal="z")
            if sl.n_points:
                p.add_mesh(sl, scalars=array, cmap="RdBu", clim=(-lim, lim),
                           scalar_bar_args={"title": f"{array} (slice z = mid)"})
            if sl.n_points:
                line = sl.contour([0.0], scalars=array)
                if line.n_points:
                    p.add_mesh(line, color="black", line_width=3)
            iso = grid.contour([0.0], scalars=array)
            if iso.n_points:
                p.add_mesh(iso, color="gold", opacity=0.85, smooth_shading=True)
            else:
                note(f"{gpath.name}: no zero isosurface")
            p.add_mesh(grid.outline(), color="black")
            p.add_text(f"{name}: {gpath.stem}  dims {tuple(grid.dimensions)}", font_size=10)
            p.view_isometric()
            written.append(_screenshot(pv, p, out / f"sdf_{name}_{gpath.stem}.png"))
            per_input[name] = per_input.get(name, 0) + 1
        except Exception as e:  # noqa: BLE001
            note(f"{gpath}: SDF grid view failed: {e}")
    return written


SIDE_STYLE = {"sdf": {"color": "tab:blue", "marker": "o", "label": "best SDF (sdf, grid)"},
              "mesh": {"color": "tab:orange", "marker": "s", "label": "best mesh"}}


def _family_axis(ax, xs) -> None:
    """Ticks at the family's parameter values, log-spaced when they span 10x or more."""
    from matplotlib import ticker

    if min(xs) > 0 and max(xs) / min(xs) >= 10:
        ax.set_xscale("log")
    ax.xaxis.set_major_locator(ticker.FixedLocator(xs))
    ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_locator(ticker.NullLocator())


def _bytes_axis(axis) -> None:
    """Log axis of bytes labelled in B, KiB, MiB, GiB at the powers of 4."""
    from matplotlib import ticker

    def fmt(v, _):
        for unit, k in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
            if v >= k:
                return f"{v / k:g} {unit}"
        return f"{v:g} B"

    axis.set_major_locator(ticker.LogLocator(base=4))
    axis.set_major_formatter(ticker.FuncFormatter(fmt))
    axis.set_minor_locator(ticker.NullLocator())
    axis.set_minor_formatter(ticker.NullFormatter())


def family_plots(fams, out: Path) -> list[Path]:
    """One PNG per class: per family, frame time (top) and bytes (bottom) of the best SDF
    and the best mesh run against the family parameter (median over replicates, bars from
    the fastest to the slowest replicate), a dotted line where the winner changes."""
    out = Path(out)
    written = []
    by_class: dict[str, list[dict]] = {}
    for f in fams:
        by_class.setdefault(f["class"], []).append(f)
    for cls, fs in by_class.items():
        n = len(fs)
        fig, axes = plt.subplots(2, n, figsize=(4.6 * n, 7.2), squeeze=False)
        for j, f in enumerate(fs):
            for i, (key, ylabel) in enumerate((("frame_ms_median", "frame time (ms, median)"),
                                               ("total_bytes", "bytes (geometry + BVH)"))):
                ax = axes[i][j]
                d = f[key]
                for side in ("sdf", "mesh"):
                    pts = [(x, p) for x, p in zip(f["xs"], d[side]) if p is not None and p[0] > 0]
                    if not pts:
                        continue
                    xs = [x for x, _ in pts]
                    med = np.array([p[0] for _, p in pts])
                    lo = med - np.array([p[1] for _, p in pts])
                    hi = np.array([p[2] for _, p in pts]) - med
                    st = SIDE_STYLE[side]
                    ax.errorbar(xs, med, yerr=[lo, hi], color=st["color"], marker=st["marker"],
                                label=st["label"], lw=1.4, ms=5, capsize=3)
                for xa, xb, old, new in d["crossovers"]:
                    xm = math.sqrt(xa * xb) if xa > 0 and xb > 0 else (xa + xb) / 2
                    ax.axvline(xm, color="k", ls=":", lw=1)
                    ax.annotate(f"{old}→{new}", (xm, 0.97), xycoords=("data", "axes fraction"),
                                ha="center", va="top", fontsize=8,
                                bbox={"boxstyle": "round", "fc": "white", "alpha": 0.8})
                _family_axis(ax, f["xs"])
                ax.set_yscale("log")
                if key == "total_bytes":
                    _bytes_axis(ax.yaxis)
                else:
                    _log_axis(ax.yaxis)
                ax.grid(True, which="both", alpha=0.3)
                ax.set_xlabel(f["axis"])
                ax.set_ylabel(ylabel)
                lvl = f"runs meeting {f['level']:g} px" if f["level"] is not None else "best at each resolution, any quality"
                ax.set_title(f"{f['family']}: {lvl}", fontsize=9)
                if ax.get_legend_handles_labels()[0]:
                    ax.legend(fontsize=7, loc="best")
                else:
                    ax.text(0.5, 0.5, "no run meets the level", ha="center", va="center",
                            transform=ax.transAxes)
        fig.suptitle(f"class {cls}: crossovers along the families")
        written.append(_save(fig, out / f"family_{cls}.png"))
    return written


def cost_model_plot(model, out: Path) -> list[Path]:
    """Predicted against measured frame time, fit half and check half."""
    if not model:
        return []
    fig, ax = plt.subplots(figsize=(5.5, 5))
    for half, color in (("fit", "tab:gray"), ("check", "tab:red")):
        pts = [(t, p) for t, p, h in model["points"] if h == half and t > 0 and p > 0]
        if pts:
            ax.scatter(*zip(*pts), s=10, color=color, alpha=0.6, label=f"{half} half ({len(pts)} runs)")
    allv = [v for t, p, _ in model["points"] for v in (t, p) if v > 0]
    if allv:
        lo, hi = min(allv), max(allv)
        ax.plot([lo, hi], [lo, hi], "k--", lw=1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    _log_axis(ax.xaxis)
    _log_axis(ax.yaxis)
    ax.set_xlabel("measured frame time (ms)")
    ax.set_ylabel("predicted frame time (ms)")
    ax.set_title("cost model: a·steps + b·nodes + d·rays + c")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return [_save(fig, Path(out) / "cost_model.png")]


def all_plots(rows, scaling_rows, artifacts, out: Path) -> list[Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    steps = [
        lambda: frame_time_vs_error(rows, out),
        lambda: bytes_vs_error(rows, out),
        lambda: build_time_vs_resolution(rows, out),
        lambda: per_ray_vs_resolution(rows, out),
        lambda: scaling_plot(scaling_rows, out),
    ]
    if artifacts:
        steps += [
            lambda: image_comparisons(rows, Path(artifacts), out),
            lambda: mesh_distance_views(Path(artifacts), out),
            lambda: sdf_grid_views(Path(artifacts), out),
        ]
    for step in steps:
        try:
            written += step()
        except Exception as e:  # noqa: BLE001 - one broken plot must not stop the rest
            note(f"a plot failed: {type(e).__name__}: {e}")
            plt.close("all")
    return written


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sdfmesh_tools.plots", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--csv", help="compare CSV (toolkit compare --csv)")
    ap.add_argument("--scaling", help="scaling CSV (toolkit compare --scaling --csv)")
    ap.add_argument("--artifacts", help="artifacts folder (toolkit compare --artifacts)")
    ap.add_argument("--out", required=True, help="output folder for the PNGs")
    a = ap.parse_args(argv)
    written = all_plots(data.read_csv(a.csv), data.read_csv(a.scaling), a.artifacts, Path(a.out))
    for p in written:
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def forest_plot(time_v, ratios, bytes_v, bytes_points, out: Path, level: float = 1.0) -> list[Path]:
    """The verdict at `level` as one figure: per class, log SDF/mesh with its 95% interval
    (none below duel.MIN_INPUTS inputs) and one dot per input; frame time from the duels
    (left), bytes from the sweep (right). Left of 1: SDF better."""
    panels = [("frame time (paired duels)", [v for v in time_v if v["level"] == level], "time",
               {(r["class"], r["input"]): math.exp(float(np.mean(r["logs"]))) for r in ratios
                if r["level"] == level}),
              ("bytes (smallest meeting the level)", [v for v in bytes_v if v["level"] == level], "bytes",
               {k: v for k, v in bytes_points.items()})]
    classes = [v["class"] for v in panels[0][1]]
    if not classes:
        return []
    fig, axes = plt.subplots(1, 2, figsize=(11, 0.45 * len(classes) + 1.6), squeeze=False)
    for ax, (title, vs, key, points) in zip(axes[0], panels):
        for y, v in enumerate(vs):
            c = v[key]
            dots = [x for (cls, _i), x in points.items() if cls == v["class"] and x > 0]
            if dots:
                jitter = np.linspace(-0.15, 0.15, len(dots)) if len(dots) > 1 else [0.0]
                ax.scatter(dots, y + np.asarray(jitter), s=12, color="tab:gray", alpha=0.7, zorder=2)
            if c.get("ratio"):
                ax.plot([c["ratio"]], [y], "D", color="tab:blue" if c["ratio"] < 1 else "tab:orange",
                        ms=7, zorder=3)
                if c.get("lo") is not None and c.get("hi") is not None:
                    ax.plot([c["lo"], c["hi"]], [y, y], "-", color="k", lw=2, zorder=3)
        ax.axvline(1.0, color="k", ls="--", lw=1)
        ax.set_xscale("log")
        lo, hi = ax.get_xlim()
        _log_axis(ax.xaxis, math.log10(hi / lo) if lo > 0 and hi > lo else None)
        ax.set_yticks(range(len(vs)))
        ax.set_yticklabels([f"{v['class']} ({v[key]['n_inputs']})" for v in vs])
        ax.invert_yaxis()
        ax.grid(True, axis="x", which="both", alpha=0.3)
        ax.set_xlabel(f"SDF / mesh at {level:g} px (left of 1: SDF better)")
        ax.set_title(title, fontsize=10)
    fig.suptitle("verdict per class: geometric mean (diamond), 95% interval over inputs (bar, ≥ 5 inputs), "
                 "inputs (dots)", fontsize=9)
    return [_save(fig, Path(out) / "forest.png")]


def pareto_plot(rows, out: Path, max_inputs: int = 6) -> list[Path]:
    """Per input (the first of each class, at most `max_inputs`), every run's frame time
    (median over replicates) against its p95 pixel error, and each side's Pareto frontier
    (the runs no other run of that side beats in both)."""
    by_input: dict[str, list[dict]] = {}
    for r in rows:
        if data.side(r) and num(r, "frame_ms_median") and num(r, "px_err_p95") is not None:
            by_input.setdefault(r.get("input", ""), []).append(r)
    first: dict[str, str] = {}
    for inp, rs in by_input.items():
        first.setdefault(data.class_of(rs[0]), inp)
    names = list(first.values())[:max_inputs]
    if not names:
        return []
    fig, axes = _panels(len(names), 4.6, 3.8)
    for ax, inp in zip(axes, names):
        for side in ("sdf", "mesh"):
            runs: dict[str, list[dict]] = {}
            for r in by_input[inp]:
                if data.side(r) == side:
                    runs.setdefault(data.label(r), []).append(r)
            pts = sorted((float(np.median([num(r, "px_err_p95") for r in v])) + 1e-4,
                          float(np.median([num(r, "frame_ms_median") for r in v]))) for v in runs.values())
            if not pts:
                continue
            st = SIDE_STYLE[side]
            ax.scatter(*zip(*pts), s=10, color=st["color"], alpha=0.35)
            front, best = [], math.inf
            for e, t in pts:
                if t < best:
                    front.append((e, t))
                    best = t
            ax.step(*zip(*front), where="post", color=st["color"], marker=st["marker"], ms=4,
                    label=f"{st['label']} frontier")
        ax.set_xscale("log")
        ax.set_yscale("log")
        _log_axis(ax.yaxis)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlabel("p95 pixel error (px)")
        ax.set_ylabel("frame time (ms)")
        ax.set_title(f"{inp} ({data.class_of(by_input[inp][0])})", fontsize=9)
        ax.legend(fontsize=7)
    fig.suptitle("Pareto frontiers: frame time against error, each side")
    return [_save(fig, Path(out) / "pareto.png")]
