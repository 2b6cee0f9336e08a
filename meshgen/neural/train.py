"""Training a mesh network (DESIGN section 6): the loop and the pieces it calls.

One run goes through up to three stages, each a number of steps in the configuration:

1. ``pretrain``: an L-BFGS least-squares fit of the network to TFI, so that training starts from
   a valid map that meets the boundary instead of a random one that first cuts the geometry's
   corners (DESIGN section 10);
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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from meshgen.errors import MeshgenError
from meshgen.neural import checkpoint as checkpoints
from meshgen.neural.config import TrainConfig, to_dict, to_yaml
from meshgen.neural.derivatives import (
    autograd_derivatives,
    grid_derivatives,
    grid_points,
    stencil_derivatives,
    training_grid,
)
from meshgen.neural.losses import boundary_loss, pde_loss, sample_boundary, sample_interior
from meshgen.neural.model import MLP, bubble, describe, normalisation, normalised_boundary
from meshgen.neural.pcgrad import assign, flatten, project_conflicting
from meshgen.neural.reweighting import UncertaintyWeights
from meshgen.neural.winslow import winslow_residual

STAGES = ("pretrain", "adam", "lbfgs")
HISTORY_COLUMNS = ("stage", "step", "L1", "L2", "total", "a1", "a2", "conflict", "lr", "seconds")
TEST_SEED = 271828  # the held-out points are the same for every run, whatever its seed
TEST_STENCIL_H = 1e-3  # test-set residual: per-point stencils in float64, truncation error ~ h^2
SUMMARY_CELLS = 30  # the final quality summary meshes 30^dim cells
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


def transfinite_tensor(problem: Problem, coords) -> torch.Tensor:
    """Normalised TFI at the broadcast of ``coords`` (float64 tensors), as float32 on the device."""
    from meshgen.tfi import transfinite

    values = transfinite(problem.boundary, [c.cpu().numpy() for c in coords])
    return torch.from_numpy(values).float().to(problem.device)


def apply_map(network: MLP, problem: Problem, points: torch.Tensor, tfi_values=None) -> torch.Tensor:
    """The normalised map at ``points`` (N, d): N(xi), or TFI(xi) + b(xi) N(xi) (``tfi_values`` (N, d))."""
    output = network(points)
    if not problem.exact:
        return output
    return tfi_values + bubble(points)[:, None] * output


def grid_residual(network: MLP, problem: Problem, axes, spacing) -> torch.Tensor:
    """Winslow residual at the interior nodes of the grid ``axes`` (1D float64 tensors, halo
    included) by finite differences: (m1, ..., md, d)."""
    nodes = grid_points(axes)
    flat = nodes.reshape(-1, problem.dim).float().to(problem.device)
    tfi_values = None
    if problem.exact:
        dim = problem.dim
        broadcast = [a.reshape([-1 if d == i else 1 for d in range(dim)]) for i, a in enumerate(axes)]
        tfi_values = transfinite_tensor(problem, broadcast).reshape(-1, dim)
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


def sample_pde_points(config: TrainConfig, dim: int, generator: torch.Generator, random: bool = True):
    """One step's interior points: a training grid (axes, spacing) for fd, random points for autograd."""
    if config.method.derivatives == "fd":
        min_scale = config.points.grid_min_scale if (random and config.points.random_grid) else 1.0
        return training_grid(dim, grid_nodes_per_axis(config, dim), generator, min_scale)
    return sample_interior(config.points.interior, dim, generator)


def pde_term(network, problem, config, sample) -> torch.Tensor:
    """L1 on one sample of :func:`sample_pde_points`."""
    if config.method.derivatives == "fd":
        return pde_loss(grid_residual(network, problem, *sample))
    return pde_loss(points_residual(network, problem, sample))


