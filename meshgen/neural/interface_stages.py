"""The stages of a set of several blocks (design notes §20): one MLP per block, trained together by
the stage runner (``meshgen.neural.stages.run_stages``, through ``meshgen.neural.train.train``, the
one training entry) on the block terms and interface terms of ``meshgen.neural.interfaces``: a fit
of every block to its TFI, then Adam (PCGrad and the learned reweighting of L1 and L2, as for one
block), then L-BFGS on fixed points.

The checkpoint has the one-block layout (``meshgen.neural.checkpoint``); its ``model`` entry adds
``blocks`` (the block names, in the set's order) and holds every block's weights under
``networks.<i>.`` in one plain ``state_dict`` (``meshgen.neural.inference.block_model`` reads
block i, and reads 0.2's one network as block 0); its ``geometry`` entry adds ``blocks`` too.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from meshgen.geometry.block_nodes import merged_mesh
from meshgen.geometry.blocks import BlockSet, tfi_blocks
from meshgen.geometry.extrusion import extrusion_of, section_of
from meshgen.neural.config import ConfigError, keys_off_default
from meshgen.neural.elliptic_start import elliptic_pools, elliptic_targets
from meshgen.neural.history import TrainState, state_from_checkpoint
from meshgen.neural.inference import check_start_model, network_blocks, neural_blocks
from meshgen.neural.interfaces import (
    ANCHOR_POINTS,
    BlockNetworks,
    block_boundary_term,
    block_pde_term,
    block_problem,
    block_sample,
    block_samples,
    fixed_block_points,
    patch_pool,
    pretrain_block_pool,
    tfi_anchor_pool,
)
from meshgen.neural.model import INPUT_MAP
from meshgen.neural.pcgrad import assign, flatten
from meshgen.neural.projected_fit import hidden_parameters, projected_fit_step
from meshgen.neural.reweighting import UncertaintyWeights
from meshgen.neural.stages import Job, Stage
from meshgen.neural.steps import (
    DEVICE_BLOCK,
    AdamSteps,
    TermRunner,
    Training,
    combined_gradients,
    lbfgs_optimizer,
    make_optimizer,
)
from meshgen.quality import quality_report, write_json

__all__ = [
    "BLOCK_STAGES",
    "BLOCK_UNUSED_KEYS",
    "SUMMARY_DIMS",
    "block_gradients",
    "block_steps",
    "block_stage_table",
    "check_block_keys",
    "describe_blocks",
    "geometry_record",
    "set_job",
    "write_block_summary",
]


def geometry_record(block_set, geometry_spec=None) -> dict:
    """What a block set's checkpoint records of its geometry: name, spec (what ``-g`` named),
    dim, parameters and block names."""
    return {
        "name": block_set.name,
        "spec": geometry_spec or block_set.name,
        "dim": block_set.dim,
        "params": dict(block_set.values),
        "blocks": list(block_set.names),
    }


SUMMARY_DIMS = 8  # the final summary and the training's block set: 8 per --dims number
BLOCK_STAGES = ("pretrain", "adam", "lbfgs")

# Configuration keys a block set has no use for, with why: refused unless they hold the default
# (``check_block_keys``), so that no setting is silently ignored. ``boundary_layout`` is not
# among them: either value describes what a block set does (each block's own map is learned).
BLOCK_UNUSED_KEYS = {
    "model.exact_boundary": "a block set's networks are soft-boundary maps, corrected to their faces and interfaces when meshing",
    "method.derivatives": "a block set takes finite differences (a grid in each block, stencils across its interfaces)",
    "points.lattice": "a block set has no smoothed layout, so no lattice on which its faces solve the discrete equations",
}


def check_block_keys(config, name: str = "block set") -> None:
    """ConfigError (one line) naming every key of ``BLOCK_UNUSED_KEYS`` that ``config`` sets away
    from its default, with why a block set cannot use it; ``points.boundary_pool`` 0 (fresh patch
    points every step) too: a block set draws them from a fixed pool."""
    chosen = keys_off_default(config, BLOCK_UNUSED_KEYS)
    unused = {key: BLOCK_UNUSED_KEYS[key] for key in chosen}
    if config.points.boundary_pool == 0:
        chosen["points.boundary_pool"] = 0
        unused["points.boundary_pool"] = "a block set draws its patch points from a fixed pool (1 or more steps' worth)"
    if unused:
        keys = ", ".join(f"{key}={chosen[key]}" for key in unused)
        reasons = "; ".join(unused.values())
        raise ConfigError(f"{name} cannot use {keys} (leave {'it' if len(unused) == 1 else 'them'} at the default): {reasons}")


def describe_blocks(training: Training, names, extrusion=None) -> dict:
    """The plain-data description of a block set's trained maps (``meshgen.neural.model``'s, plus
    ``blocks``; weights of block i under ``networks.<i>.``), and ``extruded`` (the extrusion's
    ``describe()``) for the section model of an extruded block set."""
    problem, config = training.problem, training.config
    return {
        **({"extruded": extrusion.describe()} if extrusion is not None else {}),
        "dim": problem.dim,
        "widths": [int(w) for w in config.model.widths],
        "activation": "tanh",
        "input": INPUT_MAP,
        "exact_boundary": False,
        "center": [float(c) for c in problem.center],
        "scale": float(problem.scale),
        "blocks": list(names),
        "state_dict": {k: v.detach().cpu().clone() for k, v in training.network.state_dict().items()},
    }


def _per_face(training: Training) -> int:
    problem = training.problem
    return max(8, training.config.points.boundary // max(1, len(problem.patch_faces) + len(problem.interfaces)))


def _terms(training: Training, pool, pde_sample, boundary_sample, factors):
    """L1, L2 and the gradients of the weighted terms on the networks' weights (flat), side by side."""
    networks, problem, config = training.network.networks, training.problem, training.config
    parameters = list(training.network.parameters())

    def pde_part():
        pde = block_pde_term(networks, problem, pde_sample)
        return pde, flatten(torch.autograd.grad(factors[0] * pde, parameters, allow_unused=True, materialize_grads=True))

    def boundary_part():
        boundary = block_boundary_term(networks, problem, config, pool, boundary_sample)
        return boundary, flatten(
            torch.autograd.grad(factors[1] * boundary, parameters, allow_unused=True, materialize_grads=True)
        )

    (pde, g1), (boundary, g2) = training.terms(pde_part, boundary_part)
    return pde, boundary, g1, g2


