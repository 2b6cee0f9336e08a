"""How training reports itself: a rich progress bar, plain log lines (``--quiet``), or nothing.

A reporter has ``stage(name, done, total)`` when a stage starts, ``update(row, done, total)``
after each step (``row`` is the history row: L1, L2, total, a1, a2, conflict, lr, ...) and
``message(text)`` for events such as a divergence-guard restore.
"""

from __future__ import annotations

import collections
import sys
import time

STAGE_TITLES = {"pretrain": "TFI fit", "adam": "Adam", "lbfgs": "L-BFGS"}


def describe_row(row: dict, conflict_rate: float | None) -> str:
    """The loss terms, weights, conflict rate and learning rate of a history row, in one line."""
    parts = []
    if "L1" in row:
        parts.append(f"L1 {row['L1']:.2e}  L2 {row['L2']:.2e}")
    else:
        parts.append(f"fit {row['total']:.2e}")
    if "L1" in row:
        parts.append(f"a {row['a1']:.3g} {row['a2']:.3g}")
    if conflict_rate is not None:
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
    """A progress bar per stage on stderr: step, loss terms, weights, conflict rate, lr, ETA."""

    def __init__(self, refresh_seconds: float = 0.1):
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        self.console = Console(stderr=True)
        self.progress = Progress(
            TextColumn("{task.description:>7}"),
            BarColumn(bar_width=20),
            MofNCompleteColumn(),
            TextColumn("{task.fields[losses]}"),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=self.console,
        )
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
            self.progress.update(self.task, completed=done, losses=describe_row(row, rate))

    def message(self, text):
        self.progress.console.print(text)


class LogReporter:
    """Plain lines for logs: each stage's start and every tenth of it, and every message."""

    def __init__(self, stream=None, parts: int = 10):
        self.stream = stream or sys.stderr
        self.parts = parts
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
            self._print(f"  step {row['step'] + 1} ({done}/{total})  {describe_row(row, rate)}  {row['seconds']:.1f} s")

    def message(self, text):
        self._print(text)
