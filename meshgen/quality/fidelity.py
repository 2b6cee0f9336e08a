"""Solver fidelity: how far a finite-volume solver's answer on a mesh is from an exact flow.

``potential_flow_error(X, geometry, case)`` writes the node array as an OpenFOAM case with
meshgen's own writer (``meshgen.formats``, the geometry's patches, the starting fields the writer
makes), sets the inlet velocity to the exact flow's, runs ``potentialFoam`` and returns the
largest |U - U_exact| over the cells, U_exact at OpenFOAM's own cell centres
(``meshgen.quality.faces_openfoam.cell_centres``, the pyramid decomposition the solver uses).

Beside the U that potentialFoam writes, the same figure of the velocity reconstructed here from
the face fluxes it solved for (``-writephi``), by the least-squares reconstruction that OpenFOAM's
``fvc::reconstruct`` defines: U_P = (sum_f S_f S_f / |S_f|)^-1 sum_f S_f phi_f / |S_f|. On the
semicylinder both agree; on the canal, OpenFOAM v1912's written U is wrong in every other cell along
the tube (its fluxes are smooth), so the reconstructed figure is the one that measures the mesh.

Exact potential flows of the 3D built-ins (``EXACT_FLOWS``):

- ``semicylinder``: uniform U = (0, 0, 1) along the straight axis (walls and the symmetry plane
  are parallel to it; inlet z = 0, outlet z = length).
- ``canal``: the potential vortex about the y axis, U = (R / rho) e_phi with rho = sqrt(x^2 + z^2)
  and e_phi = (-z, 0, x) / rho: irrotational, divergence free, tangent to every surface of
  revolution about the y axis (the tube's wall) and normal to the planes phi = const (the inlet
  phi = 0 and the outlet phi = pi, where the potential R phi is constant). R = bend_radius, so the
  speed is 1 on the tube's centre line.

The other 3D built-ins (topcurve, flower, bump) have no closed-form potential flow.
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.formats import write_mesh
from meshgen.geometry.patches import geometry_patches
from meshgen.quality.faces_openfoam import cell_centres, face_centres_and_areas

__all__ = ["EXACT_FLOWS", "exact_velocity", "missing_openfoam", "potential_flow_error", "reconstructed_velocity"]

EXACT_FLOWS = ("semicylinder", "canal")
BASHRC_CANDIDATES = ("/usr/share/openfoam/etc/bashrc", "/usr/lib/openfoam/openfoam/etc/bashrc")


def exact_velocity(geometry, points: np.ndarray) -> np.ndarray:
    """The exact potential flow of ``geometry`` (a bound Geometry named in ``EXACT_FLOWS``) at
    ``points`` (N, 3): (N, 3) velocities, speed 1 on the inlet's centre."""
    points = np.asarray(points, dtype=float)
    if geometry.name == "semicylinder":
        return np.broadcast_to([0.0, 0.0, 1.0], points.shape).copy()
    if geometry.name == "canal":
        x, z = points[:, 0], points[:, 2]
        rho2 = x * x + z * z
        scale = float(geometry.values["bend_radius"]) / rho2
        return np.column_stack([-z * scale, np.zeros_like(x), x * scale])
    raise MeshgenError(f"no exact potential flow is known for geometry '{geometry.name}' (known: {', '.join(EXACT_FLOWS)})")


@functools.lru_cache(maxsize=1)
def _foam_environment() -> dict | None:
    if shutil.which("potentialFoam") is None:
        return None
    env = dict(os.environ)
    bashrc = next((path for path in BASHRC_CANDIDATES if Path(path).is_file()), None)
    if bashrc is not None and "WM_PROJECT_DIR" not in env:
        result = subprocess.run(["bash", "-c", f"source {bashrc} >/dev/null 2>&1; env -0"], capture_output=True, timeout=60)
        if result.returncode == 0:
            pairs = (item.split(b"=", 1) for item in result.stdout.split(b"\0") if b"=" in item)
            env = {key.decode(): value.decode() for key, value in pairs}
    return env


def missing_openfoam() -> str | None:
    """Why potentialFoam cannot run here (None when it can)."""
    if _foam_environment() is None:
        return "OpenFOAM's potentialFoam is not installed (Debian package openfoam)"
    return None


