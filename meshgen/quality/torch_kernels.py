"""The per-cell hexahedron metrics (definitions in ``meshgen.quality.kernels``) as torch tensor code,
for a GPU (any torch device; float64), and the block-wise summary of a mesh given as slabs of node
planes, accumulated on the device.

``structured_hex_torch`` mirrors the compiled kernel (``meshgen.quality.compiled._hex_cell``)
operation by operation, the cells of a run of planes at once as tensors by component (loops over
the 8 corners and 6 faces only): numba's ``max(a, b)`` is ``b if b > a else a``, its ``min``
``b if b < a else a``, and every division is by a tensor (torch multiplies by the reciprocal when
it divides by a Python scalar on CUDA). Each elementwise operation is its own kernel, so nothing
is contracted to a fused multiply-add, and on CUDA ``+ - * / sqrt`` are correctly rounded in IEEE
double, as in the compiled kernel: there the cosines, aspect ratio, centroid skewness and scaled
Jacobian should be the compiled kernel's to the bit. torch's CPU ``sqrt`` is not correctly rounded
(SLEEF: about 1 in 150 results 1 ulp off), so on the CPU those differ by a few ulp (1e-15). The
angles come from the cosines by the device's ``acos`` (CUDA: at most 2 ulp off; torch's CPU: 1 ulp;
NumPy's ``arccos`` in the compiled path): a few 1e-14 degrees. A cell whose cosine or Jacobian sits
within those ulps of a threshold (reflex corner, inverted, degenerate edge) may be classified
otherwise.

``summarise_hex_torch`` keeps per metric the count, sum, min, max and the quantile sketch of
``meshgen.quality.sketch`` (bucket keys ceil(log|x| / log gamma), counted by ``torch.bincount``)
on the device; only the bucket counts (a few thousand per metric) come back to the host, as a
summary that ``meshgen.quality.chunked``'s merge and report take. A key differs from NumPy's only
where the device's ``log`` (1 ulp) puts a value on the other side of a bucket boundary.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from meshgen.quality import sketch as sketches
from meshgen.quality.kernels import METRICS

__all__ = [
    "CHUNK_CELLS",
    "finish_hex_angles_torch",
    "hex_planes_torch",
    "report_summaries",
    "structured_hex_torch",
    "summarise_hex_torch",
]

# Cells per run of planes evaluated at once: the cell arithmetic keeps about 150 float64 tensors
# alive (about 1.2 kB per cell), so 2^23 cells take about 10 GB of device memory.
CHUNK_CELLS = 1 << 23
_DEGREES = 180.0 / math.pi  # np.degrees multiplies by this constant
HEX_Q_OF_VTK = (0, 1, 3, 2, 4, 5, 7, 6)  # VTK corner order as corner q (centroids summed in it)


def _max(a, b):
    """numba's ``max(a, b)``: b if b > a else a."""
    return torch.where(b > a, b, a)


def _min(a, b):
    """numba's ``min(a, b)``: b if b < a else a."""
    return torch.where(b < a, b, a)


def _nanmin(a, b):
    """``compiled._nanmin``: a if a < b or a is NaN, else b."""
    return torch.where((a < b) | (a != a), a, b)


