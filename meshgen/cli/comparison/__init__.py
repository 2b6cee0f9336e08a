"""Meshing methods side by side (``meshgen compare``): one row per method or mesh file, the headline
columns of design notes §7, the best value per column, and the files a comparison leaves behind.

A comparison is plain data (what ``compare.json`` holds)::

    {"mode": "methods" | "files", "geometry", "params", "dims", "timing_repeats",
     "columns": [{"key", "label", "best"}], "best": {column key: [row names]},
     "rows": [row, ...], "valid_rule", "notes": [...]}

and a row is ``{"name", "kind": "classical" | "neural" | "file", "headline": {...}, "quality":
<the meshgen evaluate report>, "meshing_seconds", "meshing_timings", ...}`` (``"error"`` instead of
figures when the method failed).

Modules: ``columns`` (the columns, the headline figures and the ranking: plain data), ``runs``
(meshing the methods through ``meshgen.run.request``, measuring files), ``outputs`` (Markdown, CSV,
JSON). The pictures are ``meshgen.cli.plots``.
"""

from meshgen.cli.comparison.columns import (
    CAPTION,
    COLUMNS,
    COLUMNS_JSON,
    HEADLINE_METRICS,
    Column,
    best_rows,
    cell_text,
    headline,
    table,
    title,
)
from meshgen.cli.comparison.outputs import csv_text, markdown, notes, prepare_out_dir, write_tables
from meshgen.cli.comparison.runs import (
    DEFAULT_METHODS,
    Budget,
    Outcome,
    Picture,
    check_mesh_files,
    compare_files,
    compare_methods,
    method_names,
    neural_method,
    parse_checkpoints,
    parse_methods,
)

__all__ = [
    "CAPTION",
    "COLUMNS",
    "COLUMNS_JSON",
    "DEFAULT_METHODS",
    "HEADLINE_METRICS",
    "Budget",
    "Column",
    "Outcome",
    "Picture",
    "best_rows",
    "cell_text",
    "check_mesh_files",
    "compare_files",
    "compare_methods",
    "csv_text",
    "headline",
    "markdown",
    "method_names",
    "neural_method",
    "notes",
    "parse_checkpoints",
    "parse_methods",
    "prepare_out_dir",
    "table",
    "title",
    "write_tables",
]
