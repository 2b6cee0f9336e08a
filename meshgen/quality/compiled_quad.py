"""The per-cell metrics of quadrilaterals (definitions in ``meshgen.quality.kernels``) as compiled
numba kernels: ``_quad_cell`` holds the arithmetic, ``structured_quad`` (2D node arrays; face
neighbours are the cells at index +-1) and ``unstructured_quad`` (points + connectivity; neighbours
from face matching) feed it, in parallel over cells. The arithmetic follows the NumPy definition
operation by operation in IEEE double precision (``fastmath=False``) and the angles come from the
cosines through NumPy's own ``arccos`` (``finish_hex_angles``), as the hexahedra's do.

The small helpers shared with the hexahedra (``meshgen.quality.compiled``) are repeated here
rather than imported: numba's on-disk cache of a function is invalidated by changes to its own
file only, never by changes to a compiled function it calls in another file.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

import meshgen.run.jit  # noqa: F401 - numba with its BLAS probe deferred (design notes §21)
from meshgen.quality import compiled  # noqa: F401  (sets numba's threading layer first)
from meshgen.quality.angles import finish_hex_angles

__all__ = ["structured_quad", "unstructured_quad"]

# VTK corner order of a quad, as corner q (centroids are summed in this order).
QUAD_Q_OF_VTK = np.array([0, 1, 3, 2])

_JIT = {"cache": True, "fastmath": False, "nogil": True, "error_model": "numpy"}


@njit(inline="always", **_JIT)
def _nanmin(a, b):
    """np.minimum: NaN if either is NaN."""
    return a if (a < b or a != a) else b


@njit(inline="always", **_JIT)
def _short(length, tolerance):
    """An edge of a degenerate cell: not longer than ``tolerance``, or not finite (NaN, inf)."""
    return not (tolerance < length < np.inf)


@njit(inline="always", **_JIT)
def _unit2(x, y):
    length = math.sqrt(x * x + y * y)
    inverse = 1.0 / (length if length > 0.0 else 1.0)
    return x * inverse, y * inverse, length


@njit(inline="always", **_JIT)
def _finish(largest_cosine, smallest_cosine, reflex_cosine, any_reflex, aspect_ratio, centroid_alignment, face_alignment,
            scaled_jacobian, out, c):  # fmt: skip
    """The hexahedra's layout (``meshgen.quality.angles.finish_hex_angles`` makes the angles):
    row 0 the largest corner cosine, row 1 the max-angle cosine (the reflex corner's where there
    is one), row 2 the reflex flag, row 5 the face-alignment cosine."""
    out[0, c] = largest_cosine
    out[1, c] = reflex_cosine if any_reflex else smallest_cosine
    out[2, c] = 1.0 if any_reflex else 0.0
    out[3, c] = aspect_ratio
    out[4, c] = 1.0 - centroid_alignment
    out[5, c] = face_alignment
    out[6, c] = scaled_jacobian


@njit(**_JIT)
def _quad_cell(P, G, N, S, tolerance, orientation, out, degenerate, c):
    """Metrics of one quadrilateral (see ``_hex_cell``); ``P`` (4, 2), ``N`` (4, 2); ``S`` (4, 2, 2)
    scratch; ``orientation`` +1 or -1, the sign of the mesh's total area."""
    # unit edges (ux, uy)[axis, t]: axis 0 from (0,t) to (1,t), axis 1 from (t,0) to (t,1)
    ux, uy, principal, mean = S[0], S[1], S[2], S[3, 0]
    short = False
    for axis in range(2):
        step = 1 << axis
        sx = sy = total = 0.0
        for t in range(2):
            low = t << (1 - axis)
            ex, ey = P[low + step, 0] - P[low, 0], P[low + step, 1] - P[low, 1]
            x, y, length = _unit2(ex, ey)
            ux[axis, t], uy[axis, t] = x, y
            if _short(length, tolerance):
                short = True
            if t == 0:
                sx, sy, total = ex, ey, length
            else:
                sx, sy, total = sx + ex, sy + ey, total + length
        mean[axis] = total * 0.5
        px, py, _ = _unit2(sx, sy)
        principal[axis, 0], principal[axis, 1] = px, py
    degenerate[c] = short
    longest, shortest = max(mean[0], mean[1]), min(mean[0], mean[1])
    aspect_ratio = longest / shortest if shortest > 0.0 else np.inf

    def dot(t0, t1):
        return ux[0, t0] * ux[1, t1] + uy[0, t0] * uy[1, t1]

    def cross(t0, t1):
        return ux[0, t0] * uy[1, t1] - uy[0, t0] * ux[1, t1]

    c0, c1, c2, c3 = dot(0, 0), -dot(0, 1), dot(1, 1), -dot(1, 0)
    a0, a1, a2, a3 = cross(0, 0), cross(0, 1), cross(1, 1), cross(1, 0)
    largest_cosine = max(max(c0, c1), max(c2, c3))
    smallest_cosine = min(min(c0, c1), min(c2, c3))
    smallest_area = _nanmin(_nanmin(a0, a1), _nanmin(a2, a3))
    largest_area = -_nanmin(_nanmin(-a0, -a1), _nanmin(-a2, -a3))
    d1x, d1y = P[3, 0] - P[0, 0], P[3, 1] - P[0, 1]
    d2x, d2y = P[2, 0] - P[1, 0], P[2, 1] - P[1, 1]
    centre_area = d1x * d2y - d1y * d2x
    reflex = smallest_area < 0.0 if centre_area >= 0.0 else largest_area > 0.0
    scaled_jacobian = smallest_area if orientation > 0 else -largest_area

    centroid_alignment = face_alignment = 0.0
    for face in range(4):
        axis, side = face >> 1, face & 1
        other = 1 - axis
        ax, ay = ux[other, side], uy[other, side]  # the face is the edge across the normal axis
        px, py = principal[axis, 0], principal[axis, 1]
        centroid_cosine = abs(ax * py - ay * px)
        dx, dy = N[face, 0] - G[0], N[face, 1] - G[1]
        if not math.isfinite(dx + dy):
            dx, dy = px, py
        tx, ty, _ = _unit2(dx, dy)
        face_cosine = abs(ax * ty - ay * tx)
        if face == 0:
            centroid_alignment, face_alignment = centroid_cosine, face_cosine
        else:
            centroid_alignment = min(centroid_alignment, centroid_cosine)
            face_alignment = min(face_alignment, face_cosine)
    reflex_cosine = smallest_cosine if reflex else -2.0
    _finish(largest_cosine, smallest_cosine, reflex_cosine, reflex, aspect_ratio, centroid_alignment, face_alignment,
            scaled_jacobian, out, c)  # fmt: skip


