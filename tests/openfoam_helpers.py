"""Running OpenFOAM (Debian's ``openfoam`` package, v1912 or later) on cases meshgen writes: the
tools' environment, ``checkMesh`` parsed, and a potential-flow set-up (``0/`` and ``system/``)
written from the case's own ``boundary`` file, so nothing is edited by hand.

    from openfoam_helpers import needs_openfoam, check_mesh, write_potential_flow, run_tool

    report = check_mesh(case)                  # {"ok": bool, "patches": {name: faces}, "log": str}
    write_potential_flow(case, inlet="inlet", outlet="outlet", velocity=(0, 0, 1))
    result = run_tool("potentialFoam", case)   # CompletedProcess; result.stdout is the log
    U = read_vector_field(case / "0" / "U")    # (cells, 3)
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

BASHRC_CANDIDATES = ("/usr/share/openfoam/etc/bashrc", "/usr/lib/openfoam/openfoam/etc/bashrc")
FOAM_HEADER = """FoamFile
{{
    version     2.0;
    format      ascii;
    class       {class_name};
    object      {object_name};
}}
"""


@functools.lru_cache(maxsize=1)
def foam_environment() -> dict | None:
    """The environment OpenFOAM's bashrc sets up (None when OpenFOAM is not installed): computed
    once, then passed to every tool, so each call costs only the tool's own start."""
    if shutil.which("checkMesh") is None:
        return None
    bashrc = next((path for path in BASHRC_CANDIDATES if Path(path).is_file()), None)
    if bashrc is None:
        return dict(os.environ)  # a tool on PATH with its environment already set
    result = subprocess.run(["bash", "-c", f"source {bashrc} >/dev/null 2>&1; env -0"], capture_output=True, timeout=60)
    if result.returncode != 0:
        return None
    pairs = (item.split(b"=", 1) for item in result.stdout.split(b"\0") if b"=" in item)
    return {key.decode(): value.decode() for key, value in pairs}


def missing_reason() -> str | None:
    if shutil.which("checkMesh") is None or shutil.which("potentialFoam") is None:
        return "OpenFOAM (checkMesh, potentialFoam) not installed (Debian package openfoam)"
    if foam_environment() is None:
        return "OpenFOAM's bashrc could not be sourced"
    return None


needs_openfoam = pytest.mark.skipif(missing_reason() is not None, reason=missing_reason() or "needs OpenFOAM")


