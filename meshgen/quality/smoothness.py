"""Grid smoothness figures that predict a flow solver's discretisation error, on a node array.

Mean and minimum angles do not see a grid whose spacing jumps from one cell to the next or whose
grid lines wiggle; a finite-volume solver does (its interpolation weights and gradient stencils
assume smoothly varying cells). Two per-cell figures:

- ``expansion_ratio`` (grid-line definition, as structured-grid guides use it): a cell's size along
  axis a is the mean length of its edges along a (4 in 3D, 2 in 2D); across each face shared with a
  neighbour along a, the ratio of the larger of the two sizes to the smaller. A cell's figure is the
  largest over its faces (1 on a uniform grid; q on a grid graded geometrically by q; 1 for a cell
  with no neighbour). Not the ratio of neighbouring volumes, which a cell stretched along one axis
  and squeezed along another hides.
- ``grid_smoothness``: at each node and axis with a node on both sides, the second difference of
  node positions along the grid line relative to the local spacing,
  |X_(i+1) - 2 X_i + X_(i-1)| / ((|X_(i+1) - X_i| + |X_i - X_(i-1)|) / 2): 0 on straight, evenly
  spaced lines; 2 sin(dtheta / 2) on a circle sampled every dtheta; 2 (q - 1) / (q + 1) where the
  spacing grows by q. A cell's figure is the largest over its corners' grid lines.

``smoothness_figures(X)`` gives both with their summaries and worst cells (JSON-ready).
"""

from __future__ import annotations

import numpy as np

from meshgen.quality.structured import use_compiled

__all__ = ["DEFINITIONS", "expansion_ratio", "grid_smoothness", "smoothness_figures"]

DEFINITIONS = {
    "expansion_ratio": (
        "largest over a cell's faces of max(s, s')/min(s, s'), s and s' the two cells' mean edge lengths along the axis "
        "normal to the shared face (grid-line size ratio; 1 uniform, q for geometric grading q)"
    ),
    "grid_smoothness": (
        "largest over a cell's corners and axes of |X(i+1) - 2 X(i) + X(i-1)| divided by the mean of the two adjacent "
        "edge lengths along that grid line (0: straight, evenly spaced lines)"
    ),
}


def _norm(vectors: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("...i,...i->...", vectors, vectors))


def _slice(axis: int, dim: int, part: slice) -> tuple:
    index = [slice(None)] * dim
    index[axis] = part
    return tuple(index)


def _cell_sizes(edges: np.ndarray, axis: int) -> np.ndarray:
    """Mean length of each cell's edges along ``axis`` from ``edges`` (lengths of the grid's edges
    along ``axis``: n_axis along it, nodes along the others): (n1, n2[, n3])."""
    dim = edges.ndim
    for other in range(dim):
        if other != axis:
            edges = 0.5 * (edges[_slice(other, dim, slice(0, -1))] + edges[_slice(other, dim, slice(1, None))])
    return edges


