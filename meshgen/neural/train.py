"""Training a mesh network (design notes §6): the loop and the pieces it calls.

One run goes through up to three stages, each a number of steps in the configuration:

1. ``pretrain``: an L-BFGS least-squares fit of the network to TFI, so that training starts from
   a valid map that meets the boundary instead of a random one that first cuts the geometry's
   corners (design notes §10);
2. ``adam``: the method proper. Each step samples a training grid (fd) or random interior points
   (autograd) and boundary points, computes L1 (Winslow residual) and L2 (boundary), their
   gradients g1, g2 on the network's weights, combines them (PCGrad or a plain sum), gives the
   reweighting parameters their gradient of L, and takes an Adam step with step decay. With
   ``method.balance_start`` the weights a1, a2 start at the stationary point of L for the
   first losses;
3. ``lbfgs``: L-BFGS with a strong Wolfe line search on fixed points and frozen weights a1, a2.

Everything is computed on the geometry normalised to unit size (``model.normalisation``: centre
of the bounding box, largest extent); the checkpoint stores the centre and scale. All randomness after the network's initialisation comes
from one generator whose state the checkpoint keeps, so a resumed run repeats an uninterrupted one.
"""

from __future__ import annotations

import copy
import csv
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from meshgen.errors import MeshgenError
from meshgen.inputs import read_input_text
from meshgen.neural import checkpoint as checkpoints
from meshgen.neural.config import TrainConfig, to_dict, to_yaml
from meshgen.neural.derivatives import (
    autograd_derivatives,
    grid_derivatives,
    grid_from_draws,
    grid_points,
    stencil_derivatives,
    training_grid,
)
from meshgen.neural.losses import boundary_local_size, boundary_loss, pde_loss, sample_boundary, sample_interior
from meshgen.neural.model import MLP, bubble, describe, normalisation, normalised_boundary
from meshgen.neural.pcgrad import assign, flatten, project_conflicting
from meshgen.neural.reweighting import UncertaintyWeights
from meshgen.neural.winslow import winslow_residual

HISTORY_COLUMNS = ("stage", "step", "L1", "L2", "total", "a1", "a2", "conflict", "lr", "seconds")
TEST_SEED = 271828  # the held-out points are the same for every run, whatever its seed
TEST_STENCIL_H = 1e-3  # test-set residual: per-point stencils in float64, truncation error ~ h^2
SUMMARY_CELLS = 30  # the final quality summary meshes 30^dim cells
# Adam steps on a GPU between two reads of their history rows: the device runs a block behind the
# host instead of idling at each step's read (about 0.2 s of steps for the paper's network on an H100)
DEVICE_BLOCK = 100
CONFIG_HEADER = "# meshgen train: the resolved configuration of this run (repeat it with --config FILE)\n"


class TrainingDiverged(MeshgenError):
    """The loss stayed non-finite after every allowed learning-rate reduction."""


@dataclass
class Problem:
    """What the network is trained on, in normalised units (geometry scaled into [-1/2, 1/2]^d)."""

    dim: int
    boundary: object  # (N, d) cube-boundary points -> (N, d) normalised physical points, NumPy
    center: np.ndarray
    scale: float
    exact: bool  # exact-boundary form: TFI + b N
    device: torch.device


@dataclass
class TrainResult:
    checkpoint_path: Path
    stage: str  # "done", or where an interrupted run stopped
    step: int
    interrupted: bool
    seconds: float
    test_loss: dict
    checkpoint: dict
    summary: dict | None  # the final quality summary (None when interrupted or not asked for)


# ---------------------------------------------------------------------------------------------
# the map and the losses


def grid_tfi(problem: Problem, axes) -> torch.Tensor:
    """Normalised TFI at the nodes of the grid ``axes`` (1D float64 tensors), flattened in
    :func:`grid_points`' order: (n, d) float32 on the CPU."""
    from meshgen.tfi import transfinite

    dim = problem.dim
    broadcast = [a.cpu().reshape([-1 if d == i else 1 for d in range(dim)]).numpy() for i, a in enumerate(axes)]
    return torch.from_numpy(transfinite(problem.boundary, broadcast)).float().reshape(-1, dim)


def apply_map(network: MLP, problem: Problem, points: torch.Tensor, tfi_values=None) -> torch.Tensor:
    """The normalised map at ``points`` (N, d): N(xi), or TFI(xi) + b(xi) N(xi) (``tfi_values`` (N, d))."""
    output = network(points)
    if not problem.exact:
        return output
    return tfi_values + bubble(points)[:, None] * output


def grid_residual(network: MLP, problem: Problem, axes, spacing, tfi_values=None) -> torch.Tensor:
    """Winslow residual at the interior nodes of the grid ``axes`` (1D float64 tensors, halo
    included) by finite differences: (m1, ..., md, d). The exact-boundary form needs TFI at the
    nodes: ``tfi_values`` ((n, d) on the device, :func:`grid_tfi`), computed here when not given."""
    nodes = grid_points(axes)
    flat = nodes.reshape(-1, problem.dim).float().to(problem.device)
    if problem.exact and tfi_values is None:
        tfi_values = grid_tfi(problem, axes).to(problem.device)
    values = apply_map(network, problem, flat, tfi_values).reshape(*nodes.shape)
    _, first, second = grid_derivatives(values, spacing)
    return winslow_residual(first, second)


def points_residual(network: MLP, problem: Problem, points: torch.Tensor) -> torch.Tensor:
    """Winslow residual at ``points`` (N, d) with autograd derivatives: (N, d)."""
    _, first, second = autograd_derivatives(network, points.to(problem.device))
    return winslow_residual(first, second)


