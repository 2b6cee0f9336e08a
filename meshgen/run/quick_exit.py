"""Ending a command without the interpreter's teardown (design notes §21).

After a command has written its files and printed its output, CPython still tears down every
module and object it imported (``meshgen evaluate``: some 700 modules, 45 to 70 ms on a two-core
machine, a twentieth of the command) before the process exits. ``exit_quickly(status)`` does what
of that exit matters, in CPython's order, and skips the rest: the non-daemon threads are joined
(``threading._shutdown``: idle thread pools end, a working thread finishes), the ``atexit``
handlers run (temporary files, logging, the multiprocessing children), stdout and stderr are
flushed, then ``os._exit(status)``. On a Python without those hooks it is ``sys.exit(status)``.
Commands opt in by name (``meshgen.cli.QUICK_EXITS``).
"""

from __future__ import annotations

import atexit
import os
import sys
import threading

__all__ = ["exit_quickly"]


def exit_quickly(status: int):
    """Exit with ``status`` after joining the threads, the atexit handlers and a flush of stdout
    and stderr, without the interpreter's teardown (the module text); ``sys.exit(status)`` where
    this Python lacks ``threading._shutdown`` or ``atexit._run_exitfuncs``."""
    join_threads = getattr(threading, "_shutdown", None)
    run_handlers = getattr(atexit, "_run_exitfuncs", None)
    if join_threads is None or run_handlers is None or threading.current_thread() is not threading.main_thread():
        sys.exit(status)
    join_threads()
    run_handlers()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (head), a closed stream: nothing left to say
            pass
    os._exit(status)
