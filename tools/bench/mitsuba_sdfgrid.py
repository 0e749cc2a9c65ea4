"""Side-by-side benchmark: Mitsuba 3's `sdfgrid` shape against sdfmesh's grid tracer.

Run by tools/bench-mitsuba (which installs Mitsuba into its own venv). Loads one of our
`.sdf` grids (written by `toolkit convert --to grid`) into Mitsuba as an `sdfgrid` shape
(the samples as a (z, y, x, 1) tensor over the unit cube, placed by `to_world`: sample
(0, 0, 0) at the grid origin, the last sample at origin + (dims - 1) * voxel, as our
samples sit at cell corners like Mitsuba's), shoots our camera's exact primary rays
(pinhole, vertical field of view, through pixel centres, image x along up x forward as in
src/scene/camera.rs) through `Scene.ray_intersect` (closest hit plus surface interaction:
position, geometric and smooth shading normal) and through the `depth` integrator at 1 spp,
and times both after a warm-up that JIT-compiles the kernels (the compile is reported
separately). Ours: `toolkit render` of a scene that places the same grid file under the
same camera with one ambient light and no reflection (camera rays only), one frame per
process, interleaved with Mitsuba's timed calls. Prints a report and compares the hit masks pixel by pixel.
"""

import argparse
import atexit
import os
import re
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile
import time

import numpy as np


# Untimed calls before the timed runs (the first compiles the kernel).
WARMUP = 3


def KINDS(intersect, preliminary, render):
    """The Mitsuba measurements, in report order."""
    return (
        ("ray_intersect", intersect),
        ("ray_intersect_preliminary", preliminary),
        ("render depth 1spp", render),
    )


def read_sdf(path):
    """Our `.sdf` format (src/grid/io.rs): 44-byte header, f32 samples x fastest."""
    with open(path, "rb") as f:
        head = f.read(44)
        magic, version = head[:8], struct.unpack("<I", head[8:12])[0]
        if magic != b"SDFGRID\0" or version != 1:
            raise SystemExit(f"{path}: not a version-1 .sdf grid")
        dims = struct.unpack("<3I", head[12:24])
        origin = struct.unpack("<3f", head[24:36])
        voxel = struct.unpack("<f", head[36:40])[0]
        data = np.fromfile(f, dtype="<f4")
    nx, ny, nz = dims
    if data.size != nx * ny * nz:
        raise SystemExit(f"{path}: {data.size} samples, expected {nx * ny * nz}")
    return data.reshape(nz, ny, nx), np.array(origin, np.float64), float(voxel)


def read_png_rgb(path):
    """The toolkit's PNG as an (h, w, 3) uint8 array (Pillow, installed with Mitsuba)."""
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def pad_to_cube(samples, voxel):
    """Pads (z, y, x) samples to n^3 at the upper ends: edge value + distance from the edge."""
    n = max(samples.shape)
    out = samples
    for axis in range(3):
        have = out.shape[axis]
        if have == n:
            continue
        edge = np.take(out, [have - 1], axis=axis)
        steps = np.arange(1, n - have + 1, dtype=np.float32) * voxel
        shape = [1, 1, 1]
        shape[axis] = n - have
        out = np.concatenate([out, edge + steps.reshape(shape)], axis=axis)
    return np.ascontiguousarray(out, dtype=np.float32)


def camera_rays(pos, look_at, fov_deg, w, h):
    """Our RayGenerator (src/scene/camera.rs): unit directions through pixel centres."""
    forward = look_at - pos
    forward /= np.linalg.norm(forward)
    right = np.cross([0.0, 1.0, 0.0], forward)
    right /= np.linalg.norm(right)
    up = np.cross(forward, right)
    half_h = np.tan(np.radians(fov_deg) * 0.5)
    half_w = half_h * w / h
    xs = (2.0 * (np.arange(w) + 0.5) / w - 1.0) * half_w
    ys = (1.0 - 2.0 * (np.arange(h) + 0.5) / h) * half_h
    u, v = np.meshgrid(xs, ys)  # row-major: index = y * w + x
    d = forward[None, None, :] + right[None, None, :] * u[..., None] + up[None, None, :] * v[..., None]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return d.reshape(-1, 3).astype(np.float32)


