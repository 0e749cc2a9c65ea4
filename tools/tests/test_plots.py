"""The report and its plots on a tiny synthetic compare CSV, scaling CSV and artifacts folder."""

import csv
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sdfmesh_tools import data, report, stats

TOOLS = Path(__file__).resolve().parents[1]
COMMIT = "0123456789abcdef0123456789abcdef01234567"
STAMP = "2026-11-22T05:00:00Z"


def _samples(median, n=9, spread=0.05, seed=0):
    rng = np.random.default_rng(seed)
    return " ".join(f"{median * (1 + spread * x):.4f}" for x in rng.standard_normal(n))


def _row(input, repr, method, res, reference, frame, total_bytes, chamfer, rmse, *,
         triangles="", cells="", build=1.0, steps="", nodes="", seed=0):
    s = _samples(frame, seed=seed)
    vals = [float(x) for x in s.split()]
    return {
        "input": input, "repr": repr, "method": method, "resolution": res, "reference": reference,
        "triangles": triangles, "grid_cells_stored": cells,
        "geometry_bytes": int(total_bytes * 0.7), "accel_bytes": total_bytes - int(total_bytes * 0.7),
        "total_bytes": total_bytes, "build_ms": build, "frame_ms_median": f"{np.median(vals):.4f}",
        "frame_ms_min": f"{min(vals):.4f}", "frame_ms_max": f"{max(vals):.4f}", "frames": len(vals),
        "mrays_per_s": f"{0.25 / np.median(vals) * 1000:.3f}", "steps_per_ray": steps,
        "nodes_per_ray": nodes, "image_rmse": rmse,
        "image_psnr_db": "" if rmse == 0 else f"{-20 * np.log10(rmse):.2f}",
        "image_ssim": f"{1 - rmse:.4f}", "hit_mismatch_pct": f"{rmse * 10:.3f}",
        "chamfer_rel": chamfer, "hausdorff_rel": chamfer * 3 if chamfer != "" else "",
        "peak_rss_bytes": 50_000_000, "threads": 2, "width": 64, "height": 48, "depth": 3,
        "commit": COMMIT, "timestamp": STAMP, "frame_ms_samples": s, "schema_version": 1,
    }


def compare_rows():
    a = "analytic/closed-form"
    o = "mesh/original"
    return [
        _row("thesis_sdf_spheres", "analytic", "closed-form", "", a, 2.0, 400, 0, 0, steps="", nodes="", seed=1),
        _row("thesis_sdf_spheres", "sdf", "sphere-trace", "", a, 5.0, 600, 0.0002, 0.002, steps=30, seed=2),
        _row("thesis_sdf_spheres", "mesh", "parametric", 16, a, 3.0, 90_000, 0.004, 0.02,
             triangles=3000, build=2, nodes=20, seed=3),
        _row("thesis_sdf_spheres", "mesh", "parametric", 64, a, 4.0, 1_500_000, 0.0003, 0.004,
             triangles=48000, build=30, nodes=35, seed=4),
        _row("thesis_sdf_spheres", "grid", "dense", 32, a, 9.0, 140_000, 0.002, 0.01,
             cells=32768, build=12, steps=45, seed=5),
        _row("bunny", "mesh", "original", "", o, 6.0, 9_000_000, 0, 0, triangles=144046, nodes=40, seed=6),
        _row("bunny", "grid", "sample", 32, o, 12.0, 150_000, 0.008, 0.04, cells=32768, build=400,
             steps=60, seed=7),
        _row("bunny", "grid", "sample", 64, o, 14.0, 1_100_000, 0.002, 0.015, cells=262144, build=3000,
             steps=70, seed=8),
        _row("bunny", "mesh", "from-sample", 64, o, 5.0, 2_000_000, 0.0025, 0.016, triangles=40000,
             build=3100, nodes=30, seed=9),
    ]


def scaling_rows():
    rows = []
    for prim in ("sphere", "cube"):
        for repr_, method, base, slope in (("sdf", "sphere-trace", 0.5, 1.0), ("mesh", "parametric", 1.0, 0.2)):
            for i, count in enumerate((1, 10, 100)):
                t = base * count**slope
                s = _samples(t, seed=i)
                rows.append({
                    "primitive": prim, "repr": repr_, "method": method, "count": count,
                    "triangles": 0 if repr_ == "sdf" else 500 * count, "total_bytes": 100 * count,
                    "build_ms": 0.1 * count, "frame_ms_median": f"{t:.4f}", "frame_ms_min": f"{t * 0.9:.4f}",
                    "frame_ms_max": f"{t * 1.1:.4f}", "frames": 9, "fps_median": f"{1000 / t:.3f}",
                    "mrays_per_s": "1", "steps_per_ray": "", "nodes_per_ray": "", "threads": 2,
                    "width": 64, "height": 48, "depth": 3, "commit": COMMIT, "timestamp": STAMP,
                    "frame_ms_samples": s, "schema_version": 1,
                })
    return rows


