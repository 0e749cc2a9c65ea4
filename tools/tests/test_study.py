"""The study's analysis (schema-2 compare CSV): verdict per class with its interval, crossover
detection along families, the cost model, and the report built from a synthetic CSV."""

import csv
import math

import numpy as np
import pytest

from sdfmesh_tools import analysis, data, report, stats

COMMIT = "fedcba9876543210fedcba9876543210fedcba98"


def row(input, cls, rep, repr_, method, *, res="", tol="", relax="", frame=1.0, total_bytes=1000,
        quality=1.0, steps="", nodes="", mrays=1.0, reference="analytic/closed-form"):
    return {
        "input": input, "class": cls, "replicate": rep, "repr": repr_, "method": method,
        "resolution": res, "tolerance_px": tol, "relaxation": relax, "reference": reference,
        "triangles": "", "grid_cells_stored": "", "geometry_bytes": total_bytes, "accel_bytes": 0,
        "total_bytes": total_bytes, "build_ms": 1, "frame_ms_median": f"{frame:.6f}",
        "frame_ms_min": f"{frame * 0.95:.6f}", "frame_ms_max": f"{frame * 1.05:.6f}", "frames": 3,
        "mrays_per_s": f"{mrays:.6f}", "steps_per_ray": steps, "nodes_per_ray": nodes,
        "image_rmse": 0.01, "image_psnr_db": 40, "image_ssim": 0.99, "flip_mean": 0.01,
        "silhouette_mismatch_pct": 0.1, "px_err_mean": 0.1, "px_err_p95": 0.3, "px_err_max": 0.9,
        "quality_px": "" if quality is None else quality, "chamfer_rel": 1e-3, "hausdorff_rel": 3e-3,
        "peak_rss_bytes": 1e8, "threads": 2, "width": 64, "height": 64, "depth": 2,
        "commit": COMMIT, "timestamp": f"2026-12-02T07:00:0{rep}Z",
        "frame_ms_samples": f"{frame * 0.97:.6f} {frame:.6f} {frame * 1.03:.6f}", "schema_version": 2,
        "note": "",
    }


def class_rows(cls, ratios, *, noise=0.02, seed=0, bytes_ratio=0.01, n_rep=3):
    """Inputs of one class: for input i, best SDF time = ratios[i] x mesh time (3 replicates
    with multiplicative noise), plus a slower SDF run and a mesh run that meets no level."""
    rng = np.random.default_rng(seed)
    out = []
    for i, ratio in enumerate(ratios):
        name = f"{cls}_in{i}"
        mesh_t = 2.0 + i
        for rep in range(n_rep):
            e = lambda: math.exp(noise * rng.standard_normal())  # noqa: E731
            out += [
                row(name, cls, rep, "analytic", "closed-form", frame=0.5, quality=0.5),
                row(name, cls, rep, "sdf", "sphere-trace", tol=1, relax=1.6, frame=mesh_t * ratio * e(),
                    total_bytes=int(1e6 * bytes_ratio), quality=0.5),
                row(name, cls, rep, "sdf", "sphere-trace", tol=0.25, relax=1, frame=mesh_t * ratio * 3 * e(),
                    total_bytes=int(1e6 * bytes_ratio), quality=0.5),
                row(name, cls, rep, "mesh", "parametric", res=64, frame=mesh_t * e(), total_bytes=10**6,
                    quality=0.5),
                row(name, cls, rep, "mesh", "parametric", res=8, frame=mesh_t * 0.1, total_bytes=10**3,
                    quality=None),
            ]
    return out


def by_class_level(verdicts):
    return {(v["class"], v["level"]): v for v in verdicts}


