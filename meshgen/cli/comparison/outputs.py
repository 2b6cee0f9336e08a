"""The files a comparison leaves behind: ``compare.json``, ``compare.md`` (the table, best values
bold, and the rules behind it) and ``compare.csv`` (full precision), and the folder they go in."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

from meshgen.cli.comparison.columns import HEADLINE_METRICS, table, title
from meshgen.cli.tables import markdown_table
from meshgen.errors import MeshgenError, ParameterError
from meshgen.quality import VALID_RULE, write_json
from meshgen.run.atomic import atomic_write
from meshgen.run.publish import publishing

__all__ = ["CSV_FIELDS", "csv_text", "markdown", "notes", "prepare_out_dir", "write_tables"]


def notes(comparison: dict) -> list[str]:
    """The rules behind the table, for the Markdown report."""
    lines = [
        "Best value per column in bold: the mean closest to 90 degrees for the angles, the smallest "
        "value for the others (inverted cells by percentage, boundary deviation relative to the "
        "characteristic length L).",
        "Angles, skewnesses, aspect ratio and non-orthogonality are means over the cells; angles "
        "and non-orthogonality in degrees. Boundary deviation: largest distance of a boundary node "
        "from the true boundary, with its fraction of L in brackets.",
        f"Valid: {VALID_RULE}.",
    ]
    if comparison["mode"] == "methods":
        repeats = comparison.get("timing_repeats", 1)
        lines.append(
            f"Meshing time: {'median of ' + str(repeats) + ' runs' if repeats > 1 else 'one run'}; "
            "neural methods: evaluating the trained network (training time separately)."
        )
    else:
        lines.append("Meshing time: as the file records it (n/a where it does not).")
    return lines + list(comparison.get("notes", []))


def markdown(comparison: dict) -> str:
    """The comparison as Markdown: the table (best values bold), failures, the rules."""
    header, rows, highlight = table(comparison)
    lines = [f"## {title(comparison)[0].upper()}{title(comparison)[1:]}", ""]
    lines += markdown_table(header, rows, highlight)
    lines.append("")
    for row in comparison["rows"]:
        if "error" in row:
            lines.append(f"- `{row['name']}` failed: {row['error']}")
    lines += [f"- {line}" for line in notes(comparison)]
    return "\n".join(lines) + "\n"


CSV_FIELDS = (
    "name",
    "kind",
    *HEADLINE_METRICS,
    "inverted_count",
    "inverted_percent",
    "valid",
    "boundary_deviation_max",
    "boundary_deviation_max_rel",
    "boundary_deviation_mean",
    "boundary_deviation_mean_rel",
    "test_loss",
    "training_seconds",
    "meshing_seconds",
    "meshing_timings",
    "error",
)


def csv_text(comparison: dict) -> str:
    """One line per row, figures at full precision (repr), empty where undefined; timings joined by ';'."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CSV_FIELDS, lineterminator="\n")
    writer.writeheader()
    for row in comparison["rows"]:
        values = {"name": row["name"], "kind": row["kind"], "error": row.get("error", "")}
        for key, value in row.get("headline", {}).items():
            if key in CSV_FIELDS:
                values[key] = "" if value is None else value
        values["meshing_timings"] = ";".join(repr(t) for t in row.get("meshing_timings", []))
        writer.writerow(values)
    return buffer.getvalue()


def prepare_out_dir(out_dir) -> Path:
    """Create ``out_dir`` (its parent must exist) or check the existing folder is writable."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ParameterError("out", f"{{name}} {out_dir} is a file, not a folder")
    if not out_dir.exists():
        if not out_dir.parent.is_dir():
            raise ParameterError("out", f"{{name}} {out_dir}: folder {out_dir.parent} does not exist")
        try:
            out_dir.mkdir()
        except OSError as exc:
            raise MeshgenError(f"could not create {out_dir}: {exc.strerror or exc}") from exc
    if not os.access(out_dir, os.W_OK | os.X_OK):
        raise ParameterError("out", f"{{name}} {out_dir} is not writable")
    return out_dir


def write_tables(comparison: dict, out_dir) -> list[Path]:
    """``compare.json``, ``compare.md`` and ``compare.csv`` in ``out_dir``, published together
    (``meshgen.run.publish``): all three of one comparison, or the previous ones."""
    out_dir = Path(out_dir)
    with publishing(out_dir / "compare.json"):
        written = [write_json(out_dir / "compare.json", comparison)]
        for name, text in (("compare.md", markdown(comparison)), ("compare.csv", csv_text(comparison))):
            with atomic_write(out_dir / name) as temporary:
                temporary.write_text(text)
            written.append(out_dir / name)
    return written