def write_csv(path, rows, columns):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in columns})


def make_artifacts(root: Path):
    from sdfmesh_tools.offscreen import pyvista

    pv = pyvista()
    d = root / "thesis_sdf_spheres"
    d.mkdir(parents=True)
    # images: a reference and a slightly different candidate
    import matplotlib.image as mpimg

    yy, xx = np.mgrid[0:48, 0:64]
    disc = ((xx - 32) ** 2 + (yy - 24) ** 2 < 15**2).astype(float)
    ref = np.stack([disc * 0.9, disc * 0.3, disc * 0.2], axis=-1)
    cand = ref.copy()
    cand[20:24, 40:48] = 0.5
    mpimg.imsave(d / "analytic-closed-form.png", ref)
    mpimg.imsave(d / "mesh-parametric-16.png", cand)
    # meshes: a coarse candidate and a fine reference sphere
    pv.Sphere(radius=1.0, theta_resolution=8, phi_resolution=8).save(d / "mesh-parametric-16.ply")
    pv.Sphere(radius=1.0, theta_resolution=64, phi_resolution=64).save(d / "reference.ply")
    # a dense SDF grid of a sphere
    n = 17
    grid = pv.ImageData(dimensions=(n, n, n), spacing=(3 / (n - 1),) * 3, origin=(-1.5, -1.5, -1.5))
    grid.point_data["sdf"] = np.linalg.norm(grid.points, axis=1) - 1.0
    grid.save(d / "grid-dense-32.vti")


EXPECTED = [
    "frame_time_vs_chamfer.png", "frame_time_vs_image_rmse.png", "bytes_vs_chamfer.png",
    "bytes_vs_image_rmse.png", "build_time_vs_resolution.png", "steps_per_ray_vs_resolution.png",
    "nodes_per_ray_vs_resolution.png", "scaling_frame_time_vs_count.png",
    "images_thesis_sdf_spheres.png", "distance_thesis_sdf_spheres_mesh-parametric-16.png",
    "sdf_thesis_sdf_spheres_grid-dense-32.png",
]


