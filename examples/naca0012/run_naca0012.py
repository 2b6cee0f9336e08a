"""NASA TMR's 2D NACA 0012 validation case on a meshgen C-grid, solved with OpenFOAM's simpleFoam
and the Spalart-Allmaras model: lift and drag against the published values.

    python examples/naca0012/run_naca0012.py --alpha 10                 # level 0, print CL, CD, y+
    python examples/naca0012/run_naca0012.py --alpha 10 --level 1 --json out.json
    python examples/naca0012/run_naca0012.py --alpha 10 --case naca --no-mesh   # solve a case meshgen wrote

The TMR case (turbmodels.larc.nasa.gov, "2D NACA 0012 Airfoil Validation"): the NACA 0012 with a
sharp trailing edge (meshgen's ``tmr0012`` section), Re = 6e6 per chord, M = 0.15, alpha = 0, 10,
15 deg, SA with nu_tilde = 3 nu in the far field. simpleFoam is incompressible: U = 1, chord 1,
nu = 1/Re, the free stream turned by alpha (the airfoil stays put), far-field velocity and pressure
``freestream`` conditions, the wall ``noSlip`` with nut = nu_tilde = 0 (the first cells at y+ ~ 1:
no wall function). Second-order upwind convection (linearUpwind, unlimited gradients) for U and
nu_tilde, SIMPLEC with U relaxed by 0.9 and nu_tilde by 0.6 (at 0.8, CL and CD flip by 1.2e-5 and
1e-5 every other iteration for good, more than ``CHANGE``; at alpha 15 they flip so by 0.6 too,
2.4e-5 and 2.0e-5, and converge by 0.4: ``NU_TILDE_RELAXATION``), p by GAMG with the DIC-Gauss-Seidel
smoother (Gauss-Seidel took 56-84 cycles an iteration on the stretched wall cells: 4x slower).
Forces by ``forceCoeffs`` (lift square to the free stream, moments about the quarter chord).
simpleFoam runs in rounds of ``ROUND`` iterations until CL and CD change by less than ``CHANGE``
over the last ``WINDOW`` iterations (or ``--max-iterations``). At M = 0.15 compressibility raises
the lift by about 1 % (Prandtl-Glauert, 1 / sqrt(1 - M^2) = 1.0114): the table prints both.

Mesh: ``meshgen mesh -g airfoil`` (C-grid, elliptic: hyperbolic wall layer, elliptic outside),
the wall at y+ = 1 for Re 6e6 (``--yplus``) on level 0 (456 x 131 cells, 59,736), the far field
``FARFIELD`` = 1000 chords away (TMR's: 500; at 100 the missing far-field vortex cost 0.0035 in CL
and 6 counts of CD), the leading-edge spacing 0.001 chord (the geometry's default: 0.002),
``--level K`` scaling the cells per direction by 1.5^K and those lengths by (2/3)^K (DPW).
Needs OpenFOAM (v1912 or later, the ESI syntax) on PATH or in /usr/share/openfoam.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from foam_case import foam_environment, history, last_row, poly_mesh, write  # noqa: E402

REYNOLDS, MACH = 6e6, 0.15
NU = 1.0 / REYNOLDS  # U = 1, chord 1
NU_TILDE = 3.0 * NU  # TMR's far-field SA value
PRANDTL_GLAUERT = 1.0 / math.sqrt(1.0 - MACH**2)
NU_TILDE_RELAXATION = ((12.5, 0.4), (0.0, 0.6))  # (from |alpha| in degrees, nu_tilde's relaxation factor)
ROUND, WINDOW, CHANGE = 1000, 500, 1e-5  # a restart kicks CL, CD by up to 1e-5 for ~150 iterations: judge a round's last 500
# TMR, NACA 0012 at Re 6e6, M 0.15 (CFL3D on the finest grid; the range over eight codes at alpha 10).
REFERENCE = {
    0.0: {"CL": 0.0, "CD": 0.00819},
    10.0: {"CL": 1.0909, "CD": 0.01231, "CL_range": (1.0891, 1.1000), "CD_range": (0.01225, 0.01251)},
    15.0: {"CL": 1.5461, "CD": 0.02124},
}


def patch_types(case: Path) -> dict:
    """{patch name: OpenFOAM type} from the case's polyMesh/boundary."""
    text = (case / "constant" / "polyMesh" / "boundary").read_text()
    text = text[text.index("}", text.index("FoamFile")) + 1 :]
    return {name: re.search(r"type\s+(\w+)", entry)[1] for name, entry in re.findall(r"(\w+)\s*\{([^}]*)\}", text)}


