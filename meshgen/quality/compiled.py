"""The per-cell metrics of hexahedra (definitions in ``meshgen.quality.kernels``) as compiled numba
kernels (quadrilaterals: ``meshgen.quality.compiled_quad``).

One function (``_hex_cell``) holds a cell's arithmetic; drivers feed it corner coordinates and
the centroids of the face neighbours, in parallel: structured node arrays in C order
(``structured_hex``), nodes by component in a CGNS file's order (``structured_hex_file_order``,
the block-wise evaluation of a file; no transpose), and points + connectivity
(``unstructured_hex``; neighbours from face matching). Centroids are summed in the VTK corner
order. The arithmetic follows the vectorised NumPy definition operation by operation, in IEEE
double precision (``fastmath=False``), and the angles come from the cosines through NumPy's own
``arccos`` (``meshgen.quality.angles``), so the kernels agree with the NumPy definition to
round-off (tested to 1e-12).

The structured drivers hand runs of consecutive planes of cells to threads; each run keeps rings
of three planes (node planes by component, centroid planes with a NaN layer), so each plane of
centroids is summed once, and loops over rows of cells that LLVM vectorises (AVX-512: 8 cells per
instruction; ``_hex_row``, ``_file_hex_row``).

A cell is written as corners ``P[q]``, q = s0 + 2 s1 + 4 s2 for the corner at offsets
(s0, s1, s2) from the cell's first node. Compiled code is cached on disk (``cache=True``): the
first call in a fresh installation compiles for some seconds, later processes load it. numba's
cache notices changes to a function's own file only, so the functions that call one another stay
in this file.
"""

from __future__ import annotations

import math
import os

import llvmlite.binding as llvm
import numpy as np
from numba import njit, prange, uint64

from meshgen.quality.angles import finish_hex_angles
from meshgen.quality.pool import map_in_threads, threads
from meshgen.run.jit import numba

# Dask's worker threads call the kernels at once (the chunked path): numba's workqueue layer aborts
# on concurrent calls, TBB and OpenMP do not. Unless the user chose a layer, take one of those.
if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "threadsafe"

__all__ = ["finite_extent", "for_runs_of_planes", "structured_hex", "structured_hex_file_order", "unstructured_hex"]

# VTK corner order of a hexahedron, as corner q (centroids are summed in this order).
HEX_Q_OF_VTK = np.array([0, 1, 3, 2, 4, 5, 7, 6])

# The row loop over cells (``_hex_row``) reads 2 arrays and writes 8 rows: LLVM checks at run time
# that they do not overlap, more checks than its default limits (8 and 128) allow, without which
# it would not vectorise the loop. Raised for this process's LLVM (it changes what loops may be
# vectorised, never the arithmetic of one).
llvm.set_option("", "-runtime-memory-check-threshold=1024")
llvm.set_option("", "-vectorize-memory-check-threshold=1024")

# Planes of cells are handed to threads in runs of consecutive planes, this many runs per thread
# (each run computes two planes of centroids beyond its own, so few runs; more than one, so that a
# thread the OS delays holds up less).
PLANE_RUNS_PER_THREAD = 4

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
def _unit3(x, y, z):
    length = math.sqrt(x * x + y * y + z * z)
    inverse = 1.0 / (length if length > 0.0 else 1.0)
    return x * inverse, y * inverse, z * inverse, length


@njit(inline="always", **_JIT)
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(inline="always", **_JIT)
def _edge(P, low, high):
    e = _sub(P[high], P[low])
    ux, uy, uz, length = _unit3(e[0], e[1], e[2])
    return (ux, uy, uz), e, length


