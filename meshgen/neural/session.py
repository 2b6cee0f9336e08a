"""A training run as the command line starts it: every input checked before anything is written
(``prepare_run``), then the run folder, Ctrl-C handling and progress around ``train``
(``run_training``)."""

from __future__ import annotations

import os
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from meshgen.errors import MeshgenError
from meshgen.geometry.blocks import is_multiblock, load_block_set
from meshgen.geometry.plugins import load_geometry, load_recorded_geometry, looks_like_path, parse_params, plugin_module
from meshgen.neural.config import (
    ConfigError,
    dotted_items,
    from_dict,
    keys_off_default,
    parse_override,
    resolve_config,
    set_key,
    to_dict,
    validate,
)
from meshgen.neural.device import inference_device
from meshgen.neural.inference import check_start_model, is_block_model
from meshgen.neural.progress import reporter_for
from meshgen.neural.run_folder import check_run_folder, claim_run_folder, stop_signals
from meshgen.neural.wall_family_train import check_family_ranges
from meshgen.neural.wall_map import has_wall_hooks
from meshgen.run.limits import check_training_memory

__all__ = ["RUN_FILES", "RESUMABLE_KEYS", "Run", "is_run_folder", "choose_run_dir", "prepare_run", "run_training"]


RUN_FILES = ("checkpoint.pt", "config.yaml", "history.csv", "summary.json")
# What a resumed run may change: how long it goes on and how it saves or guards, nothing that
# would make the checkpoint's weights or optimiser state mean something else.
RESUMABLE_KEYS = (
    "adam.steps",
    "lbfgs.steps",
    "adam.section_steps",
    "lbfgs.section_steps",
    "adam.block_steps",
    "lbfgs.block_steps",
    "checkpoint.every",
    "guard.max_retries",
    "guard.lr_factor",
)


@dataclass
class Run:
    config: object  # TrainConfig
    geometry: object  # Geometry
    geometry_spec: str  # how to load the geometry again: a name, or a plugin file's absolute path
    run_dir: Path
    device: str
    resume: dict | None = None  # the loaded checkpoint when resuming
    resume_path: Path | None = None
    family: object | None = None  # meshgen.neural.family.Family when parameters are varied (--vary)
    fresh_name: bool = False  # run_dir is a default name: the run takes it, or the next free one
    force: bool = False  # --force: overwrite a run folder of another geometry or configuration
    block_set: object | None = None  # meshgen.geometry.blocks.BlockSet when the geometry declares blocks (one network per block)
    init: dict | None = None  # --init: {"path", "checkpoint"}, the trained weights a new block-set run starts from
    wall_ranges: dict | None = None  # --vary on a plugin round a wall: the family's ranges (meshgen.neural.wall_family)
    train_dims: tuple | None = None  # the --dims the block set was made with (a wall family meshes its members so)


def is_run_folder(path: Path) -> bool:
    """An empty folder, or one that a previous ``meshgen train`` wrote (config.yaml and a
    checkpoint or history)."""
    entries = {p.name for p in path.iterdir()}
    return not entries or ("config.yaml" in entries and bool(entries & {"checkpoint.pt", "history.csv"}))


def choose_run_dir(out, resume_path: Path | None, geometry_name: str) -> Path:
    """The run folder: ``out``, else the resumed checkpoint's folder, else a new
    ``runs/<geometry>-<timestamp>``. An existing folder must be a run folder (nothing else is
    overwritten)."""
    if out is not None:
        path = Path(out)
    elif resume_path is not None:
        path = resume_path.parent
    else:
        # Taken when the folder is made (meshgen.neural.run_folder): -2, -3 ... if taken by then.
        path = Path("runs") / f"{geometry_name}-{time.strftime('%Y%m%d-%H%M%S')}"
    if path.exists():
        if not path.is_dir():
            raise MeshgenError(f"output folder {path} exists and is a file")
        if not is_run_folder(path):
            raise MeshgenError(
                f"output folder {path} exists and is not a run folder (it holds other files): choose a new or empty folder"
            )
    # The folder, or the one it will be created in: found out now, not when the first file fails.
    existing = next((folder for folder in (path, *path.parents) if folder.exists()), Path("."))
    if not os.access(existing, os.W_OK | os.X_OK):
        raise MeshgenError(f"output folder {existing} is not writable")
    return path


