"""One network for a family of airfoil sections (``meshgen.neural.wall_family``): the NACA 4-digit
C-grids of camber 0..0.04 at 0.2..0.6 chord, thickness 0.08..0.18, at y+ 1, Re 6e6.

    python benchmarks/bench_airfoil_family.py [--quick] [--checkpoint FILE | --train] [--json FILE]

The model is the bundled one (``meshgen/_models/families/airfoil``), a CHECKPOINT, or (``--train``)
one trained now with the README's command (timed: the training row).

``held_out``: members of a grid of 5 values per parameter (the corners included; 3 with
``--quick``) and 20 drawn at random (seeded; 4 with ``--quick``), none of them a member the
network was fitted to but the corners and the middle. Each is meshed at 448 x 128 (57,344 cells) by
the model and by the elliptic method (``meshgen.neural.wall_family_train.member_check``): inverted
cells, the largest |first-cell height / asked - 1| and the largest angle of a first grid line off
the wall normal at every wall node (``bench_airfoil.wall_figures``, its trailing edge excepted),
and the mean minimum angle below the member's elliptic mesh's. Targets: 0 inverted, 3 %, 3 deg, 1 deg.
``speed``: 5 members (drawn, distinct) meshed by the model (``neural_wall_blocks``: the network and
the finish; the member's block set made before, untimed), and by the elliptic method: medians and
their ratio. Target: at most 0.05 s.
``training``: the model's training time (the run's own clock); with ``--train`` the wall time of
the command too. Target: at most 30 min on 2 cores.
``solver`` (a full run only: about 20 minutes per member on 2 cores, the two meshes solved side by
side): NACA 0012, 2412 and 4415 (closed trailing edges) at SOLVER_DIMS, meshed by the model and by
the elliptic method as OpenFOAM cases, each solved by ``examples/naca0012/run_naca0012.py``
(simpleFoam, Spalart-Allmaras, Re 6e6, alpha 10, at most ``SOLVER_ITERATIONS``): CL and CD of the
network's mesh against the elliptic mesh's. Targets: within 0.5 % and 2 %.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
DIMS = (448, 128)
RANGES = {"camber": (0.0, 0.04), "camber_position": (0.2, 0.6), "thickness": (0.08, 0.18)}
BUNDLED = REPO / "meshgen" / "_models" / "families" / "airfoil" / "checkpoint.pt"
SOLVER_MEMBERS = {
    "0012": {"thickness": 0.12},
    "2412": {"thickness": 0.12, "camber": 0.02},
    "4415": {"thickness": 0.15, "camber": 0.04},
}
SOLVER_DIMS = (224, 128)
SOLVER_ITERATIONS = 4000
TRAIN = ["train", "-g", "airfoil", *[f"--vary={n}={lo:g}:{hi:g}" for n, (lo, hi) in RANGES.items()]]


def members(points: int, drawn: int, seed: int = 0) -> list[dict]:
    """The grid of ``points`` values per parameter (corners included) and ``drawn`` random members."""
    import itertools

    axes = [[(n, float(v)) for v in np.linspace(lo, hi, points)] for n, (lo, hi) in RANGES.items()]
    grid = [dict(m) for m in itertools.product(*axes)]
    rng = np.random.default_rng(seed)
    return grid + [{n: float(lo + rng.random() * (hi - lo)) for n, (lo, hi) in RANGES.items()} for _ in range(drawn)]


def held_out(model: dict, points: int, drawn: int) -> dict:
    from types import SimpleNamespace

    from bench_airfoil import wall_figures

    from meshgen.geometry.blocks import load_block_set
    from meshgen.neural.wall_family_train import member_check

    rows = []
    for member in members(points, drawn):
        block_set = load_block_set("airfoil", {**model["family"]["base"], **member}, DIMS)
        neural, check = member_check(model, block_set)
        wall = wall_figures(SimpleNamespace(geometry=block_set, blocks=neural))  # y+ 1 at Re 6e6: the family's
        rows.append({
            "params": member,
            "inverted": check["inverted"],
            "first_cell_error": wall["first_cell_error"],
            "wall_angle_degrees": wall["worst_wall_angle_degrees"],
            "mean_min_angle": check["mean_min_angle"],
            "elliptic_mean_min_angle": check["elliptic_mean_min_angle"],
            "below_elliptic": check["gap"],
        })  # fmt: skip
    worst = max(rows, key=lambda r: r["below_elliptic"])
    result = {
        "members": len(rows),
        "grid_points": points,
        "drawn": drawn,
        "inverted": sum(r["inverted"] for r in rows),
        "members_with_inverted": [r["params"] for r in rows if r["inverted"]],
        "first_cell_error": max(r["first_cell_error"] for r in rows),
        "wall_angle_degrees": max(r["wall_angle_degrees"] for r in rows),
        "worst_below_elliptic": worst["below_elliptic"],
        "worst_member": worst["params"],
        "rows": rows,
    }
    print(f"{len(rows)} held-out members at {DIMS[0]} x {DIMS[1]}: {result['inverted']} inverted cells, first-cell error "
          f"{result['first_cell_error']:.2e}, wall angle {result['wall_angle_degrees']:.3f} deg, worst mean min angle "
          f"{result['worst_below_elliptic']:.2f} deg below the elliptic mesh's ({worst['params']})", flush=True)  # fmt: skip
    return result


def speed(model: dict, count: int = 5) -> dict:
    from meshgen.geometry.blocks import load_block_set
    from meshgen.neural.wall_map import neural_wall_blocks, wall_hooks

    network, elliptic = [], []
    neural_wall_blocks(load_block_set("airfoil", {**model["family"]["base"]}, DIMS), model)  # imports and first calls
    for member in members(0, count, seed=1):
        block_set = load_block_set("airfoil", {**model["family"]["base"], **member}, DIMS)
        start = time.perf_counter()
        neural_wall_blocks(block_set, model)
        network.append(time.perf_counter() - start)
        start = time.perf_counter()
        wall_hooks(block_set).mesh_elliptic(block_set)
        elliptic.append(time.perf_counter() - start)
    row = {
        "cells": DIMS[0] * DIMS[1],
        "seconds": statistics.median(network),
        "runs_seconds": network,
        "elliptic_seconds": statistics.median(elliptic),
    }
    row["elliptic_over_network"] = row["elliptic_seconds"] / row["seconds"]
    print(f"a member's mesh, {row['cells']} cells: {row['seconds'] * 1e3:.1f} ms (median of {count} members; elliptic "
          f"{row['elliptic_seconds']:.2f} s, {row['elliptic_over_network']:.0f}x)", flush=True)  # fmt: skip
    return row


def solver(checkpoint: Path, iterations: int = SOLVER_ITERATIONS, members=SOLVER_MEMBERS) -> dict:
    """CL and CD of each member's neural and elliptic meshes (simpleFoam, side by side)."""
    from concurrent.futures import ThreadPoolExecutor

    import meshgen

    sys.path.insert(0, str(REPO / "examples" / "naca0012"))
    from run_naca0012 import run as solve

    rows = {}
    with tempfile.TemporaryDirectory() as folder:
        for name, member in members.items():
            cases = {}
            for method in ("neural", "elliptic"):
                cases[method] = Path(folder) / f"{name}-{method}"
                model = str(checkpoint) if method == "neural" else None
                made = meshgen.mesh("airfoil", SOLVER_DIMS, method=method, params=member, model=model)
                made.write(cases[method], "openfoam", quality=False)
            with ThreadPoolExecutor(2) as pool:  # each simpleFoam a process of its own
                done = dict(zip(cases, pool.map(lambda c: solve(10.0, 0, c, iterations, quiet=True, mesh=False), cases.values())))
            row = {m: {k: done[m][k] for k in ("CL", "CD", "iterations", "converged", "change_last_window")} for m in done}
            row["cl_difference"] = done["neural"]["CL"] / done["elliptic"]["CL"] - 1.0
            row["cd_difference"] = done["neural"]["CD"] / done["elliptic"]["CD"] - 1.0
            rows[name] = row
            print(f"NACA {name} at alpha 10, {SOLVER_DIMS[0]} x {SOLVER_DIMS[1]}: CL {done['neural']['CL']:.5f} (neural) vs "
                  f"{done['elliptic']['CL']:.5f}, CD {done['neural']['CD']:.6f} vs {done['elliptic']['CD']:.6f} "
                  f"({100 * row['cl_difference']:+.3f} %, {100 * row['cd_difference']:+.3f} %)", flush=True)  # fmt: skip
    return {"dims": list(SOLVER_DIMS), "iterations": iterations, "members": rows,
            "cl_difference": max(abs(r["cl_difference"]) for r in rows.values()),
            "cd_difference": max(abs(r["cd_difference"]) for r in rows.values())}  # fmt: skip


