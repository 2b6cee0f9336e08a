"""Checkpoints: plain data only (tensors, numbers, strings, lists, dicts), written atomically and
read with ``torch.load(..., weights_only=True)``, so loading one never runs foreign code.

Layout (``FORMAT_VERSION`` 1)::

    format, format_version, meshgen_version
    model       plain description of the map (see meshgen.neural.model)
    geometry    {"name", "spec", "dim", "params"}: what to load to mesh it again
    config      the resolved training configuration (meshgen.neural.config)
    stage, stage_step, step, elapsed_seconds, history, guard
                where training stands (``meshgen.neural.history.TrainState``, written and read by
                ``state_to_checkpoint`` / ``state_from_checkpoint``): the stage ("pretrain" |
                "adam" | "lbfgs" | "done"), the steps done in it and in all, the training
                seconds, history {"rows", "last": the last history row}, guard {"lr_reductions"}
    optimizer, scheduler   state dicts of the current stage's (empty when none, e.g. bundled models)
    reweighting            state dict of the weights a1, a2 (``log_a``)
    rng         {"torch": ByteTensor, "sampler": ByteTensor}
    test_loss   {"pde", "boundary", "total"} on the fixed held-out points
    device      where it was trained ("cpu", "cuda")
"""

from __future__ import annotations

import os
import pickle
import zipfile
from pathlib import Path

import torch

from meshgen.atomic import atomic_path
from meshgen.errors import MeshgenError
from meshgen.inputs import InputError, check_input_file
from meshgen.publish import reason

__all__ = ["FORMAT", "FORMAT_VERSION", "CheckpointError", "save_checkpoint", "load_checkpoint"]


FORMAT = "meshgen-checkpoint"
FORMAT_VERSION = 1


class CheckpointError(MeshgenError):
    """A checkpoint is missing, damaged, foreign or too new."""


def save_checkpoint(path: str | os.PathLike, checkpoint: dict) -> None:
    """Write ``checkpoint`` to ``path`` atomically (a reader never sees a partial file).

    Raises CheckpointError when the file cannot be written (a full disk, no permission); a
    previous checkpoint at ``path`` is then left as it was."""
    try:
        with atomic_path(path) as temporary:
            # Through an unbuffered Python file: given a path (or a buffered file), torch reports
            # a full disk as "unexpected pos 704 vs 598" instead of the OSError (ENOSPC).
            with open(temporary, "wb", buffering=0) as handle:
                torch.save(checkpoint, handle)
    except (OSError, RuntimeError) as exc:
        # torch reports a write the file system cut short (a full tmpfs) as "unexpected pos N vs M".
        why = f"torch could not write it (is the disk full?): {reason(exc)}" if isinstance(exc, RuntimeError) else reason(exc)
        raise CheckpointError(f"could not write checkpoint {path}: {why} (any previous checkpoint there is kept)") from exc


def load_checkpoint(path: str | os.PathLike) -> dict:
    """Read a meshgen checkpoint onto the CPU with ``weights_only=True``.

    Raises CheckpointError for a missing, truncated or foreign file, or one written by a newer
    meshgen (a higher ``format_version``).
    """
    path = Path(path)
    if not path.exists():
        raise CheckpointError(f"checkpoint {path} does not exist")
    try:
        check_input_file(path, "checkpoint")  # a FIFO or a device is never handed to torch
    except InputError as exc:
        raise CheckpointError(str(exc)) from None
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, zipfile.BadZipFile, ValueError, OSError) as exc:
        raise CheckpointError(f"checkpoint {path} {_load_failure(path, exc)}") from exc
    if not isinstance(checkpoint, dict) or checkpoint.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not a meshgen checkpoint")
    version = checkpoint.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint {path} has format version {version!r}, newer than this meshgen reads ({FORMAT_VERSION}): upgrade meshgen"
        )
    missing = [key for key in ("model", "geometry", "config") if key not in checkpoint]
    if missing:
        raise CheckpointError(f"checkpoint {path} lacks {', '.join(missing)}: not a complete meshgen checkpoint")
    model, geometry = checkpoint["model"], checkpoint["geometry"]
    if not (isinstance(model, dict) and isinstance(geometry, dict) and {"name", "spec", "dim", "params"} <= set(geometry)):
        raise CheckpointError(f"checkpoint {path}: its model or geometry entry is damaged: not a meshgen checkpoint")
    if model.get("dim") != geometry["dim"]:
        raise CheckpointError(
            f"checkpoint {path} holds a {model.get('dim')}D map but records the {geometry['dim']}D geometry "
            f"'{geometry['name']}': not a consistent meshgen checkpoint"
        )
    _check_values(checkpoint, path)
    return checkpoint


def _check_values(checkpoint: dict, path: Path) -> None:
    """CheckpointError for weights that are not finite numbers, or a training state that is not
    one (a stage, non-negative step counts): a damaged file fails here, before anything is written."""
    state = checkpoint["model"].get("state_dict", {})
    tensors = list(state.values()) if isinstance(state, dict) else []
    if not all(isinstance(t, torch.Tensor) and bool(torch.isfinite(t).all()) for t in tensors):
        raise CheckpointError(f"checkpoint {path}: its network holds non-finite weights (NaN or infinity): the file is damaged")
    if "stage" in checkpoint:
        steps = [checkpoint.get(key) for key in ("step", "stage_step")]
        if checkpoint["stage"] not in ("pretrain", "adam", "lbfgs", "done") or not all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in steps
        ):
            raise CheckpointError(f"checkpoint {path}: its training state (stage, step) is damaged")


def _load_failure(path: Path, exc: Exception) -> str:
    """Why ``torch.load(path, weights_only=True)`` failed, in words for the user. (torch's own
    message on a refused object explains how to load the file unsafely: not advice to pass on.)"""
    text = " ".join(str(exc).split())
    if isinstance(exc, pickle.UnpicklingError) and "Unsupported global" in text:
        found = text[text.index("Unsupported global") :].split(" was not an allowed global")[0].split(". ")[0]
        reason = f"it carries Python objects, not plain data: {found}; refused without running them"
    elif isinstance(exc, OSError):
        reason = exc.strerror or text
    else:
        with open(path, "rb") as handle:
            is_zip = handle.read(4) == b"PK\x03\x04"  # torch's format: a zip archive
        reason = (text.split(". ")[0][:120] or type(exc).__name__) if is_zip else "not a torch zip archive"
    return f"is truncated or not a meshgen checkpoint ({reason})"
