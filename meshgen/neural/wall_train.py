"""Training a wall-layer model (``meshgen.neural.wall_map``): one network for a row of blocks round a
wall, fitted to the plugin's mesh (``wall_teacher``: the airfoil's marched layers, which its
``wall_finish`` blends into its elliptic mesh) at the training's --dims, through the stage runner (``meshgen.neural.stages.run_stages``)
as every other run.

The fit is least squares on the network's vectors N, weighted by phi^2 (phi the network's share of
the grid lines' direction): the weighted misfit is that of the directions (X - w) / d themselves.
The three stages of the configuration take it as: ``pretrain`` L-BFGS on ``pretrain.points``
nodes, ``adam`` on ``points.interior`` nodes drawn each step (with replacement), ``lbfgs`` on ``points.interior +
points.boundary`` nodes drawn once (float64 with ``lbfgs.float64``). A tenth of the nodes, drawn
once, is held out (``test_loss``). The targets are computed in float64 from the teacher's nodes
((X - w) / d at d = 1e-6 next to coordinates of 100); they are O(1), so the network trains in
float32.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from meshgen.geometry.block_nodes import merged_mesh
from meshgen.geometry.blocks import BlockSet, tfi_blocks
from meshgen.neural import wall_map
from meshgen.neural.history import TrainState, state_from_checkpoint
from meshgen.neural.interface_stages import geometry_record
from meshgen.neural.reweighting import UncertaintyWeights
from meshgen.neural.stages import Job, Stage
from meshgen.neural.steps import TermRunner, Training, lbfgs_optimizer, make_optimizer
from meshgen.neural.wall_family_train import describe_family, family_rows, validate_family
from meshgen.quality import quality_report, write_json

__all__ = ["HELD_OUT", "WallNetwork", "WallProblem", "describe_wall", "wall_job", "wall_problem", "write_wall_summary"]

HELD_OUT = 0.1  # the share of the teacher's nodes held out of training
_LEAST_WEIGHT = 1e-6  # nodes whose weight is below this carry nothing: left out


class WallNetwork(torch.nn.Module):
    """(k, inputs) -> (k, 2): a tanh MLP with ``widths`` hidden layers under ``layers.<i>.``."""

    def __init__(self, inputs: int, widths: list[int]):
        super().__init__()
        sizes = [inputs, *widths, 2]
        self.layers = torch.nn.ModuleList(torch.nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:]))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.layers[:-1]:
            x = torch.tanh(layer(x))
        return self.layers[-1](x)


@dataclass
class WallProblem:
    """The fit: inputs (k, 2|3), targets N (k, 2), weights (k,), on the training device; the same of
    the held-out nodes; the frame's scales and the training's xi tables (what the model records)."""

    inputs: torch.Tensor
    targets: torch.Tensor
    weights: torch.Tensor
    test: tuple
    scales: dict
    tables: list
    device: torch.device
    dim: int = 2


def wall_scales(block_set: BlockSet) -> dict:
    """The scales of the network's inputs and of the blend (``wall_map``): the training's first
    cell, the far field's distance, a ring or a row, d0; from the plugin's ``wall_layout``."""
    layout = dict(wall_map.wall_hooks(block_set).wall_layout(block_set.values))
    d = np.asarray(block_set.coords[0][1], dtype=float) * float(layout["distance"])
    return {
        "first_height": float(d[1]),
        "distance": float(layout["distance"]),
        "closed": bool(layout["closed"]),
        "blend_distance": float(layout.get("blend_distance", wall_map.BLEND_DISTANCE)),
    }


def wall_rows(block_set: BlockSet, scales: dict, extra=()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fit's rows of ``block_set`` (its plugin's ``wall_teacher`` at its --dims): inputs (k, 2|3
    + len(extra)), with the constant ``extra`` inputs (a family member's) appended; targets N (k, 2);
    weights phi^2 (k,); nodes of negligible weight left out. float64."""
    hooks = wall_map.wall_hooks(block_set)
    near = hooks.wall_teacher(block_set)
    frame = wall_map.wall_frame(block_set, dict(hooks.wall_layout(block_set.values)))
    d = frame.d[1:]
    phi = wall_map.blend(d, scales["blend_distance"])
    inputs, targets, weights = [], [], []
    for X, wall, normal, q in zip(near, frame.walls, frame.normals, frame.q):
        u = (X[:, 1:] - wall[:, None]) / d[None, :, None]  # float64: the grid lines' directions
        N = (u - (1.0 - phi)[None, :, None] * normal[:, None]) / phi[None, :, None]
        inputs.append(wall_map.network_inputs(q, d, scales))
        targets.append(N.reshape(-1, 2))
        weights.append(np.broadcast_to(phi**2, u.shape[:2]).reshape(-1))
    inputs, targets, weights = np.concatenate(inputs), np.concatenate(targets), np.concatenate(weights)
    if len(extra):
        inputs = np.concatenate([inputs, np.broadcast_to(np.asarray(extra, dtype=float), (len(inputs), len(extra)))], axis=1)
    keep = weights > _LEAST_WEIGHT
    return inputs[keep], targets[keep], weights[keep]


