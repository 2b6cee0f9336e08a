"""Derivatives of the network's output with respect to its input (design notes §6).

Three ways, one set of formulas:

- ``grid_derivatives``: second-order central differences on a structured grid with a one-node
  halo, r_i = (r[+e_i] - r[-e_i]) / 2h_i, r_ii = (r[+e_i] - 2 r + r[-e_i]) / h_i^2,
  r_ij = (r[+e_i+e_j] - r[+e_i-e_j] - r[-e_i+e_j] + r[-e_i-e_j]) / (4 h_i h_j). Every grid node is
  a stencil neighbour of others, so one forward pass over (m+2)^dim nodes gives the derivatives at
  m^dim nodes. ``training_grid`` shifts and rescales the grid at random each step.
- ``stencil_derivatives``: the same formulas on a private 3^dim stencil around each point (the
  costly per-point alternative; used for the held-out test set).
- ``autograd_derivatives``: exact derivatives by automatic differentiation (the PINN variants).

Shapes: ``first[..., i, c] = d r_c / d xi_i`` is (..., dim, dim); ``second[..., i, j, c]`` is
(..., dim, dim, dim), symmetric in i, j.
"""

from __future__ import annotations

import itertools

import torch

__all__ = [
    "autograd_derivatives",
    "grid_derivatives",
    "grid_from_draws",
    "grid_points",
    "lattice_grid_from_draws",
    "stencil_derivatives",
    "training_grid",
]


def _shifted(values: torch.Tensor, offsets) -> torch.Tensor:
    """The interior block of a haloed grid moved by ``offsets`` (one of -1, 0, 1 per spatial axis).
    ``values``: (..., m1+2, ..., md+2, C) -> (..., m1, ..., md, C)."""
    dim = len(offsets)
    index = [slice(None)] * (values.ndim - dim - 1)
    for axis, offset in enumerate(offsets):
        size = values.shape[values.ndim - dim - 1 + axis]
        index.append(slice(1 + offset, size - 1 + offset))
    return values[tuple(index)]


