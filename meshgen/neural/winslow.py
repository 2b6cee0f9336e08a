"""The Winslow residual (DESIGN section 5), written as on paper.

With r = (x, y, z) and the covariant metric g_ij = r_i . r_j (derivatives in xi^1..3), the
3D system is, for each component of r,

    a1 r_11 + a2 r_22 + a3 r_33 + 2 (b12 r_12 + b23 r_23 + b31 r_31) = 0,

with the cofactors of g: a1 = g22 g33 - g23^2, a2 = g11 g33 - g13^2, a3 = g11 g22 - g12^2,
b12 = g13 g23 - g12 g33, b23 = g12 g13 - g11 g23, b31 = g12 g23 - g13 g22. In 2D:
g22 r_11 - 2 g12 r_12 + g11 r_22 = 0 (the cofactors of the 2x2 metric).

Scale: the raw residual grows like length^5 (cofactors ~ length^4 times second derivatives).
Every variant divides it by the trace of the cofactor matrix, a1 + a2 + a3 (2D: g11 + g22), which
is positive for any non-degenerate map. What remains is a weighted mean of second derivatives,
homogeneous of degree one in length; training on the geometry normalised to unit size
(``model.normalisation``) makes it scale-free. ``SCALE_FLOOR`` keeps the division finite where a
map degenerates (e.g. an untrained network that is nearly constant).
"""

from __future__ import annotations

import torch

SCALE_FLOOR = 1e-6  # in units of (normalised length)^4; a healthy normalised map has a trace ~ 0.1-3


def metric(first: torch.Tensor) -> torch.Tensor:
    """Covariant metric g_ij = r_i . r_j.

    ``first``: (..., dim, dim) with first[..., i, c] = d r_c / d xi_i. Returns (..., dim, dim).
    """
    return torch.einsum("...ic,...jc->...ij", first, first)


def cofactors(g: torch.Tensor) -> torch.Tensor:
    """Cofactor matrix of a symmetric metric (= det(g) g^-1), shape (..., dim, dim).

    Written out term by term so that it stays defined where g is singular.
    """
    if g.shape[-1] == 2:
        g11, g12, g22 = g[..., 0, 0], g[..., 0, 1], g[..., 1, 1]
        return torch.stack([torch.stack([g22, -g12], -1), torch.stack([-g12, g11], -1)], -2)
    g11, g12, g13 = g[..., 0, 0], g[..., 0, 1], g[..., 0, 2]
    g22, g23, g33 = g[..., 1, 1], g[..., 1, 2], g[..., 2, 2]
    a1 = g22 * g33 - g23**2
    a2 = g11 * g33 - g13**2
    a3 = g11 * g22 - g12**2
    b12 = g13 * g23 - g12 * g33
    b23 = g12 * g13 - g11 * g23
    b31 = g12 * g23 - g13 * g22
    return torch.stack(
        [torch.stack([a1, b12, b31], -1), torch.stack([b12, a2, b23], -1), torch.stack([b31, b23, a3], -1)], -2
    )


def winslow_residual(first: torch.Tensor, second: torch.Tensor) -> torch.Tensor:
    """Scale-free Winslow residual (sum_ij C_ij r_ij) / trace(C), C the cofactors of g.

    ``first``: (..., dim, dim), first[..., i, c] = d r_c / d xi_i.
    ``second``: (..., dim, dim, dim), second[..., i, j, c] = d^2 r_c / d xi_i d xi_j (symmetric in i, j).
    Returns (..., dim): one residual per component of r. The full contraction with the symmetric
    cofactor matrix counts each mixed term twice, which is the factor 2 of the formula.
    """
    C = cofactors(metric(first))
    raw = torch.einsum("...ij,...ijc->...c", C, second)
    trace = torch.diagonal(C, dim1=-2, dim2=-1).sum(-1)
    return raw / (trace + SCALE_FLOOR)[..., None]