def _geometry_spec(spec: str) -> str:
    """How to load the geometry again: a plugin path made absolute, a name as it is."""
    return str(Path(spec).resolve()) if looks_like_path(spec) else spec


def prepare_run(
    geometry=None,
    params=(),
    preset=None,
    config_file=None,
    overrides=(),
    steps=None,
    out=None,
    resume=None,
    seed=None,
    device="auto",
    threads=None,
    vary=(),
    force=False,
    init=None,
) -> Run:
    """Check every input of ``meshgen train`` and return what to run; writes nothing.

    Raises MeshgenError (one line, exit 2) for an unknown geometry or preset, malformed YAML,
    unknown or ill-typed keys, a preset for the other dimension, a missing, truncated or foreign
    checkpoint, or an output folder that holds something other than a run. ``vary``: ``--vary
    name=low:high`` items, which make the run train a family (``meshgen.neural.family``).
    ``force``: train into an ``out`` folder that holds a run of another geometry or configuration.
    ``init``: a block set's checkpoint whose weights a new run starts from (``check_init``).
    """

    checkpoint = resume_path = family = wall_ranges = None
    _refuse_init_with(init, resume, vary)
    if resume is not None and vary:
        raise ConfigError("--vary does not apply with --resume: the checkpoint sets the ranges")
    if resume is not None:
        from meshgen.neural.checkpoint import CheckpointError, check_resumable_state, load_checkpoint  # imports torch

        for flag, value in (("--preset", preset), ("--config", config_file), ("--seed", seed)):
            if value is not None:
                raise ConfigError(
                    f"{flag} does not apply with --resume: the run goes on with the checkpoint's "
                    f"configuration (change {', '.join(RESUMABLE_KEYS)} with --set)"
                )
        resume_path = Path(resume)
        checkpoint = load_checkpoint(resume_path)
        if checkpoint.get("stage") == "done":
            raise CheckpointError(
                f"checkpoint {resume_path} is of a finished run: nothing to resume (start a new run with "
                f"--config {resume_path.parent / 'config.yaml'})"
            )
        check_resumable_state(checkpoint, resume_path)  # its optimiser state checked as its weights are, before any work
        config = from_dict(checkpoint["config"])
        for text in list(overrides) + ([f"adam.steps={steps}"] if steps is not None else []):
            key, value = parse_override(text)
            if key not in RESUMABLE_KEYS:
                raise ConfigError(f"--set {key} cannot change when resuming (allowed: {', '.join(RESUMABLE_KEYS)})")
            set_key(config, key, value)
        validate(config)
        trained_on = checkpoint["geometry"]
        spec = trained_on["spec"]
        merged = {**trained_on["params"], **parse_params(params)}
        blocks = "blocks" in trained_on  # checked without the boundary: a block set's is per block
        if geometry:
            geometry_object = load_geometry(geometry, merged, check=not blocks)
        else:
            geometry_object = load_recorded_geometry(spec, merged, check=not blocks, where=f"checkpoint {resume_path}")
        if geometry_object.name != trained_on["name"] or geometry_object.values != dict(trained_on["params"]):
            raise CheckpointError(
                f"checkpoint {resume_path} was trained on {trained_on['name']} {trained_on['params']}, "
                f"not on {geometry_object.name} {geometry_object.values}"
            )
        if geometry_object.dim != checkpoint["model"]["dim"] + ("extruded" in checkpoint["model"]):
            raise CheckpointError(
                f"checkpoint {resume_path} holds a {checkpoint['model']['dim']}D map; "
                f"geometry '{geometry_object.name}' is {geometry_object.dim}D"
            )
        if geometry is None:
            geometry = spec
        if "family" in checkpoint:
            from meshgen.neural.family import family_from_checkpoint

            family = family_from_checkpoint(checkpoint)
    else:
        geometry = geometry or "semicylinder"
        blocks = is_multiblock(geometry)
        walled = blocks and has_wall_hooks(plugin_module(geometry)[0])
        default_preset = ("wall-family" if walled else "family") if vary else "default"
        config = resolve_config(preset or default_preset, config_file, overrides, steps, seed)
        if vary and walled:
            wall_ranges = _wall_ranges(geometry, params, vary)
            params = [*params, *(f"{n}={0.5 * (lo + hi)!r}" for n, (lo, hi) in wall_ranges.items())]  # the middle member
        geometry_object = load_geometry(geometry, parse_params(params), check=not blocks)
        _refuse_unused_keys(config, geometry_object.name, blocks, bool(vary), walled)
        if vary and not walled:
            _refuse_family_keys(config, preset, overrides)
            family = _family(config, geometry_object, _geometry_spec(geometry), params, vary)
    if config.dim is not None and config.dim != geometry_object.dim:
        raise ConfigError(
            f"preset '{preset or 'default'}' is made for {config.dim}D geometries; "
            f"'{geometry_object.name}' is {geometry_object.dim}D"
        )
    check_training_size(config, geometry_object.dim)
    device = inference_device(device)
    if threads is not None:
        import torch

        torch.set_num_threads(threads)
    run_dir = choose_run_dir(out, resume_path, geometry_object.name)
    if out is not None and resume is None:
        check_run_folder(run_dir, config, geometry_object, force)
    fresh_name = out is None and resume is None
    block_set = None
    if blocks:  # its blocks, interfaces and patches checked now, before the run folder exists
        from meshgen.neural.interface_stages import SUMMARY_DIMS

        # A plugin whose blocks need more cells than the default (the airfoil's wall spacing) names its own.
        dims = getattr(plugin_module(geometry)[0], "train_dims", (SUMMARY_DIMS,) * geometry_object.dim)
        block_set = load_block_set(geometry, geometry_object.values, tuple(dims))
        if wall_ranges is not None:  # every corner a valid section of one topology, before the run folder exists
            check_family_ranges(block_set.name, block_set.values, wall_ranges, tuple(dims))
    started = None if init is None else {"path": str(init), "checkpoint": check_init(init, config, geometry_object, block_set)}
    return Run(
        config, geometry_object, _geometry_spec(geometry), run_dir, device, checkpoint, resume_path, family, fresh_name, force,
        block_set, started, wall_ranges, None if block_set is None else tuple(dims),
    )  # fmt: skip


