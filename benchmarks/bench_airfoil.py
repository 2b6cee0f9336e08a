"""Airfoils to the wall (geometries/airfoil.py): NASA TMR's NACA 0012 as a C-grid at y+ 1.

    python benchmarks/bench_airfoil.py [--quick] [--json FILE]

``mesh``: ``meshgen.mesh("airfoil", dims=(448, 128), method="elliptic", sharp=1)`` (TMR's
449 x 129 points: 57,344 cells, y+ 1 at Re 6e6), seconds (median of 3 in a warm process, after a
first call), and at every wall node the first-cell height against the asked one, the angle of the
first grid line with the wall normal (trailing edge excepted), the largest wall-normal expansion
ratio against the cap 1.15, inverted cells; then OpenFOAM's checkMesh on the written case (max
non-orthogonality, max skewness, max aspect ratio, the failed checks; target "Mesh OK", the
aspect ratio under checkMesh's 1000: the wake cut's first cells grow downstream with the cut's,
and each surface's crest is a node, ``meshgen.geometry.airfoil_spacing``).
``simpleFoam`` (full run only, about 10 minutes on one core): ``examples/naca0012/run_naca0012.py``
at alpha 10 on that mesh: CL, CD, the wall's y+, against TMR's (CFL3D: CL 1.0909, CD 0.01231 at
M 0.15; simpleFoam is incompressible: CL x 1.0114 by Prandtl-Glauert is printed beside it).
Targets: CL within [1.075, 1.100], CD within [0.0120, 0.0130], y+ at most 1.5 on average and 5
at most, the mesh in at most 5 s.
``classy_blocks`` (the anchor): classy_blocks' example ``examples/complex/airfoil/airfoil.py``
(NACA 2414 at 10 deg in a box two chords long, 3,719 cells) run from a checkout of
damogranlabs/classy_blocks (``--classy-blocks DIR`` or ``CLASSY_BLOCKS_REPO``; skipped, with the
reason, without one or without the package), then blockMesh and checkMesh; beside it meshgen's
counterpart from the example's own coordinate file: ``meshgen mesh -g naca2414.dat --param
alpha=10 --param farfield=5 --param first_height=0.002 --param growth=1.2 --dims 100 37`` (3,700
cells, the first cell the example's 0.001 at chord 0.5) and checkMesh. The example is run from a
copy in a temporary folder with the fixes classy_blocks 1.10.0's own API needs (``optimize()``
takes no ``relax``; ``take="max"`` moved from ``grade()`` to ``SimpleGrader``). Seconds: the script
plus blockMesh against the meshgen command (both separate processes, imports included). Target:
max non-orthogonality and max skewness no worse than classy_blocks'.

``neural_rows`` (``--neural [CHECKPOINT]``): the same mesh by a trained wall-layer model
(``meshgen.neural.wall_map``): seconds (median of 3 after loading), mean minimum angle against the
elliptic mesh's of the same run, first-cell error, wall angle, inverted cells. Targets: at most 0.1 s,
within 0.5 deg of the elliptic mesh's mean minimum angle, the wall figures as the elliptic mesh's.
"""

from __future__ import annotations

import argparse
import importlib.util
import inspect
import json
import os
import re
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
PARAMS = {"sharp": 1}
CAP = 1.15


