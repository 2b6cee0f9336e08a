"""``meshgen geometries show FILE -o faces.vtu``: the boundary surface with the cube face of each
triangle, to look at a face assignment (ParaView: colour by ``cube_face``) before meshing."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from meshgen.geometry import cube
from meshgen.geometry.blocks import BlockSet
from meshgen.geometry.patches import geometry_patches
from meshgen.geometry.set_surface import block_set_surface
from meshgen.geometry.surface import boundary_surface
from meshgen.run.atomic import atomic_write, check_output_file

__all__ = ["face_surface", "write_face_surface"]


def face_surface(geometry, resolution: int = 32) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (n, 3), triangles (m, 3), cube face index (m,) in ``meshgen.geometry.cube.faces`` order):
    a triangulated surface's own triangles when the geometry is one, else the boundary map
    sampled ``resolution`` cells per face side."""
    own = getattr(geometry.boundary_map, "surface_faces", None)
    if own is not None:
        return own
    surface = boundary_surface(geometry, resolution)
    per_face = 2 * int(resolution) ** 2  # boundary_surface: the faces in cube order, 2 n^2 triangles each
    return np.asarray(surface.vertices), np.asarray(surface.faces), np.repeat(np.arange(6), per_face)


def write_face_surface(geometry, path, resolution: int = 32) -> tuple[Path, int]:
    """Write ``face_surface`` as VTU with cell arrays ``cube_face`` (0..5: xi0, xi1, eta0, eta1,
    zeta0, zeta1) and ``patch`` (the index of the face's patch in the geometry's patch list),
    atomically; of a block set (``meshgen.geometry.blocks.BlockSet``) its patch faces with
    ``block`` too (``meshgen.geometry.set_surface.block_set_surface``). Returns the path and the
    triangle count."""
    import meshio

    path = check_output_file(path, "faces.vtu")
    if isinstance(geometry, BlockSet):  # the blocks' patch faces: which block, face and patch each triangle is
        points, triangles, block, face, patch = block_set_surface(geometry, resolution)
        data = {"block": [block.astype(np.int32)], "cube_face": [face.astype(np.int32)], "patch": [patch.astype(np.int32)]}
        with atomic_write(path, what="surface ") as temporary:
            meshio.Mesh(points, [("triangle", triangles)], cell_data=data).write(temporary, file_format="vtu")
        return path, len(triangles)
    points, triangles, face = face_surface(geometry, resolution)
    patch_of_face = np.zeros(6, dtype=np.int64)
    for index, patch in enumerate(geometry_patches(geometry)):
        for name in patch.faces:
            patch_of_face[cube.face_names(3).index(name)] = index
    mesh = meshio.Mesh(
        points,
        [("triangle", triangles)],
        cell_data={"cube_face": [face.astype(np.int32)], "patch": [patch_of_face[face].astype(np.int32)]},
    )
    with atomic_write(path, what="surface ") as temporary:
        mesh.write(temporary, file_format="vtu")
    return path, len(triangles)