@njit(parallel=True, **_JIT)
def _structured_quad(X, first, last, tolerance, orientation, out, degenerate):
    """``structured_quad`` without the angles (cosines left in ``out``)."""
    n1, n2 = X.shape[0] - 1, X.shape[1] - 1
    centroid = np.empty((n1, n2, 2))
    for i in prange(n1):
        for j in range(n2):
            for d in range(2):
                s = X[i, j, d]
                s = s + X[i + 1, j, d]
                s = s + X[i + 1, j + 1, d]
                s = s + X[i, j + 1, d]
                centroid[i, j, d] = s * 0.25
    m2 = last[1] - first[1]
    for i in prange(first[0], last[0]):
        P = np.empty((4, 2))
        N = np.empty((4, 2))
        S = np.empty((4, 2, 2))
        for j in range(first[1], last[1]):
            for q in range(4):
                for d in range(2):
                    P[q, d] = X[i + (q & 1), j + (q >> 1), d]
            for face in range(4):
                axis, side = face >> 1, face & 1
                delta = 1 if side else -1
                ni, nj = (i + delta, j) if axis == 0 else (i, j + delta)
                inside = 0 <= ni < n1 and 0 <= nj < n2
                for d in range(2):
                    N[face, d] = centroid[ni, nj, d] if inside else np.nan
            _quad_cell(P, centroid[i, j], N, S, tolerance, orientation, out, degenerate, (i - first[0]) * m2 + (j - first[1]))


@njit(parallel=True, **_JIT)
def _centroids(points, cells):
    """Mean of each cell's corners, summed in VTK corner order."""
    n, corners, dim = cells.shape[0], cells.shape[1], points.shape[1]
    centroid = np.empty((n, dim))
    weight = 1.0 / corners
    for c in prange(n):
        for d in range(dim):
            s = points[cells[c, 0], d]
            for k in range(1, corners):
                s = s + points[cells[c, k], d]
            centroid[c, d] = s * weight
    return centroid


@njit(parallel=True, **_JIT)
def _unstructured_quad(points, cells, neighbour, tolerance, orientation, out, degenerate):
    """``unstructured_quad`` without the angles (cosines left in ``out``)."""
    centroid = _centroids(points, cells)
    n = cells.shape[0]
    chunk = 1024
    for block in prange((n + chunk - 1) // chunk):
        P = np.empty((4, 2))
        N = np.empty((4, 2))
        S = np.empty((4, 2, 2))
        for c in range(block * chunk, min(n, (block + 1) * chunk)):
            for k in range(4):
                for d in range(2):
                    P[QUAD_Q_OF_VTK[k], d] = points[cells[c, k], d]
            for face in range(4):
                other = neighbour[face, c]
                for d in range(2):
                    N[face, d] = centroid[other, d] if other >= 0 else np.nan
            _quad_cell(P, centroid[c], N, S, tolerance, orientation, out, degenerate, c)


def structured_quad(X, first, last, tolerance, orientation, out, degenerate):
    """``structured_hex`` for a 2D node array (n1+1, n2+1, 2): the cells' metrics into ``out``
    (7, m), the angles from the kernel's cosines by NumPy's ``arccos`` (``finish_hex_angles``), so
    they are the NumPy definition's to the bit on every CPU (a libm ``acos`` in the kernel differs
    from NumPy's vectorised one in the last bit where NumPy dispatches AVX-512)."""
    _structured_quad(X, first, last, tolerance, orientation, out, degenerate)
    finish_hex_angles(out)


def unstructured_quad(points, cells, neighbour, tolerance, orientation, out, degenerate):
    """``unstructured_hex`` for quads ``cells`` (M, 4) on ``points`` (N, 2); ``neighbour`` (4, M);
    the angles as ``structured_quad``'s."""
    _unstructured_quad(points, cells, neighbour, tolerance, orientation, out, degenerate)
    finish_hex_angles(out)