def test_verdict_per_class():
    rows = (class_rows("fast", [0.5, 0.45, 0.55, 0.5], seed=1)
            + class_rows("slow", [3.0, 2.5, 3.5], seed=2, bytes_ratio=5)
            + class_rows("tie", [0.7, 1.4, 0.9, 1.1], seed=3))
    v = by_class_level(analysis.class_verdicts(rows))
    assert {c for c, _ in v} == {"fast", "slow", "tie"}
    fast = v[("fast", 1.0)]["time"]
    assert fast["n_inputs"] == 4 and fast["n_runs"] == 12
    assert 0.45 < fast["ratio"] < 0.55 and fast["hi"] < 1 and fast["within_noise"] is False
    assert analysis.winner(fast) == "sdf"
    assert analysis.verdict_text(fast, "time").startswith("**SDF 2")
    assert "faster" in analysis.verdict_text(fast, "time")
    # bytes: SDF 100x smaller in "fast", mesh 5x smaller in "slow"
    assert abs(v[("fast", 0.5)]["bytes"]["ratio"] - 0.01) < 1e-9
    assert analysis.verdict_text(v[("fast", 0.5)]["bytes"], "bytes").startswith("**SDF 100× smaller")
    slow = v[("slow", 2.0)]["time"]
    assert slow["lo"] > 1 and analysis.winner(slow) == "mesh"
    assert analysis.verdict_text(slow, "time").startswith("**mesh 2.9")
    tie = v[("tie", 0.5)]["time"]
    assert tie["within_noise"] is True and analysis.winner(tie) == "noise"
    assert "within noise" in analysis.verdict_text(tie, "time")


def test_best_run_is_the_fastest_meeting_the_level():
    rows = class_rows("c", [0.5], noise=0)
    # the unmeeting mesh run (quality empty) is 20x faster than the meeting one: never chosen
    best = analysis.best_per_run(rows, 2.0, "frame_ms_median")[("c_in0", "0")]
    assert best["mesh"]["resolution"] == 64
    assert float(best["sdf"]["tolerance_px"]) == 1
    # a level nobody meets
    rows2 = [r for r in rows if r["repr"] != "mesh" or r["resolution"] != 64]
    c = analysis.compare_sides(rows2, 1.0, "frame_ms_median")
    assert c["ratio"] is None and c["only_sdf"] == ["c_in0"]
    assert analysis.verdict_text(c) == "only SDF meets it (1 inputs)"
    assert analysis.winner(c) == "sdf"


def test_interval_holds_run_to_run_noise_of_a_single_input():
    # one input: the interval is over replicates, and wide noise contains 1
    noisy = stats.ratio_ci({"a": [math.log(0.6), math.log(1.5), math.log(1.1)]})
    assert noisy["unit"] == "runs" and noisy["within_noise"] is True
    tight = stats.ratio_ci({"a": [math.log(0.5), math.log(0.51), math.log(0.49)]})
    assert tight["within_noise"] is False and tight["hi"] < 1
    assert tight["run_spread"] is not None and tight["run_spread"] < 1.05
    # two inputs that disagree: within noise although each is tight
    split = stats.ratio_ci({"a": [math.log(0.5)] * 3, "b": [math.log(2.0)] * 3})
    assert split["unit"] == "inputs" and split["within_noise"] is True
    assert abs(split["ratio"] - 1.0) < 1e-12
    # one run of one input: a ratio and no interval
    one = stats.ratio_ci({"a": [math.log(2.0)]})
    assert one["lo"] is None and one["within_noise"] is None and abs(one["ratio"] - 2) < 1e-12
    assert "no interval" in analysis.verdict_text({**one, "only_sdf": [], "only_mesh": []})


def test_interval_coverage_on_simulated_classes():
    # true ratio 1 between inputs (sd 0.2 in log) plus run noise: the 95% interval
    # contains 1 in about 95% of simulated classes
    rng = np.random.default_rng(7)
    hits = 0
    trials = 400
    for _ in range(trials):
        logs = {}
        for i in range(5):
            mu = 0.2 * rng.standard_normal()
            logs[i] = list(mu + 0.05 * rng.standard_normal(3))
        hits += stats.ratio_ci(logs)["within_noise"]
    assert 0.90 < hits / trials < 0.99


def test_crossover_detection():
    assert stats.crossovers([1, 10, 100, 1000], ["sdf", "sdf", "mesh", "mesh"]) == [(10, 100, "sdf", "mesh")]
    assert stats.crossovers([1, 2, 3], ["mesh", None, "sdf"]) == [(1, 3, "mesh", "sdf")]
    assert stats.crossovers([1, 2, 3], ["sdf", "sdf", "sdf"]) == []


