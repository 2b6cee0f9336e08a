"""Patch parametrisations kept between runs, beside the boundary-layout cache (``meshgen.geometry.layout``):
in ``$MESHGEN_CACHE_DIR``, else ``$XDG_CACHE_HOME/meshgen``, else ``~/.cache/meshgen``, under
``parametrisations/``, one file per shape file content (its hash) and face assignment. A file that
cannot be read or written is ignored (the parametrisation is then computed)."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from meshgen import __version__
from meshgen.geometry.shapes.parametrise import PatchMap
from meshgen.run.atomic import atomic_path

__all__ = ["parametrisation_path", "read_patch_maps", "write_patch_maps"]


def parametrisation_path(content_hash: str, assignment: dict, corners: dict) -> Path | None:
    """The cache file of a shape's six patch maps; None without a content hash."""
    if not content_hash:
        return None
    identity = json.dumps(
        [__version__, content_hash, sorted(assignment.items()), sorted((str(k), int(v)) for k, v in corners.items())]
    )
    digest = hashlib.sha256(identity.encode()).hexdigest()[:32]
    folder = os.environ.get("MESHGEN_CACHE_DIR") or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "meshgen"
    return Path(folder) / "parametrisations" / f"{digest}.npz"


def read_patch_maps(path: Path | None, faces) -> dict | None:
    """Face name -> PatchMap stored at ``path``, or None when there is none or it is unreadable."""
    if path is None:
        return None
    try:
        with np.load(path, allow_pickle=False) as stored:
            maps = {}
            for name in faces:
                lengths = stored[f"{name}_side_lengths"]
                chains = tuple(np.split(stored[f"{name}_sides"], np.cumsum(lengths)[:-1]))
                maps[name] = PatchMap(
                    stored[f"{name}_vertices"],
                    stored[f"{name}_triangles"],
                    stored[f"{name}_uv"],
                    tuple(int(c) for c in stored[f"{name}_corners"]),
                    chains,
                )
    except (OSError, KeyError, ValueError, TypeError):
        return None
    return maps


def write_patch_maps(path: Path | None, maps: dict) -> None:
    """Store face name -> PatchMap at ``path`` atomically; skipped when it cannot be written."""
    if path is None:
        return
    arrays = {}
    for name, patch in maps.items():
        arrays[f"{name}_vertices"] = patch.vertices
        arrays[f"{name}_triangles"] = patch.triangles
        arrays[f"{name}_uv"] = patch.uv
        arrays[f"{name}_corners"] = np.array(patch.corners)
        arrays[f"{name}_sides"] = np.concatenate(patch.sides)
        arrays[f"{name}_side_lengths"] = np.array([len(chain) for chain in patch.sides])
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as temporary:
            with open(temporary, "wb") as file:
                np.savez(file, **arrays)
    except OSError:
        pass
