"""What one read of a block gives the block-wise report besides its cells' metrics (design notes
§21, "One pass over a file's blocks"): the shortest edge of the cells a block owns, to tell whether
the mesh's degenerate-edge tolerance classifies them as the block's own does.

An edge's length is what the quality kernels compute (``compiled._edge``, ``compiled_quad._unit2``):
the coordinate differences of the node one step up the axis minus the node, then
``sqrt(x*x + y*y [+ z*z])`` summed in that order, IEEE double without contraction (``fastmath``
off). The compiled loop finds the least positive finite sum of squares; its square root is the
least positive finite length, since a correctly rounded square root is monotone and positive for
a positive argument. Lengths above a positive floor (a block with edges at most its own
tolerance: rare) are computed by NumPy, with the same operations in the same order.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

import meshgen.run.jit  # noqa: F401 - numba with its BLAS probe deferred (design notes §21)
from meshgen.quality.pool import threads

__all__ = ["shortest_edge_above"]

_JIT = {"cache": True, "fastmath": False, "nogil": True, "error_model": "numpy"}


@njit(inline="always", **_JIT)
def _kept(s):
    """``s`` if it is positive and finite, else inf (NaN too)."""
    return s if 0.0 < s < np.inf else np.inf


@njit(**_JIT)
def _least_bits(bits, n):
    """The least of ``bits[:n]``: int64 views of doubles that are positive or +inf, whose order is
    that of the doubles (an integer minimum, which LLVM vectorises; a float one it may not reorder)."""
    least = bits[0]
    for t in range(1, n):
        least = min(least, bits[t])
    return least


@njit(parallel=True, **_JIT)
def _least_squares(F, lo, box, parts, out):
    """The least positive finite squared length of the edges between the nodes ``lo <= (i, j, k) <
    box`` of ``F`` (dim, nk, nj, ni), dim 2 (nk = 1) or 3, as ``parts`` partial results in ``out``
    (int64 views of the doubles; that of inf when none): each part takes a run of rows (k, j) and
    the edges from their nodes to the next node along each axis inside the box. The squared lengths
    of a row's edges go to a scratch row (a loop LLVM vectorises), then to the row's minimum."""
    ni, nj, nk = box[0] - lo[0], box[1] - lo[1], box[2] - lo[2]
    rows = nj * nk
    three = F.shape[0] == 3
    for part in prange(parts):
        scratch = np.empty(3 * ni)
        bits = scratch.view(np.int64)
        least = np.int64(0x7FF0000000000000)  # +inf
        for row in range(part * rows // parts, (part + 1) * rows // parts):
            k, j = lo[2] + row // nj, lo[1] + row % nj
            n = 0
            for dk, dj, di in ((0, 0, 1), (0, 1, 0), (1, 0, 0)):
                if j + dj >= box[1] or k + dk >= box[2]:
                    continue
                m = ni - di
                x, y, x1, y1 = (
                    F[0, k, j, lo[0] :],
                    F[1, k, j, lo[0] :],
                    F[0, k + dk, j + dj, lo[0] + di :],
                    F[1, k + dk, j + dj, lo[0] + di :],
                )
                if three:
                    z, z1 = F[2, k, j, lo[0] :], F[2, k + dk, j + dj, lo[0] + di :]
                    for i in range(m):
                        ex, ey, ez = x1[i] - x[i], y1[i] - y[i], z1[i] - z[i]
                        scratch[n + i] = _kept(ex * ex + ey * ey + ez * ez)
                else:
                    for i in range(m):
                        ex, ey = x1[i] - x[i], y1[i] - y[i]
                        scratch[n + i] = _kept(ex * ex + ey * ey)
                n += m
            if n:
                least = min(least, _least_bits(bits, n))
        out[part] = least


def _lengths_above(F, lo, box, floor: float) -> float:
    """The least finite edge length above ``floor`` (inf: none), by NumPy, axis by axis."""
    nodes = F[:, lo[2] : box[2], lo[1] : box[1], lo[0] : box[0]]
    least = np.inf
    for axis in (3, 2, 1):  # i, j, k
        if nodes.shape[axis] < 2:
            continue
        e = np.diff(nodes, axis=axis)
        squares = e[0] * e[0]
        for d in range(1, len(e)):
            squares = squares + e[d] * e[d]
        with np.errstate(invalid="ignore"):
            lengths = np.sqrt(squares)
            above = lengths[(lengths > floor) & (lengths < np.inf)]
        if above.size:
            least = min(least, float(above.min()))
    return least


def shortest_edge_above(F, lo, box, floor: float = 0.0) -> float:
    """The shortest finite edge longer than ``floor`` (>= 0) between the nodes ``lo <= (i, j, k) <
    box`` of ``F`` (dim, nk, nj, ni) (a 2D block: nk = 1), coordinate d of node (i, j, k) at
    [d, k, j, i]; inf when there is none. ``lo``, ``box``: (i, j, k)."""
    lo, box = tuple(int(v) for v in lo), tuple(int(v) for v in box)
    if min(b - a for a, b in zip(lo, box)) <= 0:
        return np.inf
    if floor > 0.0:
        return _lengths_above(F, lo, box, floor)
    rows = (box[1] - lo[1]) * (box[2] - lo[2])
    parts = min(rows, 4 * threads())
    out = np.empty(parts, dtype=np.int64)
    _least_squares(F, lo, box, parts, out)
    return float(np.sqrt(out.view(np.float64).min()))
