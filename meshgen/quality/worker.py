"""The quality report of a large in-memory mesh computed in a forked process that loads numba while
the parent makes the mesh (design notes §21, "The quality in a forked process").

Importing numba and loading the compiled kernels costs a process about a second of Python that
holds the GIL; in the same process it can only run after the mesh (the forward pass's many short
NumPy calls on worker threads stall behind a thread running Python). A process forked before the
mesh is made loads them on the other core meanwhile, then computes the report of the nodes the
parent hands it:

- the parent allocates, before forking, anonymous shared memory for the nodes ``(node_shape, dim)``
  float64 and the seven per-cell metrics ``(7, cells)`` float64;
- the child loads the kernels (``start_numba``, then ``load_compiled_kernels`` unless the nodes
  are there already) and waits on a pipe;
- ``submit(X)`` copies the nodes in and wakes the child, which computes ``report_in_parallel``
  (the same functions on the same values: the report and the metric arrays are those of the
  parent's own path to the bit), copies the metrics into the shared memory, says so, then sends
  the report;
- ``metrics()`` and ``report()`` wait for those, never for ever: the wait ends, the child is
  killed and the caller computes the report in its own process, as soon as the child is dead or
  stopped (state ``T`` or ``t`` in ``/proc``: SIGSTOP, a debugger), or once ``worker_timeout``
  seconds have passed since ``submit`` (a child that is alive but makes no progress: swapped out,
  stuck). The timeout is ``WAIT_BASE_SECONDS`` (loading the kernels into a cold numba cache took
  184 s on a loaded two-core machine) plus ``WAIT_SECONDS_PER_CELL`` per cell (about eight times
  the measured 2.4 microseconds a cell of the report takes there).

The child ignores Ctrl-C and the termination signals' handlers (the parent handles them and kills
the child), never runs the parent's cleanup (``os._exit``), and ends when its pipe closes (the
parent gone). Whatever goes wrong in the child (it died, a kernel raised), ``metrics()`` returns
None and the caller computes the report in its own process: the worker only changes where the same
work runs.

``meshgen evaluate`` of a large file (``EvaluationWorker``) forks one the same way as soon as the
file's extent is read: the child loads the kernels while the parent inflates the file, loads the
geometry and, once the nodes are submitted, measures the boundary deviation; the child sends back
only what the report needs of the metrics (their summaries and the solver figures:
``report_parts``), never the metric arrays, and the parent assembles the report
(``assemble_report``) as the in-process path does.

``meshgen evaluate`` forks that child earlier still, first thing when the process starts
(``meshgen.run.early.fork_early_worker``, before the parent imports NumPy, the command or the
file's first byte): the child imports NumPy and loads numba while the parent imports what reads
files and loads geometries and reads the file. The nodes' shape is not known then, so their memory
is a memory file (``memfd_create``) that the parent sizes and both processes map once the file's
extent is read; the first ``EvaluationWorker`` of the command adopts that child, and a command that
never makes one ends it (``release_early_worker``). Only where a second CPU runs the child
meanwhile.

The child allocates without transparent huge pages (NumPy asks the kernel for them on large arrays):
its arrays are touched once, and on a kernel that compacts memory to make a huge page on the first
touch (``defrag`` set to ``madvise``), those faults cost a report's first call twice its time.

Used only where it pays and is safe: on Linux (fork), where numba is not loaded yet in this
process (forking a process whose numba threads run is unsafe, and a loaded numba costs nothing
more), and for meshes that take the compiled kernels (``NUMPY_CELLS`` cells and more).
"""

from __future__ import annotations

import contextlib
import gc
import mmap
import os
import signal
import sys
import time
import types
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from meshgen.quality.faces_openfoam import non_orthogonality
from meshgen.quality.kernels import METRICS
from meshgen.quality.report import assess_in_parallel, metric_summaries, report_in_parallel
from meshgen.quality.smoothness import smoothness_figures
from meshgen.quality.structured import load_compiled_kernels as load_first_kernel
from meshgen.quality.structured import structured_metrics, use_compiled
from meshgen.run.early import end, fork, take_early_worker
from meshgen.run.signals import TERMINATING_SIGNALS