def _edge_lengths(X: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """The edge vectors along ``axis`` of node array ``X`` and their lengths."""
    edges = np.diff(X, axis=axis)
    return edges, _norm(edges)


def _ratio(size: np.ndarray, axis: int, result: np.ndarray) -> None:
    """Fold the size ratio across the faces normal to ``axis`` into the per-cell ``result``."""
    dim = size.ndim
    if size.shape[axis] < 2:
        return
    low, high = size[_slice(axis, dim, slice(0, -1))], size[_slice(axis, dim, slice(1, None))]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.maximum(low, high) / np.minimum(low, high)
    ratio = np.where(np.isnan(ratio), np.inf, ratio)
    for part in (slice(0, -1), slice(1, None)):
        np.fmax(result[_slice(axis, dim, part)], ratio, out=result[_slice(axis, dim, part)])


def _second(vectors: np.ndarray, lengths: np.ndarray, axis: int) -> np.ndarray:
    """Relative second differences at the inner nodes along ``axis`` from the edge ``vectors``
    and their ``lengths`` along it."""
    dim = lengths.ndim
    first, last = _slice(axis, dim, slice(0, -1)), _slice(axis, dim, slice(1, None))
    second = _norm(vectors[last] - vectors[first])
    spacing = 0.5 * (lengths[last] + lengths[first])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(spacing > 0, second / spacing, np.where(second > 0, np.inf, 0.0))


def expansion_ratio(X: np.ndarray) -> np.ndarray:
    """Per cell (n1, n2[, n3]): the expansion ratio (module docstring) of node array ``X``."""
    X = np.asarray(X, dtype=float)
    result = np.ones(tuple(n - 1 for n in X.shape[:-1]))
    for axis in range(X.ndim - 1):
        _ratio(_cell_sizes(_edge_lengths(X, axis)[1], axis), axis, result)
    return result


def node_smoothness(X: np.ndarray, axes=None) -> np.ndarray:
    """Per node (n1+1, n2+1[, n3+1]): the largest over ``axes`` (default all) of the relative
    second difference along that axis's grid line (module docstring); 0 where none of them has a
    node on both sides."""
    X = np.asarray(X, dtype=float)
    dim = X.ndim - 1
    result = np.zeros(X.shape[:-1])
    for axis in range(dim) if axes is None else axes:
        if X.shape[axis] < 3:
            continue
        inner = _slice(axis, dim, slice(1, -1))
        np.fmax(result[inner], _second(*_edge_lengths(X, axis), axis), out=result[inner])
    return result


def _corner_max(nodes: np.ndarray) -> np.ndarray:
    """Per cell: the largest value at its corners."""
    dim = nodes.ndim
    result = None
    for corner in np.ndindex(*(2,) * dim):
        part = nodes[tuple(slice(c, n - 1 + c) for c, n in zip(corner, nodes.shape))]
        result = part.copy() if result is None else np.fmax(result, part, out=result)
    return result


def grid_smoothness(X: np.ndarray, axes=None) -> np.ndarray:
    """Per cell (n1, n2[, n3]): the largest :func:`node_smoothness` (along ``axes``, default all)
    over the cell's corners."""
    return _corner_max(node_smoothness(X, axes))


def _summary(values: np.ndarray) -> dict:
    """mean, max, p99 of the finite ``values`` and where the max lies (a NaN counts as the least);
    ``values`` (a figure's per-cell array, nobody's after this) is reordered in place by the
    percentile's partition: no copy where every value is finite."""
    finite = np.isfinite(values)
    if finite.all():
        finite, worst = values, int(np.argmax(values))
    else:
        finite, worst = values[finite], int(np.argmax(np.where(np.isnan(values), -np.inf, values)))
    summary = {
        "mean": float(finite.mean()) if finite.size else None,
        "max": float(values.reshape(-1)[worst]),
        "p99": None,
        "worst_cell": [int(i) for i in np.unravel_index(worst, values.shape)],
    }
    if finite.size:
        summary["p99"] = float(np.percentile(finite, 99.0, overwrite_input=True))
    return summary


def smoothness_figures(X: np.ndarray, kernels: str = "auto") -> dict:
    """{"expansion_ratio": {...}, "grid_smoothness": {...}} of node array ``X``, each with mean,
    max, p99 and ``worst_cell`` (the (i, j[, k]) of the max); the smoothness also with
    ``max_by_axis`` (along the xi, eta[, zeta] grid lines alone: a wall's curvature shows on the
    lines along the wall, a kink between layers on the lines across them). JSON-ready. One pass
    over each axis's edges serves both figures.

    ``kernels``: "numpy" (this module's arithmetic), "compiled" (3D only: the same per edge, cell
    and node in ``meshgen.quality.smoothness_compiled``, agreeing to round-off) or "auto":
    compiled for 3D meshes from ``meshgen.quality.structured.NUMPY_CELLS`` cells up, as the
    per-cell metrics choose (the mesh's size alone decides)."""
    X = np.asarray(X, dtype=float)
    dim = X.ndim - 1
    if dim == 3 and use_compiled(int(np.prod([n - 1 for n in X.shape[:-1]])), kernels):
        from meshgen.quality.smoothness_compiled import cell_figures  # numba

        ratio, cell_smoothness, by_axis = cell_figures(X)
        smoothness = _summary(cell_smoothness)
        smoothness["max_by_axis"] = by_axis
        return {"expansion_ratio": _summary(ratio), "grid_smoothness": smoothness}
    ratio = np.ones(tuple(n - 1 for n in X.shape[:-1]))
    nodes = np.zeros(X.shape[:-1])
    by_axis = []
    for axis in range(dim):
        vectors, lengths = _edge_lengths(X, axis)
        _ratio(_cell_sizes(lengths, axis), axis, ratio)
        if X.shape[axis] < 3:
            by_axis.append(0.0)
            continue
        second = _second(vectors, lengths, axis)
        by_axis.append(float(np.max(second)))
        inner = _slice(axis, dim, slice(1, -1))
        np.fmax(nodes[inner], second, out=nodes[inner])
    smoothness = _summary(_corner_max(nodes))
    smoothness["max_by_axis"] = by_axis
    return {"expansion_ratio": _summary(ratio), "grid_smoothness": smoothness}
