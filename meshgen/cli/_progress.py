"""A progress bar for iterative methods: a callback ``progress(done, **figures)`` drawn with rich."""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["progress_display"]


def _format(value) -> str:
    return f"{value:.2e}" if isinstance(value, float) else str(value)


@contextmanager
def progress_display(label: str, enabled: bool):
    """Yield a callback ``progress(done, **figures)`` that draws a bar (``done`` in [0, 1]) with the
    figures beside it (e.g. cycle 4  update 1.2e-05  residual 3.0e-07) and erases it at the end;
    yield None when not ``enabled`` (not a terminal, --quiet, or a method without progress)."""
    if not enabled:
        yield None
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    columns = (TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[figures]}"), TimeElapsedColumn())
    with Progress(*columns, transient=True) as bar:
        task = bar.add_task(label, total=1.0, figures="starting")

        def progress(done: float, **figures) -> None:
            text = "  ".join(f"{name} {_format(value)}" for name, value in figures.items())
            bar.update(task, completed=done, figures=text)

        yield progress
