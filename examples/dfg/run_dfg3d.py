"""The DFG 3D-1Z benchmark (Schaefer and Turek, 1996) on a meshgen topology file, solved with
OpenFOAM's simpleFoam: steady laminar flow past a cylinder spanning a square channel at Re = 20.

    python examples/dfg/run_dfg3d.py                       # refine 0.5 and 1: an error table
    python examples/dfg/run_dfg3d.py --refine 0.5 --json out.json
    python examples/dfg/run_dfg3d.py --refine 0.3 --iterations 20   # a smoke run

Channel [0, 2.5] x [0, 0.41] x [0, 0.41], cylinder D = 0.1 with its axis along z at (0.5, 0.2);
inflow U(y, z) = 16 Um y z (H - y)(H - z) / H^4 with Um = 0.45 (mean 0.2), nu = 1e-3 (Re = 20).
The mesh: ``meshgen mesh -g examples/topologies/dfg-3d-1z.yaml --param refine=R --format openfoam``
(60,640 cells at R = 1). The set-up is run_dfg.py's (laminar, SIMPLEC, linearUpwind), the inflow a
nonuniform fixedValue list at the inlet's face centres, walls (channel and cylinder) no-slip;
converged until the initial residuals are below 1e-9 (p) and 1e-10 (U). forceCoeffs on the cylinder with
magUInf = 0.2, lRef = D and Aref = D H: c = 2 F / (rho 0.2^2 D H). Reference: c_D = 6.18533,
c_L = 0.009401 (Schaefer and Turek, 3D-1Z).

Needs OpenFOAM (v1912 or later, the ESI syntax) on PATH or in /usr/share/openfoam.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from foam_case import foam_environment, history, last_row, poly_mesh, write  # noqa: E402
from run_dfg import D, solve, write_system  # noqa: E402

TOPOLOGY = Path(__file__).resolve().parents[1] / "topologies" / "dfg-3d-1z.yaml"
REFERENCE = {"drag": 6.18533, "lift": 0.009401}
HEIGHT, U_MAX, CENTRE = 0.41, 0.45, (0.5, 0.2)
WALLS = ("walls", "cylinder")
RESIDUALS = (1e-9, 1e-10)  # the initial residuals of p and U that end the run


def inflow(y, z):
    """The inflow speed U(y, z) = 16 Um y z (H - y)(H - z) / H^4 (m/s) at points y, z (m, any shape)."""
    return 16.0 * U_MAX * y * z * (HEIGHT - y) * (HEIGHT - z) / HEIGHT**4


def set_up(case: Path, end_time: int = 4000) -> dict:
    """0/, constant/ and system/ for simpleFoam on a meshed ``case``; returns the inlet's face count."""
    points, faces, boundary = poly_mesh(case)
    count, start = boundary["inlet"]
    centres = points[faces[start : start + count]].mean(axis=1)
    speed = inflow(centres[:, 1], centres[:, 2])
    profile = "nonuniform List<vector> {} (\n{}\n)".format(count, "\n".join(f"({u:.17g} 0 0)" for u in speed))
    walls = "".join(f"    {name} {{ type noSlip; }}\n" for name in WALLS)
    write(
        case / "0" / "U",
        "volVectorField",
        "dimensions [0 1 -1 0 0 0 0];\ninternalField uniform (0 0 0);\nboundaryField\n{\n"
        f"    inlet {{ type fixedValue; value {profile}; }}\n    outlet {{ type zeroGradient; }}\n{walls}}}\n",
    )
    walls = "".join(f"    {name} {{ type zeroGradient; }}\n" for name in WALLS)
    write(
        case / "0" / "p",
        "volScalarField",
        "dimensions [0 2 -2 0 0 0 0];\ninternalField uniform 0;\nboundaryField\n{\n"
        f"    inlet {{ type zeroGradient; }}\n    outlet {{ type fixedValue; value uniform 0; }}\n{walls}}}\n",
    )
    write_system(case, cofr=(*CENTRE, HEIGHT / 2), aref=D * HEIGHT, residuals=RESIDUALS, end_time=end_time)
    return {"inlet_faces": count}


