"""The neural pipe model (one network per block of the pipe's section, ``meshgen train -g pipe``) against the multi-block
elliptic mesh, at two resolutions, through the request path (``meshgen.mesh``).

    python benchmarks/bench_blocks_neural.py [--quick] [--json FILE] [--checkpoint PATH]

The model is trained in the run, as a user trains it: ``meshgen train -g pipe`` with the default
configuration in a subprocess (imports, the elliptic start, checkpoints and summary), wall and CPU
seconds (target: at most 5 minutes on 2 cores); ``--checkpoint`` measures a given model instead.

Per resolution: the elliptic mesh (started from the TFI), the default neural mesh (the networks'
mesh after the conforming correction) and ``--polish`` (that mesh polished by the multi-block
elliptic solver; --quick leaves it out): seconds, sweeps, inverted cells, mean and worst min angle, the largest
gap between matching interface nodes (0: identical), the largest distance of a wall node from the
circle of radius R. Target (issue's benchmark row): 0 inverted, conforming, mean min angle within
0.5 deg of the elliptic mesh's at both resolutions (--dims 8 4 4 and 16 8 4; --quick: 4 2 4 and
8 4 4, not judged). The machine's load average is recorded: other work slows the wall times.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import meshgen  # noqa: E402
from meshgen.geometry.block_nodes import interface_gaps, merged_mesh  # noqa: E402
from meshgen.neural.checkpoint import load_checkpoint  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DIMS = [(8, 4, 4), (16, 8, 4)]
QUICK_DIMS = [(4, 2, 4), (8, 4, 4)]
TARGET_DEGREES = 0.5
TRAIN_TARGET_SECONDS = 300.0


def train_pipe(folder: Path) -> dict:
    """``meshgen train -g pipe --out FOLDER/run -q`` (the default configuration) in a subprocess:
    {"checkpoint", "seconds" (wall), "cpu_seconds" (the child's user + system)}."""
    command = [sys.executable, "-m", "meshgen", "train", "-g", "pipe", "--out", str(folder / "run"), "-q"]
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    before, start = os.times(), time.perf_counter()
    subprocess.run(command, check=True, env=environment, stdout=subprocess.DEVNULL)
    seconds, after = time.perf_counter() - start, os.times()
    cpu = after.children_user - before.children_user + after.children_system - before.children_system
    print(f"meshgen train -g pipe: {seconds:.1f} s (CPU {cpu:.1f} s; target {TRAIN_TARGET_SECONDS:g} s)", flush=True)
    return {"checkpoint": folder / "run" / "checkpoint.pt", "seconds": seconds, "cpu_seconds": cpu}


def measure(dims, method: str, checkpoint: Path, polish: bool | None = None) -> dict:
    options = {} if method == "elliptic" else {"model": str(checkpoint), "polish": polish}
    if polish:
        options["max_iter"] = 200
    start = time.perf_counter()
    made = meshgen.mesh("pipe", dims, method=method, **options)
    seconds = time.perf_counter() - start
    block_set = made.geometry
    points, cells, _ = merged_mesh(block_set, made.blocks)
    report = quality_report((points, cells))
    radius = block_set.values["radius"]
    wall = np.concatenate([X[-1].reshape(-1, 3) for X in made.blocks[1:]])  # xi = 1 of the four wall blocks
    info = made.info
    return {
        "dims": list(dims),
        "mesh": method if method == "elliptic" else ("neural --polish" if polish else "neural (default)"),
        "cells": int(len(cells)),
        "seconds": seconds,
        "sweeps": int(info.get("sweeps", info.get("polish", {}).get("sweeps", 0))),
        "inverted": int(report["inverted"]["count"]),
        "min_angle_mean": float(report["metrics"]["min_angle"]["mean"]),
        "min_angle_worst": float(report["metrics"]["min_angle"]["min"]),
        "interface_gap_max": max(interface_gaps(block_set, made.blocks)),
        "wall_distance_max": float(np.abs(np.hypot(wall[:, 0], wall[:, 1]) - radius).max()),
        "network_interface_gap_rel": info.get("correction", {}).get("interface_gap_before"),
    }


def run(quick: bool = False, checkpoint: Path | None = None) -> dict:
    """The rows, with the model trained here (``train_pipe``) unless ``checkpoint`` names one."""
    if checkpoint is not None:
        return measure_model(Path(checkpoint), quick)
    with tempfile.TemporaryDirectory() as folder:
        training = train_pipe(Path(folder))
        result = measure_model(training.pop("checkpoint"), quick)
    return {**result, "training": {**training, "target_seconds": TRAIN_TARGET_SECONDS}}


def measure_model(checkpoint: Path, quick: bool) -> dict:
    trained = load_checkpoint(checkpoint)
    rows, differences = [], []
    for dims in QUICK_DIMS if quick else DIMS:
        elliptic = measure(dims, "elliptic", checkpoint)
        network = measure(dims, "neural", checkpoint)
        polished = None if quick else measure(dims, "neural", checkpoint, polish=True)
        for row in (elliptic, network, polished) if polished is not None else (elliptic, network):
            row["difference_degrees"] = row["min_angle_mean"] - elliptic["min_angle_mean"]
            rows.append(row)
            print(
                f"pipe {' '.join(map(str, dims)):>8s} {row['mesh']:22s} {row['cells']:6d} cells {row['seconds']:6.1f} s "
                f"{row['sweeps']:3d} sweeps  inverted {row['inverted']}  mean min angle {row['min_angle_mean']:6.2f} "
                f"({row['difference_degrees']:+.2f})  worst {row['min_angle_worst']:5.1f}  interface gap "
                f"{row['interface_gap_max']:.1e}  wall {row['wall_distance_max']:.1e}",
                flush=True,
            )
        differences.append(abs(network["difference_degrees"]))
    neural_rows = [row for row in rows if row["mesh"] == "neural (default)"]
    met = (
        all(row["inverted"] == 0 and row["interface_gap_max"] == 0.0 for row in neural_rows)
        and max(differences) <= TARGET_DEGREES
    )
    result = {
        "quick": quick,
        "rows": rows,
        "worst_difference_degrees": max(differences),
        "target_degrees": TARGET_DEGREES,
        "met": bool(met),
        "judged": not quick,
        "model": {
            "checkpoint": str(checkpoint),
            "bytes": Path(checkpoint).stat().st_size,
            "widths": list(trained["model"]["widths"]),
            "steps": trained["step"],
            "training_seconds": trained["elapsed_seconds"],
        },
        "load_average": os.getloadavg(),
    }
    print(f"neural pipe: worst |mean min angle - elliptic's| {max(differences):.2f} deg (target {TARGET_DEGREES}): "
          f"{'met' if met else 'NOT met'}{'' if not quick else ' (quick: not judged)'}")  # fmt: skip
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--checkpoint", type=Path, default=None, help="measure this model instead of training one")
    args = parser.parse_args()
    result = run(args.quick, args.checkpoint)
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
