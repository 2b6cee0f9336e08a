"""The DFG 2D-1 benchmark (Schaefer and Turek, 1996) on a meshgen multi-block mesh, solved with
OpenFOAM's simpleFoam: steady laminar flow past a cylinder at Re = 20.

    python examples/dfg/run_dfg.py --dims 34 20            # mesh, solve, print drag, lift, dp
    python examples/dfg/run_dfg.py --dims 34 20 --json out.json --param wake_growth=1.5

Channel [0, 2.2] x [0, 0.41], cylinder D = 0.1 at (0.2, 0.2); inflow U(y) = 4 Um y (H - y) / H^2 with
Um = 0.3, nu = 1e-3 (mean velocity 0.2, Re = 20). The 2D mesh (``meshgen mesh -g dfg-cylinder
--format openfoam``) is one cell deep with ``empty`` front and back. Set-up: laminar, SIMPLEC,
second-order convection (linearUpwind), converged until the initial residuals are below 1e-9 (p)
and 1e-10 (U); forceCoeffs on the cylinder with magUInf = 0.2, lRef = D and Aref = D x depth
(c = 2 F / (rho 0.2^2 D) per unit depth). The pressure difference is p at the cylinder's front
(0.15, 0.2) minus p at its back (0.25, 0.2), each interpolated along the wall from the cylinder
faces' values (``wall_pressure``). Reference: c_D = 5.57953523384, c_L = 0.010618948146,
dp = 0.11752016697 (design notes §11).

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

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from foam_case import foam_environment, history, last_row, list_body, poly_mesh, write  # noqa: E402

REFERENCE = {"drag": 5.57953523384, "lift": 0.010618948146, "dp": 0.11752016697}
HEIGHT, U_MAX, NU, D, CENTRE = 0.41, 0.3, 1e-3, 0.1, (0.2, 0.2)


def wall_pressure(case: Path, time_name: str, angles) -> np.ndarray:
    """p on the cylinder at the polar ``angles`` (radians, about the centre (0.2, 0.2)): the
    cylinder faces' values (zero-gradient: their cells' p), interpolated along the wall by the
    quadratic through the three faces nearest in angle. The nearest face alone sits half a face
    away from a probe point, where p differs from the stagnation value by O(angle^2)."""
    points, faces, boundary = poly_mesh(case)
    count, start = boundary["cylinder"]
    owner = np.array(list_body(case / "constant" / "polyMesh" / "owner").split(), dtype=int)[start : start + count]
    pressure = np.array(list_body(case / time_name / "p").split(), dtype=float)[owner]
    centres = points[faces[start : start + count]].mean(axis=1)
    theta = np.arctan2(centres[:, 1] - CENTRE[1], centres[:, 0] - CENTRE[0])
    values = []
    for angle in angles:
        offset = np.angle(np.exp(1j * (theta - angle)))  # wrapped to (-pi, pi]
        nearest = np.argsort(np.abs(offset))[:3]
        t, v = offset[nearest], pressure[nearest]
        weights = [np.prod([(0.0 - t[j]) / (t[i] - t[j]) for j in range(3) if j != i]) for i in range(3)]
        values.append(float(np.dot(weights, v)))
    return np.array(values)


def set_up(case: Path) -> dict:
    """0/, constant/ and system/ for simpleFoam; returns the mesh's depth and cell count."""
    points, faces, boundary = poly_mesh(case)
    depth = float(points[:, 2].max() - points[:, 2].min())
    count, start = boundary["inlet"]
    y = points[faces[start : start + count]].mean(axis=1)[:, 1]
    inflow = 4.0 * U_MAX * y * (HEIGHT - y) / HEIGHT**2
    profile = "nonuniform List<vector> {} (\n{}\n)".format(count, "\n".join(f"({u:.17g} 0 0)" for u in inflow))
    write(
        case / "0" / "U",
        "volVectorField",
        "dimensions [0 1 -1 0 0 0 0];\ninternalField uniform (0 0 0);\nboundaryField\n{\n"
        f"    inlet {{ type fixedValue; value {profile}; }}\n"
        "    outlet { type zeroGradient; }\n    walls { type noSlip; }\n    cylinder { type noSlip; }\n"
        "    frontAndBack { type empty; }\n}\n",
    )
    write(
        case / "0" / "p",
        "volScalarField",
        "dimensions [0 2 -2 0 0 0 0];\ninternalField uniform 0;\nboundaryField\n{\n"
        "    inlet { type zeroGradient; }\n    outlet { type fixedValue; value uniform 0; }\n"
        "    walls { type zeroGradient; }\n    cylinder { type zeroGradient; }\n    frontAndBack { type empty; }\n}\n",
    )
    write_system(case, cofr=(*CENTRE, 0.0), aref=D * depth, residuals=(1e-9, 1e-10), end_time=5000)
    return {"depth": depth}


