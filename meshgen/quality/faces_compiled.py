"""OpenFOAM's face and cell geometry of a structured 3D node array as compiled numba kernels: the
face centres and area vectors, the cell centres, and the cosines of the internal and boundary
faces' non-orthogonality that ``meshgen.quality.faces_openfoam`` defines and summarises.

Each kernel is the NumPy definition of ``faces_openfoam`` written per face or per cell, operation
by operation in IEEE double precision (``fastmath`` off, the same order of sums), in parallel over
the first index (``prange``). Only the dot products differ: NumPy's ``einsum`` may sum the three
products in another order, so the two agree to round-off (tested to 1e-12), not to the bit. The
NumPy definition makes some 60 full-size temporaries per face family (0.75 s of CPU at 1e6 cells);
the kernels make none beside their outputs.

Arrays are as in ``faces_openfoam``: ``X`` (n1+1, n2+1, n3+1, 3); the faces normal to ``axis``
shaped like the node layers along ``axis`` and the cells along the others, + (3,); cell centres
(n1, n2, n3, 3). Compiled code is cached on disk (``cache=True``).
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

__all__ = ["boundary_cosines", "boundary_faces", "cell_centres", "face_centres_and_areas", "internal_cosines"]

CHUNK_LAYERS = 4  # layers of cells along the first axis a task of ``cell_centres`` (its faces between tasks twice)
ROOT_VSMALL = 1e-150  # OpenFOAM's ROOTVSMALL (double), added to |d| |S|
_JIT = {"cache": True, "fastmath": False, "nogil": True, "error_model": "numpy"}
# Corner offsets (di, dj, dk) of the faces normal to each axis, in the cyclic order whose right-hand
# normal points along +axis on a right-handed map (``faces_openfoam._face_corners``).
_CORNERS = np.zeros((3, 4, 3), dtype=np.int64)
for _axis, (_first, _second) in enumerate([(1, 2), (2, 0), (0, 1)]):
    for _m, (_a, _b) in enumerate([(0, 0), (1, 0), (1, 1), (0, 1)]):
        _CORNERS[_axis, _m, _first] = _a
        _CORNERS[_axis, _m, _second] = _b


@njit(inline="always", **_JIT)
def _triangle(p0, p1, p2, q0, q1, q2, e0, e1, e2):
    """The triangle (p, q, estimate e) of a face's decomposition: its normal n = (q - p) x (e - p)
    (three components), |n|, and the weighted centre sum's term |n| (p + q + e)."""
    a0, a1, a2 = q0 - p0, q1 - p1, q2 - p2
    f0, f1, f2 = e0 - p0, e1 - p1, e2 - p2
    n0 = a1 * f2 - a2 * f1
    n1 = a2 * f0 - a0 * f2
    n2 = a0 * f1 - a1 * f0
    a = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    return n0, n1, n2, a, a * (p0 + q0 + e0), a * (p1 + q1 + e1), a * (p2 + q2 + e2)


@njit(inline="always", **_JIT)
def _face(X, corners, i, j, k):
    """Centre and area vector (six numbers) of the face whose corners are ``X`` at (i, j, k) plus
    the offsets ``corners`` (4, 3): the triangles about the mean of its corners, summed in order
    from zero as the NumPy definition adds them."""
    pa = X[i + corners[0, 0], j + corners[0, 1], k + corners[0, 2]]
    pb = X[i + corners[1, 0], j + corners[1, 1], k + corners[1, 2]]
    pc = X[i + corners[2, 0], j + corners[2, 1], k + corners[2, 2]]
    pd = X[i + corners[3, 0], j + corners[3, 1], k + corners[3, 2]]
    a0, a1, a2 = pa[0], pa[1], pa[2]
    b0, b1, b2 = pb[0], pb[1], pb[2]
    c0, c1, c2 = pc[0], pc[1], pc[2]
    d0, d1, d2 = pd[0], pd[1], pd[2]
    e0 = 0.25 * (a0 + b0 + c0 + d0)
    e1 = 0.25 * (a1 + b1 + c1 + d1)
    e2 = 0.25 * (a2 + b2 + c2 + d2)
    s0, s1, s2, sa, t0, t1, t2 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for m in range(4):
        if m == 0:
            r = _triangle(a0, a1, a2, b0, b1, b2, e0, e1, e2)
        elif m == 1:
            r = _triangle(b0, b1, b2, c0, c1, c2, e0, e1, e2)
        elif m == 2:
            r = _triangle(c0, c1, c2, d0, d1, d2, e0, e1, e2)
        else:
            r = _triangle(d0, d1, d2, a0, a1, a2, e0, e1, e2)
        sa += r[3]
        s0 += r[0]
        s1 += r[1]
        s2 += r[2]
        t0 += r[4]
        t1 += r[5]
        t2 += r[6]
    if sa > 0:
        scale = 1.0 / (3.0 * sa)
        e0, e1, e2 = t0 * scale, t1 * scale, t2 * scale
    return e0, e1, e2, 0.5 * s0, 0.5 * s1, 0.5 * s2