def grid_nodes_per_axis(config: TrainConfig, dim: int) -> int:
    """fd: interior nodes per axis, m = round(points.interior^(1/d)), at least 1."""
    return max(1, round(config.points.interior ** (1.0 / dim)))


def grid_min_scale(config: TrainConfig, random: bool = True) -> float:
    """The smallest fraction of the cube a training grid spans: ``points.grid_min_scale`` for the
    randomly shifted grids of the Adam stage, 1 (the fixed grid) otherwise."""
    return config.points.grid_min_scale if (random and config.points.random_grid) else 1.0


def sample_pde_points(config: TrainConfig, dim: int, generator: torch.Generator, random: bool = True):
    """One step's interior points: a training grid (axes, spacing) for fd, random points for autograd."""
    if config.method.derivatives == "fd":
        return training_grid(dim, grid_nodes_per_axis(config, dim), generator, grid_min_scale(config, random))
    return sample_interior(config.points.interior, dim, generator)


def sample_step(config: TrainConfig, problem: Problem, generator: torch.Generator, pool=None) -> dict:
    """What the host gives one Adam step, as CPU tensors drawn from ``generator`` in a fixed order:
    ``grid`` (2 d,) float64, the draws of the training grid (fd; the exact-boundary form adds
    ``tfi`` (n, d) float32, TFI at its nodes: the geometry is NumPy code) or ``points`` (N, d)
    random interior points (autograd); then ``index`` (N,) int64 into ``pool`` (see
    :func:`boundary_pool`) or, without a pool, ``boundary_points`` and ``boundary_targets`` (N, d)
    float32 (and ``boundary_size`` (N,), the boundary's local size, with the relative boundary
    error); no boundary points for the exact-boundary form, which has no boundary loss."""
    inputs = {}
    if config.method.derivatives == "fd":
        inputs["grid"] = torch.rand(2 * problem.dim, generator=generator, dtype=torch.float64)
        if problem.exact:
            axes, _ = grid_from_draws(inputs["grid"], grid_nodes_per_axis(config, problem.dim), grid_min_scale(config))
            inputs["tfi"] = grid_tfi(problem, axes)
    else:
        inputs["points"] = sample_interior(config.points.interior, problem.dim, generator)
    if problem.exact:
        return inputs
    if pool is not None:
        inputs["index"] = torch.randint(0, len(pool), (config.points.boundary,), generator=generator)
    else:
        points = sample_boundary(config.points.boundary, problem.dim, generator)
        points, images, size = boundary_targets(problem, config, points)
        inputs["boundary_points"], inputs["boundary_targets"] = points, images
        if size is not None:
            inputs["boundary_size"] = size
    return inputs


def step_samples(training: Training, inputs: dict, pool=None):
    """The PDE sample (as :func:`pde_term` takes it) and the boundary sample ((points, images, local
    size or None), or None) of one step from its :func:`sample_step` inputs, moved to the device."""
    config, problem = training.config, training.problem
    dim = problem.dim
    if "grid" in inputs:
        axes, spacing = grid_from_draws(inputs["grid"], grid_nodes_per_axis(config, dim), grid_min_scale(config))
        pde = (axes, spacing, inputs.get("tfi"))
    else:
        pde = inputs["points"]
    if "index" in inputs:
        return pde, pool_rows(pool, inputs["index"], dim)
    if "boundary_points" in inputs:
        return pde, (inputs["boundary_points"], inputs["boundary_targets"], inputs.get("boundary_size"))
    return pde, None


def pde_term(network, problem, config, sample) -> torch.Tensor:
    """L1 on one sample of :func:`sample_pde_points`."""
    if config.method.derivatives == "fd":
        return pde_loss(grid_residual(network, problem, *sample))
    return pde_loss(points_residual(network, problem, sample))


def boundary_sample(config: TrainConfig, problem: Problem, generator: torch.Generator, pool=None):
    """One step's boundary points (N, d), their normalised images (N, d) and, with
    ``method.boundary_error: relative``, the boundary's local size there (N,) (else None), float32
    on the device: drawn from ``pool`` (see :func:`boundary_pool`) when given, else fresh."""
    dim = problem.dim
    if pool is not None:
        index = torch.randint(0, len(pool), (config.points.boundary,), generator=generator)
        return pool_rows(pool, index.to(pool.device), dim)
    points = sample_boundary(config.points.boundary, dim, generator)
    return tuple(None if t is None else t.to(problem.device) for t in boundary_targets(problem, config, points))


def pool_rows(pool: torch.Tensor, index: torch.Tensor, dim: int):
    """(points, images, local size or None) of the rows ``index`` of a :func:`boundary_pool`."""
    drawn = pool.index_select(0, index)  # several times faster than pool[index]
    return drawn[:, :dim], drawn[:, dim : 2 * dim], (drawn[:, 2 * dim] if drawn.shape[1] > 2 * dim else None)


def boundary_targets(problem: Problem, config: TrainConfig, points: torch.Tensor):
    """(points, images, local size or None) of cube-boundary ``points`` (N, d), float32 on the CPU."""
    images = problem.boundary(points.double().numpy())
    size = None
    if config.method.boundary_error == "relative":
        size = torch.from_numpy(boundary_local_size(problem.boundary, points.double().numpy(), images)).float()
    return points, torch.from_numpy(images).float(), size


