"""The Geometry of six patches assigned to the cube's faces (a triangulated surface's or a CAD
solid's): patch names and types, the length scale, and the hash that keys the layout cache."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError, MeshgenError
from meshgen.geometry.domain import Geometry
from meshgen.geometry.patches import PATCH_TYPES, check_patch_name, face_assignment, patches_from_assignment

__all__ = [
    "CAD_FORMATS",
    "SHAPE_FORMATS",
    "TRIANGULATED_FORMATS",
    "YAML_FORMATS",
    "content_hash",
    "default_patch_type",
    "file_state",
    "shape_geometry",
]

CAD_FORMATS = (".step", ".stp", ".iges", ".igs", ".brep")
TRIANGULATED_FORMATS = (".stl", ".obj", ".ply")
YAML_FORMATS = (".yaml", ".yml")
SHAPE_FORMATS = CAD_FORMATS + TRIANGULATED_FORMATS + YAML_FORMATS
FORMAT_VERSION = "shapes-1"  # part of the cache key: changes when the parametrisation does


def content_hash(paths, options: dict) -> str:
    """sha256 of the files' bytes (in order) and the options that shape the map."""
    digest = hashlib.sha256(json.dumps([FORMAT_VERSION, options], sort_keys=True, default=str).encode())
    for path in paths:
        try:
            digest.update(b"\0" + Path(path).read_bytes())
        except OSError:
            pass  # the reader reports it
    return digest.hexdigest()


def file_state(path: Path) -> tuple:
    """(resolved path, size, modification time in ns) of the file ``path``, what the shape caches
    key on; (path,) where it cannot be read (its reader then says why)."""
    try:
        status = Path(path).stat()
    except OSError:
        return (str(path),)
    return (str(Path(path).resolve()), status.st_size, status.st_mtime_ns)


def default_patch_type(name: str) -> str:
    """A patch's type from its name: inlet/inflow/outlet/outflow -> patch, symmetry -> symmetry,
    anything else wall."""
    lowered = name.lower()
    if any(word in lowered for word in ("inlet", "inflow", "outlet", "outflow")):
        return "patch"
    if "symmetry" in lowered:
        return "symmetry"
    return "wall"


def shape_geometry(block, path: Path, kind: str, types: dict | None = None, rename: dict | None = None) -> Geometry:
    """The Geometry of an assigned block (``triangulated.SurfaceBlock`` or ``cad.CadBlock``):
    patches named after the block's (``rename``: found name -> name written), of the type
    ``types`` gives (by either name) or ``default_patch_type``; length the bounding-box diagonal."""
    types, rename = dict(types or {}), dict(rename or {})
    unknown = [name for name in rename if name not in block.names]
    if unknown:
        raise GeometryError(f"{path}: 'rename' names no patch '{unknown[0]}' (patches: {', '.join(block.names)})")
    names = [rename.get(name, name) for name in block.names]
    patches = {}
    for face, index in block.assignment.items():
        name = names[index]
        kind_of = types.get(name, types.get(block.names[index], default_patch_type(name)))
        if kind_of not in PATCH_TYPES:
            raise GeometryError(f"{path}: patch '{name}': unknown type '{kind_of}' (types: {', '.join(PATCH_TYPES)})")
        patches[face] = (name, kind_of)
    pieces = block.pieces
    pieces.face_lines = tuple(f"{face:5s} <- {names[index]} ({patches[face][1]})" for face, index in block.assignment.items())
    try:
        for name in names:
            check_patch_name(name)
        patches_from_assignment(face_assignment(3, patches))
    except MeshgenError as exc:
        raise GeometryError(f"{path}: {exc}") from None
    low, high = block.extent()
    length = float(np.linalg.norm(high - low))
    return Geometry(
        name=path.stem,
        dim=3,
        description=f"{kind} {path.name}: patches {', '.join(names)}",
        defaults={},
        values={},
        boundary_map=pieces,
        length_map=lambda: length,
        source=str(path),
        patches=patches,
    )
