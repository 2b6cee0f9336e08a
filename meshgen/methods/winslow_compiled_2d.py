"""The 2D Winslow kernels of a block set's multigrid (``meshgen.methods.multigrid_set``) as
compiled numba code: the plane twins of ``meshgen.methods.winslow_compiled``'s residual, defect
and line-ADI sweep, for the many small blocks of a 2D block set, where NumPy's cost per call (about
forty array temporaries per residual) and not the arithmetic sets the pace.

The arithmetic at a node (``_node``) is that of ``meshgen.methods.winslow.winslow_operator`` in 2D
(g22 r_xixi - 2 g12 r_xieta + g11 r_etaeta, divided by g11 + g22), in IEEE double precision, its
sums ordered differently (agreement to round-off). Stencil weights per axis as arrays
(3, n_a - 1) (``meshgen.methods.multigrid.stencil_weights``). Serial (the arrays are small).
"""

from __future__ import annotations

import numpy as np
from numba import njit

import meshgen.run.jit  # noqa: F401 - numba with its BLAS probe deferred (design notes §21)

__all__ = ["defect", "jacobi_step", "lines", "operator", "relax"]

_JIT = {"cache": True, "fastmath": False, "nogil": True, "error_model": "numpy"}


@njit(inline="always", **_JIT)
def _node(R, f0, f1, s0, s1, i, j):
    """Winslow terms at interior node (i, j) (array index (i + 1, j + 1)): the residual's two
    components, unnormalised, the axial cofactors A_00 = g22, A_11 = g11 and 1 / (A_00 + A_11)."""
    ni, nj = i + 1, j + 1
    a0, a1, a2 = f0[0, i], f0[1, i], f0[2, i]
    b0, b1, b2 = f1[0, j], f1[1, j], f1[2, j]
    g00 = g11 = g01 = 0.0
    for c in range(R.shape[0]):
        x0 = a0 * R[c, ni - 1, nj] + a1 * R[c, ni, nj] + a2 * R[c, ni + 1, nj]
        x1 = b0 * R[c, ni, nj - 1] + b1 * R[c, ni, nj] + b2 * R[c, ni, nj + 1]
        g00 += x0 * x0
        g11 += x1 * x1
        g01 += x0 * x1
    A00, A11, A01 = g11, g00, -g01
    inverse_trace = 1.0 / (A00 + A11)
    out0 = out1 = 0.0
    for c in range(R.shape[0]):
        centre = R[c, ni, nj]
        r00 = s0[0, i] * R[c, ni - 1, nj] + s0[1, i] * centre + s0[2, i] * R[c, ni + 1, nj]
        r11 = s1[0, j] * R[c, ni, nj - 1] + s1[1, j] * centre + s1[2, j] * R[c, ni, nj + 1]
        r01 = (
            a0 * (b0 * R[c, ni - 1, nj - 1] + b1 * R[c, ni - 1, nj] + b2 * R[c, ni - 1, nj + 1])
            + a1 * (b0 * R[c, ni, nj - 1] + b1 * centre + b2 * R[c, ni, nj + 1])
            + a2 * (b0 * R[c, ni + 1, nj - 1] + b1 * R[c, ni + 1, nj] + b2 * R[c, ni + 1, nj + 1])
        )
        value = A00 * r00 + A11 * r11 + 2.0 * A01 * r01
        if c == 0:
            out0 = value
        else:
            out1 = value
    return out0, out1, A00, A11, inverse_trace


@njit(**_JIT)
def _jacobi(R, f, has_f, f0, f1, s0, s1, step, axial, inverse_centre):
    """The Jacobi step (N(R) - f) / centre, the axial coefficients and 1 / centre at the interior nodes."""
    for i in range(R.shape[1] - 2):
        for j in range(R.shape[2] - 2):
            v0, v1, A00, A11, inverse = _node(R, f0, f1, s0, s1, i, j)
            c0, c1 = A00 * inverse, A11 * inverse
            scale = -1.0 / (c0 * s0[1, i] + c1 * s1[1, j])
            v0, v1 = v0 * inverse, v1 * inverse
            if has_f:
                v0, v1 = v0 - f[0, i, j], v1 - f[1, i, j]
            step[0, i, j], step[1, i, j] = v0 * scale, v1 * scale
            axial[0, i, j], axial[1, i, j] = c0, c1
            inverse_centre[i, j] = scale


@njit(**_JIT)
def _defect(R, f, has_f, f0, f1, s0, s1, out):
    for i in range(R.shape[1] - 2):
        for j in range(R.shape[2] - 2):
            v0, v1, _, _, inverse = _node(R, f0, f1, s0, s1, i, j)
            v0, v1 = -v0 * inverse, -v1 * inverse
            if has_f:
                v0, v1 = v0 + f[0, i, j], v1 + f[1, i, j]
            out[0, i + 1, j + 1], out[1, i + 1, j + 1] = v0, v1


