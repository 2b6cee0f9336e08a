"""Structured-grid topology: VTK cell connectivity of a node array, flattened points, and the
partition of the node index space into blocks (meshes larger than memory)."""

from __future__ import annotations

import numpy as np

__all__ = [
    "BLOCK_NODES",
    "HEX_CORNERS",
    "HEX_FACE_LOOPS",
    "HEX_FACE_OUTWARD",
    "QUAD_CORNERS",
    "block_slices",
    "cell_connectivity",
    "flat_points",
]

BLOCK_NODES = 1 << 20  # at most: about 1e6 nodes, 25 MB of float64 coordinates per block

# Corner offsets (di, dj[, dk]) in VTK order: hexahedron (VTK_HEXAHEDRON) and quad (VTK_QUAD).
HEX_CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
QUAD_CORNERS = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])


def _hex_face_loops() -> np.ndarray:
    """(6, 4): the VTK hexahedron's corners on its faces (axis 0 side 0, axis 0 side 1, axis 1
    side 0, ...), each as a loop whose right-hand area vector points along +axis (the quality
    kernels' ``HEX_FACE_CORNERS`` list the same corners unordered, to match faces)."""
    corner_of = {tuple(int(b) for b in bits): k for k, bits in enumerate(HEX_CORNERS)}
    rows = []
    for axis in range(3):
        first, second = (axis + 1) % 3, (axis + 2) % 3
        for side in (0, 1):
            row = []
            for u, v in ((0, 0), (1, 0), (1, 1), (0, 1)):
                bits = [0, 0, 0]
                bits[axis], bits[first], bits[second] = side, u, v
                row.append(corner_of[tuple(bits)])
            rows.append(row)
    return np.array(rows)


HEX_FACE_LOOPS = _hex_face_loops()
HEX_FACE_OUTWARD = np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0])  # a right-handed cell's side 0 faces point against +axis


def cell_connectivity(node_shape) -> np.ndarray:
    """Cells of a structured grid with ``node_shape`` = (n1+1, n2+1[, n3+1]) nodes, as indices into
    the C-order flattened node array: shape (n1*n2[*n3], 8 or 4), VTK corner order, int64.
    For a right-handed map (positive Jacobian) the cells are positively oriented."""
    node_shape = tuple(int(n) for n in node_shape)
    corners = HEX_CORNERS if len(node_shape) == 3 else QUAD_CORNERS
    flat_index = np.arange(np.prod(node_shape)).reshape(node_shape)
    cell_shape = tuple(n - 1 for n in node_shape)
    columns = [flat_index[tuple(slice(o, o + c) for o, c in zip(offset, cell_shape))].reshape(-1) for offset in corners]
    return np.stack(columns, axis=1)


def flat_points(X: np.ndarray, width: int = 3) -> np.ndarray:
    """Node array (..., dim) -> (N, width) points, padded with zeros (2D meshes live in z = 0)."""
    dim = X.shape[-1]
    points = X.reshape(-1, dim)
    if dim < width:
        points = np.hstack([points, np.zeros((points.shape[0], width - dim))])
    return np.ascontiguousarray(points, dtype=float)


def block_slices(node_shape, block_nodes: int = BLOCK_NODES) -> list[list[slice]]:
    """Per index axis, the slices of the blocks along it: slabs of the last axis holding about
    ``block_nodes`` nodes; the first axis is split too when one plane of the last axis is larger."""
    node_shape = tuple(int(n) for n in node_shape)
    plane = int(np.prod(node_shape[:-1]))
    per_axis = [[slice(0, n)] for n in node_shape]
    if plane <= block_nodes:
        step = max(1, block_nodes // plane)
    else:
        step = 1
        rows = max(1, block_nodes // max(1, int(np.prod(node_shape[1:-1]))))
        per_axis[0] = [slice(s, min(s + rows, node_shape[0])) for s in range(0, node_shape[0], rows)]
    n = node_shape[-1]
    per_axis[-1] = [slice(s, min(s + step, n)) for s in range(0, n, step)]
    return per_axis
