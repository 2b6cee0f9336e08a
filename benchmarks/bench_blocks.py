"""Multi-block meshes (meshgen.blocks): the pipe O-grid's quality against resolution, and the DFG
2D-1 benchmark on the dfg-cylinder block set with OpenFOAM's simpleFoam.

    python benchmarks/bench_blocks.py [--quick] [--json FILE] [--only pipe|dfg]

``pipe``: elliptic (and TFI) meshes at N = 8, 16, 32, 50 (--quick: 8, 16) cells around a quarter of
the circumference (50: 200 around), M = N / 2 across the wall layer, 4 along the axis, and the
issue's 40 around by 80 along (10 5 80): sweeps, seconds, inverted cells, worst min and max angle,
the largest cell-size ratio across an interface and inside a block.
Targets: 0 inverted, worst min angle >= 40 deg and worst max angle <= 140 deg at every resolution
(the single-block semicylinder's degrade with refinement), ratio across interfaces <= 1.3.

``dfg``: ``examples/dfg/run_dfg.py`` at dims (28, 20) (9.5k cells) and (56, 40) (38k cells;
--quick: the first only): drag, lift and dp errors against the reference and the targets (at most
10k cells: 0.1%, 3%, 0.5%; at most 40k: 0.05%, 1%, 0.2%). Needs OpenFOAM; skipped without it.
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

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples" / "dfg"))

from meshgen.blocks import load_block_set, merged_mesh, tfi_blocks  # noqa: E402
from meshgen.elliptic_blocks import elliptic_blocks  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402

DFG_TARGETS = {10_000: {"drag": 0.001, "lift": 0.03, "dp": 0.005}, 40_000: {"drag": 0.0005, "lift": 0.01, "dp": 0.002}}


def pipe_rows(all_dims) -> list[dict]:
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
        row["targets"] = DFG_TARGETS.get(budget)
        row["met"] = budget is not None and all(abs(row[f"{k}_error"]) <= v for k, v in DFG_TARGETS[budget].items())
        rows.append(row)
        print(
            f"dfg {' '.join(map(str, dims)):>6s} {row['cells']:6d} cells  mesh {row['mesh_seconds']:5.1f} s  simpleFoam "
            f"{row['iterations']} it {row['solver_seconds']:5.1f} s  drag {100 * row['drag_error']:+.3f}%  "
            f"lift {100 * row['lift_error']:+.2f}%  dp {100 * row['dp_error']:+.3f}%  targets {'met' if row['met'] else 'not met'}",
            flush=True,
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--only", choices=["pipe", "dfg"], default=None)
    args = parser.parse_args()
    result = {"load_average": os.getloadavg()}
    if args.only in (None, "pipe"):
        sizes = [(n, n // 2, 4) for n in ((8, 16) if args.quick else (8, 16, 32, 50))]
        result["pipe"] = pipe_rows(sizes + ([] if args.quick else [(10, 5, 80)]))
    if args.only in (None, "dfg"):
        result["dfg"] = dfg_rows([(28, 20)] if args.quick else [(28, 20), (56, 40)])
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
