"""Checkpoints: plain data only (tensors, numbers, strings, lists, dicts), written atomically and
read with ``torch.load(..., weights_only=True)``, so loading one never runs foreign code.

Layout (``FORMAT_VERSION`` 1)::

    format, format_version, meshgen_version
    model       plain description of the map (see meshgen.neural.model)
    geometry    {"name", "spec", "dim", "params"}: what to load to mesh it again
    config      the resolved training configuration (meshgen.neural.config)
    stage, step, elapsed_seconds       where training stands ("pretrain" | "adam" | "lbfgs" | "done")
    optimizer, scheduler, reweighting  state dicts of the current stage
    rng         {"torch": ByteTensor, "sampler": ByteTensor}
    history     summary: {"rows", "last": {...}, "best_total"}
    test_loss   {"pde", "boundary", "total"} on the fixed held-out points
    guard       {"lr_reductions"}
"""

from __future__ import annotations

import os
import pickle
import zipfile
from pathlib import Path

import torch

from meshgen.atomic import atomic_path
from meshgen.errors import MeshgenError

FORMAT = "meshgen-checkpoint"
FORMAT_VERSION = 1


class CheckpointError(MeshgenError):
    """A checkpoint is missing, damaged, foreign or too new."""


def save_checkpoint(path: str | os.PathLike, checkpoint: dict) -> None:
    """Write ``checkpoint`` to ``path`` atomically (a reader never sees a partial file)."""
    with atomic_path(path) as temporary:
        torch.save(checkpoint, temporary)


def load_checkpoint(path: str | os.PathLike) -> dict:
    """Read a meshgen checkpoint onto the CPU with ``weights_only=True``.

    Raises CheckpointError for a missing, truncated or foreign file, or one written by a newer
    meshgen (a higher ``format_version``).
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} does not exist")
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, zipfile.BadZipFile, ValueError, OSError) as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CheckpointError(f"checkpoint {path} is truncated or not a meshgen checkpoint ({reason[:120]})") from exc
    if not isinstance(checkpoint, dict) or checkpoint.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not a meshgen checkpoint")
    version = checkpoint.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint {path} has format version {version!r}, newer than this meshgen reads "
            f"({FORMAT_VERSION}): upgrade meshgen"
        )
    missing = [key for key in ("model", "geometry", "config") if key not in checkpoint]
    if missing:
        raise CheckpointError(f"checkpoint {path} lacks {', '.join(missing)}: not a complete meshgen checkpoint")
    return checkpoint
