"""Benchmark: quality of 1e6 hexahedra (a 100^3 TFI semicylinder), structured and unstructured paths.

    python benchmarks/bench_quality.py [--dims 100 100 100] [--repeat 5] [--json FILE]

Times, median of --repeat runs: the seven per-cell metrics (``cell_metrics`` on the node array;
``cell_metrics_unstructured`` on points + VTK connectivity, which also finds the face neighbours),
and the full report with boundary deviation (``quality_report``). Target: 1e6 hexahedra
evaluated in at most 3 s on the 2-core machines. Wall and process CPU time are both given: on a
shared machine the CPU time is the steadier figure.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from meshgen.geometry import load_geometry  # noqa: E402
from meshgen.grid import cell_connectivity, flat_points  # noqa: E402
from meshgen.quality import cell_metrics, cell_metrics_unstructured, quality_report  # noqa: E402
from meshgen.tfi import tfi  # noqa: E402

TARGET_SECONDS = 3.0
REPORT = "quality_report + boundary deviation"
# (path, what): the per-cell metrics alone, then the whole report (``meshgen evaluate`` of a file
# takes the unstructured one)
CASES = [
    ("structured", "cell_metrics"),
    ("unstructured", "cell_metrics_unstructured"),
    ("structured", REPORT),
    ("unstructured", REPORT),
]


def timed(function, repeat):
    walls, cpus = [], []
    for _ in range(repeat):
        wall, cpu = time.perf_counter(), time.process_time()
        function()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
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
    results = []
    for path, what in cases or CASES:
        function = functions[(path, what)]
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
                "target_s": TARGET_SECONDS,
                "target_met": median <= TARGET_SECONDS,
            }
        )
    return {"dims": list(dims), "cells": n_cells, "repeat": repeat, "results": results}


def print_table(data: dict) -> None:
    n_cells = data["cells"]
    print(
        f"quality benchmark: {n_cells} hexahedra ({' x '.join(map(str, data['dims']))} semicylinder TFI), "
        f"median of {data['repeat']} runs, target {TARGET_SECONDS:g} s"
    )
    header = f"{'path':<13} {'what':<38} {'median s':>9} {'min s':>7} {'max s':>7} {'cpu s':>7} {'Mcells/s':>9}  target"
    print(header)
    print("-" * len(header))
    for r in data["results"]:
        print(
            f"{r['path']:<13} {r['what']:<38} {r['median_s']:9.3f} {r['min_s']:7.3f} {r['max_s']:7.3f} "
            f"{r['median_cpu_s']:7.3f} {n_cells / r['median_s'] / 1e6:9.2f}  {'met' if r['target_met'] else 'NOT met'}"
        )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dims", type=int, nargs=3, default=[100, 100, 100])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", dest="json_path", help="write the results as JSON")
    args = parser.parse_args(argv)

    data = measure(args.dims, args.repeat)
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
