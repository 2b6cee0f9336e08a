"""The Winslow residual (design notes §5), written as on paper.

With r = (x, y, z) and the covariant metric g_ij = r_i . r_j (derivatives in xi^1..3), the
3D system is, for each component of r,

    a1 r_11 + a2 r_22 + a3 r_33 + 2 (b12 r_12 + b23 r_23 + b31 r_31) = 0,

with the cofactors of g: a1 = g22 g33 - g23^2, a2 = g11 g33 - g13^2, a3 = g11 g22 - g12^2,
b12 = g13 g23 - g12 g33, b23 = g12 g13 - g11 g23, b31 = g12 g23 - g13 g22. In 2D:
g22 r_11 - 2 g12 r_12 + g11 r_22 = 0 (the cofactors of the 2x2 metric). The cofactor formulas
live in one place, ``meshgen.methods.winslow.cofactors``, shared with the elliptic solver.

Scale: the raw residual grows like length^5 (cofactors ~ length^4 times second derivatives).
Every variant divides it by the trace of the cofactor matrix, a1 + a2 + a3 (2D: g11 + g22), which
is positive for any non-degenerate map. What remains is a weighted mean of second derivatives,
homogeneous of degree one in length; training on the geometry normalised to unit size
(``model.normalisation``) makes it scale-free. ``SCALE_FLOOR`` keeps the division finite where a
map degenerates (e.g. an untrained network that is nearly constant).
"""

from __future__ import annotations

import torch

from meshgen.methods.winslow import cofactors as metric_cofactors

__all__ = ["SCALE_FLOOR", "cofactor_terms", "cofactors", "winslow_residual"]


SCALE_FLOOR = 1e-6  # in units of (normalised length)^4; a healthy normalised map has a trace ~ 0.1-3


def cofactor_terms(first: torch.Tensor):
    """The distinct cofactors of g from the first derivatives (..., dim, dim), each of shape (...):
    3D (a1, a2, a3, b12, b23, b31), 2D (g22, g11, -g12) in the same roles (a1, a2, b12).
    The formulas are ``meshgen.methods.winslow.cofactors`` (one place for both the NumPy solver and the
    networks' loss): it takes any arrays with ``*``, ``-`` and ``**``, torch tensors included."""
    r = first.unbind(-2)  # r_i = d r / d xi_i, (..., dim) each
    dim = first.shape[-1]
    g = {(i, j): (r[i] * r[j]).sum(-1) for i in range(dim) for j in range(i, dim)}
    A = metric_cofactors(g)
    if dim == 2:
        return A[0, 0], A[1, 1], A[0, 1]
    return A[0, 0], A[1, 1], A[2, 2], A[0, 1], A[1, 2], A[0, 2]


def cofactors(first: torch.Tensor) -> torch.Tensor:
    """Cofactor matrix of the metric (= det(g) g^-1 where g is regular), (..., dim, dim), from the
    first derivatives (..., dim, dim)."""
    if first.shape[-1] == 2:
        a1, a2, b12 = cofactor_terms(first)
        return torch.stack([torch.stack([a1, b12], -1), torch.stack([b12, a2], -1)], -2)
    a1, a2, a3, b12, b23, b31 = cofactor_terms(first)
    return torch.stack([torch.stack([a1, b12, b31], -1), torch.stack([b12, a2, b23], -1), torch.stack([b31, b23, a3], -1)], -2)


def winslow_residual(first: torch.Tensor, second: torch.Tensor) -> torch.Tensor:
    """Scale-free Winslow residual: the left-hand side over the cofactor trace a1 + a2 + a3.

    ``first``: (..., dim, dim), first[..., i, c] = d r_c / d xi_i.
    ``second``: (..., dim, dim, dim), second[..., i, j, c] = d^2 r_c / d xi_i d xi_j (symmetric in i, j).
    Returns (..., dim): one residual per component of r. Written term by term (no matrix products):
    for thousands of 3x3 metrics that is several times faster in torch.
    """
    # unbind rather than index: the backward of an index fills a zero tensor of second's full size
    r = [row.unbind(-2) for row in second.unbind(-3)]  # r[i][j] = d^2 r / d xi_i d xi_j, (..., dim)
    if first.shape[-1] == 2:
        a1, a2, b12 = (t[..., None] for t in cofactor_terms(first))
        raw = a1 * r[0][0] + a2 * r[1][1] + 2 * b12 * r[0][1]
        return raw / (a1 + a2 + SCALE_FLOOR)
    a1, a2, a3, b12, b23, b31 = (t[..., None] for t in cofactor_terms(first))
    raw = a1 * r[0][0] + a2 * r[1][1] + a3 * r[2][2] + 2 * (b12 * r[0][1] + b23 * r[1][2] + b31 * r[2][0])
    return raw / (a1 + a2 + a3 + SCALE_FLOOR)
