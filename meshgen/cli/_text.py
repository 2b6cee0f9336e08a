"""Lines for a person at a terminal: long lines wrap between words, continuation lines indented."""

from __future__ import annotations

import shutil
import sys
import textwrap

import click

__all__ = ["echo", "terminal_width", "wrapped"]


def terminal_width(stream=None) -> int | None:
    """The terminal's width in columns when ``stream`` (default stdout) is a terminal, else None
    (a file or pipe gets each line whole)."""
    stream = stream or sys.stdout
    if not stream.isatty():
        return None
    return shutil.get_terminal_size().columns


def wrapped(line: str, width: int | None) -> list[str]:
    """``line`` broken between words into lines of at most ``width`` characters; the continuation
    lines are indented four spaces past the line's own indent. ``width`` None: the line as it is."""
    if width is None or len(line) <= width:
        return [line]
    indent = line[: len(line) - len(line.lstrip())]
    return textwrap.wrap(
        line.strip(),
        width=width,
        initial_indent=indent,
        subsequent_indent=indent + "    ",
        break_long_words=False,
        break_on_hyphens=False,
    )


def echo(line: str, err: bool = False) -> None:
    """``click.echo`` with the line wrapped between words at the terminal's width."""
    width = terminal_width(sys.stderr if err else sys.stdout)
    for part in wrapped(line, width):
        click.echo(part, err=err)
