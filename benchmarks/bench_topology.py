"""Topology files against classy_blocks: its example scripts + blockMesh + checkMesh, and the same
layouts as meshgen topology files (TFI and elliptic) + checkMesh, in one run on one machine.

    python benchmarks/bench_topology.py [--classy-blocks DIR] [--json FILE] [--repeat N]

Rows, one per example (``EXAMPLES``): classy_blocks' script, read from a checkout of its
repository (``--classy-blocks DIR`` or ``CLASSY_BLOCKS_REPO``: its examples are not copied here),
run unchanged from a scratch folder so that its ``../case/system/blockMeshDict`` lands in a scratch
case, then ``blockMesh``; meshgen's topology file under examples/topologies/ through
``meshgen mesh --method tfi|elliptic --no-quality --format openfoam`` (checkMesh measures the
mesh). Per run: cells, checkMesh's max non-orthogonality (degrees) and max skewness, "Mesh OK",
seconds (wall clock of the processes: the script and blockMesh together; meshgen's command, its
imports included; the median of --repeat runs) and input lines (the file's lines that are not
blank and not only a comment; ``lines_total`` counts every line). An example without a topology
file yet has its meshgen rows ``None`` with the reason; without classy_blocks or blockMesh the
anchor rows are ``None`` with the reason (also without a checkout).

Targets per example: meshgen's cells within 10 % of the anchor's; its max non-orthogonality and
max skewness no worse than the anchor's; Mesh OK; fewer input lines; no slower; the elliptic
mesh's max non-orthogonality below the TFI's (the TFI of the same nodes is blockMesh's mesh).
"""

from __future__ import annotations

import argparse
import importlib.util
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

ROOT = Path(__file__).resolve().parents[1]
TOPOLOGIES = ROOT / "examples" / "topologies"
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "examples"))

from foam_case import foam_environment  # noqa: E402

from meshgen.formats._openfoam import FV_SCHEMES, FV_SOLUTION, foam_header  # noqa: E402

# name: (classy_blocks script in its repository, topology file under examples/topologies/ or None)
EXAMPLES = {
    "karman": ("examples/complex/karman.py", "karman-2d.yaml"),
    "elbow": ("examples/shape/elbow.py", "elbow-pipe-3d.yaml"),
    "t_joint": ("examples/assembly/t_joint.py", "t-joint-3d.yaml"),
}
METHODS = ("tfi", "elliptic")
CONTROL = "application blockMesh;\nstartFrom startTime;\nstartTime 0;\nstopAt endTime;\nendTime 1;\ndeltaT 1;\nwriteControl timeStep;\nwriteInterval 1;\n"  # fmt: skip


def input_lines(path: Path) -> tuple[int, int]:
    """(lines that are not blank and not only a comment, all lines) of a script or YAML file."""
    lines = path.read_text().splitlines()
    return sum(1 for line in lines if line.strip() and not line.strip().startswith("#")), len(lines)


def check_mesh(case: Path, env: dict) -> dict:
    """checkMesh's figures of ``case``: cells, max non-orthogonality, max skewness, Mesh OK."""
    text = subprocess.run(["checkMesh", "-case", str(case)], env=env, capture_output=True, text=True, timeout=600).stdout

    def number(pattern):
        found = re.search(pattern, text)
        return float(found[1]) if found else None

    cells = number(r"\n\s*cells:\s+(\d+)")
    failed = re.search(r"Failed (\d+) mesh checks", text)
    return {
        "cells": int(cells) if cells is not None else None,
        "max_non_orthogonality": number(r"Mesh non-orthogonality Max: ([0-9.eE+-]+)"),
        "max_skewness": number(r"Max skewness = ([0-9.eE+-]+)"),
        "mesh_ok": "Mesh OK" in text,
        "failed_checks": int(failed[1]) if failed else 0,
    }


def _timed(command, cwd, env) -> float:
    start = time.perf_counter()
    run = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    seconds = time.perf_counter() - start
    if run.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, command))} failed: {(run.stderr or run.stdout).strip()[-300:]}")
    return seconds


def anchor_missing(repo: Path | None) -> str | None:
    """Why the classy_blocks rows cannot run here, or None."""
    if repo is None or not all((repo / script).is_file() for script, _ in EXAMPLES.values()):
        return "no classy_blocks checkout with its examples (--classy-blocks DIR or CLASSY_BLOCKS_REPO)"
    if importlib.util.find_spec("classy_blocks") is None:
        return "classy_blocks is not installed (pip install classy_blocks)"
    if shutil.which("blockMesh") is None or shutil.which("checkMesh") is None:
        return "OpenFOAM's blockMesh/checkMesh are not installed"
    return None


def anchor_row(script: Path, env: dict, repeat: int) -> dict:
    """classy_blocks' ``script`` + blockMesh: seconds (median), checkMesh's figures, input lines."""
    runs = []
    with tempfile.TemporaryDirectory() as folder:
        work, case = Path(folder) / "work", Path(folder) / "case"
        work.mkdir()
        for name, text in (("controlDict", CONTROL), ("fvSchemes", FV_SCHEMES), ("fvSolution", FV_SOLUTION)):
            (case / "system").mkdir(parents=True, exist_ok=True)
            (case / "system" / name).write_text(foam_header("dictionary", "system", name) + text)
        for _ in range(repeat):
            shutil.rmtree(case / "constant", ignore_errors=True)
            seconds = _timed([sys.executable, str(script)], work, env)
            seconds += _timed(["blockMesh", "-case", str(case)], work, env)
            runs.append(seconds)
        row = check_mesh(case, env)
    lines, total = input_lines(script)
    return {**row, "seconds": statistics.median(runs), "runs_seconds": runs, "input_lines": lines, "lines_total": total}