def _field(case: Path, name: str, cls: str, dimensions: str, internal: str, rules: dict) -> None:
    """0/NAME: ``rules`` maps a patch type (wall, patch, empty) to its boundary entry."""
    entries = "".join(f"    {patch} {{ {rules[kind]} }}\n" for patch, kind in patch_types(case).items())
    write(case / "0" / name, cls, f"dimensions {dimensions};\ninternalField {internal};\nboundaryField\n{{\n{entries}}}\n")


def nu_tilde_relaxation(alpha: float) -> float:
    """nu_tilde's relaxation factor at incidence ``alpha`` degrees (``NU_TILDE_RELAXATION``)."""
    return next(factor for start, factor in NU_TILDE_RELAXATION if abs(alpha) >= start)


def set_up(case: Path, alpha: float, end_time: int) -> None:
    """0/, constant/ and system/ for simpleFoam with SA at ``alpha`` degrees, up to ``end_time``."""
    points = poly_mesh(case)[0]
    depth = float(points[:, 2].max() - points[:, 2].min())
    a = math.radians(alpha)
    u = f"({math.cos(a):.17g} {math.sin(a):.17g} 0)"
    empty = "type empty;"
    _field(case, "U", "volVectorField", "[0 1 -1 0 0 0 0]", f"uniform {u}",
           {"wall": "type noSlip;", "patch": f"type freestreamVelocity; freestreamValue uniform {u}; value uniform {u};",
            "empty": empty})  # fmt: skip
    _field(case, "p", "volScalarField", "[0 2 -2 0 0 0 0]", "uniform 0",
           {"wall": "type zeroGradient;", "patch": "type freestreamPressure; freestreamValue uniform 0; value uniform 0;",
            "empty": empty})  # fmt: skip
    _field(case, "nuTilda", "volScalarField", "[0 2 -1 0 0 0 0]", f"uniform {NU_TILDE:.17g}",
           {"wall": "type fixedValue; value uniform 0;",
            "patch": f"type freestream; freestreamValue uniform {NU_TILDE:.17g}; value uniform {NU_TILDE:.17g};",
            "empty": empty})  # fmt: skip
    chi3, cv1 = 27.0, 7.1
    nut = NU_TILDE * chi3 / (chi3 + cv1**3)  # SA's nu_t = nu_tilde f_v1(chi), chi = 3
    _field(case, "nut", "volScalarField", "[0 2 -1 0 0 0 0]", f"uniform {nut:.17g}",
           {"wall": "type fixedValue; value uniform 0;",
            "patch": f"type freestream; freestreamValue uniform {nut:.17g}; value uniform {nut:.17g};",
            "empty": empty})  # fmt: skip
    write(case / "constant" / "transportProperties", "dictionary", f"transportModel Newtonian;\nnu {NU:.17g};\n")
    write(case / "constant" / "turbulenceProperties", "dictionary",
          "simulationType RAS;\nRAS { RASModel SpalartAllmaras; turbulence on; printCoeffs off; }\n")  # fmt: skip
    walls = " ".join(name for name, kind in patch_types(case).items() if kind == "wall")
    write(
        case / "system" / "controlDict",
        "dictionary",
        f"application simpleFoam;\nstartFrom latestTime;\nstartTime 0;\nstopAt endTime;\nendTime {end_time};\ndeltaT 1;\n"
        f"writeControl timeStep;\nwriteInterval {end_time};\npurgeWrite 1;\nwriteFormat binary;\nwritePrecision 12;\n"
        "runTimeModifiable true;\nfunctions\n{\n"
        '    coefficients { type forceCoeffs; libs ("libforces.so"); writeControl timeStep; writeInterval 1;\n'
        f"        patches ({walls}); rho rhoInf; rhoInf 1; liftDir ({-math.sin(a):.17g} {math.cos(a):.17g} 0);\n"
        f"        dragDir ({math.cos(a):.17g} {math.sin(a):.17g} 0); CofR (0.25 0 0); pitchAxis (0 0 1);\n"
        f"        magUInf 1; lRef 1; Aref {depth:.17g}; }}\n"
        '    yPlus { type yPlus; libs ("libfieldFunctionObjects.so"); writeControl writeTime; }\n'
        "}\n",
    )
    write(
        case / "system" / "fvSchemes",
        "dictionary",
        "ddtSchemes { default steadyState; }\ngradSchemes { default Gauss linear; }\n"
        "divSchemes { default none; div(phi,U) bounded Gauss linearUpwind grad(U);\n"
        "    div(phi,nuTilda) bounded Gauss linearUpwind grad(nuTilda);\n"
        "    div((nuEff*dev2(T(grad(U))))) Gauss linear; }\n"
        "laplacianSchemes { default Gauss linear corrected; }\ninterpolationSchemes { default linear; }\n"
        "snGradSchemes { default corrected; }\nwallDist { method meshWave; }\n",
    )
    write(
        case / "system" / "fvSolution",
        "dictionary",
        "solvers\n{\n    p { solver GAMG; smoother DICGaussSeidel; tolerance 1e-10; relTol 0.1; }\n"
        '    "(U|nuTilda)" { solver smoothSolver; smoother symGaussSeidel; tolerance 1e-12; relTol 0.1; }\n}\n'
        "SIMPLE { consistent yes; nNonOrthogonalCorrectors 0; }\n"
        f"relaxationFactors {{ equations {{ U 0.9; nuTilda {nu_tilde_relaxation(alpha):g}; }} fields {{ p 1; }} }}\n",
    )


