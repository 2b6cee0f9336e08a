"""A YAML geometry file (``geometry_file``) whose ``surface`` is a sweep (``sweep_blocks``): meshed
as that sweep's block set, with the file's patch names and types and, if it names them, its caps::

    surface: cylinder.step        # a CAD solid or a triangulated surface that is a sweep
    caps: [face2, face3]          # the caps, the first on zeta0 (names as found, before rename)
    rename: {face1: wall, face2: inlet, face3: outlet}
    types: {wall: wall}           # by either name; default by the written name

- ``is_sweep_geometry(spec)`` and ``sweep_geometry_module(path)``: ``sweep_blocks``' pair
  (``is_sweep_file``, ``sweep_module``) for a bare file, these for a YAML file; the dispatch
  points (``plugins.load_geometry``, ``_plugin_module``, ``blocks.block_spec``, ``is_multiblock``)
  call them.
- ``is_sweep_yaml(path)``: the file reads as a geometry file whose ``surface`` the sweep reader,
  trying every pair, takes for what ``is_sweep_file`` of the bare file says is a sweep (or, with
  ``caps``, for anything but six four-cornered faces). Otherwise, a topology file, a ``patches``
  file, and any file that does not read are the single-block reader's (``geometry_file``), as before;
  that reader refuses ``caps``: a six-faced solid is one block, its faces chosen by ``faces``.
- ``caps`` is passed into the cap search (``sweep_read.read_sweep`` in the CAD process as two
  names, ``sweep_stl.read_surface_sweep``): only that pair, in that order, is tried, by the checks
  every pair gets, so a pair that is no sweep's caps is refused saying why (touching, a linking
  face that does not touch both, not one shape, ...).
- ``rename``, ``types``, ``caps`` name the patches found (``sweep_read``: the CAD faces' names or
  face1..; ``sweep_stl``: the solids or patch1..): a name that is none of them is one line listing
  them, as ``assemble.shape_geometry`` says it for a single block.
- ``faces`` and ``corners`` assign the six faces of one block: refused on a sweep;
  ``feature_angle`` is a triangulated surface's sharp-edge split (refused for a CAD solid).
- Modules are kept per state (path, size, modification time) of both the geometry file and the
  surface file (``_MODULES``; the surface's reads by ``sweep_blocks.read_sweep_file`` per its own
  state, the caps and the angle), so editing either takes effect in the same process.
"""

from __future__ import annotations

import types
from pathlib import Path

from meshgen.errors import GeometryError, MeshgenError
from meshgen.geometry.patches import PATCH_TYPES, check_patch_name
from meshgen.geometry.shapes.assemble import CAD_FORMATS, TRIANGULATED_FORMATS, YAML_FORMATS, default_patch_type, file_state
from meshgen.geometry.shapes.geometry_file import named_file, read_geometry_file
from meshgen.geometry.shapes.sweep_blocks import build_sweep_module, is_sweep_file, read_sweep_file, sweep_module
from meshgen.geometry.topology_file import is_topology_file

__all__ = ["is_sweep_geometry", "is_sweep_yaml", "sweep_geometry_module", "yaml_sweep_module"]

SWEEP_KINDS = ("sweep", "loft")
_MODULES: dict = {}  # (geometry file's state, surface file's state) -> module


def _is_yaml(spec) -> bool:
    return isinstance(spec, (str, Path)) and Path(str(spec)).suffix.lower() in YAML_FORMATS


def is_sweep_geometry(spec) -> bool:
    """Whether ``spec`` names a sweep's file (``sweep_blocks.is_sweep_file``) or a YAML geometry
    file over one (``is_sweep_yaml``): a block set, not the single block of ``shapes.loader``."""
    return is_sweep_yaml(Path(str(spec))) if _is_yaml(spec) else is_sweep_file(spec)


def sweep_geometry_module(path) -> types.ModuleType:
    """The block-set module of a sweep's file or of a YAML geometry file over one."""
    return yaml_sweep_module(Path(path)) if _is_yaml(path) else sweep_module(path)


