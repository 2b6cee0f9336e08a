"""The per-cell grid smoothness figures of ``meshgen.quality.smoothness`` (expansion ratio and
grid smoothness, with the smoothness's largest value along each axis) of a 3D node array as
compiled numba kernels.

Each kernel is the NumPy definition written per edge, per cell or per node, operation by
operation (``fastmath`` off; the same order of sums; NaN and infinity handled as NumPy's
``maximum``, ``fmax`` and ``where`` do), in parallel over the first index. Only the edge lengths
may differ in the last bit (NumPy's ``einsum`` may sum the three squares in another order), so the
two agree to round-off (tested to 1e-12). The NumPy definition makes some 40 full-size
temporaries (0.2 s of CPU at 1e6 cells); these kernels make the three edge-length arrays, three
cell-size arrays and their outputs. They are inlined into one compiled function (``_figures``),
which a process loads from numba's cache once (each compiled function is a load of its own, some
7 ms). Compiled code is cached on disk (``cache=True``).
"""

from __future__ import annotations

import math
import os

import numpy as np
from numba import njit, prange

from meshgen.run.jit import numba

# Dask's worker threads may call numba kernels at once: numba's workqueue layer aborts on
# concurrent calls, TBB and OpenMP do not. Unless the user chose a layer, take one of those (as
# ``meshgen.quality.compiled`` does; whichever module numba loads first sets it).
if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "threadsafe"

__all__ = ["cell_figures"]

_JIT = {"cache": True, "fastmath": False, "nogil": True, "error_model": "numpy"}


@njit(inline="always", **_JIT)
def _lengths(X, step, out, i):
    """Lengths of the grid's edges from node (i, j, k) to (i, j, k) + ``step`` (a unit offset):
    ``out[i]``."""
    for j in range(out.shape[1]):
        for k in range(out.shape[2]):
            i1, j1, k1 = i + step[0], j + step[1], k + step[2]
            d0 = X[i1, j1, k1, 0] - X[i, j, k, 0]
            d1 = X[i1, j1, k1, 1] - X[i, j, k, 1]
            d2 = X[i1, j1, k1, 2] - X[i, j, k, 2]
            out[i, j, k] = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@njit(inline="always", **_JIT)
def _sizes(lengths, p, q, out, i):
    """Mean length of the four edges along the axis of ``lengths`` of the cells (i, j, k):
    averaged over the other axes ``p`` then ``q`` (unit offsets), as ``smoothness._cell_sizes``
    does: ``out[i]``."""
    for j in range(out.shape[1]):
        for k in range(out.shape[2]):
            a = 0.5 * (lengths[i, j, k] + lengths[i + p[0], j + p[1], k + p[2]])
            b = 0.5 * (lengths[i + q[0], j + q[1], k + q[2]] + lengths[i + p[0] + q[0], j + p[1] + q[1], k + p[2] + q[2]])
            out[i, j, k] = 0.5 * (a + b)


@njit(inline="always", **_JIT)
def _ratio(s0, s1):
    """max(s0, s1) / min(s0, s1), infinity where that is NaN (either is NaN, or both are 0)."""
    if s0 != s0 or s1 != s1:
        return np.inf
    ratio = (s0 if s0 >= s1 else s1) / (s1 if s0 >= s1 else s0)
    return np.inf if ratio != ratio else ratio


@njit(inline="always", **_JIT)
def _expansion(S0, S1, S2, out, i):
    """Per cell (i, j, k): 1, and the size ratio across each face shared with a neighbour, the
    largest: ``out[i]``."""
    n0, n1, n2 = out.shape[0], out.shape[1], out.shape[2]
    for j in range(n1):
        for k in range(n2):
            largest = 1.0
            if i > 0:
                largest = max(largest, _ratio(S0[i - 1, j, k], S0[i, j, k]))
            if i < n0 - 1:
                largest = max(largest, _ratio(S0[i, j, k], S0[i + 1, j, k]))
            if j > 0:
                largest = max(largest, _ratio(S1[i, j - 1, k], S1[i, j, k]))
            if j < n1 - 1:
                largest = max(largest, _ratio(S1[i, j, k], S1[i, j + 1, k]))
            if k > 0:
                largest = max(largest, _ratio(S2[i, j, k - 1], S2[i, j, k]))
            if k < n2 - 1:
                largest = max(largest, _ratio(S2[i, j, k], S2[i, j, k + 1]))
            out[i, j, k] = largest


