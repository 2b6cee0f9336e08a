"""Training one network for a family of shapes (``meshgen train --vary``): the family's stage
table, run by ``meshgen.neural.stages.run_stages`` like a single shape's (design notes §6).

The family supplies what differs from a single shape: its problem (the members' boundary maps in
one normalisation), its loss (the weighted Winslow residual of several members on one grid, the
exact-boundary form, no boundary loss), its Adam inputs (a shifted grid and ``MEMBERS_PER_STEP``
members with their TFI, drawn on the host) and its L-BFGS batches (members covering the range,
redrawn every ``LBFGS_RESAMPLE`` steps). Resume, history, checkpoints, the divergence guard and
progress are the runner's. Configuration keys a family has no use for are refused
(``FAMILY_UNUSED_KEYS``), not ignored.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from meshgen.errors import ParameterError
from meshgen.methods.polish import polish
from meshgen.methods.tfi import parametric_grid, tfi, transfinite
from meshgen.neural import checkpoint as checkpoints
from meshgen.neural.derivatives import grid_derivatives, grid_from_draws, grid_points, training_grid
from meshgen.neural.family import (
    VALIDATION_POINTS,
    Family,
    FamilyMLP,
    describe_family_model,
    family_from_checkpoint,
    family_scale,
    member_size,
    mesh_member,
)
from meshgen.neural.history import TrainState, state_from_checkpoint
from meshgen.neural.model import bubble
from meshgen.neural.pcgrad import flatten
from meshgen.neural.reweighting import UncertaintyWeights
from meshgen.neural.stages import CheckpointWriter, Stage, TrainResult, run_stages
from meshgen.neural.steps import DEVICE_BLOCK, AdamSteps, TermRunner, Training, make_optimizer
from meshgen.neural.winslow import winslow_residual
from meshgen.quality import quality_report, write_json

__all__ = [
    "FAMILY_UNUSED_KEYS",
    "LBFGS_RESAMPLE",
    "END_SHARE",
    "MEMBERS_PER_STEP",
    "FamilyProblem",
    "check_family_keys",
    "covering_members",
    "family_gradients",
    "family_residual_loss",
    "lbfgs_batch",
    "summary_table",
    "tensors",
    "train_family",
    "write_family_summary",
]

MEMBERS_PER_STEP = 4  # members sampled per training step (their residuals are one batch)
END_SHARE = 1 / 3  # chance that an Adam member's parameter sits at an end of its range (sample_members)
TEST_MEMBERS = 8  # fixed held-out members of the test loss
TEST_SEED = 271828
LBFGS_INTERIOR = 8  # stratified members of the L-BFGS batch, beside the range's corners and middle
LBFGS_RESAMPLE = 5  # L-BFGS steps between two draws of its stratified members
SUMMARY_CELLS = 30
# What a family does not use, and why: it trains the exact-boundary form on the PDE loss alone,
# with fixed unit weights, finite differences on grids, no TFI fit and its own held-out members.
_NO_BOUNDARY_LOSS = "a family meets every member's boundary exactly and has no boundary loss"
FAMILY_UNUSED_KEYS = {
    "method.derivatives": "a family takes finite differences on shared grids",
    "method.reweighting": "a family has one loss, with a fixed weight",
    "method.balance_start": "a family has one loss, with a fixed weight",
    "method.pcgrad": "a family has one loss: no gradients to project",
    "method.point_weights": _NO_BOUNDARY_LOSS,
    "method.boundary_error": _NO_BOUNDARY_LOSS,
    "method.pde_weight": "a family has one loss, with a fixed weight",
    "method.boundary_weight": _NO_BOUNDARY_LOSS,
    "points.boundary": _NO_BOUNDARY_LOSS,
    "points.boundary_pool": _NO_BOUNDARY_LOSS,
    "points.lattice": "a family's members each have a layout of their own: no one lattice to train on",
    "points.members": "a Winslow family draws new members every step (points.members counts a wall-layer family's)",
    "pretrain.steps": "a family starts from every member's TFI (N = 0) and has no TFI fit",
    "pretrain.lr": "a family starts from every member's TFI (N = 0) and has no TFI fit",
    "pretrain.points": "a family starts from every member's TFI (N = 0) and has no TFI fit",
    "adam.weights_lr": "a family has one loss, with a fixed weight",
    "lbfgs.float64": "a family's L-BFGS stage runs in float32",
    "test.interior": f"a family's test loss is the residual of {TEST_MEMBERS} fixed members on the unshifted grid",
    "test.boundary": f"a family's test loss is the residual of {TEST_MEMBERS} fixed members on the unshifted grid",
}


def check_family_keys(keys, parameter: str = "overrides") -> None:
    """Raise a one-line ParameterError naming the configuration ``keys`` (dotted names the user
    set through ``parameter``) that a family cannot use, with why; keys a family uses pass."""
    unused = [key for key in keys if key in FAMILY_UNUSED_KEYS]
    if unused:
        reasons = "; ".join(dict.fromkeys(FAMILY_UNUSED_KEYS[key] for key in unused))
        raise ParameterError(
            parameter,
            f"{{name}} {', '.join(unused)}: a family (--vary) cannot use {'it' if len(unused) == 1 else 'them'}: {reasons}",
        )


@dataclass
class FamilyProblem:
    family: Family
    center: np.ndarray
    scale: float
    device: torch.device

    def boundary(self, values):
        """The member's boundary map in the family's normalised units: (N, d) -> (N, d)."""
        member = self.family.member(values)
        return lambda points: (member.boundary(points) - self.center) / self.scale


def sample_members(problem: FamilyProblem, count: int, generator: torch.Generator, ends: float = 0.0):
    """``count`` members in the ranges: q (count, k) float64 and the loss weights (S / s_p)^2
    (count,). Each parameter is uniform in its range, except that with probability ``ends`` it sits
    at one of the range's two ends (either with equal chance): with ``END_SHARE`` and k parameters
    a member is a corner of the box with probability END_SHARE^k and on its boundary with
    1 - (1 - END_SHARE)^k, so the corners, where members are most extreme, are trained as often as
    the validation grid meets them. The same random numbers are drawn whatever ``ends`` is."""
    shape = (count, len(problem.family.ranges))
    q = 2 * torch.rand(shape, generator=generator, dtype=torch.float64) - 1
    snap = torch.rand(shape, generator=generator, dtype=torch.float64) < ends
    side = torch.where(torch.rand(shape, generator=generator, dtype=torch.float64) < 0.5, -1.0, 1.0).to(torch.float64)
    q = torch.where(snap, side, q)
    return q, member_weights(problem, q)


def member_weights(problem: FamilyProblem, q) -> torch.Tensor:
    sizes = [member_size(problem.family.member(problem.family.values(row))) for row in q.tolist()]
    return torch.tensor([(problem.scale / size) ** 2 for size in sizes])


def members_tfi(problem: FamilyProblem, q: torch.Tensor, axes) -> torch.Tensor:
    """Normalised TFI of each member of ``q`` (B, k) at the grid of ``axes``: (B, n1, .., d) float32 on the CPU."""
    dim = len(axes)
    broadcast = [a.numpy().reshape([-1 if d == i else 1 for d in range(dim)]) for i, a in enumerate(axes)]
    values = [transfinite(problem.boundary(problem.family.values(row)), broadcast) for row in q.tolist()]
    return torch.from_numpy(np.stack(values)).float()


def family_residual_loss(network, problem: FamilyProblem, q, weights, axes, spacing, tfi_values=None):
    """Weighted mean over members of the mean squared Winslow residual on the grid ``axes`` (halo
    included), every member on the same grid, one batched forward pass."""
    nodes = grid_points(axes).float().to(problem.device)  # (n1, .., d)
    if tfi_values is None:
        tfi_values = members_tfi(problem, q, axes).to(problem.device)
    count, dim = len(q), nodes.shape[-1]
    shape = nodes.shape[:-1]
    flat = nodes.reshape(-1, dim)
    inputs_xi = flat.repeat(count, 1)
    inputs_q = q.float().to(problem.device).repeat_interleave(len(flat), dim=0)
    output = network(inputs_xi, inputs_q).reshape(count, *shape, dim)
    values = tfi_values + bubble(nodes)[..., None] * output
    _, first, second = grid_derivatives(values, spacing)
    residual = winslow_residual(first, second)  # (B, m1, .., d)
    per_member = residual.square().sum(-1).flatten(1).mean(1)
    return (per_member * weights.to(per_member)).mean()


def fixed_members(problem: FamilyProblem, count: int, seed: int, nodes: int):
    """``count`` members and the unshifted training grid with their TFI, from ``seed`` (the test
    loss)."""
    generator = torch.Generator().manual_seed(seed)
    q, weights = sample_members(problem, count, generator)
    return members_on_grid(problem, q, weights, nodes)


def members_on_grid(problem: FamilyProblem, q, weights, nodes: int):
    """Members ``q`` (B, k) with their loss ``weights`` on the unshifted training grid and their TFI
    there: the fixed batch of ``fixed_loss``."""
    axes, spacing = training_grid(problem.family.base.dim, nodes)
    return {"q": q, "weights": weights, "axes": axes, "spacing": spacing, "tfi": members_tfi(problem, q, axes).to(problem.device)}


def covering_members(parameters: int, interior: int, generator: torch.Generator) -> torch.Tensor:
    """Normalised members (2^k + 1 + interior, k) float64 that cover the box [-1, 1]^k: its corners,
    its middle and ``interior`` stratified samples (a Latin hypercube: each axis cut into
    ``interior`` equal slices, one sample in each, the slices paired at random between axes)."""
    corners = torch.tensor(list(itertools.product((-1.0, 1.0), repeat=parameters)), dtype=torch.float64)
    middle = torch.zeros((1, parameters), dtype=torch.float64)
    jitter = torch.rand((interior, parameters), generator=generator, dtype=torch.float64)
    slices = torch.stack([torch.randperm(interior, generator=generator) for _ in range(parameters)], dim=1)
    stratified = 2 * (slices + jitter) / interior - 1
    return torch.cat([corners, middle, stratified])


def lbfgs_batch(problem: FamilyProblem, nodes: int, seed: int, draw: int):
    """The L-BFGS stage's batch number ``draw``: the covering members (the range's corners, its
    middle and ``LBFGS_INTERIOR`` stratified samples) on the unshifted training grid. The stage
    draws new stratified members every ``LBFGS_RESAMPLE`` steps, so that it fits the whole range
    rather than a few members (8 uniform members, the earlier batch, left the slender corner of the
    semicylinder's range 0.85 deg below its elliptic mesh). The grid stays fixed: shifting it with
    every draw changes the objective too much for L-BFGS's curvature history (measured: the flower's
    worst member fell from +0.25 to -0.70 deg). Each draw has its own seed, so a resumed run draws
    the same batches."""
    generator = torch.Generator().manual_seed(seed + 1000003 * (draw + 1))
    q = covering_members(len(problem.family.ranges), LBFGS_INTERIOR, generator)
    return members_on_grid(problem, q, member_weights(problem, q), nodes)


def fixed_loss(network, problem, fixed) -> torch.Tensor:
    return family_residual_loss(network, problem, fixed["q"], fixed["weights"], fixed["axes"], fixed["spacing"], fixed["tfi"])


# ---------------------------------------------------------------------------------------------
# the family's steps


def grid_nodes(config, dim: int) -> int:
    """Interior nodes per axis of the training grid, as for one shape: round(points.interior^(1/d))."""
    return max(1, round(config.points.interior ** (1.0 / dim)))


def grid_min_scale(config) -> float:
    return config.points.grid_min_scale if config.points.random_grid else 1.0


def family_sample(training: Training) -> dict:
    """One Adam step's inputs, CPU tensors drawn from the run's generator: ``grid`` (2 d,) float64
    (the shifted grid's draws), ``q`` (B, k) float64 members, ``weights`` (B,) their loss weights
    and ``tfi`` (B, n1, .., d) float32 their TFI at the grid's nodes (the plugin is NumPy code)."""
    problem, config, generator = training.problem, training.config, training.generator
    dim = problem.family.base.dim
    draws = torch.rand(2 * dim, generator=generator, dtype=torch.float64)
    axes, _ = grid_from_draws(draws, grid_nodes(config, dim), grid_min_scale(config))
    q, weights = sample_members(problem, MEMBERS_PER_STEP, generator, END_SHARE)
    return {"grid": draws, "q": q, "weights": weights, "tfi": members_tfi(problem, q, axes)}


def family_gradients(training: Training, inputs: dict) -> dict:
    """The device part of one Adam step from :func:`family_sample`'s inputs (on the device), as
    ``meshgen.neural.steps.adam_gradients`` returns it: the gradient of the family loss (zero when
    the loss is not finite: the divergence guard takes over), L1 = total = the loss, L2 = 0."""
    config, problem = training.config, training.problem
    axes, spacing = grid_from_draws(inputs["grid"], grid_nodes(config, problem.family.base.dim), grid_min_scale(config))
    parameters = list(training.network.parameters())
    loss = family_residual_loss(training.network, problem, inputs["q"], inputs["weights"], axes, spacing, inputs["tfi"])
    update = flatten(torch.autograd.grad(loss, parameters))
    finite = torch.isfinite(loss)
    zero = torch.zeros((), device=loss.device)
    return {
        "update": torch.where(finite, update, torch.zeros_like(update)),
        "L1": loss.detach(),
        "L2": zero,
        "total": torch.where(finite, loss.detach(), torch.nan),
        "conflict": zero.int(),
    }


class LbfgsBatches:
    """The L-BFGS stage's batch of the current step: :func:`lbfgs_batch` number
    ``stage_step // LBFGS_RESAMPLE``, drawn when the step enters a new draw (or the stage resumes)."""

    def __init__(self, training: Training, state: TrainState):
        self.training, self.state = training, state
        self.draw, self.batch = None, None

    def __call__(self) -> dict:
        draw = self.state.stage_step // LBFGS_RESAMPLE
        if draw != self.draw:
            t = self.training
            self.draw, self.batch = (
                draw,
                lbfgs_batch(t.problem, grid_nodes(t.config, t.problem.family.base.dim), t.config.seed, draw),
            )
        return self.batch


def family_lbfgs_step(training: Training, optimizer, batches: LbfgsBatches) -> dict:
    """One L-BFGS step on the current batch; the row holds the loss after it."""
    network, problem, fixed = training.network, training.problem, batches()

    def closure():
        optimizer.zero_grad(set_to_none=True)
        loss = fixed_loss(network, problem, fixed)
        if torch.isfinite(loss):
            loss.backward()
        return loss

    optimizer.step(closure)
    with torch.no_grad():
        loss = fixed_loss(network, problem, fixed)
    return {"L1": loss, "L2": torch.zeros((), device=loss.device), "total": loss}


FAMILY_STAGES = (
    Stage(
        "adam",
        optimizer=lambda t: make_optimizer("adam", t.network, t.weights, t.config),
        points=lambda t, state: AdamSteps(t, lambda: family_sample(t), lambda inputs: family_gradients(t, inputs)),
        step=lambda t, optimizer, scheduler, steps: steps(optimizer, scheduler),
        block=lambda t: DEVICE_BLOCK if t.problem.device.type == "cuda" else 1,
    ),
    Stage(
        "lbfgs",
        optimizer=lambda t: make_optimizer("lbfgs", t.network, t.weights, t.config),
        points=LbfgsBatches,
        step=lambda t, optimizer, scheduler, batches: family_lbfgs_step(t, optimizer, batches),
    ),
)


def train_family(
    config,
    family: Family,
    run_dir,
    *,
    device: str = "cpu",
    resume: dict | None = None,
    reporter=None,
    stop=None,
    summary: bool = True,
) -> TrainResult:
    """Train one network for ``family`` (exact-boundary form, PDE loss alone): Adam on
    ``MEMBERS_PER_STEP`` members sampled per step, then L-BFGS on members covering the range
    (``lbfgs_batch``). Writes ``checkpoint.pt``, ``config.yaml``, ``history.csv`` and
    ``summary.json`` in ``run_dir``, as ``meshgen.neural.train.train`` does, and returns its
    TrainResult; ``resume`` continues a saved family checkpoint."""
    run_dir, device = Path(run_dir), torch.device(device)
    if config.boundary_layout != family.layout_name:
        raise ParameterError(
            "boundary_layout",
            f"{{name}} is {config.boundary_layout} but the family was made on the {family.layout_name} layout: "
            f"make it with make_family(..., layout={config.boundary_layout!r})",
        )
    dim = family.base.dim
    center, scale = family_scale(family)
    if resume is not None:
        center, scale = np.asarray(resume["model"]["center"]), float(resume["model"]["scale"])
    problem = FamilyProblem(family, center, scale, device)
    torch.manual_seed(config.seed)
    network = FamilyMLP(dim, len(family.ranges), config.model.widths)
    torch.nn.init.zeros_(network.layers[-1].weight)  # N = 0: every member starts from its TFI
    torch.nn.init.zeros_(network.layers[-1].bias)
    network.to(device)
    weights = UncertaintyWeights(0.5, 0.5, learned=False).to(device)  # a1 = a2 = 1: one loss, weight 1
    generator = torch.Generator().manual_seed(config.seed)
    state = TrainState(FAMILY_STAGES[0].name)
    if resume is not None:
        network.load_state_dict(resume["model"]["state_dict"])
        generator.set_state(resume["rng"]["sampler"])
        state = state_from_checkpoint(resume)
    training = Training(network, weights, problem, config, generator, TermRunner(False))
    test_members = fixed_members(problem, TEST_MEMBERS, TEST_SEED, grid_nodes(config, dim))
    layout_record = None if family.layout is None else tensors(family.layout.record())

    def describe_run() -> dict:
        with torch.no_grad():
            pde = float(fixed_loss(network, problem, test_members))
        return {
            "model": describe_family_model(network, config.model.widths, family, center, scale),
            "family": {
                "ranges": {k: [float(lo), float(hi)] for k, (lo, hi) in family.ranges.items()},
                "members_per_step": MEMBERS_PER_STEP,
                **({} if layout_record is None else {"layout": layout_record}),
            },
            "geometry": {"name": family.base.name, "spec": family.spec, "dim": dim, "params": dict(family.base.values)},
            "test_loss": {
                "pde": pde,
                "boundary": 0.0,
                "total": pde,
                "definition": f"weighted Winslow residual of {TEST_MEMBERS} fixed members on the unshifted training grid",
            },
        }

    saver = CheckpointWriter(training, describe_run, run_dir / "checkpoint.pt", state)
    checkpoint, interrupted = run_stages(
        FAMILY_STAGES, training, state, saver, run_dir, resume=resume, reporter=reporter, stop=stop
    )
    quality = write_family_summary(checkpoint, run_dir) if summary and not interrupted else None
    return TrainResult.of_run(saver, state, interrupted, checkpoint, quality)


def tensors(record: dict) -> dict:
    """``record`` with its NumPy arrays (in lists) as torch tensors: a checkpoint holds no NumPy."""
    return {
        k: [torch.from_numpy(v) if isinstance(v, np.ndarray) else v for v in value] if isinstance(value, list) else value
        for k, value in record.items()
    }


# ---------------------------------------------------------------------------------------------
# the end-of-training summary


def write_family_summary(checkpoint: dict, run_dir) -> dict:
    """Validate the family: mesh every member of its validation grid (``Family.grid``:
    ``VALIDATION_POINTS`` values per varied parameter, the box's corners included) at
    ``SUMMARY_CELLS``^d cells with the family network, polish a copy as ``meshgen mesh`` does by
    default (``meshgen.methods.polish``), mesh it with TFI, measure the three (``meshgen.quality``, boundary
    deviation included), write ``summary.json`` in ``run_dir`` and return it. ``worst`` indexes the
    worst member (:func:`worst_member`: most inverted cells of the network's mesh, then lowest mean
    minimum angle); ``failing`` lists the members whose network or polished mesh has an inverted
    cell. The per-member inverted counts are also written into the checkpoint
    (``checkpoint["family"]["validation"]``, saved again in place), so that ``meshgen mesh --param``
    can say when a member was not valid (``meshgen.neural.family.validation_note``)."""
    family = family_from_checkpoint(checkpoint)
    coords = parametric_grid([SUMMARY_CELLS] * family.base.dim)
    members = []
    for values in family.grid(VALIDATION_POINTS):
        geometry = family.member(values)
        start = time.perf_counter()
        X = mesh_member(checkpoint, values, coords)
        seconds = time.perf_counter() - start
        polished = X.copy()
        polish(polished, geometry, coords)
        members.append(
            {
                "params": values,
                "network": quality_report(X, geometry),
                "polished": quality_report(polished, geometry),
                "tfi": quality_report(tfi(geometry, None, coords), geometry),
                "meshing_seconds": seconds,
            }
        )
    failing = [
        {
            "params": m["params"],
            "network_inverted": m["network"]["inverted"]["count"],
            "polished_inverted": m["polished"]["inverted"]["count"],
        }
        for m in members
        if m["network"]["inverted"]["count"] or m["polished"]["inverted"]["count"]
    ]
    summary = {
        "dims": [SUMMARY_CELLS] * family.base.dim,
        "ranges": checkpoint["family"]["ranges"],
        "validation_points": VALIDATION_POINTS,
        "members": members,
        "worst": worst_member(members),
        "failing": failing,
        "test_loss": checkpoint["test_loss"],
        "step": checkpoint["step"],
        "training_seconds": checkpoint["elapsed_seconds"],
    }
    write_json(Path(run_dir) / "summary.json", summary)  # atomic; non-finite figures as null
    checkpoint["family"]["validation"] = {
        "points": VALIDATION_POINTS,
        "dims": [SUMMARY_CELLS] * family.base.dim,
        "members": [
            {
                "params": m["params"],
                "network_inverted": int(m["network"]["inverted"]["count"]),
                "polished_inverted": int(m["polished"]["inverted"]["count"]),
            }
            for m in members
        ],
    }
    checkpoints.save_checkpoint(Path(run_dir) / "checkpoint.pt", checkpoint)
    return summary


def worst_member(members) -> int:
    """Index of the worst of ``members`` (each with a ``"network"`` quality report): the most
    inverted cells first (an invalid mesh is worse than any valid one), then the lowest mean
    minimum angle (an undefined angle counts as the lowest)."""

    def badness(index):
        report = members[index]["network"]
        angle = report["metrics"]["min_angle"]["mean"]
        return (report["inverted"]["count"], -(angle if angle is not None else -np.inf))

    return max(range(len(members)), key=badness)


def summary_table(summary: dict) -> list[str]:
    """Lines for the terminal: per validated member, inverted cells and mean minimum angle of the
    network's mesh, of the polished mesh (what ``meshgen mesh`` writes) and of TFI's; then the
    failing members, or that there are none."""
    size = " x ".join(str(n) for n in summary["dims"])
    points = summary.get("validation_points", VALIDATION_POINTS)
    count = len(summary["members"])
    lines = [
        f"{size} meshes of {count} members, {points} values per varied parameter (the range's corners included); "
        "inverted cells, mean min angle:"
    ]

    def figures(report) -> str:
        return f"{report['inverted']['count']} inverted, {report['metrics']['min_angle']['mean']:.2f} deg"

    for index, member in enumerate(summary["members"]):
        at = ", ".join(f"{k}={v:g}" for k, v in member["params"].items())
        line = f"  {at}: network {figures(member['network'])}"
        if "polished" in member:
            line += f"; polished {figures(member['polished'])}"
        lines.append(line + f"; TFI {figures(member['tfi'])}" + ("  (worst)" if index == summary["worst"] else ""))
    failing = summary.get("failing")
    if failing is None:
        return lines

    def verdict(key: str) -> str:
        bad = sum(1 for m in failing if m[key])
        return f"all {count} valid" if not bad else f"{bad} of {count} NOT valid"

    lines.append(
        f"Validity (no inverted cell): polished meshes (what meshgen mesh writes) {verdict('polished_inverted')}; "
        f"the network's own meshes (--no-polish) {verdict('network_inverted')}."
    )
    for member in failing:
        at = ", ".join(f"{k}={v:g}" for k, v in member["params"].items())
        lines.append(
            f"  NOT valid: {at}: {member['network_inverted']} inverted cells in the network's mesh, {member['polished_inverted']} polished"
        )
    return lines
