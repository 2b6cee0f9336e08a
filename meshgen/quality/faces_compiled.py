"""OpenFOAM's face and cell geometry of a structured 3D node array as compiled numba kernels: the
face centres and area vectors, the cell centres, and the cosines of the internal and boundary
faces' non-orthogonality that ``meshgen.quality.faces_openfoam`` defines and summarises.
``cells_and_internal_cosines`` is what the report calls: the cell centres and the internal faces'
cosines, reduced as they are computed, from the nodes alone (no face or cosine arrays: at 1e6 cells
those were 200 MB, and touching them the most of a fresh report's time; design notes §21).
``face_centres_and_areas`` writes the same faces (``_face``) as arrays, for the tests that hold
them to the NumPy definition to the bit.

Each kernel is the NumPy definition of ``faces_openfoam`` written per face or per cell, operation
by operation in IEEE double precision (``fastmath`` off, the same order of sums), in parallel over
the first index (``prange``). Only the dot products differ: NumPy's ``einsum`` may sum the three
products in another order, so the two agree to round-off (tested to 1e-12), not to the bit. The
NumPy definition makes some 60 full-size temporaries per face family (0.75 s of CPU at 1e6 cells);
the kernels make none beside their outputs and a few layers of faces per task.

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

__all__ = ["cell_centres", "cells_and_internal_cosines", "face_centres_and_areas"]

CHUNK_LAYERS = 4  # layers of cells along the first axis a task of ``_cells`` (the faces between tasks: twice)
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
    """``faces_openfoam.face_centres_and_areas`` of the 3D node array ``X`` (contiguous float64):
    the faces ``_cells`` computes, as arrays (the tests' view of them; the report needs none)."""
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


@njit(inline="always", **_JIT)
def _pyramid(face, estimate, outward, sums):
    """Add the pyramid of ``face`` (centre, area vector; ``outward`` +-1) about ``estimate`` to
    ``sums`` [volume, weighted x, y, z]."""
    dot = face[3] * (face[0] - estimate[0])
    dot += face[4] * (face[1] - estimate[1])
    dot += face[5] * (face[2] - estimate[2])
    pyramid = outward * dot
    sums[0] += pyramid
    for c in range(3):
        sums[1 + c] += pyramid * (0.75 * face[c] + 0.25 * estimate[c])


@njit(inline="always", **_JIT)
def _cosine(d0, d1, d2, s0, s1, s2):
    """faceOrthogonality's cosine of the angle between d and S."""
    dot = d0 * s0 + d1 * s1 + d2 * s2
    lengths = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) * math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return dot / (lengths + ROOT_VSMALL)


@njit(inline="always", **_JIT)
def _least(cosine, low, at, flat):
    """(least, its index) after ``cosine`` (the ``flat``-th), as ``np.min`` / ``np.argmin`` keep
    them: the first NaN, else the first least."""
    if at < 0 or (not math.isnan(low) and (math.isnan(cosine) or cosine < low)):
        return cosine, flat
    return low, at


@njit(inline="always", **_JIT)
def _layer_of_faces(X, corners, i, faces):
    """``faces[j, k]`` (centre, area vector): the faces at node layer ``i`` of the first axis."""
    for j in range(faces.shape[0]):
        for k in range(faces.shape[1]):
            _store(faces[j, k], _face(X, corners, i, j, k))


@njit(inline="always", **_JIT)
def _centre(lower, upper, front, back, side_low, side_high, estimate, sums):
    """A cell's centre from its six faces (centre, area vector each), in the NumPy definition's
    order (the faces at the lower and the upper node layer along the first axis, the second, the
    third), each sum from zero, with the outward normals of a right-handed map: (x, y, z)."""
    for c in range(3):
        total = lower[c] + upper[c]
        total += front[c] + back[c]
        total += side_low[c] + side_high[c]
        estimate[c] = total / 6.0
    for m in range(4):
        sums[m] = 0.0
    _pyramid(lower, estimate, -1.0, sums)
    _pyramid(upper, estimate, 1.0, sums)
    _pyramid(front, estimate, -1.0, sums)
    _pyramid(back, estimate, 1.0, sums)
    _pyramid(side_low, estimate, -1.0, sums)
    _pyramid(side_high, estimate, 1.0, sums)
    volume = sums[0]
    if abs(volume) > 1e-300:
        return sums[1] / volume, sums[2] / volume, sums[3] / volume
    return estimate[0], estimate[1], estimate[2]


@njit(inline="always", **_JIT)
def _layer_cosines(C, i, step, faces, shift, n1, n2, sign):
    """(sum, least, index of the least) of the cosines of the internal faces between the cells
    (i, j, k) and (i, j, k) + ``step``, j < ``n1`` and k < ``n2``, in C order; the face's area
    vector is ``faces[j + shift[0], k + shift[1], 3:6]`` (``_store``'s layout)."""
    total, low, at, flat = 0.0, np.inf, -1, 0
    for j in range(n1):
        for k in range(n2):
            i1, j1, k1 = i + step[0], j + step[1], k + step[2]
            area = faces[j + shift[0], k + shift[1]]
            cosine = _cosine(
                C[i1, j1, k1, 0] - C[i, j, k, 0],
                C[i1, j1, k1, 1] - C[i, j, k, 1],
                C[i1, j1, k1, 2] - C[i, j, k, 2],
                sign * area[3],
                sign * area[4],
                sign * area[5],
            )
            total += cosine
            low, at = _least(cosine, low, at, flat)
            flat += 1
    return total, low, at


