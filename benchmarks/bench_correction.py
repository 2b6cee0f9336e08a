"""Benchmark of the boundary correction X = N + TFI[g - N]: the ``default``
preset trained on each 3D built-in geometry, its corrected mesh at 30^3, 100^3 and 200^3 cells
against the converged elliptic mesh of the same dims (inverted cells, boundary deviation, mean
minimum angle), and the raw network's figures (boundary error, inverted cells) beside them.
The network is corrected against the boundary it was trained on (its checkpoint's
``boundary_layout``, ``smoothed`` for ``default``); the elliptic reference uses its own default
layout (``smoothed``), so both meshes put their boundary nodes on the same kind of surface grid.

    python benchmarks/bench_correction.py [--quick] [--json FILE] [--checkpoints DIR]

``--checkpoints DIR``: keep each geometry's trained checkpoint in DIR/<geometry>/ and reuse one
found there (the table can then be remade without training again). --quick: semicylinder only,
a capped training budget and 20^3 cells (a smoke test, not the figures to report).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # as meshgen train does, before torch is imported

GEOMETRIES = ["canal", "flower", "semicylinder", "topcurve"]  # the 3D built-ins (bump and semidisk are 2D)
DIMS = [30, 100, 200]
# Target: mean min angle within 0.3 degrees of the elliptic mesh's. Judged one-sided ("met"): at
# most 0.3 degrees below it, since a higher mean minimum angle on a valid mesh with an exact boundary
# is a better mesh, not a miss; "within" keeps the two-sided reading beside it.
ANGLE_TOLERANCE_DEGREES = 0.3
QUICK_OVERRIDES = ["pretrain.steps=10", "adam.steps=100", "lbfgs.steps=10"]


def trained_checkpoint(geometry, folder: Path | None, overrides) -> tuple[dict, float | None, float | None]:
    """``default`` trained on ``geometry`` (or the checkpoint kept in ``folder``): (checkpoint,
    training wall seconds, training CPU seconds of this process; both None when reused)."""
    from meshgen.neural.checkpoint import load_checkpoint
    from meshgen.neural.config import resolve_config
    from meshgen.neural.train import train

    if folder is not None and (folder / "checkpoint.pt").is_file():
        return load_checkpoint(folder / "checkpoint.pt"), None, None
    config = resolve_config("default", None, overrides)
    with tempfile.TemporaryDirectory() as temporary:
        run_dir = folder or Path(temporary)
        run_dir.mkdir(parents=True, exist_ok=True)
        start, cpu = time.perf_counter(), time.process_time()
        result = train(config, geometry, run_dir, summary=False)
        return result.checkpoint, time.perf_counter() - start, time.process_time() - cpu


def torch_threads() -> int:
    import torch

    return torch.get_num_threads()


def figures(report: dict) -> dict:
    deviation = report["boundary_deviation"]
    return {
        "inverted": report["inverted"]["count"],
        "min_angle_mean": report["metrics"]["min_angle"]["mean"],
        "max_angle_mean": report["metrics"]["max_angle"]["mean"],
        "boundary_deviation_max": deviation["max"],
        "boundary_deviation_max_rel": deviation["max_rel"],
    }


def measure(geometry, checkpoint: dict, n: int) -> dict:
    """The corrected network mesh and the converged elliptic mesh of ``n``^3 cells, measured alike:
    the network on the boundary layout it was trained on, elliptic on its default layout."""
    from meshgen.geometry.layout import trained_layout, with_layout
    from meshgen.methods.correction import correct_boundary
    from meshgen.methods.elliptic import elliptic
    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.network_map import mesh_from_model
    from meshgen.quality import quality_report

    trained = with_layout(geometry, trained_layout(checkpoint))  # the boundary map the network learnt
    coords = parametric_grid([n] * 3)
    start = time.perf_counter()
    X = mesh_from_model(checkpoint["model"], coords, trained)
    network_seconds = time.perf_counter() - start
    raw_inverted = quality_report(X)["inverted"]["count"]
    start = time.perf_counter()
    info = correct_boundary(X, trained, coords)
    correction_seconds = time.perf_counter() - start
    corrected = figures(quality_report(X, geometry))
    del X
    start = time.perf_counter()
    Y, solver = elliptic(geometry, [n] * 3)  # default layout: smoothed
    elliptic_seconds = time.perf_counter() - start
    reference = figures(quality_report(Y, geometry))
    del Y
    difference = corrected["min_angle_mean"] - reference["min_angle_mean"]
    return {
        "cells_per_axis": n,
        "network_seconds": network_seconds,
        "correction_seconds": correction_seconds,
        "raw_inverted": raw_inverted,
        "raw_boundary_error": info["error_before"],
        "corrected": corrected,
        "elliptic": {
            **reference,
            "seconds": elliptic_seconds,
            "iterations": solver["iterations"],
            "converged": bool(solver["converged"]),
        },
        "min_angle_mean_difference_degrees": difference,
        "within": bool(abs(difference) <= ANGLE_TOLERANCE_DEGREES),
        "met": bool(
            corrected["inverted"] == 0
            and corrected["boundary_deviation_max_rel"] < 1e-12
            and difference >= -ANGLE_TOLERANCE_DEGREES
        ),
    }


def run(
    quick: bool = False,
    checkpoints: Path | None = None,
    verbose: bool = True,
    partial: Path | None = None,
    geometries=None,
    dims=None,
) -> dict:
    """The whole table: {"rows": [...], "all_met": bool, ...}; see the module docstring.
    ``partial``: a JSON file rewritten after each row (what a long run has measured so far);
    ``geometries``, ``dims``: a part of the table only (default: all of it)."""
    from meshgen.geometry.plugins import load_geometry

    names = geometries or (["semicylinder"] if quick else GEOMETRIES)
    dims = dims or ([20] if quick else DIMS)
    overrides = QUICK_OVERRIDES if quick else []
    rows = []
    if verbose:
        print(
            f"default preset{' ' + ' '.join(overrides) if overrides else ''}; corrected mesh vs converged elliptic "
            f"(met: 0 inverted, boundary deviation < 1e-12 of the length, min angle difference >= "
            f"-{ANGLE_TOLERANCE_DEGREES} deg; within: |difference| <= {ANGLE_TOLERANCE_DEGREES})"
        )
        print(
            f"{'geometry':<13}{'cells':>6} {'train s':>8} {'raw err':>9} {'raw inv':>8} {'inverted':>9} "
            f"{'bdev rel':>9} {'min ang':>8} {'elliptic':>9} {'diff':>7}  met within",
            flush=True,
        )
    for name in names:
        geometry = load_geometry(name)
        folder = checkpoints / name if checkpoints is not None else None
        checkpoint, seconds, cpu_seconds = trained_checkpoint(geometry, folder, overrides)
        for n in dims:
            row = {
                "geometry": name,
                "training_seconds": seconds,
                "training_cpu_seconds": cpu_seconds,
                "torch_threads": torch_threads(),
                "steps": checkpoint["step"],
                **measure(geometry, checkpoint, n),
            }
            rows.append(row)
            if partial is not None:
                partial.write_text(json.dumps(rows, indent=2) + "\n")
            if verbose:
                c, e = row["corrected"], row["elliptic"]
                print(
                    f"{name:<13}{n:>5}^3 {seconds or 0:>8.1f} {row['raw_boundary_error']['max_rel']:>9.2e} "
                    f"{row['raw_inverted']:>8d} {c['inverted']:>9d} {c['boundary_deviation_max_rel']:>9.1e} "
                    f"{c['min_angle_mean']:>8.2f} {e['min_angle_mean']:>9.2f} {row['min_angle_mean_difference_degrees']:>+7.2f}  "
                    f"{'yes' if row['met'] else 'NO':>3} {'yes' if row['within'] else 'no':>6}",
                    flush=True,
                )
    return {
        "preset": "default",
        "overrides": overrides,
        "dims": dims,
        "geometries": names,
        "capped": quick,
        "angle_tolerance_degrees": ANGLE_TOLERANCE_DEGREES,
        "rows": rows,
        "all_met": all(r["met"] for r in rows),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a smoke test: semicylinder, capped training, 20^3")
    parser.add_argument("--json", type=Path, help="write the results to this JSON file")
    parser.add_argument("--checkpoints", type=Path, help="keep (and reuse) the trained checkpoints here")
    parser.add_argument("--geometries", nargs="+", choices=GEOMETRIES, help="these geometries only")
    parser.add_argument("--dims", nargs="+", type=int, help="these cells per axis only")
    parser.add_argument("--threads", type=int, help="torch threads (as meshgen train --threads; default: torch's)")
    args = parser.parse_args()
    if args.threads is not None:
        import torch

        torch.set_num_threads(args.threads)
    results = run(
        args.quick,
        args.checkpoints,
        partial=args.json.with_suffix(".partial.json") if args.json else None,
        geometries=args.geometries,
        dims=args.dims,
    )
    print(f"all met: {results['all_met']}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
