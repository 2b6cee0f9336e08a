"""The YAML geometry file: a shape file (or one surface file per patch) with its face assignment
and patch names and types, so that ``meshgen mesh -g duct.yaml`` is explicit and repeatable::

    surface: duct.stl          # STL/OBJ/PLY or STEP/STP/IGES/IGS/BREP, relative to this file
    # patches:                 # instead of surface: one closed surface split in files, one per patch
    #   inlet: inlet.stl
    #   walls: {file: walls.stl, type: wall}
    feature_angle: 40          # degrees: sharp edges that split a single surface into patches
    faces:                     # cube face -> patch (solid, CAD face, file or patchN name)
      zeta0: inlet
      zeta1: outlet
      xi0: inner
      xi1: outer
      eta0: floor
      eta1: ceiling
    # corners:                 # instead of faces: the eight corner points at the cube's corners
    #   [[x, y, z], ...]        # (xi, eta, zeta) = (0,0,0), (0,0,1), (0,1,0), (0,1,1), (1,0,0), ...
    rename: {patch1: inlet}    # patch names as written to the mesh files
    types: {inlet: patch, outlet: patch, floor: symmetry}   # default: by name (wall otherwise)
    # caps: [face2, face3]     # a swept solid's caps (first on zeta0), instead of faces/corners

Every key is optional except ``surface`` or ``patches``. ``faces`` must name all six faces;
``corners`` (eight points, each within 1e-6 of the size of a corner vertex) fixes the assignment
instead. A left-handed assignment is refused.

A ``surface`` that is a sweep (``sweep_blocks``: a cylinder, a prism, a bend, a loft) is meshed
as that sweep's block set (``sweep_yaml``), its patches renamed and typed by ``rename`` and
``types``; ``caps`` names its two caps (patch names as found), which the cap search then checks
as it checks every pair it tries. ``faces`` and ``corners`` are refused there, and ``caps`` here:
a solid of six four-cornered faces stays one block, its faces chosen by ``faces``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry.shapes.assemble import CAD_FORMATS, TRIANGULATED_FORMATS, content_hash, shape_geometry
from meshgen.geometry.shapes.cad_process import cad_block
from meshgen.geometry.shapes.faces import FACE_NAMES
from meshgen.geometry.shapes.triangulated import surface_block
from meshgen.run.inputs import InputError, load_yaml_file, named_input_file

__all__ = ["GEOMETRY_FILE_KEYS", "load_geometry_file", "named_file", "read_geometry_file", "surface_files"]

GEOMETRY_FILE_KEYS = ("surface", "patches", "feature_angle", "faces", "corners", "rename", "types", "caps")


def read_geometry_file(path: Path) -> dict:
    """The YAML mapping of a geometry file, with its keys checked."""
    import yaml

    try:
        data = load_yaml_file(path, "geometry file")  # the limits of --config: size, no aliases, depth
    except InputError as exc:
        raise GeometryError(str(exc)) from None
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        raise GeometryError(f"geometry file {path} is not valid YAML{line}") from None
    if data is None:
        raise GeometryError(f"geometry file {path} is empty")
    if not isinstance(data, dict):
        raise GeometryError(f"geometry file {path} must be a mapping with 'surface' or 'patches'")
    unknown = [k for k in data if k not in GEOMETRY_FILE_KEYS]
    if unknown:
        raise GeometryError(f"geometry file {path}: unknown key '{unknown[0]}' (keys: {', '.join(GEOMETRY_FILE_KEYS)})")
    if ("surface" in data) == ("patches" in data):
        raise GeometryError(
            f"geometry file {path} needs exactly one of 'surface' (a shape file) and 'patches' (one file per patch)"
        )
    for key in ("faces", "rename", "types"):
        value = data.get(key)
        if value is not None and not (isinstance(value, dict) and all(isinstance(v, str) for v in value.values())):
            raise GeometryError(f"geometry file {path}: '{key}' must map names to names")
    faces = data.get("faces")
    if faces is not None and sorted(faces) != sorted(FACE_NAMES):
        raise GeometryError(f"geometry file {path}: 'faces' must name each of {', '.join(FACE_NAMES)} once")
    corners = data.get("corners")
    if corners is not None:
        if faces is not None:
            raise GeometryError(f"geometry file {path}: give 'faces' or 'corners', not both")
        try:
            array = np.array(corners, dtype=float)
        except (TypeError, ValueError):
            array = np.zeros(0)
        if array.shape != (8, 3) or not np.all(np.isfinite(array)):
            raise GeometryError(f"geometry file {path}: 'corners' must be eight points [x, y, z]")
    caps = data.get("caps")
    if caps is not None and not (
        isinstance(caps, list) and len(caps) == 2 and all(isinstance(c, str) and c for c in caps) and caps[0] != caps[1]
    ):
        raise GeometryError(f"geometry file {path}: 'caps' must be two different patch names, [first, second]")
    angle = data.get("feature_angle")
    if angle is not None and (isinstance(angle, bool) or not isinstance(angle, (int, float)) or not 0 < angle < 180):
        raise GeometryError(f"geometry file {path}: 'feature_angle' must be a number of degrees between 0 and 180")
    return data


def named_file(base: Path, value, path: Path, what: str) -> Path:
    """The file ``value`` a geometry file ``path`` names for ``what``, relative to its folder
    ``base``, checked to be a regular file (GeometryError otherwise)."""
    if not isinstance(value, str) or not value:
        raise GeometryError(f"geometry file {path}: {what} must be a file name")
    try:
        return named_input_file(base, value, f"geometry file {path}: the file {value} named for {what}")
    except InputError as exc:
        raise GeometryError(str(exc)) from None


def surface_files(path) -> list[Path]:
    """The surface files the geometry file ``path`` names (its ``surface``, or its ``patches``' files,
    resolved against its folder), for caches to key on; [] where the file does not read (its
    loader reports why)."""
    path = Path(path)
    try:
        data = read_geometry_file(path)
    except GeometryError:
        return []
    entries = [data["surface"]] if "surface" in data else list((data.get("patches") or {}).values())
    entries = [entry.get("file") if isinstance(entry, dict) else entry for entry in entries]
    return [path.parent / entry for entry in entries if isinstance(entry, str) and entry]


def load_geometry_file(path) -> object:
    """The Geometry a YAML geometry file describes (module docstring)."""
    path = Path(path)
    data = read_geometry_file(path)
    base = path.parent
    types = dict(data.get("types") or {})
    faces = data.get("faces")
    corners = data.get("corners")
    rename = dict(data.get("rename") or {})
    if "surface" in data:
        file = named_file(base, data["surface"], path, "'surface'")
        suffix = file.suffix.lower()
        options = {"yaml": path.read_bytes().hex()}  # the whole file: faces, corners, angle
        if suffix in CAD_FORMATS:
            block = cad_block(file, faces, content_hash([file], options), corners)
            kind = "CAD solid"
        elif suffix in TRIANGULATED_FORMATS:
            block = surface_block(
                [file], str(file), None, data.get("feature_angle"), faces, content_hash([file], options), corners
            )
            kind = "surface"
        else:
            raise GeometryError(f"geometry file {path}: 'surface' {data['surface']}: unknown format {suffix or '(none)'}")
    else:
        patches = data["patches"]
        if not isinstance(patches, dict) or len(patches) == 0:
            raise GeometryError(f"geometry file {path}: 'patches' must map patch names to files")
        names, files = [], []
        for name, entry in patches.items():
            if isinstance(entry, dict):
                if "type" in entry:
                    types.setdefault(str(name), str(entry["type"]))
                entry = entry.get("file")
            files.append(named_file(base, entry, path, f"patch '{name}'"))
            names.append(str(name))
        bad = [f for f in files if f.suffix.lower() not in TRIANGULATED_FORMATS]
        if bad:
            raise GeometryError(
                f"geometry file {path}: patch file {bad[0].name} is not a surface ({', '.join(TRIANGULATED_FORMATS)})"
            )
        options = {"yaml": path.read_bytes().hex()}
        block = surface_block(files, str(path), names, None, faces, content_hash(files, options), corners)
        kind = "surface"
    if data.get("caps") is not None:  # a sweep's geometry file goes to sweep_yaml instead
        raise GeometryError(
            f"geometry file {path}: 'caps' names a swept solid's caps, but {kind} {data.get('surface', 'of the patch files')} "
            f"is one block of six four-cornered faces: choose the faces on zeta0 and zeta1 with 'faces'"
        )
    return shape_geometry(block, path, kind, types, rename)