def _wall_ranges(geometry, params, vary) -> dict:
    """The checked ranges of a wall family: parameters of the plugin, neither fixed by --param nor
    free (the wall spacing's, which every member sets at will)."""
    from meshgen.neural.family import parse_vary

    ranges, module = parse_vary(vary), plugin_module(geometry)[0]
    known, free, fixed = dict(getattr(module, "params", {})), set(getattr(module, "wall_free", ())), parse_params(params)
    for name in ranges:
        if name not in known:
            raise ConfigError(
                f"--vary {name}: geometry '{module.name}' has no parameter {name!r} (its parameters: {', '.join(known)})"
            )
        if name in fixed:
            raise ConfigError(f"--param {name} and --vary {name}: a parameter is either fixed or varied")
        if name in free:
            raise ConfigError(f"--vary {name}: every member sets {name} at will (--param {name}=...), so it is not varied")
    return ranges


WALL_FAMILY_KEYS = ("points.members",)  # what only a wall family reads


def _refuse_wall_family_keys(config, wall_family: bool) -> None:
    unused = keys_off_default(config, WALL_FAMILY_KEYS) if not wall_family else {}
    if unused:
        shown = ", ".join(f"{k}={v}" for k, v in unused.items())
        raise ConfigError(f"{shown} applies to a family of sections round a wall (--vary on the airfoil) only")