__all__ = [
    "WAIT_BASE_SECONDS",
    "WAIT_SECONDS_PER_CELL",
    "EvaluationWorker",
    "QualityWorker",
    "is_stopped",
    "load_compiled_kernels",
    "quality_worker",
    "report_parts",
    "serve_early",
    "start_numba",
    "worker_fits",
    "worker_timeout",
]


PARENT_CHECK_SECONDS = 0.5  # how often a waiting child checks that its parent lives (and the parent the child)
WAIT_BASE_SECONDS = 600.0  # the parent's longest wait for a child, whatever the mesh's size (module text)
WAIT_SECONDS_PER_CELL = 2e-5  # and for each cell of the mesh


def worker_timeout(cells: int) -> float:
    """Seconds the parent waits, from ``submit``, for a worker's results on a mesh of ``cells`` cells."""
    return WAIT_BASE_SECONDS + WAIT_SECONDS_PER_CELL * int(cells)


def is_stopped(pid: int) -> bool:
    """Whether process ``pid`` is stopped (SIGSTOP, a debugger's stop: ``T`` or ``t`` in
    ``/proc/<pid>/stat``); False where that cannot be read."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:
            return handle.read().rsplit(b")", 1)[1].split()[0] in (b"T", b"t")
    except (OSError, IndexError):
        return False


def worker_fits(node_shape) -> bool:
    """Whether a mesh of ``node_shape`` nodes (its dimension's tuple, without the coordinate axis)
    gets its report from a forked worker in this process: Linux, numba not loaded here yet, and
    enough cells for the compiled kernels."""
    cells = int(np.prod([int(n) - 1 for n in node_shape]))
    return sys.platform.startswith("linux") and "numba" not in sys.modules and use_compiled(cells)


def load_compiled_kernels(dim: int) -> None:
    """Import numba and load every compiled kernel the in-memory report of a ``dim``-D node array
    calls (per-cell metrics, smoothness, face non-orthogonality), by running them on a small grid
    of the same array types."""
    rng = np.random.default_rng(0)
    axes = np.meshgrid(*[np.linspace(0.0, 1.0, 4)] * dim, indexing="ij")
    X = np.ascontiguousarray(np.stack(axes, axis=-1) + 0.01 * rng.standard_normal((4,) * dim + (dim,)))
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        structured_metrics(X, kernels="compiled")
        smoothness_figures(X, kernels="compiled")
        non_orthogonality(X, kernels="compiled")


def _shared(count: int) -> np.ndarray:
    """``count`` float64 zeros in anonymous memory that a forked child shares with this process."""
    buffer = mmap.mmap(-1, max(8, 8 * count))
    return np.frombuffer(buffer, dtype=np.float64, count=count)


def _mapped(memory: int, node_shape: tuple, size: bool = False) -> np.ndarray:
    """The node array ``(*node_shape, dim)`` float64 in memory file ``memory``, which both
    processes map; ``size``: first make the file that long (the parent)."""
    count = int(np.prod(node_shape)) * len(node_shape)
    if size:
        os.ftruncate(memory, max(8, 8 * count))
    buffer = mmap.mmap(memory, max(8, 8 * count))
    return np.frombuffer(buffer, dtype=np.float64, count=count).reshape(*node_shape, len(node_shape))


class _ForkedWorker:
    """A forked child that loads the kernels, then works on the node array handed to it
    (``submit``): the shared memory, the pipe and the bounded waits of both workers."""

    def _start(self, node_shape, serve, metric_rows: int, *arguments) -> None:
        node_shape = tuple(int(n) for n in node_shape)
        cells = int(np.prod([n - 1 for n in node_shape]))
        # a node array has one coordinate per index axis (``check_node_array``)
        self._nodes = _shared(int(np.prod(node_shape)) * len(node_shape)).reshape(*node_shape, len(node_shape))
        self._metrics = _shared(metric_rows * cells).reshape(metric_rows, cells)
        self._process, self._connection = fork(_serve, self._nodes, serve, self._metrics, *arguments)
        self._begin(cells)

    def _begin(self, cells: int) -> None:
        self._failed = False
        self._timeout = worker_timeout(cells)
        self._deadline = float("inf")

    def submit(self, X: np.ndarray) -> bool:
        """Hand node array ``X`` to the child; False (and every later call fails) when its shape is
        not the one the worker was made for or the pipe to the child is broken."""
        if X.shape != self._nodes.shape:
            self._failed = True
            return False
        np.copyto(self._nodes, X)
        self._deadline = time.monotonic() + self._timeout
        return self._send("go")

    def close(self, wait: bool = True) -> None:
        """End the child (at once if it still works) and release the pipe; ``wait``: until it is
        reaped (``meshgen.run.early.end``)."""
        end(self._process, self._connection, wait=wait)

    def _send(self, message) -> bool:
        try:
            self._connection.send(message)
            return True
        except (OSError, ValueError):
            self._failed = True
            return False

    def _receive(self, expected: str):
        if self._failed:
            return None
        try:
            while not self._connection.poll(PARENT_CHECK_SECONDS):
                if not self._process.is_alive() or is_stopped(self._process.pid) or time.monotonic() > self._deadline:
                    raise TimeoutError("the worker is gone, stopped or late")
            kind, value = self._connection.recv()
        except (EOFError, OSError, ValueError):  # TimeoutError is an OSError
            kind, value = "failed", None
        if kind != expected:
            self._failed = True
            with contextlib.suppress(OSError, ValueError, AttributeError):
                self._process.kill()  # a stopped or stuck child is not waited for again
            return None
        return True if value is None else value


class QualityWorker(_ForkedWorker):
    """A forked process computing the quality report of one node array (see the module text)."""

    def __init__(self, node_shape, geometry=None):
        self._start(node_shape, _report_and_metrics, len(METRICS), geometry)

    def metrics(self) -> dict | None:
        """The seven per-cell arrays (views of the shared memory), once the child has them; None
        when it failed."""
        if self._receive("metrics") is None:
            return None
        return {name: self._metrics[index] for index, name in enumerate(METRICS)}

    def report(self) -> dict | None:
        """The report (``quality_report``'s), once the child sent it; None when it failed."""
        return self._receive("report")


class EvaluationWorker(_ForkedWorker):
    """A forked process computing the parts of a node array's report that need numba (the
    per-cell metrics' summaries and the solver figures: ``report_parts``) for ``meshgen evaluate``,
    which reads the file and measures the boundary deviation meanwhile. The metric arrays stay in
    the child (the report needs only their summaries)."""

    def __init__(self, node_shape):
        early = take_early_worker()
        if early is not None:
            try:
                self._adopt(early, node_shape)
                return
            except OSError:  # the memory file could not take the nodes: a child of our own
                end(*early)
        self._start(node_shape, _parts, 0)

    def _adopt(self, early, node_shape) -> None:
        """Take over the child ``fork_early_worker`` forked: size its memory file for the nodes,
        map it, and tell the child their shape (it maps the same file)."""
        process, connection, memory = early
        node_shape = tuple(int(n) for n in node_shape)
        self._nodes = _mapped(memory, node_shape, size=True)
        self._process, self._connection = process, connection
        self._begin(int(np.prod([n - 1 for n in node_shape])))
        os.close(memory)
        self._send(("shape", node_shape))

    def parts(self) -> dict | None:
        """``report_parts`` of the submitted nodes, once the child sent them; None when it failed."""
        return self._receive("parts")


def report_parts(X: np.ndarray) -> dict:
    """What the report of node array ``X`` needs from the per-cell metrics and the solver figures,
    as ``assess_in_parallel`` and ``metric_summaries`` compute them: {"cells", "all_degenerate"}
    and, unless every cell is degenerate, "summaries", "counts" (``assemble_report``'s), "dim",
    "nonfinite_nodes" and "solver_figures"."""
    with ThreadPoolExecutor(max_workers=3, thread_name_prefix="meshgen-quality") as pool:
        metrics, degenerate, info = assess_in_parallel(X, None, pool)
        parts = {"cells": int(len(degenerate)), "all_degenerate": bool(degenerate.all())}
        if parts["all_degenerate"]:
            return parts
        summaries, counts = metric_summaries(metrics, degenerate, overwrite=True)  # the arrays end here
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            figures = info["solver_figures"]()
    return {
        **parts,
        "summaries": summaries,
        "counts": counts,
        "dim": info["dim"],
        "nonfinite_nodes": info["nonfinite_nodes"],
        "solver_figures": figures,
    }


@contextlib.contextmanager
def quality_worker(node_shape, geometry=None):
    """A ``QualityWorker`` for a mesh of ``node_shape`` nodes when ``worker_fits`` (else None, also
    when the process cannot be forked), closed on leaving the block."""
    worker = None
    if worker_fits(node_shape):
        with contextlib.suppress(OSError):
            worker = QualityWorker(node_shape, geometry)
    try:
        yield worker
    finally:
        if worker is not None:
            worker.close()


def _report_and_metrics(connection, nodes: np.ndarray, metrics: np.ndarray, geometry) -> None:
    """``QualityWorker``'s work: the metric arrays into the shared memory, ("metrics", None) once
    they are there, then ("report", report)."""
    with ThreadPoolExecutor(max_workers=4, thread_name_prefix="meshgen-quality") as pool:
        computed, report = report_in_parallel(nodes, geometry, pool)
        for index, name in enumerate(METRICS):
            metrics[index] = computed[name]
        connection.send(("metrics", None))
        connection.send(("report", report.result()))


def _parts(connection, nodes: np.ndarray, metrics: np.ndarray) -> None:
    """``EvaluationWorker``'s work: ("parts", ``report_parts``)."""
    connection.send(("parts", report_parts(nodes)))


def start_numba() -> None:
    """numba's import, its type registries and the first kernel (``structured.load_compiled_kernels``):
    most of the kernels' load, the part that nothing in the child can overlap. The others take
    5 to 10 ms each; a child whose nodes are there already loads them while it computes (the
    per-cell metrics' C code runs while the other parts' threads load theirs)."""
    _numba_without_extras()
    load_first_kernel()


def _numba_without_extras() -> None:
    """Leave out, in this child only, the parts of numba's start that meshgen's kernels never use
    (the child runs nothing but these kernels from numba's cache, then exits; the parent's numba,
    if it ever loads one, is untouched; before numba is imported, ``worker_fits``, and only then):

    - the CFFI support its type registries set up (``import cffi`` and cffi's C parser, about 30 ms);
    - the scan of every installed distribution for numba extensions (``entry_points()``, 20 to
      30 ms here);
    - PyYAML (about 20 ms), which numba imports to read a ``.numba_config.yaml`` in the working
      folder: left out only where there is none;
    - its lowering and typing registries (every NumPy function's implementation, about 60 ms and
      50 modules, and ``meshgen.run.jit``'s ``numba.np.arraymath`` before them, about 35 ms), which
      a kernel loaded from the cache never calls: ``_load_from_cache_alone``;
    - the overloads of built-in functions for jitclass instances that ``import numba`` registers
      (``numba.experimental.jitclass.overloads``, about 30 ms): meshgen's kernels have none.
    """
    if "numba" in sys.modules:
        return
    sys.modules.setdefault("cffi", None)  # None: ``import cffi`` raises ImportError, numba types no CFFI
    if not os.path.isfile(".numba_config.yaml"):
        sys.modules.setdefault("yaml", None)  # numba's config then reads the NUMBA_ variables alone
    overloads = "numba.experimental.jitclass.overloads"  # imported for its registrations alone
    sys.modules.setdefault(overloads, types.ModuleType(overloads))
    import numba.core.entrypoints as entrypoints

    entrypoints._already_initialized = True  # numba's own flag for "extensions loaded"
    _load_from_cache_alone()


def _load_from_cache_alone() -> None:
    """Load cached kernels without numba's registries: numba's ``Cache.load_overload`` refreshes
    the target context (imports and installs every registry, "to ensure it is initialized") before
    it reads the cache; what a cached kernel needs of that is the runtime (``rtsys.initialize``).
    A kernel not in the cache compiles as ever: numba's compiler refreshes both contexts itself.
    Where numba's internals differ from these, nothing changes."""
    from numba.core import caching
    from numba.core.runtime import nrt

    cache = getattr(caching, "Cache", None)
    needed = ("load_overload", "_load_overload", "_guard_against_spurious_io_errors")
    if cache is None or not all(hasattr(cache, name) for name in needed) or not hasattr(nrt, "rtsys"):
        return

    def load_overload(self, sig, target_context):
        nrt.rtsys.initialize(target_context)
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)

    cache.load_overload = load_overload


def _without_huge_pages() -> None:
    """Let NumPy's large arrays in this process take ordinary pages (the module text)."""
    core = getattr(np, "_core", None) or getattr(np, "core", None)
    setting = getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)
    if setting is not None:
        setting(False)


