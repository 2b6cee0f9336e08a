"""``load_shape(path)``: a Geometry from a shape file, chosen by the file's extension.

    .step .stp .iges .igs .brep   a CAD solid bounded by six four-cornered faces (gmsh, OCC); a
                                  sweep is a block set instead (``sweep_blocks``)
    .stl .obj .ply                a closed triangulated surface (trimesh; ASCII STL solids)
    .yaml .yml                    a geometry file naming the surface file(s), faces and patches

The Geometry has no parameters; its boundary map is a ``faces.BoundaryPieces`` whose
``content_hash`` (the files' bytes and the options) keys the boundary-layout cache. A file read
once in a process is kept (by path, size and modification time), so commands that load the
geometry twice parametrise it once.
"""

from __future__ import annotations

from pathlib import Path

from meshgen.errors import GeometryError
from meshgen.geometry.domain import Geometry
from meshgen.geometry.shapes.assemble import (
    CAD_FORMATS,
    SHAPE_FORMATS,
    TRIANGULATED_FORMATS,
    YAML_FORMATS,
    content_hash,
    file_state,
    shape_geometry,
)
from meshgen.geometry.shapes.cad_process import cad_block
from meshgen.geometry.shapes.geometry_file import load_geometry_file, surface_files
from meshgen.geometry.shapes.triangulated import surface_block
from meshgen.geometry.topology_file import is_topology_file
from meshgen.run.inputs import InputError, check_input_file

__all__ = ["FORMAT_HELP", "is_shape_file", "load_shape"]

FORMAT_HELP = (
    (
        "STEP, IGES, BREP",
        ".step .stp .iges .igs .brep",
        "one solid bounded by six four-cornered faces, or a sweep (read by gmsh, OCC)",
    ),
    ("STL, OBJ, PLY", ".stl .obj .ply", "a closed manifold surface; patches from STL solids or sharp edges"),
    ("geometry file", ".yaml .yml", "a surface file or one file per patch, face assignment, patch names and types"),
)

_LOADED: dict = {}


def is_shape_file(spec) -> bool:
    """Whether ``spec`` names a shape file by its extension (a topology file, YAML too, is not one)."""
    return Path(str(spec)).suffix.lower() in SHAPE_FORMATS and not is_topology_file(spec)


def load_shape(spec) -> Geometry:
    """The Geometry of a shape file (module docstring); GeometryError for anything wrong with it."""
    path = Path(str(spec))
    suffix = path.suffix.lower()
    try:
        check_input_file(path, "geometry file")  # a FIFO or a device is never opened
    except InputError as exc:
        raise GeometryError(str(exc).replace(" cannot be read: it does not exist", " does not exist")) from None
    named = surface_files(path) if suffix in YAML_FORMATS else []  # a geometry file's surfaces: edits of them count
    key = tuple(file_state(file) for file in [path, *named])
    if key in _LOADED:
        return _LOADED[key]
    if suffix in YAML_FORMATS:
        geometry = load_geometry_file(path)
    elif suffix in TRIANGULATED_FORMATS:
        block = surface_block([path], str(path), content_hash=content_hash([path], {}))
        geometry = shape_geometry(block, path, "surface")
    elif suffix in CAD_FORMATS:
        geometry = shape_geometry(cad_block(path, None, content_hash([path], {})), path, "CAD solid")
    else:
        raise GeometryError(f"{path}: unknown shape format {suffix or '(none)'} (formats: {', '.join(SHAPE_FORMATS)})")
    _LOADED[key] = geometry
    return geometry
