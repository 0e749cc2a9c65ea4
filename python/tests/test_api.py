"""The sdfmesh module's API: grids, sampling, extraction, rendering, compare, file I/O,
and the refusal of malformed arrays (ValueError, never a crash)."""

from pathlib import Path

import numpy as np
import pytest

import sdfmesh
from conftest import GENERATED, REPO

DATA = REPO / "data"


@pytest.fixture(scope="module")
def sphere():
    v, f = GENERATED["closed"]()
    return sdfmesh.Mesh.from_arrays(v, f)


def test_sphere_distances(sphere):
    q = np.array([[0, 0, 0], [2, 0, 0], [0, 0.5, 0], [0, 0, -3]], np.float32)
    d = sdfmesh.signed_distance(sphere, q)
    # An icosphere (level 2) lies within 2% inside the unit sphere.
    assert np.allclose(d, [-1, 1, -0.5, 2], atol=0.02)
    assert sphere.is_closed()
    assert sdfmesh.signed_distance(sphere, np.zeros((0, 3))).shape == (0,)


def test_load_mesh_and_save_roundtrip(tmp_path, sphere):
    p = tmp_path / "s.obj"
    sphere.save(p)
    m = sdfmesh.load_mesh(p)
    assert m.vertices.shape == sphere.vertices.shape and m.faces.shape == sphere.faces.shape
    assert m.vertices.dtype == np.float32 and m.faces.dtype == np.uint32
    with pytest.raises(OSError, match="nothere.obj"):
        sdfmesh.load_mesh(tmp_path / "nothere.obj")
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 7\n")
    with pytest.raises(ValueError, match=r"bad\.obj:3"):
        sdfmesh.load_mesh(bad)