def wall_figures(made) -> dict:
    """Worst first-cell error, wall angle and expansion ratio over the blocks' wall nodes."""
    from meshgen.geometry import cube

    heights, angles, ratios, inverted = [], [], [], 0
    for (block, face_name), (patch, _) in made.geometry.patches.items():
        X = made.blocks[block]
        d1, d2 = X[1:, 1:] - X[:-1, :-1], X[:-1, 1:] - X[1:, :-1]
        inverted = max(inverted, int(np.count_nonzero(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0] <= 0)))
        if patch != "wall":
            continue
        face = cube.face_named(face_name, 2)
        assert face.axis == 1 and face.side == 0  # the wall is eta0
        wall, first = X[:, 0], X[:, 1]
        step = first - wall
        heights.append(np.linalg.norm(step, axis=-1))
        tangent = np.gradient(wall, axis=0)
        cosine = np.abs((step * tangent).sum(-1)) / (np.linalg.norm(step, axis=-1) * np.linalg.norm(tangent, axis=-1))
        angles.append(90.0 - np.degrees(np.arccos(np.clip(cosine, 0.0, 1.0)))[1:-1])  # its ends: the trailing edge
        edges = np.linalg.norm(np.diff(X, axis=1), axis=-1)
        ratios.append((edges[:, 1:] / edges[:, :-1]).max())
    from meshgen.geometry.wall_spacing import first_cell_height

    asked = first_cell_height(1.0, 6e6).height  # the airfoil's defaults: y+ 1 at Re 6e6
    height = np.concatenate(heights)
    return {
        "first_cell_height": float(np.median(height)),
        "first_cell_spread": float((height.max() - height.min()) / np.median(height)),
        "asked_height": asked,
        "first_cell_error": float(np.abs(height / asked - 1.0).max()),
        "worst_wall_angle_degrees": float(np.concatenate(angles).max()),
        "largest_expansion_ratio": float(max(ratios)),
        "inverted": inverted,
    }


def check_mesh(made) -> dict | None:
    """checkMesh's figures of the mesh written as an OpenFOAM case; None without OpenFOAM."""
    sys.path.insert(0, str(REPO / "examples"))
    from foam_case import foam_environment

    env = foam_environment()
    with tempfile.TemporaryDirectory() as folder:
        case = Path(folder) / "naca"
        made.write(case, "openfoam", quality=False)
        try:
            run = subprocess.run(["checkMesh", "-case", str(case)], env=env, capture_output=True, text=True, timeout=600)
        except FileNotFoundError:
            return None
    text = run.stdout

    def number(pattern):
        found = re.search(pattern, text)
        return float(found[1]) if found else None

    failed = re.search(r"Failed (\d+) mesh checks", text)
    return {
        "mesh_ok": "Mesh OK" in text,
        "failed_checks": int(failed[1]) if failed else 0,
        "max_non_orthogonality": number(r"Mesh non-orthogonality Max: ([0-9.eE+-]+)"),
        "max_skewness": number(r"Max skewness = ([0-9.eE+-]+)"),
        "max_aspect_ratio": number(r"Max aspect ratio(?::| =) ([0-9.eE+-]+)"),  # ": " where the check fails
    }


def mesh_rows(repeat: int) -> dict:
    import meshgen

    meshgen.mesh("airfoil", dims=DIMS, method="elliptic", params=PARAMS)  # first call: imports, caches
    runs, made = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        made = meshgen.mesh("airfoil", dims=DIMS, method="elliptic", params=PARAMS)
        runs.append(time.perf_counter() - start)
    cells = sum(int(np.prod([n - 1 for n in X.shape[:-1]])) for X in made.blocks)
    row = {"dims": list(DIMS), "cells": cells, "seconds": statistics.median(runs), "runs_seconds": runs, **wall_figures(made)}
    row["check_mesh"] = check_mesh(made)
    print(f"airfoil C-grid {DIMS[0]} x {DIMS[1]} ({cells} cells): {row['seconds']:.2f} s; first cell {row['first_cell_height']:.3e} "
          f"(spread {row['first_cell_spread']:.1e}), worst wall angle {row['worst_wall_angle_degrees']:.2f} deg, largest "
          f"expansion ratio {row['largest_expansion_ratio']:.4f}, {row['inverted']} inverted", flush=True)  # fmt: skip
    if row["check_mesh"]:
        cm = row["check_mesh"]
        print(f"  checkMesh: max non-orthogonality {cm['max_non_orthogonality']}, max skewness {cm['max_skewness']}, "
              f"max aspect ratio {cm['max_aspect_ratio']}, "
              f"{'Mesh OK' if cm['mesh_ok'] else str(cm['failed_checks']) + ' failed check(s)'}", flush=True)  # fmt: skip
    return row


