"""SIGTERM and SIGHUP end meshgen the way Ctrl-C does: as an exception (``Terminated``, a
BaseException like KeyboardInterrupt, so no ``except Exception`` swallows it) that unwinds the
stack, so every write's cleanup runs (temporaries removed, previous files kept), instead of the
default of dying on the spot. Installed once, by the
command-line entry (``meshgen.cli.main``); a signal the parent set to be ignored (``nohup``) stays
ignored."""

from __future__ import annotations

import signal
import sys

__all__ = ["TERMINATING_SIGNALS", "Terminated", "exit_interrupted", "install_termination_handlers", "raise_terminated"]

TERMINATING_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))


class Terminated(BaseException):
    """The process was asked to stop by ``signum`` (SIGTERM, SIGHUP); the CLI exits 128 + signum."""

    def __init__(self, signum: int):
        self.signum = int(signum)
        super().__init__(signal.Signals(signum).name)


def raise_terminated(signum, frame):
    raise Terminated(signum)


def install_termination_handlers() -> None:
    """Make SIGTERM and SIGHUP raise ``Terminated`` in the main thread (ignored ones stay ignored)."""
    for signum in TERMINATING_SIGNALS:
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, raise_terminated)


def exit_interrupted(status: int):
    """Exit with ``status`` (130 after Ctrl-C, 128 + signum after SIGTERM/SIGHUP), ignoring any
    further Ctrl-C or termination signal from here on: the cleanup is done and the exit decided, and
    an impatient second Ctrl-C during the interpreter's shutdown (slow with torch loaded) would
    otherwise kill the process by the signal and replace the exit status."""
    for signum in (signal.SIGINT, *TERMINATING_SIGNALS):
        signal.signal(signum, signal.SIG_IGN)
    sys.exit(status)