def coefficient_rows(case: Path) -> Path:
    """One table of every round's forceCoeffs rows (each restart writes its own folder)."""
    tables = sorted((case / "postProcessing" / "coefficients").glob("*/coefficient*.dat"), key=lambda p: float(p.parent.name))
    merged = case / "postProcessing" / "coefficients.dat"
    header = [line for line in tables[0].read_text().splitlines() if line.startswith("#")]
    rows = [line for table in tables for line in table.read_text().splitlines() if line.strip() and not line.startswith("#")]
    merged.write_text("\n".join(header + rows) + "\n")
    return merged


def wall_yplus(case: Path) -> dict:
    """min, max, average y+ on the walls at the last write (the yPlus function object's table)."""
    tables = sorted((case / "postProcessing" / "yPlus").glob("*/yPlus.dat"), key=lambda p: float(p.parent.name))
    rows = [line.split() for line in tables[-1].read_text().splitlines() if line.strip() and not line.startswith("#")]
    last = rows[-1]  # time patch min max average
    return {"min": float(last[2]), "max": float(last[3]), "average": float(last[4])}


DIMS = (456, 131)  # level 0: 59,736 cells (TMR's 449 x 129 grid has 57,344); 131: the fewest that reach FARFIELD
FARFIELD, LE_SPACING = 1000.0, 0.001  # chords: the far field's distance, the leading edge's spacing (level 0)


def mesh_command(dims, level: int, case: Path, extra=()) -> list[str]:
    """``meshgen mesh`` of the TMR section at y+ 1, the far field ``FARFIELD`` chords away (level 0;
    the airfoil's ``level`` scales the cells by 1.5 and every designed length by 2/3 per level, DPW's rule)."""
    return [sys.executable, "-m", "meshgen", "mesh", "-g", "airfoil", "--param", "sharp=1", "--yplus", "1",
            "--reynolds", f"{REYNOLDS:g}", "--param", f"level={level}", "--param", f"farfield={FARFIELD:g}",
            "--param", f"le_spacing={LE_SPACING:g}", "--dims", *map(str, dims), "--method", "elliptic",
            "--format", "openfoam", "-o", str(case), "--no-quality", "-q", *extra]  # fmt: skip