def _surface(path: Path):
    """(the geometry file's mapping, its surface file, whether triangulated); GeometryError when it
    does not read or names no CAD or triangulated ``surface``."""
    data = read_geometry_file(path)
    if "surface" not in data:
        raise GeometryError(f"geometry file {path}: a sweep is read from one 'surface' file")
    file = named_file(path.parent, data["surface"], path, "'surface'")
    suffix = file.suffix.lower()
    if suffix not in CAD_FORMATS + TRIANGULATED_FORMATS:
        raise GeometryError(f"geometry file {path}: 'surface' {data['surface']}: unknown format {suffix or '(none)'}")
    return data, file, suffix in TRIANGULATED_FORMATS


def is_sweep_yaml(path: Path) -> bool:
    """Whether the YAML file ``path`` is a geometry file of a sweep (module docstring). Never raises:
    a file that does not read is the single-block reader's to report."""
    try:
        if not path.is_file() or is_topology_file(path):
            return False
        data, file, triangulated = _surface(path)
        found = read_sweep_file(file, None, data.get("feature_angle") if triangulated else None)
    except (MeshgenError, OSError):
        return False
    if found["kind"] == "six":
        return False
    if data.get("caps") is not None or not triangulated:
        return True
    return found["kind"] == "sweep" or bool(found.get("caps_found"))


def yaml_sweep_module(path: Path) -> types.ModuleType:
    """The block-set module of the sweep the geometry file ``path`` names, with its patch names,
    types and caps (module docstring); kept per state of both files. GeometryError (one line)."""
    data, file, triangulated = _surface(path)
    key = (file_state(path), file_state(file))
    if key in _MODULES:
        return _MODULES[key]
    angle = data.get("feature_angle")
    if angle is not None and not triangulated:
        raise GeometryError(
            f"geometry file {path}: 'feature_angle' splits a triangulated surface at its sharp edges; "
            f"the patches of the CAD solid {file.name} are its faces"
        )
    found = read_sweep_file(file, None, angle)
    names = tuple(found["names"])
    for assigning in ("faces", "corners"):
        if data.get(assigning) is not None and found["kind"] in SWEEP_KINDS:
            raise GeometryError(
                f"geometry file {path}: '{assigning}' assigns the six faces of one block, but {file.name} is a sweep "
                f"({found['summary']}), meshed as a block set: name its caps with 'caps' and its patches with 'rename'"
            )
    listing = f"(patches: {', '.join(names)})"
    rename = dict(data.get("rename") or {})
    unknown = [name for name in rename if name not in names]
    if unknown:
        raise GeometryError(f"{path}: 'rename' names no patch '{unknown[0]}' {listing}")
    written = {name: rename.get(name, name) for name in names}
    given = dict(data.get("types") or {})
    unknown = [name for name in given if name not in names and name not in written.values()]
    if unknown:
        raise GeometryError(f"{path}: 'types' names no patch '{unknown[0]}' {listing}")
    kinds, merged = {}, {}
    for name in names:
        new = written[name]
        try:
            check_patch_name(new)
        except MeshgenError as exc:
            raise GeometryError(f"{path}: {exc}") from None
        kind = given.get(new, given.get(name, default_patch_type(new)))
        if kind not in PATCH_TYPES:
            raise GeometryError(f"{path}: patch '{new}': unknown type '{kind}' (types: {', '.join(PATCH_TYPES)})")
        if merged.setdefault(new, kind) != kind:
            raise GeometryError(f"{path}: patch '{new}' (two patches renamed to it) is both {merged[new]} and {kind}")
        kinds[name] = kind
    caps = data.get("caps")
    if caps is not None:
        caps = tuple(caps)
        unknown = [name for name in caps if name not in names]
        if unknown:
            raise GeometryError(f"{path}: 'caps' names no patch '{unknown[0]}' {listing} (the names found, before 'rename')")
        automatic = tuple(names[k] for k in found["caps"]) if found["kind"] in SWEEP_KINDS else None
        if caps != automatic:
            found = read_sweep_file(file, caps, angle)
        if found["kind"] not in SWEEP_KINDS:
            why = found.get("reason", "one block of six four-cornered faces")
            raise GeometryError(f"{path}: 'caps' {caps[0]} and {caps[1]} are not the caps of a sweep: {why}")
    named = {"file": path, "where": f"{path}: 'surface' {data['surface']}", "rename": written, "kinds": kinds}
    module = build_sweep_module(file, found, {**named, "caps": caps is not None})
    _MODULES[key] = module
    return module
