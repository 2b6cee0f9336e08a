"""Closed boundary surfaces of geometries (trimesh), for viewing and for distance checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.geometry.cube import faces as cube_faces
from meshgen.methods.tfi import tfi
from meshgen.run.atomic import atomic_write, check_output_file

__all__ = ["SURFACE_EXTENSIONS", "boundary_surface", "check_surface_path", "grid_triangles", "write_surface"]

SURFACE_EXTENSIONS = (".stl", ".ply", ".obj", ".off")


def grid_triangles(n: int, flip: bool) -> np.ndarray:
    """Two triangles per cell of an (n+1) x (n+1) node grid (C-order), shape (2 n^2, 3)."""
    index = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = index[:-1, :-1].ravel(), index[1:, :-1].ravel()
    c, d = index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    triangles = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return triangles[:, ::-1] if flip else triangles


def boundary_surface(geometry, resolution: int = 64):
    """3D: the watertight triangulated image of the unit cube's surface, ``resolution`` cells per
    face edge, outward normals. 2D: the TFI-filled domain triangulated in the plane z = 0."""
    import trimesh

    n = int(resolution)
    t = np.arange(n + 1)
    u, v = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
    if geometry.dim == 2:
        X = tfi(geometry, (n, n)).reshape(-1, 2)
        vertices = np.column_stack([X, np.zeros(len(X))])
        return trimesh.Trimesh(vertices, grid_triangles(n, flip=False), process=False)
    lattice, faces = [], []
    for face in cube_faces(3):
        axis = face.axis
        b, c = (axis + 1) % 3, (axis + 2) % 3  # cyclic, so that side 1 faces outward unflipped
        nodes = np.empty((len(u), 3), dtype=np.int64)
        nodes[:, axis], nodes[:, b], nodes[:, c] = face.side * n, u, v
        faces.append(grid_triangles(n, flip=face.side == 0) + sum(len(x) for x in lattice))
        lattice.append(nodes)
    lattice = np.concatenate(lattice)
    # Faces share their edge nodes: merge them by integer lattice position, so the surface is closed.
    unique, inverse = np.unique(lattice, axis=0, return_inverse=True)
    vertices = geometry.boundary(unique / n)
    surface = trimesh.Trimesh(vertices, inverse.reshape(-1)[np.concatenate(faces)], process=False)
    if surface.volume < 0:
        surface.invert()
    return surface


def check_surface_path(path) -> Path:
    """Validate a surface output path before any work: known extension, an existing writable
    folder, not a folder itself. Returns it as a Path."""
    path = Path(path)
    if path.suffix.lower() not in SURFACE_EXTENSIONS:
        raise MeshgenError(f"unknown surface extension {path.suffix or '(none)'}; pick one of {', '.join(SURFACE_EXTENSIONS)}")
    return check_output_file(path, "surface" + SURFACE_EXTENSIONS[0])


def write_surface(geometry, path, resolution: int = 64):
    """Write ``boundary_surface`` to ``path`` (STL, PLY, OBJ or OFF by extension), atomically."""
    path = check_surface_path(path)
    surface = boundary_surface(geometry, resolution)
    with atomic_write(path) as temporary:
        surface.export(temporary, file_type=path.suffix.lower().lstrip("."))
    return path, surface
