"""Per-cell metrics of a structured node array (n1+1, n2+1[, n3+1], dim): corners and face
neighbours are views of the array, the kernels of ``meshgen.quality.kernels`` run on blocks of
``BLOCK_CELLS`` cells."""

from __future__ import annotations

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.limits import MAX_COORDINATE
from meshgen.quality.kernels import (
    BLOCK_CELLS,
    DEGENERATE_TOLERANCE,
    HEX_CORNER,
    HEX_FACES,
    METRICS,
    QUAD_CORNER,
    QUAD_FACES,
    WORST,
    cross_2d,
    hex_kernel,
    quad_kernel,
    vector_difference,
)

__all__ = ["apply_degenerate", "cell_metrics", "check_node_array", "degenerate_tolerance", "orientation_2d", "structured_metrics"]


def check_node_array(X) -> np.ndarray:
    X = np.asarray(X, dtype=float)
    if X.ndim not in (3, 4) or X.shape[-1] != X.ndim - 1 or min(X.shape[:-1]) < 2:
        raise MeshgenError(f"node array must have shape (n1+1, n2+1[, n3+1], dim) with >= 2 nodes per axis, got {X.shape}")
    return X


def degenerate_tolerance(points_or_components) -> tuple[float, int]:
    """Degenerate-edge length and the number of non-finite nodes, from the finite coordinates."""
    components = points_or_components
    finite = np.ones(components[0].shape, dtype=bool)
    for c in components:
        finite &= np.isfinite(c)
    nonfinite = int(finite.size - np.count_nonzero(finite))
    if not finite.any():
        return 0.0, nonfinite
    largest = max(float(np.abs(c[finite]).max()) for c in components)
    if largest > MAX_COORDINATE:
        raise MeshgenError(f"coordinates reach {largest:.3g}, beyond {MAX_COORDINATE:g}: lengths and volumes would overflow")
    extent = np.sqrt(sum(float(np.ptp(c[finite])) ** 2 for c in components))
    return DEGENERATE_TOLERANCE * extent, nonfinite


def orientation_2d(corner) -> float:
    """+1 if the quads' total signed area (diagonal cross products) is >= 0, else -1."""
    area = cross_2d(vector_difference(corner[(1, 1)], corner[(0, 0)]), vector_difference(corner[(0, 1)], corner[(1, 0)]))
    total = float(np.nansum(area))
    return 1.0 if total >= 0.0 else -1.0


def apply_degenerate(metrics: dict, degenerate: np.ndarray) -> None:
    if not degenerate.any():
        return
    for name, worst in WORST.items():
        metrics[name][degenerate] = worst
    sj = metrics["scaled_jacobian"]
    sj[degenerate] = np.minimum(np.where(np.isfinite(sj[degenerate]), sj[degenerate], 0.0), 0.0)


def structured_metrics(X, tolerance=None, orientation=None):
    """Per-cell metrics (C order of cells) and the degenerate mask of node array ``X``.

    ``tolerance`` (degenerate-edge length) and ``orientation`` (2D: +1 or -1) default to those of
    ``X`` itself; a block of a larger mesh passes the whole mesh's, so its cells get the values they
    get in the whole."""
    X = check_node_array(X)
    dim = X.shape[-1]
    node_shape = X.shape[:-1]
    cell_shape = tuple(n - 1 for n in node_shape)
    n_cells = int(np.prod(cell_shape))
    components = tuple(np.ascontiguousarray(X[..., c]) for c in range(dim))
    own_tolerance, nonfinite = degenerate_tolerance(components)
    tolerance = own_tolerance if tolerance is None else tolerance
    offsets = HEX_CORNER if dim == 3 else QUAD_CORNER

    def corners(first, last):
        """Views of the corners of the cells first..last-1 along axis 0."""
        return {
            s: tuple(
                c[(slice(first + s[0], last + s[0]),) + tuple(slice(o, o + n) for o, n in zip(s[1:], cell_shape[1:]))]
                for c in components
            )
            for s in offsets
        }

    all_corners = corners(0, cell_shape[0])
    weight = 1.0 / len(offsets)
    centroid = tuple(sum(corner[c] for corner in all_corners.values()) * weight for c in range(dim))
    # NaN margin of one cell on every side: the neighbour across a boundary face is "none".
    padded = tuple(np.pad(c, 1, constant_values=np.nan) for c in centroid)
    if orientation is None:
        orientation = orientation_2d(all_corners) if dim == 2 else 1.0
    faces = HEX_FACES if dim == 3 else QUAD_FACES

    metrics = {name: np.empty(cell_shape) for name in METRICS}
    degenerate = np.empty(cell_shape, dtype=bool)
    rows = max(1, BLOCK_CELLS // max(1, int(np.prod(cell_shape[1:]))))
    for first in range(0, cell_shape[0], rows):
        last = min(cell_shape[0], first + rows)
        inner = (slice(first + 1, last + 1),) + tuple(slice(1, n + 1) for n in cell_shape[1:])
        block_centroid = tuple(p[inner] for p in padded)
        neighbour = {}
        for axis, side in faces:
            shift = [0] * dim
            shift[axis] = 1 if side else -1
            index = tuple(slice(s.start + d, s.stop + d) for s, d in zip(inner, shift))
            neighbour[(axis, side)] = tuple(p[index] for p in padded)
        block = corners(first, last)
        if dim == 3:
            values, short = hex_kernel(block, block_centroid, neighbour, tolerance)
        else:
            values, short = quad_kernel(block, block_centroid, neighbour, tolerance, orientation)
        for name in METRICS:
            metrics[name][first:last] = values[name]
        degenerate[first:last] = short
    metrics = {name: values.reshape(n_cells) for name, values in metrics.items()}
    degenerate = degenerate.reshape(n_cells)
    apply_degenerate(metrics, degenerate)
    return metrics, degenerate, {"nonfinite_nodes": nonfinite}


def cell_metrics(X) -> dict[str, np.ndarray]:
    """The seven per-cell metrics of node array ``X`` (shape ``(n1+1, n2+1[, n3+1], dim)``).

    Returns a dict keyed by ``METRICS``, each an array of length n1*n2[*n3] in C order of the
    cells (i, j[, k]), float64. Angles and non-orthogonality in degrees.
    """
    return structured_metrics(X)[0]
