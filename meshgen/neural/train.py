"""Training the networks of a geometry (design notes §6, §20): ``train``, the one training entry.

Every geometry is a set of blocks, one network per block. A geometry of one boundary map is a set
of one block: one network, trained on the terms of ``meshgen.neural.problem`` by the stage table
below (exactly 0.2's single-shape training, checkpoint layout included); a set of several blocks
adds the terms across its interfaces (``meshgen.neural.interfaces``, its stage table in
``meshgen.neural.interface_stages``). Both go through one stage runner
(``meshgen.neural.stages.run_stages``), one checkpoint writer, one run folder layout and one
summary step, and their models are read by one inference path (``meshgen.neural.inference``).

One run of one block goes through up to three stages, each a number of steps in the configuration:

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
of the bounding box, largest extent); the checkpoint stores the centre and scale. All randomness after the network's
initialisation comes from one generator whose state the checkpoint keeps, so a resumed run repeats an uninterrupted one.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from pathlib import Path

import numpy as np
import torch

from meshgen.errors import MeshgenError
from meshgen.geometry.blocks import BlockSet
from meshgen.geometry.extrusion import Extrusion, extrusion_from, geometry_extrusion, section_geometry
from meshgen.geometry.layout import with_layout
from meshgen.methods.correction import correct_boundary
from meshgen.methods.tfi import parametric_grid, tfi
from meshgen.neural.config import TrainConfig
from meshgen.neural.history import TrainState, state_from_checkpoint
from meshgen.neural.interface_stages import set_job
from meshgen.neural.model import MLP, describe, mesh_from_checkpoint, normalisation, normalised_boundary
from meshgen.neural.problem import (
    Problem,
    boundary_pool,
    evaluate_losses,
    lbfgs_points,
    make_test_set,
    pretrain_pool,
    sample_step,
    test_loss,
)
from meshgen.neural.reweighting import UncertaintyWeights
from meshgen.neural.stages import CheckpointWriter, Job, Stage, TrainResult, run_stages
from meshgen.neural.steps import (
    DEVICE_BLOCK,
    AdamSteps,
    TermRunner,
    Training,
    adam_gradients,
    lbfgs_optimizer,
    lbfgs_step,
    make_optimizer,
    pretrain_step,
)
from meshgen.neural.wall_map import wall_hooks
from meshgen.neural.wall_train import wall_job
from meshgen.quality import quality_report, write_json

__all__ = [
    "SECTION_STAGE_TABLE",
    "STAGES",
    "STAGE_TABLE",
    "SUMMARY_CELLS",
    "adam_steps",
    "corrected",
    "one_block_job",
    "section_extrusion",
    "section_steps",
    "start_training",
    "train",
    "write_summary",
]

SUMMARY_CELLS = 30  # the final quality summary meshes 30^dim cells


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


def adam_steps(training: Training) -> AdamSteps:
    """The Adam stage's steps of one shape: inputs from ``sample_step``, gradients from ``adam_gradients``."""
    config, problem, generator = training.config, training.problem, training.generator
    pool = boundary_pool(problem, config)
    return AdamSteps(
        training,
        lambda: sample_step(config, problem, generator, pool),
        lambda inputs: adam_gradients(training, inputs, pool),
    )


STAGE_TABLE = (
    Stage(
        "pretrain",
        optimizer=lambda t: make_optimizer("pretrain", t.network, t.weights, t.config),
        points=lambda t, state: pretrain_pool(t.problem, t.config),
        step=lambda t, optimizer, scheduler, points: pretrain_step(t.network, t.problem, optimizer, points),
    ),
    Stage(
        "adam",
        optimizer=lambda t: make_optimizer("adam", t.network, t.weights, t.config),
        points=lambda t, state: adam_steps(t),
        step=lambda t, optimizer, scheduler, steps: steps(optimizer, scheduler),
        start=balance_start,
        block=lambda t: DEVICE_BLOCK if t.problem.device.type == "cuda" else 1,
    ),
    Stage(
        "lbfgs",
        optimizer=lbfgs_optimizer,
        points=lambda t, state: lbfgs_points(t.problem, t.config),
        step=lambda t, optimizer, scheduler, fixed: lbfgs_step(t, optimizer, fixed),
    ),
)
STAGES = tuple(stage.name for stage in STAGE_TABLE)


