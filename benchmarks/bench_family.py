"""One network for a family of shapes (``meshgen train --vary``): training time, per-member meshing
time, and each member's mesh against the elliptic mesh of that member.

    python benchmarks/bench_family.py [--quick] [--threads N] [--json FILE]

Cases (``CASES``): ``flower`` with twist 0..180, the README's ``flower`` with twist 0..180 and
amplitude 0.1..0.3 (both on the fixed layout: the flower's smoothed layout does not converge at
twist 180), and ``semicylinder`` with radius 0.5..2 and length 1..4 (the preset's smoothed layout).
Each is trained with the ``family`` preset, then every member of the validation grid (3 values per
parameter, the box's corners included: ``Family.grid``) and ``members`` random members (seeded)
are meshed at ``cells``^3 and measured with ``meshgen.quality``: inverted cells, boundary deviation
(relative to the characteristic length), mean minimum angle, and the same for the converged
elliptic mesh of the member (``meshgen.methods.elliptic.elliptic``) on the boundary layout the family was
trained on. The worst member has the most inverted cells, then the mean minimum angle furthest
from its elliptic mesh's. ``--quick``: the first and last case, fewer training steps, the grid's
members alone, 20^3 cells: the mechanism, not the figure.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

FIXED = ["boundary_layout=fixed"]  # the flower's smoothed layout does not converge at twist 180
CASES = {  # label: (geometry, ranges, configuration overrides)
    "flower": ("flower", {"twist": (0.0, 180.0)}, FIXED),
    "flower-readme": ("flower", {"twist": (0.0, 180.0), "amplitude": (0.1, 0.3)}, FIXED),
    "semicylinder": ("semicylinder", {"radius": (0.5, 2.0), "length": (1.0, 4.0)}, []),
}
TOLERANCE_DEGREES = 0.5  # the target's bound on |mean min angle - elliptic's| per member
QUICK_CASES = ("flower", "semicylinder")  # --quick: the mechanism on one- and two-parameter families
QUICK_OVERRIDES = ["adam.steps=60", "lbfgs.steps=0", "points.interior=1000"]  # a smoke test of the measurement


def measure_case(name: str, ranges: dict, members: int, cells: int, overrides=(), seed: int = 0) -> dict:
    """Train the family of ``name`` over ``ranges``, mesh the validation grid's members and
    ``members`` random ones and compare each with its elliptic mesh. Returns a JSON-ready dict."""
    import numpy as np

    from meshgen.geometry.plugins import load_geometry
    from meshgen.methods.elliptic import elliptic
    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.config import resolve_config
    from meshgen.neural.family import VALIDATION_POINTS, make_family, mesh_member
    from meshgen.neural.family_train import train_family
    from meshgen.quality import quality_report

    config = resolve_config("family", None, list(overrides), seed=seed)
    family = make_family(load_geometry(name), name, ranges, config.boundary_layout)
    with tempfile.TemporaryDirectory() as folder:
        start, start_cpu = time.perf_counter(), time.process_time()
        result = train_family(config, family, folder, summary=False)
        training = {
            "seconds": time.perf_counter() - start,
            "cpu_seconds": time.process_time() - start_cpu,
            "steps": result.step,
            "test_loss": result.test_loss["pde"],
        }
    checkpoint = result.checkpoint
    dims = (cells,) * 3
    coords = parametric_grid(dims)
    generator = np.random.default_rng(seed + 1)
    rows = []
    grid = family.grid(VALIDATION_POINTS)
    drawn = [{k: float(generator.uniform(low, high)) for k, (low, high) in ranges.items()} for _ in range(members)]
    for values in grid + drawn:
        geometry = family.member(values)
        wall = time.perf_counter()
        X = mesh_member(checkpoint, values, coords)
        meshing = time.perf_counter() - wall
        reference, info = elliptic(geometry, dims, boundary_layout=config.boundary_layout)
        network, ell = quality_report(X, geometry), quality_report(reference, geometry)
        angle, ell_angle = network["metrics"]["min_angle"]["mean"], ell["metrics"]["min_angle"]["mean"]
        rows.append(
            {
                "params": values,
                "on_grid": len(rows) < len(grid),
                "meshing_seconds": meshing,
                "inverted": network["inverted"]["count"],
                "boundary_deviation_max_rel": network["boundary_deviation"]["max_rel"],
                "min_angle_mean": angle,
                "elliptic_min_angle_mean": ell_angle,
                "elliptic_inverted": ell["inverted"]["count"],
                "elliptic_iterations": info.get("iterations"),
                "difference_degrees": angle - ell_angle,
                "within_tolerance": bool(network["inverted"]["count"] == 0 and abs(angle - ell_angle) <= TOLERANCE_DEGREES),
            }
        )
    worst = max(range(len(rows)), key=lambda i: (rows[i]["inverted"], abs(rows[i]["difference_degrees"])))
    return {
        "geometry": name,
        "ranges": {k: list(v) for k, v in ranges.items()},
        "overrides": list(overrides),
        "cells_per_axis": cells,
        "elliptic_boundary_layout": config.boundary_layout,
        "training": training,
        "members": rows,
        "validation_points": VALIDATION_POINTS,
        "meshing_seconds_median": statistics.median(r["meshing_seconds"] for r in rows),
        "worst": rows[worst],
        "all_within_tolerance": all(r["within_tolerance"] for r in rows),
        "tolerance_degrees": TOLERANCE_DEGREES,
    }


def run(quick: bool = False, seed: int = 0) -> dict:
    members, cells = (0, 20) if quick else (10, 40)
    overrides = QUICK_OVERRIDES if quick else []
    cases = {}
    for label, (name, ranges, case_overrides) in CASES.items():
        if quick and label not in QUICK_CASES:
            continue
        data = measure_case(name, ranges, members, cells, [*case_overrides, *overrides], seed)
        print_case(data)
        cases[label] = data
    import torch

    return {
        "preset": "family",
        "quick": quick,
        "members": members,
        "cells_per_axis": cells,
        "torch_threads": torch.get_num_threads(),
        "cases": cases,
    }


def print_case(data: dict) -> None:
    ranges = " ".join(f"{k}={lo:g}:{hi:g}" for k, (lo, hi) in data["ranges"].items())
    training = data["training"]
    print(
        f"{data['geometry']} {ranges}: trained {training['steps']} steps in {training['seconds']:.1f} s "
        f"(CPU {training['cpu_seconds']:.1f} s); {data['cells_per_axis']}^3 members against the elliptic mesh "
        f"on the {data['elliptic_boundary_layout']} boundary layout:"
    )
    print(f"  {'member':<32} {'mesh s':>7} {'inv':>4} {'bdev':>8} {'min ang':>8} {'elliptic':>8} {'diff':>6}")
    for row in data["members"]:
        at = ", ".join(f"{k}={v:.3g}" for k, v in row["params"].items()) + (" (grid)" if row.get("on_grid") else "")
        print(
            f"  {at:<32} {row['meshing_seconds']:7.3f} {row['inverted']:4d} {row['boundary_deviation_max_rel']:8.1e} "
            f"{row['min_angle_mean']:8.2f} {row['elliptic_min_angle_mean']:8.2f} {row['difference_degrees']:+6.2f}"
        )
    worst = data["worst"]
    print(
        f"  worst (inverted cells first, then angle): {', '.join(f'{k}={v:.3g}' for k, v in worst['params'].items())}, "
        f"{worst['inverted']} inverted, "
        f"{worst['difference_degrees']:+.2f} deg from elliptic; all within {data['tolerance_degrees']} deg and "
        f"valid: {data['all_within_tolerance']}",
        flush=True,
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="few steps, the validation grid's members at 20^3")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's, all cores)")
    args = parser.parse_args(argv)
    if args.threads is not None:
        import torch

        torch.set_num_threads(args.threads)
    data = run(args.quick)
    if args.json:
        args.json.write_text(json.dumps(data, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