def family_rows():
    """copies_N: SDF time flat at 5 ms, mesh time 1 ms x N^0.5 -> mesh wins up to 10, SDF from 100."""
    rows = []
    for n in (1, 10, 100, 1000):
        name = f"copies_{n:05d}"
        for rep in range(3):
            rows += [
                row(name, "repeat", rep, "sdf", "sphere-trace", tol=1, relax=1, frame=5.0 * (1 + 0.01 * rep),
                    total_bytes=2000, quality=0.5),
                row(name, "repeat", rep, "mesh", "extracted", res=64, frame=1.0 * n**0.5 * (1 + 0.01 * rep),
                    total_bytes=1000 * n, quality=1.0),
            ]
    # a scanned mesh: the grid faster than the re-extracted mesh from resolution 64
    for rep in range(3):
        rows.append(row("bunny", "scan", rep, "mesh", "original", frame=4.0, total_bytes=10**7, quality=0.5,
                        reference="mesh/original"))
        for res, t in ((16, 8.0), (64, 3.0), (128, 2.0)):
            rows.append(row("bunny", "scan", rep, "grid", "sample", res=res, frame=t, total_bytes=res**3 * 4,
                            quality=2.0, reference="mesh/original"))
            rows.append(row("bunny", "scan", rep, "mesh", "from-sample", res=res, frame=4.0,
                            total_bytes=10**6, quality=2.0, reference="mesh/original"))
    return rows


def test_family_crossovers():
    assert analysis.family_of("copies_01000") == ("copies", 1000)
    assert analysis.family_of("menger_3") == ("menger", 3)
    assert analysis.family_of("thin_shell") is None
    fams = {f["family"]: f for f in analysis.families(family_rows())}
    cop = fams["copies"]
    assert cop["xs"] == [1, 10, 100, 1000]
    assert cop["frame_ms_median"]["winner"] == ["mesh", "mesh", "sdf", "sdf"]
    assert cop["frame_ms_median"]["crossovers"] == [(10, 100, "mesh", "sdf")]
    # bytes: mesh 1000 B at 1 copy, SDF 2000 B: SDF smaller from 10 copies on
    assert cop["total_bytes"]["crossovers"] == [(1, 10, "mesh", "sdf")]
    med, lo, hi = cop["frame_ms_median"]["sdf"][0]
    assert lo == pytest.approx(5.0) and hi == pytest.approx(5.1) and med == pytest.approx(5.05)
    bunny = fams["bunny"]
    assert bunny["class"] == "scan" and bunny["xs"] == [16, 64, 128]
    assert bunny["frame_ms_median"]["crossovers"] == [(16, 64, "mesh", "sdf")]


def test_cost_model_recovers_known_coefficients():
    rng = np.random.default_rng(5)
    a, b, d, c = 2e-6, 5e-7, 3e-5, 0.4  # ms per step, per node, per ray; ms per frame
    rows = []
    for i in range(40):
        cls = ("x", "y")[i % 2]
        for rep in range(2):
            rays = float(rng.uniform(1e4, 2e5))
            spr = float(rng.uniform(0, 80))
            npr = float(rng.uniform(0, 60))
            t = a * rays * spr + b * rays * npr + d * rays + c
            mrays = rays / (t * 1e3)
            rows.append(row(f"{cls}_{i:02d}", cls, rep, "sdf", "sphere-trace", frame=t, mrays=mrays,
                            steps=f"{spr:.9g}", nodes=f"{npr:.9g}"))
    m = analysis.cost_model(rows)
    assert m is not None
    got = m["coef"]
    for want, g in zip((a, b, d, c), got):
        assert g == pytest.approx(want, rel=1e-3, abs=1e-9)
    assert m["median_err"] < 1e-3
    assert set(m["inputs_fit"]).isdisjoint(m["inputs_check"])
    assert len(m["inputs_fit"]) == 20 and len(m["inputs_check"]) == 20


def write_csv(path, rows):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=data.COMPARE_COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in data.COMPARE_COLUMNS})


