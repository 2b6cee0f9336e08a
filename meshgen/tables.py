"""Tables as text, shared by ``evaluate`` and ``compare``: how a figure is printed, a Markdown table,
a rich terminal table. A table is plain data: a header (list of str) and rows (lists of str);
``highlight`` is a set of (row, column) positions to emphasise (bold green in the terminal, bold
in Markdown)."""

from __future__ import annotations

import sys

# How each per-cell metric of meshgen.quality is named in tables and figure labels.
METRIC_LABELS = {
    "min_angle": "min angle (deg)",
    "max_angle": "max angle (deg)",
    "equiangle_skewness": "equiangle skewness",
    "aspect_ratio": "aspect ratio",
    "centroid_skewness": "centroid skewness",
    "non_orthogonality": "non-orthogonality (deg)",
    "scaled_jacobian": "scaled Jacobian",
}


def number(value) -> str:
    """A figure as printed in tables: 4 significant digits, ints as they are, booleans yes / NO,
    None (undefined) as n/a."""
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return "yes" if value else "NO"
    if isinstance(value, int):
        return str(value)
    return f"{value:.4g}"


def _escape(text) -> str:
    return str(text).replace("|", "\\|")


def markdown_table(header, rows, highlight=frozenset()) -> list[str]:
    """Lines of a Markdown table; the first column left-aligned, the others right-aligned."""
    lines = ["| " + " | ".join(map(_escape, header)) + " |", "|" + "|".join(["---"] + ["---:"] * (len(header) - 1)) + "|"]
    for r, row in enumerate(rows):
        cells = [f"**{_escape(cell)}**" if (r, c) in highlight else _escape(cell) for c, cell in enumerate(row)]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def print_table(header, rows, title=None, highlight=frozenset(), caption=None, file=None) -> None:
    """Print a table with rich (first column left, others right-aligned; highlighted cells bold
    green; ``caption`` below it)."""
    from rich import box
    from rich.console import Console
    from rich.table import Table
    from rich.text import Text

    console = Console(width=200, soft_wrap=False, file=file or sys.stdout)
    table = Table(title=title, caption=caption, box=box.SIMPLE_HEAD, title_justify="left", caption_justify="left")
    table.add_column(header[0])
    for name in header[1:]:
        table.add_column(name, justify="right")
    for r, row in enumerate(rows):
        # Text, not markup: file names may hold square brackets.
        table.add_row(*(Text(str(cell), style="bold green" if (r, c) in highlight else "") for c, cell in enumerate(row)))
    console.print(table)
