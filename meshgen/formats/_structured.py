"""Boundary faces of a structured grid for the formats that list them (OpenFOAM, SU2, Gmsh):
node labels of each face, going round so that its normal points out of the domain, and rows of
numbers written as text fast."""

from __future__ import annotations

import numpy as np

from meshgen.geometry import cube

__all__ = ["boundary_elements", "corner_volume", "face_nodes", "node_labels", "orientation", "write_rows"]


def orientation(X: np.ndarray) -> float:
    """+1 for a right-handed (2D: counterclockwise) map, -1 otherwise: the sign of the total
    volume (area) of the cells' corner parallelepipeds (parallelograms)."""
    return 1.0 if corner_volume(X) >= 0 else -1.0


def corner_volume(X: np.ndarray) -> float:
    """The total signed volume (2D: area) of the cells' corner parallelepipeds (parallelograms) of
    node array ``X``; a slab of nodes with one node of overlap gives its cells' share."""
    dim = X.shape[-1]
    e = [np.diff(X, axis=axis)[tuple(slice(0, -1) if d != axis else slice(None) for d in range(dim))] for axis in range(dim)]
    if dim == 2:
        return float(np.sum(e[0][..., 0] * e[1][..., 1] - e[0][..., 1] * e[1][..., 0]))
    return float(np.sum(np.einsum("...i,...i", e[0], np.cross(e[1], e[2]))))


def face_nodes(point_ids: np.ndarray, axis: int, planes: slice, outward_positive: bool) -> np.ndarray:
    """Node labels of the quadrilateral faces on the node planes ``planes`` (a slice along
    ``axis``) of the (N1, N2, N3) array ``point_ids``: shape (planes, cells along the other two
    axes in their order, 4), so that ``reshape(-1, 4)`` lists the faces in C order. They go round
    so that the normal points along +axis (``outward_positive``, for a right-handed map) or
    -axis: with b, c = axis+1, axis+2 (cyclic) the corners are o, o+e_b, o+e_b+e_c, o+e_c, whose
    normal is e_b x e_c."""
    b, c = (axis + 1) % 3, (axis + 2) % 3

    def corner(step_b, step_c):
        index = [slice(None)] * 3
        index[axis] = planes
        index[b] = slice(step_b, point_ids.shape[b] - 1 + step_b)
        index[c] = slice(step_c, point_ids.shape[c] - 1 + step_c)
        return point_ids[tuple(index)]

    nodes = np.stack([corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)], axis=-1)
    return nodes if outward_positive else nodes[..., ::-1]


def node_labels(node_shape, block) -> np.ndarray:
    """The C-order flat labels (int64) of the nodes ``block`` (one slice per axis) of a grid of
    ``node_shape`` nodes, shape of the block: built from the block alone, not the whole grid."""
    node_shape = tuple(int(n) for n in node_shape)
    strides = np.cumprod((1,) + node_shape[:0:-1])[::-1]
    labels = np.zeros((), dtype=np.int64)
    for axis, part in enumerate(block):
        start, stop, _ = part.indices(node_shape[axis])
        labels = np.add.outer(labels, np.arange(start, stop, dtype=np.int64) * int(strides[axis]))
    return labels


def boundary_elements(node_shape, face_name: str, positive: bool = True) -> np.ndarray:
    """The boundary elements on cube face ``face_name`` of a grid of ``node_shape`` nodes, as
    labels of the C-order flat nodes (0-based): 3D quads (faces, 4) with outward normals, 2D lines
    (edges, 2) running with the domain on their left (counterclockwise) for a ``positive`` map.
    Memory: the face's nodes only."""
    dim = len(node_shape)
    face = cube.face_named(face_name, dim)
    end = int(node_shape[face.axis]) - 1 if face.side else 0
    plane = tuple(slice(end, end + 1) if d == face.axis else slice(None) for d in range(dim))
    point_ids = node_labels(node_shape, plane)
    if dim == 3:
        return face_nodes(point_ids, face.axis, slice(0, 1), positive == bool(face.side)).reshape(-1, 4)
    line = np.take(point_ids, 0, axis=face.axis)
    segments = np.stack([line[:-1], line[1:]], axis=1)
    # Counterclockwise: eta0 and xi1 run with increasing index, eta1 and xi0 against it.
    forward = (face.axis == 1) != bool(face.side)
    return segments if forward == positive else segments[:, ::-1]


def write_rows(file, values: np.ndarray, row: str) -> None:
    """Write the rows of a 2D array (1D: one value a row) as text, one line each: ``row`` with a
    ``{}`` per column (``%.17g`` for floats, ``%d`` for integers), in blocks for speed."""
    values = np.asarray(values)
    spec = row.replace("{}", "%.17g" if values.dtype.kind == "f" else "%d") + "\n"
    block = 1 << 16
    for first in range(0, len(values), block):
        rows = values[first : first + block]
        file.write(((spec * len(rows)) % tuple(rows.reshape(-1).tolist())).encode())
