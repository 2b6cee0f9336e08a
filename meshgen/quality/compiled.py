"""The per-cell metrics (definitions in ``meshgen.quality.kernels``) as compiled numba kernels.

One scalar function per cell kind (``_hex_cell``, ``_quad_cell``) holds the arithmetic; four
drivers feed it corner coordinates and the centroids of the face neighbours, in parallel over
cells (``prange``): structured node arrays (``structured_hex``, ``structured_quad``; neighbours
are the cells at index +-1) and points + connectivity (``unstructured_hex``, ``unstructured_quad``;
neighbours from face matching). Centroids come first in a pass of their own, summed in the VTK
corner order. The arithmetic follows the vectorised NumPy definition operation by operation, in
IEEE double precision (``fastmath=False``), so the kernels agree with it to round-off of the
library ``acos`` (tested to 1e-12).

A cell is written as corner array ``P[q]``, q = s0 + 2 s1 (+ 4 s2) for the corner at offsets
(s0, s1[, s2]) from the cell's first node. Compiled code is cached on disk (``cache=True``): the
first call in a fresh installation compiles for some seconds, later processes load it.
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np
from numba import njit, prange

# Dask's worker threads call the kernels at once (the chunked path): numba's workqueue layer aborts
# on concurrent calls, TBB and OpenMP do not. Unless the user chose a layer, take one of those.
if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "threadsafe"

__all__ = ["finite_extent", "structured_hex", "structured_quad", "unstructured_hex", "unstructured_quad"]

_DEGREES = 180.0 / math.pi
# VTK corner order of a hexahedron / quad, as corner q (centroids are summed in this order).
HEX_Q_OF_VTK = np.array([0, 1, 3, 2, 4, 5, 7, 6])
QUAD_Q_OF_VTK = np.array([0, 1, 3, 2])

_JIT = {"cache": True, "fastmath": False, "nogil": True, "error_model": "numpy"}


@njit(inline="always", **_JIT)
def _degrees_of_cosine(cosine):
    return math.acos(min(max(cosine, -1.0), 1.0)) * _DEGREES


@njit(inline="always", **_JIT)
def _nanmin(a, b):
    """np.minimum: NaN if either is NaN."""
    return a if (a < b or a != a) else b


@njit(inline="always", **_JIT)
def _short(length, tolerance):
    """An edge of a degenerate cell: not longer than ``tolerance``, or not finite (NaN, inf)."""
    return not (tolerance < length < np.inf)


@njit(inline="always", **_JIT)
def _unit3(x, y, z):
    length = math.sqrt(x * x + y * y + z * z)
    inverse = 1.0 / (length if length > 0.0 else 1.0)
    return x * inverse, y * inverse, z * inverse, length


@njit(inline="always", **_JIT)
def _unit2(x, y):
    length = math.sqrt(x * x + y * y)
    inverse = 1.0 / (length if length > 0.0 else 1.0)
    return x * inverse, y * inverse, length


@njit(inline="always", **_JIT)
def _edge(P, low, high):
    """(unit edge, edge, length) from corner ``low`` to corner ``high``."""
    ex, ey, ez = P[high, 0] - P[low, 0], P[high, 1] - P[low, 1], P[high, 2] - P[low, 2]
    ux, uy, uz, length = _unit3(ex, ey, ez)
    return (ux, uy, uz), (ex, ey, ez), length


@njit(inline="always", **_JIT)
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(inline="always", **_JIT)
def _cross3(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(inline="always", **_JIT)
def _axis(P, l0, l1, l2, l3, step, tolerance):
    """The four edges along one axis (low corners l0..l3 for the offsets (0,0), (1,0), (0,1), (1,1)
    along the other two axes): their unit vectors, the unit principal direction (unit sum of the
    edges), the mean edge length, and whether an edge is not longer than ``tolerance``."""
    u0, e0, d0 = _edge(P, l0, l0 + step)
    u1, e1, d1 = _edge(P, l1, l1 + step)
    u2, e2, d2 = _edge(P, l2, l2 + step)
    u3, e3, d3 = _edge(P, l3, l3 + step)
    sx = e0[0] + e1[0] + e2[0] + e3[0]
    sy = e0[1] + e1[1] + e2[1] + e3[1]
    sz = e0[2] + e1[2] + e2[2] + e3[2]
    px, py, pz, _ = _unit3(sx, sy, sz)
    short = _short(d0, tolerance) or _short(d1, tolerance) or _short(d2, tolerance) or _short(d3, tolerance)
    return (u0, u1, u2, u3), (px, py, pz), (d0 + d1 + d2 + d3) * 0.25, short


@njit(inline="always", **_JIT)
def _corner_jacobian(U0, U1, U2, s0, s1, s2):
    """det of the forward unit edges at corner (s0, s1, s2), and u1 x u2 (the corner normal of
    the face normal to axis 0 there)."""
    normal = _cross3(U1[s0 + 2 * s2], U2[s0 + 2 * s1])
    return _dot3(U0[s1 + 2 * s2], normal), normal


@njit(inline="always", **_JIT)
def _face(P, G, N, face, ua0, ua1, ub0, ub1, q00, q10, q01, q11, principal, normals):
    """One hex face: (largest and smallest corner cosine, reflex corner?, |n . principal|,
    |n . unit direction to the neighbour's centroid|). ``ua0, ua1``: unit edges along the face's
    first axis at offset 0, 1 along the second; ``ub0, ub1`` along the second; ``normals``: the
    corner normals ua x ub at corners (0,0), (1,0), (1,1), (0,1) where known (axis 0), else None."""
    d1 = (P[q11, 0] - P[q00, 0], P[q11, 1] - P[q00, 1], P[q11, 2] - P[q00, 2])
    d2 = (P[q01, 0] - P[q10, 0], P[q01, 1] - P[q10, 1], P[q01, 2] - P[q10, 2])
    n = _cross3(d1, d2)
    c0, c1, c2, c3 = _dot3(ua0, ub0), -_dot3(ua0, ub1), _dot3(ua1, ub1), -_dot3(ua1, ub0)
    if normals is None:
        m0, m1 = _cross3(n, ua0), _cross3(n, ua1)
        r0, r1, r2, r3 = _dot3(m0, ub0), _dot3(m0, ub1), _dot3(m1, ub1), _dot3(m1, ub0)
    else:
        r0, r1, r2, r3 = _dot3(n, normals[0]), _dot3(n, normals[1]), _dot3(n, normals[2]), _dot3(n, normals[3])
    reflex = min(min(r0, r1), min(r2, r3)) < 0.0
    unx, uny, unz, _ = _unit3(n[0], n[1], n[2])
    centroid_cosine = abs(unx * principal[0] + uny * principal[1] + unz * principal[2])
    dx, dy, dz = N[face, 0] - G[0], N[face, 1] - G[1], N[face, 2] - G[2]
    if not math.isfinite(dx + dy + dz):
        dx, dy, dz = principal
    tx, ty, tz, _ = _unit3(dx, dy, dz)
    face_cosine = abs(unx * tx + uny * ty + unz * tz)
    return max(max(c0, c1), max(c2, c3)), min(min(c0, c1), min(c2, c3)), reflex, centroid_cosine, face_cosine


@njit(**_JIT)
def _hex_cell(P, G, N, tolerance, out, degenerate, c):
    """Metrics of one hexahedron into ``out[:, c]``, ``degenerate[c]``.

    ``P`` (8, 3) corners by q; ``G`` (3,) its centroid; ``N`` (6, 3) centroid of the cell across
    face (axis, side) at row 2 axis + side, NaN where there is none. Unit edges ``U<axis>[t]``,
    t = t0 + 2 t1 for the offsets (t0, t1) along the other two axes, ascending."""
    U0, p0, m0, short0 = _axis(P, 0, 2, 4, 6, 1, tolerance)
    U1, p1, m1, short1 = _axis(P, 0, 1, 4, 5, 2, tolerance)
    U2, p2, m2, short2 = _axis(P, 0, 1, 2, 3, 4, tolerance)
    degenerate[c] = short0 or short1 or short2
    longest = max(max(m0, m1), m2)
    shortest = min(min(m0, m1), m2)
    aspect_ratio = longest / shortest if shortest > 0.0 else np.inf

    j000, n000 = _corner_jacobian(U0, U1, U2, 0, 0, 0)
    j100, n100 = _corner_jacobian(U0, U1, U2, 1, 0, 0)
    j010, n010 = _corner_jacobian(U0, U1, U2, 0, 1, 0)
    j110, n110 = _corner_jacobian(U0, U1, U2, 1, 1, 0)
    j001, n001 = _corner_jacobian(U0, U1, U2, 0, 0, 1)
    j101, n101 = _corner_jacobian(U0, U1, U2, 1, 0, 1)
    j011, n011 = _corner_jacobian(U0, U1, U2, 0, 1, 1)
    j111, n111 = _corner_jacobian(U0, U1, U2, 1, 1, 1)
    scaled_jacobian = _nanmin(
        _nanmin(_nanmin(j000, j100), _nanmin(j110, j010)), _nanmin(_nanmin(j001, j101), _nanmin(j111, j011))
    )

    # Faces (axis, side) -> row 2 axis + side; per face (ua0, ua1, ub0, ub1) and corners q00, q10,
    # q01, q11 (offsets along its first and second axis).
    f0 = _face(P, G, N, 0, U1[0], U1[2], U2[0], U2[2], 0, 2, 4, 6, p0, (n000, n010, n011, n001))
    f1 = _face(P, G, N, 1, U1[1], U1[3], U2[1], U2[3], 1, 3, 5, 7, p0, (n100, n110, n111, n101))
    f2 = _face(P, G, N, 2, U0[0], U0[2], U2[0], U2[1], 0, 1, 4, 5, p1, None)
    f3 = _face(P, G, N, 3, U0[1], U0[3], U2[2], U2[3], 2, 3, 6, 7, p1, None)
    f4 = _face(P, G, N, 4, U0[0], U0[1], U1[0], U1[1], 0, 1, 2, 3, p2, None)
    f5 = _face(P, G, N, 5, U0[2], U0[3], U1[2], U1[3], 4, 5, 6, 7, p2, None)

    largest_cosine = max(max(max(f0[0], f1[0]), max(f2[0], f3[0])), max(f4[0], f5[0]))
    smallest_cosine = min(min(min(f0[1], f1[1]), min(f2[1], f3[1])), min(f4[1], f5[1]))
    reflex_cosine = -2.0
    for f in (f0, f1, f2, f3, f4, f5):
        if f[2]:
            reflex_cosine = max(reflex_cosine, f[1])
    any_reflex = f0[2] or f1[2] or f2[2] or f3[2] or f4[2] or f5[2]
    centroid_alignment = min(min(min(f0[3], f1[3]), min(f2[3], f3[3])), min(f4[3], f5[3]))
    face_alignment = min(min(min(f0[4], f1[4]), min(f2[4], f3[4])), min(f4[4], f5[4]))
    _finish(largest_cosine, smallest_cosine, reflex_cosine, any_reflex, aspect_ratio, centroid_alignment, face_alignment,
            scaled_jacobian, out, c)  # fmt: skip


@njit(inline="always", **_JIT)
def _finish(largest_cosine, smallest_cosine, reflex_cosine, any_reflex, aspect_ratio, centroid_alignment, face_alignment,
            scaled_jacobian, out, c):  # fmt: skip
    min_angle = _degrees_of_cosine(largest_cosine)
    max_angle = 360.0 - _degrees_of_cosine(reflex_cosine) if any_reflex else _degrees_of_cosine(smallest_cosine)
    out[0, c] = min_angle
    out[1, c] = max_angle
    out[2, c] = max((max_angle - 90.0) / 90.0, (90.0 - min_angle) / 90.0)
    out[3, c] = aspect_ratio
    out[4, c] = 1.0 - centroid_alignment
    out[5, c] = _degrees_of_cosine(face_alignment)
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


# ---------------------------------------------------------------------------------------------
# drivers


@njit(parallel=True, **_JIT)
def structured_hex(X, first, last, tolerance, out, degenerate):
    """Metrics of the cells first[d] <= index < last[d] of node array ``X`` (n1+1, n2+1, n3+1, 3)
    (the other cells serve as face neighbours) into ``out`` (7, m) and ``degenerate`` (m,), m the
    number of those cells, in C order."""
    n1, n2, n3 = X.shape[0] - 1, X.shape[1] - 1, X.shape[2] - 1
    centroid = np.empty((n1, n2, n3, 3))
    for i in prange(n1):
        for j in range(n2):
            for k in range(n3):
                for d in range(3):
                    s = X[i, j, k, d]
                    s = s + X[i + 1, j, k, d]
                    s = s + X[i + 1, j + 1, k, d]
                    s = s + X[i, j + 1, k, d]
                    s = s + X[i, j, k + 1, d]
                    s = s + X[i + 1, j, k + 1, d]
                    s = s + X[i + 1, j + 1, k + 1, d]
                    s = s + X[i, j + 1, k + 1, d]
                    centroid[i, j, k, d] = s * 0.125
    m2, m3 = last[1] - first[1], last[2] - first[2]
    for i in prange(first[0], last[0]):
        P = np.empty((8, 3))
        N = np.empty((6, 3))
        for j in range(first[1], last[1]):
            for k in range(first[2], last[2]):
                for q in range(8):
                    for d in range(3):
                        P[q, d] = X[i + (q & 1), j + ((q >> 1) & 1), k + (q >> 2), d]
                for face in range(6):
                    axis, side = face >> 1, face & 1
                    ni, nj, nk = i, j, k
                    delta = 1 if side else -1
                    if axis == 0:
                        ni += delta
                    elif axis == 1:
                        nj += delta
                    else:
                        nk += delta
                    if 0 <= ni < n1 and 0 <= nj < n2 and 0 <= nk < n3:
                        for d in range(3):
                            N[face, d] = centroid[ni, nj, nk, d]
                    else:
                        for d in range(3):
                            N[face, d] = np.nan
                c = ((i - first[0]) * m2 + (j - first[1])) * m3 + (k - first[2])
                _hex_cell(P, centroid[i, j, k], N, tolerance, out, degenerate, c)


@njit(parallel=True, **_JIT)
def structured_quad(X, first, last, tolerance, orientation, out, degenerate):
    """``structured_hex`` for a 2D node array (n1+1, n2+1, 2)."""
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
def unstructured_hex(points, cells, neighbour, tolerance, out, degenerate):
    """Metrics of hexahedra ``cells`` (M, 8) (VTK corner order) on ``points`` (N, 3); ``neighbour``
    (6, M): the cell across each face (row 2 axis + side), -1 for none."""
    centroid = _centroids(points, cells)
    n = cells.shape[0]
    chunk = 1024
    for block in prange((n + chunk - 1) // chunk):
        P = np.empty((8, 3))
        N = np.empty((6, 3))
        for c in range(block * chunk, min(n, (block + 1) * chunk)):
            for k in range(8):
                for d in range(3):
                    P[HEX_Q_OF_VTK[k], d] = points[cells[c, k], d]
            for face in range(6):
                other = neighbour[face, c]
                for d in range(3):
                    N[face, d] = centroid[other, d] if other >= 0 else np.nan
            _hex_cell(P, centroid[c], N, tolerance, out, degenerate, c)


@njit(parallel=True, **_JIT)
def unstructured_quad(points, cells, neighbour, tolerance, orientation, out, degenerate):
    """``unstructured_hex`` for quads ``cells`` (M, 4) on ``points`` (N, 2); ``neighbour`` (4, M)."""
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


@njit(parallel=True, **_JIT)
def finite_extent(points):
    """Per component (min, max) of the finite rows of ``points`` (N, d), and the number of rows
    with a non-finite coordinate; (inf, -inf) when no row is finite."""
    n, dim = points.shape
    chunk = 65536
    blocks = (n + chunk - 1) // chunk
    low = np.full((blocks, dim), np.inf)
    high = np.full((blocks, dim), -np.inf)
    bad = np.zeros(blocks, dtype=np.int64)
    for block in prange(blocks):
        for r in range(block * chunk, min(n, (block + 1) * chunk)):
            finite = True
            for d in range(dim):
                if not math.isfinite(points[r, d]):
                    finite = False
            if not finite:
                bad[block] += 1
                continue
            for d in range(dim):
                v = points[r, d]
                if v < low[block, d]:
                    low[block, d] = v
                if v > high[block, d]:
                    high[block, d] = v
    lows = np.empty(dim)
    highs = np.empty(dim)
    for d in range(dim):
        lows[d] = low[:, d].min()
        highs[d] = high[:, d].max()
    return lows, highs, bad.sum()
