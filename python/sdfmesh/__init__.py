"""sdfmesh: exact signed distances, winding numbers, SDF grids, surface extraction and
rendering of triangle meshes, from numpy. A thin layer over the sdfmesh Rust library
(its ``_sdfmesh`` extension); the work runs without the GIL, in parallel.

Example::

    import numpy as np, sdfmesh
    mesh = sdfmesh.load_mesh("bunny.obj")
    sdf = sdfmesh.signed_distance(mesh, np.random.rand(1_000_000, 3).astype(np.float32))
    grid = sdfmesh.mesh_to_grid(mesh, 128); grid.save("bunny.npy")
    back = sdfmesh.extract(grid, method="dc")
"""

from ._sdfmesh import (
    Grid,
    Mesh,
    closest_points,
    compare,
    extract,
    load_mesh,
    mesh_to_grid,
    render,
    sample_near_surface,
    signed_distance,
    winding_number,
)

__all__ = [
    "Grid",
    "Mesh",
    "closest_points",
    "compare",
    "extract",
    "load_mesh",
    "mesh_to_grid",
    "render",
    "sample_near_surface",
    "signed_distance",
    "winding_number",
]
