"""Where block computations run: Dask's local threaded scheduler, or a dask.distributed cluster.

``connect(address)`` opens a ``distributed.Client`` for ``--scheduler ADDRESS`` (or the
``DASK_SCHEDULER_ADDRESS`` environment variable, Dask's own convention), failing fast with one
line when nobody answers. ``compute_in_order_of_completion`` computes a list of dask objects with
at most ``window`` of them in flight, yielding each result as it is ready, so the caller can write
or merge it and let it go: memory stays bounded by the window, not by the mesh.
"""

from __future__ import annotations

import logging
import os

from meshgen.errors import MeshgenError

__all__ = ["ADDRESS_VARIABLE", "CONNECT_TIMEOUT_SECONDS", "compute_in_order_of_completion", "connect", "scheduler_address"]

CONNECT_TIMEOUT_SECONDS = 5
ADDRESS_VARIABLE = "DASK_SCHEDULER_ADDRESS"


def scheduler_address(address: str | None) -> str | None:
    """The address given, else ``DASK_SCHEDULER_ADDRESS``, else None (local threads)."""
    return address or os.environ.get(ADDRESS_VARIABLE) or None


def connect(address: str | None):
    """A ``distributed.Client`` connected to ``address``, or None for None (local threads).
    MeshgenError within ``CONNECT_TIMEOUT_SECONDS`` when the scheduler cannot be reached."""
    if not address:
        return None

    from distributed import Client

    logging.getLogger("distributed").setLevel(logging.CRITICAL)  # its own retries would print tracebacks
    try:
        return Client(address, timeout=CONNECT_TIMEOUT_SECONDS, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise MeshgenError(f"cannot reach the Dask scheduler at {address} ({reason[:200]})") from None


def compute_in_order_of_completion(tasks, client=None, window: int | None = None):
    """Yield ``(index, result)`` for each dask object of ``tasks`` (delayed blocks), with at most
    ``window`` computed or held at once (default: twice the workers' threads).

    Local: ``dask.compute`` on the threaded scheduler, ``window`` tasks at a time. Distributed:
    ``client.compute`` futures and ``as_completed``, a new task submitted as each one finishes.
    """
    tasks = list(tasks)
    if client is None:
        import dask
        import dask.threaded

        window = window or 2 * (os.cpu_count() or 1)
        for first in range(0, len(tasks), window):
            # The threaded scheduler's function itself: naming it "threads" would import distributed (1 s).
            results = dask.compute(*tasks[first : first + window], scheduler=dask.threaded.get)
            for offset, result in enumerate(results):
                yield first + offset, result
        return
    from distributed import as_completed

    threads = sum(client.nthreads().values()) or 1
    window = window or 2 * threads
    pending = iter(enumerate(tasks))
    index_of = {}

    def submit(count):
        futures = []
        for index, task in (item for _, item in zip(range(count), pending)):
            future = client.compute(task)
            index_of[future.key] = index
            futures.append(future)
        return futures

    running = as_completed(submit(window), loop=client.loop)
    for future in running:
        result = future.result()
        index = index_of.pop(future.key)
        future.release()
        for new in submit(1):
            running.add(new)
        yield index, result
