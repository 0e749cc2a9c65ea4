"""Shared meshes for the sdfmesh package tests: generated (closed, open, soup) and, where
present, the real meshes under ../shared/meshes."""

import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("SDFMESH_SHARED", REPO.parent / "shared")) / "meshes"


def icosphere(subdiv=2):
    """A closed, outward-oriented unit icosphere (vertices float64, faces int64)."""
    t = (1 + 5**0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
         (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdiv):
        cache, nf = {}, []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = nf
    return np.array(verts), np.array(f, dtype=np.int64)


def sphere_open():
    """The icosphere with the faces of its top cap (z > 0.7) removed: one hole."""
    v, f = icosphere(3)
    keep = v[f].mean(axis=1)[:, 2] < 0.7
    return v, f[keep]


def sphere_soup():
    """The icosphere with every face's corners duplicated (no shared vertices)."""
    v, f = icosphere(2)
    return v[f].reshape(-1, 3), np.arange(f.size, dtype=np.int64).reshape(-1, 3)


GENERATED = {"closed": icosphere, "open": sphere_open, "soup": sphere_soup}


def shared_mesh(name):
    p = SHARED / name
    if not p.exists():
        pytest.skip(f"{p} not present")
    return p


@pytest.fixture(params=sorted(GENERATED))
def generated(request):
    v, f = GENERATED[request.param]()
    return request.param, v, f