def problem_of_rows(rows: tuple, scales: dict, tables: list, device: torch.device, seed: int) -> WallProblem:
    """The fit of ``rows`` (inputs, targets, weights), a ``HELD_OUT`` share of them held out."""
    inputs, targets, weights = rows
    held = np.random.default_rng(seed).random(len(inputs)) < HELD_OUT

    def tensors(mask):
        return tuple(torch.tensor(a[mask], dtype=torch.float32, device=device) for a in (inputs, targets, weights))

    return WallProblem(*tensors(~held), tensors(held), scales, tables, device)


def wall_problem(block_set: BlockSet, device: torch.device, seed: int) -> WallProblem:
    """The fit of ``block_set`` (its plugin's ``wall_layout`` and ``wall_teacher`` at its --dims)."""
    scales = wall_scales(block_set)
    tables = [[float(x) for x in coords[0]] for coords in block_set.coords]
    return problem_of_rows(wall_rows(block_set, scales), scales, tables, device, seed)


def _misfit(network, inputs, targets, weights) -> torch.Tensor:
    dtype = next(network.parameters()).dtype
    inputs, targets, weights = inputs.to(dtype), targets.to(dtype), weights.to(dtype)
    return (weights * (network(inputs) - targets).square().sum(-1)).sum() / weights.sum()


def _lbfgs_step(training: Training, optimizer, points) -> dict:
    def closure():
        optimizer.zero_grad(set_to_none=True)
        loss = _misfit(training.network, *points)
        if torch.isfinite(loss):
            loss.backward()
        return loss

    optimizer.step(closure)
    with torch.no_grad():
        return {"total": _misfit(training.network, *points).detach()}


def _subset(problem: WallProblem, count: int, generator: torch.Generator) -> tuple:
    """``count`` distinct rows drawn at random (all of them when there are fewer)."""
    pick = torch.randperm(len(problem.inputs), generator=generator)[: min(count, len(problem.inputs))].to(problem.device)
    return problem.inputs[pick], problem.targets[pick], problem.weights[pick]


def _draw(problem: WallProblem, count: int, generator: torch.Generator) -> tuple:
    """``count`` rows drawn at random with replacement: an Adam step's (a family holds millions of
    rows, whose permutation would cost more than the step)."""
    pick = torch.randint(len(problem.inputs), (count,), generator=generator).to(problem.device)
    return problem.inputs[pick], problem.targets[pick], problem.weights[pick]


def _adam_step(training: Training, optimizer, scheduler) -> dict:
    points = _draw(training.problem, training.config.points.interior, training.generator)
    optimizer.zero_grad(set_to_none=True)
    loss = _misfit(training.network, *points)
    loss.backward()
    optimizer.step()
    scheduler.step()
    return {"total": loss.detach()}


def _stage_table() -> tuple:
    def fixed(t: Training, count: int, offset: int) -> tuple:
        return _subset(t.problem, count, torch.Generator().manual_seed(t.config.seed + offset))

    return (
        Stage(
            "pretrain",
            optimizer=lambda t: make_optimizer("pretrain", t.network, t.weights, t.config),
            points=lambda t, state: fixed(t, t.config.pretrain.points, 1),
            step=lambda t, optimizer, scheduler, points: _lbfgs_step(t, optimizer, points),
        ),
        Stage(
            "adam",
            optimizer=lambda t: make_optimizer("adam", t.network, t.weights, t.config),
            points=lambda t, state: None,
            step=lambda t, optimizer, scheduler, points: _adam_step(t, optimizer, scheduler),
        ),
        Stage(
            "lbfgs",
            optimizer=lbfgs_optimizer,
            points=lambda t, state: fixed(t, t.config.points.interior + t.config.points.boundary, 2),
            step=lambda t, optimizer, scheduler, points: _lbfgs_step(t, optimizer, points),
        ),
    )


def describe_wall(training: Training, names, family: dict | None = None) -> dict:
    """The plain-data description of a wall-layer model (``meshgen.neural.wall_map``'s layout);
    ``family``: a family's ``model["family"]`` (``meshgen.neural.wall_family``)."""
    problem = training.problem
    return {
        **({} if family is None else {"family": family}),
        "kind": wall_map.KIND,
        "dim": 2,
        "widths": [int(w) for w in training.config.model.widths],
        "activation": "tanh",
        "exact_boundary": False,  # the wall is exact by construction, the far field by the plugin's blend
        "blocks": list(names),
        "scales": dict(problem.scales),
        "tables": [list(t) for t in problem.tables],
        "state_dict": {k: v.detach().cpu().float().clone() for k, v in training.network.state_dict().items()},
    }