def mesh(refine: float, method: str, case: Path) -> float:
    """The topology file meshed at ``refine`` into the OpenFOAM case ``case``; returns seconds."""
    start = time.perf_counter()
    meshed = subprocess.run(
        [sys.executable, "-m", "meshgen", "mesh", "-g", str(TOPOLOGY), "--param", f"refine={refine:g}", "--method", method,
         "--format", "openfoam", "-o", str(case), "--no-quality", "-q"],
        capture_output=True, text=True,
    )  # fmt: skip
    if meshed.returncode != 0:
        raise SystemExit(meshed.stderr)
    return time.perf_counter() - start


def run(refine: float = 0.5, method: str = "elliptic", case: Path = Path("dfg3d-case"), end_time: int = 4000,
        quiet: bool = False) -> dict:  # fmt: skip
    """Mesh, set up, solve; returns cells, seconds, iterations, c_D, c_L, their errors against the
    reference and their largest relative changes over the last 50 iterations."""
    env = foam_environment()
    if shutil.which("simpleFoam", path=env.get("PATH")) is None:
        raise SystemExit("simpleFoam not found: install OpenFOAM (Debian: apt install openfoam)")
    shutil.rmtree(case, ignore_errors=True)
    mesh_seconds = mesh(refine, method, case)
    set_up(case, end_time)
    solved = solve(case, env)
    forces = last_row(solved["coefficients"], ["Cd", "Cl"])
    changes = history(solved["coefficients"], ["Cd", "Cl"], 50)
    cells = int(re.search(r"nCells:\s*(\d+)", (case / "constant" / "polyMesh" / "owner").read_text())[1])
    result = {
        "refine": refine,
        "method": method,
        "cells": cells,
        "iterations": solved["iterations"],
        "converged": solved["converged"],
        "drag_change_last_50": changes["Cd"],
        "lift_change_last_50": changes["Cl"],
        "mesh_seconds": mesh_seconds,
        "solver_seconds": solved["solver_seconds"],
        "drag": forces["Cd"],
        "lift": forces["Cl"],
    }
    for key in ("drag", "lift"):
        result[f"{key}_error"] = result[key] / REFERENCE[key] - 1.0
    if not quiet:
        print(f"DFG 3D-1Z on dfg-3d-1z.yaml refine={refine:g} ({method}): {cells} cells, mesh {mesh_seconds:.1f} s, "
              f"simpleFoam {solved['iterations']} iterations in {solved['solver_seconds']:.0f} s "
              f"({'converged' if solved['converged'] else 'NOT converged'}; over the last 50 iterations c_D changed "
              f"by {changes['Cd']:.1e}, c_L by {changes['Cl']:.1e})")  # fmt: skip
    return result


def table(results: list[dict]) -> str:
    """The error table: one row per refinement level."""
    lines = [f"{'refine':>6} {'cells':>7} {'iter':>5} {'c_D':>9} {'error':>8} {'c_L':>10} {'error':>8}"]
    lines += [
        f"{r['refine']:6g} {r['cells']:7d} {r['iterations']:5d} {r['drag']:9.5f} {100 * r['drag_error']:+7.2f}% "
        f"{r['lift']:10.6f} {100 * r['lift_error']:+7.1f}%"
        for r in results
    ]
    lines.append(f"{'ref':>6} {'':>7} {'':>5} {REFERENCE['drag']:9.5f} {'':>8} {REFERENCE['lift']:10.6f}")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--refine", nargs="+", type=float, default=[0.5, 1.0], help="the topology's refine levels")
    parser.add_argument("--method", default="elliptic", choices=["tfi", "elliptic"])
    parser.add_argument("--case", default="dfg3d-case", type=Path, help="the case folder (one per level: NAME-R)")
    parser.add_argument("--iterations", type=int, default=4000, help="the most simpleFoam iterations")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    results = [
        run(refine, args.method, args.case.with_name(f"{args.case.name}-{refine:g}"), args.iterations) for refine in args.refine
    ]
    print(table(results))
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
