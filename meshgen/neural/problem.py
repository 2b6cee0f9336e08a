"""What a single-shape network is trained on (design notes §6): the problem in normalised units, the
map and its Winslow residual, the losses, and every draw of points a stage makes.

All points are drawn on the host from a ``torch.Generator`` in a fixed order, so a resumed run
repeats an uninterrupted one. Boundary points come as rows [points | images | local size] (float32,
``boundary_rows``): fresh rows drawn per step, or an index into a fixed pool of such rows
(``boundary_pool``), gathered on the device by ``split_rows`` so that a CUDA graph can replay it.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import torch

from meshgen.geometry.layout import RESOLUTION
from meshgen.methods.tfi import transfinite
from meshgen.neural.config import TrainConfig
from meshgen.neural.derivatives import (
    autograd_derivatives,
    grid_derivatives,
    grid_from_draws,
    grid_points,
    lattice_grid_from_draws,
    stencil_derivatives,
    training_grid,
)
from meshgen.neural.losses import boundary_local_size, boundary_loss, pde_loss, sample_boundary, sample_interior
from meshgen.neural.model import MLP, bubble
from meshgen.neural.winslow import winslow_residual

__all__ = [
    "TEST_SEED",
    "TEST_STENCIL_H",
    "Problem",
    "apply_map",
    "base_values",
    "boundary_draw",
    "boundary_pool",
    "boundary_rows",
    "boundary_term",
    "drawn_boundary",
    "evaluate_losses",
    "grid_min_scale",
    "grid_nodes_per_axis",
    "grid_of_draws",
    "grid_residual",
    "grid_tfi_derivatives",
    "lattice_tfi",
    "lattice_tfi_derivatives",
    "lbfgs_points",
    "make_test_set",
    "network_dtype",
    "pde_term",
    "points_residual",
    "pretrain_pool",
    "sample_pde_points",
    "sample_step",
    "split_rows",
    "step_samples",
    "test_loss",
]

TEST_SEED = 271828  # the held-out points are the same for every run, whatever its seed
TEST_STENCIL_H = 1e-3  # test-set residual: per-point stencils in float64, truncation error ~ h^2


@dataclass
class Problem:
    """What the network is trained on, in normalised units (geometry scaled into [-1/2, 1/2]^d)."""

    dim: int
    boundary: object  # (N, d) cube-boundary points -> (N, d) normalised physical points, NumPy
    center: np.ndarray
    scale: float
    exact: bool  # exact-boundary form: TFI + b N
    device: torch.device
    lattice_tfi: object = None  # TFI's differences on the whole lattice (``lattice_tfi``), made at the first call
    # the exact form's base is the boundary map itself at every point, not the TFI of its edges: an
    # extruded shape's section (``meshgen.geometry.extrusion.section_geometry``), whose map is the cap
    interior_map: bool = False


def base_values(problem: Problem, points) -> np.ndarray:
    """The exact form's base at the points ``points`` (one array per axis, broadcasting: as
    ``meshgen.methods.tfi.transfinite`` takes them): the TFI of the boundary map, or with
    ``problem.interior_map`` the map itself; (broadcast shape, d) float64, normalised units."""
    if not problem.interior_map:
        return transfinite(problem.boundary, points)
    grids = np.broadcast_arrays(*[np.asarray(p, dtype=float) for p in points])
    return problem.boundary(np.stack([g.ravel() for g in grids], axis=-1)).reshape(grids[0].shape + (problem.dim,))


def grid_tfi_derivatives(problem: Problem, axes, spacing, dtype=torch.float32) -> tuple[torch.Tensor, torch.Tensor]:
    """TFI's central differences (``grid_derivatives``) at the interior nodes of the grid ``axes``,
    computed in float64 and returned as ``dtype`` (the network's) on the CPU: first ([B,] m1, .., md, d, d), second
    ([B,] m1, .., md, d, d, d). The exact-boundary form's residual adds them to the differences of
    b N alone: in float32 the differences of TFI itself (values ~1, second differences over h^2)
    leave a round-off residual (about 1e-4 at h = 1/64) that no network can remove; b N is small,
    so its differences are exact to float32's precision."""
    dim = problem.dim
    batch = list(axes[0].shape[:-1])  # a batch of grids (lattice blocks): (B, n_i) per axis
    broadcast = [a.cpu().reshape(batch + [-1 if d == i else 1 for d in range(dim)]).numpy() for i, a in enumerate(axes)]
    values = torch.from_numpy(base_values(problem, broadcast))
    _, first, second = grid_derivatives(values, [float(h) for h in spacing])
    return first.to(dtype), second.to(dtype)


def lattice_tfi(problem: Problem) -> tuple[torch.Tensor, torch.Tensor]:
    """TFI's central differences (as :func:`grid_tfi_derivatives`, float64 then float32) at every
    interior node of the smoothed layout's fine lattice (spacing 1/``RESOLUTION``): first
    ((RESOLUTION - 1)^d, d, d), second ((RESOLUTION - 1)^d, d, d, d) on the CPU (36 MB in 3D),
    computed on the first call and kept on ``problem``. Every ``points.lattice`` training grid is a
    block of the lattice, so an Adam step slices them (:func:`lattice_tfi_derivatives`) instead of
    calling the geometry's boundary map, which cost as much as the step's forward and backward pass."""
    if problem.lattice_tfi is None:
        axis = torch.linspace(0.0, 1.0, RESOLUTION + 1, dtype=torch.float64)
        problem.lattice_tfi = grid_tfi_derivatives(problem, [axis] * problem.dim, [1.0 / RESOLUTION] * problem.dim)
    return problem.lattice_tfi


def lattice_tfi_derivatives(problem: Problem, axes, spacing=None) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`grid_tfi_derivatives` (float32) of a training grid on the lattice (1D ``axes`` of
    lattice nodes, halo included; ``spacing`` 1/``RESOLUTION``, unused): its block of
    :func:`lattice_tfi`, the same numbers."""
    starts = [int(round(float(a[0]) * RESOLUTION)) for a in axes]  # the halo's lattice index: first interior node - 1
    block = tuple(slice(start, start + len(a) - 2) for start, a in zip(starts, axes))
    first, second = lattice_tfi(problem)
    return first[block], second[block]


def apply_map(network: MLP, problem: Problem, points: torch.Tensor, tfi_values=None) -> torch.Tensor:
    """The normalised map at ``points`` (N, d): N(xi), or TFI(xi) + b(xi) N(xi) (``tfi_values`` (N, d))."""
    output = network(points)
    if not problem.exact:
        return output
    return tfi_values + bubble(points)[:, None] * output


def network_dtype(network) -> torch.dtype:
    """The floating-point type of the network's weights (float32; float64 in an ``lbfgs.float64`` stage)."""
    return next(network.parameters()).dtype


def grid_residual(network: MLP, problem: Problem, axes, spacing, tfi_derivatives=None) -> torch.Tensor:
    """Winslow residual at the interior nodes of the grid ``axes`` (1D float64 tensors, halo
    included; or (B, n_i) tensors, a batch of B grids) by finite differences: ([B,] m1, ..., md, d).
    The exact-boundary form needs TFI's differences at the interior nodes: ``tfi_derivatives``
    ((first, second) on the device, :func:`grid_tfi_derivatives`), computed here when not given."""
    nodes = grid_points(axes)
    flat = nodes.reshape(-1, problem.dim).to(problem.device, network_dtype(network))
    if not problem.exact:
        _, first, second = grid_derivatives(network(flat).reshape(*nodes.shape), spacing)
        return winslow_residual(first, second)
    if tfi_derivatives is None:
        tfi_derivatives = grid_tfi_derivatives(problem, axes, spacing)
    # the differences of TFI + b N: TFI's (computed in float64) plus those of b N (in the network's type)
    _, first, second = grid_derivatives((bubble(flat)[:, None] * network(flat)).reshape(*nodes.shape), spacing)
    tfi_first, tfi_second = (t.to(problem.device, flat.dtype) for t in tfi_derivatives)
    return winslow_residual(first + tfi_first, second + tfi_second)


def points_residual(network: MLP, problem: Problem, points: torch.Tensor) -> torch.Tensor:
    """Winslow residual at ``points`` (N, d) with autograd derivatives: (N, d)."""
    _, first, second = autograd_derivatives(network, points.to(problem.device, network_dtype(network)))
    return winslow_residual(first, second)


def grid_nodes_per_axis(config: TrainConfig, dim: int) -> int:
    """fd: interior nodes per axis, m = round(points.interior^(1/d)), at least 1."""
    return max(1, round(config.points.interior ** (1.0 / dim)))


def grid_min_scale(config: TrainConfig, random: bool = True) -> float:
    """The smallest fraction of the cube a training grid spans: ``points.grid_min_scale`` for the
    randomly shifted grids of the Adam stage, 1 (the fixed grid) otherwise."""
    return config.points.grid_min_scale if (random and config.points.random_grid) else 1.0


def grid_of_draws(config: TrainConfig, dim: int, draws: torch.Tensor):
    """The training grid (axes, spacing) of an Adam step's draws ((2 d,) uniform float64): randomly
    shifted and scaled (``grid_from_draws``), or with ``points.lattice`` one block of the smoothed
    layout's fine lattice at a random lattice offset (``lattice_grid_from_draws``)."""
    nodes = grid_nodes_per_axis(config, dim)
    if config.points.lattice:  # at most RESOLUTION - 2 interior nodes per axis fit the lattice
        return lattice_grid_from_draws(draws, min(nodes, RESOLUTION - 2), RESOLUTION)
    return grid_from_draws(draws, nodes, grid_min_scale(config))


def lattice_blocks(config: TrainConfig, dim: int, generator: torch.Generator):
    """The L-BFGS stage's fixed grid with ``points.lattice``: 4^d lattice blocks of m/4 interior
    nodes per axis (as many residual points as one m^d block) at lattice offsets drawn from
    ``generator``: spread over the cube, not one corner of it (fewer, larger blocks were measured
    to let L-BFGS fit the blocks and bend the map between them)."""
    nodes = max(1, min(grid_nodes_per_axis(config, dim), RESOLUTION - 2) // 4)
    draws = torch.rand((4**dim, 2 * dim), generator=generator, dtype=torch.float64)
    return lattice_grid_from_draws(draws, nodes, RESOLUTION)


def sample_pde_points(config: TrainConfig, dim: int, generator: torch.Generator, random: bool = True):
    """One step's interior points: a training grid (axes, spacing) for fd, random points for autograd."""
    if config.method.derivatives == "fd":
        if config.points.lattice:
            return (
                grid_of_draws(config, dim, torch.rand(2 * dim, generator=generator, dtype=torch.float64))
                if random
                else lattice_blocks(config, dim, generator)
            )
        return training_grid(dim, grid_nodes_per_axis(config, dim), generator, grid_min_scale(config, random))
    return sample_interior(config.points.interior, dim, generator)


def boundary_rows(problem: Problem, config: TrainConfig, points: torch.Tensor) -> torch.Tensor:
    """Rows [points | images | local size] of cube-boundary ``points`` (N, d): (N, 2d [+ 1]) float32
    on the CPU; the local size column only with ``method.boundary_error: relative``."""
    images = problem.boundary(points.double().numpy())
    columns = [points.float(), torch.from_numpy(images).float()]
    if config.method.boundary_error == "relative":
        size = boundary_local_size(problem.boundary, points.double().numpy(), images)
        columns.append(torch.from_numpy(size).float()[:, None])
    return torch.cat(columns, dim=1)


def split_rows(rows: torch.Tensor, dim: int):
    """(points, images, local size or None) of :func:`boundary_rows` rows."""
    return rows[:, :dim], rows[:, dim : 2 * dim], (rows[:, 2 * dim] if rows.shape[1] > 2 * dim else None)


def boundary_pool(problem: Problem, config: TrainConfig):
    """``points.boundary_pool`` steps' worth of :func:`boundary_rows`, computed once, on the device:
    the geometry's boundary map is NumPy code that costs as much as a forward pass per step if
    called every step. Drawn from its own seed, so a resumed run gets the same pool; None when
    switched off (or unused: the exact-boundary form has no boundary loss)."""
    if config.points.boundary_pool == 0 or problem.exact:
        return None
    generator = torch.Generator().manual_seed(config.seed + 3)
    count = config.points.boundary * config.points.boundary_pool
    return boundary_rows(problem, config, sample_boundary(count, problem.dim, generator)).to(problem.device)


def boundary_draw(problem: Problem, config: TrainConfig, generator: torch.Generator, pool=None) -> dict:
    """One draw of ``points.boundary`` boundary points, on the CPU: ``{"index": (N,) int64}`` into
    ``pool`` when given, else ``{"boundary": (N, 2d [+ 1])}`` fresh :func:`boundary_rows`."""
    if pool is not None:
        return {"index": torch.randint(0, len(pool), (config.points.boundary,), generator=generator)}
    return {"boundary": boundary_rows(problem, config, sample_boundary(config.points.boundary, problem.dim, generator))}


def drawn_boundary(draw: dict, pool, dim: int):
    """(points, images, local size or None) of a :func:`boundary_draw` (its tensors on the device)."""
    rows = pool.index_select(0, draw["index"]) if "index" in draw else draw["boundary"]  # index_select: faster than pool[index]
    return split_rows(rows, dim)


def sample_step(config: TrainConfig, problem: Problem, generator: torch.Generator, pool=None) -> dict:
    """What the host gives one Adam step, as CPU tensors drawn from ``generator`` in a fixed order:
    ``grid`` (2 d,) float64, the draws of the training grid (fd; the exact-boundary form adds
    ``tfi_first``, ``tfi_second``, TFI's differences at its nodes: the geometry is NumPy code) or ``points`` (N, d)
    random interior points (autograd); then the :func:`boundary_draw` (none for the exact-boundary
    form, which has no boundary loss)."""
    inputs = {}
    if config.method.derivatives == "fd":
        inputs["grid"] = torch.rand(2 * problem.dim, generator=generator, dtype=torch.float64)
        if problem.exact:
            axes, spacing = grid_of_draws(config, problem.dim, inputs["grid"])
            differences = lattice_tfi_derivatives if config.points.lattice else grid_tfi_derivatives
            inputs["tfi_first"], inputs["tfi_second"] = differences(problem, axes, spacing)
    else:
        inputs["points"] = sample_interior(config.points.interior, problem.dim, generator)
    if problem.exact:
        return inputs
    return {**inputs, **boundary_draw(problem, config, generator, pool)}


def step_samples(config: TrainConfig, problem: Problem, inputs: dict, pool=None):
    """The PDE sample (as :func:`pde_term` takes it) and the boundary sample ((points, images, local
    size or None), or None) of one step from its :func:`sample_step` inputs on the device."""
    dim = problem.dim
    if "grid" in inputs:
        axes, spacing = grid_of_draws(config, dim, inputs["grid"])
        pde = (axes, spacing, (inputs["tfi_first"], inputs["tfi_second"]) if "tfi_first" in inputs else None)
    else:
        pde = inputs["points"]
    if problem.exact:
        return pde, None
    return pde, drawn_boundary(inputs, pool, dim)


def pde_term(network, problem, config, sample) -> torch.Tensor:
    """L1 on one sample of :func:`sample_pde_points`."""
    if config.method.derivatives == "fd":
        return pde_loss(grid_residual(network, problem, *sample))
    return pde_loss(points_residual(network, problem, sample))


def boundary_term(network, problem, config, sample) -> torch.Tensor:
    """L2 on one boundary sample (zero for the exact-boundary form, which meets it by construction)."""
    if problem.exact:
        return torch.zeros((), device=problem.device)
    points, targets, size = sample
    dtype = network_dtype(network)
    size = size.to(dtype) if size is not None else None
    return boundary_loss(network(points.to(dtype)), targets.to(dtype), config.method.point_weights, size)[0]


# ---------------------------------------------------------------------------------------------
# fixed points: the held-out test set, the TFI fit's pool, the L-BFGS stage's points


def make_test_set(problem: Problem, config: TrainConfig) -> dict:
    """Fixed interior and boundary points (seed ``TEST_SEED``), float64 on the CPU; ``tfi``: TFI at
    the points :func:`test_loss` evaluates (filled at its first call, the exact-boundary form's)."""
    generator = torch.Generator().manual_seed(TEST_SEED)
    margin = 2 * TEST_STENCIL_H
    interior = margin + (1 - 2 * margin) * torch.rand((config.test.interior, problem.dim), generator=generator)
    boundary = sample_boundary(config.test.boundary, problem.dim, generator).double()
    targets = torch.from_numpy(problem.boundary(boundary.numpy()))
    return {"interior": interior.double(), "boundary": boundary, "targets": targets, "tfi": {}}


def test_loss(network: MLP, problem: Problem, test_set: dict) -> dict:
    """L1 and L2 (plain mean squared distance, no point weights) on the held-out points, evaluated
    the same way for every variant: float64, per-point 3^d stencils of spacing ``TEST_STENCIL_H``.
    TFI at those points (the exact-boundary form) is computed once per test set: every checkpoint
    evaluates it, and the boundary map at the 3^d stencils cost more than the network there."""
    exact_network = copy.deepcopy(network).double().cpu()
    cache = test_set.setdefault("tfi", {})

    def mapped(points, key):
        if problem.exact and key not in cache:
            cache[key] = torch.from_numpy(base_values(problem, list(points.numpy().T)))
        return apply_map(exact_network, problem, points, cache.get(key))

    with torch.no_grad():
        _, first, second = stencil_derivatives(lambda points: mapped(points, "stencils"), test_set["interior"], TEST_STENCIL_H)
        pde = float(pde_loss(winslow_residual(first, second)))
        if problem.exact:
            boundary = float((mapped(test_set["boundary"], "boundary") - test_set["targets"]).square().sum(-1).mean())
        else:
            boundary = float((exact_network(test_set["boundary"]) - test_set["targets"]).square().sum(-1).mean())
    return {"pde": pde, "boundary": boundary, "total": pde + boundary}


def pretrain_pool(problem: Problem, config: TrainConfig) -> dict:
    """Fixed points of the TFI fit: ``pretrain.points`` interior and as many boundary points."""
    generator = torch.Generator().manual_seed(config.seed + 1)
    points = torch.cat(
        [
            sample_interior(config.pretrain.points, problem.dim, generator),
            sample_boundary(config.pretrain.points, problem.dim, generator),
        ]
    ).double()
    targets = torch.from_numpy(base_values(problem, list(points.numpy().T)))
    return {"points": points.float().to(problem.device), "targets": targets.float().to(problem.device)}


def lbfgs_points(problem: Problem, config: TrainConfig) -> dict:
    """Fixed points of the L-BFGS stage: the unshifted training grid (fd) or random points, and
    fresh boundary points, drawn from their own seed so that a resumed run gets the same ones.
    The exact-boundary form's TFI differences in float64 with ``lbfgs.float64``, else float32."""
    generator = torch.Generator().manual_seed(config.seed + 2)
    pde = sample_pde_points(config, problem.dim, generator, random=False)
    if problem.exact and config.method.derivatives == "fd":  # TFI at the fixed grid once, not per iteration
        axes, spacing = pde
        dtype = torch.float64 if config.lbfgs.float64 else torch.float32
        pde = (axes, spacing, tuple(t.to(problem.device) for t in grid_tfi_derivatives(problem, axes, spacing, dtype)))
    if problem.exact:
        return {"pde": pde, "boundary": None}
    rows = boundary_draw(problem, config, generator)["boundary"].to(problem.device)
    return {"pde": pde, "boundary": split_rows(rows, problem.dim)}


def evaluate_losses(network, problem, config, points) -> dict:
    """L1 and L2 at fixed ``points`` (as from :func:`lbfgs_points`), without updating anything."""
    return {
        "L1": pde_term(network, problem, config, points["pde"]).item(),
        "L2": boundary_term(network, problem, config, points["boundary"]).item(),
    }
