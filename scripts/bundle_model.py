"""Train the model that meshgen ships for a geometry and record how it was made and how it meshes.

    python scripts/bundle_model.py [--geometry semicylinder] [--preset exact] [--set KEY=VALUE ...] [--seed 0] [--measure-only]

``--measure-only``: keep the bundled checkpoint and its training record, measure step 3 again
(after a change to how meshes are made from a model, e.g. the boundary correction).

1. ``meshgen train -g GEOMETRY --preset PRESET [--set KEY=VALUE ...] --seed SEED --out <temporary run folder>``;
2. the checkpoint, less its optimiser and scheduler state (only a resumed run needs them, and the
   L-BFGS history is most of the file), saved with meshgen's own ``save_checkpoint`` to
   ``meshgen/_models/GEOMETRY/checkpoint.pt``;
3. ``model.json`` beside it: the command, preset, versions, date, training seconds, and the quality
   of the model's 30^d and 100^d meshes, raw (--no-correct), corrected to N + TFI[g - N], and
   corrected and polished (the default; inverted cells, mean min angle, boundary deviation, cells inverted by the correction)
   next to TFI's and elliptic's at 30^d, all computed by
   ``meshgen.quality`` on the node arrays that ``meshgen mesh`` would write.
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def figures(X, geometry) -> dict:
    from meshgen.quality import quality_report

    report = quality_report(X, geometry)
    deviation = report["boundary_deviation"]
    return {
        "cells": report["cells"],
        "inverted": report["inverted"]["count"],
        "min_angle_mean": report["metrics"]["min_angle"]["mean"],
        "max_angle_mean": report["metrics"]["max_angle"]["mean"],
        "equiangle_skewness_mean": report["metrics"]["equiangle_skewness"]["mean"],
        "scaled_jacobian_min": report["metrics"]["scaled_jacobian"]["min"],
        "boundary_deviation_max": deviation["max"],
        "boundary_deviation_max_rel": deviation["max_rel"],
        "boundary_deviation_mean": deviation["mean"],
    }


def neural_figures(model, geometry, cells: int) -> dict:
    """Figures of the network's own mesh (--no-correct), of the corrected one (what ``meshgen mesh``
    gives by default for a network trained with the exact boundary on the smoothed layout's lattice,
    ``meshgen.methods.polish.polishes_by_default``) and of the corrected and polished one (--polish)."""
    from meshgen.geometry.layout import trained_layout, with_layout
    from meshgen.methods.correction import correct_boundary
    from meshgen.methods.polish import polish
    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.network_map import mesh_from_model

    geometry = with_layout(geometry, trained_layout(model.checkpoint))  # the boundary it learnt, as meshgen mesh does
    coords = parametric_grid([cells] * geometry.dim)
    start = time.perf_counter()
    X = mesh_from_model(model.checkpoint["model"], coords, geometry)
    seconds = time.perf_counter() - start
    raw = figures(X, geometry)
    correction = correct_boundary(X, geometry, coords, count_inverted=True)
    corrected = figures(X, geometry)
    start = time.perf_counter()
    polishing = polish(X, geometry, coords)
    polish_seconds = time.perf_counter() - start
    return {
        "dims": [cells] * geometry.dim,
        "meshing_seconds": seconds,
        "no_correction": raw,
        "corrected": corrected,
        "inverted_by_correction": correction["inverted_by_correction"],
        "polished": figures(X, geometry),
        "polish_seconds": polish_seconds,
        "polish_cycles": polishing["cycles"],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--geometry", default="semicylinder")
    parser.add_argument("--preset", default="exact")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a preset setting changed for this model, as meshgen train --set (repeatable)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--measure-only", action="store_true", help="keep the bundled checkpoint; measure its quality again")
    args = parser.parse_args()
    if args.measure_only:
        return measure_only(args.geometry)

    from meshgen.geometry.plugins import load_geometry
    from meshgen.neural.checkpoint import load_checkpoint
    from meshgen.neural.models import MODELS_DIR

    folder = MODELS_DIR / args.geometry
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as run_dir:
        settings = [word for setting in args.overrides for word in ("--set", setting)]
        command = [
            "meshgen",
            "train",
            "-g",
            args.geometry,
            "--preset",
            args.preset,
            *settings,
            "--seed",
            str(args.seed),
            "--out",
            "RUN",
            "-q",
        ]
        started = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", *[run_dir if c == "RUN" else c for c in command]],
            check=True,
            env={**__import__("os").environ, "PYTHONPATH": str(REPO)},
        )
        wall = time.perf_counter() - started
        checkpoint = load_checkpoint(Path(run_dir) / "checkpoint.pt")
    model, saved = bundle(checkpoint, folder, wall)
    geometry = load_geometry(args.geometry)

    record = {
        "geometry": args.geometry,
        "params": dict(geometry.values),
        "preset": args.preset,
        "settings": list(args.overrides),
        "command": " ".join(command).replace("RUN", "<run folder>"),
        "seed": args.seed,
        **saved,
        "exact_boundary": bool(checkpoint["model"]["exact_boundary"]),
        "made_by": "python scripts/bundle_model.py " + " ".join(sys.argv[1:]),
        "quality": quality(model, geometry),
    }
    write_record(folder, record)


def bundle(checkpoint: dict, folder: Path, wall) -> tuple:
    """Save ``checkpoint`` as ``folder/checkpoint.pt`` less its optimiser and scheduler state (only
    a resumed run needs them, and the L-BFGS history is most of the file); returns the bundled
    ``TrainedModel`` and the part of ``model.json`` every bundled model records (``wall``: the
    training command's wall seconds, or None)."""
    import torch

    from meshgen import __version__
    from meshgen.neural.checkpoint import save_checkpoint
    from meshgen.neural.models import load_model

    checkpoint["optimizer"], checkpoint["scheduler"] = {}, {}
    save_checkpoint(folder / "checkpoint.pt", checkpoint)
    model = load_model(folder / "checkpoint.pt", source="bundled")
    return model, {
        "post_processing": "optimizer and scheduler state removed (needed only to resume training); saved with meshgen.neural.checkpoint.save_checkpoint",
        "meshgen_version": __version__,
        "torch_version": torch.__version__,
        "date": datetime.date.today().isoformat(),
        "training_seconds": checkpoint["elapsed_seconds"],
        "training_wall_seconds": wall,
        "steps": checkpoint["step"],
        "widths": list(checkpoint["model"]["widths"]),
        "test_loss": checkpoint["test_loss"],
        "sha256": model.sha256(),
        "bytes": (folder / "checkpoint.pt").stat().st_size,
    }


def quality(model, geometry) -> dict:
    """Step 3: the model's meshes at 30^d and 100^d next to TFI's and elliptic's at 30^d."""
    from meshgen.methods.registry import make_mesh
    from meshgen.methods.tfi import parametric_grid

    coords = parametric_grid([30] * geometry.dim)
    classical = {method: figures(make_mesh(method, geometry, coords)[0], geometry) for method in ("tfi", "elliptic")}
    return {
        "definitions": "meshgen.quality (design notes §7); boundary deviation: closest-point distance of boundary nodes from the geometry",
        "neural_30": neural_figures(model, geometry, 30),
        "neural_100": neural_figures(model, geometry, 100),
        "tfi_30": classical["tfi"],
        "elliptic_30": classical["elliptic"],
    }


def measure_only(name: str) -> None:
    from meshgen.geometry.plugins import load_geometry
    from meshgen.neural.models import MODELS_DIR, load_model

    folder = MODELS_DIR / name
    record = json.loads((folder / "model.json").read_text())
    model = load_model(folder / "checkpoint.pt", source="bundled")
    record["quality"] = quality(model, load_geometry(name))
    record["measured_by"] = "python scripts/bundle_model.py " + " ".join(sys.argv[1:])
    write_record(folder, record)


def write_record(folder: Path, record: dict) -> None:
    (folder / "model.json").write_text(json.dumps(record, indent=2) + "\n")
    print(json.dumps({k: record[k] for k in ("command", "training_seconds", "bytes", "sha256")}, indent=2))
    for name, values in record["quality"].items():
        if name == "definitions":
            continue
        print(name, json.dumps(values))


if __name__ == "__main__":
    main()