CLASSY_EXAMPLE = Path("examples") / "complex" / "airfoil"
CLASSY_MESHGEN = ["--param", "alpha=10", "--param", "farfield=5", "--param", "first_height=0.002", "--param", "growth=1.2"]
CLASSY_DIMS = ("100", "37")
CONTROL_DICT = """FoamFile { version 2.0; format ascii; class dictionary; object controlDict; }
application blockMesh; startFrom startTime; startTime 0; stopAt endTime; endTime 1; deltaT 1;
writeControl timeStep; writeInterval 1;
"""
FV_DICTS = {  # checkMesh reads both: empty ones do
    "fvSchemes": "FoamFile { version 2.0; format ascii; class dictionary; object fvSchemes; }\n"
    "ddtSchemes {} gradSchemes {} divSchemes {} laplacianSchemes {} interpolationSchemes {} snGradSchemes {}\n",
    "fvSolution": "FoamFile { version 2.0; format ascii; class dictionary; object fvSolution; }\nsolvers {}\n",
}


def check_mesh_case(case: Path, env: dict) -> dict:
    """checkMesh's cells, max non-orthogonality, max skewness and verdict of an OpenFOAM case."""
    text = subprocess.run(["checkMesh", "-case", str(case)], env=env, capture_output=True, text=True, timeout=600).stdout

    def number(pattern):
        found = re.search(pattern, text)
        return float(found[1]) if found else None

    return {
        "cells": int(number(r"cells:\s+(\d+)") or 0),
        "max_non_orthogonality": number(r"Mesh non-orthogonality Max: ([0-9.eE+-]+)"),
        "max_skewness": number(r"Max skewness = ([0-9.eE+-]+)"),
        "mesh_ok": "Mesh OK" in text,
    }


def fixed_example(text: str) -> tuple[str, list[str]]:
    """The example's text with the fixes the installed classy_blocks needs, and what they were."""
    import classy_blocks as cb

    fixes = []
    if "relax" not in inspect.signature(cb.SketchOptimizer.optimize).parameters and ", relax=True)" in text:
        text = text.replace(", relax=True)", ")")
        fixes.append("optimize(relax=True) -> optimize()")
    if "take" in inspect.signature(cb.SimpleGrader).parameters and 'grade(take="max")' in text:
        text = text.replace("cb.SimpleGrader(mesh, CELL_SIZE)", 'cb.SimpleGrader(mesh, CELL_SIZE, take="max")')
        text = text.replace('grade(take="max")', "grade()")
        fixes.append('grade(take="max") -> SimpleGrader(..., take="max").grade()')
    return text, fixes


