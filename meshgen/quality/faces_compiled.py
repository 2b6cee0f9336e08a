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


@njit(parallel=True, **_JIT)
def _faces(X, corners, centres, areas):
    """Centres and area vectors of the faces whose corner offsets are ``corners`` (4, 3), into
    ``centres`` and ``areas`` (face grid + (3,))."""
    n0, n1, n2 = centres.shape[0], centres.shape[1], centres.shape[2]
    for i in prange(n0):
        for j in range(n1):
            for k in range(n2):
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
                # The four triangles in order (sums from zero, as the NumPy definition adds them).
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
                    centres[i, j, k, 0] = t0 * scale
                    centres[i, j, k, 1] = t1 * scale
                    centres[i, j, k, 2] = t2 * scale
                else:
                    centres[i, j, k, 0] = e0
                    centres[i, j, k, 1] = e1
                    centres[i, j, k, 2] = e2
                areas[i, j, k, 0] = 0.5 * s0
                areas[i, j, k, 1] = 0.5 * s1
                areas[i, j, k, 2] = 0.5 * s2


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