def train_now(folder: Path) -> tuple[Path, float]:
    checkpoint = folder / "run" / "checkpoint.pt"
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "meshgen", *TRAIN, "--out", str(checkpoint.parent), "-q"], check=True,
                   capture_output=True, env={**os.environ, "PYTHONPATH": str(REPO)})  # fmt: skip
    return checkpoint, time.perf_counter() - start


def run(quick: bool, checkpoint=None, train: bool = False, solver_iterations: int | None = None) -> dict:
    from meshgen.neural.checkpoint_data import read_plain_checkpoint

    with tempfile.TemporaryDirectory() as folder:  # a model trained now lives here until the rows are made
        wall = None
        if train:
            checkpoint, wall = train_now(Path(folder))
        path = Path(checkpoint or BUNDLED)
        loaded = read_plain_checkpoint(path)
        model = loaded["model"]
        result = {
            "checkpoint": str(path.relative_to(REPO) if path.is_relative_to(REPO) else path),
            "model_bytes": path.stat().st_size,
            "training": {"seconds": float(loaded["elapsed_seconds"]), "steps": int(loaded["step"]), "wall_seconds": wall},
            "ranges": model["family"]["ranges"],
        }
        print(f"model {result['checkpoint']} ({result['model_bytes'] // 1000} kB): trained "
              f"{result['training']['seconds']:.0f} s, {result['training']['steps']} steps", flush=True)  # fmt: skip
        result["held_out"] = held_out(model, 3 if quick else 5, 4 if quick else 20)
        result["speed"] = speed(model)
        if not quick and shutil.which("simpleFoam", path=_foam_path()):
            result["solver"] = solver(path, solver_iterations or SOLVER_ITERATIONS)
    return result


def _foam_path() -> str:
    sys.path.insert(0, str(REPO / "examples"))
    from foam_case import foam_environment

    return foam_environment().get("PATH", "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="a 3-point grid and 4 drawn members")
    parser.add_argument("--checkpoint", help="a family checkpoint (default: the bundled one)")
    parser.add_argument("--train", action="store_true", help="train the family now with the README's command (minutes)")
    parser.add_argument("--solver-iterations", type=int, help=f"simpleFoam's cap (default {SOLVER_ITERATIONS})")
    parser.add_argument("--json", help="write the results here")
    args = parser.parse_args()
    result = run(args.quick, args.checkpoint, args.train, args.solver_iterations)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
