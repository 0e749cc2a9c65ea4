"""tools/bench-python's runner: signed distance at BENCH_POINTS points and on a BENCH_GRID^3
grid, ours (the sdfmesh package) against mesh_to_sdf, pysdf, libigl and trimesh, on the same
points on the same machine, interleaved in one run; wall time and sign errors against the
winding-number reference (libigl's fast winding number, its exact winding number where that
is within 0.01 of 1/2), counted on points farther than 1e-4 of the mesh's size from it.
Writes reports/bench/python.csv and python.txt."""

import csv
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

import sdfmesh

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "meshes"
MESHES = {"bunny": "stanford-bunny.obj", "armadillo": "armadillo.obj"}
N = int(os.environ.get("BENCH_POINTS", 1_000_000))
GRID = int(os.environ.get("BENCH_GRID", 128))
SLOW = int(os.environ.get("BENCH_SLOW_POINTS", 20_000))
# trimesh's signed_distance holds candidate lists for every point at once: 20000 points on
# the bunny took more than 19 GB (killed by the OOM killer), so it gets fewer.
TRIMESH = int(os.environ.get("BENCH_TRIMESH_POINTS", 2_000))
WANT = os.environ.get("BENCH_MESHES", "bunny,armadillo").split(",")


def peers():
    """name -> (function (v, f, trimesh mesh, points) -> signed distance, negative inside; slow?)."""
    out = {}
    # A fresh Mesh each time: the timing includes building the BVH and winding data.
    out["sdfmesh"] = (lambda m, v, f, tm, q: sdfmesh.signed_distance(sdfmesh.Mesh.from_arrays(v, f), q), False)
    try:
        import pysdf

        # pysdf: positive inside.
        out["pysdf"] = (lambda m, v, f, tm, q: -pysdf.SDF(v, f)(q), False)
    except ImportError as e:
        print(f"bench-python: pysdf unavailable: {e}", file=sys.stderr)
    try:
        import igl

        def igl_sd(m, v, f, tm, q):
            return igl.signed_distance(q, v.astype(np.float64), f.astype(np.int64),
                                       sign_type=igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER)[0]

        out["libigl"] = (igl_sd, False)
    except ImportError as e:
        print(f"bench-python: libigl unavailable: {e}", file=sys.stderr)
    try:
        import trimesh

        # trimesh: positive inside.
        out["trimesh"] = (lambda m, v, f, tm, q: -trimesh.proximity.signed_distance(tm, q), True)
    except ImportError as e:
        print(f"bench-python: trimesh unavailable: {e}", file=sys.stderr)
    try:
        import mesh_to_sdf

        # 'sample' (no OpenGL scan): 1M surface samples, normal-based signs; negative inside.
        out["mesh_to_sdf"] = (
            lambda m, v, f, tm, q: mesh_to_sdf.mesh_to_sdf(
                tm, q, surface_point_method="sample", sign_method="normal", sample_point_count=1_000_000
            ),
            True,
        )
    except Exception as e:  # pyrender may fail to import without OpenGL
        print(f"bench-python: mesh_to_sdf unavailable: {e}", file=sys.stderr)
    return out


def reference_inside(v, f, q):
    import igl

    v, f = v.astype(np.float64), f.astype(np.int64)
    w = igl.fast_winding_number(v, f, q.astype(np.float64))
    near = np.abs(w - 0.5) < 0.01
    if near.any():
        w[near] = igl.winding_number(v, f, q[near].astype(np.float64))
    return w >= 0.5


