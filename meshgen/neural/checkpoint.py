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

from meshgen.neural.checkpoint_data import (
    FORMAT,
    FORMAT_VERSION,
    CheckpointError,
    check_checkpoint,
    check_readable,
    check_resumable_state,
)
from meshgen.run.atomic import atomic_path
from meshgen.run.publish import reason

__all__ = ["FORMAT", "FORMAT_VERSION", "CheckpointError", "check_resumable_state", "load_checkpoint", "save_checkpoint"]


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
    check_readable(path)  # a FIFO or a device is never handed to torch
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, zipfile.BadZipFile, ValueError, OSError) as exc:
        raise CheckpointError(f"checkpoint {path} {_load_failure(path, exc)}") from exc
    return check_checkpoint(checkpoint, path)


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