def boundary_sample(config: TrainConfig, problem: Problem, generator: torch.Generator, pool=None):
    """One step's boundary points (N, d) and their normalised images, float32 on the device: drawn
    from ``pool`` (see :func:`boundary_pool`) when given, else fresh."""
    dim = problem.dim
    if pool is not None:
        index = torch.randint(0, len(pool), (config.points.boundary,), generator=generator)
        drawn = pool.index_select(0, index.to(pool.device))  # several times faster than pool[index]
        return drawn[:, :dim], drawn[:, dim:]
    points = sample_boundary(config.points.boundary, dim, generator)
    targets = torch.from_numpy(problem.boundary(points.double().numpy())).float()
    return points.to(problem.device), targets.to(problem.device)


def boundary_pool(problem: Problem, config: TrainConfig):
    """``points.boundary_pool`` steps' worth of boundary points with their images, computed once,
    as one (P, 2d) tensor [points | images]: the geometry's boundary map is NumPy code that costs
    as much as a forward pass per step if called every step. Drawn from its own seed, so a resumed
    run gets the same pool; None when switched off (or unused: the exact-boundary form has no
    boundary loss)."""
    if config.points.boundary_pool == 0 or problem.exact:
        return None
    generator = torch.Generator().manual_seed(config.seed + 3)
    count = config.points.boundary * config.points.boundary_pool
    points = sample_boundary(count, problem.dim, generator)
    targets = torch.from_numpy(problem.boundary(points.double().numpy())).float()
    return torch.cat([points, targets], dim=1).to(problem.device)


def boundary_term(network, problem, config, sample) -> torch.Tensor:
    """L2 on one boundary sample (zero for the exact-boundary form, which meets it by construction)."""
    if problem.exact:
        return torch.zeros((), device=problem.device)
    points, targets = sample
    return boundary_loss(network(points), targets, config.method.point_weights)[0]


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
# one step of each stage; each returns the history row's numbers


def pretrain_step(network, problem, optimizer, pool) -> dict:
    """One L-BFGS step on the mean squared distance from TFI at the fixed pool of points."""

    def closure():
        optimizer.zero_grad(set_to_none=True)
        loss = (network(pool["points"]) - pool["targets"]).square().sum(-1).mean()
        if torch.isfinite(loss):
            loss.backward()
        return loss

    optimizer.step(closure)
    return {"total": closure().item()}


def adam_step(network, weights, problem, config, optimizer, scheduler, generator, pool=None) -> dict:
    """One step of the method: losses, g1 and g2, (PCGrad), the a-gradients of L, Adam, decay."""
    parameters = list(network.parameters())
    pde = pde_term(network, problem, config, sample_pde_points(config, problem.dim, generator))
    boundary = boundary_term(network, problem, config, boundary_sample(config, problem, generator, pool))
    factor_pde, factor_boundary = weights.factors()
    if not (torch.isfinite(pde) and torch.isfinite(boundary)):
        return {"L1": pde.item(), "L2": boundary.item(), "total": math.nan}
    # The two terms come from disjoint forward passes: two backward passes cost one joint pass.
    # materialize_grads: with autograd derivatives the output bias does not enter L1 at all.
    g1 = flatten(torch.autograd.grad(factor_pde * pde, parameters, allow_unused=True, materialize_grads=True))
    if problem.exact:
        g2 = torch.zeros_like(g1)
    else:
        g2 = flatten(torch.autograd.grad(factor_boundary * boundary, parameters))
    if config.method.pcgrad:
        update, conflict = project_conflicting(g1, g2)
    else:
        update, conflict = g1 + g2, (g1 @ g2) < 0
    assign(parameters, update)
    total = weights.objective(pde.detach(), boundary.detach())
    if weights.learned:  # the a take their gradient from L itself, outside the projection
        (weights.log_a.grad,) = torch.autograd.grad(total, weights.log_a)
    lr = optimizer.param_groups[0]["lr"]
    optimizer.step()
    scheduler.step()
    a1, a2 = weights.a().tolist()
    return {"L1": pde.item(), "L2": boundary.item(), "total": total.item(), "a1": a1, "a2": a2,
            "conflict": int(conflict), "lr": lr}


