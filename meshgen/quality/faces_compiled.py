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

import numba
import numpy as np
from numba import njit, prange

# Dask's worker threads may call numba kernels at once: numba's workqueue layer aborts on
# concurrent calls, TBB and OpenMP do not. Unless the user chose a layer, take one of those (as
# ``meshgen.quality.compiled`` does; whichever module numba loads first sets it).
if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "threadsafe"

__all__ = ["cell_centres", "face_centres_and_areas", "face_cosines"]

ROOT_VSMALL = 1e-150  # OpenFOAM's ROOTVSMALL (double), added to |d| |S|
_JIT = {"cache": True, "fastmath": False, "nogil": True, "error_model": "numpy"}
# Corner offsets (di, dj, dk) of the faces normal to each axis, in the cyclic order whose right-hand
# normal points along +axis on a right-handed map (``faces_openfoam._face_corners``).
_CORNERS = np.zeros((3, 4, 3), dtype=np.int64)
for _axis, (_first, _second) in enumerate([(1, 2), (2, 0), (0, 1)]):
    for _m, (_a, _b) in enumerate([(0, 0), (1, 0), (1, 1), (0, 1)]):
        _CORNERS[_axis, _m, _first] = _a
        _CORNERS[_axis, _m, _second] = _b


@njit(parallel=True, **_JIT)
def _faces(X, corners, centres, areas):
    """Centres and area vectors of the faces whose corner offsets are ``corners`` (4, 3), into
    ``centres`` and ``areas`` (face grid + (3,))."""
    n0, n1, n2 = centres.shape[0], centres.shape[1], centres.shape[2]
    for i in prange(n0):
        p = np.empty((4, 3))
        estimate = np.empty(3)
        sum_n = np.empty(3)
        sum_ac = np.empty(3)
        for j in range(n1):
            for k in range(n2):
                for m in range(4):
                    for c in range(3):
                        p[m, c] = X[i + corners[m, 0], j + corners[m, 1], k + corners[m, 2], c]
                for c in range(3):
                    estimate[c] = 0.25 * (p[0, c] + p[1, c] + p[2, c] + p[3, c])
                    sum_n[c] = 0.0
                    sum_ac[c] = 0.0
                sum_a = 0.0
                for m in range(4):
                    following = (m + 1) % 4
                    e0 = p[following, 0] - p[m, 0]
                    e1 = p[following, 1] - p[m, 1]
                    e2 = p[following, 2] - p[m, 2]
                    f0 = estimate[0] - p[m, 0]
                    f1 = estimate[1] - p[m, 1]
                    f2 = estimate[2] - p[m, 2]
                    n0_ = e1 * f2 - e2 * f1
                    n1_ = e2 * f0 - e0 * f2
                    n2_ = e0 * f1 - e1 * f0
                    a = math.sqrt(n0_ * n0_ + n1_ * n1_ + n2_ * n2_)
                    sum_a += a
                    sum_n[0] += n0_
                    sum_n[1] += n1_
                    sum_n[2] += n2_
                    for c in range(3):
                        sum_ac[c] += a * (p[m, c] + p[following, c] + estimate[c])
                if sum_a > 0:
                    scale = 1.0 / (3.0 * sum_a)
                    for c in range(3):
                        centres[i, j, k, c] = sum_ac[c] * scale
                else:
                    for c in range(3):
                        centres[i, j, k, c] = estimate[c]
                for c in range(3):
                    areas[i, j, k, c] = 0.5 * sum_n[c]


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
def _pyramid(C, A, estimate, outward, volume_weighted, i, j, k):
    """Add the pyramid of the face (centre ``C[i, j, k]``, area ``A[i, j, k]``, ``outward`` +-1) to
    ``volume_weighted`` [volume, weighted x, y, z]."""
    dot = A[i, j, k, 0] * (C[i, j, k, 0] - estimate[0])
    dot += A[i, j, k, 1] * (C[i, j, k, 1] - estimate[1])
    dot += A[i, j, k, 2] * (C[i, j, k, 2] - estimate[2])
    pyramid = outward * dot
    volume_weighted[0] += pyramid
    for c in range(3):
        volume_weighted[1 + c] += pyramid * (0.75 * C[i, j, k, c] + 0.25 * estimate[c])


