"""Elliptic (Winslow) solver on the semicylinder: multigrid cycles, time and result per grid size.

    python benchmarks/bench_elliptic.py [--quick] [--json FILE] [--jacobi]
    python benchmarks/bench_elliptic.py --gpu N [--device cuda]   # gpu_elliptic_row(N, device)

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

TARGETS = {30: 3.0, 100: 5.0}  # cells per axis -> seconds, the targets for a 2-core CPU


def inverted_cells(X: np.ndarray) -> int:
    """Inverted cells as ``meshgen evaluate`` counts them."""
    # not at the top: gpu_elliptic_row runs on machines that may lack the file writers' libraries (isal)
    from meshgen.quality import quality_report

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


def _timed_solve(device: str, solve):
    """``(result, seconds)`` of ``solve()``, the device synchronised before and after."""
    import torch

    if device.startswith("cuda"):
        torch.cuda.synchronize()
    start = time.perf_counter()
    result = solve()
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    return result, time.perf_counter() - start


def gpu_elliptic_row(
    n: int = 100, device: str = "cuda", tol: float = 1e-12, repeats: int = 3, warmup: int = 12, cpu_3d: bool = False
) -> dict:
    """The torch multigrid (``meshgen.methods.multigrid_torch``) on the semicylinder with n^3 cells on
    ``device``, beside the NumPy/numba solver's mesh of the same run (``build_elliptic``: the section's
    2D solve, extruded), both to ``tol`` (largest node update per cycle / characteristic length).

    Device solves (median seconds of ``repeats`` after one warm-up at ``warmup``^3 that takes CUDA's
    initialisation out; host-to-device copy of the start and the copy back included):
    ``seconds_3d``, the full 3D grid from the TFI interior with the CPU mesh's boundary (its caps
    are the section's solution: the 3D problem's boundary data); ``seconds_extruded``, the
    method's own path (``extruded_solve`` with the 2D solve on the device; ``seconds_extruded_2d``
    is the 2D solve alone). ``diff_*``: max |X - X_cpu| / length. ``cpu_3d``: also the NumPy/numba
    3D solve of the same 3D start (``cpu_3d_seconds``), the like-for-like CPU figure.
    """
    import functools

    import torch

    from meshgen.geometry.layout import with_layout
    from meshgen.methods.elliptic import build_elliptic, extruded_solve
    from meshgen.methods.multigrid import solve_winslow
    from meshgen.methods.multigrid_torch import solve_winslow_torch

    plain = load_geometry("semicylinder")
    geometry = with_layout(plain, "smoothed")
    length = geometry.characteristic_length
    solve = functools.partial(solve_winslow_torch, device=device)

    def starts(cells):
        coords = parametric_grid((cells, cells, cells))
        X0 = tfi(geometry, None, coords)
        reference, seconds = _timed_solve("cpu", lambda: build_elliptic(plain, coords, tol=tol, max_iter=200))
        start = X0.copy()
        start[:, :, [0, -1]] = reference[0][:, :, [0, -1]]
        return coords, X0, start, reference, seconds

    coords, X0, start, _, _ = starts(warmup)
    solve(start, coords, tol=tol, max_iter=200, length=length)
    extruded_solve(X0, coords, tol, 200, length, solve=solve)

    coords, X0, start, (X_cpu, info_cpu), cpu_seconds = starts(n)
    solid, extruded = [], []
    for _ in range(repeats):
        solid.append(_timed_solve(device, lambda: solve(start, coords, tol=tol, max_iter=200, length=length)))
        extruded.append(_timed_solve(device, lambda: extruded_solve(X0, coords, tol, 200, length, solve=solve)))
    (X3, info3), _ = solid[-1]
    (Xe, infoe), _ = extruded[-1]
    row = {
        "cells": n,
        "device": device,
        "device_name": torch.cuda.get_device_name() if device.startswith("cuda") else "torch cpu",
        "tol": tol,
        "seconds_3d": float(np.median([s for _, s in solid])),
        "seconds_3d_all": [s for _, s in solid],
        "iterations_3d": info3["iterations"],
        "phase_seconds_3d": info3["phase_seconds"],
        "levels_3d": info3["levels"],
        "final_residual_3d": info3["final_residual"],
        "diff_3d": float(np.abs(X3 - X_cpu).max() / length),
        "seconds_extruded": float(np.median([s for _, s in extruded])),
        "seconds_extruded_2d": float(np.median([r[1]["seconds"] for r, _ in extruded])),
        "iterations_extruded": infoe["iterations"],
        "diff_extruded": float(np.abs(Xe - X_cpu).max() / length),
        "cpu_seconds": cpu_seconds,
        "cpu_iterations": info_cpu["iterations"],
        "converged": bool(info3["converged"] and infoe["converged"] and info_cpu["converged"]),
    }
    if cpu_3d:
        (_, info), seconds = _timed_solve("cpu", lambda: solve_winslow(start, coords, tol=tol, max_iter=200, length=length))
        row.update(cpu_3d_seconds=seconds, cpu_3d_iterations=info["iterations"])
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
    parser.add_argument("--gpu", type=int, default=None, metavar="N", help="only gpu_elliptic_row(N) (torch multigrid)")
    parser.add_argument("--device", default="cuda", help="torch device of --gpu [default: cuda]")
    args = parser.parse_args()
    if args.gpu is not None:
        print(json.dumps(gpu_elliptic_row(args.gpu, args.device, cpu_3d=True), indent=2))
        return

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
