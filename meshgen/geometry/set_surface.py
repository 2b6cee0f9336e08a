"""The boundary surface of a block set (``meshgen.geometry.blocks``), for ``meshgen geometries
show``: its patch faces sampled and triangulated, closed across the blocks."""

from __future__ import annotations

import dataclasses

import numpy as np

from meshgen.geometry import cube
from meshgen.geometry.block_nodes import global_numbering, merged_mesh
from meshgen.geometry.blocks import BlockSet, tfi_blocks
from meshgen.geometry.surface import check_surface_path, grid_triangles
from meshgen.run.atomic import atomic_write

__all__ = ["block_set_surface", "write_block_set_surface"]


def block_set_surface(block_set: BlockSet, resolution: int = 64):
    """The boundary of ``block_set`` sampled ``resolution`` cells per block edge: (vertices (N, 3),
    triangles (T, 3), block (T,), cube face (T,) in ``meshgen.geometry.cube.faces`` order, patch
    (T,) the index of its patch name in the order first met). 3D: the blocks' patch faces
    (interfaces left out), outward normals on right-handed blocks, nodes shared across blocks
    merged by the block set's numbering, so the surface is closed. 2D: the TFI-filled blocks
    triangulated in the plane z = 0 (block: each triangle's block; face and patch -1)."""
    n = int(resolution)
    uniform = tuple(tuple(np.linspace(0.0, 1.0, n + 1) for _ in range(block_set.dim)) for _ in block_set.names)
    sampled = dataclasses.replace(block_set, coords=uniform)  # every block n cells a side: interfaces still match
    if block_set.dim == 2:
        points, quads, owner = merged_mesh(sampled, tfi_blocks(sampled))
        triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        none = np.full(len(triangles), -1)
        return np.column_stack([points, np.zeros(len(points))]), triangles, np.tile(owner, 2), none, none
    numbering, count = global_numbering(sampled)
    vertices = np.full((count, 3), np.nan)
    names, parts = [], []
    for (block, face_name), (patch, _) in sampled.patches.items():
        face = cube.face_named(face_name, 3)
        ids = numbering[block][face.node_index]
        vertices[ids.reshape(-1)] = sampled.geometries[block].boundary(face.points(sampled.coords[block]))
        natural = -1 if face.axis == 1 else 1  # the normal of the face's (first, second) tangent axes, along its axis
        triangles = ids.reshape(-1)[grid_triangles(n, flip=natural != (1 if face.side else -1))]
        if patch not in names:
            names.append(patch)
        labels = (block, cube.face_names(3).index(face_name), names.index(patch))
        parts.append((triangles, *(np.full(len(triangles), label) for label in labels)))
    triangles, block, face, patch = (np.concatenate(column) for column in zip(*parts))
    used, triangles = np.unique(triangles, return_inverse=True)
    return vertices[used], triangles.reshape(-1, 3), block, face, patch


def write_block_set_surface(block_set: BlockSet, path, resolution: int = 64):
    """Write :func:`block_set_surface` as a triangulated surface (STL, PLY, OBJ or OFF by
    extension), atomically. Returns the path and the ``trimesh.Trimesh`` (3D: its volume
    positive)."""
    import trimesh

    path = check_surface_path(path)
    vertices, triangles = block_set_surface(block_set, resolution)[:2]
    surface = trimesh.Trimesh(vertices, triangles, process=False)
    if block_set.dim == 3 and surface.volume < 0:
        surface.invert()
    with atomic_write(path) as temporary:
        surface.export(temporary, file_type=path.suffix.lower().lstrip("."))
    return path, surface
