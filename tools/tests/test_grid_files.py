"""Grid files written by `toolkit convert --to grid` reopen in pyvista and NumPy with the
same values: the `.vti` point data, the `.npy` array and the `.sdf` samples agree exactly,
the `.vti` origin, spacing and dimensions equal the `.sdf` header, and the values are the
signed distances of the shape (checked against the exact distance of a sphere).

The toolkit binary comes from the `toolkit` fixture in conftest.py.
"""

import math
import struct
import subprocess
from pathlib import Path

import numpy as np
import pyvista as pv


def icosphere_obj(path: Path, radius: float, subdivisions: int) -> None:
    """A geodesic sphere (vertices on the sphere) written as OBJ."""
    t = (1 + 5 ** 0.5) / 2
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
             (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = [np.array(v, float) / np.linalg.norm(v) for v in verts]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    with open(path, "w") as f:
        for v in verts:
            f.write("v {:.9f} {:.9f} {:.9f}\n".format(*(radius * v)))
        for a, b, c in faces:
            f.write(f"f {a + 1} {b + 1} {c + 1}\n")


def read_sdf(path: Path):
    data = path.read_bytes()
    magic, version = data[:8], struct.unpack_from("<I", data, 8)[0]
    assert magic == b"SDFGRID\0" and version == 1
    dims = struct.unpack_from("<3I", data, 12)
    origin = struct.unpack_from("<3f", data, 24)
    voxel = struct.unpack_from("<f", data, 36)[0]
    n = dims[0] * dims[1] * dims[2]
    assert len(data) == 44 + 4 * n
    values = np.frombuffer(data, dtype="<f4", offset=44, count=n)
    return dims, origin, voxel, values


def test_vti_npy_and_sdf_agree_and_hold_the_sphere_distance(toolkit, tmp_path):
    radius = 0.8
    obj = tmp_path / "sphere.obj"
    icosphere_obj(obj, radius, 4)  # 5120 triangles; chord error 0.8 * 4.8e-4
    for ext in ("vti", "npy", "sdf"):
        r = subprocess.run([str(toolkit), "convert", str(obj), "--to", "grid", "--res", "20",
                            "-o", str(tmp_path / f"sphere.{ext}")], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr

    dims, origin, voxel, sdf_values = read_sdf(tmp_path / "sphere.sdf")
    npy = np.load(tmp_path / "sphere.npy")
    assert npy.dtype == np.float32 and npy.shape == (dims[2], dims[1], dims[0])

    grid = pv.read(str(tmp_path / "sphere.vti"))
    assert isinstance(grid, pv.ImageData)
    assert tuple(grid.dimensions) == tuple(dims)
    # The .vti header holds the same f32 values (as decimal text).
    np.testing.assert_array_equal(np.float32(grid.origin), np.float32(origin))
    np.testing.assert_array_equal(np.float32(grid.spacing), np.float32((voxel,) * 3))
    vti_values = np.asarray(grid.point_data["sdf"])
    assert vti_values.dtype == np.float32
    # Bit-identical in all three files, in the same x-fastest order.
    np.testing.assert_array_equal(vti_values, sdf_values)
    np.testing.assert_array_equal(npy.ravel(), sdf_values)

    # pyvista's own point coordinates give the exact sphere distance at each sample; the
    # inscribed icosphere is within 0.8 * 4.8e-4 of the sphere, f32 adds ~1e-7.
    exact = np.linalg.norm(np.asarray(grid.points), axis=1) - radius
    err = np.abs(vti_values - exact)
    assert err.max() < 1e-3, err.max()
    assert (np.sign(vti_values[np.abs(exact) > 1e-3]) == np.sign(exact[np.abs(exact) > 1e-3])).all()
    # The zero contour pyvista extracts is the sphere.
    surface = grid.contour([0.0], scalars="sdf")
    r = np.linalg.norm(np.asarray(surface.points), axis=1)
    assert surface.n_points > 100
    assert abs(r.mean() - radius) < 0.01 * radius and r.std() < 0.01 * radius
    assert math.isclose(voxel, 1.6 / 20, rel_tol=1e-5)
