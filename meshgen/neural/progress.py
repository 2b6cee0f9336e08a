"""How training reports itself: a rich progress bar, plain log lines (``--quiet``), or nothing.

A reporter has ``stage(name, done, total)`` when a stage starts, ``update(row, done, total)``
after each step (``row`` is the history row: L1, L2, total, a1, a2, conflict, lr, ...) and
``message(text)`` for events such as a divergence-guard restore.
"""

from __future__ import annotations

import collections
import sys
import time

__all__ = ["STAGE_TITLES", "FIELD_HELP", "shown_fields", "describe_row", "RichReporter", "LogReporter", "reporter_for"]


STAGE_TITLES = {"pretrain": "TFI fit", "adam": "Adam", "lbfgs": "L-BFGS"}
# What the optional figures of a progress line mean; ``meshgen train --help`` prints these.
FIELD_HELP = {
    "misfit": "the first fit's loss (mean squared distance from the start: the TFI map, a block set's elliptic mesh, or the marched layers round a wall)",
    "L1": "the PDE (Winslow) loss",
    "L2": "the boundary loss",
    "a": "the learned weights a1 (PDE), a2 (boundary) of the losses",
    "conflict": "share of the last 100 steps whose PDE and boundary gradients pointed apart (PCGrad then projects them)",
    "lr": "the learning rate",
}


def shown_fields(config=None) -> frozenset[str]:
    """The optional figures a run's progress lines show: ``L2`` unless the boundary is exact,
    ``a`` with reweighting, ``conflict`` with PCGrad. ``config`` None: all of them."""
    if config is None:
        return frozenset({"L2", "a", "conflict"})
    return frozenset(
        name
        for name, used in (
            ("L2", not config.model.exact_boundary),
            ("a", config.method.reweighting),
            ("conflict", config.method.pcgrad),
        )
        if used
    )


def describe_row(row: dict, conflict_rate: float | None, fields=shown_fields()) -> str:
    """The loss terms, weights, conflict rate and learning rate of a history row, in one line;
    ``fields``: the optional figures to show (``shown_fields``)."""
    parts = []
    if "L1" in row:
        parts.append(f"L1 {row['L1']:.2e}" + (f"  L2 {row['L2']:.2e}" if "L2" in fields else ""))
        if "a" in fields and "a1" in row:
            parts.append(f"a {row['a1']:.3g} {row['a2']:.3g}")
    else:
        parts.append(f"misfit {row['total']:.2e}")
    if conflict_rate is not None and "conflict" in fields:
        parts.append(f"conflict {100 * conflict_rate:.0f}%")
    parts.append(f"lr {row['lr']:.2e}")
    return "  ".join(parts)


class _ConflictRate:
    """Share of conflicting steps among the last ``window``."""

    def __init__(self, window: int = 100):
        self.flags = collections.deque(maxlen=window)

    def add(self, row) -> float | None:
        if "conflict" not in row:
            return None
        self.flags.append(row["conflict"])
        return sum(self.flags) / len(self.flags)


class RichReporter:
    BAR_WIDTH = 16

    """A progress bar per stage on stderr: stage, bar, step, ETA, then the loss terms, weights,
    conflict rate and lr, cut with an ellipsis where the terminal is too narrow for them (the bar,
    the step and the ETA always fit 80 columns)."""

    def __init__(self, refresh_seconds: float = 0.1, fields=shown_fields(), console=None):
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
        from rich.table import Column

        self.console = console or Console(stderr=True)
        fixed = {"no_wrap": True}
        self.progress = Progress(
            TextColumn("{task.description:>7}", table_column=Column(**fixed)),
            BarColumn(bar_width=self.BAR_WIDTH, table_column=Column(**fixed)),
            MofNCompleteColumn(table_column=Column(**fixed)),
            TextColumn("ETA", table_column=Column(**fixed)),
            TimeRemainingColumn(table_column=Column(**fixed)),
            TextColumn("{task.fields[losses]}", table_column=Column(**fixed)),
            console=self.console,
        )
        self.fields = fields
        self.task = None
        self.refresh_seconds = refresh_seconds
        self.last_refresh = 0.0
        self.conflicts = _ConflictRate()

    def __enter__(self):
        self.progress.start()
        return self

    def __exit__(self, *exc):
        self.progress.stop()

    def stage(self, name, done, total):
        self.task = self.progress.add_task(STAGE_TITLES.get(name, name), total=total, completed=done, losses="")

    def update(self, row, done, total):
        rate = self.conflicts.add(row)
        now = time.monotonic()
        if now - self.last_refresh >= self.refresh_seconds or done == total:
            self.last_refresh = now
            losses = describe_row(row, rate, self.fields)
            self.progress.update(self.task, completed=done, losses=self._fit(losses, total))

    def _fit(self, text: str, total: int) -> str:
        """``text`` cut with an ellipsis to the columns the stage, bar, step (done/total) and ETA
        leave on the terminal: rich would otherwise shrink those columns first."""
        step_width = 2 * len(str(total)) + 1
        # 7 stage + bar + step + 3 "ETA" + 8 time (h:mm:ss, up to 99 h), a space after each.
        room = self.console.width - (7 + self.BAR_WIDTH + step_width + 3 + 8 + 5) - 1
        if len(text) <= room:
            return text
        return text[: max(room - 1, 0)] + "…"

    def message(self, text):
        self.progress.console.print(text)


class LogReporter:
    """Plain lines for logs: each stage's start and every tenth of it, and every message."""

    def __init__(self, stream=None, parts: int = 10, fields=shown_fields()):
        self.stream = stream or sys.stderr
        self.parts = parts
        self.fields = fields
        self.conflicts = _ConflictRate()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None

    def _print(self, text):
        print(text, file=self.stream, flush=True)

    def stage(self, name, done, total):
        self.every = max(1, total // self.parts)
        self._print(f"{STAGE_TITLES.get(name, name)}: {total} steps" + (f" (from {done})" if done else ""))

    def update(self, row, done, total):
        rate = self.conflicts.add(row)
        if done % self.every == 0 or done == total:
            self._print(
                f"  step {row['step'] + 1} ({done}/{total})  {describe_row(row, rate, self.fields)}  {row['seconds']:.1f} s"
            )

    def message(self, text):
        self._print(text)


def reporter_for(config, quiet: bool = False):
    """How a run with ``config`` reports: a progress bar where someone watches stderr, log lines
    where it goes to a file or pipe or with ``quiet`` (the figures the config uses, either way)."""
    fields = shown_fields(config)
    if quiet or not sys.stderr.isatty():
        return LogReporter(fields=fields)
    return RichReporter(fields=fields)
