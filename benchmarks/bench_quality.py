"""Benchmark: quality of 1e6 hexahedra (a 100^3 TFI semicylinder), structured and unstructured paths.

    python benchmarks/bench_quality.py [--dims 100 100 100] [--repeat 5] [--json FILE]

Times, median of --repeat runs: the seven per-cell metrics (``cell_metrics`` on the node array;
``cell_metrics_unstructured`` on points + VTK connectivity, which also finds the face neighbours),
the block-wise report (``chunked_report``) of the node array and of the mesh as a ``.cgns`` file,
and the full report with boundary deviation (``quality_report``). Targets: the report of 1e6
hexahedra in at most 3 s; the compiled kernels at most 0.1 s per 1e6 hexahedra in memory
(``cell_metrics``) and block by block (the chunked rows). Wall and process CPU time are
both given (CPU: user + system seconds of all the process's threads, from ``getrusage``): on a
shared machine the CPU time is the steadier figure, and CPU seconds / 2 what 2 quiet cores take
when the work divides evenly between them. The machine's load average is recorded with each run.

``cli``: ``meshgen evaluate`` of the mesh as a .vts, end to end (a subprocess, start to exit;
target at most 0.8 s on 2 cores); ``cli_vtu``: the same of a .vtu (no target). ``first_call``: the first ``cell_metrics`` in a fresh process, with numba's cache empty (the
compile a new installation pays once) and with it filled (what every later process pays).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from meshgen.formats import write_mesh  # noqa: E402
from meshgen.geometry.grid import cell_connectivity, flat_points  # noqa: E402
from meshgen.geometry.plugins import load_geometry  # noqa: E402
from meshgen.methods.tfi import tfi  # noqa: E402
from meshgen.quality import cell_metrics, cell_metrics_unstructured, quality_report  # noqa: E402
from meshgen.quality.chunked import chunked_report  # noqa: E402

TARGET_SECONDS = 3.0
KERNEL_TARGET_SECONDS_PER_MILLION = 0.1
REPORT = "quality_report + boundary deviation"
CHUNKED_ARRAY = "chunked_report of the node array"
CHUNKED_FILE = "chunked_report of the .cgns file"
# (path, what): the per-cell metrics alone, then the whole report (``meshgen evaluate`` of a file
# takes the unstructured one)
CASES = [
    ("structured", "cell_metrics"),
    ("unstructured", "cell_metrics_unstructured"),
    ("chunked", CHUNKED_ARRAY),
    ("chunked", CHUNKED_FILE),
    ("structured", REPORT),
    ("unstructured", REPORT),
]


def process_cpu_seconds() -> float:
    """User + system CPU seconds of this process, all its threads (numba's included)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def timed(function, repeat):
    walls, cpus = [], []
    for _ in range(repeat):
        wall, cpu = time.perf_counter(), process_cpu_seconds()
        function()
        walls.append(time.perf_counter() - wall)
        cpus.append(process_cpu_seconds() - cpu)
    return walls, cpus


def measure(dims=(100, 100, 100), repeat: int = 5, cases=None) -> dict:
    """Time the quality paths on the TFI semicylinder of ``dims`` cells, each the median of
    ``repeat`` runs after one warm-up. ``cases``: a subset of the ``(path, what)`` pairs of
    ``CASES`` (default all). Returns {"dims", "cells", "repeat", "results": [row per case]}."""
    geometry = load_geometry("semicylinder")
    X = tfi(geometry, dims)
    points, cells = flat_points(X), cell_connectivity(X.shape[:-1])
    n_cells = len(cells)
    functions = {
        ("structured", "cell_metrics"): lambda: cell_metrics(X),
        ("unstructured", "cell_metrics_unstructured"): lambda: cell_metrics_unstructured(points, cells),
        ("structured", REPORT): lambda: quality_report(X, geometry),
        ("unstructured", REPORT): lambda: quality_report((points, cells), geometry),
    }
    folder = tempfile.TemporaryDirectory()
    cgns = Path(folder.name) / "mesh.cgns"
    write_mesh(cgns, X)
    functions[("chunked", CHUNKED_ARRAY)] = lambda: chunked_report(X)
    functions[("chunked", CHUNKED_FILE)] = lambda: chunked_report(str(cgns))
    results = []
    for path, what in cases or CASES:
        function = functions[(path, what)]
        target = TARGET_SECONDS if "report" in what and path != "chunked" else KERNEL_TARGET_SECONDS_PER_MILLION * n_cells / 1e6
        function()  # warm up (imports, page faults)
        walls, cpus = timed(function, repeat)
        median = statistics.median(walls)
        results.append(
            {
                "path": path,
                "what": what,
                "cells": n_cells,
                "median_s": median,
                "min_s": min(walls),
                "max_s": max(walls),
                "median_cpu_s": statistics.median(cpus),
                "runs_s": walls,
                "target_s": target,
                "target_met": median <= target,
            }
        )
    folder.cleanup()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {"dims": list(dims), "cells": n_cells, "repeat": repeat, "load_average": load, "results": results}


_FIRST_CALL = """
import time
start = time.perf_counter()
import numpy as np
from meshgen.quality.structured import structured_metrics
axes = [np.linspace(0.0, 1.0, 11)] * 3
structured_metrics(np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1), kernels="compiled")
print(time.perf_counter() - start)
"""


def first_call() -> dict:
    """Seconds of a fresh process's import and first ``cell_metrics`` (10^3 hexahedra): with an
    empty numba cache (compiling) and then with the cache that run filled (loading)."""
    environment = dict(os.environ)
    environment["PYTHONPATH"] = os.pathsep.join(
        filter(None, [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH")])
    )
    with tempfile.TemporaryDirectory() as cache:
        environment["NUMBA_CACHE_DIR"] = cache
        figures = {}
        for label in ("compile_seconds", "cached_seconds"):
            done = subprocess.run(
                [sys.executable, "-c", _FIRST_CALL], env=environment, capture_output=True, text=True, check=True
            )
            figures[label] = float(done.stdout.strip().splitlines()[-1])
    return figures


CLI_TARGET_SECONDS = 0.8


def python_loop_seconds(repeat: int = 3) -> float:
    """Best of ``repeat`` timings of a plain Python loop (6e6 multiply-adds): how fast this
    machine runs serial Python at the moment, beside a row that is mostly that (a two-core machine
    shared with others runs the same loop 1.5x slower in one hour than in another)."""
    best = float("inf")
    for _ in range(repeat):
        start, total = time.perf_counter(), 0
        for i in range(6_000_000):
            total += i * i
        best = min(best, time.perf_counter() - start)
    return best


def evaluate_cli(dims=(100, 100, 100), repeat: int = 5, suffix: str = ".vts") -> dict:
    """``meshgen evaluate`` of the TFI semicylinder's .vts (or ``suffix``: ``.vtu``, ``meshgen
    mesh``'s default; ``meshgen mesh --method tfi``), end to end: a subprocess from its start to
    its exit, as a user runs it; one warm-up run (numba's cache and the page cache warm), then the
    median of ``repeat``, wall and CPU (user + system of the process, all its threads) seconds.
    meshgen's bytecode is compiled first, as an installed meshgen has it (``bytecode.py``)."""
    from bytecode import compile_bytecode

    bytecode = compile_bytecode()
    loop = python_loop_seconds()
    root = str(Path(__file__).resolve().parents[1])
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    with tempfile.TemporaryDirectory() as folder:
        mesh = str(Path(folder) / f"semi{suffix}")
        command = [sys.executable, "-m", "meshgen"]
        made = [*command, "mesh", "--method", "tfi", "--dims", *map(str, dims), "-o", mesh, "-q"]
        subprocess.run(made, env=environment, check=True, capture_output=True)
        walls, cpus = [], []
        for run in range(repeat + 1):
            before, start = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
            subprocess.run([*command, "evaluate", mesh], env=environment, check=True, stdout=subprocess.DEVNULL)
            wall, after = time.perf_counter() - start, resource.getrusage(resource.RUSAGE_CHILDREN)
            if run:  # the first run warms up
                walls.append(wall)
                cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return {
        "cells": int(np.prod(dims)),
        "seconds": statistics.median(walls),
        "min_seconds": min(walls),
        "max_seconds": max(walls),
        "cpu_seconds": statistics.median(cpus),
        "runs_seconds": walls,
        "format": suffix,
        "target_seconds": CLI_TARGET_SECONDS if suffix == ".vts" else None,
        "python_loop_seconds": loop,
        **bytecode,
    }


def print_table(data: dict) -> None:
    n_cells = data["cells"]
    print(
        f"quality benchmark: {n_cells} hexahedra ({' x '.join(map(str, data['dims']))} semicylinder TFI), "
        f"median of {data['repeat']} runs, target {TARGET_SECONDS:g} s, load average {data.get('load_average') or 0:.1f}"
    )
    header = f"{'path':<13} {'what':<38} {'median s':>9} {'min s':>7} {'max s':>7} {'cpu s':>7} {'Mcells/s':>9}  target"
    print(header)
    print("-" * len(header))
    for r in data["results"]:
        print(
            f"{r['path']:<13} {r['what']:<38} {r['median_s']:9.3f} {r['min_s']:7.3f} {r['max_s']:7.3f} "
            f"{r['median_cpu_s']:7.3f} {n_cells / r['median_s'] / 1e6:9.2f}  {'met' if r['target_met'] else 'NOT met'}"
            f" (<= {r['target_s']:g} s)"
        )
    for cli in (data[key] for key in ("cli", "cli_vtu") if key in data):
        target = f", target <= {cli['target_seconds']:g} s" if cli.get("target_seconds") else ""
        print(
            f"meshgen evaluate of the {cli.get('format', '.vts')}, end to end: median {cli['seconds']:.3f} s "
            f"(min {cli['min_seconds']:.3f}, max {cli['max_seconds']:.3f}, cpu {cli['cpu_seconds']:.3f}) of "
            f"{len(cli['runs_seconds'])} runs{target}; bytecode {cli.get('bytecode', 'as found')}; "
            f"a Python loop of 6e6 multiply-adds just before: {cli.get('python_loop_seconds', float('nan')):.2f} s"
        )
    if "first_call" in data:
        first = data["first_call"]
        print(
            f"first cell_metrics in a fresh process (import included): {first['compile_seconds']:.1f} s with numba's cache "
            f"empty (compiling), {first['cached_seconds']:.2f} s with it filled"
        )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dims", type=int, nargs=3, default=[100, 100, 100])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", dest="json_path", help="write the results as JSON")
    args = parser.parse_args(argv)

    data = measure(args.dims, args.repeat)
    data["first_call"] = first_call()
    data["cli"] = evaluate_cli(args.dims, args.repeat)
    data["cli_vtu"] = evaluate_cli(args.dims, args.repeat, ".vtu")
    print_table(data)
    if args.json_path:
        data = {
            "benchmark": "quality",
            **data,
            "machine": {
                "cpus": os.cpu_count(),
                "processor": platform.processor(),
                "python": platform.python_version(),
                "numpy": np.__version__,
            },
        }
        Path(args.json_path).write_text(json.dumps(data, indent=2) + "\n")
        print(f"wrote {args.json_path}")


if __name__ == "__main__":
    main()
