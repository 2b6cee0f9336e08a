"""Where meshgen's metadata goes in a mesh file: the key every format stores it under, and the
JSON text it is stored as. Shared by the format modules and the registry (``meshgen.formats``)."""

from __future__ import annotations

import json
import os

import numpy as np

from meshgen.errors import FormatError

__all__ = ["METADATA_KEY", "metadata_json"]

METADATA_KEY = "meshgen"


def metadata_json(metadata: dict) -> str:
    """``metadata`` as ASCII JSON (NumPy scalars and arrays become plain numbers and lists)."""

    def plain(value):
        if isinstance(value, (np.generic, np.ndarray)):
            return value.tolist()
        if isinstance(value, os.PathLike):
            return os.fspath(value)
        raise TypeError(f"{type(value).__name__} value {value!r}")

    try:
        return json.dumps(metadata, default=plain)
    except (TypeError, ValueError) as exc:
        raise FormatError(f"metadata is not JSON-serialisable: {exc}") from exc
