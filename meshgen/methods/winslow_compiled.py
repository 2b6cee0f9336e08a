"""The 3D multigrid Winslow kernels of ``meshgen.methods.multigrid`` as compiled numba code.

Four kernels, free of temporaries; the Winslow arithmetic at a node (``_node``) is that of
``meshgen.methods.winslow.winslow_operator``, one pass over the nodes instead of about forty array-sized
temporaries:

- ``_jacobi``: the Jacobi step (N(R) - f) / centre, the axial coefficients and 1 / centre;
- ``_defect``: f - N(R), the residual that a multigrid cycle restricts;
- ``_lines_*``: the tridiagonal solves of a line-ADI sweep, one kernel per axis;
- ``_transfer_*``: a banded 1D matrix along one axis (the multigrid transfers, a few non-zeros per row).

``operator``, ``defect``, ``relax`` (one sweep of ``meshgen.methods.multigrid.smooth``) and ``transfer``
call them. Each kernel works on a range of planes (``start``, ``stop``) of the axis it runs
across, and ``_across`` hands the planes to a pool of threads in chunks (the kernels release the
GIL): plain serial kernels compile in a fraction of a second each, where numba's ``parallel=True``
takes about two seconds per parallel loop (once, then cached, but a fresh installation or a test
run pays it).

Stencil weights come per axis as arrays (3, n_a - 1): (minus, centre, plus) at each interior
index, which covers uniform and stretched axes alike. Arithmetic is IEEE double precision
(``fastmath=False``); the sums are ordered differently from the NumPy code, so the two agree to
round-off (tested to 1e-12 of the terms' size). Compiled code is cached on disk (``cache=True``).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

import meshgen.run.jit  # noqa: F401 - numba with its BLAS probe deferred (design notes §21)

__all__ = ["defect", "jacobi_step", "lines", "operator", "relax", "threads", "transfer"]

_JIT = {"cache": True, "fastmath": False, "nogil": True, "error_model": "numpy"}
CHUNKS_PER_THREAD = 4  # work split finer than the threads: a thread that the OS delays holds up less
THREADED_NODES = 3 * 30**3  # smaller arrays are done in the calling thread (a chunk's hand-over costs ~0.1 ms)
_POOL: list = []  # (process id, thread pool), made on first use in each process


def threads() -> int:
    """Threads the kernels run on: the CPUs this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _across(kernel, count: int, *args) -> None:
    """Run ``kernel(*args, start, stop)`` over the planes [0, count) of the first array in ``args``:
    on the pool in chunks when it holds at least ``THREADED_NODES`` values, else in this thread."""
    workers = threads()
    if workers == 1 or count < 2 or args[0].size < THREADED_NODES:
        kernel(*args, 0, count)
        return
    if not _POOL or _POOL[0][0] != os.getpid():  # none yet, or made before this process was forked
        _POOL[:] = [(os.getpid(), ThreadPoolExecutor(max_workers=workers, thread_name_prefix="meshgen-winslow"))]
    pool = _POOL[0][1]
    chunks = min(count, workers * CHUNKS_PER_THREAD)
    bounds = [count * c // chunks for c in range(chunks + 1)]
    for future in [pool.submit(kernel, *args, a, b) for a, b in zip(bounds[:-1], bounds[1:])]:
        future.result()


@njit(inline="always", **_JIT)
def _node(R, ni, nj, nk, f0, f1, f2, s0, s1, s2, i, j, k):
    """Winslow terms at node (ni, nj, nk) = (i, j, k) + 1 of R, interior node (i, j, k): returns the residual's three
    components, unnormalised, the axial cofactors A_00, A_11, A_22 and 1 / trace(A)."""
    a0, a1, a2 = f0[0, i], f0[1, i], f0[2, i]
    b0, b1, b2 = f1[0, j], f1[1, j], f1[2, j]
    c0, c1, c2 = f2[0, k], f2[1, k], f2[2, k]
    g00 = g11 = g22 = g01 = g12 = g02 = 0.0
    for c in range(3):
        x0 = a0 * R[c, ni - 1, nj, nk] + a1 * R[c, ni, nj, nk] + a2 * R[c, ni + 1, nj, nk]
        x1 = b0 * R[c, ni, nj - 1, nk] + b1 * R[c, ni, nj, nk] + b2 * R[c, ni, nj + 1, nk]
        x2 = c0 * R[c, ni, nj, nk - 1] + c1 * R[c, ni, nj, nk] + c2 * R[c, ni, nj, nk + 1]
        g00 += x0 * x0
        g11 += x1 * x1
        g22 += x2 * x2
        g01 += x0 * x1
        g12 += x1 * x2
        g02 += x0 * x2
    A00 = g11 * g22 - g12 * g12
    A11 = g00 * g22 - g02 * g02
    A22 = g00 * g11 - g01 * g01
    A01 = g02 * g12 - g01 * g22
    A12 = g01 * g02 - g00 * g12
    A02 = g01 * g12 - g02 * g11
    inverse_trace = 1.0 / (A00 + A11 + A22)
    out0 = out1 = out2 = 0.0
    for c in range(3):
        centre = R[c, ni, nj, nk]
        r00 = s0[0, i] * R[c, ni - 1, nj, nk] + s0[1, i] * centre + s0[2, i] * R[c, ni + 1, nj, nk]
        r11 = s1[0, j] * R[c, ni, nj - 1, nk] + s1[1, j] * centre + s1[2, j] * R[c, ni, nj + 1, nk]
        r22 = s2[0, k] * R[c, ni, nj, nk - 1] + s2[1, k] * centre + s2[2, k] * R[c, ni, nj, nk + 1]
        # mixed derivatives: the first-derivative stencil of one axis applied to the other's
        r01 = (
            a0 * (b0 * R[c, ni - 1, nj - 1, nk] + b1 * R[c, ni - 1, nj, nk] + b2 * R[c, ni - 1, nj + 1, nk])
            + a1 * (b0 * R[c, ni, nj - 1, nk] + b1 * centre + b2 * R[c, ni, nj + 1, nk])
            + a2 * (b0 * R[c, ni + 1, nj - 1, nk] + b1 * R[c, ni + 1, nj, nk] + b2 * R[c, ni + 1, nj + 1, nk])
        )
        r12 = (
            b0 * (c0 * R[c, ni, nj - 1, nk - 1] + c1 * R[c, ni, nj - 1, nk] + c2 * R[c, ni, nj - 1, nk + 1])
            + b1 * (c0 * R[c, ni, nj, nk - 1] + c1 * centre + c2 * R[c, ni, nj, nk + 1])
            + b2 * (c0 * R[c, ni, nj + 1, nk - 1] + c1 * R[c, ni, nj + 1, nk] + c2 * R[c, ni, nj + 1, nk + 1])
        )
        r02 = (
            a0 * (c0 * R[c, ni - 1, nj, nk - 1] + c1 * R[c, ni - 1, nj, nk] + c2 * R[c, ni - 1, nj, nk + 1])
            + a1 * (c0 * R[c, ni, nj, nk - 1] + c1 * centre + c2 * R[c, ni, nj, nk + 1])
            + a2 * (c0 * R[c, ni + 1, nj, nk - 1] + c1 * R[c, ni + 1, nj, nk] + c2 * R[c, ni + 1, nj, nk + 1])
        )
        value = A00 * r00 + A11 * r11 + A22 * r22 + 2.0 * (A01 * r01 + A12 * r12 + A02 * r02)
        if c == 0:
            out0 = value
        elif c == 1:
            out1 = value
        else:
            out2 = value
    return out0, out1, out2, A00, A11, A22, inverse_trace


def operator(R, f0, f1, f2, s0, s1, s2):
    """Normalised Winslow residual (3, m1, m2, m3) and axial coefficients A_aa / trace(A)
    (3, m1, m2, m3) at the interior nodes of the component-first array R (3, m1+2, m2+2, m3+2);
    ``f*``, ``s*``: first- and second-derivative weights per axis, (3, m_a)."""
    step, axial, inverse_centre, _ = _jacobi_step(R, None, (f0, f1, f2, s0, s1, s2))
    step /= inverse_centre
    return step, axial


def _jacobi_step(R, f, weights):
    m1, m2, m3 = R.shape[1] - 2, R.shape[2] - 2, R.shape[3] - 2
    step = np.empty((3, m1, m2, m3))
    axial = np.empty((3, m1, m2, m3))
    inverse_centre = np.empty((m1, m2, m3))
    largest = np.zeros(m1)
    _across(_jacobi, m1, R, R if f is None else f, f is not None, *weights, step, axial, inverse_centre, largest)
    return step, axial, inverse_centre, largest


@njit(**_JIT)
def _jacobi(R, f, has_f, f0, f1, f2, s0, s1, s2, step, axial, inverse_centre, largest, start, stop):
    """On the planes i in [start, stop): the Jacobi step (N(R) - f) / centre (``f`` used when
    ``has_f``), the axial coefficients and 1 / centre at the interior nodes, and per plane the
    largest squared norm of the step."""
    m2, m3 = R.shape[2] - 2, R.shape[3] - 2
    for i in range(start, stop):
        best = 0.0
        for j in range(m2):
            for k in range(m3):
                v0, v1, v2, A00, A11, A22, inverse = _node(R, i + 1, j + 1, k + 1, f0, f1, f2, s0, s1, s2, i, j, k)
                c0, c1, c2 = A00 * inverse, A11 * inverse, A22 * inverse
                scale = -1.0 / (c0 * s0[1, i] + c1 * s1[1, j] + c2 * s2[1, k])
                v0, v1, v2 = v0 * inverse, v1 * inverse, v2 * inverse
                if has_f:
                    v0, v1, v2 = v0 - f[0, i, j, k], v1 - f[1, i, j, k], v2 - f[2, i, j, k]
                v0, v1, v2 = v0 * scale, v1 * scale, v2 * scale
                step[0, i, j, k], step[1, i, j, k], step[2, i, j, k] = v0, v1, v2
                axial[0, i, j, k], axial[1, i, j, k], axial[2, i, j, k] = c0, c1, c2
                inverse_centre[i, j, k] = scale
                norm = v0 * v0 + v1 * v1 + v2 * v2
                if norm > best or norm != norm:  # NaN sticks
                    best = norm
        largest[i] = best


def defect(R, f, weights) -> np.ndarray:
    """f - N(R) at the interior nodes of R (3, n1+1, n2+1, n3+1) (``f``: None for zero, else
    (3, n1-1, n2-1, n3-1)), zero on its boundary: an array shaped as R, the residual a multigrid
    cycle restricts; ``weights`` as ``relax``'s."""
    out = np.zeros(R.shape)
    _across(_defect, R.shape[1] - 2, R, R if f is None else f, f is not None, *weights, out)
    return out


@njit(**_JIT)
def _defect(R, f, has_f, f0, f1, f2, s0, s1, s2, out, start, stop):
    m2, m3 = R.shape[2] - 2, R.shape[3] - 2
    for i in range(start, stop):
        for j in range(m2):
            for k in range(m3):
                v0, v1, v2, _, _, _, inverse = _node(R, i + 1, j + 1, k + 1, f0, f1, f2, s0, s1, s2, i, j, k)
                v0, v1, v2 = -v0 * inverse, -v1 * inverse, -v2 * inverse
                if has_f:
                    v0, v1, v2 = v0 + f[0, i, j, k], v1 + f[1, i, j, k], v2 + f[2, i, j, k]
                out[0, i + 1, j + 1, k + 1] = v0
                out[1, i + 1, j + 1, k + 1] = v1
                out[2, i + 1, j + 1, k + 1] = v2


# The line-ADI step: tridiagonal solves of (3, m1, m2, m3) ``step`` in place, along axis 0, then 1,
# then 2: x[i] + sub[i] x[i-1] + sup[i] x[i+1] = step[i], sub = -minus c_a / centre, sup = -plus
# c_a / centre (c_a the axis's axial coefficient, minus and plus its second-derivative weights ``w``).
# In each solve the lines of one plane advance together, so that the innermost loop is independent
# work rather than one line's chain of divisions.


@njit(**_JIT)
def _lines_first(step, axial, inverse_centre, w, pivot, start, stop):
    """Along axis 0, for the planes j in [start, stop)."""
    m1, m3 = step.shape[1], step.shape[3]
    for j in range(start, stop):
        for k in range(m3):
            pivot[0, j, k] = 1.0
        for i in range(1, m1):
            for k in range(m3):
                sub = -w[0, i] * axial[0, i, j, k] * inverse_centre[i, j, k]
                sup = -w[2, i - 1] * axial[0, i - 1, j, k] * inverse_centre[i - 1, j, k]
                factor = sub / pivot[i - 1, j, k]
                pivot[i, j, k] = 1.0 - factor * sup
                for c in range(step.shape[0]):
                    step[c, i, j, k] -= factor * step[c, i - 1, j, k]
        for k in range(m3):
            for c in range(step.shape[0]):
                step[c, m1 - 1, j, k] /= pivot[m1 - 1, j, k]
        for i in range(m1 - 2, -1, -1):
            for k in range(m3):
                sup = -w[2, i] * axial[0, i, j, k] * inverse_centre[i, j, k]
                for c in range(step.shape[0]):
                    step[c, i, j, k] = (step[c, i, j, k] - sup * step[c, i + 1, j, k]) / pivot[i, j, k]


@njit(**_JIT)
def _lines_second(step, axial, inverse_centre, w, pivot, start, stop):
    """Along axis 1, for the planes i in [start, stop)."""
    m2, m3 = step.shape[2], step.shape[3]
    for i in range(start, stop):
        for k in range(m3):
            pivot[i, 0, k] = 1.0
        for j in range(1, m2):
            for k in range(m3):
                sub = -w[0, j] * axial[1, i, j, k] * inverse_centre[i, j, k]
                sup = -w[2, j - 1] * axial[1, i, j - 1, k] * inverse_centre[i, j - 1, k]
                factor = sub / pivot[i, j - 1, k]
                pivot[i, j, k] = 1.0 - factor * sup
                for c in range(step.shape[0]):
                    step[c, i, j, k] -= factor * step[c, i, j - 1, k]
        for k in range(m3):
            for c in range(step.shape[0]):
                step[c, i, m2 - 1, k] /= pivot[i, m2 - 1, k]
        for j in range(m2 - 2, -1, -1):
            for k in range(m3):
                sup = -w[2, j] * axial[1, i, j, k] * inverse_centre[i, j, k]
                for c in range(step.shape[0]):
                    step[c, i, j, k] = (step[c, i, j, k] - sup * step[c, i, j + 1, k]) / pivot[i, j, k]


@njit(**_JIT)
def _lines_third(step, axial, inverse_centre, w, pivot, R, damping, start, stop):
    """Along axis 2, for the planes i in [start, stop); then R's interior += damping * step there."""
    m2, m3 = step.shape[2], step.shape[3]
    for i in range(start, stop):
        for j in range(m2):
            pivot[i, j, 0] = 1.0
        for k in range(1, m3):
            for j in range(m2):
                sub = -w[0, k] * axial[2, i, j, k] * inverse_centre[i, j, k]
                sup = -w[2, k - 1] * axial[2, i, j, k - 1] * inverse_centre[i, j, k - 1]
                factor = sub / pivot[i, j, k - 1]
                pivot[i, j, k] = 1.0 - factor * sup
                for c in range(step.shape[0]):
                    step[c, i, j, k] -= factor * step[c, i, j, k - 1]
        for j in range(m2):
            for c in range(step.shape[0]):
                step[c, i, j, m3 - 1] /= pivot[i, j, m3 - 1]
        for k in range(m3 - 2, -1, -1):
            for j in range(m2):
                sup = -w[2, k] * axial[2, i, j, k] * inverse_centre[i, j, k]
                for c in range(step.shape[0]):
                    step[c, i, j, k] = (step[c, i, j, k] - sup * step[c, i, j, k + 1]) / pivot[i, j, k]
        for c in range(step.shape[0]):
            for j in range(m2):
                for k in range(m3):
                    R[c, i + 1, j + 1, k + 1] += damping * step[c, i, j, k]


def relax(R, f, weights, damping: float, measure: bool, frozen=None) -> float:
    """One line-ADI sweep of N(R) = f on the interior nodes of R (3, n1+1, n2+1, n3+1), in place
    (``meshgen.methods.multigrid.smooth``); ``f``: None or (3, n1-1, n2-1, n3-1); ``weights``: the six
    (3, n_a - 1) arrays (first derivative per axis, then second). Returns the largest Jacobi step
    (Euclidean norm over the nodes) of the starting state when ``measure``, else inf. ``frozen``:
    None, or a bool array (n1-1, n2-1, n3-1) of interior nodes that do not move (their line rows
    become identities with a zero right-hand side: fixed ends of the lines through them)."""
    step, axial, inverse_centre, largest = _jacobi_step(R, f, weights)
    if frozen is not None:
        step[:, frozen] = 0.0
        axial[:, frozen] = 0.0
        inverse_centre[frozen] = 0.0
    pivot = np.empty(inverse_centre.shape)
    m1, m2 = inverse_centre.shape[:2]
    _across(_lines_first, m2, step, axial, inverse_centre, weights[3], pivot)
    _across(_lines_second, m1, step, axial, inverse_centre, weights[4], pivot)
    _across(_lines_third, m1, step, axial, inverse_centre, weights[5], pivot, R, damping)
    return float(np.sqrt(largest.max())) if measure and len(largest) else np.inf


@njit(**_JIT)
def _transfer_first(F, columns, values, out, start, stop):
    for r in range(start, stop):
        for t in range(columns.shape[1]):
            column, value = columns[r, t], values[r, t]
            if value != 0.0:
                for c in range(F.shape[0]):
                    for j in range(F.shape[2]):
                        for k in range(F.shape[3]):
                            out[c, r, j, k] += value * F[c, column, j, k]


@njit(**_JIT)
def _transfer_second(F, columns, values, out, start, stop):
    for i in range(start, stop):
        for c in range(F.shape[0]):
            for r in range(columns.shape[0]):
                for t in range(columns.shape[1]):
                    column, value = columns[r, t], values[r, t]
                    if value != 0.0:
                        for k in range(F.shape[3]):
                            out[c, i, r, k] += value * F[c, i, column, k]


@njit(**_JIT)
def _transfer_third(F, columns, values, out, start, stop):
    for i in range(start, stop):
        for c in range(F.shape[0]):
            for j in range(F.shape[2]):
                for r in range(columns.shape[0]):
                    total = 0.0
                    for t in range(columns.shape[1]):
                        total += values[r, t] * F[c, i, j, columns[r, t]]
                    out[c, i, j, r] = total


def transfer(F, columns, values, axis: int) -> np.ndarray:
    """The banded matrix M (``M[r, columns[r, t]] = values[r, t]``) along spatial ``axis`` (0, 1, 2)
    of the component-first array F (C, n1, n2, n3): a new contiguous array."""
    F = np.ascontiguousarray(F)
    shape = list(F.shape)
    shape[axis + 1] = columns.shape[0]
    out = np.zeros(shape)
    if axis == 0:  # across the target rows
        _across(_transfer_first, columns.shape[0], F, columns, values, out)
    else:  # across the planes i
        _across((_transfer_second, _transfer_third)[axis - 1], F.shape[1], F, columns, values, out)
    return out


def jacobi_step(R, f, weights):
    """The Jacobi step (N(R) - f) / centre (3, m1, m2, m3), the axial coefficients (3, m1, m2, m3)
    and 1 / centre (m1, m2, m3) at the interior nodes of R (3, m1+2, m2+2, m3+2)."""
    return _jacobi_step(R, f, weights)[:3]


def lines(step, axial, inverse_centre, weights, R, damping: float) -> None:
    """The line-ADI step's tridiagonal solves of ``step`` (k, m1, m2, m3) (in place; k: any of the
    components, each with the same rows, from ``axial`` and ``inverse_centre`` as ``jacobi_step``
    gives them), then R's interior += damping * step, R (k, m1+2, m2+2, m3+2) (``relax``'s second half)."""
    pivot = np.empty(inverse_centre.shape)
    m1, m2 = inverse_centre.shape[:2]
    _across(_lines_first, m2, step, axial, inverse_centre, weights[3], pivot)
    _across(_lines_second, m1, step, axial, inverse_centre, weights[4], pivot)
    _across(_lines_third, m1, step, axial, inverse_centre, weights[5], pivot, R, damping)
