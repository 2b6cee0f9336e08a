"""OpenFOAM case helpers shared by the examples (``examples/dfg``, ``examples/naca0012``): the
OpenFOAM environment, dictionary files, an ASCII polyMesh read back, function-object tables.
"""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import numpy as np

__all__ = ["BASHRC", "HEADER", "foam_environment", "history", "last_row", "list_body", "poly_mesh", "write"]

HEADER = "FoamFile {{ version 2.0; format ascii; class {cls}; object {name}; }}\n"
BASHRC = ("/usr/share/openfoam/etc/bashrc", "/usr/lib/openfoam/openfoam/etc/bashrc")


def foam_environment() -> dict:
    bashrc = next((path for path in BASHRC if Path(path).is_file()), None)
    if bashrc is None:
        return dict(os.environ)
    result = subprocess.run(["bash", "-c", f"source {bashrc} >/dev/null 2>&1; env -0"], capture_output=True, check=True)
    pairs = (item.split(b"=", 1) for item in result.stdout.split(b"\0") if b"=" in item)
    return {key.decode(): value.decode() for key, value in pairs}


def write(path: Path, cls: str, body: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(HEADER.format(cls=cls, name=path.name) + body)


def poly_mesh(case: Path):
    """(points (N, 3), faces (F, 4), boundary {name: (nFaces, startFace)}) of an ASCII polyMesh."""
    folder = case / "constant" / "polyMesh"

    def body(name):
        text = (folder / name).read_text()
        text = text[text.index("}", text.index("FoamFile")) + 1 :]
        return text[text.index("(") + 1 : text.rindex(")")]

    points = np.array(body("points").replace("(", " ").replace(")", " ").split(), dtype=float).reshape(-1, 3)
    faces = np.array(re.sub(r"\d+\(", " ", body("faces")).replace(")", " ").split(), dtype=int).reshape(-1, 4)
    text = (folder / "boundary").read_text()
    boundary = {
        name: (int(re.search(r"nFaces\s+(\d+)", entry)[1]), int(re.search(r"startFace\s+(\d+)", entry)[1]))
        for name, entry in re.findall(r"(\w+)\s*\{([^}]*)\}", text[text.index("}", text.index("FoamFile")) + 1 :])
    }
    return points, faces, boundary


def list_body(path: Path) -> str:
    """The text between the outer parentheses of an ASCII OpenFOAM list file (or field entry)."""
    text = path.read_text()
    text = text[text.index("}", text.index("FoamFile")) + 1 :]
    if "internalField" in text:
        text = text[text.index("internalField") :]
        text = text[: text.index("boundaryField")]
    return text[text.index("(") + 1 : text.rindex(")")]


def last_row(path: Path, columns: list[str]) -> dict:
    """The last row of an OpenFOAM function-object .dat file, by the names of its header."""
    lines = path.read_text().splitlines()
    header = [line for line in lines if line.startswith("#")][-1].lstrip("#").split()
    values = [line for line in lines if line.strip() and not line.startswith("#")][-1].split()
    return {name: float(values[header.index(name)]) for name in columns}


def history(path: Path, columns: list[str], back: int, relative: bool = True) -> dict:
    """The largest change of each column over the last ``back`` rows of a .dat file, relative to
    the last value (``relative``) or absolute."""
    lines = path.read_text().splitlines()
    header = [line for line in lines if line.startswith("#")][-1].lstrip("#").split()
    rows = np.array([line.split() for line in lines if line.strip() and not line.startswith("#")][-back - 1 :], dtype=float)
    changes = {name: float(np.ptp(rows[:, header.index(name)])) for name in columns}
    if relative:
        changes = {name: change / abs(rows[-1, header.index(name)]) for name, change in changes.items()}
    return changes