def write_system(case: Path, cofr, aref: float, residuals, end_time: int) -> None:
    """constant/ and system/ for laminar simpleFoam (SIMPLEC, linearUpwind) with forceCoeffs on the
    patch ``cylinder``: reference speed 0.2 m/s, length D, area ``aref`` (m^2), centre ``cofr`` (m);
    ``residuals``: the initial residuals (p, U) that stop the run before ``end_time`` iterations."""
    write(case / "constant" / "transportProperties", "dictionary", f"transportModel Newtonian;\nnu {NU};\n")
    write(case / "constant" / "turbulenceProperties", "dictionary", "simulationType laminar;\n")
    write(
        case / "system" / "controlDict",
        "dictionary",
        f"application simpleFoam;\nstartFrom startTime;\nstartTime 0;\nstopAt endTime;\nendTime {end_time};\ndeltaT 1;\n"
        f"writeControl timeStep;\nwriteInterval {end_time};\nwriteFormat ascii;\nwritePrecision 12;\nrunTimeModifiable false;\n"
        "functions\n{\n"
        '    coefficients { type forceCoeffs; libs ("libforces.so"); writeControl timeStep; writeInterval 1;\n'
        "        patches (cylinder); rho rhoInf; rhoInf 1; liftDir (0 1 0); dragDir (1 0 0);\n"
        f"        CofR ({' '.join(f'{c:.17g}' for c in cofr)}); pitchAxis (0 0 1); magUInf 0.2; lRef {D}; Aref {aref:.17g}; }}\n"
        "}\n",
    )
    write(
        case / "system" / "fvSchemes",
        "dictionary",
        "ddtSchemes { default steadyState; }\ngradSchemes { default Gauss linear; }\n"
        "divSchemes { default none; div(phi,U) bounded Gauss linearUpwind grad(U);\n"
        "    div((nuEff*dev2(T(grad(U))))) Gauss linear; }\n"
        "laplacianSchemes { default Gauss linear corrected; }\ninterpolationSchemes { default linear; }\n"
        "snGradSchemes { default corrected; }\n",
    )
    write(
        case / "system" / "fvSolution",
        "dictionary",
        "solvers\n{\n    p { solver GAMG; smoother GaussSeidel; tolerance 1e-12; relTol 0.01; }\n"
        "    U { solver smoothSolver; smoother symGaussSeidel; tolerance 1e-12; relTol 0.1; }\n}\n"
        f"SIMPLE {{ consistent yes; nNonOrthogonalCorrectors 1; residualControl {{ p {residuals[0]:g}; U {residuals[1]:g}; }} }}\n"
        'relaxationFactors { equations { U 0.9; ".*" 0.9; } }\n',
    )