def grid_derivatives(values: torch.Tensor, spacing) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Central differences on a structured grid with a one-node halo.

    ``values``: (..., m1+2, ..., md+2, C), the map at the grid nodes (spatial axes just before the
    last). ``spacing``: d node spacings h_i (numbers or 0-d tensors).
    Returns (centre, first, second) at the m1 x ... x md interior nodes: centre (..., m1, ..., md, C),
    first (..., m1, ..., md, d, C), second (..., m1, ..., md, d, d, C).
    """
    dim = len(spacing)

    def moved(*steps):  # moved((i, 1), (j, -1)): the interior block shifted by +e_i - e_j
        offsets = [0] * dim
        for axis, step in steps:
            offsets[axis] += step
        return _shifted(values, offsets)

    centre = moved()
    first, second = [], [[None] * dim for _ in range(dim)]
    for i in range(dim):
        forward, backward = moved((i, 1)), moved((i, -1))
        first.append((forward - backward) / (2 * spacing[i]))
        second[i][i] = (forward - 2 * centre + backward) / spacing[i] ** 2
    for i, j in itertools.combinations(range(dim), 2):
        mixed = moved((i, 1), (j, 1)) - moved((i, 1), (j, -1)) - moved((i, -1), (j, 1)) + moved((i, -1), (j, -1))
        second[i][j] = second[j][i] = mixed / (4 * spacing[i] * spacing[j])
    first = torch.stack(first, dim=-2)
    second = torch.stack([torch.stack(row, dim=-2) for row in second], dim=-3)
    return centre, first, second


def training_grid(dim: int, nodes: int, generator: torch.Generator | None = None, min_scale: float = 1.0):
    """A structured grid of ``nodes`` interior nodes per axis plus a one-node halo, inside [0, 1].

    Per axis the grid spans a fraction s of [0, 1] (s uniform in [min_scale, 1]) starting at a
    uniform offset in [0, 1 - s]; ``min_scale = 1`` gives the fixed grid whose halo lies on the
    cube's faces. The whole grid, halo included, stays inside the cube, so the boundary map and
    TFI are only ever evaluated where they are defined.
    Returns (axes, spacing): ``dim`` 1D float64 tensors of ``nodes + 2`` coordinates, and the
    ``dim`` spacings h_i = s_i / (nodes + 1) as 0-d float64 tensors.
    """
    return grid_from_draws(torch.rand(2 * dim, generator=generator, dtype=torch.float64), nodes, min_scale)


def grid_from_draws(draws: torch.Tensor, nodes: int, min_scale: float = 1.0):
    """:func:`training_grid` from its 2 dim uniform draws (float64, on any device; per axis the
    scale's and the offset's), in tensor arithmetic alone, so that a CUDA graph can replay it
    with new draws."""
    scale = min_scale + (1.0 - min_scale) * draws[0::2]
    start = (1.0 - scale) * draws[1::2]
    h = scale / (nodes + 1)
    axes = start[:, None] + h[:, None] * torch.arange(nodes + 2, dtype=torch.float64, device=draws.device)
    return list(axes.unbind(0)), list(h.unbind(0))


def lattice_grid_from_draws(draws: torch.Tensor, nodes: int, cells: int):
    """Training grids on the lattice of spacing 1/``cells`` (the smoothed layout's fine grid, on
    which its face grids solve the discrete Winslow equations): ``nodes`` interior nodes per axis
    plus a one-node halo, every node a lattice node. ``draws``: (..., 2 dim) uniform draws in
    [0, 1) as :func:`grid_from_draws` takes them (the offsets' draws, the odd entries, are used);
    per axis the offset is one of the ``cells - nodes`` lattice positions that keep the grid in
    the cube. Tensor arithmetic alone (a CUDA graph replays it). Returns (axes, spacing): ``dim``
    float64 tensors of shape (..., nodes + 2) and ``dim`` spacings 1/cells as 0-d tensors."""
    offsets = torch.floor(draws[..., 1::2] * (cells - nodes)).clamp(0, cells - nodes - 1)
    steps = torch.arange(nodes + 2, dtype=torch.float64, device=draws.device)
    axes = (offsets[..., None] + steps) / cells  # (..., dim, nodes + 2)
    # a fill, not torch.tensor: a tensor made from host data is a host-to-device copy, which a
    # CUDA graph's capture refuses (torch 2.11: 'Cannot copy between CPU and CUDA tensors')
    h = torch.full((), 1.0 / cells, dtype=torch.float64, device=draws.device)
    return list(axes.unbind(-2)), [h] * (draws.shape[-1] // 2)


def grid_points(axes) -> torch.Tensor:
    """Tensor-product nodes of ``axes``: 1D (lengths n1..nd) -> (n1, ..., nd, d), index order (i, j[, k]);
    or batches of grids, each axis (B, n_i) -> (B, n1, ..., nd, d)."""
    if axes[0].ndim == 1:
        return torch.stack(torch.meshgrid(*axes, indexing="ij"), dim=-1)
    dim = len(axes)
    shape = (axes[0].shape[0], *(a.shape[1] for a in axes))
    views = [a.reshape(a.shape[0], *[-1 if d == i else 1 for d in range(dim)]).expand(shape) for i, a in enumerate(axes)]
    return torch.stack(views, dim=-1)


def stencil_derivatives(function, points: torch.Tensor, h: float):
    """Central differences on a private 3^dim stencil of spacing ``h`` around each of ``points`` (N, d).

    ``function``: (M, d) -> (M, C). Costs 3^d evaluations per point. Returns (values, first, second)
    with shapes (N, C), (N, d, C), (N, d, d, C).
    """
    n, dim = points.shape
    offsets = h * grid_points([torch.arange(-1, 2, dtype=points.dtype, device=points.device)] * dim)
    neighbourhood = points.reshape(n, *([1] * dim), dim) + offsets  # (N, 3, ..., 3, d)
    values = function(neighbourhood.reshape(-1, dim)).reshape(n, *([3] * dim), -1)
    centre, first, second = grid_derivatives(values, [h] * dim)
    squeeze = (slice(None), *([0] * dim))
    return centre[squeeze], first[squeeze], second[squeeze]


def autograd_derivatives(function, points: torch.Tensor, create_graph: bool = True):
    """Exact first and second derivatives of ``function`` (M, d) -> (M, C) at ``points`` (N, d) by
    automatic differentiation: C backward passes for the first derivatives and C * d for the
    second. Returns (values, first, second) with shapes (N, C), (N, d, C), (N, d, d, C)."""
    points = points.detach().requires_grad_(True)
    values = function(points)
    first = []
    for c in range(values.shape[-1]):
        (gradient,) = torch.autograd.grad(values[:, c].sum(), points, create_graph=True)
        first.append(gradient)  # (N, d): d r_c / d xi_i
    second = []
    for gradient in first:
        if not gradient.requires_grad:  # an affine function: constant first derivatives
            second.append(torch.zeros(*gradient.shape, gradient.shape[-1], dtype=points.dtype, device=points.device))
            continue
        rows = [torch.autograd.grad(gradient[:, i].sum(), points, create_graph=create_graph)[0] for i in range(points.shape[1])]
        second.append(torch.stack(rows, dim=-2))  # (N, d, d)
    return values, torch.stack(first, dim=-1), torch.stack(second, dim=-1)