def test_mesh_to_grid_values_and_save(tmp_path, sphere):
    g = sdfmesh.mesh_to_grid(sphere, 32)
    nx, ny, nz = g.values.shape
    assert g.values.dtype == np.float32 and g.values.flags.f_contiguous
    o, h = np.array(g.origin), g.voxel_size
    # values[i, j, k] is the distance at origin + (i, j, k) h.
    idx = np.array([[0, 0, 0], [nx // 2, ny // 2, nz // 2], [3, 5, 7]])
    at = (o + idx * h).astype(np.float32)
    assert np.allclose(g.values[tuple(idx.T)], sdfmesh.signed_distance(sphere, at), atol=1e-6)
    for ext in ("npy", "sdf", "vti"):
        g.save(tmp_path / f"g.{ext}")
        assert (tmp_path / f"g.{ext}").stat().st_size > nx * ny * nz * 4
    # The .npy file is the grid numpy reads back (z, y, x order as the toolkit writes it).
    back = np.load(tmp_path / "g.npy")
    assert back.size == g.values.size
    t = sdfmesh.mesh_to_grid(sphere, 32, band=2)
    assert np.abs(t.values).max() <= 2 * t.voxel_size + 1e-6
    v = sdfmesh.mesh_to_grid(sphere, 32, fill="voxelize")
    assert np.mean(np.abs(v.values - g.values)) < 2 * g.voxel_size
    with pytest.raises(ValueError, match="fill"):
        sdfmesh.mesh_to_grid(sphere, 32, fill="nope")
    with pytest.raises(ValueError, match="resolution"):
        sdfmesh.mesh_to_grid(sphere, 0)


def test_sample_near_surface(sphere):
    p, d = sdfmesh.sample_near_surface(sphere, 20000, 0.05, seed=7)
    assert p.shape == (20000, 3) and d.shape == (20000,)
    r = np.linalg.norm(p, axis=1)
    assert abs(np.std(r - 1) - np.sqrt((0.05**2 + 0.005**2) / 2)) < 0.01
    assert np.allclose(d, sdfmesh.signed_distance(sphere, p))
    p2, _ = sdfmesh.sample_near_surface(sphere, 20000, 0.05, seed=7)
    assert np.array_equal(p, p2)
    assert (d < 0).mean() > 0.3 and (d > 0).mean() > 0.3


@pytest.mark.parametrize("method", ["mc", "mt", "dc"])
def test_extract_grid_roundtrip(sphere, method):
    g = sdfmesh.mesh_to_grid(sphere, 32)
    m = sdfmesh.extract(g, method=method)
    assert m.is_closed() and len(m) > 500
    # Its vertices lie on the sphere's surface to within a voxel.
    d = sdfmesh.signed_distance(sphere, m.vertices)
    assert np.abs(d).max() < g.voxel_size


def test_extract_scene_and_grid_constructor():
    scene = DATA / "scenes" / "showcase.toml"
    m = sdfmesh.extract(str(scene), method="mc", resolution=32)
    assert len(m) > 100
    x = np.linspace(-1, 1, 21, dtype=np.float32)
    vals = np.sqrt(x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2) - 0.6
    g = sdfmesh.Grid(vals.astype(np.float32), (-1, -1, -1), 0.1)
    s = sdfmesh.extract(g, method="dc")
    r = np.linalg.norm(s.vertices, axis=1)
    assert np.abs(r - 0.6).max() < 0.05
    with pytest.raises(ValueError, match="method"):
        sdfmesh.extract(g, method="xx")
    with pytest.raises(ValueError, match="no zero crossing"):
        sdfmesh.extract(sdfmesh.Grid(np.ones((4, 4, 4), np.float32), (0, 0, 0), 1.0))


def test_render_and_compare(tmp_path):
    scene = DATA / "scenes" / "coursework_primitives.toml"
    img = sdfmesh.render(scene, repr="sdf", width=48, height=32)
    assert img.shape == (32, 48, 3) and img.dtype == np.uint8 and img.std() > 1
    mesh_img = sdfmesh.render(scene, repr="mesh", res=16, width=48, height=32)
    assert np.mean(np.abs(mesh_img.astype(int) - img.astype(int))) < 40
    with pytest.raises(ValueError, match="repr"):
        sdfmesh.render(scene, repr="bogus")
    with pytest.raises(ValueError, match="width"):
        sdfmesh.render(scene, width=0)
    rows = sdfmesh.compare([scene], res=[16], frames=1, args=["--width", "32", "--height", "24", "--quiet", "--no-decimate",
                                                  "--sdf-tolerance-px", "1", "--sdf-relax", "1"])
    assert rows and {"input", "repr"} <= set(rows[0])
    assert {r["input"] for r in rows} == {"coursework_primitives"}


BAD_POINTS = [
    ("list", [[0.0, 0.0, 0.0]], "numpy array"),
    ("int dtype", np.zeros((4, 3), np.int64), "float32 or float64"),
    ("shape (N, 2)", np.zeros((4, 2), np.float32), r"shape \(4, 2\)"),
    ("1-d", np.zeros(3, np.float32), r"shape \(3,\)"),
    ("3-d", np.zeros((2, 3, 3), np.float32), "shape"),
    ("NaN", np.array([[0, 0, 0], [0, np.nan, 0]], np.float32), r"points\[1, 1\] is NaN"),
    ("inf", np.array([[np.inf, 0, 0]], np.float64), "finite"),
    ("huge f64", np.array([[1e300, 0, 0]], np.float64), "float32"),
    ("complex", np.zeros((2, 3), np.complex64), "float32 or float64"),
    ("object", np.array([[None, 1, 2]], dtype=object), "float32 or float64"),
]


@pytest.mark.parametrize("what,value,match", BAD_POINTS, ids=[b[0] for b in BAD_POINTS])
@pytest.mark.parametrize("fn", ["signed_distance", "closest_points", "winding_number"])
def test_bad_points_are_refused(sphere, fn, what, value, match):
    with pytest.raises(ValueError, match=match):
        getattr(sdfmesh, fn)(sphere, value)


def test_non_contiguous_views_are_read_correctly(sphere):
    q = np.random.default_rng(0).normal(size=(200, 6)).astype(np.float32)
    view = q[::2, ::2]  # strided in both axes
    assert not view.flags.c_contiguous
    assert np.array_equal(sdfmesh.signed_distance(sphere, view),
                          sdfmesh.signed_distance(sphere, np.ascontiguousarray(view)))
    rev = q[::-1, 2:5]
    assert np.array_equal(sdfmesh.signed_distance(sphere, rev),
                          sdfmesh.signed_distance(sphere, np.ascontiguousarray(rev)))


BAD_FACES = [
    ("negative", np.array([[0, 1, -1]]), r"faces\[0, 2\] = -1 is out of range"),
    ("huge", np.array([[0, 1, 2**40]]), "out of range"),
    ("uint64 max", np.array([[0, 1, 2**64 - 1]], np.uint64), "out of range"),
    ("too large", np.array([[0, 1, 3]]), "out of range \\(3 vertices\\)"),
    ("float", np.array([[0.0, 1.0, 2.0]]), "integer"),
    ("shape", np.array([0, 1, 2]), "shape"),
    ("empty", np.zeros((0, 3), np.int64), "empty"),
    ("degenerate", np.array([[0, 0, 1]]), "degenerate"),
]


@pytest.mark.parametrize("what,faces,match", BAD_FACES, ids=[b[0] for b in BAD_FACES])
def test_bad_faces_are_refused(what, faces, match):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    with pytest.raises(ValueError, match=match):
        sdfmesh.Mesh.from_arrays(v, faces)


@pytest.mark.parametrize("vertices,match", [
    (np.zeros((0, 3), np.float32), "empty"),
    (np.array([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]]), r"vertices\[0, 2\] is NaN"),
    (np.zeros((3, 4), np.float32), "shape"),
])
def test_bad_vertices_are_refused(vertices, match):
    with pytest.raises(ValueError, match=match):
        sdfmesh.Mesh.from_arrays(vertices, np.array([[0, 1, 2]]))


def test_bad_grid_arrays_are_refused():
    with pytest.raises(ValueError, match="float32"):
        sdfmesh.Grid(np.zeros((4, 4, 4)), (0, 0, 0), 1.0)
    with pytest.raises(ValueError, match="at least 2"):
        sdfmesh.Grid(np.zeros((1, 4, 4), np.float32), (0, 0, 0), 1.0)
    with pytest.raises(ValueError, match="voxel_size"):
        sdfmesh.Grid(np.zeros((4, 4, 4), np.float32), (0, 0, 0), -1.0)
    nan = np.zeros((4, 4, 4), np.float32)
    nan[1, 2, 3] = np.nan
    with pytest.raises(ValueError, match=r"values\[1, 2, 3\] is NaN"):
        sdfmesh.Grid(nan, (0, 0, 0), 1.0)
    with pytest.raises(ValueError, match="Grid or a scene"):
        sdfmesh.extract(42)
