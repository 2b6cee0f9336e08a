"""Elliptic (Winslow) solver on the semicylinder: multigrid cycles, time and result per grid size.

    python benchmarks/bench_elliptic.py [--quick] [--json FILE] [--jacobi]

Sizes 16^3, 30^3, 50^3, 64^3, 100^3 cells (--quick: up to 50^3), default tolerance (largest node
update per cycle 1e-6 of the characteristic length). Per size: finest-grid cycles, wall and CPU
seconds of the solve (TFI start included), final update and residual, inverted cells (a corner
Jacobian <= 0) of the elliptic and TFI meshes, and peak memory of the process so far. The
targets: 30^3 in at most 3 s, 100^3 in at most 5 s (2-core machine); the cycle count
should grow slowly with the size. --jacobi adds, for 16^3 and 30^3, the point-Jacobi sweeps of
the same equations needed to come within the tolerance of the multigrid solution (about n^2).
The machine's load average is recorded: other work on a shared machine slows the wall times.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from meshgen.geometry.plugins import load_geometry  # noqa: E402
from meshgen.methods.elliptic import elliptic  # noqa: E402
from meshgen.methods.tfi import parametric_grid, tfi  # noqa: E402
from meshgen.methods.winslow import centre_coefficient, component_array, stencils, winslow_operator  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402

TARGETS = {30: 3.0, 100: 5.0}  # cells per axis -> seconds, the targets for a 2-core CPU


def inverted_cells(X: np.ndarray) -> int:
    """Inverted cells as ``meshgen evaluate`` counts them."""
    return quality_report(X)["inverted"]["count"]


def jacobi_sweeps(geometry, dims, target: np.ndarray, tol: float, most: int = 50000) -> int:
    """Point-Jacobi sweeps of the same discrete equations from TFI until every node is within
    ``tol`` (relative to the characteristic length) of the multigrid solution ``target``."""
    coords = parametric_grid(dims)
    grid = stencils(coords)
    R, goal = component_array(tfi(geometry, dims)), component_array(target)
    length = geometry.characteristic_length
    interior = (slice(None),) + (slice(1, -1),) * 3
    for sweep in range(1, most + 1):
        residual, axial = winslow_operator(R, grid)
        R[interior] += residual / centre_coefficient(axial, grid)
        if sweep % 10 == 0 and np.sqrt(np.max(np.sum((R - goal) ** 2, axis=0))) < tol * length:
            return sweep
    return -1


def peak_memory_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


HEADER = (
    f"{'cells':>8}{'cycles':>8}{'wall [s]':>10}{'cpu [s]':>9}{'update':>10}{'residual':>10}{'inverted':>10}"
    f"{'TFI inv.':>9}{'peak MB':>9}{'target':>14}"
)


def measure_size(geometry, n: int, jacobi: bool = False) -> dict:
    """Solve the ``n``^3-cell mesh of ``geometry`` once (default tolerance) and return its row:
    cycles, wall and CPU seconds, final update and residual, inverted cells of it and of TFI, peak
    memory so far, the target where there is one, and (``jacobi``) the point-Jacobi sweeps."""
    dims = (n, n, n)
    wall, cpu = time.perf_counter(), time.process_time()
    X, info = elliptic(geometry, dims)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    row = {
        "cells": n,
        "iterations": info["iterations"],
        "seconds": wall,
        "cpu_seconds": cpu,
        "final_update": info["final_update"],
        "final_residual": info["final_residual"],
        "converged": info["converged"],
        "levels": info["levels"],
        "inverted_cells": inverted_cells(X),
        "tfi_inverted_cells": inverted_cells(tfi(geometry, dims)),
        "peak_memory_mb": peak_memory_mb(),
    }
    if n in TARGETS:
        row["target_seconds"] = TARGETS[n]
        row["target_met"] = bool(info["converged"] and wall <= TARGETS[n])
    if jacobi:
        row["jacobi_sweeps"] = jacobi_sweeps(geometry, dims, X, info["tol"])
    return row


def format_row(row: dict) -> str:
    n = row["cells"]
    target = f"<= {TARGETS[n]:.0f} s {'met' if row['target_met'] else 'NOT met'}" if n in TARGETS else ""
    return (
        f"{n:>5}^3{row['iterations']:>8}{row['seconds']:>10.2f}{row['cpu_seconds']:>9.2f}{row['final_update']:>10.1e}"
        f"{row['final_residual']:>10.1e}{row['inverted_cells']:>10}{row['tfi_inverted_cells']:>9}"
        f"{row['peak_memory_mb']:>9.0f}{target:>14}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="sizes up to 50^3 only")
    parser.add_argument("--jacobi", action="store_true", help="also count point-Jacobi sweeps at 16^3 and 30^3")
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("bench_elliptic.json"))
    args = parser.parse_args()

    geometry = load_geometry("semicylinder")
    sizes = [16, 30, 50] if args.quick else [16, 30, 50, 64, 100]
    load = os.getloadavg()
    rows = []
    print(f"semicylinder, default tolerance; load average {load[0]:.2f} on {os.cpu_count()} cores")
    print(HEADER)
    for n in sizes:
        row = measure_size(geometry, n, jacobi=args.jacobi and n in (16, 30))
        rows.append(row)
        print(format_row(row))
    for row in rows:
        if "jacobi_sweeps" in row:
            print(
                f"point Jacobi at {row['cells']}^3: {row['jacobi_sweeps']} sweeps to the same tolerance (multigrid: {row['iterations']} cycles)"
            )
    args.json.write_text(json.dumps({"geometry": "semicylinder", "load_average": load, "results": rows}, indent=2) + "\n")
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