def _unit3(x, y, z):
    length = torch.sqrt(x * x + y * y + z * z)
    inverse = 1.0 / torch.where(length > 0.0, length, 1.0)
    return x * inverse, y * inverse, z * inverse, length


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross3(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _short(length, tolerance):
    """Not longer than ``tolerance`` or not finite (NaN too)."""
    return ~((length > tolerance) & (length < math.inf))


def _axis(P, lows, step, tolerance):
    """``compiled._axis``: unit edges, principal direction, mean length, short edge? of one axis."""
    units, sums, lengths, short = [], None, [], None
    for low in lows:
        e = _sub(P[low + step], P[low])
        ux, uy, uz, length = _unit3(*e)
        units.append((ux, uy, uz))
        lengths.append(length)
        sums = list(e) if sums is None else [s + c for s, c in zip(sums, e)]
        edge_short = _short(length, tolerance)
        short = edge_short if short is None else short | edge_short
    px, py, pz, _ = _unit3(*sums)
    return units, (px, py, pz), (lengths[0] + lengths[1] + lengths[2] + lengths[3]) * 0.25, short


def _face(P, G, Nf, ua0, ua1, ub0, ub1, q00, q10, q01, q11, principal, normals):
    """``compiled._face``: (largest, smallest corner cosine, reflex?, centroid cosine, face cosine)."""
    d1 = _sub(P[q11], P[q00])
    d2 = _sub(P[q01], P[q10])
    n = _cross3(d1, d2)
    c0, c1, c2, c3 = _dot3(ua0, ub0), -_dot3(ua0, ub1), _dot3(ua1, ub1), -_dot3(ua1, ub0)
    if normals is None:
        m0, m1 = _cross3(n, ua0), _cross3(n, ua1)
        r = (_dot3(m0, ub0), _dot3(m0, ub1), _dot3(m1, ub1), _dot3(m1, ub0))
    else:
        r = tuple(_dot3(n, normal) for normal in normals)
    reflex = _min(_min(r[0], r[1]), _min(r[2], r[3])) < 0.0
    unx, uny, unz, _ = _unit3(*n)
    centroid_cosine = torch.abs(unx * principal[0] + uny * principal[1] + unz * principal[2])
    d = (Nf[0] - G[0], Nf[1] - G[1], Nf[2] - G[2])
    finite = torch.isfinite(d[0] + d[1] + d[2])
    tx, ty, tz, _ = _unit3(*(torch.where(finite, c, p) for c, p in zip(d, principal)))
    face_cosine = torch.abs(unx * tx + uny * ty + unz * tz)
    return _max(_max(c0, c1), _max(c2, c3)), _min(_min(c0, c1), _min(c2, c3)), reflex, centroid_cosine, face_cosine


def _fold(function, values):
    """function(function(v0, v1), function(v2, v3)), ... as the compiled kernel nests its six faces."""
    f = values
    return function(function(function(f[0], f[1]), function(f[2], f[3])), function(f[4], f[5]))


def _hex_cells(P, G, N, tolerance):
    """``compiled._hex_cell`` on tensors: ``P`` 8 corners by q, each a tuple of 3 component tensors;
    ``G`` the centroid, ``N`` the 6 neighbour centroids (NaN: none), each a tuple of 3. Returns
    the rows of ``compiled._store_hex`` (7 tensors: cosines still) and the degenerate mask."""
    U0, p0, m0, short0 = _axis(P, (0, 2, 4, 6), 1, tolerance)
    U1, p1, m1, short1 = _axis(P, (0, 1, 4, 5), 2, tolerance)
    U2, p2, m2, short2 = _axis(P, (0, 1, 2, 3), 4, tolerance)
    degenerate = short0 | short1 | short2
    longest = _max(_max(m0, m1), m2)
    shortest = _min(_min(m0, m1), m2)
    positive = shortest > 0.0
    aspect_ratio = torch.where(positive, longest / torch.where(positive, shortest, 1.0), math.inf)
    jacobian, normal = {}, {}
    for s in ((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)):
        s0, s1, s2 = s
        normal[s] = _cross3(U1[s0 + 2 * s2], U2[s0 + 2 * s1])
        jacobian[s] = _dot3(U0[s1 + 2 * s2], normal[s])
    j = jacobian
    scaled_jacobian = _nanmin(
        _nanmin(_nanmin(j[0, 0, 0], j[1, 0, 0]), _nanmin(j[1, 1, 0], j[0, 1, 0])),
        _nanmin(_nanmin(j[0, 0, 1], j[1, 0, 1]), _nanmin(j[1, 1, 1], j[0, 1, 1])),
    )
    n = normal
    faces = [
        _face(P, G, N[0], U1[0], U1[2], U2[0], U2[2], 0, 2, 4, 6, p0, (n[0, 0, 0], n[0, 1, 0], n[0, 1, 1], n[0, 0, 1])),
        _face(P, G, N[1], U1[1], U1[3], U2[1], U2[3], 1, 3, 5, 7, p0, (n[1, 0, 0], n[1, 1, 0], n[1, 1, 1], n[1, 0, 1])),
        _face(P, G, N[2], U0[0], U0[2], U2[0], U2[1], 0, 1, 4, 5, p1, None),
        _face(P, G, N[3], U0[1], U0[3], U2[2], U2[3], 2, 3, 6, 7, p1, None),
        _face(P, G, N[4], U0[0], U0[1], U1[0], U1[1], 0, 1, 2, 3, p2, None),
        _face(P, G, N[5], U0[2], U0[3], U1[2], U1[3], 4, 5, 6, 7, p2, None),
    ]
    largest_cosine = _fold(_max, [f[0] for f in faces])
    smallest_cosine = _fold(_min, [f[1] for f in faces])
    reflex_cosine = torch.full_like(largest_cosine, -2.0)
    any_reflex = faces[0][2]
    for index, f in enumerate(faces):
        reflex_cosine = torch.where(f[2], _max(reflex_cosine, f[1]), reflex_cosine)
        any_reflex = any_reflex | f[2] if index else any_reflex
    centroid_alignment = _fold(_min, [f[3] for f in faces])
    face_alignment = _fold(_min, [f[4] for f in faces])
    max_cosine = torch.where(any_reflex, reflex_cosine, smallest_cosine)
    rows = (
        largest_cosine,
        max_cosine,
        any_reflex.to(largest_cosine.dtype),
        aspect_ratio,
        1.0 - centroid_alignment,
        face_alignment,
        scaled_jacobian,
    )
    return rows, degenerate


def finish_hex_angles_torch(out: torch.Tensor) -> None:
    """``meshgen.quality.angles.finish_hex_angles`` on a tensor ``out`` (7, m), in place: rows 0, 1, 5
    from cosines to degrees (360 minus the max angle where row 2 flags a reflex corner), row 2 the
    equiangle skewness."""
    ninety = torch.tensor(90.0, dtype=out.dtype, device=out.device)  # a tensor: true division on CUDA too
    for row in (0, 1, 5):
        out[row] = torch.acos(out[row].clamp(-1.0, 1.0)) * _DEGREES
    out[1] = torch.where(out[2] != 0.0, 360.0 - out[1], out[1])
    out[2] = torch.maximum((out[1] - 90.0) / ninety, (90.0 - out[0]) / ninety)


def _centroids(X, i0, i1, j0, j1, k0, k1):
    """Centroids (i1-i0, j1-j0, k1-k0, 3) of cells i0 <= i < i1, ... of node tensor ``X``, summed in
    VTK corner order (``compiled._centroid_plane``)."""
    shape = (i1 - i0, j1 - j0, k1 - k0)
    total = None
    for q in HEX_Q_OF_VTK:
        s0, s1, s2 = q & 1, (q >> 1) & 1, (q >> 2) & 1
        corner = X[i0 + s0 : i0 + s0 + shape[0], j0 + s1 : j0 + s1 + shape[1], k0 + s2 : k0 + s2 + shape[2]]
        total = corner if total is None else total + corner
    return total * 0.125


def hex_planes_torch(X: torch.Tensor, a: int, b: int, first, last, tolerance: float):
    """Rows (7, m) as ``compiled.structured_hex`` leaves them (angles still cosines) and the
    degenerate mask (m,) of the cells a <= i < b, first[1] <= j < last[1], first[2] <= k < last[2]
    of node tensor ``X`` (n1+1, n2+1, n3+1, 3), C order; face neighbours from ``X``'s other cells."""
    n1, n2, n3 = (s - 1 for s in X.shape[:3])
    (j0, k0), (j1, k1) = first[1:], last[1:]
    shape = (b - a, j1 - j0, k1 - k0)
    P = []
    for q in range(8):
        s0, s1, s2 = q & 1, (q >> 1) & 1, (q >> 2) & 1
        corner = X[a + s0 : b + s0, j0 + s1 : j1 + s1, k0 + s2 : k1 + s2]
        P.append(tuple(corner[..., d] for d in range(3)))
    # centroids of the cells around, with a NaN layer where the array ends
    padded = torch.full((shape[0] + 2, shape[1] + 2, shape[2] + 2, 3), math.nan, dtype=X.dtype, device=X.device)
    lo = (max(a - 1, 0), max(j0 - 1, 0), max(k0 - 1, 0))
    hi = (min(b + 1, n1), min(j1 + 1, n2), min(k1 + 1, n3))
    at = tuple(low - start + 1 for low, start in zip(lo, (a, j0, k0)))
    padded[at[0] : at[0] + hi[0] - lo[0], at[1] : at[1] + hi[1] - lo[1], at[2] : at[2] + hi[2] - lo[2]] = _centroids(
        X, lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]
    )

    def around(o0, o1, o2):
        view = padded[1 + o0 : 1 + o0 + shape[0], 1 + o1 : 1 + o1 + shape[1], 1 + o2 : 1 + o2 + shape[2]]
        return tuple(view[..., d] for d in range(3))

    G = around(0, 0, 0)
    N = (around(-1, 0, 0), around(1, 0, 0), around(0, -1, 0), around(0, 1, 0), around(0, 0, -1), around(0, 0, 1))
    rows, degenerate = _hex_cells(P, G, N, tolerance)
    return torch.stack([r.reshape(-1) for r in rows]), degenerate.reshape(-1)