def run(
    alpha: float,
    level: int = 0,
    case: Path = Path("naca0012-case"),
    max_iterations: int = 20000,
    quiet=False,
    extra=(),
    dims=DIMS,
    mesh=True,
):
    """Mesh (not with ``mesh`` False: ``case`` holds the mesh already), check, set up, solve;
    returns cells, y+, CL, CD (and with Prandtl-Glauert), the reference and the convergence figures."""
    env = foam_environment()
    if shutil.which("simpleFoam", path=env.get("PATH")) is None:
        raise SystemExit("simpleFoam not found: install OpenFOAM (Debian: apt install openfoam)")
    start = time.perf_counter()
    if mesh:
        shutil.rmtree(case, ignore_errors=True)
        meshed = subprocess.run(mesh_command(dims, level, case, extra), capture_output=True, text=True)
        if meshed.returncode != 0:
            raise SystemExit(meshed.stderr)
    elif not (case / "constant" / "polyMesh" / "owner").is_file():
        raise SystemExit(f"{case}: no OpenFOAM mesh (meshgen mesh ... --format openfoam -o {case})")
    mesh_seconds = time.perf_counter() - start
    checked = subprocess.run(["checkMesh", "-case", str(case)], env=env, capture_output=True, text=True)
    step = min(ROUND, max_iterations)  # a round: ROUND iterations, or all of a shorter run
    set_up(case, alpha, step)
    control = case / "system" / "controlDict"
    start, iterations, changes = time.perf_counter(), 0, {"CL": math.inf, "CD": math.inf}
    while iterations < max_iterations:
        # the next round: only endTime changes (the case restarts from its latest time)
        control.write_text(re.sub(r"endTime \d+;", f"endTime {iterations + step};", control.read_text()))
        solved = subprocess.run(["simpleFoam", "-case", str(case)], env=env, capture_output=True, text=True)
        if solved.returncode != 0:
            raise SystemExit(solved.stdout[-3000:] + solved.stderr[-3000:])
        iterations += step
        table = coefficient_rows(case)
        if iterations > WINDOW:
            found = history(table, ["Cd", "Cl"], WINDOW, relative=False)
            changes = {"CD": found["Cd"], "CL": found["Cl"]}
            if max(changes.values()) < CHANGE:
                break
    solver_seconds = time.perf_counter() - start
    forces = last_row(table, ["Cd", "Cl"])
    cells = int(re.search(r"nCells:\s*(\d+)", (case / "constant" / "polyMesh" / "owner").read_text())[1])
    reference = REFERENCE.get(float(alpha), {})
    result = {
        "alpha": alpha,
        "level": level,
        "cells": cells,
        "check_mesh_ok": "Mesh OK" in checked.stdout,
        "iterations": iterations,
        "converged": max(changes.values()) < CHANGE,
        "change_last_window": changes,
        "mesh_seconds": mesh_seconds,
        "solver_seconds": solver_seconds,
        "CL": forces["Cl"],
        "CD": forces["Cd"],
        "CL_prandtl_glauert": forces["Cl"] * PRANDTL_GLAUERT,
        "yplus": wall_yplus(case),
        "reference": reference,
    }
    if not quiet:
        print(f"NACA 0012 (TMR) alpha {alpha:g}, level {level}: {cells} cells, mesh {mesh_seconds:.1f} s, checkMesh "
              f"{'OK' if result['check_mesh_ok'] else 'NOT OK'}, simpleFoam {iterations} iterations in {solver_seconds:.0f} s "
              f"({'converged' if result['converged'] else 'NOT converged'}: CL, CD changed by {changes['CL']:.1e}, "
              f"{changes['CD']:.1e} over the last {WINDOW})")  # fmt: skip
        print(f"  CL {result['CL']:.4f} (x Prandtl-Glauert at M 0.15: {result['CL_prandtl_glauert']:.4f})   "
              f"CD {result['CD']:.5f}   y+ average {result['yplus']['average']:.2f}, max {result['yplus']['max']:.2f}")  # fmt: skip
        if reference:
            print(f"  TMR (CFL3D, M 0.15): CL {reference['CL']:.4f}  CD {reference['CD']:.5f}")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--alpha", type=float, default=10.0, help="incidence, degrees (TMR: 0, 10, 15)")
    parser.add_argument("--level", type=int, default=0, help="grid level: cells per direction x 1.5^level")
    parser.add_argument("--dims", nargs=2, type=int, default=list(DIMS), metavar=("N", "M"), help="level 0's cells")
    parser.add_argument("--case", default="naca0012-case", type=Path)
    parser.add_argument("--max-iterations", type=int, default=20000)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument("--no-mesh", action="store_true", help="solve the mesh --case holds (a meshgen OpenFOAM case)")
    args = parser.parse_args()
    result = run(args.alpha, args.level, args.case, args.max_iterations, dims=tuple(args.dims), mesh=not args.no_mesh)
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