def run_tool(tool: str, case, *args, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run OpenFOAM's ``tool -case CASE ARGS`` with the OpenFOAM environment; stdout and stderr
    together in ``.stdout``."""
    return subprocess.run(
        [tool, "-case", str(case), *map(str, args)],
        env=foam_environment(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=timeout,
    )


def check_mesh(case) -> dict:
    """``checkMesh`` on ``case``: {"ok": "Mesh OK." printed and exit 0, "patches": {name: faces}
    from its patch-topology table, "cells": the cell count, "log": the output}."""
    result = run_tool("checkMesh", case)
    log = result.stdout
    table = log.split("Checking patch topology", 1)[-1].split("Checking faceZone", 1)[0]
    patches = {name: int(faces) for name, faces in re.findall(r"^\s{4}(\S+)\s+(\d+)\s+\d+\s+ok", table, re.M)}
    cells = re.search(r"^\s*cells:\s+(\d+)", log, re.M)
    return {
        "ok": result.returncode == 0 and "\nMesh OK." in log,
        "patches": patches,
        "cells": int(cells[1]) if cells else None,
        "log": log,
    }


def boundary_types(case) -> dict[str, str]:
    """Patch name -> type, from ``constant/polyMesh/boundary`` (as OpenFOAM reads it)."""
    text = (Path(case) / "constant" / "polyMesh" / "boundary").read_text()
    text = text[text.find("}", text.find("FoamFile")) + 1 :]
    return {name: re.search(r"type\s+(\w+);", body)[1] for name, body in re.findall(r"(\S+)\s*\{([^}]*)\}", text)}


def write_dict(path: Path, class_name: str, body: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(FOAM_HEADER.format(class_name=class_name, object_name=path.name) + body)


def write_potential_flow(case, inlet: str, outlet: str, velocity=(0.0, 0.0, 1.0), non_orthogonal_correctors: int = 10) -> None:
    """``system/`` (controlDict, fvSchemes, fvSolution) and ``0/`` (U, p) for ``potentialFoam``:
    U fixed to ``velocity`` on ``inlet``, p fixed to 0 on ``outlet``, slip on walls, and the
    constraint types (symmetry, empty) where the boundary file has them; any other patch zero
    gradient. Overwrites what the case has in those files."""
    case = Path(case)
    ux, uy, uz = velocity
    U, p = {}, {}
    for name, kind in boundary_types(case).items():
        if name == inlet:
            U[name], p[name] = f"type fixedValue; value uniform ({ux} {uy} {uz});", "type zeroGradient;"
        elif name == outlet:
            U[name], p[name] = "type zeroGradient;", "type fixedValue; value uniform 0;"
        elif kind == "wall":
            U[name], p[name] = "type slip;", "type zeroGradient;"
        elif kind in ("symmetry", "symmetryPlane", "empty"):
            U[name] = p[name] = f"type {kind};"
        else:
            U[name], p[name] = "type zeroGradient;", "type zeroGradient;"

    def field(entries, dimensions, internal):
        patches = "".join(f"    {name} {{ {entry} }}\n" for name, entry in entries.items())
        return f"dimensions {dimensions};\ninternalField uniform {internal};\nboundaryField\n{{\n{patches}}}\n"

    write_dict(case / "0" / "U", "volVectorField", field(U, "[0 1 -1 0 0 0 0]", "(0 0 0)"))
    write_dict(case / "0" / "p", "volScalarField", field(p, "[0 2 -2 0 0 0 0]", "0"))
    write_dict(
        case / "system" / "controlDict",
        "dictionary",
        "application potentialFoam;\nstartFrom startTime;\nstartTime 0;\nstopAt endTime;\nendTime 1;\n"
        "deltaT 1;\nwriteControl timeStep;\nwriteInterval 1;\nwriteFormat ascii;\nwritePrecision 12;\n",
    )
    write_dict(
        case / "system" / "fvSchemes",
        "dictionary",
        "ddtSchemes { default steadyState; }\ngradSchemes { default Gauss linear; }\n"
        "divSchemes { default none; div(div(phi,U)) Gauss linear; }\n"
        "laplacianSchemes { default Gauss linear corrected; }\ninterpolationSchemes { default linear; }\n"
        "snGradSchemes { default corrected; }\n",
    )
    write_dict(
        case / "system" / "fvSolution",
        "dictionary",
        "solvers\n{\n    Phi { solver PCG; preconditioner DIC; tolerance 1e-10; relTol 0; }\n"
        "    p { solver PCG; preconditioner DIC; tolerance 1e-10; relTol 0; }\n}\n"
        f"potentialFlow {{ nNonOrthogonalCorrectors {non_orthogonal_correctors}; }}\n",
    )


def read_vector_field(path) -> np.ndarray:
    """The internalField of an ASCII volVectorField: (cells, 3); a uniform one as (1, 3)."""
    text = Path(path).read_text()
    uniform = re.search(r"internalField\s+uniform\s+\(([^)]*)\)", text)
    if uniform:
        return np.array(uniform[1].split(), dtype=float).reshape(1, 3)
    match = re.search(r"internalField\s+nonuniform\s+List<vector>\s*(\d+)\s*\((.*?)\)\s*;", text, re.S)
    count, body = int(match[1]), match[2]
    return np.array(body.replace("(", " ").replace(")", " ").split(), dtype=float).reshape(count, 3)


def solver_residuals(log: str, field: str = "Phi") -> list[tuple[float, float]]:
    """(initial, final) residual of every solve of ``field`` in a solver log."""
    pattern = rf"Solving for {field}, Initial residual = ([^,]+), Final residual = ([^,]+),"
    return [(float(a), float(b)) for a, b in re.findall(pattern, log)]