def main():
    import trimesh

    tools = peers()
    rows = []
    rng = np.random.default_rng(1)
    tasks = os.environ.get("BENCH_TASKS", "points,grid").split(",")
    for key in WANT:
        path = SHARED / MESHES[key]
        if not path.exists():
            print(f"bench-python: {path} not present, skipped", file=sys.stderr)
            continue
        mesh = sdfmesh.load_mesh(path)
        v, f = mesh.vertices, mesh.faces.astype(np.int64)
        tm = trimesh.Trimesh(v, f, process=False)
        lo, hi = v.min(0), v.max(0)
        scale = float((hi - lo).max())
        pad = 0.1 * (hi - lo)
        # Half uniform in the padded box, half near the surface (DeepSDF-like).
        near, _ = sdfmesh.sample_near_surface(mesh, N - N // 2, 0.01 * scale, seed=3)
        q = np.vstack([rng.uniform(lo - pad, hi + pad, size=(N // 2, 3)).astype(np.float32), near])
        g = sdfmesh.mesh_to_grid(mesh, GRID)
        gi = np.stack(np.meshgrid(*[np.arange(s) for s in g.values.shape], indexing="ij"), -1).reshape(-1, 3)
        gq = (np.array(g.origin) + gi * g.voxel_size).astype(np.float32)
        t0 = time.perf_counter()
        inside = reference_inside(v, f, q)
        ginside = reference_inside(v, f, gq)
        ref_time = time.perf_counter() - t0
        unsigned = np.abs(sdfmesh.signed_distance(mesh, q))
        # gq runs k fastest (C order of values[i, j, k]).
        gunsigned = np.abs(g.values.reshape(-1))
        far, gfar = unsigned > 1e-4 * scale, gunsigned > 1e-4 * scale
        print(f"{key}: {len(f)} faces, closed {mesh.is_closed()}, reference in {ref_time:.1f} s", flush=True)
        for task, pts, ins, ok in (("points", q, inside, far), ("grid", gq, ginside, gfar)):
            if task not in tasks:
                continue
            for name, (fn, slow) in tools.items():
                n = len(pts)
                sub = pts
                cap = TRIMESH if name == "trimesh" else SLOW
                if slow and n > cap:
                    idx = rng.choice(n, cap, replace=False)
                    sub = pts[idx]
                else:
                    idx = None
                t0 = time.perf_counter()
                if name == "sdfmesh" and task == "grid":
                    vals = sdfmesh.mesh_to_grid(sdfmesh.Mesh.from_arrays(v, f), GRID).values.reshape(-1)
                else:
                    vals = np.asarray(fn(mesh, v, f, tm, sub), dtype=np.float64)
                wall = time.perf_counter() - t0
                sel = ok if idx is None else ok[idx]
                rins = ins if idx is None else ins[idx]
                wrong = int(np.count_nonzero((vals[sel] < 0) != rins[sel]))
                counted = int(sel.sum())
                scaled = wall * n / len(sub)
                rows.append({
                    "mesh": key, "faces": len(f), "task": task if task == "points" else f"grid{GRID}",
                    "tool": name, "points": n, "points_run": len(sub), "wall_s": round(wall, 4),
                    "wall_s_at_points": round(scaled, 4), "sign_errors": wrong, "signs_counted": counted,
                    "sign_error_rate": f"{wrong / max(counted, 1):.2e}",
                })
                print("  " + ", ".join(f"{k}={v}" for k, v in rows[-1].items()), flush=True)
    out = REPO / "reports" / "bench"
    suffix = os.environ.get("BENCH_SUFFIX", "")
    with open(out / f"python{suffix}.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = [
        "# tools/bench-python: signed distance from Python, one run, interleaved, same points",
        f"# machine: {platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs, "
        f"Python {platform.python_version()}, numpy {np.__version__}",
        f"# {N} points (half uniform in the box padded 10%, half near the surface, sigma 1% of the size); "
        f"grid {GRID}^3 (+2 cells margin); mesh_to_sdf on {SLOW}, trimesh on {TRIMESH} of the points, "
        "time scaled to all (wall_s_at_points)",
        "# sign errors: against libigl's winding number (fast; exact within 0.01 of 1/2), on points "
        "farther than 1e-4 of the mesh's size",
        "",
        f"{'mesh':10} {'task':8} {'tool':12} {'wall s':>9} {'x ours':>8} {'sign errors':>22}",
    ]
    for r in rows:
        ours = next(x for x in rows if x["mesh"] == r["mesh"] and x["task"] == r["task"] and x["tool"] == "sdfmesh")
        lines.append(
            f"{r['mesh']:10} {r['task']:8} {r['tool']:12} {r['wall_s_at_points']:9.3f} "
            f"{r['wall_s_at_points'] / ours['wall_s_at_points']:8.1f} "
            f"{r['sign_errors']:>8} / {r['signs_counted']:<8} ({r['sign_error_rate']})"
        )
    (out / f"python{suffix}.txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