def boundary_pool(problem: Problem, config: TrainConfig):
    """``points.boundary_pool`` steps' worth of boundary points with their images (and local sizes),
    computed once, as one (P, 2d [+ 1]) tensor [points | images | size]: the geometry's boundary
    map is NumPy code that costs as much as a forward pass per step if called every step. Drawn
    from its own seed, so a resumed run gets the same pool; None when switched off (or unused: the
    exact-boundary form has no boundary loss)."""
    if config.points.boundary_pool == 0 or problem.exact:
        return None
    generator = torch.Generator().manual_seed(config.seed + 3)
    count = config.points.boundary * config.points.boundary_pool
    points, images, size = boundary_targets(problem, config, sample_boundary(count, problem.dim, generator))
    columns = [points, images] + ([size[:, None]] if size is not None else [])
    return torch.cat(columns, dim=1).to(problem.device)


def boundary_term(network, problem, config, sample) -> torch.Tensor:
    """L2 on one boundary sample (zero for the exact-boundary form, which meets it by construction)."""
    if problem.exact:
        return torch.zeros((), device=problem.device)
    points, targets, size = sample
    return boundary_loss(network(points), targets, config.method.point_weights, size)[0]


# ---------------------------------------------------------------------------------------------
# the held-out test set


def make_test_set(problem: Problem, config: TrainConfig) -> dict:
    """Fixed interior and boundary points (seed ``TEST_SEED``), float64 on the CPU."""
    generator = torch.Generator().manual_seed(TEST_SEED)
    margin = 2 * TEST_STENCIL_H
    interior = margin + (1 - 2 * margin) * torch.rand((config.test.interior, problem.dim), generator=generator)
    boundary = sample_boundary(config.test.boundary, problem.dim, generator).double()
    targets = torch.from_numpy(problem.boundary(boundary.numpy()))
    return {"interior": interior.double(), "boundary": boundary, "targets": targets}


def test_loss(network: MLP, problem: Problem, test_set: dict) -> dict:
    """L1 and L2 (plain mean squared distance, no point weights) on the held-out points, evaluated
    the same way for every variant: float64, per-point 3^d stencils of spacing ``TEST_STENCIL_H``."""
    from meshgen.tfi import transfinite

    exact_network = copy.deepcopy(network).double().cpu()

    def mapped(points):
        tfi_values = torch.from_numpy(transfinite(problem.boundary, list(points.numpy().T))) if problem.exact else None
        return apply_map(exact_network, problem, points, tfi_values)

    with torch.no_grad():
        _, first, second = stencil_derivatives(mapped, test_set["interior"], TEST_STENCIL_H)
        pde = float(pde_loss(winslow_residual(first, second)))
        if problem.exact:
            boundary = float((mapped(test_set["boundary"]) - test_set["targets"]).square().sum(-1).mean())
        else:
            boundary = float((exact_network(test_set["boundary"]) - test_set["targets"]).square().sum(-1).mean())
    return {"pde": pde, "boundary": boundary, "total": pde + boundary}


# ---------------------------------------------------------------------------------------------
# both cores: the two terms of a step side by side


class TermRunner:
    """Runs the PDE and the boundary term of a step (two disjoint forward and backward passes) side
    by side on a CPU with ``parallel`` set, one in a worker thread, each with a single-threaded
    torch: the networks are too small for torch to split one product well over two cores (measured:
    2 threads per product gave no gain), but two independent passes keep both cores busy. Else (one
    core, or a GPU, which queues both anyway) one after the other. The same arithmetic either way,
    so a run repeats bit for bit with the same seed and threads."""

    def __init__(self, parallel: bool):
        from concurrent.futures import ThreadPoolExecutor

        self.pool = ThreadPoolExecutor(max_workers=1) if parallel else None

    def __call__(self, first, second):
        """(first(), second()): ``first`` in the worker thread when parallel."""
        if self.pool is None:
            return first(), second()
        pending = self.pool.submit(first)
        result = second()
        return pending.result(), result

    def close(self):
        if self.pool is not None:
            self.pool.shutdown()


@dataclass
class Training:
    """What the stages' steps work on: the network, the reweighting weights, the problem, the
    configuration, the sampler's generator and the term runner."""

    network: MLP
    weights: UncertaintyWeights
    problem: Problem
    config: TrainConfig
    generator: torch.Generator
    terms: TermRunner


# ---------------------------------------------------------------------------------------------
# one step of each stage; each returns the history row's numbers, those computed on the device as
# 0-d tensors there (the loop reads them once per step, in one transfer)


def pretrain_step(network, problem, optimizer, pool) -> dict:
    """One L-BFGS step on the mean squared distance from TFI at the fixed pool of points."""

    def closure():
        optimizer.zero_grad(set_to_none=True)
        loss = (network(pool["points"]) - pool["targets"]).square().sum(-1).mean()
        if torch.isfinite(loss):
            loss.backward()
        return loss

    optimizer.step(closure)
    with torch.no_grad():
        return {"total": (network(pool["points"]) - pool["targets"]).square().sum(-1).mean()}


def term_gradients(training: Training, pde_sample, boundary_sample_, factors):
    """L1 and L2 on one sample each, and g1, g2: the gradients of the weighted terms on the
    network's weights (flat), computed side by side (``Training.terms``)."""
    network, problem, config = training.network, training.problem, training.config
    parameters = list(network.parameters())

    def pde_part():
        pde = pde_term(network, problem, config, pde_sample)
        # materialize_grads: with autograd derivatives the output bias does not enter L1 at all.
        return pde, flatten(torch.autograd.grad(factors[0] * pde, parameters, allow_unused=True, materialize_grads=True))

    def boundary_part():
        if problem.exact:
            zero = torch.zeros((), device=problem.device)
            return zero, torch.zeros(sum(p.numel() for p in parameters), device=problem.device)
        boundary = boundary_term(network, problem, config, boundary_sample_)
        return boundary, flatten(torch.autograd.grad(factors[1] * boundary, parameters))

    (pde, g1), (boundary, g2) = training.terms(pde_part, boundary_part)
    return pde, boundary, g1, g2