@njit(parallel=True, **_JIT)
def _faces(X, corners, centres, areas):
    """Centres and area vectors of the faces whose corner offsets are ``corners`` (4, 3), into
    ``centres`` and ``areas`` (face grid + (3,))."""
    n0, n1, n2 = centres.shape[0], centres.shape[1], centres.shape[2]
    for i in prange(n0):
        for j in range(n1):
            for k in range(n2):
                face = _face(X, corners, i, j, k)
                for c in range(3):
                    centres[i, j, k, c] = face[c]
                    areas[i, j, k, c] = face[3 + c]


def face_centres_and_areas(X: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """``faces_openfoam.face_centres_and_areas`` of the 3D node array ``X`` (contiguous float64)."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    shape = [n - 1 for n in X.shape[:-1]]
    shape[axis] += 1
    centres = np.empty((*shape, 3))
    areas = np.empty((*shape, 3))
    if min(shape) > 0:
        _faces(X, _CORNERS[axis], centres, areas)
    return centres, areas


@njit(inline="always", **_JIT)
def _store(faces, face):
    for c in range(6):
        faces[c] = face[c]


@njit(parallel=True, **_JIT)
def _cells(X, corners, out, chunk):
    """Cell centres of the node array ``X`` into ``out`` (n1, n2, n3, 3), ``chunk`` layers of cells
    along the first axis a task. Each face is computed once (``_face``) for the two cells beside
    it (within a task): the faces normal to the first axis a layer at a time, to the second a row,
    to the third one by one; then per cell the mean of its six face centres and its pyramids in the
    NumPy definition's order (the faces at the lower and the upper node layer along the first axis,
    the second, the third), each sum from zero. The pyramids take the outward normals of a
    right-handed map: a left-handed map negates every pyramid and every sum exactly, so the
    centres (their ratio) are the same to the bit."""
    n0, n1, n2 = out.shape[0], out.shape[1], out.shape[2]
    for block in prange((n0 + chunk - 1) // chunk):
        first, stop = block * chunk, min(block * chunk + chunk, n0)
        lower, upper = np.empty((n1, n2, 6)), np.empty((n1, n2, 6))  # centre, area vector
        front, back = np.empty((n2, 6)), np.empty((n2, 6))
        faces = np.empty((6, 6))
        estimate = np.empty(3)
        sums = np.empty(4)
        for j in range(n1):
            for k in range(n2):
                _store(lower[j, k], _face(X, corners[0], first, j, k))
        for i in range(first, stop):
            for j in range(n1):
                for k in range(n2):
                    _store(upper[j, k], _face(X, corners[0], i + 1, j, k))
            for k in range(n2):
                _store(front[k], _face(X, corners[1], i, 0, k))
            for j in range(n1):
                for k in range(n2):
                    _store(back[k], _face(X, corners[1], i, j + 1, k))
                _store(faces[5], _face(X, corners[2], i, j, 0))
                for k in range(n2):
                    for c in range(6):
                        faces[0, c] = lower[j, k, c]
                        faces[1, c] = upper[j, k, c]
                        faces[2, c] = front[k, c]
                        faces[3, c] = back[k, c]
                        faces[4, c] = faces[5, c]
                    _store(faces[5], _face(X, corners[2], i, j, k + 1))
                    for c in range(3):
                        total = faces[0, c] + faces[1, c]
                        total += faces[2, c] + faces[3, c]
                        total += faces[4, c] + faces[5, c]
                        estimate[c] = total / 6.0
                    for m in range(4):
                        sums[m] = 0.0
                    for slot in range(6):
                        dot = faces[slot, 3] * (faces[slot, 0] - estimate[0])
                        dot += faces[slot, 4] * (faces[slot, 1] - estimate[1])
                        dot += faces[slot, 5] * (faces[slot, 2] - estimate[2])
                        pyramid = (1.0 if slot % 2 else -1.0) * dot
                        sums[0] += pyramid
                        for c in range(3):
                            sums[1 + c] += pyramid * (0.75 * faces[slot, c] + 0.25 * estimate[c])
                    volume = sums[0]
                    for c in range(3):
                        out[i, j, k, c] = sums[1 + c] / volume if abs(volume) > 1e-300 else estimate[c]
                front, back = back, front
            lower, upper = upper, lower


def cell_centres(X: np.ndarray) -> np.ndarray:
    """``faces_openfoam.cell_centres`` of the 3D node array ``X`` (contiguous float64), computed
    from the nodes cell by cell (no face arrays): (n1, n2, n3, 3)."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    out = np.empty((*(n - 1 for n in X.shape[:-1]), 3))
    if out.size:
        _cells(X, _CORNERS, out, CHUNK_LAYERS)
    return out