@njit(inline="always", **_JIT)
def _second(X, lengths, step, nodes, i):
    """Relative second differences along ``step`` at the inner nodes (``smoothness._second``)
    (i, j, k) + ``step``, folded into ``nodes`` with fmax: (their largest, whether one is NaN),
    for NumPy's NaN-propagating ``max``."""
    n1, n2 = nodes.shape[1] - 2 * step[1], nodes.shape[2] - 2 * step[2]
    largest = -np.inf
    nan = False
    for j in range(n1):
        for k in range(n2):
            i1, j1, k1 = i + step[0], j + step[1], k + step[2]  # the inner node
            i2, j2, k2 = i1 + step[0], j1 + step[1], k1 + step[2]
            e0 = (X[i2, j2, k2, 0] - X[i1, j1, k1, 0]) - (X[i1, j1, k1, 0] - X[i, j, k, 0])
            e1 = (X[i2, j2, k2, 1] - X[i1, j1, k1, 1]) - (X[i1, j1, k1, 1] - X[i, j, k, 1])
            e2 = (X[i2, j2, k2, 2] - X[i1, j1, k1, 2]) - (X[i1, j1, k1, 2] - X[i, j, k, 2])
            second = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            spacing = 0.5 * (lengths[i1, j1, k1] + lengths[i, j, k])
            if spacing > 0:
                value = second / spacing
            elif second > 0:
                value = np.inf
            else:
                value = 0.0
            if value != value:
                nan = True
            elif value > largest:
                largest = value
            old = nodes[i1, j1, k1]
            if value > old or old != old:  # fmax: NaN only where both are
                nodes[i1, j1, k1] = value
    return largest, nan


@njit(inline="always", **_JIT)
def _corner_max(nodes, out, i):
    """Per cell (i, j, k): the largest value at its eight corners (none is NaN): ``out[i]``."""
    for j in range(out.shape[1]):
        for k in range(out.shape[2]):
            largest = nodes[i, j, k]
            for a in range(2):
                for b in range(2):
                    for c in range(2):
                        largest = max(largest, nodes[i + a, j + b, k + c])
            out[i, j, k] = largest


@njit(parallel=True, **_JIT)
def _figures(X, unit, lengths, sizes, ratio, nodes, row_max, row_nan, smoothness):
    """Both figures of the 3D node array ``X`` in one kernel (one load from numba's cache), each
    step in parallel over the first index: the edge lengths along each axis (``lengths``, a tuple
    of three arrays), the cells' sizes (``sizes``), the expansion ratio (``ratio``), the relative
    second differences folded into ``nodes`` with their largest and NaN per first index and axis
    (``row_max``, ``row_nan``: (3, n1 + 1), axes with fewer than three nodes left alone), and the
    grid smoothness (``smoothness``)."""
    for axis in range(3):
        edges = lengths[axis]
        for i in prange(edges.shape[0]):
            _lengths(X, unit[axis], edges, i)
    for axis in range(3):
        # the other two axes in increasing order, as ``smoothness._cell_sizes`` averages over them
        p, q = unit[1 if axis == 0 else 0], unit[1 if axis == 2 else 2]
        for i in prange(ratio.shape[0]):
            _sizes(lengths[axis], p, q, sizes[axis], i)
    for i in prange(ratio.shape[0]):
        _expansion(sizes[0], sizes[1], sizes[2], ratio, i)
    for axis in range(3):
        if nodes.shape[axis] < 3:
            continue
        for i in prange(nodes.shape[0] - 2 * unit[axis][0]):
            row_max[axis, i], row_nan[axis, i] = _second(X, lengths[axis], unit[axis], nodes, i)
    for i in prange(smoothness.shape[0]):
        _corner_max(nodes, smoothness, i)


def cell_figures(X: np.ndarray):
    """(expansion ratio per cell, grid smoothness per cell, the smoothness's largest value along
    each axis) of the 3D node array ``X``, as ``meshgen.quality.smoothness`` defines them."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    node_shape = X.shape[:-1]
    cells = tuple(n - 1 for n in node_shape)
    unit = np.eye(3, dtype=np.int64)
    lengths = tuple(np.empty(tuple(n - 1 if d == axis else n for d, n in enumerate(node_shape))) for axis in range(3))
    sizes = tuple(np.empty(cells) for _ in range(3))
    ratio, smoothness = np.empty(cells), np.empty(cells)
    nodes = np.zeros(node_shape)
    row_max, row_nan = np.full((3, node_shape[0]), -np.inf), np.zeros((3, node_shape[0]), dtype=np.bool_)
    _figures(X, unit, lengths, sizes, ratio, nodes, row_max, row_nan, smoothness)
    by_axis = []
    for axis in range(3):
        if node_shape[axis] < 3:
            by_axis.append(0.0)
            continue
        rows = node_shape[0] - 2 * unit[axis][0]
        by_axis.append(float("nan") if row_nan[axis, :rows].any() else float(row_max[axis, :rows].max()))
    return ratio, smoothness, by_axis