def adam_gradients(training: Training, inputs: dict, pool=None) -> dict:
    """The device part of one step of the method, from the step's :func:`sample_step` inputs (on
    the device): L1, L2, their gradients g1, g2 combined into the update of the network's weights
    (PCGrad or the sum; zero when a loss is not finite, and the loop restores the last good state),
    L and its gradient on the reweighting parameters (``a_gradient``, learned weights only), and
    whether g1 and g2 conflict. Reads nothing back to the host and changes nothing, so that it can
    be captured into a CUDA graph (:mod:`meshgen.neural.cudagraph`)."""
    weights, config = training.weights, training.config
    pde_sample, boundary_points = step_samples(training, inputs, pool)
    factors = weights.factors().detach()
    pde, boundary, g1, g2 = term_gradients(training, pde_sample, boundary_points, factors)
    finite = torch.isfinite(pde) & torch.isfinite(boundary)
    if config.method.pcgrad:
        update, conflict = project_conflicting(g1, g2)
    else:
        update, conflict = g1 + g2, (g1 @ g2) < 0
    total = weights.objective(pde.detach(), boundary.detach())
    gradients = {
        "update": torch.where(finite, update, torch.zeros_like(update)),
        "L1": pde.detach(),
        "L2": boundary.detach(),
        "total": torch.where(finite, total.detach(), torch.nan),
        "conflict": conflict.int(),
    }
    if weights.learned:  # the a take their gradient from L itself, outside the projection
        (gradients["a_gradient"],) = torch.autograd.grad(total, weights.log_a)
    return gradients


def apply_adam(training: Training, optimizer, scheduler, gradients: dict) -> dict:
    """Give the network and the reweighting parameters their gradients from :func:`adam_gradients`
    and take the Adam step with its decay; returns the history row's numbers (0-d tensors, copied
    out of ``gradients``, which a CUDA graph overwrites at its next replay)."""
    weights = training.weights
    lr = optimizer.param_groups[0]["lr"]  # the rate of this step, before the decay
    assign(list(training.network.parameters()), gradients["update"])
    if weights.learned:
        weights.log_a.grad = gradients["a_gradient"].clone()
    losses = torch.stack([gradients["L1"], gradients["L2"], gradients["total"]])  # one copy
    conflict = gradients["conflict"].clone()
    optimizer.step()
    scheduler.step()
    a = weights.a().detach()
    return {"L1": losses[0], "L2": losses[1], "total": losses[2], "a1": a[0], "a2": a[1], "conflict": conflict, "lr": lr}


def adam_step(network, weights, problem, config, optimizer, scheduler, generator, pool=None, terms=None) -> dict:
    """One step of the method, eagerly: draw its inputs, :func:`adam_gradients`, :func:`apply_adam`.
    Non-finite losses return the row without a step (the loop's divergence guard takes over)."""
    training = Training(network, weights, problem, config, generator, terms or TermRunner(False))
    inputs = {name: value.to(problem.device) for name, value in sample_step(config, problem, generator, pool).items()}
    return apply_adam(training, optimizer, scheduler, adam_gradients(training, inputs, pool))


class AdamSteps:
    """The Adam stage's steps for one run: each draws its inputs on the host (:func:`sample_step`)
    and runs :func:`adam_gradients` on the device, eagerly on a CPU, as one replayed CUDA graph on
    a GPU (:mod:`meshgen.neural.cudagraph`), then :func:`apply_adam`."""

    def __init__(self, training: Training, pool=None):
        self.training, self.pool = training, pool
        device = training.problem.device

        def gradients(inputs):
            return adam_gradients(training, inputs, pool)

        if device.type == "cuda":
            from meshgen.neural.cudagraph import CapturedFunction

            self.gradients = CapturedFunction(gradients, device)
        else:
            self.gradients = lambda inputs: gradients({k: v.to(device) for k, v in inputs.items()})

    def __call__(self, optimizer, scheduler) -> dict:
        t = self.training
        inputs = sample_step(t.config, t.problem, t.generator, self.pool)
        return apply_adam(t, optimizer, scheduler, self.gradients(inputs))


def lbfgs_step(network, weights, problem, config, optimizer, fixed, terms=None) -> dict:
    """One L-BFGS step (``lbfgs.max_iter`` iterations) on the fixed points, a1 and a2 frozen."""
    training = Training(network, weights, problem, config, None, terms or TermRunner(False))
    parameters = list(network.parameters())
    factors = weights.factors().detach()
    last = {}

    def closure():
        pde, boundary, g1, g2 = term_gradients(training, fixed["pde"], fixed["boundary"], factors)
        assign(parameters, g1 + g2)
        last.update(L1=pde.detach(), L2=boundary.detach())
        return (factors[0] * pde + factors[1] * boundary).detach()

    optimizer.step(closure)
    total = weights.objective(last["L1"], last["L2"]).detach()
    a = weights.a().detach()
    return {**last, "total": total, "a1": a[0], "a2": a[1], "lr": optimizer.param_groups[0]["lr"]}


