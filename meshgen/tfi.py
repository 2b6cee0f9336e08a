"""Transfinite interpolation (Gordon-Hall, linear blending; DESIGN section 4).

The interpolant is the Boolean sum of the linear projectors along each parametric axis,

    X = sum over non-empty axis subsets S of (-1)^(|S|+1) sum over sides s in {0,1}^S
        prod_{d in S} L_{s_d}(t_d) F(t with t_d = s_d for d in S),    L_0(t) = 1 - t, L_1(t) = t,

which in 3D is the six face terms, minus the twelve edge terms, plus the eight vertex terms, and
in 2D the Coons patch. It reproduces the boundary map F exactly.
"""

from __future__ import annotations

import itertools

import numpy as np


def parametric_grid(dims) -> list[np.ndarray]:
    """Uniform parametric node coordinates: one array of ``n + 1`` values in [0, 1] per cell count."""
    return [np.linspace(0.0, 1.0, int(n) + 1) for n in dims]


def transfinite(boundary, coords) -> np.ndarray:
    """Gordon-Hall interpolant of ``boundary`` at parametric coordinates ``coords``.

    ``boundary``: ``(N, dim) -> (N, dim)`` map of the unit cube's boundary.
    ``coords``: ``dim`` mutually broadcastable arrays (t_1, ..., t_dim) in [0, 1]; e.g. three
    arrays of shape (N,) for scattered points, or shapes (n1, 1, 1), (1, n2, 1), (1, 1, n3) for a
    tensor grid, where each face term is then evaluated on its face alone.
    Returns the physical points, shape ``broadcast(coords) + (dim,)``.
    """
    coords = [np.asarray(c, dtype=float) for c in coords]
    dim = len(coords)
    shape = np.broadcast_shapes(*(c.shape for c in coords))
    terms = []  # (sign, blending weight, the term's points on the boundary as broadcast arrays)
    for size in range(1, dim + 1):
        sign = 1.0 if size % 2 else -1.0
        for axes in itertools.combinations(range(dim), size):
            for sides in itertools.product((0.0, 1.0), repeat=size):
                weight = np.ones(())
                fixed = list(coords)
                for axis, side in zip(axes, sides):
                    weight = weight * (coords[axis] if side else 1.0 - coords[axis])
                    fixed[axis] = np.asarray(side)
                terms.append((sign, weight, np.broadcast_arrays(*fixed)))
    # One call of the boundary map for the points of all terms: a plugin's cost is mostly per call
    # when the terms are small (edges, vertices, a training grid's faces).
    points = np.concatenate([np.stack([a.reshape(-1) for a in fixed], axis=1) for _, _, fixed in terms])
    images = boundary(points)
    result = np.zeros(shape + (dim,))
    start = 0
    for sign, weight, fixed in terms:
        count = fixed[0].size
        result += sign * weight[..., None] * images[start : start + count].reshape(*fixed[0].shape, dim)
        start += count
    return result


def tfi(geometry, dims, coords: list[np.ndarray] | None = None) -> np.ndarray:
    """Transfinite-interpolation mesh of ``geometry``.

    ``dims``: cells per axis (n1, n2[, n3]). ``coords``: optional 1D parametric node positions per
    axis (default uniform), e.g. clustered towards a wall.
    Returns the node array X, shape ``(n1+1, n2+1[, n3+1], dim)``, float64.
    """
    if coords is None:
        coords = parametric_grid(dims)
    dim = len(coords)
    if dim != geometry.dim:
        raise ValueError(f"{dim} axes given for the {geometry.dim}D geometry '{geometry.name}'")
    axes = [c.reshape([-1 if d == a else 1 for d in range(dim)]) for a, c in enumerate(coords)]
    return transfinite(geometry.boundary, axes)
