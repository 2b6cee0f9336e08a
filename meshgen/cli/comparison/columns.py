"""The columns of a comparison and how rows rank in them (plain data; see ``meshgen.cli.comparison``).

A row's ``headline`` holds the table's figures at full precision:

- ``min_angle`` ... ``non_orthogonality``: the means of the per-cell metrics (degrees for angles
  and non-orthogonality);
- ``inverted_count``, ``inverted_percent``, ``valid`` (no inverted cell);
- ``boundary_deviation_max``, ``_max_rel`` (relative to the characteristic length), ``_mean``,
  ``_mean_rel``: distance of the boundary nodes from the true boundary (None without a geometry);
- ``test_loss``: the trained network's loss on the held-out points (neural methods);
- ``training_seconds``; ``meshing_seconds``: the median of ``timing_repeats`` runs (files: what
  the file records).

Best per column: the smallest value, except the angles, where the mean closest to 90 degrees is
best (the largest mean min angle, the smallest mean max angle); inverted cells rank by percentage
and boundary deviation by its relative maximum, so meshes of different sizes and geometries rank
fairly. Values equal up to round-off (relative 1e-9; boundary deviation below 1e-12 of the
characteristic length) tie, and every tied row is marked. A column needs two rows with a value to
have a best one. ``valid`` has no best.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from meshgen.cli.tables import number

__all__ = [
    "CAPTION",
    "COLUMNS",
    "COLUMNS_JSON",
    "HEADLINE_METRICS",
    "TIE_RELATIVE",
    "Column",
    "best_rows",
    "cell_text",
    "headline",
    "number_or_none",
    "table",
    "title",
]


@dataclass(frozen=True)
class Column:
    key: str  # the headline figure that ranks the column
    label: str  # in Markdown and JSON
    short: str  # in the terminal, where 13 columns must fit
    best: str | None  # "min", "near90" (closest to 90 degrees) or None
    zero: float = 0.0  # values below this are round-off: they tie with zero


COLUMNS = (
    Column("min_angle", "min angle (deg)", "min angle", "near90"),
    Column("max_angle", "max angle (deg)", "max angle", "near90"),
    Column("equiangle_skewness", "equiangle skewness", "equiangle skew", "min"),
    Column("aspect_ratio", "aspect ratio", "aspect ratio", "min"),
    Column("centroid_skewness", "centroid skewness", "centroid skew", "min"),
    Column("non_orthogonality", "non-orthogonality (deg)", "non-orth", "min"),
    Column("inverted_percent", "inverted cells", "inverted", "min"),
    Column("valid", "valid", "valid", None),
    Column("boundary_deviation_max_rel", "boundary deviation max (of L)", "boundary dev", "min", zero=1e-12),
    Column("test_loss", "test-set loss", "test loss", "min"),
    Column("training_seconds", "training (s)", "train (s)", "min"),
    Column("meshing_seconds", "meshing (s)", "mesh (s)", "min"),
)
COLUMNS_JSON = [{"key": c.key, "label": c.label, "best": c.best} for c in COLUMNS]
HEADLINE_METRICS = ("min_angle", "max_angle", "equiangle_skewness", "aspect_ratio", "centroid_skewness", "non_orthogonality")
TIE_RELATIVE = 1e-9


def headline(report: dict | None, **figures) -> dict:
    """The table's figures of a quality report (``meshgen evaluate``'s schema) plus ``figures``
    (test_loss, training_seconds, meshing_seconds; missing ones None)."""
    values = {key: None for key in (*HEADLINE_METRICS, "inverted_count", "inverted_percent", "valid")}
    values.update({f"boundary_deviation_{s}": None for s in ("max", "max_rel", "mean", "mean_rel")})
    if report is not None:
        for name in HEADLINE_METRICS:
            values[name] = report["metrics"][name]["mean"]
        values["inverted_count"] = report["inverted"]["count"]
        values["inverted_percent"] = 100.0 * report["inverted"]["fraction"]
        values["valid"] = report["valid"]
        deviation = report.get("boundary_deviation") or {}
        for stat in ("max", "max_rel", "mean", "mean_rel"):
            values[f"boundary_deviation_{stat}"] = deviation.get(stat)
    for key in ("test_loss", "training_seconds", "meshing_seconds"):
        values[key] = figures.get(key)
    return values


def number_or_none(value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def best_rows(rows) -> dict[str, list[str]]:
    """Column key -> names of the rows with the best value (see the module's docstring)."""
    best = {}
    for column in COLUMNS:
        if column.best is None:
            continue
        scored = []
        for row in rows:
            value = number_or_none(row.get("headline", {}).get(column.key))
            if value is None:
                continue
            score = abs(value - 90.0) if column.best == "near90" else value
            scored.append((max(score, column.zero) if column.best == "min" else score, row["name"]))
        if len(scored) < 2:
            continue
        top = min(score for score, _ in scored)
        tolerance = TIE_RELATIVE * abs(top)
        best[column.key] = [name for score, name in scored if score - top <= tolerance]
    return best


def cell_text(column: Column, values: dict, short: bool = False) -> str:
    """How a headline figure reads in the tables (``short``: the terminal's, boundary deviation
    without its relative value)."""
    if column.key == "inverted_percent":
        if values["inverted_count"] is None:
            return "n/a"
        return f"{values['inverted_count']} ({values['inverted_percent']:.3g}%)"
    if column.key == "boundary_deviation_max_rel":
        if values["boundary_deviation_max"] is None:
            return "n/a"
        if short:
            return number(values["boundary_deviation_max"])
        return f"{number(values['boundary_deviation_max'])} ({number(values['boundary_deviation_max_rel'])})"
    if column.key == "test_loss" and values["test_loss"] is not None:
        return f"{values['test_loss']:.3e}"
    if column.key.endswith("_seconds") and values[column.key] is not None:
        return f"{values[column.key]:.3g}"
    return number(values[column.key])


def table(comparison: dict, short: bool = False) -> tuple[list[str], list[list[str]], set[tuple[int, int]]]:
    """(header, rows, highlighted (row, column) cells) of a comparison; failed rows read 'failed'.
    ``short``: the terminal's compact headers and cells."""
    header = ["method" if comparison["mode"] == "methods" else "mesh", *(c.short if short else c.label for c in COLUMNS)]
    rows, highlight = [], set()
    for r, row in enumerate(comparison["rows"]):
        if "error" in row:
            rows.append([row["name"], *(["failed"] + [""] * (len(COLUMNS) - 1))])
            continue
        rows.append([row["name"], *(cell_text(c, row["headline"], short) for c in COLUMNS)])
        for c, column in enumerate(COLUMNS, start=1):
            if row["name"] in comparison["best"].get(column.key, ()):
                highlight.add((r, c))
    return header, rows, highlight


def title(comparison: dict) -> str:
    if comparison["mode"] == "files":
        text = f"comparison of {len(comparison['rows'])} meshes"
    else:
        text = f"comparison on {comparison['geometry']}, {' x '.join(map(str, comparison['dims']))} cells"
    repeats = comparison.get("timing_repeats", 1)
    if comparison["mode"] == "methods" and repeats > 1:
        text += f" (meshing time: median of {repeats} runs)"
    return text


CAPTION = (
    "Means over the cells; angles and non-orth(ogonality) in degrees; boundary dev: largest distance of a "
    "boundary node from the true boundary; best per column in bold green (angles: closest to 90)."
)