def evaluate_losses(network, problem, config, points) -> dict:
    """L1 and L2 at fixed ``points`` (as from :func:`lbfgs_points`), without updating anything."""
    return {
        "L1": pde_term(network, problem, config, points["pde"]).item(),
        "L2": boundary_term(network, problem, config, points["boundary"]).item(),
    }


def make_optimizer(stage: str, network, weights, config: TrainConfig):
    """The optimiser (and scheduler, or None) of ``stage``: L-BFGS for the TFI fit (a least-squares
    fit, where it converges in a fraction of Adam's time) and for the last stage, Adam between."""
    if stage == "adam":
        groups = [{"params": list(network.parameters())}]
        if weights.learned:
            groups.append({"params": [weights.log_a], "lr": config.adam.weights_lr or config.adam.lr})
        optimizer = torch.optim.Adam(groups, lr=config.adam.lr)
        scheduler = torch.optim.lr_scheduler.StepLR(optimizer, config.adam.decay_every, gamma=config.adam.decay)
        return optimizer, scheduler
    lbfgs = config.lbfgs
    optimizer = torch.optim.LBFGS(
        network.parameters(),
        lr=config.pretrain.lr if stage == "pretrain" else lbfgs.lr,
        max_iter=lbfgs.max_iter,
        history_size=lbfgs.history_size,
        line_search_fn="strong_wolfe",
        # Run every iteration: torch's default tolerances (absolute, 1e-7 on the gradient, 1e-9 on
        # the change) stop it early on our small normalised losses.
        tolerance_grad=0.0,
        tolerance_change=0.0,
    )
    return optimizer, None


def pretrain_pool(problem: Problem, config: TrainConfig) -> dict:
    """Fixed points of the TFI fit: ``pretrain.points`` interior and as many boundary points."""
    from meshgen.tfi import transfinite

    generator = torch.Generator().manual_seed(config.seed + 1)
    points = torch.cat(
        [
            sample_interior(config.pretrain.points, problem.dim, generator),
            sample_boundary(config.pretrain.points, problem.dim, generator),
        ]
    ).double()
    targets = torch.from_numpy(transfinite(problem.boundary, list(points.numpy().T)))
    return {"points": points.float().to(problem.device), "targets": targets.float().to(problem.device)}


def lbfgs_points(problem: Problem, config: TrainConfig) -> dict:
    """Fixed points of the L-BFGS stage: the unshifted training grid (fd) or random points, and
    boundary points, drawn from their own seed so that a resumed run gets the same ones."""
    generator = torch.Generator().manual_seed(config.seed + 2)
    pde = sample_pde_points(config, problem.dim, generator, random=False)
    if problem.exact and config.method.derivatives == "fd":  # TFI at the fixed grid once, not per iteration
        axes, spacing = pde
        pde = (axes, spacing, grid_tfi(problem, axes).to(problem.device))
    return {"pde": pde, "boundary": boundary_sample(config, problem, generator)}


# ---------------------------------------------------------------------------------------------
# the stages: a table, so the loop never branches on a stage's name


def balance_start(training: Training, say) -> None:
    """``method.balance_start``: a1, a2 from the stationary point of L for the first losses."""
    weights, config = training.weights, training.config
    if not (weights.learned and config.method.balance_start):
        return
    losses = evaluate_losses(training.network, training.problem, config, lbfgs_points(training.problem, config))
    weights.balance(losses["L1"], losses["L2"])
    say(
        f"reweighting started at the balance of L1 {losses['L1']:.3g}, L2 {losses['L2']:.3g}: "
        f"a1 {weights.a()[0]:.3g}, a2 {weights.a()[1]:.3g}"
    )


@dataclass(frozen=True)
class Stage:
    """One stage of training: how to make its optimiser, the fixed points it uses, one step, and
    what to do before its first step."""

    name: str
    optimizer: Callable  # (Training) -> (optimizer, scheduler or None)
    points: Callable  # (Training) -> the stage's fixed points (or None)
    step: Callable  # (Training, optimizer, scheduler, points) -> the history row's numbers
    start: Callable = lambda training, say: None  # (Training, say) before the stage's first step
    # (Training) -> steps taken between two reads of their rows (one wait for the device)
    block: Callable = lambda training: 1


STAGE_TABLE = (
    Stage(
        "pretrain",
        optimizer=lambda t: make_optimizer("pretrain", t.network, t.weights, t.config),
        points=lambda t: pretrain_pool(t.problem, t.config),
        step=lambda t, optimizer, scheduler, points: pretrain_step(t.network, t.problem, optimizer, points),
    ),
    Stage(
        "adam",
        optimizer=lambda t: make_optimizer("adam", t.network, t.weights, t.config),
        points=lambda t: AdamSteps(t, boundary_pool(t.problem, t.config)),
        step=lambda t, optimizer, scheduler, steps: steps(optimizer, scheduler),
        start=balance_start,
        block=lambda t: DEVICE_BLOCK if t.problem.device.type == "cuda" else 1,
    ),
    Stage(
        "lbfgs",
        optimizer=lambda t: make_optimizer("lbfgs", t.network, t.weights, t.config),
        points=lambda t: lbfgs_points(t.problem, t.config),
        step=lambda t, optimizer, scheduler, fixed: lbfgs_step(
            t.network, t.weights, t.problem, t.config, optimizer, fixed, t.terms
        ),
    ),
)
STAGES = tuple(stage.name for stage in STAGE_TABLE)


# ---------------------------------------------------------------------------------------------
# the state a checkpoint keeps


