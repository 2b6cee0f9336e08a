"""The quality report of a large mesh computed by a forked worker (``meshgen.quality.worker``) is
the in-process report, to the bit; a worker that fails or dies leaves the command's result
unchanged. Each run is a new interpreter (``meshgen mesh`` in a subprocess), where numba is not
loaded yet: the only case the worker is used in."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import meshio
import numpy as np
import pytest

from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi
from meshgen.quality import quality_report
from meshgen.quality.kernels import METRICS
from meshgen.quality.structured import NUMPY_CELLS, structured_metrics

DIMS = (80, 80, 80)  # 512,000 cells: the compiled kernels' size (NUMPY_CELLS), so the worker's

# Runs a meshgen command in a new interpreter after ``{patch}``; says on stderr the worker's pid and
# which process computed WHAT ("WHAT from the worker" when the worker's METHOD returned them).
DRIVER_TEMPLATE = """
import sys
import meshgen.quality.worker as worker
original_found = worker.CLASS.METHOD
def found(self):
    value = original_found(self)
    print("WHAT from the worker" if value is not None else "WHAT not from the worker", file=sys.stderr)
    return value
worker.CLASS.METHOD = found
original_init = worker.CLASS.__init__
def init(self, *arguments):
    original_init(self, *arguments)
    print(f"worker {{self._process.pid}}", file=sys.stderr, flush=True)
worker.CLASS.__init__ = init
{patch}
from meshgen.cli import main
sys.argv[0] = "meshgen"
main()
"""


def worker_driver(worker_class: str, method: str, what: str) -> str:
    return DRIVER_TEMPLATE.replace("CLASS", worker_class).replace("METHOD", method).replace("WHAT", what)


DRIVER = worker_driver("QualityWorker", "metrics", "metrics")  # meshgen mesh's per-cell metrics

FAILURES = {
    "raises": "def failing():\n    raise MemoryError('no memory in the worker')\nworker.start_numba = failing",
    "dies": "import os\ndef dying():\n    os._exit(9)\nworker.start_numba = dying",
    # SIGSTOP (a debugger, a job-control stop): seen in /proc at once, the worker killed
    "stopped": "import os, signal\ndef stopping():\n    os.kill(os.getpid(), signal.SIGSTOP)\nworker.start_numba = stopping",
    # alive but making no progress: the wait ends at worker_timeout (shortened here to 1 s)
    "stuck": (
        "import time\ndef stuck():\n    time.sleep(3600)\nworker.start_numba = stuck\n"
        "worker.WAIT_BASE_SECONDS, worker.WAIT_SECONDS_PER_CELL = 1.0, 0.0"
    ),
}


def mesh_command(folder, patch: str = "") -> list[str]:
    command = [sys.executable, "-c", DRIVER.format(patch=patch), "mesh", "-g", "semicylinder", "--method", "tfi"]
    return command + ["--dims", *map(str, DIMS), "-o", str(folder / "mesh.vtu"), "-q"]


def run_mesh(folder, patch: str = "") -> subprocess.CompletedProcess:
    return subprocess.run(mesh_command(folder, patch), capture_output=True, text=True, timeout=300)


def alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (an orphan's exit may wait to be reaped)."""
    try:
        with open(f"/proc/{pid}/stat") as handle:
            return handle.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.fixture(scope="module")
def expected():
    """The mesh's per-cell metrics and report, computed in this process."""
    geometry = load_geometry("semicylinder")
    X = tfi(geometry, DIMS)
    return structured_metrics(X)[0], quality_report(X, geometry)


