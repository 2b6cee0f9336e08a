"""``load_shape(path)``: a Geometry from a shape file, chosen by the file's extension.

    .step .stp .iges .igs .brep   a CAD solid bounded by six four-cornered faces (gmsh, OCC)
    .stl .obj .ply                a closed triangulated surface (trimesh; ASCII STL solids)
    .yaml .yml                    a geometry file naming the surface file(s), faces and patches

The Geometry has no parameters; its boundary map is a ``faces.BoundaryPieces`` whose
``content_hash`` (the files' bytes and the options) keys the boundary-layout cache.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry import Geometry

__all__ = [
    "CAD_FORMATS",
    "SHAPE_FORMATS",
    "TRIANGULATED_FORMATS",
    "YAML_FORMATS",
    "content_hash",
    "default_patch_type",
    "is_shape_file",
    "load_shape",
    "shape_geometry",
]

CAD_FORMATS = (".step", ".stp", ".iges", ".igs", ".brep")
TRIANGULATED_FORMATS = (".stl", ".obj", ".ply")
YAML_FORMATS = (".yaml", ".yml")
SHAPE_FORMATS = CAD_FORMATS + TRIANGULATED_FORMATS + YAML_FORMATS
FORMAT_VERSION = "shapes-1"  # part of the cache key: bump when the parametrisation changes


def is_shape_file(spec: str) -> bool:
    return Path(str(spec)).suffix.lower() in SHAPE_FORMATS


def content_hash(paths, options: dict) -> str:
    """sha256 of the files' bytes (in order) and the options that shape the map."""
    digest = hashlib.sha256(json.dumps([FORMAT_VERSION, options], sort_keys=True, default=str).encode())
    for path in paths:
        try:
            digest.update(b"\0" + Path(path).read_bytes())
        except OSError:
            pass  # the reader reports it
    return digest.hexdigest()


def default_patch_type(name: str) -> str:
    """A patch's type from its name: inlet/inflow/outlet/outflow -> patch, symmetry -> symmetry,
    anything else wall."""
    lowered = name.lower()
    if any(word in lowered for word in ("inlet", "inflow", "outlet", "outflow")):
        return "patch"
    if "symmetry" in lowered:
        return "symmetry"
    return "wall"


def shape_geometry(block, path: Path, kind: str, types: dict | None = None) -> Geometry:
    """The Geometry of an assigned block (``triangulated.SurfaceBlock`` or ``cad.CadBlock``):
    patches named after the patches (types from ``types`` or ``default_patch_type``), length
    the bounding-box diagonal of the corner points and edges."""
    from meshgen.patches import PATCH_TYPES

    types = dict(types or {})
    names = block.names
    patches = {}
    for face, index in block.assignment.items():
        name = names[index]
        kind_of = types.get(name, default_patch_type(name))
        if kind_of not in PATCH_TYPES:
            raise GeometryError(f"{path}: patch '{name}': unknown type '{kind_of}' (types: {', '.join(PATCH_TYPES)})")
        patches[face] = (name, kind_of)
    pieces = block.pieces
    pieces.face_lines = tuple(f"{face:5s} <- {names[index]} ({patches[face][1]})" for face, index in block.assignment.items())
    from meshgen.errors import MeshgenError
    from meshgen.patches import face_assignment, patches_from_assignment

    try:
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


def load_shape(spec) -> Geometry:
    """The Geometry of a shape file (module docstring); GeometryError for anything wrong with it."""
    path = Path(str(spec))
    suffix = path.suffix.lower()
    if not path.exists():
        raise GeometryError(f"geometry file {path} does not exist")
    if not path.is_file():
        raise GeometryError(f"geometry file {path} is not a file")
    if suffix in YAML_FORMATS:
        from meshgen.shapes.geometry_file import load_geometry_file

        return load_geometry_file(path)
    if suffix in TRIANGULATED_FORMATS:
        return load_triangulated([path], path)
    if suffix in CAD_FORMATS:
        return load_cad(path)
    raise GeometryError(f"{path}: unknown shape format {suffix or '(none)'} (formats: {', '.join(SHAPE_FORMATS)})")


def load_triangulated(paths, path: Path, names=None, feature_angle=None, faces=None, types=None) -> Geometry:
    from meshgen.shapes.triangulated import surface_block

    options = {"names": names, "feature_angle": feature_angle, "faces": faces}
    block = surface_block(paths, str(path), names, feature_angle, faces, content_hash(paths, options))
    return shape_geometry(block, path, "surface", types)


def load_cad(path: Path, faces=None, types=None) -> Geometry:
    from meshgen.shapes.cad import cad_block

    block = cad_block(path, faces, content_hash([path], {"faces": faces}))
    return shape_geometry(block, path, "CAD solid", types)
