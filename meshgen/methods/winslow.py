"""The discrete Winslow operator of design notes §5 on a structured tensor grid (NumPy).

With r = (x, y[, z]) and the covariant metric g_ab = r_a . r_b (derivatives in the parametric
coordinates), the Winslow system is, for every component of r,

    sum_a A_aa r_aa + 2 sum_{a<b} A_ab r_ab = 0,      A = cofactor matrix of g,

i.e. in 3D a1 = A_11 = g22 g33 - g23^2, a2 = g11 g33 - g13^2, a3 = g11 g22 - g12^2,
b12 = A_12 = g13 g23 - g12 g33, b23 = g12 g13 - g11 g23, b31 = g12 g23 - g13 g22, and in 2D
g22 r_xixi - 2 g12 r_xieta + g11 r_etaeta = 0 (A_11 = g22, A_22 = g11, A_12 = -g12).

Derivatives are the second-order central differences of the parametric node grid: on a uniform
axis with spacing h,

    r_a  = (r[+a] - r[-a]) / 2h,     r_aa = (r[+a] - 2 r + r[-a]) / h^2,
    r_ab = (r[+a+b] - r[+a-b] - r[-a+b] + r[-a-b]) / (4 h_a h_b),

and on a stretched axis (wall clustering) the three-point formulas exact for quadratics, of which
the above are the uniform case; r_ab is always the product of the two first-derivative stencils.

The raw residual grows like length^5 (and like the cube of the cells' size ratios); we divide it
by the positive scale ``a1 + a2 [+ a3]`` (the trace of A), which makes it scale-free (a length, per
unit parametric length squared) without changing its zeros.

Layout: the operator works on component-first arrays ``R`` of shape ``(dim, n1+1, n2+1[, n3+1])``
(each component contiguous, which the shifted-slice stencils need to be fast); ``node_array`` and
``component_array`` convert from and to the node array ``X`` of shape ``(n1+1, n2+1[, n3+1], dim)``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Stencils",
    "centre_coefficient",
    "cofactors",
    "component_array",
    "node_array",
    "stencils",
    "winslow_operator",
    "winslow_residual",
]


@dataclass(frozen=True)
class Stencils:
    """Three-point finite-difference weights at the interior nodes of a tensor grid.

    ``first[a]`` and ``second[a]``: the weights (minus, centre, plus) of the first and second
    derivative along axis ``a``: Python floats on a uniform axis (the centre weight of the first
    derivative is then exactly 0.0 and skipped), else arrays shaped to broadcast along that axis
    over the interior nodes, ``(n_a - 1, 1, 1)``, ``(1, n_a - 1, 1)``, ...
    """

    coords: tuple
    first: tuple
    second: tuple

    @property
    def dim(self) -> int:
        return len(self.coords)


def stencils(coords) -> Stencils:
    """Finite-difference weights of the parametric node coordinates ``coords`` (one 1D array of
    ``n_a + 1`` increasing values per axis, at least 3 nodes each)."""
    coords = tuple(np.asarray(t, dtype=float) for t in coords)
    dim = len(coords)
    first, second = [], []
    for axis, t in enumerate(coords):
        if len(t) < 3:
            raise ValueError(f"axis {axis} has {len(t) - 1} cell(s): the Winslow stencil needs at least 2")
        spacing = np.diff(t)
        if np.any(spacing <= 0):
            raise ValueError(f"parametric coordinates of axis {axis} must increase")
        h = (t[-1] - t[0]) / (len(t) - 1)
        if np.allclose(spacing, h, rtol=1e-12, atol=0.0):
            first.append((-0.5 / h, 0.0, 0.5 / h))
            second.append((1.0 / h**2, -2.0 / h**2, 1.0 / h**2))
            continue
        shape = [1] * dim
        shape[axis] = -1
        minus, plus = spacing[:-1], spacing[1:]  # h- = t_i - t_{i-1}, h+ = t_{i+1} - t_i
        first.append(
            tuple(
                w.reshape(shape)
                for w in (-plus / (minus * (minus + plus)), (plus - minus) / (minus * plus), minus / (plus * (minus + plus)))
            )
        )
        second.append(
            tuple(
                w.reshape(shape) for w in (2.0 / (minus * (minus + plus)), -2.0 / (minus * plus), 2.0 / (plus * (minus + plus)))
            )
        )
    return Stencils(coords, tuple(first), tuple(second))


def _along(F: np.ndarray, axis: int, offset: int, trimmed: tuple) -> np.ndarray:
    """View of the component-first array F (dim, ...) at its inner nodes along ``axis`` shifted by
    ``offset`` (-1, 0, +1), and at the inner nodes of the ``trimmed`` axes (the rest whole)."""
    index = [slice(None)] * F.ndim
    for other in trimmed:
        index[other + 1] = slice(1, -1)
    index[axis + 1] = slice(1 + offset, F.shape[axis + 1] - 1 + offset)
    return F[tuple(index)]


def _interior(F: np.ndarray, axes: tuple) -> np.ndarray:
    """View of F (dim, ...) at the inner nodes of ``axes`` (the other axes whole)."""
    index = [slice(None)] * F.ndim
    for axis in axes:
        index[axis + 1] = slice(1, -1)
    return F[tuple(index)]


def _stencil(F: np.ndarray, axis: int, weights, trimmed: tuple = ()):
    """Three-point stencil ``weights`` = (minus, centre, plus) along ``axis`` of F (dim, ...), at
    F's inner nodes along ``axis`` and along the ``trimmed`` axes.

    Returns ``(values, factor)`` with the stencil equal to ``factor * values``: on a uniform axis
    ``values`` is the plain difference (F[+] - F[-], or F[+] - 2F + F[-]) and ``factor`` its
    weight, so that callers fold the factor into a scalar coefficient instead of scaling a vector;
    on a stretched axis ``values`` is the weighted sum and ``factor`` 1.
    """
    minus, centre, plus = weights
    forward, backward = _along(F, axis, 1, trimmed), _along(F, axis, -1, trimmed)
    if isinstance(plus, float):
        if centre == 0.0:  # uniform first derivative
            return forward - backward, plus
        values = forward + backward  # uniform second derivative
        values -= _along(F, axis, 0, trimmed)
        values -= _along(F, axis, 0, trimmed)
        return values, plus
    values = plus * forward + minus * backward
    values += centre * _along(F, axis, 0, trimmed)
    return values, 1.0


def cofactors(g: dict) -> dict:
    """Cofactor matrix A of the symmetric metric ``g`` ({(a, b): array} for a <= b), same layout.
    3D: design notes §5's a1, a2, a3 on the diagonal and b12, b23, b31 off it; 2D: g22, g11, -g12."""
    if (2, 2) in g:
        g11, g22, g33 = g[0, 0], g[1, 1], g[2, 2]
        g12, g23, g13 = g[0, 1], g[1, 2], g[0, 2]
        return {
            (0, 0): g22 * g33 - g23**2,
            (1, 1): g11 * g33 - g13**2,
            (2, 2): g11 * g22 - g12**2,
            (0, 1): g13 * g23 - g12 * g33,
            (1, 2): g12 * g13 - g11 * g23,
            (0, 2): g12 * g23 - g13 * g22,
        }
    return {(0, 0): g[1, 1], (1, 1): g[0, 0], (0, 1): -g[0, 1]}