def check_result(folder, expected) -> None:
    metrics, report = expected
    mesh = meshio.read(folder / "mesh.vtu")
    for name in METRICS:
        assert np.array_equal(mesh.cell_data[name][0], metrics[name], equal_nan=True), name
    sidecar = json.loads((folder / "mesh.vtu.quality.json").read_text())
    report = json.loads(json.dumps(report))  # as the sidecar stores it
    assert {key: sidecar[key] for key in report} == report


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked: Linux only")
def test_the_worker_is_used_only_where_it_pays():
    """In a new interpreter: a large mesh gets a worker until numba is loaded; a small one never."""
    assert int(np.prod(DIMS)) >= NUMPY_CELLS
    shape = tuple(n + 1 for n in DIMS)
    script = (
        "from meshgen.quality.worker import worker_fits\n"
        f"print(worker_fits({shape}), worker_fits((11, 11, 11)))\n"
        "import numba\n"
        f"print(worker_fits({shape}))\n"
    )
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["True", "False", "False"]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked: Linux only")
def test_the_worker_computes_the_in_process_report(tmp_path, expected):
    result = run_mesh(tmp_path)
    assert result.returncode == 0, result.stderr
    assert "metrics from the worker" in result.stderr
    check_result(tmp_path, expected)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked: Linux only")
@pytest.mark.parametrize("failure", sorted(FAILURES))
def test_a_failing_worker_leaves_the_result_unchanged(tmp_path, expected, failure):
    """A worker that raises, dies, is stopped or is stuck: the command computes the report itself
    (no hang: ``run_mesh`` times out), and no worker is left behind."""
    result = run_mesh(tmp_path, FAILURES[failure])
    assert result.returncode == 0, result.stderr
    worker = int(result.stderr.split("worker ", 1)[1].split()[0])  # a worker was forked, and failed
    assert "metrics from the worker" not in result.stderr and "Traceback" not in result.stderr
    check_result(tmp_path, expected)
    deadline = time.monotonic() + 10.0  # killed by the command; its exit may wait a moment to be reaped
    while alive(worker) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(worker)


def test_the_wait_for_a_worker_is_bounded_by_the_mesh_size():
    from meshgen.quality.worker import WAIT_BASE_SECONDS, WAIT_SECONDS_PER_CELL, is_stopped, worker_timeout

    assert worker_timeout(0) == WAIT_BASE_SECONDS and worker_timeout(10**6) == WAIT_BASE_SECONDS + 10**6 * WAIT_SECONDS_PER_CELL
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        assert not is_stopped(child.pid)
        os.kill(child.pid, signal.SIGSTOP)
        deadline = time.monotonic() + 10.0
        while not is_stopped(child.pid) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert is_stopped(child.pid)
    finally:
        child.kill()
        child.wait()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked: Linux only")
def test_a_killed_command_leaves_no_worker_behind(tmp_path):
    """SIGKILL leaves the parent no cleanup: the worker must notice on its own and end."""
    process = subprocess.Popen(mesh_command(tmp_path), stderr=subprocess.PIPE, text=True)
    try:
        line = process.stderr.readline()  # the worker's pid, printed when it is forked
        assert line.startswith("worker "), line
        worker = int(line.split()[1])
        assert alive(worker)
    finally:
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
    # its kernels load first (a second or two; a minute or more where numba compiles them into an
    # empty cache, as on a fresh CI machine), then it sees the parent gone
    deadline = time.monotonic() + 300.0
    while alive(worker) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(worker)


# In a new interpreter: the kernels ``load_compiled_kernels`` loads are all the report of a large
# mesh calls, in the same types (else the worker would leave part of numba's load to the report).
NO_LATE_LOAD = """
import numpy as np
from meshgen.geometry.plugins import load_geometry
from meshgen.quality.worker import _shared, load_compiled_kernels
from meshgen.methods.tfi import tfi
from numba.core import dispatcher

load_compiled_kernels({dim})
late = []
original = dispatcher.Dispatcher._compile_for_args
def watched(self, *arguments, **keywords):
    late.append(self.py_func.__name__)
    return original(self, *arguments, **keywords)
dispatcher.Dispatcher._compile_for_args = watched
from concurrent.futures import ThreadPoolExecutor
from meshgen.quality.report import report_in_parallel
geometry = load_geometry("{name}")
X = tfi(geometry, {dims})
nodes = _shared(X.size).reshape(X.shape)  # as the worker holds them
np.copyto(nodes, X)
with ThreadPoolExecutor(max_workers=4) as pool:
    report_in_parallel(nodes, geometry, pool)[1].result()
print("late:", sorted(set(late)))
"""


