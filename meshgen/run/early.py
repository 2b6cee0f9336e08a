"""What a command starts before click parses it or the command's module is imported (design notes
§21, "meshgen evaluate: the child forked first").

``meshgen evaluate`` forks the child that loads numba and computes the quality report's parts
(``meshgen.quality.worker``) as the process starts: ``python -m meshgen`` calls ``start_early``
before it imports click, NumPy, the file readers or the geometry plugins, so the child's start
(NumPy, numba, the kernels) and the parent's (the command, the file) overlap from the first tenth of
a second. This module imports only the standard library (``multiprocessing`` when it forks).

- ``start_early(args)``: the early start of the command ``args`` names (``EARLY_STARTS``), the
  cyclic garbage collector off until the command's body calls ``resume_collection``;
- ``fork_early_worker()``: that child, with a memory file (``memfd_create``) for the nodes, whose
  size is not known yet; the command's first ``EvaluationWorker`` adopts both
  (``take_early_worker``), or ``release_early_worker`` ends the child;
- ``fork(serve, *arguments)`` and ``end(process, connection, memory)``: how every quality worker is
  forked and ended.
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import os
import sys

__all__ = [
    "EARLY_CHILD",
    "EARLY_STARTS",
    "end",
    "fork",
    "fork_early_worker",
    "release_early_worker",
    "start_early",
    "take_early_worker",
]

# name -> module:function run first when the command starts, before click parses it or the command's
# module is imported: evaluate forks the process that loads numba meanwhile.
EARLY_STARTS = {"evaluate": "meshgen.run.early:fork_early_worker"}


_collection_paused = False  # whether start_early turned the cyclic garbage collector off


def start_early(args) -> None:
    """Run the early start of the command ``args`` name (``EARLY_STARTS``), unless it only asks for
    help. The cyclic garbage collector is off from here until the command body calls
    ``resume_collection``: the imports before it (some 700 modules) make hundreds of thousands of
    objects and no garbage, and the collections they trigger cost the child forked here 0.05 s of
    its 0.4 s start (it inherits the setting, and keeps it: ``meshgen.quality.worker``)."""
    global _collection_paused
    if args and args[0] in EARLY_STARTS and not {"-h", "--help"} & set(args):
        if gc.isenabled():
            gc.disable()
            _collection_paused = True
        module_name, function_name = EARLY_STARTS[args[0]].split(":")
        getattr(importlib.import_module(module_name), function_name)()


def resume_collection() -> None:
    """Turn the cyclic garbage collector back on if ``start_early`` turned it off (a command's
    body, once its imports are done, before it does its work)."""
    global _collection_paused
    if _collection_paused:
        _collection_paused = False
        gc.enable()


def fork(serve, *arguments):
    """(process, connection): a forked child (a daemon) running ``serve(child end, parent end, this
    process's pid, *arguments)``; ``connection`` is this process's end of the pipe between them."""
    import multiprocessing

    context = multiprocessing.get_context("fork")
    connection, child_end = context.Pipe()
    arguments = (child_end, connection, os.getpid(), *arguments)
    process = context.Process(target=serve, args=arguments, name="meshgen-quality", daemon=True)
    process.start()
    child_end.close()
    return process, connection


def end(process, connection, memory: int | None = None, wait: bool = True) -> None:
    """Kill the child ``process`` (if it still runs), reap it, close its pipe and ``memory`` file.
    ``wait`` False: do not wait while the kernel takes the dead child's memory back (10 ms for a
    worker that measured a large mesh); multiprocessing reaps it at its next fork or at exit."""
    with contextlib.suppress(OSError, ValueError):
        process.kill()
        if wait:
            process.join()
    connection.close()
    if memory is not None:
        with contextlib.suppress(OSError):
            os.close(memory)


_early = None  # (process, connection, memory file) of the child fork_early_worker forked, until taken


def fork_early_worker() -> None:
    """Fork, first thing in ``meshgen evaluate``, the child the command's first ``EvaluationWorker``
    adopts: Linux with ``memfd_create``, two CPUs or more for this process, numba not loaded here.
    Nothing happens where one of those is missing or the fork fails."""
    global _early
    if _early is not None or not sys.platform.startswith("linux") or not hasattr(os, "memfd_create"):
        return
    if "numba" in sys.modules or len(os.sched_getaffinity(0)) < 2:
        return
    try:
        memory = os.memfd_create("meshgen-nodes")
    except OSError:
        return
    try:
        _early = (*fork(_serve_early, memory), memory)
    except OSError:
        os.close(memory)


# module:function the early child runs (as ``serve(child end, parent end, parent pid, memory
# file)``), named here and imported in the child only: this module imports nothing of meshgen's.
EARLY_CHILD = "meshgen.quality.worker:serve_early"


def _serve_early(connection, parent_end, parent: int, memory: int) -> None:
    """The early child: ``EARLY_CHILD``, imported here, in the child (NumPy with it). Any failure
    to import it ends the child quietly (the parent, finding it gone, computes the report itself)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and ends the child
    try:
        module_name, function_name = EARLY_CHILD.split(":")
        serve = getattr(importlib.import_module(module_name), function_name)
    except BaseException:  # noqa: BLE001 - no traceback from a helper process
        os._exit(1)
    serve(connection, parent_end, parent, memory)


def take_early_worker():
    """The early child's (process, connection, memory file), once; None when there is none or it
    died meanwhile."""
    global _early
    early, _early = _early, None
    if early is not None and not early[0].is_alive():
        end(*early)
        return None
    return early


def release_early_worker() -> None:
    """End the child ``fork_early_worker`` forked if no ``EvaluationWorker`` adopted it."""
    early = take_early_worker()
    if early is not None:
        end(*early)