def _refuse_unused_keys(config, name: str, blocks: bool, vary: bool, walled: bool) -> None:
    """ConfigError for a family of several blocks that are not sections round a wall, and for keys
    the run would not read (``BLOCK_ONLY_KEYS``, ``WALL_FAMILY_KEYS``, a block set's own refusals)."""
    if vary and blocks and not walled:
        raise ConfigError(
            f"--vary trains a family of one-block shapes or of sections round a wall; '{name}' is made of several blocks"
        )
    _refuse_wall_family_keys(config, vary and walled)
    _refuse_block_only_keys(config, blocks, name)
    if blocks:  # keys a block set cannot use are refused, not ignored
        from meshgen.neural.interface_stages import check_block_keys

        check_block_keys(config, f"block set '{name}'")


BLOCK_ONLY_KEYS = (
    "method.tfi_anchor",
    "adam.block_steps",
    "lbfgs.block_steps",
)  # keys only a block set uses: refused away from their default for one shape


def _refuse_block_only_keys(config, blocks: bool, name: str) -> None:
    """ConfigError naming the keys of ``BLOCK_ONLY_KEYS`` that ``config`` sets away from their
    default when the geometry is one block (a shape or a family of shapes), where nothing reads them."""
    if blocks:
        return
    unused = [f"{key}={value}" for key, value in keys_off_default(config, BLOCK_ONLY_KEYS).items()]
    if config.pretrain.target == "elliptic":  # one block fits its TFI (auto and tfi)
        unused.append("pretrain.target=elliptic")
    if unused:
        raise ConfigError(f"'{name}' is one block: {', '.join(unused)} applies to block sets only (leave it at the default)")


def _refuse_init_with(init, resume, vary) -> None:
    if init is not None and (resume is not None or vary):
        raise ConfigError(
            f"--init starts a new run from a checkpoint's weights: it does not go with {'--resume' if resume is not None else '--vary'}"
        )


def check_init(path, config, geometry, block_set) -> dict:
    """The loaded checkpoint at ``path`` for ``--init``, or a one-line error: the geometry must be a
    block set (``block_set`` not None), the checkpoint a block-set model of ``geometry`` (same name
    and parameters) with ``config``'s widths, and the run must not start with the fit to the TFI
    (``pretrain.steps`` 0), which would replace its weights."""
    from meshgen.neural.checkpoint import CheckpointError, load_checkpoint  # imports torch

    if block_set is None:
        raise ConfigError(f"--init is made for block sets (one network per block); '{geometry.name}' is one block")
    checkpoint = load_checkpoint(Path(path))
    model, trained_on = checkpoint["model"], checkpoint["geometry"]
    if not is_block_model(model):
        raise CheckpointError(f"--init {path}: not a block set's model")
    if trained_on["name"] != geometry.name or dict(trained_on["params"]) != geometry.values:
        raise CheckpointError(
            f"--init {path} was trained on {trained_on['name']} {trained_on['params']}, not on {geometry.name} {geometry.values}"
        )
    check_start_model(model, block_set, "--init")
    if list(model["widths"]) != list(config.model.widths):
        raise ConfigError(
            f"--init {path} has model.widths={list(model['widths'])}, the run {list(config.model.widths)}: set them equal"
        )
    if config.pretrain.steps != 0:
        raise ConfigError(
            f"--init starts from trained weights, which the fit to the TFI would replace: --set pretrain.steps=0 (got {config.pretrain.steps})"
        )
    return checkpoint


