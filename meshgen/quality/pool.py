"""The process's thread pool for the quality path's NumPy work (angles from cosines, the summaries
of a block's metrics): NumPy releases the GIL inside its loops, so columns or metrics spread over
the CPUs this process may use."""

from __future__ import annotations

import os
import threading

__all__ = ["map_in_threads", "threads"]

_POOL = []
_LOCK = threading.Lock()


def threads() -> int:
    """The CPUs this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


_PREFIX = "meshgen-quality"


def map_in_threads(function, items) -> list:
    """``[function(item) for item in items]``, the calls spread over the pool (in this thread when
    there is one item or one CPU, or when this thread is one of the pool's: a pool task waiting on
    the pool it occupies could wait forever)."""
    items = list(items)
    if len(items) < 2 or threads() == 1 or threading.current_thread().name.startswith(_PREFIX):
        return [function(item) for item in items]
    from concurrent.futures import ThreadPoolExecutor

    with _LOCK:
        if not _POOL or _POOL[0][0] != os.getpid():  # none yet, or made before this process was forked
            _POOL[:] = [(os.getpid(), ThreadPoolExecutor(max_workers=threads(), thread_name_prefix=_PREFIX))]
        pool = _POOL[0][1]
    return list(pool.map(function, items))