def section_steps(training: Training, name: str) -> int:
    """The steps of stage ``name`` in a run that trains an extruded shape's section: on the
    smoothed layout the stage's ``section_steps`` where the configuration sets it (the cap there
    already solves the lattice equations: design notes §15), else its ``steps``; on the fixed
    layout always its ``steps`` (that cap is a Coons patch, with everything left to learn)."""
    stage = getattr(training.config, name)
    chosen = getattr(stage, "section_steps", None)
    if chosen is None or training.config.boundary_layout != "smoothed":
        return stage.steps
    return chosen


SECTION_STAGE_TABLE = tuple(
    dataclasses.replace(stage, total=functools.partial(section_steps, name=stage.name)) for stage in STAGE_TABLE
)


def train(
    config: TrainConfig,
    subject,
    run_dir,
    *,
    device: str = "cpu",
    resume: dict | None = None,
    reporter=None,
    stop=None,
    geometry_spec: str | None = None,
    summary: bool = True,
    init: dict | None = None,
    ranges: dict | None = None,
    dims: tuple | None = None,
) -> TrainResult:
    """Train (or, with ``resume`` = a loaded checkpoint, continue training) the networks of
        ``subject``: a Geometry (a set of one block, one network: :func:`one_block_job`) or a
        ``meshgen.geometry.blocks.BlockSet`` of several blocks (one network per block, with interface
        terms: ``meshgen.neural.interface_stages.set_job``).

        ``run_dir``: existing folder for ``checkpoint.pt``, ``config.yaml``, ``history.csv`` and
        ``summary.json``. ``reporter``: an object with ``stage(name, done, total)``,
        ``update(row, done, total)`` and ``message(text)`` (see ``meshgen.neural.progress``), or None.
        ``stop``: a callable polled before each step; when it returns True the state is saved and the
        run returns with ``interrupted=True``. ``geometry_spec``: how to load the geometry again (its
        name or plugin path; default its name). ``summary``: mesh the geometry at the end and write the
        quality summary. ``init`` ({"path", "checkpoint"}, ``meshgen train --init``): a block set's new
        run starting from a checkpoint's weights. ``ranges`` (name -> (lo, hi)): a block set round a wall
    trains the family about it (``meshgen.neural.wall_family``), its members meshed at ``dims`` (the
    --dims the block set was made with). On a CPU with two or more torch threads, the two
        terms of a step run side by side (``meshgen.neural.steps.TermRunner``), torch single-threaded meanwhile.
    """
    run_dir = Path(run_dir)
    if isinstance(subject, BlockSet) and wall_hooks(subject) is not None:
        if init is not None:
            raise MeshgenError(
                f"--init is not available for '{subject.name}': its model is a wall-layer network (meshgen.neural.wall_map)"
            )
        job = wall_job(config, subject, torch.device(device), resume, geometry_spec, ranges, dims)
    elif ranges:
        raise MeshgenError(f"--vary on '{subject.name}': its networks take no parameters as inputs")
    elif isinstance(subject, BlockSet):
        job = set_job(config, subject, torch.device(device), resume, geometry_spec, init)
    elif init is not None:
        raise MeshgenError(f"--init is made for block sets (one network per block); '{subject.name}' is one block")
    else:
        job = one_block_job(config, subject, torch.device(device), resume, geometry_spec)
    saver = CheckpointWriter(job.training, job.describe, run_dir / "checkpoint.pt", job.state)
    checkpoint, interrupted = run_stages(
        job.table, job.training, job.state, saver, run_dir, resume=resume, reporter=reporter, stop=stop
    )
    quality = job.summary(checkpoint, run_dir) if summary and not interrupted else None
    return TrainResult.of_run(saver, job.state, interrupted, checkpoint, quality)


def section_extrusion(config: TrainConfig, geometry, resume=None) -> Extrusion | None:
    """The extrusion whose 2D section a one-block run trains (design notes §20), or None (a network
    of the geometry's dimension): an exact-boundary run on an extruded 3D geometry
    (``meshgen.geometry.extrusion.geometry_extrusion``); a resumed run keeps its checkpoint's kind."""
    if resume is not None:
        entry = resume["model"].get("extruded")
        return None if entry is None else extrusion_from(entry)
    return geometry_extrusion(geometry) if config.model.exact_boundary else None


