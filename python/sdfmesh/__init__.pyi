"""Type stubs of the sdfmesh package (the extension module sdfmesh._sdfmesh)."""

import os
from typing import Any, Literal, Sequence

import numpy as np
import numpy.typing as npt

_Path = str | os.PathLike[str]
_Points = npt.NDArray[np.float32] | npt.NDArray[np.float64]

class Mesh:
    """A triangle mesh (float32 vertices, uint32 faces); immutable. The search structures
    are built on the first query and reused."""

    @staticmethod
    def from_arrays(vertices: _Points, faces: npt.NDArray[np.integer[Any]]) -> Mesh:
        """Vertices (V, 3) float32/float64, faces (F, 3) integer, counter-clockwise seen
        from outside. Degenerate faces are dropped (face ids still index `faces`).
        Raises ValueError for a wrong dtype or shape, non-finite coordinates, out-of-range
        (negative, too large) indices, empty arrays."""
    @property
    def vertices(self) -> npt.NDArray[np.float32]:
        """(V, 3), a copy."""
    @property
    def faces(self) -> npt.NDArray[np.uint32]:
        """(F, 3), a copy (degenerate faces dropped)."""
    @property
    def bounds(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(min, max) corners of the bounding box."""
    def is_closed(self) -> bool:
        """Whether every edge is shared by exactly two consistently oriented faces."""
    def save(self, path: _Path) -> None:
        """Writes .obj, .ply, .glb or .stl (by the extension), atomically."""
    def __len__(self) -> int:
        """Number of faces."""

class Grid:
    """A signed distance grid: values[i, j, k] is the distance at origin + (i, j, k) *
    voxel_size."""

    def __init__(
        self, values: npt.NDArray[np.float32], origin: Sequence[float], voxel_size: float
    ) -> None:
        """From a float32 (nx, ny, nz) array (copied), each axis >= 2, no NaN."""
    @property
    def values(self) -> npt.NDArray[np.float32]:
        """(nx, ny, nz), Fortran order; the grid's own storage (no copy)."""
    @property
    def origin(self) -> tuple[float, float, float]: ...
    @property
    def voxel_size(self) -> float: ...
    @property
    def shape(self) -> list[int]: ...
    def save(self, path: _Path) -> None:
        """Writes .sdf, .npy or .vti as `toolkit convert` does, atomically."""

def load_mesh(path: _Path) -> Mesh:
    """Loads OBJ, glTF/GLB, PLY or STL (vertices welded, degenerate faces dropped).
    OSError when the file cannot be read, ValueError naming file:line for bad content."""

def signed_distance(mesh: Mesh, points: _Points) -> npt.NDArray[np.float32]:
    """(N,) exact distance to the nearest face, negative where the generalized winding
    number is >= 1/2 (open meshes and soups included)."""

def closest_points(
    mesh: Mesh, points: _Points
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.int64]]:
    """(closest points (N, 3), distances (N,), face indices (N,))."""

def winding_number(mesh: Mesh, points: _Points, exact: bool = False) -> npt.NDArray[np.float32]:
    """(N,) generalized winding number; fast (about 1e-3, refined near 1/2) or exact."""

def mesh_to_grid(
    mesh: Mesh,
    resolution: int,
    band: int | None = None,
    fill: Literal["sample", "voxelize"] = "sample",
    margin: int = 2,
) -> Grid:
    """`resolution` cells along the longest axis of the bounding box plus `margin` cells
    per side; `band=K` truncates values to +-K voxels."""

def sample_near_surface(
    mesh: Mesh, n: int, sigma: float, uniform: float = 0.0, seed: int = 0
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """DeepSDF recipe: surface points moved by N(0, sigma^2) (half) and N(0, sigma^2/10)
    (half), a fraction `uniform` uniform in the padded box; (points (n, 3), sdf (n,))."""

def extract(
    source: Grid | _Path,
    method: Literal["mc", "mt", "dc"] = "mc",
    resolution: int | None = None,
) -> Mesh:
    """Zero level set of a Grid (trilinear) or of a scene file's bounded SDF objects."""

def render(
    scene: _Path,
    repr: str = "analytic",
    res: int = 64,
    width: int | None = None,
    height: int | None = None,
    depth: int | None = None,
    args: Sequence[str] | None = None,
) -> npt.NDArray[np.uint8]:
    """`toolkit render` into a (height, width, 3) uint8 image."""

def compare(
    inputs: Sequence[_Path],
    csv: _Path | None = None,
    res: Sequence[int] | None = None,
    frames: int | None = None,
    args: Sequence[str] | None = None,
) -> list[dict[str, Any]]:
    """`toolkit compare`; one dict per CSV row."""