def block_gradients(training: Training, inputs: dict, pool: dict) -> dict:
    """The device part of one Adam step (``meshgen.neural.steps.adam_gradients`` for a block set):
    L1, L2, the update (PCGrad or the sum), L and the reweighting gradient."""
    weights, config = training.weights, training.config
    pde_sample, boundary_sample = block_samples(config, training.problem, inputs)
    factors = weights.factors().detach()
    pde, boundary, g1, g2 = _terms(training, pool, pde_sample, boundary_sample, factors)
    return combined_gradients(weights, config.method.pcgrad, pde, boundary, g1, g2)


def _pretrain_step(training: Training, optimizer, pools) -> dict:
    networks = training.network.networks

    def loss():
        return torch.stack([(net(p["points"]) - p["targets"]).square().sum(-1).mean() for net, p in zip(networks, pools)]).mean()

    def closure():
        optimizer.zero_grad(set_to_none=True)
        value = loss()
        if torch.isfinite(value):
            value.backward()
        return value

    optimizer.step(closure)
    with torch.no_grad():
        return {"total": loss()}


def _held_out_config(config):
    """``config`` with the held-out draw's sizes (``test.interior``, ``test.boundary``) as its points'."""
    points = dataclasses.replace(config.points, interior=config.test.interior, boundary=config.test.boundary)
    return dataclasses.replace(config, points=points)


def _fixed_losses(training: Training, pool, fixed, config=None) -> tuple:
    """(L1, L2) at the fixed draw ``fixed`` (made with ``config``'s sizes: the training's by default)."""
    pde_sample, boundary_sample = block_samples(config or training.config, training.problem, fixed, random=False)
    with torch.no_grad():
        pde = block_pde_term(training.network.networks, training.problem, pde_sample)
        boundary = block_boundary_term(training.network.networks, training.problem, training.config, pool, boundary_sample)
    return float(pde), float(boundary)


def _lbfgs_step(training: Training, optimizer, pool, fixed) -> dict:
    parameters = list(training.network.parameters())
    weights = training.weights
    factors = weights.factors().detach()
    pde_sample, boundary_sample = block_samples(training.config, training.problem, fixed, random=False)
    last = {}

    def closure():
        pde, boundary, g1, g2 = _terms(training, pool, pde_sample, boundary_sample, factors)
        assign(parameters, g1 + g2)
        last.update(L1=pde.detach(), L2=boundary.detach())
        return (factors[0] * pde + factors[1] * boundary).detach()

    optimizer.step(closure)
    a = weights.a().detach()
    total = weights.objective(last["L1"], last["L2"]).detach()
    return {**last, "total": total, "a1": a[0], "a2": a[1], "lr": optimizer.param_groups[0]["lr"]}