def assert_not_blank(path: Path):
    import matplotlib.image as mpimg

    img = mpimg.imread(path)
    assert img.size > 0, path
    rgb = img[..., :3].reshape(-1, 3)
    assert float(rgb.std()) > 0, f"{path} is blank"
    assert len(np.unique(rgb, axis=0)) > 1, f"{path} is one colour"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    write_csv(tmp / "compare.csv", compare_rows(), data.COMPARE_COLUMNS)
    write_csv(tmp / "scaling.csv", scaling_rows(), data.SCALING_COLUMNS)
    make_artifacts(tmp / "artifacts")
    (tmp / "summary.json").write_text('{"inputs": 2}')
    out = tmp / "out"
    env = dict(os.environ, PYTHONPATH=str(TOOLS) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run(
        [sys.executable, "-m", "sdfmesh_tools.report", "--csv", str(tmp / "compare.csv"),
         "--scaling", str(tmp / "scaling.csv"), "--summary", str(tmp / "summary.json"),
         "--artifacts", str(tmp / "artifacts"), "--out", str(out),
         "--commands", "toolkit compare --csv compare.csv"],
        env=env, capture_output=True, text=True, timeout=300,
    )
    print(r.stdout, r.stderr)
    assert r.returncode == 0, r.stderr
    return out, r.stdout


@pytest.mark.parametrize("name", EXPECTED)
def test_png_written_and_not_blank(run, name):
    out, log = run
    path = out / name
    assert path.is_file(), f"{name} missing; log:\n{log}"
    assert_not_blank(path)


def test_report_contents(run):
    out, _ = run
    text = (out / "REPORT.md").read_text()
    # the per-input sections and plots are in the appendix file the report links
    appendix = (out / "appendix-inputs.md").read_text()
    assert "](appendix-inputs.md)" in text
    for name in ("thesis_sdf_spheres", "bunny"):
        assert f"`{name}`" in appendix
    text += appendix
    assert "95% confidence interval [" in text
    assert "Mann-Whitney" in text
    assert "## The answer" in text
    assert "H1:" in text and "H2:" in text and "H0" in text
    assert COMMIT in text and STAMP in text
    assert "toolkit compare --csv compare.csv" in text
    # the hypotheses' classes are absent from this schema-1 CSV: said so, not guessed
    assert "H1: class `smooth` not measured in this run." in text
    assert "No class could be compared" in text
    # every PNG is linked relatively
    for name in EXPECTED:
        assert f"]({name})" in text, name
    # the scanned mesh: mesh/original is fastest and, with its CI, significantly so
    assert "mesh faster" in text
    assert "**many primitives** (scaling CSV)" in text


def test_missing_columns_and_rows_do_not_crash(tmp_path):
    # only a few columns, one input with a single row, and a row with empty cells
    path = tmp_path / "thin.csv"
    rows = [
        {"input": "thesis_sdf_csg", "repr": "analytic", "method": "closed-form"},
        {"input": "thesis_sdf_csg", "repr": "mesh", "method": "extracted", "frame_ms_median": ""},
    ]
    write_csv(path, rows, ["input", "repr", "method", "frame_ms_median"])
    out = tmp_path / "out"
    report.write_report(path, out, scaling=tmp_path / "absent.csv", artifacts=tmp_path / "none")
    text = (out / "REPORT.md").read_text() + (out / "appendix-inputs.md").read_text()
    assert "thesis_sdf_csg" in text
    assert "not measured in this run" in text
    # an empty CSV (header only) too
    empty = tmp_path / "empty.csv"
    write_csv(empty, [], data.COMPARE_COLUMNS)
    report.write_report(empty, tmp_path / "out2")
    assert (tmp_path / "out2" / "REPORT.md").is_file()
    assert "## Hard cases" not in (tmp_path / "out2" / "REPORT.md").read_text()
    # the hard-case table (toolkit hard --table) goes in verbatim
    hard = tmp_path / "hard.md"
    hard.write_text("| case | representation |\n|---|---|\n| thin_features | grid |\n")
    report.write_report(empty, tmp_path / "out3", hard=hard)
    text = (tmp_path / "out3" / "REPORT.md").read_text()
    assert "## Hard cases" in text and "| thin_features | grid |" in text


def test_ratio_ci_covers_the_true_ratio():
    rng = np.random.default_rng(3)
    a = 2.0 * (1 + 0.05 * rng.standard_normal(200))
    b = 4.0 * (1 + 0.05 * rng.standard_normal(200))
    ratio, lo, hi = stats.ratio_of_medians_ci(a, b)
    assert lo < 0.5 < hi and abs(ratio - 0.5) < 0.02
    assert stats.mann_whitney_p(a, b) < 1e-6
    assert stats.ratio_of_medians_ci([1.0], [2.0]) == (0.5, None, None)


def test_labels_and_sides():
    r = {"repr": "sdf", "method": "sphere-trace", "resolution": "", "tolerance_px": "1",
         "relaxation": "1.6"}
    assert data.label(r) == "sdf/sphere-trace tol=1 relax=1.6"
    assert data.label({"repr": "mesh", "method": "parametric", "resolution": "64"}) == "mesh/parametric@64"
    assert data.side(r) == "sdf" and data.side({"repr": "grid"}) == "sdf"
    assert data.side({"repr": "mesh"}) == "mesh" and data.side({"repr": "analytic"}) is None
    assert data.meets({"quality_px": "1"}, 1.0) and not data.meets({"quality_px": "2"}, 1.0)
    assert not data.meets({"quality_px": ""}, 2.0)
    assert data.class_of({}) == "unclassified" and data.replicate_of({"replicate": ""}) == "0"


def test_forest_plot_tick_labels_do_not_overlap(tmp_path, monkeypatch):
    """A bytes axis spanning six decades (SDF 1000x smaller in one class, 50x larger in
    another) and a time axis spanning two: every visible tick label of both panels is clear
    of its neighbours."""
    from sdfmesh_tools import plots

    classes = [f"class{i}" for i in range(8)]
    spread = np.geomspace(1e-3, 50.0, len(classes))
    time_v, bytes_v, ratios, points = [], [], [], {}
    for c, b in zip(classes, spread):
        t = float(np.clip(b, 0.3, 3.0))
        time_v.append({"class": c, "level": 1.0, "time": {"ratio": t, "lo": t / 1.3, "hi": t * 1.3, "n_inputs": 8}})
        bytes_v.append({"class": c, "level": 1.0, "bytes": {"ratio": b, "lo": b / 3, "hi": b * 3, "n_inputs": 8}})
        for k in range(8):
            ratios.append({"class": c, "input": f"{c}_{k}", "level": 1.0, "logs": [math.log(t) + 0.05 * k]})
            points[(c, f"{c}_{k}")] = b * (1.5 ** (k - 4))
    seen = []

    def check(fig, path):
        fig.tight_layout()
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        for ax in fig.axes:
            lo, hi = ax.get_xlim()
            labels = [t for t in ax.xaxis.get_ticklabels()
                      if t.get_visible() and t.get_text() and lo <= t.get_position()[0] <= hi]
            seen.append((ax.get_title(), [t.get_text() for t in labels]))
            assert len(labels) >= 3, seen[-1]
            boxes = sorted((t.get_window_extent(renderer) for t in labels), key=lambda b: b.x0)
            for a, b in zip(boxes, boxes[1:]):
                assert a.x1 <= b.x0, seen[-1]
        return real_save(fig, path)

    real_save = plots._save
    monkeypatch.setattr(plots, "_save", check)
    assert plots.forest_plot(time_v, ratios, bytes_v, points, tmp_path)
    assert len(seen) == 2 and "bytes" in seen[1][0], seen