def classy_blocks_rows(repo: Path | None) -> dict:
    """classy_blocks' NACA 2414 example (blockMesh, checkMesh) and meshgen's counterpart (checkMesh)."""
    sys.path.insert(0, str(REPO / "examples"))
    from foam_case import foam_environment

    if shutil.which("checkMesh") is None:
        return {"skipped": "OpenFOAM (blockMesh, checkMesh) not installed"}
    env = foam_environment()
    example = repo / CLASSY_EXAMPLE if repo is not None else None
    result = {}
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        data = example / "naca2414.dat" if example is not None and (example / "naca2414.dat").is_file() else None
        spec = ["-g", str(data)] if data is not None else ["-g", "airfoil", "--param", "naca=2414"]
        command = [sys.executable, "-m", "meshgen", "mesh", *spec, *CLASSY_MESHGEN, "--dims", *CLASSY_DIMS, "-m", "elliptic"]
        command += ["--no-quality", "-o", str(folder / "meshgen"), "--format", "openfoam"]
        start = time.perf_counter()
        made = subprocess.run(command, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
        seconds = time.perf_counter() - start
        if made.returncode != 0:
            raise RuntimeError(made.stderr)
        result["meshgen"] = {
            "command": " ".join(["meshgen", *command[3:]]),
            "seconds": seconds,
            **check_mesh_case(folder / "meshgen", env),
        }
        if importlib.util.find_spec("classy_blocks") is None:
            result["skipped"] = "classy_blocks not installed (pip install classy_blocks)"
        elif example is None or not (example / "airfoil.py").is_file():
            result["skipped"] = (
                "no classy_blocks checkout with examples/complex/airfoil (--classy-blocks DIR or CLASSY_BLOCKS_REPO)"
            )
        else:
            from importlib.metadata import version

            work = folder / "classy" / CLASSY_EXAMPLE
            work.mkdir(parents=True)
            shutil.copy(example / "naca2414.dat", work)
            text, fixes = fixed_example((example / "airfoil.py").read_text())
            (work / "airfoil.py").write_text(text)
            case = folder / "classy" / "examples" / "case"
            (case / "system").mkdir(parents=True)
            for name, text in {"controlDict": CONTROL_DICT, **FV_DICTS}.items():
                (case / "system" / name).write_text(text)
            start = time.perf_counter()
            script = subprocess.run([sys.executable, "airfoil.py"], cwd=work, capture_output=True, text=True)
            script_seconds = time.perf_counter() - start
            if script.returncode != 0:
                raise RuntimeError(script.stderr[-2000:])
            start = time.perf_counter()
            subprocess.run(["blockMesh", "-case", str(case)], env=env, capture_output=True, text=True, check=True)
            block_mesh_seconds = time.perf_counter() - start
            result["classy_blocks"] = {
                "version": version("classy_blocks"), "fixes": fixes, "script_seconds": script_seconds,
                "blockmesh_seconds": block_mesh_seconds, "seconds": script_seconds + block_mesh_seconds, **check_mesh_case(case, env),
            }  # fmt: skip
    for name, row in ((n, result.get(n)) for n in ("classy_blocks", "meshgen")):
        if row:
            print(f"NACA 2414 alpha 10, {name}: {row['cells']} cells, checkMesh max non-orthogonality {row['max_non_orthogonality']}, "
                  f"max skewness {row['max_skewness']}, {row['seconds']:.2f} s", flush=True)  # fmt: skip
    if "skipped" in result:
        print(f"NACA 2414 alpha 10, classy_blocks: skipped: {result['skipped']}", flush=True)
    return result


def solver_row() -> dict:
    sys.path.insert(0, str(REPO / "examples" / "naca0012"))
    from run_naca0012 import run

    with tempfile.TemporaryDirectory() as folder:
        return run(10.0, 0, Path(folder) / "case")


def _median_seconds(call, repeat: int) -> tuple[float, list]:
    runs = []
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        runs.append(time.perf_counter() - start)
    return statistics.median(runs), runs


def neural_rows(checkpoint=None, preset: str = "default", repeat: int = 3) -> dict:
    """The neural C-grid (``meshgen.neural.wall_map``) at DIMS: a model trained with ``preset`` (``meshgen
    train -g airfoil --param sharp=1``, timed) unless ``checkpoint`` is given; after loading it and a
    first call, the median of ``repeat`` meshes: ``seconds`` (network and the airfoil's finish,
    ``neural_blocks``), ``request_seconds`` (``meshgen.mesh``, the block set and checks included),
    the forward pass alone in float32 and float64; the mean minimum angle against the elliptic
    mesh's in the same run, the first-cell error and the wall angle at every wall node, inverted cells."""
    import meshgen
    from meshgen.geometry.blocks import load_block_set
    from meshgen.neural import wall_map
    from meshgen.neural.inference import neural_blocks
    from meshgen.neural.models import load_model

    row = {"dims": list(DIMS), "preset": None if checkpoint else preset}
    with tempfile.TemporaryDirectory() as folder:
        if checkpoint is None:
            checkpoint = Path(folder) / "run" / "checkpoint.pt"
            command = [sys.executable, "-m", "meshgen", "train", "-g", "airfoil", "--param", "sharp=1", "-p", preset]
            start = time.perf_counter()
            subprocess.run([*command, "--out", str(checkpoint.parent), "-q"], check=True, capture_output=True,
                           env={**os.environ, "PYTHONPATH": str(REPO)})  # fmt: skip
            row["train_wall_seconds"] = time.perf_counter() - start
        model = load_model(checkpoint)
        row["training_seconds"] = float(model.checkpoint["elapsed_seconds"])
        row["held_out_misfit"] = float(model.checkpoint["test_loss"]["total"])
        block_set = load_block_set("airfoil", PARAMS, DIMS)
        description = model.checkpoint["model"]
        neural_blocks(block_set, description)  # first call: caches
        row["seconds"], row["runs_seconds"] = _median_seconds(lambda: neural_blocks(block_set, description), repeat)
        made = meshgen.mesh("airfoil", DIMS, method="neural", params=PARAMS, model=model)
        row["request_seconds"] = _median_seconds(
            lambda: meshgen.mesh("airfoil", DIMS, method="neural", params=PARAMS, model=model), repeat
        )[0]
        frame = wall_map.wall_frame(
            block_set, wall_map.wall_hooks(block_set).wall_layout(block_set.values), description["tables"]
        )
        inputs = [wall_map.network_inputs(q, frame.d, description["scales"]) for q in frame.q]
        layers = wall_map.network_layers(description)
        doubled = [(w.astype(np.float64), b.astype(np.float64)) for w, b in layers]
        row["forward_float32_seconds"] = _median_seconds(lambda: [wall_map.forward(layers, x) for x in inputs], repeat)[0]
        row["forward_float64_seconds"] = _median_seconds(
            lambda: [wall_map.forward_with(doubled, x, np.float64) for x in inputs], repeat
        )[0]
    elliptic = meshgen.mesh("airfoil", DIMS, method="elliptic", params=PARAMS)
    row["cells"] = sum(int(np.prod([n - 1 for n in X.shape[:-1]])) for X in made.blocks)
    row["mean_min_angle"] = made.report()["metrics"]["min_angle"]["mean"]
    row["elliptic_mean_min_angle"] = elliptic.report()["metrics"]["min_angle"]["mean"]
    row["min_angle_below_elliptic"] = row["elliptic_mean_min_angle"] - row["mean_min_angle"]
    row.update(wall_figures(made))
    print(f"airfoil neural C-grid {DIMS[0]} x {DIMS[1]} ({row['cells']} cells): {row['seconds']:.3f} s "
          f"(meshgen.mesh {row['request_seconds']:.3f} s; forward float32 {row['forward_float32_seconds']:.3f} s, float64 "
          f"{row['forward_float64_seconds']:.3f} s); mean min angle {row['mean_min_angle']:.2f} deg, elliptic "
          f"{row['elliptic_mean_min_angle']:.2f}; first-cell error {row['first_cell_error']:.2e}, worst wall angle "
          f"{row['worst_wall_angle_degrees']:.3f} deg, {row['inverted']} inverted; trained in {row['training_seconds']:.0f} s",
          flush=True)  # fmt: skip
    return row


def run(quick: bool, classy_blocks: Path | None = None) -> dict:
    """The mesh rows and the classy_blocks anchor; a full run also trains the neural C-grid
    (``neural_rows``, minutes) and runs simpleFoam (about an hour)."""
    result = {"load_average": list(os.getloadavg()), "mesh": mesh_rows(1 if quick else 3)}
    repo = classy_blocks or (Path(os.environ["CLASSY_BLOCKS_REPO"]) if os.environ.get("CLASSY_BLOCKS_REPO") else None)
    result["classy_blocks"] = classy_blocks_rows(repo)
    if not quick:
        result["neural"] = neural_rows()
        result["simplefoam_alpha_10"] = solver_row()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the mesh rows only (the solver runs for about an hour)")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--classy-blocks", type=Path, default=None, help="a checkout of damogranlabs/classy_blocks")
    parser.add_argument("--neural", nargs="?", const="", default=None, metavar="CHECKPOINT",
                        help="the neural rows only (neural_rows), of CHECKPOINT or of a model trained now")  # fmt: skip
    args = parser.parse_args()
    if args.neural is not None:
        result = {"load_average": list(os.getloadavg()), "neural": neural_rows(args.neural or None)}
    else:
        result = run(args.quick, args.classy_blocks)
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