def lbfgs_points(training: Training, pool_count: int) -> tuple[dict, dict]:
    """The L-BFGS stage's (patch pool, fixed draw): patch and interface points on regular lattices
    (``fixed_block_points(..., lattice=...)``), as many per face as a step's draw."""
    problem, config = training.problem, training.config
    per_face = _per_face(training)
    pool = patch_pool(problem, per_face, config.seed + 3, lattice=True)
    count = pool["points"].shape[1]
    return pool, fixed_block_points(problem, config, pool_count, config.seed + 2, lattice=count)


def block_steps(training: Training, name: str) -> int:
    """The steps of stage ``name`` (adam, lbfgs) of a block set's run: its ``block_steps`` where the
    networks are fitted to the elliptic mesh first (``pretrain.target`` auto or elliptic, and
    ``pretrain.steps`` above 0: not an ``--init`` run) and the configuration sets it, else its ``steps``."""
    config = training.config
    stage = getattr(config, name)
    if config.pretrain.target == "tfi" or config.pretrain.steps == 0 or stage.block_steps is None:
        return stage.steps
    return stage.block_steps


def block_stage_table(pool: dict, pool_count: int, start_pools=None, start_note: str | None = None) -> tuple:
    """The stages of a block set's run (the runner's table): ``pretrain``, ``adam``, ``lbfgs``.
    ``start_pools`` (a callable giving the fit's per-block pools, ``elliptic_start.elliptic_pools``):
    what ``pretrain`` fits the networks to, ``start_note`` the line that says so; None: their TFI at
    ``pretrain.points`` random points."""

    def balance(training: Training, say) -> None:
        weights, config = training.weights, training.config
        if not (weights.learned and config.method.balance_start):
            return
        fixed = fixed_block_points(training.problem, config, pool_count, config.seed + 2)
        pde, boundary = _fixed_losses(training, pool, fixed)
        weights.balance(pde, boundary)
        say(f"reweighting started at the balance of L1 {pde:.3g}, L2 {boundary:.3g}")

    def fitted(t: Training):
        """The fit to the elliptic mesh moves the hidden layers (the output layer is solved), in
        float64: in float32 the features' round-off stalls L-BFGS's line search within a few
        iterations (the wedge's section at a misfit of 1.8e-6, where float64 reaches 1e-8)."""
        if start_pools is None:
            return None
        t.network.double()
        return hidden_parameters(t.network.networks)

    def adam_steps(t: Training) -> AdamSteps:
        return AdamSteps(
            t,
            lambda: block_sample(t.problem, t.config, t.generator, pool_count),
            lambda inputs: block_gradients(t, inputs, pool),
        )

    return (
        Stage(
            "pretrain",
            optimizer=lambda t: make_optimizer("pretrain", t.network, t.weights, t.config, fitted(t)),
            points=lambda t, state: (
                start_pools()
                if start_pools is not None
                else pretrain_block_pool(t.problem, t.config.pretrain.points, t.config.seed + 1)
            ),
            step=lambda t, optimizer, scheduler, pools: (
                _pretrain_step(t, optimizer, pools)
                if start_pools is None
                else projected_fit_step(t.network.networks, optimizer, pools)
            ),
            start=lambda t, say: say(start_note) if start_note else None,
            title=None if start_pools is None else "Elliptic fit",
        ),
        Stage(
            "adam",
            optimizer=lambda t: make_optimizer("adam", t.network, t.weights, t.config),
            points=lambda t, state: adam_steps(t),
            step=lambda t, optimizer, scheduler, steps: steps(optimizer, scheduler),
            start=balance,
            block=lambda t: DEVICE_BLOCK if t.problem.device.type == "cuda" else 1,
            total=lambda t: block_steps(t, "adam"),
        ),
        Stage(
            "lbfgs",
            optimizer=lbfgs_optimizer,
            points=lambda t, state: lbfgs_points(t, pool_count),
            step=lambda t, optimizer, scheduler, points: _lbfgs_step(t, optimizer, *points),
            total=lambda t: block_steps(t, "lbfgs"),
        ),
    )