@dataclass
class TrainState:
    """Where training stands: the part of a checkpoint that is not the network, the weights, the
    optimiser or the random state (see ``checkpoint.py`` for the whole layout)."""

    stage: str = STAGES[0]  # or "done"
    stage_step: int = 0  # steps done in this stage
    step: int = 0  # steps done in all stages (= history rows)
    elapsed: float = 0.0  # training seconds before this process
    lr_reductions: int = 0  # by the divergence guard, over the whole run
    last_row: dict = field(default_factory=dict)  # the last history row


def state_from_checkpoint(checkpoint: dict) -> TrainState:
    return TrainState(
        checkpoint["stage"],
        checkpoint["stage_step"],
        checkpoint["step"],
        checkpoint["elapsed_seconds"],
        checkpoint["guard"]["lr_reductions"],
        dict(checkpoint["history"]["last"]),
    )


def state_to_checkpoint(state: TrainState, seconds: float) -> dict:
    """The checkpoint entries of ``state``; ``seconds``: training seconds of this process so far."""
    return {
        "stage": state.stage,
        "stage_step": state.stage_step,
        "step": state.step,
        "elapsed_seconds": state.elapsed + seconds,
        "history": {"rows": state.step, "last": dict(state.last_row)},
        "guard": {"lr_reductions": state.lr_reductions},
    }


# ---------------------------------------------------------------------------------------------
# history file