def lbfgs_step(network, weights, problem, config, optimizer, fixed) -> dict:
    """One L-BFGS step (``lbfgs.max_iter`` iterations) on the fixed points, a1 and a2 frozen."""
    factor_pde, factor_boundary = weights.factors()
    last = {}

    def closure():
        optimizer.zero_grad(set_to_none=True)
        pde = pde_term(network, problem, config, fixed["pde"])
        boundary = boundary_term(network, problem, config, fixed["boundary"])
        loss = factor_pde * pde + factor_boundary * boundary
        if torch.isfinite(loss):
            loss.backward()
        last.update(L1=pde.item(), L2=boundary.item())
        return loss

    optimizer.step(closure)
    losses = torch.tensor([last["L1"], last["L2"]], device=weights.log_a.device)
    total = weights.objective(losses[0], losses[1]).item()
    a1, a2 = weights.a().tolist()
    return {**last, "total": total, "a1": a1, "a2": a2, "lr": optimizer.param_groups[0]["lr"]}


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
        [sample_interior(config.pretrain.points, problem.dim, generator),
         sample_boundary(config.pretrain.points, problem.dim, generator)]
    ).double()
    targets = torch.from_numpy(transfinite(problem.boundary, list(points.numpy().T)))
    return {"points": points.float().to(problem.device), "targets": targets.float().to(problem.device)}


def lbfgs_points(problem: Problem, config: TrainConfig) -> dict:
    """Fixed points of the L-BFGS stage: the unshifted training grid (fd) or random points, and
    boundary points, drawn from their own seed so that a resumed run gets the same ones."""
    generator = torch.Generator().manual_seed(config.seed + 2)
    return {
        "pde": sample_pde_points(config, problem.dim, generator, random=False),
        "boundary": boundary_sample(config, problem, generator),
    }


# ---------------------------------------------------------------------------------------------
# history file