@njit(parallel=True, **_JIT)
def _cells(C0, A0, C1, A1, C2, A2, sign, out):
    n0, n1, n2 = out.shape[0], out.shape[1], out.shape[2]
    for i in prange(n0):
        estimate = np.empty(3)
        sums = np.empty(4)
        for j in range(n1):
            for k in range(n2):
                for c in range(3):
                    total = C0[i, j, k, c] + C0[i + 1, j, k, c]
                    total += C1[i, j, k, c] + C1[i, j + 1, k, c]
                    total += C2[i, j, k, c] + C2[i, j, k + 1, c]
                    estimate[c] = total / 6.0
                for s in range(4):
                    sums[s] = 0.0
                _pyramid(C0, A0, estimate, -sign, sums, i, j, k)
                _pyramid(C0, A0, estimate, sign, sums, i + 1, j, k)
                _pyramid(C1, A1, estimate, -sign, sums, i, j, k)
                _pyramid(C1, A1, estimate, sign, sums, i, j + 1, k)
                _pyramid(C2, A2, estimate, -sign, sums, i, j, k)
                _pyramid(C2, A2, estimate, sign, sums, i, j, k + 1)
                volume = sums[0]
                for c in range(3):
                    out[i, j, k, c] = sums[1 + c] / volume if abs(volume) > 1e-300 else estimate[c]


def cell_centres(faces, sign: float) -> np.ndarray:
    """``faces_openfoam.cell_centres`` from the three axes' :func:`face_centres_and_areas`
    ``faces`` and the map's orientation ``sign`` (+1 or -1): (n1, n2, n3, 3)."""
    (C0, A0), (C1, A1), (C2, A2) = faces
    out = np.empty((C1.shape[0], C0.shape[1], C0.shape[2], 3))
    if out.size:
        _cells(C0, A0, C1, A1, C2, A2, float(sign), out)
    return out


@njit(inline="always", **_JIT)
def _cosine(d0, d1, d2, s0, s1, s2):
    """faceOrthogonality's cosine of the angle between d and S."""
    dot = d0 * s0 + d1 * s1 + d2 * s2
    lengths = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) * math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return dot / (lengths + ROOT_VSMALL)


@njit(parallel=True, **_JIT)
def _internal(C, areas, step, sign, out):
    """Cosines of the internal faces: out[i, j, k] for the face between cells (i, j, k) and
    (i, j, k) + ``step`` (one unit along the axis), the face at node layer + ``step``."""
    n0, n1, n2 = out.shape[0], out.shape[1], out.shape[2]
    for i in prange(n0):
        for j in range(n1):
            for k in range(n2):
                i1, j1, k1 = i + step[0], j + step[1], k + step[2]
                out[i, j, k] = _cosine(
                    C[i1, j1, k1, 0] - C[i, j, k, 0],
                    C[i1, j1, k1, 1] - C[i, j, k, 1],
                    C[i1, j1, k1, 2] - C[i, j, k, 2],
                    sign * areas[i1, j1, k1, 0],
                    sign * areas[i1, j1, k1, 1],
                    sign * areas[i1, j1, k1, 2],
                )


def face_cosines(C: np.ndarray, faces, axis: int, sign: float):
    """Cosines of the faces normal to ``axis`` (``faces``: that axis's centres and areas, ``C``:
    the cell centres, ``sign``: the orientation): the internal faces (node layers 1 to n-1 along
    ``axis``) and the boundary faces of layer 0 and of the last layer (each with that axis dropped),
    as ``faces_openfoam.non_orthogonality`` defines them."""
    centres, areas = faces
    shape = list(C.shape[:-1])
    shape[axis] -= 1
    internal = np.empty(shape)
    step = np.zeros(3, dtype=np.int64)
    step[axis] = 1
    if internal.size:
        _internal(C, areas, step, float(sign), internal)
    boundary = []
    last = centres.shape[axis] - 1
    for side, outward, cell in ((0, -1.0, 0), (last, 1.0, -1)):
        d = np.take(centres, side, axis) - np.take(C, cell, axis)
        S = outward * (sign * np.take(areas, side, axis))
        dot = d[..., 0] * S[..., 0] + d[..., 1] * S[..., 1] + d[..., 2] * S[..., 2]
        lengths = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]) * np.sqrt(
            S[..., 0] * S[..., 0] + S[..., 1] * S[..., 1] + S[..., 2] * S[..., 2]
        )
        boundary.append(dot / (lengths + ROOT_VSMALL))
    return internal, boundary