@pytest.mark.parametrize(("name", "dims"), [("semicylinder", DIMS), ("semidisk", (720, 720))])
def test_the_warm_up_loads_every_kernel_the_report_calls(name, dims):
    assert int(np.prod(dims)) >= NUMPY_CELLS
    script = NO_LATE_LOAD.format(dim=len(dims), name=name, dims=dims)
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines()[-1] == "late: []"


EVALUATE_DRIVER = worker_driver("EvaluationWorker", "parts", "parts")  # meshgen evaluate's numba parts


def run_evaluate(path, patch: str = "") -> subprocess.CompletedProcess:
    command = [sys.executable, "-c", EVALUATE_DRIVER.format(patch=patch), "evaluate", str(path), "--json", "-"]
    return subprocess.run(command, capture_output=True, text=True, timeout=300)


def in_process_report(path) -> dict:
    """``meshgen evaluate --json``'s report of ``path`` computed in this process, no worker."""
    from unittest import mock

    from meshgen.quality import files, json_ready

    with mock.patch.object(files, "worker_fits", lambda node_shape: False):
        return json.loads(json.dumps(json_ready(files.evaluate_file(path)), allow_nan=False))


def vts_and_report(folder, name: str, dims, suffix: str = ".vts") -> tuple:
    """A .vts (or ``suffix``) file meshgen wrote of geometry ``name`` at ``dims`` cells, and its
    in-process report."""
    command = [sys.executable, "-m", "meshgen", "mesh", "-g", name, "--method", "tfi", "--dims", *map(str, dims)]
    path = folder / f"mesh{suffix}"
    made = subprocess.run([*command, "-o", str(path), "-q"], capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    return path, in_process_report(path)


@pytest.fixture(scope="module")
def large_vts(tmp_path_factory):
    """A .vts of ``DIMS`` cells (the compiled kernels' size) and its in-process report."""
    return vts_and_report(tmp_path_factory.mktemp("evaluate"), "semicylinder", DIMS)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked: Linux only")
@pytest.mark.parametrize("dim", [3, 2])
def test_the_evaluation_worker_gives_the_in_process_report(large_vts, tmp_path, dim):
    """``meshgen evaluate`` of a large .vts: numba's parts of the report in a forked worker, the
    boundary deviation in the command's process; the report is the in-process one to the bit
    (a 2D file's nodes drop the third coordinate: the worker's are (n1+1, n2+1, 2))."""
    path, expected = large_vts if dim == 3 else vts_and_report(tmp_path, "semidisk", (720, 720))
    assert expected["cells"] >= NUMPY_CELLS and expected["dim"] == dim
    result = run_evaluate(path)
    assert result.returncode == 0, result.stderr
    assert "parts from the worker" in result.stderr
    assert expected["boundary_deviation"]["max"] < 1e-12 and "solver_figures" in expected
    assert json.loads(result.stdout) == expected


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked: Linux only")
@pytest.mark.parametrize("failure", ["dies", "raises"])
def test_a_failing_evaluation_worker_leaves_the_report_unchanged(large_vts, failure):
    path, expected = large_vts
    result = run_evaluate(path, FAILURES[failure])
    assert result.returncode == 0, result.stderr
    worker = int(result.stderr.split("worker ", 1)[1].split()[0])
    assert "parts from the worker" not in result.stderr and "Traceback" not in result.stderr
    assert json.loads(result.stdout) == expected
    deadline = time.monotonic() + 10.0
    while alive(worker) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(worker)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked: Linux only")
def test_a_large_file_that_is_no_structured_grid_ends_its_worker_unused(tmp_path):
    """A large .vts meshgen did not write (no dims recorded): the worker forked while it was read
    is closed unused, and the unstructured path reports as without it."""
    from meshgen.formats import write_mesh

    axes = [np.linspace(0.0, 1.0, n + 1) for n in DIMS]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    X[..., 0] += 0.3 * X[..., 1] ** 2
    path = tmp_path / "foreign.vts"
    write_mesh(path, X)
    result = run_evaluate(path)
    assert result.returncode == 0, result.stderr
    assert "worker " in result.stderr and "parts" not in result.stderr
    report = json.loads(result.stdout)
    assert not report["structured"] and report == in_process_report(path)


# Says on stderr the pid of the child ``meshgen evaluate`` forked first ("early PID", "early None"
# when it forked none) and, at the command's exit, whether that child is still there.
EARLY = """
import atexit, os
import meshgen.run.early as early_start
original_early = early_start.fork_early_worker
def early():
    original_early()
    pid = early_start._early[0].pid if early_start._early else None
    print(f"early {pid}", file=sys.stderr, flush=True)
    def running():  # a process that exists and is no zombie (multiprocessing reaps the dead at exit)
        try:
            return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"
        except (OSError, TypeError):
            return False
    atexit.register(lambda: print(f"early child at exit: {running()}", file=sys.stderr))
early_start.fork_early_worker = early
"""


def early_pid(stderr: str) -> int | None:
    word = stderr.split("early ", 1)[1].split()[0]
    return None if word == "None" else int(word)


@pytest.mark.skipif(not sys.platform.startswith("linux") or len(os.sched_getaffinity(0)) < 2, reason="forked on Linux, two CPUs")
def test_meshgen_evaluate_measures_with_the_child_it_forked_first(large_vts):
    """The child forked when ``meshgen evaluate`` starts (before the file is opened) is the worker
    that computes the report's parts; the report is the in-process one; the child is gone when the
    command exits."""
    path, expected = large_vts
    result = run_evaluate(path, EARLY)
    assert result.returncode == 0, result.stderr
    pid = early_pid(result.stderr)
    assert pid is not None and f"worker {pid}" in result.stderr and "parts from the worker" in result.stderr
    assert json.loads(result.stdout) == expected
    assert "early child at exit: False" in result.stderr


# ``python -m meshgen ...`` with an audit hook that says, at the process's first fork, whether NumPy
# and click were imported by then.
FIRST_FORK = """
import runpy, sys
def hook(event, arguments):
    if event == "os.fork" and not hasattr(sys, "first_fork"):
        sys.first_fork = True
        print("first fork: numpy", "numpy" in sys.modules, "click", "click" in sys.modules, file=sys.stderr, flush=True)
sys.addaudithook(hook)
sys.argv = ["meshgen", *sys.argv[1:]]
runpy.run_module("meshgen", run_name="__main__", alter_sys=True)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux") or len(os.sched_getaffinity(0)) < 2, reason="forked on Linux, two CPUs")
def test_python_m_meshgen_forks_the_early_child_before_numpy_and_click(large_vts):
    """``python -m meshgen evaluate`` forks its child before it imports NumPy or click (the child
    imports them itself, while the parent does), and the report is the in-process one."""
    path, expected = large_vts
    command = [sys.executable, "-c", FIRST_FORK, "evaluate", str(path), "--json", "-"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert "first fork: numpy False click False" in result.stderr
    assert json.loads(result.stdout) == expected


# Says on stderr whether the cyclic garbage collector runs in the parent as the file's evaluation
# starts and in the child as it computes the report's parts.
COLLECTOR = """
import gc
import meshgen.quality.files as files
original_evaluate = files.evaluate_file
def evaluate_file(*arguments, **keywords):
    print(f"parent collects: {gc.isenabled()}", file=sys.stderr, flush=True)
    return original_evaluate(*arguments, **keywords)
files.evaluate_file = evaluate_file
original_parts = worker._parts
def parts(connection, nodes, metrics):
    print(f"child collects: {gc.isenabled()}", file=sys.stderr, flush=True)
    return original_parts(connection, nodes, metrics)
worker._parts = parts
"""


@pytest.mark.skipif(not sys.platform.startswith("linux") or len(os.sched_getaffinity(0)) < 2, reason="forked on Linux, two CPUs")
def test_the_collector_is_off_for_the_start_and_the_child_only(large_vts):
    """``meshgen evaluate`` starts with the cyclic garbage collector off (the imports make no
    garbage), turns it back on when the command's body begins, before any file is read; the child
    keeps it off; the report is the in-process one."""
    path, expected = large_vts
    result = run_evaluate(path, COLLECTOR)
    assert result.returncode == 0, result.stderr
    assert "parent collects: True" in result.stderr and "child collects: False" in result.stderr
    assert "parts from the worker" in result.stderr and json.loads(result.stdout) == expected


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked: Linux only")
def test_without_the_early_child_the_worker_is_forked_once_the_extent_is_read(large_vts):
    """Where ``meshgen evaluate`` forks no child first (one CPU, no memory files), the worker
    forked when the file's extent is read gives the same report."""
    path, expected = large_vts
    result = run_evaluate(path, "import meshgen.run.early\nmeshgen.run.early.fork_early_worker = lambda: None")
    assert result.returncode == 0, result.stderr
    assert "parts from the worker" in result.stderr
    assert json.loads(result.stdout) == expected


@pytest.mark.skipif(not sys.platform.startswith("linux") or len(os.sched_getaffinity(0)) < 2, reason="forked on Linux, two CPUs")
def test_a_small_file_ends_the_early_child_unused(tmp_path):
    """A file too small for the compiled kernels: the early child is ended unused (not left to
    load numba beside the command) and the report is the in-process one."""
    path, expected = vts_and_report(tmp_path, "semicylinder", (8, 8, 8))
    result = run_evaluate(path, EARLY)
    assert result.returncode == 0, result.stderr
    assert early_pid(result.stderr) is not None and "worker " not in result.stderr.replace("early child", "")
    assert json.loads(result.stdout) == expected
    assert "early child at exit: False" in result.stderr


def test_asking_evaluate_for_help_forks_nothing():
    command = [sys.executable, "-c", EVALUATE_DRIVER.format(patch=EARLY), "evaluate", "--help"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "Usage:" in result.stdout and "early" not in result.stderr


@pytest.mark.skipif(not sys.platform.startswith("linux") or len(os.sched_getaffinity(0)) < 2, reason="forked on Linux, two CPUs")
def test_a_large_vtu_is_measured_by_the_child_forked_first(tmp_path):
    """A .vtu (``meshgen mesh``'s default format) has no extent to read first: the early child
    loads numba while the whole file is read and takes the nodes after; the report is the
    in-process one."""
    path, expected = vts_and_report(tmp_path, "semicylinder", DIMS, ".vtu")
    assert expected["structured"] and expected["cells"] >= NUMPY_CELLS
    result = run_evaluate(path, EARLY)
    assert result.returncode == 0, result.stderr
    pid = early_pid(result.stderr)
    assert pid is not None and f"worker {pid}" in result.stderr and "parts from the worker" in result.stderr
    assert json.loads(result.stdout) == expected


def test_the_worker_module_leaves_the_file_readers_unimported():
    """``meshgen evaluate`` forks its worker once ``meshgen.quality.worker`` is imported: that import
    must not pull in ``meshgen.quality.files`` (every format's reader, the geometry plugins), which
    ``meshgen.quality`` imports only when one of its names is asked for."""
    code = (
        "import sys, meshgen.quality.worker\n"
        "print('meshgen.quality.files' in sys.modules)\n"
        "from meshgen.quality import evaluate_file\n"
        "print('meshgen.quality.files' in sys.modules, evaluate_file.__module__)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.split() == ["False", "True", "meshgen.quality.files"]