def test_report_puts_the_answer_first(tmp_path):
    rows = (class_rows("smooth", [0.5, 0.45, 0.55], seed=1)
            + class_rows("csg", [0.7, 1.4, 0.9, 1.1], seed=3) + family_rows())
    # cost-model inputs: steps and nodes on every row
    for r in rows:
        r["steps_per_ray"] = "" if r["repr"] == "mesh" else 20
        r["nodes_per_ray"] = 30 if r["repr"] == "mesh" else 1
    path = tmp_path / "compare.csv"
    write_csv(path, rows)
    out = tmp_path / "out"
    report.write_report(path, out, commands="tools/study")
    text = (out / "REPORT.md").read_text()
    first = text.index("## The answer")
    assert first < text.index("## Crossovers") < text.index("## Cost model") < text.index("## Machine and run")
    head = text[:text.index("## Crossovers")]
    assert "**smooth** (3)" in head and "**csg** (4)" in head and "**scan** (1)" in head
    assert "**SDF 2" in head and "within noise" in head
    assert "| run-to-run |" in head and "×/÷1.0" in head
    assert "between 10 and 100 from mesh to sdf" in text
    assert "(family_repeat.png)" in text and "(family_scan.png)" in text
    assert (out / "family_repeat.png").is_file() and (out / "cost_model.png").is_file()
    assert "a: per distance evaluation" in text and "check half" in text
    assert "H1 (class `smooth`, time): ≤ 0.5 px: supports" in text
    assert COMMIT in text
    # the per-input appendix is its own file and uses one replicate
    assert "(appendix-inputs.md)" in text and "## Results per input" not in text
    appendix = (out / "appendix-inputs.md").read_text()
    appendix = appendix[appendix.index("## Results per input (replicate 0)"):]
    assert "### `smooth_in0` (smooth)" in appendix


# ---------------------------------------------------------------------------------------
# tools/gen-scenes


def _gen():
    import importlib.machinery
    import importlib.util

    path = str(report.Path(__file__).resolve().parents[1] / "gen-scenes")
    loader = importlib.machinery.SourceFileLoader("gen_scenes", path)
    spec = importlib.util.spec_from_loader("gen_scenes", loader)
    mod = importlib.util.module_from_spec(spec)
    loader.exec_module(mod)
    return mod


