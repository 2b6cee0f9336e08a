"""Mesh quality (design notes §7): per-cell metrics, their summaries and the validity verdict.

Where things are:

- ``kernels``: the metric definitions; ``compiled``: the numba kernels; ``numpy_kernels``: the same
  metrics in plain NumPy (small meshes, and the compiled kernels' test reference);
- ``structured``: node arrays (``cell_metrics``); ``faces``: unstructured cells, face neighbours
  by face matching (``match_faces``, ``cell_metrics_unstructured``);
- ``report``: summaries, inverted cells, verdict, boundary deviation (``quality_report``);
- ``text``: the terminal lines (``summary_lines``);
- ``files``: mesh files, the ``<mesh>.quality.json`` sidecar, JSON (``evaluate_file``,
  ``write_mesh_with_quality``, ``write_json``);
- ``chunked`` and ``sketch``: meshes larger than memory, block by block on Dask, percentiles by a
  mergeable quantile sketch.

This module re-exports the public names, so ``from meshgen.quality import X`` keeps working. Those
of ``files`` are imported when first asked for: ``files`` reads and writes every format and loads
geometries (a quarter of a second of imports), which the forked quality worker
(``meshgen.quality.worker``) and the kernels never need.
"""

import importlib

from meshgen.quality.faces import CELL_TYPES, cell_metrics_unstructured, cells_for_quality, match_faces
from meshgen.quality.kernels import (
    BLOCK_CELLS,
    DEFINITIONS,
    DEGENERATE_TOLERANCE,
    HEX_CORNER,
    HEX_FACE_CORNERS,
    HEX_FACES,
    METRICS,
    QUAD_CORNER,
    QUAD_FACE_CORNERS,
    QUAD_FACES,
    STATS,
    VALID_FRACTION,
    VALID_RULE,
    WORST,
)
from meshgen.quality.report import quality_report, summarize
from meshgen.quality.structured import cell_metrics
from meshgen.quality.text import summary_lines

_FILES_NAMES = (
    "as_node_array",
    "evaluate_file",
    "json_ready",
    "recorded_metadata",
    "sidecar_path",
    "write_json",
    "write_mesh_alone",
    "write_mesh_with_quality",
)

__all__ = [
    "BLOCK_CELLS",
    "CELL_TYPES",
    "DEFINITIONS",
    "DEGENERATE_TOLERANCE",
    "HEX_CORNER",
    "HEX_FACE_CORNERS",
    "HEX_FACES",
    "METRICS",
    "QUAD_CORNER",
    "QUAD_FACE_CORNERS",
    "QUAD_FACES",
    "STATS",
    "VALID_FRACTION",
    "VALID_RULE",
    "WORST",
    "as_node_array",
    "cell_metrics",
    "cell_metrics_unstructured",
    "cells_for_quality",
    "evaluate_file",
    "json_ready",
    "match_faces",
    "quality_report",
    "recorded_metadata",
    "sidecar_path",
    "summarize",
    "summary_lines",
    "write_json",
    "write_mesh_alone",
    "write_mesh_with_quality",
]


def __getattr__(name):
    if name in _FILES_NAMES:
        return getattr(importlib.import_module("meshgen.quality.files"), name)
    raise AttributeError(f"module 'meshgen.quality' has no attribute {name!r}")
