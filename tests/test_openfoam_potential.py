"""A real solver on meshgen's meshes: OpenFOAM's potentialFoam, uniform flow through the semicylinder.

Inflow U = (0, 0, 1) on the cap zeta0 (z = 0), outlet on zeta1 (z = L), slip walls elsewhere:
the exact answer is U = (0, 0, 1) in every cell. A finite-volume solver reproduces it on a mesh
whose cells are prisms along the flow (an extruded section); cells skewed along z (the fixed
layout's elliptic mesh: Coons caps, Winslow layers behind them) give errors of order one.
The mesh goes through Plot3D ASCII (.fmt) and ``plot3dToFoam -noBlank``; ``topoSet`` and
``createPatch`` cut the inlet and outlet out of its one boundary patch.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from meshgen.formats import write_mesh
from meshgen.methods.elliptic import elliptic

TOOLS = ("plot3dToFoam", "topoSet", "createPatch", "potentialFoam")
missing = [tool for tool in TOOLS if shutil.which(tool) is None]
pytestmark = pytest.mark.skipif(bool(missing), reason=f"OpenFOAM not installed ({', '.join(missing)} not on PATH)")

HEADER = "FoamFile {{ version 2.0; format ascii; class {cls}; object {name}; }}\n"
DICTIONARIES = {
    "system/controlDict": "application potentialFoam; startFrom startTime; startTime 0; stopAt endTime; endTime 1;\n"
    "deltaT 1; writeControl timeStep; writeInterval 1; writeFormat ascii; writePrecision 17;\n"
    "writeCompression off; timeFormat general; timePrecision 6; runTimeModifiable false;\n",
    "system/fvSchemes": "ddtSchemes { default steadyState; } gradSchemes { default Gauss linear; }\n"
    "divSchemes { default none; } laplacianSchemes { default Gauss linear corrected; }\n"
    "interpolationSchemes { default linear; } snGradSchemes { default corrected; }\n",
    "system/fvSolution": "solvers { Phi { solver PCG; preconditioner DIC; tolerance 1e-13; relTol 0; } }\n"
    "potentialFlow { nNonOrthogonalCorrectors 20; }\n",
    "system/topoSetDict": "actions (\n"
    " { name inletFaces; type faceSet; action new; source boxToFace; sourceInfo { box (-9 -9 -1e-6) (9 9 1e-6); } }\n"
    " { name outletFaces; type faceSet; action new; source boxToFace; sourceInfo { box (-9 -9 {below}) (9 9 {above}); } }\n"
    ");\n",
    "system/createPatchDict": "pointSync false; patches (\n"
    " { name inlet; patchInfo { type patch; } constructFrom set; set inletFaces; }\n"
    " { name outlet; patchInfo { type patch; } constructFrom set; set outletFaces; }\n);\n",
    "0/U": "dimensions [0 1 -1 0 0 0 0]; internalField uniform (0 0 0); boundaryField {\n"
    " inlet { type fixedValue; value uniform (0 0 1); } outlet { type zeroGradient; }\n"
    " defaultFaces { type slip; } }\n",
    "0/p": "dimensions [0 2 -2 0 0 0 0]; internalField uniform 0; boundaryField {\n"
    " inlet { type zeroGradient; } outlet { type fixedValue; value uniform 0; } defaultFaces { type zeroGradient; } }\n",
}


def _environment() -> dict:
    """OpenFOAM's tools need its etc folder; Debian's packages find it without a sourced bashrc
    when these two variables point at it."""
    env = dict(os.environ)
    if "WM_PROJECT_DIR" not in env and Path("/usr/share/openfoam/etc/controlDict").is_file():
        env["WM_PROJECT_DIR"] = "/usr/share/openfoam"
        env["FOAM_ETC"] = "/usr/share/openfoam/etc"
    return env


def _run(case: Path, *command: str) -> None:
    result = subprocess.run(command, cwd=case, env=_environment(), capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "FOAM FATAL" not in result.stdout, (command, result.stdout[-2000:], result.stderr[-2000:])


def _cell_velocities(path: Path) -> np.ndarray:
    text = path.read_text()
    body = text[text.index("internalField") :]
    count = int(body.split("\n")[1])
    rows = re.findall(r"\(([^()]*)\)", body.split("(", 1)[1])[:count]
    return np.array([[float(v) for v in row.split()] for row in rows])


def potential_flow_error(X: np.ndarray, length: float, case: Path) -> float:
    """max over cells of |U - (0, 0, 1)| from potentialFoam on the node array X (z from 0 to length)."""
    for name, text in DICTIONARIES.items():
        path = case / name
        path.parent.mkdir(parents=True, exist_ok=True)
        cls = {"0/U": "volVectorField", "0/p": "volScalarField"}.get(name, "dictionary")
        text = text.replace("{below}", f"{length - 1e-6!r}").replace("{above}", f"{length + 1e-6!r}")
        path.write_text(HEADER.format(cls=cls, name=path.name) + text)
    write_mesh(case / "mesh.fmt", X)
    _run(case, "plot3dToFoam", "-noBlank", "mesh.fmt")
    _run(case, "topoSet")
    _run(case, "createPatch", "-overwrite")
    boundary = (case / "constant/polyMesh/boundary").read_text()
    cap_faces = X.shape[0] - 1
    cap_faces *= X.shape[1] - 1
    for patch in ("inlet", "outlet"):  # the patches hold exactly one cap each
        assert re.search(rf"{patch}\s*\{{[^}}]*nFaces\s+{cap_faces};", boundary), boundary
    _run(case, "potentialFoam")
    U = _cell_velocities(case / "0/U")
    assert len(U) == np.prod([n - 1 for n in X.shape[:-1]])
    return float(np.linalg.norm(U - [0.0, 0.0, 1.0], axis=1).max())


def test_potential_flow_is_exact_on_the_smoothed_elliptic_mesh(tmp_path, semicylinder):
    dims = (8, 8, 8)
    X, info = elliptic(semicylinder, dims)
    assert info["boundary_layout"] == "smoothed"
    error = potential_flow_error(X, semicylinder.values["length"], tmp_path / "smoothed")
    assert error < 1e-3
    # The baseline that the test can tell apart: the fixed layout's mesh is far off.
    fixed, _ = elliptic(semicylinder, dims, boundary_layout="fixed")
    assert potential_flow_error(fixed, semicylinder.values["length"], tmp_path / "fixed") > 1e-2