def serve_early(connection, parent_end, parent: int, memory: int) -> None:
    """The child ``meshgen.run.early.fork_early_worker`` forks (its ``EARLY_CHILD``): ``_serve``
    of the ``EvaluationWorker``'s parts (no metric arrays come back), the nodes to come in the
    memory file ``memory``."""
    _serve(connection, parent_end, parent, memory, _parts, None)


def _wait(connection, parent: int) -> None:
    """Wait for the parent's next message; EOFError when the parent is gone."""
    while not connection.poll(PARENT_CHECK_SECONDS):
        if os.getppid() != parent:
            raise EOFError("the parent is gone")


def _serve(connection, parent_end, parent: int, nodes, work, *arguments) -> None:
    """The child: load the kernels, wait for the nodes, then ``work(connection, nodes,
    *arguments)`` sends what it computed; ("error", text) if anything fails. ``nodes``: the node
    array in shared memory, or (an early child) the memory file they will lie in, whose shape the
    parent sends first (("shape", node_shape)). It ends when the parent does: its copy of the
    parent's end of the pipe is closed first, so the pipe ends with the parent, and the wait also
    checks that ``parent`` is still its parent."""
    parent_end.close()
    gc.disable()  # a child of imports, numba's start and one report: no garbage worth a collection
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for signum in TERMINATING_SIGNALS:
        signal.signal(signum, signal.SIG_DFL)
    status = 0
    try:
        _without_huge_pages()
        start_numba()
        if not isinstance(nodes, np.ndarray):
            _wait(connection, parent)
            kind, node_shape = connection.recv()
            if kind != "shape":
                raise EOFError("no nodes to come")
            nodes = _mapped(nodes, tuple(node_shape))
        if not connection.poll(0):  # no nodes yet: the other kernels load meanwhile, else while the first part runs
            load_compiled_kernels(nodes.shape[-1])
        _wait(connection, parent)
        if connection.recv() == "go":
            work(connection, nodes, *arguments)
    except EOFError:  # the parent is gone
        status = 1
    except BaseException as error:  # noqa: BLE001 - reported to the parent, which computes the report itself
        status = 1
        try:
            connection.send(("error", f"{type(error).__name__}: {error}"))
        except (OSError, ValueError):
            pass
    finally:
        connection.close()
        sys.stdout.flush()
        os._exit(status)  # never the parent's cleanup (atexit, publications in flight)