def test_generated_scenes_are_current_and_stems_unique():
    import subprocess
    import sys

    root = report.Path(__file__).resolve().parents[2]
    r = subprocess.run([sys.executable, str(root / "tools" / "gen-scenes"), "--check"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    stems = [p.stem for p in (root / "data" / "scenes").rglob("*.toml")]
    assert len(stems) == len(set(stems)), "two inputs share a file stem (the CSV's input column)"
    classes = {p.parent.name for p in (root / "data" / "scenes").rglob("*.toml")} - {"scenes"}
    for cls in ("blend", "repeat", "fractal", "many", "thin", "cad", "smooth", "csg"):
        assert cls in classes
        assert len(list((root / "data" / "scenes" / cls).glob("*.toml"))) >= 3, cls


def test_menger_cross_arms_reach_past_the_box():
    gen = _gen()
    for level in (1, 2, 3, 4):
        node = gen.menger(level)
        assert node["children"][0]["half_size"] == [1, 1, 1]
        for i, cutter in enumerate(node["children"][1:]):
            if cutter["type"] == "repeat":
                period, count = cutter["period"][0], cutter["count"][0]
                cross = cutter["child"]
            else:
                period, count, cross = 2.0, 1, cutter
            edge = period * (count - 1) / 2  # centre of the outermost copy
            arm = max(cross["children"][0]["half_size"])
            # past the face by a margin, never ending on it
            assert edge + arm > 1 + 1e-3, (level, i)


def test_a_fallback_row_is_never_the_mesh_sides_best(tmp_path):
    """A mesh-asked run that was sphere traced (schema 3: repr `sdf`, asked_repr `mesh`; or
    partly, `sdf+mesh`) is the fastest run meeting the level, yet neither side's best."""
    rows = [
        row("thin_shell", "thin", 0, "analytic", "closed-form", frame=0.5, quality=0.5),
        row("thin_shell", "thin", 0, "sdf", "sphere-trace", tol=0.25, relax=1, frame=4.0, quality=0.5),
        row("thin_shell", "thin", 0, "mesh", "parametric", res=64, frame=2.0, quality=0.5),
    ]
    for repr_, frame in (("sdf", 0.1), ("sdf+mesh", 0.2)):
        r = row("thin_shell", "thin", 0, repr_, "parametric", res=16, frame=frame, quality=0.5)
        r["asked_repr"] = "mesh"
        rows.append(r)
    for r in rows:
        r["schema_version"] = 3
        data.normalize(r)
    assert [data.side(r) for r in rows] == [None, "sdf", "mesh", None, None]
    best = analysis.best_per_run(rows, 0.5, "frame_ms_median")[("thin_shell", "0")]
    assert best["mesh"]["resolution"] == 64 and best["mesh"]["repr"] == "mesh"
    assert best["sdf"]["method"] == "sphere-trace"
    tests = report.hypothesis_tests(rows)["thin_shell"]
    assert all(c is None or c["mesh"]["resolution"] == 64 for _, c in tests)
    # Only the fallbacks meet it on the mesh side: no mesh side at all.
    rows[2]["quality_px"] = ""
    best = analysis.best_per_run(rows, 0.5, "frame_ms_median")[("thin_shell", "0")]
    assert best["mesh"] is None
    assert analysis.compare_sides(rows, 0.5, "frame_ms_median")["only_sdf"] == ["thin_shell"]

    # A schema-2 CSV (no asked_repr column) still loads, asked_repr taken from repr.
    old = [c for c in data.COMPARE_COLUMNS if c != "asked_repr"]
    path = tmp_path / "v2.csv"
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=old)
        w.writeheader()
        for r in rows[:3]:
            w.writerow({c: (2 if c == "schema_version" else r.get(c, "")) for c in old})
    read = data.read_csv(path)
    assert [r["asked_repr"] for r in read] == ["analytic", "sdf", "mesh"]
    assert [data.side(r) for r in read] == [None, "sdf", "mesh"]
    assert data.is_reference(read[0]) and not data.is_reference(read[1])


def test_decimated_meshes_are_mesh_side_candidates_outside_the_resolution_sweep():
    """A scan's decimations (`mesh/decimated-<target>`, no resolution) count for the mesh
    side like the original: the fastest and the smallest mesh runs meeting a level may be
    one; the per-resolution crossover table and the resolution sweep leave them out."""
    ref = "mesh/original"
    rows = [
        row("bunny", "scan", 0, "mesh", "original", frame=3.0, total_bytes=5_000_000, quality=0.5, reference=ref),
        row("bunny", "scan", 0, "mesh", "decimated-25%", frame=2.0, total_bytes=1_300_000, quality=1.0,
            reference=ref),
        row("bunny", "scan", 0, "mesh", "decimated-2%", frame=1.5, total_bytes=100_000, quality=2.0,
            reference=ref),
        row("bunny", "scan", 0, "grid", "sample", res=16, frame=4.0, total_bytes=50_000, quality=2.0, reference=ref),
        row("bunny", "scan", 0, "grid", "sample", res=32, frame=5.0, total_bytes=300_000, quality=1.0,
            reference=ref),
        row("bunny", "scan", 0, "mesh", "from-sample", res=16, frame=2.5, total_bytes=200_000, quality=2.0,
            reference=ref),
        row("bunny", "scan", 0, "mesh", "from-sample", res=32, frame=2.6, total_bytes=800_000, quality=1.0,
            reference=ref),
    ]
    for r in rows:
        r["schema_version"] = 3
        data.normalize(r)
    assert [data.is_decimated(r) for r in rows] == [False, True, True, False, False, False, False]
    assert all(data.side(r) == "mesh" for r in rows if data.is_decimated(r))
    assert data.label(rows[1]) == "mesh/decimated-25%"
    best = analysis.best_per_run(rows, 1.0, "frame_ms_median")[("bunny", "0")]
    assert best["mesh"]["method"] == "decimated-25%"
    smallest = analysis.best_per_run(rows, 2.0, "total_bytes")[("bunny", "0")]
    assert smallest["mesh"]["method"] == "decimated-2%" and smallest["sdf"]["resolution"] == 16
    table, _ = report.crossover(rows)
    assert [t[0] for t in table] == [16, 32]
    assert not any("decimated" in t[1] or "decimated" in t[3] for t in table)
    sweep = [f for f in analysis.families(rows) if f["class"] == "scan"]
    assert sweep and sweep[0]["xs"] == [16, 32]