@njit(inline="always", **_JIT)
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(inline="always", **_JIT)
def _cross3(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(inline="always", **_JIT)
def _axis(P, l0, l1, l2, l3, step, tolerance):
    u0, e0, d0 = _edge(P, l0, l0 + step)
    u1, e1, d1 = _edge(P, l1, l1 + step)
    u2, e2, d2 = _edge(P, l2, l2 + step)
    u3, e3, d3 = _edge(P, l3, l3 + step)
    sx = e0[0] + e1[0] + e2[0] + e3[0]
    sy = e0[1] + e1[1] + e2[1] + e3[1]
    sz = e0[2] + e1[2] + e2[2] + e3[2]
    px, py, pz, _ = _unit3(sx, sy, sz)
    short = _short(d0, tolerance) | _short(d1, tolerance) | _short(d2, tolerance) | _short(d3, tolerance)
    return (u0, u1, u2, u3), (px, py, pz), (d0 + d1 + d2 + d3) * 0.25, short


@njit(inline="always", **_JIT)
def _corner_jacobian(U0, U1, U2, s0, s1, s2):
    normal = _cross3(U1[s0 + 2 * s2], U2[s0 + 2 * s1])
    return _dot3(U0[s1 + 2 * s2], normal), normal


@njit(inline="always", **_JIT)
def _face(P, G, Nf, ua0, ua1, ub0, ub1, q00, q10, q01, q11, principal, normals):
    """One hex face: (largest and smallest corner cosine, reflex corner?, |n . principal|,
    |n . unit direction to the neighbour's centroid ``Nf``|). ``ua0, ua1``: unit edges along the
    face's first axis at offset 0, 1 along the second; ``ub0, ub1`` along the second; ``normals``:
    the corner normals ua x ub at corners (0,0), (1,0), (1,1), (0,1) where known (axis 0), else None."""
    d1 = _sub(P[q11], P[q00])
    d2 = _sub(P[q01], P[q10])
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
    dx, dy, dz = Nf[0] - G[0], Nf[1] - G[1], Nf[2] - G[2]
    finite = math.isfinite(dx + dy + dz)
    dx = dx if finite else principal[0]
    dy = dy if finite else principal[1]
    dz = dz if finite else principal[2]
    tx, ty, tz, _ = _unit3(dx, dy, dz)
    face_cosine = abs(unx * tx + uny * ty + unz * tz)
    return max(max(c0, c1), max(c2, c3)), min(min(c0, c1), min(c2, c3)), reflex, centroid_cosine, face_cosine


@njit(inline="always", **_JIT)
def _hex_cell(P, G, N, tolerance):
    """Metrics of one hexahedron, the angles still as cosines: (largest corner cosine, cosine of the
    largest angle, whether that is a reflex corner's, aspect ratio, non-orthogonality, face-alignment
    cosine, scaled Jacobian, degenerate).

    ``P`` 8 corners by q, each an (x, y, z) tuple; ``G`` its centroid; ``N`` 6 centroids of the cell
    across face (axis, side) at 2 axis + side, NaN where there is none. Unit edges ``U<axis>[t]``,
    t = t0 + 2 t1 for the offsets (t0, t1) along the other two axes, ascending. Branch-free (selects
    only), so that a loop over cells vectorises."""
    U0, p0, m0, short0 = _axis(P, 0, 2, 4, 6, 1, tolerance)
    U1, p1, m1, short1 = _axis(P, 0, 1, 4, 5, 2, tolerance)
    U2, p2, m2, short2 = _axis(P, 0, 1, 2, 3, 4, tolerance)
    degenerate = short0 | short1 | short2
    longest = max(max(m0, m1), m2)
    shortest = min(min(m0, m1), m2)
    aspect_ratio = longest / (shortest if shortest > 0.0 else 1.0) if shortest > 0.0 else np.inf
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
    f0 = _face(P, G, N[0], U1[0], U1[2], U2[0], U2[2], 0, 2, 4, 6, p0, (n000, n010, n011, n001))
    f1 = _face(P, G, N[1], U1[1], U1[3], U2[1], U2[3], 1, 3, 5, 7, p0, (n100, n110, n111, n101))
    f2 = _face(P, G, N[2], U0[0], U0[2], U2[0], U2[1], 0, 1, 4, 5, p1, None)
    f3 = _face(P, G, N[3], U0[1], U0[3], U2[2], U2[3], 2, 3, 6, 7, p1, None)
    f4 = _face(P, G, N[4], U0[0], U0[1], U1[0], U1[1], 0, 1, 2, 3, p2, None)
    f5 = _face(P, G, N[5], U0[2], U0[3], U1[2], U1[3], 4, 5, 6, 7, p2, None)
    largest_cosine = max(max(max(f0[0], f1[0]), max(f2[0], f3[0])), max(f4[0], f5[0]))
    smallest_cosine = min(min(min(f0[1], f1[1]), min(f2[1], f3[1])), min(f4[1], f5[1]))
    reflex_cosine = -2.0
    reflex_cosine = max(reflex_cosine, f0[1]) if f0[2] else reflex_cosine
    reflex_cosine = max(reflex_cosine, f1[1]) if f1[2] else reflex_cosine
    reflex_cosine = max(reflex_cosine, f2[1]) if f2[2] else reflex_cosine
    reflex_cosine = max(reflex_cosine, f3[1]) if f3[2] else reflex_cosine
    reflex_cosine = max(reflex_cosine, f4[1]) if f4[2] else reflex_cosine
    reflex_cosine = max(reflex_cosine, f5[1]) if f5[2] else reflex_cosine
    any_reflex = f0[2] | f1[2] | f2[2] | f3[2] | f4[2] | f5[2]
    centroid_alignment = min(min(min(f0[3], f1[3]), min(f2[3], f3[3])), min(f4[3], f5[3]))
    face_alignment = min(min(min(f0[4], f1[4]), min(f2[4], f3[4])), min(f4[4], f5[4]))
    max_cosine = reflex_cosine if any_reflex else smallest_cosine
    return (
        largest_cosine,
        max_cosine,
        any_reflex,
        aspect_ratio,
        1.0 - centroid_alignment,
        face_alignment,
        scaled_jacobian,
        degenerate,
    )


# ---------------------------------------------------------------------------------------------
# drivers


@njit(inline="always", **_JIT)
def _node(X, i, j, k):
    return (X[0, i, j, k], X[1, i, j, k], X[2, i, j, k])


@njit(**_JIT)
def _hex_row(nodes, centroid, a0, a1, cp, cc, cn, j, k0, k1, tolerance, out, degenerate, c0):
    """Cells (i, j, k0 <= k < k1) of one plane of cells i into ``out[:, c0 + k - k0]`` as
    ``_store_hex`` leaves them.

    ``nodes`` (3, 3, n2+1, n3+1) a ring of node planes by component, planes i and i+1 at slots
    ``a0``, ``a1``; ``centroid`` (3, 3, n2+2, n3+2) a ring of cell centroid planes with a layer of
    NaN around them, the cells i-1, i, i+1 at slots ``cp``, ``cc``, ``cn`` (cell (i, j, k) at
    [:, cc, j+1, k+1]), so that a missing face neighbour is NaN without a branch (``_node_plane``,
    ``_centroid_plane`` fill them). Unsigned indices and unit strides along k let LLVM vectorise
    this loop over cells: numba wraps negative signed indices, and a runtime stride makes LLVM
    version the loop on it being 1."""
    a0, a1, cp, cc, cn = uint64(a0), uint64(a1), uint64(cp), uint64(cc), uint64(cn)
    j, c0 = uint64(j), uint64(c0)
    one = uint64(1)
    j1, two = j + one, one + one
    for kk in range(uint64(k1 - k0)):
        k = kk + uint64(k0)
        P = (
            _node(nodes, a0, j, k),
            _node(nodes, a1, j, k),
            _node(nodes, a0, j1, k),
            _node(nodes, a1, j1, k),
            _node(nodes, a0, j, k + one),
            _node(nodes, a1, j, k + one),
            _node(nodes, a0, j1, k + one),
            _node(nodes, a1, j1, k + one),
        )
        kc = k + one
        G = _node(centroid, cc, j1, kc)
        N = (
            _node(centroid, cp, j1, kc),
            _node(centroid, cn, j1, kc),
            _node(centroid, cc, j, kc),
            _node(centroid, cc, j + two, kc),
            _node(centroid, cc, j1, k),
            _node(centroid, cc, j1, kc + one),
        )
        _store_hex(_hex_cell(P, G, N, tolerance), out, degenerate, c0 + kk)


@njit(inline="always", **_JIT)
def _store_hex(r, out, degenerate, c):
    """``_hex_cell``'s cosines and metrics into ``out[:, c]``; ``finish_hex_angles`` turns the
    cosines into angles."""
    out[0, c] = r[0]
    out[1, c] = r[1]
    out[2, c] = 1.0 if r[2] else 0.0
    out[3, c] = r[3]
    out[4, c] = r[4]
    out[5, c] = r[5]
    out[6, c] = r[6]
    degenerate[c] = r[7]


@njit(**_JIT)
def _node_plane(X, i, nodes, slot):
    """Node plane i of ``X`` (n1+1, n2+1, n3+1, 3) into ``nodes[:, slot]`` (by component)."""
    for j in range(X.shape[1]):
        for k in range(X.shape[2]):
            for d in range(3):
                nodes[d, slot, j, k] = X[i, j, k, d]


@njit(**_JIT)
def _centroid_plane(nodes, a0, a1, present, centroid, slot):
    """Centroids of a plane of cells into the interior of ``centroid[:, slot]`` (its NaN layer
    kept), from its node planes at slots ``a0``, ``a1`` of ``nodes``, summed in VTK corner order;
    NaN where the plane is not ``present`` (beyond the mesh)."""
    n2, n3 = nodes.shape[2] - 1, nodes.shape[3] - 1
    a0, a1, slot = uint64(a0), uint64(a1), uint64(slot)
    one = uint64(1)
    for d in range(3):
        for j in range(uint64(n2)):
            for k in range(uint64(n3)):
                s = nodes[d, a0, j, k]
                s = s + nodes[d, a1, j, k]
                s = s + nodes[d, a1, j + one, k]
                s = s + nodes[d, a0, j + one, k]
                s = s + nodes[d, a0, j, k + one]
                s = s + nodes[d, a1, j, k + one]
                s = s + nodes[d, a1, j + one, k + one]
                s = s + nodes[d, a0, j + one, k + one]
                centroid[d, slot, j + one, k + one] = s * 0.125 if present else np.nan


@njit(**_JIT)
def _hex_planes(X, i0, i1, first, last, tolerance, out, degenerate):
    """Cells of the planes i0 <= i < i1 of ``structured_hex``, in order, each node plane copied
    by component and each centroid plane summed once (rings of three planes: the cells i-1, i, i+1
    and the node planes i, i+1, i+2)."""
    n1, n2, n3 = X.shape[0] - 1, X.shape[1] - 1, X.shape[2] - 1
    m2, m3 = last[1] - first[1], last[2] - first[2]
    nodes = np.empty((3, 3, n2 + 1, n3 + 1))
    centroid = np.full((3, 3, n2 + 2, n3 + 2), np.nan)
    # node plane p at slot p % 3; cell plane c (c >= -1) at slot (c + 1) % 3
    if i0 >= 1:
        _node_plane(X, i0 - 1, nodes, (i0 - 1) % 3)
    _node_plane(X, i0, nodes, i0 % 3)
    _centroid_plane(nodes, (i0 - 1) % 3, i0 % 3, i0 >= 1, centroid, i0 % 3)
    _node_plane(X, i0 + 1, nodes, (i0 + 1) % 3)
    _centroid_plane(nodes, i0 % 3, (i0 + 1) % 3, True, centroid, (i0 + 1) % 3)
    for i in range(i0, i1):
        if i + 2 <= n1:
            _node_plane(X, i + 2, nodes, (i + 2) % 3)
        _centroid_plane(nodes, (i + 1) % 3, (i + 2) % 3, i + 1 < n1, centroid, (i + 2) % 3)
        for j in range(first[1], last[1]):
            c0 = ((i - first[0]) * m2 + (j - first[1])) * m3
            _hex_row(nodes, centroid, i % 3, (i + 1) % 3, i % 3, (i + 1) % 3, (i + 2) % 3, j, first[2], last[2],
                     tolerance, out, degenerate, c0)  # fmt: skip


def for_runs_of_planes(kernel, begin: int, end: int) -> None:
    """``kernel(p0, p1)`` over runs of consecutive planes covering [begin, end), the runs spread
    over the CPUs (``meshgen.quality.pool``; the kernels release the GIL). Threads rather than
    ``prange``: numba compiles a parallel loop around the inlined cell arithmetic in minutes, the
    serial kernel in seconds."""
    planes = end - begin
    runs = max(1, min(planes, PLANE_RUNS_PER_THREAD * threads()))
    bounds = [begin + planes * r // runs for r in range(runs + 1)]
    map_in_threads(lambda run: kernel(*run), [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a])


def structured_hex(X, first, last, tolerance, out, degenerate):
    """Metrics of the cells first[d] <= index < last[d] of node array ``X`` (n1+1, n2+1, n3+1, 3)
    (the other cells serve as face neighbours) into ``out`` (7, m) and ``degenerate`` (m,), m the
    number of those cells, in C order. Runs of planes of cells in parallel, rows of cells along k
    each a vectorised loop (``_hex_row``), then the angles from the cosines (``finish_hex_angles``)."""
    first, last = tuple(int(v) for v in first), tuple(int(v) for v in last)
    for_runs_of_planes(lambda i0, i1: _hex_planes(X, i0, i1, first, last, tolerance, out, degenerate), first[0], last[0])
    finish_hex_angles(out)


@njit(**_JIT)
def _file_centroid_plane(F, k, present, centroid, slot):
    """Centroids of the plane of cells k of ``F`` (3, n3+1, n2+1, n1+1) (coordinate d of node (i, j, k)
    at [d, k, j, i]) into the interior of ``centroid[:, slot]`` (cell (i, j) at [:, slot, j+1, i+1]),
    summed in VTK corner order; NaN where the plane is not ``present`` (beyond the mesh)."""
    if not present:
        centroid[:, slot, 1:-1, 1:-1] = np.nan
        return
    n2, n1 = F.shape[2] - 1, F.shape[3] - 1
    k, slot = uint64(k), uint64(slot)
    one = uint64(1)
    for d in range(3):
        for j in range(uint64(n2)):
            for i in range(uint64(n1)):
                s = F[d, k, j, i]
                s = s + F[d, k, j, i + one]
                s = s + F[d, k, j + one, i + one]
                s = s + F[d, k, j + one, i]
                s = s + F[d, k + one, j, i]
                s = s + F[d, k + one, j, i + one]
                s = s + F[d, k + one, j + one, i + one]
                s = s + F[d, k + one, j + one, i]
                centroid[d, slot, j + one, i + one] = s * 0.125


@njit(**_JIT)
def _file_hex_row(F, centroid, k, cp, cc, cn, j, i0, i1, tolerance, out, degenerate, c0):
    """``_hex_row`` of the cells (i0 <= i < i1, j, k) of ``F`` (``_file_centroid_plane``): the loop
    runs along i, unit stride in the file's order; the centroids of the cell planes k-1, k, k+1 at
    slots ``cp``, ``cc``, ``cn``."""
    k, cp, cc, cn, j, c0 = uint64(k), uint64(cp), uint64(cc), uint64(cn), uint64(j), uint64(c0)
    one = uint64(1)
    k1, j1, two = k + one, j + one, one + one
    for ii in range(uint64(i1 - i0)):
        i = ii + uint64(i0)
        P = (
            _node(F, k, j, i),
            _node(F, k, j, i + one),
            _node(F, k, j1, i),
            _node(F, k, j1, i + one),
            _node(F, k1, j, i),
            _node(F, k1, j, i + one),
            _node(F, k1, j1, i),
            _node(F, k1, j1, i + one),
        )
        ic = i + one
        G = _node(centroid, cc, j1, ic)
        N = (
            _node(centroid, cc, j1, i),
            _node(centroid, cc, j1, ic + one),
            _node(centroid, cc, j, ic),
            _node(centroid, cc, j + two, ic),
            _node(centroid, cp, j1, ic),
            _node(centroid, cn, j1, ic),
        )
        _store_hex(_hex_cell(P, G, N, tolerance), out, degenerate, c0 + ii)


@njit(**_JIT)
def _file_hex_planes(F, k0, k1, first, last, tolerance, out, degenerate):
    """Cells of the planes k0 <= k < k1 of ``structured_hex_file_order``, in order, each plane of
    centroids summed once (a ring of three: the cells k-1, k, k+1)."""
    n3, n2, n1 = F.shape[1] - 1, F.shape[2] - 1, F.shape[3] - 1
    m1, m2 = last[0] - first[0], last[1] - first[1]
    centroid = np.full((3, 3, n2 + 2, n1 + 2), np.nan)
    # cell plane c (c >= -1) at slot (c + 1) % 3
    _file_centroid_plane(F, k0 - 1, k0 >= 1, centroid, k0 % 3)
    _file_centroid_plane(F, k0, True, centroid, (k0 + 1) % 3)
    for k in range(k0, k1):
        _file_centroid_plane(F, k + 1, k + 1 < n3, centroid, (k + 2) % 3)
        for j in range(first[1], last[1]):
            c0 = ((k - first[2]) * m2 + (j - first[1])) * m1
            _file_hex_row(F, centroid, k, k % 3, (k + 1) % 3, (k + 2) % 3, j, first[0], last[0], tolerance, out,
                          degenerate, c0)  # fmt: skip


def structured_hex_file_order(F, first, last, tolerance, out, degenerate):
    """``structured_hex`` of nodes by component in a CGNS file's order: ``F`` (3, n3+1, n2+1, n1+1),
    coordinate d of node (i, j, k) at [d, k, j, i] (what HDF5 reads without a transpose). Cells
    ``first[d] <= (i, j, k)[d] < last[d]``, written to ``out`` (7, m) and ``degenerate`` (m,) in the
    file's order (i fastest). Each cell's arithmetic is ``structured_hex``'s, so its values are the
    same to the bit; only their order differs."""
    first, last = tuple(int(v) for v in first), tuple(int(v) for v in last)
    for_runs_of_planes(lambda k0, k1: _file_hex_planes(F, k0, k1, first, last, tolerance, out, degenerate), first[2], last[2])
    finish_hex_angles(out)


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


@njit(inline="always", **_JIT)
def _corner(points, cells, c, k):
    return (points[cells[c, k], 0], points[cells[c, k], 1], points[cells[c, k], 2])


@njit(inline="always", **_JIT)
def _neighbour_centroid(centroid, neighbour, face, c):
    other = neighbour[face, c]
    if other < 0:
        return (np.nan, np.nan, np.nan)
    return (centroid[other, 0], centroid[other, 1], centroid[other, 2])


@njit(**_JIT)
def _hex_cells(points, cells, neighbour, centroid, tolerance, out, degenerate, first, last):
    """Cells ``first <= c < last`` of ``unstructured_hex``."""
    for c in range(first, last):
        # corners by q (VTK order 0, 1, 3, 2, 4, 5, 7, 6)
        P = (_corner(points, cells, c, 0), _corner(points, cells, c, 1), _corner(points, cells, c, 3),
             _corner(points, cells, c, 2), _corner(points, cells, c, 4), _corner(points, cells, c, 5),
             _corner(points, cells, c, 7), _corner(points, cells, c, 6))  # fmt: skip
        N = (_neighbour_centroid(centroid, neighbour, 0, c), _neighbour_centroid(centroid, neighbour, 1, c),
             _neighbour_centroid(centroid, neighbour, 2, c), _neighbour_centroid(centroid, neighbour, 3, c),
             _neighbour_centroid(centroid, neighbour, 4, c), _neighbour_centroid(centroid, neighbour, 5, c))  # fmt: skip
        _store_hex(_hex_cell(P, (centroid[c, 0], centroid[c, 1], centroid[c, 2]), N, tolerance), out, degenerate, c)


def unstructured_hex(points, cells, neighbour, tolerance, out, degenerate):
    """Metrics of hexahedra ``cells`` (M, 8) (VTK corner order) on ``points`` (N, 3) into ``out``
    (7, M) and ``degenerate`` (M,); ``neighbour`` (6, M): the cell across each face (row 2 axis +
    side), -1 for none."""
    _unstructured_hex_cosines(points, cells, neighbour, tolerance, out, degenerate)
    finish_hex_angles(out)


@njit(parallel=True, **_JIT)
def _unstructured_hex_cosines(points, cells, neighbour, tolerance, out, degenerate):
    """``unstructured_hex`` with the angles still as cosines (``_store_hex``)."""
    centroid = _centroids(points, cells)
    n = cells.shape[0]
    chunk = 1024
    for block in prange((n + chunk - 1) // chunk):
        _hex_cells(points, cells, neighbour, centroid, tolerance, out, degenerate, block * chunk, min(n, (block + 1) * chunk))


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