def winslow_operator(R: np.ndarray, grid: Stencils) -> tuple[np.ndarray, list[np.ndarray]]:
    """Normalised Winslow residual at the interior nodes, and its axial coefficients.

    ``R``: component-first node array, shape ``(dim, n1+1, n2+1[, n3+1])``.
    Returns ``(residual, axial)``: ``residual``, shape ``(dim, n1-1, n2-1[, n3-1])``, is
    ``(sum_a A_aa r_aa + 2 sum_{a<b} A_ab r_ab) / trace(A)``; ``axial[a]``, shape
    ``(n1-1, n2-1[, n3-1])``, is ``A_aa / trace(A)``, the weight of r_aa, from which a solver
    builds its frozen-coefficient point or line operators (``centre_coefficient``).
    """
    dim = grid.dim
    axes = range(dim)
    # First derivatives along each axis at all nodes of the other axes: r_a is their interior,
    # and the mixed derivative r_ab is the first-derivative stencil of axis a applied to them.
    along = [_stencil(R, a, grid.first[a]) for a in axes]
    r = [_interior(along[a][0], tuple(b for b in axes if b != a)) for a in axes]
    g = {(a, b): np.einsum("c...,c...->...", r[a], r[b]) * (along[a][1] * along[b][1]) for a in axes for b in range(a, dim)}
    A = cofactors(g)
    inverse_trace = 1.0 / sum(A[a, a] for a in axes)

    residual = np.zeros((R.shape[0],) + inverse_trace.shape)  # components: dim, or 3 on a surface
    for a, b in itertools.combinations(axes, 2):
        derivative_b, factor_b = along[b]  # interior along b; the stencil trims a and the third axis
        values, factor_a = _stencil(derivative_b, a, grid.first[a], tuple(c for c in axes if c not in (a, b)))
        values *= A[a, b] * (2.0 * factor_a * factor_b * inverse_trace)
        residual += values
    del along, r, g  # memory: dim + 1 mesh-sized arrays
    for a in axes:
        values, factor = _stencil(R, a, grid.second[a], tuple(b for b in axes if b != a))
        values *= A[a, a] * (factor * inverse_trace)
        residual += values
    return residual, [A[a, a] * inverse_trace for a in axes]


def centre_coefficient(axial: list[np.ndarray], grid: Stencils) -> np.ndarray:
    """Minus the derivative of the normalised residual with respect to its own node, coefficients
    frozen: ``-sum_a (A_aa / trace) w_aa``, w_aa the centre weight of r_aa (2 / h_a^2 uniform);
    positive. The mixed terms' centre weights (non-zero only on stretched axes, and small there)
    are left out: this is the divisor of a Jacobi step, not part of the equations."""
    return -sum(c * w[1] for c, w in zip(axial, grid.second))


def component_array(X: np.ndarray) -> np.ndarray:
    """Node array (n1+1, ..., dim) -> contiguous component-first array (dim, n1+1, ...)."""
    return np.ascontiguousarray(np.moveaxis(np.asarray(X, dtype=float), -1, 0))


def node_array(R: np.ndarray) -> np.ndarray:
    """Component-first array (dim, n1+1, ...) -> contiguous node array (n1+1, ..., dim)."""
    return np.ascontiguousarray(np.moveaxis(R, 0, -1))


def winslow_residual(X: np.ndarray, coords=None) -> np.ndarray:
    """Normalised discrete Winslow residual of the node array ``X`` (n1+1, n2+1[, n3+1], dim) at its
    interior nodes, shape (n1-1, n2-1[, n3-1], dim); ``coords``: the parametric node coordinates
    per axis (default uniform on [0, 1]). Zero for a converged elliptic mesh and for any affine map."""
    X = np.asarray(X, dtype=float)
    if coords is None:
        coords = [np.linspace(0.0, 1.0, n) for n in X.shape[:-1]]
    residual, _ = winslow_operator(component_array(X), stencils(coords))
    return node_array(residual)