@njit(inline="always", **_JIT)
def _cell_block(X, corners, sign, out, first, stop, sums, lows, where):
    """The cell centres of the layers of cells ``first`` to ``stop`` - 1 into ``out``, and the
    cosines of their internal faces but those to the layer below ``first`` (``_cells``)."""
    n1, n2 = out.shape[1], out.shape[2]
    steps = np.eye(3, dtype=np.int64)
    lower, upper = np.empty((n1, n2, 6)), np.empty((n1, n2, 6))  # centre, area vector
    across = np.empty((n1 + 1, n2, 6))  # the layer's faces normal to the second axis
    along = np.empty((n1, n2 + 1, 6))  # and to the third
    estimate, scratch = np.empty(3), np.empty(4)
    _layer_of_faces(X, corners[0], first, lower)
    for i in range(first, stop):
        _layer_of_faces(X, corners[0], i + 1, upper)
        for j in range(n1 + 1):
            for k in range(n2):
                _store(across[j, k], _face(X, corners[1], i, j, k))
        for j in range(n1):
            for k in range(n2 + 1):
                _store(along[j, k], _face(X, corners[2], i, j, k))
        for j in range(n1):
            for k in range(n2):
                centre = _centre(
                    lower[j, k], upper[j, k], across[j, k], across[j + 1, k], along[j, k], along[j, k + 1], estimate, scratch
                )
                for c in range(3):
                    out[i, j, k, c] = centre[c]
        if i > first:  # the faces at node layer i, to the layer below (``lower`` holds them)
            sums[0, i - 1], lows[0, i - 1], where[0, i - 1] = _layer_cosines(out, i - 1, steps[0], lower, (0, 0), n1, n2, sign)
        sums[1, i], lows[1, i], where[1, i] = _layer_cosines(out, i, steps[1], across, (1, 0), n1 - 1, n2, sign)
        sums[2, i], lows[2, i], where[2, i] = _layer_cosines(out, i, steps[2], along, (0, 1), n1, n2 - 1, sign)
        lower, upper = upper, lower


@njit(parallel=True, **_JIT)
def _cells(X, corners, sign, out, chunk, sums, lows, where):
    """Cell centres of the node array ``X`` into ``out`` (n1, n2, n3, 3), and the internal faces'
    cosines reduced per layer of faces: ``sums[axis, layer]`` their sum in C order, ``lows`` the
    least (NaN if one is NaN, as ``np.min``), ``where`` its index within the layer (the first NaN,
    else the first least, as ``np.argmin``).

    ``chunk`` layers of cells along the first axis a task (``_cell_block``): each face is computed
    once (``_face``) for the two cells beside it, into buffers (the faces normal to the first axis
    a node layer at a time, to the second and the third a layer of cells at a time), then each
    cell's centre (``_centre``). The pyramids take the outward normals of a right-handed map: a
    left-handed map negates every pyramid and every sum exactly, so the centres (their ratio) are
    the same to the bit. Once a layer of cells has its centres, the internal faces within it and
    those to the layer below (in the same task) get their cosines (``_layer_cosines``), ``sign``
    (the map's orientation) on the area vectors; the faces between two tasks' layers after every
    task is done, a layer of them at a time."""
    n0 = out.shape[0]
    for block in prange((n0 + chunk - 1) // chunk):
        _cell_block(X, corners, sign, out, block * chunk, min(block * chunk + chunk, n0), sums, lows, where)
    steps = np.eye(3, dtype=np.int64)
    for block in prange(1, (n0 + chunk - 1) // chunk):
        i = block * chunk - 1  # the cell layer below a task's first: the faces between them
        layer = np.empty((out.shape[1], out.shape[2], 6))
        _layer_of_faces(X, corners[0], i + 1, layer)
        sums[0, i], lows[0, i], where[0, i] = _layer_cosines(out, i, steps[0], layer, (0, 0), out.shape[1], out.shape[2], sign)


def cells_and_internal_cosines(X: np.ndarray, sign: float):
    """The cell centres (n1, n2, n3, 3) of the 3D node array ``X`` (``faces_openfoam.cell_centres``)
    and, for each axis, its internal faces' cosines with orientation ``sign`` (+1 or -1), reduced
    without an array of them: (sum, count, least, index of the least) as ``np.sum``, ``size``,
    ``np.min`` and ``np.unravel_index(np.argmin)`` of that array (shaped like the cells, one fewer
    along the axis) give them; (0.0, 0, None, None) where there are none. The sums are added layer
    by layer along the first axis, so they agree with NumPy's to round-off."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    cells = tuple(n - 1 for n in X.shape[:-1])
    C = np.empty((*cells, 3))
    sums, lows = np.zeros((3, max(cells[0], 1))), np.zeros((3, max(cells[0], 1)))
    where = np.full((3, max(cells[0], 1)), -1, dtype=np.int64)
    if C.size:
        _cells(X, _CORNERS, float(sign), C, CHUNK_LAYERS, sums, lows, where)
    reduced = []
    for axis in range(3):
        shape = list(cells)
        shape[axis] -= 1
        if min(shape) <= 0:
            reduced.append((0.0, 0, None, None))
            continue
        layer = int(np.argmin(lows[axis, : shape[0]]))  # the first layer holding a NaN, else the first least
        index = np.unravel_index(layer * shape[1] * shape[2] + int(where[axis, layer]), shape)
        total = float(sums[axis, : shape[0]].sum())
        reduced.append((total, int(np.prod(shape)), float(lows[axis, layer]), tuple(int(i) for i in index)))
    return C, reduced


def cell_centres(X: np.ndarray) -> np.ndarray:
    """``faces_openfoam.cell_centres`` of the 3D node array ``X``, computed from the nodes cell by
    cell (``cells_and_internal_cosines``' first part): (n1, n2, n3, 3)."""
    return cells_and_internal_cosines(X, 1.0)[0]