def one_block_job(config: TrainConfig, geometry, device: torch.device, resume=None, geometry_spec=None) -> Job:
    """The run (``meshgen.neural.stages.Job``) of a geometry of one boundary map: one network on
    the terms of ``meshgen.neural.problem``, :data:`STAGE_TABLE`, 0.2's checkpoint layout (one
    network under ``layers.<k>.``, no ``blocks`` entry), the summary of :func:`write_summary`.
    An extruded geometry under the exact boundary (:func:`section_extrusion`) trains the 2D
    network of its section: X = C + b N, C the laid-out boundary's zeta = 0 cap (on the smoothed
    layout, the section's 2D Winslow grid on the layout's fine lattice) in place of TFI; the
    checkpoint records the extrusion (``model["extruded"]``), its stages take ``section_steps``
    (:data:`SECTION_STAGE_TABLE`) and its mesh is the section's extruded
    (``meshgen.neural.network_map.section_plane``)."""
    extrusion = section_extrusion(config, geometry, resume)
    geometry = with_layout(geometry, config.boundary_layout)  # the boundary the network learns
    trained = geometry if extrusion is None else section_geometry(geometry, extrusion)
    training, state = start_training(config, trained, device, resume, interior_map=extrusion is not None)
    problem, test_set = training.problem, make_test_set(training.problem, config)

    def describe_run() -> dict:
        network = training.network
        model = describe(network, config.model.widths, problem.exact, problem.center, problem.scale)
        return {
            "model": model if extrusion is None else {**model, "extruded": extrusion.describe()},
            "geometry": {
                "name": geometry.name,
                "spec": geometry_spec or geometry.name,
                "dim": geometry.dim,
                "params": dict(geometry.values),
            },
            "reweighting": {k: v.detach().cpu() for k, v in training.weights.state_dict().items()},
            "test_loss": test_loss(network, problem, test_set),
        }

    def summary(checkpoint, run_dir):
        return write_summary(checkpoint, geometry, run_dir)

    return Job(training, state, STAGE_TABLE if extrusion is None else SECTION_STAGE_TABLE, describe_run, summary)


def start_training(config: TrainConfig, geometry, device: torch.device, resume: dict | None, interior_map: bool = False):
    """The Training (network initialised from the seed, or from ``resume``) and its TrainState.
    ``interior_map``: the exact form's base is the geometry's map itself (``Problem.interior_map``)."""
    dim = geometry.dim
    center, scale = normalisation(geometry)
    if resume is not None:  # the checkpoint's normalisation, bit for bit
        center, scale = np.asarray(resume["model"]["center"]), float(resume["model"]["scale"])
    boundary = normalised_boundary(geometry, center, scale)
    problem = Problem(dim, boundary, center, scale, config.model.exact_boundary, device, interior_map=interior_map)
    torch.manual_seed(config.seed)
    network = MLP(dim, config.model.widths)
    if problem.exact:  # N = 0: training starts from TFI itself
        torch.nn.init.zeros_(network.layers[-1].weight)
        torch.nn.init.zeros_(network.layers[-1].bias)
    network.to(device)
    weights = UncertaintyWeights(config.method.pde_weight, config.method.boundary_weight, config.method.reweighting)
    weights.to(device)
    generator = torch.Generator().manual_seed(config.seed)
    state = TrainState(STAGES[0])
    if resume is not None:
        if resume["model"]["state_dict"]["layers.0.weight"].dtype == torch.float64:  # stopped in an lbfgs.float64 stage
            network.double()
        network.load_state_dict(resume["model"]["state_dict"])
        weights.load_state_dict(resume["reweighting"])
        generator.set_state(resume["rng"]["sampler"])
        state = state_from_checkpoint(resume)
    parallel = device.type == "cpu" and torch.get_num_threads() >= 2
    return Training(network, weights, problem, config, generator, TermRunner(parallel)), state


# ---------------------------------------------------------------------------------------------
# the final summary


def corrected(X: np.ndarray, geometry, coords) -> np.ndarray:
    """A copy of node array ``X`` corrected to X + TFI[g - X] (what ``meshgen mesh`` makes of a
    network's mesh by default; ``meshgen.methods.correction.correct_boundary``)."""
    X = X.copy()
    correct_boundary(X, geometry, coords)
    return X


def write_summary(checkpoint: dict, geometry, run_dir) -> dict:
    """Mesh ``SUMMARY_CELLS``^d cells with the trained map and with TFI, measure both with
    ``meshgen.quality`` (boundary deviation included), and the network's mesh after the boundary
    correction X + TFI[g - X] (``corrected``: what ``meshgen mesh`` writes), write ``summary.json`` in ``run_dir`` and return it."""
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