def meshgen_row(topology: Path, method: str, env: dict, repeat: int) -> dict:
    """``meshgen mesh`` of the topology file with ``method`` into an OpenFOAM case: as ``anchor_row``."""
    runs = []
    env = {**env, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))}
    with tempfile.TemporaryDirectory() as folder:
        case = Path(folder) / "case"
        command = [sys.executable, "-m", "meshgen", "mesh", "-g", str(topology), "--method", method, "--no-quality"]
        for _ in range(repeat):
            shutil.rmtree(case, ignore_errors=True)
            runs.append(_timed([*command, "--format", "openfoam", "-o", str(case)], folder, env))
        row = check_mesh(case, env)
    lines, total = input_lines(topology)
    return {**row, "seconds": statistics.median(runs), "runs_seconds": runs, "input_lines": lines, "lines_total": total}


def verdict(anchor: dict | None, rows: dict) -> dict | None:
    """The targets of one example, each True/False (None where a row is missing)."""
    tfi, elliptic = rows.get("tfi"), rows.get("elliptic")
    if anchor is None or tfi is None:
        return None
    found = {}
    for method, row in rows.items():
        if row is None:
            continue
        found[method] = {
            "cells_within_10_percent": abs(row["cells"] / anchor["cells"] - 1.0) <= 0.1,
            "non_orthogonality_no_worse": row["max_non_orthogonality"] <= anchor["max_non_orthogonality"] + 1e-6,
            "skewness_no_worse": row["max_skewness"] <= anchor["max_skewness"] + 1e-6,
            "mesh_ok": row["mesh_ok"],
            "fewer_input_lines": row["input_lines"] < anchor["input_lines"],
            "no_slower": row["seconds"] <= anchor["seconds"],
        }
    if elliptic is not None:
        found["elliptic_lowers_non_orthogonality"] = elliptic["max_non_orthogonality"] < tfi["max_non_orthogonality"]
    return found


def run(repeat: int = 1, names=None, classy_blocks: Path | None = None) -> dict:
    env = foam_environment()
    repo = classy_blocks or (Path(os.environ["CLASSY_BLOCKS_REPO"]) if os.environ.get("CLASSY_BLOCKS_REPO") else None)
    missing = anchor_missing(repo)
    result = {"load_average": list(os.getloadavg()), "versions": versions(env), "examples": {}}
    for name, (script, topology) in EXAMPLES.items():
        if names and name not in names:
            continue
        entry: dict = {"anchor": None, "anchor_skipped": missing}
        if missing is None:
            entry["anchor"] = anchor_row(repo / script, env, repeat)
        for method in METHODS:
            if topology is None:
                entry[method], entry[f"{method}_skipped"] = None, "no topology file for this example yet"
            elif shutil.which("checkMesh") is None:
                entry[method], entry[f"{method}_skipped"] = None, "OpenFOAM's checkMesh is not installed"
            else:
                entry[method] = meshgen_row(TOPOLOGIES / topology, method, env, repeat)
        entry["targets"] = verdict(entry["anchor"], {m: entry[m] for m in METHODS})
        result["examples"][name] = entry
    return result


def versions(env: dict) -> dict:
    """classy_blocks' and OpenFOAM's versions (None where missing)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        classy = version("classy_blocks")
    except PackageNotFoundError:
        classy = None
    foam = env.get("WM_PROJECT_VERSION") or None
    return {"classy_blocks": classy, "openfoam": foam, "python": sys.version.split()[0]}


def table(result: dict) -> str:
    """The rows as a text table."""
    head = f"{'example':9} {'run':9} {'cells':>7} {'non-orth':>9} {'skewness':>9} {'OK':>3} {'seconds':>8} {'lines':>6}"
    out = [head, "-" * len(head)]
    for name, entry in result["examples"].items():
        for run_name in ("anchor", *METHODS):
            row = entry[run_name]
            label = "classy+bM" if run_name == "anchor" else run_name
            if row is None:
                why = entry.get("anchor_skipped" if run_name == "anchor" else f"{run_name}_skipped")
                out.append(f"{name:9} {label:9} skipped: {why}")
                continue
            out.append(
                f"{name:9} {label:9} {row['cells']:>7} {row['max_non_orthogonality']:>9.2f} {row['max_skewness']:>9.3f} "
                f"{'yes' if row['mesh_ok'] else 'NO':>3} {row['seconds']:>8.2f} {row['input_lines']:>6}"
            )
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, default=None, help="write the rows here as JSON")
    parser.add_argument("--repeat", type=int, default=3, help="runs per row; the median is reported (default 3)")
    parser.add_argument("--only", nargs="*", choices=sorted(EXAMPLES), help="these examples only")
    parser.add_argument("--classy-blocks", type=Path, default=None, help="a checkout of classy_blocks' repository")
    args = parser.parse_args()
    result = run(max(1, args.repeat), args.only, args.classy_blocks)
    print(f"classy_blocks {result['versions']['classy_blocks']}, OpenFOAM {result['versions']['openfoam']}")
    print(table(result))
    for name, entry in result["examples"].items():
        if entry["targets"]:
            print(f"{name}: {json.dumps(entry['targets'])}")
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