def _runs(first: int, last: int, plane_cells: int, chunk_cells: int):
    planes = max(1, chunk_cells // max(plane_cells, 1))
    return [(a, min(a + planes, last)) for a in range(first, last, planes)]


def structured_hex_torch(X: torch.Tensor, tolerance: float, first=None, last=None, chunk_cells: int = CHUNK_CELLS):
    """Metrics (7, m) in ``METRICS`` order (angles in degrees) and degenerate mask (m,) of the cells
    first[d] <= index < last[d] of node tensor ``X`` (n1+1, n2+1, n3+1, 3) float64 on any device, C
    order: ``compiled.structured_hex``'s ``out`` and ``degenerate`` (degenerate cells' values left as
    computed). The other cells of ``X`` serve as face neighbours; runs of planes of about
    ``chunk_cells`` cells at a time."""
    if X.ndim != 4 or X.shape[-1] != 3 or min(X.shape[:3]) < 2:
        raise ValueError(f"node tensor must have shape (n1+1, n2+1, n3+1, 3) with >= 2 nodes per axis, got {tuple(X.shape)}")
    cells = tuple(s - 1 for s in X.shape[:3])
    first = tuple(int(v) for v in (first if first is not None else (0, 0, 0)))
    last = tuple(int(v) for v in (last if last is not None else cells))
    plane = (last[1] - first[1]) * (last[2] - first[2])
    m = max(0, last[0] - first[0]) * plane
    out = torch.empty((len(METRICS), m), dtype=X.dtype, device=X.device)
    degenerate = torch.empty(m, dtype=torch.bool, device=X.device)
    for a, b in _runs(first[0], last[0], plane, chunk_cells):
        rows, mask = hex_planes_torch(X, a, b, first, last, tolerance)
        out[:, (a - first[0]) * plane : (b - first[0]) * plane] = rows
        degenerate[(a - first[0]) * plane : (b - first[0]) * plane] = mask
    finish_hex_angles_torch(out)
    return out, degenerate


# ---------------------------------------------------------------------------------------------
# summaries on the device


def _keys(magnitudes: torch.Tensor) -> torch.Tensor:
    """Sketch bucket keys ceil(log m / log gamma) (``sketch.sketch_of``), int64."""
    log_gamma = torch.tensor(sketches.LOG_GAMMA, dtype=magnitudes.dtype, device=magnitudes.device)
    return torch.ceil(torch.log(magnitudes) / log_gamma).to(torch.int64)


def _add_counts(store: dict, name, keys: torch.Tensor, low: int, high: int) -> None:
    """Counts of ``keys`` (all in low..high) into ``store[name]`` = (offset, device counts), grown as needed."""
    counts = torch.bincount(keys - low, minlength=high - low + 1)
    if name not in store:
        store[name] = (low, counts)
        return
    offset, total = store[name]
    start, end = min(offset, low), max(offset + total.numel(), high + 1)
    if start < offset or end > offset + total.numel():
        grown = torch.zeros(end - start, dtype=total.dtype, device=total.device)
        grown[offset - start : offset - start + total.numel()] = total
        offset, total = start, grown
    total[low - offset : low - offset + counts.numel()] += counts
    store[name] = (offset, total)


class _Accumulator:
    """Counts, sums, minima, maxima and sketch buckets of the metrics, on the device."""

    def __init__(self, device):
        self.device = device
        self.counts = torch.zeros(3, dtype=torch.int64, device=device)  # cells, inverted, degenerate
        self.sums = torch.zeros(len(METRICS), dtype=torch.float64, device=device)
        self.low = torch.full((len(METRICS),), math.inf, dtype=torch.float64, device=device)
        self.high = torch.full((len(METRICS),), -math.inf, dtype=torch.float64, device=device)
        self.kept = 0
        self.zeros = torch.zeros(len(METRICS), dtype=torch.int64, device=device)
        self.buckets = {}  # (metric, sign) -> (offset, counts)

    def add(self, out: torch.Tensor, degenerate: torch.Tensor) -> None:
        """Cells' metrics ``out`` (7, m) (angles finished) and their ``degenerate`` mask (m,)."""
        sj = out[METRICS.index("scaled_jacobian")]
        inverted = degenerate | ~(sj > 0.0)
        self.counts += torch.stack([torch.tensor(degenerate.numel(), device=self.device), inverted.sum(), degenerate.sum()])
        if bool(degenerate.any()):
            out = out[:, ~degenerate]
        if out.shape[1] == 0:
            return
        self.kept += out.shape[1]
        self.sums += out.sum(dim=1)
        self.low = torch.minimum(self.low, out.amin(dim=1))
        self.high = torch.maximum(self.high, out.amax(dim=1))
        magnitude = out.abs()
        large = magnitude >= sketches.SMALLEST  # NaN: a zero, as in sketch_of
        self.zeros += (~large).sum(dim=1)
        keys, parts = _keys(torch.where(large, magnitude, 1.0)), []
        for row in range(len(METRICS)):
            positive = large[row] & (out[row] > 0.0)
            if bool(positive.all()):  # most metrics: no selection
                parts.append(((row, 1), keys[row]))
            else:
                parts.append(((row, 1), keys[row][positive]))
                parts.append(((row, -1), keys[row][large[row] & ~positive]))
        parts = [(name, k) for name, k in parts if k.numel()]
        bounds = torch.stack([torch.stack([k.min(), k.max()]) for _, k in parts]).tolist() if parts else []
        for (name, k), (low, high) in zip(parts, bounds):
            _add_counts(self.buckets, name, k, int(low), int(high))

    def summary(self) -> dict:
        """The block summary of ``meshgen.quality.chunked`` (host values): cells, inverted,
        degenerate, and per metric count, sum, min, max and sketch."""
        cells, inverted, degenerate = self.counts.tolist()
        result = {"cells": cells, "inverted": inverted, "degenerate": degenerate, "metrics": {}}
        if not self.kept:
            return result
        sums, low, high, zeros = self.sums.tolist(), self.low.tolist(), self.high.tolist(), self.zeros.tolist()
        for row, name in enumerate(METRICS):
            signs = {}
            for sign in (1, -1):
                offset, counts = self.buckets.get((row, sign), (0, None))
                host = np.zeros(0, dtype=np.int64) if counts is None else counts.cpu().numpy()
                nonzero = np.flatnonzero(host)  # trimmed as sketch_of's buckets are
                if nonzero.size:
                    host, offset = host[nonzero[0] : nonzero[-1] + 1], offset + int(nonzero[0])
                signs[sign] = sketches.Buckets(int(offset), np.ascontiguousarray(host)) if nonzero.size else sketches.Buckets()
            sketch = sketches.QuantileSketch(signs[1], signs[-1], int(zeros[row]))
            result["metrics"][name] = {"count": self.kept, "sum": sums[row], "min": low[row], "max": high[row], "sketch": sketch}
        return result


def summarise_hex_torch(node_slabs, tolerance: float, chunk_cells: int = CHUNK_CELLS) -> dict:
    """The summary of a hexahedral mesh given as slabs along its first axis, computed and
    accumulated on the slabs' device: ``node_slabs`` an iterable of (X, first, last), X a float64
    node tensor (p+1, n2+1, n3+1, 3) of consecutive node planes of the mesh (the slab's own cells
    with a halo: the node plane before them and the one after, where the mesh has them), and the
    slab's own cells the planes first <= i < last of X (each cell of the mesh owned by one slab).
    ``tolerance``: the mesh's degenerate-edge length (``structured.box_tolerance`` of its bounding
    box). Returns the block summary of ``meshgen.quality.chunked`` (cells, inverted, degenerate;
    per metric count, sum, min, max, sketch), host values; ``report_summaries`` makes the report's
    figures from it."""
    accumulator = None
    for X, first, last in node_slabs:
        if accumulator is None:
            accumulator = _Accumulator(X.device)
        n2, n3 = X.shape[1] - 1, X.shape[2] - 1
        for a, b in _runs(int(first), int(last), n2 * n3, chunk_cells):
            rows, degenerate = hex_planes_torch(X, a, b, (a, 0, 0), (b, n2, n3), tolerance)
            finish_hex_angles_torch(rows)
            accumulator.add(rows, degenerate)
            del rows, degenerate
    if accumulator is None:
        raise ValueError("no slabs to summarise")
    return accumulator.summary()


def report_summaries(summary: dict) -> dict:
    """{metric: {mean, min, max, p01, p99}} of a summary (``summarise_hex_torch``) as
    ``meshgen.quality.chunked.chunked_report`` makes them (p01, p99 from the sketch)."""
    parts = {name: summary["metrics"].get(name) for name in METRICS}
    return {
        name: sketches.part_figures(part) if part is not None else dict.fromkeys(("mean", "min", "max", "p01", "p99"))
        for name, part in parts.items()
    }