def median(xs):
    return statistics.median(xs)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("grid", help="our .sdf grid file")
    ap.add_argument("--toolkit", default="target/release/toolkit")
    ap.add_argument("--size", default="1000x1000")
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    args = ap.parse_args()
    w, h = (int(s) for s in args.size.split("x"))
    threads = [int(t) for t in args.threads.split(",")]

    samples, origin, voxel = read_sdf(args.grid)
    dims = samples.shape[::-1]
    # Mitsuba 3.9.1's sdfgrid misses every ray when the sample counts along x and z differ
    # (checked on a sphere grid: 32x32x32 and 32x40x32 hit, 40x32x32 and 32x32x40 miss), so
    # the grid is padded to a cube at its upper ends with the edge value plus the distance
    # from the edge (all positive: our grids keep a margin of outside cells), which adds no
    # surface; the padding voxels hold no surface, so Mitsuba's per-voxel BVH ignores them.
    samples = pad_to_cube(samples, voxel)
    nz, ny, nx = samples.shape
    extent = (np.array([nx, ny, nz], np.float64) - 1.0) * voxel  # Mitsuba's unit cube
    real = (np.array(dims, np.float64) - 1.0) * voxel  # our grid's box
    centre = origin + real * 0.5
    # Camera: looking at the grid's centre from the front-right and above, the box's
    # diagonal filling about 80% of the vertical field of view.
    fov = 40.0
    diag = float(np.linalg.norm(real))
    dist = 0.6 * diag / np.tan(np.radians(fov) * 0.5)
    dirn = np.array([0.35, 0.3, -1.0])
    dirn /= np.linalg.norm(dirn)
    pos = centre + dirn * dist
    print(
        f"grid {args.grid}: {dims[0]}x{dims[1]}x{dims[2]} samples, voxel {voxel:.6g}, "
        f"origin {origin.round(6).tolist()} (padded to {nx}x{ny}x{nz} for Mitsuba)"
    )
    print(f"camera: position {pos.round(5).tolist()}, look_at {centre.round(5).tolist()}, fov {fov} (vertical), {w}x{h}")

    import drjit as dr
    import mitsuba as mi

    print(f"mitsuba {mi.__version__}, drjit {dr.__version__}, variant {args.variant}")
    mi.set_variant(args.variant)

    # Distances in the unit cube's units (the padded grid is a cube, so the scale is uniform;
    # the intersection only needs the sign changes and normals are normalised anyway).
    grid = mi.TensorXf(np.ascontiguousarray((samples / np.max(extent))[..., None], dtype=np.float32))
    to_world = mi.ScalarTransform4f().translate(origin.tolist()).scale(extent.tolist())
    t0 = time.perf_counter()
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "depth"},
            "sensor": {
                "type": "perspective",
                "fov": fov,
                "fov_axis": "y",
                "to_world": mi.ScalarTransform4f().look_at(
                    origin=pos.tolist(), target=centre.tolist(), up=[0.0, 1.0, 0.0]
                ),
                "film": {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": 1},
            },
            "shape": {"type": "sdfgrid", "grid": grid, "to_world": to_world, "bsdf": {"type": "diffuse"}},
        }
    )
    load_ms = (time.perf_counter() - t0) * 1e3
    print(f"mitsuba scene load (grid upload, voxel boxes, Embree BVH): {load_ms:.1f} ms")

    dirs = camera_rays(pos, centre, fov, w, h)
    n = w * h
    o = mi.Point3f(*[dr.full(mi.Float, float(c), n) for c in pos])
    d = mi.Vector3f(mi.Float(dirs[:, 0]), mi.Float(dirs[:, 1]), mi.Float(dirs[:, 2]))
    ray = mi.Ray3f(o, d)
    dr.eval(ray)
    dr.sync_thread()

    def intersect():
        si = scene.ray_intersect(ray)
        valid = si.is_valid()
        dr.eval(si.t, si.n, si.sh_frame.n, valid)
        dr.sync_thread()
        return si, valid

    def preliminary():
        pi = scene.ray_intersect_preliminary(ray)
        dr.eval(pi.t)
        dr.sync_thread()
        return pi

    def render():
        img = mi.render(scene, spp=1, seed=0)
        dr.eval(img)
        dr.sync_thread()
        return img

    # Ours: the same grid file in a scene, camera rays only (one ambient light, depth 0).
    tmp = tempfile.mkdtemp(prefix="bench-mitsuba-")
    atexit.register(shutil.rmtree, tmp, True)
    scene_path = os.path.join(tmp, "grid.toml")
    with open(scene_path, "w") as f:
        f.write(
            "[camera]\n"
            f"position = [{', '.join(repr(float(c)) for c in pos)}]\n"
            f"look_at = [{', '.join(repr(float(c)) for c in centre)}]\n"
            f"fov = {fov}\nwidth = {w}\nheight = {h}\n\n"
            "[settings]\nmax_depth = 0\nbackground = [0, 0, 0]\n\n"
            '[[lights]]\ntype = "ambient"\nintensity = 1\n\n'
            "[materials.white]\ncolor = [1, 1, 1]\n\n"
            f'[[objects]]\ntype = "grid"\npath = "{os.path.abspath(args.grid)}"\nmaterial = "white"\n'
        )
    png = os.path.join(tmp, "ours.png")
    pat = re.compile(r"frame ([0-9.]+) ms, (\d+) rays \((\d+) shadow\), ([0-9.]+) Mrays/s, ([0-9.]+) march steps/ray")
    describe = ""

    def ours_frame(t):
        """One `toolkit render` process at t threads: (frame ms, rays, shadow rays, steps/ray)."""
        nonlocal describe
        env = dict(os.environ, RAYON_NUM_THREADS=str(t))
        p = subprocess.run([args.toolkit, "render", scene_path, "-o", png], env=env, capture_output=True, text=True)
        if p.returncode != 0:
            raise SystemExit(f"toolkit render failed: {p.stderr.strip()}")
        m = pat.search(p.stdout + p.stderr)
        if not m:
            raise SystemExit(f"no summary line in toolkit output: {p.stdout}{p.stderr}")
        describe = (p.stdout + p.stderr).strip()
        return float(m.group(1)), int(m.group(2)), int(m.group(3)), float(m.group(5))

    def timed(fn):
        t0 = time.perf_counter()
        out = fn()
        return (time.perf_counter() - t0) * 1e3, out

    # Per thread count: Mitsuba's warm-up calls, then interleaved rounds (one toolkit
    # process, then one call of each Mitsuba kind), so that both sides see the same load.
    results = {}
    ours = {}
    for t in threads:
        dr.set_thread_count(t)
        warm = {name: [timed(fn)[0] for _ in range(WARMUP)] for name, fn in KINDS(intersect, preliminary, render)}
        times = {name: [] for name in warm}
        frames = []
        for _ in range(args.runs):
            frames.append(ours_frame(t))
            for name, fn in KINDS(intersect, preliminary, render):
                ms, out = timed(fn)
                times[name].append(ms)
                if name == "ray_intersect":
                    si, valid = out
                    mask_mi = np.array(valid, dtype=bool).reshape(h, w)
                    t_mi = np.array(si.t, dtype=np.float64).reshape(h, w)
        results[t] = {name: (warm[name][0], median(times[name]), times[name], warm[name]) for name in warm}
        ours[t] = frames
    mask_ours = read_png_rgb(png).max(axis=2) > 0

    print()
    print("ours (toolkit render, last run's output):")
    for line in describe.splitlines():
        print(f"  {line}")
    print()
    rays = w * h
    print(f"{w}x{h} = {rays} camera rays; medians of {args.runs} interleaved rounds; ms and Mrays/s")
    print(f"{'threads':>7} {'side':<34} {'first ms':>9} {'median ms':>10} {'Mrays/s':>8} {'ours/them':>9}")
    for t in threads:
        frames = ours[t]
        ours_ms = median([f[0] for f in frames])
        shadow = frames[0][2]
        ours_mr = rays / (ours_ms * 1e3)
        print(f"{t:>7} {'ours: toolkit render (grid)':<34} {'-':>9} {ours_ms:>10.2f} {ours_mr:>8.2f} {'':>9}"
              f"   (frames: {', '.join(f'{f[0]:.1f}' for f in frames)}; {frames[0][1]} rays, {shadow} shadow, "
              f"{frames[0][3]:.2f} march steps/ray)")
        for name, _ in KINDS(None, None, None):
            first, med, times, warm = results[t][name]
            mr = rays / (med * 1e3)
            print(f"{t:>7} {'mitsuba ' + name:<34} {first:>9.1f} {med:>10.2f} {mr:>8.2f} {ours_mr / mr:>8.2f}x"
                  f"   (warm-up: {', '.join(f'{x:.1f}' for x in warm)}; runs: {', '.join(f'{x:.1f}' for x in times)})")
    print(f"first ms: the first of {WARMUP} untimed warm-up calls at that thread count, which traces and")
    print("JIT-compiles the kernels (tools/bench-mitsuba starts with an empty kernel cache; kernels are")
    print("cached, so a later thread count mostly reuses them).")
    print("ray_intersect: closest hit + surface interaction (position, normals); preliminary: closest hit")
    print("distance only; render depth 1spp: the `depth` integrator through Mitsuba's own sensor, sampler")
    print("and film (its rays jittered within the pixel). ours/them: Mitsuba's median ms / ours.")

    both = mask_ours & mask_mi
    differ = int(np.count_nonzero(mask_ours != mask_mi))
    print()
    print(
        f"hit masks: ours {int(mask_ours.sum())} px, mitsuba ray_intersect {int(mask_mi.sum())} px, "
        f"both {int(both.sum())}; silhouette disagreement {differ} px = {100.0 * differ / rays:.3f}% "
        f"(agreement {100.0 - 100.0 * differ / rays:.3f}%)"
    )
    if both.any():
        tv = t_mi[both]
        print(f"mitsuba hit distances on common pixels: {tv.min():.4f} to {tv.max():.4f}")


if __name__ == "__main__":
    sys.exit(main())
