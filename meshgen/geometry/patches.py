"""Named boundary patches: which faces of the reference cube (``meshgen.geometry.cube``) form which patch,
and of what type, for the formats solvers read (OpenFOAM, CGNS, SU2, Gmsh, .vts).

A geometry plugin may declare its patches as a dict from cube face name to ``(patch name, type)``::

    patches = {"zeta0": ("inlet", "patch"), "zeta1": ("outlet", "patch"),
               "xi0": ("wall", "wall"), "xi1": ("wall", "wall"), "eta1": ("wall", "wall"),
               "eta0": ("symmetry", "symmetry")}

Faces it leaves out keep their own name (``xi0`` .. ``zeta1``) and the type ``patch``. Several
faces may share one name (they must then share the type); ``--patch FACE=NAME[:TYPE]`` overrides
a face at meshing time. Types: ``wall``; ``patch`` (inflow, outflow, anything generic);
``symmetry``; ``empty`` (the front and back of a 2D mesh extruded for OpenFOAM).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from meshgen.errors import MeshgenError
from meshgen.geometry import cube

__all__ = [
    "DEFAULT_TYPE",
    "NAME_PATTERN",
    "PATCH_TYPES",
    "Patch",
    "as_records",
    "check_covers",
    "check_patch_name",
    "default_patches",
    "face_assignment",
    "flow_role",
    "from_records",
    "geometry_patches",
    "parse_patch_options",
    "patches_from_assignment",
]

PATCH_TYPES = ("wall", "patch", "symmetry", "empty")
DEFAULT_TYPE = "patch"
# What any patch name must be (each format may be stricter: meshgen.formats.check_patches):
# 1 to 64 printable ASCII characters, no spaces, quotes or backslashes.
NAME_PATTERN = re.compile(r"[!#-&(-\[\]-~]{1,64}")


@dataclass(frozen=True)
class Patch:
    """A named boundary patch: the cube faces it covers (names, in cube order) and its type."""

    name: str
    type: str
    faces: tuple[str, ...]


INFLOW_WORDS, OUTFLOW_WORDS = ("inlet", "inflow"), ("outlet", "outflow")


def flow_role(patch) -> str | None:
    """ "inflow" or "outflow" for a ``patch``-type patch whose name says so (inlet, inflow /
    outlet, outflow, any case), else None: how CGNS BC types and OpenFOAM's starting fields tell
    an inlet from an outlet."""
    if patch.type != "patch":
        return None
    lowered = patch.name.lower()
    if any(word in lowered for word in INFLOW_WORDS):
        return "inflow"
    if any(word in lowered for word in OUTFLOW_WORDS):
        return "outflow"
    return None


def face_assignment(dim: int, declared: dict | None = None, overrides: dict | None = None) -> dict[str, tuple[str, str]]:
    """Face name -> (patch name, type) for every face of the ``dim``-cube: the defaults (face name,
    ``patch``), then a plugin's ``declared`` patches, then ``overrides`` (``parse_patch_options``).
    MeshgenError for an unknown face, type or invalid name."""
    assignment = {name: (name, DEFAULT_TYPE) for name in cube.face_names(dim)}
    for source, entries in (("declared", declared or {}), ("--patch", overrides or {})):
        for face, (name, kind) in entries.items():
            if face not in assignment:
                raise MeshgenError(
                    f"{source} patch: unknown face '{face}' of a {dim}D mesh (faces: {', '.join(cube.face_names(dim))})"
                )
            check_patch_name(name)
            kind = assignment[face][1] if kind is None else kind
            if kind not in PATCH_TYPES:
                raise MeshgenError(f"{source} patch {face}={name}: unknown type '{kind}' (types: {', '.join(PATCH_TYPES)})")
            assignment[face] = (name, kind)
    return assignment


def patches_from_assignment(assignment: dict[str, tuple[str, str]]) -> list[Patch]:
    """The patches of a face assignment, in the order of their first face; MeshgenError when faces
    that share a name disagree on the type."""
    faces_of: dict[str, list[str]] = {}
    type_of: dict[str, str] = {}
    for face, (name, kind) in assignment.items():
        if name in type_of and type_of[name] != kind:
            raise MeshgenError(
                f"patch '{name}' is {type_of[name]} on {faces_of[name][0]} but {kind} on {face}: "
                "faces sharing a name share its type"
            )
        type_of[name] = kind
        faces_of.setdefault(name, []).append(face)
    return [Patch(name, type_of[name], tuple(faces)) for name, faces in faces_of.items()]


def default_patches(dim: int) -> list[Patch]:
    """One ``patch`` per face, named after it (``xi0`` .. ``zeta1``)."""
    return patches_from_assignment(face_assignment(dim))


def geometry_patches(geometry, overrides: dict | None = None) -> list[Patch]:
    """The patches of a ``meshgen.geometry.plugins.Geometry``: its declared ones, then ``overrides``."""
    return patches_from_assignment(face_assignment(geometry.dim, geometry.patches, overrides))


def check_patch_name(name) -> None:
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise MeshgenError(
            f"patch name {name!r} is not valid: 1 to 64 printable ASCII characters, no spaces, quotes or backslashes"
        )


def parse_patch_options(items, dim: int) -> dict[str, tuple[str, str | None]]:
    """``["zeta0=inflow:patch", "eta0=floor"]`` -> {face: (name, type or None)}: the ``--patch
    FACE=NAME[:TYPE]`` options (a missing TYPE keeps the face's type). MeshgenError when malformed."""
    overrides = {}
    for item in items:
        face, sep, rest = item.partition("=")
        name, _, kind = rest.partition(":")
        face, name, kind = face.strip(), name.strip(), kind.strip()
        if not sep or not face or not name:
            raise MeshgenError(f"malformed --patch {item!r}: expected FACE=NAME[:TYPE], e.g. zeta0=inlet:patch")
        if face not in cube.face_names(dim):
            raise MeshgenError(
                f"--patch {item!r}: unknown face '{face}' of a {dim}D mesh (faces: {', '.join(cube.face_names(dim))})"
            )
        if kind and kind not in PATCH_TYPES:
            raise MeshgenError(f"--patch {item!r}: unknown type '{kind}' (types: {', '.join(PATCH_TYPES)})")
        check_patch_name(name)
        overrides[face] = (name, kind or None)
    return overrides


def as_records(patches) -> list[dict]:
    """JSON-ready ``[{"name", "type", "faces"}]`` (what metadata and ``--json`` carry)."""
    return [{"name": p.name, "type": p.type, "faces": list(p.faces)} for p in patches]


def from_records(records) -> list[Patch]:
    return [Patch(str(r["name"]), str(r["type"]), tuple(r["faces"])) for r in records]


def check_covers(patches, dim: int) -> list[Patch]:
    """``patches`` (Patch objects, records, or None for the defaults) checked to cover every face of
    the ``dim``-cube exactly once; returned as Patch objects."""
    if patches is None:
        return default_patches(dim)
    patches = [p if isinstance(p, Patch) else from_records([p])[0] for p in patches]
    assignment = {}
    for patch in patches:
        check_patch_name(patch.name)
        if patch.type not in PATCH_TYPES:
            raise MeshgenError(f"patch '{patch.name}': unknown type '{patch.type}' (types: {', '.join(PATCH_TYPES)})")
        for face in patch.faces:
            if face not in cube.face_names(dim):
                raise MeshgenError(f"patch '{patch.name}': unknown face '{face}' of a {dim}D mesh")
            if face in assignment:
                raise MeshgenError(f"face {face} is in both patch '{assignment[face][0]}' and '{patch.name}'")
            assignment[face] = (patch.name, patch.type)
    missing = [face for face in cube.face_names(dim) if face not in assignment]
    if missing:
        raise MeshgenError(f"no patch covers the face(s) {', '.join(missing)}")
    return patches_from_assignment({face: assignment[face] for face in cube.face_names(dim)})
