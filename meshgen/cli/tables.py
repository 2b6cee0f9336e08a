"""Tables as text, shared by ``evaluate`` and ``compare``: how a figure is printed, a Markdown table,
a rich terminal table. A table is plain data: a header (list of str) and rows (lists of str);
``highlight`` is a set of (row, column) positions to emphasise (bold green in the terminal, bold
in Markdown)."""

from __future__ import annotations

import contextlib
import io
import shutil
import sys

__all__ = ["METRIC_LABELS", "markdown_table", "number", "print_table", "transposed", "warm_up"]

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


def transposed(header, rows, highlight=frozenset()):
    """The table turned by a quarter: a row per column of the original, a column per row (the
    first column's entries become the header). Returns (header, rows, highlight)."""
    new_header = [header[0], *(row[0] for row in rows)]
    new_rows = [[header[c], *(row[c] for row in rows)] for c in range(1, len(header))]
    return new_header, new_rows, {(c - 1, r + 1) for r, c in highlight}


def print_table(header, rows, title=None, highlight=frozenset(), caption=None, file=None, fit_terminal=False) -> None:
    """Print a table with rich (first column left, others right-aligned; highlighted cells bold
    green; ``caption`` below it). Full width into files and pipes; ``fit_terminal``: on a terminal
    too narrow for the table, print it transposed (a column per row)."""
    from rich.console import Console

    stream = file or sys.stdout
    columns = _terminal_columns(stream)
    console = Console(width=columns or 200, soft_wrap=False, file=stream)
    table = _rich_table(header, rows, title, highlight, caption)
    natural = console.measure(table, options=console.options.update_width(10_000)).maximum
    if fit_terminal and columns is not None and natural > columns:
        turned_header, turned_rows, turned_highlight = transposed(header, rows, highlight)
        table = _rich_table(turned_header, turned_rows, title, turned_highlight, caption)
    console.print(table)


def warm_up() -> None:
    """Import rich and print a small table into memory, so that the next ``print_table`` pays
    only for its own table (the first one costs some 40 ms more: rich's imports and caches), e.g.
    on a thread while a command waits for its results. Errors are left to that print."""
    with contextlib.suppress(Exception):
        print_table(["quantity", "value"], [["cells", "1"]], title="warm-up", file=io.StringIO())


def _terminal_columns(stream) -> int | None:
    """The width of the terminal ``stream`` writes to; None for a file or pipe."""
    try:
        return shutil.get_terminal_size().columns if stream.isatty() else None
    except (AttributeError, ValueError):
        return None


def _rich_table(header, rows, title=None, highlight=frozenset(), caption=None):
    from rich import box
    from rich.table import Table
    from rich.text import Text

    table = Table(title=title, caption=caption, box=box.SIMPLE_HEAD, title_justify="left", caption_justify="left")
    table.add_column(header[0])
    for name in header[1:]:
        table.add_column(name, justify="right")
    for r, row in enumerate(rows):
        # Text, not markup: file names may hold square brackets.
        table.add_row(*(Text(str(cell), style="bold green" if (r, c) in highlight else "") for c, cell in enumerate(row)))
    return table