def _refuse_family_keys(config, preset, overrides) -> None:
    """A family refuses the keys it cannot use (``family_train.FAMILY_UNUSED_KEYS``) when the user
    sets them: every such ``--set`` key, and such a key of ``--config FILE`` whose value differs from
    the preset's (a family run's own config.yaml holds every key, at the preset's values)."""
    from meshgen.neural.family_train import check_family_keys

    given = [parse_override(text)[0] for text in overrides]
    chosen, preset_only = dotted_items(to_dict(config)), dotted_items(to_dict(resolve_config(preset or "family")))
    changed = [key for key in chosen if key not in given and chosen[key] != preset_only.get(key)]
    check_family_keys(given)
    check_family_keys(changed, "config_file")


def check_training_size(config, dim: int) -> None:
    """MeshgenError, before the run folder exists, when the network and the points of one step
    would not fit in memory (``meshgen.run.limits.training_bytes``): the finite-difference residual
    evaluates the network at each point and its 2 dim neighbours."""
    points = config.points
    per_step = max(
        points.interior * (2 * dim + 1) + points.boundary,
        config.pretrain.points * 2,
        config.test.interior * (2 * dim + 1) + config.test.boundary,
    )
    check_training_memory(config.model.widths, dim, per_step, config.lbfgs.history_size)


def _family(config, geometry, spec: str, params, vary):
    """The checked family of ``--vary`` items (``meshgen.neural.family.make_family``)."""
    from meshgen.neural.family import make_family, parse_vary

    ranges = parse_vary(vary)
    both = sorted(set(ranges) & set(parse_params(params)))
    if both:
        raise ConfigError(f"--param {both[0]} and --vary {both[0]}: a parameter is either fixed or varied")
    if not config.model.exact_boundary:
        raise ConfigError(
            "--vary trains the exact-boundary form (TFI + b N) alone: use --preset family or exact, "
            "or --set model.exact_boundary=true"
        )
    # smoothed: the layout solved on a grid over the box and interpolated (meshgen.geometry.layout_family)
    return make_family(geometry, spec, ranges, config.boundary_layout)


def _trainer(run: Run):
    """(training function, what it trains, its extra keywords) of ``run``: a family, or the
    geometry's set of networks (``meshgen.neural.train.train``: one block, or a block set's
    ``block_set``), all run by the one stage runner (design notes §15)."""
    if run.family is not None:
        from meshgen.neural.family_train import train_family

        return train_family, run.family, {}
    from meshgen.neural.train import train

    subject = run.block_set if run.block_set is not None else run.geometry
    return (
        train,
        subject,
        {"geometry_spec": run.geometry_spec, "init": run.init, "ranges": run.wall_ranges, "dims": run.train_dims},
    )


def run_training(run: Run, quiet: bool = False):
    """Create the run folder, train with a progress bar (or log lines), save on the first Ctrl-C
    (a second one aborts). Returns the TrainResult."""
    created, release = claim_run_folder(run)  # a folder of its own, locked while the run trains
    reporter = reporter_for(run.config, quiet)
    stop_requested = threading.Event()

    def on_interrupt(signum, frame):
        if stop_requested.is_set():
            raise KeyboardInterrupt
        stop_requested.set()
        reporter.message("Stopping after this step to save a checkpoint (Ctrl-C again to abort without saving)")

    # SIGTERM and SIGHUP (a batch system, a closed terminal) stop the run like Ctrl-C: saved, resumable.
    previous = {signum: signal.signal(signum, on_interrupt) for signum in stop_signals()}
    try:
        with reporter:
            trainer, subject, extra = _trainer(run)
            return trainer(
                run.config,
                subject,
                run.run_dir,
                device=run.device,
                resume=run.resume,
                reporter=reporter,
                stop=stop_requested.is_set,
                **extra,
            )
    except BaseException:
        # A run that fails before writing anything (e.g. a plugin that fails on its first points)
        # leaves no empty folder behind.
        if created and not any(run.run_dir.iterdir()):
            run.run_dir.rmdir()
        raise
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        release()