def open_history(path: Path, keep_until_step: int | None):
    """Open ``history.csv`` for appending. A new run starts it; a resumed run keeps the rows of the
    steps its checkpoint holds: a checkpoint at step N has done rows 0 .. N-1 (rows written after
    it, by a run killed before its next checkpoint, belong to the lost part)."""
    rows = []
    if keep_until_step is not None and path.is_file():
        # A row cut short by a kill (or an edited file) is dropped: a history is data, read leniently.
        text = read_input_text(path, "history").splitlines()
        rows = [row for row in csv.DictReader(text) if _history_step(row) is not None and _history_step(row) < keep_until_step]
    handle = open(path, "w", newline="")
    writer = csv.DictWriter(handle, fieldnames=HISTORY_COLUMNS, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    return handle, writer


def check_resumable(training: Training, resume: dict) -> None:
    """CheckpointError unless the optimiser and scheduler states of ``resume`` load into its stage's
    own (a damaged or stitched checkpoint fails here, before the run folder is written)."""
    for stage in STAGE_TABLE:
        if stage.name != resume["stage"]:
            continue
        optimizer, scheduler = stage.optimizer(training)
        try:
            optimizer.load_state_dict(resume["optimizer"])
            if scheduler is not None:
                scheduler.load_state_dict(resume["scheduler"])
        except (KeyError, TypeError, ValueError, RuntimeError, IndexError) as exc:
            raise checkpoints.CheckpointError(
                f"the checkpoint's optimiser state does not fit its stage '{stage.name}' ({type(exc).__name__}): the file is damaged"
            ) from None


def _history_step(row: dict) -> int | None:
    """The step of a history row, None for a row that is not a whole one (missing columns)."""
    try:
        return int(row["step"]) if None not in row.values() and None not in row else None
    except (KeyError, TypeError, ValueError):
        return None


def _format_row(row: dict) -> dict:
    return {k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()}


def read_rows(steps: list[dict], network) -> tuple[list[dict], bool]:
    """The numbers of consecutive steps (0-d tensors on the device, or Python numbers) as Python
    numbers, and whether all of them are good (finite losses, finite weights after the last): one
    transfer from the device, the only wait for it in the loop outside L-BFGS (whose line search
    reads its losses itself)."""
    keys = [k for k, v in steps[0].items() if isinstance(v, torch.Tensor)]
    finite_weights = torch.isfinite(torch.stack([p.detach().sum() for p in network.parameters()]).sum())
    values = torch.stack(
        [numbers[k].detach().double().reshape(()) for numbers in steps for k in keys] + [finite_weights.double()]
    ).tolist()
    rows = []
    for index, numbers in enumerate(steps):
        read = values[index * len(keys) : (index + 1) * len(keys)]
        rows.append({**numbers, **{k: (int(v) if k == "conflict" else v) for k, v in zip(keys, read)}})
    return rows, bool(values[-1]) and all(math.isfinite(row["total"]) for row in rows)


# ---------------------------------------------------------------------------------------------
# the divergence guard


class DivergenceGuard:
    """Keeps the last good state of a stage; after a non-finite step, restores it with a lower
    learning rate (``guard.lr_factor``), at most ``guard.max_retries`` times in a row. The loop
    checks steps a block at a time (one step on a CPU, ``DEVICE_BLOCK`` Adam steps on a GPU): a
    non-finite step anywhere in a block sends the run back to the state before the block."""

    def __init__(self, training: Training, optimizer, scheduler, state: TrainState):
        self.training, self.optimizer, self.scheduler, self.state = training, optimizer, scheduler, state
        self.failures = 0
        self.good = self._snapshot()

    def _snapshot(self) -> dict:
        """Deep copies of everything a step changes (cheap next to a step: a few small tensors)."""
        return copy.deepcopy(
            {
                "network": self.training.network.state_dict(),
                "weights": self.training.weights.state_dict(),
                "optimizer": self.optimizer.state_dict(),
                "scheduler": self.scheduler.state_dict() if self.scheduler is not None else None,
            }
        )

    def accept(self) -> None:
        """The step was good: it becomes the state to come back to."""
        self.failures = 0
        self.good = self._snapshot()

    def reject(self, stage: str, say) -> bool:
        """The step was not finite: restore the last good state with a lower learning rate. Returns
        False when the retries are spent (the good state restored, the learning rate not lowered)."""
        config = self.training.config.guard
        self.failures += 1
        lowered = [group["lr"] * config.lr_factor for group in self.optimizer.param_groups]
        self.training.network.load_state_dict(self.good["network"])
        self.training.weights.load_state_dict(self.good["weights"])
        self.optimizer.load_state_dict(copy.deepcopy(self.good["optimizer"]))
        if self.scheduler is not None:
            self.scheduler.load_state_dict(self.good["scheduler"])
        if self.failures > config.max_retries:
            return False
        for group, lr in zip(self.optimizer.param_groups, lowered):
            group["lr"] = lr
        self.state.lr_reductions += 1
        say(
            f"non-finite loss at step {self.state.step} ({stage}): restored the last good state, "
            f"learning rate lowered to {self.optimizer.param_groups[0]['lr']:.3g}"
        )
        return True


# ---------------------------------------------------------------------------------------------
# the loop


def train(
    config: TrainConfig,
    geometry,
    run_dir,
    *,
    device: str = "cpu",
    resume: dict | None = None,
    reporter=None,
    stop=None,
    geometry_spec: str | None = None,
    summary: bool = True,
) -> TrainResult:
    """Train (or, with ``resume`` = a loaded checkpoint, continue training) a mesh network.

    ``run_dir``: existing folder for ``checkpoint.pt``, ``config.yaml``, ``history.csv`` and
    ``summary.json``. ``reporter``: an object with ``stage(name, done, total)``,
    ``update(row, done, total)`` and ``message(text)`` (see ``meshgen.neural.progress``), or None.
    ``stop``: a callable polled before each step; when it returns True the state is saved and the
    run returns with ``interrupted=True``. ``geometry_spec``: how to load the geometry again (its
    name or plugin path; default its name). ``summary``: mesh 30^d cells at the end and write the
    quality summary. On a CPU with two or more torch threads, the two terms of a step run side by
    side (:class:`TermRunner`), torch single-threaded meanwhile.
    """
    from meshgen.layout import with_layout

    geometry = with_layout(geometry, config.boundary_layout)  # the boundary the network learns
    run_dir, stop = Path(run_dir), stop or (lambda: False)
    say = reporter.message if reporter is not None else (lambda text: None)
    training, state = start_training(config, geometry, torch.device(device), resume)
    saver = CheckpointWriter(training, geometry, geometry_spec, run_dir / "checkpoint.pt", state)
    if resume is not None:
        check_resumable(training, resume)  # before config.yaml and history.csv are touched
    (run_dir / "config.yaml").write_text(CONFIG_HEADER + to_yaml(config))
    history_file, history = open_history(run_dir / "history.csv", state.step if resume is not None else None)
    threads = torch.get_num_threads()
    if training.terms.pool is not None:
        torch.set_num_threads(1)
    interrupted = False
    try:
        for stage in STAGE_TABLE[STAGES.index(state.stage) :] if state.stage != "done" else ():
            total = getattr(config, stage.name).steps
            state.stage = stage.name
            if state.stage_step >= total:
                state.stage_step = 0
                continue
            optimizer, scheduler = stage.optimizer(training)
            saver.optimizer, saver.scheduler = optimizer, scheduler
            if resume is not None and resume["stage"] == stage.name:
                optimizer.load_state_dict(resume["optimizer"])
                if scheduler is not None:
                    scheduler.load_state_dict(resume["scheduler"])
            points = stage.points(training)
            if state.stage_step == 0:
                stage.start(training, say)
            if reporter is not None:
                reporter.stage(stage.name, state.stage_step, total)
            guard = DivergenceGuard(training, optimizer, scheduler, state)
            block = stage.block(training)
            every = config.checkpoint.every
            while state.stage_step < total and not (interrupted := stop()):
                # a block of steps, read back at once: on a GPU the host runs ahead of the device
                # instead of waiting for it at every step; it ends at a checkpoint and the stage's end
                count = min(block, total - state.stage_step, every - state.step % every)
                steps = [(stage.step(training, optimizer, scheduler, points), saver.seconds()) for _ in range(count)]
                rows, good = read_rows([numbers for numbers, _ in steps], training.network)
                if not good:  # the whole block is taken again from the last good state
                    if not guard.reject(stage.name, say):
                        saver.save(history_file)
                        raise TrainingDiverged(
                            f"training diverged: the loss stayed non-finite at step {state.step} after "
                            f"{config.guard.max_retries} learning-rate reductions; the last good state is "
                            f"saved in {saver.path}"
                        )
                    continue
                guard.accept()
                for row, (_, seconds) in zip(rows, steps):
                    row = {"stage": stage.name, "step": state.step, **row, "seconds": seconds}
                    row.setdefault("lr", optimizer.param_groups[0]["lr"])
                    row.setdefault("a1", training.weights.a()[0].item())  # the TFI fit leaves them as they are
                    row.setdefault("a2", training.weights.a()[1].item())
                    history.writerow(_format_row(row))
                    state.last_row, state.stage_step, state.step = row, state.stage_step + 1, state.step + 1
                    if reporter is not None:
                        reporter.update(row, state.stage_step, total)
                if state.step % every == 0:
                    saver.save(history_file)
            if interrupted:
                break
            state.stage_step = 0
        if not interrupted:
            state.stage = "done"
        checkpoint = saver.save(history_file)
    finally:
        history_file.close()
        training.terms.close()
        torch.set_num_threads(threads)
    quality = write_summary(checkpoint, geometry, run_dir) if summary and not interrupted else None
    return TrainResult(
        saver.path,
        state.stage,
        state.step,
        interrupted,
        checkpoint["elapsed_seconds"],
        checkpoint["test_loss"],
        checkpoint,
        quality,
    )


def start_training(config: TrainConfig, geometry, device: torch.device, resume: dict | None):
    """The Training (network initialised from the seed, or from ``resume``) and its TrainState."""
    dim = geometry.dim
    center, scale = normalisation(geometry)
    if resume is not None:  # the checkpoint's normalisation, bit for bit
        center, scale = np.asarray(resume["model"]["center"]), float(resume["model"]["scale"])
    problem = Problem(dim, normalised_boundary(geometry, center, scale), center, scale, config.model.exact_boundary, device)
    torch.manual_seed(config.seed)
    network = MLP(dim, config.model.widths)
    if problem.exact:  # N = 0: training starts from TFI itself
        torch.nn.init.zeros_(network.layers[-1].weight)
        torch.nn.init.zeros_(network.layers[-1].bias)
    network.to(device)
    weights = UncertaintyWeights(config.method.pde_weight, config.method.boundary_weight, config.method.reweighting)
    weights.to(device)
    generator = torch.Generator().manual_seed(config.seed)
    state = TrainState()
    if resume is not None:
        network.load_state_dict(resume["model"]["state_dict"])
        weights.load_state_dict(resume["reweighting"])
        generator.set_state(resume["rng"]["sampler"])
        state = state_from_checkpoint(resume)
    parallel = device.type == "cpu" and torch.get_num_threads() >= 2
    return Training(network, weights, problem, config, generator, TermRunner(parallel)), state


class CheckpointWriter:
    """Saves the whole checkpoint of a run (layout: ``checkpoint.py``): the network's description,
    the geometry, the configuration, the TrainState, the current stage's optimiser, the random
    state and the test-set loss. Keeps the clock of this process's training seconds."""

    def __init__(self, training: Training, geometry, geometry_spec, path: Path, state: TrainState):
        self.training, self.geometry, self.spec, self.path, self.state = training, geometry, geometry_spec, path, state
        self.optimizer = self.scheduler = None
        self.test_set = make_test_set(training.problem, training.config)
        self.started = time.perf_counter()

    def seconds(self) -> float:
        """Training seconds so far, earlier processes of a resumed run included."""
        return self.state.elapsed + time.perf_counter() - self.started

    def save(self, history_file) -> dict:
        from meshgen import __version__

        history_file.flush()
        t, geometry = self.training, self.geometry
        problem = t.problem
        checkpoint = {
            "format": checkpoints.FORMAT,
            "format_version": checkpoints.FORMAT_VERSION,
            "meshgen_version": __version__,
            "model": describe(t.network, t.config.model.widths, problem.exact, problem.center, problem.scale),
            "geometry": {
                "name": geometry.name,
                "spec": self.spec or geometry.name,
                "dim": geometry.dim,
                "params": dict(geometry.values),
            },
            "config": to_dict(t.config),
            **state_to_checkpoint(self.state, time.perf_counter() - self.started),
            "optimizer": self.optimizer.state_dict() if self.optimizer is not None else {},
            "scheduler": self.scheduler.state_dict() if self.scheduler is not None else {},
            "reweighting": {k: v.detach().cpu() for k, v in t.weights.state_dict().items()},
            "rng": {"sampler": t.generator.get_state(), "torch": torch.get_rng_state()},
            "test_loss": test_loss(t.network, problem, self.test_set),
            "device": str(problem.device),
        }
        checkpoints.save_checkpoint(self.path, checkpoint)
        return checkpoint


# ---------------------------------------------------------------------------------------------
# the final summary


def corrected(X: np.ndarray, geometry, coords) -> np.ndarray:
    """A copy of node array ``X`` corrected to X + TFI[g - X] (what ``meshgen mesh`` makes of a
    network's mesh by default; ``meshgen.correction.correct_boundary``)."""
    from meshgen.correction import correct_boundary

    X = X.copy()
    correct_boundary(X, geometry, coords)
    return X


def write_summary(checkpoint: dict, geometry, run_dir) -> dict:
    """Mesh ``SUMMARY_CELLS``^d cells with the trained map and with TFI, measure both with
    ``meshgen.quality`` (boundary deviation included), and the network's mesh after the boundary
    correction X + TFI[g - X] (``corrected``: what ``meshgen mesh`` writes), write ``summary.json`` in ``run_dir`` and return it."""
    from meshgen.neural.model import mesh_from_checkpoint
    from meshgen.quality import quality_report, write_json
    from meshgen.tfi import parametric_grid, tfi

    coords = parametric_grid([SUMMARY_CELLS] * geometry.dim)
    start = time.perf_counter()
    X = mesh_from_checkpoint(checkpoint, coords, geometry)
    meshing_seconds = time.perf_counter() - start
    summary = {
        "dims": [SUMMARY_CELLS] * geometry.dim,
        "network": quality_report(X, geometry),
        "corrected": quality_report(corrected(X, geometry, coords), geometry),
        "tfi": quality_report(tfi(geometry, None, coords), geometry),
        "meshing_seconds": meshing_seconds,
        "test_loss": checkpoint["test_loss"],
        "step": checkpoint["step"],
        "training_seconds": checkpoint["elapsed_seconds"],
    }
    write_json(Path(run_dir) / "summary.json", summary)  # atomic; non-finite figures as null
    return summary