@njit(**_JIT)
def _lines(step, axial, inverse_centre, w0, w1, pivot, R, damping):
    """The line-ADI step's tridiagonal solves along axis 0, then axis 1 (as the 3D kernels'), then
    R's interior += damping * step."""
    m1, m2 = step.shape[1], step.shape[2]
    for j in range(m2):
        pivot[0, j] = 1.0
    for i in range(1, m1):
        for j in range(m2):
            sub = -w0[0, i] * axial[0, i, j] * inverse_centre[i, j]
            sup = -w0[2, i - 1] * axial[0, i - 1, j] * inverse_centre[i - 1, j]
            factor = sub / pivot[i - 1, j]
            pivot[i, j] = 1.0 - factor * sup
            for c in range(step.shape[0]):
                step[c, i, j] -= factor * step[c, i - 1, j]
    for j in range(m2):
        for c in range(step.shape[0]):
            step[c, m1 - 1, j] /= pivot[m1 - 1, j]
    for i in range(m1 - 2, -1, -1):
        for j in range(m2):
            sup = -w0[2, i] * axial[0, i, j] * inverse_centre[i, j]
            for c in range(step.shape[0]):
                step[c, i, j] = (step[c, i, j] - sup * step[c, i + 1, j]) / pivot[i, j]
    for i in range(m1):
        pivot[i, 0] = 1.0
        for j in range(1, m2):
            sub = -w1[0, j] * axial[1, i, j] * inverse_centre[i, j]
            sup = -w1[2, j - 1] * axial[1, i, j - 1] * inverse_centre[i, j - 1]
            factor = sub / pivot[i, j - 1]
            pivot[i, j] = 1.0 - factor * sup
            for c in range(step.shape[0]):
                step[c, i, j] -= factor * step[c, i, j - 1]
        for c in range(step.shape[0]):
            step[c, i, m2 - 1] /= pivot[i, m2 - 1]
        for j in range(m2 - 2, -1, -1):
            sup = -w1[2, j] * axial[1, i, j] * inverse_centre[i, j]
            for c in range(step.shape[0]):
                step[c, i, j] = (step[c, i, j] - sup * step[c, i, j + 1]) / pivot[i, j]
        for j in range(m2):
            for c in range(step.shape[0]):
                R[c, i + 1, j + 1] += damping * step[c, i, j]


def jacobi_step(R, f, weights):
    """The Jacobi step (N(R) - f) / centre (2, m1, m2), the axial coefficients (2, m1, m2) and
    1 / centre (m1, m2) at the interior nodes of R (2, m1+2, m2+2); ``f``: None or (2, m1, m2)."""
    m1, m2 = R.shape[1] - 2, R.shape[2] - 2
    step, axial, inverse_centre = np.empty((2, m1, m2)), np.empty((2, m1, m2)), np.empty((m1, m2))
    _jacobi(R, R if f is None else f, f is not None, *weights, step, axial, inverse_centre)
    return step, axial, inverse_centre


def operator(R, weights):
    """Normalised Winslow residual (2, m1, m2) and axial coefficients (2, m1, m2) at the interior
    nodes of R (2, m1+2, m2+2); ``weights``: first- and second-derivative weights per axis (3, m_a)."""
    step, axial, inverse_centre = jacobi_step(R, None, weights)
    return step / inverse_centre, axial


def defect(R, f, weights) -> np.ndarray:
    """f - N(R) at the interior nodes of R (2, n1+1, n2+1) (``f``: None for zero, else
    (2, n1-1, n2-1)), zero on its boundary: an array shaped as R."""
    out = np.zeros(R.shape)
    _defect(R, R if f is None else f, f is not None, *weights, out)
    return out


def relax(R, f, weights, damping: float, frozen=None) -> None:
    """One line-ADI sweep of N(R) = f on the interior nodes of R (2, n1+1, n2+1), in place;
    ``frozen``: as ``meshgen.methods.winslow_compiled.relax`` takes them."""
    step, axial, inverse_centre = jacobi_step(R, f, weights)
    if frozen is not None:
        step[:, frozen] = 0.0
        axial[:, frozen] = 0.0
        inverse_centre[frozen] = 0.0
    _lines(step, axial, inverse_centre, weights[2], weights[3], np.empty(inverse_centre.shape), R, damping)


def lines(step, axial, inverse_centre, weights, R, damping: float) -> None:
    """The line-ADI step's tridiagonal solves of ``step`` (k, m1, m2) (in place; k: any of the
    components, each with the same rows, from ``axial`` and ``inverse_centre`` as ``jacobi_step``
    gives them), then R's interior += damping * step, R (k, m1+2, m2+2)."""
    _lines(step, axial, inverse_centre, weights[2], weights[3], np.empty(inverse_centre.shape), R, damping)