@njit(inline="always", **_JIT)
def _cosine(d0, d1, d2, s0, s1, s2):
    """faceOrthogonality's cosine of the angle between d and S."""
    dot = d0 * s0 + d1 * s1 + d2 * s2
    lengths = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) * math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return dot / (lengths + ROOT_VSMALL)


@njit(parallel=True, **_JIT)
def _internal(X, corners, C, step, sign, sums, lows, where):
    """The internal faces normal to one axis (corner offsets ``corners``), face by face: the face
    between cells (i, j, k) and (i, j, k) + ``step`` lies at node layer (i, j, k) + ``step``. Per
    layer ``i`` of faces: the sum of their cosines in C order (``sums[i]``), the least (``lows[i]``,
    NaN if one is NaN, as ``np.min``) and its index within the layer (``where[i]``: the first NaN,
    else the first least, as ``np.argmin``)."""
    n0, n1, n2 = sums.shape[0], C.shape[1] - step[1], C.shape[2] - step[2]
    for i in prange(n0):
        total = 0.0
        low = np.inf
        at = -1
        flat = 0
        for j in range(n1):
            for k in range(n2):
                i1, j1, k1 = i + step[0], j + step[1], k + step[2]
                face = _face(X, corners, i1, j1, k1)
                cosine = _cosine(
                    C[i1, j1, k1, 0] - C[i, j, k, 0],
                    C[i1, j1, k1, 1] - C[i, j, k, 1],
                    C[i1, j1, k1, 2] - C[i, j, k, 2],
                    sign * face[3],
                    sign * face[4],
                    sign * face[5],
                )
                total += cosine
                if at < 0 or (not math.isnan(low) and (math.isnan(cosine) or cosine < low)):
                    low = cosine
                    at = flat
                flat += 1
        sums[i] = total
        lows[i] = low
        where[i] = at


def internal_cosines(X: np.ndarray, C: np.ndarray, axis: int, sign: float):
    """The cosines of the internal faces normal to ``axis`` (node layers 1 to n-1 along it) of the
    node array ``X`` with cell centres ``C`` and orientation ``sign`` (+1 or -1), reduced without
    an array of them: (sum, count, least, index of the least), as ``np.sum``, ``size``, ``np.min``
    and ``np.unravel_index(np.argmin)`` of that array (shaped like the cells, one fewer along
    ``axis``) give them; the sum is added layer by layer along the first axis, so it agrees with
    NumPy's to round-off. (0.0, 0, None, None) when there are none."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    shape = list(C.shape[:-1])
    shape[axis] -= 1
    if min(shape) <= 0:
        return 0.0, 0, None, None
    step = np.zeros(3, dtype=np.int64)
    step[axis] = 1
    sums, lows = np.empty(shape[0]), np.empty(shape[0])
    where = np.empty(shape[0], dtype=np.int64)
    _internal(X, _CORNERS[axis], C, step, float(sign), sums, lows, where)
    layer = int(np.argmin(lows))  # the first layer holding a NaN, else the first with the least
    index = np.unravel_index(layer * shape[1] * shape[2] + int(where[layer]), shape)
    return float(sums.sum()), int(np.prod(shape)), float(lows[layer]), tuple(int(i) for i in index)


def boundary_faces(X: np.ndarray, axis: int):
    """``face_centres_and_areas`` of the two boundary node layers along ``axis`` (first, last),
    each with that axis dropped: [(centres, areas), (centres, areas)], shapes (cells along the
    other two axes) + (3,)."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    sides = []
    for layer in (0, X.shape[axis] - 1):
        nodes = np.ascontiguousarray(np.take(X, [layer], axis=axis))
        centres, areas = face_centres_and_areas(nodes, axis)
        sides.append((np.take(centres, 0, axis), np.take(areas, 0, axis)))
    return sides


def boundary_cosines(C: np.ndarray, sides, axis: int, sign: float) -> list[np.ndarray]:
    """Cosines of the boundary faces normal to ``axis`` (``sides``: their ``boundary_faces``) with
    cell centres ``C`` and orientation ``sign``: first layer, last layer (that axis dropped)."""
    cosines = []
    for (centres, areas), outward, cell in zip(sides, (-1.0, 1.0), (0, -1)):
        d = centres - np.take(C, cell, axis)
        S = outward * (sign * areas)
        dot = d[..., 0] * S[..., 0] + d[..., 1] * S[..., 1] + d[..., 2] * S[..., 2]
        lengths = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]) * np.sqrt(
            S[..., 0] * S[..., 0] + S[..., 1] * S[..., 1] + S[..., 2] * S[..., 2]
        )
        cosines.append(dot / (lengths + ROOT_VSMALL))
    return cosines
