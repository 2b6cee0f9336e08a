"""Where meshgen's metadata goes in a mesh file: the key every format stores it under, and the
JSON text it is stored as. Shared by the format modules and the registry (``meshgen.formats``).

Same input, same bytes: wall-clock timings (keys ``seconds`` and ``*_seconds`` at any depth) stay
out of mesh files, so two identical runs write byte-identical meshes; the ``.quality.json``
sidecar written with the mesh keeps them."""

from __future__ import annotations

import json
import os

import numpy as np

from meshgen.errors import FormatError

__all__ = ["METADATA_KEY", "is_timing", "metadata_json", "without_timings"]

METADATA_KEY = "meshgen"


def is_timing(key) -> bool:
    """Whether a metadata key holds a wall-clock time (``seconds``, ``meshing_seconds`` ...)."""
    return isinstance(key, str) and (key == "seconds" or key.endswith("_seconds"))


def without_timings(value):
    """``value`` (metadata: dicts, lists, numbers, strings) without its timing keys, at any depth."""
    if isinstance(value, dict):
        return {key: without_timings(item) for key, item in value.items() if not is_timing(key)}
    if isinstance(value, (list, tuple)):
        return [without_timings(item) for item in value]
    return value


def metadata_json(metadata: dict) -> str:
    """``metadata`` without its timings (``without_timings``) as ASCII JSON (NumPy scalars and
    arrays become plain numbers and lists)."""

    def plain(value):
        if isinstance(value, (np.generic, np.ndarray)):
            return value.tolist()
        if isinstance(value, os.PathLike):
            return os.fspath(value)
        raise TypeError(f"{type(value).__name__} value {value!r}")

    try:
        return json.dumps(without_timings(metadata), default=plain)
    except (TypeError, ValueError) as exc:
        raise FormatError(f"metadata is not JSON-serialisable: {exc}") from exc
