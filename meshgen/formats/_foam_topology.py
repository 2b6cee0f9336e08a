"""The topology of a structured grid's OpenFOAM polyMesh: internal faces in upper-triangular
order, the cells owning boundary faces, the boundary file's entries and the sizes in the files'
notes, all label arithmetic on index ranges (a slab of a mesh larger than memory as well as the
whole mesh: ``meshgen.formats._openfoam``, ``meshgen.formats._foam_streamed``)."""

from __future__ import annotations

import numpy as np

from meshgen.formats._structured import face_nodes, node_labels
from meshgen.geometry import cube

__all__ = ["boundary_owner", "internal_faces", "patch_entries", "poly_mesh_note"]


def internal_faces(point_ids: np.ndarray, cell_ids: np.ndarray, positive: bool):
    """(face nodes (F, 4), owner (F,), neighbour (F,)) int32 of the internal faces of a structured
    grid of node labels ``point_ids`` (N1, N2, N3) and cell labels ``cell_ids`` (N1-1, N2-1, N3-1),
    in upper-triangular order: for each cell in C order, its faces towards the k+1, j+1 and i+1
    neighbours (whose numbers increase in that order), so no sorting is needed."""
    cells = cell_ids.size
    table_nodes = np.zeros((cells, 3, 4), dtype=np.int32)
    table_neighbour = np.full((cells, 3), -1, dtype=np.int32)
    for slot, axis in enumerate((2, 1, 0)):
        before = tuple(slice(0, -1) if d == axis else slice(None) for d in range(3))
        after = tuple(slice(1, None) if d == axis else slice(None) for d in range(3))
        local = (cell_ids[before] - cell_ids.flat[0]).reshape(-1)  # the owners' rows in the table
        table_nodes[local, slot] = face_nodes(point_ids, axis, slice(1, -1), positive).reshape(-1, 4)  # planes between cells
        table_neighbour[local, slot] = cell_ids[after].reshape(-1)
    present = table_neighbour >= 0
    owner = np.broadcast_to(cell_ids.reshape(-1, 1), (cells, 3))[present]
    return table_nodes[present], owner.astype(np.int32), table_neighbour[present]


def boundary_owner(cell_shape, face_name: str) -> np.ndarray:
    """The cells (int32 labels, C order) owning the boundary faces of cube face ``face_name``, in
    the order of ``boundary_elements``."""
    face = cube.face_named(face_name, 3)
    end = cell_shape[face.axis] - 1 if face.side else 0
    plane = tuple(slice(end, end + 1) if d == face.axis else slice(None) for d in range(3))
    return node_labels(cell_shape, plane).reshape(-1).astype(np.int32)


def patch_entries(node_shape, patches) -> list:
    """[(name, type, nFaces, startFace)] of the boundary file: the boundary faces follow the
    internal ones, patch by patch, each patch's cube faces in its order."""
    cell_shape = [n - 1 for n in node_shape]
    start = sum((cell_shape[a] - 1) * int(np.prod(cell_shape)) // cell_shape[a] for a in range(3))
    entries = []
    for patch in patches:
        count = 0
        for face_name in patch.faces:
            axis = cube.face_named(face_name, 3).axis
            count += int(np.prod(cell_shape)) // cell_shape[axis]
        entries.append((patch.name, patch.type, count, start))
        start += count
    return entries


def poly_mesh_note(node_shape) -> str:
    """The ``note`` of the owner and neighbour files: the mesh's sizes, as OpenFOAM writes it."""
    cell_shape = [n - 1 for n in node_shape]
    cells = int(np.prod(cell_shape))
    internal = sum((cell_shape[a] - 1) * cells // cell_shape[a] for a in range(3))
    boundary = sum(2 * cells // cell_shape[a] for a in range(3))
    return f"nPoints:{int(np.prod(node_shape))}  nCells:{cells}  nFaces:{internal + boundary}  nInternalFaces:{internal}"