def _run(tool: str, case: Path, *args: str) -> str:
    result = subprocess.run(
        [tool, "-case", str(case), *args],
        env=_foam_environment(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=1800,
    )
    if result.returncode != 0 or "FOAM FATAL" in result.stdout:
        tail = " | ".join(result.stdout.strip().splitlines()[-6:])
        raise MeshgenError(f"{tool} failed on {case}: {tail}")
    return result.stdout


def _read_vectors(path: Path, count: int) -> np.ndarray:
    """The internalField of an ASCII volVectorField of ``count`` cells: (count, 3)."""
    text = path.read_text()
    uniform = re.search(r"internalField\s+uniform\s+\(([^)]*)\)", text)
    if uniform:
        return np.broadcast_to(np.array(uniform[1].split(), dtype=float), (count, 3)).copy()
    match = re.search(r"internalField\s+nonuniform\s+List<vector>\s*(\d+)\s*\((.*?)\)\s*;", text, re.S)
    values = np.array(match[2].replace("(", " ").replace(")", " ").split(), dtype=float).reshape(int(match[1]), 3)
    if len(values) != count:
        raise MeshgenError(f"{path}: {len(values)} cell values, expected {count}")
    return values


def _set_inlet_profile(case: Path, patch: str, velocities: np.ndarray) -> None:
    """Replace the inlet's boundary condition in ``case/0/U`` by a fixedValue of ``velocities``
    (one row per face of the patch, in the patch's face order)."""
    path = case / "0" / "U"
    text = path.read_text()
    rows = "\n".join(f"({u:.17g} {v:.17g} {w:.17g})" for u, v, w in velocities)
    entry = f"{patch}\n    {{\n        type fixedValue;\n        value nonuniform List<vector> {len(velocities)}\n(\n{rows}\n);\n    }}"
    text, count = re.subn(rf"\b{re.escape(patch)}\s*\{{[^{{}}]*\}}", lambda _: entry, text, count=1)
    if count != 1:
        raise MeshgenError(f"{path}: no entry for patch '{patch}'")
    path.write_text(text)


def _cap_face_centres(X: np.ndarray, side: int) -> np.ndarray:
    """OpenFOAM's face centres of the cap zeta = ``side``, in the writer's face order (C order of
    the face's (i, j))."""
    centres, _ = face_centres_and_areas(X, 2)
    return centres[:, :, -1 if side else 0].reshape(-1, 3)


def _foam_list(text: str, kind: str = "scalar") -> np.ndarray:
    """The first ``N ( ... )`` list of an ASCII OpenFOAM file's text: labels or scalars."""
    match = re.search(r"^(\d+)\s*\((.*?)^\)", text, re.S | re.M)
    values = np.array(match[2].split(), dtype=np.int64 if kind == "label" else float)
    if len(values) != int(match[1]):
        raise MeshgenError(f"an OpenFOAM list of {match[1]} entries has {len(values)}")
    return values


def _foam_rows(text: str) -> list[list[str]]:
    """The rows ``(a b c)`` of the first list of an ASCII OpenFOAM file (points, faces), as words."""
    match = re.search(r"^(\d+)\s*\(\s*$", text, re.M)
    rows = re.findall(r"\(([^()]*)\)", text[match.end() :])[: int(match[1])]
    return [row.split() for row in rows]


def _face_areas(case: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Area vectors (OpenFOAM's triangle fan), owners and neighbours of an ASCII quad polyMesh."""
    mesh = case / "constant" / "polyMesh"
    points = np.array(_foam_rows((mesh / "points").read_text()), dtype=float)
    faces = np.array(_foam_rows((mesh / "faces").read_text()), dtype=np.int64)
    corners = points[faces]  # (F, 4, 3)
    estimate = corners.mean(axis=1)
    areas = np.zeros_like(estimate)
    for m in range(4):
        areas += 0.5 * np.cross(corners[:, (m + 1) % 4] - corners[:, m], estimate - corners[:, m])
    owner = _foam_list((mesh / "owner").read_text(), "label")
    neighbour = _foam_list((mesh / "neighbour").read_text(), "label")
    return areas, owner, neighbour


def _face_fluxes(case: Path, faces: int, internal: int) -> np.ndarray:
    """potentialFoam's face fluxes (``0/phi``): internal faces, then each patch's in the order of
    ``constant/polyMesh/boundary``."""
    text = (case / "0" / "phi").read_text()
    flux = np.empty(faces)
    flux[:internal] = _foam_list(text[text.index("internalField") :])
    boundary = (case / "constant" / "polyMesh" / "boundary").read_text()
    fields = text[text.index("boundaryField") :]
    for name, count, start in re.findall(r"(\w+)\s*\{[^}]*?nFaces\s+(\d+);\s*startFace\s+(\d+);", boundary):
        entry = re.search(rf"\b{name}\s*\{{(.*?)\n    \}}", fields, re.S)[1]
        uniform = re.search(r"value\s+uniform\s+(\S+);", entry)
        part = slice(int(start), int(start) + int(count))
        flux[part] = float(uniform[1]) if uniform else _foam_list(entry[entry.index("List<scalar>") + 12 :])
    return flux


def reconstructed_velocity(case) -> np.ndarray:
    """Cell velocities (cells, 3) of an ASCII case from its ``0/phi`` by the least-squares
    reconstruction of OpenFOAM's ``fvc::reconstruct`` (module docstring)."""
    case = Path(case)
    areas, owner, neighbour = _face_areas(case)
    flux = _face_fluxes(case, len(areas), len(neighbour))
    cells = int(owner.max()) + 1
    magnitude = np.linalg.norm(areas, axis=1)
    unit = areas / magnitude[:, None]
    tensor = np.zeros((cells, 3, 3))
    vector = np.zeros((cells, 3))
    outer = unit[:, :, None] * areas[:, None, :]
    weighted = unit * flux[:, None]
    for cell_of_face, faces in ((owner, slice(None)), (neighbour, slice(0, len(neighbour)))):
        np.add.at(tensor, cell_of_face, outer[faces])
        np.add.at(vector, cell_of_face, weighted[faces])
    return np.linalg.solve(tensor, vector[..., None])[..., 0]


def potential_flow_error(X: np.ndarray, geometry, case) -> dict:
    """potentialFoam on node array ``X`` (n1+1, n2+1, n3+1, 3) of ``geometry`` (its patches: the
    inlet on zeta = 0, the outlet on zeta = 1), written to the new folder ``case`` with meshgen's
    OpenFOAM writer. The inlet gets the exact flow's velocity (uniform flows keep the writer's own
    inlet condition). Returns {"max": max over cells of |U - U_exact|, "mean", "p99",
    "worst_cell": (i, j, k) of the max, "cells": count, and "max_from_fluxes",
    "worst_cell_from_fluxes": the same of the velocity reconstructed from the solver's fluxes}. Raises MeshgenError when OpenFOAM is missing
    or a tool fails."""

    reason = missing_openfoam()
    if reason is not None:
        raise MeshgenError(reason)
    if X.ndim != 4:
        raise MeshgenError("solver fidelity is measured on 3D meshes")
    case = Path(case)
    patches = geometry_patches(geometry)
    write_mesh(case, X, patches=patches, format="openfoam", binary=False)
    inlet = next(patch.name for patch in patches if "zeta0" in patch.faces)
    if geometry.name != "semicylinder":
        _set_inlet_profile(case, inlet, exact_velocity(geometry, _cap_face_centres(X, 0)))
    _run("potentialFoam", case, "-writephi")
    cell_shape = tuple(n - 1 for n in X.shape[:-1])
    centres = cell_centres(X).reshape(-1, 3)
    U = _read_vectors(case / "0" / "U", len(centres))
    exact = exact_velocity(geometry, centres)
    error = np.linalg.norm(U - exact, axis=1)
    worst = int(np.argmax(error))
    reconstructed = np.linalg.norm(reconstructed_velocity(case) - exact, axis=1)
    return {
        "max_from_fluxes": float(reconstructed.max()),
        "worst_cell_from_fluxes": [int(i) for i in np.unravel_index(int(np.argmax(reconstructed)), cell_shape)],
        "max": float(error[worst]),
        "mean": float(error.mean()),
        "p99": float(np.percentile(error, 99.0)),
        "worst_cell": [int(i) for i in np.unravel_index(worst, cell_shape)],
        "cells": len(error),
    }