def wall_job(config, block_set: BlockSet, device: torch.device, resume=None, geometry_spec=None, ranges=None, dims=None) -> Job:
    """The run (``meshgen.neural.stages.Job``) of a wall-layer model of ``block_set`` (its plugin
    defines ``meshgen.neural.wall_map.HOOKS``), or its continuation (``resume``). ``ranges`` (name ->
    (lo, hi)): a family about the middle member ``block_set``, its members meshed at ``dims``
    (``meshgen.neural.wall_family_train``); a resumed family takes both from its checkpoint."""
    family = None
    if resume is not None and "family" in resume["model"]:
        family = resume["model"]["family"]
        ranges, dims = {n: tuple(r) for n, r in family["ranges"].items()}, tuple(family["train_dims"])
    if ranges:
        family = family or describe_family(block_set, ranges, dims)
        scales = wall_scales(block_set)
        rows = family_rows(block_set, ranges, dims, scales, config.points.members, config.seed, wall_rows)
        tables = [[float(x) for x in coords[0]] for coords in block_set.coords]
        problem = problem_of_rows(rows, scales, tables, device, config.seed)
    else:
        problem = wall_problem(block_set, device, config.seed)
    torch.manual_seed(config.seed)
    inputs = (3 if problem.scales["closed"] else 2) + (len(ranges) if ranges else 0)
    network = WallNetwork(inputs, list(config.model.widths)).to(device)
    weights = UncertaintyWeights(1.0, 1.0, learned=False).to(device)  # one term: nothing to weigh
    generator = torch.Generator().manual_seed(config.seed)
    state = TrainState("pretrain")
    if resume is not None:
        if next(iter(resume["model"]["state_dict"].values())).dtype == torch.float64:
            network.double()
        network.load_state_dict(resume["model"]["state_dict"])
        generator.set_state(resume["rng"]["sampler"])
        state = state_from_checkpoint(resume)
    training = Training(network, weights, problem, config, generator, TermRunner(False))

    def describe_run() -> dict:
        with torch.no_grad():
            held_out = float(_misfit(network, *problem.test)) if len(problem.test[0]) else float("nan")
        return {
            "model": describe_wall(training, block_set.names, family),
            "geometry": geometry_record(block_set, geometry_spec),
            "reweighting": {k: v.detach().cpu() for k, v in weights.state_dict().items()},
            "test_loss": {"pde": held_out, "boundary": 0.0, "total": held_out, "fit": held_out},
        }

    def summary(checkpoint, run_dir):
        if family is not None:
            return write_family_summary(checkpoint, block_set, run_dir)
        return write_wall_summary(checkpoint, block_set, run_dir)

    return Job(training, state, _stage_table(), describe_run, summary)


def write_wall_summary(checkpoint: dict, block_set: BlockSet, run_dir) -> dict:
    """Quality of the training's --dims meshed by the model (what ``meshgen mesh`` writes), by the
    plugin's elliptic mesh (its teacher) and by TFI; ``summary.json``."""

    def report(Xs):
        points, cells, _ = merged_mesh(block_set, Xs)
        return quality_report((points, cells))

    neural, _ = wall_map.neural_wall_blocks(block_set, checkpoint["model"], check=False)  # inverted cells reported
    dims = [sum(len(c[0]) - 1 for c in block_set.coords), len(block_set.coords[0][1]) - 1]
    summary = {
        "dims": dims,
        "network": report(neural),
        "corrected": report(neural),
        "elliptic": report(wall_map.elliptic_reference(block_set)),
        "tfi": report(tfi_blocks(block_set)),
        "test_loss": checkpoint["test_loss"],
        "step": checkpoint["step"],
        "training_seconds": checkpoint["elapsed_seconds"],
    }
    write_json(Path(run_dir) / "summary.json", summary)
    return summary


def write_family_summary(checkpoint: dict, block_set: BlockSet, run_dir) -> dict:
    """A family's check (``meshgen.neural.wall_family_train.validate_family``: a grid of members,
    the corners included, meshed by the model and by the elliptic method); ``summary.json``."""
    summary = {
        "family": validate_family(checkpoint["model"], block_set.name),
        "test_loss": checkpoint["test_loss"],
        "step": checkpoint["step"],
        "training_seconds": checkpoint["elapsed_seconds"],
    }
    write_json(Path(run_dir) / "summary.json", summary)
    return summary
