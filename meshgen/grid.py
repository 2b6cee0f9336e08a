"""Structured-grid topology: VTK cell connectivity of a node array, flattened points."""

from __future__ import annotations

import numpy as np

# Corner offsets (di, dj[, dk]) in VTK order: hexahedron (VTK_HEXAHEDRON) and quad (VTK_QUAD).
HEX_CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
QUAD_CORNERS = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])


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