def open_history(path: Path, keep_until_step: int | None):
    """Open ``history.csv`` for appending. A new run starts it; a resumed run keeps the rows of the
    steps its checkpoint holds: a checkpoint at step N has done rows 0 .. N-1 (rows written after
    it, by a run killed before its next checkpoint, belong to the lost part)."""
    rows = []
    if keep_until_step is not None and path.is_file():
        with open(path, newline="") as handle:
            rows = [row for row in csv.DictReader(handle) if int(row["step"]) < keep_until_step]
    handle = open(path, "w", newline="")
    writer = csv.DictWriter(handle, fieldnames=HISTORY_COLUMNS, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    return handle, writer


def _format_row(row: dict) -> dict:
    return {k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()}


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
    quality summary.
    """
    from meshgen import __version__
    from meshgen.layout import with_layout

    geometry = with_layout(geometry, config.boundary_layout)  # the boundary the network learns
    run_dir = Path(run_dir)
    device = torch.device(device)
    stop = stop or (lambda: False)
    say = reporter.message if reporter is not None else (lambda text: None)
    dim = geometry.dim
    center, scale = normalisation(geometry)
    if resume is not None:  # the checkpoint's normalisation, bit for bit
        center, scale = np.asarray(resume["model"]["center"]), float(resume["model"]["scale"])
    problem = Problem(dim, normalised_boundary(geometry, center, scale), center, scale,
                      config.model.exact_boundary, device)

    torch.manual_seed(config.seed)
    network = MLP(dim, config.model.widths)
    if problem.exact:  # N = 0: training starts from TFI itself
        torch.nn.init.zeros_(network.layers[-1].weight)
        torch.nn.init.zeros_(network.layers[-1].bias)
    network.to(device)
    weights = UncertaintyWeights(config.method.pde_weight, config.method.boundary_weight, config.method.reweighting)
    weights.to(device)
    generator = torch.Generator().manual_seed(config.seed)
    stage, stage_step, step, elapsed = STAGES[0], 0, 0, 0.0
    lr_reductions = 0
    if resume is not None:
        network.load_state_dict(resume["model"]["state_dict"])
        weights.load_state_dict(resume["reweighting"])
        generator.set_state(resume["rng"]["sampler"])
        stage, stage_step, step = resume["stage"], resume["stage_step"], resume["step"]
        elapsed, lr_reductions = resume["elapsed_seconds"], resume["guard"]["lr_reductions"]
    test_set = make_test_set(problem, config)
    checkpoint_path = run_dir / "checkpoint.pt"
    (run_dir / "config.yaml").write_text(CONFIG_HEADER + to_yaml(config))
    history_file, history = open_history(run_dir / "history.csv", step if resume is not None else None)
    last_row: dict = dict(resume["history"]["last"]) if resume is not None else {}
    optimizer = scheduler = None
    started = time.perf_counter()

    def save(stage_name):
        history_file.flush()
        state = {
            "format": checkpoints.FORMAT,
            "format_version": checkpoints.FORMAT_VERSION,
            "meshgen_version": __version__,
            "model": describe(network, config.model.widths, problem.exact, center, scale),
            "geometry": {"name": geometry.name, "spec": geometry_spec or geometry.name, "dim": dim,
                         "params": dict(geometry.values)},
            "config": to_dict(config),
            "stage": stage_name,
            "stage_step": stage_step,
            "step": step,
            "elapsed_seconds": elapsed + (time.perf_counter() - started),
            "optimizer": optimizer.state_dict() if optimizer is not None else {},
            "scheduler": scheduler.state_dict() if scheduler is not None else {},
            "reweighting": {k: v.detach().cpu() for k, v in weights.state_dict().items()},
            "rng": {"sampler": generator.get_state(), "torch": torch.get_rng_state()},
            "history": {"rows": step, "last": dict(last_row)},
            "test_loss": test_loss(network, problem, test_set),
            "guard": {"lr_reductions": lr_reductions},
            "device": str(device),
        }
        checkpoints.save_checkpoint(checkpoint_path, state)
        return state

    interrupted = False
    try:
        for stage in STAGES[STAGES.index(stage) :] if stage != "done" else ():
            total = getattr(config, stage).steps
            if stage_step >= total:
                stage_step = 0
                continue
            optimizer, scheduler = make_optimizer(stage, network, weights, config)
            if resume is not None and resume["stage"] == stage:
                optimizer.load_state_dict(resume["optimizer"])
                if scheduler is not None:
                    scheduler.load_state_dict(resume["scheduler"])
            fit_points = pretrain_pool(problem, config) if stage == "pretrain" else None
            pool = boundary_pool(problem, config) if stage == "adam" else None
            fixed = lbfgs_points(problem, config) if stage == "lbfgs" else None
            if stage == "adam" and stage_step == 0 and weights.learned and config.method.balance_start:
                losses = evaluate_losses(network, problem, config, lbfgs_points(problem, config))
                weights.balance(losses["L1"], losses["L2"])
                say(f"reweighting started at the balance of L1 {losses['L1']:.3g}, L2 {losses['L2']:.3g}: "
                    f"a1 {weights.a()[0]:.3g}, a2 {weights.a()[1]:.3g}")
            if reporter is not None:
                reporter.stage(stage, stage_step, total)
            good = _snapshot(network, weights, optimizer, scheduler)
            failures = 0
            while stage_step < total:
                if stop():
                    interrupted = True
                    break
                if stage == "pretrain":
                    row = pretrain_step(network, problem, optimizer, fit_points)
                elif stage == "adam":
                    row = adam_step(network, weights, problem, config, optimizer, scheduler, generator, pool)
                else:
                    row = lbfgs_step(network, weights, problem, config, optimizer, fixed)
                if not (math.isfinite(row["total"]) and _finite(network)):
                    # Divergence guard: back to the last good state, a smaller learning rate.
                    failures += 1
                    lowered = [group["lr"] * config.guard.lr_factor for group in optimizer.param_groups]
                    _restore(good, network, weights, optimizer, scheduler)
                    if failures > config.guard.max_retries:
                        save(stage)
                        raise TrainingDiverged(
                            f"training diverged: the loss stayed non-finite at step {step} after "
                            f"{config.guard.max_retries} learning-rate reductions; the last good state is "
                            f"saved in {checkpoint_path}"
                        )
                    for group, lr in zip(optimizer.param_groups, lowered):
                        group["lr"] = lr
                    lr_reductions += 1
                    say(f"non-finite loss at step {step} ({stage}): restored the last good state, "
                        f"learning rate lowered to {optimizer.param_groups[0]['lr']:.3g}")
                    continue
                failures = 0
                good = _snapshot(network, weights, optimizer, scheduler)
                row = {"stage": stage, "step": step, **row, "seconds": elapsed + time.perf_counter() - started}
                row.setdefault("lr", optimizer.param_groups[0]["lr"])
                if stage == "pretrain":
                    row.update(a1=weights.a()[0].item(), a2=weights.a()[1].item())
                history.writerow(_format_row(row))
                last_row = row
                stage_step += 1
                step += 1
                if reporter is not None:
                    reporter.update(row, stage_step, total)
                if step % config.checkpoint.every == 0:
                    save(stage)
            if interrupted:
                break
            stage_step = 0
        final_stage = stage if interrupted else "done"
        state = save(final_stage)
    finally:
        history_file.close()
    seconds = elapsed + time.perf_counter() - started
    quality = write_summary(state, geometry, run_dir) if summary and not interrupted else None
    return TrainResult(checkpoint_path, final_stage, step, interrupted, seconds, state["test_loss"], state, quality)


def _snapshot(network, weights, optimizer, scheduler) -> dict:
    """Deep copies of everything a step changes (cheap next to a step: a few small tensors)."""
    return copy.deepcopy({
        "network": network.state_dict(),
        "weights": weights.state_dict(),
        "optimizer": optimizer.state_dict(),
        "scheduler": scheduler.state_dict() if scheduler is not None else None,
    })


def _restore(snapshot, network, weights, optimizer, scheduler) -> None:
    network.load_state_dict(snapshot["network"])
    weights.load_state_dict(snapshot["weights"])
    optimizer.load_state_dict(copy.deepcopy(snapshot["optimizer"]))
    if scheduler is not None:
        scheduler.load_state_dict(snapshot["scheduler"])


def _finite(network) -> bool:
    """Whether every weight is finite (a sum is non-finite as soon as one term is)."""
    return bool(torch.isfinite(torch.stack([p.sum() for p in network.parameters()]).sum()))


# ---------------------------------------------------------------------------------------------
# the final summary


def snapped(X: np.ndarray, geometry, coords) -> np.ndarray:
    """A copy of node array ``X`` with its boundary nodes moved onto the geometry's boundary map
    (what a soft-boundary mesh looks like once made to conform)."""
    from meshgen.neural.inference import snap_boundary

    X = X.copy()
    snap_boundary(X, geometry, coords)
    return X


def write_summary(checkpoint: dict, geometry, run_dir) -> dict:
    """Mesh ``SUMMARY_CELLS``^d cells with the trained map and with TFI, measure both with
    ``meshgen.quality`` (boundary deviation included), count the cells that snapping the network's
    boundary nodes onto the geometry inverts, write ``summary.json`` in ``run_dir`` and return it."""
    import json

    from meshgen.atomic import atomic_path
    from meshgen.neural.model import mesh_from_checkpoint
    from meshgen.quality import quality_report
    from meshgen.tfi import parametric_grid, tfi

    coords = parametric_grid([SUMMARY_CELLS] * geometry.dim)
    start = time.perf_counter()
    X = mesh_from_checkpoint(checkpoint, coords, geometry)
    meshing_seconds = time.perf_counter() - start
    summary = {
        "dims": [SUMMARY_CELLS] * geometry.dim,
        "network": quality_report(X, geometry),
        "inverted_after_snapping": quality_report(snapped(X, geometry, coords))["inverted"]["count"],
        "tfi": quality_report(tfi(geometry, None, coords), geometry),
        "meshing_seconds": meshing_seconds,
        "test_loss": checkpoint["test_loss"],
        "step": checkpoint["step"],
        "training_seconds": checkpoint["elapsed_seconds"],
    }
    with atomic_path(Path(run_dir) / "summary.json") as temporary:
        temporary.write_text(json.dumps(summary, indent=2) + "\n")
    return summary