def solve(case: Path, env: dict) -> dict:
    """simpleFoam on ``case``: seconds, iterations, whether the residual controls stopped it, and
    the forceCoeffs table (a Path)."""
    start = time.perf_counter()
    solved = subprocess.run(["simpleFoam", "-case", str(case)], env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if solved.returncode != 0:
        raise SystemExit(solved.stdout[-3000:] + solved.stderr[-3000:])
    return {
        "solver_seconds": seconds,
        "iterations": len(re.findall(r"^Time = ", solved.stdout, re.M)),
        "converged": "SIMPLE solution converged" in solved.stdout,
        "coefficients": next((case / "postProcessing" / "coefficients").glob("*/coefficient*.dat")),
    }


def run(dims, method: str = "elliptic", case: Path = Path("dfg-case"), quiet: bool = False, params=()) -> dict:
    """Mesh, set up, solve; returns cells, seconds (mesh, solver), drag, lift, dp, their errors and
    the convergence checks. ``params``: ``NAME=VALUE`` strings for meshgen's ``--param``."""
    env = foam_environment()
    if shutil.which("simpleFoam", path=env.get("PATH")) is None:
        raise SystemExit("simpleFoam not found: install OpenFOAM (Debian: apt install openfoam)")
    shutil.rmtree(case, ignore_errors=True)
    start = time.perf_counter()
    options = [item for value in params for item in ("--param", value)]
    meshed = subprocess.run(
        [sys.executable, "-m", "meshgen", "mesh", "-g", "dfg-cylinder", "--dims", *map(str, dims), *options, "--method", method,
         "--format", "openfoam", "-o", str(case), "--no-quality", "-q"],
        capture_output=True, text=True,
    )  # fmt: skip
    if meshed.returncode != 0:
        raise SystemExit(meshed.stderr)
    mesh_seconds = time.perf_counter() - start
    set_up(case)
    solved = solve(case, env)
    iterations, solver_seconds, coefficients = solved["iterations"], solved["solver_seconds"], solved["coefficients"]
    forces = last_row(coefficients, ["Cd", "Cl"])
    changes = history(coefficients, ["Cd", "Cl"], 50)
    last_time = max(
        (folder for folder in case.iterdir() if folder.name.isdigit() and folder.name != "0"), key=lambda f: int(f.name)
    )
    front, back = wall_pressure(case, last_time.name, [np.pi, 0.0])
    cells = int(re.search(r"nCells:\s*(\d+)", (case / "constant" / "polyMesh" / "owner").read_text())[1])
    result = {
        "dims": list(dims),
        "method": method,
        "params": list(params),
        "cells": cells,
        "iterations": iterations,
        "converged": solved["converged"],
        "drag_change_last_50": changes["Cd"],
        "lift_change_last_50": changes["Cl"],
        "mesh_seconds": mesh_seconds,
        "solver_seconds": solver_seconds,
        "drag": forces["Cd"],
        "lift": forces["Cl"],
        "dp": front - back,
    }
    for key in ("drag", "lift", "dp"):
        result[f"{key}_error"] = result[key] / REFERENCE[key] - 1.0
    if not quiet:
        print(f"DFG 2D-1 on dfg-cylinder --dims {' '.join(map(str, dims))} ({method}): {cells} cells, "
              f"mesh {mesh_seconds:.1f} s, simpleFoam {iterations} iterations in {solver_seconds:.1f} s "
              f"({'converged' if result['converged'] else 'NOT converged'}; over the last 50 iterations drag changed "
              f"by {changes['Cd']:.1e}, lift by {changes['Cl']:.1e})")  # fmt: skip
        for key, label in (("drag", "drag c_D"), ("lift", "lift c_L"), ("dp", "dp")):
            print(f"  {label:9s} {result[key]:.6g}   reference {REFERENCE[key]:.6g}   error {100 * result[key + '_error']:+.3f}%")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dims", nargs=2, type=int, default=[34, 20], metavar=("N", "M"))
    parser.add_argument("--method", default="elliptic", choices=["tfi", "elliptic"])
    parser.add_argument("--case", default="dfg-case", type=Path)
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="a dfg-cylinder parameter")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    result = run(args.dims, args.method, args.case, params=args.param)
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