def set_job(config, block_set: BlockSet, device: torch.device, resume=None, geometry_spec=None, init=None) -> Job:
    """The run (``meshgen.neural.stages.Job``) of one model for ``block_set`` (several blocks), or
    its continuation (``resume``): one network per block, the block set's stage table. The networks
    map each block's unit cube; meshes of any --dims come from them. ``init``: {"path",
    "checkpoint"} (``meshgen train --init``): a new run whose networks and loss weights start as
    that checkpoint's (its normalisation, its weights' type), recorded in the checkpoint's ``init``
    entry."""
    center = scale = None
    start = resume if resume is not None else (init or {}).get("checkpoint")
    extrusion = extrusion_of(block_set)  # an extruded set is trained on its section (design notes §20)
    trained_set = block_set if extrusion is None else section_of(block_set, extrusion)
    if start is not None:
        check_start_model(start["model"], block_set, "--resume" if resume is not None else "--init")
        center, scale = start["model"]["center"], start["model"]["scale"]
    problem = block_problem(trained_set, device, center, scale)
    start_pools, say_start = None, None
    needed = config.pretrain.steps > 0 or config.method.tfi_anchor > 0
    if needed and config.pretrain.target != "tfi":  # the fit and the pull go to the set's fine elliptic mesh (design notes §20)
        fine, targets, account = elliptic_targets(trained_set, geometry_spec or block_set.name)

        def start_pools():
            return elliptic_pools(fine, targets, problem.center, problem.scale, device)

        say_start = f"the networks start from {account}"
    problem.anchor_weight = config.method.tfi_anchor
    if config.method.tfi_anchor <= 0:
        problem.anchor = []
    elif start_pools is not None:
        problem.anchor = elliptic_pools(fine, targets, problem.center, problem.scale, device, ANCHOR_POINTS, config.seed + 6)
    else:
        problem.anchor = tfi_anchor_pool(problem, ANCHOR_POINTS, config.seed + 6)
    torch.manual_seed(config.seed)
    network = BlockNetworks(problem.dim, list(config.model.widths), len(trained_set.names)).to(device)
    weights = UncertaintyWeights(config.method.pde_weight, config.method.boundary_weight, config.method.reweighting)
    weights.to(device)
    generator = torch.Generator().manual_seed(config.seed)
    state = TrainState(BLOCK_STAGES[0])
    if start is not None:
        if next(iter(start["model"]["state_dict"].values())).dtype == torch.float64:  # saved in an lbfgs.float64 stage
            network.double()
        network.load_state_dict(start["model"]["state_dict"])
        weights.load_state_dict(start["reweighting"])
    if resume is not None:
        generator.set_state(resume["rng"]["sampler"])
        state = state_from_checkpoint(resume)
    started_from = resume.get("init") if resume is not None else None
    if init is not None:
        checkpoint = init["checkpoint"]
        started_from = {
            "path": str(init["path"]),
            "step": int(checkpoint["step"]),
            "training_seconds": float(checkpoint["elapsed_seconds"]),
        }
    parallel = device.type == "cpu" and torch.get_num_threads() >= 2
    training = Training(network, weights, problem, config, generator, TermRunner(parallel))
    pool_count = _per_face(training) * config.points.boundary_pool
    pool = patch_pool(problem, pool_count, config.seed + 3)
    held_out = _held_out_config(config)
    test_points = fixed_block_points(problem, held_out, pool_count, config.seed + 5)

    def describe_run() -> dict:
        pde, boundary = _fixed_losses(training, pool, test_points, held_out)
        return {
            "model": describe_blocks(training, block_set.names, extrusion),
            "geometry": geometry_record(block_set, geometry_spec),
            "reweighting": {k: v.detach().cpu() for k, v in weights.state_dict().items()},
            "test_loss": {"pde": pde, "boundary": boundary, "total": pde + boundary},
            **({"init": started_from} if started_from is not None else {}),
        }

    def summary(checkpoint, run_dir):
        return write_block_summary(checkpoint, block_set, run_dir)

    return Job(training, state, block_stage_table(pool, pool_count, start_pools, say_start), describe_run, summary)


def write_block_summary(checkpoint: dict, block_set: BlockSet, run_dir) -> dict:
    """Quality of the block set's mesh (the training's --dims) from the networks alone, after the
    conforming correction (what ``meshgen mesh`` writes), and by TFI; ``summary.json``."""

    def report(Xs):
        points, cells, _ = merged_mesh(block_set, Xs)
        return quality_report((points, cells))

    corrected, info = neural_blocks(block_set, checkpoint["model"])
    summary = {
        "dims": [SUMMARY_DIMS] * block_set.dim,
        "network": report(network_blocks(checkpoint["model"], block_set)),
        "corrected": report(corrected),
        "tfi": report(tfi_blocks(block_set)),
        "interface_gap_before": info["interface_gap_before"],
        "test_loss": checkpoint["test_loss"],
        "step": checkpoint["step"],
        "training_seconds": checkpoint["elapsed_seconds"],
    }
    write_json(Path(run_dir) / "summary.json", summary)
    return summary
