"""Multi-block meshes (meshgen.geometry.blocks): the pipe O-grid's quality against resolution, and the DFG
2D-1 benchmark on the dfg-cylinder block set with OpenFOAM's simpleFoam.

    python benchmarks/bench_blocks.py [--quick] [--json FILE] [--only pipe|dfg|speed]

``pipe``: elliptic (and TFI) meshes at N = 8, 16, 32, 50 (--quick: 8, 16) cells around a quarter of
the circumference (50: 200 around), M = N / 2 across the wall layer, 4 along the axis, and the
issue's 40 around by 80 along (10 5 80): sweeps, seconds, inverted cells, worst min and max angle,
the largest cell-size ratio across an interface and inside a block; on the 10 5 80 mesh (the
elliptic solver's default tolerance), potentialFoam with a uniform inlet velocity: the largest
|U - U_inlet| over the cells (the mesh is an extrusion, so the exact answer is uniform).
Targets: 0 inverted, worst min angle >= 40 deg and worst max angle <= 140 deg at every resolution
(the single-block semicylinder's degrade with refinement), ratio across interfaces <= 1.3,
potentialFoam max |U - U_inlet| < 1e-6 (skipped without OpenFOAM).

``dfg``: ``examples/dfg/run_dfg.py`` (default ``wake_growth``) at dims (17, 10), (34, 20) and
(68, 40): 2.4k, 9.6k and 38k cells, each size twice the last in every direction: drag, lift and dp
errors against the reference, the observed order of convergence, and the targets on the two
larger rows (at most 10k cells: 0.1%, 3%, 0.5%; at most 40k: 0.05%, 1%, 0.2%); each row also says
whether simpleFoam met its residual controls and how much drag and lift moved over the last 50
iterations. Needs OpenFOAM; skipped without it.
``speed``: the elliptic solver on block sets against one block, in one warm process, medians of 3
(--quick: 1): ``meshgen mesh -g dfg-cylinder --dims 34 20 --method elliptic``'s solve (target at
most 1 s); the pipe at 50 50 80 (1.0e6 hexahedra, solved as its section and extruded, the
default) over the semicylinder at 100^3 (1.0e6 hexahedra; target at most 1.5x); and, not judged,
the same pipe solved by the 3D multigrid (``as_extrusion=False``, a set that is not an extrusion
pays this; full run only).
The machine's load average is recorded: other work on a shared machine slows the wall times.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples" / "dfg"))

from meshgen.geometry.block_nodes import merged_mesh
from meshgen.geometry.blocks import load_block_set, tfi_blocks  # noqa: E402
from meshgen.methods.elliptic import elliptic_blocks  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402

DFG_DIMS = [(17, 10), (34, 20), (68, 40)]  # a refinement series: the last two are the 10k and the 40k rows
DFG_TARGETS = {10_000: {"drag": 0.001, "lift": 0.03, "dp": 0.005}, 40_000: {"drag": 0.0005, "lift": 0.01, "dp": 0.002}}


POTENTIAL_TARGET = 1e-6  # potentialFoam's max |U - U_inlet| on the pipe


def pipe_potential_error(block_set, Xs) -> float | None:
    """potentialFoam on the pipe mesh ``Xs`` with U = (0, 0, 1) at the inlet: the largest
    |U - (0, 0, 1)| over the cells (None without OpenFOAM)."""
    from openfoam_helpers import missing_reason, read_vector_field, run_tool, write_potential_flow

    from meshgen.formats.multiblock import write_blocks

    if missing_reason() is not None:
        return None
    with tempfile.TemporaryDirectory() as folder:
        case = write_blocks(Path(folder) / "pipe", block_set, Xs, format_name="openfoam")
        write_potential_flow(case, inlet="inlet", outlet="outlet", velocity=(0.0, 0.0, 1.0))
        solved = run_tool("potentialFoam", case, timeout=1200)
        if solved.returncode != 0:
            raise RuntimeError(solved.stdout[-2000:])
        U = read_vector_field(case / "0" / "U")
    return float(np.max(np.linalg.norm(U - [0.0, 0.0, 1.0], axis=1)))


def pipe_rows(all_dims, potential_dims=()) -> list[dict]:
    from blocks_helpers import size_ratios

    rows = []
    for dims in all_dims:
        block_set = load_block_set("pipe", None, dims)
        for method in ("tfi", "elliptic"):
            start = time.perf_counter()
            Xs, info = (tfi_blocks(block_set), {}) if method == "tfi" else elliptic_blocks(block_set)
            seconds = time.perf_counter() - start
            points, cells, _ = merged_mesh(block_set, Xs)
            report = quality_report((points, cells))
            across, inside = size_ratios(block_set, Xs)
            rows.append(
                {
                    "dims": list(dims),
                    "method": method,
                    "cells": block_set.cells,
                    "sweeps": info.get("sweeps", 0),
                    "seconds": seconds,
                    "inverted": report["inverted"]["count"],
                    "worst_min_angle": report["metrics"]["min_angle"]["min"],
                    "worst_max_angle": report["metrics"]["max_angle"]["max"],
                    "ratio_across": across,
                    "ratio_inside": inside,
                }
            )
            row = rows[-1]
            if method == "elliptic" and tuple(dims) in potential_dims:
                row["potential_error"] = pipe_potential_error(block_set, Xs)
                row["potential_met"] = None if row["potential_error"] is None else row["potential_error"] < POTENTIAL_TARGET
                print(f"pipe {' '.join(map(str, dims))} elliptic (default tol, {info.get('sweeps')} sweeps): potentialFoam "
                      f"max |U - U_in| {row['potential_error']} (target < {POTENTIAL_TARGET:g})", flush=True)  # fmt: skip
            print(
                f"pipe {' '.join(map(str, dims)):>9s} {method:8s} {row['cells']:7d} cells  {row['sweeps']:4d} sweeps "
                f"{seconds:7.1f} s  inverted {row['inverted']}  min angle {row['worst_min_angle']:5.1f}  "
                f"max angle {row['worst_max_angle']:5.1f}  size ratio across {across:.2f} (inside {inside:.2f})",
                flush=True,
            )
    return rows


def dfg_rows(all_dims) -> list[dict]:
    if shutil.which("simpleFoam") is None and not Path("/usr/share/openfoam/etc/bashrc").is_file():
        print("dfg: skipped (OpenFOAM's simpleFoam not installed)")
        return []
    from run_dfg import run

    rows = []
    for dims in all_dims:
        with tempfile.TemporaryDirectory() as folder:
            row = run(dims, "elliptic", Path(folder) / "case", quiet=True)
        budget = min(b for b in DFG_TARGETS if b >= row["cells"]) if row["cells"] <= max(DFG_TARGETS) else None
        if budget == min(DFG_TARGETS) and row["cells"] < budget / 2:
            budget = None  # the coarse row of the series: not what the 10k target is set for
        row["targets"] = DFG_TARGETS.get(budget)
        row["met"] = None if budget is None else all(abs(row[f"{k}_error"]) <= v for k, v in DFG_TARGETS[budget].items())
        rows.append(row)
        print(
            f"dfg {' '.join(map(str, dims)):>6s} {row['cells']:6d} cells  mesh {row['mesh_seconds']:5.1f} s  simpleFoam "
            f"{row['iterations']} it {row['solver_seconds']:5.1f} s  drag {100 * row['drag_error']:+.3f}%  "
            f"lift {100 * row['lift_error']:+.2f}%  dp {100 * row['dp_error']:+.3f}%  converged {row['converged']}  "
            f"targets {'-' if row['met'] is None else ('met' if row['met'] else 'not met')}",
            flush=True,
        )
    for key in ("drag", "lift", "dp") if len(rows) == 3 else ():
        e = [row[f"{key}_error"] for row in rows]
        if (e[0] - e[1]) * (e[1] - e[2]) > 0:  # monotone: the observed order of the three doubling sizes
            order = float(np.log2((e[0] - e[1]) / (e[1] - e[2])))
            print(f"dfg {key}: observed order {order:.2f}", flush=True)
            rows[-1][f"{key}_observed_order"] = order
    return rows


def speed_rows(quick: bool) -> dict:
    """Seconds of the block-set elliptic solves against the one-block semicylinder (module docstring)."""
    from meshgen.geometry import load_geometry
    from meshgen.methods.elliptic import elliptic, elliptic_blocks

    repeat = 1 if quick else 3
    elliptic_blocks(load_block_set("pipe", None, (4, 4, 4)))  # compiled kernels loaded before any timing
    elliptic(load_geometry("semicylinder"), dims=(8, 8, 8))

    def timed(function):
        runs, info = [], None
        for _ in range(repeat):
            start = time.perf_counter()
            info = function()
            runs.append(time.perf_counter() - start)
        return {"seconds": float(np.median(runs)), "runs_seconds": runs, "cycles": info.get("sweeps", info.get("iterations"))}

    dfg = load_block_set("dfg-cylinder", None, (34, 20))
    pipe = load_block_set("pipe", None, (50, 50, 80))
    result = {
        "dfg_34x20": timed(lambda: elliptic_blocks(dfg)[1]),
        "semicylinder_100": timed(lambda: elliptic(load_geometry("semicylinder"), dims=(100, 100, 100))[1]),
        "pipe_50_50_80": timed(lambda: elliptic_blocks(load_block_set("pipe", None, (50, 50, 80)))[1]),
    }
    result["pipe_cells"] = int(sum(np.prod([len(t) - 1 for t in c]) for c in pipe.coords))
    result["pipe_over_semicylinder"] = result["pipe_50_50_80"]["seconds"] / result["semicylinder_100"]["seconds"]
    if not quick:
        once = {"repeat": 1}
        start = time.perf_counter()
        info = elliptic_blocks(pipe, as_extrusion=False)[1]
        once.update(seconds=time.perf_counter() - start, cycles=info["sweeps"])
        result["pipe_50_50_80_3d"] = once
        result["pipe_3d_over_semicylinder"] = once["seconds"] / result["semicylinder_100"]["seconds"]
    for key in ("dfg_34x20", "semicylinder_100", "pipe_50_50_80", "pipe_50_50_80_3d"):
        if key in result:
            print(f"speed {key:18s} {result[key]['seconds']:7.2f} s  {result[key]['cycles']} cycles", flush=True)
    print(f"speed pipe / semicylinder {result['pipe_over_semicylinder']:.3f}x", flush=True)
    return result


def run(quick: bool, only: str | None = None) -> dict:
    """The pipe and DFG rows (``--quick``: the pipe at N = 8, 16 only: the DFG and the 40 x 80
    pipe take minutes)."""
    result = {"load_average": list(os.getloadavg())}
    if only in (None, "pipe"):
        sizes = [(n, n // 2, 4) for n in ((8, 16) if quick else (8, 16, 32, 50))]
        result["pipe"] = pipe_rows(sizes + ([] if quick else [(10, 5, 80)]), potential_dims=() if quick else [(10, 5, 80)])
    if only in (None, "dfg") and not quick:
        result["dfg"] = dfg_rows(DFG_DIMS)
    if only in (None, "speed"):
        result["speed"] = speed_rows(quick)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--only", choices=["pipe", "dfg", "speed"], default=None)
    args = parser.parse_args()
    result = run(args.quick, args.only)
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
