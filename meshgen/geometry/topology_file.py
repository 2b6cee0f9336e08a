"""The topology file: a block set written as data (YAML), in the spirit of OpenFOAM's blockMeshDict::

    name: channel                        # optional: the geometry's name (default: the file's stem)
    vertices:                            # a list (named 0, 1, ...) or a mapping name -> point
      a: [0, 0]
      b: [1, 0]
      ...
    blocks:                              # 3D: 8 vertices in blockMesh order; 2D: 4, counterclockwise
      - [a, b, c, d]
      - {name: right, vertices: [b, e, f, c]}
    edges:                               # optional; straight lines otherwise
      - {arc: [b, c], through: [1.2, 0.5]}        # or center: [x, y(, z)] (a circle about it)
      - {polyline: [a, b], points: [[0.5, -0.1]]}   # or spline: [a, b] (points between a and b)
    cells:
      size: 0.05                         # every chain of parallel edges: longest edge / size cells
      counts: [[a, b, 20]]               # or per edge: the chain through a-b gets 20 cells
    grading:
      ratios: [[a, d, 4]]                # last cell / first cell along a -> d, on its chain
      first_cell: {wall: 0.001}          # first-cell height on these patches' faces
      growth: 1.2                        # the largest cell-to-cell growth first_cell may make
    patches:                             # faces by their vertices (3D: 4, 2D: 2)
      inlet: {type: patch, faces: [[a, d]]}
      left: {type: cyclic, neighbour: right, faces: [[a, d]]}   # a pair, each naming the other:
      right: {type: cyclic, neighbour: left, faces: [[b, c]]}   # the same faces up to a translation
      # or, on one side of a pair: rotation: {center: [0, 0], angle: 90}  (3D: axis: [0, 0, 1] too):
      # its neighbour is it turned by the angle (degrees, right-handed) about the axis through center
    default_patch: {name: walls, type: wall}     # every face not listed (default: defaultFaces, wall)
    surfaces:                            # optional: surfaces that faces are projected onto
      wall: {cylinder: {axis: [0, 0, 1], point: [0, 0, 0], radius: 0.5}}
    # project: wall   in a patch (its faces), a block ({xi0: wall}: faces by name) or an edge entry
    # slide: true     beside a patch's project: its nodes slide on the surface in the elliptic solve

``read_topology`` parses and checks it (one-line GeometryError per problem); ``is_topology_file``
tells a topology file from the YAML geometry file of ``meshgen.geometry.shapes``.
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError, did_you_mean
from meshgen.geometry.cube import face_named, face_names
from meshgen.geometry.topology_project import read_surfaces
from meshgen.geometry.topology_shorthand import checked_keys, expand_joint, expand_pipe, topology_error
from meshgen.run.inputs import MAX_YAML_BYTES, InputError, load_yaml, read_input_text

__all__ = ["EDGE_KINDS", "TOPOLOGY_KEYS", "Topology", "is_topology_file", "read_topology"]

TOPOLOGY_KEYS = ("name", "description", "vertices", "blocks", "joint", "pipe", "edges", "cells", "grading", "patches")
TOPOLOGY_KEYS += ("default_patch", "surfaces")
EDGE_KINDS = ("arc", "polyline", "spline")
_EDGE_KEYS = EDGE_KINDS + ("line", "through", "center", "points", "project")
_CELL_KEYS = ("size", "counts")
_GRADING_KEYS = ("ratios", "first_cell", "growth")
_PATCH_KEYS = ("type", "faces", "neighbour", "rotation", "project", "slide")
_PATCH_TYPES = ("wall", "patch", "symmetry", "cyclic")
_MARK = re.compile(r"^(vertices|blocks|joint|pipe)\s*:", re.MULTILINE)
_SEEN: dict = {}


@dataclass
class Topology:
    """A topology file checked: vertex names and points (V, dim), blocks as vertex indices (8 or
    4 each), curved edges {(i, j): (kind, points (K, dim))}, counts [(i, j, n)], ratios [(i, j,
    r)], first-cell heights {patch: H}, patches {name: (type, [vertex index tuples])}, cyclic pairs
    [(patch, its neighbour)] (each pair once, in the order of the file; a rotating patch first),
    rotations {patch: (centre (dim,), axis (3,), angle in degrees)}, surfaces {name: Surface},
    projected faces {frozenset of vertex indices: surface name}, projected edges {(i, j), i < j:
    surface name} and the projected faces whose nodes slide (``slide: true``)."""

    path: Path
    name: str
    description: str
    dim: int
    vertex_names: list
    points: np.ndarray
    block_names: list
    blocks: np.ndarray
    edges: dict = field(default_factory=dict)
    size: float | None = None
    counts: list = field(default_factory=list)
    ratios: list = field(default_factory=list)
    first_cell: dict = field(default_factory=dict)
    growth: float | None = None
    patches: dict = field(default_factory=dict)
    default_patch: tuple = ("defaultFaces", "wall")
    cyclic: list = field(default_factory=list)
    rotations: dict = field(default_factory=dict)
    surfaces: dict = field(default_factory=dict)
    projections: dict = field(default_factory=dict)
    edge_projections: dict = field(default_factory=dict)
    sliding: set = field(default_factory=set)


def is_topology_file(spec) -> bool:
    """Whether ``spec`` names a regular ``.yaml``/``.yml`` file with a top-level ``vertices`` or
    ``blocks`` key (a topology file, not a shape geometry file). Never raises."""
    path = Path(str(spec))
    if path.suffix.lower() not in (".yaml", ".yml"):
        return False
    try:
        status = os.stat(path)
    except OSError:
        return False
    if not stat.S_ISREG(status.st_mode):
        return False
    key = (str(path.resolve()), status.st_size, status.st_mtime_ns)
    if key not in _SEEN:
        try:
            _SEEN[key] = bool(_MARK.search(read_input_text(path, "topology file", MAX_YAML_BYTES)))
        except InputError:
            _SEEN[key] = False
    return _SEEN[key]


def _number(path, where: str, value, positive=True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or (positive and value <= 0):
        topology_error(path, f"{where} must be a {'positive ' if positive else ''}number, got {value!r}"[:200])
    return float(value)


def _points(path, where: str, value, dim: int) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        array = np.zeros(0)
    if array.ndim == 1 and array.size == dim:
        array = array[None]
    if array.ndim != 2 or array.shape[1] != dim or not np.all(np.isfinite(array)) or len(array) == 0:
        topology_error(path, f"{where} must be points of {dim} numbers each")
    return array


def read_topology(path) -> Topology:
    """The topology file ``path`` parsed (YAML safe loader with meshgen's limits) and checked for
    its structure: keys, vertex references, numbers. Geometric checks are ``meshgen.geometry.topology``'s."""
    import yaml

    path = Path(path)
    try:
        data = load_yaml(read_input_text(path, "topology file", MAX_YAML_BYTES), f"topology file {path}")
    except InputError as exc:
        raise GeometryError(str(exc)) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" (line {mark.line + 1})" if mark is not None else ""
        raise GeometryError(
            f"topology file {path} is not plain YAML data{line}: {str(getattr(exc, 'problem', ''))[:80]}"
        ) from None
    data = checked_keys(path, "the file", data, TOPOLOGY_KEYS)
    if "joint" in data:
        data = expand_joint(path, data)
    if "pipe" in data:
        data = expand_pipe(path, data)
    for key in ("vertices", "blocks"):
        if key not in data:
            topology_error(path, f"needs '{key}'")
    names, raw = _vertices(path, data["vertices"])
    if len(set(names)) != len(names):
        topology_error(path, "two vertices have one name")
    index = {name: i for i, name in enumerate(names)}
    block_names, blocks, dim, block_projections = _blocks(path, data["blocks"], index)
    points = _points(path, "vertices", raw, dim) if len(raw) else None
    if points is None or len(points) != len(names):
        topology_error(path, f"vertices must be points of {dim} numbers each")
    stem = re.sub(r"[^A-Za-z0-9_-]", "-", path.stem).lstrip("-_")[:64] or "topology"
    topology = Topology(
        path, str(data.get("name", stem)), str(data.get("description", f"block set of the topology file {path.name}")),
        dim, names, points, block_names, blocks,
    )  # fmt: skip

    topology.surfaces = read_surfaces(path, data["surfaces"], dim) if "surfaces" in data else {}
    for block, faces in block_projections.items():
        for face, name in faces.items():
            corners = _BLOCK_FACES[dim][face]
            _project(topology, f"block '{block_names[block]}' {face}", frozenset(int(blocks[block][c]) for c in corners), name)
    _edges(topology, data.get("edges") or [])
    _cells(topology, checked_keys(path, "cells", data.get("cells") or {}, _CELL_KEYS))
    _grading(topology, checked_keys(path, "grading", data.get("grading") or {}, _GRADING_KEYS))
    _patches(topology, data.get("patches") or {})
    if "default_patch" in data:
        default = checked_keys(path, "default_patch", data["default_patch"], ("name", "type"))
        kind = str(default.get("type", "wall"))
        if kind not in _PATCH_TYPES or kind == "cyclic":
            topology_error(path, f"default_patch has type '{kind}' (types: wall, patch, symmetry; a cyclic patch needs its pair)")
        topology.default_patch = (str(default.get("name", "defaultFaces")), kind)
    return topology


def _vertex(topology: Topology, where: str, value) -> int:
    """The index of the vertex named ``value`` (GeometryError naming the nearest name otherwise)."""
    key, names = str(value), topology.vertex_names
    if key not in names:
        topology_error(topology.path, f"{where} names a missing vertex '{key}'{did_you_mean(key, names)}")
    return names.index(key)


def _pair(topology: Topology, where: str, value) -> tuple[int, int]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        topology_error(topology.path, f"{where} must name two vertices [a, b]")
    i, j = _vertex(topology, where, value[0]), _vertex(topology, where, value[1])
    if i == j:
        topology_error(topology.path, f"{where} names vertex '{topology.vertex_names[i]}' twice")
    return i, j


def _edges(topology: Topology, entries) -> None:
    path, names, dim = topology.path, topology.vertex_names, topology.dim
    if not isinstance(entries, list):
        topology_error(path, "edges must be a list of curved edges")
    for number, entry in enumerate(entries):
        entry = checked_keys(path, f"edges[{number}]", entry, _EDGE_KEYS)
        kinds = [k for k in EDGE_KINDS + ("line",) if k in entry]
        if len(kinds) != 1:
            topology_error(
                path, f"edges[{number}] needs one of {', '.join(EDGE_KINDS)} (or line with project) naming its two vertices"
            )
        kind = kinds[0]
        i, j = _pair(topology, f"edges[{number}] ({kind})", entry[kind])
        where = f"edge {kind} {names[i]}-{names[j]}"
        if "project" in entry:
            if (min(i, j), max(i, j)) in topology.edge_projections:
                topology_error(path, f"{where} is given twice")
            topology.edge_projections[min(i, j), max(i, j)] = _surface_name(topology, where, entry["project"])
        if kind == "line":
            if "project" not in entry or len(entry) != 2:
                topology_error(path, f"{where}: a line entry only projects a straight edge: {{line: [a, b], project: NAME}}")
            continue
        if kind == "arc":
            if ("through" in entry) == ("center" in entry):
                topology_error(path, f"{where} needs one of 'through' (a point on the arc) and 'center'")
            how = "through" if "through" in entry else "center"
            extra = (how, _points(path, f"{where}: {how}", entry[how], dim)[0])
        else:
            if "points" not in entry:
                topology_error(path, f"{where} needs 'points' (the points between its vertices)")
            extra = ("points", _points(path, f"{where}: points", entry["points"], dim))
        if (i, j) in topology.edges or (j, i) in topology.edges:
            topology_error(path, f"{where} is given twice")
        topology.edges[i, j] = (kind, *extra)


def _cells(topology: Topology, cells: dict) -> None:
    path = topology.path
    if "size" in cells:
        topology.size = _number(path, "cells: size", cells["size"])
    for number, entry in enumerate(cells.get("counts") or []):
        if not isinstance(entry, (list, tuple)) or len(entry) != 3:
            topology_error(path, f"cells: counts[{number}] must be [a, b, cells]")
        i, j = _pair(topology, f"cells: counts[{number}]", entry[:2])
        n = entry[2]
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            topology_error(path, f"cells: counts[{number}] must give a positive whole number of cells, got {n!r}"[:200])
        topology.counts.append((i, j, n))


def _grading(topology: Topology, grading: dict) -> None:
    path = topology.path
    for number, entry in enumerate(grading.get("ratios") or []):
        if not isinstance(entry, (list, tuple)) or len(entry) != 3:
            topology_error(path, f"grading: ratios[{number}] must be [a, b, last cell / first cell]")
        i, j = _pair(topology, f"grading: ratios[{number}]", entry[:2])
        topology.ratios.append((i, j, _number(path, f"grading: ratios[{number}]", entry[2])))
    first = grading.get("first_cell") or {}
    if not isinstance(first, dict):
        topology_error(path, "grading: first_cell must map patch names to first-cell heights")
    topology.first_cell = {str(k): _number(path, f"grading: first_cell of '{k}'", v) for k, v in first.items()}
    if "growth" in grading:
        topology.growth = _number(path, "grading: growth", grading["growth"])
        if topology.growth <= 1.0:
            topology_error(path, f"grading: growth must be above 1, got {topology.growth:g}")


def _patches(topology: Topology, patches) -> None:
    path, dim = topology.path, topology.dim
    corners = 4 if dim == 3 else 2
    if not isinstance(patches, dict):
        topology_error(path, "patches must map patch names to {type: ..., faces: [...]}")
    for name, entry in patches.items():
        entry = checked_keys(path, f"patch '{name}'", entry, _PATCH_KEYS)
        kind = str(entry.get("type", "wall"))
        if kind not in _PATCH_TYPES:
            topology_error(
                path,
                f"patch '{name}' has unknown type '{kind}' (types: {', '.join(_PATCH_TYPES)}){did_you_mean(kind, _PATCH_TYPES)}",
            )
        faces = entry.get("faces")
        if not isinstance(faces, list) or not faces:
            topology_error(path, f"patch '{name}' needs 'faces': a list of faces, each {corners} vertices")
        listed = []
        for face in faces:
            if not isinstance(face, (list, tuple)) or len(face) != corners:
                topology_error(path, f"patch '{name}': a face of a {dim}D block has {corners} vertices, got {face!r}"[:200])
            listed.append(tuple(_vertex(topology, f"patch '{name}'", v) for v in face))
        topology.patches[str(name)] = (kind, listed)
        if "project" in entry:
            for face in listed:
                _project(topology, f"patch '{name}'", frozenset(face), entry["project"])
        if "slide" in entry:
            if not isinstance(entry["slide"], bool) or "project" not in entry:
                topology_error(path, f"patch '{name}': 'slide' is true or false, on a patch with 'project'")
            if entry["slide"]:
                topology.sliding.update(frozenset(face) for face in listed)
        if kind != "cyclic" and "rotation" in entry:
            topology_error(path, f"patch '{name}': only a cyclic patch has a 'rotation'")
        if (kind == "cyclic") != ("neighbour" in entry):
            topology_error(
                path,
                f"patch '{name}': "
                + (
                    "a cyclic patch needs 'neighbour': the patch it pairs with"
                    if kind == "cyclic"
                    else "only a cyclic patch has a 'neighbour'"
                ),
            )
    for name, (kind, _) in topology.patches.items():
        if kind != "cyclic":
            continue
        other = str(patches[name]["neighbour"])
        back = patches.get(other) if other in topology.patches else None
        if other == name or not isinstance(back, dict) or back.get("type") != "cyclic" or str(back.get("neighbour")) != name:
            topology_error(
                path, f"cyclic patch '{name}': its neighbour '{other}' must be another cyclic patch whose neighbour is '{name}'"
            )
        if "rotation" in patches[name]:
            if "rotation" in back:
                topology_error(path, f"cyclic patches '{name}' and '{other}' both give a rotation: give it on one side")
            topology.rotations[name] = _rotation(topology, name, patches[name]["rotation"])
        if (other, name) not in topology.cyclic and (name, other) not in topology.cyclic:
            topology.cyclic.append((name, other) if "rotation" in patches[name] or "rotation" not in back else (other, name))


def _rotation(topology: Topology, name: str, value) -> tuple:
    """(centre (dim,), unit axis (3,), angle in degrees) of a cyclic patch's ``rotation``."""
    path, dim = topology.path, topology.dim
    where = f"patch '{name}': rotation"
    value = checked_keys(path, where, value, ("center", "axis", "angle"))
    if "center" not in value or "angle" not in value or (dim == 3 and "axis" not in value):
        topology_error(path, f"{where} needs center and angle (degrees)" + (" and axis" if dim == 3 else ""))
    centre = _points(path, f"{where}: center", value["center"], dim)[0]
    axis = _points(path, f"{where}: axis", value.get("axis", [0, 0, 1]), 3)[0]
    if not np.linalg.norm(axis) > 0 or (dim == 2 and (axis[0] or axis[1])):
        topology_error(
            path, f"{where}: axis must be a nonzero vector" + (" along z (a 2D set turns about z)" if dim == 2 else "")
        )
    angle = _number(path, f"{where}: angle", value["angle"], positive=False)
    return tuple(float(v) for v in centre), tuple(float(v) for v in axis / np.linalg.norm(axis)), angle


def _surface_name(topology: Topology, where: str, name) -> str:
    """``name`` checked against the file's surfaces."""
    known = list(topology.surfaces)
    if str(name) not in known:
        listed = f" (surfaces: {', '.join(known)})" if known else " (the file declares no surfaces)"
        topology_error(
            topology.path, f"{where} projects onto an unknown surface '{name}'{listed}{did_you_mean(str(name), known)}"
        )
    return str(name)


def _project(topology: Topology, where: str, face: frozenset, name) -> None:
    """Record that ``face`` (its vertex indices) is projected onto the surface ``name``."""
    name = _surface_name(topology, where, name)
    if topology.projections.get(face, name) != name:
        topology_error(topology.path, f"{where}: its face is projected onto '{topology.projections[face]}' and '{name}'")
    topology.projections[face] = name


def _vertices(path, value) -> tuple[list, list]:
    """(names, raw points) of ``vertices``: a list (names '0', '1', ...) or a mapping."""
    if isinstance(value, list):
        return [str(i) for i in range(len(value))], value
    if isinstance(value, dict):
        return [str(k) for k in value], list(value.values())
    topology_error(path, "vertices must be a list of points or a mapping name -> point")


def _blocks(path, value, index) -> tuple[list, np.ndarray, int, dict]:
    """(block names, vertex indices (B, 4 or 8), dim, {block: {face name: surface name}}) of ``blocks``."""
    if not isinstance(value, list) or not value:
        topology_error(path, "blocks must be a list of blocks (3D: 8 vertices each, 2D: 4)")
    names, rows, projections = [], [], {}
    for number, entry in enumerate(value):
        if isinstance(entry, dict):
            entry = checked_keys(path, f"blocks[{number}]", entry, ("name", "vertices", "project"))
            name, vertices = str(entry.get("name", f"b{number}")), entry.get("vertices")
            if "project" in entry:
                allowed = face_names(3 if isinstance(vertices, list) and len(vertices) == 8 else 2)
                projections[number] = {
                    str(k): v for k, v in checked_keys(path, f"block '{name}' project", entry["project"], allowed).items()
                }
        else:
            name, vertices = f"b{number}", entry
        if not isinstance(vertices, list) or len(vertices) not in (4, 8):
            topology_error(path, f"block '{name}' needs 8 vertices (3D, blockMesh order) or 4 (2D), got {vertices!r}"[:200])
        row = []
        for v in vertices:
            if str(v) not in index:
                topology_error(path, f"block '{name}' names a missing vertex '{v}'{did_you_mean(str(v), list(index))}")
            row.append(index[str(v)])
        if len(set(row)) != len(row):
            topology_error(path, f"block '{name}' names a vertex twice")
        if name in names:
            topology_error(path, f"two blocks are named '{name}'")
        names.append(name)
        rows.append(row)
    if len({len(r) for r in rows}) != 1:
        topology_error(path, "blocks mix 8 vertices (3D) and 4 (2D)")
    return names, np.array(rows, dtype=int), 3 if len(rows[0]) == 8 else 2, projections


# The corners (blockMesh order; 2D: the first four) of each named face of a block.
_CUBE = {3: np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])}
_CUBE[2] = _CUBE[3][:4, :2]
_BLOCK_FACES = {
    dim: {
        name: np.flatnonzero(_CUBE[dim][:, face_named(name, dim).axis] == face_named(name, dim).side) for name in face_names(dim)
    }
    for dim in (2, 3)
}
